// Reyes displacement (issue 12, paper 000 sec. 3.1): a constant displacement of a plane and of a curved
// bicubic equals the offset surface; a displaced teapot has no pinholes; the bound contains every displaced
// point; bad bounds and unknown displacement shaders are errors; the ray tracer no longer warns that it
// ignores it (it displaces: tests/test_rt_displacement.cpp).
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "engine/frame.h"
#include "render/render.h"
#include "reyes/displace.h"
#include "reyes/grid.h"
#include "reyes/pipeline.h"
#include "rib_test_util.h"
#include "shading/minmax_mip.h"
#include "shading/texture.h"
#include "test_util.h"

namespace tessera::test::displacement_tests {

namespace {

std::string writeGrey(const std::string& name, int n, const std::vector<float>& px) {
    const std::string path = (testScratchDir() / name).string();
    auto out = OIIO::ImageOutput::create(path);
    OIIO::ImageSpec spec(n, n, 1, OIIO::TypeFloat);
    out->open(path, spec);
    out->write_image(OIIO::TypeFloat, px.data());
    out->close();
    return path;
}

// Every diced vertex of every piece of the scene's patches, in camera space (orthographic views only:
// raster positions are inverted exactly up to the 1/256-pixel fixed point), with the piece's raster bound.
struct DicedVertex {
    Vec3 P;
    uint32_t patch;
    bool insideBound;
};
// A scene's patches and quadrics in its camera's space, welded, the Reyes view over them (culling
// nothing, grids of at most maxGrid micropolygons a side) and every piece, split up front.
struct SplitScene {
    RenderSettings settings;
    FrameSetup frame;
    PatchArray patches;
    std::vector<PlacedQuadric> quadrics;
    DisplacementFrame disp;
    ReyesView view;
    PieceList pieces;
    SplitScene(const Scene& scene, int maxGrid)
        : frame(scene, settings),
          patches(welded(patchesInCameraSpace(scene, frame.camera.cameraFromWorld))),
          quadrics(quadricsInSpace(scene, frame.camera.cameraFromWorld)),
          disp(makeDisplacementFrame(scene, frame.textures.get(), patches, 1.f)),
          view(frame.camera) {
        view.patches = patches.data();
        view.quadrics = quadrics.data();
        view.projector = frame.projector;
        if (disp.any()) view.displacement = &disp;
        view.maxGridEdge = maxGrid;
        view.cullX0 = view.cullY0 = -1e9f, view.cullX1 = view.cullY1 = 1e9f;
        SplitStats stats;
        pieces = splitPatches(view, scene, 0.f, nullptr, stats);
    }
    static PatchArray welded(PatchArray p) {
        weldSharedEdges(p, defaultWeldTolerance(p));
        return p;
    }
};

std::vector<DicedVertex> diceAll(const Scene& scene, int maxGrid = 16) {
    const SplitScene split(scene, maxGrid);
    const FrameSetup& frame = split.frame;
    const ReyesView& view = split.view;
    const PieceList& pieces = split.pieces;
    std::vector<DicedVertex> out;
    const Projector& pr = view.projector;
    for (const Piece& piece : pieces) {
        const PatchAttributes& a = scene.attributes[piece.patch];
        ShadeInputs in{a.kind,  &scene.materials[a.material], a.twoSided, a.flipNormal, frame.lights,
                       a.object};
        Grid g;
        diceAndShade(view, piece, in, g);
        for (int v = 0; v < g.vertexCount(); ++v) {
            const float rx = g.X[v] / kSubpixelScale, ry = g.Y[v] / kSubpixelScale;
            const float eps = 1.f / kSubpixelScale;
            out.push_back({Vec3{(rx - pr.ox) / pr.sx, (ry - pr.oy) / pr.sy, g.Z[v]}, piece.patch,
                           rx >= piece.x0 - eps && rx <= piece.x1 + eps && ry >= piece.y0 - eps &&
                               ry <= piece.y1 + eps});
        }
    }
    return out;
}

std::string orthoRib(int res, const std::string& body, float window = 1.f) {
    const std::string w = std::to_string(window);
    return "Format " + std::to_string(res) + " " + std::to_string(res) +
           " 1\nProjection \"orthographic\"\nScreenWindow -" + w + " " + w + " -" + w + " " + w +
           "\nWorldBegin\nLightSource \"ambientlight\" 1\nTranslate 0 0 5\n" + body + "\nWorldEnd\n";
}

}  // namespace

// A shadow map's depth pass dices with its own loop (positions only, interior vertices from per-column
// terms): every piece's raster positions and depths must be those of the frame's dicer, bit for bit, on
// bicubic patches (with and without displacement, whose shared edges take canonical positions) and on
// quadrics.
TEST(Displacement, TheDepthPassDicesTheFramesPositions) {
    for (const char* name : {"displaced_teapot", "teapot", "quadrics"}) {
        const Scene scene = loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/" + name + ".rib", nullptr);
        const SplitScene split(scene, 16);
        const FrameSetup& frame = split.frame;
        const ReyesView& view = split.view;
        size_t vertices = 0, differ = 0, pieceCount = 0;
        Grid full, depth;
        for (const Piece& piece : split.pieces) {
            if (++pieceCount % 8 != 0) continue;  // an eighth of the pieces keeps the test short
            const PatchAttributes& a = scene.attributes[piece.patch];
            ShadeInputs in{a.kind,  &scene.materials[a.material], a.twoSided, a.flipNormal, frame.lights,
                           a.object};
            in.textures = frame.textures.get();
            in.quadric = quadricOf(view, a);
            diceAndShade(view, piece, in, full);
            in.depthOnly = true;
            diceAndShade(view, piece, in, depth);
            ASSERT_EQ(depth.vertexCount(), full.vertexCount());
            EXPECT_TRUE(depth.twoSided);
            for (int v = 0; v < full.vertexCount(); ++v) {
                ++vertices;
                differ += full.X[v] != depth.X[v] || full.Y[v] != depth.Y[v] ||
                          std::memcmp(&full.Z[v], &depth.Z[v], sizeof(float)) != 0;
            }
        }
        EXPECT_GT(vertices, 5000u) << name;
        EXPECT_EQ(differ, 0u) << name << ": of " << vertices << " vertices";
    }
}

// A constant displacement d ("offset") of a plane: every diced point is at distance d from the plane, on the
// side of the patch's normal, and its shading normal is the plane's.
TEST(Displacement, ConstantOffsetOfAPlaneIsTheOffsetPlane) {
    const float d = 0.125f;
    Loaded l = load(orthoRib(256, "Displacement \"offset\" \"Km\" " + std::to_string(d) +
                                      "\nPatch \"bilinear\" \"P\" [-1 -1 0  1 -1 0  -1 1 0  1 1 0]"));
    const std::vector<DicedVertex> vs = diceAll(l.scene);
    ASSERT_GT(vs.size(), 100u);
    for (const DicedVertex& v : vs) {
        EXPECT_NEAR(std::fabs(v.P.z - 5.f), d, 1e-5f);
        EXPECT_NEAR(v.P.z, vs[0].P.z, 1e-5f);  // all on one side
        EXPECT_TRUE(v.insideBound);
    }
}

// A known height field: a plane z = 0 (s along x, t along y) displaced by bumpy with h(s, t) = 0.5 + 0.5
// sin(2 pi s) (a 256 x 256 texture, periodic like the lookups) is the surface z = c Km h(s) (c = +-1, the
// side of the patch's normal, read from the rendered P). Its analytic normal is (-c Km dh/dx, 0, 1) up to
// its sign, dh/dx = (pi / 2) cos(2 pi s); the shading normals of both engines (the N AOV, facing the viewer)
// match it within 2 degrees wherever the pixel's footprint lies inside the plane.
TEST(Displacement, HeightFieldNormalsMatchTheAnalyticOnes) {
    const int n = 256;
    std::vector<float> px(size_t(n) * n);
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i)
            px[size_t(j) * n + i] = 0.5f + 0.5f * float(std::sin(2 * 3.14159265358979 * (i + 0.5) / n));
    const std::string tex = writeGrey("sine256.exr", n, px);
    const float Km = 0.1f;
    const int res = 64;
    Loaded l = load(orthoRib(res,
                             "Displacement \"bumpy\" \"Km\" " + std::to_string(Km) + " \"texturename\" \"" +
                                 tex + "\"\nPatch \"bilinear\" \"P\" [-1 -1 0  1 -1 0  -1 1 0  1 1 0]",
                             1.2f));
    const Projector pr(l.scene.camera);
    for (const char* engine : {"reyes", "rt"}) {
        SCOPED_TRACE(engine);
        RenderSettings rs;
        rs.engine = engine;
        rs.threads = 2;
        rs.output.channels = kChannelNormal | kChannelPosition;
        const Image img = render(l.scene, rs).image;
        const ImagePlane *N = img.plane("N"), *P = img.plane("P");
        ASSERT_NE(N, nullptr);
        ASSERT_NE(P, nullptr);
        auto at = [&](const ImagePlane* plane, int x, int y) {
            const size_t i = img.index(x, y) * 3;
            return Vec3{plane->values[i], plane->values[i + 1], plane->values[i + 2]};
        };
        auto pixelOf = [&](float wx, float wy) {  // world (x, y) -> pixel
            return std::pair<int, int>{int(pr.ox + pr.sx * wx), int(pr.oy + pr.sy * wy)};
        };
        // c: where h is largest (s = 1/4, x = -1/2) against where it is smallest (s = 3/4, x = 1/2).
        const auto [xa, ya] = pixelOf(-0.5f, 0.f);
        const auto [xb, yb] = pixelOf(0.5f, 0.f);
        const float dz = at(P, xa, ya).z - at(P, xb, yb).z;
        ASSERT_NEAR(std::fabs(dz), Km, 0.1f * Km) << "the relief of the height field";
        const float c = dz > 0 ? 1.f : -1.f;
        int compared = 0;
        double worst = 0;
        for (int y = 0; y < res; ++y)
            for (int x = 0; x < res; ++x) {
                const float wx = (x + 0.5f - pr.ox) / pr.sx, wy = (y + 0.5f - pr.oy) / pr.sy;
                if (std::fabs(wx) > 0.9f || std::fabs(wy) > 0.9f) continue;
                const float s = (wx + 1) / 2;
                const float dhdx = float(3.14159265358979 / 2 * std::cos(2 * 3.14159265358979 * s));
                // Camera space is world space moved along z; facing the viewer (at -z) means n.z < 0.
                Vec3 want = normalize(Vec3{-c * Km * dhdx, 0, 1});
                if (want.z > 0) want = -want;
                const Vec3 got = normalize(at(N, x, y));
                const double deg =
                    std::acos(std::clamp(double(dot(got, want)), -1.0, 1.0)) * 180 / 3.14159265358979;
                worst = std::max(worst, deg);
                ++compared;
            }
        EXPECT_GT(compared, 2000);
        EXPECT_LT(worst, 2.0) << "largest angle to the analytic normal, degrees";
    }
}

