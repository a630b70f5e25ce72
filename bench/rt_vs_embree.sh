#!/usr/bin/env bash
# Ray tracer against the Embree triangle baseline (issue 18): per scene, Tessera's rt and
# build/embree_baseline run alternately R times at 800x600, 4 spp, 2 threads; minimum build and trace time,
# largest peak RSS of each process (/usr/bin/time). Needs build/embree_baseline (apt-get install
# libembree-dev, then rebuild). Usage: R=3 SCENES="teapot killeroo" bench/rt_vs_embree.sh [path/to/tessera]
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BIN="${1:-$ROOT/build/tessera}"
EMBREE="$ROOT/build/embree_baseline"
R="${R:-3}"
[ -x "$EMBREE" ] || { echo "no $EMBREE (apt-get install libembree-dev, rebuild)"; exit 2; }
TMP="$(mktemp -d /tmp/rt_vs_embree.XXXXXX)"
trap 'rm -rf "$TMP"' EXIT
for sc in ${SCENES:-teapot killeroo bigguy killeroo2 bigguy9 bigguy24}; do
    : > "$TMP/t"; : > "$TMP/e"
    for _ in $(seq "$R"); do
        m=$( { /usr/bin/time -f "%M" "$BIN" render "$ROOT/scenes/$sc.rib" --engine rt --threads 2 --res 800x600 \
            --spp 4 --stats "$TMP/s.json" -o "$TMP/t.png" -q; } 2>&1 | tail -1)
        python3 -c "import json;s=json.load(open('$TMP/s.json'));print(s['build_ms'],s['trace_ms'],$m)" >> "$TMP/t"
        m=$( { /usr/bin/time -f "%M" "$EMBREE" "$ROOT/scenes/$sc.rib" --res 800x600 --spp 4 --threads 2 --runs 1 \
            -o "$TMP/e.png" > "$TMP/e.json"; } 2>&1 | tail -1)
        python3 -c "import json;s=json.load(open('$TMP/e.json'));print(s['tessellate_ms']+s['build_ms'],s['trace_ms_median'],$m,s['embree_bytes_peak']+s['mesh_bytes'])" >> "$TMP/e"
    done
    python3 - "$sc" "$TMP/t" "$TMP/e" <<'PY'
import sys
sc, t, e = sys.argv[1], [list(map(float, l.split())) for l in open(sys.argv[2])], [list(map(float, l.split())) for l in open(sys.argv[3])]
tb, tt, tp = min(r[0] for r in t), min(r[1] for r in t), max(r[2] for r in t) / 1024
eb, et, ep, eby = min(r[0] for r in e), min(r[1] for r in e), max(r[2] for r in e) / 1024, e[-1][3] / 2**20
print(f"| {sc} | {tb:.0f} | {eb:.0f} | {tt:.0f} | {et:.0f} | {tt/et:.2f} | {tp:.0f} | {ep:.0f} ({eby:.0f}) | {tp/ep:.2f} |")
PY
done
