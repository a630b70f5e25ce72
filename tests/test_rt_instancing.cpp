// Instancing in the ray tracer (docs/rt.md, "Instancing"): the patches of RIB ObjectInstances that are
// affine copies of their object's first instance share its subpatch trees, the rays moved into its frame.
// The truth is the copy path (RenderSettings::instancing off: every instance builds its own trees) and
// Reyes, which dices every instance.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>

#include "film/image_compare.h"
#include "render/render.h"
#include "rib_test_util.h"
#include "rt/accel.h"
#include "rt/trace_service.h"
#include "rt/traversal.h"
#include "test_util.h"

namespace tessera::test::rt_instancing_tests {
namespace {

// Three teapots (one object, 32 patches): as defined; turned and scaled non-uniformly; tilted, mirrored
// (a negative scale turns the orientation) and squashed. Three instances of a bumpy bicubic patch, one under
// a B-spline basis (other control points: it keeps its own tree). A mirror that reflects the teapots, a
// floor that takes their shadows.
std::string instancedScene(int width, int height) {
    return "Format " + std::to_string(width) + " " + std::to_string(height) +
           " 1\nPixelSamples 2 2\nProjection \"perspective\" \"fov\" 40\n"
           "Translate 0 0 14\nRotate -120 1 0 0\nRotate 20 0 0 1\nWorldBegin\n"
           "LightSource \"ambientlight\" 1 \"intensity\" 0.2\nAttribute \"light\" \"shadows\" [\"on\"]\n"
           "LightSource \"distantlight\" 2 \"intensity\" 0.9 \"from\" [-1 -2 3] \"to\" [0 0 0]\n"
           "ObjectBegin \"pot\"\nScale 0.012 0.012 0.012\nReadArchive \"" TESSERA_SOURCE_DIR
           "/scenes/archives/teapot_geometry.rib\"\nObjectEnd\n"
           "ObjectBegin \"bump\"\nPatch \"bicubic\" \"P\" [0 0 0  1 0 0.4  2 0 -0.3  3 0 0   0 1 0.5  1 1 1  "
           "2 1 -0.5  3 1 0.2   0 2 -0.2  1 2 0.3  2 2 1.2  3 2 0   0 3 0  1 3 -0.4  2 3 0.3  3 3 0.1]\n"
           "ObjectEnd\nSurface \"plastic\"\n"
           "AttributeBegin\nTranslate -2.5 -1 0\nColor [0.8 0.3 0.2]\nObjectInstance \"pot\"\nAttributeEnd\n"
           "AttributeBegin\nTranslate 2 -1.5 0\nRotate 60 0 0 1\nScale 1.4 0.6 1.1\nColor [0.2 0.5 0.9]\n"
           "ObjectInstance \"pot\"\nAttributeEnd\n"
           "AttributeBegin\nTranslate 0 2 0.3\nRotate 35 1 1 0\nScale -1 1 0.8\nColor [0.3 0.8 0.3]\n"
           "ObjectInstance \"pot\"\nAttributeEnd\n"
           "AttributeBegin\nTranslate -4 3 0\nScale 0.7 0.7 0.7\nObjectInstance \"bump\"\nAttributeEnd\n"
           "AttributeBegin\nTranslate 3 2 0\nRotate 90 0 0 1\nScale 0.7 0.5 0.7\nObjectInstance \"bump\"\n"
           "AttributeEnd\n"
           "AttributeBegin\nBasis \"b-spline\" 1 \"b-spline\" 1\nTranslate -1 -5 0\nObjectInstance \"bump\"\n"
           "AttributeEnd\n"
           "AttributeBegin\nSurface \"mirror\"\nTranslate 0 -5.5 1.5\nRotate 80 1 0 0\n"
           "Patch \"bilinear\" \"P\" [-5 -2 0  5 -2 0  -5 2 0  5 2 0]\nAttributeEnd\n"
           "AttributeBegin\nColor [0.7 0.7 0.65]\n"
           "Patch \"bilinear\" \"P\" [-7 -7 -0.01  7 -7 -0.01  -7 7 -0.01  7 7 -0.01]\nAttributeEnd\n"
           "WorldEnd\n";
}

RenderResult renderRt(const Scene& s, bool instancing, int threads = 2, int depth = 6) {
    RenderSettings rs;
    rs.engine = "rt";
    rs.threads = threads;
    rs.subpatchDepth = depth;
    rs.instancing = instancing;
    return render(s, rs);
}

TEST(RtInstancing, SharedTreesRenderAsCopies) {
    // Camera rays, shadow rays and the mirror's reflection rays all reach the instances; even and odd
    // subpatch depths (the odd one ends with the pair step); the AVX2 and SSE2 traversal kernels.
    const Scene s = load(instancedScene(160, 120)).scene;
    for (int depth : {5, 6}) {
        for (bool avx2 : {true, false}) {
            SCOPED_TRACE("depth " + std::to_string(depth) + (avx2 ? " avx2" : " sse2"));
            rtUseAvx2(avx2);
            const RenderResult shared = renderRt(s, true, 2, depth), copies = renderRt(s, false, 2, depth);
            rtUseAvx2(true);
            // 2 x 32 teapot patches and one bump patch use their prototype's trees; the B-spline bump does
            // not (its control points are not the prototype's moved).
            EXPECT_EQ(shared.stats["instancing"]["shared_patches"].get<size_t>(), 65u);
            EXPECT_EQ(shared.stats["instancing"]["instances"].get<size_t>(), 3u);
            EXPECT_EQ(copies.stats["instancing"]["shared_patches"].get<size_t>(), 0u);
            EXPECT_EQ(shared.stats["subpatch_trees"].get<size_t>() + 65u,
                      copies.stats["subpatch_trees"].get<size_t>());
            EXPECT_GT(shared.stats["rays"]["reflection"].get<uint64_t>(), 0u);
            EXPECT_GT(shared.stats["rays"]["shadow"].get<uint64_t>(), 0u);
            const ImageDiff d = compareImages(shared.image, copies.image, 0.1f);
            std::printf("instanced vs copies (%s): PSNR %.1f dB, alpha differs on %.4f%%, max %.2g\n",
                        avx2 ? "avx2" : "sse2", d.psnrColor, 100 * d.alphaMismatch, d.maxAbsColor);
            EXPECT_EQ(d.alphaMismatch, 0.0);
            EXPECT_LT(d.meanAbsAlpha, 1e-5);
            // The prototype's boxes moved are not the instance's own boxes, so a few Newton starts differ
            // (a folded patch's other root now and then: docs/rt.md, Newton starts only at leaf centres).
            EXPECT_GT(d.psnrColor, 60.0);
        }
    }
}

TEST(RtInstancing, RaysHitInstancesAsTheirCopies) {
    // Rays aimed at points of every surface from all around, through the scalar reference path and the
    // wavefront path: the instanced accel finds the copy accel's hits (same patch, same distance to the
    // Newton tolerance), the non-uniformly scaled and mirrored teapots included.
    const Scene s = load(instancedScene(64, 48)).scene;
    RtAccel shared, copies;
    const Mat4 toSpace = s.camera.cameraFromWorld;
    buildRtAccel(s, toSpace, 6, false, shared, nullptr, kDefaultTimeSlabs, nullptr, true);
    buildRtAccel(s, toSpace, 6, false, copies, nullptr, kDefaultTimeSlabs, nullptr, false);
    ASSERT_TRUE(shared.instanced());
    ASSERT_FALSE(copies.instanced());
    EXPECT_EQ(shared.sharedPatches, 65u);
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> uni(0.f, 1.f);
    std::vector<Ray> rays;
    const float size = maxComponent(copies.bounds.diagonal());
    for (uint32_t p = 0; p < copies.patches.size(); ++p)
        for (int k = 0; k < 24; ++k) {
            const Vec3 target = evalPatch(copies.patches[p], uni(rng), uni(rng));
            Vec3 dir{uni(rng) - 0.5f, uni(rng) - 0.5f, uni(rng) - 0.5f};
            if (dot(dir, dir) < 1e-4f) dir = {0, 0, 1};
            Ray r;
            r.o = target - normalize(dir) * (0.7f * size);
            r.d = dir * (0.5f + 2.f * uni(rng));  // not unit length: t in units of d
            rays.push_back(r);
        }
    TraceOptions opt;
    std::vector<RayHit> batchShared, batchCopies;
    traceBatch(shared, rays, opt, batchShared);
    traceBatch(copies, rays, opt, batchCopies);
    int hits = 0, disagree = 0, onShared = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
        RayHit a, b;
        traceRayScalar(shared, rays[i], opt, a);
        traceRayScalar(copies, rays[i], opt, b);
        for (const auto& [x, y] : {std::pair{a, b}, std::pair{batchShared[i], batchCopies[i]}}) {
            hits += y.hit;
            const float tol = 1e-4f * size / std::sqrt(dot(rays[i].d, rays[i].d));
            const bool same =
                x.hit == y.hit && (!x.hit || (x.patch == y.patch && std::fabs(x.h.t - y.h.t) < tol));
            disagree += !same;

            onShared += x.hit && shared.placement(x.patch) != nullptr;
        }
    }
    std::printf("%zu rays x 2 paths: %d hits (%d on shared patches), %d disagree\n", rays.size(), hits,
                onShared, disagree);
    EXPECT_GT(onShared, 1000);
    EXPECT_LE(disagree, hits / 1000);  // grazing rays along a silhouette at most
}

TEST(RtInstancing, EightTeapotsShareOneTreeSetPerObject) {
    // scenes/instanced_teapots.rib: two objects (the same teapot under two handles), four instances each.
    Scene s = loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/instanced_teapots.rib",
                        [](const std::string&) {});
    ASSERT_EQ(s.instances.size(), 8u);
    s.camera.width = 200;
    s.camera.height = 150;
    const RenderResult shared = renderRt(s, true), copies = renderRt(s, false);
    EXPECT_EQ(shared.stats["instancing"]["shared_patches"].get<size_t>(), 6u * 32u);
    const double bytesShared = shared.stats["memory"]["subpatch_bytes"].get<double>();
    const double bytesCopies = copies.stats["memory"]["subpatch_bytes"].get<double>();
    // 64 teapot trees + 21 others against 256 + 21; the leaf tables shared by all patches stay.
    std::printf("subpatch bytes: %.0f shared, %.0f copies (%.3f)\n", bytesShared, bytesCopies,
                bytesShared / bytesCopies);
    EXPECT_EQ(shared.stats["subpatch_trees"].get<size_t>(), 85u);
    EXPECT_EQ(copies.stats["subpatch_trees"].get<size_t>(), 277u);
    // Per tree the same bytes (quads and root box), beside the leaf tables of the depth-6 forest (64 leaves:
    // a centre and five bases each).
    const double tables = 64.0 * (sizeof(Vec2) + 5 * sizeof(LeafBasis));
    EXPECT_DOUBLE_EQ((bytesShared - tables) / 85.0, (bytesCopies - tables) / 277.0);
    EXPECT_LT(bytesShared - tables, 0.35 * (bytesCopies - tables));  // 85 / 277 trees
    const ImageDiff d = compareImages(shared.image, copies.image, 0.1f);
    EXPECT_EQ(d.alphaMismatch, 0.0);
    EXPECT_GT(d.psnrColor, 70.0);
}

