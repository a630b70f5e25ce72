// Motion blur and depth of field (issue 11, docs/motion.md): the blurred film against analytic truth
// (time-averaged coverage of a moving square, the thin-lens circle of confusion of an edge), the three
// sampling schemes against each other, and the engines against each other.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <numbers>
#include <string>

#include "core/hash.h"
#include "core/motion_transform.h"
#include "film/blur_pattern.h"
#include "film/image_compare.h"
#include "io/image_io.h"
#include "io/scene_loader.h"
#include "render/render.h"
#include "reyes/grid.h"
#include "reyes/rasterize.h"
#include "reyes/split.h"
#include "test_util.h"

namespace tessera::test::motion_tests {

namespace {

// `p` turned by `degrees` about the view axis through depth `depth` (the line x = y = 0 there).
BezierPatch turnedAboutViewAxis(const BezierPatch& p, double degrees, float depth) {
    const Mat4 r = Mat4::rotate(degrees, 0, 0, 1);
    BezierPatch turned;
    for (int c = 0; c < 16; ++c) turned.cp[c] = r.point(p.cp[c] - Vec3{0, 0, depth}) + Vec3{0, 0, depth};
    return turned;
}

// A patch moving linearly from `a` (time 0) to `b` (time 1).
void addMovingPatch(Scene& s, const BezierPatch& a, const BezierPatch& b, uint32_t object = 0) {
    addPatch(s, a, object);
    PatchAttributes& attr = s.attributes.back();
    attr.motion.first = uint32_t(s.motionPatches.size());
    attr.motion.count = 2;
    s.motionPatches.push_back(a);
    s.motionPatches.push_back(b);
    s.motionTimes.push_back(0.f);
    s.motionTimes.push_back(1.f);
}

// Constant white surface (colour = coverage), box filter one pixel wide: a pixel's alpha is its
// time- (and lens-) averaged coverage.
Scene coverageScene(int w, int h) {
    Scene s = cameraSpaceScene(w, h, 40.f);
    s.materials[0] = defaultMaterial(MaterialType::Constant);
    s.camera.shutterOpen = 0.f;
    s.camera.shutterClose = 1.f;
    return s;
}

// Samples per pixel come from the scene (setSpp).
RenderSettings settingsFor(const char* engine, BlurSampling scheme = BlurSampling::BoundingBox) {
    RenderSettings rs;
    rs.engine = engine;
    rs.threads = 2;
    rs.blur.sampling = scheme;
    return rs;
}

// Eight patches of a sphere of radius 0.8 moving from centre `from` to `to` over the shutter [0, 1], through
// a lens (f/4, focal length 0.5) focused at depth 3.
Scene movingSphereThroughLens(int width, int height, Vec3 from, Vec3 to) {
    Scene s = cameraSpaceScene(width, height, 40.f);
    s.camera.shutterClose = 1.f;
    s.camera.fStop = 4.f;
    s.camera.focalLength = 0.5f;
    s.camera.focalDistance = 3.f;
    const auto a = octantSphere(0.8f, from), b = octantSphere(0.8f, to);
    for (size_t i = 0; i < a.size(); ++i) addMovingPatch(s, a[i], b[i]);
    return s;
}

void setSpp(Scene& s, int nx, int ny) {
    s.image.pixelSamplesX = nx;
    s.image.pixelSamplesY = ny;
}

void dumpIfAsked(const Image& im, const std::string& name) {
    if (const char* dir = std::getenv("TESSERA_TEST_IMAGES"))
        writePng(std::string(dir) + "/" + name + ".png", im, {});
}

// Overlap of [a0, a1] with [b0, b1].
double overlap(double a0, double a1, double b0, double b1) {
    return std::max(0.0, std::min(a1, b1) - std::max(a0, b0));
}

double rmse(const Image& a, const Image& b) {
    double s = 0;
    for (size_t i = 0; i < a.rgba.size(); ++i) s += (a.rgba[i] - b.rgba[i]) * (a.rgba[i] - b.rgba[i]);
    return std::sqrt(s / a.rgba.size());
}

}  // namespace

TEST(MotionBlur, MovingSquareCoverageIsTheTimeAveragedSweep) {
    // A square at depth 5 slides +0.6 along x over the shutter. The raster x of its edges moves linearly
    // (a fronto-parallel square: raster = x / z * sx + ox), so the alpha of pixel column [x, x + 1] in a row
    // the square covers is the time average of the overlap of [x, x+1] with [L(t), R(t)], integrated here by
    // brute force over 20000 time steps.
    Scene s = coverageScene(96, 64);
    addMovingPatch(s, flatSquare(1.f, 5.f, -0.3f, 0.f), flatSquare(1.f, 5.f, 0.3f, 0.f));
    setSpp(s, 16, 16);
    const Projector pr(s.camera);
    const double L0 = (-0.8 / 5.0) * pr.sx + pr.ox, R0 = (0.2 / 5.0) * pr.sx + pr.ox;
    const double shift = (0.6 / 5.0) * pr.sx;
    const int y = 32;  // a row inside the square at every time
    for (const char* engine : {"reyes", "rt"}) {
        for (BlurSampling scheme :
             {BlurSampling::BoundingBox, BlurSampling::Interleaved, BlurSampling::Simple}) {
            const RenderResult r = render(s, settingsFor(engine, scheme));
            dumpIfAsked(r.image, std::string("moving_square_") + engine + "_" + blurSamplingName(scheme));
            double maxErr = 0, sumErr = 0;
            for (int x = 0; x < s.camera.width; ++x) {
                double expected = 0;
                const int steps = 20000;
                for (int k = 0; k < steps; ++k) {
                    const double t = (k + 0.5) / steps;
                    expected += overlap(x, x + 1, L0 + shift * t, R0 + shift * t);
                }
                expected /= steps;
                const double err = std::abs(alphaAt(r.image, x, y) - expected);
                maxErr = std::max(maxErr, err);
                sumErr += err;
            }
            SCOPED_TRACE(std::string(engine) + " " + blurSamplingName(scheme));
            RecordProperty(std::string("max_error_") + engine + "_" + blurSamplingName(scheme),
                           std::to_string(maxErr));
            // 256 samples per pixel. bbox and simple: each pixel's (x, t) pairs are jointly stratified (one
            // Sobol' point), a few 1/256 at worst. Interleaved: a pixel's times are stratified but paired
            // with its film positions by a permutation (a Latin hypercube), so its error is about twice as
            // large.
            const bool interleaved = scheme == BlurSampling::Interleaved;
            EXPECT_LT(maxErr, interleaved ? 0.04 : 0.02) << "max |alpha - analytic| over the row";
            EXPECT_LT(sumErr / s.camera.width, interleaved ? 0.008 : 0.004)
                << "mean |alpha - analytic| over the row";
        }
    }
}

TEST(MotionBlur, NoBlurRendersTheShutterOpenPosition) {
    Scene s = coverageScene(96, 64);
    addMovingPatch(s, flatSquare(1.f, 5.f, -0.3f, 0.f), flatSquare(1.f, 5.f, 0.3f, 0.f));
    Scene sharp = coverageScene(96, 64);
    addPatch(sharp, flatSquare(1.f, 5.f, -0.3f, 0.f));
    for (const char* engine : {"reyes", "rt"}) {
        RenderSettings rs = settingsFor(engine);
        rs.blur.enabled = false;
        const RenderResult blurOff = render(s, rs);
        const RenderResult reference = render(sharp, settingsFor(engine));
        EXPECT_EQ(blurOff.image.rgba, reference.image.rgba) << engine;
    }
}

TEST(DepthOfField, EdgeBlurIsTheThinLensCircleOfConfusion) {
    // A square nearer than the focal plane: every point of it is imaged as a disk of radius
    // c = lensRadius * |1/fd - 1/z| * sx pixels (thin lens), so across its left edge the alpha is the
    // fraction of that disk on the square's side of the edge line: for signed distance d from the line,
    // A(d) = (acos(-d/c) ... ) the circular-segment area / (pi c^2), box-filtered over the pixel.
    Scene s = coverageScene(128, 64);
    addPatch(s, flatSquare(2.f, 4.f, 0.7f, 0.f));
    s.camera.fStop = 2.f;
    s.camera.focalLength = 2.f;  // lens radius 0.5
    s.camera.focalDistance = 8.f;
    setSpp(s, 16, 16);
    const Projector pr(s.camera);
    const double c = pr.lensRadius * std::abs(1.0 / 8.0 - 1.0 / 4.0) * pr.sx;
    ASSERT_GT(c, 3.0);
    const double edge = (-0.3 / 4.0) * pr.sx + pr.ox;  // raster x of the left edge
    auto covered = [&](double d) {  // fraction of the disk at signed distance d inside the edge
        if (d >= c) return 1.0;
        if (d <= -c) return 0.0;
        // The part of a radius-c disk beyond a chord at distance h from its centre has area
        // c^2 acos(h/c) - h sqrt(c^2 - h^2) (for -c <= h <= c); the square covers the part beyond h = -d.
        const double h = -d;
        return (c * c * std::acos(h / c) - h * std::sqrt(c * c - h * h)) / (std::numbers::pi * c * c);
    };
    for (const char* engine : {"reyes", "rt"}) {
        for (BlurSampling scheme : {BlurSampling::BoundingBox, BlurSampling::Interleaved}) {
            const RenderResult r = render(s, settingsFor(engine, scheme));
            dumpIfAsked(r.image, std::string("dof_edge_") + engine + "_" + blurSamplingName(scheme));
            double maxErr = 0;
            for (int x = int(edge - c) - 2; x <= int(edge + c) + 2; ++x) {
                double expected = 0;
                for (int k = 0; k < 200; ++k) expected += covered(x + (k + 0.5) / 200 - edge);
                expected /= 200;
                maxErr = std::max(maxErr, std::abs(alphaAt(r.image, x, 32) - expected));
                if (std::getenv("TESSERA_TEST_VERBOSE"))
                    printf("x %d alpha %f expected %f\n", x, alphaAt(r.image, x, 32), expected);
            }
            EXPECT_LT(maxErr, 0.04) << engine << " " << blurSamplingName(scheme);
        }
    }
}

TEST(DepthOfField, SquareInTheFocalPlaneStaysSharp) {
    Scene s = coverageScene(96, 64);
    addPatch(s, flatSquare(1.f, 5.f, 0.2f, 0.f));
    Scene pinhole = s;
    s.camera.fStop = 1.f;
    s.camera.focalLength = 1.f;  // a wide lens (radius 0.5)
    s.camera.focalDistance = 5.f;
    setSpp(s, 4, 4);
    setSpp(pinhole, 4, 4);
    for (const char* engine : {"reyes", "rt"}) {
        const RenderResult lens = render(s, settingsFor(engine));
        const RenderResult sharp = render(pinhole, settingsFor(engine));
        double maxErr = 0;
        for (size_t i = 3; i < lens.image.rgba.size(); i += 4)
            maxErr = std::max(maxErr, double(std::abs(lens.image.rgba[i] - sharp.image.rgba[i])));
        // The lens moves an in-focus point by lensRadius * (1/fd - 1/z) = 0 (up to rounding).
        EXPECT_LT(maxErr, 1.0 / 16 + 1e-6) << engine;
    }
}

TEST(MotionBlur, SchemesConvergeToTheSameImage) {
    // A lit sphere moving diagonally with a lens: each scheme's error against a 1024-spp bbox reference
    // falls from 16 to 64 spp and is small at 64.
    const Scene s = movingSphereThroughLens(64, 48, {-0.4f, -0.1f, 4.f}, {0.4f, 0.1f, 4.f});
    Scene ref = s;
    setSpp(ref, 32, 32);
    const RenderResult reference = render(ref, settingsFor("reyes"));
    dumpIfAsked(reference.image, "sphere_reference");
    for (BlurSampling scheme : {BlurSampling::BoundingBox, BlurSampling::Interleaved, BlurSampling::Simple}) {
        Scene s16 = s, s64 = s;
        setSpp(s16, 4, 4);
        setSpp(s64, 8, 8);
        const double e16 = rmse(render(s16, settingsFor("reyes", scheme)).image, reference.image);
        const RenderResult r64 = render(s64, settingsFor("reyes", scheme));
        dumpIfAsked(r64.image, std::string("sphere_64_") + blurSamplingName(scheme));
        const double e64 = rmse(r64.image, reference.image);
        RecordProperty(std::string("rmse16_") + blurSamplingName(scheme), std::to_string(e16));
        RecordProperty(std::string("rmse64_") + blurSamplingName(scheme), std::to_string(e64));
        EXPECT_LT(e64, e16) << blurSamplingName(scheme);
        EXPECT_LT(e64, 0.02) << blurSamplingName(scheme);
    }
}

TEST(MotionBlur, ImagesAreTheSameForAnyThreadCount) {
    Scene s = movingSphereThroughLens(64, 48, {-0.4f, 0.f, 4.f}, {0.4f, 0.f, 4.f});
    setSpp(s, 4, 4);
    for (BlurSampling scheme : {BlurSampling::BoundingBox, BlurSampling::Interleaved, BlurSampling::Simple}) {
        RenderSettings one = settingsFor("reyes", scheme), two = one;
        one.threads = 1;
        two.threads = 2;
        two.bucketSize = 8;
        EXPECT_EQ(render(s, one).image.rgba, render(s, two).image.rgba) << blurSamplingName(scheme);
    }
}

TEST(MotionBlur, BlurredSphereHasNoPinholes) {
    // Crack-free dicing must stay crack-free at every time: pixels the moving sphere covers during the
    // whole shutter are fully covered by every sample (alpha exactly 1), for every scheme.
    Scene s = cameraSpaceScene(80, 60, 40.f);
    s.camera.shutterClose = 1.f;
    setSpp(s, 4, 4);
    const auto a = octantSphere(1.f, {-0.2f, 0.f, 4.f}), b = octantSphere(1.f, {0.2f, 0.f, 4.f});
    for (size_t i = 0; i < a.size(); ++i) addMovingPatch(s, a[i], b[i]);
    const Projector pr(s.camera);
    for (BlurSampling scheme : {BlurSampling::BoundingBox, BlurSampling::Interleaved, BlurSampling::Simple}) {
        const RenderResult r = render(s, settingsFor("reyes", scheme));
        int inside = 0, holes = 0;
        for (int y = 0; y < s.camera.height; ++y)
            for (int x = 0; x < s.camera.width; ++x) {
                // Covered at all times: the pixel's corners lie within 0.8 of both end centres (the
                // silhouette radius at depth 4 is just under 1; margin for the projection).
                bool always = true;
                for (double cx : {-0.2, 0.2})
                    for (int c = 0; c < 4; ++c) {
                        const Vec3 p = pr.fromRaster(float(x + (c & 1)), float(y + (c >> 1)));
                        const double X = p.x * 3.2, Y = p.y * 3.2;  // on the sphere's front at depth ~3.2
                        if ((X - cx) * (X - cx) + Y * Y > 0.6 * 0.6) always = false;
                    }
                if (!always) continue;
                ++inside;
                if (alphaAt(r.image, x, y) != 1.f) ++holes;
            }
        EXPECT_GT(inside, 100);
        EXPECT_EQ(holes, 0) << blurSamplingName(scheme);
    }
}

TEST(BlurPattern, InterleavedPermutationFollowsThePaperRule) {
    // perm = (tilenumber + tile_x + tile_y) mod P, tilenumber = tile_y * ceil(width / K) + tile_x
    // (Sattler and Steinberger, eqs. 2 and 3); each permutation is a bijection of the N = spp K^2 samples.
    const BlurPattern p = makeBlurPattern(BlurSampling::Interleaved, true, true, 4, 30, 3, 64, 7);
    EXPECT_EQ(p.tilesPerRow, 10);
    EXPECT_EQ(p.tileSamples(), 36);
    for (int ty = 0; ty < 20; ++ty)
        for (int tx = 0; tx < 10; ++tx) EXPECT_EQ(p.tilePermutation(tx, ty), (ty * 10 + tx + tx + ty) % 64);
    for (int k = 0; k < 64; ++k) {
        std::vector<int> seen(36, 0);
        for (int n = 0; n < 36; ++n) {
            const int q = p.perm[size_t(k) * 36 + n];
            ++seen[q];
            EXPECT_EQ(p.inverse[size_t(k) * 36 + q], n);
        }
        for (int q = 0; q < 36; ++q) EXPECT_EQ(seen[q], 1);
    }
    // Every tile holds each of its N (t, lens) samples exactly once.
    for (int ty = 0; ty < 3; ++ty)
        for (int tx = 0; tx < 3; ++tx) {
            std::vector<int> seen(36, 0);
            for (int py = ty * 3; py < ty * 3 + 3; ++py)
                for (int px = tx * 3; px < tx * 3 + 3; ++px)
                    for (int slot = 0; slot < 4; ++slot) ++seen[p.tileSampleOf(px, py, slot)];
            for (int n = 0; n < 36; ++n) EXPECT_EQ(seen[n], 1);
        }
}

TEST(MotionBlur, StrataBoundsChangeNoSampleOnlyTheTestCount) {
    // The bbox scheme's cut bounds are an exact optimisation: the same image as the paper's single
    // extended bound, with fewer sample tests.
    Scene s = movingSphereThroughLens(64, 48, {-0.4f, 0.f, 4.f}, {0.4f, 0.f, 4.f});
    setSpp(s, 4, 4);
    for (int lensOn = 0; lensOn < 2; ++lensOn) {
        Scene sc = s;
        if (!lensOn) sc.camera.fStop = INFINITY;
        RenderSettings cut = settingsFor("reyes"), whole = cut;
        whole.blur.strataBounds = false;
        const RenderResult rc = render(sc, cut), rw = render(sc, whole);
        EXPECT_EQ(rc.image.rgba, rw.image.rgba) << "lens " << lensOn;
        EXPECT_LT(rc.stats["sample_tests"].get<uint64_t>(), rw.stats["sample_tests"].get<uint64_t>() / 2);
    }
}

// The AVX2 paths of the bbox rasterizer (candidate filters eight at a time writing the passing entries out
// branch-free; exact tests of eight samples against a micropolygon in 32-bit relative coordinates) against
// the four-wide SSE2 filters and one-by-one tests: the same image, attribute planes and sample-test count
// for motion, a lens, both, the interleaved scheme through the strata, and micropolygons wide enough for
// the exact test's scalar lanes.
TEST(MotionBlur, Avx2FiltersEqualTheFourWideFilters) {
    struct Case {
        const char* scene;
        bool lens, motion;
        BlurSampling scheme;
        float shadingRate =
            1.f;  // 4000: micropolygons of about 60 x 60 pixels (the exact test's scalar lanes)
    };
    for (const Case& c : {Case{"motion_teapot", false, true, BlurSampling::BoundingBox},
                          Case{"dof_teapot", true, false, BlurSampling::BoundingBox},
                          Case{"motion_teapot", true, true, BlurSampling::BoundingBox},
                          Case{"dof_teapot", true, false, BlurSampling::Interleaved},
                          Case{"dof_teapot", true, false, BlurSampling::BoundingBox, 4000.f},
                          Case{"motion_teapot", true, true, BlurSampling::BoundingBox, 4000.f}}) {
        Scene s = loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/" + c.scene + ".rib",
                            [](const std::string&) {});
        s.camera.width = 200;
        s.camera.height = 150;
        if (c.lens && s.camera.lensRadius() == 0.f) {  // the teapot's lens of dof_teapot.rib
            s.camera.fStop = 0.8f, s.camera.focalLength = 1.f, s.camera.focalDistance = 11.f;
        }
        for (PatchAttributes& at : s.attributes) at.shadingRate = c.shadingRate;
        RenderSettings rs = settingsFor("reyes", c.scheme);
        rs.output.channels = kAllFilmChannels;
        const Avx2Renders r = renderWithAndWithoutReyesAvx2(s, rs);
        const RenderResult& a = r.with;
        const uint64_t tests = a.stats["sample_tests"].get<uint64_t>();
        std::printf("%s lens %d scheme %s rate %g: AVX2 path %s, %llu sample tests\n", c.scene, int(c.lens),
                    blurSamplingName(c.scheme), c.shadingRate, r.avx2 ? "on" : "off",
                    (unsigned long long)tests);
        expectSameRender(a, r.without, c.scene);
        EXPECT_GT(tests, c.shadingRate > 1.f ? 10000u : 100000u);
        EXPECT_EQ(a.stats["blur"]["lens"].get<bool>(), c.lens);
        EXPECT_EQ(a.stats["blur"]["motion"].get<bool>(), c.motion);
    }
}

