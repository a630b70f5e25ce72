// Shadow-map lookups: the visibility of a light at a shading point from depth maps rendered from the light
// (Reyes renders them with its own pipeline, paper 001 sec. 3.5; reyes/shadow_maps.h). Plain data and
// inline kernels, so that any engine (and a device backend) can read a map.
//
// A lookup is percentage-closer filtered (Reeves, Salesin and Cook, "Rendering antialiased shadows with
// depth maps", SIGGRAPH 1987): the depth test is made at every texel under a box of `filterWidth` texels
// centred on the point's projection, and the results are averaged with the texels' overlap with the box as
// weights, so the shadow's edge is a ramp about filterWidth texels wide. Each texel's test compares the
// texel's depth with the depth of the receiver's tangent plane seen through that texel's centre
// (receiver-plane depth bias), not with the point's own depth: a flat or convex lit surface then never
// shadows itself however wide the filter, and only a small constant bias (`bias` texels, for the error of
// the map's micropolygons and rounding) is needed, so contact shadows do not detach.
#pragma once
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

#include "core/hostdevice.h"
#include "core/transform.h"
#include "core/vec.h"

namespace tessera {

// A rigid (or any affine) map p' = M p + t in single precision.
struct AffineFrame {
    float m[3][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}};
    TESSERA_HD Vec3 point(Vec3 p) const {
        return {m[0][0] * p.x + m[0][1] * p.y + m[0][2] * p.z + m[0][3],
                m[1][0] * p.x + m[1][1] * p.y + m[1][2] * p.z + m[1][3],
                m[2][0] * p.x + m[2][1] * p.y + m[2][2] * p.z + m[2][3]};
    }
    TESSERA_HD Vec3 vector(Vec3 v) const {
        return {m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z, m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
                m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z};
    }
};

// One depth image: texel (x, y) holds the nearest light-space depth z seen through its centre (x + 0.5,
// y + 0.5), infinity where nothing was seen. Light space is the face camera's space (RenderMan camera
// convention, +z away from the light); texel coordinates as the camera's raster: x/z sx + ox, y/z sy + oy
// (orthographic: x sx + ox, y sy + oy).
struct ShadowMapFace {
    AffineFrame lightFromShading;  // the engine's shading space to this face's light space
    bool perspective = false;
    float sx = 1, sy = 1, ox = 0, oy = 0;
    int width = 0, height = 0;     // texels
    const float* depth = nullptr;  // width * height; nullptr: an empty face (everything lit)
};

// The map of one light: one face (distant: orthographic; spot: perspective), or six (a cube map around a
// point light: +x, -x, +y, -y, +z, -z of `cubeFromShading`, each covering its 90 degrees plus a margin of
// the filter's width, so that a lookup stays on the face of its direction's major axis).
struct ShadowMapLookup {
    const ShadowMapFace* faces = nullptr;
    int faceCount = 0;
    AffineFrame cubeFromShading;  // cube maps: shading space to light-centred axes
    float bias = 0.5f;            // texels
    float filterWidth = 2.f;      // texels
};

// Texel-space position and world size of a texel at light-space point p.
TESSERA_HD void shadowMapProject(const ShadowMapFace& f, Vec3 p, float& tx, float& ty, float& texelWorld) {
    const float iz = f.perspective ? 1.f / p.z : 1.f;
    tx = p.x * iz * f.sx + f.ox;
    ty = p.y * iz * f.sy + f.oy;
    texelWorld = (f.perspective ? p.z : 1.f) / std::fabs(f.sx);
}

// Light-space depth of the receiver's tangent plane (through p, normal n) seen through texel position
// (tx, ty). Where the plane is (nearly) parallel to the lines of sight the point's own depth is used.
TESSERA_HD float receiverPlaneDepth(const ShadowMapFace& f, Vec3 p, Vec3 n, float tx, float ty) {
    const float x = (tx - f.ox) / f.sx, y = (ty - f.oy) / f.sy;
    if (!f.perspective) {  // lines of sight along +z through (x, y)
        if (!(std::fabs(n.z) > 1e-4f * (std::fabs(n.x) + std::fabs(n.y)))) return p.z;
        return p.z - (n.x * (x - p.x) + n.y * (y - p.y)) / n.z;
    }
    // The line of sight t (x, y, 1) meets the plane n.(q - p) = 0 at t = n.p / n.(x, y, 1); depth = t.
    const float nd = n.x * x + n.y * y + n.z, np = n.x * p.x + n.y * p.y + n.z * p.z;
    const float t = np / nd;
    if (!(std::fabs(nd) > 1e-4f * (std::fabs(n.x) + std::fabs(n.y) + std::fabs(n.z))) || !(t > 0.f))
        return p.z;
    return t;
}

