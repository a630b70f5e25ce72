// Scene input for motion blur and depth of field (docs/motion.md, "Scene input"): Shutter, DepthOfField,
// MotionBegin/MotionEnd around transformations (object and camera) and primitives (deformation), the
// Hider and GeometricApproximation options, their errors, the RIB writer's round trip and the CLI flags.
// Positions are checked against analytic values.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "io/image_io.h"
#include "io/rib_reader.h"
#include "io/rib_writer.h"
#include "io/scene_loader.h"
#include "rib_test_util.h"
#include "test_support.h"

namespace tessera::test::motion_input_tests {

namespace fs = std::filesystem;

namespace {

constexpr double kPi = 3.14159265358979323846;

const char* kSquare = "Patch \"bilinear\" \"P\" [0 0 0  1 0 0  0 1 0  1 1 0]\n";

// Line 1 options, line 2 WorldBegin, line 3 a light, then `body` from line 4 on.
std::string world(const std::string& options, const std::string& body) {
    return options + "\nWorldBegin\nLightSource \"ambientlight\" 1\n" + body + "WorldEnd\n";
}

}  // namespace

TEST(MotionInput, ShutterAndDepthOfFieldReachTheCamera) {
    Loaded l = load(world("Shutter 0.25 0.75 DepthOfField 2.8 0.05 4", kSquare));
    EXPECT_FLOAT_EQ(l.scene.camera.shutterOpen, 0.25f);
    EXPECT_FLOAT_EQ(l.scene.camera.shutterClose, 0.75f);
    EXPECT_FLOAT_EQ(l.scene.camera.fStop, 2.8f);
    EXPECT_FLOAT_EQ(l.scene.camera.focalLength, 0.05f);
    EXPECT_FLOAT_EQ(l.scene.camera.focalDistance, 4.f);
    EXPECT_NEAR(l.scene.camera.lensRadius(), 0.05 / 5.6, 1e-7);
    // No arguments: a pinhole again.
    Loaded p = load(world("DepthOfField 2.8 0.05 4\nDepthOfField", kSquare));
    EXPECT_TRUE(std::isinf(p.scene.camera.fStop));
    EXPECT_EQ(p.scene.camera.lensRadius(), 0.f);
    EXPECT_FALSE(p.scene.hasMotion());
}

TEST(MotionInput, TranslateBlockMovesLinearly) {
    Loaded l = load(world("Shutter 0 1", "MotionBegin [0 1]\nTranslate 0 0 0\nTranslate 2 0 0\nMotionEnd\n" +
                                             std::string(kSquare)));
    const Scene& s = l.scene;
    ASSERT_EQ(s.patches.size(), 1u);
    EXPECT_TRUE(s.attributes[0].motion.moving());
    EXPECT_EQ(s.attributes[0].motion.count, 2u);  // a translation needs no extra keys
    EXPECT_TRUE(s.hasMotion());
    for (float t : {0.f, 0.25f, 0.5f, 1.f}) {
        const BezierPatch p = patchAtTime(s, 0, t);
        expectVec(p.cp[0], {2 * t, 0, 0});
        expectVec(p.cp[15], {1 + 2 * t, 1, 0});
    }
    expectVec(s.patches[0].cp[0], {0, 0, 0});  // shutter open
}

// A Rotate block followed by a static Translate: the object swings on the arc of radius r, at the angle
// that grows linearly with time (not on the chord between the keys' positions).
TEST(MotionInput, RotateBlockStaysOnTheCircle) {
    const float r = 3.f;
    Loaded l = load(world("Shutter 0 1",
                          "MotionBegin [0 1]\nRotate 0 0 0 1\nRotate 90 0 0 1\nMotionEnd\n"
                          "Translate 3 0 0\n"
                          "Patch \"bilinear\" \"P\" [0 0 0  0 0 0  0 0 0  0 0 0]\n"));
    const Scene& s = l.scene;
    ASSERT_TRUE(s.attributes[0].motion.moving());
    EXPECT_EQ(s.attributes[0].motion.count, 46u);  // 90 degrees in 2-degree segments
    for (float t : {0.f, 0.1f, 0.33f, 0.5f, 0.77f, 1.f}) {
        const Vec3 p = patchAtTime(s, 0, t).cp[0];
        EXPECT_NEAR(std::hypot(p.x, p.y), r, 2e-4 * r) << "t " << t;
        EXPECT_NEAR(std::atan2(p.y, p.x), t * kPi / 2, 1e-3) << "t " << t;
        EXPECT_NEAR(p.z, 0, 1e-6);
    }
    // The same with the rotation applied to an object placed off the axis.
    Loaded m = load(world("Shutter 0 1",
                          "MotionBegin [0 1]\nRotate 0 0 0 1\nRotate 90 0 0 1\nMotionEnd\n"
                          "Patch \"bilinear\" \"P\" [3 0 0  3 0 0  3 0 0  3 0 0]\n"));
    const Vec3 mid = patchAtTime(m.scene, 0, 0.5f).cp[0];
    EXPECT_NEAR(std::hypot(mid.x, mid.y), r, 2e-4 * r);
    EXPECT_NEAR(std::atan2(mid.y, mid.x), kPi / 4, 1e-4);
}

// Rotate keys about one axis interpolate their angle: a full turn between two keys is a full turn (the
// matrices of Rotate 0 and Rotate 360 are equal), and 270 degrees do not become -90.
TEST(MotionInput, RotateKeysTurnByTheirAngle) {
    for (double total : {360.0, 270.0}) {
        Loaded l =
            load(world("Shutter 0 1", "MotionBegin [0 1]\nRotate 0 0 0 1\nRotate " + std::to_string(total) +
                                          " 0 0 1\nMotionEnd\n"
                                          "Patch \"bilinear\" \"P\" [2 0 0  2 0 0  2 0 0  2 0 0]\n"));
        const Scene& s = l.scene;
        ASSERT_TRUE(s.attributes[0].motion.moving()) << total;
        EXPECT_EQ(s.attributes[0].motion.count, uint32_t(total / 2 + 1));
        for (float t : {0.1f, 0.25f, 0.5f, 0.8f}) {
            const Vec3 p = patchAtTime(s, 0, t).cp[0];
            const double expected = t * total * kPi / 180;
            EXPECT_NEAR(std::hypot(p.x, p.y), 2, 4e-4) << total << " t " << t;
            EXPECT_NEAR(std::cos(expected), p.x / 2, 1e-3) << total << " t " << t;
            EXPECT_NEAR(std::sin(expected), p.y / 2, 1e-3) << total << " t " << t;
        }
    }
}

// Two moving factors with different times: evaluated at the union of times, each on its own keys.
TEST(MotionInput, TwoMotionBlocksWithDifferentTimes) {
    Loaded l = load(world("Shutter 0 1",
                          "MotionBegin [0 1]\nTranslate 0 0 0\nTranslate 0 0 4\nMotionEnd\n"
                          "MotionBegin [0.5 1]\nTranslate 0 0 0\nTranslate 2 0 0\nMotionEnd\n" +
                              std::string(kSquare)));
    const Scene& s = l.scene;
    ASSERT_EQ(s.attributes[0].motion.count, 3u);  // times 0, 0.5, 1
    expectVec(patchAtTime(s, 0, 0.25f).cp[0], {0, 0, 1});
    expectVec(patchAtTime(s, 0, 0.5f).cp[0], {0, 0, 2});
    expectVec(patchAtTime(s, 0, 0.75f).cp[0], {1, 0, 3});
}

TEST(MotionInput, IdenticalKeysAreStatic) {
    Loaded l = load(world("Shutter 0 1",
                          "MotionBegin [0 1]\nTranslate 1 0 0\nTranslate 1 0 0\nMotionEnd\n"
                          "MotionBegin [0 1]\n" +
                              std::string(kSquare) + kSquare + "MotionEnd\n"));
    EXPECT_FALSE(l.scene.attributes[0].motion.moving());
    EXPECT_TRUE(l.scene.motionPatches.empty());
    EXPECT_FALSE(l.scene.hasMotion());
    expectVec(l.scene.patches[0].cp[0], {1, 0, 0});
}

TEST(MotionInput, DeformationKeysAndShutterOpenPosition) {
    const std::string body = "MotionBegin [0.5 1]\n" + std::string(kSquare) +
                             "Patch \"bilinear\" \"P\" [0 0 2  1 0 2  0 1 2  1 1 4]\nMotionEnd\n";
    Loaded l = load(world("Shutter 0.5 1", body));
    const Scene& s = l.scene;
    ASSERT_EQ(s.patches.size(), 1u);
    ASSERT_EQ(s.attributes[0].motion.count, 2u);
    EXPECT_EQ(s.objectCount, 1u);  // one object per motion block
    expectVec(s.patches[0].cp[15], {1, 1, 0});
    expectVec(patchAtTime(s, 0, 0.75f).cp[15], {1, 1, 2});
    expectVec(patchAtTime(s, 0, 0.75f).cp[0], {0, 0, 1});
    // With the shutter closed (RI default 0 0) any times are accepted; the scene is at time 0, clamped to
    // the keys, and nothing blurs.
    Loaded c = load(world("", "MotionBegin [-1 1]\n" + std::string(kSquare) +
                                  "Patch \"bilinear\" \"P\" [0 0 2  1 0 2  0 1 2  1 1 4]\nMotionEnd\n"));
    expectVec(c.scene.patches[0].cp[15], {1, 1, 2});
    EXPECT_FALSE(c.scene.hasMotion());
    // A deforming NuPatch under a moving transformation: both kinds of keys, times at their union.
    const char* nu0 = "NuPatch 2 2 [0 0 1 1] 0 1 2 2 [0 0 1 1] 0 1 \"P\" [0 0 0 1 0 0 0 1 0 1 1 0]\n";
    const char* nu1 = "NuPatch 2 2 [0 0 1 1] 0 1 2 2 [0 0 1 1] 0 1 \"P\" [0 0 1 1 0 1 0 1 1 1 1 1]\n";
    Loaded n = load(world("Shutter 0 1",
                          "MotionBegin [0 0.5]\nTranslate 0 0 0\nTranslate 4 0 0\nMotionEnd\n"
                          "MotionBegin [0 1]\n" +
                              std::string(nu0) + nu1 + "MotionEnd\n"));
    ASSERT_EQ(n.scene.attributes[0].motion.count, 3u);
    expectVec(patchAtTime(n.scene, 0, 0.25f).cp[0], {2, 0, 0.25f});
    expectVec(patchAtTime(n.scene, 0, 0.75f).cp[0], {4, 0, 0.75f});
}

TEST(MotionInput, CameraMotionIsRefinedAndStartsAtShutterOpen) {
    // Camera translation: two keys; cameraFromWorld is the camera at shutter open.
    Loaded t =
        load(world("Shutter 0.2 1 MotionBegin [0.2 1] Translate 0 0 5 Translate 1 0 5 MotionEnd", kSquare));
    const Camera& c = t.scene.camera;
    ASSERT_EQ(c.motion.size(), 2u);
    EXPECT_TRUE(c.moving());
    expectVec(c.cameraFromWorld.point({0, 0, 0}), {0, 0, 5});
    expectVec(c.cameraFromWorldAt(0.6).point({0, 0, 0}), {0.5f, 0, 5});
    // A 30-degree turn: keys every 2 degrees.
    Loaded r = load(world(
        "Shutter 0 1 Translate 0 0 5 MotionBegin [0 1] Rotate 0 0 1 0 Rotate 30 0 1 0 MotionEnd", kSquare));
    ASSERT_EQ(r.scene.camera.motion.size(), 16u);
    const Vec3 p = r.scene.camera.cameraFromWorldAt(0.5).point({1, 0, 0});
    EXPECT_NEAR(p.x, std::cos(15 * kPi / 180), 1e-4);
    EXPECT_NEAR(p.z, 5 - std::sin(15 * kPi / 180), 1e-4);
    // The patches do not move: only the camera.
    EXPECT_FALSE(r.scene.attributes[0].motion.moving());
    EXPECT_TRUE(r.scene.hasMotion());
}

TEST(MotionInput, OptionsForBlurAndApproximation) {
    Loaded l =
        load(world("Hider \"hidden\" \"string blursampling\" \"interleaved\" \"int blurtilesize\" 8 "
                   "\"int blurpermutations\" [16] \"jitter\" [0] \"depthfilter\" \"min\"",
                   "GeometricApproximation \"motionfactor\" 1.5\nGeometricApproximation \"focusfactor\" 2\n"
                   "GeometricApproximation \"flatness\" 0.5\n" +
                       std::string(kSquare)));
    EXPECT_EQ(l.scene.image.blurSampling, "interleaved");
    EXPECT_EQ(l.scene.image.blurTileSize, 8);
    EXPECT_EQ(l.scene.image.blurPermutations, 16);
    EXPECT_FLOAT_EQ(l.scene.attributes[0].motionFactor, 1.5f);
    EXPECT_FLOAT_EQ(l.scene.attributes[0].focusFactor, 2.f);
    EXPECT_FALSE(l.scene.image.jitter);  // Hider "jitter" [0]: strata centres (film/sampler.h)
    int flatness = 0, depthfilter = 0;
    for (const std::string& w : l.warnings) {
        flatness += contains(w, "\"flatness\" is not supported");
        depthfilter += contains(w, "depthfilter");
    }
    EXPECT_EQ(flatness, 1);
    EXPECT_EQ(depthfilter, 1);
}

TEST(MotionInput, MovingLightsArePlacedAtShutterOpenWithAWarning) {
    Loaded l = load(world("Shutter 0 1",
                          "MotionBegin [0 1] Translate 1 0 0 Translate 3 0 0 MotionEnd\n"
                          "LightSource \"pointlight\" 2 \"from\" [0 0 0]\n" +
                              std::string(kSquare)));
    ASSERT_EQ(l.scene.lights.size(), 2u);
    expectVec(l.scene.lights[1].from, {1, 0, 0});
    int n = 0;
    for (const std::string& w : l.warnings) n += contains(w, "lights do not move");
    EXPECT_EQ(n, 1);
}

TEST(MotionInput, MotionShadingUsesTheFirstKey) {
    Loaded l =
        load(world("", "MotionBegin [0 1] Color [1 0 0] Color [0 1 0] MotionEnd\n" + std::string(kSquare)));
    EXPECT_EQ(l.scene.materials[l.scene.attributes[0].material].Cs, (Color{1, 0, 0}));
}

TEST(MotionInput, Errors) {
    const std::string sq = kSquare;
    EXPECT_TRUE(contains(expectError(world("Shutter 1 0", sq), 1), "close (0) is before open (1)"));
    EXPECT_TRUE(contains(expectError(world("", "Shutter 0 1\n" + sq), 4), "before WorldBegin"));
    EXPECT_TRUE(contains(expectError(world("DepthOfField 0 1 2", sq), 1), "must be positive"));
    EXPECT_TRUE(contains(expectError(world("DepthOfField 2 1", sq), 1), "DepthOfField"));
    EXPECT_TRUE(contains(expectError(world("Hider \"hidden\" \"string blursampling\" \"fast\"", sq), 1),
                         "\"blursampling\" must be"));
    EXPECT_TRUE(
        contains(expectError(world("Hider \"hidden\" \"int blurtilesize\" 17", sq), 1), "from 2 to 16"));
    EXPECT_TRUE(
        contains(expectError(world("Hider \"hidden\" \"int blurpermutations\" 0", sq), 1), "from 1 to 4096"));
    EXPECT_TRUE(
        contains(expectError(world("", "GeometricApproximation \"motionfactor\" -1\n" + sq), 4), ">= 0"));
    EXPECT_TRUE(
        contains(expectError(world("Shutter 0 1", "MotionBegin [0]\nTranslate 1 0 0\nMotionEnd\n" + sq), 4),
                 "at least 2 times"));
    EXPECT_TRUE(
        contains(expectError(world("Shutter 0 1", "MotionBegin [0.5 0.5]\n" + sq), 4), "must increase"));
    EXPECT_TRUE(
        contains(expectError(world("Shutter 0 1", "MotionBegin [0 1]\nTranslate 1 0 0\nMotionEnd\n" + sq), 6),
                 "has 2 times but 1 requests"));
    EXPECT_TRUE(contains(
        expectError(
            world("Shutter 0 1", "MotionBegin [0 1]\nScale 1 1 1\nScale 2 2 2\nScale 3 3 3\nMotionEnd\n"), 7),
        "more Scale requests than the 2 times"));
    EXPECT_TRUE(
        contains(expectError(world("Shutter 0 1", "MotionBegin [0 1]\nTranslate 1 0 0\nRotate 9 0 0 1\n"), 6),
                 "mixes Translate (line 5) and Rotate"));
    EXPECT_TRUE(contains(expectError(world("Shutter 0 1", "MotionBegin [0 1]\nAttributeBegin\n"), 5),
                         "AttributeBegin is not allowed inside a motion block"));
    EXPECT_TRUE(contains(expectError(world("Shutter 0 1", "MotionBegin [0 1]\nIdentity\n"), 5),
                         "Identity is not allowed"));
    EXPECT_TRUE(contains(expectError(world("Shutter 0 1", "MotionBegin [0 1]\nMotionBegin [0 1]\n"), 5),
                         "nested MotionBegin"));
    EXPECT_TRUE(
        contains(expectError(world("", "MotionEnd\n" + sq), 4), "MotionEnd without a matching MotionBegin"));
    EXPECT_TRUE(contains(expectError("WorldBegin\nMotionBegin [0 1]\nTranslate 1 0 0\n", 3),
                         "end of file inside the motion block opened at"));
    EXPECT_TRUE(contains(expectError(world("Shutter 0 1", "MotionBegin [0 2]\n"), 4),
                         "time 2 is outside the shutter interval [0, 1]"));
    // Camera motion before Shutter: checked at WorldBegin, reported at its MotionBegin.
    EXPECT_TRUE(
        contains(expectError("MotionBegin [0 2]\nTranslate 0 0 1\nTranslate 0 0 2\nMotionEnd\nShutter 0 1\n"
                             "WorldBegin\n" +
                                 sq + "WorldEnd\n",
                             1),
                 "outside the shutter interval"));
    std::string bicubic = "Patch \"bicubic\" \"P\" [";
    for (int i = 0; i < 48; ++i) bicubic += " 0";
    bicubic += "]\n";
    EXPECT_TRUE(contains(expectError(world("Shutter 0 1", "MotionBegin [0 1]\n" + sq + bicubic), 6),
                         "same topology"));
    const char* mesh2 =
        "PatchMesh \"bilinear\" 2 \"nonperiodic\" 2 \"nonperiodic\" \"P\" [0 0 0 1 0 0 0 1 0 1 1 0]\n";
    const char* mesh3 =
        "PatchMesh \"bilinear\" 3 \"nonperiodic\" 2 \"nonperiodic\" \"P\" [0 0 0 1 0 0 2 0 0 0 1 0 1 1 0 2 1 "
        "0]\n";
    EXPECT_TRUE(
        contains(expectError(world("Shutter 0 1", "MotionBegin [0 1]\n" + std::string(mesh2) + mesh3), 6),
                 "key 2 is PatchMesh \"bilinear\" 3"));
    EXPECT_TRUE(contains(expectError(world("Shutter 0 1", "MotionBegin [0 1]\n" + sq), 6),
                         "WorldEnd is not allowed"));
}

// Limits (docs/errors.md): a few bytes must not ask for millions of keys.
TEST(MotionInput, KeyCountsAreLimited) {
    std::ostringstream times, rotates;
    times << "[";
    for (int k = 0; k <= 12; ++k) {
        times << " " << k;
        rotates << "Rotate " << 179 * k << " 0 0 1\n";
    }
    times << " ]";
    // 12 segments of 179 degrees: 12 x 90 = 1080 sample times, more than 1025.
    EXPECT_TRUE(contains(expectError(world("Shutter 0 12", "MotionBegin " + times.str() + "\n" +
                                                               rotates.str() + "MotionEnd\n" + kSquare),
                                     4 + 15),
                         "more than 1025 keys"));
    std::ostringstream many;
    many << "MotionBegin [";
    for (int k = 0; k < 2000; ++k) many << " " << k;
    many << "]\n";
    EXPECT_TRUE(contains(expectError(world("", many.str()), 4), "more than 1025 times"));
    // A closed shutter says that nothing will blur.
    Loaded l = load(
        world("", "MotionBegin [0 1] Translate 0 0 0 Translate 1 0 0 MotionEnd\n" + std::string(kSquare)));
    int n = 0;
    for (const std::string& w : l.warnings) n += contains(w, "closed shutter");
    EXPECT_EQ(n, 1);
}

TEST(MotionInput, RibWriterRoundTripsMotion) {
    Loaded l =
        load(world("Shutter 0 1 DepthOfField 4 0.5 6 Hider \"hidden\" \"string blursampling\" \"simple\" "
                   "Translate 0 0 5 MotionBegin [0 1] Rotate 0 0 1 0 Rotate 10 0 1 0 MotionEnd",
                   "GeometricApproximation \"motionfactor\" 1\n"
                   "MotionBegin [0 1]\nRotate 0 0 0 1\nRotate 20 0 0 1\nMotionEnd\n" +
                       std::string(kSquare) + "Translate 3 0 0\n" + kSquare));
    std::stringstream out;
    tessera::writeRib(l.scene, out);
    Scene back;
    readRibText(out.str(), "roundtrip.rib", back, nullptr);
    const Scene& a = l.scene;
    EXPECT_EQ(back.camera.shutterOpen, a.camera.shutterOpen);
    EXPECT_EQ(back.camera.shutterClose, a.camera.shutterClose);
    EXPECT_EQ(back.camera.fStop, a.camera.fStop);
    EXPECT_EQ(back.camera.focalDistance, a.camera.focalDistance);
    EXPECT_EQ(back.image.blurSampling, "simple");
    ASSERT_EQ(back.camera.motion.size(), a.camera.motion.size());
    for (size_t k = 0; k < a.camera.motion.size(); ++k)
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j)
                EXPECT_NEAR(back.camera.motion[k].matrix.m[i][j], a.camera.motion[k].matrix.m[i][j], 1e-6);
    ASSERT_EQ(back.patches.size(), a.patches.size());
    ASSERT_EQ(back.motionPatches.size(), a.motionPatches.size());
    for (size_t i = 0; i < a.patches.size(); ++i) {
        EXPECT_EQ(back.attributes[i].motion.count, a.attributes[i].motion.count);
        EXPECT_EQ(back.attributes[i].motionFactor, 1.f);
        for (float t : {0.f, 0.3f, 1.f})
            for (int c = 0; c < 16; ++c)
                expectVec(patchAtTime(back, i, t).cp[c], patchAtTime(a, i, t).cp[c], 1e-6f);
    }
}

