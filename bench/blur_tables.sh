#!/usr/bin/env bash
# Motion blur and depth of field (issue 11): the paper's Tables 1 and 2 as ratios on this machine, and the
# issue's teapot frames, by tessera_blur_bench (bench/blur_bench.cpp, in process, errors in float).
#  - table1: Killeroo spinning 30 degrees about its up axis, seen from above (scenes/killeroo_spin.rib):
#    sharp, simple and bbox at 16/25/64 spp, interleaved K = 2, 3, 4 x P = 1, 64 at 16 spp.
#  - table2: the still Killeroo of the same scene through a lens focused on its head (--dof).
#  - teapot: scenes/motion_teapot.rib and scenes/dof_teapot.rib at 16 spp, every scheme and the sharp frame,
#    both engines for the default scheme (rt at 16 and 64 spp).
# Timings (engine_ms, median of RUNS) at RES; RMSE of premultiplied RGB against a bbox reference at REF_SPP
# rendered at QRES (RMSE runs are separate, smaller renders: a 1024-spp reference at 800x600 takes tens of
# minutes here). Writes bench/results/blur_<timestamp>.json (one object per line).
# Usage: bench/blur_tables.sh [build dir]   (RES, QRES, REF_SPP, RUNS, THREADS, PARTS override)
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BUILD="${1:-$ROOT/build}"
BIN="$BUILD/tessera_blur_bench"
RES="${RES:-800x600}"
QRES="${QRES:-400x300}"
REF_SPP="${REF_SPP:-1024}"
RUNS="${RUNS:-3}"
THREADS="${THREADS:-2}"
PARTS="${PARTS:-table1 table2 teapot}"
mkdir -p "$ROOT/bench/results"
OUT="$ROOT/bench/results/blur_$(date -u +%Y%m%dT%H%M%SZ).json"
: > "$OUT"
run() {  # label, then tessera_blur_bench arguments
    local label="$1"; shift
    "$BIN" "$@" --threads "$THREADS" | while IFS= read -r line; do
        echo "{\"part\":\"$label\",${line#\{}" | tee -a "$OUT"
    done
}
KILLEROO="$ROOT/scenes/killeroo_spin.rib"
KDOF="0.5,50,505"  # fstop, focal length, focal distance (the head is about 500 units below the camera)
for part in $PARTS; do
    case "$part" in
    table1)
        run table1_time "$KILLEROO" --res "$RES" --ref-spp 0 --runs "$RUNS" --sharp --spp "16 25 64" --schemes "simple bbox"
        run table1_time "$KILLEROO" --res "$RES" --ref-spp 0 --runs "$RUNS" --spp "16" --schemes interleaved --tiles "2 3 4" --perms "1 64"
        run table1_rmse "$KILLEROO" --res "$QRES" --ref-spp "$REF_SPP" --runs 1 --sharp --spp "16 25 64" --schemes "simple bbox"
        run table1_rmse "$KILLEROO" --res "$QRES" --ref-spp "$REF_SPP" --runs 1 --spp "16" --schemes interleaved --tiles "2 3 4" --perms "1 64"
        ;;
    table2)
        run table2_time "$KILLEROO" --no-motion --dof "$KDOF" --res "$RES" --ref-spp 0 --runs "$RUNS" --sharp --spp "16 25 64" --schemes "simple bbox"
        run table2_time "$KILLEROO" --no-motion --dof "$KDOF" --res "$RES" --ref-spp 0 --runs "$RUNS" --spp "16" --schemes interleaved --tiles "2 3 4" --perms "64"
        run table2_rmse "$KILLEROO" --no-motion --dof "$KDOF" --res "$QRES" --ref-spp "$REF_SPP" --runs 1 --sharp --spp "16 25 64" --schemes "simple bbox"
        run table2_rmse "$KILLEROO" --no-motion --dof "$KDOF" --res "$QRES" --ref-spp "$REF_SPP" --runs 1 --spp "16" --schemes interleaved --tiles "2 3 4" --perms "64"
        ;;
    teapot)
        for scene in motion_teapot dof_teapot; do
            run "teapot_${scene}" "$ROOT/scenes/$scene.rib" --res "$RES" --ref-spp 256 --runs "$RUNS" --sharp --spp 16 --schemes "bbox simple interleaved" --tiles 2
            run "teapot_${scene}_rt" "$ROOT/scenes/$scene.rib" --engine rt --res "$RES" --ref-spp 0 --runs "$RUNS" --sharp --spp "16 64" --schemes bbox
        done
        ;;
    esac
done
echo "wrote $OUT" >&2
