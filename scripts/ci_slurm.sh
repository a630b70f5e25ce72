#!/usr/bin/env bash
# CI: the Slurm render farm for real. Installs slurm-wlm, starts a one-node cluster on the loopback address
# (slurmctld + slurmd as root, AuthType=auth/none, CredType=cred/none, free high ports, its own slurm.conf
# via SLURM_CONF, state, spool, logs and pid files under a mktemp -d; /etc/slurm is never read), then
#   1. scripts/slurm_render.sh SCENE 4 (shadow-map job, job array, dependent assemble, TESSERA_SLURM_WAIT=1)
#      equals the single render pixel for pixel (tessera_imgdiff: max colour and alpha difference 0), the
#      maps were rendered once into the tiles' cache, and scripts/render_tiles.sh (the same contract on
#      xargs -P) equals it too;
#   2. a tile whose first render fails is retried and the image is still exact;
#   3. a tile that always fails is reported (index, exit status) and the assemble job refuses the incomplete
#      set (tessera assemble: "tile 2 of 4 is missing"), slurm_render.sh exits nonzero, no image is written;
#   4. bad arguments exit with 2.
# The daemons are always stopped (trap EXIT) and their ports checked free; on failure it prints the daemon and
# job logs. Needs build/tessera and build/tessera_imgdiff (scripts/build.sh). Fails, never skips, when the
# daemons cannot start. Usage: bash scripts/ci_slurm.sh
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$PWD
scene=scenes/teapot.rib
opts=(--res 160x120 --spp 4)

bash scripts/install_packages.sh slurm-wlm
for b in build/tessera build/tessera_imgdiff; do
    [ -x "$b" ] || { echo "error: $b is missing: build first (bash scripts/build.sh)" >&2; exit 1; }
done
for c in slurmctld slurmd sbatch sinfo squeue scancel; do
    command -v "$c" >/dev/null || { echo "error: $c not found after installing slurm-wlm" >&2; exit 1; }
done

