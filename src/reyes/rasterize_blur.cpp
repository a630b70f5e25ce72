#include "reyes/rasterize_blur.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <type_traits>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__GNUC__) && defined(__x86_64__)
#include <immintrin.h>
#define TESSERA_BLUR_AVX2 1
#endif

#include "engine/motion.h"
#include "reyes/edge_functions.h"
#include "reyes/rasterize.h"

namespace tessera {
namespace {

// Raster coordinate to fixed point for moved vertices, after the same clamp as rasterToFixed. Every moved
// vertex goes through this one function, so shared vertices of neighbouring micropolygons stay bit-identical.
inline int64_t blurredToFixed(float v) {
    constexpr float kLimit = float(1 << 20) * kSubpixelScale;
    const float f = std::min(kLimit, std::max(-kLimit, v * kSubpixelScale));
    return int64_t(f + (f >= 0.f ? 0.5f : -0.5f));  // float rounding, truncating conversion: no libm call
}

// A vertex moved to time segment (k, w) and lens point `lens`: fixed-point raster position and depth.
struct MovedVertex {
    int64_t X, Y;
    float Z;
    bool valid;
};
// kLens false: the lens point is (0, 0) and the shift is skipped (x + 0 c sx is x: the same result).
template <bool kLens = true>
inline MovedVertex moveVertex(const Grid& g, size_t v, int k, float w, Vec2 lens, float sx, float sy) {
    MovedVertex m;
    float x, y, z, c = 0.f;
    if (g.knots == 1) {
        m.valid = g.knotValid[v];
        x = g.knotX[v], y = g.knotY[v], z = g.knotZ[v];
        if constexpr (kLens) c = g.knotC[v];
    } else {
        const size_t n = size_t(g.vertexCount()), a = size_t(k) * n + v, b = a + n;
        m.valid = g.knotValid[a] & g.knotValid[b];
        x = g.knotX[a] + w * (g.knotX[b] - g.knotX[a]);
        y = g.knotY[a] + w * (g.knotY[b] - g.knotY[a]);
        z = g.knotZ[a] + w * (g.knotZ[b] - g.knotZ[a]);
        if constexpr (kLens) c = g.knotC[a] + w * (g.knotC[b] - g.knotC[a]);
    }
    if constexpr (kLens) {
        m.X = blurredToFixed(x + lens.x * c * sx);
        m.Y = blurredToFixed(y + lens.y * c * sy);
    } else {
        m.X = blurredToFixed(x), m.Y = blurredToFixed(y);
    }
    m.Z = z;
    return m;
}

// A micropolygon's corners moved to one (time, lens point), in fixed point, with their depths.
struct MovedQuad {
    int32_t X[4], Y[4];  // within blurredToFixed's clamp of +-2^20 pixels, i.e. +-2^28
    float Z[4];
    int64_t minX, maxX, minY, maxY;
    bool valid;
};

inline void finishQuad(MovedQuad& q) {
    q.minX = std::min({q.X[0], q.X[1], q.X[2], q.X[3]}), q.maxX = std::max({q.X[0], q.X[1], q.X[2], q.X[3]});
    q.minY = std::min({q.Y[0], q.Y[1], q.Y[2], q.Y[3]}), q.maxY = std::max({q.Y[0], q.Y[1], q.Y[2], q.Y[3]});
}

// A micropolygon's corners over one timeline segment k, read once for all its samples of that segment:
// position, depth and lens coefficient at knot k and their change to knot k + 1 (0 for a grid of one
// knot). moveQuad computes from them exactly what moveVertex computes (a + w (b - a), the same float
// operations), so corners shared with a neighbour stay bit-identical.
struct CornerSegment {
    float x[4], dx[4], y[4], dy[4], z[4], dz[4], c[4], dc[4];
    bool valid;
    int k = -1;  // the segment held (-1: none yet)
};
inline void loadCorners(const Grid& g, const int vid[4], int k, CornerSegment& s) {
    s.k = k;
    s.valid = true;
    const size_t n = size_t(g.vertexCount());
    for (int c = 0; c < 4; ++c) {
        if (g.knots == 1) {
            const size_t v = size_t(vid[c]);
            s.valid &= bool(g.knotValid[v]);
            s.x[c] = g.knotX[v], s.y[c] = g.knotY[v], s.z[c] = g.knotZ[v], s.c[c] = g.knotC[v];
            s.dx[c] = s.dy[c] = s.dz[c] = s.dc[c] = 0.f;
            continue;
        }
        const size_t a = size_t(k) * n + size_t(vid[c]), b = a + n;
        s.valid &= bool(g.knotValid[a] & g.knotValid[b]);
        s.x[c] = g.knotX[a], s.dx[c] = g.knotX[b] - g.knotX[a];
        s.y[c] = g.knotY[a], s.dy[c] = g.knotY[b] - g.knotY[a];
        s.z[c] = g.knotZ[a], s.dz[c] = g.knotZ[b] - g.knotZ[a];
        s.c[c] = g.knotC[a], s.dc[c] = g.knotC[b] - g.knotC[a];
    }
}

template <bool kLens = true>
inline MovedQuad moveQuad(const CornerSegment& s, float w, Vec2 lens, const Projector& pr) {
    MovedQuad q;
    q.valid = s.valid;
#if defined(__SSE2__)
    // The four corners at once, lane by lane the scalar operations below (and moveVertex's): the same
    // products and sums in the same order, the clamp of blurredToFixed as max then min (a NaN clamps to
    // -limit in both), and its rounding offset of +-0.5 from the sign (for -0 both give 0).
    const __m128 w4 = _mm_set1_ps(w);
    __m128 x = _mm_add_ps(_mm_loadu_ps(s.x), _mm_mul_ps(w4, _mm_loadu_ps(s.dx)));
    __m128 y = _mm_add_ps(_mm_loadu_ps(s.y), _mm_mul_ps(w4, _mm_loadu_ps(s.dy)));
    if constexpr (kLens) {
        const __m128 cc = _mm_add_ps(_mm_loadu_ps(s.c), _mm_mul_ps(w4, _mm_loadu_ps(s.dc)));
        x = _mm_add_ps(x, _mm_mul_ps(_mm_mul_ps(_mm_set1_ps(lens.x), cc), _mm_set1_ps(pr.sx)));
        y = _mm_add_ps(y, _mm_mul_ps(_mm_mul_ps(_mm_set1_ps(lens.y), cc), _mm_set1_ps(pr.sy)));
    }
    const __m128 limit = _mm_set1_ps(float(1 << 20) * kSubpixelScale), scale = _mm_set1_ps(kSubpixelScale);
    const __m128 half = _mm_set1_ps(0.5f), sign = _mm_set1_ps(-0.f);
    auto toFixed = [&](__m128 v) {
        const __m128 f =
            _mm_min_ps(_mm_max_ps(_mm_mul_ps(v, scale), _mm_sub_ps(_mm_setzero_ps(), limit)), limit);
        return _mm_cvttps_epi32(_mm_add_ps(f, _mm_or_ps(half, _mm_and_ps(f, sign))));
    };
    _mm_storeu_si128(reinterpret_cast<__m128i*>(q.X), toFixed(x));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(q.Y), toFixed(y));
    _mm_storeu_ps(q.Z, _mm_add_ps(_mm_loadu_ps(s.z), _mm_mul_ps(w4, _mm_loadu_ps(s.dz))));
#else
    for (int c = 0; c < 4; ++c) {
        const float x = s.x[c] + w * s.dx[c], y = s.y[c] + w * s.dy[c];
        if constexpr (kLens) {
            const float cc = s.c[c] + w * s.dc[c];
            q.X[c] = blurredToFixed(x + lens.x * cc * pr.sx);
            q.Y[c] = blurredToFixed(y + lens.y * cc * pr.sy);
        } else {
            q.X[c] = blurredToFixed(x), q.Y[c] = blurredToFixed(y);
        }
        q.Z[c] = s.z[c] + w * s.dz[c];
    }
#endif
    return q;  // without its box (finishQuad): the bbox scheme's sample passed the bound at its (t, lens)
}

// Signed doubled area of corners (0, 1, 2) of a moved quad.
inline int64_t signedArea(const MovedQuad& q) {
    const int64_t X0 = q.X[0], Y0 = q.Y[0];
    return (q.X[1] - X0) * (q.Y[2] - Y0) - (q.X[2] - X0) * (q.Y[1] - Y0);
}

// The moved quad's triangles (0,1,2) and (0,2,3).
constexpr int kQuadTriangles[2][3] = {{0, 1, 2}, {0, 2, 3}};
inline TriangleEdges quadTriangle(const MovedQuad& q, int tri) {
    const int* c = kQuadTriangles[tri];
    return setupTriangleEdges(q.X[c[0]], q.Y[c[0]], q.X[c[1]], q.Y[c[1]], q.X[c[2]], q.Y[c[2]]);
}

// Both triangles set up once, for the passes of the simple and interleaved schemes in which many samples
// meet the same moved quad.
struct QuadSetup {
    TriangleEdges tri[2];
};
inline QuadSetup setupQuad(const MovedQuad& q) {
    return {{quadTriangle(q, 0), quadTriangle(q, 1)}};
}

// A sample inside triangle tri of a moved quad, with weights l1, l2 of its corners 1 and 2 (in the
// corners' order): the depth of the moved corners, and the write when it is nearer than the sample's.
template <bool kAttributes>
inline void writeMovedHit(const Grid& g, const int vid[4], const MovedQuad& q, int tri, float l1, float l2,
                          size_t i, SampleTile& tile, float nearZ) {
    const float l0 = 1.f - l1 - l2;
    const int* c = kQuadTriangles[tri];
    const float z = l0 * q.Z[c[0]] + l1 * q.Z[c[1]] + l2 * q.Z[c[2]];
    if (z < tile.z[i] && z >= nearZ)
        writeSampleHit<kAttributes>(g, vid[c[0]], vid[c[1]], vid[c[2]], l0, l1, l2, z, i, tile);
}

// Test sample i against a moved quad whose triangles are set up once (QuadSetup: the simple and
// interleaved passes, where many samples meet the same moved quad) with the sharp rasterizer's edge
// functions (edge_functions.h).
template <bool kAttributes>
inline bool testMovedSample(const Grid& g, const int vid[4], const MovedQuad& q, size_t i, SampleTile& tile,
                            float nearZ, const QuadSetup& setup) {
    const int64_t sx = tile.sx[i], sy = tile.sy[i];
    if (sx < q.minX || sx > q.maxX || sy < q.minY || sy > q.maxY) return false;
    for (int tri = 0; tri < 2; ++tri) {
        const TriangleEdges& t = setup.tri[tri];
        float l0, l1, l2;
        if (!t.valid || !insideTriangle(t, sx, sy, l0, l1, l2)) continue;
        if (t.swapped) std::swap(l1, l2);  // back to the corners' order
        writeMovedHit<kAttributes>(g, vid, q, tri, l1, l2, i, tile, nearZ);
        return true;
    }
    return false;
}

// testMovedSample for a quad met by one sample (the bbox scheme): the same integer edge functions,
// fill rule and weights as setupTriangleEdges + insideTriangle (so the same hits, bit for bit), evaluated
// directly at the sample, edge by edge, with the weights' division only for a hit. No box test first:
// the sample passed the quad's bound at its (t, lens), and one outside the box fails an edge anyway.
template <bool kAttributes>
inline bool testMovedSampleOnce(const Grid& g, const int vid[4], const MovedQuad& q, size_t i,
                                SampleTile& tile, float nearZ) {
    const int64_t sx = tile.sx[i], sy = tile.sy[i];
    auto edge = [sx, sy](int64_t xa, int64_t ya, int64_t xb, int64_t yb) {
        return (xb - xa) * (sy - ya) - (yb - ya) * (sx - xa) - fillBias(xa, ya, xb, yb);
    };
    for (int tri = 0; tri < 2; ++tri) {
        const int* c = kQuadTriangles[tri];
        const int64_t x0 = q.X[c[0]], y0 = q.Y[c[0]];
        int64_t x1 = q.X[c[1]], y1 = q.Y[c[1]], x2 = q.X[c[2]], y2 = q.Y[c[2]];
        int64_t area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
        if (area == 0) continue;
        const bool swapped = area < 0;
        if (swapped) {  // counter-clockwise, as setupTriangleEdges orients it
            std::swap(x1, x2), std::swap(y1, y2);
            area = -area;
        }
        const int64_t w0 = edge(x1, y1, x2, y2);
        if (w0 < 0) continue;
        const int64_t w1 = edge(x2, y2, x0, y0);
        if (w1 < 0) continue;
        const int64_t w2 = edge(x0, y0, x1, y1);
        if (w2 < 0) continue;
        const float invArea = 1.f / float(area);
        float l1 = float(w1) * invArea, l2 = float(w2) * invArea;
        if (swapped) std::swap(l1, l2);  // back to the corners' order
        writeMovedHit<kAttributes>(g, vid, q, tri, l1, l2, i, tile, nearZ);
        return true;
    }
    return false;
}

// One-sided culling of a moved micropolygon: it is drawn when it faces the camera at the sample's time.
// At shutter open `front0` says whether it faces the camera with raster area sign `sign0`; when the sign
// flips it has turned over.
inline bool facesCamera(bool twoSided, bool front0, int64_t sign0, const MovedQuad& q) {
    if (twoSided) return true;
    const int64_t s = signedArea(q);
    const bool same = (s > 0) == (sign0 > 0);
    return front0 ? same : !same;
}

struct Span {
    int px0, px1, py0, py1;  // inclusive pixel range inside the tile region
    bool empty() const { return px0 > px1 || py0 > py1; }
};
inline Span pixelSpan(const Rect& reg, int64_t minX, int64_t maxX, int64_t minY, int64_t maxY) {
    Span s;
    s.px0 = int(std::max<int64_t>(reg.x0, minX >> kSubpixelBits));
    s.px1 = int(std::min<int64_t>(reg.x1 - 1, maxX >> kSubpixelBits));
    s.py0 = int(std::max<int64_t>(reg.y0, minY >> kSubpixelBits));
    s.py1 = int(std::min<int64_t>(reg.y1 - 1, maxY >> kSubpixelBits));
    return s;
}

// Facing at shutter open of a micropolygon (one-sided culling, see facesCamera).
inline void openFacing(const Grid& g, const int vid[4], bool& front0, int64_t& sign0) {
    front0 = g.front[vid[0]] | g.front[vid[1]] | g.front[vid[2]] | g.front[vid[3]];
    sign0 = 1;
    if (!g.twoSided) {
        const int64_t X0 = g.X[vid[0]], Y0 = g.Y[vid[0]];
        sign0 = (g.X[vid[1]] - X0) * (g.Y[vid[2]] - Y0) - (g.X[vid[2]] - X0) * (g.Y[vid[1]] - Y0);
        if (sign0 == 0) sign0 = 1;
    }
}

// A micropolygon's raster box and lens-coefficient range at one knot. Between two knots every corner
// moves linearly, and the minimum of linear functions is concave (the maximum convex), so the box at
// time t lies inside the linear interpolation of the two knot boxes: bounds at any time need no
// per-corner work.
struct KnotBox {
    float x0, x1, y0, y1, c0, c1;
};
inline KnotBox lerpBox(const KnotBox& p, const KnotBox& q, float w) {
    return KnotBox{p.x0 + w * (q.x0 - p.x0), p.x1 + w * (q.x1 - p.x1), p.y0 + w * (q.y0 - p.y0),
                   p.y1 + w * (q.y1 - p.y1), p.c0 + w * (q.c0 - p.c0), p.c1 + w * (q.c1 - p.c1)};
}
inline KnotBox unionBox(const KnotBox& a, const KnotBox& b) {
    return KnotBox{std::min(a.x0, b.x0), std::max(a.x1, b.x1), std::min(a.y0, b.y0),
                   std::max(a.y1, b.y1), std::min(a.c0, b.c0), std::max(a.c1, b.c1)};
}
constexpr KnotBox kEmptyBox{INFINITY, -INFINITY, INFINITY, -INFINITY, INFINITY, -INFINITY};

// Slack of the float bounds, in pixels: the moved corners are rounded to 1/256 pixel, and the
// interpolated box and the interpolated corners round differently (about 1e-4 pixel at 1e3 pixels).
constexpr float kBoundSlack = 3.f / kSubpixelScale;

// floor() for the bounds' pixel spans, without the libm call that std::floor is on baseline x86-64
// (no SSE4.1 round instruction). Bounds lie within the 2^20-pixel clamp of blurredToFixed.
inline int floorToInt(float v) {
    const int i = int(v);
    return i - (float(i) > v);
}

// Edge e of `cells` lens cells along an axis: -1 + 2 e / cells (the same values, without the division for
// the one or two cells used).
inline float lensCellEdge(int e, int cells) {
    return cells == 2 ? float(e - 1) : cells == 1 ? float(2 * e - 1) : -1.f + 2.f * float(e) / float(cells);
}

// Lens cell `cell` of `cells` along one axis spans l in [-1 + 2 cell / cells, -1 + 2 (cell + 1) / cells].
// When l keeps one sign there, min over c in [a, b] of l c is l * lo and the max is l * hi for every l of
// the cell; returns false for a cell that straddles l = 0. (Samples lie in their cell up to float rounding
// of about 1e-7, far inside kBoundSlack.)
inline bool shiftFactors(int cell, int cells, float a, float b, float& lo, float& hi) {
    const float l0 = lensCellEdge(cell, cells), l1 = lensCellEdge(cell + 1, cells);
    if (l0 >= 0.f) {
        lo = std::min(a, b), hi = std::max(a, b);
        return true;
    }
    if (l1 <= 0.f) {
        lo = std::max(a, b), hi = std::min(a, b);
        return true;
    }
    lo = hi = 0.f;
    return false;
}

#if defined(__SSE2__)
// The lanes of entries e .. e + 3 that `out` does not mark (and that lie before end), in order: hit(entry).
template <class Hit>
inline void forEachInside(__m128 out, uint32_t e, uint32_t end, Hit& hit) {
    unsigned in = ~unsigned(_mm_movemask_ps(out)) & 15u;
    if (!in) return;  // the common case: all four outside (the tail's mask only matters for a hit)
    if (end - e < 4) in &= (1u << (end - e)) - 1u;
    for (; in; in &= in - 1) hit(e + uint32_t(__builtin_ctz(in)));
}
#endif

// Candidate samples in structure-of-arrays form, read four at a time: BlurStrata's entries, or the
// candidates a block of micropolygons gathered (BlockCandidates). Padded with kRunPadding entries past the
// last, so the filters' reads past a run's end stay inside (those lanes are masked off).
struct CandidateView {
    const float *fx, *fy, *time, *lensX, *lensY;
    const uint32_t* sample;
};
inline CandidateView viewOf(const BlurStrata& s) {
    return {s.fx.data(), s.fy.data(), s.time.data(), s.lensX.data(), s.lensY.data(), s.sample.data()};
}

// The bound of a still micropolygon (depth of field only) over one lens cell whose l.x and l.y keep one
// sign (shiftFactors): at lens point l it is [x0 + l.x loX, x1 + l.x hiX] x [y0 + l.y loY, y1 + l.y hiY].
struct StillLensBound {
    float x0, x1, y0, y1, loX, hiX, loY, hiY;
};

// Calls hit(e) for each entry e of [first, end) of the strata whose position lies in `b` at its own lens
// point, in order. Most entries fail (the bound over a lens cell is the micropolygon grown by the cell's
// share of its circle of confusion, the bound at one lens point is the micropolygon), so the test runs four
// entries at a time; it is the scalar test's float operations lane by lane (the same products and sums),
// so the same entries pass.
template <class Hit>
inline void filterStillLens(const CandidateView& s, uint32_t first, uint32_t end, const StillLensBound& b,
                            Hit&& hit) {
#if defined(__SSE2__)
    const __m128 x0 = _mm_set1_ps(b.x0), x1 = _mm_set1_ps(b.x1), y0 = _mm_set1_ps(b.y0),
                 y1 = _mm_set1_ps(b.y1), loX = _mm_set1_ps(b.loX), hiX = _mm_set1_ps(b.hiX),
                 loY = _mm_set1_ps(b.loY), hiY = _mm_set1_ps(b.hiY);
    for (uint32_t e = first; e < end; e += 4) {  // reads up to 3 entries past end: the padding
        const __m128 lx = _mm_loadu_ps(&s.lensX[e]), ly = _mm_loadu_ps(&s.lensY[e]);
        const __m128 fx = _mm_loadu_ps(&s.fx[e]), fy = _mm_loadu_ps(&s.fy[e]);
        __m128 out = _mm_or_ps(_mm_cmplt_ps(fx, _mm_add_ps(x0, _mm_mul_ps(lx, loX))),
                               _mm_cmpgt_ps(fx, _mm_add_ps(x1, _mm_mul_ps(lx, hiX))));
        out = _mm_or_ps(out, _mm_or_ps(_mm_cmplt_ps(fy, _mm_add_ps(y0, _mm_mul_ps(ly, loY))),
                                       _mm_cmpgt_ps(fy, _mm_add_ps(y1, _mm_mul_ps(ly, hiY)))));
        forEachInside(out, e, end, hit);
    }
#else
    for (uint32_t e = first; e < end; ++e) {
        const float lx = s.lensX[e], ly = s.lensY[e], fx = s.fx[e], fy = s.fy[e];
        if (fx < b.x0 + lx * b.loX || fx > b.x1 + lx * b.hiX || fy < b.y0 + ly * b.loY ||
            fy > b.y1 + ly * b.hiY)
            continue;
        hit(e);
    }
#endif
}

// The bound of a still micropolygon at any lens point l (depth of field only): its box grown by the least
// and the greatest of l.x c0 sx and l.x c1 sx (likewise for y), [c0, c1] its lens coefficients. One bound
// for every lens cell (the block path's per-micropolygon filter, over candidates of all cells).
struct StillBound {
    float x0, x1, y0, y1, ax, bx, ay, by;  // ax = c0 sx, bx = c1 sx, ay = c0 sy, by = c1 sy
};

// Calls hit(e) for each entry e of [first, end) whose position lies in `b` at its own lens point, in order;
// four entries at a time as filterStillLens.
template <class Hit>
inline void filterStill(const CandidateView& s, uint32_t first, uint32_t end, const StillBound& b,
                        Hit&& hit) {
#if defined(__SSE2__)
    const __m128 x0 = _mm_set1_ps(b.x0), x1 = _mm_set1_ps(b.x1), y0 = _mm_set1_ps(b.y0),
                 y1 = _mm_set1_ps(b.y1), ax = _mm_set1_ps(b.ax), bx = _mm_set1_ps(b.bx),
                 ay = _mm_set1_ps(b.ay), by = _mm_set1_ps(b.by);
    for (uint32_t e = first; e < end; e += 4) {  // reads up to 3 entries past end: the padding
        const __m128 lx = _mm_loadu_ps(&s.lensX[e]), ly = _mm_loadu_ps(&s.lensY[e]);
        const __m128 fx = _mm_loadu_ps(&s.fx[e]), fy = _mm_loadu_ps(&s.fy[e]);
        const __m128 xa = _mm_mul_ps(lx, ax), xb = _mm_mul_ps(lx, bx), ya = _mm_mul_ps(ly, ay),
                     yb = _mm_mul_ps(ly, by);
        __m128 out = _mm_or_ps(_mm_cmplt_ps(fx, _mm_add_ps(x0, _mm_min_ps(xa, xb))),
                               _mm_cmpgt_ps(fx, _mm_add_ps(x1, _mm_max_ps(xa, xb))));
        out = _mm_or_ps(out, _mm_or_ps(_mm_cmplt_ps(fy, _mm_add_ps(y0, _mm_min_ps(ya, yb))),
                                       _mm_cmpgt_ps(fy, _mm_add_ps(y1, _mm_max_ps(ya, yb)))));
        forEachInside(out, e, end, hit);
    }
#else
    for (uint32_t e = first; e < end; ++e) {
        const float lx = s.lensX[e], ly = s.lensY[e], fx = s.fx[e], fy = s.fy[e];
        const float xa = lx * b.ax, xb = lx * b.bx, ya = ly * b.ay, yb = ly * b.by;
        if (fx < b.x0 + std::min(xa, xb) || fx > b.x1 + std::max(xa, xb) || fy < b.y0 + std::min(ya, yb) ||
            fy > b.y1 + std::max(ya, yb))
            continue;
        hit(e);
    }
#endif
}

// The bound of a micropolygon over one segment of the knot timeline: its box at the segment's knots p and
// q (equal for a grid that does not move), lerped at w = (t - t0) invDt, then grown by the lens point
// times the lerped lens-coefficient range (inBoundAt's bound, for a sample of that segment).
struct SegmentBound {
    KnotBox p, q;
    float t0, invDt, sx, sy;
};

// Calls hit(e) for each entry e of [first, end) whose position lies in `b` at its own time (and, with
// kLens, lens point), in order; four entries at a time as filterStillLens. The time -> w map may differ
// from timelineSegment's in the last bit, and a sample at a knot may be lerped a rounding past the
// segment's end: both far inside kBoundSlack.
template <bool kLens, class Hit>
inline void filterSegment(const CandidateView& s, uint32_t first, uint32_t end, const SegmentBound& b,
                          Hit&& hit) {
#if defined(__SSE2__)
    const __m128 slack = _mm_set1_ps(kBoundSlack), t0 = _mm_set1_ps(b.t0), invDt = _mm_set1_ps(b.invDt);
    const __m128 px0 = _mm_set1_ps(b.p.x0), dx0 = _mm_set1_ps(b.q.x0 - b.p.x0);
    const __m128 px1 = _mm_set1_ps(b.p.x1), dx1 = _mm_set1_ps(b.q.x1 - b.p.x1);
    const __m128 py0 = _mm_set1_ps(b.p.y0), dy0 = _mm_set1_ps(b.q.y0 - b.p.y0);
    const __m128 py1 = _mm_set1_ps(b.p.y1), dy1 = _mm_set1_ps(b.q.y1 - b.p.y1);
    const __m128 pc0 = _mm_set1_ps(b.p.c0), dc0 = _mm_set1_ps(b.q.c0 - b.p.c0);
    const __m128 pc1 = _mm_set1_ps(b.p.c1), dc1 = _mm_set1_ps(b.q.c1 - b.p.c1);
    const __m128 sx = _mm_set1_ps(b.sx), sy = _mm_set1_ps(b.sy);
    for (uint32_t e = first; e < end; e += 4) {  // reads up to 3 entries past end: the padding
        const __m128 w = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(&s.time[e]), t0), invDt);
        __m128 x0 = _mm_sub_ps(_mm_add_ps(px0, _mm_mul_ps(w, dx0)), slack);
        __m128 x1 = _mm_add_ps(_mm_add_ps(px1, _mm_mul_ps(w, dx1)), slack);
        __m128 y0 = _mm_sub_ps(_mm_add_ps(py0, _mm_mul_ps(w, dy0)), slack);
        __m128 y1 = _mm_add_ps(_mm_add_ps(py1, _mm_mul_ps(w, dy1)), slack);
        if constexpr (kLens) {
            const __m128 c0 = _mm_add_ps(pc0, _mm_mul_ps(w, dc0)), c1 = _mm_add_ps(pc1, _mm_mul_ps(w, dc1));
            const __m128 ax = _mm_mul_ps(_mm_loadu_ps(&s.lensX[e]), sx);
            const __m128 ay = _mm_mul_ps(_mm_loadu_ps(&s.lensY[e]), sy);
            const __m128 xa = _mm_mul_ps(ax, c0), xb = _mm_mul_ps(ax, c1);
            const __m128 ya = _mm_mul_ps(ay, c0), yb = _mm_mul_ps(ay, c1);
            x0 = _mm_add_ps(x0, _mm_min_ps(xa, xb)), x1 = _mm_add_ps(x1, _mm_max_ps(xa, xb));
            y0 = _mm_add_ps(y0, _mm_min_ps(ya, yb)), y1 = _mm_add_ps(y1, _mm_max_ps(ya, yb));
        }
        const __m128 fx = _mm_loadu_ps(&s.fx[e]), fy = _mm_loadu_ps(&s.fy[e]);
        const __m128 out = _mm_or_ps(_mm_or_ps(_mm_cmplt_ps(fx, x0), _mm_cmpgt_ps(fx, x1)),
                                     _mm_or_ps(_mm_cmplt_ps(fy, y0), _mm_cmpgt_ps(fy, y1)));
        forEachInside(out, e, end, hit);
    }
