// OBJ control meshes: statements, index forms, diagnostics with file:line, and Big Guy end to end.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "io/obj_reader.h"
#include "io/scene_loader.h"
#include "test_support.h"

namespace tessera::test::obj_tests {

namespace fs = std::filesystem;

namespace {

std::string writeObj(const std::string& text, const std::string& name = "mesh.obj") {
    return tessera::test::writeTestFile(name, text);
}

const char* kCubeVerts =
    "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n";

// Expects loading `text` to fail at `line` with a message containing `part`.
void expectError(const std::string& text, int line, const std::string& part) {
    std::string path = writeObj(text);
    try {
        loadScene(path, {});
        ADD_FAILURE() << "no error; expected line " << line << ": " << part;
    } catch (const InputError& e) {
        std::string prefix = path + ":" + std::to_string(line) + ": error:";
        EXPECT_EQ(std::string(e.what()).rfind(prefix, 0), 0u) << e.what();
        EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
    }
}

}  // namespace

TEST(Obj, StatementsAndIndexForms) {
    std::string text = std::string("# a cube\nmtllib cube.mtl\no cube\ng box\ns 1\nusemtl red\n") +
                       kCubeVerts +
                       "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\n"
                       "f 1/1 4/2 3/3 2/4\n"          // v/vt
                       "f 5/1/1 6/2/1 7/3/1 8/4/1\n"  // v/vt/vn
                       "f 1//1 2//1 6//1 5//1\n"      // v//vn
                       "f -7 -6 -2 -3\n"              // relative: 2 3 7 6
                       "f 3 4 8 7 # trailing comment\n"
                       "f 4 \\\n 1 5 8\n";  // line continuation
    ObjMesh m = parseObj(text, "cube.obj", {});
    ASSERT_EQ(m.mesh.points.size(), 8u);
    ASSERT_EQ(m.mesh.faceSizes.size(), 6u);
    EXPECT_EQ((std::vector<int>(m.mesh.faceVerts.begin(), m.mesh.faceVerts.begin() + 4)),
              (std::vector<int>{0, 3, 2, 1}));
    EXPECT_EQ((std::vector<int>(m.mesh.faceVerts.begin() + 12, m.mesh.faceVerts.begin() + 16)),
              (std::vector<int>{1, 2, 6, 5}));
    EXPECT_EQ(m.faceLine[0], 20);
    EXPECT_EQ(m.faceLine[5], 25);  // where the continued line starts
    std::vector<std::string> warnings;
    Scene s = loadScene(writeObj(text), [&](const std::string& w) { warnings.push_back(w); });
    EXPECT_EQ(s.patches.size(), 6u * 16);  // a cube at the default level 2 (no camera at conversion)
    EXPECT_TRUE(warnings.empty()) << warnings[0];
    EXPECT_EQ(s.objectCount, 1u);
    EXPECT_FALSE(s.lights.empty());
}

TEST(Obj, UnsupportedStatementsWarnOnce) {
    std::vector<std::string> warnings;
    std::string text = std::string(kCubeVerts) +
                       "l 1 2\nl 2 3\np 1\nf 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\n"
                       "f 3 4 8 7\nf 4 1 5 8\n";
    loadScene(writeObj(text), [&](const std::string& w) { warnings.push_back(w); });
    ASSERT_EQ(warnings.size(), 2u);
    EXPECT_NE(warnings[0].find(":9: warning: OBJ statement 'l'"), std::string::npos) << warnings[0];
}

TEST(Obj, Errors) {
    std::string v = kCubeVerts;  // lines 1..8
    expectError(v + "f 1 2\n", 9, "at least 3 vertices");
    expectError(v + "f 1 2 0\n", 9, "index 0");
    expectError(v + "f 1 2 9\n", 9, "out of range");
    expectError(v + "\nf 1 2 -9\n", 10, "before the first vertex");
    expectError(v + "f 1 2 x\n", 9, "bad vertex reference 'x'");
    expectError(v + "f 1 2 3/a\n", 9, "bad vertex reference '3/a'");
    expectError("v 1 2\n", 1, "3 coordinates");
    expectError("v 1 2 abc\n", 1, "expected a number");
    expectError(v, 8, "no faces");
    // Topology errors point at the face's line.
    expectError(v + "f 1 2 3\nf 1 2 4\n", 10, "same direction");
    expectError(v + "f 1 2 3 2\n", 9, "twice");
}

TEST(Obj, BigGuy) {
    std::string path = std::string(TESSERA_SHARED_DATA) + "/bigguy/obj/bigguy.obj";
    if (!fs::exists(path)) GTEST_SKIP() << "shared data not found";
    std::vector<std::string> warnings;
    Scene s = loadScene(path, [&](const std::string& w) { warnings.push_back(w); });
    EXPECT_EQ(s.patches.size(), 1450u * 16);  // level 2 (kDefaultSubdivLevel)
    EXPECT_TRUE(warnings.empty());
    // Format override gives the same result; a wrong override fails cleanly.
    EXPECT_EQ(loadScene(path, {}, SceneFormat::Obj).patches.size(), 1450u * 16);
    EXPECT_THROW(loadScene(path, {}, SceneFormat::Micropolis), InputError);
}

TEST(Obj, DetectedByContentWithoutExtension) {
    std::string text =
        std::string(kCubeVerts) + "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";
    std::string path = writeObj(text, "cube");
    EXPECT_EQ(detectSceneFormat(path), SceneFormat::Obj);
    EXPECT_EQ(loadScene(path, {}).patches.size(), 6u * 16);
}

}  // namespace tessera::test::obj_tests
