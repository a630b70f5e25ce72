// Reyes engine against independent truth: analytic coverage, watertightness of closed surfaces,
// culling, and convergence with the sample count.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <numbers>

#include "engine/frame.h"
#include "io/scene_loader.h"
#include "reyes/displace.h"
#include "reyes/pipeline.h"
#include "reyes/rasterize.h"
#include "scene/weld.h"
#include "test_support.h"
#include "test_util.h"

namespace tessera::test::reyes_tests {

namespace {
RenderResult renderWith(const Scene& s, int threads = 2) {
    RenderSettings rs;
    rs.engine = "reyes";
    rs.threads = threads;
    return render(s, rs);
}
}  // namespace

TEST(ReyesAnalytic, FlatSquareCoversExpectedArea) {
    // A square of side 2 at depth 5 under a 40-degree fov on a 200x200 image.
    Scene s = cameraSpaceScene(200, 200, 40.f);
    s.image.pixelSamplesX = s.image.pixelSamplesY = 4;
    addPatch(s, flatSquare(2.f, 5.f));
    RenderResult r = renderWith(s);
    const double pixelsPerUnit = 100.0 / (5.0 * std::tan(20.0 * std::numbers::pi / 180.0));
    const double side = 2.0 * pixelsPerUnit;  // ~109.9 pixels
    const double expected = side * side;
    const double got = alphaSum(r.image);
    // Coverage error is confined to the boundary: allow a quarter pixel along the perimeter.
    EXPECT_NEAR(got, expected, 0.25 * 4 * side) << "alpha sum " << got << " expected " << expected;
    // Pixels well inside are fully covered, pixels well outside are empty.
    const double lo = 100 - side / 2, hi = 100 + side / 2;
    for (int y = 0; y < 200; ++y)
        for (int x = 0; x < 200; ++x) {
            double cx = x + 0.5, cy = y + 0.5;
            bool inside = cx > lo + 1.5 && cx < hi - 1.5 && cy > lo + 1.5 && cy < hi - 1.5;
            bool outside = cx < lo - 1.5 || cx > hi + 1.5 || cy < lo - 1.5 || cy > hi + 1.5;
            if (inside) {
                ASSERT_EQ(alphaAt(r.image, x, y), 1.f) << x << "," << y;
            }
            if (outside) {
                ASSERT_EQ(alphaAt(r.image, x, y), 0.f) << x << "," << y;
            }
        }
}

TEST(ReyesAnalytic, MatteSquareHasLambertShading) {
    // Matte, ambient 0.2 + one distant light: Ci = Cs * (Ka*0.2 + Kd * max(0, N.L)), with N facing the eye.
    Scene s = cameraSpaceScene(64, 64, 40.f);
    addPatch(s, flatSquare(2.f, 5.f));
    RenderResult r = renderWith(s);
    Vec3 L = -normalize(Vec3{0.3f, -0.4f, 1.f});
    float expected = 0.2f + std::max(0.f, dot(Vec3{0, 0, -1}, L));
    const float* p = r.image.pixel(32, 32);
    EXPECT_NEAR(p[0], expected, 1e-3f);
    EXPECT_NEAR(p[1], expected, 1e-3f);
    EXPECT_EQ(p[3], 1.f);
}

TEST(ReyesCulling, PatchBehindCameraOrOutsideViewIsCulled) {
    Scene s = cameraSpaceScene(64, 64, 40.f);
    addPatch(s, flatSquare(2.f, -5.f));             // behind the eye
    addPatch(s, flatSquare(2.f, 5.f, 100.f, 0.f));  // far to the right of the view
    RenderResult r = renderWith(s);
    EXPECT_EQ(r.stats["patches_culled"].get<int>(), 2);
    EXPECT_EQ(r.stats["grids"].get<int>(), 0);
    EXPECT_EQ(alphaSum(r.image), 0.0);
}

TEST(ReyesCulling, PatchCrossingTheEyePlaneIsSplitNotProjected) {
    // A floor running from behind the camera to far in front: the part in front must render, finite.
    Scene s = cameraSpaceScene(96, 64, 60.f);
    BezierPatch floor;
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 4; ++u) floor.at(u, v) = {-20.f + 40.f * u / 3.f, -1.f, -10.f + 60.f * v / 3.f};
    addPatch(s, floor);
    RenderResult r = renderWith(s);
    // The bottom half of the image sees the floor, the top half sky.
    EXPECT_EQ(alphaAt(r.image, 48, 60), 1.f);
    EXPECT_EQ(alphaAt(r.image, 48, 5), 0.f);
    for (float v : r.image.rgba) ASSERT_TRUE(std::isfinite(v));
}

// Watertightness: a closed surface over an empty background must have alpha exactly 1 at every pixel
// whose filter support lies inside the silhouette, whatever the resolution and shading rate.
struct WatertightCase {
    int width, height;
    float shadingRate;
    int maxGrid;
};
class ReyesWatertight : public ::testing::TestWithParam<WatertightCase> {};

