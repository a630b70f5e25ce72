#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "io/scene_loader.h"
#include "test_support.h"

namespace tessera::test::bpt_tests {

namespace fs = std::filesystem;

namespace {

std::string writeBpt(const std::string& text) {
    return tessera::test::writeTestFile("input.bpt", text);
}

// Error text of loading `text` as a .bpt file; checks the "<file>:<line>: error:" prefix.
std::string expectError(const std::string& text, int line) {
    std::string path = writeBpt(text);
    std::string msg;
    try {
        loadBpt(path, {});
    } catch (const InputError& e) {
        msg = e.what();
        EXPECT_EQ(e.line(), line);
    }
    std::string prefix = path + ":" + std::to_string(line) + ": error:";
    EXPECT_EQ(msg.rfind(prefix, 0), 0u) << "expected prefix '" << prefix << "', got '" << msg << "'";
    return msg;
}

std::string patchText(int degreeU = 3, int degreeV = 3) {
    std::string s = std::to_string(degreeU) + " " + std::to_string(degreeV) + "\n";
    for (int k = 0; k < 16; ++k) s += std::to_string(k % 4) + " " + std::to_string(k / 4) + " 0\n";
    return s;
}

}  // namespace

TEST(Bpt, TeapotPatchesAndBounds) {
    Scene s = loadScene(std::string(TESSERA_TEST_DATA) + "/teapot.bpt", {});
    ASSERT_EQ(s.patches.size(), 32u);
    EXPECT_EQ(s.attributes.size(), 32u);
    Bounds3 b = s.worldBounds();
    EXPECT_NEAR(b.lo.x, -3, 1e-5);
    EXPECT_NEAR(b.lo.y, -2, 1e-5);
    EXPECT_NEAR(b.lo.z, 0, 1e-5);
    EXPECT_NEAR(b.hi.x, 3.525, 1e-5);
    EXPECT_NEAR(b.hi.y, 2, 1e-5);
    EXPECT_NEAR(b.hi.z, 3.15, 1e-5);
    // First patch, first row: 1.4 0.0 2.4 / 1.4 -0.784 2.4 (u varies fastest).
    EXPECT_FLOAT_EQ(s.patches[0].at(1, 0).y, -0.784f);
    // Default framing, plastic material, lights.
    EXPECT_EQ(s.camera.width, 800);
    EXPECT_EQ(s.camera.height, 600);
    ASSERT_EQ(s.materials.size(), 1u);
    EXPECT_EQ(s.materials[0].type, MaterialType::Plastic);
    EXPECT_FALSE(s.lights.empty());
    EXPECT_EQ(s.objectCount, 1u);
}

TEST(Bpt, SmallFileRowMajor) {
    std::string path = writeBpt("1\n" + patchText());
    Scene s = loadBpt(path, {});
    ASSERT_EQ(s.patches.size(), 1u);
    EXPECT_EQ(s.patches[0].at(2, 1).x, 2.f);
    EXPECT_EQ(s.patches[0].at(2, 1).y, 1.f);
    EXPECT_EQ(s.sourcePath, path);
}

TEST(Bpt, TruncatedFile) {
    std::string text = "2\n" + patchText() + "3 3\n0 0 0\n1 0 0\n";  // second patch has 2 of 16 points
    std::string msg = expectError(text, 21);
    EXPECT_NE(msg.find("unexpected end of file"), std::string::npos) << msg;
}

TEST(Bpt, BadDegree) {
    std::string msg = expectError("2\n" + patchText() + patchText(2, 3), 19);
    EXPECT_NE(msg.find("degree 2 3"), std::string::npos) << msg;
}

TEST(Bpt, BadNumber) {
    std::string text = "1\n" + patchText();
    text.replace(text.find("2 1 0"), 5, "2 x 0");  // point 6 is on line 9
    std::string msg = expectError(text, 9);
    EXPECT_NE(msg.find("'x'"), std::string::npos) << msg;
}

TEST(Bpt, NaNAndInfinity) {
    std::string text = "1\n" + patchText();
    text.replace(text.find("3 0 0"), 5, "3 nan 0");  // point 3 on line 6
    expectError(text, 6);
    std::string inf = "1\n" + patchText();
    inf.replace(inf.find("1 1 0"), 5, "1 inf 0");  // point 5 on line 8
    expectError(inf, 8);
}

TEST(Bpt, WrongAndNegativeCounts) {
    expectError("-1\n", 1);
    expectError("1.5\n" + patchText(), 1);
    std::string msg = expectError("1\n" + patchText() + patchText(), 19);  // one more patch than declared
    EXPECT_NE(msg.find("trailing"), std::string::npos) << msg;
    expectError("", 1);
}

}  // namespace tessera::test::bpt_tests
