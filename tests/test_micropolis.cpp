// The Micropolis indexed-vertex text format: detection, the staged teapot and Big Guy, diagnostics.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "io/micropolis_reader.h"
#include "io/scene_loader.h"
#include "test_support.h"

namespace tessera::test::micropolis_tests {

namespace fs = std::filesystem;

namespace {

std::string writeText(const std::string& text, const std::string& name = "model") {
    return tessera::test::writeTestFile(name, text);
}

// One flat patch: 16 vertices of a 4 x 4 grid.
std::string onePatch(const std::string& indices = "1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16", int count = 16) {
    std::string t = "1\n" + indices + "\n" + std::to_string(count) + "\n";
    for (int k = 0; k < count; ++k) t += std::to_string(k % 4) + "," + std::to_string(k / 4) + ",0.5\n";
    return t;
}

void expectError(const std::string& text, int line, const std::string& part) {
    try {
        parseMicropolis(text, "m");
        ADD_FAILURE() << "no error; expected line " << line << ": " << part;
    } catch (const InputError& e) {
        EXPECT_EQ(e.line(), line) << e.what();
        EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
    }
}

}  // namespace

TEST(Micropolis, SmallFileRowMajor) {
    auto patches = parseMicropolis(onePatch(), "m");
    ASSERT_EQ(patches.size(), 1u);
    EXPECT_EQ(patches[0].at(1, 0), (Vec3{1, 0, 0.5f}));
    EXPECT_EQ(patches[0].at(0, 1), (Vec3{0, 1, 0.5f}));
    EXPECT_EQ(patches[0].at(3, 3), (Vec3{3, 3, 0.5f}));
    EXPECT_TRUE(looksLikeMicropolis(onePatch()));
    EXPECT_FALSE(looksLikeMicropolis("32\n3 3\n1.4 0.0 2.4\n"));  // .bpt
    EXPECT_FALSE(looksLikeMicropolis("WorldBegin\n"));
}

TEST(Micropolis, Errors) {
    expectError("x\n", 1, "patch count");
    expectError("0\n", 1, "must be positive");
    expectError("1\n1,2,3\n16\n", 2, "3 vertex indices; expected 16");
    expectError(onePatch("1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,17"), 2, "outside 1..16");
    expectError(onePatch("1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,0"), 2, "outside 1..16");
    expectError(onePatch("1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,a"), 2, "integer vertex index");
    expectError("2\n" + onePatch().substr(2), 3, "expected 16");
    std::string t = onePatch();
    expectError(t + "1,2,3\n", 20, "trailing data");
    expectError(t.substr(0, t.size() - 8), 18, "unexpected end of file");  // at the last line
    expectError("1\n1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16\n16\n0,0\n", 4, "expected x,y,z");
    expectError("1\n1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16\n16\n0,0,nan\n", 4, "expected a number");
}

TEST(Micropolis, TeapotEqualsBpt) {
    std::string mp = std::string(TESSERA_SHARED_DATA) + "/teapot/micropolis/teapot";
    std::string bpt = std::string(TESSERA_TEST_DATA) + "/teapot.bpt";
    if (!fs::exists(mp) || !fs::exists(bpt)) GTEST_SKIP() << "shared data not found";
    EXPECT_EQ(detectSceneFormat(mp), SceneFormat::Micropolis);
    Scene a = loadScene(mp, {});
    Scene b = loadScene(bpt, {});
    ASSERT_EQ(a.patches.size(), 32u);
    ASSERT_EQ(b.patches.size(), 32u);
    for (size_t p = 0; p < 32; ++p)
        for (int k = 0; k < 16; ++k) EXPECT_EQ(a.patches[p].cp[k], b.patches[p].cp[k]) << p << " " << k;
    // Same framing as the .bpt (z up).
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            EXPECT_EQ(a.camera.cameraFromWorld.m[i][j], b.camera.cameraFromWorld.m[i][j]);
}

TEST(Micropolis, BigGuy) {
    std::string path = std::string(TESSERA_SHARED_DATA) + "/bigguy/micropolis/bigguy";
    if (!fs::exists(path)) GTEST_SKIP() << "shared data not found";
    Scene s = loadScene(path, {});
    EXPECT_EQ(s.patches.size(), 3570u);
    Bounds3 b = s.worldBounds();
    EXPECT_NEAR(b.lo.y, -3.0, 1e-4);
    EXPECT_NEAR(b.hi.y, 3.0, 1e-4);
    EXPECT_EQ(loadScene(path, {}, SceneFormat::Micropolis).patches.size(), 3570u);
}

TEST(Micropolis, FormatOverrideAndNames) {
    std::string path = writeText(onePatch(), "model.txt");
    EXPECT_EQ(loadScene(path, {}).patches.size(), 1u);  // detected by content
    EXPECT_EQ(loadScene(path, {}, SceneFormat::Micropolis).patches.size(), 1u);
    EXPECT_THROW(loadScene(path, {}, SceneFormat::Rib), InputError);
    EXPECT_EQ(parseSceneFormat("micropolis"), SceneFormat::Micropolis);
    EXPECT_EQ(parseSceneFormat("OBJ"), SceneFormat::Obj);
    EXPECT_EQ(parseSceneFormat("mesh"), std::nullopt);
    EXPECT_THROW(detectSceneFormat(writeText("x", "k.mscene")), InputError);
}

}  // namespace tessera::test::micropolis_tests