TEST_P(ReyesWatertight, SphereHasNoPinholes) {
    const WatertightCase c = GetParam();
    Scene s = cameraSpaceScene(c.width, c.height, 70.f);
    s.image.pixelSamplesX = s.image.pixelSamplesY = 5;
    // Close to the eye, so strong perspective makes neighbouring patches dice at different rates.
    const Vec3 centre{0.3f, -0.2f, 3.2f};
    const float radius = 1.7f;
    // Rotate the sphere so patch seams and a pole face the camera obliquely.
    Mat4 m = Mat4::translate(centre.x, centre.y, centre.z) * Mat4::rotate(35, 1, 0.4, 0.2) *
             Mat4::translate(-centre.x, -centre.y, -centre.z);
    for (BezierPatch p : octantSphere(radius, centre)) {
        for (Vec3& cp : p.cp) cp = m.point(cp);
        addPatch(s, p);
    }
    for (auto& a : s.attributes) a.shadingRate = c.shadingRate;
    RenderSettings rs;
    rs.threads = 2;
    rs.maxGridEdge = c.maxGrid;
    RenderResult r = render(s, rs);
    // Truth from ray casting: a pixel must be covered if the rays through its corners all hit a sphere
    // 1% smaller (the bicubic sphere deviates from a true sphere by < 0.03%).
    Projector proj(s.camera);
    auto rayHitsSphere = [&](float rx, float ry) {
        // Raster -> camera-space direction through z = 1.
        Vec3 dir = normalize(Vec3{(rx - proj.ox) / proj.sx, (ry - proj.oy) / proj.sy, 1.f});
        float b = dot(dir, centre), r = radius * 0.99f;
        return b * b - (dot(centre, centre) - r * r) > 0.f;
    };
    int checked = 0, holes = 0;
    for (int y = 0; y < c.height; ++y)
        for (int x = 0; x < c.width; ++x) {
            if (!(rayHitsSphere(x, y) && rayHitsSphere(x + 1, y) && rayHitsSphere(x, y + 1) &&
                  rayHitsSphere(x + 1, y + 1)))
                continue;
            ++checked;
            if (alphaAt(r.image, x, y) != 1.f) ++holes;
        }
    EXPECT_GT(checked, 50);
    EXPECT_EQ(holes, 0) << "pinhole pixels inside the silhouette, of " << checked << "; micropolygons "
                        << r.stats["micropolygons"] << " grids " << r.stats["grids"];
}

INSTANTIATE_TEST_SUITE_P(
    Resolutions, ReyesWatertight,
    ::testing::Values(WatertightCase{64, 48, 1.f, 16}, WatertightCase{200, 150, 0.5f, 16},
                      WatertightCase{301, 217, 4.f, 16}, WatertightCase{256, 256, 1.f, 3},
                      WatertightCase{480, 360, 2.f, 7}, WatertightCase{97, 131, 0.25f, 32},
                      WatertightCase{320, 240, 16.f, 16}, WatertightCase{400, 300, 64.f, 4}));

TEST(ReyesWatertight, TeapotBodyHasNoPinholesAtManyRates) {
    // The teapot's body and bottom are closed and share edges exactly. Render only those patches
    // (the first 4 body patches x 2 rows and the 4 bottom ones) over black and look for holes inside.
    Scene s = loadScene(std::string(TESSERA_TEST_DATA) + "/teapot.bpt", [](const std::string&) {});
    Scene body = s;
    body.patches.clear();
    body.attributes.clear();
    // Patches 0..7: rim and body (Newell's order); the bottom is the last 4.
    for (int i : {4, 5, 6, 7, 28, 29, 30, 31}) {
        body.patches.push_back(s.patches[i]);
        body.attributes.push_back(s.attributes[i]);
    }
    for (float rate : {0.5f, 1.f, 3.f}) {
        body.camera.width = 320;
        body.camera.height = 240;
        for (auto& a : body.attributes) a.shadingRate = rate;
        body.image.filter = FilterType::Box;
        body.image.filterWidthX = body.image.filterWidthY = 1;
        RenderResult r = renderWith(body);
        // Box filter: alpha is exactly 1 where all samples are covered; look for isolated holes.
        const int pinholes = countPinholes(r.image, 1.f);
        EXPECT_EQ(pinholes, 0) << "shading rate " << rate;
        EXPECT_GT(alphaSum(r.image), 1000.0);
    }
}

TEST(ReyesSampling, TeapotCoverageConvergesWithSpp) {
    Scene s = loadScene(std::string(TESSERA_TEST_DATA) + "/teapot.bpt", [](const std::string&) {});
    s.camera.width = 200;
    s.camera.height = 150;
    auto coverage = [&](int n) {
        s.image.pixelSamplesX = s.image.pixelSamplesY = n;
        return renderWith(s).image;
    };
    Image a4 = coverage(2), a16 = coverage(4), a64 = coverage(8);
    auto meanDiff = [](const Image& a, const Image& b) {
        double d = 0;
        for (size_t i = 3; i < a.rgba.size(); i += 4) d += std::fabs(a.rgba[i] - b.rgba[i]);
        return d / (a.rgba.size() / 4);
    };
    double d4 = meanDiff(a4, a64), d16 = meanDiff(a16, a64);
    EXPECT_LT(d16, 0.01) << "mean |alpha16 - alpha64| = " << d16;
    EXPECT_LT(d16, d4) << "spp 16 should be closer to spp 64 than spp 4 (" << d16 << " vs " << d4 << ")";
    // Total coverage agrees to 0.5%.
    EXPECT_NEAR(alphaSum(a16), alphaSum(a64), 0.005 * alphaSum(a64));
}

TEST(ReyesDeterminism, SameImageForAnyThreadCount) {
    Scene s = loadScene(std::string(TESSERA_TEST_DATA) + "/teapot.bpt", [](const std::string&) {});
    s.camera.width = 160;
    s.camera.height = 120;
    RenderResult a = renderWith(s, 1), b = renderWith(s, 2);
    ASSERT_EQ(a.image.rgba.size(), b.image.rgba.size());
    EXPECT_TRUE(a.image.rgba == b.image.rgba);
}

