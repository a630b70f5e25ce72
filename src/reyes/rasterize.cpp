#include "reyes/rasterize.h"

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <vector>
#if defined(__GNUC__) && defined(__x86_64__)
#include <immintrin.h>
#endif

#include "core/cpu.h"
#include "reyes/edge_functions.h"

namespace tessera {
namespace {

// One triangle of a micropolygon: its edge functions (edge_functions.h) and the grid vertices of its oriented
// corners (v[0] weight from edge 0 etc.). Int = int32_t: in coordinates relative to (ox, oy), for the AVX2
// path's small micropolygons (the same A, B and weights; C relative to the origin).
template <class Int>
struct TriangleSetupOf {
    TriangleEdgesOf<Int> e;
    int v[3];
    bool valid;
};
using TriangleSetup = TriangleSetupOf<int64_t>;

template <class Int = int64_t>
inline TriangleSetupOf<Int> setupTriangle(const Grid& g, int i0, int i1, int i2, int64_t ox = 0,
                                          int64_t oy = 0) {
    TriangleSetupOf<Int> t;
    t.e = setupTriangleEdges<Int>(Int(g.X[i0] - ox), Int(g.Y[i0] - oy), Int(g.X[i1] - ox), Int(g.Y[i1] - oy),
                                  Int(g.X[i2] - ox), Int(g.Y[i2] - oy));
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

// Samples are stratified: sample (sxi, syi) of pixel (px, py) lies in stratum (px*nx+sxi, py*ny+syi) of a
// global nx-by-ny-per-pixel lattice. A micropolygon's bounding box therefore names exactly the strata, hence
// the samples, that can fall inside it.
struct StrataLattice {
    Rect reg;
    int nx, ny, spp, tw;
    int64_t sx0, sx1, sy0, sy1;  // the tile's strata
    explicit StrataLattice(const SampleTile& tile)
        : reg(tile.region),
          nx(tile.nx),
          ny(tile.ny),
          spp(tile.spp),
          tw(tile.region.width()),
          sx0(int64_t(reg.x0) * nx),
          sx1(int64_t(reg.x1) * nx - 1),
          sy0(int64_t(reg.y0) * ny),
          sy1(int64_t(reg.y1) * ny - 1) {}
};

// One micropolygon (grid quad a, b = a + 1, c = a + stride + 1, d = a + stride): its bound, the strata the
// bound overlaps and its two triangles (t0, t1: 64-bit; r0, r1: 32-bit relative to the bound's corner, the
// AVX2 path's).
struct Micropolygon {
    int64_t minX, maxX, minY, maxY, qx0, qx1, qy0, qy1;
    TriangleSetup t0, t1;
    TriangleSetupOf<int32_t> r0, r1;
    size_t strata() const { return size_t(qx1 - qx0 + 1) * size_t(qy1 - qy0 + 1); }
};

// false when the micropolygon faces away (one-sided grid) or overlaps no stratum of the tile; else its
// bound and strata are set.
[[gnu::always_inline]] inline bool boundMicropolygon(const Grid& g, int a, int stride, const StrataLattice& s,
                                                     Micropolygon& m) {
    const int b = a + 1, c = a + stride + 1, d = a + stride;
    if (!g.twoSided && !(g.front[a] | g.front[b] | g.front[c] | g.front[d])) return false;
    m.minX = std::min({g.X[a], g.X[b], g.X[c], g.X[d]});
    m.maxX = std::max({g.X[a], g.X[b], g.X[c], g.X[d]});
    m.minY = std::min({g.Y[a], g.Y[b], g.Y[c], g.Y[d]});
    m.maxY = std::max({g.Y[a], g.Y[b], g.Y[c], g.Y[d]});
    // Strata overlapped by the bounding box (floor division of fixed point by the stratum size).
    m.qx0 = std::max(s.sx0, (m.minX * s.nx) >> kSubpixelBits);
    m.qx1 = std::min(s.sx1, (m.maxX * s.nx) >> kSubpixelBits);
    m.qy0 = std::max(s.sy0, (m.minY * s.ny) >> kSubpixelBits);
    m.qy1 = std::min(s.sy1, (m.maxY * s.ny) >> kSubpixelBits);
    return m.qx0 <= m.qx1 && m.qy0 <= m.qy1;
}

// The micropolygon's 64-bit triangles; false when both are degenerate.
[[gnu::always_inline]] inline bool setupTriangles(const Grid& g, int a, int stride, Micropolygon& m) {
    m.t0 = setupTriangle(g, a, a + 1, a + stride + 1);
    m.t1 = setupTriangle(g, a, a + stride + 1, a + stride);
    return m.t0.valid || m.t1.valid;
}

// boundMicropolygon, then setupTriangles: false when it faces away, overlaps no stratum of the tile or is
// degenerate.
[[gnu::always_inline]] inline bool setupMicropolygon(const Grid& g, int a, int stride, const StrataLattice& s,
                                                     Micropolygon& m) {
    return boundMicropolygon(g, a, stride, s, m) && setupTriangles(g, a, stride, m);
}

// visit(pixel, sample index) for the sample of each stratum the micropolygon's bound overlaps, in rows.
template <class Visit>
[[gnu::always_inline]] inline void forEachStratum(const Micropolygon& m, const StrataLattice& s,
                                                  Visit&& visit) {
    const int pxStart = int(m.qx0 / s.nx), sxiStart = int(m.qx0 - int64_t(pxStart) * s.nx);
    for (int64_t qy = m.qy0; qy <= m.qy1; ++qy) {
        const int py = int(qy / s.ny), syi = int(qy - int64_t(py) * s.ny);
        const size_t rowPix = size_t(py - s.reg.y0) * s.tw - s.reg.x0;
        int px = pxStart, sxi = sxiStart;
        for (int64_t qx = m.qx0; qx <= m.qx1; ++qx) {
            const size_t pix = rowPix + px;
            visit(pix, pix * s.spp + size_t(syi * s.nx + sxi));
            if (++sxi == s.nx) sxi = 0, ++px;
        }
    }
}

// The scalar test of sample si (of pixel pix) against the micropolygon: in its bound, then in a triangle
// (the first one first), then the depth test and the write.
template <bool kAttributes>
[[gnu::always_inline]] inline void testSample(const Micropolygon& m, const Grid& g, size_t pix, size_t si,
                                              SampleTile& tile, float nearZ) {
    const int64_t sx = tile.sx[si], sy = tile.sy[si];
    if (sx < m.minX || sx > m.maxX || sy < m.minY || sy > m.maxY) return;
    const bool hit = (m.t0.valid && shadeSampleIfInside<kAttributes>(m.t0, g, sx, sy, si, tile, nearZ)) ||
                     (m.t1.valid && shadeSampleIfInside<kAttributes>(m.t1, g, sx, sy, si, tile, nearZ));
    if (hit) tile.pixelHit[pix] = 1;
}

// testSample for a tile in stratum order (SampleTile::enterStrataOrder): the sample of stratum s, its depth
// and colour written at s.
[[gnu::always_inline]] inline void testStratum(const Micropolygon& m, const Grid& g, size_t s,
                                               SampleTile& tile, float nearZ) {
    const int64_t sx = tile.strataX[s], sy = tile.strataY[s];
    if (sx < m.minX || sx > m.maxX || sy < m.minY || sy > m.maxY) return;
    for (const TriangleSetup* t : {&m.t0, &m.t1}) {
        float l0, l1, l2;
        if (!t->valid || !insideTriangle(t->e, sx, sy, l0, l1, l2)) continue;
        const int a = t->v[0], b = t->v[1], c = t->v[2];
        const float z = l0 * g.Z[a] + l1 * g.Z[b] + l2 * g.Z[c];
        tile.strataCovered[s] = -1;
        if (!(z < tile.strataZ[s]) || z < nearZ) return;
        tile.strataZ[s] = z;
        tile.strataR[s] = l0 * g.R[a] + l1 * g.R[b] + l2 * g.R[c];
        tile.strataG[s] = l0 * g.G[a] + l1 * g.G[b] + l2 * g.G[c];
        tile.strataB[s] = l0 * g.B[a] + l1 * g.B[b] + l2 * g.B[c];
        tile.strataA[s] = 1.f;
        return;
    }
}

template <bool kAttributes>
uint64_t rasterizeGridImpl(const Grid& g, SampleTile& tile, float nearZ) {
    tile.leaveStrataOrder();
    uint64_t tests = 0;
    const StrataLattice lattice(tile);
    const int stride = g.nu + 1;
    Micropolygon m;
    for (int j = 0; j < g.nv; ++j)
        for (int i = 0; i < g.nu; ++i) {
            if (!setupMicropolygon(g, j * stride + i, stride, lattice, m)) continue;
            tests += m.strata();
            forEachStratum(m, lattice, [&](size_t pix, size_t si) {
                testSample<kAttributes>(m, g, pix, si, tile, nearZ);
            });
        }
    return tests;
}

#if defined(__GNUC__) && defined(__x86_64__)
#define TESSERA_REYES_AVX2 1
// rasterizeGridImpl with the inside tests of 8 samples at once (AVX2, compiled for it by a target
// attribute, run when the CPU has it). A micropolygon whose bound spans less than kAvx2Span fixed-point
// units (32 pixels) is tested in coordinates relative to its bound's corner: there every edge function
// value fits 32 bits (|A|, |B| < 2^13, |offset| < 2^13 + 256, |C| < 2^27) and equals the 64-bit one, so the
// same samples are inside. A and B and the offsets also fit 16 bits, so A dx + B dy is one multiply-add
// of 16-bit pairs (vpmaddwd, exact) instead of two 32-bit multiplies. Larger micropolygons take the scalar
// loop.
constexpr int64_t kAvx2Span = int64_t(1) << 13;

struct EdgeLanes {
    __m256i AB[3], C[3];  // AB: A in the low 16 bits of each 32-bit lane, B in the high 16
    int valid;
};

// t set up relative to the bound's corner: the edge function at (corner + dx, corner + dy) is A dx + B dy +
// C.
__attribute__((target("avx2"))) inline EdgeLanes edgeLanes(const TriangleSetupOf<int32_t>& t) {
    EdgeLanes e;
    e.valid = t.valid;
    for (int k = 0; k < 3; ++k) {
        e.AB[k] = _mm256_set1_epi32(
            int32_t(uint32_t(uint16_t(int16_t(t.e.A[k]))) | uint32_t(uint16_t(int16_t(t.e.B[k]))) << 16));
        e.C[k] = _mm256_set1_epi32(t.e.C[k]);
    }
    return e;
}

// The lanes whose sample (dx, dy) lies inside the triangle (all three edge functions >= 0), as set sign
// bits (none for an invalid triangle); dxdy: dx in the low 16 bits of each lane, dy in the high 16; w1, w2:
// the edge functions of edges 1 and 2 (the weights of oriented vertices 1 and 2 times the doubled area, as
// insideTriangle computes them).
__attribute__((target("avx2"))) inline __m256i insideLanes(const EdgeLanes& e, __m256i dxdy, __m256i& w1,
                                                           __m256i& w2) {
    __m256i w[3];
    for (int k = 0; k < 3; ++k) w[k] = _mm256_add_epi32(_mm256_madd_epi16(e.AB[k], dxdy), e.C[k]);
    w1 = w[1], w2 = w[2];
    const __m256i any = _mm256_or_si256(_mm256_or_si256(w[0], w[1]), w[2]);
    return _mm256_andnot_si256(any, _mm256_set1_epi32(e.valid ? -1 : 0));  // sign clear: inside
}

// A sample inside triangle t with edge values w1, w2 (insideTriangle's, from the AVX2 lanes): the weights,
// depth test and write as shadeSampleIfInside does them.
template <bool kAttributes, class Setup>
[[gnu::always_inline]] inline void shadeInsideSample(const Setup& t, const Grid& g, int64_t w1, int64_t w2,
                                                     size_t i, size_t pix, SampleTile& tile, float nearZ) {
    const float l1 = float(w1) * t.e.invArea, l2 = float(w2) * t.e.invArea, l0 = 1.f - l1 - l2;
    const int a = t.v[0], b = t.v[1], c = t.v[2];
    const float z = l0 * g.Z[a] + l1 * g.Z[b] + l2 * g.Z[c];
    tile.pixelHit[pix] = 1;
    if (!(z < tile.z[i]) || z < nearZ) return;
    writeSampleHit<kAttributes>(g, a, b, c, l0, l1, l2, z, i, tile);
}

// Depth and colour at 8 lanes, each interpolated on triangle t0 of the micropolygon where `in0` (sign bits)
// marks it inside t0, else on t1, with edge values w[t][0], w[t][1]: writeSampleHit's values.
struct alignas(32) HitLanes {
    float z[8], r[8], g[8], b[8];
};

// Per lane: `first` where the sign bit of `onFirst` is set, else `second`.
__attribute__((target("avx2"))) inline __m256 pickLanes(__m256 onFirst, __m256 first, __m256 second) {
    return _mm256_blendv_ps(second, first, onFirst);
}

// l0 v[a] + l1 v[b] + l2 v[c] per lane, the vertices of the lane's triangle.
__attribute__((target("avx2"))) inline void interpolateLanes(const Micropolygon& m, __m256 onFirst, __m256 l0,
                                                             __m256 l1, __m256 l2,
                                                             const std::vector<float>& v, float* out) {
    __m256 at[3];
    for (int k = 0; k < 3; ++k)
        at[k] =
            pickLanes(onFirst, _mm256_set1_ps(v[size_t(m.r0.v[k])]), _mm256_set1_ps(v[size_t(m.r1.v[k])]));
    _mm256_store_ps(out, _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(l0, at[0]), _mm256_mul_ps(l1, at[1])),
                                       _mm256_mul_ps(l2, at[2])));
}

__attribute__((target("avx2"))) inline HitLanes hitLanes(const Micropolygon& m, const Grid& g, __m256i in0,
                                                         const __m256i (&w)[2][2]) {
    const __m256 onFirst = _mm256_castsi256_ps(in0);
    // Edge values fit 32 bits, so converting them from 32 bits rounds as the scalar path's 64-bit ones.
    const __m256 inv = pickLanes(onFirst, _mm256_set1_ps(m.r0.e.invArea), _mm256_set1_ps(m.r1.e.invArea));
    const __m256 w1 = pickLanes(onFirst, _mm256_cvtepi32_ps(w[0][0]), _mm256_cvtepi32_ps(w[1][0]));
    const __m256 w2 = pickLanes(onFirst, _mm256_cvtepi32_ps(w[0][1]), _mm256_cvtepi32_ps(w[1][1]));
    const __m256 l1 = _mm256_mul_ps(w1, inv), l2 = _mm256_mul_ps(w2, inv);
    const __m256 l0 = _mm256_sub_ps(_mm256_sub_ps(_mm256_set1_ps(1.f), l1), l2);
    HitLanes h;
    interpolateLanes(m, onFirst, l0, l1, l2, g.Z, h.z);
    interpolateLanes(m, onFirst, l0, l1, l2, g.R, h.r);
    interpolateLanes(m, onFirst, l0, l1, l2, g.G, h.g);
    interpolateLanes(m, onFirst, l0, l1, l2, g.B, h.b);
    return h;
}

// hitLanes when every hit lane lies in triangle t (edge values w[0], w[1]): the same operations on t's
// values, without choosing per lane.
__attribute__((target("avx2"))) inline void interpolateLanesOf(const TriangleSetupOf<int32_t>& t, __m256 l0,
                                                               __m256 l1, __m256 l2,
                                                               const std::vector<float>& v, float* out) {
    _mm256_store_ps(out, _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(l0, _mm256_set1_ps(v[size_t(t.v[0])])),
                                                     _mm256_mul_ps(l1, _mm256_set1_ps(v[size_t(t.v[1])]))),
                                       _mm256_mul_ps(l2, _mm256_set1_ps(v[size_t(t.v[2])]))));
}
__attribute__((target("avx2"))) inline HitLanes hitLanesOf(const TriangleSetupOf<int32_t>& t, const Grid& g,
                                                           const __m256i (&w)[2]) {
    const __m256 inv = _mm256_set1_ps(t.e.invArea);
    const __m256 l1 = _mm256_mul_ps(_mm256_cvtepi32_ps(w[0]), inv),
                 l2 = _mm256_mul_ps(_mm256_cvtepi32_ps(w[1]), inv);
    const __m256 l0 = _mm256_sub_ps(_mm256_sub_ps(_mm256_set1_ps(1.f), l1), l2);
    HitLanes h;
    interpolateLanesOf(t, l0, l1, l2, g.Z, h.z);
    interpolateLanesOf(t, l0, l1, l2, g.R, h.r);
    interpolateLanesOf(t, l0, l1, l2, g.G, h.g);
    interpolateLanesOf(t, l0, l1, l2, g.B, h.b);
    return h;
}

