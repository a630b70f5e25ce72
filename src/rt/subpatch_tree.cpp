#include "rt/subpatch_tree.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "rt/intersect.h"
#if defined(__SSE2__)
#include <immintrin.h>
#endif

namespace tessera {
namespace {

// True when every normal dPdu x dPdv of the patch (times `sign`) has a positive dot product with every
// point of its hull box, i.e. the subpatch faces away from the origin everywhere. dPdu x dPdv is a
// degree (5,5) polynomial whose Bernstein coefficients are non-negative combinations of the cross products
// a_{i1,j1} x b_{i2,j2} of the derivative nets, so testing those cross products is conservative.
bool facesAwayFromOrigin(const BezierPatch& p, const Bounds3& box, float sign) {
    Vec3 a[3][4], b[4][3];  // a: dPdu net (u: 3, v: 4), b: dPdv net (u: 4, v: 3)
    for (int j = 0; j < 4; ++j)
        for (int i = 0; i < 3; ++i) a[i][j] = (p.at(i + 1, j) - p.at(i, j)) * sign;
    for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 4; ++i) b[i][j] = p.at(i, j + 1) - p.at(i, j);
    for (int i1 = 0; i1 < 3; ++i1)
        for (int j1 = 0; j1 < 4; ++j1)
            for (int i2 = 0; i2 < 4; ++i2)
                for (int j2 = 0; j2 < 3; ++j2) {
                    Vec3 c = cross(a[i1][j1], b[i2][j2]);
                    // min over the box of dot(P, c)
                    float m = 0;
                    for (int k = 0; k < 3; ++k) m += std::min(c[k] * box.lo[k], c[k] * box.hi[k]);
                    if (!(m > 0.f)) return false;
                }
    return true;
}

// One de Casteljau split at 1/2 of `width` cubics at once (one float of each per array): the control
// points a, p1, p2, p3 become the 7 points a, q1, p1, q3, p2, q5, p3 of the two halves. The seven arrays
// are disjoint (restrict parameters, so the loop vectorizes).
__attribute__((noinline)) void halfSplit(const float* __restrict a, float* __restrict p1,
                                         float* __restrict p2, const float* __restrict p3,
                                         float* __restrict q1, float* __restrict q3, float* __restrict q5,
                                         size_t width) {
    for (size_t w = 0; w < width; ++w) {
        const float x0 = a[w], x1 = p1[w], x2 = p2[w], x3 = p3[w];
        const float m01 = 0.5f * (x0 + x1), m12 = 0.5f * (x1 + x2), m23 = 0.5f * (x2 + x3);
        const float m012 = 0.5f * (m01 + m12), m123 = 0.5f * (m12 + m23);
        q1[w] = m01;
        p1[w] = m012;
        q3[w] = 0.5f * (m012 + m123);
        p2[w] = m123;
        q5[w] = m23;
    }
}

// Uniform subdivision of a cubic into 2^m pieces by repeated halving (de Casteljau at 1/2), in place:
// point k of the result (k = 0 .. 3 * 2^m) starts at base + k * stride and has `width` floats (width <=
// stride); the four control points must be at k = 0, 2^m, 2 * 2^m, 3 * 2^m. Every point is a vector of
// `width` floats, so one call subdivides many curves at once (a whole row of the grid below).
void subdivideUniform(float* base, size_t stride, size_t width, int m) {
    for (int level = 0; level < m; ++level) {
        const size_t h = size_t(1) << (m - level - 1);  // new spacing (in points)
        const size_t segs = size_t(1) << level;
        for (size_t s = 0; s < segs; ++s) {
            float* a = base + (6 * h * s) * stride;
            halfSplit(a, a + 2 * h * stride, a + 4 * h * stride, a + 6 * h * stride, a + h * stride,
                      a + 3 * h * stride, a + 5 * h * stride, width);
        }
    }
}

// Min and max over 4 arrays (elementwise), and over 4 floats 3 apart (windows of 4 points along a row).
// n is rounded up to a multiple of 4: the arrays must be readable / writable that far (padded).
void minMax4(const float* r0, const float* r1, const float* r2, const float* r3, float* lo, float* hi,
             size_t n) {
#if defined(__SSE2__)
    for (size_t f = 0; f < n; f += 4) {
        const __m128 a0 = _mm_loadu_ps(r0 + f), a1 = _mm_loadu_ps(r1 + f), a2 = _mm_loadu_ps(r2 + f),
                     a3 = _mm_loadu_ps(r3 + f);
        _mm_storeu_ps(lo + f, _mm_min_ps(_mm_min_ps(a0, a1), _mm_min_ps(a2, a3)));
        _mm_storeu_ps(hi + f, _mm_max_ps(_mm_max_ps(a0, a1), _mm_max_ps(a2, a3)));
    }
#else
    for (size_t f = 0; f < n; ++f) {
        lo[f] = std::min(std::min(r0[f], r1[f]), std::min(r2[f], r3[f]));
        hi[f] = std::max(std::max(r0[f], r1[f]), std::max(r2[f], r3[f]));
    }
#endif
}
void windowMinMax(const float* lo, const float* hi, float* wl, float* wh, size_t n) {
#if defined(__SSE2__)
    for (size_t f = 0; f < n; f += 4) {
        _mm_storeu_ps(wl + f, _mm_min_ps(_mm_min_ps(_mm_loadu_ps(lo + f), _mm_loadu_ps(lo + f + 3)),
                                         _mm_min_ps(_mm_loadu_ps(lo + f + 6), _mm_loadu_ps(lo + f + 9))));
        _mm_storeu_ps(wh + f, _mm_max_ps(_mm_max_ps(_mm_loadu_ps(hi + f), _mm_loadu_ps(hi + f + 3)),
                                         _mm_max_ps(_mm_loadu_ps(hi + f + 6), _mm_loadu_ps(hi + f + 9))));
    }
#else
    for (size_t f = 0; f < n; ++f) {
        wl[f] = std::min(std::min(lo[f], lo[f + 3]), std::min(lo[f + 6], lo[f + 9]));
        wh[f] = std::max(std::max(hi[f], hi[f + 3]), std::max(hi[f + 6], hi[f + 9]));
    }
#endif
}

// The relative and absolute margin of enlargedHull for box b: the rounding of subdivided control points.
float roundingMargin(const Bounds3& b) {
    auto mx = [](float x, float y) { return x < y ? y : x; };
    const float mag =
        mx(mx(mx(std::fabs(b.lo.x), std::fabs(b.hi.x)), mx(std::fabs(b.lo.y), std::fabs(b.hi.y))),
           mx(std::fabs(b.lo.z), std::fabs(b.hi.z)));
    const float ext = mx(mx(b.hi.x - b.lo.x, b.hi.y - b.lo.y), b.hi.z - b.lo.z);
    return 1e-5f * ext + 4e-7f * mag + 1e-30f;
}

// Enlarge a box by roundingMargin.
Bounds3 enlarge(Bounds3 b) {
    const float eps = roundingMargin(b);
    b.lo -= Vec3{eps, eps, eps};
    b.hi += Vec3{eps, eps, eps};
    return b;
}

// The slabs are grown by this share of the leaf box's diagonal: a ray passing that close to a leaf keeps
// its start. The slab test is exact without it, but Newton relies on such neighbouring starts where a
// leaf's own start misses its root: a ray through a shared edge or a grazing contact (the start converges
// just outside the patch, or to the other end of a long near-tangent contact), where a neighbour's start
// converged to the root. RtSeams and RtHierarchy's seam and wavefront tests, and Killeroo's frames against
// Embree's fine tessellation, were as before from 0.06 up; at 0 (every leaf the ray misses dropped) they
// lost 11 of 6,528 seam rays and changed 22 of Killeroo's 480,000 pixels (half of them to a farther root).
constexpr float kSlabGrowth = 0.06f;
// Lane `lane` of a slab group: the slab of the leaf whose 4 x 4 control points start at `net` (xyz
// interleaved, rows `rowFloats` apart, u along a row) and whose box is `box` (enlarged; for the rounding
// margin). The Newton part of the margin is added by addNewtonMargin.
void setLeafSlab(LeafSlab4& g, int lane, const float* net, size_t rowFloats, const Bounds3& box) {
    auto point = [&](int j, int i) {
        const float* q = net + size_t(j) * rowFloats + 3 * size_t(i);
        return Vec3{q[0], q[1], q[2]};
    };
    // The normal of the net's mean u and v directions: any unit vector gives a slab that holds the leaf,
    // one near the normal a thin one.
    const Vec3 p00 = point(0, 0), p03 = point(0, 3), p30 = point(3, 0), p33 = point(3, 3);
    const Vec3 c = cross((p03 + p33) - (p00 + p30), (p30 + p33) - (p00 + p03));
    const float len = length(c);
    float lo = INFINITY, hi = -INFINITY;
    Vec3 n{0.f, 0.f, 0.f};
    if (len > 0.f && std::isfinite(len)) {
        n = c * (1.f / len);
        for (int j = 0; j < 4; ++j) {
            const float* r = net + size_t(j) * rowFloats;
            for (int i = 0; i < 4; ++i) {
                const float h = n.x * r[3 * i] + n.y * r[3 * i + 1] + n.z * r[3 * i + 2];
                lo = lo < h ? lo : h, hi = hi > h ? hi : h;
            }
        }
        // The boxes' margin (enlarge): the control points are rounded de Casteljau results, and n.P is
        // rounded too.
        const float m = roundingMargin(box) + kSlabGrowth * length(box.hi - box.lo);
        lo -= m, hi += m;
    }
    if (!(std::isfinite(lo) && std::isfinite(hi))) n = {0.f, 0.f, 0.f}, lo = -INFINITY, hi = INFINITY;
    g.n[0][lane] = n.x, g.n[1][lane] = n.y, g.n[2][lane] = n.z;
    g.lo[lane] = lo, g.hi[lane] = hi;
}

void openSlabs(LeafSlab4* g, size_t groups) {
    for (size_t k = 0; k < groups; ++k)
        for (int lane = 0; lane < 4; ++lane) {
            for (int a = 0; a < 3; ++a) g[k].n[a][lane] = 0.f;
            g[k].lo[lane] = -INFINITY, g[k].hi[lane] = INFINITY;
        }
}

// Four Newton tolerances of the patch whose root box is `root` (newtonTolerance without the ray's origin,
// whose part the candidate stages add per ray) on every slab of its tree: a root Newton accepts may lie that
// far off the surface.
void addNewtonMargin(LeafSlab4* g, size_t groups, const Bounds3& root) {
    const float m = 4.f * newtonTolerance(root, Vec3{0.f, 0.f, 0.f});
    for (size_t k = 0; k < groups; ++k)
        for (int lane = 0; lane < 4; ++lane) g[k].lo[lane] -= m, g[k].hi[lane] += m;
}

// One patch's tree. The leaves form a grid of nu x nv subpatches (nu = 2^ceil(D/2) in u, nv = 2^floor(D/2)
// in v); their control points are the (3 nu + 1) x (3 nv + 1) grid made by subdividing the rows in u,
// then all columns at once in v (de Casteljau at 1/2, the same splits as the tree, in another order).
// Leaf boxes are the enlarged hulls of their 4x4 windows of the grid; every inner box is the union of
// its two children (conservative: the children's hulls contain the subpatch).
struct TreeBuilder {
    int depth, mu, mv;  // mu + mv = depth
    size_t nu, nv, cols, rows;
    std::vector<float> grid;           // rows x cols points, xyz interleaved
    std::vector<float> rowLo, rowHi;   // scratch: min/max over the 4 grid rows of one leaf row
    std::vector<float> winLo, winHi;   // per leaf row: min/max over the 4x4 window starting at each float
    std::vector<uint32_t> leafOfCell;  // cell b * nu + a -> leaf index in the tree's numbering