// The AVX2 sample test (8 samples at a time, 32-bit edge functions relative to the micropolygon's bound)
// against the scalar 64-bit loop: the same samples covered, the same image and attribute planes, the same
// count of tests; a close-up makes micropolygons wider than the AVX2 path's 32 pixels (scalar fallback).
TEST(ReyesRasterize, Avx2SampleTestsEqualTheScalarLoop) {
    // The AVX2 path reads the strata of a micropolygon's bound row by row from the tile's stratum-ordered
    // copy of the positions: square and non-square strata lattices (4x4, 1x2, 2x4), micropolygons of
    // about a pixel, of about 10 x 10 pixels (rows of 40 strata: several 8-lane loads a row) and of about
    // 60 x 60 pixels (the scalar loop's, past the 32-bit range). With the film's attribute channels the
    // AVX2 path writes hit by hit in pixel order; without them (`plain`) it tests depth and writes 8 lanes
    // at once in the tile's stratum order (SampleTile::enterStrataOrder).
    const std::pair<int, int> lattices[] = {{4, 4}, {1, 2}, {2, 4}};
    for (const bool plain : {false, true})
        for (const char* name : {"teapot", "killeroo"}) {
            Scene s = loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/" + name + ".rib",
                                [](const std::string&) {});
            s.camera.width = 200;
            s.camera.height = 150;
            for (const auto& [nx, ny] : lattices)
                for (float shadingRate : {1.f, 100.f, 4000.f}) {
                    if (nx != 4 && shadingRate == 4000.f) continue;
                    s.image.pixelSamplesX = nx, s.image.pixelSamplesY = ny;
                    RenderSettings rs;
                    rs.engine = "reyes";
                    rs.threads = 2;
                    for (PatchAttributes& at : s.attributes) at.shadingRate = shadingRate;
                    rs.output.channels = plain ? 0u : kAllFilmChannels;
                    const Avx2Renders r = renderWithAndWithoutReyesAvx2(s, rs);
                    const RenderResult& a = r.with;
                    const std::string what = std::string(name) + " " + std::to_string(nx) + "x" +
                                             std::to_string(ny) + " rate " + std::to_string(shadingRate) +
                                             (plain ? " (no attribute channels)" : "");
                    std::printf("%s: AVX2 path %s, %llu sample tests\n", what.c_str(), r.avx2 ? "on" : "off",
                                (unsigned long long)a.stats["sample_tests"].get<uint64_t>());
                    expectSameRender(a, r.without, what);
                    EXPECT_GT(a.stats["sample_tests"].get<uint64_t>(), 0u);
                }
        }
}