TEST(MotionBlur, InterleavedSamplesThroughTheStrataGiveThePaperPerPassImage) {
    // The interleaved scheme is a choice of (t, lens) per sample; with strata bounds on, Reyes rasterizes
    // it as the bbox scheme does (each sample at its own time and lens point) instead of moving the grid
    // once per tile sample as the paper's GPU version does (strata bounds off): the same hits.
    Scene s = movingSphereThroughLens(64, 48, {-0.4f, 0.f, 4.f}, {0.4f, 0.f, 4.f});
    setSpp(s, 2, 2);
    for (int lensOn = 0; lensOn < 2; ++lensOn) {
        Scene sc = s;
        if (!lensOn) sc.camera.fStop = INFINITY;
        RenderSettings strata = settingsFor("reyes", BlurSampling::Interleaved), perPass = strata;
        strata.blur.tileSize = perPass.blur.tileSize = 3;
        perPass.blur.strataBounds = false;
        const RenderResult a = render(sc, strata), b = render(sc, perPass);
        EXPECT_TRUE(a.stats["blur"]["strata_bounds"].get<bool>());
        EXPECT_FALSE(b.stats["blur"]["strata_bounds"].get<bool>());
        EXPECT_EQ(a.image.rgba, b.image.rgba) << "lens " << lensOn;
        double covered = 0;
        for (size_t i = 3; i < a.image.rgba.size(); i += 4) covered += a.image.rgba[i];
        EXPECT_GT(covered, 100.0) << "lens " << lensOn;  // the sphere is in the frame
    }
}

