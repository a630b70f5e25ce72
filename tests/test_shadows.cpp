// Shadows (issue 13): which lights cast them (RIB Attribute "light" "shadows", --shadows), decided the same
// way in both engines; Reyes' ray-traced shadows against the ray tracer; Reyes' shadow maps (paper 001 sec.
// 3.5) against analytic shadows (outline, acne, contact) and against the ray tracer.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "core/random.h"
#include "film/image_compare.h"
#include "io/rib_writer.h"
#include "io/scene_loader.h"
#include "render/render.h"
#include "reyes/shadow_maps.h"
#include "rib_test_util.h"
#include "shading/shadow_map.h"
#include "test_util.h"

namespace tessera::test::shadows_tests {

namespace {

// Matte floor z = 10 facing the camera, a unit square occluder at z = 8 and a point light at (2, 0, 4),
// no ambient light: the shadow is the square projected from the light onto the floor, scaled by
// (10 - 4) / (8 - 4): x in [-1.75, -0.25], y in [-0.75, 0.75] (as RtShadow.SquareShadowMatches...).
Scene squareOverFloor(bool castsShadows) {
    Scene s = cameraSpaceScene(100, 100, 40.f);
    s.lights = {{LightType::Point, {36, 36, 36}, {2, 0, 4}, {0, 0, 0}}};
    s.lights[0].castsShadows = castsShadows;
    addPatch(s, planarPatch({-20, -20, 10}, {40, 0, 0}, {0, 40, 0}));
    addPatch(s, planarPatch({-0.5f, -0.5f, 8}, {1, 0, 0}, {0, 1, 0}));
    return s;
}

// Mean red of the floor pixels well inside the analytic shadow of squareOverFloor (1.5 pixels of margin),
// and how many there are.
double meanInShadow(const Scene& s, const Image& img, int& count) {
    const Projector pr(s.camera);
    double sum = 0;
    count = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            const float cx = (x + 0.5f - pr.ox) / pr.sx, cy = (y + 0.5f - pr.oy) / pr.sy;
            const float fx = cx * 10, fy = cy * 10, m = 1.5f / (pr.sx / 10);
            if (std::fabs(cx * 8) < 0.5f + m && std::fabs(cy * 8) < 0.5f + m) continue;  // sees the square
            if (fx > -1.75f + m && fx < -0.25f - m && std::fabs(fy) < 0.75f - m) {
                sum += img.pixel(x, y)[0];
                ++count;
            }
        }
    return count ? sum / count : 0.0;
}

RenderResult renderWith(const Scene& s, const std::string& engine, ShadowOverride shadows,
                        ReyesShadows reyes = ReyesShadows::Raytrace) {
    RenderSettings rs;
    rs.engine = engine;
    rs.threads = 2;
    rs.shadows = shadows;
    rs.reyesShadows = reyes;
    return render(s, rs);
}

Scene shippedScene(const std::string& name, int width, int height) {
    Scene s = loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/" + name, [](const std::string&) {});
    s.camera.width = width;
    s.camera.height = height;
    return s;
}

}  // namespace

TEST(ShadowAttribute, EachLightTakesTheValueCurrentWhenItIsDeclared) {
    const Loaded l = load(R"(Format 8 8 1
WorldBegin
LightSource "distantlight" 1
Attribute "light" "shadows" ["on"]
LightSource "ambientlight" 2
LightSource "distantlight" 3
AttributeBegin
  Attribute "light" "string shadows" "off"
  LightSource "pointlight" 4
AttributeEnd
LightSource "spotlight" 5
Attribute "light" "shadows" ["off"]
Patch "bilinear" "P" [0 0 1 1 0 1 0 1 1 1 1 1]
WorldEnd
)");
    ASSERT_EQ(l.scene.lights.size(), 5u);
    EXPECT_FALSE(l.scene.lights[0].castsShadows);  // the RIB default: off
    EXPECT_FALSE(l.scene.lights[1].castsShadows);  // ambient light never casts
    EXPECT_TRUE(l.scene.lights[2].castsShadows);
    EXPECT_FALSE(l.scene.lights[3].castsShadows);  // inline declaration, bare string
    EXPECT_TRUE(l.scene.lights[4].castsShadows);   // AttributeEnd restored "on"; the later "off" is too late
    for (const std::string& w : l.warnings) EXPECT_EQ(w.find("Attribute"), std::string::npos) << w;
}

TEST(ShadowAttribute, AValueOtherThanOnOrOffIsAnErrorNamingTheLine) {
    const std::string msg = expectError(R"(WorldBegin
LightSource "distantlight" 1
Attribute "light"
   "shadows" ["yes"]
WorldEnd
)",
                                        4);
    EXPECT_TRUE(contains(msg, "\"shadows\" must be \"on\" or \"off\", found \"yes\"")) << msg;
    expectError("WorldBegin\nAttribute \"light\" \"shadows\" [1]\nWorldEnd\n", 2);
}