// A shadow map's depth pass writes straight into the map (rasterizeGridDepth) instead of going through a
// sample tile: against rasterizeGrid on a tile whose samples sit at the texel centres (the AVX2 and the
// scalar path), the same depth in every texel, bit for bit, with fewer sample tests (the centres inside each
// micropolygon's bound, not every texel the bound overlaps). The grids
// overlap one another, reach past the bucket, hold micropolygons from a third of a texel to 100 texels
// wide (past the AVX2 path's 32), degenerate ones, vertices exactly on texel centres (the fill rule
// decides), vertices nearer than the near plane and one one-sided grid; rows of 1 to 20 micropolygons (the
// AVX2 path takes 8 at a time).
TEST(ReyesRasterize, DepthPassEqualsTheSampleTileRasterizer) {
    const int width = 128, height = 96;
    const Rect target{16, 8, 80, 72};
    const float nearZ = 0.5f;
    uint32_t state = 7;
    auto uniform = [&] {
        state = state * 1664525u + 1013904223u;
        return float(state >> 8) / 16777216.f;
    };
    std::vector<Grid> grids;
    for (float texels : {0.35f, 1.f, 1.f, 2.5f, 8.f, 40.f, 100.f})
        for (int copy = 0; copy < 3; ++copy) {
            Grid g;
            g.nu = 1 + int(uniform() * 20.f), g.nv = 1 + int(uniform() * 9.f);  // rows of 8 and fewer
            const float x0 = target.x0 - 6.f + uniform() * (target.width() + 12.f - texels * g.nu * 0.5f);
            const float y0 = target.y0 - 6.f + uniform() * (target.height() + 12.f - texels * g.nv * 0.5f);
            const bool onCentres = copy == 1;  // every vertex on a texel centre (integer steps only)
            const bool collapsedRow = copy == 2;
            for (int j = 0; j <= g.nv; ++j)
                for (int i = 0; i <= g.nu; ++i) {
                    float x = x0 + texels * (i + 0.3f * (uniform() - 0.5f));
                    float y = y0 + texels * ((collapsedRow && j == 1 ? 0 : j) + 0.3f * (uniform() - 0.5f));
                    if (onCentres) x = std::floor(x) + 0.5f, y = std::floor(y) + 0.5f;
                    g.X.push_back(rasterToFixed(x)), g.Y.push_back(rasterToFixed(y));
                    g.Z.push_back(0.3f + 4.f * uniform());  // some in front of the near plane
                    g.front.push_back(uint8_t(uniform() < 0.5f));
                }
            g.R.assign(g.X.size(), 0.f), g.G = g.R, g.B = g.R;
            g.twoSided = copy != 0 || texels != 2.5f;  // as the depth pass dices them, but for one grid
            grids.push_back(std::move(g));
        }
    // The sample tests: the texel centres of the target inside each micropolygon's bound (none for one
    // facing away on a one-sided grid).
    uint64_t centres = 0;
    for (const Grid& g : grids)
        for (int j = 0; j < g.nv; ++j)
            for (int i = 0; i < g.nu; ++i) {
                const int a = j * (g.nu + 1) + i, corners[4] = {a, a + 1, a + g.nu + 2, a + g.nu + 1};
                if (!g.twoSided &&
                    !(g.front[a] | g.front[a + 1] | g.front[a + g.nu + 2] | g.front[a + g.nu + 1]))
                    continue;
                int32_t x0 = INT32_MAX, x1 = INT32_MIN, y0 = INT32_MAX, y1 = INT32_MIN;
                for (int c : corners)
                    x0 = std::min(x0, g.X[c]), x1 = std::max(x1, g.X[c]), y0 = std::min(y0, g.Y[c]),
                    y1 = std::max(y1, g.Y[c]);
                int64_t n = 0;
                for (int y = target.y0; y < target.y1; ++y)
                    for (int x = target.x0; x < target.x1; ++x) {
                        const int32_t cx = x * 256 + 128, cy = y * 256 + 128;
                        n += cx >= x0 && cx <= x1 && cy >= y0 && cy <= y1;
                    }
                centres += uint64_t(n);
            }
    const float inf = std::numeric_limits<float>::infinity(), outside = -7.f;
    for (const bool avx2 : {true, false}) {
        reyesUseAvx2(avx2);
        std::vector<float> depth(size_t(width) * height, outside);
        for (int y = target.y0; y < target.y1; ++y)
            for (int x = target.x0; x < target.x1; ++x) depth[size_t(y) * width + x] = inf;
        uint64_t tests = 0;
        for (const Grid& g : grids) tests += rasterizeGridDepth(g, target, depth.data(), width, nearZ);
        SampleTile tile;
        tile.deferPixelFill = true;
        tile.reset(target, 1, 1, 0, inf, SamplerKind::Jittered);
        size_t i = 0;
        for (int y = target.y0; y < target.y1; ++y)
            for (int x = target.x0; x < target.x1; ++x, ++i)
                tile.sx[i] = (x << kSubpixelBits) + 128, tile.sy[i] = (y << kSubpixelBits) + 128;
        uint64_t tileTests = 0;
        for (const Grid& g : grids) tileTests += rasterizeGrid(g, tile, nearZ);
        tile.leaveStrataOrder();
        EXPECT_EQ(tests, centres) << "AVX2 " << avx2;
        int covered = 0, differ = 0;
        i = 0;
        for (int y = 0; y < height; ++y)
            for (int x = 0; x < width; ++x) {
                const float d = depth[size_t(y) * width + x];
                if (x < target.x0 || x >= target.x1 || y < target.y0 || y >= target.y1) {
                    differ += d != outside;  // nothing written beside the bucket
                    continue;
                }
                const float want = tile.z[size_t(y - target.y0) * target.width() + size_t(x - target.x0)];
                differ += std::memcmp(&d, &want, sizeof d) != 0;
                covered += d < inf;
            }
        std::printf("AVX2 %d: %d of %d texels covered, %d differ; %llu sample tests (the tile's: %llu)\n",
                    int(avx2), covered, target.width() * target.height(), differ, (unsigned long long)tests,
                    (unsigned long long)tileTests);
        EXPECT_EQ(differ, 0) << "AVX2 " << avx2;
        EXPECT_GT(covered, target.width() * target.height() / 2);
    }
    reyesUseAvx2(true);
}

TEST(ReyesWatertight, EdgesSharedOnlyUpToRoundingAreWelded) {
    // Perturb every patch independently by ~1e-6 relative, as a basis conversion's rounding would: shared
    // edges are then equal only approximately. The weld pass must restore watertightness.
    Scene s = loadScene(std::string(TESSERA_TEST_DATA) + "/teapot.bpt", [](const std::string&) {});
    Scene body = s;
    body.patches.clear();
    body.attributes.clear();
    uint32_t state = 12345;
    auto noise = [&] {
        state = state * 1664525u + 1013904223u;
        return (float(state >> 8) / 16777216.f - 0.5f) * 6e-6f;
    };
    for (int i : {4, 5, 6, 7, 28, 29, 30, 31}) {
        BezierPatch p = s.patches[i];
        for (Vec3& c : p.cp) c += Vec3{noise(), noise(), noise()};
        body.patches.push_back(p);
        body.attributes.push_back(s.attributes[i]);
    }
    body.camera.width = 320;
    body.camera.height = 240;
    body.image.filter = FilterType::Box;
    body.image.filterWidthX = body.image.filterWidthY = 1;
    for (auto& a : body.attributes) a.shadingRate = 4.f;
    RenderResult r = renderWith(body);
    EXPECT_GT(r.stats["welded_edges"].get<int>(), 0);
    const int pinholes = countPinholes(r.image, 1.f);
    EXPECT_EQ(pinholes, 0);
}

TEST(Weld, UnifiesNearlyEqualEdgesAndLeavesDistinctOnesAlone) {
    BezierPatch a = flatSquare(2.f, 5.f, 0.f, 0.f), b = flatSquare(2.f, 5.f, 2.f, 0.f);
    // b's u=0 edge coincides with a's u=1 edge up to 1e-7.
    for (int v = 0; v < 4; ++v) b.at(0, v) += Vec3{1e-7f, -1e-7f, 0.f};
    BezierPatch far = flatSquare(2.f, 5.f, 10.f, 0.f);
    std::vector<BezierPatch> ps = {a, b, far};
    WeldResult w = weldSharedEdges(ps, 1e-5f);
    for (int v = 0; v < 4; ++v) EXPECT_TRUE(ps[1].at(0, v) == ps[0].at(3, v)) << v;
    EXPECT_EQ(w.cornersMoved, 2u);
    EXPECT_EQ(w.edgesWelded, 1u);
    for (int k = 0; k < 16; ++k) EXPECT_TRUE(ps[2].cp[k] == far.cp[k]);
}

