#include "rt/newton_lanes.h"

#include <immintrin.h>

#include <cstring>

#include "core/cpu.h"

namespace tessera {
namespace {

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define TESSERA_LANES_AVX2 1
#endif

typedef float f8 __attribute__((vector_size(32)));
typedef int32_t i8 __attribute__((vector_size(32)));
static_assert(kNewtonLanes == 8);

// The whole iteration in one always-inlined body, compiled twice below (AVX2 and the SSE2 baseline).
// Every expression mirrors newtonIterate<float> / evalProjected (intersect.h) operation for operation;
// the branches there become lane selects here.
__attribute__((always_inline)) inline unsigned stepImpl(NewtonLanes& L) {
    f8 u, v, eps, prevNorm, evals, clamps;
    std::memcpy(&u, L.u, 32);
    std::memcpy(&v, L.v, 32);
    std::memcpy(&eps, L.eps, 32);
    std::memcpy(&prevNorm, L.prevNorm, 32);
    std::memcpy(&evals, L.evals, 32);
    std::memcpy(&clamps, L.clamps, 32);
    const i8 absMask = i8{} + 0x7fffffff;
#define TESSERA_ABS(x) ((f8)((i8)(x)&absMask))

    // Bernstein basis and derivatives in u (BU, DU) and v (bv, dv), as in evalProjected.
    f8 s = 1.f - u, t = u;
    const f8 BU0 = s * s * s, BU1 = 3.f * t * s * s, BU2 = 3.f * t * t * s, BU3 = t * t * t;
    const f8 DU0 = -3.f * s * s, DU1 = 3.f * s * s - 6.f * t * s, DU2 = 6.f * t * s - 3.f * t * t,
             DU3 = 3.f * t * t;
    s = 1.f - v, t = v;
    const f8 bv0 = s * s * s, bv1 = 3.f * t * s * s, bv2 = 3.f * t * t * s, bv3 = t * t * t;
    const f8 dv0 = -3.f * s * s, dv1 = 3.f * s * s - 6.f * t * s, dv2 = 6.f * t * s - 3.f * t * t,
             dv3 = 3.f * t * t;

    // Column i of the projected net weighted by the v basis (S) and its derivative (T), then the dot
    // products with the u basis summed as (x0 + x2) + (x1 + x3) (the 4-wide reduction's order).
    f8 r[2], ju[2], jv[2];
    for (int plane = 0; plane < 2; ++plane) {
        const float(*a)[kNewtonLanes] = plane == 0 ? L.a1 : L.a2;
        f8 S[4], T[4];
        for (int i = 0; i < 4; ++i) {
            f8 p0, p1, p2, p3;
            std::memcpy(&p0, a[i], 32);
            std::memcpy(&p1, a[4 + i], 32);
            std::memcpy(&p2, a[8 + i], 32);
            std::memcpy(&p3, a[12 + i], 32);
            S[i] = (p0 * bv0 + p1 * bv1) + (p2 * bv2 + p3 * bv3);
            T[i] = (p0 * dv0 + p1 * dv1) + (p2 * dv2 + p3 * dv3);
        }
        r[plane] = (S[0] * BU0 + S[2] * BU2) + (S[1] * BU1 + S[3] * BU3);
        ju[plane] = (S[0] * DU0 + S[2] * DU2) + (S[1] * DU1 + S[3] * DU3);
        jv[plane] = (T[0] * BU0 + T[2] * BU2) + (T[1] * BU1 + T[3] * BU3);
    }
    const f8 r1 = r[0], r2 = r[1], j11 = ju[0], j21 = ju[1], j12 = jv[0], j22 = jv[1];

    const f8 ar1 = TESSERA_ABS(r1), ar2 = TESSERA_ABS(r2);
    const f8 norm = ar1 > ar2 ? ar1 : ar2;
    const i8 isNan = ~(norm == norm);
    const f8 det = j11 * j22 - j12 * j21;
    const f8 aj11 = TESSERA_ABS(j11), aj12 = TESSERA_ABS(j12), aj21 = TESSERA_ABS(j21),
             aj22 = TESSERA_ABS(j22);
    const f8 ja = aj11 > aj12 ? aj11 : aj12, jb = aj21 > aj22 ? aj21 : aj22;
    const f8 jscale = ja > jb ? ja : jb;
    const i8 singular = ~(TESSERA_ABS(det) > 1e-12f * jscale * jscale) | (jscale == 0.f);
    const f8 inv = 1.f / det;
    const f8 stepU = (j22 * r1 - j12 * r2) * inv, stepV = (j11 * r2 - j21 * r1) * inv;

    // Converged: the free final step (skipped where the Jacobian is singular).
    const i8 converged = ~isNan & (norm < eps);
    const f8 uConv = singular ? u : u - stepU, vConv = singular ? v : v - stepV;
    // Diverging (|R| doubled after the third iteration).
    const i8 diverged = ~isNan & ~converged & (evals >= 3.f) & (norm > 2.f * prevNorm);
    // Singular, not converged: nudge towards the centre.
    const f8 uNudge = u + (u < 0.5f ? f8{} + 1.f : f8{} - 1.f) * 1e-3f;
    const f8 vNudge = v + (v < 0.5f ? f8{} + 1.f : f8{} - 1.f) * 1e-3f;
    // Regular step, damped to at most 0.5 in either parameter.
    const f8 asu = TESSERA_ABS(stepU), asv = TESSERA_ABS(stepV);
    const f8 sm = asu > asv ? asu : asv;
    const i8 damp = sm > 0.5f;
    const f8 k = 0.5f / sm;
    const f8 su = damp ? stepU * k : stepU, sv = damp ? stepV * k : stepV;
    const f8 uStep = u - su, vStep = v - sv;
    const i8 outside = (uStep < -0.25f) | (uStep > 1.25f) | (vStep < -0.25f) | (vStep > 1.25f);
    const f8 clampsStep = outside ? clamps + 1.f : f8{};
    const i8 leftTwice = outside & (clampsStep > 1.f);
    const f8 uClamped = outside ? (uStep < 0.f ? f8{} : (uStep > 1.f ? f8{} + 1.f : uStep)) : uStep;
    const f8 vClamped = outside ? (vStep < 0.f ? f8{} : (vStep > 1.f ? f8{} + 1.f : vStep)) : vStep;

    const i8 going = ~isNan & ~converged & ~diverged;  // lanes that iterate on (unless they leave twice)
    const i8 failedNow = isNan | diverged | (going & ~singular & leftTwice);
    const f8 uNext = converged ? uConv : (singular ? uNudge : uClamped);
    const f8 vNext = converged ? vConv : (singular ? vNudge : vClamped);
    const f8 clampsNext = singular ? clamps : clampsStep;
    // Reported count: evaluations + 1 when converged (the free step), the loop index on a failure.
    const f8 evalsNext = failedNow ? evals : evals + 1.f;
    const i8 exhausted = ~converged & ~failedNow & (evalsNext >= 16.f);
    const i8 status = converged ? i8{} + int32_t(kLaneConverged)
                                : ((failedNow | exhausted) ? i8{} + int32_t(kLaneFailed) : i8{});
    const f8 prevNext = norm;
#undef TESSERA_ABS

    std::memcpy(L.u, &uNext, 32);
    std::memcpy(L.v, &vNext, 32);
    std::memcpy(L.prevNorm, &prevNext, 32);
    std::memcpy(L.evals, &evalsNext, 32);
    std::memcpy(L.clamps, &clampsNext, 32);
    std::memcpy(L.status, &status, 32);
    unsigned finished = 0;
    for (int l = 0; l < kNewtonLanes; ++l) finished |= unsigned(status[l] != 0) << l;
    return finished;
}

// The projection in one always-inlined body, compiled twice like the step. Sums left to right as
// projectPatch: ((n.x X + n.y Y) + n.z Z) + d.
__attribute__((always_inline)) inline void projectImpl(NewtonLanes& L, int l, const LaneRayFrame& f,
                                                       const float* x, const float* y, const float* z,
                                                       float depth[16]) {
    for (int h = 0; h < 16; h += 8) {
        f8 X, Y, Z;
        std::memcpy(&X, x + h, 32);
        std::memcpy(&Y, y + h, 32);
        std::memcpy(&Z, z + h, 32);
        const f8 a1 = ((f.n1[0] * X + f.n1[1] * Y) + f.n1[2] * Z) + f.d1;
        const f8 a2 = ((f.n2[0] * X + f.n2[1] * Y) + f.n2[2] * Z) + f.d2;
        const f8 t = (((X - f.o[0]) * f.d[0] + (Y - f.o[1]) * f.d[1]) + (Z - f.o[2]) * f.d[2]) * f.invDD;
        std::memcpy(depth + h, &t, 32);
        for (int k = 0; k < 8; ++k) L.a1[h + k][l] = a1[k], L.a2[h + k][l] = a2[k];
    }
}

// The square roots of 8 lanes as two 4-wide ones (the same bits as sqrtss; SSE2 serves both builds).
__attribute__((always_inline)) inline void sqrtInPlace(f8& x) {
    __m128 lo, hi;
    std::memcpy(&lo, &x, 16);
    std::memcpy(&hi, reinterpret_cast<const char*>(&x) + 16, 16);
    lo = _mm_sqrt_ps(lo), hi = _mm_sqrt_ps(hi);
    std::memcpy(&x, &lo, 16);
    std::memcpy(reinterpret_cast<char*>(&x) + 16, &hi, 16);
}

// makeRayPlanes (intersect.h) and the frame's 1 / (d.d) for 8 rays, in one always-inlined body compiled
// twice. Same expressions in the same order (Vec3's dot, cross, length and component-wise normalize);
// the branch on the major axis becomes a select.
__attribute__((always_inline)) inline void framesImpl(const float* ox, const float* oy, const float* oz,
                                                      const float* dx, const float* dy, const float* dz,
                                                      int n, LaneRayFrame* out) {
    const i8 absMask = i8{} + 0x7fffffff;
    const f8 zero = f8{};
    for (int b = 0; b < n; b += 8) {
        f8 OX, OY, OZ, DX, DY, DZ;
        std::memcpy(&OX, ox + b, 32);
        std::memcpy(&OY, oy + b, 32);
        std::memcpy(&OZ, oz + b, 32);
        std::memcpy(&DX, dx + b, 32);
        std::memcpy(&DY, dy + b, 32);
        std::memcpy(&DZ, dz + b, 32);
        const f8 ax = (f8)((i8)DX & absMask), ay = (f8)((i8)DY & absMask), az = (f8)((i8)DZ & absMask);
        const i8 xMajor = (ax > ay) & (ax > az);
        // n1 = x major ? (dy, -dx, 0) : (0, dz, -dy), normalized
        f8 n1x = xMajor ? DY : zero, n1y = xMajor ? -DX : DZ, n1z = xMajor ? zero : -DY;
        f8 l1 = (n1x * n1x + n1y * n1y) + n1z * n1z;
        sqrtInPlace(l1);
        const i8 pos1 = l1 > zero;
        n1x = pos1 ? n1x / l1 : n1x, n1y = pos1 ? n1y / l1 : n1y, n1z = pos1 ? n1z / l1 : n1z;
        // n2 = normalize(cross(n1, d))
        f8 n2x = n1y * DZ - n1z * DY, n2y = n1z * DX - n1x * DZ, n2z = n1x * DY - n1y * DX;
        f8 l2 = (n2x * n2x + n2y * n2y) + n2z * n2z;
        sqrtInPlace(l2);
        const i8 pos2 = l2 > zero;
        n2x = pos2 ? n2x / l2 : n2x, n2y = pos2 ? n2y / l2 : n2y, n2z = pos2 ? n2z / l2 : n2z;
        const f8 d1 = -((n1x * OX + n1y * OY) + n1z * OZ), d2 = -((n2x * OX + n2y * OY) + n2z * OZ);
        const f8 invDD = 1.f / ((DX * DX + DY * DY) + DZ * DZ);
        for (int k = 0; k < 8 && b + k < n; ++k)
            out[b + k] = LaneRayFrame{
                {n1x[k], n1y[k], n1z[k]}, d1[k],   {n2x[k], n2y[k], n2z[k]}, d2[k], {OX[k], OY[k], OZ[k]},
                {DX[k], DY[k], DZ[k]},    invDD[k]};
    }
}

unsigned stepBaseline(NewtonLanes& lanes) {
    return stepImpl(lanes);
}

#if defined(TESSERA_LANES_AVX2)
__attribute__((target("avx2"))) unsigned stepAvx2(NewtonLanes& lanes) {
    return stepImpl(lanes);
}
#endif

void projectBaseline(NewtonLanes& lanes, int l, const LaneRayFrame& f, const float* x, const float* y,
                     const float* z, float depth[16]) {
    projectImpl(lanes, l, f, x, y, z, depth);
}

#if defined(TESSERA_LANES_AVX2)
__attribute__((target("avx2"))) void projectAvx2(NewtonLanes& lanes, int l, const LaneRayFrame& f,
                                                 const float* x, const float* y, const float* z,
                                                 float depth[16]) {
    projectImpl(lanes, l, f, x, y, z, depth);
}
#endif

void framesBaseline(const float* ox, const float* oy, const float* oz, const float* dx, const float* dy,
                    const float* dz, int n, LaneRayFrame* out) {
    framesImpl(ox, oy, oz, dx, dy, dz, n, out);
}

#if defined(TESSERA_LANES_AVX2)
__attribute__((target("avx2"))) void framesAvx2(const float* ox, const float* oy, const float* oz,
                                                const float* dx, const float* dy, const float* dz, int n,
                                                LaneRayFrame* out) {
    framesImpl(ox, oy, oz, dx, dy, dz, n, out);
}
#endif

// The AVX2 builds where the processor has them (core/cpu.h), else the SSE2 ones.
using ProjectFn = void (*)(NewtonLanes&, int, const LaneRayFrame&, const float*, const float*, const float*,
                           float*);
using StepFn = unsigned (*)(NewtonLanes&);
using FramesFn = void (*)(const float*, const float*, const float*, const float*, const float*, const float*,
                          int, LaneRayFrame*);
#if defined(TESSERA_LANES_AVX2)
const ProjectFn kProject = cpuHasAvx2() ? projectAvx2 : projectBaseline;
const StepFn kStep = cpuHasAvx2() ? stepAvx2 : stepBaseline;
const FramesFn kFrames = cpuHasAvx2() ? framesAvx2 : framesBaseline;
#else
const ProjectFn kProject = projectBaseline;
const StepFn kStep = stepBaseline;
const FramesFn kFrames = framesBaseline;
#endif

}  // namespace

unsigned newtonLanesStep(NewtonLanes& lanes) {
    return kStep(lanes);
}

void projectIntoLane(NewtonLanes& lanes, int l, const LaneRayFrame& f, const float* x, const float* y,
                     const float* z, float depth[16]) {
    kProject(lanes, l, f, x, y, z, depth);
}

void projectIntoLaneBaseline(NewtonLanes& lanes, int l, const LaneRayFrame& f, const float* x, const float* y,
                             const float* z, float depth[16]) {
    projectBaseline(lanes, l, f, x, y, z, depth);
}

void makeLaneRayFrames(const float* ox, const float* oy, const float* oz, const float* dx, const float* dy,
                       const float* dz, int n, LaneRayFrame* out) {
    kFrames(ox, oy, oz, dx, dy, dz, n, out);
}

void makeLaneRayFramesBaseline(const float* ox, const float* oy, const float* oz, const float* dx,
                               const float* dy, const float* dz, int n, LaneRayFrame* out) {
    framesBaseline(ox, oy, oz, dx, dy, dz, n, out);
}

unsigned newtonLanesStepBaseline(NewtonLanes& lanes) {
    return stepBaseline(lanes);
}

}  // namespace tessera