namespace {
// A convex object under a distant light and an ambient one: the ray tracer's shadows darken nothing that
// the light reaches, so both engines should see the same image.
Scene crossEngineScene() {
    Scene s = cameraSpaceScene(96, 72, 40.f);
    s.camera.shutterClose = 1.f;
    s.lights = {{LightType::Ambient, {0.2f, 0.2f, 0.2f}, {}, {}},
                {LightType::Distant, {1, 1, 1}, {0, 0, 0}, {0.3f, -0.4f, 1.f}}};
    return s;
}
void expectEnginesAgree(const Scene& s, BlurSampling scheme, const char* what) {
    RenderSettings reyes = settingsFor("reyes", scheme), rt = settingsFor("rt", scheme);
    const RenderResult a = render(s, reyes), b = render(s, rt);
    dumpIfAsked(a.image, std::string("cross_reyes_") + what);
    dumpIfAsked(b.image, std::string("cross_rt_") + what);
    const ImageDiff d = compareImages(a.image, b.image, 0.1f);
    ::testing::Test::RecordProperty(std::string("psnr_") + what + "_" + blurSamplingName(scheme),
                                    std::to_string(d.psnrColor));
    ::testing::Test::RecordProperty(std::string("alpha_") + what + "_" + blurSamplingName(scheme),
                                    std::to_string(d.alphaMismatch));
    EXPECT_GE(d.psnrColor, 35.0) << what << " " << blurSamplingName(scheme);
    EXPECT_LT(d.alphaMismatch, 0.005) << what << " " << blurSamplingName(scheme);
    EXPECT_LT(d.meanAbsAlpha, 0.01) << what << " " << blurSamplingName(scheme);
}
}  // namespace