    explicit TreeBuilder(int d) : depth(d), mu((d + 1) / 2), mv(d / 2) {
        nu = size_t(1) << mu, nv = size_t(1) << mv;
        cols = 3 * nu + 1, rows = 3 * nv + 1;
        grid.resize(rows * cols * 3 + 16);  // padded: the min/max passes run 4 floats at a time
        rowLo.resize(3 * cols + 16), rowHi.resize(3 * cols + 16);
        winLo.resize(nv * 3 * cols + 16), winHi.resize(nv * 3 * cols + 16);
        leafOfCell.resize(nu * nv);
        for (uint32_t l = 0; l < (1u << d); ++l) {
            uint32_t a = 0, b = 0;
            for (int k = 0; k < d; ++k) {
                const uint32_t bit = (l >> (d - 1 - k)) & 1u;
                if ((k & 1) == 0)
                    a = (a << 1) | bit;
                else
                    b = (b << 1) | bit;
            }
            leafOfCell[b * nu + a] = l;
        }
    }

    // `slabs` (optional): the tree's leaf slab groups (SubpatchForest::slabGroupsPerTree of them).
    void build(const BezierPatch& p, Bounds3* boxes, uint8_t* back, float sign, LeafSlab4* slabs = nullptr) {
        float* g = grid.data();
        const size_t rowFloats = 3 * cols;
        for (int j = 0; j < 4; ++j) {
            float* row = g + size_t(j) * nv * rowFloats;
            for (int i = 0; i < 4; ++i) {
                const Vec3& c = p.cp[4 * j + i];
                float* q = row + 3 * size_t(i) * nu;
                q[0] = c.x, q[1] = c.y, q[2] = c.z;
            }
            subdivideUniform(row, 3, 3, mu);
        }
        subdivideUniform(g, rowFloats, rowFloats, mv);
        // Leaf bounds, elementwise over the grid (vectorizes): for each leaf row b, the min/max over its
        // 4 grid rows, then over 4 consecutive points (3 floats apart) along u.
        const size_t span = rowFloats - 9;  // windows of 4 points start at float f < span
        for (size_t b = 0; b < nv; ++b) {
            const float* r0 = g + 3 * b * rowFloats;
            minMax4(r0, r0 + rowFloats, r0 + 2 * rowFloats, r0 + 3 * rowFloats, rowLo.data(), rowHi.data(),
                    rowFloats);
            windowMinMax(rowLo.data(), rowHi.data(), winLo.data() + b * rowFloats,
                         winHi.data() + b * rowFloats, span);
        }
        const uint32_t firstLeaf = (1u << depth) - 1u;
        for (size_t b = 0; b < nv; ++b)
            for (size_t a = 0; a < nu; ++a) {
                const float* wl = winLo.data() + b * rowFloats + 9 * a;
                const float* wh = winHi.data() + b * rowFloats + 9 * a;
                Bounds3 bb;
                bb.lo = {wl[0], wl[1], wl[2]};
                bb.hi = {wh[0], wh[1], wh[2]};
                const uint32_t node = firstLeaf + leafOfCell[b * nu + a];
                boxes[node] = enlarge(bb);
                if (slabs) {
                    const uint32_t leaf = leafOfCell[b * nu + a];
                    setLeafSlab(slabs[leaf >> 2], int(leaf & 3), g + 3 * b * rowFloats + 9 * a, rowFloats,
                                boxes[node]);
                }
                if (back) {
                    BezierPatch leaf;
                    for (int j = 0; j < 4; ++j)
                        for (int i = 0; i < 4; ++i) {
                            const float* q = g + (3 * b + j) * rowFloats + 3 * (3 * a + i);
                            leaf.cp[4 * j + i] = {q[0], q[1], q[2]};
                        }
                    back[node] = facesAwayFromOrigin(leaf, boxes[node], sign);
                }
            }
        for (uint32_t i = firstLeaf; i-- > 0;) {
            boxes[i] = boxes[2 * i + 1];
            boxes[i].extend(boxes[2 * i + 2]);
            if (back) back[i] = back[2 * i + 1] & back[2 * i + 2];
        }
        if (slabs) addNewtonMargin(slabs, depth >= 2 ? size_t(1) << (depth - 2) : 1, boxes[0]);
    }
};

}  // namespace

