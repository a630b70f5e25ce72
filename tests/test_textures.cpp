// Textures (issue 12): OpenImageIO lookups against analytic values (a constant texture, a checker's filtered
// value, a gradient's bilinear value), RI s, t through every Reyes split and the ray tracer's hit (u,v) on
// Patch, PatchMesh and NuPatch, paintedplastic in both engines, MakeTexture, the search path, and missing
// or unreadable files as errors naming the line and the file.
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "film/image_compare.h"
#include "render/render.h"
#include "rib_test_util.h"
#include "shading/texture.h"

namespace tessera::test::textures_tests {

namespace {

// Writes a float image (channels interleaved, row 0 at the top) with OpenImageIO.
std::string writeImage(const std::string& name, int w, int h, int channels, const std::vector<float>& px) {
    const std::string path = (testScratchDir() / name).string();
    auto out = OIIO::ImageOutput::create(path);
    EXPECT_TRUE(out) << OIIO::geterror();
    OIIO::ImageSpec spec(w, h, channels, OIIO::TypeFloat);
    EXPECT_TRUE(out->open(path, spec));
    EXPECT_TRUE(out->write_image(OIIO::TypeFloat, px.data()));
    out->close();
    return path;
}

// A checker of `squares` x `squares` squares of `texels` texels each, 0 and 1 (one channel).
std::string writeChecker(const std::string& name, int squares, int texels) {
    const int n = squares * texels;
    std::vector<float> px(size_t(n) * n);
    for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) px[size_t(y) * n + x] = float(((x / texels) + (y / texels)) & 1);
    return writeImage(name, n, n, 1, px);
}

// R = s, G = t at texel centres ((i + 0.5) / n), B = 0: a bilinear lookup returns (s, t) exactly.
std::string writeGradient(const std::string& name, int n) {
    std::vector<float> px(size_t(n) * n * 3);
    for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
            float* p = &px[(size_t(y) * n + x) * 3];
            p[0] = (x + 0.5f) / n, p[1] = (y + 0.5f) / n, p[2] = 0.f;
        }
    return writeImage(name, n, n, 3, px);
}

// An orthographic view of [-1,1]^2 at z = 5 lit by an ambient light of 1 only: a paintedplastic surface with
// Ka 1 and Kd = Ks = 0 shows Cs * texture exactly.
std::string viewRib(int res, const std::string& surface, const std::string& geometry) {
    return "Format " + std::to_string(res) + " " + std::to_string(res) +
           " 1\nProjection \"orthographic\"\nScreenWindow -1 1 -1 1\nPixelSamples 2 2\n"
           "PixelFilter \"box\" 1 1\nWorldBegin\nLightSource \"ambientlight\" 1 \"intensity\" 1\n"
           "Translate 0 0 5\n" +
           surface + "\n" + geometry + "\nWorldEnd\n";
}
const std::string kPaint = "\"Ka\" 1 \"Kd\" 0 \"Ks\" 0";
// A bilinear patch over [-2,2]^2, beyond the view on every side; raster y is down and RI y up.
const std::string kSquare = "Patch \"bilinear\" \"P\" [-2 -2 0  2 -2 0  -2 2 0  2 2 0]";

RenderResult renderScene(const Scene& s, const std::string& engine, uint32_t channels = 0, int maxGrid = 16) {
    RenderSettings rs;
    rs.engine = engine;
    rs.threads = 2;
    rs.output.channels = channels;
    rs.maxGridEdge = maxGrid;
    return render(s, rs);
}

// The (u,v) on geometry covering [-2,2]^2 seen at pixel (px, py) of a res x res image of [-1,1]^2.
Vec2 pixelUV(int px, int py, int res) {
    const float x = 2.f * (px + 0.5f) / res - 1.f, y = 1.f - 2.f * (py + 0.5f) / res;
    return {(x + 2.f) / 4.f, (y + 2.f) / 4.f};
}

// An affine s, t of the view's (u, v) = ((x+1)/2, (y+1)/2), inside [0.2, 0.8] (away from the wrap).
Vec2 affineST(Vec2 uv) {
    return {0.3f + 0.3f * uv.x + 0.1f * uv.y, 0.25f - 0.05f * uv.x + 0.5f * uv.y};
}

}  // namespace