TEST(MotionBlurCrossEngine, MovingSphereWithLensAgrees) {
    // The same (x, y, t, lens) samples in both engines: Reyes moves micropolygons, the ray tracer traces from
    // the lens at the sample's time; at 256 spp the images agree.
    Scene s = crossEngineScene();
    s.camera.fStop = 2.f;
    s.camera.focalLength = 0.5f;
    s.camera.focalDistance = 3.f;
    const auto a = octantSphere(0.8f, {-0.5f, -0.2f, 4.f}), b = octantSphere(0.8f, {0.5f, 0.2f, 4.5f});
    for (size_t i = 0; i < a.size(); ++i) addMovingPatch(s, a[i], b[i]);
    setSpp(s, 16, 16);
    for (BlurSampling scheme : {BlurSampling::BoundingBox, BlurSampling::Simple, BlurSampling::Interleaved})
        expectEnginesAgree(s, scheme, "sphere");
}

namespace {
// A square turning 90 degrees in its plane about the view axis, with keys every 2 degrees as the RIB
// reader makes them (46 knot segments).
Scene turningSquareScene() {
    Scene s = crossEngineScene();
    s.materials[0] = defaultMaterial(MaterialType::Constant);
    const BezierPatch square = flatSquare(1.4f, 5.f, 0.2f, 0.1f);
    std::vector<TransformKey> keys{{0.0, Mat4()}, {1.0, Mat4::rotate(90, 0, 0, 1)}};
    keys = refineTransformKeys(keys, kMaxMotionSegmentRadians);
    addPatch(s, square);
    PatchAttributes& attr = s.attributes.back();
    attr.motion.first = 0;
    attr.motion.count = uint32_t(keys.size());
    for (const TransformKey& k : keys) {
        BezierPatch p;
        for (int c = 0; c < 16; ++c) {
            const Vec3 q = square.cp[c] - Vec3{0, 0, 5.f};
            p.cp[c] = k.matrix.point(q) + Vec3{0, 0, 5.f};
        }
        s.motionPatches.push_back(p);
        s.motionTimes.push_back(float(k.time));
    }
    return s;
}
}  // namespace

