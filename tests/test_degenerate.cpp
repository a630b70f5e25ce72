// Degenerate geometry (issue 5): collapsed edges and corners, patches collapsed to a point or a line,
// folded patches, poles, tiny and huge scene scales, patches at or through the eye plane and non-finite
// control points. Both engines must render them without NaNs, black dots or crashes.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "io/scene_loader.h"
#include "render/render.h"
#include "test_util.h"

namespace tessera::test::degenerate_tests {

class Degenerate : public ::testing::TestWithParam<std::string> {
  protected:
    Image renderScene(const Scene& s) const {
        RenderSettings st;
        st.engine = GetParam();
        st.threads = 2;
        st.maxDepth = 1;
        return render(s, st).image;
    }
};

namespace {

// Every channel finite, coverage in [0, 1], colour premultiplied (no colour without coverage).
void expectFiniteImage(const Image& img) {
    int bad = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            const float* p = img.pixel(x, y);
            bool ok = std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]) &&
                      std::isfinite(p[3]) && p[3] >= 0.f && p[3] <= 1.0001f && p[0] >= 0.f && p[1] >= 0.f &&
                      p[2] >= 0.f;
            if (!ok && bad++ < 5)
                ADD_FAILURE() << "pixel (" << x << "," << y << ") = " << p[0] << " " << p[1] << " " << p[2]
                              << " " << p[3];
        }
    EXPECT_EQ(bad, 0) << "non-finite or out-of-range pixels";
}

float luminance(const float* p) {
    return 0.2126f * p[0] + 0.7152f * p[1] + 0.0722f * p[2];
}

// A flat patch facing the camera under an ambient and a distant light has one colour: every fully
// covered pixel must have it (a degenerate normal shows up as a dark or bright dot).
void expectUniformColour(const Image& img, float tolerance = 0.02f) {
    std::vector<float> lum;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x)
            if (img.pixel(x, y)[3] > 0.999f) lum.push_back(luminance(img.pixel(x, y)));
    ASSERT_GT(lum.size(), 20u) << "the patch is visible";
    std::vector<float> sorted = lum;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    float median = sorted[sorted.size() / 2];
    ASSERT_GT(median, 0.05f) << "lit, not black";
    int off = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            const float* p = img.pixel(x, y);
            if (p[3] <= 0.999f) continue;
            if (std::fabs(luminance(p) - median) > tolerance * median && off++ < 5)
                ADD_FAILURE() << "pixel (" << x << "," << y << ") luminance " << luminance(p) << ", median "
                              << median;
        }
    EXPECT_EQ(off, 0);
}

// No isolated dark pixel: every fully covered pixel whose 8 neighbours are covered is at least 60% as
// bright as their mean.
void expectNoBlackDots(const Image& img) {
    int dots = 0;
    for (int y = 1; y + 1 < img.height; ++y)
        for (int x = 1; x + 1 < img.width; ++x) {
            if (img.pixel(x, y)[3] < 0.999f) continue;
            float sum = 0;
            bool covered = true;
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    if (dx == 0 && dy == 0) continue;
                    const float* q = img.pixel(x + dx, y + dy);
                    covered &= q[3] > 0.999f;
                    sum += luminance(q);
                }
            if (!covered) continue;
            float l = luminance(img.pixel(x, y)), mean = sum / 8;
            if (l < 0.6f * mean && dots++ < 5)
                ADD_FAILURE() << "dark dot at (" << x << "," << y << "): " << l << " vs neighbours " << mean;
        }
    EXPECT_EQ(dots, 0);
}

Scene oneLitPatch(const BezierPatch& p, int size = 64) {
    Scene s = cameraSpaceScene(size, size, 40.f);
    s.lights[1].to = {0, 0, 1};  // a distant light straight along the view: flat patches are evenly lit
    addPatch(s, p);
    return s;
}

}  // namespace

TEST_P(Degenerate, CollapsedEdge) {
    BezierPatch square = flatSquare(2, 5);
    double full = alphaSum(renderScene(oneLitPatch(square)));
    // All four control points of the top edge equal: a triangle-like patch with a degenerate edge.
    BezierPatch p = square;
    for (int u = 0; u < 4; ++u) p.at(u, 3) = {0, 1, 5};
    Image img = renderScene(oneLitPatch(p));
    expectFiniteImage(img);
    expectUniformColour(img);
    double a = alphaSum(img);
    EXPECT_GT(a, 0.4 * full);
    EXPECT_LT(a, 0.9 * full);
}