void subpatchLeafRect(int depth, uint32_t leaf, float& u0, float& u1, float& v0, float& v1) {
    float du = 1.f, dv = 1.f;
    u0 = v0 = 0.f;
    for (int k = 0; k < depth; ++k) {
        uint32_t bit = (leaf >> (depth - 1 - k)) & 1u;
        if ((k & 1) == 0) {
            du *= 0.5f;
            u0 += float(bit) * du;
        } else {
            dv *= 0.5f;
            v0 += float(bit) * dv;
        }
    }
    u1 = u0 + du;
    v1 = v0 + dv;
}

Bounds3 enlargedHull(const BezierPatch& p) {
    return enlarge(hullBounds(p));
}

namespace {
void splatRows(LeafBasis& b) {
    for (int j = 0; j < 4; ++j)
        for (int k = 0; k < 4; ++k)
            for (int lane = 0; lane < 4; ++lane) b.mvSplat[j][k][lane] = b.mv[j][k];
}

// from + sign * v * step as a decode may round it: both roundings (the volatile keeps the compiler from
// fusing them) or, where the build has FMA (then the compiler may fuse the decode's multiply-add), fused;
// `lower`: the smaller of the two, else the larger. (Without __FMA__ no code of the build can fuse: the
// AVX2 kernels' target attribute leaves FMA out; std::fma would be a slow library call here.)
float decodedBound(float from, float sign, float step, int v, bool lower) {
    volatile float product = float(v) * step;
    const float separate = from + sign * product;
#if defined(__FMA__)
    const float fused = std::fma(sign * float(v), step, from);
    return lower ? std::min(separate, fused) : std::max(separate, fused);
#else
    (void)lower;
    return separate;
#endif
}
}  // namespace