#else
    for (uint32_t e = first; e < end; ++e) {
        const float w = (s.time[e] - b.t0) * b.invDt;
        float x0 = b.p.x0 + w * (b.q.x0 - b.p.x0) - kBoundSlack,
              x1 = b.p.x1 + w * (b.q.x1 - b.p.x1) + kBoundSlack;
        float y0 = b.p.y0 + w * (b.q.y0 - b.p.y0) - kBoundSlack,
              y1 = b.p.y1 + w * (b.q.y1 - b.p.y1) + kBoundSlack;
        if constexpr (kLens) {
            const float c0 = b.p.c0 + w * (b.q.c0 - b.p.c0), c1 = b.p.c1 + w * (b.q.c1 - b.p.c1);
            const float ax = s.lensX[e] * b.sx, ay = s.lensY[e] * b.sy;
            x0 += std::min(ax * c0, ax * c1), x1 += std::max(ax * c0, ax * c1);
            y0 += std::min(ay * c0, ay * c1), y1 += std::max(ay * c0, ay * c1);
        }
        if (s.fx[e] < x0 || s.fx[e] > x1 || s.fy[e] < y0 || s.fy[e] > y1) continue;
        hit(e);
    }
#endif
}

#if TESSERA_BLUR_AVX2
// The candidate filters eight entries at a time (AVX2, compiled for it by a target attribute and run when
// reyesAvx2Active): the same float operations lane by lane as the four-wide and scalar filters (no fused
// multiply-add: the target leaves FMA off), so the same entries pass. Instead of a branch per group with a
// hit (taken for about a third of the groups, so mispredicted often), each group's passing entries are
// written to a sink in order, branch-free: the lanes of the group's mask come from kLaneLists (four bits
// per lane) and the count advances by the mask's population. A sink needs room for end - first + 8.
constexpr std::array<uint32_t, 256> makeLaneLists() {
    std::array<uint32_t, 256> t{};
    for (uint32_t m = 0; m < 256; ++m) {
        uint32_t packed = 0, n = 0;
        for (uint32_t lane = 0; lane < 8; ++lane)
            if (m & (1u << lane)) packed |= lane << (4 * n++);
        t[m] = packed;
    }
    return t;
}
inline constexpr std::array<uint32_t, 256> kLaneLists = makeLaneLists();

