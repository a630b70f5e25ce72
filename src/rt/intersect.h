// Ray / bicubic patch intersection by Newton iteration (Martin et al. 2000, "Practical ray tracing of
// trimmed NURBS surfaces", sec. 3): the ray is the intersection of two planes (n1,d1), (n2,d2) and the
// root of R(u,v) = (n1.Q(u,v) + d1, n2.Q(u,v) + d2) is found from an initial guess given by a subpatch
// leaf. Plain functions over plain data: no globals, no allocation.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>
#if defined(__SSE2__)
#include <immintrin.h>
#endif

#include "core/bezier.h"
#include "core/hostdevice.h"
#include "rt/subpatch_tree.h"

namespace tessera {

struct Ray {
    Vec3 o, d;  // d need not be unit length; t is measured in units of d
    float tmin = 0.f, tmax = std::numeric_limits<float>::infinity();
};

struct RayPlanes {
    Vec3 n1, n2;
    float d1 = 0, d2 = 0;
};

// Two orthogonal unit planes whose intersection is the ray's line.
__attribute__((always_inline)) inline RayPlanes makeRayPlanes(Vec3 o, Vec3 d) {
    RayPlanes p;
    Vec3 n1 = (std::fabs(d.x) > std::fabs(d.y) && std::fabs(d.x) > std::fabs(d.z)) ? Vec3{d.y, -d.x, 0.f}
                                                                                   : Vec3{0.f, d.z, -d.y};
    n1 = normalize(n1);
    Vec3 n2 = normalize(cross(n1, d));
    p.n1 = n1;
    p.n2 = n2;
    p.d1 = -dot(n1, o);
    p.d2 = -dot(n2, o);
    return p;
}

// Reciprocal direction for slab tests; zero components become huge finite values (no 0 * inf NaNs).
TESSERA_HD Vec3 safeInverse(Vec3 d) {
    auto inv = [](float x) { return std::fabs(x) > 1e-30f ? 1.f / x : (x >= 0.f ? 1e30f : -1e30f); };
    return {inv(d.x), inv(d.y), inv(d.z)};
}

// Slab test; on a hit returns the entry and exit distances (clamped to [tmin, tmax]). Plain compares
// (minss/maxss), no initializer lists: this is the traversal's inner kernel.
TESSERA_HD bool rayBoxInterval(const Bounds3& b, const Vec3& o, const Vec3& inv, float tmin, float tmax,
                               float& tEnter, float& tExit) {
    const float tx0 = (b.lo.x - o.x) * inv.x, tx1 = (b.hi.x - o.x) * inv.x;
    const float ty0 = (b.lo.y - o.y) * inv.y, ty1 = (b.hi.y - o.y) * inv.y;
    const float tz0 = (b.lo.z - o.z) * inv.z, tz1 = (b.hi.z - o.z) * inv.z;
    // std::min/std::max map to minss/maxss (no branches).
    float t0 = std::max(std::max(std::min(tx0, tx1), std::min(ty0, ty1)), std::max(std::min(tz0, tz1), tmin));
    float t1 = std::min(std::min(std::max(tx0, tx1), std::max(ty0, ty1)), std::min(std::max(tz0, tz1), tmax));
    tEnter = t0;
    tExit = t1;
    return t0 <= t1;
}

TESSERA_HD bool rayBox(const Bounds3& b, Vec3 o, Vec3 inv, float tmin, float tmax, float& tEnter) {
    float tExit;
    return rayBoxInterval(b, o, inv, tmin, tmax, tEnter, tExit);
}

// Slab test of two adjacent boxes b[0], b[1] (the two children of a subpatch node). Returns bit 0 / bit 1
// when the ray hits b[0] / b[1], with entry and exit distances in te[], tx[] (same arithmetic as
// rayBoxInterval). With GCC the 12 floats are processed 4-wide.
struct PairRay {
#if defined(__GNUC__) && !defined(__clang__)
    typedef float f4 __attribute__((vector_size(16)));
    f4 o0, o1, o2, i0, i1, i2;  // o and 1/d in the lane order of three consecutive 4-float loads
#endif
    Vec3 o, inv;
    PairRay(Vec3 o_, Vec3 inv_) : o(o_), inv(inv_) {
#if defined(__GNUC__) && !defined(__clang__)
        o0 = f4{o.x, o.y, o.z, o.x}, o1 = f4{o.y, o.z, o.x, o.y}, o2 = f4{o.z, o.x, o.y, o.z};
        i0 = f4{inv.x, inv.y, inv.z, inv.x}, i1 = f4{inv.y, inv.z, inv.x, inv.y};
        i2 = f4{inv.z, inv.x, inv.y, inv.z};
#endif
    }
};

inline int rayBoxPair(const Bounds3* b, const PairRay& r, float tmin, float tmax, float te[2], float tx[2]) {
#if defined(__GNUC__) && !defined(__clang__)
    static_assert(sizeof(Bounds3) == 24);
    typedef float f4 __attribute__((vector_size(16)));
    typedef int i4 __attribute__((vector_size(16)));
    f4 v0, v1, v2;
    const float* f = &b[0].lo.x;
    __builtin_memcpy(&v0, f, 16);
    __builtin_memcpy(&v1, f + 4, 16);
    __builtin_memcpy(&v2, f + 8, 16);
    // v0 = (A.lo.x A.lo.y A.lo.z A.hi.x), v1 = (A.hi.y A.hi.z B.lo.x B.lo.y), v2 = (B.lo.z B.hi.x B.hi.y
    // B.hi.z)
    const f4 t0 = (v0 - r.o0) * r.i0, t1 = (v1 - r.o1) * r.i1, t2 = (v2 - r.o2) * r.i2;
    const f4 lo = __builtin_shuffle(t0, t1, i4{0, 1, 6, 7});  // A.x A.y B.x B.y (lo planes)
    const f4 m = __builtin_shuffle(t0, t1, i4{3, 4, 2, 5});
    const f4 hi = __builtin_shuffle(m, t2, i4{0, 1, 5, 6});  // A.x A.y B.x B.y (hi planes)
    const f4 z = __builtin_shuffle(m, t2, i4{2, 3, 4, 7});   // A.zlo A.zhi B.zlo B.zhi
    const f4 zs = __builtin_shuffle(z, i4{1, 0, 3, 2});
    const f4 nxy = lo < hi ? lo : hi, fxy = lo < hi ? hi : lo;
    const f4 nz = z < zs ? z : zs, fz = z < zs ? zs : z;
    const f4 nxys = __builtin_shuffle(nxy, i4{1, 0, 3, 2}), fxys = __builtin_shuffle(fxy, i4{1, 0, 3, 2});
    f4 n = nxy > nxys ? nxy : nxys, x = fxy < fxys ? fxy : fxys;
    n = n > nz ? n : nz;
    x = x < fz ? x : fz;
    const f4 vmin = f4{tmin, tmin, tmin, tmin}, vmax = f4{tmax, tmax, tmax, tmax};
    n = n > vmin ? n : vmin;
    x = x < vmax ? x : vmax;
    te[0] = n[0], te[1] = n[2], tx[0] = x[0], tx[1] = x[2];
    return (n[0] <= x[0] ? 1 : 0) | (n[2] <= x[2] ? 2 : 0);
#else
    return (rayBoxInterval(b[0], r.o, r.inv, tmin, tmax, te[0], tx[0]) ? 1 : 0) |
           (rayBoxInterval(b[1], r.o, r.inv, tmin, tmax, te[1], tx[1]) ? 2 : 0);
#endif
}

struct NewtonParams {
    float epsR;               // residual tolerance (world units)
    float domainTol = 1e-4f;  // accepted distance of the root outside [0,1]^2 (then clamped)
};

struct PatchHit {
    float t = std::numeric_limits<float>::infinity();
    float u = 0, v = 0;
    Vec3 p, dpdu, dpdv;  // at the root (dpdu x dpdv may vanish at a collapsed edge)
    // A displaced patch's micro-grid hit (rt/displaced.h): the unit shading normal interpolated from the
    // displaced vertices, orientation applied (zero for every other hit).
    Vec3 ns;
    int iterations = 0;
    bool hit = false;
};

// Residual tolerance for a patch whose box is `box`, seen from ray origin o: a few float ulps of the
// magnitudes involved (the residual n.Q + d cancels terms of size |Q| and |o|).
TESSERA_HD float newtonTolerance(const Bounds3& box, Vec3 o) {
    float mag = 0;
    for (int k = 0; k < 3; ++k)
        mag = std::max({mag, std::fabs(box.lo[k]), std::fabs(box.hi[k]), std::fabs(o[k])});
    return 2e-6f * mag + 1e-6f * maxComponent(box.diagonal()) + 1e-30f;
}

// The 16 control points projected on the ray's two planes: R(u,v) = (sum a1 B B, sum a2 B B). Computed once
// per (ray, patch) and shared by all the Newton starts of that pair.
template <class T>
struct alignas(16) ProjectedPatch {
    T a1[16], a2[16];  // row-major like BezierPatch::cp: [4 * j + i], u index i
};

template <class T>
TESSERA_HD void projectPatch(const BezierPatch& patch, const T n1[3], const T n2[3], T d1, T d2,
                             ProjectedPatch<T>& pp) {
    for (int k = 0; k < 16; ++k) {
        const Vec3& c = patch.cp[k];
        pp.a1[k] = n1[0] * T(c.x) + n1[1] * T(c.y) + n1[2] * T(c.z) + d1;
        pp.a2[k] = n2[0] * T(c.x) + n2[1] * T(c.y) + n2[2] * T(c.z) + d2;
    }
}

TESSERA_HD void projectPatch(const BezierPatch& patch, const RayPlanes& pl, ProjectedPatch<float>& pp) {
    const float n1[3] = {pl.n1.x, pl.n1.y, pl.n1.z}, n2[3] = {pl.n2.x, pl.n2.y, pl.n2.z};
    projectPatch<float>(patch, n1, n2, pl.d1, pl.d2, pp);
}

// R = (r1, r2) and its Jacobian [j11 j12; j21 j22] (columns d/du, d/dv) at (u, v): scalar reference.
template <class T>
TESSERA_HD void evalProjected(const ProjectedPatch<T>& pp, T u, T v, T& r1, T& r2, T& j11, T& j12, T& j21,
                              T& j22) {
    T bu[4], bv[4], du[4], dv[4];
    T s = 1 - u, t = u;
    bu[0] = s * s * s, bu[1] = 3 * t * s * s, bu[2] = 3 * t * t * s, bu[3] = t * t * t;
    du[0] = -3 * s * s, du[1] = 3 * s * s - 6 * t * s, du[2] = 6 * t * s - 3 * t * t, du[3] = 3 * t * t;
    s = 1 - v, t = v;
    bv[0] = s * s * s, bv[1] = 3 * t * s * s, bv[2] = 3 * t * t * s, bv[3] = t * t * t;
    dv[0] = -3 * s * s, dv[1] = 3 * s * s - 6 * t * s, dv[2] = 6 * t * s - 3 * t * t, dv[3] = 3 * t * t;
    r1 = r2 = j11 = j12 = j21 = j22 = 0;
    for (int j = 0; j < 4; ++j) {
        const T* p1 = pp.a1 + 4 * j;
        const T* p2 = pp.a2 + 4 * j;
        T c1 = p1[0] * bu[0] + p1[1] * bu[1] + p1[2] * bu[2] + p1[3] * bu[3];
        T c2 = p2[0] * bu[0] + p2[1] * bu[1] + p2[2] * bu[2] + p2[3] * bu[3];
        T e1 = p1[0] * du[0] + p1[1] * du[1] + p1[2] * du[2] + p1[3] * du[3];
        T e2 = p2[0] * du[0] + p2[1] * du[1] + p2[2] * du[2] + p2[3] * du[3];
        r1 += c1 * bv[j], r2 += c2 * bv[j];
        j11 += e1 * bv[j], j21 += e2 * bv[j];
        j12 += c1 * dv[j], j22 += c2 * dv[j];
    }
}

#if defined(__GNUC__) && !defined(__clang__)
// Float: 4-wide (GCC vector extensions, SSE2 at least). Rows of the projected net are weighted by the v
// basis first (vectors over the u index), then dotted with the u basis; the six dot products are
// reduced together. Same polynomial as the scalar version, different summation order.
namespace rtsimd {
typedef float f4 __attribute__((vector_size(16)));
typedef int i4 __attribute__((vector_size(16)));
inline f4 load4(const float* p) {
    f4 v;
    __builtin_memcpy(&v, p, sizeof(v));
    return v;
}
inline f4 splat(float x) {
    return f4{x, x, x, x};
}
// (sum of a, sum of b, sum of c, sum of d)
inline f4 hsum4(f4 a, f4 b, f4 c, f4 d) {
    const f4 ab = __builtin_shuffle(a, b, i4{0, 4, 1, 5}) + __builtin_shuffle(a, b, i4{2, 6, 3, 7});
    const f4 cd = __builtin_shuffle(c, d, i4{0, 4, 1, 5}) + __builtin_shuffle(c, d, i4{2, 6, 3, 7});
    return __builtin_shuffle(ab, cd, i4{0, 1, 4, 5}) + __builtin_shuffle(ab, cd, i4{2, 3, 6, 7});
}
}  // namespace rtsimd

inline void evalProjected(const ProjectedPatch<float>& pp, float u, float v, float& r1, float& r2, float& j11,
                          float& j12, float& j21, float& j22) {
    using namespace rtsimd;
    float s = 1 - u, t = u;
    const f4 BU = {s * s * s, 3 * t * s * s, 3 * t * t * s, t * t * t};
    const f4 DU = {-3 * s * s, 3 * s * s - 6 * t * s, 6 * t * s - 3 * t * t, 3 * t * t};
    s = 1 - v, t = v;
    const f4 bv0 = splat(s * s * s), bv1 = splat(3 * t * s * s), bv2 = splat(3 * t * t * s),
             bv3 = splat(t * t * t);
    const f4 dv0 = splat(-3 * s * s), dv1 = splat(3 * s * s - 6 * t * s), dv2 = splat(6 * t * s - 3 * t * t),
             dv3 = splat(3 * t * t);
    const f4 p0 = load4(pp.a1), p1 = load4(pp.a1 + 4), p2 = load4(pp.a1 + 8), p3 = load4(pp.a1 + 12);
    const f4 q0 = load4(pp.a2), q1 = load4(pp.a2 + 4), q2 = load4(pp.a2 + 8), q3 = load4(pp.a2 + 12);
    const f4 S1 = (p0 * bv0 + p1 * bv1) + (p2 * bv2 + p3 * bv3);
    const f4 T1 = (p0 * dv0 + p1 * dv1) + (p2 * dv2 + p3 * dv3);
    const f4 S2 = (q0 * bv0 + q1 * bv1) + (q2 * bv2 + q3 * bv3);
    const f4 T2 = (q0 * dv0 + q1 * dv1) + (q2 * dv2 + q3 * dv3);
    const f4 A = hsum4(S1 * BU, S2 * BU, S1 * DU, S2 * DU);
    const f4 B = hsum4(T1 * BU, T2 * BU, T1 * BU, T2 * BU);
    r1 = A[0], r2 = A[1], j11 = A[2], j21 = A[3];
    j12 = B[0], j22 = B[1];
}
#endif

// Ray-frame hull test of one leaf: the leaf sub-patch's projected Bernstein coefficients (pp mapped by the
// leaf's change of basis) bound R over the leaf (convex hull property). Returns false when r1 or r2 keeps
// one sign beyond `margin` on all 16 coefficients: then |R| > margin on the whole leaf and no Newton
// iterate inside it can converge (|R| < eps <= margin). Exact up to float rounding of the coefficients,
// which the margin covers (a few ulps of the coefficients; the caller passes 4 eps).
inline bool leafMayHit(const ProjectedPatch<float>& pp, const LeafBasis& lb, float margin) {
#if defined(__SSE2__)
    // Rows first (mv, stored splatted), then columns (mu rows times lane splats of the row).
    auto mv = [&](int j, int k) { return _mm_load_ps(lb.mvSplat[j][k]); };
    const __m128 mu0 = _mm_load_ps(lb.mu[0]), mu1 = _mm_load_ps(lb.mu[1]), mu2 = _mm_load_ps(lb.mu[2]),
                 mu3 = _mm_load_ps(lb.mu[3]);
    auto plane = [&](const float* a, __m128& lo, __m128& hi) {
        const __m128 a0 = _mm_load_ps(a), a1 = _mm_load_ps(a + 4), a2 = _mm_load_ps(a + 8),
                     a3 = _mm_load_ps(a + 12);
        for (int j = 0; j < 4; ++j) {
            const __m128 r = _mm_add_ps(_mm_add_ps(_mm_mul_ps(mv(j, 0), a0), _mm_mul_ps(mv(j, 1), a1)),
                                        _mm_add_ps(_mm_mul_ps(mv(j, 2), a2), _mm_mul_ps(mv(j, 3), a3)));
            const __m128 c = _mm_add_ps(_mm_add_ps(_mm_mul_ps(_mm_shuffle_ps(r, r, 0x00), mu0),
                                                   _mm_mul_ps(_mm_shuffle_ps(r, r, 0x55), mu1)),
                                        _mm_add_ps(_mm_mul_ps(_mm_shuffle_ps(r, r, 0xaa), mu2),
                                                   _mm_mul_ps(_mm_shuffle_ps(r, r, 0xff), mu3)));
            lo = j == 0 ? c : _mm_min_ps(lo, c);
            hi = j == 0 ? c : _mm_max_ps(hi, c);
        }
    };
    // One plane at a time: most rejected leaves are rejected by the first.
    auto rejects = [&](const float* a) {
        __m128 lo, hi;
        plane(a, lo, hi);
        // (min lo, -max hi) > margin in either: the plane separates the leaf from the ray.
        const __m128 x = _mm_unpacklo_ps(lo, _mm_xor_ps(hi, _mm_set1_ps(-0.f)));  // lo0 -hi0 lo1 -hi1
        const __m128 y = _mm_unpackhi_ps(lo, _mm_xor_ps(hi, _mm_set1_ps(-0.f)));  // lo2 -hi2 lo3 -hi3
        const __m128 m1 = _mm_min_ps(x, y);
        const __m128 m = _mm_min_ps(m1, _mm_movehl_ps(m1, m1));  // lanes 0, 1: min lo, -max hi
        return (_mm_movemask_ps(_mm_cmpgt_ps(m, _mm_set1_ps(margin))) & 3) != 0;
    };
    return !rejects(pp.a1) && !rejects(pp.a2);
#else
    float min1 = INFINITY, min2 = INFINITY, max1 = -INFINITY, max2 = -INFINITY;
    for (int j = 0; j < 4; ++j)
        for (int i = 0; i < 4; ++i) {
            float c1 = 0, c2 = 0;
            for (int jj = 0; jj < 4; ++jj)
                for (int ii = 0; ii < 4; ++ii) {
                    const float w = lb.mv[j][jj] * lb.mu[ii][i];
                    c1 += w * pp.a1[4 * jj + ii], c2 += w * pp.a2[4 * jj + ii];
                }
            min1 = std::min(min1, c1), max1 = std::max(max1, c1);
            min2 = std::min(min2, c2), max2 = std::max(max2, c2);
        }
    return !(min1 > margin || min2 > margin || max1 < -margin || max2 < -margin);
#endif
}

// The 16 Bernstein coefficients over one leaf (row j: the v index, entry i: the u index) of a scalar
// function given by its 16 coefficients over the patch (row-major like ProjectedPatch), mapped by the
// leaf's change of basis.
TESSERA_HD void leafCoefficients(const float a[16], const LeafBasis& lb, float c[16]) {
#if defined(__SSE2__)
    const __m128 a0 = _mm_loadu_ps(a), a1 = _mm_loadu_ps(a + 4), a2 = _mm_loadu_ps(a + 8),
                 a3 = _mm_loadu_ps(a + 12);
    const __m128 mu0 = _mm_load_ps(lb.mu[0]), mu1 = _mm_load_ps(lb.mu[1]), mu2 = _mm_load_ps(lb.mu[2]),
                 mu3 = _mm_load_ps(lb.mu[3]);
    for (int j = 0; j < 4; ++j) {
        const __m128 r = _mm_add_ps(_mm_add_ps(_mm_mul_ps(_mm_load_ps(lb.mvSplat[j][0]), a0),
                                               _mm_mul_ps(_mm_load_ps(lb.mvSplat[j][1]), a1)),
                                    _mm_add_ps(_mm_mul_ps(_mm_load_ps(lb.mvSplat[j][2]), a2),
                                               _mm_mul_ps(_mm_load_ps(lb.mvSplat[j][3]), a3)));
        _mm_storeu_ps(c + 4 * j, _mm_add_ps(_mm_add_ps(_mm_mul_ps(_mm_shuffle_ps(r, r, 0x00), mu0),
                                                       _mm_mul_ps(_mm_shuffle_ps(r, r, 0x55), mu1)),
                                            _mm_add_ps(_mm_mul_ps(_mm_shuffle_ps(r, r, 0xaa), mu2),
                                                       _mm_mul_ps(_mm_shuffle_ps(r, r, 0xff), mu3))));
    }
#else
    for (int j = 0; j < 4; ++j)
        for (int i = 0; i < 4; ++i) {
            float x = 0;
            for (int jj = 0; jj < 4; ++jj)
                for (int ii = 0; ii < 4; ++ii) x += lb.mv[j][jj] * lb.mu[ii][i] * a[4 * jj + ii];
            c[4 * j + i] = x;
        }
#endif
}

TESSERA_HD float maxCoefficient(const float c[16]) {
    float hi = c[0];
    for (int k = 1; k < 16; ++k) hi = std::max(hi, c[k]);
    return hi;
}

// Largest Bernstein coefficient of the four quarters of a 4x4 net: the net split at its middle in v and
// in u by de Casteljau (7 x 7 points, shared by neighbouring quarters). An upper bound of the function
// over the net's domain (convex hull property of each quarter) that is at most maxCoefficient(c) and
// tighter where the net bulges: a quarter's net lies about 4x closer to the surface.
TESSERA_HD float quartersMaxCoefficient(const float c[16]) {
#if defined(__SSE2__)
    const __m128 half = _mm_set1_ps(0.5f);
    auto mid = [&](__m128 x, __m128 y) { return _mm_mul_ps(_mm_add_ps(x, y), half); };
    // In v, across the rows: the 7 rows c0, a, l2, m (the middle), r1, e, c3.
    const __m128 c0 = _mm_loadu_ps(c), c1 = _mm_loadu_ps(c + 4), c2 = _mm_loadu_ps(c + 8),
                 c3 = _mm_loadu_ps(c + 12);
    const __m128 a = mid(c0, c1), b = mid(c1, c2), e = mid(c2, c3), l2 = mid(a, b), r1 = mid(b, e),
                 m = mid(l2, r1);
    // In u: each half's 4 rows transposed to columns, split across the columns like the rows above.
    auto splitMax = [&](__m128 x0, __m128 x1, __m128 x2, __m128 x3) {
        _MM_TRANSPOSE4_PS(x0, x1, x2, x3);
        const __m128 p = mid(x0, x1), q = mid(x1, x2), t = mid(x2, x3), pq = mid(p, q), qt = mid(q, t),
                     pm = mid(pq, qt);
        return _mm_max_ps(_mm_max_ps(_mm_max_ps(x0, p), _mm_max_ps(pq, pm)),
                          _mm_max_ps(_mm_max_ps(qt, t), x3));
    };
    __m128 hi = _mm_max_ps(splitMax(c0, a, l2, m), splitMax(m, r1, e, c3));
    hi = _mm_max_ps(hi, _mm_movehl_ps(hi, hi));
    hi = _mm_max_ss(hi, _mm_shuffle_ps(hi, hi, 0x55));
    return _mm_cvtss_f32(hi);
#else
    float rows[7][4], hi = -INFINITY;
    for (int i = 0; i < 4; ++i) {
        const float a = 0.5f * (c[i] + c[4 + i]), b = 0.5f * (c[4 + i] + c[8 + i]),
                    e = 0.5f * (c[8 + i] + c[12 + i]), l2 = 0.5f * (a + b), r1 = 0.5f * (b + e);
        const float col[7] = {c[i], a, l2, 0.5f * (l2 + r1), r1, e, c[12 + i]};
        for (int j = 0; j < 7; ++j) rows[j][i] = col[j];
    }
    for (const auto& x : rows) {
        const float p = 0.5f * (x[0] + x[1]), q = 0.5f * (x[1] + x[2]), t = 0.5f * (x[2] + x[3]),
                    pq = 0.5f * (p + q), qt = 0.5f * (q + t);
        for (const float y : {x[0], p, pq, 0.5f * (pq + qt), qt, t, x[3]}) hi = std::max(hi, y);
    }
    return hi;
#endif
}

// Largest Bernstein coefficient over one leaf of a scalar function given by its 16 coefficients over the
// patch: an upper bound of the function on the leaf (convex hull property).
TESSERA_HD float leafMaxCoefficient(const float a[16], const LeafBasis& lb) {
    float c[16];
    leafCoefficients(a, lb, c);
    return maxCoefficient(c);
}

// Newton iteration on the projected patch from (u, v) (updated in place). Stops on convergence
// (|R|inf < eps, then one free step), leaving the domain, divergence, or 16 iterations. A singular
// Jacobian (collapsed edge) nudges the iterate towards the domain centre. Returns convergence;
// `iterations` receives the number of evaluations (+1 for the free step).
template <class T>
TESSERA_HD bool newtonIterate(const ProjectedPatch<T>& pp, T eps, T& u, T& v, int& iterations) {
    const T outer = T(0.25);  // iterates may wander this far outside the domain before giving up
    T prevNorm = std::numeric_limits<T>::infinity();
    int it = 0, clamps = 0;
    bool converged = false;
    for (; it < 16; ++it) {
        T r1, r2, j11, j12, j21, j22;
        evalProjected(pp, u, v, r1, r2, j11, j12, j21, j22);
        const T ar1 = std::fabs(r1), ar2 = std::fabs(r2);
        const T norm = ar1 > ar2 ? ar1 : ar2;
        if (!(norm == norm)) break;  // NaN
        const T det = j11 * j22 - j12 * j21;
        const T aj11 = std::fabs(j11), aj12 = std::fabs(j12), aj21 = std::fabs(j21), aj22 = std::fabs(j22);
        const T ja = aj11 > aj12 ? aj11 : aj12, jb = aj21 > aj22 ? aj21 : aj22;
        const T jscale = ja > jb ? ja : jb;
        const bool singular = !(std::fabs(det) > T(1e-12) * jscale * jscale) || jscale == 0;
        if (norm < eps) {
            converged = true;
            // One more (free) Newton step: the residual is already small, so this one is quadratic and
            // brings the root to the precision floor without another convergence test.
            if (!singular) {
                const T inv = 1 / det;
                u -= (j22 * r1 - j12 * r2) * inv;
                v -= (j11 * r2 - j21 * r1) * inv;
            }
            break;
        }
        if (it >= 3 && norm > 2 * prevNorm) break;  // diverging
        prevNorm = norm;
        if (singular) {
            // Singular Jacobian (a pole or a fold): step towards the centre and try again.
            u += (u < T(0.5) ? T(1) : T(-1)) * T(1e-3);
            v += (v < T(0.5) ? T(1) : T(-1)) * T(1e-3);
            continue;
        }
        const T inv = 1 / det;
        T su = (j22 * r1 - j12 * r2) * inv;
        T sv = (j11 * r2 - j21 * r1) * inv;
        // Damp wild steps (near-singular Jacobian far from the root).
        const T maxStep = T(0.5);
        const T asu = std::fabs(su), asv = std::fabs(sv);
        const T sm = asu > asv ? asu : asv;
        if (sm > maxStep) {
            const T k = maxStep / sm;
            su *= k, sv *= k;
        }
        u -= su;
        v -= sv;
        if (u < -outer || u > 1 + outer || v < -outer || v > 1 + outer) {
            // Left the domain: clamp back once (near a collapsed edge u is nearly free and may run off
            // while v converges); leaving it twice in a row means the root is on another patch.
            if (++clamps > 1) break;
            u = std::clamp(u, T(0), T(1));
            v = std::clamp(v, T(0), T(1));
        } else {
            clamps = 0;
        }
    }
    iterations = it + (converged ? 1 : 0);
    return converged;
}

// Domain rule for a converged root (u, v): inside [0,1]^2 up to `domainTol`, or outside but the clamped
// point still lies on the ray (|R| < 2 eps: a root at a collapsed edge, where u is free, or within rounding
// of a shared edge). Returns the clamped parameters. `projection()` gives the projected patch; it is
// called only for a root outside the domain's tolerance (the Newton stage gathers it then).
template <class T, class GetProjection>
__attribute__((always_inline)) inline bool acceptRootDomainWith(GetProjection&& projection, T eps, T u, T v,
                                                                float domainTol, float& uc, float& vc) {
    const T tol = T(domainTol);
    uc = std::clamp(float(u), 0.f, 1.f);
    vc = std::clamp(float(v), 0.f, 1.f);
    if (u < -tol || u > 1 + tol || v < -tol || v > 1 + tol) {
        const ProjectedPatch<T>& pp = projection();
        T bu[4], bv[4];
        T s = 1 - T(uc), w = T(uc);
        bu[0] = s * s * s, bu[1] = 3 * w * s * s, bu[2] = 3 * w * w * s, bu[3] = w * w * w;
        s = 1 - T(vc), w = T(vc);
        bv[0] = s * s * s, bv[1] = 3 * w * s * s, bv[2] = 3 * w * w * s, bv[3] = w * w * w;
        T r1 = 0, r2 = 0;
        for (int j = 0; j < 4; ++j)
            for (int i = 0; i < 4; ++i)
                r1 += pp.a1[4 * j + i] * bu[i] * bv[j], r2 += pp.a2[4 * j + i] * bu[i] * bv[j];
        if (!(std::max(std::fabs(r1), std::fabs(r2)) < 2 * eps)) return false;
    }
    return true;
}

template <class T>
__attribute__((always_inline)) inline bool acceptRootDomain(const ProjectedPatch<T>& pp, T eps, T u, T v,
                                                            float domainTol, float& uc, float& vc) {
    return acceptRootDomainWith<T>([&]() -> const ProjectedPatch<T>& { return pp; }, eps, u, v, domainTol, uc,
                                   vc);
}

// Newton iteration from (u0, v0) in precision T (float in the renderer; double as the reference for the
// precision measurement): projection, newtonIterate, domain rule, then the point and t along the ray.
template <class T>
bool newtonSolve(const BezierPatch& patch, const RayPlanes& pl, const Ray& ray, float u0, float v0,
                 const NewtonParams& prm, PatchHit& out) {
    struct V3 {
        T x, y, z;
    };
    V3 n1{pl.n1.x, pl.n1.y, pl.n1.z}, n2{pl.n2.x, pl.n2.y, pl.n2.z};
    T d1 = pl.d1, d2 = pl.d2;
    if constexpr (sizeof(T) > sizeof(float)) {
        // Reference precision: build the planes in T as well.
        const T dx = ray.d.x, dy = ray.d.y, dz = ray.d.z;
        V3 a = (std::fabs(dx) > std::fabs(dy) && std::fabs(dx) > std::fabs(dz)) ? V3{dy, -dx, 0}
                                                                                : V3{0, dz, -dy};
        T la = std::sqrt(a.x * a.x + a.y * a.y + a.z * a.z);
        n1 = {a.x / la, a.y / la, a.z / la};
        V3 b{n1.y * dz - n1.z * dy, n1.z * dx - n1.x * dz, n1.x * dy - n1.y * dx};
        T lb = std::sqrt(b.x * b.x + b.y * b.y + b.z * b.z);
        n2 = {b.x / lb, b.y / lb, b.z / lb};
        d1 = -(n1.x * T(ray.o.x) + n1.y * T(ray.o.y) + n1.z * T(ray.o.z));
        d2 = -(n2.x * T(ray.o.x) + n2.y * T(ray.o.y) + n2.z * T(ray.o.z));
    }
    ProjectedPatch<T> pp;
    const T n1a[3] = {n1.x, n1.y, n1.z}, n2a[3] = {n2.x, n2.y, n2.z};
    projectPatch<T>(patch, n1a, n2a, d1, d2, pp);
    const T eps = T(prm.epsR);
    T u = u0, v = v0;
    int iters = 0;
    const bool converged = newtonIterate<T>(pp, eps, u, v, iters);
    out.iterations = iters;
    if (!converged) return false;
    float uc, vc;
    if (!acceptRootDomain<T>(pp, eps, u, v, prm.domainTol, uc, vc)) return false;
    // Point and t along the ray (in the chosen precision).
    SurfacePoint sp = evalPatchDeriv(patch, uc, vc);
    T t;
    if constexpr (sizeof(T) == sizeof(float)) {
        t = dot(sp.p - ray.o, ray.d) / dot(ray.d, ray.d);
    } else {
        // Reference: evaluate the position in double as well.
        T bu[4], bv[4];
        T s = 1 - u, w = u;
        bu[0] = s * s * s, bu[1] = 3 * w * s * s, bu[2] = 3 * w * w * s, bu[3] = w * w * w;
        s = 1 - v, w = v;
        bv[0] = s * s * s, bv[1] = 3 * w * s * s, bv[2] = 3 * w * w * s, bv[3] = w * w * w;
        T q[3] = {0, 0, 0};
        for (int j = 0; j < 4; ++j)
            for (int i = 0; i < 4; ++i)
                for (int k = 0; k < 3; ++k) q[k] += T(patch.cp[j * 4 + i][k]) * bu[i] * bv[j];
        T num = 0, den = 0;
        for (int k = 0; k < 3; ++k) {
            num += (q[k] - T(ray.o[k])) * T(ray.d[k]);
            den += T(ray.d[k]) * T(ray.d[k]);
        }
        t = num / den;
    }
    if (!(t > T(ray.tmin) && t < T(ray.tmax))) return false;
    out.t = float(t);
    out.u = uc;
    out.v = vc;
    out.p = sp.p;
    out.dpdu = sp.dpdu;
    out.dpdv = sp.dpdv;
    out.hit = true;
    return true;
}

// Closest root on one patch over all leaves of its subpatch tree that the ray hits (the scalar reference
// used by the tests, and by traceRayScalar). `tree` is the patch's tree in a SubpatchForest.
// `backface` (optional) skips nodes marked back-facing. Returns the number of Newton runs in *runs.
// Newton for one leaf of half-size (hu, hv) centred at (u0, v0): start at the centre; if that fails or
// converges to a root outside the leaf (which the leaf owning it will find), retry from the four quarter
// points (only with `retry`: it costs 4x on every empty leaf, measured 8x slower renders, so the renderer
// does not use it; see docs/rt.md), for folded or strongly curved leaves such as the teapot's knob.
// Returns the closest valid root over the attempts; `iterations` accumulates, `runs` counts the solves.
template <class T>
bool solveLeaf(const BezierPatch& patch, const RayPlanes& pl, const Ray& ray, float u0, float v0, float hu,
               float hv, const NewtonParams& prm, PatchHit& out, uint32_t& runs, uint32_t& iterations,
               bool retry = false) {
    PatchHit h;
    bool ok = newtonSolve<T>(patch, pl, ray, u0, v0, prm, h);
    ++runs;
    iterations += uint32_t(h.iterations);
    if (ok) out = h;
    if (!retry || (ok && std::fabs(h.u - u0) <= 1.5f * hu && std::fabs(h.v - v0) <= 1.5f * hv)) return ok;
    static constexpr float kQ[4][2] = {{-0.5f, -0.5f}, {0.5f, -0.5f}, {-0.5f, 0.5f}, {0.5f, 0.5f}};
    for (const auto& q : kQ) {
        PatchHit g;
        bool okq = newtonSolve<T>(patch, pl, ray, u0 + q[0] * hu, v0 + q[1] * hv, prm, g);
        ++runs;
        iterations += uint32_t(g.iterations);
        if (okq && (!ok || g.t < out.t)) {
            out = g;
            ok = true;
            if (std::fabs(g.u - u0) <= 1.5f * hu && std::fabs(g.v - v0) <= 1.5f * hv) break;
        }
    }
    return ok;
}

TESSERA_HD void leafHalfSize(int depth, float& hu, float& hv) {
    hu = 0.5f / float(1 << ((depth + 1) / 2));
    hv = 0.5f / float(1 << (depth / 2));
}

// The duplicate-root rule's reach: a root within (du, dv) of a leaf's centre (its half sizes and 1%)
// counts as the leaf's, since Newton from the leaf's centre finds it.
TESSERA_HD void rootRuleReach(int depth, float& du, float& dv) {
    float hu, hv;
    leafHalfSize(depth, hu, hv);
    du = 1.01f * hu, dv = 1.01f * hv;
}

struct AcceptAnyHit {
    bool operator()(const PatchHit&) const { return true; }
};

// intersectPatch (below) with the patch's tree given and its boxes tested with a ray of origin boxO and
// inverse direction boxInv that has the same distances as `ray` (an instance's patch through its prototype's
// tree, with the ray in the prototype's frame: RtAccel::placement); `toleranceBox`: the patch's root box for
// Newton's tolerance.
template <class T = float, class Accept = AcceptAnyHit>
bool intersectPatchTree(const BezierPatch& patch, const SubpatchForest& forest, uint32_t tree,
                        const Bounds3& toleranceBox, Vec3 boxO, Vec3 boxInv, const Ray& ray, PatchHit& best,
                        const uint8_t* backface, uint32_t* runs, uint32_t* iterations, Accept&& accept) {
    const RayPlanes pl = makeRayPlanes(ray.o, ray.d);
    NewtonParams prm{newtonTolerance(toleranceBox, ray.o)};
    if constexpr (sizeof(T) > sizeof(float)) prm.epsR *= 1e-4f;
    const uint32_t firstLeaf = forest.firstLeaf();
    float hu, hv;
    leafHalfSize(forest.depth, hu, hv);
    uint32_t stack[32];
    int sp = 0;
    stack[sp++] = 0;
    bool found = false;
    Ray r = ray;
    while (sp > 0) {
        const uint32_t n = stack[--sp];
        float te;
        if (!rayBox(forest.nodeBox(tree, n), boxO, boxInv, r.tmin, r.tmax, te)) continue;
        if (backface && backface[n]) continue;
        if (n >= firstLeaf) {
            const Vec2 c = forest.leafCentre[n - firstLeaf];
            PatchHit h;
            uint32_t nr = 0, ni = 0;
            bool ok = solveLeaf<T>(patch, pl, r, c.x, c.y, hu, hv, prm, h, nr, ni);
            if (runs) *runs += nr;
            if (iterations) *iterations += ni;
            if (ok && h.t < r.tmax && accept(h)) {
                best = h;
                r.tmax = h.t;
                found = true;
            }
            continue;
        }
        stack[sp++] = 2 * n + 2;
        stack[sp++] = 2 * n + 1;
    }
    return found;
}

// The nearest hit on `patch` (accepted by `accept`) from Newton in each leaf of its subpatch tree that the
// ray passes through.
template <class T = float, class Accept = AcceptAnyHit>
bool intersectPatch(const BezierPatch& patch, const SubpatchForest& forest, uint32_t patchId, const Ray& ray,
                    PatchHit& best, const uint8_t* backface = nullptr, uint32_t* runs = nullptr,
                    uint32_t* iterations = nullptr, Accept&& accept = Accept()) {
    return intersectPatchTree<T>(patch, forest, patchId, forest.roots[patchId], ray.o, safeInverse(ray.d),
                                 ray, best, backface, runs, iterations, std::forward<Accept>(accept));
}

}  // namespace tessera