TEST(ShadowAttribute, TheWrittenRibKeepsEachLightsChoice) {
    Loaded l = load(R"(WorldBegin
Attribute "light" "shadows" ["on"]
LightSource "distantlight" 1
Attribute "light" "shadows" ["off"]
LightSource "pointlight" 2
Attribute "light" "shadows" ["on"]
LightSource "spotlight" 3
Patch "bilinear" "P" [0 0 1 1 0 1 0 1 1 1 1 1]
WorldEnd
)");
    const std::string out = (testScratchDir() / "written.rib").string();
    writeRib(l.scene, out);
    const Scene back = loadScene(out, [](const std::string&) {});
    ASSERT_EQ(back.lights.size(), 3u);
    EXPECT_TRUE(back.lights[0].castsShadows);
    EXPECT_FALSE(back.lights[1].castsShadows);
    EXPECT_TRUE(back.lights[2].castsShadows);
}

TEST(ShadowAttribute, ShadowMapParametersAreTakenByEachLightAndChecked) {
    const Loaded l = load(R"(WorldBegin
Attribute "light" "shadows" ["on"]
LightSource "distantlight" 1
AttributeBegin
  Attribute "shadow" "resolution" [512] "float shadingrate" [4] "bias" [1.5] "filterwidth" [3]
  LightSource "spotlight" 2
AttributeEnd
Attribute "shadow" "filterwidth" [1]
LightSource "pointlight" 3
Patch "bilinear" "P" [0 0 1 1 0 1 0 1 1 1 1 1]
WorldEnd
)");
    ASSERT_EQ(l.scene.lights.size(), 3u);
    const ShadowMapParams defaults;
    EXPECT_EQ(l.scene.lights[0].shadowMap, defaults);
    EXPECT_EQ(l.scene.lights[0].shadowMap.resolution, 0);  // automatic
    const ShadowMapParams& spot = l.scene.lights[1].shadowMap;
    EXPECT_EQ(spot.resolution, 512);
    EXPECT_EQ(spot.shadingRate, 4.f);
    EXPECT_EQ(spot.bias, 1.5f);
    EXPECT_EQ(spot.filterWidth, 3.f);
    EXPECT_EQ(l.scene.lights[2].shadowMap.resolution, 0);  // the block restored the defaults
    EXPECT_EQ(l.scene.lights[2].shadowMap.filterWidth, 1.f);
    // The written RIB keeps them.
    const std::string out = (testScratchDir() / "maps.rib").string();
    writeRib(l.scene, out);
    const Scene back = loadScene(out, [](const std::string&) {});
    ASSERT_EQ(back.lights.size(), 3u);
    for (size_t i = 0; i < 3; ++i) EXPECT_EQ(back.lights[i].shadowMap, l.scene.lights[i].shadowMap) << i;

    std::string msg = expectError("WorldBegin\nAttribute \"shadow\" \"resolution\" [100.5]\nWorldEnd\n", 2);
    EXPECT_TRUE(
        contains(msg, "\"resolution\" must be an integer from 8 to 16384 (or 0: automatic), found 100.5"))
        << msg;
    msg = expectError("WorldBegin\nAttribute \"shadow\"\n \"filterwidth\" [0.5]\nWorldEnd\n", 3);
    EXPECT_TRUE(contains(msg, "\"filterwidth\" must be a number from 1 to 64, found 0.5")) << msg;
    expectError("WorldBegin\nAttribute \"shadow\" \"bias\" [-1]\nWorldEnd\n", 2);
    expectError("WorldBegin\nAttribute \"shadow\" \"shadingrate\" [\"fine\"]\nWorldEnd\n", 2);
}

TEST(ShadowAttribute, TheDefaultLightsOfInputsWithoutARibCastShadows) {
    // What the ray tracer always did for .bpt, OBJ and Micropolis inputs (docs/inputs.md).
    const Scene s = loadScene(std::string(TESSERA_TEST_DATA) + "/teapot.bpt", [](const std::string&) {});
    int casting = 0;
    for (const Light& l : s.lights) {
        EXPECT_EQ(l.castsShadows, l.type != LightType::Ambient);
        casting += l.castsShadows;
    }
    EXPECT_EQ(casting, 2);
}