// Where the AVX2 filters put the entries that pass: their indices (IndexSink), or, for a block gathering its
// candidates, the entries themselves (CopySink: each array's passing lanes permuted to the front). Both
// write eight lanes per group, so they need room for eight past the last entry.
struct IndexSink {
    uint32_t* index;
};
struct CopySink {
    float *fx, *fy, *time, *lensX, *lensY;
    uint32_t* sample;
};

__attribute__((target("avx2"))) inline void packLanes(const float* from, float* to, __m256i lanes) {
    _mm256_storeu_ps(to, _mm256_permutevar8x32_ps(_mm256_loadu_ps(from), lanes));
}

// The passing lanes of entries e .. e + 7 (those `out` does not mark, before end) written at position n of
// the sink, in order; returns how many.
template <class Sink>
__attribute__((target("avx2,popcnt"))) inline uint32_t compactLanes(__m256 out, uint32_t e, uint32_t end,
                                                                    const CandidateView& s, const Sink& sink,
                                                                    uint32_t n) {
    const uint32_t left = std::min(end - e, 8u);
    const unsigned in = ~unsigned(_mm256_movemask_ps(out)) & ((1u << left) - 1u);
    const __m256i lanes = _mm256_and_si256(_mm256_srlv_epi32(_mm256_set1_epi32(int(kLaneLists[in])),
                                                             _mm256_setr_epi32(0, 4, 8, 12, 16, 20, 24, 28)),
                                           _mm256_set1_epi32(15));
    if constexpr (std::is_same_v<Sink, IndexSink>) {
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(sink.index + n),
                            _mm256_add_epi32(_mm256_set1_epi32(int(e)), lanes));
    } else {
        packLanes(s.fx + e, sink.fx + n, lanes), packLanes(s.fy + e, sink.fy + n, lanes);
        packLanes(s.time + e, sink.time + n, lanes);
        packLanes(s.lensX + e, sink.lensX + n, lanes), packLanes(s.lensY + e, sink.lensY + n, lanes);
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(sink.sample + n),
                            _mm256_permutevar8x32_epi32(
                                _mm256_loadu_si256(reinterpret_cast<const __m256i*>(s.sample + e)), lanes));
    }
    return uint32_t(__builtin_popcount(in));
}

// The lanes whose point (fx, fy) lies outside [x0, x1] x [y0, y1] (the filters' last step).
__attribute__((target("avx2"))) inline __m256 outsideBox8(__m256 fx, __m256 fy, __m256 x0, __m256 x1,
                                                          __m256 y0, __m256 y1) {
    return _mm256_or_ps(_mm256_or_ps(_mm256_cmp_ps(fx, x0, _CMP_LT_OQ), _mm256_cmp_ps(fx, x1, _CMP_GT_OQ)),
                        _mm256_or_ps(_mm256_cmp_ps(fy, y0, _CMP_LT_OQ), _mm256_cmp_ps(fy, y1, _CMP_GT_OQ)));
}

// filterStillLens, eight at a time: the passing entries of [first, end) into the sink; returns their count.
template <class Sink>
__attribute__((target("avx2,popcnt"))) uint32_t filterStillLensAvx2(const CandidateView& s, uint32_t first,
                                                                    uint32_t end, const StillLensBound& b,
                                                                    const Sink& sink) {
    const __m256 x0 = _mm256_set1_ps(b.x0), x1 = _mm256_set1_ps(b.x1), y0 = _mm256_set1_ps(b.y0),
                 y1 = _mm256_set1_ps(b.y1), loX = _mm256_set1_ps(b.loX), hiX = _mm256_set1_ps(b.hiX),
                 loY = _mm256_set1_ps(b.loY), hiY = _mm256_set1_ps(b.hiY);
    uint32_t n = 0;
    for (uint32_t e = first; e < end; e += 8) {  // reads up to 7 entries past end: the padding
        const __m256 lx = _mm256_loadu_ps(&s.lensX[e]), ly = _mm256_loadu_ps(&s.lensY[e]);
        const __m256 fx = _mm256_loadu_ps(&s.fx[e]), fy = _mm256_loadu_ps(&s.fy[e]);
        const __m256 out8 = outsideBox8(
            fx, fy, _mm256_add_ps(x0, _mm256_mul_ps(lx, loX)), _mm256_add_ps(x1, _mm256_mul_ps(lx, hiX)),
            _mm256_add_ps(y0, _mm256_mul_ps(ly, loY)), _mm256_add_ps(y1, _mm256_mul_ps(ly, hiY)));
        n += compactLanes(out8, e, end, s, sink, n);
    }
    return n;
}