TEST(MotionBlurCrossEngine, RotatingSquareAgrees) {
    // The square's edges' endpoints change lexicographic order during the turn, which Reyes' later knots
    // must not mistake for a reversed edge. Constant white: the images are the time-averaged coverage.
    Scene s = turningSquareScene();
    setSpp(s, 16, 16);
    expectEnginesAgree(s, BlurSampling::BoundingBox, "rotating_square");
}

TEST(MotionBlur, StrataBoundsAreExactOverManyKnots) {
    // The sweep walks every knot segment of a turn (each sample in the one segment that owns its time), and
    // with a lens the grouped strata span several segments: neither may lose or add a hit.
    Scene s = turningSquareScene();
    setSpp(s, 4, 4);
    for (int lensOn = 0; lensOn < 2; ++lensOn) {
        Scene sc = s;
        if (lensOn) sc.camera.fStop = 2.f, sc.camera.focalLength = 0.5f, sc.camera.focalDistance = 3.f;
        RenderSettings cut = settingsFor("reyes"), whole = cut;
        whole.blur.strataBounds = false;
        const RenderResult rc = render(sc, cut), rw = render(sc, whole);
        EXPECT_EQ(rc.image.rgba, rw.image.rgba) << "lens " << lensOn;
        EXPECT_LT(rc.stats["sample_tests"].get<uint64_t>(), rw.stats["sample_tests"].get<uint64_t>() / 2);
        EXPECT_GT(rc.stats["blur"]["knots"].get<int>(), 40);
    }
}

