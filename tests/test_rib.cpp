#include <gtest/gtest.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <charconv>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "core/basis.h"
#include "io/rib_lexer.h"
#include "io/rib_reader.h"
#include "io/rib_shaders.h"
#include "io/rib_writer.h"
#include "io/scene_loader.h"
#include "rib_test_util.h"
#include "shading/registry.h"
#include "test_support.h"

namespace tessera::test::rib_tests {

namespace fs = std::filesystem;

namespace {

fs::path testDir() {
    return tessera::test::testScratchDir();
}

const char* kUnitSquare = "Patch \"bilinear\" \"P\" [0 0 0  1 0 0  0 1 0  1 1 0]\n";

// Options, then a world holding `body` and one unit square patch.
std::string scene(const std::string& options, const std::string& body) {
    return options + "\nWorldBegin\n" + body + "\n" + kUnitSquare + "WorldEnd\n";
}

int countWarnings(const std::vector<std::string>& ws, const std::string& part) {
    int n = 0;
    for (const auto& w : ws) {
        size_t at = w.find(": warning: ");  // match the message only, not the (test-named) path
        n += at != std::string::npos && contains(w.substr(at), part);
    }
    return n;
}

}  // namespace

// ---- lexer ----------------------------------------------------------------------------------

TEST(RibLexer, TokensAndLines) {
    RibLexer lex("Format 640 .5 -2e-1 +3 # comment\n\"a\\\"b\\n\" [ 1\n 2 ] -x", "f");
    std::vector<Token> t;
    while (lex.peek().type != TokenType::End) t.push_back(lex.next());
    ASSERT_EQ(t.size(), 11u);
    EXPECT_EQ(t[0].type, TokenType::Request);
    EXPECT_EQ(t[0].text, "Format");
    EXPECT_EQ(t[1].number, 640);
    EXPECT_EQ(t[2].number, 0.5);
    EXPECT_DOUBLE_EQ(t[3].number, -0.2);
    EXPECT_EQ(t[4].number, 3);
    EXPECT_EQ(t[5].type, TokenType::String);
    EXPECT_EQ(t[5].text, "a\"b\n");
    EXPECT_EQ(t[5].line, 2);
    EXPECT_EQ(t[6].type, TokenType::ArrayBegin);
    EXPECT_EQ(t[8].line, 3);
    EXPECT_EQ(t[9].type, TokenType::ArrayEnd);
    EXPECT_EQ(t[10].type, TokenType::Other);
    EXPECT_EQ(t[10].text, "-x");
}

// The lexer reads most numbers by a fast path (an exact integer divided by an exact power of ten); every
// number must still be the double std::from_chars gives, bit for bit: random decimals of 1 to 18 digits
// with the point anywhere, signs, leading zeros, and exponents (which take from_chars itself).
TEST(RibLexer, NumbersEqualFromChars) {
    std::mt19937 rng(18);
    std::vector<std::string> words = {"0",
                                      "-0",
                                      "+0",
                                      "0.",
                                      ".0",
                                      "-.5",
                                      "1e3",
                                      "2.5E-3",
                                      "123456789012345",
                                      "1234567890123456",
                                      "0.000000000000001",
                                      "999999999999999.",
                                      "-7.",
                                      "00012.500",
                                      "0.1",
                                      "0.2",
                                      "0.3",
                                      "9007199254740993"};
    for (int i = 0; i < 20000; ++i) {
        const int digits = 1 + int(rng() % 18), point = int(rng() % (digits + 1));
        std::string w = rng() % 3 == 0 ? "-" : (rng() % 5 == 0 ? "+" : "");
        for (int d = 0; d < digits; ++d) {
            if (d == point) w += '.';
            w += char('0' + rng() % 10);
        }
        if (rng() % 7 == 0) w += "e" + std::to_string(int(rng() % 21) - 10);
        words.push_back(w);
    }
    std::string text;
    for (const std::string& w : words) text += w + " ";
    RibLexer lex(text, "numbers");
    for (const std::string& w : words) {
        const Token t = lex.next();
        ASSERT_EQ(t.type, TokenType::Number) << w;
        double expected = 0;
        const char* first = w.data() + (w[0] == '+' ? 1 : 0);
        std::from_chars(first, w.data() + w.size(), expected);
        EXPECT_EQ(std::bit_cast<uint64_t>(t.number), std::bit_cast<uint64_t>(expected)) << w;
    }
}

// ---- options ---------------------------------------------------------------------------------

TEST(RibOptions, FormatAndSampling) {
    Loaded l = load(scene(
        "Format 320 200 2\nPixelSamples 3 4\nPixelFilter \"box\" 1 1.5\nExposure 1.5 2.2\nClipping 0.5 500",
        ""));
    EXPECT_EQ(l.scene.camera.width, 320);
    EXPECT_EQ(l.scene.camera.height, 200);
    EXPECT_EQ(l.scene.camera.pixelAspect, 2.f);
    EXPECT_EQ(l.scene.image.pixelSamplesX, 3);
    EXPECT_EQ(l.scene.image.pixelSamplesY, 4);
    EXPECT_EQ(l.scene.image.filter, FilterType::Box);
    EXPECT_EQ(l.scene.image.filterWidthY, 1.5f);
    EXPECT_EQ(l.scene.image.exposureGain, 1.5f);
    EXPECT_EQ(l.scene.image.exposureGamma, 2.2f);
    EXPECT_EQ(l.scene.camera.nearClip, 0.5f);
    EXPECT_EQ(l.scene.camera.farClip, 500.f);
}

TEST(RibOptions, ProjectionScreenWindowAspectDisplay) {
    Loaded l =
        load(scene("Projection \"perspective\" \"fov\" 37.5\nScreenWindow -2 2 -1 1\nFrameAspectRatio 2\n"
                   "Display \"out/image.tif\" \"file\" \"rgba\" \"string compression\" \"lzw\"",
                   ""));
    EXPECT_TRUE(l.scene.camera.perspective);
    EXPECT_EQ(l.scene.camera.fovDegrees, 37.5f);
    EXPECT_TRUE(l.scene.camera.hasScreenWindow);
    EXPECT_EQ(l.scene.camera.screenWindow[0], -2.f);
    EXPECT_EQ(l.scene.camera.screenWindow[3], 1.f);
    EXPECT_EQ(l.scene.camera.frameAspect, 2.f);
    EXPECT_EQ(l.scene.image.displayName, "out/image.tif");
    // The only warning: the scene has no lights.
    EXPECT_EQ(l.warnings.size(), 1u);
    EXPECT_EQ(countWarnings(l.warnings, "no light sources"), 1);

    Loaded o = load(scene("Projection \"orthographic\"", ""));
    EXPECT_FALSE(o.scene.camera.perspective);
}

TEST(RibOptions, PixelFilterNames) {
    EXPECT_EQ(load(scene("PixelFilter \"triangle\" 2 2", "")).scene.image.filter, FilterType::Triangle);
    EXPECT_EQ(load(scene("PixelFilter \"catmull-rom\" 3 3", "")).scene.image.filter, FilterType::CatmullRom);
    Loaded l = load(scene("PixelFilter \"box\" 1 1\nPixelFilter \"sinc\" 4 4", ""));
    EXPECT_EQ(l.scene.image.filter, FilterType::Box);  // unsupported filter keeps the previous one
    EXPECT_EQ(countWarnings(l.warnings, "sinc"), 1);
}

TEST(RibOptions, OptionAndVersionWarnings) {
    Loaded l =
        load(scene("version 3.03\nOption \"searchpath\" \"shader\" [\"../shaders:&\"]\n"
                   "Option \"limits\" \"eyesplits\" 3\nOption \"limits\" \"bucketsize\" [16 16]",
                   ""));
    EXPECT_EQ(countWarnings(l.warnings, "limits"), 1);
    EXPECT_EQ(countWarnings(l.warnings, "searchpath"), 0);
    EXPECT_EQ(countWarnings(l.warnings, "version"), 0);
}

TEST(RibOptions, OnlyFirstFrameIsLoaded) {
    std::string frame =
        "FrameBegin 1\nFormat 100 100 1\nWorldBegin\n" + std::string(kUnitSquare) + "WorldEnd\nFrameEnd\n";
    std::string second = "FrameBegin 2\nFormat 50 50 1\nWorldBegin\n" + std::string(kUnitSquare) +
                         kUnitSquare + "WorldEnd\nFrameEnd\n";
    Loaded l = load(frame + second);
    EXPECT_EQ(l.scene.camera.width, 100);
    EXPECT_EQ(l.scene.patches.size(), 1u);
    EXPECT_EQ(countWarnings(l.warnings, "frame"), 1);
}

// ---- transformations -------------------------------------------------------------------------

TEST(RibTransforms, CameraTransformAtWorldBegin) {
    Loaded l = load(scene("Translate 0 0 5\nRotate 90 0 1 0", ""));
    const Mat4& c = l.scene.camera.cameraFromWorld;
    Mat4 expect = Mat4::translate(0, 0, 5) * Mat4::rotate(90, 0, 1, 0);
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) EXPECT_NEAR(c.m[i][j], expect.m[i][j], 1e-12);
    // The world CTM starts at identity: the patch is stored unchanged.
    expectVec(l.scene.patches[0].at(3, 3), {1, 1, 0});
}