// filterStill, eight at a time, as filterStillLensAvx2.
template <class Sink>
__attribute__((target("avx2,popcnt"))) uint32_t filterStillAvx2(const CandidateView& s, uint32_t first,
                                                                uint32_t end, const StillBound& b,
                                                                const Sink& sink) {
    const __m256 x0 = _mm256_set1_ps(b.x0), x1 = _mm256_set1_ps(b.x1), y0 = _mm256_set1_ps(b.y0),
                 y1 = _mm256_set1_ps(b.y1), ax = _mm256_set1_ps(b.ax), bx = _mm256_set1_ps(b.bx),
                 ay = _mm256_set1_ps(b.ay), by = _mm256_set1_ps(b.by);
    uint32_t n = 0;
    for (uint32_t e = first; e < end; e += 8) {  // reads up to 7 entries past end: the padding
        const __m256 lx = _mm256_loadu_ps(&s.lensX[e]), ly = _mm256_loadu_ps(&s.lensY[e]);
        const __m256 fx = _mm256_loadu_ps(&s.fx[e]), fy = _mm256_loadu_ps(&s.fy[e]);
        const __m256 xa = _mm256_mul_ps(lx, ax), xb = _mm256_mul_ps(lx, bx), ya = _mm256_mul_ps(ly, ay),
                     yb = _mm256_mul_ps(ly, by);
        const __m256 out8 = outsideBox8(
            fx, fy, _mm256_add_ps(x0, _mm256_min_ps(xa, xb)), _mm256_add_ps(x1, _mm256_max_ps(xa, xb)),
            _mm256_add_ps(y0, _mm256_min_ps(ya, yb)), _mm256_add_ps(y1, _mm256_max_ps(ya, yb)));
        n += compactLanes(out8, e, end, s, sink, n);
    }
    return n;
}

// filterSegment, eight at a time, as filterStillLensAvx2.
template <bool kLens, class Sink>
__attribute__((target("avx2,popcnt"))) uint32_t filterSegmentAvx2(const CandidateView& s, uint32_t first,
                                                                  uint32_t end, const SegmentBound& b,
                                                                  const Sink& sink) {
    const __m256 slack = _mm256_set1_ps(kBoundSlack), t0 = _mm256_set1_ps(b.t0),
                 invDt = _mm256_set1_ps(b.invDt);
    const __m256 px0 = _mm256_set1_ps(b.p.x0), dx0 = _mm256_set1_ps(b.q.x0 - b.p.x0);
    const __m256 px1 = _mm256_set1_ps(b.p.x1), dx1 = _mm256_set1_ps(b.q.x1 - b.p.x1);
    const __m256 py0 = _mm256_set1_ps(b.p.y0), dy0 = _mm256_set1_ps(b.q.y0 - b.p.y0);
    const __m256 py1 = _mm256_set1_ps(b.p.y1), dy1 = _mm256_set1_ps(b.q.y1 - b.p.y1);
    const __m256 pc0 = _mm256_set1_ps(b.p.c0), dc0 = _mm256_set1_ps(b.q.c0 - b.p.c0);
    const __m256 pc1 = _mm256_set1_ps(b.p.c1), dc1 = _mm256_set1_ps(b.q.c1 - b.p.c1);
    const __m256 sx = _mm256_set1_ps(b.sx), sy = _mm256_set1_ps(b.sy);
    uint32_t n = 0;
    for (uint32_t e = first; e < end; e += 8) {  // reads up to 7 entries past end: the padding
        const __m256 w = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(&s.time[e]), t0), invDt);
        __m256 x0 = _mm256_sub_ps(_mm256_add_ps(px0, _mm256_mul_ps(w, dx0)), slack);
        __m256 x1 = _mm256_add_ps(_mm256_add_ps(px1, _mm256_mul_ps(w, dx1)), slack);
        __m256 y0 = _mm256_sub_ps(_mm256_add_ps(py0, _mm256_mul_ps(w, dy0)), slack);
        __m256 y1 = _mm256_add_ps(_mm256_add_ps(py1, _mm256_mul_ps(w, dy1)), slack);
        if constexpr (kLens) {
            const __m256 c0 = _mm256_add_ps(pc0, _mm256_mul_ps(w, dc0)),
                         c1 = _mm256_add_ps(pc1, _mm256_mul_ps(w, dc1));
            const __m256 ax = _mm256_mul_ps(_mm256_loadu_ps(&s.lensX[e]), sx);
            const __m256 ay = _mm256_mul_ps(_mm256_loadu_ps(&s.lensY[e]), sy);
            const __m256 xa = _mm256_mul_ps(ax, c0), xb = _mm256_mul_ps(ax, c1);
            const __m256 ya = _mm256_mul_ps(ay, c0), yb = _mm256_mul_ps(ay, c1);
            x0 = _mm256_add_ps(x0, _mm256_min_ps(xa, xb)), x1 = _mm256_add_ps(x1, _mm256_max_ps(xa, xb));
            y0 = _mm256_add_ps(y0, _mm256_min_ps(ya, yb)), y1 = _mm256_add_ps(y1, _mm256_max_ps(ya, yb));
        }
        const __m256 out8 = outsideBox8(_mm256_loadu_ps(&s.fx[e]), _mm256_loadu_ps(&s.fy[e]), x0, x1, y0, y1);
        n += compactLanes(out8, e, end, s, sink, n);
    }
    return n;
}

// The samples waiting for their exact test against one micropolygon (the AVX2 test takes eight at a
// time, and one stratum's list is often shorter): sample index, time and lens point, padded by eight.
struct PendingTests {
    std::vector<uint32_t> sample;
    std::vector<float> time, lensX, lensY;
    uint32_t count = 0;
    void add(const CandidateView& v, const uint32_t* list, uint32_t n) {
        const size_t need = size_t(count) + n + 8;
        if (need > sample.size()) {
            const size_t size = std::max(need, 2 * sample.size());
            sample.resize(size), time.resize(size), lensX.resize(size), lensY.resize(size);
        }
        for (uint32_t i = 0; i < n; ++i, ++count) {
            const uint32_t e = list[i];
            sample[count] = v.sample[e], time[count] = v.time[e];
            lensX[count] = v.lensX[e], lensY[count] = v.lensY[e];
        }
    }
};

// The exact test of eight samples against one micropolygon at once (each sample at its own time and lens
// point): testAt's moveQuad, facesCamera and testMovedSampleOnce, lane by lane, with the same results.
// The corners are moved by the SSE2 moveQuad's float operations (timeline segment 0: the grid has at
// most one linear motion, w = the sample's time clamped to [0, 1] as timelineSegment gives it). The
// integer edge functions are evaluated relative to the sample: with corner offsets d = X - sx below 2^14
// the edge function (xb - xa)(sy - ya) - (yb - ya)(sx - xa) equals the cross product dxa dyb - dxb dya
// exactly and fits 32 bits, and the doubled area is the sum of the three edges' cross products; a lane
// with a larger offset (a micropolygon wider than 64 pixels at that sample) goes to `scalar`. A hit's
// weights and depth are computed as the scalar test computes them, from the same integers.
struct EdgeLanes8 {
    __m256i cross;           // dxa dyb - dxb dya of the edge a -> b
    __m256i biasAB, biasBA;  // fillBias of a -> b and of b -> a (0 or 1)
};
__attribute__((target("avx2"))) inline EdgeLanes8 edgeLanes8(__m256i dxa, __m256i dya, __m256i dxb,
                                                             __m256i dyb) {
    EdgeLanes8 e;
    e.cross = _mm256_sub_epi32(_mm256_mullo_epi32(dxa, dyb), _mm256_mullo_epi32(dxb, dya));
    const __m256i zero = _mm256_setzero_si256(), one = _mm256_set1_epi32(1);
    const __m256i dy = _mm256_sub_epi32(dyb, dya), dx = _mm256_sub_epi32(dxb, dxa);
    const __m256i dyZero = _mm256_cmpeq_epi32(dy, zero);
    // fillBias(a, b) = 0 when dy > 0 or (dy == 0 and dx < 0), else 1; b -> a negates dy and dx.
    const __m256i ownsAB =
        _mm256_or_si256(_mm256_cmpgt_epi32(dy, zero), _mm256_and_si256(dyZero, _mm256_cmpgt_epi32(zero, dx)));
    const __m256i ownsBA =
        _mm256_or_si256(_mm256_cmpgt_epi32(zero, dy), _mm256_and_si256(dyZero, _mm256_cmpgt_epi32(dx, zero)));
    e.biasAB = _mm256_add_epi32(one, ownsAB);  // mask -1 -> 0, 0 -> 1
    e.biasBA = _mm256_add_epi32(one, ownsBA);
    return e;
}

// One triangle of the quad over eight lanes: inside mask, and per lane the oriented weights w1, w2 (of the
// oriented corners 1 and 2), the positive doubled area and whether corners 1 and 2 were swapped (as
// testMovedSampleOnce orients the triangle counter-clockwise). Edges given as e12 (corner 1 -> 2),
// e20 (2 -> 0), e01 (0 -> 1).
struct TriangleLanes8 {
    __m256i inside, w1, w2, area, swapped;
    __m256i signedArea;  // before orienting (its sign is facesCamera's for the first triangle)
};
__attribute__((target("avx2"))) inline TriangleLanes8 triangleLanes8(const EdgeLanes8& e12,
                                                                     const EdgeLanes8& e20,
                                                                     const EdgeLanes8& e01) {
    TriangleLanes8 t;
    const __m256i zero = _mm256_setzero_si256();
    const __m256i area = _mm256_add_epi32(_mm256_add_epi32(e01.cross, e12.cross), e20.cross);
    t.signedArea = area;
    t.swapped = _mm256_cmpgt_epi32(zero, area);
    // Counter-clockwise: w0 = E12, w1 = E20, w2 = E01. Swapped (corners 0, 2, 1): w0 = E21, w1 = E10,
    // w2 = E02, with E_ba = -E_ab and b -> a's own bias.
    const __m256i w0 =
        _mm256_blendv_epi8(_mm256_sub_epi32(e12.cross, e12.biasAB),
                           _mm256_sub_epi32(_mm256_sub_epi32(zero, e12.cross), e12.biasBA), t.swapped);
    t.w1 = _mm256_blendv_epi8(_mm256_sub_epi32(e20.cross, e20.biasAB),
                              _mm256_sub_epi32(_mm256_sub_epi32(zero, e01.cross), e01.biasBA), t.swapped);
    t.w2 = _mm256_blendv_epi8(_mm256_sub_epi32(e01.cross, e01.biasAB),
                              _mm256_sub_epi32(_mm256_sub_epi32(zero, e20.cross), e20.biasBA), t.swapped);
    t.area = _mm256_abs_epi32(area);
    const __m256i anyNegative = _mm256_or_si256(_mm256_or_si256(w0, t.w1), t.w2);
    t.inside = _mm256_andnot_si256(
        _mm256_or_si256(_mm256_cmpeq_epi32(area, zero), _mm256_cmpgt_epi32(zero, anyNegative)),
        _mm256_set1_epi32(-1));
    return t;
}