// The same on a strongly curved bicubic (a dome, like a patch of a sphere): every displaced point lies at
// distance d from the undisplaced surface (closest-point distance, an independent check of the exact normal),
// within the dicing tolerance; two such patches sharing an edge move its points identically.
TEST(Displacement, ConstantOffsetOfACurvedBicubicIsTheOffsetSurface) {
    const float d = 0.1f;
    std::string P;
    for (int j = 0; j < 4; ++j)
        for (int i = 0; i < 4; ++i) {
            const float x = -1 + 2 * i / 3.f, y = -1 + 2 * j / 3.f;
            P += std::to_string(x) + " " + std::to_string(y) + " " +
                 std::to_string(-0.8f * (2 - x * x - y * y)) + " ";
        }
    Loaded l = load(orthoRib(
        256, "Displacement \"offset\" \"Km\" " + std::to_string(d) + "\nPatch \"bicubic\" \"P\" [" + P + "]",
        1.5f));
    PatchArray cam = patchesInCameraSpace(l.scene, l.scene.camera.cameraFromWorld);
    const std::vector<DicedVertex> vs = diceAll(l.scene);
    ASSERT_GT(vs.size(), 100u);
    float worst = 0;
    for (size_t i = 0; i < vs.size(); i += 7)
        worst = std::max(worst, std::fabs(distanceToPatch(cam[0], vs[i].P) - d));
    EXPECT_LT(worst, 2e-4f);
    for (const DicedVertex& v : vs) EXPECT_TRUE(v.insideBound);
}