TEST(RibTransforms, TranslateRotateScaleConcatenate) {
    // CTM = T * R * S: points are scaled first, then rotated, then translated.
    Loaded l = load(scene("", "Translate 10 0 0\nRotate 90 0 0 1\nScale 2 2 2"));
    expectVec(l.scene.patches[0].at(3, 0), {10, 2, 0});  // (1,0,0) -> (2,0,0) -> (0,2,0) -> (10,2,0)
    expectVec(l.scene.patches[0].at(0, 3), {8, 0, 0});   // (0,1,0) -> (0,2,0) -> (-2,0,0) -> (8,0,0)
}

TEST(RibTransforms, ConcatTransformAndTransform) {
    // RIB matrices are row-vector: the translation is in elements 12..14.
    Loaded l = load(scene("", "Translate 1 0 0\nConcatTransform [2 0 0 0  0 2 0 0  0 0 2 0  0 0 3 1]"));
    expectVec(l.scene.patches[0].at(3, 3), {3, 2, 3});
    // Transform replaces the CTM (inside the world: relative to world space).
    Loaded t = load(scene("", "Translate 100 0 0\nTransform [1 0 0 0  0 1 0 0  0 0 1 0  0 0 7 1]"));
    expectVec(t.scene.patches[0].at(0, 0), {0, 0, 7});
    Loaded id = load(scene("", "Translate 100 0 0\nIdentity"));
    expectVec(id.scene.patches[0].at(0, 0), {0, 0, 0});
}

TEST(RibTransforms, TransformAndAttributeBlocksRestore) {
    Loaded l = load(scene("", std::string("TransformBegin\nTranslate 5 0 0\n") + kUnitSquare +
                                  "TransformEnd\nAttributeBegin\nTranslate 0 5 0\nSides 1\n" + kUnitSquare +
                                  "AttributeEnd\n"));
    ASSERT_EQ(l.scene.patches.size(), 3u);
    expectVec(l.scene.patches[0].at(0, 0), {5, 0, 0});
    expectVec(l.scene.patches[1].at(0, 0), {0, 5, 0});
    expectVec(l.scene.patches[2].at(0, 0), {0, 0, 0});
    EXPECT_FALSE(l.scene.attributes[1].twoSided);
    EXPECT_TRUE(l.scene.attributes[2].twoSided);  // AttributeEnd restored Sides 2
}

TEST(RibTransforms, CoordinateSystems) {
    Loaded l =
        load(scene("", "Translate 3 0 0\nCoordinateSystem \"lamp\"\nIdentity\nCoordSysTransform \"lamp\""));
    expectVec(l.scene.patches[0].at(0, 0), {3, 0, 0});
}

// ---- attributes --------------------------------------------------------------------------------

TEST(RibAttributes, ShadingRateSidesAndObjectIds) {
    Loaded l = load(scene("ShadingRate 4", std::string(kUnitSquare) + "ShadingRate 0.25\nSides 1\n"));
    ASSERT_EQ(l.scene.attributes.size(), 2u);
    EXPECT_EQ(l.scene.attributes[0].shadingRate, 4.f);
    EXPECT_EQ(l.scene.attributes[1].shadingRate, 0.25f);
    EXPECT_TRUE(l.scene.attributes[0].twoSided);
    EXPECT_FALSE(l.scene.attributes[1].twoSided);
    // One object id per attribute block: both squares are in the world block.
    EXPECT_EQ(l.scene.attributes[0].object, 0u);
    EXPECT_EQ(l.scene.attributes[1].object, 0u);
    EXPECT_EQ(l.scene.objectCount, 1u);
}

TEST(RibAttributes, ObjectIdsFollowAttributeBlocksAndIdentifierNames) {
    // Object ids (paper 004's attribute test and the id AOV need one per object, not per patch): each
    // attribute block is one object, its nested blocks others; a name given by Attribute "identifier"
    // joins every primitive declared under it, wherever it is; the block after a named one is new again.
    const std::string square = kUnitSquare;
    Loaded l = load(scene(
        "", square + square + "AttributeBegin\n" + square + "AttributeBegin\n" + square + "AttributeEnd\n" +
                square + "AttributeEnd\n" + "AttributeBegin\nAttribute \"identifier\" \"name\" \"lid\"\n" +
                square + "AttributeEnd\nAttributeBegin\nAttribute \"identifier\" \"name\" \"lid\"\n" +
                square + "AttributeEnd\n" + square));
    std::vector<uint32_t> ids;
    for (const PatchAttributes& a : l.scene.attributes) ids.push_back(a.object);
    EXPECT_EQ(ids, (std::vector<uint32_t>{0, 0, 1, 2, 1, 3, 3, 0, 0}));  // scene() adds a last square
    EXPECT_EQ(l.scene.objectCount, 4u);
}

TEST(RibAttributes, OrientationAndHandedness) {
    std::string p = kUnitSquare;
    Loaded l =
        load(scene("", p + "Orientation \"rh\"\n" + p + "ReverseOrientation\n" + p +
                           "Orientation \"outside\"\nScale 1 1 -1\n" + p + "Orientation \"inside\"\n"));
    ASSERT_EQ(l.scene.attributes.size(), 5u);
    EXPECT_FALSE(l.scene.attributes[0].flipNormal);  // default "outside" == "lh"
    EXPECT_TRUE(l.scene.attributes[1].flipNormal);   // "rh"
    EXPECT_FALSE(l.scene.attributes[2].flipNormal);  // reversed back to "lh"
    EXPECT_TRUE(l.scene.attributes[3].flipNormal);   // mirrored CTM
    EXPECT_FALSE(l.scene.attributes[4].flipNormal);  // "inside" and mirrored
}

// The reader remembers the last transformation's handedness (OrientationCache): transformations that
// alternate between mirrored and not each get their own answer.
TEST(RibAttributes, HandednessFollowsEveryTransformationChange) {
    std::string p = kUnitSquare;
    const std::string mirrored = "AttributeBegin\nScale -1 1 1\n" + p + "AttributeEnd\n";
    Loaded l = load(scene("", p + mirrored + p + mirrored + mirrored + "Scale 2 2 2\n" + p +
                                  "Scale 1 -1 1\n" + p + "Scale 1 1 -1\n" + p));
    std::vector<bool> flips;
    for (const PatchAttributes& a : l.scene.attributes) flips.push_back(a.flipNormal);
    // scene() adds a last square under the world's final transformation (two mirrors: not mirrored).
    EXPECT_EQ(flips, (std::vector<bool>{false, true, false, true, true, false, true, false, false}));
}

