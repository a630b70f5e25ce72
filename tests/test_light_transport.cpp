// Area lights, the path tracer and its BSDFs (issue 14, docs/light_transport.md) against closed forms:
//  - a rectangle light above a floor: the floor's radiance is Kd Le F, F the point-to-rectangle form
//    factor (Lambert's polygon formula), for the direct integrator's soft-shadow samples and the path
//    tracer alike (nothing else in the scene reflects);
//  - a white furnace: inside a closed sphere that emits Le and reflects with albedo a, the radiance is
//    Le / (1 - a) everywhere (the path tracer), Le (1 + a) for one bounce (the direct integrator);
//  - every BSDF's sampling weights average to its albedo computed independently (uniform directions),
//    never above 1;
//  - RMSE at least halves when the samples per pixel quadruple; the path tracer equals the direct
//    integrator within noise where a shadow falls (no interreflection to add).
// Means over pixels are t-tested at a fixed seed (every pixel scrambles its own samples, so pixels are
// independent).
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "floor_scenes.h"
#include "rib_test_util.h"
#include "shading/path_bsdf.h"
#include "test_util.h"

namespace tessera::test::light_transport_tests {
namespace {

constexpr float kLe = 12.f;
// The light: a 1 x 1 rectangle at height 1 above the floor (z = 4), beside the view (x in [2, 3]: the
// view's half-width at z = 4 is 1.46), emitting towards the floor (+z: dP/du x dP/dv of planarPatch).
const Wall kLightRect{{{2, -0.5f, 4}, {3, -0.5f, 4}, {3, 0.5f, 4}, {2, 0.5f, 4}}};

Scene litFloor(int size, int samples, bool occluder = false) {
    Scene s = cameraSpaceScene(size, size, 40.f);
    s.lights.clear();
    s.materials[0].Ka = 0.f;  // matte, Kd 1, Cs 1
    addPatch(s, flatSquare(8.f, 5.f));
    Material black = defaultMaterial(MaterialType::Matte);
    black.Ka = black.Kd = 0.f;
    s.materials.push_back(black);
    Light area;
    area.type = LightType::Area;
    area.color = {kLe, kLe, kLe};
    area.samples = samples;
    area.castsShadows = true;
    s.lights.push_back(area);
    addPatch(s, planarPatch(kLightRect.corner[0], {1, 0, 0}, {0, 1, 0}), 1);
    s.attributes.back().material = 1;
    s.attributes.back().areaLight = 0;
    if (occluder) {  // a black card between light and floor, casting a soft shadow into the view
        addPatch(s, planarPatch({0.9f, -0.4f, 4.5f}, {0.6f, 0, 0}, {0, 0.8f, 0}), 2);
        s.attributes.back().material = 1;
    }
    return s;
}

RenderSettings rtSettings(Integrator integrator, int maxDepth = 16) {
    RenderSettings rs;
    rs.engine = "rt";
    rs.threads = 2;
    rs.integrator = integrator;
    rs.maxDepth = maxDepth;
    return rs;
}

// The floor's exact radiance at a pixel: Kd Le F averaged over a 4 x 4 grid of the pixel's points (the
// box filter's footprint), so that the pixel-centre error stays far below the noise.
double floorTruth(int px, int py, int size) {
    const float half = std::tan(20.f * 3.14159265f / 180.f);
    double sum = 0;
    for (int j = 0; j < 4; ++j)
        for (int i = 0; i < 4; ++i) {
            const float x = (2.f * (px + (i + 0.5f) / 4.f) / size - 1.f) * half;
            const float y = (1.f - 2.f * (py + (j + 0.5f) / 4.f) / size) * half;
            sum += kLe * polygonFormFactor(kLightRect, {x * 5.f, y * 5.f, 5.f}, {0, 0, -1});
        }
    return sum / 16.0;
}

// Per-pixel differences (image minus truth) as an estimate of their mean, and their RMSE.
struct PixelErrors {
    Estimate e;
    double rmse = 0;
};
template <class Truth>
PixelErrors pixelErrors(const Image& img, int size, Truth&& truth) {
    std::vector<double> v;
    for (int py = 0; py < size; ++py)
        for (int px = 0; px < size; ++px) v.push_back(double(img.pixel(px, py)[0]) - truth(px, py));
    PixelErrors pe;
    pe.e.n = v.size();
    double ss = 0;
    for (double x : v) pe.e.mean += x, ss += x * x;
    pe.e.mean /= double(v.size());
    pe.rmse = std::sqrt(ss / double(v.size()));
    double var = 0;
    for (double x : v) var += (x - pe.e.mean) * (x - pe.e.mean);
    pe.e.standardError = std::sqrt(var / double(v.size() - 1) / double(v.size()));
    return pe;
}

TEST(AreaLights, FloorRadianceIsTheRectangleFormFactorInBothIntegrators) {
    const int size = 32;
    Scene s = litFloor(size, 16);
    s.image.pixelSamplesX = s.image.pixelSamplesY = 2;
    auto truth = [&](int px, int py) { return floorTruth(px, py, size); };
    const RenderResult direct = render(s, rtSettings(Integrator::Direct));
    const PixelErrors d = pixelErrors(direct.image, size, truth);
    expectMean(d.e, 0.0, "direct");
    const RenderResult path = render(s, rtSettings(Integrator::Path));
    const PixelErrors p = pixelErrors(path.image, size, truth);
    expectMean(p.e, 0.0, "path");
    // The light itself: outside the view, so every pixel is floor; the truth spans a wide range.
    EXPECT_GT(truth(size - 1, size / 2), 20.0 * truth(0, size / 2));
    EXPECT_LT(d.rmse, 0.05 * truth(size - 1, size / 2)) << d.rmse;
    EXPECT_EQ(direct.stats["rays"]["shadow"].get<uint64_t>(), uint64_t(size * size * 4 * 16));
}

TEST(AreaLights, TheLightIsSeenWithItsRadianceFromTheFrontOnly) {
    // A light square facing the eye fills the view: every pixel is Le; turned away (flipped), black.
    Scene s = cameraSpaceScene(8, 8, 20.f);
    s.lights.clear();
    Light area;
    area.type = LightType::Area;
    area.color = {kLe, 0.5f * kLe, 1.f};
    s.lights.push_back(area);
    addPatch(s, flatSquare(4.f, 5.f));
    s.attributes.back().areaLight = 0;
    s.attributes.back().flipNormal = true;  // dP/du x dP/dv is +z, away from the eye: flipped it faces it
    s.materials[0].Ka = s.materials[0].Kd = 0.f;
    for (Integrator in : {Integrator::Direct, Integrator::Path}) {
        const RenderResult r = render(s, rtSettings(in));
        EXPECT_NEAR(r.image.pixel(3, 4)[0], kLe, 1e-4f);
        EXPECT_NEAR(r.image.pixel(3, 4)[1], 0.5f * kLe, 1e-4f);
        EXPECT_NEAR(r.image.pixel(3, 4)[2], 1.f, 1e-4f);
    }
    s.attributes.back().flipNormal = false;
    const RenderResult back = render(s, rtSettings(Integrator::Path));
    EXPECT_EQ(back.image.pixel(3, 4)[0], 0.f);
    EXPECT_EQ(back.image.pixel(3, 4)[3], 1.f);  // still covered
}

TEST(PathTracer, WhiteFurnaceConvergesToLeOverOneMinusAlbedo) {
    // A closed sphere (radius 5, the eye at its centre) emitting Le = 1 inwards with a matte albedo a.
    const std::string rib = R"(Format 16 16 1
PixelSamples 4 4
PixelFilter "box" 1 1
Projection "perspective" "fov" [90]
WorldBegin
AttributeBegin
  AreaLightSource "arealight" 1 "intensity" [1]
  Surface "matte" "Ka" [0] "Kd" [0.5]
  ReverseOrientation
  Sphere 5 -5 5 360
AttributeEnd
WorldEnd
)";
    const Loaded l = load(rib);
    ASSERT_EQ(l.scene.lights.size(), 1u);
    ASSERT_EQ(l.scene.lights[0].type, LightType::Area);
    const int size = 16;
    auto constant = [](double v) { return [v](int, int) { return v; }; };
    // Path: L = Le / (1 - a) = 2 (Russian roulette ends the paths; 64 bounces leave 0.5^64 out).
    const RenderResult path = render(l.scene, rtSettings(Integrator::Path, 64));
    expectMean(pixelErrors(path.image, size, constant(2.0)).e, 0.0, "furnace_path");
    // Direct: the emission seen plus one bounce of the enclosure's irradiance pi Le: Le (1 + a).
    const RenderResult direct = render(l.scene, rtSettings(Integrator::Direct));
    expectMean(pixelErrors(direct.image, size, constant(1.5)).e, 0.0, "furnace_direct");
    // Truncated: at the last vertex next-event estimation takes the light's whole share (no BSDF sample
    // follows to complete the MIS pair), so --max-depth d gives the first d + 2 terms of the series:
    // Le (1 + a) with no bounce (the direct integrator's answer), Le (1 + a + a^2) with one.
    const RenderResult none = render(l.scene, rtSettings(Integrator::Path, 0));
    expectMean(pixelErrors(none.image, size, constant(1.5)).e, 0.0, "furnace_path_no_bounce");
    const RenderResult one = render(l.scene, rtSettings(Integrator::Path, 1));
    expectMean(pixelErrors(one.image, size, constant(1.75)).e, 0.0, "furnace_path_one_bounce");
}

TEST(PathTracer, RmseAtLeastHalvesWhenSamplesQuadruple) {
    const int size = 24;
    auto truth = [&](int px, int py) { return floorTruth(px, py, size); };
    double previous = 0;
    for (int n : {1, 2, 4}) {
        Scene s = litFloor(size, 1);
        s.image.pixelSamplesX = s.image.pixelSamplesY = n;
        const double rmse = pixelErrors(render(s, rtSettings(Integrator::Path)).image, size, truth).rmse;
        ::testing::Test::RecordProperty("rmse_spp" + std::to_string(n * n), std::to_string(rmse));
        if (previous > 0) {
            EXPECT_LT(rmse, 0.55 * previous) << n * n << " spp";
        }
        previous = rmse;
    }
}

TEST(PathTracer, EqualsTheDirectIntegratorInAShadowWithNothingToInterreflect) {
    const int size = 32;
    Scene s = litFloor(size, 64, true);
    s.image.pixelSamplesX = s.image.pixelSamplesY = 4;
    const RenderResult direct = render(s, rtSettings(Integrator::Direct));
    const RenderResult path = render(s, rtSettings(Integrator::Path));
    // The shadow is in view: part of the floor gets less than the unshadowed form factor.
    int shadowed = 0;
    for (int py = 0; py < size; ++py)
        for (int px = 0; px < size; ++px)
            shadowed += direct.image.pixel(px, py)[0] < 0.8 * floorTruth(px, py, size) &&
                        direct.image.pixel(px, py)[0] > 0.f;
    EXPECT_GT(shadowed, 40);
    auto directValue = [&](int px, int py) { return double(direct.image.pixel(px, py)[0]); };
    expectMean(pixelErrors(path.image, size, directValue).e, 0.0, "path_minus_direct");
}

// ---- The BSDFs ----

struct Albedo {
    Color sampled, uniform;
    double pdfMass = 0;
};
// Albedo of `b` for outgoing direction at cos(theta) = cosO, two ways: the mean of its sampling weights,
// and f cos / (1 / 2 pi) averaged over uniform directions (independent of its sampling and density);
// pdfMass: the density integrated over the hemisphere the same way (at most 1).
Albedo albedoOf(const PathBsdf& b, float cosO, int n) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u01(0.f, 1.f);
    const Vec3 N{0, 0, 1};
    const Vec3 wo{std::sqrt(1.f - cosO * cosO), 0.f, cosO};
    const Vec3 I = -wo;
    Albedo a;
    double ss[3] = {0, 0, 0}, us[3] = {0, 0, 0}, mass = 0;
    for (int i = 0; i < n; ++i) {
        const PathBsdfSample s = pathBsdfSample(b, N, I, u01(rng), u01(rng), u01(rng));
        if (s.valid) ss[0] += s.weight.x, ss[1] += s.weight.y, ss[2] += s.weight.z;
        const Vec3 wi = uniformHemisphere(u01(rng), u01(rng));
        const Color f = pathBsdfEval(b, N, wo, wi) * (wi.z * 6.2831853f);
        us[0] += f.x, us[1] += f.y, us[2] += f.z;
        mass += pathBsdfPdf(b, N, wo, wi) * 6.2831853;
    }
    a.sampled = {float(ss[0] / n), float(ss[1] / n), float(ss[2] / n)};
    a.uniform = {float(us[0] / n), float(us[1] / n), float(us[2] / n)};
    a.pdfMass = mass / n;
    return a;
}

