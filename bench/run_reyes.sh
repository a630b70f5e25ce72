#!/usr/bin/env bash
# Reyes benchmark: the teapot at 800x600, PixelSamples 4x4, ShadingRate 1 (scenes/teapot.rib), median of
# 5 runs on 2 threads and on 1 thread (for the speed-up). Prints JSON records and saves them to
# bench/results/reyes.json.
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x build/tessera_bench ] || bash scripts/build.sh
out=bench/results/reyes.json
mkdir -p bench/results && rm -f "$out"
runs=${RUNS:-5}
for threads in 2 1; do
  build/tessera_bench --name "reyes_teapot_800x600_16spp_sr1_t$threads" --runs "$runs" --json "$out" -- \
    render scenes/teapot.rib --res 800x600 --spp 16 --shading-rate 1 --threads "$threads"
done
python3 - "$out" <<'PY' || true
import json, sys
recs = {r["name"]: r for r in json.load(open(sys.argv[1]))}
t2 = recs["reyes_teapot_800x600_16spp_sr1_t2"]; t1 = recs["reyes_teapot_800x600_16spp_sr1_t1"]
print(f"2 threads: {t2['render_ms_median']:.1f} ms render, {t2['wall_ms_median']:.1f} ms wall, "
      f"{t2['micropolygons_per_s']/1e6:.2f} M micropolygons/s, peak {t2['peak_rss_mb_max']:.1f} MB; "
      f"speed-up over 1 thread: {t1['render_ms_median']/t2['render_ms_median']:.2f}x")
PY
