#include "reyes/rasterize.h"

#include <algorithm>

namespace tessera {
namespace {

// One triangle of a micropolygon, set up for exact integer point-in-triangle tests.
// Edge function E_ab(p) = (b.x-a.x)(p.y-a.y) - (b.y-a.y)(p.x-a.x) = A*p.x + B*p.y + C, made positive
// inside by orienting the triangle counter-clockwise (positive area).
struct TriangleSetup {
    int64_t A[3], B[3], C[3];
    float invArea;
    int v[3];  // grid vertex indices, v[0] weight from edge 0 etc.
    bool valid;
};

// Edge a->b owns samples exactly on it when it is a "top" or "left" edge; the neighbouring triangle walks
// the same edge the other way, so a sample on a shared edge belongs to exactly one of them.
inline int64_t fillBias(int64_t ax, int64_t ay, int64_t bx, int64_t by) {
    int64_t dy = by - ay, dx = bx - ax;
    return (dy > 0 || (dy == 0 && dx < 0)) ? 0 : 1;
}

inline TriangleSetup setupTriangle(const Grid& g, int i0, int i1, int i2) {
    TriangleSetup t;
    int64_t x0 = g.X[i0], y0 = g.Y[i0], x1 = g.X[i1], y1 = g.Y[i1], x2 = g.X[i2], y2 = g.Y[i2];
    int64_t area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
    t.valid = area != 0;
    if (area < 0) {
        std::swap(x1, x2);
        std::swap(y1, y2);
        std::swap(i1, i2);
        area = -area;
    }
    t.v[0] = i0, t.v[1] = i1, t.v[2] = i2;
    const int64_t xs[3] = {x0, x1, x2}, ys[3] = {y0, y1, y2};
    for (int e = 0; e < 3; ++e) {
        // Edge opposite vertex e, from vertex e+1 to e+2: its function is the weight of vertex e.
        int a = (e + 1) % 3, b = (e + 2) % 3;
        t.A[e] = -(ys[b] - ys[a]);
        t.B[e] = xs[b] - xs[a];
        t.C[e] = -(t.A[e] * xs[a] + t.B[e] * ys[a]) - fillBias(xs[a], ys[a], xs[b], ys[b]);
    }
    t.invArea = t.valid ? 1.f / float(area) : 0.f;
    return t;
}

// Tests the sample against the triangle; on a hit writes the interpolated depth/colour if nearer (and the
// film's attribute channels when it has any).
template <bool kAttributes>
inline bool shadeSampleIfInside(const TriangleSetup& t, const Grid& g, int64_t sx, int64_t sy, size_t i,
                                SampleTile& tile, float nearZ) {
    const int64_t w0 = t.A[0] * sx + t.B[0] * sy + t.C[0];
    const int64_t w1 = t.A[1] * sx + t.B[1] * sy + t.C[1];
    const int64_t w2 = t.A[2] * sx + t.B[2] * sy + t.C[2];
    if ((w0 | w1 | w2) < 0) return false;
    // Barycentric weights (the fill-rule bias shifts them by at most 1 unit: negligible).
    const float l1 = float(w1) * t.invArea, l2 = float(w2) * t.invArea, l0 = 1.f - l1 - l2;
    const int a = t.v[0], b = t.v[1], c = t.v[2];
    const float z = l0 * g.Z[a] + l1 * g.Z[b] + l2 * g.Z[c];
    if (!(z < tile.z[i]) || z < nearZ) return true;
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
        // Reyes has no shadows or textures yet: no lights in shadow, untextured.
        tile.setAttributes(i, g.objectId, N, 0, false);
    }
    return true;
}

template <bool kAttributes>
uint64_t rasterizeGridImpl(const Grid& g, SampleTile& tile, float nearZ) {
    uint64_t tests = 0;
    const Rect& reg = tile.region;
    const int stride = g.nu + 1;
    const int nx = tile.nx, ny = tile.ny, spp = tile.spp, tw = reg.width();
    // Samples are stratified: sample (sxi, syi) of pixel (px, py) lies in stratum (px*nx+sxi, py*ny+syi) of
    // a global nx-by-ny-per-pixel lattice. A micropolygon's bounding box therefore names exactly the strata,
    // hence the samples, that can fall inside it.
    const int64_t sx0 = int64_t(reg.x0) * nx, sx1 = int64_t(reg.x1) * nx - 1;
    const int64_t sy0 = int64_t(reg.y0) * ny, sy1 = int64_t(reg.y1) * ny - 1;
    for (int j = 0; j < g.nv; ++j) {
        for (int i = 0; i < g.nu; ++i) {
            const int a = j * stride + i, b = a + 1, c = a + stride + 1, d = a + stride;
            if (!g.twoSided && !(g.front[a] | g.front[b] | g.front[c] | g.front[d])) continue;
            const int64_t minX = std::min({g.X[a], g.X[b], g.X[c], g.X[d]});
            const int64_t maxX = std::max({g.X[a], g.X[b], g.X[c], g.X[d]});
            const int64_t minY = std::min({g.Y[a], g.Y[b], g.Y[c], g.Y[d]});
            const int64_t maxY = std::max({g.Y[a], g.Y[b], g.Y[c], g.Y[d]});
            // Strata overlapped by the bounding box (floor division of fixed point by the stratum size).
            int64_t qx0 = std::max(sx0, (minX * nx) >> kSubpixelBits);
            int64_t qx1 = std::min(sx1, (maxX * nx) >> kSubpixelBits);
            int64_t qy0 = std::max(sy0, (minY * ny) >> kSubpixelBits);
            int64_t qy1 = std::min(sy1, (maxY * ny) >> kSubpixelBits);
            if (qx0 > qx1 || qy0 > qy1) continue;
            const TriangleSetup t0 = setupTriangle(g, a, b, c);
            const TriangleSetup t1 = setupTriangle(g, a, c, d);
            if (!t0.valid && !t1.valid) continue;
            const int pxStart = int(qx0 / nx), sxiStart = int(qx0 - int64_t(pxStart) * nx);
            for (int64_t qy = qy0; qy <= qy1; ++qy) {
                const int py = int(qy / ny), syi = int(qy - int64_t(py) * ny);
                const size_t rowPix = size_t(py - reg.y0) * tw - reg.x0;
                int px = pxStart, sxi = sxiStart;
                for (int64_t qx = qx0; qx <= qx1; ++qx) {
                    const size_t pix = rowPix + px;
                    const size_t si = pix * spp + size_t(syi * nx + sxi);
                    if (++sxi == nx) sxi = 0, ++px;
                    const int64_t sx = tile.sx[si], sy = tile.sy[si];
                    ++tests;
                    if (sx < minX || sx > maxX || sy < minY || sy > maxY) continue;
                    bool hit =
                        (t0.valid && shadeSampleIfInside<kAttributes>(t0, g, sx, sy, si, tile, nearZ)) ||
                        (t1.valid && shadeSampleIfInside<kAttributes>(t1, g, sx, sy, si, tile, nearZ));
                    if (hit) tile.pixelHit[pix] = 1;
                }
            }
        }
    }
    return tests;
}

}  // namespace

uint64_t rasterizeGrid(const Grid& g, SampleTile& tile, float nearZ) {
    return tile.channels ? rasterizeGridImpl<true>(g, tile, nearZ) : rasterizeGridImpl<false>(g, tile, nearZ);
}

}  // namespace tessera