work=$(mktemp -d "${TMPDIR:-/tmp}/tessera_slurm.XXXXXX")
ctld_pid= slurmd_pid= ok=0
port_open() { (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null; }
show_logs() {
    local f
    for f in "$work"/slurmctld.log "$work"/slurmd.log "$work"/slurmctld.out "$work"/slurmd.out; do
        [ -s "$f" ] && { echo "----- $f (last 40 lines)"; tail -n 40 "$f"; }
    done
    for f in "$work"/*.tiles/*.log; do
        [ -s "$f" ] && { echo "----- $f"; cat "$f"; }
    done
    return 0
}
stop_daemons() {
    local rc=$? p t
    set +e
    if [ -n "$ctld_pid" ] && kill -0 "$ctld_pid" 2>/dev/null; then
        squeue -h -o %i 2>/dev/null | xargs -r scancel 2>/dev/null
    fi
    for p in $slurmd_pid $ctld_pid; do kill -TERM "$p" 2>/dev/null; done
    for ((t = 0; t < 100; ++t)); do  # 10 s, then SIGKILL
        alive=0
        for p in $slurmd_pid $ctld_pid; do kill -0 "$p" 2>/dev/null && alive=1; done
        [ $alive = 0 ] && break
        sleep 0.1
    done
    for p in $slurmd_pid $ctld_pid; do
        kill -0 "$p" 2>/dev/null && { echo "warning: daemon $p ignored SIGTERM; killing it" >&2; kill -KILL "$p"; }
    done
    wait 2>/dev/null
    for p in ${ctld_port:-} ${slurmd_port:-}; do
        port_open "$p" && { echo "error: port $p is still open after stopping the daemons" >&2; rc=1; }
    done
    if [ "$ok" = 1 ] && [ "$rc" = 0 ]; then
        rm -rf "$work"
    else
        echo "=== ci_slurm: FAILED (exit $rc); logs follow, everything is in $work" >&2
        show_logs >&2
        [ "$rc" = 0 ] && rc=1
    fi
    exit "$rc"
}
trap stop_daemons EXIT
fail() { echo "error: $*" >&2; exit 1; }

# Two free high ports (nothing listening), in a range of their own per run.
pick_port() {
    local p
    for _ in $(seq 50); do
        p=$((20000 + RANDOM % 40000))
        [ "$p" != "${ctld_port:-}" ] && ! port_open "$p" && { echo "$p"; return; }
    done
    fail "no free port found"
}
ctld_port=$(pick_port)
slurmd_port=$(pick_port)
node=$(hostname -s)
mkdir -p "$work/state" "$work/spool"
: >"$work/plugstack.conf"
export SLURM_CONF=$work/slurm.conf
cat >"$SLURM_CONF" <<EOF
# One-node test cluster of scripts/ci_slurm.sh
ClusterName=tessera-ci
SlurmctldHost=$node(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
SlurmUser=root
SlurmdUser=root
AuthType=auth/none
CredType=cred/none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SwitchType=switch/none
MpiDefault=none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/builtin
# Look at pending jobs every second (default 60 s): a dependent job (the assemble step, a retried tile)
# starts as soon as what it waits for ends.
SchedulerParameters=sched_interval=1
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
ReturnToService=2
SlurmdParameters=config_overrides
MailProg=/bin/true
PlugStackConfig=$work/plugstack.conf
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
NodeName=$node NodeAddr=127.0.0.1 CPUs=$(nproc) RealMemory=500 State=UNKNOWN
PartitionName=ci Nodes=$node Default=YES MaxTime=INFINITE State=UP
EOF

echo "starting slurmctld (port $ctld_port) and slurmd (port $slurmd_port, node $node) in $work"
slurmctld -D >"$work/slurmctld.out" 2>&1 &
ctld_pid=$!
slurmd -D -N "$node" >"$work/slurmd.out" 2>&1 &
slurmd_pid=$!
for ((t = 0; ; ++t)); do
    kill -0 "$ctld_pid" 2>/dev/null || fail "slurmctld exited at start (permissions? see its log below)"
    kill -0 "$slurmd_pid" 2>/dev/null || fail "slurmd exited at start (permissions? see its log below)"
    state=$(sinfo -h -n "$node" -o %t 2>/dev/null || true)
    [ "$state" = idle ] && break
    [ "$t" -ge 120 ] && fail "node $node not idle after 60 s (sinfo says '${state:-nothing}')"
    sleep 0.5
done
echo "cluster up after $((t / 2)) s:"
sinfo

tessera=$repo/build/tessera
imgdiff=$repo/build/tessera_imgdiff
same_pixels() {  # same_pixels A B: tessera_imgdiff reports no colour or alpha difference
    local j
    j=$("$imgdiff" "$1" "$2") || fail "tessera_imgdiff $1 $2 failed"
    for k in max_abs_color alpha_mismatch_fraction mean_abs_alpha; do
        grep -Eq "\"$k\": 0(\.0+)?(e[+-]?0+)?,?\$" <<<"$j" || { echo "$j" >&2; fail "$1 and $2 differ ($k)"; }
    done
    echo "  $1 == $2 (pixels)"
}
farm() { timeout 90 env TESSERA_SLURM_WAIT=1 "$@"; }

echo "=== single render"
"$tessera" render "$scene" -q "${opts[@]}" -o "$work/single.exr"

echo "=== 1. slurm_render.sh $scene 4 (job array + assemble)"
t0=$SECONDS
farm bash scripts/slurm_render.sh "$scene" 4 "$work/farm.exr" "${opts[@]}" || fail "slurm_render.sh failed"
echo "  took $((SECONDS - t0)) s"
same_pixels "$work/farm.exr" "$work/single.exr"
# Reyes: the shadow maps were rendered once, by the job before the array, into the tiles' cache.
grep -Eq "shadow maps: 0 read, [1-9][0-9]* rendered" "$work/farm.tiles/maps.log" ||
    fail "the shadow-map job did not render the maps (maps.log: $(cat "$work/farm.tiles/maps.log"))"
ls "$work"/farm.tiles/shadowmaps/shadow-*.tsm >/dev/null 2>&1 || fail "no shadow map in the tiles' cache"
TESSERA_JOBS=2 bash scripts/render_tiles.sh "$scene" 4 "$work/local.exr" "${opts[@]}"
same_pixels "$work/local.exr" "$work/single.exr"

# A stand-in binary that fails (exit 3) the first render of tile FAIL_ONCE and every render of FAIL_ALWAYS.
cat >"$work/flaky_tessera" <<EOF
#!/usr/bin/env bash
for a in "\$@"; do
    case \$a in
        "\${FAIL_ALWAYS:-x}/"*) echo "flaky_tessera: tile \$a fails" >&2; exit 3 ;;
        "\${FAIL_ONCE:-x}/"*) [ -e "$work/failed_once" ] || { : >"$work/failed_once"; echo "flaky_tessera: tile \$a fails once" >&2; exit 3; } ;;
    esac
done
exec "$tessera" "\$@"
EOF
chmod +x "$work/flaky_tessera"

echo "=== 2. tile 1 fails once: retried"
FAIL_ONCE=1 TESSERA=$work/flaky_tessera farm bash scripts/slurm_render.sh "$scene" 4 "$work/retry.exr" "${opts[@]}" ||
    fail "slurm_render.sh failed although the failing tile succeeds when retried"
grep -q "tile 1 of 4: attempt 1 failed with exit status 3" "$work"/retry.tiles/tile-*_1.log || fail "tile 1's log does not report the failed attempt"
grep -q "tile 1 of 4: done" "$work"/retry.tiles/tile-*_1.log || fail "tile 1's log does not report the retry"
same_pixels "$work/retry.exr" "$work/single.exr"

echo "=== 3. tile 2 always fails: reported, the assemble job refuses the incomplete set"
set +e
FAIL_ALWAYS=2 TESSERA=$work/flaky_tessera farm bash scripts/slurm_render.sh "$scene" 4 "$work/broken.exr" "${opts[@]}" \
    >"$work/broken.out" 2>&1
rc=$?
set -e
cat "$work/broken.out"
[ "$rc" -ne 0 ] || fail "slurm_render.sh exited 0 with a failed tile"
[ "$rc" -ne 124 ] || fail "slurm_render.sh timed out instead of reporting the failed tile"
[ "$rc" -eq 2 ] || fail "slurm_render.sh exited $rc, expected 2 (the assemble job's refusal)"
[ ! -e "$work/broken.exr" ] || fail "an image was written from an incomplete set"
grep -q "tile 2 of 4: FAILED after 2 attempts (exit status 3)" "$work"/broken.tiles/tile-*_2.log ||
    fail "tile 2's log does not report its failure"
grep -q "error: tile 2 of 4 is missing: failed exit=3 attempts=2" "$work/broken.tiles/assemble.log" ||
    fail "the assemble job does not name the failed tile"
grep -q "error: assemble: tile 2 of 4 is missing" "$work/broken.tiles/assemble.log" ||
    fail "tessera assemble did not refuse the incomplete set"
for i in 0 1 3; do [ -f "$work/broken.tiles/tile$i.exr" ] || fail "tile $i missing although it succeeded"; done

echo "=== 4. bad arguments exit with 2"
for args in "$scene 0 $work/x.exr" "$scene four $work/x.exr" "no_such.rib 4 $work/x.exr" "$scene 4 $work/x.png" \
    "$scene 4 $work/x.exr --tile 1/4" "$scene 4"; do
    set +e
    # shellcheck disable=SC2086
    bash scripts/slurm_render.sh $args >/dev/null 2>"$work/bad.err"
    rc=$?
    set -e
    [ "$rc" = 2 ] || fail "slurm_render.sh $args exited $rc, expected 2"
    grep -Eq "error|usage" "$work/bad.err" || fail "slurm_render.sh $args printed no message"
done
[ -z "$(squeue -h -o %i)" ] || fail "jobs left in the queue: $(squeue -h)"
ok=1
echo "=== ci_slurm: all Slurm checks passed"