TEST(ShadowCasting, TheLightsChoiceAndTheOverrideDecideBothEnginesShadows) {
    // Floor pixels in the square's analytic shadow: black when the light casts shadows, lit otherwise;
    // the ray tracer and Reyes with ray-traced shadows alike.
    for (const char* engine : {"rt", "reyes"})
        for (bool casts : {false, true})
            for (ShadowOverride o : {ShadowOverride::Scene, ShadowOverride::On, ShadowOverride::Off}) {
                const Scene s = squareOverFloor(casts);
                const RenderResult r = renderWith(s, engine, o);
                int n = 0;
                const double inShadow = meanInShadow(s, r.image, n);
                const bool expectShadow = o == ShadowOverride::On || (o == ShadowOverride::Scene && casts);
                std::printf("%s: light casts %d, --shadows %s: %d floor pixels in the shadow, mean %.4f\n",
                            engine, casts, shadowOverrideName(o), n, inShadow);
                ASSERT_GT(n, 50);
                if (expectShadow)
                    EXPECT_EQ(inShadow, 0.0) << engine << " " << casts << " " << shadowOverrideName(o);
                else
                    EXPECT_GT(inShadow, 0.2) << engine << " " << casts << " " << shadowOverrideName(o);
                const nlohmann::json& st = r.stats;
                const uint64_t rays = std::string(engine) == "rt" ? st["rays"]["shadow"].get<uint64_t>()
                                      : st.contains("shadows") ? st["shadows"]["shadow_rays"].get<uint64_t>()
                                                               : 0;
                EXPECT_EQ(rays > 0, expectShadow) << engine;
            }
}

TEST(ReyesRayTracedShadows, AgreeWithTheRayTracerOnShippedScenes) {
    // Reyes answering its visibility queries with the trace service's shadow rays against the ray tracer
    // (issue 13: >= 40 dB), on shipped scenes whose key light casts shadows. Reyes without shadows against
    // the same ray-traced image is printed; in the box, where Big Guy's shadow covers much of the floor, it
    // must be far worse (the shadows are what is compared; the teapot's self-shadows are small).
    for (const char* name : {"bigguy_box.rib", "teapot.rib"}) {
        const Scene s = shippedScene(name, 240, 180);
        const RenderResult rt = renderWith(s, "rt", ShadowOverride::Scene);
        const RenderResult reyes = renderWith(s, "reyes", ShadowOverride::Scene, ReyesShadows::Raytrace);
        const RenderResult bare = renderWith(s, "reyes", ShadowOverride::Off);
        const ImageDiff d = compareImages(reyes.image, rt.image, 0.1f);
        const ImageDiff without = compareImages(bare.image, rt.image, 0.1f);
        std::printf(
            "%s 240x180: Reyes ray-traced shadows vs rt PSNR %.2f dB (Reyes without shadows %.2f dB), "
            "%llu shadow rays\n",
            name, d.psnrColor, without.psnrColor,
            (unsigned long long)reyes.stats["shadows"]["shadow_rays"].get<uint64_t>());
        ::testing::Test::RecordProperty(std::string("psnr_") + name, std::to_string(d.psnrColor));
        EXPECT_GE(d.psnrColor, 40.0) << name;
        EXPECT_LT(d.alphaMismatch, 0.005) << name;
        if (std::string(name) == "bigguy_box.rib") {
            EXPECT_GT(d.psnrColor, without.psnrColor + 10.0);
        }
    }
}

// ---- Shadow maps rendered by the Reyes pipeline -------------------------------------------------------

namespace {

// The scene's lights in its camera space, each casting shadows as the scene says (FrameSetup's rule).
std::vector<ShadingLight> shadingLights(const Scene& s) {
    std::vector<ShadingLight> out;
    for (const Light& l : s.lights) out.push_back(prepareLight(l, s.camera.cameraFromWorld));
    return out;
}

// The maps of a scene whose world space is its camera space (cameraSpaceScene).
ShadowMaps mapsOf(const Scene& s) {
    RenderSettings rs;
    rs.threads = 2;
    return ShadowMaps(s, rs, s.camera, shadingLights(s));
}

// The world size of a texel of an orthographic map.
float orthoTexel(const ShadowMapLookup& m) {
    return 1.f / std::fabs(m.faces[0].sx);
}

// Points and normals on the patches of `s` from index `first` on, on an n x n (u,v) grid per patch.
void surfacePoints(const Scene& s, size_t first, int n, std::vector<Vec3>& P, std::vector<Vec3>& N) {
    for (size_t i = first; i < s.patches.size(); ++i)
        for (int b = 0; b <= n; ++b)
            for (int a = 0; a <= n; ++a) {
                const float u = float(a) / n, v = float(b) / n;
                const Vec3 nrm = patchNormal(s.patches[i], u, v);
                if (!(dot(nrm, nrm) > 0.f)) continue;  // a pole
                P.push_back(evalPatch(s.patches[i], u, v));
                N.push_back(normalize(nrm));
            }
}

Light distantLight(Vec3 towardsLight, float intensity = 1.f) {
    Light l;
    l.type = LightType::Distant;
    l.color = {intensity, intensity, intensity};
    l.from = towardsLight;
    l.to = {0, 0, 0};
    l.castsShadows = true;
    return l;
}

// Distance from point c to the line through F along unit direction L, and whether c lies ahead on it.
float lineDistance(Vec3 F, Vec3 L, Vec3 c, bool& ahead) {
    const Vec3 d = c - F;
    const float t = dot(d, L);
    ahead = t > 0.f;
    return length(d - L * t);
}

}  // namespace

