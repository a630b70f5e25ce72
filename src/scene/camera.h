// Camera and image options following the RenderMan camera model (RI spec 3.2, ch. 4):
// camera space is left-handed, +x right, +y up, +z into the screen; a perspective projection maps
// the screen window onto the raster.
#pragma once
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "core/hostdevice.h"
#include "core/motion_transform.h"
#include "core/transform.h"

namespace tessera {

struct Camera {
    int width = 640, height = 480;  // Format xres yres
    float pixelAspect = 1.f;
    bool perspective = true;
    float fovDegrees = 90.f;  // Projection "perspective" "fov": the full angle of the shorter screen axis
    bool hasScreenWindow = false;
    float screenWindow[4] = {-1, 1, -1, 1};  // left right bottom top
    float frameAspect = 0.f;                 // FrameAspectRatio, 0 = from the resolution
    float nearClip = 1e-4f, farClip = 1e30f;
    Mat4 cameraFromWorld;  // the CTM at WorldBegin, at shutter open
    // A moving camera (MotionBegin around the camera transform): keys refined to at most 2 degrees of turn
    // per segment (refineTransformKeys); empty or one key: static. cameraFromWorldAt interpolates them.
    std::vector<TransformKey> motion;
    // RI Shutter open close: the interval the camera sample's time spans (RI default 0 0: no motion).
    float shutterOpen = 0.f, shutterClose = 0.f;
    // RI DepthOfField fstop focallength focaldistance (camera-space units); fstop = infinity: pinhole.
    float fStop = std::numeric_limits<float>::infinity(), focalLength = 0.f, focalDistance = 0.f;

    // Thin lens (RI spec 3.2, sec. 4.1.3): radius = focallength / (2 fstop); 0 for a pinhole.
    float lensRadius() const {
        return (std::isfinite(fStop) && fStop > 0.f && focalLength > 0.f) ? focalLength / (2.f * fStop) : 0.f;
    }
    // Time of a camera sample u in [0,1) within the shutter interval.
    float timeAt(float u) const { return shutterOpen + (shutterClose - shutterOpen) * u; }
    bool hasShutter() const { return shutterClose > shutterOpen; }
    bool moving() const { return motion.size() > 1 && hasShutter(); }
    // The camera transform at scene time `time` (decomposed interpolation between the keys).
    Mat4 cameraFromWorldAt(double time) const {
        return motion.size() > 1 ? transformAt(motion, time) : cameraFromWorld;
    }

    float aspect() const { return frameAspect > 0 ? frameAspect : width * pixelAspect / height; }
    // Screen window, the default derived from the frame aspect ratio as the spec prescribes.
    void window(float& l, float& r, float& b, float& t) const;
};

// Everything needed to project camera-space points to raster space and to generate camera rays,
// precomputed: the one place both engines take the camera model from.
struct Projector {
    float sx, sy, ox, oy;  // raster = (x/z * sx + ox, y/z * sy + oy) for perspective (sy < 0: y up)
    bool perspective;
    float nearClip, farClip;
    float lensRadius = 0.f, focalDistance = 0.f;  // thin lens (0: pinhole)
    explicit Projector(const Camera& c);
    // Raster position of a camera-space point (caller guarantees z > 0 for perspective).
    Vec3 toRaster(Vec3 p) const {
        float iz = perspective ? 1.f / p.z : 1.f;
        return {p.x * iz * sx + ox, p.y * iz * sy + oy, p.z};
    }
    // Bounding rectangle, in raster space, of the projected corners of a camera-space box: it contains the
    // box's projection when the box lies in front of the eye. False (rectangle unusable) when a corner is at
    // or behind the eye of a perspective camera.
    bool rasterBounds(const Bounds3& b, float& x0, float& x1, float& y0, float& y1) const {
        x0 = y0 = INFINITY, x1 = y1 = -INFINITY;
        for (int c = 0; c < 8; ++c) {
            const Vec3 p{c & 1 ? b.hi.x : b.lo.x, c & 2 ? b.hi.y : b.lo.y, c & 4 ? b.hi.z : b.lo.z};
            if (perspective && !(p.z > 0.f)) return false;
            const Vec3 r = toRaster(p);
            x0 = std::min(x0, r.x), x1 = std::max(x1, r.x), y0 = std::min(y0, r.y), y1 = std::max(y1, r.y);
        }
        return true;
    }
    // Camera-space point on the z = 1 plane (perspective) or the z = 0 plane (orthographic) that projects
    // to raster position (x, y).
    Vec3 fromRaster(float x, float y) const {
        return {(x - ox) / sx, (y - oy) / sy, perspective ? 1.f : 0.f};
    }

