#include "reyes/rasterize.h"

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <vector>
#if defined(__GNUC__) && defined(__x86_64__)
#include <immintrin.h>
#endif

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

#if defined(__GNUC__) && defined(__x86_64__)
#define TESSERA_REYES_AVX2 1
// rasterizeGridImpl with the inside tests of 8 samples at once (AVX2, compiled for it by a target
// attribute, run when the CPU has it). A micropolygon whose bound spans less than kAvx2Span fixed-point
// units (32 pixels) is tested in coordinates relative to its bound's corner: there every edge function
// value fits 32 bits (|A|, |B| < 2^13, |offset| < 2^13 + 256, |C| < 2^27) and equals the 64-bit one, so the
// same samples are inside; each inside sample is then shaded by the scalar path (same depth and colour).
// Larger micropolygons take the scalar loop.
constexpr int64_t kAvx2Span = int64_t(1) << 13;

struct EdgeLanes {
    __m256i A[3], B[3], C[3];
    int valid;
};

__attribute__((target("avx2"))) inline EdgeLanes edgeLanes(const TriangleSetup& t, int64_t ox, int64_t oy) {
    EdgeLanes e;
    e.valid = t.valid;
    for (int k = 0; k < 3; ++k) {
        // C relative to (ox, oy): the edge function at (ox + dx, oy + dy) is A dx + B dy + (A ox + B oy + C).
        const int64_t c = t.e.A[k] * ox + t.e.B[k] * oy + t.e.C[k];
        e.A[k] = _mm256_set1_epi32(int32_t(t.e.A[k]));
        e.B[k] = _mm256_set1_epi32(int32_t(t.e.B[k]));
        e.C[k] = _mm256_set1_epi32(int32_t(c));
    }
    return e;
}

// The lanes whose sample (dx, dy) lies inside the triangle (all three edge functions >= 0), as set sign
// bits (none for an invalid triangle).
__attribute__((target("avx2"))) inline __m256i insideLanes(const EdgeLanes& e, __m256i dx, __m256i dy) {
    __m256i any = _mm256_setzero_si256();
    for (int k = 0; k < 3; ++k) {
        const __m256i w = _mm256_add_epi32(
            _mm256_add_epi32(_mm256_mullo_epi32(e.A[k], dx), _mm256_mullo_epi32(e.B[k], dy)), e.C[k]);
        any = _mm256_or_si256(any, w);
    }
    return _mm256_andnot_si256(any, _mm256_set1_epi32(e.valid ? -1 : 0));  // sign clear: inside
}

