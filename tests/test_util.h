// Helpers shared by the tests: small hand-made scenes with known answers.
#pragma once
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "render/render.h"
#include "reyes/rasterize.h"
#include "scene/camera.h"
#include "scene/scene.h"
#include "shading/registry.h"

namespace tessera::test {

// A scene whose world space is camera space: the eye at the origin looking down +z, +y up.
inline Scene cameraSpaceScene(int width, int height, float fovDegrees) {
    Scene s;
    s.camera.width = width;
    s.camera.height = height;
    s.camera.fovDegrees = fovDegrees;
    s.camera.nearClip = 0.01f;
    s.camera.farClip = 1000.f;
    s.materials.push_back(defaultMaterial(MaterialType::Matte));
    s.lights.push_back({LightType::Ambient, {0.2f, 0.2f, 0.2f}, {}, {}});
    s.lights.push_back({LightType::Distant, {1, 1, 1}, {0, 0, 0}, {0.3f, -0.4f, 1.f}});
    s.image.filter = FilterType::Box;
    s.image.filterWidthX = s.image.filterWidthY = 1.f;
    return s;
}

// Keeps the scene's ambient lights and lights it from the eye: a point light at the camera position, warm,
// of intensity 1 at the centre of the scene. It casts no shadows (nor would any be visible), so both
// engines' shading is compared without their shadows.
inline void lightFromEye(Scene& s) {
    const Vec3 eye = s.camera.cameraFromWorld.inverse().point({0, 0, 0});
    std::vector<Light> lights;
    for (const Light& l : s.lights)
        if (l.type == LightType::Ambient) lights.push_back(l);
    const float d = length(eye - s.worldBounds().center());
    lights.push_back({LightType::Point, Color{1.f, 0.9f, 0.8f} * (d * d), eye, eye});
    s.lights = lights;
}

inline void addPatch(Scene& s, const BezierPatch& p, uint32_t object = 0) {
    s.patches.push_back(p);
    PatchAttributes a;
    a.object = object;
    s.attributes.push_back(a);
    s.objectCount = std::max(s.objectCount, object + 1);
}

// A flat parallelogram origin + s eu + t ev, s, t in [0, 1], as a bicubic patch (dP/du x dP/dv along
// eu x ev).
inline BezierPatch planarPatch(Vec3 origin, Vec3 eu, Vec3 ev) {
    BezierPatch p;
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 4; ++u) p.at(u, v) = origin + eu * (u / 3.f) + ev * (v / 3.f);
    return p;
}

// A flat square in the plane z = depth, centred on the view axis, side `side`.
inline BezierPatch flatSquare(float side, float depth, float cx = 0, float cy = 0) {
    BezierPatch p;
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 4; ++u)
            p.at(u, v) = {cx + side * (u / 3.f - 0.5f), cy + side * (v / 3.f - 0.5f), depth};
    return p;
}

// Control point u (0..3) of the cubic Bezier quarter circle of quadrant q (0..3, counter-clockwise) of the
// unit circle, rotated with exact swaps and negations so that neighbouring quadrants share bit-identical
// points.
inline void quarterCirclePoint(int u, int q, float& x, float& y) {
    const float k = 0.5522847f;  // cubic Bezier quarter-circle constant
    const float cx[4] = {1, 1, k, 0}, cy[4] = {0, k, 1, 1};
    x = cx[u], y = cy[u];
    for (int r = 0; r < q; ++r) {
        const float t = x;
        x = -y;
        y = t;
    }
}

// A closed sphere-like surface of 8 bicubic patches (one per octant, collapsed edges at the poles).
// Shared edges are bit-identical, as in real models whose patches share control points.
inline std::vector<BezierPatch> octantSphere(float radius, Vec3 centre) {
    const float k = 0.5522847f;                              // cubic Bezier quarter-circle constant
    const float pr[4] = {1, 1, k, 0}, pz[4] = {0, k, 1, 1};  // profile: radius and height
    std::vector<BezierPatch> out;
    for (int hemi = 0; hemi < 2; ++hemi)
        for (int q = 0; q < 4; ++q) {
            BezierPatch p;
            for (int v = 0; v < 4; ++v)
                for (int u = 0; u < 4; ++u) {
                    float x, y;
                    quarterCirclePoint(u, q, x, y);
                    float z = hemi == 0 ? pz[v] : -pz[v];
                    // Keep the normal orientation consistent: mirror u for the lower hemisphere.
                    int uu = hemi == 0 ? u : 3 - u;
                    p.at(uu, v) = {centre.x + radius * pr[v] * x, centre.y + radius * pr[v] * y,
                                   centre.z + radius * z};
                }
            out.push_back(p);
        }
    return out;
}

