#include "reyes/rasterize.h"

#include <algorithm>
#include <cstdint>

#include "reyes/edge_functions.h"

namespace tessera {
namespace {

// One triangle of a micropolygon: its edge functions (edge_functions.h) and the grid vertices of its oriented
// corners (v[0] weight from edge 0 etc.).
struct TriangleSetup {
    TriangleEdges e;
    int v[3];
    bool valid;
};

inline TriangleSetup setupTriangle(const Grid& g, int i0, int i1, int i2) {
    TriangleSetup t;
    t.e = setupTriangleEdges(g.X[i0], g.Y[i0], g.X[i1], g.Y[i1], g.X[i2], g.Y[i2]);
    t.valid = t.e.valid;
    if (t.e.swapped) std::swap(i1, i2);
    t.v[0] = i0, t.v[1] = i1, t.v[2] = i2;
    return t;
}

// Tests the sample against the triangle; on a hit writes the interpolated depth/colour if nearer (and the
// film's attribute channels when it has any).
template <bool kAttributes>
inline bool shadeSampleIfInside(const TriangleSetup& t, const Grid& g, int64_t sx, int64_t sy, size_t i,
                                SampleTile& tile, float nearZ) {
    float l0, l1, l2;
    if (!insideTriangle(t.e, sx, sy, l0, l1, l2)) return false;
    const int a = t.v[0], b = t.v[1], c = t.v[2];
    const float z = l0 * g.Z[a] + l1 * g.Z[b] + l2 * g.Z[c];
    if (!(z < tile.z[i]) || z < nearZ) return true;
    writeSampleHit<kAttributes>(g, a, b, c, l0, l1, l2, z, i, tile);
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

template <bool kAttributes>
uint64_t rasterizeGridNearestImpl(const Grid& g, SampleTile& tile, float nearZ) {
    uint64_t tests = 0;
    const Rect& reg = tile.region;
    const int stride = g.nu + 1;
    const int spp = tile.spp, tw = reg.width();
    for (int j = 0; j < g.nv; ++j) {
        for (int i = 0; i < g.nu; ++i) {
            const int a = j * stride + i, b = a + 1, c = a + stride + 1, d = a + stride;
            if (!g.twoSided && !(g.front[a] | g.front[b] | g.front[c] | g.front[d])) continue;
            // The middle point, fixed point (floor of the mean), and the pixel that holds it.
            const int64_t mx = (int64_t(g.X[a]) + g.X[b] + g.X[c] + g.X[d]) >> 2;
            const int64_t my = (int64_t(g.Y[a]) + g.Y[b] + g.Y[c] + g.Y[d]) >> 2;
            const int64_t px = mx >> kSubpixelBits, py = my >> kSubpixelBits;
            if (px < reg.x0 || px >= reg.x1 || py < reg.y0 || py >= reg.y1) continue;
            const size_t pix = size_t(py - reg.y0) * tw + size_t(px - reg.x0);
            size_t si = pix * spp;
            int64_t best = INT64_MAX;
            for (int s = 0; s < spp; ++s) {
                const size_t k = pix * spp + size_t(s);
                const int64_t dx = tile.sx[k] - mx, dy = tile.sy[k] - my;
                const int64_t d2 = dx * dx + dy * dy;
                if (d2 < best) best = d2, si = k;
            }
            ++tests;
            const int64_t sx = tile.sx[si], sy = tile.sy[si];
            const TriangleSetup t0 = setupTriangle(g, a, b, c);
            bool hit = t0.valid && shadeSampleIfInside<kAttributes>(t0, g, sx, sy, si, tile, nearZ);
            if (!hit) {
                const TriangleSetup t1 = setupTriangle(g, a, c, d);
                hit = t1.valid && shadeSampleIfInside<kAttributes>(t1, g, sx, sy, si, tile, nearZ);
            }
            if (hit) tile.pixelHit[pix] = 1;
        }
    }
    return tests;
}

}  // namespace

uint64_t rasterizeGridNearest(const Grid& g, SampleTile& tile, float nearZ) {
    return tile.channels ? rasterizeGridNearestImpl<true>(g, tile, nearZ)
                         : rasterizeGridNearestImpl<false>(g, tile, nearZ);
}

uint64_t rasterizeGrid(const Grid& g, SampleTile& tile, float nearZ) {
    return tile.channels ? rasterizeGridImpl<true>(g, tile, nearZ) : rasterizeGridImpl<false>(g, tile, nearZ);
}

}  // namespace tessera
