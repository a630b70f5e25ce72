#!/usr/bin/env bash
# Sampler comparison (redesign issue, part 1): RMSE of Owen-scrambled Sobol' and of the jittered strata
# against a 1024-spp reference, at 4, 16 and 64 spp, three shipped scenes, both engines.
# The reference uses the jittered sampler with another seed (1000), so it favours neither sampler; a
# second reference (seed 2000) measures the reference's own noise, RMSE(ref, ref2) / sqrt(2), which adds
# in quadrature to every RMSE in the table. Images are rendered and compared in process, in float, by
# tessera_sampler_rmse (bench/sampler_rmse.cpp; build with -DTESSERA_BENCH=ON): half-float EXR would
# add quantisation of about the size of a 64-spp error.
# RMSE of premultiplied RGB clamped to [0,1] over all pixels, and split into silhouette pixels (reference
# coverage not all 1 in the 3x3 neighbourhood) and covered interior pixels; RMSE = sqrt(mean MSE) over
# the seeds.
# Usage: bench/sampler_rmse.sh [path/to/tessera_sampler_rmse] [threads] [WxH]
#   (defaults build/tessera_sampler_rmse, 2 threads, 200x150; SCENES, ENGINES, SPPS, SEEDS, REF_SPP and
#   EXTRA_SCENES (paths) override the sets). EXTRA_SCENES defaults to a control without any edge: one
#   plastic bilinear patch filling the frame under a point light ("flat"), where only smooth shading
#   and the pixel filter are integrated.
# Writes bench/results/sampler_rmse_<timestamp>.json and prints the markdown table of docs/sampler.md.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BIN="${1:-$ROOT/build/tessera_sampler_rmse}"
THREADS="${2:-2}"
RES="${3:-200x150}"
SCENES="${SCENES:-teapot killeroo bigguy}"
ENGINES="${ENGINES:-reyes rt}"
SPPS="${SPPS:-4 16 64}"
SEEDS="${SEEDS:-0 1 2 3}"
REF_SPP="${REF_SPP:-1024}"
TMP="$(mktemp -d /tmp/tessera_sampler_rmse.XXXXXX)"
trap 'rm -rf "$TMP"' EXIT
cat > "$TMP/flat.rib" <<'RIB'
Format 200 150 1.0
Projection "perspective" "fov" 40
Translate 0 0 10
WorldBegin
LightSource "pointlight" 1 "intensity" 30 "from" [0.5 0.3 -3]
Color [1 .6 .3]
Surface "plastic" "Ka" 0.1 "Kd" 0.6 "Ks" 0.8 "roughness" 0.3
Patch "bilinear" "P" [-20 -20 0  20 -20 0  -20 20 0  20 20 0]
WorldEnd
RIB
EXTRA_SCENES="${EXTRA_SCENES-$TMP/flat.rib}"
mkdir -p "$ROOT/bench/results"
OUT="$ROOT/bench/results/sampler_rmse_$(date -u +%Y%m%dT%H%M%SZ).json"

rows="$TMP/rows.txt"
: > "$rows"
paths=""
for scene in $SCENES; do paths="$paths $ROOT/scenes/$scene.rib"; done
for path in $paths $EXTRA_SCENES; do
    name="$(basename "$path" .rib)"
    for engine in $ENGINES; do
        t0=$(date +%s)
        "$BIN" "$path" "$engine" "$RES" "$THREADS" "$REF_SPP" "$SPPS" "$SEEDS" | sed "s|^|$name $engine |" >> "$rows"
        echo "$name $engine: $(($(date +%s) - t0)) s" >&2
    done
done

python3 - "$rows" "$OUT" "$RES" "$REF_SPP" "$SEEDS" <<'EOF'
import json, math, sys
from collections import defaultdict
rows, out, res, ref_spp, seeds = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]), sys.argv[5]
runs, refnoise, order = [], {}, []
mse = defaultdict(lambda: [0.0, 0.0, 0.0, 0])  # all, silhouette, interior MSE sums; count
for line in open(rows):
    scene, engine, spp, sampler, seed, js = line.split(maxsplit=5)
    d = json.loads(js)
    if (scene, engine) not in order:
        order.append((scene, engine))
    if sampler == "reference2":  # two independent references: each has RMSE(ref, ref2) / sqrt(2)
        refnoise[(scene, engine)] = d["rmse"] / math.sqrt(2)
        continue
    runs.append(dict(scene=scene, engine=engine, spp=int(spp), sampler=sampler, seed=int(seed), **d))
    m = mse[(scene, engine, int(spp), sampler)]
    for i, key in enumerate(("rmse", "rmse_silhouette", "rmse_interior")):
        m[i] += d[key] ** 2
    m[3] += 1
rm = {k: [math.sqrt(v[i] / v[3]) for i in range(3)] for k, v in mse.items()}
summary = [{"scene": k[0], "engine": k[1], "spp": k[2], "sampler": k[3], "rmse": v[0], "rmse_silhouette": v[1],
            "rmse_interior": v[2]} for k, v in sorted(rm.items())]
json.dump({"resolution": res, "seeds": seeds.split(),
           "reference": {"spp": ref_spp, "sampler": "jittered", "seed": 1000},
           "reference_rmse": {f"{s} {e}": v for (s, e), v in refnoise.items()},
           "summary": summary, "runs": runs}, open(out, "w"), indent=2)
print("| scene | engine | spp | RMSE Sobol | RMSE jittered | Sobol / jittered | silhouette: Sobol / jit. "
      "| interior: Sobol / jit. | reference's own RMSE |")
print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
for scene, engine in order:
    for spp in sorted({k[2] for k in rm if k[:2] == (scene, engine)}):
        k = (scene, engine, spp)
        s, j = rm[k + ("sobol",)], rm[k + ("jittered",)]
        ratio = lambda i: s[i] / j[i] if j[i] > 0 else float("nan")
        print(f"| {scene} | {engine} | {spp} | {s[0]:.6f} | {j[0]:.6f} | {ratio(0):.3f} | {ratio(1):.3f} "
              f"| {ratio(2):.3f} | {refnoise[(scene, engine)]:.6f} |")
print(f"\n(written {out})", file=sys.stderr)
EOF
