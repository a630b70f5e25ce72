#!/usr/bin/env bash
# Cost of the sampler (redesign issue, part 1): the teapot benchmarks with --sampler sobol and jittered,
# interleaved runs, median render_ms from --stats.
#   rt:    teapot 1024x1024, 1 spp, --engine rt
#   reyes: teapot as shipped (800x600, PixelSamples 4x4)
# Usage: bench/sampler_perf.sh [path/to/tessera] [runs] [threads]   (defaults build/tessera, 7, 2)
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BIN="${1:-$ROOT/build/tessera}"
RUNS="${2:-7}"
THREADS="${3:-2}"
TMP="$(mktemp -d /tmp/tessera_sampler_perf.XXXXXX)"
trap 'rm -rf "$TMP"' EXIT
for ((r = 0; r < RUNS; ++r)); do
    for sampler in sobol jittered; do
        "$BIN" render "$ROOT/scenes/teapot.rib" -q -o "$TMP/a.png" --res 1024x1024 --spp 1 --threads "$THREADS" \
            --engine rt --sampler "$sampler" --stats "$TMP/rt_${sampler}_$r.json"
        "$BIN" render "$ROOT/scenes/teapot.rib" -q -o "$TMP/a.png" --threads "$THREADS" --sampler "$sampler" \
            --stats "$TMP/reyes_${sampler}_$r.json"
    done
done
python3 - "$TMP" "$RUNS" <<'EOF'
import json, statistics, sys
tmp, runs = sys.argv[1], int(sys.argv[2])
for bench in ("rt", "reyes"):
    med = {}
    for s in ("sobol", "jittered"):
        ms = [json.load(open(f"{tmp}/{bench}_{s}_{r}.json"))["render_ms"] for r in range(runs)]
        med[s] = statistics.median(ms)
        print(f"{bench:5s} {s:8s} median {med[s]:8.1f} ms  (min {min(ms):.1f}, max {max(ms):.1f}, {runs} runs)")
    print(f"{bench:5s} sobol / jittered = {med['sobol'] / med['jittered']:.3f}")
EOF
