#!/usr/bin/env bash
# The ray tracer's whole-process instructions (callgrind, 1 thread: repeatable on a loaded machine) on the
# frames issue 18 tracks, for two tessera binaries (e.g. a session's first and last), with the candidate
# and Newton-start counts of each and whether the images are byte-identical. Two runs at a time.
# Writes bench/results/rt_instructions.json.
# Usage: bash bench/rt_instructions.sh OLD_BINARY NEW_BINARY
set -euo pipefail
cd "$(dirname "$0")/.."
OLD=$1 NEW=$2
OUT=bench/results
mkdir -p "$OUT"
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
declare -A FRAME=(
  [teapot_1024]="scenes/teapot.rib --res 1024x1024 --spp 1"
  [teapot]="scenes/teapot.rib --res 800x600 --spp 4"
  [killeroo]="scenes/killeroo.rib --res 800x600 --spp 4"
  [bigguy]="scenes/bigguy.rib --res 800x600 --spp 4"
  [bigguy24]="scenes/bigguy24.rib --res 800x600 --spp 4"
)
run() {  # run NAME WHICH BINARY
    # shellcheck disable=SC2086
    valgrind --tool=callgrind --callgrind-out-file="$TMP/$1.$2.cg" "$3" render ${FRAME[$1]} --engine rt \
        --threads 1 -o "$TMP/$1.$2.png" --stats "$TMP/$1.$2.json" --quiet 2> "$TMP/$1.$2.log" > /dev/null
}
for name in teapot_1024 teapot killeroo bigguy bigguy24; do
    run "$name" old "$OLD" &
    run "$name" new "$NEW"
    wait
done
python3 - "$TMP" <<'PY'
import json, re, sys, filecmp
tmp = sys.argv[1]
out = {}
for name in ["teapot_1024", "teapot", "killeroo", "bigguy", "bigguy24"]:
    row = {}
    for which in ["old", "new"]:
        log = open(f"{tmp}/{name}.{which}.log").read()
        stats = json.load(open(f"{tmp}/{name}.{which}.json"))
        row[which] = {"instructions": int(re.search(r"Collected : (\d+)", log).group(1)),
                      "candidates": stats["candidates"], "newton_runs": stats["newton_runs"]}
    row["ratio"] = row["new"]["instructions"] / row["old"]["instructions"]
    row["images_identical"] = filecmp.cmp(f"{tmp}/{name}.old.png", f"{tmp}/{name}.new.png", shallow=False)
    out[name] = row
    print(f"{name}: {row['old']['instructions'] / 1e6:,.0f} -> {row['new']['instructions'] / 1e6:,.0f} M "
          f"({100 * (row['ratio'] - 1):+.1f}%), images identical: {row['images_identical']}")
json.dump(out, open("bench/results/rt_instructions.json", "w"), indent=1)
PY