void quantizeQuad(const Bounds3* b, const Bounds3& frame, SubpatchQuad& q) {
    // An empty box (lo > hi on an axis) is stored as the frame's low corner (as a displaced leaf without
    // triangles, a point).
    bool empty[4];
    for (int c = 0; c < 4; ++c)
        empty[c] = !(b[c].lo.x <= b[c].hi.x && b[c].lo.y <= b[c].hi.y && b[c].lo.z <= b[c].hi.z);
    for (int a = 0; a < 3; ++a) {
        float lo = frame.lo[a], hi = frame.hi[a];
        for (int c = 0; c < 4; ++c)
            if (!empty[c]) lo = std::min(lo, b[c].lo[a]), hi = std::max(hi, b[c].hi[a]);
        if (!(lo <= hi)) lo = hi = 0.f;
        if (!std::isfinite((hi - lo) * (1.f / 255.f))) {  // astronomically large: a frame of finite steps
            lo = std::max(lo, -std::numeric_limits<float>::max() / 2),
            hi = std::min(hi, std::numeric_limits<float>::max() / 2);
        }
        q.frameLo[a] = lo, q.frameHi[a] = hi;
        const float step = q.step(a), inv = step > 0.f ? 1.f / step : 0.f;
#if defined(__SSE2__) && !defined(__FMA__)
        // The four boxes at once (the forest build's hot loop), as the scalar loop below: rounded down,
        // then stepped back while a decode (product and sum rounded separately: no FMA in this build)
        // passes the bound; at 0 steps a decode is the frame's end, which always holds.
        if (!(empty[0] || empty[1] || empty[2] || empty[3]) && step > 0.f) {
            const __m128 blo = _mm_setr_ps(b[0].lo[a], b[1].lo[a], b[2].lo[a], b[3].lo[a]);
            const __m128 bhi = _mm_setr_ps(b[0].hi[a], b[1].hi[a], b[2].hi[a], b[3].hi[a]);
            const __m128 lo4 = _mm_set1_ps(lo), hi4 = _mm_set1_ps(hi), st = _mm_set1_ps(step);
            const __m128 iv = _mm_set1_ps(inv), zero = _mm_setzero_ps(), top = _mm_set1_ps(255.f);
            __m128i up =
                _mm_cvttps_epi32(_mm_min_ps(_mm_max_ps(_mm_mul_ps(_mm_sub_ps(blo, lo4), iv), zero), top));
            __m128i down =
                _mm_cvttps_epi32(_mm_min_ps(_mm_max_ps(_mm_mul_ps(_mm_sub_ps(hi4, bhi), iv), zero), top));
            bool done = false;
            for (int pass = 0; pass < 4 && !done; ++pass) {
                const __m128 decLo = _mm_add_ps(lo4, _mm_mul_ps(_mm_cvtepi32_ps(up), st));
                const __m128 decHi = _mm_sub_ps(hi4, _mm_mul_ps(_mm_cvtepi32_ps(down), st));
                const __m128i badLo = _mm_castps_si128(_mm_cmpgt_ps(decLo, blo));  // all ones: one step back
                const __m128i badHi = _mm_castps_si128(_mm_cmplt_ps(decHi, bhi));
                done = _mm_movemask_epi8(_mm_or_si128(badLo, badHi)) == 0;
                up = _mm_add_epi32(up, badLo), down = _mm_add_epi32(down, badHi);
            }
            if (done) {
                alignas(16) int32_t u[4], d[4];
                _mm_store_si128(reinterpret_cast<__m128i*>(u), up);
                _mm_store_si128(reinterpret_cast<__m128i*>(d), down);
                for (int c = 0; c < 4; ++c) q.lo[a][c] = uint8_t(u[c]), q.hi[a][c] = uint8_t(d[c]);
                continue;
            }
        }
#endif
        for (int c = 0; c < 4; ++c) {
            int up = 0, down = empty[c] ? 255 : 0;  // from the frame's ends: decoded exactly
            if (!empty[c] && step > 0.f) {
                // Rounded down (the truncation of a number >= 0), then checked as a decode rounds.
                up = int(std::clamp((b[c].lo[a] - lo) * inv, 0.f, 255.f));
                down = int(std::clamp((hi - b[c].hi[a]) * inv, 0.f, 255.f));
                while (up > 0 && decodedBound(lo, 1.f, step, up, false) > b[c].lo[a]) --up;
                while (down > 0 && decodedBound(hi, -1.f, step, down, true) < b[c].hi[a]) --down;
            }
            q.lo[a][c] = uint8_t(up), q.hi[a][c] = uint8_t(down);
        }
    }
}

