// Bicubic Bezier patches: evaluation, derivatives, de Casteljau subdivision, bounds.
// Plain functions over plain data (no allocation, no globals) so any backend can share them.
// Control points are row-major: cp[v * 4 + u], u varies fastest (the RIB convention).
#pragma once
#include "core/hostdevice.h"
#include "core/vec.h"

namespace tessera {

struct BezierPatch {
    Vec3 cp[16];
    Vec3& at(int u, int v) { return cp[v * 4 + u]; }
    const Vec3& at(int u, int v) const { return cp[v * 4 + u]; }
};

struct SurfacePoint {
    Vec3 p, dpdu, dpdv;
};

// Cubic Bernstein basis B_i(t) and its derivative.
TESSERA_HD void bernstein3(float t, float b[4]) {
    float s = 1.f - t;
    b[0] = s * s * s;
    b[1] = 3.f * t * s * s;
    b[2] = 3.f * t * t * s;
    b[3] = t * t * t;
}
TESSERA_HD void bernstein3Deriv(float t, float d[4]) {
    float s = 1.f - t;
    d[0] = -3.f * s * s;
    d[1] = 3.f * s * s - 6.f * t * s;
    d[2] = 6.f * t * s - 3.f * t * t;
    d[3] = 3.f * t * t;
}

TESSERA_HD Vec3 evalCurve(const Vec3 c[4], float t) {
    float b[4];
    bernstein3(t, b);
    return c[0] * b[0] + c[1] * b[1] + c[2] * b[2] + c[3] * b[3];
}

// Position only.
Vec3 evalPatch(const BezierPatch& patch, float u, float v);
// Position and both first partial derivatives, sharing the basis evaluation.
SurfacePoint evalPatchDeriv(const BezierPatch& patch, float u, float v);

// evalPatch / evalPatchDeriv in two steps, for grids whose vertices share their u values: the sums of
// each row of the control net at one u (the row's point and its u-derivative), then their combination at
// v. evalPatchDeriv is these two steps; evalPatch (points only) does the same operations in the same
// order, so evalPatchAt and the point of evalPatchDerivAt give its bits.
struct PatchRowsAtU {
    alignas(16) float point[4][4];  // row j: x, y, z, 0
    alignas(16) float du[4][4];
};
void patchRowsAtU(const BezierPatch& patch, float u, PatchRowsAtU& rows);
Vec3 evalPatchAt(const PatchRowsAtU& rows, float v);               // = evalPatch(patch, u, v)
SurfacePoint evalPatchDerivAt(const PatchRowsAtU& rows, float v);  // = evalPatchDeriv(patch, u, v)

// Geometric normal dP/du x dP/dv. At a collapsed edge (e.g. the teapot's poles) one derivative vanishes;
// the normal is then the limit taken from just inside the domain, so poles shade like their neighbourhood.
Vec3 patchNormal(const BezierPatch& patch, float u, float v);

// de Casteljau split of a cubic curve at t.
void splitCurve(const Vec3 c[4], float t, Vec3 left[4], Vec3 right[4]);
// Split a patch at parameter t in u (lo = [0,t], hi = [t,1]) or in v.
void splitPatchU(const BezierPatch& p, float t, BezierPatch& lo, BezierPatch& hi);
void splitPatchV(const BezierPatch& p, float t, BezierPatch& lo, BezierPatch& hi);
// Control points of the sub-rectangle [u0,u1] x [v0,v1] (exact reparametrisation by de Casteljau).
BezierPatch subPatch(const BezierPatch& p, float u0, float u1, float v0, float v1);

// Bound of the control hull, which contains the surface (convex hull property).
Bounds3 hullBounds(const BezierPatch& p);

// Edge e of the patch as 4 control points: 0: v=0 (u increasing), 1: u=1 (v increasing),
// 2: v=1 (u increasing), 3: u=0 (v increasing).
void patchEdge(const BezierPatch& p, int e, Vec3 out[4]);

}  // namespace tessera