TEST(MotionBlurCrossEngine, ShippedMotionScenesAgree) {
    // scenes/motion_teapot.rib and dof_teapot.rib at 160x120, 64 spp, lit from the eye (Reyes has no
    // shadows).
    for (const char* name : {"motion_teapot", "dof_teapot"}) {
        Scene s = loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/" + name + ".rib",
                            [](const std::string&) {});
        s.camera.width = 160;
        s.camera.height = 120;
        setSpp(s, 8, 8);
        lightFromEye(s);
        expectEnginesAgree(s, BlurSampling::BoundingBox, name);
    }
}

TEST(MotionBlur, LaterKnotsKeepTheEdgeLatticeOrder) {
    // A square turning about the view axis: its left edge's endpoints swap lexicographic order right after
    // shutter open. Every grid vertex at a later knot must be the knot's patch at the same lattice point, so
    // along each grid row and column the vertices keep their order (a mirrored edge lattice would reverse
    // a boundary row), and each knot's corner is the patch's corner at that knot.
    Scene s = cameraSpaceScene(96, 72, 40.f);
    const BezierPatch square = flatSquare(1.4f, 5.f, 0.2f, 0.1f);
    const BezierPatch turned = turnedAboutViewAxis(square, 20, 5.f);
    const Projector pr(s.camera);
    ReyesView view(s.camera);
    const BezierPatch* knots[2] = {&square, &turned};
    view.patches = &square;
    view.knotPatches = {knots[0], knots[1]};
    const std::vector<uint32_t> moving{0};
    view.moving = &moving;
    view.cullX0 = -100, view.cullY0 = -100, view.cullX1 = 200, view.cullY1 = 200;
    std::vector<Piece> pieces;
    SplitCounters counters;
    splitPatch(view, 0, 1.f, pieces, counters);
    ASSERT_FALSE(pieces.empty());
    const Material m = defaultMaterial(MaterialType::Constant);
    const ShadeInputs in{SurfaceKind::BicubicBezier, &m, true, false, {}, 0, false};
    for (const Piece& piece : pieces) {
        Grid g;
        diceAndShade(view, piece, in, g);
        ASSERT_EQ(g.knots, 2);
        const int n = g.vertexCount(), stride = g.nu + 1;
        // Along a row, consecutive vertices advance in the same direction at both knots (the turn is 20
        // degrees, so a step's direction turns by 20 degrees, never reverses).
        for (int j = 0; j <= g.nv; ++j)
            for (int i = 0; i < g.nu; ++i) {
                const int a = j * stride + i, b = a + 1;
                const float d0x = g.knotX[b] - g.knotX[a], d0y = g.knotY[b] - g.knotY[a];
                const float d1x = g.knotX[n + b] - g.knotX[n + a], d1y = g.knotY[n + b] - g.knotY[n + a];
                EXPECT_GT(d0x * d1x + d0y * d1y, 0.f) << "row " << j << " step " << i;
            }
        for (int i = 0; i <= g.nu; ++i)
            for (int j = 0; j < g.nv; ++j) {
                const int a = j * stride + i, b = a + stride;
                const float d0x = g.knotX[b] - g.knotX[a], d0y = g.knotY[b] - g.knotY[a];
                const float d1x = g.knotX[n + b] - g.knotX[n + a], d1y = g.knotY[n + b] - g.knotY[n + a];
                EXPECT_GT(d0x * d1x + d0y * d1y, 0.f) << "column " << i << " step " << j;
            }
    }
}

