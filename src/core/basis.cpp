#include "core/basis.h"

namespace tessera {

Basis bezierBasis() { return {{{-1, 3, -3, 1}, {3, -6, 3, 0}, {-3, 3, 0, 0}, {1, 0, 0, 0}}, 3}; }
Basis bsplineBasis() {
    const double s = 1.0 / 6.0;
    return {{{-s, 3 * s, -3 * s, s}, {3 * s, -6 * s, 3 * s, 0}, {-3 * s, 0, 3 * s, 0}, {s, 4 * s, s, 0}}, 1};
}
Basis catmullRomBasis() {
    return {{{-0.5, 1.5, -1.5, 0.5}, {1, -2.5, 2, -0.5}, {-0.5, 0, 0.5, 0}, {0, 1, 0, 0}}, 1};
}
// RiHermiteBasis: geometry (P0, R0, P1, R1), step 2.
Basis hermiteBasis() { return {{{2, 1, -2, 1}, {-3, -2, 3, -1}, {0, 1, 0, 0}, {1, 0, 0, 0}}, 2}; }
Basis powerBasis() { return {{{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}}, 4}; }

std::optional<Basis> basisByName(std::string_view name) {
    if (name == "bezier") return bezierBasis();
    if (name == "b-spline" || name == "bspline") return bsplineBasis();
    if (name == "catmull-rom") return catmullRomBasis();
    if (name == "hermite") return hermiteBasis();
    if (name == "power") return powerBasis();
    return std::nullopt;
}

namespace {
// Mb^-1 for the Bezier basis matrix above (rows: control point index; exact rationals).
constexpr double kBezierInv[4][4] = {
    {0, 0, 0, 1}, {0, 0, 1.0 / 3.0, 1}, {0, 1.0 / 3.0, 2.0 / 3.0, 1}, {1, 1, 1, 1}};

// C = Mb^-1 * M: maps the basis' geometry vector to Bezier control points.
void changeMatrix(const Basis& b, double c[4][4]) {
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) {
            double s = 0;
            for (int k = 0; k < 4; ++k) s += kBezierInv[i][k] * b.m[k][j];
            c[i][j] = s;
        }
}
}  // namespace

BezierPatch toBezier(const Vec3 in[16], const Basis& uBasis, const Basis& vBasis) {
    double cu[4][4], cv[4][4];
    changeMatrix(uBasis, cu);
    changeMatrix(vBasis, cv);
    // Tensor product: B[v][u] = sum_{j,i} cv[v][j] * cu[u][i] * G[j][i].
    BezierPatch out;
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 4; ++u) {
            double x = 0, y = 0, z = 0;
            for (int j = 0; j < 4; ++j)
                for (int i = 0; i < 4; ++i) {
                    double w = cv[v][j] * cu[u][i];
                    x += w * in[j * 4 + i].x;
                    y += w * in[j * 4 + i].y;
                    z += w * in[j * 4 + i].z;
                }
            out.cp[v * 4 + u] = {float(x), float(y), float(z)};
        }
    return out;
}

}  // namespace tessera