// Edges are grouped by their end corners' representatives: corners at -0 and +0 are one corner (as the
// positions compare), and a pole where many patches meet (more edges at one corner than the small-bucket
// sort takes) still welds every shared edge onto its first patch's copy.
TEST(Weld, SignedZeroCornersAndAPoleOfManyPatchesWeld) {
    {
        BezierPatch a = flatSquare(2.f, 5.f, -1.f, 0.f), b = flatSquare(2.f, 5.f, 1.f, 0.f);
        for (int v = 0; v < 4; ++v) a.at(3, v).x = 0.f, b.at(0, v).x = -0.f;  // the shared edge at x = 0
        b.at(0, 1).y += 1e-7f, b.at(0, 2).y -= 1e-7f;                         // its inner points a bit off
        std::vector<BezierPatch> ps = {a, b};
        const WeldResult w = weldSharedEdges(ps, 1e-5f);
        EXPECT_EQ(w.edgesWelded, 1u);
        for (int v = 0; v < 4; ++v) EXPECT_TRUE(ps[1].at(0, v) == ps[0].at(3, v)) << v;
    }
    // 48 wedges around the origin: wedge k spans angles k and k + 1; its v = 0 edge runs from the pole out
    // along angle k, its v = 3 edge along angle k + 1 (wedge k + 1's v = 0 edge, jittered there).
    const int n = 48;
    const float tol = 1e-4f;
    auto ray = [&](int k, float r) {
        const double a = 2.0 * 3.14159265358979 * (k % n) / n;
        return Vec3{float(r * std::cos(a)), float(r * std::sin(a)), 0.f};
    };
    std::vector<BezierPatch> ps(n);
    for (int k = 0; k < n; ++k)
        for (int v = 0; v < 4; ++v)
            for (int u = 0; u < 4; ++u) {
                const Vec3 a = ray(k, 1.f + u / 3.f), b = ray(k + 1, 1.f + u / 3.f);
                ps[size_t(k)].at(u, v) = a * (1.f - v / 3.f) + b * (v / 3.f);
                if (u == 0) ps[size_t(k)].at(u, v) = ray(k, 0.f);  // the pole (some coordinates -0)
            }
    // Shared edge between wedge k (v = 3) and wedge k + 1 (v = 0): the later patch's copy is jittered.
    for (int k = 0; k + 1 < n; ++k)
        for (int u = 1; u < 4; ++u) ps[size_t(k + 1)].at(u, 0) += Vec3{2e-5f, -2e-5f, 1e-5f};
    const std::vector<BezierPatch> before = ps;
    const WeldResult w = weldSharedEdges(ps, tol);
    size_t wrong = 0;
    for (int k = 0; k + 1 < n; ++k)
        for (int u = 0; u < 4; ++u) wrong += !(ps[size_t(k + 1)].at(u, 0) == before[size_t(k)].at(u, 3));
    // The last wedge's v = 3 edge meets the first wedge's v = 0 edge: the first patch keeps its own copy.
    for (int u = 0; u < 4; ++u) wrong += !(ps[size_t(n - 1)].at(u, 3) == before[0].at(u, 0));
    EXPECT_EQ(wrong, 0u);
    EXPECT_GE(w.edgesWelded, size_t(n - 1));
}

// A corner whose block index does not fit 32 bits (2^31 blocks of 64 tol from the origin) is clamped and
// taken by the pass in patch order: the pair near the origin still welds, the far patches (which share an
// exact edge there) are left as they are.
TEST(Weld, CornersBeyondThirtyTwoBitBlocksAreLeftToThePatchOrderPass) {
    BezierPatch a = flatSquare(2.f, 5.f, 0.f, 0.f), b = flatSquare(2.f, 5.f, 2.f, 0.f);
    for (int v = 0; v < 4; ++v) b.at(0, v) += Vec3{1e-7f, -1e-7f, 0.f};
    BezierPatch farA = flatSquare(2.f, 5.f, 0.f, 0.f), farB = flatSquare(2.f, 5.f, 2.f, 0.f);
    for (int k = 0; k < 16; ++k) farA.cp[k].x += 1e12f, farB.cp[k].x += 1e12f;
    std::vector<BezierPatch> ps = {a, b, farA, farB};
    const WeldResult w = weldSharedEdges(ps, 1e-5f);
    for (int v = 0; v < 4; ++v) EXPECT_TRUE(ps[1].at(0, v) == ps[0].at(3, v)) << v;
    EXPECT_EQ(w.cornersMoved, 2u);
    EXPECT_EQ(w.edgesWelded, 1u);
    for (int k = 0; k < 16; ++k) EXPECT_TRUE(ps[2].cp[k] == farA.cp[k] && ps[3].cp[k] == farB.cp[k]) << k;
}

