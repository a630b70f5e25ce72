#!/usr/bin/env bash
# Builds Aqsis 1.8.4, the peer Reyes renderer of issue 18, from its public source into DEST (outside this
# repository; nothing of it is committed), for bench/reyes_vs_aqsis.sh. Measured with aqsis/aqsis master
# 937ead9a (2025-08-22, reports 1.8.4; it has no release tags) and its partio submodule (wdas/partio
# 7cb3743c), which builds unmodified with g++ 12, Boost 1.74 and OpenEXR 3 on Debian 12: about 25 minutes
# on 2 cores.
# Usage: bench/build_aqsis.sh DEST [SRC]   (SRC: an existing checkout with the submodule; default: clone
# from GitHub into DEST/src). Then: bench/reyes_vs_aqsis.sh DEST/install/bin/aqsis
set -euo pipefail
DEST="${1:?usage: bench/build_aqsis.sh DEST [SRC]}"
mkdir -p "$DEST"
DEST="$(cd "$DEST" && pwd)"
SRC="${2:-$DEST/src}"
AQSIS_COMMIT=937ead9a
PARTIO_COMMIT=7cb3743c6e19c04ac049c05f8f81af2f24410ea3
if [ ! -d "$SRC/.git" ] && [ ! -f "$SRC/CMakeLists.txt" ]; then
    git clone -q https://github.com/aqsis/aqsis.git "$SRC"
    git -C "$SRC" checkout -q "$AQSIS_COMMIT"
    git clone -q https://github.com/wdas/partio.git "$SRC/thirdparty/partio/src"
    git -C "$SRC/thirdparty/partio/src" checkout -q "$PARTIO_COMMIT"
fi
[ -d "$SRC/thirdparty/partio/src/src/lib" ] || { echo "$SRC: the partio submodule (thirdparty/partio/src) is missing" >&2; exit 2; }

# Boost components, TIFF, PNG, zlib; OpenEXR and Imath (the shader VM needs them); flex, bison and xslt
# for the RIB parser and the generated sources.
PKGS="cmake g++ make libboost-dev libboost-filesystem-dev libboost-iostreams-dev libboost-wave-dev
 libboost-test-dev libboost-thread-dev libboost-regex-dev libboost-system-dev libboost-program-options-dev
 libboost-timer-dev libboost-date-time-dev libtiff-dev libpng-dev zlib1g-dev libopenexr-dev libimath-dev
 libxslt1-dev xsltproc flex bison time"
export DEBIAN_FRONTEND=noninteractive
apt-get install -y -q --no-install-recommends $PKGS >/dev/null ||
    { apt-get update -q >/dev/null && apt-get install -y -q --no-install-recommends $PKGS >/dev/null; }

# Renderer only: no Qt viewer, docs, pdiff or crowd plug-ins; OpenMP (used only by indirectdiffuse) and the
# experimental threading off, as the 1.8 release ships. LIBDIR=lib gives the installed binaries an RPATH
# that finds their libraries on the first configure.
rm -rf "$DEST/build" && mkdir -p "$DEST/build"
cmake -S "$SRC" -B "$DEST/build" -DCMAKE_BUILD_TYPE=Release -DCMAKE_INSTALL_PREFIX="$DEST/install" \
    -DLIBDIR=lib -DAQSIS_USE_QT=OFF -DAQSIS_USE_OPENMP=OFF -DAQSIS_ENABLE_DOCS=OFF -DAQSIS_USE_PDIFF=OFF \
    -DAQSIS_ENABLE_MASSIVE=OFF -DAQSIS_ENABLE_SIMBIONT=OFF -DAQSIS_ENABLE_THREADING=OFF >/dev/null
nice -n 19 make -C "$DEST/build" -j"$(nproc)" >/dev/null
nice -n 19 make -C "$DEST/build" install >/dev/null  # also compiles the standard shaders (aqsl)
for s in surface/plastic surface/matte light/ambientlight light/distantlight; do
    [ -f "$DEST/install/share/aqsis/shaders/$s.slx" ] || { echo "shader $s.slx missing" >&2; exit 1; }
done
"$DEST/install/bin/aqsis" -version