// blurredToFixed over eight lanes as moveQuad's SSE2 form computes it (clamp as max then min, rounding
// offset +-0.5 from the sign, truncating conversion).
__attribute__((target("avx2"))) inline __m256i toFixed8(__m256 v) {
    const __m256 limit = _mm256_set1_ps(float(1 << 20) * kSubpixelScale);
    const __m256 f = _mm256_min_ps(_mm256_max_ps(_mm256_mul_ps(v, _mm256_set1_ps(kSubpixelScale)),
                                                 _mm256_sub_ps(_mm256_setzero_ps(), limit)),
                                   limit);
    return _mm256_cvttps_epi32(
        _mm256_add_ps(f, _mm256_or_ps(_mm256_set1_ps(0.5f), _mm256_and_ps(f, _mm256_set1_ps(-0.f)))));
}

template <bool kAttributes, class Scalar>
__attribute__((target("avx2,popcnt"))) void testEntriesAvx2(const Grid& g, const int vid[4],
                                                            const CornerSegment& s, bool twoSided,
                                                            bool frontIfPositive, const PendingTests& p,
                                                            bool lensOn, const Projector& pr,
                                                            SampleTile& tile, float nearZ, Scalar&& scalar) {
    const bool moving = g.knots == 2;
    const __m256i reach = _mm256_set1_epi32((1 << 14) - 1);
    const int spp = tile.spp;
    const uint32_t n = p.count;
    for (uint32_t b = 0; b < n; b += 8) {
        const uint32_t count = std::min(8u, n - b);
        alignas(32) int32_t sx[8], sy[8];
        uint32_t sample[8];
        for (uint32_t l = 0; l < 8; ++l) {  // lanes past count repeat the last sample (and are masked off)
            sample[l] = p.sample[b + std::min(l, count - 1)];
            sx[l] = tile.sx[sample[l]], sy[l] = tile.sy[sample[l]];
        }
        // timelineSegment's w: 0 for one knot; for two, the time clamped to [0, 1].
        __m256 w = _mm256_setzero_ps();
        if (moving) {
            const __m256 u = _mm256_loadu_ps(&p.time[b]);
            w = _mm256_blendv_ps(u, _mm256_set1_ps(1.f), _mm256_cmp_ps(u, _mm256_set1_ps(1.f), _CMP_GE_OQ));
            w = _mm256_blendv_ps(w, _mm256_setzero_ps(), _mm256_cmp_ps(u, _mm256_setzero_ps(), _CMP_LE_OQ));
        }
        const __m256 lx = _mm256_loadu_ps(&p.lensX[b]), ly = _mm256_loadu_ps(&p.lensY[b]);
        const __m256i sxv = _mm256_load_si256(reinterpret_cast<const __m256i*>(sx)),
                      syv = _mm256_load_si256(reinterpret_cast<const __m256i*>(sy));
        __m256i dx[4], dy[4];
        __m256i far = _mm256_setzero_si256();
        for (int c = 0; c < 4; ++c) {
            __m256 x = _mm256_add_ps(_mm256_set1_ps(s.x[c]), _mm256_mul_ps(w, _mm256_set1_ps(s.dx[c])));
            __m256 y = _mm256_add_ps(_mm256_set1_ps(s.y[c]), _mm256_mul_ps(w, _mm256_set1_ps(s.dy[c])));
            if (lensOn) {
                const __m256 cc =
                    _mm256_add_ps(_mm256_set1_ps(s.c[c]), _mm256_mul_ps(w, _mm256_set1_ps(s.dc[c])));
                x = _mm256_add_ps(x, _mm256_mul_ps(_mm256_mul_ps(lx, cc), _mm256_set1_ps(pr.sx)));
                y = _mm256_add_ps(y, _mm256_mul_ps(_mm256_mul_ps(ly, cc), _mm256_set1_ps(pr.sy)));
            }
            dx[c] = _mm256_sub_epi32(toFixed8(x), sxv);
            dy[c] = _mm256_sub_epi32(toFixed8(y), syv);
            far = _mm256_or_si256(far, _mm256_or_si256(_mm256_cmpgt_epi32(_mm256_abs_epi32(dx[c]), reach),
                                                       _mm256_cmpgt_epi32(_mm256_abs_epi32(dy[c]), reach)));
        }
        const EdgeLanes8 e01 = edgeLanes8(dx[0], dy[0], dx[1], dy[1]),
                         e12 = edgeLanes8(dx[1], dy[1], dx[2], dy[2]),
                         e20 = edgeLanes8(dx[2], dy[2], dx[0], dy[0]),
                         e23 = edgeLanes8(dx[2], dy[2], dx[3], dy[3]),
                         e30 = edgeLanes8(dx[3], dy[3], dx[0], dy[0]);
        // Edge 0 -> 2 of the second triangle (0, 2, 3) is edge 2 -> 0 walked the other way.
        const EdgeLanes8 e02{_mm256_sub_epi32(_mm256_setzero_si256(), e20.cross), e20.biasBA, e20.biasAB};
        const TriangleLanes8 t0 = triangleLanes8(e12, e20, e01), t1 = triangleLanes8(e23, e30, e02);
        const unsigned lanes = (1u << count) - 1u;
        const unsigned farMask = unsigned(_mm256_movemask_ps(_mm256_castsi256_ps(far))) & lanes;
        unsigned faces = lanes & ~farMask;
        if (!twoSided) {  // facesCamera: the signed area of corners (0, 1, 2) against the shutter-open facing
            const unsigned positive = unsigned(_mm256_movemask_ps(
                _mm256_castsi256_ps(_mm256_cmpgt_epi32(t0.signedArea, _mm256_setzero_si256()))));
            faces &= frontIfPositive ? positive : ~positive;
        }
        const unsigned in0 = unsigned(_mm256_movemask_ps(_mm256_castsi256_ps(t0.inside))) & faces;
        const unsigned in1 = unsigned(_mm256_movemask_ps(_mm256_castsi256_ps(t1.inside))) & faces & ~in0;
        if (in0 | in1) {
            alignas(32) int32_t w1[2][8], w2[2][8], area[2][8], swapped[2][8];
            alignas(32) float ws[8];
            _mm256_store_si256(reinterpret_cast<__m256i*>(w1[0]), t0.w1),
                _mm256_store_si256(reinterpret_cast<__m256i*>(w1[1]), t1.w1);
            _mm256_store_si256(reinterpret_cast<__m256i*>(w2[0]), t0.w2),
                _mm256_store_si256(reinterpret_cast<__m256i*>(w2[1]), t1.w2);
            _mm256_store_si256(reinterpret_cast<__m256i*>(area[0]), t0.area),
                _mm256_store_si256(reinterpret_cast<__m256i*>(area[1]), t1.area);
            _mm256_store_si256(reinterpret_cast<__m256i*>(swapped[0]), t0.swapped),
                _mm256_store_si256(reinterpret_cast<__m256i*>(swapped[1]), t1.swapped);
            _mm256_store_ps(ws, w);
            for (unsigned hit = in0 | in1; hit; hit &= hit - 1) {
                const int l = __builtin_ctz(hit), tri = (in0 >> l) & 1u ? 0 : 1;
                // testMovedSampleOnce's weights and moveQuad's depths, from the same integers and floats.
                const float invArea = 1.f / float(area[tri][l]);
                float l1 = float(w1[tri][l]) * invArea, l2 = float(w2[tri][l]) * invArea;
                if (swapped[tri][l]) std::swap(l1, l2);
                MovedQuad q;
                for (int c = 0; c < 4; ++c) q.Z[c] = s.z[c] + ws[l] * s.dz[c];
                writeMovedHit<kAttributes>(g, vid, q, tri, l1, l2, sample[l], tile, nearZ);
                tile.pixelHit[sample[l] / size_t(spp)] = 1;
            }
        }
        for (unsigned f = farMask; f; f &= f - 1) scalar(b + uint32_t(__builtin_ctz(f)));
    }
}
#endif

// Whether sample point (fx, fy) (pixels) can be inside the micropolygon at the sample's time (segment k,
// weight w) and lens point: the box at that time, grown by the lens point times the corners'
// lens-coefficient range (x + l c sx >= min x + min over c of l c sx). A dozen flops, against moving
// four corners and setting up the edges: most samples a bound meets fail here.
inline bool inBoundAt(const KnotBox* knotBox, int knots, int k, float w, Vec2 lens, const Projector& pr,
                      bool lensOn, float fx, float fy) {
    const KnotBox b = knots == 1 ? knotBox[0] : lerpBox(knotBox[k], knotBox[k + 1], w);
    float x0 = b.x0 - kBoundSlack, x1 = b.x1 + kBoundSlack, y0 = b.y0 - kBoundSlack, y1 = b.y1 + kBoundSlack;
    if (lensOn) {
        const float ax = lens.x * pr.sx, ay = lens.y * pr.sy;
        const float xa = ax * b.c0, xb = ax * b.c1, ya = ay * b.c0, yb = ay * b.c1;
        x0 += std::min(xa, xb), x1 += std::max(xa, xb), y0 += std::min(ya, yb), y1 += std::max(ya, yb);
    }
    return fx >= x0 && fx <= x1 && fy >= y0 && fy <= y1;
}

// A box grown by the shift of lens cell (cx, cy) of L x L: x + l c sx >= min x + min (l c sx) over the
// cell and the box's lens coefficients (likewise for y); the box itself without a lens.
struct CellBound {
    float x0, x1, y0, y1;
};
inline CellBound cellBound(const KnotBox& box, int cx, int cy, int L, const Projector& pr, bool lensOn) {
    CellBound b{box.x0, box.x1, box.y0, box.y1};
    if (!lensOn) return b;
    auto grow = [&](int a, float s, float& lo, float& hi) {
        const float l0 = lensCellEdge(a, L), l1 = lensCellEdge(a + 1, L);
        const float v[4] = {l0 * box.c0 * s, l0 * box.c1 * s, l1 * box.c0 * s, l1 * box.c1 * s};
        lo += std::min({v[0], v[1], v[2], v[3]}), hi += std::max({v[0], v[1], v[2], v[3]});
    };
    grow(cx, pr.sx, b.x0, b.x1);
    grow(cy, pr.sy, b.y0, b.y1);
    return b;
}

// The bound of a still box over lens cell (cx, cy) at each sample's own lens point (StillLensBound), when
// the cell's l.x and l.y keep one sign (shiftFactors); false when one straddles l = 0.
inline bool stillLensBound(const KnotBox& b0, int cx, int cy, int L, const Projector& pr, StillLensBound& b) {
    b.x0 = b0.x0 - kBoundSlack, b.x1 = b0.x1 + kBoundSlack, b.y0 = b0.y0 - kBoundSlack,
    b.y1 = b0.y1 + kBoundSlack;
    const bool oneX = shiftFactors(cx, L, b0.c0 * pr.sx, b0.c1 * pr.sx, b.loX, b.hiX);
    const bool oneY = shiftFactors(cy, L, b0.c0 * pr.sy, b0.c1 * pr.sy, b.loY, b.hiY);
    return oneX && oneY;
}