TEST(ShadowMaps, ASpheresShadowOnTheFloorMatchesTheAnalyticProjectionWithinTheFilterWidth) {
    // A sphere of radius 1 at height 2 above the floor y = 0 under a distant light: a floor point is in
    // shadow when its line towards the light passes within the radius of the centre (in the map's plane,
    // orthogonal to the light, that distance is the distance from the shadow's outline). Away from the
    // outline by more than the filter box's half diagonal (the box reaches (w/2) sqrt 2 texels along a
    // diagonal) plus half a texel's diagonal (the map is sampled at texel centres), the lookups must be
    // exactly 0 (shadow) or 1 (lit); the band around it is the filtered edge.
    for (float filterWidth : {1.f, 2.f, 4.f}) {
        Scene s = cameraSpaceScene(64, 64, 40.f);
        const Vec3 L = normalize(Vec3{0.4f, 1.f, 0.25f}), centre{0, 2, 0};
        s.lights = {distantLight(L)};
        s.lights[0].shadowMap.filterWidth = filterWidth;
        addPatch(s, planarPatch({-4, 0, -4}, {8, 0, 0}, {0, 0, 8}));
        for (const BezierPatch& p : octantSphere(1.f, centre)) addPatch(s, p);
        const ShadowMaps maps = mapsOf(s);
        const ShadowMapLookup* m = maps.lookup(0);
        ASSERT_NE(m, nullptr);
        const float texel = orthoTexel(*m), band = (0.5f * filterWidth + 0.5f) * std::sqrt(2.f) * texel;
        int shadowed = 0, lit = 0, wrong = 0, inBand = 0;
        double worstTexels = 0;  // the farthest from the outline a wrong answer lies
        for (float z = -2.5f; z <= 2.5f; z += 0.0037f)
            for (float x = -2.5f; x <= 2.5f; x += 0.0371f) {
                const Vec3 F{x, 0, z};
                bool ahead;
                const float d = lineDistance(F, L, centre, ahead) - 1.f;  // < 0: in the shadow
                if (!ahead) continue;
                const float v = maps.visibility(0, F, {0, 1, 0});
                if (std::fabs(d) < band) {
                    ++inBand;
                    continue;
                }
                const bool expectShadow = d < 0.f;
                (expectShadow ? shadowed : lit)++;
                if (v != (expectShadow ? 0.f : 1.f)) {
                    ++wrong;
                    worstTexels = std::max(worstTexels, double(std::fabs(d) / texel));
                }
            }
        std::printf(
            "filter %.0f texels (texel %.4f): %d shadowed and %d lit floor points outside the %.1f-texel "
            "band (%d in it), %d wrong (farthest %.2f texels from the outline)\n",
            filterWidth, texel, shadowed, lit, band / texel, inBand, wrong, worstTexels);
        EXPECT_GT(shadowed, 5000);
        EXPECT_GT(lit, 5000);
        EXPECT_EQ(wrong, 0) << "filter width " << filterWidth;
    }
}

TEST(ShadowMaps, ALitConvexSphereDoesNotShadowItself) {
    // Acne: every point of a convex sphere that faces the light must see it, for each kind of map (an
    // orthographic map for a distant light, a perspective one for a spot light, a cube map for a point
    // light), lights from the camera's side and from elsewhere, at the default bias and filter widths up
    // to 4 texels (the receiver-plane test keeps a tilted surface from shadowing itself under a wide filter).
    // Each map is rendered once; the filter width is a lookup parameter.
    const Vec3 centre{0.2f, -0.1f, 6.f};
    for (int kind = 0; kind < 3; ++kind)
        for (const Vec3& from : {Vec3{0, 0, 0}, Vec3{3.f, 2.f, 2.f}, Vec3{-2.f, 3.f, 8.f}}) {
            Scene s = cameraSpaceScene(64, 64, 40.f);
            Light l;
            l.castsShadows = true;
            l.from = from;
            l.to = centre;
            l.type = kind == 0 ? LightType::Distant : kind == 1 ? LightType::Spot : LightType::Point;
            if (kind == 0) l.from = from - centre;  // a distant light shines along from -> to
            if (kind == 0) l.to = {0, 0, 0};
            s.lights = {l};
            for (const BezierPatch& p : octantSphere(1.f, centre)) addPatch(s, p);
            const ShadowMaps maps = mapsOf(s);
            const ShadingLight sl = shadingLights(s)[0];
            std::vector<Vec3> P, N;
            surfacePoints(s, 0, 40, P, N);
            for (float filterWidth : {2.f, 4.f}) {
                ShadowMapLookup lookup = *maps.lookup(0);
                lookup.filterWidth = filterWidth;
                int facing = 0, shadowed = 0;
                double worst = 1;
                for (size_t i = 0; i < P.size(); ++i) {
                    const LightSample ls = sampleLight(sl, P[i]);
                    const Vec3 out = normalize(P[i] - centre);
                    if (!ls.valid || !(dot(out, ls.L) > 1e-3f)) continue;  // faces away (or the terminator)
                    ++facing;
                    const float v = shadowMapVisibility(lookup, P[i], N[i]);
                    if (v < 1.f) ++shadowed, worst = std::min(worst, double(v));
                }
                // The same points with the receiver pushed a texel away from the light (a negative bias):
                // they shadow themselves, so the count above would see acne.
                ShadowMapLookup pushed = lookup;
                pushed.bias = -1.f;
                int acne = 0;
                for (size_t i = 0; i < P.size(); ++i)
                    if (dot(normalize(P[i] - centre), sampleLight(sl, P[i]).L) > 0.1f)
                        acne += shadowMapVisibility(pushed, P[i], N[i]) < 1.f;
                EXPECT_GT(acne, facing / 4);
                std::printf(
                    "filter %.0f, %s light from (%g, %g, %g): %d lit points, %d shadowed (lowest %.3f)\n",
                    filterWidth,
                    kind == 0   ? "distant"
                    : kind == 1 ? "spot"
                                : "point",
                    from.x, from.y, from.z, facing, shadowed, worst);
                EXPECT_GT(facing, 1000);
                EXPECT_EQ(shadowed, 0) << kind << " " << from.x << " " << from.y << " " << from.z;
            }
        }
}