// The bound contains every displaced point: random bicubic patches with random noise textures and random
// amplitudes, diced finely, every vertex inside its piece's (grown) raster bound.
TEST(Displacement, TheBoundContainsEveryDisplacedPoint) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> U(-1.f, 1.f);
    for (int trial = 0; trial < 4; ++trial) {
        std::vector<float> px(32 * 32);
        for (float& p : px) p = U(rng) * 2.f;  // values in [-2, 2]
        const std::string tex = "noise" + std::to_string(trial) + ".exr";
        writeGrey(tex, 32, px);
        std::string P;
        for (int j = 0; j < 4; ++j)
            for (int i = 0; i < 4; ++i)
                P += std::to_string(-1 + 2 * i / 3.f + 0.3f * U(rng)) + " " +
                     std::to_string(-1 + 2 * j / 3.f + 0.3f * U(rng)) + " " + std::to_string(0.8f * U(rng)) +
                     " ";
        Loaded l = load(orthoRib(128,
                                 "Displacement \"bumpy\" \"Km\" " + std::to_string(0.2f * U(rng)) +
                                     " \"texturename\" \"" + tex + "\"\nPatch \"bicubic\" \"P\" [" + P + "]",
                                 2.f));
        const std::vector<DicedVertex> vs = diceAll(l.scene, 4);
        ASSERT_GT(vs.size(), 50u);
        size_t outside = 0;
        for (const DicedVertex& v : vs) outside += !v.insideBound;
        EXPECT_EQ(outside, 0u) << "trial " << trial;
    }
}