TEST(RibAttributes, SurfaceColorAndMaterials) {
    Loaded l =
        load(scene("", std::string("Color [1 0.5 0.25]\n"
                                   "Surface \"plastic\" \"Ka\" 0.1 \"Kd\" 0.2 \"Ks\" 0.9 \"roughness\" 0.05 "
                                   "\"specularcolor\" [1 0 0]\n") +
                           kUnitSquare + kUnitSquare + "Surface \"metal\"\nColor 0 1 0\n" + kUnitSquare));
    ASSERT_EQ(l.scene.patches.size(), 4u);
    // Plastic (used twice) and green metal (the last two patches): one entry per distinct material.
    ASSERT_EQ(l.scene.materials.size(), 2u);
    EXPECT_EQ(l.scene.attributes[0].material, l.scene.attributes[1].material);
    const Material& m = l.scene.materials[l.scene.attributes[0].material];
    EXPECT_EQ(m.type, MaterialType::Plastic);
    expectVec(m.Cs, {1, 0.5f, 0.25f});
    EXPECT_FLOAT_EQ(m.Ka, 0.1f);
    EXPECT_FLOAT_EQ(m.Kd, 0.2f);
    EXPECT_FLOAT_EQ(m.Ks, 0.9f);
    EXPECT_FLOAT_EQ(m.roughness, 0.05f);
    expectVec(m.specularColor, {1, 0, 0});
    const Material& g = l.scene.materials[l.scene.attributes[2].material];
    EXPECT_EQ(g.type, MaterialType::Metal);
    expectVec(g.Cs, {0, 1, 0});
    EXPECT_EQ(g.Ks, defaultMaterial(MaterialType::Metal).Ks);
}

TEST(RibAttributes, EqualMaterialsShareOneEntryAmongMany) {
    // 3,000 patches cycling through 1,000 colours: one material per colour, each patch with its colour's
    // (the index that replaced the linear search per primitive).
    std::string body;
    for (int i = 0; i < 3000; ++i) {
        const int c = i % 1000;
        body += "Color 0 " + std::to_string(c) + " 1\n" + kUnitSquare;
    }
    Loaded l = load(scene("", body));
    ASSERT_EQ(l.scene.patches.size(), 3001u);
    ASSERT_EQ(l.scene.materials.size(), 1000u);  // the last square keeps colour 999's
    for (size_t i = 0; i < 3000; ++i) {
        const Material& m = l.scene.materials[l.scene.attributes[i].material];
        EXPECT_EQ(m.Cs.y, float(i % 1000)) << i;
        EXPECT_EQ(l.scene.attributes[i].material, l.scene.attributes[i % 1000].material) << i;
    }
    EXPECT_EQ(l.scene.attributes[3000].material, l.scene.attributes[2999].material);
}

TEST(RibAttributes, MirrorGlassAndInlineDeclarations) {
    Loaded l = load(scene("", "Surface \"glass\" \"uniform float eta\" 1.33 \"float Kt\" [0.5]"));
    const Material& m = l.scene.materials[l.scene.attributes[0].material];
    EXPECT_EQ(m.type, MaterialType::Glass);
    EXPECT_FLOAT_EQ(m.eta, 1.33f);
    EXPECT_FLOAT_EQ(m.Kt, 0.5f);
    Loaded r = load(scene("", "Surface \"mirror\" \"Kr\" 0.8"));
    EXPECT_EQ(r.scene.materials[0].type, MaterialType::Mirror);
    EXPECT_FLOAT_EQ(r.scene.materials[0].Kr, 0.8f);
}

TEST(RibAttributes, UnknownSurfaceKeepsPreviousWithOneWarning) {
    Loaded l = load(scene("", "Surface \"metal\"\nSurface \"wood2\" \"txtscale\" [0.1]\nSurface \"wood2\""));
    EXPECT_EQ(l.scene.materials[l.scene.attributes[0].material].type, MaterialType::Metal);
    EXPECT_EQ(countWarnings(l.warnings, "wood2"), 1);
}

TEST(RibAttributes, OpacityAndIdentifier) {
    Loaded l = load(scene("", "Opacity [0.5 0.5 0.5]\nAttribute \"identifier\" \"name\" [\"teapot\"]"));
    EXPECT_EQ(countWarnings(l.warnings, "Opacity"), 1);
    expectVec(l.scene.materials[0].Os, {0.5f, 0.5f, 0.5f});
    Loaded o = load(scene("", "Opacity 1 1 1\nAttribute \"displacementbound\" \"sphere\" [2]"));
    EXPECT_EQ(countWarnings(o.warnings, "Opacity"), 0);
    // Supported since issue 12 (docs/textures.md): stored in world units, no warning.
    EXPECT_EQ(countWarnings(o.warnings, "displacementbound"), 0);
    EXPECT_GT(o.scene.attributes[0].displacementBound, 0.f);
}

TEST(RibAttributes, DeclareGivesParameterSizes) {
    // A declared (unused) color parameter must have 3 values.
    Loaded l = load(scene("Declare \"tint\" \"uniform color\"", "Surface \"matte\" \"tint\" [1 0 0]"));
    EXPECT_EQ(countWarnings(l.warnings, "tint"), 1);  // accepted but not supported
    std::string msg =
        expectError(scene("Declare \"tint\" \"uniform color\"", "Surface \"matte\" \"tint\" [1 0]"), 3);
    EXPECT_TRUE(contains(msg, "tint")) << msg;
}

// ---- lights --------------------------------------------------------------------------------------

TEST(RibLights, StandardLightsInWorldSpace) {
    Loaded l = load(scene("LightSource \"pointlight\" 9 \"intensity\" 5",
                          "LightSource \"ambientlight\" 1 \"intensity\" 0.5 \"lightcolor\" [1 0.5 0]\n"
                          "Translate 0 0 10\n"
                          "LightSource \"distantlight\" 2 \"from\" [0 1 0] \"to\" [0 0 0]\n"
                          "LightSource \"pointlight\" \"key\" \"intensity\" 20 \"from\" [1 2 3]\n"
                          "LightSource \"distantlight\" 3"));
    ASSERT_EQ(l.scene.lights.size(), 4u);  // the one before WorldBegin is ignored
    EXPECT_EQ(countWarnings(l.warnings, "before WorldBegin"), 1);
    EXPECT_EQ(l.scene.lights[0].type, LightType::Ambient);
    expectVec(l.scene.lights[0].color, {0.5f, 0.25f, 0});
    EXPECT_EQ(l.scene.lights[1].type, LightType::Distant);
    expectVec(l.scene.lights[1].from, {0, 1, 10});
    expectVec(l.scene.lights[1].to, {0, 0, 10});
    EXPECT_EQ(l.scene.lights[2].type, LightType::Point);
    expectVec(l.scene.lights[2].from, {1, 2, 13});
    expectVec(l.scene.lights[2].color, {20, 20, 20});
    // distantlight defaults: from (0,0,0) to (0,0,1), intensity 1, white.
    expectVec(l.scene.lights[3].from, {0, 0, 10});
    expectVec(l.scene.lights[3].to, {0, 0, 11});
    expectVec(l.scene.lights[3].color, {1, 1, 1});
}

TEST(RibLights, UnsupportedLightAndIlluminateWarn) {
    Loaded l = load(scene("", "LightSource \"arealight\" 1\nIlluminate 1 0\nIlluminate 1 1"));
    EXPECT_TRUE(l.scene.lights.empty());
    EXPECT_EQ(countWarnings(l.warnings, "arealight"), 1);
    EXPECT_EQ(countWarnings(l.warnings, "Illuminate"), 1);
}

// ---- geometry -------------------------------------------------------------------------------------

TEST(RibGeometry, BilinearPatchIsExact) {
    Loaded l = load(scene("", "Patch \"bilinear\" \"P\" [0 0 0  2 0 1  0 3 -1  4 5 6]"));
    ASSERT_EQ(l.scene.patches.size(), 2u);
    const BezierPatch& p = l.scene.patches[0];
    Vec3 c[4] = {{0, 0, 0}, {2, 0, 1}, {0, 3, -1}, {4, 5, 6}};
    for (float u : {0.f, 0.3f, 0.5f, 1.f})
        for (float v : {0.f, 0.25f, 0.8f, 1.f}) {
            Vec3 expect = lerp(lerp(c[0], c[1], u), lerp(c[2], c[3], u), v);
            expectVec(evalPatch(p, u, v), expect, 1e-5f);
        }
}