TEST(ShadowMaps, APlateLeaningOnTheFloorLeaksNoMoreLightThanItsBiasLifts) {
    // A unit plate leaning on the floor y = 0 along its edge x = 0 at angle a, under a distant light from -x
    // at elevation e: its shadow on the floor runs from the contact line to x = cos a + sin a / tan e. Near
    // the contact the plate is barely above the floor: a floor point at x sees the plate x sin a / sin(e + a)
    // nearer to the light, so a depth bias of b texels lifts the shadow off the contact ("peter panning")
    // up to x = b texel sin(e + a) / sin a, which is b sin(e + a) sin e / sin a texels in the map's plane
    // (a floor distance d is d sin e there), and the filter spreads the edge by half its width. Every floor
    // point in the shadow beyond that, the outline's texel and the filter (or beyond half the filter and a
    // texel, where the lift is smaller) must be fully dark; at 60 degrees the default bias lifts less than
    // the filter, so the shadow there reaches the contact; four times the bias must leak beyond the default
    // bias's reach (the test sees peter panning).
    const float e = 45.f * 3.14159265f / 180.f;
    const Vec3 L{-std::cos(e), std::sin(e), 0.f};
    for (float aDeg : {30.f, 60.f})
        for (float biasScale : {1.f, 4.f}) {
            const float a = aDeg * 3.14159265f / 180.f;
            Scene s = cameraSpaceScene(64, 64, 40.f);
            s.lights = {distantLight(L)};
            const float defaultBias = s.lights[0].shadowMap.bias;
            s.lights[0].shadowMap.bias *= biasScale;
            addPatch(s, planarPatch({-3, 0, -3}, {0, 0, 6}, {6, 0, 0}));
            addPatch(s, planarPatch({0, 0, -0.5f}, {0, 0, 1}, {std::cos(a), std::sin(a), 0}));
            const ShadowMaps maps = mapsOf(s);
            const float texel = orthoTexel(*maps.lookup(0));
            const ShadowMapParams& sm = s.lights[0].shadowMap;
            const float edge = 0.5f * sm.filterWidth + 1.f;  // texels: the filtered outline
            auto lift = [&](float bias) { return bias * std::sin(e + a) * std::sin(e) / std::sin(a); };
            const float reach = std::max(lift(sm.bias), lift(defaultBias)) + edge;  // texels, map plane
            const float end = std::cos(a) + std::sin(a) / std::tan(e);
            int tested = 0, leaks = 0, beyondDefault = 0;
            float farthestLeak = 0;  // map-plane distance from the contact line of the farthest lit point
            for (float x = 0.f; x < end; x += 0.25f * texel) {
                const float fromContact = x * std::sin(e) / texel, fromEnd = (end - x) * std::sin(e) / texel;
                if (fromContact < edge || fromEnd < edge) continue;
                for (float z = -0.5f + edge * texel; z <= 0.5f - edge * texel; z += 0.021f) {
                    if (maps.visibility(0, {x, 0, z}, {0, 1, 0}) == 0.f) {
                        ++tested;
                        continue;
                    }
                    ++tested, ++leaks;
                    farthestLeak = std::max(farthestLeak, fromContact);
                    beyondDefault += fromContact > lift(defaultBias) + edge;
                    EXPECT_LE(fromContact, reach) << aDeg << " " << biasScale << ": x " << x << " z " << z;
                }
            }
            std::printf(
                "plate at %.0f deg, bias %.1f texels: %d floor points in its shadow, %d lit (up to %.2f "
                "texels from the contact; the bias lifts it %.2f texels)\n",
                aDeg, sm.bias, tested, leaks, farthestLeak, lift(sm.bias));
            EXPECT_GT(tested, 1000);
            if (biasScale == 1.f && aDeg == 60.f) {
                EXPECT_EQ(leaks, 0);
            }
            if (biasScale == 4.f) {
                EXPECT_GT(beyondDefault, 0) << aDeg;
            }
        }
}