TEST(Displacement, BadBoundsAreErrorsAndUnknownShadersWarn) {
    const std::string patch = "\nPatch \"bilinear\" \"P\" [-1 -1 0  1 -1 0  -1 1 0  1 1 0]";
    // An unknown displacement shader is said once (as an unknown Surface) and leaves the surface undisplaced.
    Loaded w = load(orthoRib(8, "Displacement \"wobbly\" \"Km\" 1\nDisplacement \"wobbly\"" + patch));
    int said = 0;
    for (const std::string& m : w.warnings)
        said += contains(m, "displacement shader \"wobbly\" is not supported");
    EXPECT_EQ(said, 1);
    EXPECT_EQ(w.scene.attributes[0].displacement, -1);
    std::string msg;
    msg = expectError(orthoRib(8, "Attribute \"displacementbound\" \"sphere\" -1" + patch), 7);
    EXPECT_TRUE(contains(msg, "\"sphere\" must be a number >= 0")) << msg;
    msg = expectError(
        orthoRib(8, "Attribute \"displacementbound\" \"sphere\" 1 \"coordinatesystem\" \"nowhere\"" + patch),
        7);
    EXPECT_TRUE(contains(msg, "unknown coordinate system \"nowhere\"")) << msg;
    msg =
        expectError(orthoRib(8, "Attribute \"displacementbound\" \"coordinatesystem\" \"world\"" + patch), 7);
    EXPECT_TRUE(contains(msg, "missing \"sphere\"")) << msg;
    msg = expectError(orthoRib(8, "Displacement \"bumpy\" \"texturename\" \"none.tx\"" + patch), 7);
    EXPECT_TRUE(contains(msg, "\"none.tx\" not found")) << msg;
    // The bound converts to world units by the space's scale.
    Loaded l = load(
        orthoRib(8,
                 "Scale 3 3 3\nAttribute \"displacementbound\" \"sphere\" 2 \"coordinatesystem\" \"object\"\n"
                 "Displacement \"offset\" \"Km\" 0.1" +
                     patch));
    EXPECT_NEAR(l.scene.attributes[0].displacementBound, 6.f, 1e-5f);
}

TEST(Displacement, TheRayTracerNoLongerIgnoresDisplacement) {
    Loaded l = load(orthoRib(
        8, "Displacement \"offset\" \"Km\" 0.1\nPatch \"bilinear\" \"P\" [-1 -1 0  1 -1 0  -1 1 0  1 1 0]"));
    RenderSettings rs;
    for (const char* engine : {"rt", "reyes"}) {
        rs.engine = engine;
        for (const std::string& w : render(l.scene, rs).warnings)
            EXPECT_FALSE(contains(w, "ignores displacement")) << engine;
    }
}