TEST_P(Degenerate, TwoCollapsedEdgesMeetingAtACorner) {
    BezierPatch p = flatSquare(2, 5);
    Vec3 corner = p.at(0, 0);
    for (int k = 0; k < 4; ++k) p.at(k, 0) = p.at(0, k) = corner;
    Image img = renderScene(oneLitPatch(p));
    expectFiniteImage(img);
    expectUniformColour(img);
    EXPECT_GT(alphaSum(img), 100.0);
}

TEST_P(Degenerate, CollapsedCornerBlock) {
    // The 2x2 control points at one corner coincide: both derivatives vanish at that corner.
    BezierPatch p = flatSquare(2, 5);
    for (int v = 0; v < 2; ++v)
        for (int u = 0; u < 2; ++u) p.at(u, v) = p.at(0, 0);
    Image img = renderScene(oneLitPatch(p));
    expectFiniteImage(img);
    expectUniformColour(img);
    EXPECT_GT(alphaSum(img), 100.0);
}

TEST_P(Degenerate, PatchCollapsedToAPoint) {
    BezierPatch p;
    for (Vec3& c : p.cp) c = {0.01f, 0.02f, 5.f};
    Image img = renderScene(oneLitPatch(p));
    expectFiniteImage(img);
    EXPECT_LT(alphaSum(img), 1.5) << "at most a pixel's worth of coverage";
}

TEST_P(Degenerate, ZeroAreaPatches) {
    // All control points on one line.
    BezierPatch line;
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 4; ++u) {
            float t = (u + v) / 6.f;
            line.at(u, v) = {-1 + 2 * t, -0.5f + t, 5 + t};
        }
    Image img = renderScene(oneLitPatch(line));
    expectFiniteImage(img);
    EXPECT_LT(alphaSum(img), 4.0);
    // A flat patch seen exactly edge-on (its plane contains the eye).
    BezierPatch edgeOn;
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 4; ++u) edgeOn.at(u, v) = {0.f, -1 + 2 * u / 3.f, 4 + 2 * v / 3.f};
    img = renderScene(oneLitPatch(edgeOn));
    expectFiniteImage(img);
    EXPECT_LT(alphaSum(img), 40.0) << "at most a one-pixel line";
}

TEST_P(Degenerate, PatchFoldedOntoItself) {
    // In v the surface goes up and comes back down within the plane z = 5: it covers the lower part twice
    // and has a fold line where dP/dv = 0.
    BezierPatch p = flatSquare(2, 5);
    const float ys[4] = {-1.f, 1.5f, 1.5f, -0.5f};
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 4; ++u) p.at(u, v).y = ys[v];
    Image img = renderScene(oneLitPatch(p));
    expectFiniteImage(img);
    expectUniformColour(img);
    EXPECT_GT(alphaSum(img), 100.0);
}

TEST_P(Degenerate, SpherePolesHaveNoBlackDots) {
    // Eight patches with collapsed edges at the poles; one pole faces the camera at the image centre.
    Scene s = cameraSpaceScene(96, 96, 30.f);
    for (const BezierPatch& p : octantSphere(1.f, {0, 0, 5})) addPatch(s, p);
    Image img = renderScene(s);
    expectFiniteImage(img);
    expectNoBlackDots(img);
    // The pole pixel matches the ring of pixels around it.
    const float* c = img.pixel(48, 48);
    float ring = 0;
    int n = 0;
    for (int dy = -2; dy <= 2; ++dy)
        for (int dx = -2; dx <= 2; ++dx)
            if (std::max(std::abs(dx), std::abs(dy)) == 2)
                ring += luminance(img.pixel(48 + dx, 48 + dy)), ++n;
    ring /= float(n);
    EXPECT_GT(c[3], 0.999f);
    EXPECT_NEAR(luminance(c), ring, 0.1f * ring);
    // The other pole, seen from the side: rotate the sphere so the pole lies on the silhouette's inside.
    Scene side = cameraSpaceScene(96, 96, 30.f);
    for (BezierPatch p : octantSphere(1.f, {0, 0, 0})) {
        for (Vec3& q : p.cp) q = {q.x, q.z * 0.8f + q.y * 0.6f, 5 + q.z * -0.6f + q.y * 0.8f};
        addPatch(side, p);
    }
    img = renderScene(side);
    expectFiniteImage(img);
    expectNoBlackDots(img);
}