TEST(RibGeometry, BicubicPatchRowMajor) {
    std::string pts;
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 4; ++u)
            pts += std::to_string(u) + " " + std::to_string(v) + " " + std::to_string(u * v) + " ";
    Loaded l = load(scene("", "Patch \"bicubic\" \"P\" [" + pts + "]"));
    expectVec(l.scene.patches[0].at(2, 1), {2, 1, 2});
    expectVec(l.scene.patches[0].at(1, 3), {1, 3, 3});
}

TEST(RibGeometry, PwWithUnitWeightAccepted) {
    Loaded l = load(scene("", "Patch \"bilinear\" \"Pw\" [0 0 0 1  1 0 0 1  0 1 0 1  1 1 0 1]"));
    ASSERT_EQ(l.scene.patches.size(), 2u);
    expectVec(l.scene.patches[0].at(3, 3), {1, 1, 0});
    std::string msg =
        expectError(scene("", "Patch \"bilinear\" \"Pw\" [0 0 0 1  1 0 0 2  0 1 0 1  1 1 0 1]"), 3);
    EXPECT_TRUE(contains(msg, "rational patches are not supported")) << msg;
}

TEST(RibGeometry, PzIsWarnedAndSkipped) {
    Loaded l = load(scene("", "Patch \"bilinear\" \"Pz\" [0 1 2 3]"));
    EXPECT_EQ(l.scene.patches.size(), 1u);
    EXPECT_EQ(countWarnings(l.warnings, "Pz"), 1);
}

TEST(RibGeometry, BSplinePatchMeshEvaluatesToTheSpline) {
    // A 5 x 4 b-spline mesh (step 1): 2 x 1 patches. Compare with the uniform cubic B-spline.
    std::vector<Vec3> g;
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 5; ++u) g.push_back({float(u), float(v), float((u * 7 + v * 3) % 5) * 0.5f});
    std::string pts;
    for (Vec3 p : g) pts += std::to_string(p.x) + " " + std::to_string(p.y) + " " + std::to_string(p.z) + " ";
    Loaded l = load(scene("",
                          "Basis \"b-spline\" 1 \"b-spline\" 1\nPatchMesh \"bicubic\" 5 \"nonperiodic\" 4 "
                          "\"nonperiodic\" \"P\" [" +
                              pts + "]"));
    ASSERT_EQ(l.scene.patches.size(), 3u);
    auto bspline = [](float t, float w[4]) {
        float s = 1 - t;
        w[0] = s * s * s / 6;
        w[1] = (3 * t * t * t - 6 * t * t + 4) / 6;
        w[2] = (-3 * t * t * t + 3 * t * t + 3 * t + 1) / 6;
        w[3] = t * t * t / 6;
    };
    for (int patch = 0; patch < 2; ++patch)
        for (float u : {0.f, 0.4f, 1.f})
            for (float v : {0.f, 0.7f, 1.f}) {
                float wu[4], wv[4];
                bspline(u, wu);
                bspline(v, wv);
                Vec3 expect;
                for (int j = 0; j < 4; ++j)
                    for (int i = 0; i < 4; ++i) expect += g[j * 5 + patch + i] * (wu[i] * wv[j]);
                expectVec(evalPatch(l.scene.patches[patch], u, v), expect, 1e-4f);
            }
}

TEST(RibGeometry, BasisArrayMatchesNamedBasis) {
    // RiBSplineBasis as written in a RIB file (row by row) must equal the named "b-spline".
    std::string pts;
    for (int k = 0; k < 16; ++k)
        pts += std::to_string(k % 4) + " " + std::to_string(k / 4) + " " + std::to_string(k % 3) + " ";
    std::string m =
        "[-0.16666667 0.5 -0.5 0.16666667  0.5 -1 0.5 0  -0.5 0 0.5 0  0.16666667 0.66666667 0.16666667 0]";
    Loaded named =
        load(scene("", "Basis \"b-spline\" 1 \"b-spline\" 1\nPatch \"bicubic\" \"P\" [" + pts + "]"));
    Loaded array = load(scene("", "Basis " + m + " 1 " + m + " 1\nPatch \"bicubic\" \"P\" [" + pts + "]"));
    for (int k = 0; k < 16; ++k) expectVec(named.scene.patches[0].cp[k], array.scene.patches[0].cp[k], 1e-5f);
}

TEST(RibGeometry, PatchMeshCountsAndWrapping) {
    // Bilinear 3 x 2 nonperiodic: 2 patches; periodic in u: 3 patches, the last wraps to column 0.
    std::string pts = "[0 0 0  1 0 0  2 0 0  0 1 0  1 1 0  2 1 0]";
    Loaded np = load(scene("", "PatchMesh \"bilinear\" 3 \"nonperiodic\" 2 \"nonperiodic\" \"P\" " + pts));
    EXPECT_EQ(np.scene.patches.size(), 3u);
    Loaded per = load(scene("", "PatchMesh \"bilinear\" 3 \"periodic\" 2 \"nonperiodic\" \"P\" " + pts));
    ASSERT_EQ(per.scene.patches.size(), 4u);
    expectVec(per.scene.patches[2].at(0, 0), {2, 0, 0});
    expectVec(per.scene.patches[2].at(3, 0), {0, 0, 0});
    // Bicubic Bezier (step 3): 7 nonperiodic points give 2 patches; 6 periodic give 2.
    std::string row7, row6;
    for (int i = 0; i < 7; ++i) row7 += std::to_string(i) + " 0 0 ";
    for (int i = 0; i < 6; ++i) row6 += std::to_string(i) + " 0 0 ";
    std::string p7, p6;
    for (int v = 0; v < 4; ++v) p7 += row7, p6 += row6;
    EXPECT_EQ(load(scene("", "PatchMesh \"bicubic\" 7 \"nonperiodic\" 4 \"nonperiodic\" \"P\" [" + p7 + "]"))
                  .scene.patches.size(),
              3u);
    EXPECT_EQ(load(scene("", "PatchMesh \"bicubic\" 6 \"periodic\" 4 \"nonperiodic\" \"P\" [" + p6 + "]"))
                  .scene.patches.size(),
              3u);
}

TEST(RibGeometry, PatchMeshInvalidCountsAreErrors) {
    std::string msg =
        expectError(scene("", "PatchMesh \"bicubic\" 5 \"nonperiodic\" 4 \"nonperiodic\" \"P\" [0 0 0]"), 3);
    EXPECT_TRUE(contains(msg, "4 + k * 3")) << msg;
    msg = expectError(
        scene("", "PatchMesh \"bilinear\" 2 \"nonperiodic\" 2 \"nonperiodic\" \"P\" [0 0 0 1 0 0 0 1 0]"), 3);
    EXPECT_TRUE(contains(msg, "needs 12 values")) << msg;
}

TEST(RibGeometry, PeriodicTestFromAqsis) {
    std::string path =
        std::string(TESSERA_SHARED_DATA) + "/rib/aqsis-regression/RIBs/Primitives/periodic_test.rib";
    if (!fs::exists(path)) GTEST_SKIP() << "shared data not found: " << path;
    std::vector<std::string> warnings;
    Scene s = loadScene(path, [&](const std::string& w) { warnings.push_back(w); });
    // Two bilinear meshes (4 periodic x 2 and 2 x 4 periodic: 4 patches each) and two bicubic
    // Bezier meshes (12 periodic x 4 and 4 x 12 periodic, step 3: 4 patches each).
    EXPECT_EQ(s.patches.size(), 16u);
    EXPECT_EQ(s.objectCount, 3u);  // the bilinear meshes in the world block, each bicubic in its own block
    int bicubicPatches = 0;
    for (const PatchAttributes& a : s.attributes) bicubicPatches += a.object >= 1;
    EXPECT_EQ(bicubicPatches, 8);
    EXPECT_EQ(s.camera.width, 200);
    EXPECT_EQ(s.lights.size(), 3u);
    EXPECT_EQ(s.attributes[0].shadingRate, 2.f);
    EXPECT_EQ(countWarnings(warnings, "limits"), 1);
}

