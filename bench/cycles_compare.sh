#!/usr/bin/env bash
# Tessera's path tracer against an independent one, Blender's Cycles (issue 14): the Big Guy box
# (scenes/bigguy_box_area.rib) with every surface Lambertian (Big Guy's plastic made matte, so that both
# renderers have exactly the same BSDFs), the same area light (front side only), camera and patches
# (Cycles gets Big Guy's Bezier patches tessellated to 8 x 8 quads each by bench/cycles_box.py). Both at
# equal samples per pixel, each against its own converged render and against the other's; both with 2
# threads, 16 bounces, no clamping, no denoising; pixel filters differ (Tessera: the RI default Gaussian
# 2 x 2; Cycles: Gaussian 1.5), which the converged comparison includes.
# Needs Blender (Debian `blender`; not a build dependency: this is a benchmark). Writes
# bench/results/cycles_compare_<timestamp>.json and prints a markdown table.
# Usage: bench/cycles_compare.sh [build dir]   (RES, SPPS, REF_SPP override)
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BUILD="${1:-$ROOT/build}"
RES="${RES:-200}"
SPPS="${SPPS:-4 16 64}"
REF_SPP="${REF_SPP:-1024}"
command -v blender > /dev/null || { echo "cycles_compare.sh: needs blender (apt-get install blender)" >&2; exit 2; }
mkdir -p "$ROOT/bench/results"
OUT="$ROOT/bench/results/cycles_compare_$(date -u +%Y%m%dT%H%M%SZ).json"
TMP="$(mktemp -d)"
SCENE="$ROOT/scenes/.cycles_box.rib"  # beside the scene for its ReadArchive path
trap 'rm -rf "$TMP" "$SCENE"' EXIT
sed 's/^Surface "plastic" "Ka" \[ 1 \] "Kd" \[ 0.8 \] "Ks" \[ 0.35 \] "roughness" \[ 0.15 \]/Surface "matte" "Ka" [ 1 ] "Kd" [ 0.8 ]/' \
    "$ROOT/scenes/bigguy_box_area.rib" > "$SCENE"
grep -q 'Surface "plastic"' "$SCENE" && { echo "the matte substitution failed" >&2; exit 1; }
tessera() {  # spp, output
    local t0=$(date +%s.%N)
    "$BUILD/tessera" render "$SCENE" --engine rt --integrator path --max-depth 16 --res "${RES}x${RES}" \
        --spp "$1" --threads 2 -q -o "$2"
    echo "$(date +%s.%N) - $t0" | bc
}
cycles() {  # spp, output
    local t0=$(date +%s.%N)
    blender -b --python "$ROOT/bench/cycles_box.py" -- "$ROOT/scenes/archives/bigguy_patches.rib" "$2" "$RES" "$1" \
        > "$TMP/blender.log" 2>&1 || { cat "$TMP/blender.log" >&2; exit 1; }
    echo "$(date +%s.%N) - $t0" | bc
}
psnr() { "$BUILD/tessera_imgdiff" "$1" "$2" | python3 -c "import json,sys; print(json.load(sys.stdin)['psnr_db'])"; }
means() { "$BUILD/tessera_imgdiff" "$1" "$2" | python3 -c "import json,sys; j=json.load(sys.stdin); print(j['mean_rgb_a'], j['mean_rgb_b'])"; }
tref=$(tessera "$REF_SPP" "$TMP/t_ref.exr")
cref=$(cycles "$REF_SPP" "$TMP/c_ref.exr")
"$BUILD/tessera_imgdiff" --to-png "$TMP/t_ref.exr" "$ROOT/bench/results/cycles_compare_tessera.png"
"$BUILD/tessera_imgdiff" --to-png "$TMP/c_ref.exr" "$ROOT/bench/results/cycles_compare_cycles.png"
read -r tmean cmean <<< "$(means "$TMP/t_ref.exr" "$TMP/c_ref.exr")"
python3 -c "import json; print(json.dumps({'row': 'converged', 'spp': $REF_SPP, 'psnr_db': $(psnr "$TMP/t_ref.exr" "$TMP/c_ref.exr"), 'tessera_mean_rgb': $tmean, 'cycles_mean_rgb': $cmean, 'tessera_s': $tref, 'cycles_s': $cref}))" > "$OUT"
for spp in $SPPS; do
    ts=$(tessera "$spp" "$TMP/t.exr")
    cs=$(cycles "$spp" "$TMP/c.exr")
    python3 -c "import json; print(json.dumps({'row': 'equal spp', 'spp': $spp, 'tessera_vs_own_ref_db': $(psnr "$TMP/t.exr" "$TMP/t_ref.exr"), 'cycles_vs_own_ref_db': $(psnr "$TMP/c.exr" "$TMP/c_ref.exr"), 'tessera_vs_cycles_ref_db': $(psnr "$TMP/t.exr" "$TMP/c_ref.exr"), 'cycles_vs_tessera_ref_db': $(psnr "$TMP/c.exr" "$TMP/t_ref.exr"), 'tessera_vs_cycles_db': $(psnr "$TMP/t.exr" "$TMP/c.exr"), 'tessera_s': $ts, 'cycles_s': $cs}))" >> "$OUT"
done
python3 - "$OUT" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
c = rows[0]
print(f"converged ({c['spp']} spp): Tessera vs Cycles {c['psnr_db']:.1f} dB; mean RGB {c['tessera_mean_rgb']:.4f} vs "
      f"{c['cycles_mean_rgb']:.4f} ({100 * (c['tessera_mean_rgb'] / c['cycles_mean_rgb'] - 1):+.2f}%); "
      f"time {c['tessera_s']:.1f} s vs {c['cycles_s']:.1f} s\n")
print("| spp | Tessera vs its converged | Cycles vs its converged | Tessera vs Cycles' converged | Cycles vs Tessera's converged | Tessera vs Cycles | Tessera s | Cycles s |")
print("|---:|---:|---:|---:|---:|---:|---:|---:|")
for r in rows[1:]:
    print(f"| {r['spp']} | {r['tessera_vs_own_ref_db']:.1f} | {r['cycles_vs_own_ref_db']:.1f} | {r['tessera_vs_cycles_ref_db']:.1f} | "
          f"{r['cycles_vs_tessera_ref_db']:.1f} | {r['tessera_vs_cycles_db']:.1f} | {r['tessera_s']:.2f} | {r['cycles_s']:.2f} |")
PY
echo "wrote $OUT"