TEST(PathBsdf, SamplingWeightsMatchTheIndependentAlbedoAndNeverExceedOne) {
    Material matte = defaultMaterial(MaterialType::Matte);
    matte.Cs = {0.8f, 0.5f, 0.2f};
    Material plastic = defaultMaterial(MaterialType::Plastic);
    plastic.roughness = 0.3f;
    Material metal = defaultMaterial(MaterialType::Metal);
    metal.Ks = 1.f, metal.roughness = 0.2f, metal.Cs = {0.9f, 0.7f, 0.4f};
    Material bright = defaultMaterial(MaterialType::Plastic);  // Kd + Ks = 2: scaled to sum to 1
    bright.Kd = bright.Ks = 1.f;
    bright.roughness = 0.5f;
    struct Case {
        const char* name;
        Material m;
    };
    for (const Case& c :
         {Case{"matte", matte}, Case{"plastic", plastic}, Case{"metal", metal}, Case{"bright", bright}}) {
        const PathBsdf b = pathBsdfOf(c.m);
        for (float cosO : {0.95f, 0.6f, 0.25f}) {
            const Albedo a = albedoOf(b, cosO, 400000);
            SCOPED_TRACE(std::string(c.name) + " cos " + std::to_string(cosO));
            for (int k = 0; k < 3; ++k) {
                const float s = (&a.sampled.x)[k], u = (&a.uniform.x)[k];
                EXPECT_NEAR(s, u, 0.01f + 0.02f * u);
                EXPECT_LE(s, 1.005f);
                EXPECT_LE(u, 1.01f);
            }
            EXPECT_LE(a.pdfMass, 1.01);
            if (c.m.type == MaterialType::Matte) {
                EXPECT_NEAR(a.pdfMass, 1.0, 0.01);
                EXPECT_NEAR(a.sampled.x, 0.8f, 1e-4f);  // cosine sampling: the weight is the albedo
            }
        }
    }
    // Delta lobes: the mirror reflects Kr Cs about the normal; glass splits by Fresnel and never loses
    // more than its Kt and Kr leave.
    Material mirror = defaultMaterial(MaterialType::Mirror);
    mirror.Cs = {0.9f, 0.9f, 0.9f};
    const PathBsdfSample ms =
        pathBsdfSample(pathBsdfOf(mirror), {0, 0, 1}, normalize(Vec3{1, 0, -1}), 0.3f, 0.f, 0.f);
    ASSERT_TRUE(ms.valid && ms.delta);
    EXPECT_NEAR(ms.wi.z, std::sqrt(0.5f), 1e-5f);
    EXPECT_NEAR(ms.weight.x, 0.9f, 1e-6f);
    // Below the surface there is nothing to sample.
    const PathBsdfSample below =
        pathBsdfSample(pathBsdfOf(matte), {0, 0, 1}, Vec3{0, 0, 1}, 0.5f, 0.5f, 0.5f);
    EXPECT_TRUE(!below.valid ||
                below.wi.z < 0.f);  // the normal faces the viewer: the sample stays on its side
}