TEST(RibGeometry, GeometryOutsideWorldIsAnError) {
    std::string msg = expectError(std::string("Format 10 10 1\n") + kUnitSquare, 2);
    EXPECT_TRUE(contains(msg, "outside WorldBegin")) << msg;
}

// ---- whole files ---------------------------------------------------------------------------------

TEST(RibFiles, UtahTeapotRib) {
    std::string path = std::string(TESSERA_SHARED_DATA) + "/rib/ribtools/uteapot.rib";
    if (!fs::exists(path)) GTEST_SKIP() << "shared data not found: " << path;
    std::vector<std::string> warnings;
    Scene s = loadScene(path, [&](const std::string& w) { warnings.push_back(w); });
    EXPECT_EQ(s.patches.size(), 32u);
    EXPECT_EQ(s.lights.size(), 4u);
    EXPECT_EQ(s.camera.width, 640);
    EXPECT_EQ(s.camera.height, 400);
    EXPECT_EQ(s.camera.fovDegrees, 25.f);
    EXPECT_EQ(s.image.displayName, "uteapot.tif");
    EXPECT_EQ(countWarnings(warnings, "'set'"), 1);
    EXPECT_EQ(countWarnings(warnings, "wood2"), 1);
    // The stray `set -x` is reported at line 1.
    EXPECT_EQ(warnings[0].rfind(path + ":1: warning:", 0), 0u) << warnings[0];
    // "wood2" is unsupported, so the plastic surface before it stays in effect.
    EXPECT_EQ(s.materials[s.attributes[0].material].type, MaterialType::Plastic);
    Bounds3 b = s.worldBounds();
    expectVec(b.lo, {-120, -80, 0}, 1e-3f);
    expectVec(b.hi, {141, 80, 120}, 1e-3f);
}

TEST(RibFiles, ReadArchiveRelativePaths) {
    fs::path d = testDir();
    writeFile(d / "parts" / "square.rib", "ReadArchive \"deeper/moved.rib\"\n");
    writeFile(d / "parts" / "deeper" / "moved.rib", std::string("Translate 0 0 4\n") + kUnitSquare);
    std::string top = writeFile(d / "top.rib", "WorldBegin\nReadArchive \"parts/square.rib\"\nWorldEnd\n");
    Scene s = loadScene(top, {});
    ASSERT_EQ(s.patches.size(), 1u);
    expectVec(s.patches[0].at(0, 0), {0, 0, 4});
}

TEST(RibFiles, ErrorInsideArchiveNamesTheArchive) {
    fs::path d = testDir();
    std::string inc = writeFile(d / "inc" / "bad.rib", "Translate 1 2\n\nTranslate 1 2 3 4\n");
    std::string top = writeFile(d / "top.rib", "WorldBegin\nReadArchive \"inc/bad.rib\"\nWorldEnd\n");
    std::string msg = errorOfFile(top);
    std::string expectFile = (d / "inc" / "bad.rib").string();
    EXPECT_EQ(msg.rfind(expectFile + ":1: error:", 0), 0u) << msg;
}

// Runs `body` with archives recorded on their first read (the default) and on their second (the path
// of archives past the first-read budget).
template <class Body>
void withEitherRecording(Body&& body) {
    for (const size_t bytes : {size_t(64) << 20, size_t(0)}) {
        struct Restore {
            size_t bytes;
            ~Restore() { setArchiveFirstReadRecordBytes(bytes); }
        } restore{setArchiveFirstReadRecordBytes(bytes)};
        SCOPED_TRACE(bytes ? "archives recorded on their first read"
                           : "archives recorded on their second read");
        body();
    }
}

TEST(RibFiles, ArchiveReadAgainIsReplayedAsRead) {
    withEitherRecording([&] {
        // From its second read on, an archive is replayed from its recorded requests (not lexed again): the
        // same patches as the text written out in full, and errors that only its fourth use meets still name
        // the archive and its line.
        fs::path d = testDir();
        const std::string part = std::string("# a square\n") + kUnitSquare + "AttributeEnd\n";
        writeFile(d / "part.rib", part);
        std::string byArchive = "WorldBegin\n", inline_ = "WorldBegin\n";
        for (int i = 0; i < 4; ++i) {
            const std::string open = "AttributeBegin\nTranslate " + std::to_string(i) + " 0.5 0\n";
            byArchive += open + "ReadArchive \"part.rib\"\n";
            inline_ += open + part;
        }
        const Scene a = loadScene(writeFile(d / "archive.rib", byArchive + "WorldEnd\n"), {});
        const Scene b = loadScene(writeFile(d / "inline.rib", inline_ + "WorldEnd\n"), {});
        ASSERT_EQ(a.patches.size(), 4u);
        ASSERT_EQ(b.patches.size(), 4u);
        for (size_t i = 0; i < 4; ++i)
            for (int k = 0; k < 16; ++k) {
                EXPECT_EQ(a.patches[i].cp[k].x, b.patches[i].cp[k].x);
                EXPECT_EQ(a.patches[i].cp[k].y, b.patches[i].cp[k].y);
                EXPECT_EQ(a.patches[i].cp[k].z, b.patches[i].cp[k].z);
            }
        // A fifth read closes an attribute block that is not open: the replayed tokens' file and line.
        const std::string msg =
            errorOfFile(writeFile(d / "bad.rib", byArchive + "ReadArchive \"part.rib\"\nWorldEnd\n"));
        const int squareLines = int(std::count(kUnitSquare, kUnitSquare + std::strlen(kUnitSquare), '\n'));
        EXPECT_EQ(
            msg.rfind((d / "part.rib").string() + ":" + std::to_string(2 + squareLines) + ": error:", 0), 0u)
            << msg;
        EXPECT_TRUE(contains(msg, "AttributeEnd")) << msg;
    });
}