namespace {
// Time slabs of a blurred frame (SubpatchForest::slabCount): the timeline's segments in equal runs, as
// many slabs as `maxSlabs` and the memory budget allow; none for a static frame or a single slab.
void planTimeSlabs(SubpatchForest& f, std::span<const BezierPatch> patches, const FrameMotion* motion,
                   int maxSlabs, size_t budgetBytes) {
    f.slabCount = 0;
    f.slabOfSegment.clear(), f.slabKnots.clear(), f.slabPatch.clear(), f.slabQuads.clear();
    f.slabRoots.clear();
    if (!motion || motion->knotCount() < 3 || maxSlabs < 2) return;
    uint32_t moving = 0;
    f.slabPatch.assign(patches.size(), SubpatchForest::kNoSlabs);
    for (size_t i = 0; i < patches.size(); ++i)
        if (motion->moving(i)) f.slabPatch[i] = moving++;
    const int segments = motion->knotCount() - 1;
    const size_t perSlab = std::max<size_t>(1, size_t(moving) * f.quadsPerPatch * sizeof(SubpatchQuad));
    const int slabs = int(std::min<size_t>({size_t(maxSlabs), size_t(segments), budgetBytes / perSlab}));
    if (moving == 0 || slabs < 2) {
        f.slabPatch.clear();
        return;
    }
    const int perRun = (segments + slabs - 1) / slabs;
    f.slabCount = (segments + perRun - 1) / perRun;
    for (int k = 0; k < segments; ++k) f.slabOfSegment.push_back(uint8_t(k / perRun));
    for (int s = 0; s < f.slabCount; ++s) f.slabKnots.push_back(uint32_t(s * perRun));
    f.slabKnots.push_back(uint32_t(segments));
    f.slabQuads.resize(size_t(moving) * f.slabCount * f.quadsPerPatch);
    f.slabRoots.resize(size_t(moving) * f.slabCount);
}

// The quads of one tree (levels 2, 4, ...: node n's grandchildren 4n+3 .. 4n+6) from its boxes, top down:
// each quad quantized in the frame of its node's box as decoded (the root's is exact), so that every
// decoded box lies inside its parent's.
void writeQuads(const Bounds3* bx, int depth, SubpatchQuad* q) {
    thread_local std::vector<Bounds3> decoded;
    decoded.resize((2u << depth) - 1u);
    decoded[0] = bx[0];
    for (uint32_t first = 0, k = 0; 2 * k + 2 <= uint32_t(depth); ++k, first = 4 * first + 3) {
        const bool framesBelow = 2 * k + 4 <= uint32_t(depth);  // the grandchildren have quads
        for (uint32_t n = first; n <= 2 * first; ++n, ++q) {
            quantizeQuad(&bx[4 * n + 3], decoded[n], *q);
            if (framesBelow)
                for (int c = 0; c < 4; ++c) decoded[4 * n + 3 + c] = q->box(c);
        }
    }
}

// What the forest keeps of tree `tree`'s boxes `bx` (all its nodes): the quads, the root and, for an odd
// depth, the leaves.
void storeTree(SubpatchForest& f, size_t tree, const Bounds3* bx) {
    writeQuads(bx, f.depth, f.quads.data() + tree * f.quadsPerPatch);
    f.roots[tree] = bx[0];
    if (f.depth & 1)
        std::copy(bx + f.firstLeaf(), bx + f.nodesPerPatch, f.oddLeaves.data() + (tree << f.depth));
}
}  // namespace

