#!/usr/bin/env bash
# The benchmark suite: every shipped scene x engine (reyes, rt) with the median and minimum of N runs, the
# Embree triangle baseline beside the ray tracer, image quality (PSNR between the engines and against a
# high-spp reference), and scaling with patch count, resolution, spp and threads.
#
#   bash bench/run_suite.sh [--quick]
#
# Writes bench/results/suite.json (one record per scene x engine x setting), bench/results/SUMMARY.md and
# bench/results/scaling_*.svg. RUNS=N overrides the number of runs (default 3; --quick: 1 and fewer scenes).
set -euo pipefail
cd "$(dirname "$0")/.."
QUICK=0
[ "${1:-}" = "--quick" ] && QUICK=1
RUNS=${RUNS:-$([ $QUICK = 1 ] && echo 1 || echo 3)}
OUT=bench/results
mkdir -p "$OUT/images"
JSON=$OUT/suite.json
rm -f "$JSON" "$OUT"/quality.json "$OUT"/embree.json

[ -x build/tessera_bench ] && [ -x build/tessera_imgdiff ] || bash scripts/build.sh
HAVE_EMBREE=0
if [ -x build/embree_baseline ]; then HAVE_EMBREE=1; else
  echo "NOTE: Embree is not installed (apt-get install libembree-dev, then re-run scripts/build.sh):"
  echo "      the triangle baseline is skipped."
fi

if [ $QUICK = 1 ]; then
  SCENES="teapot killeroo bigguy"
else
  SCENES="teapot killeroo bigguy killeroo2 bigguy9 bigguy24"
fi
RES=800x600
SPP=4

bench() {  # name, then tessera arguments
  local name=$1; shift
  build/tessera_bench --name "$name" --runs "$RUNS" --json "$JSON" -- "$@" > /dev/null
  echo "  $name done"
}

echo "== scenes x engines ($RES, $SPP spp, $RUNS runs each)"
for s in $SCENES; do
  for e in reyes rt; do
    bench "scene:$s:$e" render "scenes/$s.rib" --engine $e --res $RES --spp $SPP
    build/tessera render "scenes/$s.rib" --engine $e --res $RES --spp $SPP -q -o "$OUT/images/$s-$e.exr"
  done
  # Reference: the Reyes engine at 64 spp.
  build/tessera render "scenes/$s.rib" --engine reyes --res $RES --spp 64 -q -o "$OUT/images/$s-ref.exr"
  for pair in "reyes rt" "reyes ref" "rt ref"; do
    set -- $pair
    build/tessera_imgdiff "$OUT/images/$s-$1.exr" "$OUT/images/$s-$2.exr" |
      python3 -c "import json,sys; d=json.load(sys.stdin); d['scene']='$s'; d['pair']='$1-$2'; print(json.dumps(d))" \
      >> "$OUT/quality.json"
  done
  if [ $HAVE_EMBREE = 1 ]; then
    build/embree_baseline "scenes/$s.rib" --res $RES --spp $SPP --runs "$RUNS" -o "$OUT/images/$s-embree.exr" |
      python3 -c "import json,sys; d=json.load(sys.stdin); d['scene']='$s'; print(json.dumps(d))" >> "$OUT/embree.json"
    echo "  embree:$s done"
  fi
done

echo "== scaling with resolution (teapot, $SPP spp)"
for r in 400x300 800x600 1600x1200; do
  for e in reyes rt; do bench "res:$r:$e" render scenes/teapot.rib --engine $e --res $r --spp $SPP; done
done
echo "== scaling with samples per pixel (teapot, $RES)"
for n in 1 4 16 64; do
  for e in reyes rt; do bench "spp:$n:$e" render scenes/teapot.rib --engine $e --res $RES --spp $n; done
done
echo "== threads (1 vs 2)"
for s in teapot killeroo; do
  for e in reyes rt; do
    for t in 1 2; do bench "threads:$s:$e:$t" render "scenes/$s.rib" --engine $e --res $RES --spp $SPP --threads $t; done
  done
done

python3 bench/summarize.py "$OUT"
echo "wrote $JSON, $OUT/SUMMARY.md and $OUT/scaling_*.svg"