// Where a lookup at light-space point p reads a face: its texel position (tx, ty), the filter box's half
// width, the bias in world units and the texel rows and columns under the box. False when p is not in
// front of the face's map (no map, behind the light, projecting off any map, or a box wider than any map):
// the point is lit.
struct ShadowFootprint {
    float tx, ty, half, biasWorld;
    int x0, x1, y0, y1;
};
TESSERA_HD bool shadowFootprint(const ShadowMapFace& f, Vec3 p, float bias, float filterWidth,
                                ShadowFootprint& fp) {
    if (!f.depth || (f.perspective && !(p.z > 0.f))) return false;  // no map, or behind the light
    float texelWorld;
    shadowMapProject(f, p, fp.tx, fp.ty, texelWorld);
    if (!(std::fabs(fp.tx) < 1e8f && std::fabs(fp.ty) < 1e8f)) return false;
    fp.half = 0.5f * filterWidth, fp.biasWorld = bias * texelWorld;
    if (!(fp.half < 1e8f)) return false;  // a filter wider than any map (and the range of floorToInt)
    // floor(v) as an int for |v| < 2^31 (here under 2e8), without a call to floorf: truncation, then one
    // down for negative non-integers.
    auto floorToInt = [](float v) {
        const int i = int(v);
        return float(i) > v ? i - 1 : i;
    };
    fp.x0 = floorToInt(fp.tx - fp.half), fp.x1 = floorToInt(fp.tx + fp.half);
    fp.y0 = floorToInt(fp.ty - fp.half), fp.y1 = floorToInt(fp.ty + fp.half);
    return true;
}

// The percentage-closer filter texel by texel over footprint fp of point p
// (shadowMapFaceVisibilityEachTexel).
TESSERA_HD float shadowFilterEachTexel(const ShadowMapFace& f, Vec3 p, Vec3 n, const ShadowFootprint& fp) {
    const float tx = fp.tx, ty = fp.ty, half = fp.half, biasWorld = fp.biasWorld;
    float lit = 0.f, total = 0.f;
    for (int y = fp.y0; y <= fp.y1; ++y) {
        const float wy = std::fmin(float(y + 1), ty + half) - std::fmax(float(y), ty - half);
        if (!(wy > 0.f)) continue;
        for (int x = fp.x0; x <= fp.x1; ++x) {
            const float wx = std::fmin(float(x + 1), tx + half) - std::fmax(float(x), tx - half);
            if (!(wx > 0.f)) continue;
            const float w = wx * wy;
            total += w;
            if (x < 0 || y < 0 || x >= f.width || y >= f.height) {
                lit += w;
                continue;
            }
            const float stored = f.depth[size_t(y) * size_t(f.width) + size_t(x)];
            const float receiver = receiverPlaneDepth(f, p, n, float(x) + 0.5f, float(y) + 0.5f);
            if (receiver - biasWorld <= stored) lit += w;
        }
    }
    return total > 0.f ? lit / total : 1.f;
}

// Percentage-closer filtered visibility in [0, 1] of one face at light-space point p with normal n, texel
// by texel as the filter is defined: the receiver plane's depth (receiverPlaneDepth) against each texel
// under the box, weighted by the texel's overlap with it. Texels outside the face and empty texels count as
// lit. shadowMapFaceVisibility gives the same bits faster; this form serves footprints it does not take,
// and is the reference its test and benchmark compare with.
TESSERA_HD float shadowMapFaceVisibilityEachTexel(const ShadowMapFace& f, Vec3 p, Vec3 n, float bias,
                                                  float filterWidth) {
    ShadowFootprint fp;
    return shadowFootprint(f, p, bias, filterWidth, fp) ? shadowFilterEachTexel(f, p, n, fp) : 1.f;
}

