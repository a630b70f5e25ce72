#!/usr/bin/env bash
# Builds the libFuzzer targets (clang, -fsanitize=fuzzer,address,undefined) into build-fuzz/ (or in the
# sanitizer stage's build-asan/ when that was configured with them, as CI does) and runs each
# for a fixed time from the seed corpus (fuzz/corpus/<target>, plus the shipped scenes). A crash, leak,
# sanitizer report, timeout or out-of-memory fails the script; the input is left in
# <build>/artifacts/<target>/: fix the bug, then keep the input in fuzz/regressions/<target>/.
# Usage: bash scripts/ci_fuzz.sh [seconds per target (default 45)] [targets... (default: all)]
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
SECONDS_PER_TARGET=${1:-45}
shift || true

# Debian packages (only the missing ones): the build's own plus clang and its libFuzzer runtime.
source scripts/packages.sh
PACKAGES=("${TESSERA_PACKAGES[@]}" clang libclang-rt-14-dev)
bash scripts/install_packages.sh "${PACKAGES[@]}"

TARGETS=("$@")
if ((${#TARGETS[@]} == 0)); then
  TARGETS=(rib bpt)
  [ -f src/io/obj_reader.h ] && TARGETS+=(obj)
fi

B=build-fuzz
if [ -f build-asan/CMakeCache.txt ] && grep -q '^TESSERA_FUZZ:BOOL=ON' build-asan/CMakeCache.txt; then
  # The sanitizer stage's build (scripts/ci_sanitize.sh) has the targets: only they are compiled and linked.
  B=build-asan
else
  cmake -S . -B $B -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER=clang++ -DTESSERA_FUZZ=ON \
    -DTESSERA_TESTS=OFF -DTESSERA_BENCH=OFF -DTESSERA_PYTHON=OFF >/dev/null
fi
cmake --build $B -j"$(nproc)" --target "${TARGETS[@]/#/fuzz_}"

# As scripts/ci_sanitize.sh: OpenImageIO 2.4's TextureSystem::destroy trips the sized-delete check inside
# the library.
export ASAN_OPTIONS=${ASAN_OPTIONS:-new_delete_type_mismatch=0}
# One fuzzer per core at a time (libFuzzer runs single-threaded): the same time per target, the stage's
# wall time about halved on two cores.
fuzz_one() {
  local t=$1
  local work=$B/corpus/$t        # grows across runs; the seeds stay in fuzz/corpus/<t>
  local seeds=$B/seeds/$t        # the shipped scenes and shared models, when present
  local art=$B/artifacts/$t
  local run=$B/run/$t            # scratch directory: relative ReadArchive names resolve there
  mkdir -p "$work" "$seeds" "$art" "$run"
  case $t in
    rib) cp scenes/*.rib scenes/archives/*.rib "$seeds"/ 2>/dev/null || true
         find ../shared/data -name '*.rib' -size -16k -exec cp {} "$seeds"/ \; 2>/dev/null || true ;;
    bpt) find ../shared/data -name '*.bpt' -size -16k -exec cp {} "$seeds"/ \; 2>/dev/null || true ;;
    obj) find ../shared/data -name '*.obj' -size -16k -exec cp {} "$seeds"/ \; 2>/dev/null || true ;;
  esac
  local dict=()
  [ -f fuzz/$t.dict ] && dict=(-dict="$ROOT/fuzz/$t.dict")
  local log=$B/fuzz_$t.log
  if (cd "$run" && "$ROOT/$B/fuzz/fuzz_$t" -max_total_time="$SECONDS_PER_TARGET" -max_len=16384 -timeout=5 \
        -rss_limit_mb=2048 -malloc_limit_mb=1024 -print_final_stats=1 -artifact_prefix="$ROOT/$art/" \
        "${dict[@]}" "$ROOT/$work" "$ROOT/fuzz/corpus/$t" "$ROOT/$seeds") >"$log" 2>&1; then
    local execs cov
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo "?")
    cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 || true)
    echo "fuzz_$t: ok, $execs executions, $cov, corpus $(ls "$work" | wc -l) inputs"
  else
    echo "fuzz_$t: FAILED (log: $log); inputs:"
    ls -1 "$art"
    grep -E "ERROR|runtime error|invariant|Test unit written" "$log" | head -20 || true
    return 1
  fi
}

status=0
pids=()
for t in "${TARGETS[@]}"; do
  while (($(jobs -rp | wc -l) >= $(nproc))); do sleep 1; done
  echo "--- fuzz_$t: ${SECONDS_PER_TARGET} s"
  fuzz_one "$t" > "$B/fuzz_$t.summary" 2>&1 &
  pids+=($!)
done
for i in "${!TARGETS[@]}"; do
  wait "${pids[$i]}" || status=1
  cat "$B/fuzz_${TARGETS[$i]}.summary"
done
exit $status
