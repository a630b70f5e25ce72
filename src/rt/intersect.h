// Ray / bicubic patch intersection by Newton iteration (Martin et al. 2000, "Practical ray tracing of
// trimmed NURBS surfaces", sec. 3): the ray is the intersection of two planes (n1,d1), (n2,d2) and the
// root of R(u,v) = (n1.Q(u,v) + d1, n2.Q(u,v) + d2) is found from an initial guess given by a subpatch
// leaf. Plain functions over plain data: no globals, no allocation.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "core/bezier.h"
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
inline RayPlanes makeRayPlanes(Vec3 o, Vec3 d) {
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
inline Vec3 safeInverse(Vec3 d) {
    auto inv = [](float x) { return std::fabs(x) > 1e-30f ? 1.f / x : (x >= 0.f ? 1e30f : -1e30f); };
    return {inv(d.x), inv(d.y), inv(d.z)};
}

// Slab test; on a hit returns the entry distance (clamped to tmin).
inline bool rayBox(const Bounds3& b, Vec3 o, Vec3 inv, float tmin, float tmax, float& tEnter) {
    float tx0 = (b.lo.x - o.x) * inv.x, tx1 = (b.hi.x - o.x) * inv.x;
    float ty0 = (b.lo.y - o.y) * inv.y, ty1 = (b.hi.y - o.y) * inv.y;
    float tz0 = (b.lo.z - o.z) * inv.z, tz1 = (b.hi.z - o.z) * inv.z;
    float t0 = std::max({std::min(tx0, tx1), std::min(ty0, ty1), std::min(tz0, tz1), tmin});
    float t1 = std::min({std::max(tx0, tx1), std::max(ty0, ty1), std::max(tz0, tz1), tmax});
    tEnter = t0;
    return t0 <= t1;
}

struct NewtonParams {
    float epsR;               // residual tolerance (world units)
    float domainTol = 1e-4f;  // accepted distance of the root outside [0,1]^2 (then clamped)
};

struct PatchHit {
    float t = std::numeric_limits<float>::infinity();
    float u = 0, v = 0;
    Vec3 p, dpdu, dpdv;  // at the root (dpdu x dpdv may vanish at a collapsed edge)
    int iterations = 0;
    bool hit = false;
};

// Residual tolerance for a patch whose box is `box`, seen from ray origin o: a few float ulps of the
// magnitudes involved (the residual n.Q + d cancels terms of size |Q| and |o|).
inline float newtonTolerance(const Bounds3& box, Vec3 o) {
    float mag = 0;
    for (int k = 0; k < 3; ++k)
        mag = std::max({mag, std::fabs(box.lo[k]), std::fabs(box.hi[k]), std::fabs(o[k])});
    return 2e-6f * mag + 1e-6f * maxComponent(box.diagonal()) + 1e-30f;
}

// Newton iteration from (u0, v0) in precision T (float in the renderer; double as the reference for the
// precision measurement). Stops on convergence (|R|inf < epsR), leaving the domain, divergence, or 16
// iterations. A singular Jacobian (collapsed edge) nudges the iterate towards the domain centre.
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
    // Project the control points on the two plane normals once: R and J then need 2D evaluation only.
    T a1[16], a2[16];
    for (int k = 0; k < 16; ++k) {
        const Vec3& c = patch.cp[k];
        a1[k] = n1.x * T(c.x) + n1.y * T(c.y) + n1.z * T(c.z) + d1;
        a2[k] = n2.x * T(c.x) + n2.y * T(c.y) + n2.z * T(c.z) + d2;
    }
    const T eps = T(prm.epsR);
    const T outer = T(0.25);  // iterates may wander this far outside the domain before giving up
    T u = u0, v = v0;
    T prevNorm = std::numeric_limits<T>::infinity();
    int it = 0, clamps = 0;
    bool converged = false;
    for (; it < 16; ++it) {
        T bu[4], bv[4], du[4], dv[4];
        {
            T s = 1 - u, t = u;
            bu[0] = s * s * s, bu[1] = 3 * t * s * s, bu[2] = 3 * t * t * s, bu[3] = t * t * t;
            du[0] = -3 * s * s, du[1] = 3 * s * s - 6 * t * s, du[2] = 6 * t * s - 3 * t * t,
            du[3] = 3 * t * t;
            s = 1 - v, t = v;
            bv[0] = s * s * s, bv[1] = 3 * t * s * s, bv[2] = 3 * t * t * s, bv[3] = t * t * t;
            dv[0] = -3 * s * s, dv[1] = 3 * s * s - 6 * t * s, dv[2] = 6 * t * s - 3 * t * t,
            dv[3] = 3 * t * t;
        }
        T r1 = 0, r2 = 0, j11 = 0, j12 = 0, j21 = 0, j22 = 0;
        for (int j = 0; j < 4; ++j) {
            const T* p1 = a1 + 4 * j;
            const T* p2 = a2 + 4 * j;
            T c1 = p1[0] * bu[0] + p1[1] * bu[1] + p1[2] * bu[2] + p1[3] * bu[3];
            T c2 = p2[0] * bu[0] + p2[1] * bu[1] + p2[2] * bu[2] + p2[3] * bu[3];
            T e1 = p1[0] * du[0] + p1[1] * du[1] + p1[2] * du[2] + p1[3] * du[3];
            T e2 = p2[0] * du[0] + p2[1] * du[1] + p2[2] * du[2] + p2[3] * du[3];
            r1 += c1 * bv[j], r2 += c2 * bv[j];
            j11 += e1 * bv[j], j21 += e2 * bv[j];
            j12 += c1 * dv[j], j22 += c2 * dv[j];
        }
        const T norm = std::max(std::fabs(r1), std::fabs(r2));
        if (!(norm == norm)) break;  // NaN
        T det = j11 * j22 - j12 * j21;
        const T jscale = std::max({std::fabs(j11), std::fabs(j12), std::fabs(j21), std::fabs(j22)});
        const bool singular = !(std::fabs(det) > T(1e-12) * jscale * jscale) || jscale == 0;
        if (norm < eps) {
            converged = true;
            // One more (free) Newton step: the residual is already small, so this one is quadratic and
            // brings the root to the precision floor without another convergence test.
            if (!singular) {
                u -= (j22 * r1 - j12 * r2) / det;
                v -= (j11 * r2 - j21 * r1) / det;
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
        T su = (j22 * r1 - j12 * r2) / det;
        T sv = (j11 * r2 - j21 * r1) / det;
        // Damp wild steps (near-singular Jacobian far from the root).
        const T maxStep = T(0.5);
        const T sm = std::max(std::fabs(su), std::fabs(sv));
        if (sm > maxStep) su *= maxStep / sm, sv *= maxStep / sm;
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
    out.iterations = it + (converged ? 1 : 0);
    if (!converged) return false;
    const T tol = T(prm.domainTol);
    const float uc = std::clamp(float(u), 0.f, 1.f), vc = std::clamp(float(v), 0.f, 1.f);
    if (u < -tol || u > 1 + tol || v < -tol || v > 1 + tol) {
        // Outside the domain: accept the clamped point only if it still lies on the ray (a root at a
        // collapsed edge, where u is free, or within rounding of a shared edge).
        T bu[4], bv[4];
        T s = 1 - T(uc), w = T(uc);
        bu[0] = s * s * s, bu[1] = 3 * w * s * s, bu[2] = 3 * w * w * s, bu[3] = w * w * w;
        s = 1 - T(vc), w = T(vc);
        bv[0] = s * s * s, bv[1] = 3 * w * s * s, bv[2] = 3 * w * w * s, bv[3] = w * w * w;
        T r1 = 0, r2 = 0;
        for (int j = 0; j < 4; ++j)
            for (int i = 0; i < 4; ++i)
                r1 += a1[4 * j + i] * bu[i] * bv[j], r2 += a2[4 * j + i] * bu[i] * bv[j];
        if (!(std::max(std::fabs(r1), std::fabs(r2)) < 2 * eps)) return false;
    }
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
// used by the tests, and by traceRayScalar). `tree` is the patch's box array from a SubpatchForest.
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

inline void leafHalfSize(int depth, float& hu, float& hv) {
    hu = 0.5f / float(1 << ((depth + 1) / 2));
    hv = 0.5f / float(1 << (depth / 2));
}

struct AcceptAnyHit {
    bool operator()(const PatchHit&) const { return true; }
};

template <class T = float, class Accept = AcceptAnyHit>
bool intersectPatch(const BezierPatch& patch, const SubpatchForest& forest, uint32_t patchId, const Ray& ray,
                    PatchHit& best, const uint8_t* backface = nullptr, uint32_t* runs = nullptr,
                    uint32_t* iterations = nullptr, Accept&& accept = Accept()) {
    const Bounds3* tree = forest.tree(patchId);
    const Vec3 inv = safeInverse(ray.d);
    const RayPlanes pl = makeRayPlanes(ray.o, ray.d);
    NewtonParams prm{newtonTolerance(tree[0], ray.o)};
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
        if (!rayBox(tree[n], r.o, inv, r.tmin, r.tmax, te)) continue;
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

}  // namespace tessera