// shadowMapFaceVisibilityEachTexel's result, bit for bit, in about half its time where the footprint lies
// inside the map and is at most 8 texels wide (the rest is left to it).
TESSERA_HD float shadowMapFaceVisibility(const ShadowMapFace& f, Vec3 p, Vec3 n, float bias,
                                         float filterWidth) {
    ShadowFootprint fp;
    if (!shadowFootprint(f, p, bias, filterWidth, fp)) return 1.f;
    const float tx = fp.tx, ty = fp.ty, half = fp.half, biasWorld = fp.biasWorld;
    const int x0 = fp.x0, x1 = fp.x1, y0 = fp.y0, y1 = fp.y1;
    // A texel's weight: its overlap with the box along one axis (0 or less: outside the box). Plain
    // comparisons, not fminf / fmaxf (calls here): they differ only between -0 and +0, where the overlap is
    // 0 and the texel is skipped either way; tx and ty are finite.
    auto overlap = [](int k, float lo, float hi) {
        const float a = float(k + 1) < hi ? float(k + 1) : hi, b = float(k) > lo ? float(k) : lo;
        return a - b;
    };
    constexpr int kColumns = 8;
    if (x1 - x0 < kColumns && x0 >= 0 && y0 >= 0 && x1 < f.width && y1 < f.height) {
        // The common footprint, inside the map and at most kColumns texels wide: receiverPlaneDepth at the
        // texel centres from its terms in x, computed once per column, and in y, once per row (the same
        // operations, so the same bits; per texel, its three divisions were most of a lookup).
        float columnTerm[kColumns], columnWeight[kColumns];
        const int columns = x1 - x0 + 1;
        for (int i = 0; i < columns; ++i) {
            const float lx = (float(x0 + i) + 0.5f - f.ox) / f.sx;
            columnTerm[i] = f.perspective ? n.x * lx : n.x * (lx - p.x);
            columnWeight[i] = overlap(x0 + i, tx - half, tx + half);
        }
        const float np = n.x * p.x + n.y * p.y + n.z * p.z;
        const float ndLimit = 1e-4f * (std::fabs(n.x) + std::fabs(n.y) + std::fabs(n.z));
        const bool flat = !f.perspective && !(std::fabs(n.z) > 1e-4f * (std::fabs(n.x) + std::fabs(n.y)));
        float lit = 0.f, total = 0.f;
        for (int y = y0; y <= y1; ++y) {
            const float wy = overlap(y, ty - half, ty + half);
            if (!(wy > 0.f)) continue;
            const float ly = (float(y) + 0.5f - f.oy) / f.sy;
            const float rowTerm = f.perspective ? n.y * ly : n.y * (ly - p.y);
            const float* row = f.depth + size_t(y) * size_t(f.width) + size_t(x0);
            for (int i = 0; i < columns; ++i) {
                if (!(columnWeight[i] > 0.f)) continue;
                const float w = columnWeight[i] * wy;
                total += w;
                float receiver;
                if (!f.perspective) {
                    receiver = flat ? p.z : p.z - (columnTerm[i] + rowTerm) / n.z;
                } else {
                    const float nd = columnTerm[i] + rowTerm + n.z, t = np / nd;
                    receiver = !(std::fabs(nd) > ndLimit) || !(t > 0.f) ? p.z : t;
                }
                if (receiver - biasWorld <= row[i]) lit += w;
            }
        }
        return total > 0.f ? lit / total : 1.f;
    }
    return shadowFilterEachTexel(f, p, n, fp);
}

// The face of a cube map that a light-centred direction d falls in: the major axis, + before -.
TESSERA_HD int cubeFaceOf(Vec3 d) {
    const float ax = std::fabs(d.x), ay = std::fabs(d.y), az = std::fabs(d.z);
    if (ax >= ay && ax >= az) return d.x >= 0.f ? 0 : 1;
    if (ay >= az) return d.y >= 0.f ? 2 : 3;
    return d.z >= 0.f ? 4 : 5;
}

// Visibility of the map's light at shading-space point P with normal N (either side).
TESSERA_HD float shadowMapVisibility(const ShadowMapLookup& map, Vec3 P, Vec3 N) {
    if (map.faceCount <= 0) return 1.f;
    const int face = map.faceCount == 6 ? cubeFaceOf(map.cubeFromShading.point(P)) : 0;
    const ShadowMapFace& f = map.faces[face];
    return shadowMapFaceVisibility(f, f.lightFromShading.point(P), f.lightFromShading.vector(N), map.bias,
                                   map.filterWidth);
}

// ---- maps read from files (host only; shadow_map.cpp) ---------------------------------------------------

// The affine part of m (its last row is taken to be 0 0 0 1).
inline AffineFrame affineFrameOf(const Mat4& m) {
    AffineFrame f;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 4; ++c) f.m[r][c] = float(m.m[r][c]);
    return f;
}

// The face of a depth map made by another view (a Display "zfile", MakeShadow's output), for lookups from
// shading space: its light space is that view's camera space (worldToCamera), its texel mapping that
// view's worldToNDC (RenderMan's NDC: x, y in [0, 1] from the top-left corner) times width and height.
// Returns "" and fills `face` (all but `depth`), or says why the matrices are not those of a perspective
// or orthographic camera looking along +z (skewed or off-axis projections are not read).
std::string fileShadowMapFace(const Mat4& worldToCamera, const Mat4& worldToNDC, int width, int height,
                              const Mat4& worldFromShading, ShadowMapFace& face);

}  // namespace tessera