// A 120 x 120 grid of patches whose shared control points differ by up to half the tolerance: the weld
// (in parallel by blocks of cells, and by edge keys) must give every shared point the value of its copy in
// the first patch in order, as one greedy pass in patch order does, and move every other copy.
// An n x n grid of unit patches whose control points are moved by +-(0.1 .. 0.25) tol (never 0) each, so
// that shared points match only up to tol. `copies`, when given: every control point by its exact grid
// position (in thirds), as (patch, cp) copies in patch order.
std::vector<BezierPatch> jitteredPatchGrid(
    int n, float tol, std::map<std::pair<int, int>, std::vector<std::pair<size_t, int>>>* copies) {
    std::vector<BezierPatch> ps(size_t(n) * n);
    // The weld decides the corners of a block of 64 tol that all lie inside it on their own (in parallel),
    // the others in patch order: the grid lies mid-block in z so that both kinds occur (at z = 0 every corner
    // would lie on a block side).
    const float zMid = 32.f * tol;
    uint32_t state = 12345u;
    auto jitter = [&]() {
        state = state * 1664525u + 1013904223u;
        const float m = 0.1f + 0.15f * float(state >> 8) / float(1u << 24);
        return (state & 1u) ? m * tol : -m * tol;
    };
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            const size_t pi = size_t(j) * n + size_t(i);
            for (int row = 0; row < 4; ++row)
                for (int col = 0; col < 4; ++col) {
                    ps[pi].cp[row * 4 + col] = Vec3{float(i) + float(col) / 3.f + jitter(),
                                                    float(j) + float(row) / 3.f + jitter(), zMid + jitter()};
                    if (copies) (*copies)[{3 * i + col, 3 * j + row}].push_back({pi, row * 4 + col});
                }
        }
    return ps;
}

TEST(Weld, AGridOfJitteredPatchesTakesEachSharedPointFromItsFirstPatch) {
    const int n = 120;
    const float tol = 1e-3f;
    std::map<std::pair<int, int>, std::vector<std::pair<size_t, int>>> copies;
    std::vector<BezierPatch> ps = jitteredPatchGrid(n, tol, &copies);
    const std::vector<BezierPatch> before = ps;
    const WeldResult w = weldSharedEdges(ps, tol);
    size_t moved = 0, shared = 0, wrong = 0;
    for (const auto& [position, list] : copies) {
        if (list.size() < 2) continue;
        ++shared;
        const Vec3 first = before[list[0].first].cp[list[0].second];
        for (const auto& [pi, cp] : list) wrong += !(ps[pi].cp[cp] == first);
        moved += list.size() - 1;
    }
    EXPECT_EQ(wrong, 0u) << "of " << shared << " shared points";
    // Inner grid corners have 4 copies (3 move), those on the border but not at a grid corner 2 (1 moves).
    const size_t sharedCorners = size_t(n - 1) * (n - 1) * 3 + size_t(4 * (n - 1));
    EXPECT_EQ(w.cornersMoved, sharedCorners);
    EXPECT_EQ(w.edgesWelded, size_t(2) * n * (n - 1));
    EXPECT_GT(moved, w.cornersMoved);  // the edges' inner points moved too
}

// The weld's plan (kept for motion blur) replayed on the patches before the weld gives the welded patches
// bit for bit, and neither the patches nor the plan depend on the thread count. A patch with a NaN corner
// and one with an infinite corner take part only through their finite corners. The grid is large enough
// that the corner grouping takes both its levels (runs of buckets, then buckets).
TEST(Weld, ThePlanReplaysTheWeldAndNothingDependsOnTheThreadCount) {
    const int n = 150;
    const float tol = 1e-3f;
    std::vector<BezierPatch> original = jitteredPatchGrid(n, tol, nullptr);
    original[7].cp[0].x = std::numeric_limits<float>::quiet_NaN();
    original[size_t(n) * 40 + 3].cp[15].y = std::numeric_limits<float>::infinity();
    std::vector<BezierPatch> one = original, four = original;
    WeldPlan planOne, planFour;
    WeldResult wOne, wFour;
    tbb::task_arena(1).execute([&] { wOne = weldSharedEdges(one, tol, &planOne); });
    tbb::task_arena(4).execute([&] { wFour = weldSharedEdges(four, tol, &planFour); });
    EXPECT_EQ(wOne.cornersMoved, wFour.cornersMoved);
    EXPECT_EQ(wOne.edgesWelded, wFour.edgesWelded);
    // Every inner grid corner has 3 copies to move and each border one 1. Each non-finite corner removes one
    // move: the NaN one is the second copy of a border corner (not moved now), the infinite one the first
    // copy of an inner corner (whose 3 other copies keep 2 moves).
    const size_t sharedCorners = size_t(n - 1) * (n - 1) * 3 + size_t(4 * (n - 1));
    EXPECT_EQ(wOne.cornersMoved, sharedCorners - 2);
    ASSERT_EQ(planOne.size(), planFour.size());
    size_t samePlan = 0;
    for (size_t i = 0; i < planOne.size(); ++i)
        samePlan += planOne[i].dstPatch == planFour[i].dstPatch &&
                    planOne[i].srcPatch == planFour[i].srcPatch && planOne[i].dstCp == planFour[i].dstCp &&
                    planOne[i].srcCp == planFour[i].srcCp;
    EXPECT_EQ(samePlan, planOne.size());
    std::vector<BezierPatch> replayed = original;
    applyWeldPlan(planOne, replayed);
    size_t differ = 0, replayDiffers = 0, moved = 0;
    for (size_t pi = 0; pi < original.size(); ++pi)
        for (int k = 0; k < 16; ++k) {
            auto bits = [](Vec3 v) {
                uint32_t b[3];
                std::memcpy(b, &v, sizeof b);
                return std::array<uint32_t, 3>{b[0], b[1], b[2]};
            };
            differ += bits(one[pi].cp[k]) != bits(four[pi].cp[k]);
            replayDiffers += bits(replayed[pi].cp[k]) != bits(one[pi].cp[k]);
            moved += bits(one[pi].cp[k]) != bits(original[pi].cp[k]);
        }
    EXPECT_EQ(differ, 0u);
    EXPECT_EQ(replayDiffers, 0u);
    EXPECT_GT(moved, wOne.cornersMoved);
    EXPECT_TRUE(std::isnan(one[7].cp[0].x));
    EXPECT_TRUE(std::isinf(one[size_t(n) * 40 + 3].cp[15].y));
}

