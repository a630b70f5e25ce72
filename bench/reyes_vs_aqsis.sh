#!/usr/bin/env bash
# Reyes against Aqsis 1.8 on the same RIB (issue 18): by default the sharp teapot (scenes/dof_teapot.rib
# without its DepthOfField line: 800x600, PixelSamples 4 4, ShadingRate 1, plastic) and Killeroo (796x515,
# 16 spp, matte); SCENES="teapot killeroo bigguy24" for others. Shadows off in both. Aqsis and Tessera (2
# threads, and 1 thread) run alternately R times: wall time and peak RSS of each whole process, Tessera's
# engine time from its stats. Aqsis is built from its public source beside this repository by
# bench/build_aqsis.sh, never committed (docs/benchmarks/fixed_costs.md, "Session 23"); pass its binary.
# Usage: R=5 bench/reyes_vs_aqsis.sh /path/to/aqsis [path/to/tessera]
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
AQSIS="${1:?usage: bench/reyes_vs_aqsis.sh /path/to/aqsis [tessera]}"
BIN="${2:-$ROOT/build/tessera}"
R="${R:-5}"
[ -x "$AQSIS" ] || { echo "no Aqsis binary at $AQSIS"; exit 2; }
TMP="$(mktemp -d /tmp/reyes_vs_aqsis.XXXXXX)"
trap 'rm -rf "$TMP"' EXIT
mkdir -p "$TMP/archives" "$ROOT/bench/results"
cp "$ROOT"/scenes/archives/*.rib "$TMP/archives/"
# The RIBs as both renderers read them: the image goes to a TIFF (Aqsis' "file" driver) in $TMP; no depth
# of field; Tessera's per-light shadow attribute left out (without it lights cast no shadows in Tessera).
# "teapot" is dof_teapot.rib without its DepthOfField line; other names are scenes/NAME.rib.
for sc in ${SCENES:-teapot killeroo}; do
    src="$ROOT/scenes/$sc.rib"
    [ "$sc" = teapot ] && src="$ROOT/scenes/dof_teapot.rib"
    [ -f "$src" ] || { echo "no scene $src"; exit 2; }
    sed -e "s#^Display .*#Display \"$TMP/$sc.tif\" \"file\" \"rgba\"#" -e '/^DepthOfField /d' \
        -e '/^Attribute "light" "shadows"/d' "$src" > "$TMP/$sc.rib"
done
OUT="$ROOT/bench/results/reyes_vs_aqsis.json"
echo "[" > "$OUT"
first=1
for sc in ${SCENES:-teapot killeroo}; do
    : > "$TMP/rows"
    for _ in $(seq "$R"); do
        # Wall time from the shell's clock in ns (/usr/bin/time's %e has 10 ms steps); peak RSS from %M.
        s0=$(date +%s%N)
        m=$( { cd "$TMP" && /usr/bin/time -f "%M" "$AQSIS" "$TMP/$sc.rib" > /dev/null; } 2>&1 | tail -1)
        a="$(python3 -c "print(($(date +%s%N) - $s0) / 1e9)") $m"
        for t in 2 1; do
            s0=$(date +%s%N)
            m=$( { /usr/bin/time -f "%M" "$BIN" render "$TMP/$sc.rib" --engine reyes --shadows off \
                --threads "$t" -q -o "$TMP/t.png" --stats "$TMP/s.json"; } 2>&1 | tail -1)
            w="$(python3 -c "print(($(date +%s%N) - $s0) / 1e9)") $m"
            e=$(python3 -c "import json;s=json.load(open('$TMP/s.json'));print(s['engine_ms'],s['load_ms'])")
            echo "$a $t $w $e" >> "$TMP/rows"
        done
    done
    [ $first = 1 ] || echo "," >> "$OUT"
    first=0
    python3 - "$sc" "$TMP/rows" >> "$OUT" <<'PY'
import json, statistics, sys
sc, rows = sys.argv[1], [l.split() for l in open(sys.argv[2])]
aq = [float(r[0]) for r in rows[::2]]
aq_rss = max(int(r[1]) for r in rows) / 1024
rec = {"scene": sc, "aqsis_wall_s": aq, "aqsis_peak_mb": aq_rss}
for t in ("2", "1"):
    sel = [r for r in rows if r[2] == t]
    rec[f"tessera_t{t}_wall_s"] = [float(r[3]) for r in sel]
    rec[f"tessera_t{t}_engine_ms"] = [float(r[5]) for r in sel]
    rec[f"tessera_t{t}_load_ms"] = [float(r[6]) for r in sel]
    rec[f"tessera_t{t}_peak_mb"] = max(int(r[4]) for r in sel) / 1024
w2, e2 = rec["tessera_t2_wall_s"], rec["tessera_t2_engine_ms"]
rec["ratio_wall_min"] = min(aq) / min(w2)
rec["ratio_wall_median"] = statistics.median(aq) / statistics.median(w2)
rec["ratio_engine_min"] = min(aq) / (min(e2) / 1000)
sys.stderr.write(
    f"{sc}: Aqsis {min(aq):.2f} s min, {statistics.median(aq):.2f} median ({aq_rss:.0f} MB); "
    f"Tessera 2 threads wall {min(w2):.3f} / {statistics.median(w2):.3f} s, engine {min(e2):.0f} ms "
    f"load {min(rec['tessera_t2_load_ms']):.0f} ms ({rec['tessera_t2_peak_mb']:.0f} MB); 1 thread wall {min(rec['tessera_t1_wall_s']):.3f} s. "
    f"Aqsis / Tessera: wall {rec['ratio_wall_min']:.1f}x (min) {rec['ratio_wall_median']:.1f}x (median), "
    f"Aqsis wall / Tessera engine {rec['ratio_engine_min']:.1f}x\n")
print(json.dumps(rec, indent=1))
PY
done
echo "]" >> "$OUT"
echo "saved $OUT"