namespace {

// A sphere above a floor seen from above and in front, lit by `light` (and a little ambient light).
Scene sphereOverFloor(const Light& light) {
    Scene s;
    s.camera.width = 160;
    s.camera.height = 120;
    s.camera.fovDegrees = 45.f;
    s.camera.nearClip = 0.1f;
    s.camera.farClip = 100.f;
    // Eye at (0, 4, -7) looking at the origin (RenderMan camera: +x right, +y up, +z into the screen).
    const Vec3 eye{0, 4, -7}, z = normalize(Vec3{0, 0, 0} - eye), x = normalize(cross(Vec3{0, 1, 0}, z)),
                              y = cross(z, x);
    const Vec3 axes[3] = {x, y, z};
    for (int r = 0; r < 3; ++r) {
        s.camera.cameraFromWorld.m[r][0] = axes[r].x, s.camera.cameraFromWorld.m[r][1] = axes[r].y;
        s.camera.cameraFromWorld.m[r][2] = axes[r].z, s.camera.cameraFromWorld.m[r][3] = -dot(axes[r], eye);
    }
    s.image.pixelSamplesX = s.image.pixelSamplesY = 4;
    s.materials.push_back(defaultMaterial(MaterialType::Matte));
    s.lights = {{LightType::Ambient, {0.1f, 0.1f, 0.1f}, {}, {}}, light};
    addPatch(s, planarPatch({-4, 0, -4}, {8, 0, 0}, {0, 0, 8}));
    for (const BezierPatch& p : octantSphere(1.f, {0, 1.5f, 0})) addPatch(s, p);
    return s;
}

}  // namespace

// A lookup's percentage-closer filter computes the receiver plane's depth from terms per texel column and
// row; it must give the bits of the filter that evaluates receiverPlaneDepth at every texel
// (shadowMapFaceVisibilityEachTexel), on orthographic and perspective faces, for normals facing, grazing and
// perpendicular to the lines of sight, footprints inside, across and beyond the map's edges, and filter
// widths up to beyond the column terms' 8 texels.
TEST(ShadowMaps, TheFilteredLookupEqualsTheFilterEvaluatingEachTexel) {
    const int size = 64;
    std::vector<float> depth(size_t(size) * size);
    uint32_t draw = 99u;
    auto uniform = [&]() { return hashToUnit(hash32(draw++)); };
    // A bumpy surface 10 units from the light, some texels empty.
    for (size_t i = 0; i < depth.size(); ++i)
        depth[i] = uniform() < 0.05f ? std::numeric_limits<float>::infinity() : 10.f + 0.3f * uniform();
    size_t compared = 0, differ = 0, partial = 0;
    for (const bool perspective : {false, true}) {
        ShadowMapFace f;
        f.perspective = perspective;
        f.width = f.height = size;
        f.depth = depth.data();
        // Orthographic: light-space x, y in [-4, 4] over the map; perspective: 90 degrees (x/z in [-1, 1]).
        f.sx = perspective ? 32.f : 8.f, f.sy = perspective ? -32.f : -8.f, f.ox = f.oy = 32.f;
        for (int k = 0; k < 4000; ++k) {
            const float span = perspective ? 11.f : 4.5f;  // a little beyond the map's edges
            const Vec3 p{(2.f * uniform() - 1.f) * span, (2.f * uniform() - 1.f) * span, 9.5f + uniform()};
            Vec3 n{2.f * uniform() - 1.f, 2.f * uniform() - 1.f, 2.f * uniform() - 1.f};
            if (k % 7 == 0) n.z = 0.f;                  // parallel to the lines of sight
            if (k % 11 == 0) n = Vec3{0.f, 0.f, -1.f};  // facing the light
            const float widths[] = {1.f, 2.f, 3.5f, 7.9f, 12.f};
            const float width = widths[k % 5], bias = k % 3 == 0 ? 0.f : 1.f;
            // Every third lookup sees texels holding exactly its receiver depths less the bias (a tie: lit)
            // or the float below (shadowed), so that a receiver depth one bit off changes the result.
            const int tie = k % 3 == 1 ? 0 : k % 3 == 2 ? 1 : -1;
            if (tie >= 0) {
                float tx, ty, texelWorld;
                shadowMapProject(f, p, tx, ty, texelWorld);
                const float half = 0.5f * width;
                for (int y = int(std::floor(ty - half)); y <= int(std::floor(ty + half)); ++y)
                    for (int x = int(std::floor(tx - half)); x <= int(std::floor(tx + half)); ++x) {
                        if (x < 0 || y < 0 || x >= size || y >= size) continue;
                        float d =
                            receiverPlaneDepth(f, p, n, float(x) + 0.5f, float(y) + 0.5f) - bias * texelWorld;
                        if (tie == 1) d = std::nextafter(d, -std::numeric_limits<float>::infinity());
                        depth[size_t(y) * size + size_t(x)] = d;
                    }
            }
            const float got = shadowMapFaceVisibility(f, p, n, bias, width);
            const float want = shadowMapFaceVisibilityEachTexel(f, p, n, bias, width);
            ++compared;
            differ += std::memcmp(&got, &want, sizeof got) != 0;
            partial += want > 0.f && want < 1.f;
        }
    }
    EXPECT_EQ(differ, 0u) << "of " << compared << " lookups";
    EXPECT_GT(partial, compared / 4);  // the filter straddles shadow edges, not only all-lit or all-dark
}