TEST(RtInstancing, AgreesWithReyes) {
    // The eight teapots lit from the eye (no shadows: those are Reyes' maps against the ray tracer's rays,
    // tests/test_shadows.cpp): coverage and shading of every instance as Reyes dices it.
    Scene s = loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/instanced_teapots.rib",
                        [](const std::string&) {});
    s.camera.width = 200;
    s.camera.height = 150;
    lightFromEye(s);
    RenderSettings rs;
    rs.threads = 2;
    rs.engine = "reyes";
    const RenderResult reyes = render(s, rs);
    const RenderResult rt = renderRt(s, true);
    EXPECT_GT(rt.stats["instancing"]["shared_patches"].get<size_t>(), 0u);
    const ImageDiff d = compareImages(reyes.image, rt.image, 0.1f);
    std::printf("instanced teapots, Reyes vs rt: alpha differs on %.3f%%, PSNR %.2f dB\n",
                100 * d.alphaMismatch, d.psnrColor);
    EXPECT_LT(d.alphaMismatch, 0.005);
    EXPECT_GE(d.psnrColor, 35.0);
}

TEST(RtInstancing, SameImageForAnyThreadCount) {
    const Scene s = load(instancedScene(120, 90)).scene;
    const RenderResult one = renderRt(s, true, 1), two = renderRt(s, true, 2), four = renderRt(s, true, 4);
    EXPECT_GT(one.stats["instancing"]["shared_patches"].get<size_t>(), 0u);
    EXPECT_TRUE(one.image.rgba == two.image.rgba);
    EXPECT_TRUE(one.image.rgba == four.image.rgba);
}

