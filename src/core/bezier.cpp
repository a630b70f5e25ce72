#include "core/bezier.h"

#include <cstring>

#if defined(__SSE2__)
#include <immintrin.h>
#endif

namespace tessera {

#if defined(__SSE2__)
namespace {
// A control point in lanes 0..2 (lane 3 zero), without reading past the Vec3.
inline __m128 loadVec3(const Vec3& p) {
    double xy;  // x and y as one 8-byte load (memcpy: Vec3 is only 4-byte aligned)
    std::memcpy(&xy, &p.x, sizeof(xy));
    return _mm_movelh_ps(_mm_castpd_ps(_mm_set_sd(xy)), _mm_load_ss(&p.z));
}
inline Vec3 storeVec3(__m128 v) {  // lanes extracted in registers (no store and reload)
    return {_mm_cvtss_f32(v), _mm_cvtss_f32(_mm_shuffle_ps(v, v, 0x55)), _mm_cvtss_f32(_mm_movehl_ps(v, v))};
}
}  // namespace
#endif

// The SSE paths evaluate x, y, z in the lanes of one vector with the scalar code's operations in the
// same order, so both give identical results.
Vec3 evalPatch(const BezierPatch& patch, float u, float v) {
    float bu[4], bv[4];
    bernstein3(u, bu);
    bernstein3(v, bv);
#if defined(__SSE2__)
    const __m128 b0 = _mm_set1_ps(bu[0]), b1 = _mm_set1_ps(bu[1]), b2 = _mm_set1_ps(bu[2]),
                 b3 = _mm_set1_ps(bu[3]);
    __m128 r = _mm_setzero_ps();
    for (int j = 0; j < 4; ++j) {
        const Vec3* row = &patch.cp[j * 4];
        const __m128 c = _mm_add_ps(
            _mm_add_ps(_mm_add_ps(_mm_mul_ps(loadVec3(row[0]), b0), _mm_mul_ps(loadVec3(row[1]), b1)),
                       _mm_mul_ps(loadVec3(row[2]), b2)),
            _mm_mul_ps(loadVec3(row[3]), b3));
        r = _mm_add_ps(r, _mm_mul_ps(c, _mm_set1_ps(bv[j])));
    }
    return storeVec3(r);
#else
    Vec3 r;
    for (int j = 0; j < 4; ++j) {
        Vec3 row = patch.cp[j * 4] * bu[0] + patch.cp[j * 4 + 1] * bu[1] + patch.cp[j * 4 + 2] * bu[2] +
                   patch.cp[j * 4 + 3] * bu[3];
        r += row * bv[j];
    }
    return r;
#endif
}

void patchRowsAtU(const BezierPatch& patch, float u, PatchRowsAtU& rows) {
    float bu[4], du[4];
    bernstein3(u, bu);
    bernstein3Deriv(u, du);
#if defined(__SSE2__)
    const __m128 b0 = _mm_set1_ps(bu[0]), b1 = _mm_set1_ps(bu[1]), b2 = _mm_set1_ps(bu[2]),
                 b3 = _mm_set1_ps(bu[3]);
    const __m128 d0 = _mm_set1_ps(du[0]), d1 = _mm_set1_ps(du[1]), d2 = _mm_set1_ps(du[2]),
                 d3 = _mm_set1_ps(du[3]);
    for (int j = 0; j < 4; ++j) {
        const Vec3* row = &patch.cp[j * 4];
        const __m128 r0 = loadVec3(row[0]), r1 = loadVec3(row[1]), r2 = loadVec3(row[2]),
                     r3 = loadVec3(row[3]);
        _mm_store_ps(rows.point[j], _mm_add_ps(_mm_add_ps(_mm_add_ps(_mm_mul_ps(r0, b0), _mm_mul_ps(r1, b1)),
                                                          _mm_mul_ps(r2, b2)),
                                               _mm_mul_ps(r3, b3)));
        _mm_store_ps(rows.du[j], _mm_add_ps(_mm_add_ps(_mm_add_ps(_mm_mul_ps(r0, d0), _mm_mul_ps(r1, d1)),
                                                       _mm_mul_ps(r2, d2)),
                                            _mm_mul_ps(r3, d3)));
    }
#else
    for (int j = 0; j < 4; ++j) {
        const Vec3* row = &patch.cp[j * 4];
        const Vec3 cu = row[0] * bu[0] + row[1] * bu[1] + row[2] * bu[2] + row[3] * bu[3];
        const Vec3 cdu = row[0] * du[0] + row[1] * du[1] + row[2] * du[2] + row[3] * du[3];
        rows.point[j][0] = cu.x, rows.point[j][1] = cu.y, rows.point[j][2] = cu.z, rows.point[j][3] = 0.f;
        rows.du[j][0] = cdu.x, rows.du[j][1] = cdu.y, rows.du[j][2] = cdu.z, rows.du[j][3] = 0.f;
    }
#endif
}

Vec3 evalPatchAt(const PatchRowsAtU& rows, float v) {
    float bv[4];
    bernstein3(v, bv);
#if defined(__SSE2__)
    __m128 r = _mm_setzero_ps();
    for (int j = 0; j < 4; ++j) r = _mm_add_ps(r, _mm_mul_ps(_mm_load_ps(rows.point[j]), _mm_set1_ps(bv[j])));
    return storeVec3(r);
#else
    Vec3 r;
    for (int j = 0; j < 4; ++j) r += Vec3{rows.point[j][0], rows.point[j][1], rows.point[j][2]} * bv[j];
    return r;
#endif
}

SurfacePoint evalPatchDerivAt(const PatchRowsAtU& rows, float v) {
    float bv[4], dv[4];
    bernstein3(v, bv);
    bernstein3Deriv(v, dv);
    SurfacePoint s;
#if defined(__SSE2__)
    __m128 p = _mm_setzero_ps(), pu = _mm_setzero_ps(), pv = _mm_setzero_ps();
    for (int j = 0; j < 4; ++j) {
        const __m128 cu = _mm_load_ps(rows.point[j]), cdu = _mm_load_ps(rows.du[j]);
        const __m128 bvj = _mm_set1_ps(bv[j]);
        p = _mm_add_ps(p, _mm_mul_ps(cu, bvj));
        pv = _mm_add_ps(pv, _mm_mul_ps(cu, _mm_set1_ps(dv[j])));
        pu = _mm_add_ps(pu, _mm_mul_ps(cdu, bvj));
    }
    s.p = storeVec3(p), s.dpdu = storeVec3(pu), s.dpdv = storeVec3(pv);
#else
    for (int j = 0; j < 4; ++j) {
        const Vec3 cu{rows.point[j][0], rows.point[j][1], rows.point[j][2]};
        const Vec3 cdu{rows.du[j][0], rows.du[j][1], rows.du[j][2]};
        s.p += cu * bv[j];
        s.dpdv += cu * dv[j];
        s.dpdu += cdu * bv[j];
    }
#endif
    return s;
}

// The two steps at one (u, v): one definition of the derivative evaluation.
SurfacePoint evalPatchDeriv(const BezierPatch& patch, float u, float v) {
    PatchRowsAtU rows;
    patchRowsAtU(patch, u, rows);
    return evalPatchDerivAt(rows, v);
}

Vec3 patchNormal(const BezierPatch& patch, float u, float v) {
    SurfacePoint s = evalPatchDeriv(patch, u, v);
    Vec3 n = cross(s.dpdu, s.dpdv);
    float scale = dot(s.dpdu, s.dpdu) + dot(s.dpdv, s.dpdv);
    // A collapsed edge makes one derivative (near) zero. Step towards the domain centre; the normal
    // converges to the pole's tangent-plane normal as the step shrinks.
    for (float step = 1e-3f; dot(n, n) <= 1e-12f * scale * scale && step < 0.2f; step *= 4.f) {
        float uu = u + (u < 0.5f ? step : -step);
        float vv = v + (v < 0.5f ? step : -step);
        SurfacePoint t = evalPatchDeriv(patch, uu, vv);
        n = cross(t.dpdu, t.dpdv);
    }
    return n;
}

void splitCurve(const Vec3 c[4], float t, Vec3 left[4], Vec3 right[4]) {
    Vec3 p01 = lerp(c[0], c[1], t), p12 = lerp(c[1], c[2], t), p23 = lerp(c[2], c[3], t);
    Vec3 p012 = lerp(p01, p12, t), p123 = lerp(p12, p23, t);
    Vec3 mid = lerp(p012, p123, t);
    left[0] = c[0];
    left[1] = p01;
    left[2] = p012;
    left[3] = mid;
    right[0] = mid;
    right[1] = p123;
    right[2] = p23;
    right[3] = c[3];
}

void splitPatchU(const BezierPatch& p, float t, BezierPatch& lo, BezierPatch& hi) {
    for (int j = 0; j < 4; ++j) splitCurve(&p.cp[j * 4], t, &lo.cp[j * 4], &hi.cp[j * 4]);
}

void splitPatchV(const BezierPatch& p, float t, BezierPatch& lo, BezierPatch& hi) {
    for (int i = 0; i < 4; ++i) {
        Vec3 col[4] = {p.cp[i], p.cp[4 + i], p.cp[8 + i], p.cp[12 + i]}, a[4], b[4];
        splitCurve(col, t, a, b);
        for (int j = 0; j < 4; ++j) {
            lo.cp[j * 4 + i] = a[j];
            hi.cp[j * 4 + i] = b[j];
        }
    }
}

BezierPatch subPatch(const BezierPatch& p, float u0, float u1, float v0, float v1) {
    BezierPatch a = p, lo, hi;
    // Cut at u1 (keep the low part), then at u0 relative to the remaining [0,u1] (keep the high part).
    if (u1 < 1.f) {
        splitPatchU(a, u1, lo, hi);
        a = lo;
    }
    if (u0 > 0.f && u1 > 0.f) {
        splitPatchU(a, u0 / u1, lo, hi);
        a = hi;
    }
    if (v1 < 1.f) {
        splitPatchV(a, v1, lo, hi);
        a = lo;
    }
    if (v0 > 0.f && v1 > 0.f) {
        splitPatchV(a, v0 / v1, lo, hi);
        a = hi;
    }
    return a;
}

Bounds3 hullBounds(const BezierPatch& p) {
    Bounds3 b;
#if defined(__SSE2__)
    // minps(c, lo) is (c < lo ? c : lo), exactly std::min(lo, c) of Bounds3::extend (NaN and signed zeros
    // included), and maxps likewise: the same bounds, x, y and z at once (the weld's tolerance and the
    // framing take the hull of every patch).
    __m128 lo = loadVec3(b.lo), hi = loadVec3(b.hi);
    for (const Vec3& c : p.cp) {
        const __m128 v = loadVec3(c);
        lo = _mm_min_ps(v, lo);
        hi = _mm_max_ps(v, hi);
    }
    b.lo = storeVec3(lo), b.hi = storeVec3(hi);
#else
    for (const Vec3& c : p.cp) b.extend(c);
#endif
    return b;
}

void patchEdge(const BezierPatch& p, int e, Vec3 out[4]) {
    for (int k = 0; k < 4; ++k) {
        switch (e) {
            case 0:
                out[k] = p.cp[k];
                break;
            case 1:
                out[k] = p.cp[k * 4 + 3];
                break;
            case 2:
                out[k] = p.cp[12 + k];
                break;
            default:
                out[k] = p.cp[k * 4];
                break;
        }
    }
}

}  // namespace tessera