TEST(ReyesShadowMaps, EveryKindOfMapAgreesWithRayTracedShadows) {
    // The same Reyes render with its shadow maps and with the trace service's shadow rays: an orthographic
    // map (distant light), a perspective one (spot light), a cube map (point light, and a spot light whose
    // cone is too wide for one perspective map). The maps' filtered edges are the difference.
    Light distant = distantLight({1.f, 3.f, -0.5f}, 1.f);
    Light spot;
    spot.type = LightType::Spot;
    spot.from = {2.f, 5.f, -1.f};
    spot.to = {0, 0, 0};
    spot.color = {30, 30, 30};
    spot.coneAngle = 0.6f;
    spot.castsShadows = true;
    Light wideSpot = spot;
    wideSpot.coneAngle = 1.3f;
    Light point = spot;
    point.type = LightType::Point;
    const std::pair<const char*, Light> cases[] = {
        {"distant", distant}, {"spot", spot}, {"wide spot", wideSpot}, {"point", point}};
    for (const auto& [name, light] : cases) {
        const Scene s = sphereOverFloor(light);
        const RenderResult map = renderWith(s, "reyes", ShadowOverride::Scene, ReyesShadows::Map);
        const RenderResult rays = renderWith(s, "reyes", ShadowOverride::Scene, ReyesShadows::Raytrace);
        const RenderResult none = renderWith(s, "reyes", ShadowOverride::Off);
        const ImageDiff d = compareImages(map.image, rays.image, 0.1f);
        const ImageDiff without = compareImages(none.image, rays.image, 0.1f);
        const nlohmann::json& m = map.stats["shadows"]["maps"][0];
        std::printf(
            "%s light: Reyes shadow map vs ray-traced shadows PSNR %.2f dB (no shadows: %.2f dB); %d "
            "face(s) of %d texels, %.1f ms\n",
            name, d.psnrColor, without.psnrColor, m["faces"].get<int>(), m["resolution"].get<int>(),
            m["ms"].get<double>());
        ::testing::Test::RecordProperty(std::string("psnr_map_") + name, std::to_string(d.psnrColor));
        EXPECT_EQ(m["faces"].get<int>(),
                  std::string(name) == "distant" || std::string(name) == "spot" ? 1 : 6);
        EXPECT_GE(d.psnrColor, 38.0) << name;
        EXPECT_GT(d.psnrColor, without.psnrColor + 10.0) << name;
    }
}

TEST(ReyesShadowMaps, OneMapPerLightThatCastsShadowsRenderedOncePerFrame) {
    // Three lights, two casting shadows: two maps (their lights' indices, their kinds), timed, each looked
    // up by every grid vertex that faces its light; none for the light without shadows.
    Light spot;
    spot.type = LightType::Spot;
    spot.from = {2.f, 5.f, -1.f};
    spot.color = {30, 30, 30};
    spot.castsShadows = true;
    Scene s = sphereOverFloor(distantLight({1.f, 3.f, -0.5f}, 0.5f));
    s.lights.push_back(spot);
    s.lights.push_back(distantLight({-1.f, 2.f, 0.f}, 0.3f));
    s.lights.back().castsShadows = false;
    const RenderResult r = renderWith(s, "reyes", ShadowOverride::Scene, ReyesShadows::Map);
    const nlohmann::json& sh = r.stats["shadows"];
    ASSERT_EQ(sh["method"], "map");
    ASSERT_EQ(sh["maps"].size(), 2u);
    EXPECT_EQ(sh["maps"][0]["light"], 1);
    EXPECT_EQ(sh["maps"][0]["type"], "distant");
    EXPECT_EQ(sh["maps"][1]["light"], 2);
    EXPECT_EQ(sh["maps"][1]["type"], "spot");
    double sum = 0;
    for (const auto& m : sh["maps"]) {
        EXPECT_GT(m["micropolygons"].get<uint64_t>(), 1000u);
        EXPECT_GT(m["ms"].get<double>(), 0.0);
        sum += m["ms"].get<double>();
    }
    EXPECT_GE(sh["maps_ms"].get<double>(), sum);
    EXPECT_EQ(r.stats["stage_ms"]["shadow_maps"], sh["maps_ms"]);
    EXPECT_GT(sh["lookups"].get<uint64_t>(), 1000u);
    // --shadows off: no map at all.
    const RenderResult off = renderWith(s, "reyes", ShadowOverride::Off, ReyesShadows::Map);
    EXPECT_FALSE(off.stats.contains("shadows"));
}

