#!/usr/bin/env bash
# Slurm render farm: scripts/slurm_render.sh SCENE N OUT.exr [tessera render options...]
# With Reyes (the default engine) it first submits a job that renders the scene's shadow maps once
# (tessera render --shadow-maps-only) into OUT.tiles/shadowmaps, which the tiles read (--shadow-map-cache)
# instead of each rendering them again; the array runs after it (afterany: if it failed, each tile makes
# its own maps). Then a job array of N tasks (sbatch --array=0-(N-1)); task I runs
#   tessera render SCENE --tile I/N -o OUT.tiles/tileI.exr [options] --threads ${SLURM_CPUS_PER_TASK:-1}
# and retries a failed render (TESSERA_SLURM_RETRIES times, default 1), logging the tile index and exit status
# of each failed attempt; a tile file appears only once its render succeeded. Then it submits an assemble
# job (--dependency=afterany on the array, so it also runs when a tile failed) that names every missing tile
# with its exit status and log, and runs tessera assemble, which joins a complete set into OUT.exr and
# refuses an incomplete one (exit 2). This is the contract of scripts/render_tiles.sh (xargs -P locally).
# OUT.tiles/ (next to OUT.exr, so nodes that share the filesystem see it) holds the tiles, the job scripts
# and the logs (tile-ARRAYID_I.log, assemble.log).
# Environment: TESSERA (binary, default build/tessera of this repository), TESSERA_SLURM_PARTITION,
# TESSERA_SLURM_CPUS (--cpus-per-task), TESSERA_SLURM_RETRIES, TESSERA_SLURM_SBATCH_ARGS (more sbatch
# options, split on spaces, e.g. "--time=10 --account=x"), TESSERA_SLURM_WAIT=1 (block until the assemble
# job ends, sbatch --wait, and exit with its status; otherwise print the job ids and exit 0).
# Exit status: 2 for bad arguments; with TESSERA_SLURM_WAIT=1, the assemble job's (0 ok, 2 incomplete set).
set -euo pipefail

die() { echo "slurm_render.sh: error: $*" >&2; exit 2; }
if [ $# -lt 3 ]; then
    echo "usage: $0 SCENE N OUT.exr [tessera render options...]" >&2
    exit 2
fi
scene=$1 n=$2 out=$3
shift 3
case $n in '' | *[!0-9]*) die "N must be a positive integer, got '$n'" ;; esac
n=$((10#$n))
[ "$n" -ge 1 ] || die "N must be >= 1, got $n"
[ -f "$scene" ] || die "no such scene file: '$scene'"
case $out in *.exr) ;; *) die "OUT must be an .exr file (tiles carry their place in the image), got '$out'" ;; esac
threads=1 engine=reyes prev=
for a in "$@"; do
    case $a in
        -o | --output | --tile | --tile=* | --frames | --frames=* | --shadow-map-cache | --shadow-maps-only)
            die "option '$a' is set by the farm (each task renders --tile I/N into OUT.tiles/)" ;;
        --threads | --threads=*) threads= ;;  # the caller's --threads wins over SLURM_CPUS_PER_TASK
        --engine=*) engine=${a#--engine=} ;;
    esac
    [ "$prev" = --engine ] && engine=$a
    prev=$a
done
retries=${TESSERA_SLURM_RETRIES:-1}
case $retries in '' | *[!0-9]*) die "TESSERA_SLURM_RETRIES must be a count, got '$retries'" ;; esac
cpus=${TESSERA_SLURM_CPUS:-}
case $cpus in '' ) ;; *[!0-9]* | 0) die "TESSERA_SLURM_CPUS must be a positive integer, got '$cpus'" ;; esac
command -v sbatch >/dev/null || die "sbatch not found (is Slurm installed and in PATH?)"

abspath() { (cd "$(dirname "$1")" && echo "$PWD/$(basename "$1")"); }
tessera=${TESSERA:-$(dirname "$0")/../build/tessera}
[ -x "$tessera" ] || die "tessera binary '$tessera' is not executable (build it, or set TESSERA)"
tessera=$(abspath "$tessera")
scene=$(abspath "$scene")
outdir=$(dirname "$out")
[ -d "$outdir" ] || die "the folder of OUT does not exist: '$outdir'"
out=$(abspath "$out")
dir=${out%.exr}.tiles
mkdir -p "$dir"
# Tiles of an earlier run must not complete this one.
rm -f "$dir"/tile*.exr "$dir"/tile*.status "$dir"/tile-*.log "$dir"/assemble.log