template <bool kAttributes>
__attribute__((target("avx2"))) uint64_t rasterizeGridAvx2(const Grid& g, SampleTile& tile, float nearZ) {
    uint64_t tests = 0;
    const Rect& reg = tile.region;
    const int stride = g.nu + 1;
    const int nx = tile.nx, ny = tile.ny, spp = tile.spp, tw = reg.width();
    const int64_t sx0 = int64_t(reg.x0) * nx, sx1 = int64_t(reg.x1) * nx - 1;
    const int64_t sy0 = int64_t(reg.y0) * ny, sy1 = int64_t(reg.y1) * ny - 1;
    std::vector<int32_t> index;  // the candidate samples of one micropolygon, row by row
    std::vector<uint32_t> pixelOf;
    for (int j = 0; j < g.nv; ++j) {
        for (int i = 0; i < g.nu; ++i) {
            const int a = j * stride + i, b = a + 1, c = a + stride + 1, d = a + stride;
            if (!g.twoSided && !(g.front[a] | g.front[b] | g.front[c] | g.front[d])) continue;
            const int64_t minX = std::min({g.X[a], g.X[b], g.X[c], g.X[d]});
            const int64_t maxX = std::max({g.X[a], g.X[b], g.X[c], g.X[d]});
            const int64_t minY = std::min({g.Y[a], g.Y[b], g.Y[c], g.Y[d]});
            const int64_t maxY = std::max({g.Y[a], g.Y[b], g.Y[c], g.Y[d]});
            int64_t qx0 = std::max(sx0, (minX * nx) >> kSubpixelBits);
            int64_t qx1 = std::min(sx1, (maxX * nx) >> kSubpixelBits);
            int64_t qy0 = std::max(sy0, (minY * ny) >> kSubpixelBits);
            int64_t qy1 = std::min(sy1, (maxY * ny) >> kSubpixelBits);
            if (qx0 > qx1 || qy0 > qy1) continue;
            const TriangleSetup t0 = setupTriangle(g, a, b, c);
            const TriangleSetup t1 = setupTriangle(g, a, c, d);
            if (!t0.valid && !t1.valid) continue;
            const int pxStart = int(qx0 / nx), sxiStart = int(qx0 - int64_t(pxStart) * nx);
            const size_t count = size_t(qx1 - qx0 + 1) * size_t(qy1 - qy0 + 1);
            tests += count;
            if (maxX - minX >= kAvx2Span || maxY - minY >= kAvx2Span) {
                // A large micropolygon: the scalar loop of rasterizeGridImpl.
                for (int64_t qy = qy0; qy <= qy1; ++qy) {
                    const int py = int(qy / ny), syi = int(qy - int64_t(py) * ny);
                    const size_t rowPix = size_t(py - reg.y0) * tw - reg.x0;
                    int px = pxStart, sxi = sxiStart;
                    for (int64_t qx = qx0; qx <= qx1; ++qx) {
                        const size_t pix = rowPix + px;
                        const size_t si = pix * spp + size_t(syi * nx + sxi);
                        if (++sxi == nx) sxi = 0, ++px;
                        const int64_t sx = tile.sx[si], sy = tile.sy[si];
                        if (sx < minX || sx > maxX || sy < minY || sy > maxY) continue;
                        bool hit =
                            (t0.valid && shadeSampleIfInside<kAttributes>(t0, g, sx, sy, si, tile, nearZ)) ||
                            (t1.valid && shadeSampleIfInside<kAttributes>(t1, g, sx, sy, si, tile, nearZ));
                        if (hit) tile.pixelHit[pix] = 1;
                    }
                }
                continue;
            }
            // The candidates in the scalar loop's order (rows of strata), padded to a multiple of 8 with
            // the first one (its lanes are masked off).
            index.resize((count + 7) & ~size_t(7));
            pixelOf.resize(index.size());
            size_t n = 0;
            for (int64_t qy = qy0; qy <= qy1; ++qy) {
                const int py = int(qy / ny), syi = int(qy - int64_t(py) * ny);
                const size_t rowPix = size_t(py - reg.y0) * tw - reg.x0;
                int px = pxStart, sxi = sxiStart;
                for (int64_t qx = qx0; qx <= qx1; ++qx, ++n) {
                    const size_t pix = rowPix + px;
                    index[n] = int32_t(pix * spp + size_t(syi * nx + sxi));
                    pixelOf[n] = uint32_t(pix);
                    if (++sxi == nx) sxi = 0, ++px;
                }
            }
            for (size_t k = n; k < index.size(); ++k) index[k] = index[0];
            const EdgeLanes e0 = edgeLanes(t0, minX, minY), e1 = edgeLanes(t1, minX, minY);
            const __m256i ox = _mm256_set1_epi32(int32_t(minX)), oy = _mm256_set1_epi32(int32_t(minY));
            const __m256i spanX = _mm256_set1_epi32(int32_t(maxX - minX)),
                          spanY = _mm256_set1_epi32(int32_t(maxY - minY));
            const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
            for (size_t k = 0; k < n; k += 8) {
                const __m256i idx = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(&index[k]));
                const __m256i dx = _mm256_sub_epi32(
                    _mm256_i32gather_epi32(reinterpret_cast<const int*>(tile.sx.data()), idx, 4), ox);
                const __m256i dy = _mm256_sub_epi32(
                    _mm256_i32gather_epi32(reinterpret_cast<const int*>(tile.sy.data()), idx, 4), oy);
                // In the bound: 0 <= d <= span (as the scalar loop's minX <= sx <= maxX).
                const __m256i out =
                    _mm256_or_si256(_mm256_or_si256(_mm256_cmpgt_epi32(_mm256_setzero_si256(), dx),
                                                    _mm256_cmpgt_epi32(dx, spanX)),
                                    _mm256_or_si256(_mm256_cmpgt_epi32(_mm256_setzero_si256(), dy),
                                                    _mm256_cmpgt_epi32(dy, spanY)));
                const __m256i live = _mm256_cmpgt_epi32(_mm256_set1_epi32(int32_t(n - k)), lane);
                const __m256i in = _mm256_or_si256(insideLanes(e0, dx, dy), insideLanes(e1, dx, dy));
                // Sign bits: inside either triangle, a real candidate, in the bound.
                const __m256i hitLanes = _mm256_andnot_si256(out, _mm256_and_si256(live, in));
                unsigned mask = unsigned(_mm256_movemask_ps(_mm256_castsi256_ps(hitLanes)));
                for (; mask; mask &= mask - 1) {
                    const size_t m = k + size_t(__builtin_ctz(mask));
                    const size_t si = size_t(index[m]);
                    const int64_t sx = tile.sx[si], sy = tile.sy[si];
                    bool hit =
                        (t0.valid && shadeSampleIfInside<kAttributes>(t0, g, sx, sy, si, tile, nearZ)) ||
                        (t1.valid && shadeSampleIfInside<kAttributes>(t1, g, sx, sy, si, tile, nearZ));
                    if (hit) tile.pixelHit[pixelOf[m]] = 1;
                }
            }
        }
    }
    return tests;
}

std::atomic<bool> gReyesAvx2Allowed{true};

bool cpuHasAvx2() {
    static const bool has = [] {
        __builtin_cpu_init();
        return bool(__builtin_cpu_supports("avx2"));
    }();
    return has;
}
#else
#define TESSERA_REYES_AVX2 0
#endif

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
#if TESSERA_REYES_AVX2
    if (cpuHasAvx2() && gReyesAvx2Allowed.load(std::memory_order_relaxed))
        return tile.channels ? rasterizeGridAvx2<true>(g, tile, nearZ)
                             : rasterizeGridAvx2<false>(g, tile, nearZ);
#endif
    return tile.channels ? rasterizeGridImpl<true>(g, tile, nearZ) : rasterizeGridImpl<false>(g, tile, nearZ);
}

bool reyesUseAvx2(bool allow) {
#if TESSERA_REYES_AVX2
    gReyesAvx2Allowed.store(allow, std::memory_order_relaxed);
    return allow && cpuHasAvx2();
#else
    (void)allow;
    return false;
#endif
}

}  // namespace tessera