// The distance from P to a patch's surface: fine sampling, then a shrinking pattern search around the
// nearest sample (an independent closest-point check of offset surfaces).
inline float distanceToPatch(const BezierPatch& p, Vec3 P, int n = 64) {
    float best = 1e30f, bu = 0, bv = 0;
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) {
            const float d = length(evalPatch(p, float(i) / n, float(j) / n) - P);
            if (d < best) best = d, bu = float(i) / n, bv = float(j) / n;
        }
    for (float h = 1.f / n; h > 1e-7f; h *= 0.5f) {
        bool moved = true;
        while (moved) {
            moved = false;
            for (int k = 0; k < 4; ++k) {
                const float u = std::clamp(bu + (k == 0 ? h : k == 1 ? -h : 0.f), 0.f, 1.f);
                const float v = std::clamp(bv + (k == 2 ? h : k == 3 ? -h : 0.f), 0.f, 1.f);
                const float d = length(evalPatch(p, u, v) - P);
                if (d < best) best = d, bu = u, bv = v, moved = true;
            }
        }
    }
    return best;
}

inline float alphaAt(const Image& img, int x, int y) {
    return img.pixel(x, y)[3];
}

// Pinholes: pixels not fully covered (alpha below `covered`) whose eight neighbours all are.
inline int countPinholes(const Image& img, float covered = 0.999f) {
    auto isCovered = [&](int x, int y) { return img.pixel(x, y)[3] >= covered; };
    int holes = 0;
    for (int y = 1; y + 1 < img.height; ++y)
        for (int x = 1; x + 1 < img.width; ++x) {
            if (isCovered(x, y)) continue;
            bool surrounded = true;
            for (int dy = -1; dy <= 1 && surrounded; ++dy)
                for (int dx = -1; dx <= 1; ++dx)
                    if ((dx || dy) && !isCovered(x + dx, y + dy)) {
                        surrounded = false;
                        break;
                    }
            holes += surrounded;
        }
    return holes;
}

inline double alphaSum(const Image& img) {
    double s = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) s += img.pixel(x, y)[3];
    return s;
}

// An orthographic top view (looking down world -z) of [-1.5, 1.5]^2, one quadric RIB snippet at the origin.
inline std::string topView(const std::string& body, int res) {
    return "Format " + std::to_string(res) + " " + std::to_string(res) +
           " 1\nPixelSamples 4 4\nPixelFilter \"box\" 1 1\nProjection \"orthographic\"\n"
           "ScreenWindow -1.5 1.5 -1.5 1.5\nTranslate 0 0 5\nRotate 180 1 0 0\nWorldBegin\n"
           "LightSource \"ambientlight\" 1 \"intensity\" [1]\nSides 2\nSurface \"matte\"\n" +
           body + "\nWorldEnd\n";
}

// Per-pixel coverage of `inside` by 16 x 16 point samples, through the scene's own projection.
inline std::vector<double> exactCoverage(const Scene& s, const std::function<bool(double, double)>& inside) {
    const Projector pr(s.camera);
    const Mat4 worldFromCamera = s.camera.cameraFromWorld.inverse();
    const int w = s.camera.width, h = s.camera.height;
    std::vector<double> cov(size_t(w) * h, 0.0);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            int n = 0;
            for (int j = 0; j < 16; ++j)
                for (int i = 0; i < 16; ++i) {
                    const Vec3 world =
                        worldFromCamera.point(pr.fromRaster(x + (i + 0.5f) / 16, y + (j + 0.5f) / 16));
                    n += inside(world.x, world.y);
                }
            cov[size_t(y) * w + x] = n / 256.0;
        }
    return cov;
}

// A scene rendered with the Reyes AVX2 paths allowed and not (reyesUseAvx2); `avx2`: whether they ran.
struct Avx2Renders {
    RenderResult with, without;
    bool avx2 = false;
};
inline Avx2Renders renderWithAndWithoutReyesAvx2(const Scene& s, const RenderSettings& rs) {
    Avx2Renders r;
    r.avx2 = reyesUseAvx2(true);
    r.with = render(s, rs);
    reyesUseAvx2(false);
    r.without = render(s, rs);
    reyesUseAvx2(true);
    return r;
}

// Two renders the same bit for bit: colour, every plane (values and ids) and the count of sample tests.
inline void expectSameRender(const RenderResult& a, const RenderResult& b, const std::string& what) {
    EXPECT_TRUE(a.image.rgba == b.image.rgba) << what;
    ASSERT_EQ(a.image.planes.size(), b.image.planes.size()) << what;
    for (size_t p = 0; p < a.image.planes.size(); ++p) {
        EXPECT_TRUE(a.image.planes[p].values == b.image.planes[p].values)
            << what << " " << a.image.planes[p].name;
        EXPECT_TRUE(a.image.planes[p].ids == b.image.planes[p].ids) << what << " " << a.image.planes[p].name;
    }
    EXPECT_EQ(a.stats["sample_tests"], b.stats["sample_tests"]) << what;
}

}  // namespace tessera::test