TEST(RtInstancing, NotWithBackfaceCullingOrMotion) {
    // Back-facing marks depend on where the eye is in the prototype's frame, and moving patches have their
    // own swept boxes: both keep every instance's own trees.
    Scene s = load(instancedScene(64, 48)).scene;
    RenderSettings rs;
    rs.engine = "rt";
    rs.threads = 2;
    rs.cullBackfaces = true;
    EXPECT_EQ(render(s, rs).stats["instancing"]["shared_patches"].get<size_t>(), 0u);
    const Scene moving =
        load(
            "Format 64 48 1\nShutter 0 1\nProjection \"perspective\" \"fov\" 40\nTranslate 0 0 8\n"
            "WorldBegin\nLightSource \"ambientlight\" 1\nObjectBegin 1\n"
            "Patch \"bilinear\" \"P\" [0 0 0 1 0 0 0 1 0 1 1 0.5]\nObjectEnd\n"
            "ObjectInstance 1\nAttributeBegin\nMotionBegin [0 1]\nTranslate 0 0 0\nTranslate 1 0 "
            "0\nMotionEnd\n"
            "ObjectInstance 1\nAttributeEnd\nAttributeBegin\nTranslate -2 0 0\nObjectInstance 1\n"
            "AttributeEnd\nWorldEnd\n")
            .scene;
    // The moving instance is not recorded; the static ones are, and share while nothing moves in the
    // frame. Here something moves, so nothing is shared.
    ASSERT_EQ(moving.instances.size(), 2u);
    rs.cullBackfaces = false;
    EXPECT_EQ(render(moving, rs).stats["instancing"]["shared_patches"].get<size_t>(), 0u);
}

}  // namespace
}  // namespace tessera::test::rt_instancing_tests
