#!/usr/bin/env bash
# The ray tracer's leaf slabs (docs/rt.md, "Leaf slabs") against --no-leaf-slabs, in one binary: per frame
# the candidates, Newton starts and slab-culled pairs (--stats), the minimum and median trace time of R
# interleaved runs on 2 threads, and with CALLGRIND=1 the whole process's instructions on 1 thread (the
# repeatable measure on a noisy machine). Writes bench/results/leaf_slabs.json.
# Usage: R=5 CALLGRIND=1 bash bench/leaf_slabs.sh [path/to/tessera]
set -euo pipefail
cd "$(dirname "$0")/.."
BIN="${1:-build/tessera}"
R="${R:-5}"
OUT=bench/results
mkdir -p "$OUT"
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
FRAMES=("teapot 1024x1024 1" "teapot 800x600 4" "killeroo 800x600 4" "bigguy 800x600 4")
: > "$TMP/rows"
for frame in "${FRAMES[@]}"; do
  read -r scene res spp <<< "$frame"
  for run in $(seq "$R"); do
    for mode in slabs none; do
      flag=""; [ $mode = none ] && flag="--no-leaf-slabs"
      # shellcheck disable=SC2086
      "$BIN" render "scenes/$scene.rib" --engine rt --res "$res" --spp "$spp" --threads 2 $flag \
        --stats "$TMP/s.json" -o "$TMP/i.png" -q
      python3 -c "
import json; s = json.load(open('$TMP/s.json'))
print('$scene $res $spp $mode', s['trace_ms'], s['candidates'], s['newton_runs'], s['slab_culled'], s['leaf_slabs'])" \
        >> "$TMP/rows"
    done
  done
  if [ "${CALLGRIND:-0}" = 1 ]; then
    for mode in slabs none; do
      flag=""; [ $mode = none ] && flag="--no-leaf-slabs"
      # shellcheck disable=SC2086
      valgrind --tool=callgrind --callgrind-out-file="$TMP/cg" "$BIN" render "scenes/$scene.rib" --engine rt \
        --res "$res" --spp "$spp" --threads 1 $flag -o "$TMP/i.png" -q 2> "$TMP/cg.log" > /dev/null
      echo "$scene $res $spp $mode instructions $(grep -o 'Collected : [0-9]*' "$TMP/cg.log" | awk '{print $3}')" \
        >> "$TMP/rows"
    done
  fi
done
python3 - "$TMP/rows" "$OUT/leaf_slabs.json" <<'PY'
import json, statistics, sys
rows = [l.split() for l in open(sys.argv[1])]
out = {}
for r in rows:
    key = f"{r[0]} {r[1]} {r[2]} spp"
    e = out.setdefault(key, {}).setdefault(r[3], {"trace_ms": []})
    if r[4] == "instructions":
        e["instructions"] = int(r[5])
    else:
        e["trace_ms"].append(float(r[4]))
        e["candidates"], e["newton_runs"], e["slab_culled"] = int(r[5]), int(r[6]), int(r[7])
        e["leaf_slabs"] = r[8] == "True"
for key, m in out.items():
    for e in m.values():
        t = e.pop("trace_ms")
        e["trace_ms_min"], e["trace_ms_median"] = round(min(t), 1), round(statistics.median(t), 1)
    s, n = m["slabs"], m["none"]
    m["ratios"] = {k: round(s[k] / n[k], 4) for k in ("candidates", "newton_runs", "trace_ms_min", "trace_ms_median",
                                                      "instructions") if k in s and n.get(k)}
json.dump(out, open(sys.argv[2], "w"), indent=2)
for key, m in out.items():
    print(key, m["ratios"])
PY
