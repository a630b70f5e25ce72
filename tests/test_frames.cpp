// Multi-frame RIB (RI spec 3.2, sec. 4.1.1): each frame read with the options outside frames before it and
// its own; the CLI renders every frame (or those --frames picks) to its own Display name.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>

#include "io/diagnostics.h"
#include "io/image_io.h"
#include "io/rib_reader.h"
#include "shading/light.h"
#include "test_support.h"

namespace tessera::test::frames_tests {

namespace fs = std::filesystem;

namespace {

fs::path framesDir() {
    fs::path d = fs::temp_directory_path() / ("tessera_frames_" + std::to_string(getpid()));
    fs::create_directories(d);
    return d;
}

// Two frames of one bilinear patch: Format 40x30 outside the frames is the default of both; frame 2
// overrides it locally; a Format after frame 2 belongs to no frame before it.
std::string twoFrameRib(int secondNumber = 2) {
    const std::string world =
        "WorldBegin LightSource \"distantlight\" 1 Surface \"matte\" "
        "Patch \"bilinear\" \"P\" [-1 -1 0 1 -1 0 -1 1 0 1 1 0] WorldEnd\n";
    return "Format 40 30 1\nProjection \"perspective\" \"fov\" 40\nTranslate 0 0 5\n"
           "FrameBegin 1\nDisplay \"one.png\" \"file\" \"rgba\"\n" +
           world + "FrameEnd\nFrameBegin " + std::to_string(secondNumber) +
           "\nDisplay \"two.png\" \"file\" \"rgba\"\nFormat 20 10 1\n" + world + "FrameEnd\nFormat 64 64 1\n";
}

fs::path writeFile(const fs::path& path, const std::string& text) {
    std::ofstream(path) << text;
    return path;
}

const WarningSink kQuiet = [](const std::string&) {};

}  // namespace

TEST(Frames, ListsFrameNumbersInFileOrder) {
    const fs::path rib = writeFile(framesDir() / "list.rib", twoFrameRib(7));
    const std::vector<RibFrame> frames = ribFrames(rib.string());
    ASSERT_EQ(frames.size(), 2u);
    EXPECT_EQ(frames[0].number, 1);
    EXPECT_EQ(frames[1].number, 7);
    EXPECT_EQ(frames[0].line, 4);
}

TEST(Frames, OptionsOutsideFramesAreEveryFramesDefaultInsideLocal) {
    const fs::path rib = writeFile(framesDir() / "options.rib", twoFrameRib());
    Scene first, second;
    readRibFrame(rib.string(), 0, first, kQuiet);
    readRibFrame(rib.string(), 1, second, kQuiet);
    EXPECT_EQ(first.image.displayName, "one.png");
    EXPECT_EQ(second.image.displayName, "two.png");
    // Frame 1: the Format before FrameBegin; the Format of frame 2 and the one after it do not leak back.
    EXPECT_EQ(first.camera.width, 40);
    EXPECT_EQ(first.camera.height, 30);
    // Frame 2: its own Format; the one after its FrameEnd is not its option.
    EXPECT_EQ(second.camera.width, 20);
    EXPECT_EQ(second.camera.height, 10);
    EXPECT_EQ(first.patches.size(), 1u);
    EXPECT_EQ(second.patches.size(), 1u);
}

TEST(Frames, CliRendersEveryFrameToItsDisplayName) {
    const fs::path dir = framesDir() / "all";
    fs::remove_all(dir);
    fs::create_directories(dir);
    writeFile(dir / "s.rib", twoFrameRib());
    std::string out;
    ASSERT_EQ(runTesseraIn(dir, "render s.rib --quiet", &out), 0) << out;
    const Image one = readPng((dir / "one.png").string()), two = readPng((dir / "two.png").string());
    EXPECT_EQ(one.width, 40);
    EXPECT_EQ(one.height, 30);
    EXPECT_EQ(two.width, 20);
    EXPECT_EQ(two.height, 10);
}

TEST(Frames, CliFramesPicksOneOrARange) {
    const fs::path dir = framesDir() / "pick";
    fs::remove_all(dir);
    fs::create_directories(dir);
    writeFile(dir / "s.rib", twoFrameRib());
    std::string out;
    ASSERT_EQ(runTesseraIn(dir, "render s.rib --quiet --frames 2", &out), 0) << out;
    EXPECT_FALSE(fs::exists(dir / "one.png"));
    EXPECT_TRUE(fs::exists(dir / "two.png"));
    fs::remove(dir / "two.png");
    ASSERT_EQ(runTesseraIn(dir, "render s.rib --quiet --frames 1-2", &out), 0) << out;
    EXPECT_TRUE(fs::exists(dir / "one.png"));
    EXPECT_TRUE(fs::exists(dir / "two.png"));
    // One frame picked: -o names its image.
    ASSERT_EQ(runTesseraIn(dir, "render s.rib --quiet --frames 1 -o picked.png", &out), 0) << out;
    EXPECT_EQ(readPng((dir / "picked.png").string()).width, 40);
}

TEST(Frames, CliFrameOutsideTheFileIsAnErrorAfterEarlierFramesAreWritten) {
    const fs::path dir = framesDir() / "outside";
    fs::remove_all(dir);
    fs::create_directories(dir);
    writeFile(dir / "s.rib", twoFrameRib());
    std::string out;
    EXPECT_EQ(runTesseraIn(dir, "render s.rib --quiet --frames 1-3", &out), 2);
    EXPECT_NE(out.find("no frame 3"), std::string::npos) << out;
    EXPECT_TRUE(fs::exists(dir / "one.png"));
    EXPECT_TRUE(fs::exists(dir / "two.png"));
    EXPECT_EQ(runTesseraIn(dir, "render s.rib --quiet --frames 9", &out), 2);
    EXPECT_NE(out.find("s.rib: error: --frames 9: the file has no frame 9 (its frames: 1 2)"),
              std::string::npos)
        << out;
    EXPECT_EQ(runTesseraIn(dir, "render s.rib --quiet --frames 2-1", &out), 2);
    EXPECT_NE(out.find("is not N or A-B"), std::string::npos) << out;
    // Several frames but one -o: refused before anything renders.
    fs::remove(dir / "one.png");
    EXPECT_EQ(runTesseraIn(dir, "render s.rib --quiet -o x.png", &out), 2);
    EXPECT_NE(out.find("each frame writes its own Display name"), std::string::npos) << out;
    EXPECT_FALSE(fs::exists(dir / "one.png"));
    EXPECT_FALSE(fs::exists(dir / "x.png"));
}

namespace {

// Frame 1: a depth pass of a large plane 5 units in front of the camera; frame 2: MakeShadow of it and
// a beauty render.
std::string depthPassRib(const std::string& makeShadowInput = "plane.z") {
    const std::string world =
        "WorldBegin LightSource \"distantlight\" 1 Surface \"matte\" "
        "Patch \"bilinear\" \"P\" [-10 -10 0 10 -10 0 -10 10 0 10 10 0] WorldEnd\n";
    return "Format 32 24 1\nProjection \"perspective\" \"fov\" 40\nTranslate 0 0 5\n"
           "FrameBegin 1\nDisplay \"plane.z\" \"zfile\" \"z\"\n" +
           world + "FrameEnd\nFrameBegin 2\nMakeShadow \"" + makeShadowInput +
           "\" \"plane.shad\"\nDisplay \"beauty.png\" \"file\" \"rgba\"\n" + world + "FrameEnd\n";
}

}  // namespace

TEST(Frames, DepthMapRoundTripKeepsValuesAndMatrices) {
    DepthMap map;
    map.width = 3;
    map.height = 2;
    map.depth = {1.f, 2.5f, 3.f, std::numeric_limits<float>::infinity(), 0.25f, 7.f};
    map.worldToCamera = Mat4::translate(0, 0, 5);
    map.worldToNDC.m[0][1] = 0.5;
    const std::string path = (framesDir() / "roundtrip.z").string();
    writeDepthMap(path, map);
    const DepthMap back = readDepthMap(path);
    EXPECT_EQ(back.width, 3);
    EXPECT_EQ(back.height, 2);
    EXPECT_EQ(back.depth, map.depth);
    EXPECT_EQ(back.kind, "zfile");
    EXPECT_DOUBLE_EQ(back.worldToCamera.m[2][3], 5.0);
    EXPECT_DOUBLE_EQ(back.worldToNDC.m[0][1], 0.5);
    EXPECT_DOUBLE_EQ(back.worldToNDC.m[1][0], 0.0);
}

TEST(Frames, ZfileDisplayWritesCameraDepthAndMakeShadowConvertsIt) {
    const fs::path dir = framesDir() / "zfile";
    fs::remove_all(dir);
    fs::create_directories(dir);
    writeFile(dir / "s.rib", depthPassRib());
    std::string out;
    ASSERT_EQ(runTesseraIn(dir, "render s.rib --quiet", &out), 0) << out;
    const DepthMap z = readDepthMap((dir / "plane.z").string());
    ASSERT_EQ(z.width, 32);
    ASSERT_EQ(z.height, 24);
    EXPECT_EQ(z.kind, "zfile");
    // A plane facing the camera at distance 5: camera-space depth 5 at every pixel.
    for (float d : z.depth) ASSERT_NEAR(d, 5.f, 1e-3f);
    EXPECT_DOUBLE_EQ(z.worldToCamera.m[2][3], 5.0);  // Translate 0 0 5
    const DepthMap shadow = readDepthMap((dir / "plane.shad").string());
    EXPECT_EQ(shadow.kind, "shadow");
    EXPECT_EQ(shadow.depth, z.depth);
    EXPECT_TRUE(fs::exists(dir / "beauty.png"));
}

TEST(Frames, MakeShadowOfAMissingFileOrNotADepthMapIsAnInputError) {
    const fs::path dir = framesDir() / "badshadow";
    fs::remove_all(dir);
    fs::create_directories(dir);
    // Missing: frame 2 alone was asked for, so no frame made plane.z.
    writeFile(dir / "s.rib", depthPassRib());
    std::string out;
    EXPECT_EQ(runTesseraIn(dir, "render s.rib --quiet --frames 2", &out), 2);
    EXPECT_NE(out.find("s.rib:9: error: MakeShadow: depth file"), std::string::npos) << out;
    EXPECT_NE(out.find("plane.z\" not found"), std::string::npos) << out;
    EXPECT_FALSE(fs::exists(dir / "plane.shad"));
    // An RGBA OpenEXR image is not a depth map.
    Image rgba(4, 4);
    writeExr((dir / "beauty.exr").string(), rgba);
    writeFile(dir / "t.rib", depthPassRib("beauty.exr"));
    Scene scene;
    try {
        readRibFrame((dir / "t.rib").string(), 1, scene, kQuiet);
        ADD_FAILURE() << "MakeShadow of an RGBA image was accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("MakeShadow: "), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("not a depth map"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(fs::exists(dir / "plane.shad"));
}

// RI spec 3.2, appendix A, spotlight: Cl = intensity * lightcolor / (L.L) * cosangle^beamdistribution *
// smoothstep(cos(coneangle), cos(coneangle - conedeltaangle), cosangle), evaluated here in double from
// the formula, through the RIB reader's LightSource "spotlight" parameters.
TEST(Frames, SpotlightConeFalloffFollowsTheRiFormula) {
    const fs::path rib = writeFile(framesDir() / "spot.rib",
                                   "Format 8 8 1\nWorldBegin\nLightSource \"spotlight\" 1 \"intensity\" 3 "
                                   "\"from\" [0 0 0] \"to\" [0 0 1] "
                                   "\"coneangle\" 0.5 \"conedeltaangle\" 0.2 \"beamdistribution\" 3\n"
                                   "Patch \"bilinear\" \"P\" [-1 -1 2 1 -1 2 -1 1 2 1 1 2]\nWorldEnd\n");
    Scene scene;
    readRibFrame(rib.string(), 0, scene, kQuiet);
    ASSERT_EQ(scene.lights.size(), 1u);
    const ShadingLight light = prepareLight(scene.lights[0], Mat4::identity());
    auto smooth = [](double e0, double e1, double x) {
        const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
        return t * t * (3 - 2 * t);
    };
    int inside = 0, band = 0;
    for (double angle = 0; angle < 0.6; angle += 0.01) {
        const double r = 2.5;
        const Vec3 P{float(r * std::sin(angle)), 0.f, float(r * std::cos(angle))};
        const LightSample s = sampleLight(light, P);
        const double c = std::cos(angle);
        const double expected = 3.0 / (r * r) * std::pow(c, 3.0) * smooth(std::cos(0.5), std::cos(0.3), c);
        EXPECT_NEAR(s.valid ? s.Cl.x : 0.f, expected, 2e-4 * 3.0 / (r * r)) << "angle " << angle;
        inside += expected > 0;
        band += expected > 0 && angle > 0.3;
    }
    EXPECT_GT(inside, 40);  // the cone and the smoothstep band are both sampled
    EXPECT_GT(band, 10);
}

}  // namespace tessera::test::frames_tests
