// Shared checks for the fuzz targets: a parser may accept its input or reject it with an InputError, and
// whatever it accepts must be renderable (finite control points, sizes within the documented limits).
// Anything else (another exception, a crash, a sanitizer report) is a bug.
#pragma once
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "core/bezier.h"

namespace tessera::fuzz {

[[noreturn]] inline void bug(const char* what) {
    std::fprintf(stderr, "fuzz invariant violated: %s\n", what);
    std::abort();
}

inline void checkPatches(const std::vector<BezierPatch>& patches) {
    for (const BezierPatch& p : patches)
        for (const Vec3& c : p.cp)
            if (!std::isfinite(c.x) || !std::isfinite(c.y) || !std::isfinite(c.z))
                bug("accepted a non-finite control point");
}

}  // namespace tessera::fuzz