    bool hasLens() const { return lensRadius > 0.f; }
    // Thin lens, ray through the focal-plane point: a lens point a on the unit disk shifts the screen image
    // of a point at camera-space depth z by a * lensCoefficient(z) * (sx, sy) raster pixels.
    float lensCoefficient(float z) const { return lensRadius * (1.f / focalDistance - 1.f / z); }
    // The largest |lensCoefficient| over depths [z0, z1] (0 for a pinhole): |1/fd - 1/z| is largest at an
    // end.
    float maxLensCoefficient(float z0, float z1) const {
        if (!hasLens() || !perspective) return 0.f;
        return std::max(std::abs(lensCoefficient(z0)), std::abs(lensCoefficient(z1)));
    }
    // Radius in raster pixels of the circle of confusion of a camera-space depth z (Reyes' blur bound).
    float circleOfConfusion(float z) const {
        if (!hasLens() || !perspective) return 0.f;
        return std::abs(lensCoefficient(z)) * std::max(std::abs(sx), std::abs(sy));
    }
    // Screen-space shift (raster pixels) of a point at depth z seen through lens position (lu, lv) in
    // [-1,1]^2 on the unit disk: what Reyes adds to a micropolygon's raster position for a lens sample.
    Vec2 lensShift(float z, Vec2 lens) const {
        if (!hasLens() || !perspective) return {};
        const float k = lensCoefficient(z);
        return {lens.x * k * sx, lens.y * k * sy};
    }
};

// Camera ray for a raster position and a lens position on the unit disk (camera space, unnormalised
// direction). Pinhole: from the eye through the pixel. Thin lens: from the lens point through the point of
// the focal plane that the pinhole ray would hit (pbrt-v4's thin-lens camera, RI focaldistance).
struct CameraRay {
    Vec3 origin, direction;
};
inline CameraRay generateRay(const Projector& p, Vec2 raster, Vec2 lensDisk) {
    const Vec3 onPlane = p.fromRaster(raster.x, raster.y);
    CameraRay r;
    if (p.perspective) {
        r.origin = {0, 0, 0};
        r.direction = onPlane;
    } else {
        r.origin = onPlane;
        r.direction = {0, 0, 1};
    }
    if (p.hasLens() && p.perspective) {
        const Vec3 focus = onPlane * p.focalDistance;  // onPlane.z = 1
        r.origin = {lensDisk.x * p.lensRadius, lensDisk.y * p.lensRadius, 0.f};
        r.direction = focus - r.origin;
    }
    return r;
}

// sin x and cos x for |x| <= pi/4 by the minimax polynomials of Cephes' sinf and cosf (within about one ulp
// there). The concentric map's angle never leaves that range, and these plain multiply-adds run lane by
// lane in the blurred film's AVX2 path (BlurPattern::pixelSamplesAt) with the same bits, which libm's sincosf
// would not give.
// The polynomials' coefficients (sin: x^3, x^5, x^7; cos: x^4, x^6, x^8), named once for both paths.
constexpr float kSin3 = -1.6666654611e-1f, kSin5 = 8.3321608736e-3f, kSin7 = -1.9515295891e-4f;
constexpr float kCos4 = 4.166664568298827e-2f, kCos6 = -1.388731625493765e-3f, kCos8 = 2.443315711809948e-5f;
constexpr float kQuarterPi = 0.78539816f;
TESSERA_HD void sinCosQuarterTurn(float x, float& s, float& c) {
    const float z = x * x;
    s = x + x * z * (kSin3 + z * (kSin5 + z * kSin7));
    c = 1.f - 0.5f * z + z * z * (kCos4 + z * (kCos6 + z * kCos8));
}

// Concentric map of [0,1)^2 onto the unit disk (Shirley and Chiu 1997): keeps the sampler's
// stratification on the lens. With the major axis a (|a| > |b|) the point is a (cos phi, sin phi),
// phi = pi/4 b/a; with b major, phi = pi/2 - pi/4 a/b, i.e. b (sin x, cos x) with x = pi/4 a/b.
TESSERA_HD Vec2 squareToDisk(float u, float v) {
    const float a = 2.f * u - 1.f, b = 2.f * v - 1.f;
    if (a == 0.f && b == 0.f) return {0.f, 0.f};
    const bool aMajor = std::abs(a) > std::abs(b);
    const float r = aMajor ? a : b, x = kQuarterPi * (aMajor ? b / a : a / b);
    float s, c;
    sinCosQuarterTurn(x, s, c);
    return aMajor ? Vec2{r * c, r * s} : Vec2{r * s, r * c};
}

}  // namespace tessera