// A displaced teapot has no pinholes: with a constant offset (the normals of neighbouring patches averaged
// at creases and poles) and with a texture that jumps across patch edges (tiles.png: each patch sees other
// tiles at its two sides, so each side alone would move a shared point differently), every pixel well inside
// the undisplaced teapot's silhouette is fully covered, by every sample (alpha exactly 1).
TEST(Displacement, DisplacedTeapotHasNoPinholes) {
    const std::string scenes = std::string(TESSERA_SOURCE_DIR) + "/scenes/";
    auto teapot = [&](const std::string& displacement) {
        return writeRib(
            "Format 160 120 1\nPixelSamples 2 2\nPixelFilter \"box\" 1 1\n"
            "Projection \"perspective\" \"fov\" 32\nTranslate 0 0 10\nRotate -115 1 0 0\n"
            "Rotate 19 0 0 1\nTranslate -0.625 0 -1.25\nWorldBegin\n"
            "Option \"searchpath\" \"texture\" \"" +
                scenes + "textures\"\nSurface \"constant\"\n" + displacement +
                "\nScale 0.025 0.025 0.025\nReadArchive \"" + scenes +
                "archives/teapot_geometry.rib\"\nWorldEnd\n",
            "teapot" + std::to_string(displacement.size()) + ".rib");
    };
    auto renderAlpha = [&](const std::string& path) {
        const Scene s = loadScene(path, [](const std::string&) {});
        RenderSettings rs;
        rs.threads = 2;
        return render(s, rs).image;
    };
    const Image plain = renderAlpha(teapot(""));
    // Inside: the undisplaced teapot covers the pixel and every pixel within 2 of it.
    std::vector<uint8_t> inside(size_t(plain.width) * plain.height, 0);
    int insideCount = 0;
    for (int y = 2; y < plain.height - 2; ++y)
        for (int x = 2; x < plain.width - 2; ++x) {
            bool all = true;
            for (int dy = -2; dy <= 2; ++dy)
                for (int dx = -2; dx <= 2; ++dx) all = all && plain.pixel(x + dx, y + dy)[3] == 1.f;
            inside[size_t(y) * plain.width + x] = all;
            insideCount += all;
        }
    ASSERT_GT(insideCount, 3000);
    for (const std::string& d :
         {std::string("Displacement \"offset\" \"Km\" 0.04"),
          std::string("Displacement \"bumpy\" \"Km\" 0.08 \"texturename\" \"tiles.png\"")}) {
        const Image img = renderAlpha(teapot(d));
        int holes = 0;
        for (int y = 0; y < img.height; ++y)
            for (int x = 0; x < img.width; ++x)
                if (inside[size_t(y) * img.width + x] && img.pixel(x, y)[3] != 1.f) ++holes;
        EXPECT_EQ(holes, 0) << d;
    }
}

// Two patches meeting at a ridge (a 90-degree crease) seen from the front: displaced by a constant along
// their own normals alone, the ridge would open a gap of sqrt(2) d (or overlap, for the other sign). The
// shared edge moves along the canonical (averaged) normal from both sides, so every pixel stays covered.
TEST(Displacement, ACreaseStaysClosed) {
    for (const char* km : {"0.1", "-0.1"}) {
        Loaded l = load(orthoRib(64,
                                 std::string("Surface \"constant\"\nDisplacement \"offset\" \"Km\" ") + km +
                                     "\nPatch \"bilinear\" \"P\" [-1 -1 0  0 -1 -1  -1 1 0  0 1 -1]"
                                     "\nPatch \"bilinear\" \"P\" [0 -1 -1  1 -1 0  0 1 -1  1 1 0]",
                                 0.7f));
        RenderSettings rs;
        rs.threads = 2;
        const Image img = render(l.scene, rs).image;
        int holes = 0;
        for (int y = 0; y < img.height; ++y)
            for (int x = 0; x < img.width; ++x) holes += img.pixel(x, y)[3] < 1.f - 1e-4f;  // filter rounding
        EXPECT_EQ(holes, 0) << "Km " << km;
    }
}

