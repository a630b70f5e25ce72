#!/usr/bin/env bash
# Sampler comparison (redesign issue, part 1): RMSE of Owen-scrambled Sobol' and of the jittered strata
# against a 1024-spp reference, at 4, 16 and 64 spp, three shipped scenes, both engines.
# The reference uses the jittered sampler with another seed (--seed 1000), so it favours neither sampler;
# a second reference (--seed 2000) measures the reference's own noise: RMSE(ref, ref2) / sqrt(2), which
# adds in quadrature to every RMSE in the table.
# Usage: bench/sampler_rmse.sh [path/to/tessera] [path/to/tessera_imgdiff] [threads] [WxH]
#   (defaults build/tessera, build/tessera_imgdiff (-DTESSERA_BENCH=ON), 2 threads, 200x150)
# Writes bench/results/sampler_rmse_<timestamp>.json and prints the markdown table of docs/sampler.md.
# RMSE is over premultiplied RGB clamped to [0,1], all pixels, from tessera_imgdiff's PSNR
# (RMSE = 10^(-PSNR/20)), and split into silhouette pixels (reference coverage not all 1 in the 3x3
# neighbourhood) and covered interior; images are half-float EXR (quantisation well below the errors).
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BIN="${1:-$ROOT/build/tessera}"
DIFF="${2:-$ROOT/build/tessera_imgdiff}"
THREADS="${3:-2}"
RES="${4:-200x150}"
SCENES="${SCENES:-teapot killeroo bigguy}"
ENGINES="${ENGINES:-reyes rt}"
SPPS="${SPPS:-4 16 64}"
SEEDS="${SEEDS:-0 1 2 3}"  # RMSE = sqrt(mean MSE over these seeds)
REF_SPP="${REF_SPP:-1024}"
TMP="$(mktemp -d /tmp/tessera_sampler_rmse.XXXXXX)"
trap 'rm -rf "$TMP"' EXIT
mkdir -p "$ROOT/bench/results"
OUT="$ROOT/bench/results/sampler_rmse_$(date -u +%Y%m%dT%H%M%SZ).json"

render() {  # scene engine spp sampler seed output
    "$BIN" render "$ROOT/scenes/$1.rib" -q -o "$6" --res "$RES" --engine "$2" --spp "$3" --sampler "$4" \
        --seed "$5" --threads "$THREADS"
}
rows="$TMP/rows.txt"
: > "$rows"
for scene in $SCENES; do
    for engine in $ENGINES; do
        ref="$TMP/${scene}_${engine}_ref.exr"
        t0=$(date +%s)
        render "$scene" "$engine" "$REF_SPP" jittered 1000 "$ref"
        echo "$scene $engine reference: $(($(date +%s) - t0)) s" >&2
        render "$scene" "$engine" "$REF_SPP" jittered 2000 "$TMP/ref2.exr"
        echo "$scene $engine $REF_SPP reference2 2000 $("$DIFF" "$TMP/ref2.exr" "$ref" | tr -d '\n ')" >> "$rows"
        for spp in $SPPS; do
            for sampler in sobol jittered; do
                for seed in $SEEDS; do
                    img="$TMP/${scene}_${engine}_${spp}_${sampler}.exr"
                    render "$scene" "$engine" "$spp" "$sampler" "$seed" "$img"
                    echo "$scene $engine $spp $sampler $seed $("$DIFF" "$img" "$ref" | tr -d '\n ')" >> "$rows"
                done
            done
        done
    done
done

python3 - "$rows" "$OUT" "$RES" "$REF_SPP" "$SEEDS" <<'EOF'
import json, math, sys
from collections import defaultdict
rows, out, res, ref_spp, seeds = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]), sys.argv[5]
runs, refnoise = [], {}
mse = defaultdict(lambda: [0.0, 0.0, 0.0, 0])  # all, silhouette, interior MSE sums; count
for line in open(rows):
    scene, engine, spp, sampler, seed, js = line.split(maxsplit=5)
    d = json.loads(js)
    rmse = 10 ** (-d["psnr_db"] / 20) if d["psnr_db"] is not None else 0.0
    if sampler == "reference2":  # two independent references: each has RMSE(ref, ref2) / sqrt(2)
        refnoise[(scene, engine)] = rmse / math.sqrt(2)
        continue
    runs.append({"scene": scene, "engine": engine, "spp": int(spp), "sampler": sampler, "seed": int(seed),
                 "rmse": rmse, "rmse_silhouette": d["rmse_silhouette"], "rmse_interior": d["rmse_interior"],
                 "silhouette_pixels": d["silhouette_pixels"], "interior_pixels": d["interior_pixels"]})
    m = mse[(scene, engine, int(spp), sampler)]
    m[0] += rmse ** 2
    m[1] += d["rmse_silhouette"] ** 2
    m[2] += d["rmse_interior"] ** 2
    m[3] += 1
rm = {k: [math.sqrt(v[i] / v[3]) for i in range(3)] for k, v in mse.items()}
summary = [{"scene": k[0], "engine": k[1], "spp": k[2], "sampler": k[3], "rmse": v[0], "rmse_silhouette": v[1],
            "rmse_interior": v[2]} for k, v in sorted(rm.items())]
json.dump({"resolution": res, "seeds": seeds.split(),
           "reference": {"spp": ref_spp, "sampler": "jittered", "seed": 1000},
           "reference_rmse": {f"{s} {e}": v for (s, e), v in refnoise.items()},
           "summary": summary, "runs": runs}, open(out, "w"), indent=2)
keys = sorted({k[:3] for k in rm})
print("| scene | engine | spp | RMSE Sobol | RMSE jittered | Sobol / jittered | silhouette: Sobol / jit. "
      "| interior: Sobol / jit. | reference's own RMSE |")
print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
for k in keys:
    s, j = rm[k + ("sobol",)], rm[k + ("jittered",)]
    ratio = lambda i: s[i] / j[i] if j[i] > 0 else float("nan")
    print(f"| {k[0]} | {k[1]} | {k[2]} | {s[0]:.5f} | {j[0]:.5f} | {ratio(0):.3f} | {ratio(1):.3f} "
          f"| {ratio(2):.3f} | {refnoise[k[:2]]:.5f} |")
print(f"\n(written {out})", file=sys.stderr)
EOF