// The candidates a block of micropolygons gathered from the strata for one lens cell (its bound at each
// sample's own lens point contains theirs), which each micropolygon of the block then filters with its
// own bound: structure of arrays, padded as BlurStrata's.
struct BlockCandidates {
    std::vector<float> fx, fy, time, lensX, lensY;
    std::vector<uint32_t> sample;
    uint32_t count = 0;
    // Room for `more` entries past count, and the padding.
    void reserve(uint32_t more) {
        const size_t need = size_t(count) + more + BlurStrata::kRunPadding;
        if (need <= fx.size()) return;
        const size_t n = std::max(need, 2 * fx.size());
        fx.resize(n), fy.resize(n), time.resize(n), lensX.resize(n), lensY.resize(n), sample.resize(n);
    }
    void add(const CandidateView& s, uint32_t e) {  // after reserve
        fx[count] = s.fx[e], fy[count] = s.fy[e], time[count] = s.time[e];
        lensX[count] = s.lensX[e], lensY[count] = s.lensY[e];
        sample[count++] = s.sample[e];
    }
    CandidateView view() const {
        return {fx.data(), fy.data(), time.data(), lensX.data(), lensY.data(), sample.data()};
    }
};

// Blocks: micropolygons go through the strata kBlockSide x kBlockSide at a time when the block blurs by at
// least kBlockMinBlur pixels (its circle of confusion or the grid's motion). The block's bound over a lens
// cell is about (b + r)^2 pixels against b^2 (1 + r)^2 for its b^2 micropolygons one by one (r: the cell's
// share of the blur), so the strata are read once for the block; each micropolygon then filters only the
// block's candidates (about spp b^2 samples, contiguous). For small blurs that second filter costs more
// than it saves. dof_teapot, 1 thread, callgrind: 20.1 G instructions without blocks, 11.8 G with b = 2,
// 10.3 G with 3, 10.0 G with 4 (the sample stage 1.29 -> 0.86 s); the threshold matters little between 1
// and 3 pixels.
constexpr int kBlockSide = 4;
constexpr float kBlockMinBlur = 2.f;
constexpr float kBlockSlack = 1.f / 512.f;