// The min/max mip map (paper 001 sec. 3.1) against brute force: on a random texture of odd size, the read of
// any texel rectangle at the level of its extent bounds the true min and max of its texels, and is exact
// for one aligned block; st reads wrap as the lookups do (periodic) and reach past the border as black.
TEST(TextureMinMaxMip, ReadsBoundTheTexelsOfRandomRectangles) {
    std::mt19937 rng(12);
    const int w = 37, h = 23;
    std::vector<float> px(size_t(w) * h);
    std::uniform_real_distribution<float> U(-3.f, 5.f);
    for (float& p : px) p = U(rng);
    const MinMaxMip mip = buildMinMaxMip(w, h, px);
    ASSERT_EQ(mip.levels.size(), 7u);  // 37x23, 19x12, 10x6, 5x3, 3x2, 2x1, 1x1
    auto brute = [&](int x0, int x1, int y0, int y1, float& lo, float& hi) {
        lo = INFINITY, hi = -INFINITY;
        for (int y = y0; y <= y1; ++y)
            for (int x = x0; x <= x1; ++x)
                lo = std::min(lo, px[size_t(y) * w + x]), hi = std::max(hi, px[size_t(y) * w + x]);
    };
    const float globalLo = *std::min_element(px.begin(), px.end()),
                globalHi = *std::max_element(px.begin(), px.end());
    int tighter = 0;
    for (int trial = 0; trial < 2000; ++trial) {
        int x0 = int(rng() % w), x1 = int(rng() % w), y0 = int(rng() % h), y1 = int(rng() % h);
        if (trial % 2)
            x1 = std::min(w - 1, x0 + int(rng() % 4)), y1 = std::min(h - 1, y0 + int(rng() % 4));  // small
        if (x1 < x0) std::swap(x0, x1);
        if (y1 < y0) std::swap(y0, y1);
        float lo = INFINITY, hi = -INFINITY, tlo, thi;
        minMaxInRect(mip, x0, x1, y0, y1, lo, hi);
        brute(x0, x1, y0, y1, tlo, thi);
        ASSERT_LE(lo, tlo) << x0 << ".." << x1 << " x " << y0 << ".." << y1;
        ASSERT_GE(hi, thi) << x0 << ".." << x1 << " x " << y0 << ".." << y1;
        ASSERT_GE(lo, globalLo);
        ASSERT_LE(hi, globalHi);
        tighter += hi - lo < globalHi - globalLo;
    }
    EXPECT_GT(tighter, 500);  // the small rectangles read much less than the whole range
    // One aligned block of level L reads exactly its texels.
    for (int L = 0; L < 4; ++L)
        for (int j = 0; j < 3; ++j) {
            const int n = 1 << L, x0 = j * n, y0 = (j % 2) * n;
            float lo = INFINITY, hi = -INFINITY, tlo, thi;
            minMaxInRect(mip, x0, x0 + n - 1, y0, y0 + n - 1, lo, hi);
            brute(x0, x0 + n - 1, y0, y0 + n - 1, tlo, thi);
            EXPECT_EQ(lo, tlo);
            EXPECT_EQ(hi, thi);
        }
    // st reads: the bilinear footprint of the rectangle, wrapped (periodic) or past the border (black: 0).
    for (int trial = 0; trial < 500; ++trial) {
        std::uniform_real_distribution<float> S(-1.5f, 2.5f), D(0.f, 0.3f);
        const float s0 = S(rng), t0 = S(rng), s1 = s0 + D(rng), t1 = t0 + D(rng);
        float lo, hi;
        ASSERT_TRUE(minMaxInST(mip, s0, s1, t0, t1, lo, hi));
        float tlo = INFINITY, thi = -INFINITY;
        const int xa = int(std::floor(s0 * w - 0.5f)), xb = int(std::floor(s1 * w - 0.5f)) + 1;
        const int ya = int(std::floor(t0 * h - 0.5f)), yb = int(std::floor(t1 * h - 0.5f)) + 1;
        for (int y = ya; y <= yb; ++y)
            for (int x = xa; x <= xb; ++x) {
                const float v = px[size_t(((y % h) + h) % h) * w + size_t(((x % w) + w) % w)];
                tlo = std::min(tlo, v), thi = std::max(thi, v);
            }
        ASSERT_LE(lo, tlo);
        ASSERT_GE(hi, thi);
    }
    MinMaxMip black = buildMinMaxMip(w, h, px, TexelWrap::Black, TexelWrap::Black);
    float lo, hi;
    ASSERT_TRUE(minMaxInST(black, 0.95f, 1.2f, 0.4f, 0.5f, lo, hi));
    EXPECT_LE(lo, 0.f);
    EXPECT_GE(hi, 0.f);
}

