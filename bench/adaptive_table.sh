#!/usr/bin/env bash
# PSNR of fixed 1/4/9/16 spp and --adaptive at several thresholds against a 256-spp reference, all with a
# one-pixel box filter (the adaptive pixel is the paper's box weighting), for docs/benchmarks/adaptive.md.
# Usage: bash bench/adaptive_table.sh SCENE.rib [RES] [OUTDIR]   (needs build/tessera, build/tessera_imgdiff)
set -euo pipefail
cd "$(dirname "$0")/.."
scene=$1 res=${2:-200x200} out=${3:-/tmp/tessera_adaptive}
mkdir -p "$out"
box="$(dirname "$scene")/.adaptive_box_$(basename "$scene")"  # beside the scene: its archives resolve
sed -E '/^(PixelFilter|PixelSamples)/d; s/^(Format .*)$/\1\nPixelFilter "box" 1 1/' "$scene" > "$box"
trap 'rm -f "$box"' EXIT
render() { build/tessera render "$box" --engine rt --res "$res" --threads 2 -q "$@"; }
[[ -f $out/ref.exr ]] || render --spp 256 -o "$out/ref.exr" --stats "$out/ref.json"
row() {  # name, stats file, image
    python3 - "$1" "$2" "$(build/tessera_imgdiff "$out/ref.exr" "$3")" <<'PY'
import json, sys
name, stats, diff = sys.argv[1], json.load(open(sys.argv[2])), json.loads(sys.argv[3])
a = stats.get("adaptive", {})
cam = a.get("camera_rays_per_pixel", stats["spp"])
print(f"| {name} | {diff['psnr_db']:.2f} | {cam:.2f} | {100 * cam / 9:.0f}% | {stats['rays_total']} | "
      f"{100 * a.get('active_fraction', 1.0 if stats['spp'] > 1 else 0.0):.1f}% | {stats['render_ms']:.0f} |")
PY
}
echo "| run | PSNR dB | camera rays/pixel | of fixed 9 | rays traced | active subpixels | ms |"
echo "|---|---|---|---|---|---|---|"
for spp in 1 4 9 16; do
    render --spp $spp -o "$out/f$spp.exr" --stats "$out/f$spp.json"
    row "fixed $spp" "$out/f$spp.json" "$out/f$spp.exr"
done
for t in 0.1 0.3 0.6 1.0; do
    render --adaptive --adaptive-threshold $t -o "$out/a$t.exr" --stats "$out/a$t.json" --adaptive-map "$out/a$t.png"
    row "adaptive $t" "$out/a$t.json" "$out/a$t.exr"
done
