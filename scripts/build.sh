#!/usr/bin/env bash
# Installs the Debian packages Tessera needs (only those missing), then configures and builds a Release
# build in build/. Usage: bash scripts/build.sh [extra cmake args...]
set -euo pipefail
cd "$(dirname "$0")/.."

PACKAGES=(g++ cmake make pkg-config libtbb-dev libopenexr-dev libpng-dev zlib1g-dev libcli11-dev
          libfmt-dev nlohmann-json3-dev libgtest-dev libgmock-dev libbenchmark-dev python3)
bash scripts/install_packages.sh "${PACKAGES[@]}"

cmake -S . -B build -DCMAKE_BUILD_TYPE=Release "$@" >/dev/null
cmake --build build -j"$(nproc)"
