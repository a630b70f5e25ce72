// The shading module against closed-form answers: the RI standard shaders with the RenderMan specular
// convention, the spotlight's cone, which light samples ask for visibility, the traced lobes of glass.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "film/film.h"
#include "render/render.h"
#include "shading/registry.h"
#include "shading/surface.h"
#include "test_util.h"

namespace tessera::test::shading_tests {

namespace {

ShadingLight distantFrom(Vec3 towardsLight, Color c) {
    Light l = defaultLight(LightType::Distant);
    l.color = c;
    l.from = towardsLight;
    l.to = {0, 0, 0};
    return prepareLight(l, Mat4{});
}

Color shadeOne(const Material& m, Vec3 N, Vec3 I, const std::vector<ShadingLight>& lights) {
    const Vec3 P{0, 0, 0};
    SurfacePoints pts;
    pts.count = 1;
    pts.P = &P;
    pts.N = &N;
    pts.I = &I;
    LightSamples ls;
    sampleLights(lights, std::span<const Material>(&m, 1), pts, ls);
    Color Ci;
    shadeSurfaces(std::span<const Material>(&m, 1), pts, ls, &Ci);
    return Ci;
}

}  // namespace

TEST(Shading, PlasticFollowsTheRenderManSpecularConvention) {
    // Light at 40 degrees from N in the xz plane, eye on N: H is at 20 degrees, N.L = cos 40.
    const float a = 40.f * float(M_PI) / 180.f;
    const Vec3 N{0, 0, -1}, I{0, 0, 1};  // looking down +z at a surface facing the eye
    const Vec3 L{std::sin(a), 0, -std::cos(a)};
    Material m = defaultMaterial(MaterialType::Plastic);
    m.Cs = {0.8f, 0.5f, 0.2f};
    m.Ka = 0.3f, m.Kd = 0.6f, m.Ks = 0.7f, m.roughness = 0.25f;
    m.specularColor = {1.f, 0.9f, 0.8f};
    Light amb = defaultLight(LightType::Ambient);
    amb.color = {0.1f, 0.2f, 0.3f};
    const std::vector<ShadingLight> lights = {prepareLight(amb, Mat4{}), distantFrom(L * 10.f, {1, 1, 1})};
    const Color got = shadeOne(m, N, I, lights);
    // RI plastic: Cs * (Ka ambient + Kd N.L Cl) + specularcolor * Ks * Cl * (N.H)^(1/(roughness/8)).
    const float spec = std::pow(std::cos(a / 2), 8.f / m.roughness);
    const Color want =
        m.Cs * (amb.color * m.Ka + Color{1, 1, 1} * (m.Kd * std::cos(a))) + m.specularColor * (m.Ks * spec);
    EXPECT_NEAR(got.x, want.x, 1e-5f);
    EXPECT_NEAR(got.y, want.y, 1e-5f);
    EXPECT_NEAR(got.z, want.z, 1e-5f);
    // The spec's 1/roughness would give a visibly broader highlight: the convention is what is tested.
    EXPECT_GT(std::pow(std::cos(a / 2), 1.f / m.roughness) - spec, 0.2f);
}

TEST(Shading, MatteAndMetalAndConstant) {
    const Vec3 N{0, 1, 0}, I{0, -1, 0};
    const std::vector<ShadingLight> lights = {distantFrom({0, 5, 0}, {0.5f, 0.5f, 0.5f})};
    Material matte = defaultMaterial(MaterialType::Matte);
    matte.Cs = {1, 0.5f, 0.25f};
    EXPECT_NEAR(shadeOne(matte, N, I, lights).y, 0.25f, 1e-6f);  // Kd N.L Cl Cs = 1 * 1 * 0.5 * 0.5
    Material metal = defaultMaterial(MaterialType::Metal);       // L = V = N: H = N, lobe = 1
    EXPECT_NEAR(shadeOne(metal, N, I, lights).x, 0.5f, 1e-6f);
    Material c = defaultMaterial(MaterialType::Constant);
    c.Cs = {0.1f, 0.2f, 0.3f};
    EXPECT_NEAR(shadeOne(c, N, I, lights).z, 0.3f, 1e-7f);
    // Lit from behind: a one-sided light contributes nothing, whichever side N was given on.
    const std::vector<ShadingLight> behind = {distantFrom({0, -5, 0}, {1, 1, 1})};
    EXPECT_EQ(shadeOne(matte, N, Vec3{0, 1, 0} * -1.f, behind).x, 0.f);
}

TEST(Shading, SpotlightConeAndFalloff) {
    Light l = defaultLight(LightType::Spot);
    l.from = {0, 0, 0};
    l.to = {0, 0, 1};
    l.color = {4, 4, 4};
    l.coneAngle = 0.5f;
    l.coneDeltaAngle = 0.1f;
    l.beamDistribution = 3.f;
    const ShadingLight s = prepareLight(l, Mat4{});
    auto at = [&](float angle, float dist) {
        return sampleLight(s, Vec3{std::sin(angle), 0, std::cos(angle)} * dist);
    };
    // Inside the inner cone: intensity / d^2 * cos^beam.
    LightSample in = at(0.2f, 2.f);
    ASSERT_TRUE(in.valid);
    EXPECT_NEAR(in.Cl.x, 4.f / 4.f * std::pow(std::cos(0.2f), 3.f), 1e-5f);
    EXPECT_NEAR(in.dist, 2.f, 1e-6f);
    // Between the cones: the RI smoothstep of the cosines.
    const float mid = 0.45f;
    const float t = (std::cos(mid) - std::cos(0.5f)) / (std::cos(0.4f) - std::cos(0.5f));
    EXPECT_NEAR(at(mid, 1.f).Cl.x, 4.f * std::pow(std::cos(mid), 3.f) * t * t * (3 - 2 * t), 1e-4f);
    // Outside the cone: no light.
    EXPECT_FALSE(at(0.55f, 1.f).valid);
}

TEST(Shading, OnlyFrontFacingShadowCastingLightsAskForVisibility) {
    Light ambient = defaultLight(LightType::Ambient);
    ambient.castsShadows = true;  // ambient light is never occluded, whatever it says
    std::vector<ShadingLight> lights = {prepareLight(ambient, Mat4{}), distantFrom({0, 0, -1}, {1, 1, 1}),
                                        distantFrom({0, 0, 1}, {1, 1, 1}),
                                        distantFrom({0, 0, -1}, {1, 1, 1})};
    lights[1].castsShadows = lights[2].castsShadows = true;  // lights[3] casts none: it is never asked
    EXPECT_FALSE(lights[0].castsShadows);
    const Material mats[2] = {defaultMaterial(MaterialType::Matte), defaultMaterial(MaterialType::Constant)};
    const Vec3 P[2] = {{0, 0, 5}, {0, 0, 5}}, N[2] = {{0, 0, -1}, {0, 0, -1}}, I[2] = {{0, 0, 1}, {0, 0, 1}};
    const uint32_t mi[2] = {0, 1};
    SurfacePoints pts{2, P, N, I, mi};
    LightSamples ls;
    sampleLights(lights, mats, pts, ls);
    ASSERT_EQ(ls.lights, 4u);
    EXPECT_EQ(ls.needsVisibility[ls.index(0, 0)], 0);  // ambient
    EXPECT_EQ(ls.needsVisibility[ls.index(0, 1)], 1);  // in front
    EXPECT_EQ(ls.needsVisibility[ls.index(0, 2)], 0);  // behind the surface
    EXPECT_EQ(ls.needsVisibility[ls.index(0, 3)], 0);  // in front, casts no shadows
    for (size_t l = 0; l < 4; ++l) EXPECT_EQ(ls.needsVisibility[ls.index(1, l)], 0);  // constant: unlit
    // Occluding the one queried light leaves the ambient term and the light without shadows.
    ls.visibility[ls.index(0, 1)] = 0.f;
    Color Ci[2];
    shadeSurfaces(mats, pts, ls, Ci);
    EXPECT_NEAR(Ci[0].x, 2.f, 1e-6f);  // Ka * ambient (1) * Cs (1) + Kd * 1 * N.L (1)
}

TEST(Shading, UnoccludedBatchesGiveEachPointsOwnBits) {
    // shadeSurfacesUnoccluded shades four points at a time (one material, ambient, distant and point
    // lights): every point must get the bits shadeSurfaceLights gives it alone, over every material, for
    // normals facing towards and away from the eye, a point light at one of the points, and a batch whose
    // size is not a multiple of four.
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(-1.f, 1.f);
    const size_t n = 103;
    std::vector<Vec3> P(n), N(n), I(n);
    for (size_t i = 0; i < n; ++i) {
        P[i] = {3 * u(rng), 3 * u(rng), 4 + u(rng)};
        N[i] = normalize(Vec3{u(rng), u(rng), u(rng)});
        I[i] = normalize(P[i]);
    }
    std::vector<ShadingLight> lights;
    auto add = [&](LightType type, Vec3 from, Vec3 to, Color c) {
        Light l = defaultLight(type);
        l.color = c, l.from = from, l.to = to;
        lights.push_back(prepareLight(l, Mat4{}));
    };
    add(LightType::Ambient, {}, {}, {0.1f, 0.2f, 0.3f});
    add(LightType::Distant, {1, 2, -3}, {0, 0, 0}, {0.9f, 0.8f, 0.7f});
    add(LightType::Point, {0.5f, 4, 1}, {}, {20, 18, 15});
    add(LightType::Distant, {-2, -1, -1}, {0, 0, 0}, {0.3f, 0.3f, 0.5f});
    add(LightType::Point, P[9], {}, {5, 5, 5});  // at point 9 itself: no light there
    const MaterialType types[] = {
        MaterialType::Matte,          MaterialType::Plastic, MaterialType::Metal, MaterialType::ShinyMetal,
        MaterialType::PaintedPlastic, MaterialType::Mirror,  MaterialType::Glass, MaterialType::Glossy};
    int compared = 0, lit = 0;
    for (MaterialType type : types) {
        Material m = defaultMaterial(type);
        m.Cs = {0.8f, 0.6f, 0.4f};
        m.Kd = 0.7f, m.Ks = 0.6f, m.roughness = 0.13f;
        SurfacePoints pts;
        pts.count = n;
        pts.P = P.data(), pts.N = N.data(), pts.I = I.data();
        std::vector<Color> batch(n);
        shadeSurfacesUnoccluded(lights, std::span<const Material>(&m, 1), pts, batch.data());
        for (size_t i = 0; i < n; ++i) {
            const Color alone = shadeSurfaceLights(
                m, N[i], I[i], lights.size(), [&](size_t l) { return sampleLight(lights[l], P[i]); },
                [](size_t) { return 1.f; });
            EXPECT_EQ(std::memcmp(&alone, &batch[i], sizeof(Color)), 0)
                << int(type) << " point " << i << ": " << alone.x << " " << alone.y << " " << alone.z
                << " alone, " << batch[i].x << " " << batch[i].y << " " << batch[i].z << " in the batch";
            ++compared;
            const Color ambientAlone = shadeSurfaceLights(
                m, N[i], I[i], 1, [&](size_t l) { return sampleLight(lights[l], P[i]); },
                [](size_t) { return 1.f; });
            lit += !(alone == ambientAlone);
        }
    }
    EXPECT_EQ(compared, 8 * int(n));
    EXPECT_GT(lit, int(n));  // the lights reach the points, not only the ambient term
}

TEST(Shading, GlassSplitsTheWeightByFresnel) {
    Material g = defaultMaterial(MaterialType::Glass);
    TracedLobe lobes[2];
    // Normal incidence from outside: F = ((eta - 1) / (eta + 1))^2; reflection + transmission = weight.
    const int n = tracedLobes(g, Vec3{0, 0, 1}, Vec3{0, 0, -1}, Color{1, 1, 1}, 1e-4f, lobes);
    ASSERT_EQ(n, 2);
    const float F = std::pow((g.eta - 1) / (g.eta + 1), 2.f);
    EXPECT_NEAR(lobes[0].weight.x, F, 1e-6f);
    EXPECT_NEAR(lobes[1].weight.x, 1 - F, 1e-6f);
    EXPECT_TRUE(lobes[1].transmitted);
    EXPECT_NEAR(lobes[0].direction.z, -1.f, 1e-6f);
    EXPECT_NEAR(lobes[1].direction.z, 1.f, 1e-6f);
    // From inside beyond the critical angle: total internal reflection only.
    const float a = 60.f * float(M_PI) / 180.f;  // sin 60 * 1.5 > 1
    const int tir =
        tracedLobes(g, Vec3{std::sin(a), 0, std::cos(a)}, Vec3{0, 0, 1}, Color{1, 1, 1}, 1e-4f, lobes);
    ASSERT_EQ(tir, 1);
    EXPECT_NEAR(lobes[0].weight.x, 1.f, 1e-6f);
    // Snell's law for a refracted lobe at 30 degrees from outside.
    const float b = 30.f * float(M_PI) / 180.f;
    ASSERT_EQ(tracedLobes(g, Vec3{std::sin(b), 0, std::cos(b)}, Vec3{0, 0, -1}, Color{1, 1, 1}, 0.f, lobes),
              2);
    EXPECT_NEAR(lobes[1].direction.x, std::sin(b) / g.eta, 1e-5f);
    // Opaque surfaces have no traced lobes.
    EXPECT_EQ(tracedLobes(defaultMaterial(MaterialType::Plastic), Vec3{0, 0, 1}, Vec3{0, 0, -1},
                          Color{1, 1, 1}, 0.f, lobes),
              0);
}

TEST(ShaderRegistry, EveryEntryRoundTrips) {
    for (const SurfaceShaderInfo& s : surfaceShaders()) {
        const SurfaceShaderInfo* f = findSurfaceShader(s.name);
        ASSERT_NE(f, nullptr) << s.name;
        EXPECT_EQ(f->type, s.type);
        EXPECT_EQ(surfaceShaderInfo(s.type).name, s.name);
        EXPECT_EQ(defaultMaterial(s.type).type, s.type);
        EXPECT_EQ(s.traced, surfaceHasTracedLobes(s.type)) << s.name;
    }
    for (const LightShaderInfo& l : lightShaders()) {
        ASSERT_NE(findLightShader(l.name), nullptr) << l.name;
        EXPECT_EQ(defaultLight(l.type).type, l.type);
    }
    EXPECT_EQ(findSurfaceShader("wood2"), nullptr);
    EXPECT_EQ(findLightShader("glowlight"), nullptr);
    EXPECT_EQ(findLightShader("arealight")->type, LightType::Area);
}

// ---- the same radiance in both engines -------------------------------------------------------------------

TEST(Shading, BothEnginesGiveTheShadingModuleRadianceForTheSameHit) {
    // A plastic square facing the eye, lit by a distant, a point and a spot light: each pixel's one sample
    // sees a known hit (P on the plane z = 5, N = -z, I from the eye), whose radiance the shading module
    // gives directly; both engines must give the same through their own paths (Reyes: diced grid,
    // interpolated vertex colours; the ray tracer: the exact hit with shadow rays that all miss).
    using namespace tessera::test;
    Scene s = cameraSpaceScene(40, 40, 30.f);
    s.image.pixelSamplesX = s.image.pixelSamplesY = 1;
    Material m = defaultMaterial(MaterialType::Plastic);
    m.Cs = {0.9f, 0.6f, 0.3f};
    m.roughness = 0.3f;
    s.materials = {m};
    Light amb = defaultLight(LightType::Ambient);
    amb.color = {0.05f, 0.05f, 0.05f};
    Light sun = defaultLight(LightType::Distant);
    sun.from = {0.3f, -0.4f, 0.f};
    sun.to = {0.f, 0.f, 1.f};
    sun.color = {0.6f, 0.6f, 0.6f};
    Light pt = defaultLight(LightType::Point);
    pt.from = {0.5f, 0.5f, 3.f};
    pt.color = {3, 3, 3};
    Light spot = defaultLight(LightType::Spot);
    spot.from = {-0.5f, 0.f, 2.f};
    spot.to = {-0.3f, 0.f, 5.f};
    spot.color = {4, 4, 4};
    spot.coneAngle = 0.4f;
    s.lights = {amb, sun, pt, spot};
    addPatch(s, flatSquare(4.f, 5.f));
    s.attributes[0].shadingRate = 0.05f;  // Reyes' vertex interpolation error well below the tolerance

    const Projector proj(s.camera);
    std::vector<ShadingLight> lights;
    for (const Light& l : s.lights) lights.push_back(prepareLight(l, Mat4{}));
    SampleTile tile;
    tile.reset(Rect{0, 0, 40, 40}, 1, 1, 0, 1.f, SamplerKind::Sobol);
    for (const char* engine : {"rt", "reyes"}) {
        RenderSettings rs;
        rs.engine = engine;
        rs.threads = 2;
        const RenderResult r = render(s, rs);
        double worst = 0;
        for (int py = 0; py < 40; ++py)
            for (int px = 0; px < 40; ++px) {
                const size_t i = size_t(py) * 40 + px;
                const Vec3 d = proj.fromRaster(tile.sx[i] / kSubpixelScale, tile.sy[i] / kSubpixelScale);
                const Vec3 P = d * 5.f, N{0, 0, 1}, I = normalize(d);
                LightSample ls[4];
                float vis[4] = {1, 1, 1, 1};
                for (int l = 0; l < 4; ++l) ls[l] = sampleLight(lights[l], P);
                const Color want = shadeSurfacePoint(m, N, I, ls, vis, 4);
                const float* got = r.image.pixel(px, py);
                ASSERT_EQ(got[3], 1.f) << engine;
                worst = std::max({worst, double(std::abs(got[0] - want.x)), double(std::abs(got[1] - want.y)),
                                  double(std::abs(got[2] - want.z))});
            }
        // The ray tracer shades the exact hit; Reyes interpolates colours over micropolygons of 0.05 pixel.
        EXPECT_LT(worst, std::string(engine) == "rt" ? 1e-4 : 5e-3) << engine;
        std::printf("%s: largest difference from the shading module %.2e\n", engine, worst);
    }
}

}  // namespace tessera::test::shading_tests
