#!/usr/bin/env bash
# Ray-tracer benchmark (issue 3): teapot 1024x1024, 1 spp, primary only / + one shadow light / + one
# reflection bounce (mirror floor), then 1, 4, 16, 64 teapot copies. Mrays/s per ray kind from --stats.
# Usage: bench/bench_rt.sh [path/to/tessera] [threads]   (default build/apps/tessera/tessera, 2 threads)
# Prints a table and writes bench/results/rt_<timestamp>.json.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BIN="${1:-$ROOT/build/apps/tessera/tessera}"
[ -x "$BIN" ] || BIN="$ROOT/build/tessera"
THREADS="${2:-2}"
TMP="$(mktemp -d /tmp/tessera_bench_rt.XXXXXX)"
trap 'rm -rf "$TMP"' EXIT
SRC="$ROOT/scenes/teapot.rib"

# Teapot geometry only (the lines between the Surface and WorldEnd), for ReadArchive.
awk '/^Surface/{on=1; next} /^WorldEnd/{on=0} on' "$SRC" > "$TMP/teapot_geom.rib"
header() {  # camera and options of the original scene, then WorldBegin, lights ($1), surface
    awk '/^WorldBegin/{exit} {print}' "$SRC"
    echo "WorldBegin"
    echo "Identity"
    printf '%b\n' "$1"
    echo 'Color [1 .5 .3]'
    echo 'Surface "plastic" "Ka" 0.1 "Kd" 0.05 "Ks" 1.0 "roughness" 0.1 "specularcolor" [1 .4 .1]'
}
AMB='LightSource "ambientlight" 1 "intensity" .4 "lightcolor" [.4 0 1]'
KEY='LightSource "distantlight" 2 "intensity" 1.0 "from" [-50 300 200] "to" [0 0 0] "lightcolor" [1 .8 .7]'
FLOOR='AttributeBegin\nSurface "mirror" "Kr" 0.8\nPatch "bilinear" "P" [-400 -400 0  400 -400 0  -400 400 0  400 400 0]\nAttributeEnd'

{ header "$AMB"; echo "ReadArchive \"$TMP/teapot_geom.rib\""; echo WorldEnd; } > "$TMP/primary.rib"
{ header "$AMB\n$KEY"; echo "ReadArchive \"$TMP/teapot_geom.rib\""; echo WorldEnd; } > "$TMP/shadow.rib"
{ header "$AMB\n$KEY"; echo "ReadArchive \"$TMP/teapot_geom.rib\""; printf '%b\n' "$FLOOR"; echo WorldEnd; } > "$TMP/reflect.rib"
for n in 1 2 4 8; do  # n x n copies, scaled to keep the frame filled
    {
        header "$AMB\n$KEY"
        s=$(python3 -c "print(1.0/$n)")
        echo "Scale $s $s $s"
        for ((i = 0; i < n; ++i)); do for ((j = 0; j < n; ++j)); do
            x=$(python3 -c "print(($i - ($n - 1) / 2) * 260)")
            y=$(python3 -c "print(($j - ($n - 1) / 2) * 200)")
            echo "TransformBegin"; echo "Translate $x $y 0"; echo "ReadArchive \"$TMP/teapot_geom.rib\""; echo "TransformEnd"
        done; done
        echo WorldEnd
    } > "$TMP/copies$((n * n)).rib"
done

run() {  # name rib max-depth [extra flags]
    local name=$1 rib=$2 depth=$3
    shift 3
    "$BIN" render "$rib" --engine rt --res 1024x1024 --spp 1 --threads "$THREADS" --max-depth "$depth" -q \
        -o "$TMP/$name.png" --stats "$TMP/$name.json" "$@"
    python3 - "$TMP/$name.json" "$name" <<'PY'
import json, sys
s = json.load(open(sys.argv[1])); name = sys.argv[2]
ms = s["trace_ms"]; r = s["rays"]
mr = {k: (v / (ms * 1e3) if ms > 0 else 0) for k, v in r.items()}
st = s["stage_ms"]
print(f"{name:14s} patches {s['patches_in']:5d} build {s['build_ms']:7.2f} ms  trace {ms:8.1f} ms  "
      f"rays {s['rays_total']:8d} ({s['mrays_per_s']:.2f} Mrays/s)  cand/ray {s['candidates_per_ray']:.2f}  "
      f"newton it {s['newton_iterations']['mean']:.2f}  cpu ms trav {st['traversal_cpu']:.0f} newton {st['newton_cpu']:.0f} "
      f"shade {st['shading_cpu']:.0f}  mem/patch {s['memory']['bytes_per_patch']:.0f} B")
print("               by kind (rays of the kind / trace time): " +
      ", ".join(f"{k} {v:.2f}" for k, v in mr.items() if r[k] > 0) + " Mrays/s")
out = {"name": name, "trace_ms": ms, "build_ms": s["build_ms"], "rays": r, "mrays_per_s_by_kind": mr,
       "mrays_per_s": s["mrays_per_s"], "stage_ms": st, "candidates_per_ray": s["candidates_per_ray"],
       "newton_mean": s["newton_iterations"]["mean"], "patches": s["patches_in"], "memory": s["memory"]}
open(sys.argv[1] + ".summary", "w").write(json.dumps(out))
PY
}

run primary "$TMP/primary.rib" 0
run primary_cull "$TMP/primary.rib" 0 --cull-backfaces
run shadow "$TMP/shadow.rib" 0
run reflect "$TMP/reflect.rib" 1
for c in 1 4 16 64; do run "copies$c" "$TMP/copies$c.rib" 0; done

mkdir -p "$ROOT/bench/results"
OUT="$ROOT/bench/results/rt_$(date +%Y%m%d_%H%M%S).json"
python3 - "$OUT" "$TMP"/*.summary <<'PY'
import json, sys
json.dump({"bench": "rt", "runs": [json.load(open(f)) for f in sys.argv[2:]]}, open(sys.argv[1], "w"), indent=1)
PY
echo "saved $OUT"