void buildSubpatchForest(std::span<const BezierPatch> patches, int depth, SubpatchForest& f,
                         bool backfaceFromOrigin, std::span<const uint8_t> flip, const FrameMotion* motion,
                         int maxSlabs, size_t slabBudgetBytes, std::span<const PlacedQuadric* const> quadrics,
                         bool leafSlabs) {
    depth = std::clamp(depth, 0, kMaxSubpatchDepth);
    f.depth = depth;
    f.nodesPerPatch = (2u << depth) - 1u;
    f.roots.resize(patches.size());
    f.oddLeaves.clear();
    if (depth & 1) f.oddLeaves.resize(patches.size() << depth);
    f.backfacing.clear();
    if (backfaceFromOrigin) f.backfacing.assign(patches.size() * f.nodesPerPatch, 0);
    f.quadsPerPatch = ((1u << (2 * (depth / 2))) - 1u) / 3u;
    f.quads.resize(patches.size() * f.quadsPerPatch);
    f.quadBack.clear();
    if (backfaceFromOrigin) f.quadBack.assign(f.quads.size(), 0);
    f.knotLeaves.clear();
    if (motion) f.knotLeaves.resize(motion->keys.size() << depth);
    planTimeSlabs(f, patches, motion, maxSlabs, slabBudgetBytes);
    const uint32_t leaves = 1u << depth;
    f.leafSlabs.clear();
    if (leafSlabs) f.leafSlabs.resize(patches.size() * f.slabGroupsPerTree());
    f.leafCentre.resize(leaves);
    f.leafBasis.resize(leaves);
    f.quarterBasis.resize(4 * size_t(leaves));
    for (uint32_t l = 0; l < leaves; ++l) {
        float u0, u1, v0, v1;
        subpatchLeafRect(depth, l, u0, u1, v0, v1);
        f.leafCentre[l] = {0.5f * (u0 + u1), 0.5f * (v0 + v1)};
        // Control point k of the cubic on [a, b] is the blossom f(a, .., b, ..) with 3 - k a's: de
        // Casteljau of each unit basis vector with the parameters a^(3-k) b^k (exact in double).
        auto basis = [](double a, double b, float m[4][4], bool rows) {
            for (int src = 0; src < 4; ++src)
                for (int k = 0; k < 4; ++k) {
                    double c[4] = {0, 0, 0, 0};
                    c[src] = 1;
                    for (int s = 0; s < 3; ++s) {
                        const double t = s < 3 - k ? a : b;
                        for (int q = 0; q < 3 - s; ++q) c[q] = (1 - t) * c[q] + t * c[q + 1];
                    }
                    (rows ? m[k][src] : m[src][k]) = float(c[0]);
                }
        };
        basis(u0, u1, f.leafBasis[l].mu, false);
        basis(v0, v1, f.leafBasis[l].mv, true);
        splatRows(f.leafBasis[l]);
        const double um = 0.5 * (double(u0) + u1), vm = 0.5 * (double(v0) + v1);
        for (int q = 0; q < 4; ++q) {
            LeafBasis& b = f.quarterBasis[4 * l + q];
            basis((q & 1) ? um : u0, (q & 1) ? u1 : um, b.mu, false);
            basis((q & 2) ? vm : v0, (q & 2) ? v1 : vm, b.mv, true);
            splatRows(b);
        }
    }
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, patches.size(), 16), [&](const tbb::blocked_range<size_t>& r) {
            TreeBuilder tb(depth);  // scratch grid, reused over the range
            std::vector<Bounds3> treeBoxes(f.nodesPerPatch), knotBoxes, slabBoxes;
            for (size_t i = r.begin(); i != r.end(); ++i) {
                uint8_t* back = backfaceFromOrigin ? f.backfacing.data() + i * f.nodesPerPatch : nullptr;
                float sign = (!flip.empty() && flip[i]) ? -1.f : 1.f;
                Bounds3* boxes = treeBoxes.data();
                const size_t groups = f.slabGroupsPerTree();
                LeafSlab4* treeSlabs = leafSlabs ? f.leafSlabs.data() + i * groups : nullptr;
                if (treeSlabs && depth < 2) openSlabs(treeSlabs, groups);  // the lanes past the tree's leaves
                const PlacedQuadric* quadric = quadrics.empty() ? nullptr : quadrics[i];
                if (quadric) {
                    // The leaves' boxes, then every inner box the union of its children's (as for patches).
                    for (uint32_t j = 0; j < (1u << depth); ++j) {
                        float u0, u1, v0, v1;
                        subpatchLeafRect(depth, j, u0, u1, v0, v1);
                        const Bounds3 ob = quadricBounds(quadric->q, u0, u1, v0, v1);
                        BezierPatch corners;  // the box's corners in the patches' space
                        for (int c = 0; c < 16; ++c)
                            corners.cp[c] = affinePoint(quadric->toSpace,
                                                        {c & 1 ? ob.hi.x : ob.lo.x, c & 2 ? ob.hi.y : ob.lo.y,
                                                         c & 4 ? ob.hi.z : ob.lo.z});
                        boxes[(1u << depth) - 1 + j] = enlargedHull(corners);
                    }
                    for (uint32_t nd = (1u << depth) - 1; nd-- > 0;) {
                        boxes[nd] = boxes[2 * nd + 1];
                        boxes[nd].extend(boxes[2 * nd + 2]);
                    }
                    if (treeSlabs) openSlabs(treeSlabs, groups);
                } else {
                    tb.build(patches[i], boxes, back, sign, treeSlabs);
                }
                if (motion && motion->moving(i)) {
                    // Swept boxes: the union over the knots (knot 0 is patches[i]); the leaves per knot.
                    knotBoxes.resize(f.nodesPerPatch);
                    const BezierPatch* keys = motion->patchKeys(i);
                    const uint32_t leaves = 1u << depth, first = f.firstLeaf();
                    Bounds3* kl = f.knotLeaves.data() + (size_t(motion->firstKey[i]) << depth);
                    std::copy(boxes + first, boxes + first + leaves, kl);
                    // Per slab, the union of its knots' trees (knot 0 is in slab 0, a knot between two
                    // slabs in both).
                    const int slabs = f.slabCount;
                    slabBoxes.assign(size_t(slabs) * f.nodesPerPatch, Bounds3());
                    auto addToSlabs = [&](int k, const Bounds3* tree) {
                        for (int sl = 0; sl < slabs; ++sl) {
                            if (uint32_t(k) < f.slabKnots[sl] || uint32_t(k) > f.slabKnots[sl + 1]) continue;
                            Bounds3* sb = slabBoxes.data() + size_t(sl) * f.nodesPerPatch;
                            for (uint32_t nd = 0; nd < f.nodesPerPatch; ++nd) sb[nd].extend(tree[nd]);
                        }
                    };
                    addToSlabs(0, boxes);
                    for (int k = 1; k < motion->knotCount(); ++k) {
                        tb.build(keys[k], knotBoxes.data(), nullptr, sign);
                        std::copy(knotBoxes.data() + first, knotBoxes.data() + first + leaves,
                                  kl + k * leaves);
                        addToSlabs(k, knotBoxes.data());
                        for (uint32_t nd = 0; nd < f.nodesPerPatch; ++nd) boxes[nd].extend(knotBoxes[nd]);
                    }
                    for (int sl = 0; sl < slabs; ++sl) {
                        const Bounds3* sb = slabBoxes.data() + size_t(sl) * f.nodesPerPatch;
                        const size_t at = size_t(f.slabPatch[i]) * slabs + sl;
                        writeQuads(sb, depth, f.slabQuads.data() + at * f.quadsPerPatch);
                        f.slabRoots[at] = sb[0];
                    }
                    if (back) std::fill(back, back + f.nodesPerPatch, uint8_t(0));
                    if (treeSlabs) openSlabs(treeSlabs, groups);  // the slabs hold knot 0 only
                }
                storeTree(f, i, boxes);
                if (!backfaceFromOrigin) continue;
                uint8_t* qb = f.quadBack.data() + i * f.quadsPerPatch;
                for (uint32_t first = 0, k = 0; 2 * k + 2 <= uint32_t(depth); ++k, first = 4 * first + 3)
                    for (uint32_t n = first; n <= 2 * first; ++n) {  // the 4^k nodes of level 2k
                        uint8_t bits = 0;
                        for (uint32_t c = 0; c < 4; ++c)
                            if (back[4 * n + 3 + c] || back[2 * n + 1 + (c >> 1)]) bits |= uint8_t(1u << c);
                        *qb++ = bits;
                    }
            }
        });
}