// ---- the command line ------------------------------------------------------------------------------

namespace {

struct CommandResult {
    int exitCode;
    std::string output;
};

CommandResult runTessera(const std::string& args) {
    const fs::path log = tessera::test::testScratchDir() / "cli.log";
    const std::string cmd = std::string(TESSERA_BINARY) + " " + args + " > '" + log.string() + "' 2>&1";
    const int status = std::system(cmd.c_str());
    std::ifstream f(log);
    std::stringstream ss;
    ss << f.rdbuf();
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, ss.str()};
}

// An orthographic view of x in [-2, 2], y in [-1.5, 1.5] on 80 x 60 pixels; a 0.5 x 0.5 square centred on
// (-1.25, 0) at time 0 moving +2 in x over the shutter 0 1.
const char* kMovingSquare = R"(Format 80 60 1
PixelSamples 2 2
Shutter 0 1
Projection "orthographic"
ScreenWindow -2 2 -1.5 1.5
Translate 0 0 5
WorldBegin
LightSource "ambientlight" 1
Surface "constant"
MotionBegin [0 1]
Translate 0 0 0
Translate 2 0 0
MotionEnd
Patch "bilinear" "P" [-1.5 -0.25 0  -1 -0.25 0  -1.5 0.25 0  -1 0.25 0]
WorldEnd
)";

