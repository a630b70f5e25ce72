#!/usr/bin/env bash
# Area lights and path tracing (issue 14): the soft-shadow and path-tracing columns of paper 002's Table
# 5.1 as ratios on this machine, on the box scene (scenes/bigguy_box_area.rib). Soft shadows: the direct
# integrator at 16 and 64 shadow rays per hit (--light-samples), 1 camera ray per pixel; path tracing: 1, 4
# and 16 spp (the paper's point: time linear in spp). Per row: rays traced, trace wall time and thread time
# per ray (trace wall x threads / rays). Gloss (Table 5.3): scenes/bigguy_box_glossy.rib with every
# "spread" set to the paper's 0.1 / 0.4 / 0.6 at 4 reflection rays per camera hit, and 0.4 at 16.
# Writes bench/results/light_transport_<timestamp>.json (one object per line) and prints a markdown table.
# Usage: bench/light_transport_table.sh [build dir]   (RES, THREADS, SCENE override)
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BUILD="${1:-$ROOT/build}"
BIN="$BUILD/tessera"
RES="${RES:-128x128}"
THREADS="${THREADS:-2}"
SCENE="${SCENE:-bigguy_box_area}"
mkdir -p "$ROOT/bench/results"
OUT="$ROOT/bench/results/light_transport_$(date -u +%Y%m%dT%H%M%SZ).json"
: > "$OUT"
TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT
SCENE_FILE="$ROOT/scenes/$SCENE.rib"
row() {  # label, then tessera options (the scene: $SCENE_FILE)
    local label=$1
    shift
    "$BIN" render "$SCENE_FILE" --engine rt --res "$RES" --threads "$THREADS" -q -o "$TMP/i.exr" \
        --stats "$TMP/s.json" "$@"
    python3 - "$label" "$TMP/s.json" "$THREADS" >> "$OUT" <<'PY'
import json, sys
label, path, threads = sys.argv[1], sys.argv[2], int(sys.argv[3])
s = json.load(open(path))
rays = s["rays_total"]
print(json.dumps({"row": label, "rays": rays, "shadow_rays": s["rays"]["shadow"], "trace_ms": s["trace_ms"],
                  "us_per_ray": s["trace_ms"] * 1e3 * threads / rays, "integrator": s["integrator"]}))
PY
}
row "soft shadows, 16 rays/hit" --spp 1 --light-samples 16
row "soft shadows, 64 rays/hit" --spp 1 --light-samples 64
row "path, 1 spp" --integrator path --spp 1
row "path, 4 spp" --integrator path --spp 4
row "path, 16 spp" --integrator path --spp 16
# Beside the scene for its ReadArchive path; removed on exit.
GLOSS="$ROOT/scenes/.gloss_bench.rib"
trap 'rm -rf "$TMP" "$GLOSS"' EXIT
for cfg in "0.1 4" "0.4 4" "0.6 4" "0.4 16"; do
    set -- $cfg
    sed "s/\"spread\" \[ [0-9.]* \]/\"spread\" [ $1 ]/g; s/\"samples\" \[ 4 \]/\"samples\" [ $2 ]/g" \
        "$ROOT/scenes/bigguy_box_glossy.rib" > "$GLOSS"
    SCENE_FILE="$GLOSS" row "gloss, spread $1, $2 rays/hit" --spp 1
done
python3 - "$OUT" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
print("| row | rays | trace ms | us per ray (thread time) | time / first row of its kind |")
print("|---|---:|---:|---:|---:|")
base = {}
for r in rows:
    kind = r["integrator"] + (" gloss" if r["row"].startswith("gloss") else "")
    base.setdefault(kind, r["trace_ms"])
    print(f'| {r["row"]} | {r["rays"]:,} | {r["trace_ms"]:.0f} | {r["us_per_ray"]:.3f} | {r["trace_ms"] / base[kind]:.2f} |')
PY
echo "wrote $OUT"