void setSubpatchLeafBoxes(SubpatchForest& f, uint32_t patch, std::span<const Bounds3> leaves) {
    std::vector<Bounds3> tree(f.nodesPerPatch);
    for (uint32_t n = 0; n < f.nodesPerPatch; ++n)
        tree[n] = f.nodeBox(patch, n);  // leaves not given keep theirs
    Bounds3* boxes = tree.data();
    const uint32_t first = f.firstLeaf();
    for (uint32_t l = 0; l < leaves.size() && first + l < f.nodesPerPatch; ++l) boxes[first + l] = leaves[l];
    for (uint32_t n = first; n-- > 0;) {
        boxes[n] = boxes[2 * n + 1];
        boxes[n].extend(boxes[2 * n + 2]);
    }
    storeTree(f, patch, boxes);
    if (!f.leafSlabs.empty())
        openSlabs(f.leafSlabs.data() + size_t(patch) * f.slabGroupsPerTree(), f.slabGroupsPerTree());
    if (!f.backfacing.empty())
        std::fill_n(f.backfacing.data() + size_t(patch) * f.nodesPerPatch, f.nodesPerPatch, uint8_t(0));
    if (!f.quadBack.empty())
        std::fill_n(f.quadBack.data() + size_t(patch) * f.quadsPerPatch, f.quadsPerPatch, uint8_t(0));
}

}  // namespace tessera
