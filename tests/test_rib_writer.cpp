// writeRib: what our reader reads back must be the same scene (patches bit-identical).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "io/rib_writer.h"
#include "io/scene_loader.h"
#include "test_support.h"

namespace tessera::test::rib_writer_tests {

namespace fs = std::filesystem;

namespace {

fs::path testDir() {
    return tessera::test::testScratchDir();
}

void expectSameScene(const Scene& a, const Scene& b) {
    ASSERT_EQ(a.patches.size(), b.patches.size());
    EXPECT_EQ(std::memcmp(a.patches.data(), b.patches.data(), a.patches.size() * sizeof(BezierPatch)), 0);
    EXPECT_EQ(a.camera.width, b.camera.width);
    EXPECT_EQ(a.camera.height, b.camera.height);
    EXPECT_EQ(a.camera.fovDegrees, b.camera.fovDegrees);
    EXPECT_EQ(a.camera.perspective, b.camera.perspective);
    EXPECT_EQ(a.camera.nearClip, b.camera.nearClip);
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            EXPECT_DOUBLE_EQ(a.camera.cameraFromWorld.m[i][j], b.camera.cameraFromWorld.m[i][j]);
    EXPECT_EQ(a.image.pixelSamplesX, b.image.pixelSamplesX);
    ASSERT_EQ(a.lights.size(), b.lights.size());
    for (size_t i = 0; i < a.lights.size(); ++i) {
        EXPECT_EQ(a.lights[i].type, b.lights[i].type);
        EXPECT_EQ(a.lights[i].color, b.lights[i].color);
        EXPECT_EQ(a.lights[i].from, b.lights[i].from);
        EXPECT_EQ(a.lights[i].to, b.lights[i].to);
    }
    ASSERT_EQ(a.attributes.size(), b.attributes.size());
    for (size_t i = 0; i < a.attributes.size(); ++i) {
        const Material& ma = a.materials[a.attributes[i].material];
        const Material& mb = b.materials[b.attributes[i].material];
        EXPECT_EQ(ma.type, mb.type);
        EXPECT_EQ(ma.Cs, mb.Cs);
        EXPECT_EQ(ma.Kd, mb.Kd);
        EXPECT_EQ(ma.Ks, mb.Ks);
        EXPECT_EQ(ma.roughness, mb.roughness);
        EXPECT_EQ(a.attributes[i].flipNormal, b.attributes[i].flipNormal) << i;
        EXPECT_EQ(a.attributes[i].twoSided, b.attributes[i].twoSided);
        EXPECT_EQ(a.attributes[i].shadingRate, b.attributes[i].shadingRate);
    }
}

}  // namespace

TEST(RibWriter, RoundTripRibScene) {
    std::string src = std::string(TESSERA_SOURCE_DIR) + "/scenes/teapot.rib";
    Scene a = loadScene(src, {});
    std::string out = (testDir() / "teapot_out.rib").string();
    writeRib(a, out);
    Scene b = loadScene(out, {});
    expectSameScene(a, b);
    // No temporary file is left behind.
    size_t files = 0;
    for (auto& e : fs::directory_iterator(testDir())) files += e.is_regular_file();
    EXPECT_EQ(files, 1u);
}

TEST(RibWriter, RoundTripHandMadeSceneWithAttributes) {
    std::string text =
        "Format 200 100 1\nProjection \"perspective\" \"fov\" [40]\nScale 1 1 -1\nTranslate 0 0 "
        "-5\nWorldBegin\n"
        "LightSource \"ambientlight\" 1 \"intensity\" [0.2]\n"
        "LightSource \"pointlight\" 2 \"from\" [1 2 3] \"intensity\" [5]\n"
        "AttributeBegin\nColor 1 0 0\nSurface \"plastic\" \"roughness\" [0.3]\nSides 1\nShadingRate 4\n"
        "Patch \"bilinear\" \"P\" [0 0 0 1 0 0 0 1 0 1 1 0]\nAttributeEnd\n"
        "AttributeBegin\nReverseOrientation\nSurface \"matte\" \"Kd\" [0.7]\n"
        "Patch \"bilinear\" \"P\" [0 0 1 1 0 1 0 1 1 1 1 1]\nAttributeEnd\nWorldEnd\n";
    fs::path in = testDir() / "in.rib";
    std::ofstream(in) << text;
    Scene a = loadScene(in.string(), {});
    std::string out = (testDir() / "out.rib").string();
    writeRib(a, out);
    expectSameScene(a, loadScene(out, {}));
}

TEST(RibWriter, ConvertedObjKeepsSharedEdgesBitIdentical) {
    std::string obj = std::string(TESSERA_SHARED_DATA) + "/bigguy/obj/bigguy.obj";
    if (!fs::exists(obj)) GTEST_SKIP() << "shared data not found";
    Scene a = loadScene(obj, {});
    std::string out = (testDir() / "bigguy.rib").string();
    writeRib(a, out);
    Scene b = loadScene(out, {});
    ASSERT_EQ(b.patches.size(), 1450u * 16);  // OpenSubdiv, level 2
    EXPECT_EQ(std::memcmp(a.patches.data(), b.patches.data(), a.patches.size() * sizeof(BezierPatch)), 0);
}

TEST(RibWriter, UnwritablePathThrows) {
    Scene a = loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/teapot.rib", {});
    EXPECT_THROW(writeRib(a, (testDir() / "missing_dir" / "x.rib").string()), std::runtime_error);
    std::ostringstream text;
    writeRib(a, text);
    EXPECT_NE(text.str().find("Patch \"bicubic\" \"P\" ["), std::string::npos);
    EXPECT_NE(text.str().find("WorldEnd"), std::string::npos);
}

}  // namespace tessera::test::rib_writer_tests