// A corner within tol of two representatives snaps onto the one the cell search finds first: the one in
// its own cell, even when the other (in a neighbour cell) was made earlier. Both ways of searching must
// agree: the linear search of a small block and the cell table (the corners near a block side, here more
// than 32 of them).
TEST(Weld, ACornerNearTwoRepresentativesTakesTheOneInItsOwnCell) {
    const float tol = 0.01f;                 // cells of 4 tol = 0.04, blocks of 16 cells = 0.64
    auto patchAt = [](Vec3 c0, float far) {  // corner 0 at c0, the other three far apart
        BezierPatch p;
        const Vec3 c[4] = {c0, {far, 100.f, 0.f}, {far, 200.f, 0.f}, {far, 300.f, 0.f}};
        for (int j = 0; j < 4; ++j)
            for (int i = 0; i < 4; ++i) {
                const float u = float(i) / 3.f, v = float(j) / 3.f;
                p.cp[j * 4 + i] =
                    c[0] * ((1 - u) * (1 - v)) + c[1] * (u * (1 - v)) + c[2] * ((1 - u) * v) + c[3] * (u * v);
            }
        return p;
    };
    for (float shift : {0.f, 0.64f - 0.0405f}) {  // inside a block; the trio near a block's upper side
        // A in cell 0 (made first), B in cell 1, 0.0159 from A (> tol: its own representative); P in cell
        // 1, 0.0065 from A and 0.0094 from B.
        const Vec3 A{0.039f + shift, 0.02f, 0.02f}, B{0.0549f + shift, 0.02f, 0.02f},
            P{0.0455f + shift, 0.02f, 0.02f};
        std::vector<BezierPatch> ps = {patchAt(A, 1000.f), patchAt(B, 2000.f), patchAt(P, 3000.f)};
        if (shift > 0.f)  // 40 more corners near block sides: the rest takes the table
            for (int k = 0; k < 40; ++k)
                ps.push_back(patchAt({0.64f * float(k + 3) + 0.001f, 5.f * k, 0.f}, 4000.f + k));
        weldSharedEdges(ps, tol);
        EXPECT_TRUE(ps[2].cp[0] == B) << "shift " << shift;
        EXPECT_TRUE(ps[0].cp[0] == A && ps[1].cp[0] == B) << "shift " << shift;
    }
}

TEST(ReyesSides, OneSidedSurfacesFacingAwayAreCulled) {
    // flatSquare has dP/du x dP/dv = +z, pointing away from the eye: back-facing unless flipped.
    Scene s = cameraSpaceScene(64, 64, 40.f);
    addPatch(s, flatSquare(2.f, 5.f));
    s.attributes[0].twoSided = false;
    EXPECT_EQ(alphaSum(renderWith(s).image), 0.0) << "Sides 1, facing away";
    s.attributes[0].flipNormal = true;  // e.g. ReverseOrientation
    EXPECT_GT(alphaSum(renderWith(s).image), 100.0) << "Sides 1, facing the eye";
    s.attributes[0].twoSided = true;
    s.attributes[0].flipNormal = false;
    EXPECT_GT(alphaSum(renderWith(s).image), 100.0) << "Sides 2";
}

// DiagSplit's rule (split.cpp): an edge longer on screen than the grid limit is cut at its parametric
// middle and each half measured again, so a surface whose edges reach far off screen (a ground plane
// running under the camera, a sky sphere around it) is diced for the part in view. With one uniform
// lattice per edge these made 43 M and 19 M micropolygons for a few thousand pixels.
TEST(ReyesSplit, SurfacesReachingBehindTheEyeAreDicedForTheirPartInView) {
    struct Case {
        const char* name;
        const char* rib;
        double minCoverage;
    } cases[] = {
        {"ground plane under the camera",
         "Format 160 120 1\nPixelSamples 2 2\nProjection \"perspective\" \"fov\" [50]\nRotate -95 1 0 0\n"
         "Translate 0 0 -1\nWorldBegin\nSurface \"constant\"\n"
         "Patch \"bilinear\" \"P\" [-500 -500 0 500 -500 0 -500 500 0 500 500 0]\nWorldEnd\n",
         0.5},
        {"sky sphere around the camera",
         "Format 160 120 1\nPixelSamples 2 2\nProjection \"perspective\" \"fov\" [50]\nWorldBegin\n"
         "Surface \"constant\"\nSphere 50 -50 50 360\nWorldEnd\n",
         1.0},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.name);
        const std::string path = tessera::test::writeTestFile("scene.rib", c.rib);
        Scene s = loadScene(path, [](const std::string&) {});
        RenderResult r = renderWith(s);
        const double pixels = 160.0 * 120.0;
        const double micropolygons = r.stats["micropolygons"].get<double>();
        std::cout << c.name << ": " << micropolygons << " micropolygons for " << pixels << " pixels\n";
        EXPECT_LT(micropolygons, 20.0 * pixels);
        EXPECT_GE(alphaSum(r.image), c.minCoverage * pixels - 1.0);  // and nothing in view went missing
    }
}

