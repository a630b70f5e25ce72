#!/usr/bin/env bash
# Installs the Debian packages Tessera needs (only those missing), then configures and builds a Release
# build in build/.
# Usage: bash scripts/build.sh [TARGET...] [-DCMAKE_OPTION=...]
#   no target: everything (the CLI, the tests, the benchmarks); `tessera`: only the CLI and its library,
#   which is all that rendering needs (the README's first command). Words starting with '-' go to cmake.
set -euo pipefail
cd "$(dirname "$0")/.."

TARGETS=()
CMAKE_ARGS=()
for a in "$@"; do
  if [[ $a == -* ]]; then CMAKE_ARGS+=("$a"); else TARGETS+=(--target "$a"); fi
done

source scripts/packages.sh
# The Python module and its tests (apps/python, tests/python): pybind11 on Debian's python3, numpy, pytest.
PACKAGES=("${TESSERA_PACKAGES[@]}" libgtest-dev libgmock-dev libbenchmark-dev python3 python3-dev pybind11-dev
          python3-numpy python3-pytest)
bash scripts/install_packages.sh "${PACKAGES[@]}"

cmake -S . -B build -DCMAKE_BUILD_TYPE=Release "${CMAKE_ARGS[@]}" >/dev/null
cmake --build build -j"$(nproc)" "${TARGETS[@]}"
