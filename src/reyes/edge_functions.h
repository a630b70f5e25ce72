// The sample test both Reyes rasterizers share (rasterize.cpp for sharp grids, rasterize_blur.cpp for
// moved micropolygons): exact 64-bit integer edge functions on the 1/256-pixel fixed point with the
// top-left fill rule, so a sample on an edge shared by two triangles belongs to exactly one of them, and
// the write of a covered sample.
#pragma once
#include <cstdint>
#include <type_traits>
#include <utility>

#include "film/film.h"
#include "reyes/grid.h"

namespace tessera {

// Edge a->b owns samples exactly on it when it is a "top" or "left" edge; the neighbouring triangle walks
// the same edge the other way, so a sample on a shared edge belongs to exactly one of them.
template <class Int = int64_t>
inline Int fillBias(std::type_identity_t<Int> ax, std::type_identity_t<Int> ay, std::type_identity_t<Int> bx,
                    std::type_identity_t<Int> by) {
    const Int dy = by - ay, dx = bx - ax;
    return (dy > 0 || (dy == 0 && dx < 0)) ? 0 : 1;
}

// One triangle set up for point-in-triangle tests. Edge function E_ab(p) = (b.x-a.x)(p.y-a.y) -
// (b.y-a.y)(p.x-a.x) = A*p.x + B*p.y + C, made positive inside by orienting the triangle counter-clockwise
// (positive area): when the given order is clockwise, vertices 1 and 2 are swapped (`swapped`). Edge e runs
// from vertex e+1 to e+2 of the oriented triangle, so its function is the weight of oriented vertex e.
// Int = int32_t: for coordinates relative to a nearby origin whose products fit 32 bits (the AVX2
// rasterizer's micropolygons under 2^13 units: the same A, B, area and weights, and C relative to it).
template <class Int>
struct TriangleEdgesOf {
    Int A[3], B[3], C[3];
    float invArea;
    bool valid, swapped;
};
using TriangleEdges = TriangleEdgesOf<int64_t>;

// Int is never deduced from the arguments (int32 grid coordinates still set up in 64 bits).
template <class Int = int64_t>
inline TriangleEdgesOf<Int> setupTriangleEdges(std::type_identity_t<Int> x0, std::type_identity_t<Int> y0,
                                               std::type_identity_t<Int> x1, std::type_identity_t<Int> y1,
                                               std::type_identity_t<Int> x2, std::type_identity_t<Int> y2) {
    TriangleEdgesOf<Int> t;
    Int area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
    t.valid = area != 0;
    t.swapped = area < 0;
    if (area < 0) {
        std::swap(x1, x2);
        std::swap(y1, y2);
        area = -area;
    }
    const Int xs[3] = {x0, x1, x2}, ys[3] = {y0, y1, y2};
    for (int e = 0; e < 3; ++e) {
        const int a = (e + 1) % 3, b = (e + 2) % 3;
        t.A[e] = -(ys[b] - ys[a]);
        t.B[e] = xs[b] - xs[a];
        t.C[e] = -(t.A[e] * xs[a] + t.B[e] * ys[a]) - fillBias<Int>(xs[a], ys[a], xs[b], ys[b]);
    }
    t.invArea = t.valid ? 1.f / float(area) : 0.f;
    return t;
}

// Whether fixed-point sample (sx, sy) lies inside; if so the barycentric weights of the oriented
// vertices (the fill-rule bias shifts them by at most 1 unit: negligible).
inline bool insideTriangle(const TriangleEdges& t, int64_t sx, int64_t sy, float& l0, float& l1, float& l2) {
    const int64_t w0 = t.A[0] * sx + t.B[0] * sy + t.C[0];
    const int64_t w1 = t.A[1] * sx + t.B[1] * sy + t.C[1];
    const int64_t w2 = t.A[2] * sx + t.B[2] * sy + t.C[2];
    if ((w0 | w1 | w2) < 0) return false;
    l1 = float(w1) * t.invArea, l2 = float(w2) * t.invArea, l0 = 1.f - l1 - l2;
    return true;
}

// A covered sample: depth z and the colour (and, when the film has them, the attributes) interpolated from
// grid vertices a, b, c with weights l0, l1, l2.
template <bool kAttributes>
inline void writeSampleHit(const Grid& g, int a, int b, int c, float l0, float l1, float l2, float z,
                           size_t i, SampleTile& tile) {
    tile.z[i] = z;
    tile.r[i] = l0 * g.R[a] + l1 * g.R[b] + l2 * g.R[c];
    tile.g[i] = l0 * g.G[a] + l1 * g.G[b] + l2 * g.G[c];
    tile.b[i] = l0 * g.B[a] + l1 * g.B[b] + l2 * g.B[c];
    tile.a[i] = 1.f;
    if constexpr (kAttributes) {
        Vec3 N;
        if (!g.NX.empty())
            N = normalize(Vec3{l0 * g.NX[a] + l1 * g.NX[b] + l2 * g.NX[c],
                               l0 * g.NY[a] + l1 * g.NY[b] + l2 * g.NY[c],
                               l0 * g.NZ[a] + l1 * g.NZ[b] + l2 * g.NZ[c]});
        // Lights in shadow: the nearest vertex's count (counts are not interpolated).
        int shadowed = 0;
        if (!g.shadowedLights.empty())
            shadowed = g.shadowedLights[l0 >= l1 && l0 >= l2 ? a : l1 >= l2 ? b : c];
        tile.setAttributes(i, g.objectId, N, shadowed, g.textured);
        if (!g.albedo.empty())
            tile.setSurfaceAovs(i, g.albedo[a] * l0 + g.albedo[b] * l1 + g.albedo[c] * l2,
                                g.P[a] * l0 + g.P[b] * l1 + g.P[c] * l2,
                                g.Cs[a] * l0 + g.Cs[b] * l1 + g.Cs[c] * l2);
    }
}

}  // namespace tessera
