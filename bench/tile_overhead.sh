#!/usr/bin/env bash
# Farm tiles' overhead (issue 17): the CPU time (user + system) of rendering a scene as N tiles, one
# `tessera render --tile I/N` process each with one thread, against the single render, for N = 1, 4, 16,
# 64. What a tile repeats: loading the scene, the engine's set-up (split and bound in Reyes, the BVH in the
# ray tracer), the shadow maps (Reyes) and the filter margin's samples around the tile. Reyes is measured
# twice: each tile rendering its own shadow maps ("maps": "per tile"), and the farm scripts' way, one
# --shadow-maps-only job into a --shadow-map-cache that the tiles read ("maps": "cached", the job's CPU
# counted). Writes bench/results/tile_overhead.json.
# Usage: bench/tile_overhead.sh [SCENE] [render options...]   (default: scenes/teapot.rib --res 640x480)
set -euo pipefail
cd "$(dirname "$0")/.."
scene=${1:-scenes/teapot.rib}
shift || true
opts=("$@")
[ ${#opts[@]} -gt 0 ] || opts=(--res 640x480)
tessera=build/tessera
command -v /usr/bin/time >/dev/null || { echo "error: needs /usr/bin/time (apt-get install time)" >&2; exit 2; }
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
mkdir -p bench/results
cpu_of() {  # CPU seconds (user + sys) of the command
    /usr/bin/time -f "%U %S" -o "$dir/t" "$@" >/dev/null 2>&1
    awk '{print $1 + $2}' "$dir/t"
}
rows=()
for mode in reyes reyes-cached rt; do
    engine=${mode%-cached}
    maps="per tile" cache=()
    [ "$engine" = rt ] && maps="none (traced)"
    single=$(cpu_of "$tessera" render "$scene" -q --threads 1 --engine "$engine" "${opts[@]}" -o "$dir/one.exr")
    for n in 1 4 16 64; do
        total=0
        if [ "$mode" = reyes-cached ]; then
            maps=cached
            rm -rf "$dir/maps"
            cache=(--shadow-map-cache "$dir/maps")
            total=$(cpu_of "$tessera" render "$scene" -q --threads 1 "${opts[@]}" "${cache[@]}" --shadow-maps-only)
        fi
        for ((i = 0; i < n; ++i)); do
            t=$(cpu_of "$tessera" render "$scene" -q --threads 1 --engine "$engine" "${opts[@]}" "${cache[@]}" \
                --tile "$i/$n" -o "$dir/t$i.exr")
            total=$(awk -v a="$total" -v b="$t" 'BEGIN {print a + b}')
        done
        ratio=$(awk -v a="$total" -v b="$single" 'BEGIN {printf "%.3f", a / b}')
        echo "$engine (maps: $maps): $n tiles: ${total} s CPU, single ${single} s: x$ratio"
        rows+=("{\"engine\": \"$engine\", \"maps\": \"$maps\", \"tiles\": $n, \"cpu_s\": $total, \"single_cpu_s\": $single, \"ratio\": $ratio}")
    done
done
{
    echo "{\"scene\": \"$scene\", \"options\": \"${opts[*]}\", \"rows\": ["
    (IFS=,; echo "${rows[*]}")
    echo "]}"
} > bench/results/tile_overhead.json
echo "wrote bench/results/tile_overhead.json"
