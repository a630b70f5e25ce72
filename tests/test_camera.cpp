// The camera model's thin lens and shutter against geometry: rays of one pixel through different lens
// points meet on the focal plane, and the circle of confusion is the spread of a point's images.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "scene/camera.h"

namespace tessera::test::camera_tests {

namespace {
Camera lensCamera() {
    Camera c;
    c.width = 400;
    c.height = 300;
    c.fovDegrees = 40.f;
    c.fStop = 2.8f;
    c.focalLength = 0.05f;
    c.focalDistance = 5.f;
    return c;
}
Vec3 atDepth(const CameraRay& r, float z) {
    return r.origin + r.direction * ((z - r.origin.z) / r.direction.z);
}
}  // namespace

TEST(Camera, LensRadiusAndShutterFollowRi) {
    Camera c = lensCamera();
    EXPECT_FLOAT_EQ(c.lensRadius(), 0.05f / (2 * 2.8f));
    c.shutterOpen = 0.25f;
    c.shutterClose = 0.75f;
    EXPECT_FLOAT_EQ(c.timeAt(0.5f), 0.5f);
    EXPECT_FLOAT_EQ(c.timeAt(0.f), 0.25f);
    Camera pinhole;
    EXPECT_EQ(pinhole.lensRadius(), 0.f);
    EXPECT_FALSE(Projector(pinhole).hasLens());
}

TEST(Camera, PinholeRayProjectsBackToItsRasterPosition) {
    Camera c = lensCamera();
    c.fStop = std::numeric_limits<float>::infinity();
    const Projector p(c);
    const CameraRay r = generateRay(p, {123.25f, 77.5f}, {0.3f, -0.2f});
    EXPECT_EQ(r.origin, (Vec3{0, 0, 0}));
    const Vec3 q = p.toRaster(atDepth(r, 7.f));
    EXPECT_NEAR(q.x, 123.25f, 1e-3f);
    EXPECT_NEAR(q.y, 77.5f, 1e-3f);
}

TEST(Camera, ThinLensRaysMeetOnTheFocalPlaneAndSpreadByTheCircleOfConfusion) {
    const Projector p(lensCamera());
    ASSERT_TRUE(p.hasLens());
    const Vec2 raster{250.f, 100.f};
    const Vec3 focus = atDepth(generateRay(p, raster, {0, 0}), 5.f);
    const float zNear = 2.f;
    float spread = 0.f;
    for (int k = 0; k < 16; ++k) {
        const float phi = 2.f * float(M_PI) * k / 16;
        const Vec2 lens{std::cos(phi), std::sin(phi)};  // the lens rim
        const CameraRay r = generateRay(p, raster, lens);
        EXPECT_NEAR(r.origin.x, lens.x * p.lensRadius, 1e-7f);
        const Vec3 f = atDepth(r, 5.f);
        EXPECT_NEAR(f.x, focus.x, 1e-5f);
        EXPECT_NEAR(f.y, focus.y, 1e-5f);
        // The point of depth zNear this ray sees, projected through the pinhole: its distance from the
        // raster position is the circle of confusion at zNear, and lensShift says where it moved.
        const Vec3 q = atDepth(r, zNear);
        const Vec3 pin = p.toRaster(q);
        const Vec2 shift = p.lensShift(zNear, lens);
        EXPECT_NEAR(pin.x + shift.x, raster.x, 2e-3f);
        EXPECT_NEAR(pin.y + shift.y, raster.y, 2e-3f);
        spread = std::max(spread, std::hypot(pin.x - raster.x, pin.y - raster.y));
    }
    EXPECT_NEAR(spread, p.circleOfConfusion(zNear), 1e-2f);
    EXPECT_NEAR(p.circleOfConfusion(5.f), 0.f, 1e-6f);  // in focus
    EXPECT_GT(p.circleOfConfusion(50.f), 0.f);
}

TEST(Camera, ConcentricDiskMapMatchesTheTrigonometricForm) {
    // squareToDisk's polynomial sine and cosine against the map written with std::cos and std::sin in
    // double precision, over a dense grid of the square and its edges and axes.
    double worst = 0;
    for (int i = 0; i <= 512; ++i)
        for (int j = 0; j <= 512; ++j) {
            const float u = std::min(float(i) / 512.f, 0.99999994f),
                        v = std::min(float(j) / 512.f, 0.99999994f);
            const double a = 2.0 * u - 1.0, b = 2.0 * v - 1.0;
            double x = 0, y = 0;
            if (a != 0 || b != 0) {
                const double pi4 = std::numbers::pi / 4;
                const double r = std::abs(a) > std::abs(b) ? a : b;
                const double phi = std::abs(a) > std::abs(b) ? pi4 * (b / a) : 2 * pi4 - pi4 * (a / b);
                x = r * std::cos(phi), y = r * std::sin(phi);
            }
            const Vec2 d = squareToDisk(u, v);
            worst = std::max({worst, std::abs(d.x - x), std::abs(d.y - y)});
        }
    std::printf("largest difference from the trigonometric map: %.3g\n", worst);
    EXPECT_LT(worst, 4e-7);
}

TEST(Camera, ConcentricDiskMapStaysInTheDisk) {
    for (int i = 0; i < 32; ++i)
        for (int j = 0; j < 32; ++j) {
            const Vec2 d = squareToDisk((i + 0.5f) / 32, (j + 0.5f) / 32);
            EXPECT_LE(d.x * d.x + d.y * d.y, 1.f + 1e-6f);
        }
    // The corners of the square go to the rim, the centre to the centre.
    const Vec2 c = squareToDisk(1.f, 1.f);
    EXPECT_NEAR(c.x * c.x + c.y * c.y, 1.f, 1e-6f);
    const Vec2 o = squareToDisk(0.5f, 0.5f);
    EXPECT_EQ(o.x, 0.f);
}

}  // namespace tessera::test::camera_tests