// Alpha centroid of a rendered PNG.
Vec2 alphaCentroid(const std::string& png) {
    Image img = readPng(png);
    double sx = 0, sy = 0, sa = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            const double a = img.pixel(x, y)[3];
            sx += a * (x + 0.5), sy += a * (y + 0.5), sa += a;
        }
    return sa > 0 ? Vec2{float(sx / sa), float(sy / sa)} : Vec2{-1, -1};
}

}  // namespace

TEST(MotionCli, NoBlurRendersTheShutterOpenPosition) {
    const std::string scene = writeRib(kMovingSquare);
    const std::string png = (tessera::test::testScratchDir() / "square.png").string();
    CommandResult r = runTessera("render " + scene + " -o " + png + " --engine reyes --no-blur -q");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    Vec2 c = alphaCentroid(png);  // x = (-1.25 + 2) / 4 * 80 = 15, y = 30
    EXPECT_NEAR(c.x, 15, 0.3);
    EXPECT_NEAR(c.y, 30, 0.3);
    // --shutter moves shutter open to 0.5: the square is then at x = -0.25 (raster 35).
    r = runTessera("render " + scene + " -o " + png + " --engine reyes --no-blur --shutter 0.5,1 -q");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    c = alphaCentroid(png);
    EXPECT_NEAR(c.x, 35, 0.3);
    EXPECT_NEAR(c.y, 30, 0.3);
}

