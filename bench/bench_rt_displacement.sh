#!/usr/bin/env bash
# Ray-traced displacement (issue 12, "Ray tracer"): time and memory of --engine rt on the displaced teapot
# (scenes/displaced_teapot.rib) against the same scene undisplaced (its Displacement line removed), and
# Reyes on both for reference, at 800x600 (the scene's own resolution and 16 spp) and at 400x300.
# Also the rt with the grids built lazily under a 4 MiB budget. Ratios displaced / smooth come from the
# same run. Usage:
#   bench/bench_rt_displacement.sh [path/to/tessera] [threads]   (default build/tessera, 2 threads)
# Prints a table and writes bench/results/rt_displacement_<timestamp>.json.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BIN="${1:-$ROOT/build/tessera}"
THREADS="${2:-2}"
TMP="$(mktemp -d /tmp/tessera_bench_rtdisp.XXXXXX)"
trap 'rm -rf "$TMP"' EXIT
cd "$ROOT/scenes"
grep -v '^Displacement' displaced_teapot.rib > smooth_teapot_tmp.rib
trap 'rm -rf "$TMP" "$ROOT/scenes/smooth_teapot_tmp.rib"' EXIT
for res in 800x600 400x300; do
    for engine in rt reyes; do
        for scene in displaced_teapot smooth_teapot_tmp; do
            name="${scene%_tmp}_${engine}_${res}"
            "$BIN" render "$scene.rib" --engine "$engine" --res "$res" --threads "$THREADS" -q \
                -o "$TMP/$name.png" --stats "$TMP/$name.json"
        done
    done
    # The grids built lazily under a budget of about half what they need (up front: 36 MiB at 800x600, 9 MiB
    # at 400x300). Much smaller budgets thrash: every tile rebuilds grids (800x600 at 4 MiB ran > 20 min).
    mb=$([ "$res" = 800x600 ] && echo 16 || echo 4)
    name="displaced_teapot_rt-lazy${mb}MiB_$res"
    "$BIN" render displaced_teapot.rib --engine rt --res "$res" --threads "$THREADS" -q \
        --displacement-cache-mb "$mb" -o "$TMP/$name.png" --stats "$TMP/$name.json"
done
mkdir -p "$ROOT/bench/results"
OUT="$ROOT/bench/results/rt_displacement_$(date -u +%Y%m%dT%H%M%SZ).json"
python3 - "$TMP" "$OUT" <<'PY'
import json, sys, os
tmp, out = sys.argv[1], sys.argv[2]
rows = {}
for f in sorted(os.listdir(tmp)):
    if f.endswith('.json'):
        s = json.load(open(os.path.join(tmp, f)))
        d = s.get('displaced', {})
        rows[f[:-5]] = {
            'engine_ms': s.get('engine_ms'), 'trace_ms': s.get('trace_ms'), 'build_ms': s.get('build_ms'),
            'peak_rss_mb': s.get('peak_rss_mb'), 'displaced_bytes': d.get('bytes', 0),
            'displaced_triangles': d.get('triangles', 0), 'displaced_build_ms': d.get('build_ms', 0),
            'rays_total': s.get('rays_total'), 'micropolygons': s.get('micropolygons'),
            'grids_built': d.get('grids_built', 0), 'grids_dropped': d.get('grids_dropped', 0),
            'peak_resident_bytes': d.get('peak_resident_bytes', 0)}
ratios = {}
for res in ('800x600', '400x300'):
    for eng in ('rt', 'reyes'):
        a, b = rows[f'displaced_teapot_{eng}_{res}'], rows[f'smooth_teapot_{eng}_{res}']
        ratios[f'{eng}_{res}'] = {'engine_ms': a['engine_ms'] / b['engine_ms'],
                                  'peak_rss_mb': a['peak_rss_mb'] / b['peak_rss_mb']}
json.dump({'runs': rows, 'ratios_displaced_over_smooth': ratios}, open(out, 'w'), indent=1)
print('| run | engine ms | build ms (displaced grids) | trace ms | peak RSS MB | grids MB (peak resident) | '
      'triangles | grids built / dropped |')
print('|---|---|---|---|---|---|---|---|')
for k, r in rows.items():
    print(f"| {k} | {r['engine_ms']:.0f} | {r['build_ms'] or 0:.0f} ({r['displaced_build_ms']:.0f}) | "
          f"{r['trace_ms'] or 0:.0f} | {r['peak_rss_mb']:.0f} | {r['peak_resident_bytes'] / 2**20:.1f} | "
          f"{r['displaced_triangles']} | {r['grids_built']} / {r['grids_dropped']} |")
for k, r in ratios.items():
    print(f"displaced / smooth, {k}: time {r['engine_ms']:.2f}x, peak memory {r['peak_rss_mb']:.2f}x")
print('wrote', out)
PY