// The bounding-box scheme (paper 000, sec. 3.3): each micropolygon meets every sample whose (x, y) its
// bound over the shutter and lens covers, each at the sample's own (t, lens). With strata bounds the
// bound is cut into one per (time group, lens cell), which meets only the samples of its cell
// (BlurStrata: per row, one contiguous run under the bound's columns), and every sample of a run is first
// checked against the bound at its own (t, lens) (the four-wide filters, or inBoundAt) before it is tested
// exactly (testMovedSampleOnce): the same hits as the paper's single bound, with far fewer tests.
template <bool kAttributes>
uint64_t rasterizeBoundingBox(const Grid& g, SampleTile& tile, float nearZ, const BlurRasterContext& ctx,
                              const BlurStrata& strata) {
    const Projector& pr = *ctx.projector;
    const std::vector<float>& knots = *ctx.knots;
    const Rect& reg = tile.region;
    const int stride = g.nu + 1, spp = tile.spp;
    uint64_t tests = 0;
    const bool cut = ctx.strataBounds && !strata.start.empty();
    const int T = cut ? strata.timeStrata : 1, L = cut ? strata.lensCells : 1;
    const int LL = L * L;
    const size_t nv = size_t(g.vertexCount());
    const bool allValid = g.allKnotsValid;
    const bool lensOn = pr.hasLens() && pr.perspective;
    const bool still = g.knots == 1 && allValid;
    const CandidateView entries = viewOf(strata);
#if TESSERA_BLUR_AVX2
    const bool avx2 = reyesAvx2Active();
    const bool deferTests = avx2 && g.knots <= 2;
    thread_local std::array<PendingTests, kBlockSide * kBlockSide> pending;
#endif
    thread_local std::vector<uint32_t> passed;  // the entries a filter passed
    // Cost model: a group costs a bound and a run lookup per row and fine stratum, and the samples in its
    // bound number about spp (1 + motion / groups) per covered pixel, so the total is least near
    // groups = sqrt(spp * motion / 2).
    const int wanted = std::clamp(int(std::ceil(std::sqrt(0.5f * float(spp) * g.motionPixels))), 1, T);
    const int group = std::max(1, T / wanted), groups = (T + group - 1) / group;
    // The groups' ends on the knot timeline.
    thread_local std::vector<int> endKnot;
    thread_local std::vector<float> endWeight;
    endKnot.resize(size_t(groups) + 1), endWeight.resize(size_t(groups) + 1);
    for (int e = 0; e <= groups; ++e)
        timelineSegment(knots.data(), g.knots, float(std::min(T, e * group)) / T, endKnot[e], endWeight[e]);

    // How far the lens moves a box with lens coefficients `box.c0 .. c1` at most, in raster x and y.
    auto lensReach = [&](const KnotBox& box, float& gx, float& gy) {
        const float cmax = lensOn ? std::max(std::abs(box.c0), std::abs(box.c1)) : 0.f;
        gx = cmax * std::abs(pr.sx), gy = cmax * std::abs(pr.sy);
    };
    // One micropolygon: its corners, raster box per knot, facing at shutter open and the corners of the
    // timeline segment its last sample met.
    struct Micropolygon {
        int vid[4];
        int slot;  // in the block (knot boxes, pending tests)
        const KnotBox* knotBox;
        KnotBox all;  // over every knot
        bool front0;
        int64_t sign0;
        CornerSegment corners;
    };
    constexpr int kBlockSize = kBlockSide * kBlockSide;
    thread_local std::vector<KnotBox> knotBoxes;
    knotBoxes.resize(size_t(kBlockSize) * size_t(g.knots));
    // Micropolygon (i, j) into m, its knot boxes into slot `slot`; false when its bound over the whole
    // shutter and lens misses the tile (most visits of a blurred grid's buckets end here).
    auto load = [&](int i, int j, int slot, Micropolygon& m) {
        const int a = j * stride + i;
        m.vid[0] = a, m.vid[1] = a + 1, m.vid[2] = a + stride + 1, m.vid[3] = a + stride;
        KnotBox* knotBox = &knotBoxes[size_t(slot) * size_t(g.knots)];
        m.knotBox = knotBox;
        m.slot = slot;
        m.all = kEmptyBox;
        for (int kn = 0; kn < g.knots; ++kn) {
            KnotBox kb = kEmptyBox;
            for (int c = 0; c < 4; ++c) {
                const size_t at = size_t(kn) * nv + m.vid[c];
                kb.x0 = std::min(kb.x0, g.knotX[at]), kb.x1 = std::max(kb.x1, g.knotX[at]);
                kb.y0 = std::min(kb.y0, g.knotY[at]), kb.y1 = std::max(kb.y1, g.knotY[at]);
                kb.c0 = std::min(kb.c0, g.knotC[at]), kb.c1 = std::max(kb.c1, g.knotC[at]);
            }
            knotBox[kn] = kb;
            m.all = unionBox(m.all, kb);
        }
        const KnotBox& all = m.all;
        float gx, gy;
        lensReach(all, gx, gy);
        if (allValid && (all.x1 + gx < float(reg.x0) - 1.f || all.x0 - gx > float(reg.x1) + 1.f ||
                         all.y1 + gy < float(reg.y0) - 1.f || all.y0 - gy > float(reg.y1) + 1.f))
            return false;
        openFacing(g, m.vid, m.front0, m.sign0);
        m.corners.k = -1;
        return true;
    };
    // Sample si at its time and lens point: moved corners, then the exact test (counted by the callers).
    auto testAt = [&](Micropolygon& m, size_t si, int k, float w, Vec2 lens) {
        if (k != m.corners.k) loadCorners(g, m.vid, k, m.corners);
        const MovedQuad q =
            lensOn ? moveQuad<true>(m.corners, w, lens, pr) : moveQuad<false>(m.corners, w, lens, pr);
        if (!q.valid || !facesCamera(g.twoSided, m.front0, m.sign0, q)) return;
        if (testMovedSampleOnce<kAttributes>(g, m.vid, q, si, tile, nearZ))
            tile.pixelHit[si / size_t(spp)] = 1;
    };
    // Sample si at normalised shutter time `time` and lens point `lens` (testAt at time's knot segment).
    auto testAtTime = [&](Micropolygon& m, size_t si, float time, Vec2 lens) {
        int k;
        float w;
        timelineSegment(knots.data(), g.knots, time, k, w);
        testAt(m, si, k, w, lens);
    };
    // The pixel span of a bound; every pixel of the tile when a corner is behind the near plane at some time.
    auto spanOf = [&](const CellBound& b) {
        return allValid ? pixelSpan(reg, int64_t(floorToInt(b.x0 - kBoundSlack)) << kSubpixelBits,
                                    int64_t(floorToInt(b.x1 + kBoundSlack)) << kSubpixelBits,
                                    int64_t(floorToInt(b.y0 - kBoundSlack)) << kSubpixelBits,
                                    int64_t(floorToInt(b.y1 + kBoundSlack)) << kSubpixelBits)
                        : Span{reg.x0, reg.x1 - 1, reg.y0, reg.y1 - 1};
    };

    // The paper's one bound over the whole shutter and lens, against every sample of the tile in it.
    auto rasterizeUncut = [&](Micropolygon& m) {
        const KnotBox& all = m.all;
        float gx, gy;
        lensReach(all, gx, gy);
        const int64_t bx0 = int64_t((all.x0 - gx - kBoundSlack) * kSubpixelScale),
                      bx1 = int64_t((all.x1 + gx + kBoundSlack) * kSubpixelScale),
                      by0 = int64_t((all.y0 - gy - kBoundSlack) * kSubpixelScale),
                      by1 = int64_t((all.y1 + gy + kBoundSlack) * kSubpixelScale);
        const Span sp =
            allValid ? pixelSpan(reg, bx0, bx1, by0, by1) : Span{reg.x0, reg.x1 - 1, reg.y0, reg.y1 - 1};
        for (int py = sp.py0; py <= sp.py1; ++py)
            for (int px = sp.px0; px <= sp.px1; ++px)
                for (int sl = 0; sl < spp; ++sl) {
                    const size_t si = (size_t(py - reg.y0) * reg.width() + (px - reg.x0)) * spp + sl;
                    if (allValid &&
                        (tile.sx[si] < bx0 || tile.sx[si] > bx1 || tile.sy[si] < by0 || tile.sy[si] > by1))
                        continue;
                    ++tests;
                    testAtTime(m, si, tile.time[si], tile.lens[si]);
                }
    };

    // The bound at each sample's own (t, lens) for stratum tb and lens cell (cx, cy), of knot boxes
    // knotBox: for a still box over a one-signed cell (StillLensBound), for a stratum that one linear
    // motion holds whole (SegmentBound), else per sample (inBoundAt).
    struct StratumBound {
        enum Kind { Still, StillAnyCell, Segment, PerSample } kind;
        StillLensBound still;
        StillBound stillAnyCell;
        SegmentBound segment;
        const KnotBox* knotBox;
    };
    auto stratumBound = [&](const KnotBox* knotBox, int tb, int cx, int cy, bool perCell = true) {
        StratumBound b;
        b.knotBox = knotBox;
        // A still micropolygon (depth of field only): the bound at lens point l is its box grown by
        // l.x [c0, c1] sx and l.y [c0, c1] sy. Where the cell's l.x keeps one sign, the least shift is
        // l.x times one end of that range, known per cell (likewise for y): two multiply-adds per side
        // and sample.
        if (perCell && still && lensOn && stillLensBound(knotBox[0], cx, cy, L, pr, b.still)) {
            b.kind = StratumBound::Still;
            return b;
        }
        if (!perCell && still && lensOn) {  // every cell at once: the shift's ends per sample (StillBound)
            const KnotBox& k = knotBox[0];
            b.kind = StratumBound::StillAnyCell;
            b.stillAnyCell =
                StillBound{k.x0 - kBoundSlack, k.x1 + kBoundSlack, k.y0 - kBoundSlack, k.y1 + kBoundSlack,
                           k.c0 * pr.sx,       k.c1 * pr.sx,       k.c0 * pr.sy,       k.c1 * pr.sy};
            return b;
        }
        const int seg = g.knots == 1 ? 0 : strata.stratumSegment[size_t(tb)];
        if (!allValid || seg < 0) {
            b.kind = StratumBound::PerSample;
            return b;
        }
        b.kind = StratumBound::Segment;
        SegmentBound& sb = b.segment;
        sb.p = knotBox[size_t(seg)];
        sb.q = g.knots == 1 ? sb.p : knotBox[size_t(seg) + 1];
        sb.t0 = g.knots == 1 ? 0.f : knots[size_t(seg)];
        sb.invDt = g.knots == 1 ? 0.f : strata.segmentInvDt[size_t(seg)];
        sb.sx = pr.sx, sb.sy = pr.sy;
        return b;
    };
#if TESSERA_BLUR_AVX2
    // The AVX2 filter of a bound's kind (not PerSample) over [first, end) of `v`, into `sink`; returns the
    // count that passed.
    auto filterAvx2 = [&](const StratumBound& b, const CandidateView& v, uint32_t first, uint32_t end,
                          const auto& sink) -> uint32_t {
        switch (b.kind) {
            case StratumBound::Still:
                return filterStillLensAvx2(v, first, end, b.still, sink);
            case StratumBound::StillAnyCell:
                return filterStillAvx2(v, first, end, b.stillAnyCell, sink);
            default:
                return lensOn ? filterSegmentAvx2<true>(v, first, end, b.segment, sink)
                              : filterSegmentAvx2<false>(v, first, end, b.segment, sink);
        }
    };
#endif
    // The entries of [first, end) of `v` inside bound b at the entry's own (t, lens), in order, as one list:
    // hits(list, count).
    auto filterEntries = [&](const StratumBound& b, const CandidateView& v, uint32_t first, uint32_t end,
                             auto&& hits) {
        if (passed.size() < size_t(end - first) + 8) passed.resize(2 * (size_t(end - first) + 8));
        uint32_t* out = passed.data();
        uint32_t n = 0;
        auto hit = [&](uint32_t e) { out[n++] = e; };
#if TESSERA_BLUR_AVX2
        if (avx2 && b.kind != StratumBound::PerSample) {
            n = filterAvx2(b, v, first, end, IndexSink{out});
            if (n) hits(static_cast<const uint32_t*>(out), n);
            return;
        }
#endif
        switch (b.kind) {
            case StratumBound::Still:
                filterStillLens(v, first, end, b.still, hit);
                break;
            case StratumBound::StillAnyCell:
                filterStill(v, first, end, b.stillAnyCell, hit);
                break;
            case StratumBound::Segment:
                if (lensOn)
                    filterSegment<true>(v, first, end, b.segment, hit);
                else
                    filterSegment<false>(v, first, end, b.segment, hit);
                break;
            case StratumBound::PerSample:
                for (uint32_t e = first; e < end; ++e) {
                    int k;
                    float w;
                    timelineSegment(knots.data(), g.knots, v.time[e], k, w);
                    if (allValid && !inBoundAt(b.knotBox, g.knots, k, w, Vec2{v.lensX[e], v.lensY[e]}, pr,
                                               lensOn, v.fx[e], v.fy[e]))
                        continue;
                    hit(e);
                }
                break;
        }
        if (n) hits(static_cast<const uint32_t*>(out), n);
    };
    // Entry e of `v` tested exactly against micropolygon m at the entry's own time and lens point.
    auto testEntry = [&](Micropolygon& m, const CandidateView& v, uint32_t e) {
        testAtTime(m, v.sample[e], v.time[e], Vec2{v.lensX[e], v.lensY[e]});
    };
    // The entries of a list tested exactly against micropolygon m. With AVX2, when the grid has at most one
    // linear motion (every sample in timeline segment 0), they wait in m's PendingTests and are tested
    // eight at a time by flush: a sample meets a micropolygon at most once (it lies in one stratum), and
    // the micropolygons of a block are flushed in the block's order, so each sample still meets them in
    // that order (the same depth-test winners). Otherwise one by one, now.
    auto testEntries = [&](Micropolygon& m, const CandidateView& v, const uint32_t* list, uint32_t n) {
        tests += n;
#if TESSERA_BLUR_AVX2
        if (deferTests) {
            pending[size_t(m.slot)].add(v, list, n);
            return;
        }
#endif
        for (uint32_t i = 0; i < n; ++i) testEntry(m, v, list[i]);
    };
    auto flush = [&](Micropolygon& m) {
#if TESSERA_BLUR_AVX2
        PendingTests& p = pending[size_t(m.slot)];
        if (p.count == 0) return;
        if (m.corners.k != 0) loadCorners(g, m.vid, 0, m.corners);
        if (m.corners.valid)
            testEntriesAvx2<kAttributes>(
                g, m.vid, m.corners, g.twoSided, m.front0 == (m.sign0 > 0), p, lensOn, pr, tile, nearZ,
                [&](uint32_t i) {
                    testAtTime(m, p.sample[i], p.time[i], Vec2{p.lensX[i], p.lensY[i]});
                });
        p.count = 0;
#else
        (void)m;
#endif
    };

    // The strata that a bound (knot boxes knotBox, `all` over every knot) meets: per time group and lens
    // cell, the runs of the rows under the group's bound over the cell; per stratum of the group, each run
    // goes to visit(bound, first, end) (which filters its entries with the stratum's bound at their own
    // t and lens), then done(tb, cx, cy).
    auto walkStrata = [&](const KnotBox* knotBox, const KnotBox& all, auto&& visit, auto&& done) {
        // One linear motion (two knots, so w = t): only the groups whose times can bring the bound to the
        // tile, with one stratum to spare on each side for the bounds' rounding. A micropolygon that
        // sweeps across several buckets meets each in a part of the shutter (motion_teapot: about half).
        int gFirst = 0, gLast = groups - 1;
        if (g.knots == 2 && allValid) {
            float gx, gy;
            lensReach(all, gx, gy);
            gx += 1.f, gy += 1.f;
            float ta = 0.f, tb = 1.f;
            // Keep the w in [ta, tb] where p + w (q - p) >= b.
            auto atLeast = [&](float p, float q, float b) {
                const float d = q - p;
                if (d > 0.f)
                    ta = std::max(ta, (b - p) / d);
                else if (d < 0.f)
                    tb = std::min(tb, (b - p) / d);
                else if (p < b)
                    ta = 2.f;
            };
            const KnotBox &p = knotBox[0], &q = knotBox[1];
            atLeast(p.x1, q.x1, float(reg.x0) - gx), atLeast(-p.x0, -q.x0, -(float(reg.x1) + gx));
            atLeast(p.y1, q.y1, float(reg.y0) - gy), atLeast(-p.y0, -q.y0, -(float(reg.y1) + gy));
            if (!(ta <= tb)) return;
            gFirst = std::max(0, int(ta * float(T)) - 1) / group;
            gLast = std::min(T - 1, int(tb * float(T)) + 1) / group;
        }
        for (int gi = gFirst; gi <= gLast; ++gi) {
            const int j0 = gi * group, j1 = std::min(T, j0 + group);
            KnotBox box;
            if (g.knots == 1) {
                box = knotBox[0];
            } else {
                const int ka = endKnot[gi], kb = endKnot[gi + 1];
                box = unionBox(lerpBox(knotBox[ka], knotBox[ka + 1], endWeight[gi]),
                               lerpBox(knotBox[kb], knotBox[kb + 1], endWeight[gi + 1]));
                for (int kn = ka + 1; kn <= kb; ++kn) box = unionBox(box, knotBox[kn]);
            }
            for (int lc = 0; lc < LL; ++lc) {
                const int cx = lc % L, cy = lc / L;
                const Span sp = spanOf(cellBound(box, cx, cy, L, pr, lensOn));
                if (sp.empty()) continue;
                const int c0 = sp.px0 - reg.x0, c1 = sp.px1 - reg.x0 + 1;
                for (int tb = j0; tb < j1; ++tb) {
                    const StratumBound b = stratumBound(knotBox, tb, cx, cy);
                    for (int py = sp.py0; py <= sp.py1; ++py) {
                        const size_t base = strata.runBase(py, tb * LL + lc);
                        const uint32_t first = strata.start[base + c0], end = strata.start[base + c1];
                        if (first == end) continue;
                        visit(b, first, end);
                    }
                    done(tb, cx, cy);
                }
            }
        }
    };
    auto rasterizeOne = [&](Micropolygon& m) {
        if (!cut) return rasterizeUncut(m);
        walkStrata(
            m.knotBox, m.all,
            [&](const StratumBound& b, uint32_t first, uint32_t end) {
                filterEntries(b, entries, first, end,
                              [&](const uint32_t* list, uint32_t n) { testEntries(m, entries, list, n); });
            },
            [](int, int, int) {});
        flush(m);
    };

    // Blocks of micropolygons (kBlockSide) for blurred grids sampled through the strata. A block's
    // micropolygons are tested in its row-major order, so of two that meet a sample at exactly the same
    // depth (a fold of the grid) the sample keeps the one a row-major pass would keep only within a block.
    if (!cut || !allValid) {
        Micropolygon m;
        for (int j = 0; j < g.nv; ++j)
            for (int i = 0; i < g.nu; ++i)
                if (load(i, j, 0, m)) rasterizeOne(m);
        return tests;
    }
    // A grid that is still or has one linear motion has one bound per micropolygon for every stratum and
    // lens cell (the segment bound, evaluated at each sample's own time and lens point): each
    // micropolygon then filters everything its block gathered once, instead of once per stratum and lens
    // cell (16 strata at 16 spp, 4 cells). Each sample lies in one stratum and cell, so it still meets each
    // micropolygon once. (A still grid's bound over every cell, StillBound, takes the ends of l c sx per
    // sample: the same products as the per-cell StillLensBound, so the same samples pass.)
    const bool oneBound = g.knots <= 2;
    thread_local BlockCandidates candidates;
    thread_local std::vector<KnotBox> blockBoxes;
    blockBoxes.resize(size_t(g.knots));
    for (int bj = 0; bj < g.nv; bj += kBlockSide)
        for (int bi = 0; bi < g.nu; bi += kBlockSide) {
            Micropolygon ms[kBlockSize];
            int n = 0;
            for (int j = bj; j < std::min(g.nv, bj + kBlockSide); ++j)
                for (int i = bi; i < std::min(g.nu, bi + kBlockSide); ++i)
                    if (load(i, j, n, ms[n])) ++n;
            if (n == 0) continue;
            // The block's knot boxes: the union of its micropolygons', grown by kBlockSlack so that the
            // block's bound at any (t, lens) contains theirs despite the bounds' float rounding.
            KnotBox blockAll = kEmptyBox;
            for (int kn = 0; kn < g.knots; ++kn) {
                KnotBox u = kEmptyBox;
                for (int m = 0; m < n; ++m) u = unionBox(u, ms[m].knotBox[kn]);
                u.x0 -= kBlockSlack, u.x1 += kBlockSlack, u.y0 -= kBlockSlack, u.y1 += kBlockSlack;
                blockBoxes[size_t(kn)] = u;
                blockAll = unionBox(blockAll, u);
            }
            float cocX, cocY;
            lensReach(blockAll, cocX, cocY);
            if (n == 1 || std::max({cocX, cocY, g.motionPixels}) < kBlockMinBlur) {
                for (int m = 0; m < n; ++m) rasterizeOne(ms[m]);
                continue;
            }
            candidates.count = 0;
            walkStrata(
                blockBoxes.data(), blockAll,
                [&](const StratumBound& b, uint32_t first, uint32_t end) {
                    candidates.reserve(end - first);
#if TESSERA_BLUR_AVX2
                    if (avx2 && b.kind != StratumBound::PerSample) {  // the entries packed in place
                        BlockCandidates& c = candidates;
                        const uint32_t at = c.count;
                        c.count += filterAvx2(
                            b, entries, first, end,
                            CopySink{c.fx.data() + at, c.fy.data() + at, c.time.data() + at,
                                     c.lensX.data() + at, c.lensY.data() + at, c.sample.data() + at});
                        return;
                    }
#endif
                    filterEntries(b, entries, first, end, [&](const uint32_t* list, uint32_t n) {
                        for (uint32_t i = 0; i < n; ++i) candidates.add(entries, list[i]);
                    });
                },
                [&](int tb, int cx, int cy) {
                    if (candidates.count == 0 || oneBound) return;
                    const CandidateView gathered = candidates.view();
                    for (int m = 0; m < n; ++m)
                        filterEntries(stratumBound(ms[m].knotBox, tb, cx, cy), gathered, 0, candidates.count,
                                      [&](const uint32_t* list, uint32_t count) {
                                          testEntries(ms[m], gathered, list, count);
                                      });
                    candidates.count = 0;
                });
            if (oneBound && candidates.count) {
                const CandidateView gathered = candidates.view();
                for (int m = 0; m < n; ++m)
                    filterEntries(stratumBound(ms[m].knotBox, 0, 0, 0, false), gathered, 0, candidates.count,
                                  [&](const uint32_t* list, uint32_t count) {
                                      testEntries(ms[m], gathered, list, count);
                                  });
            }
            for (int m = 0; m < n; ++m) flush(ms[m]);
        }
    return tests;
}