TEST(Textures, LookupsMatchAnalyticValues) {
    const std::string checker = writeChecker("checker.exr", 8, 8);  // 64 x 64 texels
    const std::string gradient = writeGradient("gradient.exr", 64);
    const std::vector<std::string> files{checker, gradient};
    Textures tex(files);
    ASSERT_EQ(tex.size(), 2u);
    // A point lookup at a square's centre is the square's value.
    for (int i = 0; i < 8; ++i)
        for (int j = 0; j < 8; ++j) {
            TextureLookup q;
            q.s = (i + 0.5f) / 8, q.t = (j + 0.5f) / 8;
            q.dsdx = q.dtdy = 1e-4f;
            EXPECT_NEAR(tex.value(0, q), float((i + j) & 1), 1e-4f) << i << " " << j;
        }
    // A footprint of 4 x 4 squares: the box-filtered checker over any such square region is 1/2 exactly
    // (2 periods each way), and every mip level at or above it holds 1/2.
    for (int k = 0; k < 20; ++k) {
        TextureLookup q;
        q.s = 0.3f + 0.02f * k, q.t = 0.6f - 0.017f * k;
        q.dsdx = q.dtdy = 0.5f;
        EXPECT_NEAR(tex.value(0, q), 0.5f, 0.02f) << k;
    }
    // A gradient's lookups are (s, t) at any footprint that stays inside (linear data stays linear).
    for (int k = 0; k < 20; ++k) {
        TextureLookup q;
        q.s = 0.25f + 0.025f * k, q.t = 0.7f - 0.02f * k;
        q.dsdx = q.dtdy = k % 2 ? 1e-3f : 0.05f;
        const Color c = tex.color(1, q);
        EXPECT_NEAR(c.x, q.s, 1e-3f);
        EXPECT_NEAR(c.y, q.t, 1e-3f);
    }
    float lo, hi;
    tex.range(0, lo, hi);
    EXPECT_EQ(lo, 0.f);
    EXPECT_EQ(hi, 1.f);
}

TEST(Textures, ConstantTextureTimesCsInBothEngines) {
    writeImage("constant.exr", 16, 16, 3, [] {
        std::vector<float> px;
        for (int i = 0; i < 256; ++i) px.insert(px.end(), {0.25f, 0.5f, 0.75f});
        return px;
    }());
    Loaded l = load(viewRib(
        16, "Color 1 0.5 1\nSurface \"paintedplastic\" \"texturename\" \"constant.exr\" " + kPaint, kSquare));
    ASSERT_EQ(l.scene.textures.size(), 1u);
    for (const char* engine : {"reyes", "rt"}) {
        const RenderResult r = renderScene(l.scene, engine, kChannelHasTexture);
        const ImagePlane* textured = r.image.plane("textured");
        ASSERT_TRUE(textured);
        for (int y = 0; y < 16; ++y)
            for (int x = 0; x < 16; ++x) {
                const float* p = r.image.pixel(x, y);
                EXPECT_NEAR(p[0], 0.25f, 1e-4f) << engine;
                EXPECT_NEAR(p[1], 0.25f, 1e-4f) << engine;
                EXPECT_NEAR(p[2], 0.75f, 1e-4f) << engine;
                EXPECT_EQ(textured->values[r.image.index(x, y)], 1.f) << engine;
            }
    }
}

TEST(Textures, FineCheckerFiltersToItsMeanInBothEngines) {
    // 64 squares across 16 pixels: every pixel covers 4 x 4 squares, whose filtered value is 1/2; point
    // sampling would alias to 0s and 1s.
    writeChecker("fine.exr", 64, 4);
    Loaded l =
        load(viewRib(16, "Surface \"paintedplastic\" \"texturename\" \"fine.exr\" " + kPaint, kSquare));
    for (const char* engine : {"reyes", "rt"}) {
        const RenderResult r = renderScene(l.scene, engine);
        for (int y = 0; y < 16; ++y)
            for (int x = 0; x < 16; ++x)
                EXPECT_NEAR(r.image.pixel(x, y)[0], 0.5f, 0.03f) << engine << " " << x;
    }
}

