#include "reyes/rasterize.h"

#include <algorithm>

namespace tessera {
namespace {

struct Vtx {
    int64_t x, y;
    float z, r, g, b;
};

// Edge a->b owns samples exactly on it when it is a "top" or "left" edge for a positive-area triangle:
// one of the two triangles sharing an edge walks it in each direction, so exactly one includes the sample.
inline int64_t fillBias(const Vtx& a, const Vtx& b) {
    int64_t dy = b.y - a.y, dx = b.x - a.x;
    return (dy > 0 || (dy == 0 && dx < 0)) ? 0 : 1;
}

uint64_t rasterizeTriangle(Vtx v0, Vtx v1, Vtx v2, SampleTile& tile, float nearZ) {
    int64_t area = (v1.x - v0.x) * (v2.y - v0.y) - (v2.x - v0.x) * (v1.y - v0.y);
    if (area == 0) return 0;
    if (area < 0) {
        std::swap(v1, v2);
        area = -area;
    }
    const int64_t minX = std::min({v0.x, v1.x, v2.x}), maxX = std::max({v0.x, v1.x, v2.x});
    const int64_t minY = std::min({v0.y, v1.y, v2.y}), maxY = std::max({v0.y, v1.y, v2.y});
    const Rect& reg = tile.region;
    // Pixels whose samples can lie in the bounding box.
    int px0 = int(std::max<int64_t>(minX >> kSubpixelBits, reg.x0));
    int px1 = int(std::min<int64_t>(maxX >> kSubpixelBits, reg.x1 - 1));
    int py0 = int(std::max<int64_t>(minY >> kSubpixelBits, reg.y0));
    int py1 = int(std::min<int64_t>(maxY >> kSubpixelBits, reg.y1 - 1));
    if (px0 > px1 || py0 > py1) return 0;

    // Edge function E_ab(p) = (b.x-a.x)(p.y-a.y) - (b.y-a.y)(p.x-a.x) = A*p.x + B*p.y + C.
    auto setup = [](const Vtx& a, const Vtx& b, int64_t& A, int64_t& B, int64_t& C) {
        A = -(b.y - a.y);
        B = (b.x - a.x);
        C = -(A * a.x + B * a.y);
    };
    int64_t A0, B0, C0, A1, B1, C1, A2, B2, C2;
    setup(v1, v2, A0, B0, C0);  // weight of v0
    setup(v2, v0, A1, B1, C1);  // weight of v1
    setup(v0, v1, A2, B2, C2);  // weight of v2
    C0 -= fillBias(v1, v2);
    C1 -= fillBias(v2, v0);
    C2 -= fillBias(v0, v1);
    const float invArea = 1.f / float(area);

    const int tw = reg.width();
    const int spp = tile.spp;
    uint64_t tests = 0;
    for (int py = py0; py <= py1; ++py) {
        for (int px = px0; px <= px1; ++px) {
            const size_t pix = size_t(py - reg.y0) * tw + (px - reg.x0);
            const size_t base = pix * spp;
            bool hit = false;
            for (int s = 0; s < spp; ++s) {
                const size_t i = base + s;
                const int64_t sx = tile.sx[i], sy = tile.sy[i];
                ++tests;
                if (sx < minX || sx > maxX || sy < minY || sy > maxY) continue;
                const int64_t w0 = A0 * sx + B0 * sy + C0;
                const int64_t w1 = A1 * sx + B1 * sy + C1;
                const int64_t w2 = A2 * sx + B2 * sy + C2;
                if ((w0 | w1 | w2) < 0) continue;
                // Barycentric weights (the bias only shifts ties; it does not matter for interpolation).
                const float l1 = float(w1) * invArea, l2 = float(w2) * invArea, l0 = 1.f - l1 - l2;
                const float z = l0 * v0.z + l1 * v1.z + l2 * v2.z;
                if (!(z < tile.z[i]) || z < nearZ) continue;
                tile.z[i] = z;
                tile.r[i] = l0 * v0.r + l1 * v1.r + l2 * v2.r;
                tile.g[i] = l0 * v0.g + l1 * v1.g + l2 * v2.g;
                tile.b[i] = l0 * v0.b + l1 * v1.b + l2 * v2.b;
                tile.a[i] = 1.f;
                hit = true;
            }
            if (hit) tile.pixelHit[pix] = 1;
        }
    }
    return tests;
}

}  // namespace

uint64_t rasterizeGrid(const Grid& g, SampleTile& tile, float nearZ) {
    uint64_t tests = 0;
    const int stride = g.nu + 1;
    auto vtx = [&](int idx) { return Vtx{g.X[idx], g.Y[idx], g.Z[idx], g.R[idx], g.G[idx], g.B[idx]}; };
    const int64_t rx0 = int64_t(tile.region.x0) << kSubpixelBits, rx1 = int64_t(tile.region.x1) << kSubpixelBits;
    const int64_t ry0 = int64_t(tile.region.y0) << kSubpixelBits, ry1 = int64_t(tile.region.y1) << kSubpixelBits;
    for (int j = 0; j < g.nv; ++j) {
        for (int i = 0; i < g.nu; ++i) {
            const int a = j * stride + i, b = a + 1, c = a + stride + 1, d = a + stride;
            // Quick reject of micropolygons outside the tile.
            int32_t qx0 = std::min({g.X[a], g.X[b], g.X[c], g.X[d]}), qx1 = std::max({g.X[a], g.X[b], g.X[c], g.X[d]});
            int32_t qy0 = std::min({g.Y[a], g.Y[b], g.Y[c], g.Y[d]}), qy1 = std::max({g.Y[a], g.Y[b], g.Y[c], g.Y[d]});
            if (qx1 < rx0 || qx0 >= rx1 || qy1 < ry0 || qy0 >= ry1) continue;
            if (!g.twoSided && !(g.front[a] | g.front[b] | g.front[c] | g.front[d])) continue;
            tests += rasterizeTriangle(vtx(a), vtx(b), vtx(c), tile, nearZ);
            tests += rasterizeTriangle(vtx(a), vtx(c), vtx(d), tile, nearZ);
        }
    }
    return tests;
}

}  // namespace tessera