// value where the sign bit of `pass` is set, else what `to` holds.
__attribute__((target("avx2"))) inline void writeLanes(float* to, __m256 value, __m256 pass) {
    _mm256_storeu_ps(to, _mm256_blendv_ps(_mm256_loadu_ps(to), value, pass));
}

// The sample tests of the micropolygon's bound read row by row from the tile's stratum-ordered copy of
// the positions (SampleTile::buildStrataOrder): a row's strata are contiguous there, so 8 lanes load
// straight from memory where the pixel-ordered samples would need an index list and gathers.
// Without attributes the depth, colour and coverage are written in stratum order too (the tile stays in it
// until the bucket's last grid: SampleTile::enterStrataOrder), so a row group's depth test and writes are
// 8-lane vector operations; with attributes they go to the pixel-ordered arrays hit by hit.
template <bool kAttributes>
__attribute__((target("avx2"))) uint64_t rasterizeGridAvx2(const Grid& g, SampleTile& tile, float nearZ) {
    uint64_t tests = 0;
    if constexpr (kAttributes) {
        tile.leaveStrataOrder();
        if (!tile.hasStrataOrder()) tile.buildStrataOrder();
    } else {
        tile.enterStrataOrder();
    }
    const StrataLattice lattice(tile);
    const int stride = g.nu + 1;
    const size_t latticeWidth = size_t(lattice.tw) * size_t(lattice.nx);
    const int32_t* strataX = tile.strataX.data();
    const int32_t* strataY = tile.strataY.data();
    const SampleTile::StrataLine* columns = tile.strataColumn.data();
    const SampleTile::StrataLine* rows = tile.strataRow.data();
    const size_t spp = size_t(tile.spp);
    const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    Micropolygon m;
    for (int j = 0; j < g.nv; ++j) {
        for (int i = 0; i < g.nu; ++i) {
            const int a = j * stride + i;
            if (!boundMicropolygon(g, a, stride, lattice, m)) continue;
            if (m.maxX - m.minX >= kAvx2Span || m.maxY - m.minY >= kAvx2Span) {
                if (!setupTriangles(g, a, stride, m)) continue;
                tests += m.strata();
                if constexpr (kAttributes) {
                    forEachStratum(m, lattice, [&](size_t pix, size_t si) {
                        testSample<kAttributes>(m, g, pix, si, tile, nearZ);
                    });
                } else {
                    for (int64_t qy = m.qy0; qy <= m.qy1; ++qy)
                        for (int64_t qx = m.qx0; qx <= m.qx1; ++qx)
                            testStratum(m, g,
                                        size_t(qy - lattice.sy0) * latticeWidth + size_t(qx - lattice.sx0),
                                        tile, nearZ);
                }
                continue;
            }
            // Small enough for 32 bits relative to the bound's corner (see kAvx2Span).
            m.r0 = setupTriangle<int32_t>(g, a, a + 1, a + stride + 1, m.minX, m.minY);
            m.r1 = setupTriangle<int32_t>(g, a, a + stride + 1, a + stride, m.minX, m.minY);
            if (!m.r0.valid && !m.r1.valid) continue;
            tests += m.strata();
            const EdgeLanes e0 = edgeLanes(m.r0), e1 = edgeLanes(m.r1);
            const __m256i ox = _mm256_set1_epi32(int32_t(m.minX)), oy = _mm256_set1_epi32(int32_t(m.minY));
            const size_t col0 = size_t(m.qx0 - lattice.sx0);
            const int rowLength = int(m.qx1 - m.qx0 + 1);
            for (int64_t qy = m.qy0; qy <= m.qy1; ++qy) {
                const size_t row = size_t(qy - lattice.sy0);
                const size_t base = row * latticeWidth + col0;  // the row's first stratum
                for (int k = 0; k < rowLength; k += 8) {
                    const __m256i dx = _mm256_sub_epi32(
                        _mm256_loadu_si256(reinterpret_cast<const __m256i*>(strataX + base + k)), ox);
                    const __m256i dy = _mm256_sub_epi32(
                        _mm256_loadu_si256(reinterpret_cast<const __m256i*>(strataY + base + k)), oy);
                    // The lanes of the row's strata. The scalar test's bound test is left out: a sample
                    // that passes all three edge tests lies in the closed triangle, so in the bound.
                    const __m256i live = _mm256_cmpgt_epi32(_mm256_set1_epi32(rowLength - k), lane);
                    const __m256i dxdy = _mm256_blend_epi16(dx, _mm256_slli_epi32(dy, 16), 0xAA);
                    __m256i w[2][2];
                    const __m256i in0 = insideLanes(e0, dxdy, w[0][0], w[0][1]);
                    const __m256i in1 = insideLanes(e1, dxdy, w[1][0], w[1][1]);
                    // Sign bits: a real candidate inside the first triangle, else the second (the scalar
                    // test's order).
                    const unsigned first =
                        unsigned(_mm256_movemask_ps(_mm256_castsi256_ps(_mm256_and_si256(live, in0))));
                    const unsigned second =
                        unsigned(_mm256_movemask_ps(_mm256_castsi256_ps(_mm256_and_si256(live, in1)))) &
                        ~first;
                    if (!(first | second)) continue;
                    if constexpr (!kAttributes) {
                        // The hit lanes' weights, depth and colour for all 8 lanes at once, each lane with
                        // its triangle's values (the first where inside it): shadeInsideSample's float
                        // operations in its order, so the same bits. The lanes' strata are contiguous in
                        // the stratum-ordered depth and colour: the depth test (the scalar path's: written
                        // where z < the old depth and not z < nearZ) and the writes are vector operations.
                        const HitLanes h = !second  ? hitLanesOf(m.r0, g, w[0])
                                           : !first ? hitLanesOf(m.r1, g, w[1])
                                                    : hitLanes(m, g, in0, w);
                        const __m256i covered =
                            _mm256_or_si256(_mm256_and_si256(live, in0), _mm256_and_si256(live, in1));
                        const size_t at = base + size_t(k);
                        int32_t* cov = tile.strataCovered.data() + at;
                        _mm256_storeu_si256(
                            reinterpret_cast<__m256i*>(cov),
                            _mm256_or_si256(_mm256_loadu_si256(reinterpret_cast<__m256i*>(cov)), covered));
                        const __m256 z = _mm256_load_ps(h.z);
                        float* zs = tile.strataZ.data() + at;
                        const __m256 pass =
                            _mm256_and_ps(_mm256_and_ps(_mm256_castsi256_ps(covered),
                                                        _mm256_cmp_ps(z, _mm256_loadu_ps(zs), _CMP_LT_OQ)),
                                          _mm256_cmp_ps(z, _mm256_set1_ps(nearZ), _CMP_NLT_UQ));
                        if (_mm256_movemask_ps(pass) == 0) continue;
                        writeLanes(zs, z, pass);
                        writeLanes(tile.strataR.data() + at, _mm256_load_ps(h.r), pass);
                        writeLanes(tile.strataG.data() + at, _mm256_load_ps(h.g), pass);
                        writeLanes(tile.strataB.data() + at, _mm256_load_ps(h.b), pass);
                        writeLanes(tile.strataA.data() + at, _mm256_set1_ps(1.f), pass);
                        continue;
                    }
                    alignas(32) int32_t wv[2][2][8];
                    for (int t = 0; t < 2; ++t)
                        for (int q = 0; q < 2; ++q)
                            _mm256_store_si256(reinterpret_cast<__m256i*>(wv[t][q]), w[t][q]);
                    for (unsigned mask = first | second; mask; mask &= mask - 1) {
                        const int l = __builtin_ctz(mask), t = (first >> l) & 1u ? 0 : 1;
                        const SampleTile::StrataLine column = columns[col0 + size_t(k + l)];
                        const size_t pix = size_t(rows[row].pixel + column.pixel);
                        shadeInsideSample<kAttributes>(t ? m.r1 : m.r0, g, wv[t][0][l], wv[t][1][l],
                                                       pix * spp + size_t(rows[row].slot + column.slot), pix,
                                                       tile, nearZ);
                    }
                }
            }
        }
    }
    return tests;
}