TEST(AreaLights, RibDeclaresThemAndRejectsBadSampleCounts) {
    const Loaded l = load(R"(WorldBegin
AttributeBegin
AreaLightSource "arealight" 3 "intensity" [2] "lightcolor" [1 0.5 0.25] "samples" [8]
Patch "bilinear" "P" [0 0 0 1 0 0 0 1 0 1 1 0]
AttributeEnd
Patch "bilinear" "P" [0 0 1 1 0 1 0 1 1 1 1 1]
WorldEnd
)");
    ASSERT_EQ(l.scene.lights.size(), 1u);
    EXPECT_EQ(l.scene.lights[0].type, LightType::Area);
    EXPECT_EQ(l.scene.lights[0].samples, 8);
    EXPECT_FLOAT_EQ(l.scene.lights[0].color.y, 1.f);
    ASSERT_EQ(l.scene.attributes.size(), 2u);
    EXPECT_EQ(l.scene.attributes[0].areaLight, 0);   // inside the light's attribute block
    EXPECT_EQ(l.scene.attributes[1].areaLight, -1);  // after it
    std::string msg =
        expectError("WorldBegin\nAreaLightSource \"arealight\" 1 \"samples\" [0]\nWorldEnd\n", 2);
    EXPECT_TRUE(contains(msg, "samples")) << msg;
    const Loaded wrong = load(
        "WorldBegin\nAreaLightSource \"pointlight\" 1\nLightSource \"arealight\" 2\n"
        "Patch \"bilinear\" \"P\" [0 0 0 1 0 0 0 1 0 1 1 0]\nWorldEnd\n");
    EXPECT_TRUE(wrong.scene.lights.empty());
    ASSERT_GE(wrong.warnings.size(), 2u);  // and: no light sources
    EXPECT_TRUE(contains(wrong.warnings[0], "not an area light shader")) << wrong.warnings[0];
    EXPECT_TRUE(contains(wrong.warnings[1], "AreaLightSource")) << wrong.warnings[1];
}

}  // namespace
}  // namespace tessera::test::light_transport_tests