// The pyramid a render builds reads the texture file's texels through OpenImageIO: equal to the pyramid of
// the values written.
TEST(TextureMinMaxMip, IsBuiltFromTheFilesTexels) {
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> U(-1.f, 2.f);
    std::vector<float> px(20 * 20);
    for (float& p : px) p = U(rng);
    const std::string path = writeGrey("mip.exr", 20, px);
    const std::vector<std::string> files{path};
    const Textures textures(files);
    const MinMaxMip& mip = textures.minMaxMip(0);
    const MinMaxMip ref = buildMinMaxMip(20, 20, px);
    ASSERT_EQ(mip.levels.size(), ref.levels.size());
    for (size_t l = 0; l < ref.levels.size(); ++l) {
        EXPECT_EQ(mip.levels[l].lo, ref.levels[l].lo) << l;
        EXPECT_EQ(mip.levels[l].hi, ref.levels[l].hi) << l;
    }
    EXPECT_EQ(mip.wrapS, TexelWrap::Periodic);
}

namespace {

// The teapot at 160x120 displaced by a texture of random noise (high frequency: a texel is about a pixel),
// rendered with displacement-aware splitting at `threshold` (0: off).
RenderResult noisyTeapot(float threshold, const std::string& texture) {
    const std::string scenes = std::string(TESSERA_SOURCE_DIR) + "/scenes/";
    const std::string rib = writeRib(
        "Format 160 120 1\nPixelSamples 2 2\nPixelFilter \"box\" 1 1\n"
        "Projection \"perspective\" \"fov\" 32\nTranslate 0 0 10\nRotate -115 1 0 0\n"
        "Rotate 19 0 0 1\nTranslate -0.625 0 -1.25\nWorldBegin\nSurface \"constant\"\n"
        "Displacement \"bumpy\" \"Km\" 0.08 \"texturename\" \"" +
            texture + "\"\nScale 0.025 0.025 0.025\nReadArchive \"" + scenes +
            "archives/teapot_geometry.rib\"\nWorldEnd\n",
        "noisy_teapot.rib");
    const Scene s = loadScene(rib, [](const std::string&) {});
    RenderSettings rs;
    rs.threads = 2;
    rs.displacementSplit = threshold;
    return render(s, rs);
}

}  // namespace

// Displacement-aware splitting (paper 001 sec. 3.1): with a high-frequency texture the teapot is split into
// more pieces and micropolygons, and its displaced micropolygons get smaller on screen (mean and largest
// side, measured from the diced grids); a larger threshold splits less; every pixel inside stays covered.
TEST(DisplacementSplit, HighFrequencyTextureGetsMorePiecesAndSmallerMicropolygons) {
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> U(0.f, 1.f);
    std::vector<float> px(64 * 64);
    for (float& p : px) p = U(rng);
    const std::string tex = writeGrey("noise64.exr", 64, px);
    const RenderResult off = noisyTeapot(0.f, tex), on = noisyTeapot(1.f, tex), loose = noisyTeapot(4.f, tex);
    auto count = [](const RenderResult& r, const char* key) { return r.stats.at(key).get<uint64_t>(); };
    auto side = [](const RenderResult& r, const char* key) {
        return r.stats.at("displaced").at(key).get<double>();
    };
    EXPECT_GT(count(on, "pieces"), count(off, "pieces"));
    EXPECT_GT(count(on, "micropolygons"), count(off, "micropolygons"));
    EXPECT_GT(count(on, "grid_vertices"), count(off, "grid_vertices"));
    EXPECT_LT(side(on, "mean_longest_side_px"), side(off, "mean_longest_side_px"));
    EXPECT_LT(side(on, "max_longest_side_px"), side(off, "max_longest_side_px"));
    EXPECT_LE(count(loose, "micropolygons"), count(on, "micropolygons"));
    EXPECT_GE(count(loose, "micropolygons"), count(off, "micropolygons"));
    // No pinholes with the extra splitting: every pixel whose 5x5 neighbourhood the unsplit render covers
    // fully is covered fully (shared edges split alike from both sides).
    int inside = 0, holes = 0;
    for (int y = 2; y < off.image.height - 2; ++y)
        for (int x = 2; x < off.image.width - 2; ++x) {
            bool all = true;
            for (int dy = -2; dy <= 2; ++dy)
                for (int dx = -2; dx <= 2; ++dx) all = all && off.image.pixel(x + dx, y + dy)[3] == 1.f;
            if (!all) continue;
            ++inside;
            holes += on.image.pixel(x, y)[3] != 1.f;
        }
    EXPECT_GT(inside, 3000);
    EXPECT_EQ(holes, 0);
}

}  // namespace tessera::test::displacement_tests
