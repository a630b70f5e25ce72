// The multi-channel film: object ids and depth come from the sample nearest each pixel centre, exactly;
// normals and shadow counts are filtered over covered samples.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

#include "film/film.h"
#include "io/scene_loader.h"
#include "render/render.h"
#include "test_util.h"

namespace tessera::test::film_tests {

namespace {

constexpr float kDepth[2] = {5.f, 4.f}, kCx[2] = {-0.5f, 0.3f}, kCy[2] = {0.f, 0.1f}, kHalf[2] = {0.8f, 0.6f};

// Two overlapping squares: object 0 at depth 5 on the left, object 1 at depth 4 on the right, nearer.
Scene twoSquares() {
    Scene s = cameraSpaceScene(48, 32, 40.f);
    s.image.pixelSamplesX = s.image.pixelSamplesY = 2;
    addPatch(s, flatSquare(2 * kHalf[0], kDepth[0], kCx[0], kCy[0]), 0);
    addPatch(s, flatSquare(2 * kHalf[1], kDepth[1], kCx[1], kCy[1]), 1);
    return s;
}

// The object and depth seen by the camera ray through raster position (x, y), analytically.
void seenAt(const Projector& proj, float x, float y, uint32_t& id, float& depth) {
    const Vec3 d = proj.fromRaster(x, y);
    auto inside = [&](int k) {
        return std::abs(d.x * kDepth[k] - kCx[k]) <= kHalf[k] &&
               std::abs(d.y * kDepth[k] - kCy[k]) <= kHalf[k];
    };
    if (inside(1)) {
        id = 1, depth = kDepth[1];
    } else if (inside(0)) {
        id = 0, depth = kDepth[0];
    } else {
        id = kNoObject, depth = std::numeric_limits<float>::infinity();
    }
}

// Distance in pixels from a raster position to the nearest square edge (to skip samples whose analytic
// answer is within rounding of an edge).
float edgeDistance(const Projector& proj, float x, float y) {
    float best = 1e9f;
    for (int k = 0; k < 2; ++k) {
        for (float ex : {kCx[k] - kHalf[k], kCx[k] + kHalf[k]})
            best = std::min(best, std::abs(x - proj.toRaster({ex, 0, kDepth[k]}).x));
        for (float ey : {kCy[k] - kHalf[k], kCy[k] + kHalf[k]})
            best = std::min(best, std::abs(y - proj.toRaster({0, ey, kDepth[k]}).y));
    }
    return best;
}

}  // namespace

TEST(Film, IdAndDepthAreExactAtTheSampleNearestThePixelCentre) {
    const Scene scene = twoSquares();
    const Projector proj(scene.camera);
    for (const char* engine : {"reyes", "rt"}) {
        RenderSettings rs;
        rs.engine = engine;
        rs.threads = 2;
        rs.output.channels = kAllFilmChannels;
        const RenderResult r = render(scene, rs);
        const ImagePlane* id = r.image.plane("id");
        const ImagePlane* z = r.image.plane("z");
        const ImagePlane* N = r.image.plane("N");
        ASSERT_TRUE(id && z && N) << engine;
        // The film's own sample positions (the same for both engines and every tile).
        SampleTile tile;
        tile.reset(Rect{0, 0, scene.camera.width, scene.camera.height}, 2, 2, rs.seed,
                   std::numeric_limits<float>::infinity(), rs.sampler);
        int checked = 0, ones = 0, zeros = 0, background = 0;
        for (int py = 0; py < scene.camera.height; ++py)
            for (int px = 0; px < scene.camera.width; ++px) {
                const size_t near = nearestSampleToCentre(tile, px, py);
                const float sx = tile.sx[near] / kSubpixelScale, sy = tile.sy[near] / kSubpixelScale;
                if (edgeDistance(proj, sx, sy) < 0.02f) continue;  // on an edge: either answer is right
                uint32_t wantId;
                float wantZ;
                seenAt(proj, sx, sy, wantId, wantZ);
                const size_t pix = size_t(py) * scene.camera.width + px;
                ASSERT_EQ(id->ids[pix], wantId) << engine << " pixel " << px << "," << py;
                if (wantId == kNoObject) {
                    EXPECT_TRUE(std::isinf(z->values[pix]));
                    ++background;
                } else {
                    EXPECT_NEAR(z->values[pix], wantZ, 1e-3f) << engine << " pixel " << px << "," << py;
                    // Flat squares facing the eye: the filtered normal is exactly -z.
                    EXPECT_NEAR(N->values[pix * 3 + 2], -1.f, 1e-5f);
                    (wantId ? ones : zeros)++;
                }
                ++checked;
            }
        EXPECT_GT(ones, 100) << engine;
        EXPECT_GT(zeros, 100) << engine;
        EXPECT_GT(background, 100) << engine;
        EXPECT_GT(checked, 48 * 32 * 9 / 10) << engine;
    }
}

TEST(Film, ReconstructionFiltersShadowCountsAndTakesIdsFromTheNearestSample) {
    // A hand-filled 3x3 tile, 4 samples per pixel, box filter of one pixel: the centre pixel sees only
    // its own samples.
    SampleTile tile;
    tile.reset(Rect{0, 0, 3, 3}, 2, 2, 7, std::numeric_limits<float>::infinity(), SamplerKind::Sobol,
               kAllFilmChannels);
    for (size_t i = 0; i < tile.sampleCount(); ++i) {
        tile.a[i] = 1.f;
        tile.z[i] = 2.f + float(i);
        tile.pixelHit[i / 4] = 1;
        tile.setAttributes(i, uint32_t(100 + i), Vec3{0, 0, -1}, int(i % 4), (i % 2) != 0);
    }
    ImageOptions o;
    o.filter = FilterType::Box;
    o.filterWidthX = o.filterWidthY = 1.f;
    const PixelFilter filter = makeFilter(o);
    Image img(3, 3);
    img.addPlanes(kAllFilmChannels);
    reconstruct(tile, filter, Rect{0, 0, 3, 3}, img);
    const size_t near = nearestSampleToCentre(tile, 1, 1);
    ASSERT_GE(near, 16u);
    ASSERT_LT(near, 20u);
    EXPECT_EQ(img.plane("id")->ids[4], 100 + near);
    EXPECT_FLOAT_EQ(img.plane("z")->values[4], 2.f + float(near));
    EXPECT_FLOAT_EQ(img.plane("textured")->values[4], float(near % 2));
    // The box filter of width 1 weighs the pixel's own four samples equally: mean of 0,1,2,3.
    EXPECT_NEAR(img.plane("shadows")->values[4], 1.5f, 1e-6f);
    // No channels asked: no planes, no per-sample attribute storage.
    SampleTile plain;
    plain.reset(Rect{0, 0, 3, 3}, 2, 2, 7, 1.f, SamplerKind::Sobol);
    EXPECT_TRUE(plain.objectId.empty());
    EXPECT_TRUE(plain.normalX.empty());
}

TEST(Film, Avx2TilePositionsEqualThePerPixelLoop) {
    // Lattices of 1, 2 and 4 strata a pixel take the AVX2 path (8 samples at a time); its positions and
    // sample indices must be filmSamplesFixed's, pixel by pixel, including rows whose last pixels do not
    // fill a group of 8 samples and pixel coordinates past 16 bits (the seed keeps their low 16 bits).
    const std::pair<int, int> lattices[] = {{1, 1}, {2, 1}, {1, 2}, {2, 2}, {4, 1}, {1, 4}};
    const Rect regions[] = {{0, 0, 37, 5}, {1021, 3, 1030, 9}, {65530, 65533, 65541, 65537}};
    size_t compared = 0;
    for (const auto& [nx, ny] : lattices)
        for (const Rect& region : regions)
            for (uint32_t seed : {0u, 7u, 12345u}) {
                SampleTile tile;
                const bool avx2 = filmUseAvx2(true);
                tile.reset(region, nx, ny, seed, 1.f, SamplerKind::Sobol);
                const FilmPattern pattern = filmPattern(nx, ny, seed);
                const size_t spp = size_t(nx * ny);
                std::vector<int32_t> x(spp), y(spp);
                std::vector<uint32_t> index(spp);
                size_t i = 0;
                for (int py = region.y0; py < region.y1; ++py)
                    for (int px = region.x0; px < region.x1; ++px, i += spp) {
                        filmSamplesFixed(pattern, px, py, x.data(), y.data(), index.data());
                        for (size_t s = 0; s < spp; ++s) {
                            ASSERT_EQ(tile.sx[i + s], x[s]) << nx << "x" << ny << " pixel " << px << "," << py
                                                            << " slot " << s << " (AVX2 " << avx2 << ")";
                            ASSERT_EQ(tile.sy[i + s], y[s])
                                << nx << "x" << ny << " pixel " << px << "," << py;
                            ASSERT_EQ(tile.sampleIndex[i + s], index[s]) << nx << "x" << ny;
                            ++compared;
                        }
                    }
            }
    EXPECT_GT(compared, 10000u);
}

TEST(Film, DeferredFillReachesEitherOrderAndIsNeverReconstructedUnfilled) {
    // A Reyes tile (deferPixelFill) is reset without filling its depth and colour; whichever order is
    // asked for first gets reset's fill, also over a previous tile's values, as an undeferred tile has it.
    const Rect region{3, 5, 9, 10};
    const float farZ = 1e30f;
    SampleTile filled;
    filled.reset(region, 4, 4, 11, farZ, SamplerKind::Sobol);
    auto dirty = [](SampleTile& t) {
        for (std::vector<float>* v : {&t.z, &t.r, &t.g, &t.b, &t.a}) std::fill(v->begin(), v->end(), 7.f);
        t.enterStrataOrder();
        for (std::vector<float>* v : {&t.strataZ, &t.strataR, &t.strataG, &t.strataB, &t.strataA})
            std::fill(v->begin(), v->end(), 7.f);
        t.leaveStrataOrder();
    };
    auto expectFill = [&](const SampleTile& t, const char* what) {
        EXPECT_FALSE(t.pixelFillPending) << what;
        EXPECT_TRUE(t.z == filled.z) << what;
        for (const std::vector<float>* v : {&t.r, &t.g, &t.b, &t.a}) EXPECT_TRUE(*v == filled.r) << what;
        EXPECT_TRUE(t.sx == filled.sx && t.sy == filled.sy) << what;
    };
    ASSERT_EQ(filled.z.front(), farZ);
    ASSERT_EQ(filled.r.back(), 0.f);

    SampleTile pixelFirst;
    pixelFirst.deferPixelFill = true;
    pixelFirst.reset(region, 4, 4, 11, farZ, SamplerKind::Sobol);
    dirty(pixelFirst);
    pixelFirst.reset(region, 4, 4, 11, farZ, SamplerKind::Sobol);
    EXPECT_TRUE(pixelFirst.pixelFillPending);
    pixelFirst.leaveStrataOrder();
    expectFill(pixelFirst, "pixel order first");

    SampleTile strataFirst;
    strataFirst.deferPixelFill = true;
    strataFirst.reset(region, 4, 4, 11, farZ, SamplerKind::Sobol);
    dirty(strataFirst);
    strataFirst.reset(region, 4, 4, 11, farZ, SamplerKind::Sobol);
    strataFirst.enterStrataOrder();
    const size_t n = strataFirst.sampleCount();
    for (size_t i = 0; i < n; ++i) {
        ASSERT_EQ(strataFirst.strataZ[i], farZ) << i;
        ASSERT_EQ(strataFirst.strataA[i], 0.f) << i;
        ASSERT_EQ(strataFirst.strataCovered[i], 0) << i;
    }
    strataFirst.leaveStrataOrder();
    expectFill(strataFirst, "stratum order first");
    for (uint8_t hit : strataFirst.pixelHit) EXPECT_EQ(hit, 0);

    SampleTile pending;
    pending.deferPixelFill = true;
    pending.reset(region, 4, 4, 11, farZ, SamplerKind::Sobol);
    Image img(region);
    EXPECT_THROW(reconstruct(pending, makeFilter(ImageOptions{}), region, img), std::logic_error);
}

TEST(Film, ARegionRendersTheSamePixelsAsTheWholeImage) {
    // A crop window or farm tile goes through the same render path: its pixels equal the whole render's,
    // bit for bit, in both engines (same samples, same filter margins), and its planes too.
    Scene scene = twoSquares();
    scene.image.filter = FilterType::Gaussian;
    scene.image.filterWidthX = scene.image.filterWidthY = 2.f;
    for (const char* engine : {"reyes", "rt"}) {
        RenderSettings rs;
        rs.engine = engine;
        rs.threads = 2;
        rs.output.channels = kChannelObjectId | kChannelDepth;
        const RenderResult whole = render(scene, rs);
        rs.view.region = Rect{13, 7, 45, 29};
        const RenderResult part = render(scene, rs);
        ASSERT_EQ(part.image.width, 32);
        ASSERT_EQ(part.image.height, 22);
        EXPECT_EQ(part.image.x0, 13);
        int differing = 0;
        for (int y = 7; y < 29; ++y)
            for (int x = 13; x < 45; ++x) {
                for (int c = 0; c < 4; ++c)
                    differing += part.image.pixel(x, y)[c] != whole.image.pixel(x, y)[c];
                differing += part.image.plane("id")->ids[part.image.index(x, y)] !=
                             whole.image.plane("id")->ids[whole.image.index(x, y)];
            }
        EXPECT_EQ(differing, 0) << engine;
        // And it does less work: fewer buckets (Reyes) or camera rays (the ray tracer's tile is bigger than
        // this image).
        const char* work = std::string(engine) == "rt" ? "rays_total" : "buckets";
        EXPECT_LT(part.stats[work].get<double>(), whole.stats[work].get<double>()) << engine;
    }
}

// The image buffer's allocator (core/buffer_allocator.h): large buffers come 2 MB-aligned for huge pages,
// small ones from operator new; both behave as ordinary vectors (zeroed, copied, grown across the
// threshold, compared).
// The film's AVX2 paths (reconstruction summing eight samples at a time; a blurred pixel's times and lens
// points eight at a time) against the scalar ones: the same image, bit for bit, for sample counts whose rows
// are whole groups of eight (16 spp), leave a partial group (9 spp) or hold fewer than eight (2 spp), with
// and without a lens, and with a wide filter (width 4: five pixels of samples per row).
TEST(Film, Avx2ReconstructionAndBlurSamplesEqualTheScalarPaths) {
    Scene base =
        loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/dof_teapot.rib", [](const std::string&) {});
    base.camera.width = 160;
    base.camera.height = 120;
    for (int spp : {4, 3, 1})
        for (bool lens : {false, true})
            // Radii 1 and 2, and unequal ones (the AVX2 path tabulates the X and Y factors apart).
            for (auto [widthX, widthY] : {std::pair{2.f, 2.f}, {4.f, 4.f}, {4.f, 2.f}}) {
                Scene s = base;
                s.image.pixelSamplesX = s.image.pixelSamplesY = spp;
                s.image.filterWidthX = widthX;
                s.image.filterWidthY = widthY;
                if (!lens) s.camera.fStop = INFINITY;
                RenderSettings rs;
                rs.engine = "reyes";
                rs.threads = 2;
                const bool avx2 = filmUseAvx2(true);
                const RenderResult a = render(s, rs);
                filmUseAvx2(false);
                const RenderResult b = render(s, rs);
                filmUseAvx2(true);
                EXPECT_TRUE(a.image.rgba == b.image.rgba)
                    << "spp " << spp * spp << " lens " << lens << " width " << widthX << " x " << widthY
                    << " (AVX2 " << avx2 << ")";
                double covered = 0;
                for (size_t i = 3; i < a.image.rgba.size(); i += 4) covered += a.image.rgba[i];
                EXPECT_GT(covered, 1000.0);
            }
}

TEST(BufferAllocator, LargeAndSmallBuffersBehaveAsVectors) {
    const size_t big = size_t(1024) * 1024 * 4;  // a 1024 x 1024 RGBA float image: 16 MB
    Image image(Rect{0, 0, 1024, 1024});
    ASSERT_EQ(image.rgba.size(), big);
    EXPECT_EQ(reinterpret_cast<uintptr_t>(image.rgba.data()) % kHugePageBytes, 0u);
    size_t nonzero = 0;
    for (float v : image.rgba) nonzero += v != 0.f;
    EXPECT_EQ(nonzero, 0u);
    image.rgba[big - 1] = 3.f, image.rgba[7] = 2.f;
    const Image copy = image;
    EXPECT_TRUE(copy.rgba == image.rgba);
    EXPECT_EQ(copy.rgba[big - 1], 3.f);

    std::vector<float, BufferAllocator<float>> grown(16, 1.f);  // small: operator new
    for (size_t i = 0; grown.size() * sizeof(float) < 2 * kHugeBufferBytes; ++i) grown.push_back(float(i));
    EXPECT_EQ(grown[15], 1.f);
    EXPECT_EQ(grown[16], 0.f);
    EXPECT_EQ(grown.back(), float(grown.size() - 17));
    grown.resize(8);  // shrinking keeps the buffer; freeing it takes the large path's free
    grown.shrink_to_fit();
    EXPECT_EQ(grown.size(), 8u);
    EXPECT_EQ(grown[7], 1.f);
}

}  // namespace tessera::test::film_tests