namespace tessera::test::light_transport_tests {
namespace {

// RI Imager "background" (appendix A): Ci += (1 - alpha) background, alpha = 1, in both engines: empty
// pixels are the colour, covered ones unchanged, edge pixels composited by their coverage.
TEST(Imager, BackgroundCompositesUnderTheImageInBothEngines) {
    const std::string body = R"(Format 48 32 1
PixelSamples 4 4
Projection "perspective" "fov" [30]
Translate 0 0 6
WorldBegin
LightSource "distantlight" 1
Sphere 1 -1 1 360
WorldEnd
)";
    const Loaded plain = load(body);
    const Loaded bg = load("Imager \"background\" \"background\" [0.2 0.3 0.5]\n" + body);
    ASSERT_TRUE(bg.scene.image.hasBackground);
    ASSERT_EQ(plain.scene.quadrics.size(), 1u);
    ASSERT_EQ(plain.scene.camera.width, 48);
    for (const char* engine : {"reyes", "rt"}) {
        RenderSettings rs;
        rs.engine = engine;
        rs.threads = 2;
        const RenderResult a = render(plain.scene, rs), b = render(bg.scene, rs);
        int empty = 0, covered = 0;
        for (int y = 0; y < 32; ++y)
            for (int x = 0; x < 48; ++x) {
                const float* p = a.image.pixel(x, y);
                const float* q = b.image.pixel(x, y);
                const float open = 1.f - p[3];
                EXPECT_NEAR(q[0], p[0] + open * 0.2f, 1e-6f) << engine << " " << x << "," << y;
                EXPECT_NEAR(q[1], p[1] + open * 0.3f, 1e-6f);
                EXPECT_NEAR(q[2], p[2] + open * 0.5f, 1e-6f);
                EXPECT_EQ(q[3], 1.f);
                empty += p[3] == 0.f;
                covered += p[3] > 0.999f;
            }
        EXPECT_GT(empty, 50) << engine;
        EXPECT_GT(covered, 20) << engine << " centre alpha " << a.image.pixel(24, 16)[3] << " size "
                               << a.image.width << "x" << a.image.height;
    }
    expectError("Imager \"background\" \"background\" [-1 0 0]\n" + body, 1);
    const Loaded other = load("Imager \"clamptoalpha\"\n" + body);
    EXPECT_FALSE(other.scene.image.hasBackground);
    ASSERT_FALSE(other.warnings.empty());
    EXPECT_TRUE(contains(other.warnings[0], "clamptoalpha")) << other.warnings[0];
}

}  // namespace
}  // namespace tessera::test::light_transport_tests
