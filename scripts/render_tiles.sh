#!/usr/bin/env bash
# Local render farm: scripts/render_tiles.sh SCENE N OUT.exr [render options...]
# Renders the N tiles of SCENE (tessera render --tile I/N) in parallel with xargs -P (TESSERA_JOBS jobs,
# default: the number of cores; each render gets --threads 1 unless the options say otherwise), then joins
# them with tessera assemble, which refuses an incomplete or mixed set. The same contract a Slurm job
# array uses: one task per tile index, then a dependent assemble. With Reyes (the default engine) a first
# job renders the scene's shadow maps once (--shadow-maps-only) into a cache the tiles read
# (--shadow-map-cache), instead of every tile rendering them again. Exit status: tessera's (2 bad input).
set -euo pipefail
if [ $# -lt 3 ]; then
    echo "usage: $0 SCENE N OUT.exr [tessera render options...]" >&2
    exit 2
fi
scene=$1 n=$2 out=$3
shift 3
tessera=${TESSERA:-$(dirname "$0")/../build/tessera}
case $n in '' | *[!0-9]*) echo "error: N must be a positive integer, got '$n'" >&2; exit 2 ;; esac
[ "$n" -ge 1 ] || { echo "error: N must be >= 1" >&2; exit 2; }
jobs=${TESSERA_JOBS:-$(nproc)}
dir=$(mktemp -d "${TMPDIR:-/tmp}/tessera_tiles.XXXXXX")
trap 'rm -rf "$dir"' EXIT
threads=(--threads 1)
engine=reyes prev=
for a in "$@"; do
    [ "$a" = --threads ] && threads=()
    [ "$prev" = --engine ] && engine=$a
    case $a in --engine=*) engine=${a#--engine=} ;; esac
    prev=$a
done
maps=()
if [ "$engine" = reyes ]; then
    maps=(--shadow-map-cache "$dir/shadowmaps")
    "$tessera" render "$scene" -q "$@" "${maps[@]}" --shadow-maps-only ||
        { echo "error: the shadow-map job failed; nothing rendered" >&2; exit 2; }
fi
export scene n dir tessera
seq 0 $((n - 1)) | xargs -P "$jobs" -I{} "$tessera" render "$scene" -q "${threads[@]}" "$@" "${maps[@]}" \
    --tile {}/"$n" -o "$dir/tile{}.exr" || { echo "error: a tile failed; nothing assembled" >&2; exit 2; }
tiles=()
for ((i = 0; i < n; ++i)); do tiles+=("$dir/tile$i.exr"); done
"$tessera" assemble "${tiles[@]}" -o "$out"