TEST(RibFiles, ReplayedPrimitivesReuseTheirShapeOnlyUnderTheSameState) {
    withEitherRecording([&] {
        // From an archive's first replay its primitives keep the shape they were read as, reused while the
        // declarations, the basis and the texture coordinates are the same. Every read must give the patches
        // of the text written out in full: after a Basis change (a B-spline patch converts to other Bezier
        // points), a TextureCoordinates change and a Declare; and when a replayed archive reads an archive
        // for the first time (the search path changed), whose requests are parsed, not replayed: two patches
        // there must not be taken for one.
        fs::path d = testDir();
        auto curved = [](float lift) {
            std::string p = "Patch \"bicubic\" \"P\" [";
            for (int j = 0; j < 4; ++j)
                for (int i = 0; i < 4; ++i)
                    p += " " + std::to_string(i) + " " + std::to_string(j) + " " +
                         std::to_string(lift + 0.25f * float(i * j % 3));
            return p + " ]\n";
        };
        writeFile(d / "a" / "inner.rib", curved(1.f) + curved(2.f));
        writeFile(d / "b" / "inner.rib", curved(3.f) + curved(4.f));
        const std::string outer = std::string("ReadArchive \"inner.rib\"\n") + curved(5.f);
        writeFile(d / "outer.rib", outer);
        auto search = [&](const char* dir) {
            return "Option \"searchpath\" \"archive\" [\"" + (d / dir).string() + ":" + d.string() + "\"]\n";
        };
        const std::string searchA = search("a"), searchB = search("b");
        // Between reads: what the state changes to before each (an empty string: nothing).
        const std::vector<std::string> before = {searchA,
                                                 "",
                                                 "",
                                                 "",
                                                 "Basis \"b-spline\" 1 \"b-spline\" 1\n",
                                                 "",
                                                 "TextureCoordinates 0 0 2 0 0 2 2 2\n",
                                                 "Declare \"P\" \"vertex point\"\n",
                                                 searchB,
                                                 ""};
        std::string byArchive = "WorldBegin\n", inline_ = "WorldBegin\n";
        const std::string innerA = curved(1.f) + curved(2.f), innerB = curved(3.f) + curved(4.f);
        bool inB = false;
        for (const std::string& b : before) {
            byArchive += b + "ReadArchive \"outer.rib\"\n";
            inB = inB || b == searchB;
            inline_ += (b.rfind("Option", 0) == 0 ? "" : b) + (inB ? innerB : innerA) + curved(5.f);
        }
        const Scene a = loadScene(writeFile(d / "archive.rib", byArchive + "WorldEnd\n"), {});
        const Scene e = loadScene(writeFile(d / "inline.rib", inline_ + "WorldEnd\n"), {});
        ASSERT_EQ(a.patches.size(), 3 * before.size());
        ASSERT_EQ(e.patches.size(), a.patches.size());
        int differing = 0;
        for (size_t i = 0; i < a.patches.size(); ++i) {
            for (int k = 0; k < 16; ++k) {
                EXPECT_EQ(a.patches[i].cp[k].x, e.patches[i].cp[k].x) << "patch " << i;
                EXPECT_EQ(a.patches[i].cp[k].y, e.patches[i].cp[k].y) << "patch " << i;
                EXPECT_EQ(a.patches[i].cp[k].z, e.patches[i].cp[k].z) << "patch " << i;
            }
            const PatchTexCoords ta = texCoordsOf(a, i), te = texCoordsOf(e, i);
            for (int k = 0; k < 4; ++k) {
                EXPECT_EQ(ta.st[k].x, te.st[k].x) << "patch " << i;
                EXPECT_EQ(ta.st[k].y, te.st[k].y) << "patch " << i;
            }
            differing += i >= 3 && a.patches[i].cp[5].z != a.patches[i - 3].cp[5].z;
        }
        EXPECT_GT(differing, 0);  // the state changes did change the shapes read
    });
}

TEST(RibFiles, ArchiveRecordedWhileSkippingAFrameIsCollectedStrictlyWhenLoaded) {
    withEitherRecording([&] {
        // Frames not loaded are skipped with their arguments collected tolerantly. An archive holding a
        // frame, read three times while loading the third frame, is recorded on its second read, inside a
        // skipped frame: its third read, the frame loaded, must meet the stray ']' as the text does (a replay
        // of the tolerantly collected requests would drop it silently), and without it load the frame's
        // square.
        fs::path d = testDir();
        const std::string top =
            "ReadArchive \"frame.rib\"\nReadArchive \"frame.rib\"\nReadArchive \"frame.rib\"\n";
        auto frame = [&](const std::string& translate) {
            return "FrameBegin 1\nWorldBegin\n" + translate + "\n" + kUnitSquare + "WorldEnd\nFrameEnd\n";
        };
        writeFile(d / "frame.rib", frame("Translate 1 2 ] 3"));
        const std::string bad = writeFile(d / "top.rib", top);
        try {
            Scene s;
            readRibFrame(bad, 2, s, {});
            ADD_FAILURE() << "the third read loaded the frame without meeting the stray ']'";
        } catch (const InputError& e) {
            const std::string msg = e.what();
            EXPECT_EQ(msg.rfind((d / "frame.rib").string() + ":3: error:", 0), 0u) << msg;
            EXPECT_TRUE(contains(msg, "Translate")) << msg;
        }
        writeFile(d / "frame.rib", frame("Translate 1 2 3"));
        Scene s;
        readRibFrame(writeFile(d / "good.rib", top), 2, s, {});
        ASSERT_EQ(s.patches.size(), 1u);
        expectVec(s.patches[0].at(0, 0), {1, 2, 3});
    });
}

TEST(RibFiles, UnreadableArchiveIsAnErrorAtTheReadArchiveLine) {
    withEitherRecording([&] {
        // An archive that exists but cannot be read (a gzip header over garbage): the error names the
        // including file and the ReadArchive line, not the archive; also after another archive's replays
        // (which must hand the reader back to the including file).
        fs::path d = testDir();
        writeFile(d / "part.rib", std::string(kUnitSquare));
        writeFile(d / "bad.rib", std::string("\x1f\x8b") + " not a gzip stream");
        for (const char* text : {"WorldBegin\nReadArchive \"bad.rib\"\nWorldEnd\n",
                                 "WorldBegin\nReadArchive \"part.rib\"\nReadArchive \"part.rib\"\n"
                                 "ReadArchive \"part.rib\"\nReadArchive \"bad.rib\"\nWorldEnd\n"}) {
            const std::string top = writeFile(d / "top.rib", text);
            const std::string msg = errorOfFile(top);
            const int line =
                int(std::count(text, text + std::strlen(text), '\n'));  // the line before WorldEnd
            EXPECT_EQ(msg.rfind(top + ":" + std::to_string(line - 1) + ": error:", 0), 0u) << msg;
            EXPECT_TRUE(contains(msg, "cannot read")) << msg;
        }
    });
}

TEST(RibFiles, RecursiveArchiveIsAnError) {
    fs::path d = testDir();
    std::string loop = writeFile(d / "loop.rib", "# includes itself\nReadArchive \"loop.rib\"\n");
    std::string top = writeFile(d / "top.rib", "WorldBegin\nReadArchive \"loop.rib\"\nWorldEnd\n");
    std::string msg = errorOfFile(top);
    EXPECT_TRUE(contains(msg, "nested more than")) << msg;
    EXPECT_EQ(msg.rfind(loop + ":2: error:", 0), 0u) << msg;
}

TEST(RibFiles, GzippedRib) {
    std::string text = scene("Format 123 45 1", "");
    std::string path = (testDir() / "scene.rib.gz").string();
    gzFile f = gzopen(path.c_str(), "wb");
    ASSERT_NE(f, nullptr);
    ASSERT_EQ(gzwrite(f, text.data(), unsigned(text.size())), int(text.size()));
    gzclose(f);
    Scene s = loadScene(path, {});
    EXPECT_EQ(s.camera.width, 123);
    EXPECT_EQ(s.patches.size(), 1u);
}

TEST(RibFiles, UnknownRequestsWarnOncePerName) {
    Loaded l = load(scene("set -x\nAtmosphere \"fog\"\nAtmosphere \"fog\"",
                          "Points \"P\" [0 0 0]\nPoints \"P\" [1 1 1]"));
    EXPECT_EQ(countWarnings(l.warnings, "'Atmosphere'"), 1);
    EXPECT_EQ(countWarnings(l.warnings, "'Points'"), 1);
    EXPECT_EQ(countWarnings(l.warnings, "'set'"), 1);
    EXPECT_EQ(l.scene.patches.size(), 1u);
}

// ---- errors: each reports "<file>:<line>: error:" ------------------------------------------------

TEST(RibErrors, UnknownToken) {
    std::string msg = expectError("Format 10 10 1\n\n@@@\n", 3);
    EXPECT_TRUE(contains(msg, "@@@")) << msg;
    expectError(scene("", "Translate 1 2 3 }"), 3);
}

TEST(RibErrors, WrongArraySize) {
    std::string msg = expectError(scene("", "Patch \"bicubic\" \"P\" [0 0 0 1 1 1]"), 3);
    EXPECT_TRUE(contains(msg, "48")) << msg;
    expectError(scene("", "Color [1 0]"), 3);
    expectError(scene("", "Surface \"plastic\"\n  \"specularcolor\" [1 0 0 0]"), 4);
}

TEST(RibErrors, MissingParameterValue) {
    std::string msg = expectError(scene("", "Surface \"plastic\" \"Kd\"\n"), 3);
    EXPECT_TRUE(contains(msg, "missing value for parameter \"Kd\"")) << msg;
}

