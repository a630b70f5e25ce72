#!/usr/bin/env bash
# Ambient occlusion (issue 14): paper 002's Table 5.1 as ratios on this machine. Per model (Big Guy,
# Killeroo, 2 Killeroos, 9 Big Guys: the shipped scenes) and rays per hit (64 .. 1024), one camera ray per
# pixel at RES and --integrator ao: rays traced, trace time and time per ray (thread time: trace wall x
# threads / rays). The paper's point: time per ray is flat in the ray count and grows slowly with the model.
# Writes bench/results/ao_<timestamp>.json (one object per line) and prints a markdown table.
# Usage: bench/ao_table.sh [build dir]   (RES, THREADS, COUNTS, SCENES override)
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BUILD="${1:-$ROOT/build}"
BIN="$BUILD/tessera"
RES="${RES:-256x256}"
THREADS="${THREADS:-2}"
COUNTS="${COUNTS:-64 128 256 512 1024}"
SCENES="${SCENES:-bigguy killeroo killeroo2 bigguy9}"
mkdir -p "$ROOT/bench/results"
OUT="$ROOT/bench/results/ao_$(date -u +%Y%m%dT%H%M%SZ).json"
: > "$OUT"
TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT
for scene in $SCENES; do
    for n in $COUNTS; do
        "$BIN" render "$ROOT/scenes/$scene.rib" --engine rt --integrator ao --ao-samples "$n" --res "$RES" \
            --spp 1 --threads "$THREADS" -q -o "$TMP/ao.exr" --stats "$TMP/s.json"
        python3 - "$scene" "$n" "$TMP/s.json" "$THREADS" >> "$OUT" <<'PY'
import json, sys
scene, n, path, threads = sys.argv[1], int(sys.argv[2]), sys.argv[3], int(sys.argv[4])
s = json.load(open(path))
rays = s["rays_total"]
print(json.dumps({"scene": scene, "rays_per_hit": n, "hits": s["hits"]["primary"], "rays": rays,
                  "trace_ms": s["trace_ms"], "us_per_ray": s["trace_ms"] * 1e3 * threads / rays,
                  "patches": s["patches_in"], "res": s.get("width", 0)}))
PY
    done
done
python3 - "$OUT" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
counts = sorted({r["rays_per_hit"] for r in rows})
print("| model (patches, hits) | " + " | ".join(f"{c}" for c in counts) + " |")
print("|---|" + "---:|" * len(counts))
for scene in dict.fromkeys(r["scene"] for r in rows):
    rs = {r["rays_per_hit"]: r for r in rows if r["scene"] == scene}
    first = next(iter(rs.values()))
    cells = [f'{rs[c]["rays"]:,}; {rs[c]["trace_ms"]:.0f} ms; {rs[c]["us_per_ray"]:.3f}' for c in counts if c in rs]
    print(f'| {scene} ({first["patches"]}, {first["hits"]}) | ' + " | ".join(cells) + " |")
PY
echo "wrote $OUT"
