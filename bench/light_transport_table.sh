#!/usr/bin/env bash
# Area lights and path tracing (issue 14): the soft-shadow and path-tracing columns of paper 002's Table
# 5.1 as ratios on this machine, on the box scene (scenes/bigguy_box_area.rib). Soft shadows: the direct
# integrator at 16 and 64 shadow rays per hit (--light-samples), 1 camera ray per pixel; path tracing: 1, 4
# and 16 spp (the paper's point: time linear in spp). Per row: rays traced, trace wall time and thread time
# per ray (trace wall x threads / rays).
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
row() {  # label, then tessera options
    local label=$1
    shift
    "$BIN" render "$ROOT/scenes/$SCENE.rib" --engine rt --res "$RES" --threads "$THREADS" -q -o "$TMP/i.exr" \
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
python3 - "$OUT" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
print("| row | rays | trace ms | us per ray (thread time) | time / first row of its kind |")
print("|---|---:|---:|---:|---:|")
base = {}
for r in rows:
    kind = r["integrator"]
    base.setdefault(kind, r["trace_ms"])
    print(f'| {r["row"]} | {r["rays"]:,} | {r["trace_ms"]:.0f} | {r["us_per_ray"]:.3f} | {r["trace_ms"] / base[kind]:.2f} |')
PY
echo "wrote $OUT"