std::atomic<bool> gReyesAvx2Allowed{true};

#else
#define TESSERA_REYES_AVX2 0
#endif

template <bool kAttributes>
uint64_t rasterizeGridNearestImpl(const Grid& g, SampleTile& tile, float nearZ) {
    tile.leaveStrataOrder();
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

// rasterizeGridDepth's test of sample (sx, sy) against triangle t: insideTriangle, then the depth as
// shadeSampleIfInside interpolates it, written where nearer and not nearer than nearZ.
[[gnu::always_inline]] inline bool depthTestSample(const TriangleSetup& t, const Grid& g, int64_t sx,
                                                   int64_t sy, float& depth, float nearZ) {
    float l0, l1, l2;
    if (!t.valid || !insideTriangle(t.e, sx, sy, l0, l1, l2)) return false;
    const float z = l0 * g.Z[size_t(t.v[0])] + l1 * g.Z[size_t(t.v[1])] + l2 * g.Z[size_t(t.v[2])];
    if (z < depth && !(z < nearZ)) depth = z;
    return true;
}

constexpr int32_t kHalfTexel = 1 << (kSubpixelBits - 1);  // a texel's centre, fixed point

// The texel centres (p << 8) + 128 of `target` inside [lo, hi]: p from ceil((lo - 128) / 256) to
// floor((hi - 128) / 256).
[[gnu::always_inline]] inline int32_t firstCentreAtOrAbove(int32_t lo) {
    return (lo + kHalfTexel - 1) >> kSubpixelBits;
}
[[gnu::always_inline]] inline int32_t lastCentreAtOrBelow(int32_t hi) {
    return (hi - kHalfTexel) >> kSubpixelBits;
}

// rasterizeGridDepth for micropolygon a of grid g (corners a, a + 1, a + stride + 1, a + stride): its
// texel centres inside `target` tested and written; returns their count.
[[gnu::always_inline]] inline uint64_t depthMicropolygon(const Grid& g, int a, int stride, Rect target,
                                                         float* depth, int width, float nearZ) {
    const int b = a + 1, c = a + stride + 1, d = a + stride;
    if (!g.twoSided && !(g.front[a] | g.front[b] | g.front[c] | g.front[d])) return 0;
    const int32_t* X = g.X.data();
    const int32_t* Y = g.Y.data();
    const int32_t minX = std::min(std::min(X[a], X[b]), std::min(X[c], X[d]));
    const int32_t maxX = std::max(std::max(X[a], X[b]), std::max(X[c], X[d]));
    const int32_t minY = std::min(std::min(Y[a], Y[b]), std::min(Y[c], Y[d]));
    const int32_t maxY = std::max(std::max(Y[a], Y[b]), std::max(Y[c], Y[d]));
    // The texel centres inside the bound: a micropolygon of about a texel holds one or none.
    const int32_t cx0 = std::max(target.x0, firstCentreAtOrAbove(minX));
    const int32_t cx1 = std::min(target.x1 - 1, lastCentreAtOrBelow(maxX));
    const int32_t cy0 = std::max(target.y0, firstCentreAtOrAbove(minY));
    const int32_t cy1 = std::min(target.y1 - 1, lastCentreAtOrBelow(maxY));
    if (cx0 > cx1 || cy0 > cy1) return 0;
    // The first triangle first (a sample on the diagonal belongs to one of them); the second is set up only
    // for a centre the first does not hold.
    const TriangleSetup t0 = setupTriangle(g, a, b, c);
    TriangleSetup t1;
    bool haveT1 = false;
    for (int32_t py = cy0; py <= cy1; ++py) {
        const int64_t sy = (int64_t(py) << kSubpixelBits) + kHalfTexel;
        float* row = depth + size_t(py) * size_t(width);
        for (int32_t px = cx0; px <= cx1; ++px) {
            const int64_t sx = (int64_t(px) << kSubpixelBits) + kHalfTexel;
            if (depthTestSample(t0, g, sx, sy, row[px], nearZ)) continue;
            if (!haveT1) t1 = setupTriangle(g, a, c, d), haveT1 = true;
            depthTestSample(t1, g, sx, sy, row[px], nearZ);
        }
    }
    return uint64_t(cx1 - cx0 + 1) * uint64_t(cy1 - cy0 + 1);
}

uint64_t rasterizeGridDepthScalar(const Grid& g, Rect target, float* depth, int width, float nearZ) {
    uint64_t tests = 0;
    const int stride = g.nu + 1;
    for (int j = 0; j < g.nv; ++j)
        for (int i = 0; i < g.nu; ++i)
            tests += depthMicropolygon(g, j * stride + i, stride, target, depth, width, nearZ);
    return tests;
}

#if TESSERA_REYES_AVX2
// Triangle (0, 1, 2) of 8 micropolygons in coordinates relative to each lane's sample, for
// rasterizeGridDepthAvx2: the lanes whose sample it holds (sign bits) and its depth there, as
// setupTriangle and depthTestSample compute them (oriented counter-clockwise, the same edge integers, the
// same float operations: the same bits). Every coordinate is under 2^13 + 256 from the sample, so the
// edge functions (products under 2^27) fit 32 bits and equal the 64-bit ones.
struct DepthLanes {
    __m256i inside;
    __m256 z;
};

__attribute__((target("avx2"))) inline __m256i loadLanes(const int32_t* p) {
    return _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p));
}