TEST(ReyesShadowMaps, AgreeWithTheRayTracersHardShadowsOnShippedScenes) {
    // Issue 13: Reyes with its shadow maps against the ray tracer with hard shadows, >= 32 dB, on shipped
    // scenes whose key light casts shadows: a point light's cube map (the box), distant lights' orthographic
    // maps (the teapot's self-shadows, the Killeroo: the lowest agreement without shadows, 37.5 dB at
    // 400x300). Reyes without shadows against the same image is printed for comparison.
    for (const char* name : {"bigguy_box.rib", "teapot.rib", "killeroo.rib"}) {
        const Scene s = shippedScene(name, 240, 180);
        const RenderResult rt = renderWith(s, "rt", ShadowOverride::Scene);
        const RenderResult reyes = renderWith(s, "reyes", ShadowOverride::Scene, ReyesShadows::Map);
        const RenderResult bare = renderWith(s, "reyes", ShadowOverride::Off);
        const ImageDiff d = compareImages(reyes.image, rt.image, 0.1f);
        const ImageDiff without = compareImages(bare.image, rt.image, 0.1f);
        std::printf(
            "%s 240x180: Reyes shadow maps vs rt PSNR %.2f dB (Reyes without shadows %.2f dB), maps "
            "%.0f ms of %.0f ms\n",
            name, d.psnrColor, without.psnrColor, reyes.stats["shadows"]["maps_ms"].get<double>(),
            reyes.stats["engine_ms"].get<double>());
        ::testing::Test::RecordProperty(std::string("psnr_map_") + name, std::to_string(d.psnrColor));
        EXPECT_GE(d.psnrColor, 32.0) << name;
        EXPECT_LT(d.alphaMismatch, 0.005) << name;
        if (std::string(name) == "bigguy_box.rib") {
            EXPECT_GT(d.psnrColor, without.psnrColor + 10.0);
        }
    }
}

TEST(ReyesShadowMaps, TheShadowCountChannelCountsTheLightsInShadowInBothEngines) {
    // The film's shadow-count channel (--aov shadows): 1 on the floor inside the square's shadow, 0 where the
    // light reaches it, from the ray tracer's shadow rays and from Reyes' maps or rays alike.
    const Scene s = squareOverFloor(true);
    const Projector pr(s.camera);
    for (int method = 0; method < 3; ++method) {
        RenderSettings rs;
        rs.engine = method == 0 ? "rt" : "reyes";
        rs.reyesShadows = method == 2 ? ReyesShadows::Raytrace : ReyesShadows::Map;
        rs.threads = 2;
        rs.output.channels = kChannelShadowCount;
        const RenderResult r = render(s, rs);
        const ImagePlane* plane = r.image.plane("shadows");
        ASSERT_NE(plane, nullptr);
        int inShadow = 0, lit = 0, wrong = 0;
        for (int y = 0; y < r.image.height; ++y)
            for (int x = 0; x < r.image.width; ++x) {
                const float cx = (x + 0.5f - pr.ox) / pr.sx, cy = (y + 0.5f - pr.oy) / pr.sy;
                const float fx = cx * 10, fy = cy * 10, m = 1.5f / (pr.sx / 10);
                if (std::fabs(cx * 8) < 0.5f + m && std::fabs(cy * 8) < 0.5f + m) continue;  // the square
                const bool shadow = fx > -1.75f + m && fx < -0.25f - m && std::fabs(fy) < 0.75f - m;
                const bool light = fx < -1.75f - m || fx > -0.25f + m || std::fabs(fy) > 0.75f + m;
                const float v = plane->values[r.image.index(x, y)];
                if (shadow) ++inShadow, wrong += v != 1.f;
                if (light) ++lit, wrong += v != 0.f;
            }
        std::printf("%s: %d pixels in the shadow, %d lit, %d with another count\n",
                    method == 0   ? "rt"
                    : method == 1 ? "reyes maps"
                                  : "reyes rays",
                    inShadow, lit, wrong);
        EXPECT_GT(inShadow, 50);
        EXPECT_GT(lit, 5000);
        EXPECT_EQ(wrong, 0) << method;
    }
}

}  // namespace tessera::test::shadows_tests