template <bool kAttributes>
uint64_t rasterizeImpl(const Grid& g, SampleTile& tile, float nearZ, const BlurRasterContext& ctx,
                       const BlurStrata& strata) {
    const Projector& pr = *ctx.projector;
    const BlurPattern& pat = *ctx.pattern;
    const std::vector<float>& knots = *ctx.knots;
    const Rect& reg = tile.region;
    const int stride = g.nu + 1, spp = tile.spp, tw = reg.width();
    const int vertices = g.vertexCount();
    uint64_t tests = 0;
    auto sampleIndex = [&](int px, int py, int slot) {
        return (size_t(py - reg.y0) * tw + size_t(px - reg.x0)) * spp + size_t(slot);
    };

    if (pat.scheme != BlurSampling::BoundingBox && !blurUsesStrata(pat.scheme, ctx.strataBounds)) {
        // Simple, and interleaved as the paper runs it: every micropolygon of the grid takes the same
        // (t, lens) per pass, so the whole grid is moved once per pass (each vertex shared by four
        // micropolygons) and then sampled. With strata bounds the interleaved samples go through the bbox
        // rasterizer instead (each at its own time and lens point: the same hits): a pass meets one sample
        // per K x K tile, so N = spp K^2 passes cost more than the strata's bounds (dof_teapot, 2 threads:
        // 4.7 -> 0.95 s).
        thread_local std::vector<MovedVertex> moved;
        moved.resize(vertices);
        const bool interleaved = pat.scheme == BlurSampling::Interleaved;
        const int K = pat.tileSize, KK = K * K, passes = interleaved ? pat.tileSamples() : spp;
        for (int n = 0; n < passes; ++n) {
            int k;
            float w;
            timelineSegment(knots.data(), g.knots, pat.time[n], k, w);
            const Vec2 lens = pat.lensPoint[n];
            int64_t gx0 = INT64_MAX, gx1 = INT64_MIN, gy0 = INT64_MAX, gy1 = INT64_MIN;
            for (int v = 0; v < vertices; ++v) {
                moved[v] = moveVertex(g, size_t(v), k, w, lens, pr.sx, pr.sy);
                gx0 = std::min(gx0, moved[v].X), gx1 = std::max(gx1, moved[v].X);
                gy0 = std::min(gy0, moved[v].Y), gy1 = std::max(gy1, moved[v].Y);
            }
            if (pixelSpan(reg, gx0, gx1, gy0, gy1).empty()) continue;  // the grid misses this tile now
            for (int j = 0; j < g.nv; ++j)
                for (int i = 0; i < g.nu; ++i) {
                    const int a = j * stride + i;
                    const int vid[4] = {a, a + 1, a + stride + 1, a + stride};
                    MovedQuad q;
                    q.valid = true;
                    for (int c = 0; c < 4; ++c) {
                        const MovedVertex& m = moved[vid[c]];
                        q.valid &= m.valid;
                        q.X[c] = m.X, q.Y[c] = m.Y, q.Z[c] = m.Z;
                    }
                    if (!q.valid) continue;
                    finishQuad(q);
                    const Span sp = pixelSpan(reg, q.minX, q.maxX, q.minY, q.maxY);
                    if (sp.empty()) continue;
                    bool front0;
                    int64_t sign0;
                    openFacing(g, vid, front0, sign0);
                    if (!facesCamera(g.twoSided, front0, sign0, q)) continue;
                    const QuadSetup setup = setupQuad(q);
                    if (!interleaved) {
                        for (int py = sp.py0; py <= sp.py1; ++py)
                            for (int px = sp.px0; px <= sp.px1; ++px) {
                                ++tests;
                                if (testMovedSample<kAttributes>(g, vid, q, sampleIndex(px, py, n), tile,
                                                                 nearZ, setup))
                                    tile.pixelHit[size_t(py - reg.y0) * tw + (px - reg.x0)] = 1;
                            }
                        continue;
                    }
                    const int N = passes;
                    for (int ty = sp.py0 / K; ty <= sp.py1 / K; ++ty)
                        for (int tx = sp.px0 / K; tx <= sp.px1 / K; ++tx) {
                            const int qn = pat.perm[size_t(pat.tilePermutation(tx, ty)) * N + n];
                            const int inTile = qn % KK, slot = qn / KK;
                            const int px = tx * K + inTile % K, py = ty * K + inTile / K;
                            if (px < sp.px0 || px > sp.px1 || py < sp.py0 || py > sp.py1) continue;
                            ++tests;
                            if (testMovedSample<kAttributes>(g, vid, q, sampleIndex(px, py, slot), tile,
                                                             nearZ, setup))
                                tile.pixelHit[size_t(py - reg.y0) * tw + (px - reg.x0)] = 1;
                        }
                }
        }
        return tests;
    }

    return rasterizeBoundingBox<kAttributes>(g, tile, nearZ, ctx, strata);
}

}  // namespace

void BlurStrata::configure(const BlurPattern& p, const std::vector<float>& knots) {
    // Lens cells: 2 x 2 (a cell never straddles l = 0, so a still micropolygon's bound over it has
    // one-signed shift factors). Finer cells cut the samples in each bound but cost a run lookup per row
    // and cell, which the four-wide filter made the larger cost: on dof_teapot (1 thread, sample stage)
    // 2 x 2 cells against the earlier sqrt(spp)^2: 1.33 vs 1.60 s at 16 spp (800x600), 0.75 vs 1.09 s
    // at 64 spp (400x300); at 256 spp (200x150) 0.57 s against 0.60 (4 x 4) and 0.72 (8 x 8).
    timeStrata = p.motion ? std::min(256, p.spp) : 1;
    lensCells = p.lens && p.spp >= 4 ? 2 : 1;
    stratumSegment.assign(size_t(timeStrata), -1);
    const int count = int(knots.size());
    for (int tb = 0; tb < timeStrata; ++tb) {
        // Samples of stratum tb have tb <= t T < tb + 1 (build's cellOf).
        const float lo = float(tb) / float(timeStrata), hi = float(tb + 1) / float(timeStrata);
        int k;
        float w;
        timelineSegment(knots.data(), count, lo, k, w);
        if (count <= 1 || hi <= knots[size_t(k) + 1] + 1e-6f) stratumSegment[size_t(tb)] = count <= 1 ? 0 : k;
    }
    segmentInvDt.assign(size_t(std::max(1, count - 1)), 0.f);
    for (int k = 0; k + 1 < count; ++k)
        segmentInvDt[size_t(k)] = 1.f / (knots[size_t(k) + 1] - knots[size_t(k)]);
}

void BlurStrata::build(const SampleTile& tile) {
    const int C = cells(), spp = tile.spp, L = lensCells;
    x0 = tile.region.x0, y0 = tile.region.y0, cols = tile.region.width();
    const int rows = tile.region.height();
    const size_t samples = size_t(cols) * rows * spp;
    // Counting sort by (row, cell, column): count into start[base + col + 1], then a running sum over the
    // whole array makes every block's first entry the previous block's end.
    start.assign(size_t(rows) * C * (cols + 1), 0);
    auto cellOf = [&](size_t si) {
        const int tb = std::min(timeStrata - 1, int(tile.time[si] * timeStrata));
        const int lx = std::clamp(int((tile.lens[si].x + 1.f) * 0.5f * L), 0, L - 1);
        const int ly = std::clamp(int((tile.lens[si].y + 1.f) * 0.5f * L), 0, L - 1);
        return (tb * L + ly) * L + lx;
    };
    // Each sample's slot in `start` (its row, cell and column), computed once for the count and the fill.
    thread_local std::vector<uint32_t> slot;
    slot.resize(samples);
    for (int py = 0; py < rows; ++py)
        for (int px = 0; px < cols; ++px)
            for (int s = 0; s < spp; ++s) {
                const size_t si = (size_t(py) * cols + px) * spp + s;
                slot[si] = uint32_t(runBase(y0 + py, cellOf(si)) + size_t(px));
                ++start[slot[si] + 1];
            }
    uint32_t running = 0;
    for (size_t b = 0; b < start.size(); b += size_t(cols + 1)) {
        start[b] = running;  // the block's first entry
        for (int c = 1; c <= cols; ++c) running = start[b + c] += running;
    }
    const size_t padded = samples + kRunPadding;
    // Every entry below `samples` is written below; the padding is zero.
    for (auto* v : {&fx, &fy, &time, &lensX, &lensY}) {
        v->resize(padded);
        std::fill(v->begin() + std::ptrdiff_t(samples), v->end(), 0.f);
    }
    sample.resize(padded);
    std::fill(sample.begin() + std::ptrdiff_t(samples), sample.end(), 0u);
    thread_local std::vector<uint32_t> fill;
    fill.assign(start.begin(), start.end());
    for (size_t si = 0; si < samples; ++si) {
        const uint32_t e = fill[slot[si]]++;
        fx[e] = float(tile.sx[si]) * (1.f / kSubpixelScale);
        fy[e] = float(tile.sy[si]) * (1.f / kSubpixelScale);
        time[e] = tile.time[si];
        lensX[e] = tile.lens[si].x, lensY[e] = tile.lens[si].y;
        sample[e] = uint32_t(si);
    }
}

uint64_t rasterizeBlurredGrid(const Grid& grid, SampleTile& tile, float nearZ, const BlurRasterContext& ctx,
                              const BlurStrata& strata) {
    tile.leaveStrataOrder();  // a sharp grid of the bucket may have left it in stratum order
    return tile.channels ? rasterizeImpl<true>(grid, tile, nearZ, ctx, strata)
                         : rasterizeImpl<false>(grid, tile, nearZ, ctx, strata);
}

}  // namespace tessera
