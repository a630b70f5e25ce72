// Ray-traced displacement (issue 12, "Ray tracer"; rt/displaced.h): a constant offset of a plane and of a
// curved bicubic traced against the analytic offset surface; the wavefront and the scalar paths agree;
// shadow rays are blocked by the displaced surface, not the undisplaced one; the displaced teapot renders
// as in Reyes (PSNR, alpha); displaced teapot and Catmull-Clark models have no pinholes, also with
// neighbouring patches diced at different rates.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "engine/frame.h"
#include "film/image_compare.h"
#include "render/displaced_dicer.h"
#include "render/render.h"
#include "rib_test_util.h"
#include "rt/accel.h"
#include "rt/trace_service.h"
#include "test_util.h"

namespace tessera::test::rt_displacement_tests {

namespace {

// The scene's accel in camera space with its displaced patches diced as renderRt dices them (`lazy`:
// built when first reached, whatever the budget).
void buildDisplacedAccel(const Scene& scene, RtAccel& acc, bool lazy = false) {
    const RenderSettings rs;
    const FrameSetup frame(scene, rs);
    RtDisplacementOptions d;
    d.dicer = makeReyesDisplacedDicer(scene, rs, frame);
    d.forceLazy = lazy;
    ASSERT_TRUE(d.dicer);
    buildRtAccel(scene, frame.camera.cameraFromWorld, 6, false, acc, nullptr, kDefaultTimeSlabs, &d);
    ASSERT_TRUE(acc.displaced.any());
}

// A perspective view of one bicubic patch (RIB control points, world = camera space shifted by 5 in z),
// displaced by the constant "offset" shader.
Loaded offsetScene(const std::string& patch, float km, int res = 200) {
    return load("Format " + std::to_string(res) + " " + std::to_string(res) +
                " 1\nShadingRate 0.5\nProjection \"perspective\" \"fov\" 40\nWorldBegin\n"
                "LightSource \"ambientlight\" 1\nTranslate 0 0 5\nDisplacement \"offset\" \"Km\" " +
                std::to_string(km) + "\n" + patch + "\nWorldEnd\n");
}

Vec3 orientedPatchNormal(const RtAccel& acc, uint32_t patch, float u, float v) {
    const SurfacePoint sp = evalPatchDeriv(acc.patches[patch], u, v);
    const Vec3 n = normalize(cross(sp.dpdu, sp.dpdv));
    return acc.flip[patch] ? -n : n;
}

const char* kPlane = "Patch \"bilinear\" \"P\" [-1 -1 0  1 -1 0  -1 1 0  1 1 0]";
// A dome: a bicubic whose middle control points rise (curved in both directions).
const char* kDome =
    "Patch \"bicubic\" \"P\" [-1 -1 0  -0.33 -1 0.3  0.33 -1 0.3  1 -1 0  -1 -0.33 0.3  -0.33 -0.33 0.8  "
    "0.33 -0.33 0.8  1 -0.33 0.3  -1 0.33 0.3  -0.33 0.33 0.8  0.33 0.33 0.8  1 0.33 0.3  -1 1 0  -0.33 1 "
    "0.3  "
    "0.33 1 0.3  1 1 0]";

}  // namespace

// A constant offset d of a plane: camera rays aimed at the offset plane hit it at the analytic distance,
// with the plane's normal as the shading normal, in the wavefront and the scalar paths alike.
TEST(RtDisplacement, ConstantOffsetOfAPlaneHitsTheOffsetPlane) {
    for (float km : {0.15f, -0.15f}) {
        SCOPED_TRACE(km);
        Loaded l = offsetScene(kPlane, km);
        RtAccel acc;
        buildDisplacedAccel(l.scene, acc);
        std::mt19937 rng(7);
        std::uniform_real_distribution<float> U(0.05f, 0.95f);
        std::vector<Ray> rays;
        std::vector<float> expected;
        const Vec3 n = orientedPatchNormal(acc, 0, 0.5f, 0.5f);
        const Vec3 P0 = evalPatch(acc.patches[0], 0.5f, 0.5f) + n * km;
        for (int i = 0; i < 400; ++i) {
            const Vec3 target = evalPatch(acc.patches[0], U(rng), U(rng)) + n * km;
            const Vec3 d = normalize(target);
            rays.push_back(Ray{{0, 0, 0}, d, 1e-3f, 1e30f});
            expected.push_back(dot(P0, n) / dot(d, n));  // the offset plane through P0
        }
        std::vector<RayHit> batch;
        traceBatch(acc, rays, TraceOptions{}, batch);
        float worst = 0.f, worstN = 0.f;
        int misses = 0;
        for (size_t i = 0; i < rays.size(); ++i) {
            RayHit scalar;
            const bool hit = traceRayScalar(acc, rays[i], TraceOptions{}, scalar);
            if (!hit || !batch[i].hit) {
                ++misses;
                continue;
            }
            EXPECT_EQ(scalar.h.t, batch[i].h.t);
            worst = std::max(worst, std::fabs(batch[i].h.t - expected[i]) / expected[i]);
            worstN = std::max(worstN, length(hitNormal(acc, 0, batch[i].h) - n));
        }
        std::printf("offset plane Km %.2f: max |dt|/t %.2e, max |N - n| %.2e\n", km, worst, worstN);
        EXPECT_EQ(misses, 0);
        EXPECT_LT(worst, 1e-5f);
        EXPECT_LT(worstN, 1e-4f);
    }
}

// A constant offset d of a curved bicubic: every hit lies at distance |d| from the undisplaced surface (the
// offset surface), within the chords of the micro-grid, and hits are found wherever the offset surface is.
TEST(RtDisplacement, ConstantOffsetOfACurvedBicubicHitsTheOffsetSurface) {
    for (float km : {0.1f, -0.1f}) {
        SCOPED_TRACE(km);
        Loaded l = offsetScene(kDome, km);
        RtAccel acc;
        buildDisplacedAccel(l.scene, acc);
        std::mt19937 rng(11);
        std::uniform_real_distribution<float> U(0.05f, 0.95f);
        float worst = 0.f;
        int misses = 0;
        for (int i = 0; i < 200; ++i) {
            const float u = U(rng), v = U(rng);
            const Vec3 target = evalPatch(acc.patches[0], u, v) + orientedPatchNormal(acc, 0, u, v) * km;
            const Ray ray{{0, 0, 0}, normalize(target), 1e-3f, 1e30f};
            RayHit h;
            if (!traceRayScalar(acc, ray, TraceOptions{}, h)) {
                ++misses;
                continue;
            }
            worst = std::max(worst, std::fabs(distanceToPatch(acc.patches[0], h.h.p) - std::fabs(km)));
        }
        // Micropolygons of 0.7 pixel (ShadingRate 0.5) of a 200-pixel view at depth ~5: ~0.015 units; the
        // chord error over the dome's curvature radius (~1) is ~3e-5; the float grid ~1e-6.
        std::printf("offset dome Km %.2f: max | dist - |d| | %.2e\n", km, worst);
        EXPECT_EQ(misses, 0);
        EXPECT_LT(worst, 2e-4f);
    }
}

// Random rays through the displaced teapot's box: the wavefront stages (traversal, Newton stage with the
// micro-grid leaves) and the scalar reference find the same hits.
TEST(RtDisplacement, WavefrontAndScalarPathsAgree) {
    Scene s = loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/displaced_teapot.rib", {});
    s.camera.width = 200, s.camera.height = 150;
    for (bool lazy : {false, true}) {
        SCOPED_TRACE(lazy ? "lazy" : "up front");
        RtAccel acc;
        buildDisplacedAccel(s, acc, lazy);
        EXPECT_EQ(acc.displaced.lazy(), lazy);
        std::mt19937 rng(3);
        std::uniform_real_distribution<float> U(0.f, 1.f);
        std::vector<Ray> rays;
        const Bounds3 b = acc.bounds;
        for (int i = 0; i < 3000; ++i) {
            const Vec3 p{b.lo.x + U(rng) * (b.hi.x - b.lo.x), b.lo.y + U(rng) * (b.hi.y - b.lo.y),
                         b.lo.z + U(rng) * (b.hi.z - b.lo.z)};
            rays.push_back(Ray{{0, 0, 0}, normalize(p), 1e-3f, 1e30f});
        }
        for (bool shadow : {false, true}) {
            TraceOptions opt;
            opt.anyHit = shadow;
            std::vector<RayHit> batch;
            traceBatch(acc, rays, opt, batch);
            int disagree = 0, hits = 0;
            for (size_t i = 0; i < rays.size(); ++i) {
                RayHit h;
                const bool hit = traceRayScalar(acc, rays[i], opt, h);
                hits += hit;
                disagree += hit != batch[i].hit || (!shadow && hit && h.h.t != batch[i].h.t);
            }
            EXPECT_GT(hits, 500);
            EXPECT_EQ(disagree, 0) << (shadow ? "shadow" : "closest");
        }
    }
}

// Shadow rays see the displaced surface: from points between a plane and its offset, rays along the offset
// direction are blocked (they cross the displaced plane) and rays away from it are not; from points beyond
// the offset it is the other way round. The undisplaced plane would answer the opposite for the first set.
TEST(RtDisplacement, ShadowRaysAreBlockedByTheDisplacedPlane) {
    const float km = 0.3f;
    Loaded l = offsetScene(kPlane, km);
    RtAccel acc;
    buildDisplacedAccel(l.scene, acc);
    const Vec3 n = orientedPatchNormal(acc, 0, 0.5f, 0.5f);
    rt::RayList rays;
    std::vector<uint8_t> expectBlocked;
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> U(0.2f, 0.8f);
    for (int i = 0; i < 200; ++i) {
        const Vec3 base = evalPatch(acc.patches[0], U(rng), U(rng));
        for (float h : {0.5f * km, 1.5f * km})
            for (float dir : {1.f, -1.f}) {
                const Vec3 o = base + n * h;
                rays.push(o, n * dir, 0.f, 1e30f, 0, {1, 1, 1}, rt::kNone, rt::kShadow, 0);
                // Blocked when the ray heads towards the displaced plane (at height km).
                expectBlocked.push_back((h < km) == (dir > 0.f));
            }
    }
    rt::TraceService service(acc);
    std::vector<uint8_t> blocked;
    service.occluded(rays, blocked);
    int wrong = 0;
    for (size_t i = 0; i < blocked.size(); ++i) wrong += blocked[i] != expectBlocked[i];
    EXPECT_EQ(wrong, 0);
}

namespace {

RenderResult renderWith(const Scene& s, const std::string& engine) {
    RenderSettings rs;
    rs.engine = engine;
    rs.threads = 2;
    return render(s, rs);
}

}  // namespace

// Both engines render scenes/displaced_teapot.rib alike: coverage, and the colour with the teapot lit from
// the eye (no shadows: Reyes' shadow maps and the ray tracer's shadow rays differ at the bumps' own
// shadows, printed for information with the RIB's own lights).
TEST(RtDisplacement, DisplacedTeapotAgreesWithReyes) {
    Scene s = loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/displaced_teapot.rib", {});
    s.camera.width = 320, s.camera.height = 240;
    Scene orig = s;
    lightFromEye(s);
    const RenderResult reyes = renderWith(s, "reyes"), rt = renderWith(s, "rt");
    for (const std::string& w : rt.warnings) EXPECT_EQ(w.find("displace"), std::string::npos) << w;
    const ImageDiff d = compareImages(reyes.image, rt.image, 0.1f);
    const Image rtO = renderWith(orig, "rt").image;
    const ImageDiff dO = compareImages(renderWith(orig, "reyes").image, rtO, 0.1f);
    // Reyes with the ray tracer's shadow rays (--reyes-shadows raytrace) traces the same micro-grids.
    RenderSettings rs;
    rs.threads = 2;
    rs.reyesShadows = ReyesShadows::Raytrace;
    const RenderResult reyesRt = render(orig, rs);
    for (const std::string& w : reyesRt.warnings) EXPECT_EQ(w.find("displace"), std::string::npos) << w;
    const ImageDiff dR = compareImages(reyesRt.image, rtO, 0.1f);
    std::printf(
        "displaced teapot 320x240 16 spp, eye light: alpha differs on %.3f%% of pixels, PSNR %.2f dB\n",
        100 * d.alphaMismatch, d.psnrColor);
    std::printf("  original RIB lights (key light's shadows): alpha %.3f%%, PSNR %.2f dB\n",
                100 * dO.alphaMismatch, dO.psnrColor);
    std::printf("  original RIB lights, Reyes with ray-traced shadows: alpha %.3f%%, PSNR %.2f dB\n",
                100 * dR.alphaMismatch, dR.psnrColor);
    EXPECT_LT(d.alphaMismatch, 0.005);
    EXPECT_GE(d.psnrColor, 35.0);
    EXPECT_GE(dR.psnrColor, 35.0);
    EXPECT_LT(dO.alphaMismatch, 0.005);
    EXPECT_GT(rt.stats["displaced"]["triangles"].get<uint64_t>(), 10000u);
}

// No pinholes in the ray-traced displaced teapot (a constant offset, and a texture whose tiles jump across
// patch edges) and the displaced Big Guy (Catmull-Clark through OpenSubdiv): shared edges are diced on
// their own lattice and moved identically from both sides (reyes/displace.h), and the ray-triangle test is
// watertight. Neighbouring patches are diced at different rates already (each edge's lattice follows its
// own length on screen, DiagSplit); the offset teapot and Big Guy are also rendered with neighbours of
// different shading rates (0.5 and 3 alternating by patch).
TEST(RtDisplacement, DisplacedTeapotAndCatmullClarkHaveNoPinholes) {
    const std::string scenes = std::string(TESSERA_SOURCE_DIR) + "/scenes/";
    auto box = [](Scene& s, int w, int h) {
        s.camera.width = w, s.camera.height = h;
        s.image.filter = FilterType::Box;
        s.image.filterWidthX = s.image.filterWidthY = 1;
        s.image.pixelSamplesX = s.image.pixelSamplesY = 2;
    };
    const std::string teapotRib = writeRib(
        "Format 160 120 1\nProjection \"perspective\" \"fov\" 32\nTranslate 0 0 10\nRotate -115 1 0 0\n"
        "Rotate 19 0 0 1\nTranslate -0.625 0 -1.25\nWorldBegin\nOption \"searchpath\" \"texture\" \"" +
            scenes +
            "textures\"\nSurface \"constant\"\nDisplacement \"bumpy\" \"Km\" 0.08 \"texturename\" "
            "\"tiles.png\"\n"
            "Scale 0.025 0.025 0.025\nReadArchive \"" +
            scenes + "archives/teapot_geometry.rib\"\nWorldEnd\n",
        "rt_displaced_teapot.rib");
    Scene tiles = loadScene(teapotRib, {});
    box(tiles, 160, 120);
    Scene offset = tiles;
    offset.displacements[0] = DisplacementShader{DisplacementType::Offset, 0.04f, -1};
    Scene bigguy = loadScene(scenes + "bigguy.rib", {});
    box(bigguy, 160, 160);
    bigguy.displacements.push_back(DisplacementShader{DisplacementType::Offset, 0.15f, -1});
    for (PatchAttributes& a : bigguy.attributes) a.displacement = 0;
    struct Case {
        const char* name;
        Scene* scene;
    };
    for (const Case& c :
         {Case{"teapot offset", &offset}, Case{"teapot tiles", &tiles}, Case{"bigguy", &bigguy}})
        for (bool mixedRates : {false, true}) {
            // Neighbours with different ShadingRate measure their shared edge with the smaller
            // micropolygon side of the two (split.h, PieceEdge::side): where the texture jumps across the
            // edge (tiles) the vertices still meet (before: 3 pinholes here, 2 in Reyes).
            SCOPED_TRACE(std::string(c.name) + (mixedRates ? ", mixed rates" : ""));
            Scene s = *c.scene;
            if (mixedRates)
                for (size_t i = 0; i < s.attributes.size(); ++i)
                    s.attributes[i].shadingRate = i % 2 ? 3.f : 0.5f;
            const RenderResult r = renderWith(s, "rt");
            EXPECT_EQ(countPinholes(r.image, 1.f), 0);
            EXPECT_GT(alphaSum(r.image), 2000.0);
            EXPECT_GT(r.stats["displaced"]["patches"].get<uint64_t>(), 0u);
            if (mixedRates) {
                const RenderResult reyes = renderWith(s, "reyes");
                EXPECT_EQ(countPinholes(reyes.image, 1.f), 0) << "Reyes";
            }
        }
}

// Under a memory budget too small for all grids, they are built lazily (conservative subpatch boxes) and
// the least recently used dropped and built again: the image is the one of the grids built up front (the
// same triangles; only ties between triangles sharing an edge may resolve differently), the budget holds,
// and there are still no pinholes.
TEST(RtDisplacement, LazyGridsUnderABudgetRenderTheSameImage) {
    Scene s = loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/displaced_teapot.rib", {});
    s.camera.width = 200, s.camera.height = 150;
    s.image.filter = FilterType::Box;
    s.image.filterWidthX = s.image.filterWidthY = 1;
    s.image.pixelSamplesX = s.image.pixelSamplesY = 2;
    RenderSettings rs;
    rs.engine = "rt";
    rs.threads = 2;
    const RenderResult eager = render(s, rs);
    rs.displacementCacheMb = 1;
    const RenderResult lazy = render(s, rs);
    const nlohmann::json& d = lazy.stats["displaced"];
    EXPECT_FALSE(eager.stats["displaced"]["lazy"].get<bool>());
    EXPECT_TRUE(d["lazy"].get<bool>());
    EXPECT_GT(d["grids_dropped"].get<uint64_t>(), 0u);
    EXPECT_GT(d["grids_built"].get<uint64_t>(), d["patches"].get<uint64_t>());
    // The budget holds, but for the grid being built when it is passed (at most one grid over).
    EXPECT_LE(d["peak_resident_bytes"].get<uint64_t>(),
              (uint64_t(1) << 20) + d["bytes_all"].get<uint64_t>() / 8);
    const ImageDiff diff = compareImages(eager.image, lazy.image, 0.1f);
    std::printf("lazy (1 MiB, %llu builds, %llu dropped) vs up front: alpha %.4f%%, PSNR %.2f dB\n",
                (unsigned long long)d["grids_built"].get<uint64_t>(),
                (unsigned long long)d["grids_dropped"].get<uint64_t>(), 100 * diff.alphaMismatch,
                diff.psnrColor);
    EXPECT_EQ(diff.alphaMismatch, 0.0);
    EXPECT_GE(diff.psnrColor, 50.0);
    EXPECT_EQ(countPinholes(lazy.image, 1.f), 0);
}

// A displaced patch that moves is traced undisplaced (motion-blurred micro-grids are not built): the render
// says so; a static displaced patch in the same frame is still displaced.
TEST(RtDisplacement, MovingDisplacedPatchesAreWarnedAbout) {
    Loaded l = load(
        "Format 32 32 1\nShutter 0 1\nProjection \"perspective\" \"fov\" 40\nWorldBegin\n"
        "LightSource \"ambientlight\" 1\nTranslate 0 0 5\nDisplacement \"offset\" \"Km\" 0.1\n"
        "AttributeBegin\nMotionBegin [0 1]\nTranslate 0 0 0\nTranslate 0.5 0 0\nMotionEnd\n" +
        std::string(kPlane) + "\nAttributeEnd\nAttributeBegin\nTranslate 0 2.5 0\n" + kPlane +
        "\nAttributeEnd\nWorldEnd\n");
    RenderSettings rs;
    rs.engine = "rt";
    rs.threads = 2;
    const RenderResult r = render(l.scene, rs);
    bool said = false;
    for (const std::string& w : r.warnings) said = said || contains(w, "displaced surfaces that move");
    EXPECT_TRUE(said);
    EXPECT_EQ(r.stats["displaced"]["patches"].get<uint64_t>(), 1u);
}

}  // namespace tessera::test::rt_displacement_tests