TEST(RibErrors, UnterminatedString) {
    std::string msg = expectError("Format 10 10 1\nDisplay \"out.tif\" \"file\" \"rgb\nWorldBegin\n", 2);
    EXPECT_TRUE(contains(msg, "unterminated string")) << msg;
    expectError("WorldBegin\n\nSurface \"matte", 3);
}

TEST(RibErrors, UnbalancedEnds) {
    std::string msg = expectError(scene("", "AttributeEnd"), 3);
    EXPECT_TRUE(contains(msg, "AttributeEnd")) << msg;
    expectError(scene("", "TransformBegin\nAttributeEnd"), 4);
    expectError("WorldEnd\n", 1);
}

TEST(RibErrors, EndOfFileInsideBlock) {
    std::string msg = expectError(std::string("WorldBegin\nAttributeBegin\n") + kUnitSquare + "\n# end\n", 5);
    EXPECT_TRUE(contains(msg, "AttributeBegin")) << msg;
    expectError("WorldBegin\nPatch \"bilinear\" \"P\" [0 0 0 1 0 0\n0 1 0 1 1 0", 3);  // inside an array
}

TEST(RibErrors, NaNNumber) {
    std::string msg = expectError(scene("", "Translate 1 nan 0"), 3);
    EXPECT_TRUE(contains(msg, "nan")) << msg;
    expectError(scene("Format 10 10 1\nScreenWindow -1 1 -inf 1", ""), 2);
    expectError(scene("", "Scale 1e999 1 1"), 3);
}

TEST(RibErrors, MissingReadArchiveFile) {
    std::string msg = expectError("WorldBegin\n\nReadArchive \"no/such/file.rib\"\nWorldEnd\n", 3);
    EXPECT_TRUE(contains(msg, "file.rib")) << msg;
}

TEST(RibErrors, EmptyFile) {
    std::string msg = expectError("", 1);
    EXPECT_TRUE(contains(msg, "empty")) << msg;
    msg = expectError("# only a comment\nFormat 10 10 1\n", 2);
    EXPECT_TRUE(contains(msg, "no geometry")) << msg;
}

TEST(RibErrors, MissingFile) {
    std::string path = (testDir() / "missing.rib").string();
    std::string msg = errorOfFile(path);
    EXPECT_EQ(msg.rfind(path + ": error:", 0), 0u) << msg;
}

TEST(RibErrors, WrongArgumentTypesAndCounts) {
    expectError(scene("Format 10 \"ten\" 1", ""), 1);
    expectError(scene("", "Translate 1 2"), 3);
    expectError(scene("", "Sides 3"), 3);
    expectError(scene("", "Basis \"bezier\" 3 \"nurbs\" 3"), 3);
    expectError(scene("", "Orientation \"up\""), 3);
    expectError(scene("", "Surface \"plastic\" \"Kd\" \"high\""), 3);
    expectError(scene("", "Surface \"plastic\" 0.5"), 3);
    expectError(scene("", "Patch \"biquadratic\" \"P\" [0 0 0]"), 3);
}

// ---- shader parameter tables (src/io/rib_shaders.h) -----------------------------------------------
// These iterate the tables themselves, so a new row is tested without touching this file.

namespace {

// A RIB value for a table row: `v` for floats, (v, v + 1/64, v + 2/64) for colours and points.
std::string ribValue(rib::ShaderParamType type, double v) {
    char buf[96];
    if (type == rib::ShaderParamType::Float)
        std::snprintf(buf, sizeof buf, "[%.17g]", v);
    else
        std::snprintf(buf, sizeof buf, "[%.17g %.17g %.17g]", v, v + 1 / 64., v + 2 / 64.);
    return buf;
}

// Sets the field a row names in `target` to the value ribValue() wrote.
template <class Target>
void setField(const rib::ShaderParam<Target>& row, double v, Target& target) {
    if (row.type == rib::ShaderParamType::Float)
        target.*(row.scalar) = float(v);
    else
        target.*(row.triple) = {float(v), float(v + 1 / 64.), float(v + 2 / 64.)};
}

bool sameMaterialFields(const Material& a, const Material& b) {
    return a.type == b.type && a.Cs == b.Cs && a.Os == b.Os && a.Ka == b.Ka && a.Kd == b.Kd && a.Ks == b.Ks &&
           a.roughness == b.roughness && a.specularColor == b.specularColor && a.Kr == b.Kr && a.Kt == b.Kt &&
           a.eta == b.eta && a.glossSamples == b.glossSamples && a.spread == b.spread;
}

}  // namespace

TEST(RibShaderTables, EverySurfaceRowSetsTheFieldItNames) {
    ASSERT_FALSE(rib::surfaceShaders().empty());
    for (const rib::SurfaceShader& shader : rib::surfaceShaders()) {
        for (size_t k = 0; k < shader.params.size(); ++k) {
            const rib::ShaderParam<Material>& row = shader.params[k];
            // Distinct from every default; glossy's "samples" is a count of at least 1.
            const double v = std::string(row.name) == "samples" ? 8.0 + double(k) : 0.3 + 0.125 * double(k);
            SCOPED_TRACE(std::string(shader.name) + " " + row.name);
            Loaded l = load(scene("", std::string("Surface \"") + shader.name + "\" \"" + row.name + "\" " +
                                          ribValue(row.type, v)));
            EXPECT_EQ(countWarnings(l.warnings, std::string("\"") + row.name + "\""), 0);
            Material expected = defaultMaterial(shader.type);
            setField(row, v, expected);
            ASSERT_EQ(l.scene.materials.size(), 1u);
            const Material& got = l.scene.materials[0];
            EXPECT_TRUE(sameMaterialFields(got, expected)) << "the value did not arrive in (only) its field";
        }
    }
}

TEST(RibShaderTables, EveryLightRowSetsTheFieldItNames) {
    ASSERT_FALSE(rib::lightShaders().empty());
    for (const rib::LightShader& shader : rib::lightShaders()) {
        for (size_t k = 0; k < shader.params.size(); ++k) {
            const rib::ShaderParam<rib::LightShaderParams>& row = shader.params[k];
            // "samples" (area lights) is a count of at least 1.
            const double v = std::string(row.name) == "samples" ? 8.0 + double(k) : 0.3 + 0.125 * double(k);
            SCOPED_TRACE(std::string(shader.name) + " " + row.name);
            const char* request = shader.type == LightType::Area ? "AreaLightSource \"" : "LightSource \"";
            Loaded l = load(scene("", std::string(request) + shader.name + "\" 1 \"" + row.name + "\" " +
                                          ribValue(row.type, v)));
            EXPECT_EQ(countWarnings(l.warnings, std::string("\"") + row.name + "\""), 0);
            rib::LightShaderParams expected;
            setField(row, v, expected);
            ASSERT_EQ(l.scene.lights.size(), 1u);
            const Light& got = l.scene.lights[0];
            // The world's CTM is the identity here, so "from" and "to" arrive unchanged.
            EXPECT_EQ(got.type, shader.type);
            EXPECT_EQ(got.color, expected.lightcolor * expected.intensity);
            EXPECT_EQ(got.from, expected.from);
            EXPECT_EQ(got.to, expected.to);
            EXPECT_EQ(got.samples, int(expected.samples));
        }
    }
}