// Splitting on demand (LazyPieces, reyes/pipeline.h) must hand each bucket exactly the pieces, in the same
// order, that splitting every surface up front and binning the pieces gives (splitPatches + binPieces, the
// engine's earlier path, kept as this oracle), with the same split counts; and it must free a surface's
// pieces after its last bucket, so that fewer are alive at once than the frame makes.
TEST(LazyPieces, BucketsSeeTheUpFrontSplitsPiecesInOrder) {
    struct Case {
        const char* name;
        std::string path;
        int bucketSize;
        float shadingRate;  // > 0: a shadow map's override
    } cases[] = {
        {"teapot", std::string(TESSERA_SOURCE_DIR) + "/scenes/teapot.rib", 16, 0.f},
        {"killeroo", std::string(TESSERA_SOURCE_DIR) + "/scenes/killeroo.rib", 32, 0.f},
        {"quadrics", std::string(TESSERA_SOURCE_DIR) + "/scenes/quadrics.rib", 16, 0.f},
        {"displaced teapot", std::string(TESSERA_SOURCE_DIR) + "/scenes/displaced_teapot.rib", 16, 0.f},
        {"bigguy, coarse override", std::string(TESSERA_SOURCE_DIR) + "/scenes/bigguy.rib", 64, 4.f},
        {"ground plane through the eye plane",
         tessera::test::writeTestFile(
             "ground.rib",
             "Format 160 120 1\nPixelSamples 2 2\nProjection \"perspective\" \"fov\" [50]\nRotate -95 1 0 0\n"
             "Translate 0 0 -1\nWorldBegin\nSurface \"constant\"\n"
             "Patch \"bilinear\" \"P\" [-500 -500 0 500 -500 0 -500 500 0 500 500 0]\nWorldEnd\n"),
         16, 0.f},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.name);
        Scene scene = loadScene(c.path, [](const std::string&) {});
        RenderSettings rs;
        const FrameSetup frame(scene, rs);
        PatchArray patches = patchesInCameraSpace(scene, frame.camera.cameraFromWorld);
        weldSharedEdges(patches, defaultWeldTolerance(patches));
        const std::vector<PlacedQuadric> quadrics = quadricsInSpace(scene, frame.camera.cameraFromWorld);
        ReyesView view(frame.camera);
        view.patches = patches.data();
        view.quadrics = quadrics.data();
        view.projector = frame.projector;
        const DisplacementFrame disp = makeDisplacementFrame(
            scene, frame.textures.get(), patches, float(frame.camera.cameraFromWorld.maxStretch()));
        if (disp.any()) view.displacement = &disp;
        const Rect& region = frame.region;
        view.cullX0 = float(region.x0 - 3), view.cullY0 = float(region.y0 - 3);
        view.cullX1 = float(region.x1 + 3), view.cullY1 = float(region.y1 + 3);
        const BucketLayout layout(region, c.bucketSize);

        SplitStats upFrontStats;
        const PieceList upFront = splitPatches(view, scene, c.shadingRate, nullptr, upFrontStats);
        const BucketedPieces binned = binPieces(upFront, layout, 3, 3, 16);
        LazyPieces lazy(view, scene, c.shadingRate, layout, 3, 3, 16);

        uint64_t visits = 0, mismatches = 0;
        for (int b = 0; b < layout.count(); ++b) {
            uint32_t k = binned.start[b];
            lazy.forEach(
                b, [](const Piece&, Grid&) {},
                [&](const Piece& p, const Grid&) {
                    ++visits;
                    if (k >= binned.start[b + 1]) {
                        ++mismatches;
                        return;
                    }
                    const Piece& q = upFront[binned.pieces[k++]];
                    bool same = p.patch == q.patch && p.x0 == q.x0 && p.y0 == q.y0 && p.x1 == q.x1 &&
                                p.y1 == q.y1 && pieceGridU(p) == pieceGridU(q) &&
                                pieceGridV(p) == pieceGridV(q);
                    for (int i = 0; i < 4; ++i)
                        same = same && p.uv[i].x == q.uv[i].x && p.uv[i].y == q.uv[i].y;
                    mismatches += !same;
                });
            mismatches += binned.start[b + 1] - k;  // pieces the lazy bucket did not see
        }
        const SplitStats lazyStats = lazy.stats();
        std::cout << c.name << ": " << upFront.size() << " pieces, " << visits << " bucket visits, at most "
                  << lazy.peakPieces() << " alive at once\n";
        EXPECT_GT(upFront.size(), 0u);
        EXPECT_EQ(visits, binned.pieces.size());
        EXPECT_EQ(mismatches, 0u);
        EXPECT_EQ(lazy.pieceCount(), upFront.size());
        EXPECT_EQ(lazyStats.splits, upFrontStats.splits);
        EXPECT_EQ(lazyStats.pieceCulls, upFrontStats.pieceCulls);
        EXPECT_EQ(lazyStats.patchesCulled, upFrontStats.patchesCulled);
        EXPECT_EQ(lazy.piecesBeyondSurface(), 0u);
        EXPECT_LE(lazy.peakPieces(), upFront.size());
        // Killeroo covers many bucket rows: surfaces finished above the current row are freed.
        if (std::string(c.name) == "killeroo") {
            EXPECT_LT(lazy.peakPieces(), upFront.size() / 2);
        }
    }
}

}  // namespace tessera::test::reyes_tests