TEST(BlurPattern, PreparedTimeAndLensSeedsMatchTheSampler) {
    // SampleTile::setBlur's per-pixel fast path gives the same bits as sampleBits.
    for (uint32_t px = 0; px < 40; ++px) {
        const uint32_t ps = pixelSeed(int(px), int(px * 7 % 13), 3);
        const TimeLensSeeds seeds = timeLensSeeds(ps);
        for (uint32_t i = 0; i < 300; ++i) {
            EXPECT_EQ(timeBits(seeds, i), sampleBits(ps, i, kDimTime));
            uint32_t u, v;
            lensBits(seeds, i, u, v);
            EXPECT_EQ(u, sampleBits(ps, i, kDimLensU));
            EXPECT_EQ(v, sampleBits(ps, i, kDimLensV));
        }
    }
}

TEST(BlurPattern, PixelSamplesEightAtATimeEqualOneByOne) {
    // SampleTile::setBlur's batch (AVX2 where the CPU has it) against pixelSampleAt, bit for bit, for time
    // alone, lens alone and both, over counts that leave partial groups of eight and sample indices up to
    // 2^16 (the film's Sobol' indices need not be the slots).
    for (int kind = 0; kind < 3; ++kind) {
        const BlurPattern p =
            makeBlurPattern(BlurSampling::BoundingBox, kind != 1, kind != 0, 16, 64, 4, 64, 7);
        for (int px = 0; px < 30; ++px) {
            const TimeLensSeeds seeds = timeLensSeeds(pixelSeed(px, 3 * px % 17, p.seed));
            for (int n : {1, 7, 8, 13, 16, 64}) {
                std::vector<uint32_t> indices(static_cast<size_t>(n));
                for (int i = 0; i < n; ++i)
                    indices[size_t(i)] = px % 2 ? uint32_t(i) : hash32(uint32_t(i + px)) & 0xffffu;
                std::vector<float> t(size_t(n), -1.f);
                std::vector<Vec2> lens(size_t(n), Vec2{-2.f, -2.f});
                p.pixelSamplesAt(seeds, indices.data(), n, t.data(), lens.data());
                for (int i = 0; i < n; ++i) {
                    float t1;
                    Vec2 l1;
                    p.pixelSampleAt(seeds, indices[size_t(i)], t1, l1);
                    ASSERT_EQ(t[size_t(i)], t1) << kind << " " << px << " " << i;
                    ASSERT_EQ(lens[size_t(i)].x, l1.x) << kind << " " << px << " " << i;
                    ASSERT_EQ(lens[size_t(i)].y, l1.y) << kind << " " << px << " " << i;
                }
            }
        }
    }
}