// s, t given as varying values (or TextureCoordinates) on Patch, PatchMesh and NuPatch: each pixel shows
// the analytic s, t of its centre, with Reyes splitting into tiny grids (max grid 2) and in the ray tracer.
TEST(Textures, TexCoordsFollowSplitsAndHits) {
    writeGradient("gradient.exr", 64);
    const int res = 24;
    auto stList = [](const std::vector<Vec2>& uvs) {
        std::string out;
        for (Vec2 uv : uvs) {
            const Vec2 st = affineST(uv);
            out += std::to_string(st.x) + " " + std::to_string(st.y) + " ";
        }
        return out;
    };
    // PatchMesh bilinear 3 x 3: 2 x 2 patches, 9 varying values.
    std::string meshP, nuP;
    std::vector<Vec2> grid;
    for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i) {
            meshP += std::to_string(-2 + 2 * i) + " " + std::to_string(-2 + 2 * j) + " 0 ";
            grid.push_back({i / 2.f, j / 2.f});
        }
    const std::vector<std::string> geometry = {
        kSquare + " \"st\" [" + stList({{0, 0}, {1, 0}, {0, 1}, {1, 1}}) + "]",
        "PatchMesh \"bilinear\" 3 \"nonperiodic\" 3 \"nonperiodic\" \"P\" [" + meshP + "] \"st\" [" +
            stList(grid) + "]",
        // Order-2 NURBS with 2 spans each way: varying values at the knots 0, 0.5, 1.
        "NuPatch 3 2 [0 0 0.5 1 1] 0 1 3 2 [0 0 0.5 1 1] 0 1 \"P\" [" + meshP + "] \"st\" [" + stList(grid) +
            "]",
        // s and t as two varying floats.
        [&] {
            std::string s, t;
            for (Vec2 uv : std::vector<Vec2>{{0, 0}, {1, 0}, {0, 1}, {1, 1}}) {
                s += std::to_string(affineST(uv).x) + " ";
                t += std::to_string(affineST(uv).y) + " ";
            }
            return kSquare + " \"s\" [" + s + "] \"t\" [" + t + "]";
        }(),
    };
    for (const std::string& geo : geometry) {
        Loaded l =
            load(viewRib(res, "Surface \"paintedplastic\" \"texturename\" \"gradient.exr\" " + kPaint, geo));
        for (const char* engine : {"reyes", "rt"}) {
            const RenderResult r = renderScene(l.scene, engine, 0, 2);
            double worst = 0;
            for (int y = 0; y < res; ++y)
                for (int x = 0; x < res; ++x) {
                    const Vec2 st = affineST(pixelUV(x, y, res));
                    const float* p = r.image.pixel(x, y);
                    worst = std::max({worst, double(std::fabs(p[0] - st.x)), double(std::fabs(p[1] - st.y))});
                }
            EXPECT_LT(worst, 2e-3) << engine << ": " << geo.substr(0, 40);
        }
    }
    // The default s, t of a PatchMesh go from 0 to 1 over the whole mesh (RI spec 3.2, sec. 5.2), mapped
    // here by TextureCoordinates to [0.2, 0.8]^2.
    Loaded l =
        load(viewRib(res,
                     "TextureCoordinates 0.2 0.2 0.8 0.2 0.2 0.8 0.8 0.8\n"
                     "Surface \"paintedplastic\" \"texturename\" \"gradient.exr\" " +
                         kPaint,
                     "PatchMesh \"bilinear\" 3 \"nonperiodic\" 3 \"nonperiodic\" \"P\" [" + meshP + "]"));
    for (const char* engine : {"reyes", "rt"}) {
        const RenderResult r = renderScene(l.scene, engine, 0, 2);
        double worst = 0;
        for (int y = 0; y < res; ++y)
            for (int x = 0; x < res; ++x) {
                const Vec2 uv = pixelUV(x, y, res);
                const float* p = r.image.pixel(x, y);
                worst = std::max({worst, double(std::fabs(p[0] - (0.2f + 0.6f * uv.x))),
                                  double(std::fabs(p[1] - (0.2f + 0.6f * uv.y)))});
            }
        EXPECT_LT(worst, 2e-3) << engine;
    }
}

TEST(Textures, MakeTextureWritesATiledMipMappedTexture) {
    writeChecker("picture.exr", 8, 8);
    Loaded l = load(viewRib(16,
                            "MakeTexture \"picture.exr\" \"picture.tx\" \"clamp\" \"periodic\" \"box\" 1 1\n"
                            "Option \"searchpath\" \"texture\" \"nowhere:@\"\n"
                            "Surface \"paintedplastic\" \"texturename\" \"picture.tx\" " +
                                kPaint,
                            kSquare));
    ASSERT_EQ(l.scene.textures.size(), 1u);
    auto in = OIIO::ImageInput::open(l.scene.textures[0]);
    ASSERT_TRUE(in);
    EXPECT_GT(in->spec().tile_width, 0);
    int levels = 0;
    while (in->seek_subimage(0, levels)) ++levels;
    EXPECT_EQ(levels, 7);  // 64, 32, ..., 1
    EXPECT_EQ(in->spec(0, 0).get_string_attribute("wrapmodes"), "clamp,periodic");
}

