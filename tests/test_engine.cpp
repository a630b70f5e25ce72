// The render path both engines share: the bucket loop's cancellation and progress, and what an engine
// says about effects it does not render.
#include <gtest/gtest.h>

#include <atomic>
#include <mutex>
#include <vector>

#include "render/render.h"
#include "shading/registry.h"
#include "test_util.h"

namespace tessera::test::engine_tests {

namespace {
// Big enough for many buckets in both engines (the ray tracer's tiles are 64 pixels at 4 spp).
Scene sphereScene() {
    Scene s = cameraSpaceScene(320, 256, 40.f);
    for (const BezierPatch& p : octantSphere(1.f, {0, 0, 4})) addPatch(s, p);
    return s;
}
}  // namespace

TEST(TileLoop, NoBucketStartsAfterTheCancelFlagIsSeen) {
    // Cancellation at a known point of the work: one thread, the flag raised from the progress callback
    // after the third bucket; the loop must render exactly three buckets and report the cancel.
    const Scene scene = sphereScene();
    for (const char* engine : {"reyes", "rt"}) {
        std::atomic<bool> cancel{false};
        int calls = 0;
        RenderSettings rs;
        rs.engine = engine;
        rs.threads = 1;
        rs.bucketSize = 16;
        rs.cancel = &cancel;
        rs.progress = [&](uint64_t, uint64_t) {
            if (++calls == 3) cancel = true;
        };
        const RenderResult r = render(scene, rs);
        EXPECT_TRUE(r.cancelled) << engine;
        EXPECT_EQ(r.stats["buckets_rendered"].get<int>(), 3) << engine;
        EXPECT_GT(r.stats["buckets"].get<int>(), 3) << engine;
        EXPECT_EQ(calls, 3) << engine;
    }
}

TEST(TileLoop, ProgressGrowsToTheTotalWork) {
    const Scene scene = sphereScene();
    for (const char* engine : {"reyes", "rt"}) {
        std::mutex m;
        std::vector<std::pair<uint64_t, uint64_t>> seen;
        RenderSettings rs;
        rs.engine = engine;
        rs.threads = 2;
        rs.bucketSize = 16;
        rs.progress = [&](uint64_t done, uint64_t total) {
            std::lock_guard<std::mutex> lock(m);
            seen.push_back({done, total});
        };
        const RenderResult r = render(scene, rs);
        ASSERT_FALSE(r.cancelled);
        ASSERT_EQ(int(seen.size()), r.stats["buckets"].get<int>()) << engine;
        uint64_t maxDone = 0;
        for (const auto& [done, total] : seen) {
            EXPECT_EQ(total, seen[0].second);
            EXPECT_LE(done, total);
            maxDone = std::max(maxDone, done);
        }
        EXPECT_EQ(maxDone, seen[0].second) << engine;  // the last bucket finishes the work
    }
}

TEST(TileLoop, ProgressWeighsBucketsByTheirWork) {
    // A sphere in one corner of the frame: most buckets are empty. Work-weighted progress gives the
    // empty buckets a small share, so finishing the first (empty) half of the buckets is well under half
    // of the work: the time estimate no longer rises as the render reaches the sphere.
    Scene scene = cameraSpaceScene(128, 128, 40.f);
    for (const BezierPatch& p : octantSphere(0.4f, {0.8f, -0.8f, 4})) addPatch(scene, p);
    for (const char* engine : {"reyes", "rt"}) {
        std::vector<uint64_t> done;
        uint64_t total = 0;
        RenderSettings rs;
        rs.engine = engine;
        rs.threads = 1;
        rs.bucketSize = 16;
        rs.progress = [&](uint64_t d, uint64_t t) { done.push_back(d), total = t; };
        render(scene, rs);
        ASSERT_FALSE(done.empty());
        const double halfBuckets = double(done[done.size() / 2 - 1]) / double(total);
        EXPECT_LT(halfBuckets, 0.25) << engine << ": work share after half the buckets";
    }
}

TEST(Engines, ReyesSaysOnceThatReflectionsNeedTheRayTracer) {
    Scene scene = sphereScene();
    scene.materials = {defaultMaterial(MaterialType::Mirror), defaultMaterial(MaterialType::Glass)};
    scene.attributes[1].material = 1;
    RenderSettings rs;
    rs.threads = 2;
    const RenderResult reyes = render(scene, rs);
    ASSERT_EQ(reyes.warnings.size(), 1u);
    EXPECT_NE(reyes.warnings[0].find("--engine rt"), std::string::npos);
    rs.engine = "rt";
    EXPECT_TRUE(render(scene, rs).warnings.empty());
    // Reyes shades mirror and glass with their local terms (the highlight), not as black or as plastic
    // with the traced part ignored silently: the image is not empty.
    double sum = 0;
    for (float v : reyes.image.rgba) sum += v;
    EXPECT_GT(sum, 0.0);
}

TEST(Engines, AViewCameraReplacesTheScenesCamera) {
    // The entry takes a view: a pass with another camera (a shadow map's light, a second eye) renders what
    // a scene with that camera renders, bit for bit, in both engines.
    const Scene scene = sphereScene();
    Camera other = scene.camera;
    other.width = 160;
    other.height = 120;
    other.cameraFromWorld = Mat4::translate(0.4, -0.2, 1.0);
    Scene moved = scene;
    moved.camera = other;
    for (const char* engine : {"reyes", "rt"}) {
        RenderSettings rs;
        rs.engine = engine;
        rs.threads = 2;
        const RenderResult want = render(moved, rs);
        rs.view.camera = &other;
        const RenderResult got = render(scene, rs);
        ASSERT_EQ(got.image.width, 160);
        EXPECT_EQ(got.image.rgba, want.image.rgba) << engine;
        EXPECT_NE(got.image.rgba, render(scene, RenderSettings{}).image.rgba);
    }
}

}  // namespace tessera::test::engine_tests
