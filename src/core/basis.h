// Cubic spline bases of the RenderMan Interface (RI spec 3.2, sec. 5.4, RiBasis) and the exact
// change of basis to Bezier form: G_bezier = Mb^-1 * M * G for each parametric direction.
#pragma once
#include <optional>
#include <string_view>

#include "core/bezier.h"

namespace tessera {

struct Basis {
    double m[4][4];  // P(t) = [t^3 t^2 t 1] * m * G
    int step;        // RI default step for the basis (how many control points to advance per patch)
};

Basis bezierBasis();
Basis bsplineBasis();
Basis catmullRomBasis();
Basis hermiteBasis();
Basis powerBasis();
// Look up a basis by its RIB name; nullopt if unknown.
std::optional<Basis> basisByName(std::string_view name);

// Convert 16 control points in (uBasis, vBasis) to a Bezier patch (same surface, exactly).
BezierPatch toBezier(const Vec3 in[16], const Basis& uBasis, const Basis& vBasis);

}  // namespace tessera