// The teapot scaled by 1e-6 .. 1e6 (camera, clipping planes and all) is the same picture.
TEST_P(Degenerate, SceneScaleFromMicroToMega) {
    Scene base = loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/teapot.rib", nullptr);
    base.camera.width = 80;
    base.camera.height = 60;
    base.image.pixelSamplesX = base.image.pixelSamplesY = 2;
    auto scaled = [&](double k) {
        Scene s = base;
        for (BezierPatch& p : s.patches)
            for (Vec3& c : p.cp) c = c * float(k);
        s.camera.cameraFromWorld =
            Mat4::scale(k, k, k) * base.camera.cameraFromWorld * Mat4::scale(1 / k, 1 / k, 1 / k);
        s.camera.nearClip = float(base.camera.nearClip * k);
        s.camera.farClip = float(std::min(1e30, base.camera.farClip * k));
        for (Light& l : s.lights) l.from = l.from * float(k), l.to = l.to * float(k);
        return s;
    };
    Image ref = renderScene(scaled(1));
    expectFiniteImage(ref);
    double refAlpha = alphaSum(ref);
    ASSERT_GT(refAlpha, 0.2 * 80 * 60);
    for (double k : {1e-6, 1e-3, 1e3, 1e6}) {
        SCOPED_TRACE("scale " + std::to_string(k));
        Image img = renderScene(scaled(k));
        expectFiniteImage(img);
        EXPECT_NEAR(alphaSum(img), refAlpha, 0.01 * refAlpha);
        int differ = 0;
        double lumRef = 0, lum = 0;
        for (int y = 0; y < ref.height; ++y)
            for (int x = 0; x < ref.width; ++x) {
                differ += std::fabs(img.pixel(x, y)[3] - ref.pixel(x, y)[3]) > 0.3f;
                lumRef += luminance(ref.pixel(x, y));
                lum += luminance(img.pixel(x, y));
            }
        EXPECT_LE(differ, 10) << "pixels whose coverage changed with the scale";
        EXPECT_NEAR(lum, lumRef, 0.02 * lumRef) << "same shading at every scale";
    }
}

TEST_P(Degenerate, PatchesAtAndThroughTheEyePlane) {
    // A floor running from behind the eye (z = -3) to the far distance, crossing the eye plane.
    BezierPatch floor;
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 4; ++u) floor.at(u, v) = {-2 + 4 * u / 3.f, -0.5f, -3 + 12 * v / 3.f};
    Image img = renderScene(oneLitPatch(floor));
    expectFiniteImage(img);
    EXPECT_GT(alphaSum(img), 200.0) << "the part in front of the eye is visible";
    // One edge exactly in the eye plane (z = 0).
    BezierPatch touching;
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 4; ++u)
            touching.at(u, v) = {-1 + 2 * u / 3.f, -0.5f + 0.3f * v / 3.f, 4 * v / 3.f};
    img = renderScene(oneLitPatch(touching));
    expectFiniteImage(img);
    // A patch through the eye point itself, and one entirely behind the eye.
    BezierPatch throughEye = flatSquare(2, 0);
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 4; ++u) throughEye.at(u, v).z = -1 + 2 * v / 3.f;
    img = renderScene(oneLitPatch(throughEye));
    expectFiniteImage(img);
    img = renderScene(oneLitPatch(flatSquare(2, -5)));
    expectFiniteImage(img);
    EXPECT_EQ(alphaSum(img), 0.0) << "nothing behind the eye is visible";
}

TEST_P(Degenerate, NonFiniteControlPointsNeverReachThePixels) {
    // The loaders reject NaN and infinity (test_errors.cpp); a scene built in code may still hold them.
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    for (float bad : {nan, inf, -inf}) {
        SCOPED_TRACE(bad);
        Scene s = oneLitPatch(flatSquare(2, 5));
        BezierPatch p = flatSquare(1, 4, 0.5f, 0.5f);
        p.at(1, 2).z = bad;
        addPatch(s, p);
        BezierPatch q = flatSquare(1, 4, -0.5f, -0.5f);
        for (Vec3& c : q.cp) c.x = bad;
        addPatch(s, q);
        Image img = renderScene(s);
        expectFiniteImage(img);
        EXPECT_GT(alphaSum(img), 100.0) << "the good patch is still drawn";
    }
}

INSTANTIATE_TEST_SUITE_P(Engines, Degenerate, ::testing::Values("reyes", "rt"),
                         [](const auto& info) { return info.param; });

}  // namespace tessera::test::degenerate_tests