TEST(MotionBlur, MotionFactorCoarsensOnlyBlurredGeometry) {
    // GeometricApproximation "motionfactor": the shading rate of a moving patch grows with its blur
    // (rate * max(1, factor * blur / 16)); a still patch, and every patch at factor 0, keeps its rate.
    Scene s = coverageScene(96, 64);
    addMovingPatch(s, flatSquare(1.f, 5.f, -0.6f, 0.f), flatSquare(1.f, 5.f, 0.6f, 0.f));
    addPatch(s, flatSquare(0.6f, 5.f, 0.f, 0.5f));
    setSpp(s, 4, 4);
    const RenderResult plain = render(s, settingsFor("reyes"));
    Scene coarse = s;
    for (PatchAttributes& a : coarse.attributes) a.motionFactor = 4.f;
    const RenderResult r = render(coarse, settingsFor("reyes"));
    EXPECT_LT(r.stats["micropolygons"].get<uint64_t>(), plain.stats["micropolygons"].get<uint64_t>() / 2);
    // In the same blurred frame a still patch is not coarsened: the factor on the still square alone changes
    // nothing.
    Scene stillFactor = s;
    stillFactor.attributes[1].motionFactor = 4.f;
    const RenderResult st = render(stillFactor, settingsFor("reyes"));
    EXPECT_EQ(st.stats["micropolygons"], plain.stats["micropolygons"]);
    EXPECT_EQ(st.image.rgba, plain.image.rgba);
    // Coarser shading of a flat constant square changes its coverage by little.
    const ImageDiff d = compareImages(plain.image, r.image, 0.1f);
    EXPECT_LT(d.meanAbsAlpha, 0.01);
}

}  // namespace tessera::test::motion_tests

namespace tessera::test::motion_tests {

// LazyPieces dices into recycled grids (Grid::clearKeepingStorage): a grid that held a blurred piece with
// normals, diced again for a still piece without them, equals a grid diced fresh: no knots, normals or
// blur flag left over from its previous piece.
TEST(MotionBlur, RecycledGridEqualsAFreshOne) {
    Scene s = cameraSpaceScene(96, 72, 40.f);
    const BezierPatch square = flatSquare(1.4f, 5.f, 0.2f, 0.1f);
    const BezierPatch turned = turnedAboutViewAxis(square, 20, 5.f);
    ReyesView moving(s.camera);
    const BezierPatch* knots[2] = {&square, &turned};
    moving.patches = &square;
    moving.knotPatches = {knots[0], knots[1]};
    const std::vector<uint32_t> movingIds{0};
    moving.moving = &movingIds;
    moving.cullX0 = -100, moving.cullY0 = -100, moving.cullX1 = 200, moving.cullY1 = 200;
    ReyesView still(s.camera);
    still.patches = &turned;
    still.cullX0 = -100, still.cullY0 = -100, still.cullX1 = 200, still.cullY1 = 200;
    std::vector<Piece> movingPieces, stillPieces;
    SplitCounters counters;
    splitPatch(moving, 0, 1.f, movingPieces, counters);
    splitPatch(still, 0, 1.f, stillPieces, counters);
    ASSERT_FALSE(movingPieces.empty());
    ASSERT_FALSE(stillPieces.empty());
    const Material m = defaultMaterial(MaterialType::Plastic);
    const Light light{LightType::Distant, {1, 1, 1}, {0, 0, 0}, {0.3f, -0.4f, 1.f}};
    const std::vector<ShadingLight> lights{prepareLight(light, Mat4{})};
    ShadeInputs withNormals{SurfaceKind::BicubicBezier, &m, false, false, lights, 3, true};
    ShadeInputs plain{SurfaceKind::BicubicBezier, &m, true, false, lights, 1, false};

    Grid recycled;
    diceAndShade(moving, movingPieces[0], withNormals, recycled);
    ASSERT_TRUE(recycled.blurred);
    ASSERT_EQ(recycled.knots, 2);
    ASSERT_FALSE(recycled.NX.empty());
    const size_t capacity = recycled.X.capacity();
    recycled.clearKeepingStorage();
    EXPECT_GE(recycled.X.capacity(), capacity);  // the storage stays
    diceAndShade(still, stillPieces[0], plain, recycled);
    Grid fresh;
    diceAndShade(still, stillPieces[0], plain, fresh);

    EXPECT_EQ(recycled.nu, fresh.nu);
    EXPECT_EQ(recycled.nv, fresh.nv);
    EXPECT_EQ(recycled.twoSided, fresh.twoSided);
    EXPECT_EQ(recycled.objectId, fresh.objectId);
    EXPECT_EQ(recycled.knots, fresh.knots);
    EXPECT_EQ(recycled.blurred, fresh.blurred);
    EXPECT_EQ(recycled.allKnotsValid, fresh.allKnotsValid);
    EXPECT_EQ(recycled.motionPixels, fresh.motionPixels);
    int arrays = 0;
    fresh.forEachArray([&](auto& freshArray, auto Grid::*member) {
        EXPECT_TRUE(freshArray == recycled.*member) << "array " << arrays;
        ++arrays;
    });
    EXPECT_EQ(arrays, 19);
    EXPECT_TRUE(recycled.NX.empty());
    EXPECT_TRUE(recycled.knotX.empty());
}

}  // namespace tessera::test::motion_tests