TEST(Textures, MissingOrUnreadableTexturesAreErrors) {
    std::string msg =
        expectError(viewRib(8, "Surface \"paintedplastic\" \"texturename\" \"nope.tif\"", kSquare), 9);
    EXPECT_TRUE(contains(msg, "\"nope.tif\" not found")) << msg;
    writeTestFile("garbage.tif", "this is not an image");
    msg = expectError(viewRib(8, "Surface \"paintedplastic\" \"texturename\" \"garbage.tif\"", kSquare), 9);
    EXPECT_TRUE(contains(msg, "cannot read texture file") && contains(msg, "garbage.tif")) << msg;
    msg = expectError(
        viewRib(8, "MakeTexture \"absent.exr\" \"a.tx\" \"clamp\" \"clamp\" \"box\" 1 1", kSquare), 9);
    EXPECT_TRUE(contains(msg, "absent.exr")) << msg;
    writeChecker("p.exr", 2, 2);
    msg = expectError(viewRib(8, "MakeTexture \"p.exr\" \"a.tx\" \"mirror\" \"clamp\" \"box\" 1 1", kSquare),
                      9);
    EXPECT_TRUE(contains(msg, "wrap mode")) << msg;
    // The search path decides where a name is found.
    msg = expectError(viewRib(8,
                              "Option \"searchpath\" \"texture\" \"elsewhere\"\n"
                              "Surface \"paintedplastic\" \"texturename\" \"p.exr\"",
                              kSquare),
                      10);
    EXPECT_TRUE(contains(msg, "elsewhere")) << msg;
}

// The shipped textured teapot: both engines look up the same filtered texels (the same st and footprint
// at the same surface point), so their images agree as closely as untextured ones do.
TEST(Textures, BothEnginesAgreeOnTheTexturedTeapot) {
    Scene s =
        loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/textured_teapot.rib", [](const std::string&) {});
    s.camera.width = 200, s.camera.height = 150;
    s.image.pixelSamplesX = s.image.pixelSamplesY = 3;
    const RenderResult reyes = renderScene(s, "reyes"), rt = renderScene(s, "rt");
    const ImageDiff d = compareImages(reyes.image, rt.image);
    std::printf("textured teapot 200x150 9 spp, Reyes vs rt: PSNR %.2f dB, alpha mismatch %.4f\n",
                d.psnrColor, d.alphaMismatch);
    EXPECT_GE(d.psnrColor, 35.0);
    EXPECT_LT(d.alphaMismatch, 0.01);
}

// --adaptive's texture path (paper 004, tau_pte): a checker of 0.5 and 0.55 has a contrast (0.048) below the
// colour threshold's (1.02 x 0.3 in green), so only the texture flag can refine it: with tau_pte = 0.02 the
// subpixels along the checker's edges refine, with tau_pte = 1 nothing does (the paper's rule takes a
// disagreeing attribute's threshold even where it is laxer than tau_col).
TEST(Textures, AdaptiveTextureThresholdRefinesATexturedSurfaceAlongItsEdges) {
    const int squares = 8, texels = 8, n = squares * texels;
    std::vector<float> px(size_t(n) * n);
    for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) px[size_t(y) * n + x] = ((x / texels) + (y / texels)) & 1 ? 0.55f : 0.5f;
    writeImage("low_contrast_checker.exr", n, n, 1, px);
    const int res = 32;  // the view [-1,1]^2 of the checker over [-2,2]^2: a square every 8 pixels
    Loaded l = load(viewRib(
        res, "Surface \"paintedplastic\" \"texturename\" \"low_contrast_checker.exr\" " + kPaint, kSquare));
    auto refine = [&](float texture) {
        RenderSettings rs;
        rs.engine = "rt";
        rs.threads = 2;
        rs.adaptive.enabled = true;
        rs.adaptive.thresholds.texture = texture;
        return render(l.scene, rs);
    };
    const RenderResult lax = refine(1.f);
    EXPECT_EQ(std::count(lax.refinedSubpixels.begin(), lax.refinedSubpixels.end(), 1), 0);
    const RenderResult strict = refine(0.02f);
    int refined = 0, nearEdge = 0;
    for (int y = 0; y < 2 * res; ++y)
        for (int x = 0; x < 2 * res; ++x) {
            if (!strict.refinedSubpixels[size_t(y) * 2 * res + x]) continue;
            ++refined;
            // Subpixel (x, y) covers raster [x/2, x/2 + 1/2); its test reaches the next pixel centre.
            auto nearLine = [](int sub) { return std::abs(((sub + 1) / 2 + 4) % 8 - 4) <= 1; };
            nearEdge += nearLine(x) || nearLine(y);
        }
    EXPECT_GT(refined, 2 * 3 * 2 * res);  // two subpixel columns along each of the 3 inner edges, each way
    EXPECT_EQ(nearEdge, refined);
    EXPECT_EQ(strict.stats["adaptive"]["active_subpixels"].get<int>(), refined);
}

}  // namespace tessera::test::textures_tests
