#!/usr/bin/env bash
# Instruction counts (callgrind: repeatable on a loaded machine) of the teapot benchmarks for two tessera
# binaries, e.g. the previous commit's and this one's, whole run and engine alone (renderRt / renderReyes,
# inclusive). Writes bench/results/callgrind_compare.json.
# Usage: bash bench/callgrind_compare.sh OLD_BINARY NEW_BINARY
set -euo pipefail
cd "$(dirname "$0")/.."
OLD=$1 NEW=$2
OUT=bench/results
mkdir -p "$OUT"
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
S=scenes/teapot.rib
declare -A ARGS=(
  [rt]="--engine rt --res 512x512 --spp 1"
  [reyes]="--engine reyes --res 400x300"
)
json="{"
for bench in rt reyes; do
  for which in old new; do
    bin=$OLD; [ $which = new ] && bin=$NEW
    # shellcheck disable=SC2086
    valgrind --tool=callgrind --callgrind-out-file="$TMP/$bench.$which" "$bin" render $S ${ARGS[$bench]} \
      --threads 1 -o "$TMP/$bench.$which.png" --quiet 2> "$TMP/$bench.$which.log" > /dev/null
    total=$(grep -o 'Collected : [0-9]*' "$TMP/$bench.$which.log" | awk '{print $3}')
    fn=$([ $bench = rt ] && echo renderRt || echo renderReyes)
    engine=$(callgrind_annotate --inclusive=yes "$TMP/$bench.$which" 2>/dev/null |
             grep -E "tessera::$fn\(tessera::Scene const&, tessera::RenderSettings const&\) \[" | head -1 |
             awk '{gsub(",", "", $1); print $1}')
    eval "${bench}_${which}_total=$total ${bench}_${which}_engine=${engine:-0}"
  done
  ot=${bench}_old_total nt=${bench}_new_total oe=${bench}_old_engine ne=${bench}_new_engine
  json+="\"$bench\": {\"args\": \"${ARGS[$bench]} --threads 1\", \"old_total\": ${!ot}, \"new_total\": ${!nt},"
  json+=" \"old_engine\": ${!oe}, \"new_engine\": ${!ne},"
  json+=" \"ratio_total\": $(python3 -c "print(round(${!nt}/${!ot}, 4))"),"
  json+=" \"ratio_engine\": $(python3 -c "print(round(${!ne}/max(1,${!oe}), 4))")},"
done
json="${json%,}}"
echo "$json" | python3 -m json.tool | tee "$OUT/callgrind_compare.json"