// The fill-rule bias of edge (dx, dy) per lane: 0 where it owns the samples on it (fillBias), else 1.
__attribute__((target("avx2"))) inline __m256i fillBiasLanes(__m256i dx, __m256i dy) {
    const __m256i zero = _mm256_setzero_si256();
    const __m256i owns =
        _mm256_or_si256(_mm256_cmpgt_epi32(dy, zero),
                        _mm256_and_si256(_mm256_cmpeq_epi32(dy, zero), _mm256_cmpgt_epi32(zero, dx)));
    return _mm256_andnot_si256(owns, _mm256_set1_epi32(1));
}

// The edge function of edge a->b at the origin less the fill-rule bias (setupTriangleEdges' C, the value
// insideTriangle tests): (by - ay) ax - (bx - ax) ay - bias.
__attribute__((target("avx2"))) inline __m256i edgeAtOrigin(__m256i ax, __m256i ay, __m256i bx, __m256i by) {
    const __m256i dx = _mm256_sub_epi32(bx, ax), dy = _mm256_sub_epi32(by, ay);
    return _mm256_sub_epi32(_mm256_sub_epi32(_mm256_mullo_epi32(dy, ax), _mm256_mullo_epi32(dx, ay)),
                            fillBiasLanes(dx, dy));
}