// An oracle independent of the tables: the RIB writer names each Material field itself. A material
// with a distinct value in every field, written and read back, must give each row's field its value.
TEST(RibShaderTables, RowsAgreeWithTheRibWriter) {
    for (const rib::SurfaceShader& shader : rib::surfaceShaders()) {
        SCOPED_TRACE(shader.name);
        Scene out;
        Material m = defaultMaterial(shader.type);
        m.Ka = 0.11f, m.Kd = 0.22f, m.Ks = 0.33f, m.roughness = 0.044f, m.specularColor = {0.5f, 0.6f, 0.7f};
        m.Kr = 0.55f, m.Kt = 0.66f, m.eta = 1.77f;
        out.materials.push_back(m);
        out.lights.push_back(Light{});
        BezierPatch b;
        for (int k = 0; k < 16; ++k) b.cp[k] = {float(k % 4), float(k / 4), 0};
        out.patches.push_back(b);
        out.attributes.push_back(PatchAttributes{});
        out.objectCount = 1;
        std::ostringstream text;
        writeRib(out, text);
        Scene in;
        readRibText(text.str(), "written.rib", in, [](const std::string&) {});
        ASSERT_EQ(in.materials.size(), 1u);
        ASSERT_EQ(in.materials[0].type, shader.type);
        int checked = 0;
        for (const rib::ShaderParam<Material>& row : shader.params) {
            if (!contains(text.str(), std::string("\"") + row.name + "\"")) continue;  // not written
            ++checked;
            if (row.type == rib::ShaderParamType::Float)
                EXPECT_EQ(in.materials[0].*(row.scalar), m.*(row.scalar)) << row.name;
            else
                EXPECT_EQ(in.materials[0].*(row.triple), m.*(row.triple)) << row.name;
        }
        EXPECT_TRUE(checked > 0 || shader.type == MaterialType::Constant);
    }
}

TEST(RibShaderTables, WrongTypeOrSizeGivesTheDeclarationError) {
    for (const rib::SurfaceShader& shader : rib::surfaceShaders())
        for (const rib::ShaderParam<Material>& row : shader.params) {
            SCOPED_TRACE(std::string(shader.name) + " " + row.name);
            const std::string type = rib::declarationOf(row.type).type;
            std::string head = std::string("Surface \"") + shader.name + "\" \"" + row.name + "\" ";
            std::string msg = expectError(scene("", head + "\"x\""), 3);
            EXPECT_TRUE(contains(msg, std::string("Surface: parameter \"") + row.name + "\" (" + type +
                                          ") needs numbers, found string \"x\""))
                << msg;
            const int n = row.type == rib::ShaderParamType::Float ? 1 : 3;
            msg = expectError(scene("", head + "[1 2 3 4]"), 3);
            EXPECT_TRUE(contains(msg, std::string("Surface: parameter \"") + row.name + "\" needs " +
                                          std::to_string(n) + " values (1 x uniform " + type + "), got 4"))
                << msg;
        }
    for (const rib::LightShader& shader : rib::lightShaders())
        for (const rib::ShaderParam<rib::LightShaderParams>& row : shader.params) {
            SCOPED_TRACE(std::string(shader.name) + " " + row.name);
            const std::string type = rib::declarationOf(row.type).type;
            std::string msg = expectError(
                scene("", std::string("LightSource \"") + shader.name + "\" 1\n  \"" + row.name + "\" \"x\""),
                4);
            EXPECT_TRUE(contains(msg, std::string("LightSource: parameter \"") + row.name + "\" (" + type +
                                          ") needs numbers, found string \"x\""))
                << msg;
        }
}

TEST(RibShaderTables, ParametersWithoutARowWarnOnceAndAreIgnored) {
    // "to" only aims distant lights; "from" has no meaning for an ambient light (RI spec appendix A).
    Loaded l = load(scene("",
                          "LightSource \"ambientlight\" 1 \"from\" [1 2 3] \"to\" [1 1 1]\n"
                          "LightSource \"pointlight\" 2 \"to\" [1 1 1]\n"
                          "Surface \"matte\" \"bumpiness\" 2 \"uniform float fuzz\" 1\n"
                          "Surface \"matte\" \"bumpiness\" 3"));
    EXPECT_EQ(countWarnings(l.warnings, "LightSource \"ambientlight\": parameter \"from\" is not supported"),
              1);
    EXPECT_EQ(countWarnings(l.warnings, "LightSource \"pointlight\": parameter \"to\" is not supported"), 1);
    EXPECT_EQ(countWarnings(l.warnings, "Surface \"matte\": parameter \"bumpiness\" is not declared"), 1);
    EXPECT_EQ(countWarnings(l.warnings, "Surface \"matte\": parameter \"fuzz\" is not supported"), 1);
    ASSERT_EQ(l.scene.lights.size(), 2u);
    EXPECT_EQ(l.scene.lights[0].from, (Vec3{0, 0, 0}));
    EXPECT_EQ(l.scene.lights[1].to, (Vec3{0, 0, 1}));
    EXPECT_TRUE(sameMaterialFields(l.scene.materials[0], defaultMaterial(MaterialType::Matte)));
}

TEST(RibShaderTables, DeclareOverridesARowsDeclaration) {
    // Declare replaces the predeclared type: the size check follows it, the row then wants 1 number.
    std::string msg =
        expectError(scene("Declare \"Kd\" \"uniform color\"", "Surface \"plastic\" \"Kd\" [1 2 3]"), 3);
    EXPECT_TRUE(contains(msg, "Surface: parameter \"Kd\" needs 1 number, found an array of 3 numbers"))
        << msg;
    msg = expectError(scene("Declare \"Kd\" \"uniform color\"", "Surface \"plastic\" \"Kd\" [1]"), 3);
    EXPECT_TRUE(contains(msg, "Surface: parameter \"Kd\" needs 3 values (1 x uniform color), got 1")) << msg;
}

TEST(RibShaderTables, ShaderNamesAndRowsAreUnique) {
    std::set<std::string> surfaces, lights;
    for (const rib::SurfaceShader& s : rib::surfaceShaders()) {
        EXPECT_TRUE(surfaces.insert(s.name).second) << s.name;
        std::set<std::string> rows;
        for (const auto& row : s.params)
            EXPECT_TRUE(rows.insert(row.name).second) << s.name << " " << row.name;
    }
    for (const rib::LightShader& s : rib::lightShaders()) {
        EXPECT_TRUE(lights.insert(s.name).second) << s.name;
        std::set<std::string> rows;
        for (const auto& row : s.params)
            EXPECT_TRUE(rows.insert(row.name).second) << s.name << " " << row.name;
    }
}

// The shipped scenes parse to the same content as before the reader was split into files
// (counts from scenes/README.md; lights and materials as loaded by the original reader; objects one per
// attribute block).
TEST(RibFiles, ShippedScenesKeepTheirContent) {
    struct Expect {
        const char* name;
        size_t patches, objects, lights, materials;
    };
    const Expect cases[] = {
        {"teapot", 32, 7, 4, 1},    {"killeroo", 11532, 1, 3, 1},  {"killeroo2", 23064, 2, 3, 2},
        {"bigguy", 23200, 1, 3, 1}, {"bigguy_box", 3575, 6, 2, 4},  // bigguy: OpenSubdiv, level 2
    };
    for (const Expect& c : cases) {
        SCOPED_TRACE(c.name);
        Scene s = loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/" + c.name + ".rib",
                            [](const std::string&) {});
        EXPECT_EQ(s.patches.size(), c.patches);
        EXPECT_EQ(s.attributes.size(), c.patches);
        EXPECT_EQ(s.objectCount, c.objects);
        EXPECT_EQ(s.lights.size(), c.lights);
        EXPECT_EQ(s.materials.size(), c.materials);
    }
}

// The RIB parameter tables and the shader registry name the same shaders with the same kinds, so a shader
// registered for the engines can be used from RIB and vice versa.
TEST(RibShaderTables, MatchTheShaderRegistry) {
    for (const SurfaceShaderInfo& s : tessera::surfaceShaders()) {
        const rib::SurfaceShader* t = rib::findSurfaceShader(s.name);
        ASSERT_NE(t, nullptr) << s.name;
        EXPECT_EQ(t->type, s.type) << s.name;
    }
    for (const rib::SurfaceShader& t : rib::surfaceShaders())
        EXPECT_NE(tessera::findSurfaceShader(t.name), nullptr);
    for (const LightShaderInfo& l : tessera::lightShaders()) {
        const rib::LightShader* t = rib::findLightShader(l.name);
        ASSERT_NE(t, nullptr) << l.name;
        EXPECT_EQ(t->type, l.type) << l.name;
    }
    for (const rib::LightShader& t : rib::lightShaders())
        EXPECT_NE(tessera::findLightShader(t.name), nullptr);
}

}  // namespace tessera::test::rib_tests