# The job scripts, with every path and option quoted into them.
q() { printf '%q' "$1"; }                           # one word
qs() { local a; for a in "$@"; do printf '%q ' "$a"; done; }  # words, each followed by a space
maps=()
[ "$engine" = reyes ] && maps=(--shadow-map-cache "$dir/shadowmaps")
if [ ${#maps[@]} -gt 0 ]; then
    cat >"$dir/maps.sbatch" <<EOF
#!/usr/bin/env bash
# Written by scripts/slurm_render.sh: the scene's shadow maps, once, for the $n tiles.
exec $(q "$tessera") render $(q "$scene") $(qs "$@")$(qs "${maps[@]}")--shadow-maps-only
EOF
    chmod +x "$dir/maps.sbatch"
fi
cat >"$dir/tile.sbatch" <<EOF
#!/usr/bin/env bash
# Written by scripts/slurm_render.sh: renders tile \$SLURM_ARRAY_TASK_ID of $n, retried $retries time(s).
set -u
i=\${SLURM_ARRAY_TASK_ID:?not run as a Slurm array task}
threads=()
$( [ -n "$threads" ] && echo 'threads=(--threads "${SLURM_CPUS_PER_TASK:-1}")' )
tile=$(q "$dir")/tile\$i.exr
part=$(q "$dir")/tile\$i.part.exr
status=$(q "$dir")/tile\$i.status
rm -f "\$part" "\$status"
attempt=0
while :; do
    attempt=\$((attempt + 1))
    echo "tile \$i of $n: attempt \$attempt on \$(hostname) (job \${SLURM_ARRAY_JOB_ID:-?}_\$i)"
    $(q "$tessera") render $(q "$scene") -q "\${threads[@]}" $(qs "$@")$(qs "${maps[@]}")--tile "\$i/$n" -o "\$part"
    rc=\$?
    if [ \$rc -eq 0 ] && [ -f "\$part" ]; then
        mv -f "\$part" "\$tile"
        echo "ok attempts=\$attempt" >"\$status"
        echo "tile \$i of $n: done"
        exit 0
    fi
    [ \$rc -eq 0 ] && rc=1  # exit 0 without an image is a failure too
    echo "tile \$i of $n: attempt \$attempt failed with exit status \$rc" >&2
    echo "failed exit=\$rc attempts=\$attempt host=\$(hostname)" >"\$status"
    [ \$attempt -gt $retries ] && break
    echo "tile \$i of $n: retrying" >&2
done
rm -f "\$part"
echo "tile \$i of $n: FAILED after \$attempt attempts (exit status \$rc)" >&2
exit \$rc
EOF

cat >"$dir/assemble.sbatch" <<EOF
#!/usr/bin/env bash
# Written by scripts/slurm_render.sh: checks the $n tiles, then joins them (tessera assemble refuses an
# incomplete or mixed set).
set -u
dir=$(q "$dir")
out=$(q "$out")
tiles=() missing=()
for ((i = 0; i < $n; ++i)); do
    if [ -f "\$dir/tile\$i.exr" ]; then
        tiles+=("\$dir/tile\$i.exr")
    else
        missing+=(\$i)
        why="did not run or did not finish (no status file)"
        [ -f "\$dir/tile\$i.status" ] && why=\$(cat "\$dir/tile\$i.status")
        log=\$(ls "\$dir"/tile-*_\$i.log 2>/dev/null | head -1)
        echo "error: tile \$i of $n is missing: \$why\${log:+; log: \$log}" >&2
    fi
done
if [ \${#missing[@]} -gt 0 ]; then
    echo "error: \${#missing[@]} of $n tiles missing (\${missing[*]}); \$out not assembled" >&2
    [ \${#tiles[@]} -eq 0 ] && exit 2
fi
$(q "$tessera") assemble "\${tiles[@]}" -o "\$out"
rc=\$?
[ \${#missing[@]} -gt 0 ] && [ \$rc -eq 0 ] && rc=2
[ \$rc -eq 0 ] && echo "assembled $n tiles into \$out"
exit \$rc
EOF
chmod +x "$dir/tile.sbatch" "$dir/assemble.sbatch"

common=(--parsable --open-mode=append)
[ -n "${TESSERA_SLURM_PARTITION:-}" ] && common+=(--partition="$TESSERA_SLURM_PARTITION")
# shellcheck disable=SC2206
[ -n "${TESSERA_SLURM_SBATCH_ARGS:-}" ] && common+=($TESSERA_SLURM_SBATCH_ARGS)
tilearg=(--array="0-$((n - 1))" --requeue --job-name=tessera-tiles -o "$dir/tile-%A_%a.log")
[ -n "$cpus" ] && tilearg+=(--cpus-per-task="$cpus")

if [ ${#maps[@]} -gt 0 ]; then
    mapsjob=$(sbatch "${common[@]}" --job-name=tessera-maps -o "$dir/maps.log" "$dir/maps.sbatch") ||
        die "sbatch of the shadow-map job failed"
    mapsjob=${mapsjob%%;*}
    echo "shadow maps: job $mapsjob (log $dir/maps.log)"
    tilearg+=(--dependency="afterany:$mapsjob")
fi
array=$(sbatch "${common[@]}" "${tilearg[@]}" "$dir/tile.sbatch") || die "sbatch of the tile array failed"
array=${array%%;*}
echo "tiles: job array $array (tasks 0-$((n - 1)), logs $dir/tile-${array}_I.log)"
asm=(--dependency="afterany:$array" --kill-on-invalid-dep=yes --job-name=tessera-assemble -o "$dir/assemble.log")
if [ "${TESSERA_SLURM_WAIT:-0}" = 1 ]; then
    # sbatch --wait prints the id at submission (stdbuf: line by line into the pipe), then blocks.
    set +e
    stdbuf -oL sbatch "${common[@]}" --wait "${asm[@]}" "$dir/assemble.sbatch" |
        while read -r id; do echo "assemble: job ${id%%;*} (after $array; log $dir/assemble.log), waiting"; done
    rc=${PIPESTATUS[0]}
    set -e
    if [ "$rc" -eq 0 ]; then
        echo "done: $out"
    else
        echo "slurm_render.sh: error: the assemble job failed (exit status $rc):" >&2
        sed 's/^/  /' "$dir/assemble.log" >&2 2>/dev/null || true
    fi
    exit "$rc"
fi
job=$(sbatch "${common[@]}" "${asm[@]}" "$dir/assemble.sbatch") || {
    scancel "$array" 2>/dev/null
    die "sbatch of the assemble job failed (tile array $array cancelled)"
}
echo "assemble: job ${job%%;*} (after $array; log $dir/assemble.log)"