__attribute__((target("avx2"))) inline DepthLanes depthLanes(__m256i x0, __m256i y0, __m256i x1, __m256i y1,
                                                             __m256i x2, __m256i y2, __m256 z0, __m256 z1,
                                                             __m256 z2) {
    __m256i area = _mm256_sub_epi32(_mm256_mullo_epi32(_mm256_sub_epi32(x1, x0), _mm256_sub_epi32(y2, y0)),
                                    _mm256_mullo_epi32(_mm256_sub_epi32(x2, x0), _mm256_sub_epi32(y1, y0)));
    const __m256i valid =
        _mm256_xor_si256(_mm256_cmpeq_epi32(area, _mm256_setzero_si256()), _mm256_set1_epi32(-1));
    // Clockwise lanes: vertices 1 and 2 swapped.
    const __m256i cw = _mm256_cmpgt_epi32(_mm256_setzero_si256(), area);
    const __m256 cwf = _mm256_castsi256_ps(cw);
    const __m256i ox1 = _mm256_blendv_epi8(x1, x2, cw), oy1 = _mm256_blendv_epi8(y1, y2, cw);
    const __m256i ox2 = _mm256_blendv_epi8(x2, x1, cw), oy2 = _mm256_blendv_epi8(y2, y1, cw);
    const __m256 oz1 = _mm256_blendv_ps(z1, z2, cwf), oz2 = _mm256_blendv_ps(z2, z1, cwf);
    area = _mm256_abs_epi32(area);
    const __m256i w0 = edgeAtOrigin(ox1, oy1, ox2, oy2);
    const __m256i w1 = edgeAtOrigin(ox2, oy2, x0, y0);
    const __m256i w2 = edgeAtOrigin(x0, y0, ox1, oy1);
    DepthLanes out;
    out.inside = _mm256_andnot_si256(_mm256_or_si256(_mm256_or_si256(w0, w1), w2), valid);
    const __m256 invArea = _mm256_div_ps(_mm256_set1_ps(1.f), _mm256_cvtepi32_ps(area));
    const __m256 l1 = _mm256_mul_ps(_mm256_cvtepi32_ps(w1), invArea);
    const __m256 l2 = _mm256_mul_ps(_mm256_cvtepi32_ps(w2), invArea);
    const __m256 l0 = _mm256_sub_ps(_mm256_sub_ps(_mm256_set1_ps(1.f), l1), l2);
    out.z =
        _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(l0, z0), _mm256_mul_ps(l1, oz1)), _mm256_mul_ps(l2, oz2));
    return out;
}