TEST(MotionCli, InfoSummarisesMotion) {
    CommandResult r = runTessera("info " + writeRib(kMovingSquare));
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_TRUE(contains(r.output, "shutter:  0 .. 1")) << r.output;
    EXPECT_TRUE(contains(r.output, "motion:   1 moving patches (2 keys), camera static")) << r.output;
}

TEST(MotionCli, BadValuesExitWith2) {
    const std::string scene = writeRib(kMovingSquare);
    const std::string png = (tessera::test::testScratchDir() / "bad.png").string();
    struct Case {
        std::string flags, message;
    };
    const std::vector<Case> cases = {
        {"--shutter 1", "is not OPEN,CLOSE"},
        {"--shutter 0,1,2", "is not OPEN,CLOSE"},
        {"--shutter 1,0", "close is before open"},
        {"--dof 2,1", "is not FSTOP,FOCALLENGTH,FOCALDISTANCE"},
        {"--dof 0,1,5", "must be positive"},
        {"--blur-sampling fast", "--blur-sampling"},
        {"--blur-tile 1", "from 2 to 16"},
        {"--blur-tile 17", "from 2 to 16"},
        {"--blur-permutations 0", "from 1 to 4096"},
        {"--blur-permutations 5000", "from 1 to 4096"},
        {"--blur-sampling interleaved --blur-tile 16 --spp 512", "65536"},
    };
    for (const Case& c : cases) {
        CommandResult r = runTessera("render " + scene + " -o " + png + " " + c.flags + " -q");
        EXPECT_EQ(r.exitCode, 2) << c.flags << ": " << r.output;
        EXPECT_TRUE(contains(r.output, c.message)) << c.flags << ": " << r.output;
    }
}

}  // namespace tessera::test::motion_input_tests