// rasterizeGridDepthScalar with 8 micropolygons of a row at a time: their bounds and texel centres, and,
// for each that holds exactly one centre and spans under 2^13 units (32 texels), its two triangles' tests
// and depths (depthLanes). The writes then go lane by lane in the scalar loop's order (the depth test keeps
// the first of equal depths), each other micropolygon through depthMicropolygon in its turn.
__attribute__((target("avx2"))) uint64_t rasterizeGridDepthAvx2(const Grid& g, Rect target, float* depth,
                                                                int width, float nearZ) {
    if (!g.twoSided) return rasterizeGridDepthScalar(g, target, depth, width, nearZ);
    uint64_t tests = 0;
    const int stride = g.nu + 1;
    const int32_t* X = g.X.data();
    const int32_t* Y = g.Y.data();
    const float* Z = g.Z.data();
    const __m256i tx0 = _mm256_set1_epi32(target.x0), tx1 = _mm256_set1_epi32(target.x1 - 1);
    const __m256i ty0 = _mm256_set1_epi32(target.y0), ty1 = _mm256_set1_epi32(target.y1 - 1);
    const __m256i belowHalf = _mm256_set1_epi32(kHalfTexel - 1), half = _mm256_set1_epi32(kHalfTexel);
    const __m256i span = _mm256_set1_epi32(int32_t(kAvx2Span)), two = _mm256_set1_epi32(2);
    for (int j = 0; j < g.nv; ++j) {
        if (g.nu < 8) {
            for (int i = 0; i < g.nu; ++i)
                tests += depthMicropolygon(g, j * stride + i, stride, target, depth, width, nearZ);
            continue;
        }
        for (int i = 0; i < g.nu; i += 8) {
            // The row's last group ends at its end (the loads stay inside the grid), its lanes that the
            // group before did left out.
            const int start = std::min(i, g.nu - 8);
            const unsigned fresh = (0xffu << (i - start)) & 0xffu;
            const int a = j * stride + start, d = a + stride;  // lane k: corners a+k, a+k+1, d+k+1, d+k
            const __m256i xa = loadLanes(X + a), xb = loadLanes(X + a + 1), xc = loadLanes(X + d + 1),
                          xd = loadLanes(X + d);
            const __m256i ya = loadLanes(Y + a), yb = loadLanes(Y + a + 1), yc = loadLanes(Y + d + 1),
                          yd = loadLanes(Y + d);
            const __m256i minX = _mm256_min_epi32(_mm256_min_epi32(xa, xb), _mm256_min_epi32(xc, xd));
            const __m256i maxX = _mm256_max_epi32(_mm256_max_epi32(xa, xb), _mm256_max_epi32(xc, xd));
            const __m256i minY = _mm256_min_epi32(_mm256_min_epi32(ya, yb), _mm256_min_epi32(yc, yd));
            const __m256i maxY = _mm256_max_epi32(_mm256_max_epi32(ya, yb), _mm256_max_epi32(yc, yd));
            const __m256i cx0 =
                _mm256_max_epi32(tx0, _mm256_srai_epi32(_mm256_add_epi32(minX, belowHalf), kSubpixelBits));
            const __m256i cx1 =
                _mm256_min_epi32(tx1, _mm256_srai_epi32(_mm256_sub_epi32(maxX, half), kSubpixelBits));
            const __m256i cy0 =
                _mm256_max_epi32(ty0, _mm256_srai_epi32(_mm256_add_epi32(minY, belowHalf), kSubpixelBits));
            const __m256i cy1 =
                _mm256_min_epi32(ty1, _mm256_srai_epi32(_mm256_sub_epi32(maxY, half), kSubpixelBits));
            const __m256i nx = _mm256_sub_epi32(cx1, cx0), ny = _mm256_sub_epi32(cy1, cy0);  // centres - 1
            const __m256i none = _mm256_or_si256(nx, ny);  // sign: no centre
            const unsigned some = ~unsigned(_mm256_movemask_ps(_mm256_castsi256_ps(none))) & fresh;
            if (!some) continue;
            // Up to 2 x 2 centres and a span under 2^13 in both directions: the vector tests, one pass per
            // centre of the 2 x 2 (the lanes that hold it).
            const __m256i small = _mm256_and_si256(_mm256_cmpgt_epi32(span, _mm256_sub_epi32(maxX, minX)),
                                                   _mm256_cmpgt_epi32(span, _mm256_sub_epi32(maxY, minY)));
            const __m256i fewX = _mm256_cmpgt_epi32(two, nx), fewY = _mm256_cmpgt_epi32(two, ny);
            const unsigned vectored = unsigned(_mm256_movemask_ps(_mm256_castsi256_ps(
                                          _mm256_and_si256(_mm256_and_si256(fewX, fewY), small)))) &
                                      some;
            alignas(32) int32_t centreX[8], centreY[8], centres[8];
            alignas(32) float zs[4][8];
            unsigned hits[4] = {0, 0, 0, 0};
            if (vectored) {
                const __m256 za = _mm256_loadu_ps(Z + a), zb = _mm256_loadu_ps(Z + a + 1);
                const __m256 zc = _mm256_loadu_ps(Z + d + 1), zd = _mm256_loadu_ps(Z + d);
                const __m256i sx0 = _mm256_add_epi32(_mm256_slli_epi32(cx0, kSubpixelBits), half);
                const __m256i sy0 = _mm256_add_epi32(_mm256_slli_epi32(cy0, kSubpixelBits), half);
                for (int q = 0; q < 4; ++q) {
                    const int qx = q & 1, qy = q >> 1;
                    const __m256i holds = _mm256_and_si256(_mm256_cmpgt_epi32(nx, _mm256_set1_epi32(qx - 1)),
                                                           _mm256_cmpgt_epi32(ny, _mm256_set1_epi32(qy - 1)));
                    const unsigned lanes =
                        unsigned(_mm256_movemask_ps(_mm256_castsi256_ps(holds))) & vectored;
                    if (!lanes) continue;
                    const __m256i sx = _mm256_add_epi32(sx0, _mm256_set1_epi32(qx << kSubpixelBits));
                    const __m256i sy = _mm256_add_epi32(sy0, _mm256_set1_epi32(qy << kSubpixelBits));
                    const __m256i ax = _mm256_sub_epi32(xa, sx), ay = _mm256_sub_epi32(ya, sy);
                    const __m256i bx = _mm256_sub_epi32(xb, sx), by = _mm256_sub_epi32(yb, sy);
                    const __m256i cx = _mm256_sub_epi32(xc, sx), cy = _mm256_sub_epi32(yc, sy);
                    const __m256i dx = _mm256_sub_epi32(xd, sx), dy = _mm256_sub_epi32(yd, sy);
                    const DepthLanes t0 = depthLanes(ax, ay, bx, by, cx, cy, za, zb, zc);
                    const DepthLanes t1 = depthLanes(ax, ay, cx, cy, dx, dy, za, zc, zd);
                    hits[q] = unsigned(_mm256_movemask_ps(
                                  _mm256_castsi256_ps(_mm256_or_si256(t0.inside, t1.inside)))) &
                              lanes;
                    _mm256_store_ps(zs[q], _mm256_blendv_ps(t1.z, t0.z, _mm256_castsi256_ps(t0.inside)));
                }
                _mm256_store_si256(reinterpret_cast<__m256i*>(centreX), cx0);
                _mm256_store_si256(reinterpret_cast<__m256i*>(centreY), cy0);
                _mm256_store_si256(reinterpret_cast<__m256i*>(centres),
                                   _mm256_mullo_epi32(_mm256_add_epi32(nx, _mm256_set1_epi32(1)),
                                                      _mm256_add_epi32(ny, _mm256_set1_epi32(1))));
            }
            for (unsigned mask = some; mask; mask &= mask - 1) {
                const int k = __builtin_ctz(mask);
                if (!((vectored >> k) & 1u)) {
                    tests += depthMicropolygon(g, a + k, stride, target, depth, width, nearZ);
                    continue;
                }
                tests += uint64_t(centres[k]);
                for (int q = 0; q < 4; ++q) {
                    if (!((hits[q] >> k) & 1u)) continue;
                    float& texel =
                        depth[size_t(centreY[k] + (q >> 1)) * size_t(width) + size_t(centreX[k] + (q & 1))];
                    const float z = zs[q][k];
                    if (z < texel && !(z < nearZ)) texel = z;
                }
            }
        }
    }
    return tests;
}
#endif

}  // namespace

uint64_t rasterizeGridDepth(const Grid& g, Rect target, float* depth, int width, float nearZ) {
#if TESSERA_REYES_AVX2
    if (reyesAvx2Active()) return rasterizeGridDepthAvx2(g, target, depth, width, nearZ);
#endif
    return rasterizeGridDepthScalar(g, target, depth, width, nearZ);
}

uint64_t rasterizeGridNearest(const Grid& g, SampleTile& tile, float nearZ) {
    return tile.channels ? rasterizeGridNearestImpl<true>(g, tile, nearZ)
                         : rasterizeGridNearestImpl<false>(g, tile, nearZ);
}

uint64_t rasterizeGrid(const Grid& g, SampleTile& tile, float nearZ) {
#if TESSERA_REYES_AVX2
    if (reyesAvx2Active())
        return tile.channels ? rasterizeGridAvx2<true>(g, tile, nearZ)
                             : rasterizeGridAvx2<false>(g, tile, nearZ);
#endif
    return tile.channels ? rasterizeGridImpl<true>(g, tile, nearZ) : rasterizeGridImpl<false>(g, tile, nearZ);
}

bool reyesAvx2Active() {
#if TESSERA_REYES_AVX2
    return cpuHasAvx2() && gReyesAvx2Allowed.load(std::memory_order_relaxed);
#else
    return false;
#endif
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
