// Reyes' micropolygon samplers (paper 000 sec. 3.2, issue 12): the nearest-neighbour sampler leaves holes
// that the bounding-box sampler does not, fewer at a smaller shading rate, and where it covers a sample it
// writes what the bounding-box sampler writes; the option and the RIB Hider parameter.
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "render/render.h"
#include "render/render_options.h"
#include "rib_test_util.h"

namespace tessera::test::micropolygon_sampling_tests {

namespace {

// A plastic square tilted in perspective, larger than the frame (every sample lies on it), lit by a point
// light so that colours vary over it; one centred sample per pixel and a 1-pixel box filter, so a pixel
// is its sample and its alpha says whether it was covered.
std::string tiltedQuad(double shadingRate) {
    return "Format 96 72 1\nPixelSamples 1 1\nPixelFilter \"box\" 1 1\nShadingRate " +
           std::to_string(shadingRate) +
           "\nProjection \"perspective\" \"fov\" 40\nWorldBegin\n"
           "LightSource \"pointlight\" 1 \"from\" [0.5 0.8 2] \"intensity\" 6\n"
           "Translate 0 0 4\nRotate 35 1 0.3 0\nRotate 17 0 0 1\nSurface \"plastic\"\n"
           "Patch \"bilinear\" \"P\" [-6 -6 0  6 -6 0  -6 6 0  6 6 0]\nWorldEnd\n";
}

struct Rendered {
    RenderResult r;
    uint64_t emptyPixels;
};

Rendered renderWith(const std::string& rib, const std::string& sampling) {
    Loaded l = load(rib);
    RenderOptions o;
    o.threads = 2;
    o.sampler = "centred";
    o.micropolygonSampling = sampling;
    RenderSettings rs;
    applyRenderOptions(l.scene, o, rs);
    Rendered out{render(l.scene, rs), 0};
    out.emptyPixels = out.r.stats.at("empty_pixels").get<uint64_t>();
    EXPECT_EQ(out.r.stats.at("micropolygon_sampling").get<std::string>(), sampling);
    return out;
}

// Pixels with alpha 0 (one sample per pixel: not covered), counted from the image.
uint64_t uncovered(const Image& img) {
    uint64_t n = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) n += img.pixel(x, y)[3] == 0.f;
    return n;
}

}  // namespace

TEST(ReyesNearestSampler, LeavesHolesTheBoundingBoxSamplerCoversFewerAtASmallerRate) {
    const Rendered box1 = renderWith(tiltedQuad(1), "bbox");
    const Rendered nn1 = renderWith(tiltedQuad(1), "nearest");
    const Rendered box4 = renderWith(tiltedQuad(0.25), "bbox");
    const Rendered nn4 = renderWith(tiltedQuad(0.25), "nearest");
    // The counter is the image's own count of uncovered pixels.
    for (const Rendered* r : {&box1, &nn1, &box4, &nn4}) EXPECT_EQ(r->emptyPixels, uncovered(r->r.image));
    // The square fills the frame: the bounding-box sampler covers every sample.
    EXPECT_EQ(box1.emptyPixels, 0u);
    EXPECT_EQ(box4.emptyPixels, 0u);
    // One sample per micropolygon of about a pixel leaves holes; a quarter of the area leaves far fewer.
    EXPECT_GT(nn1.emptyPixels, 0u);
    EXPECT_LT(nn4.emptyPixels * 4, nn1.emptyPixels) << nn4.emptyPixels << " vs " << nn1.emptyPixels;
    // Nearest tests one sample per micropolygon, the bounding box several.
    EXPECT_LT(nn1.r.stats.at("sample_tests").get<uint64_t>(),
              box1.r.stats.at("sample_tests").get<uint64_t>());
    // Where both cover a sample they wrote the same micropolygon's colour and depth.
    for (const auto& [box, nn] : {std::pair{&box1, &nn1}, std::pair{&box4, &nn4}}) {
        int compared = 0;
        for (int y = 0; y < nn->r.image.height; ++y)
            for (int x = 0; x < nn->r.image.width; ++x) {
                const float* p = nn->r.image.pixel(x, y);
                const float* q = box->r.image.pixel(x, y);
                if (p[3] != 1.f) continue;
                ++compared;
                for (int c = 0; c < 4; ++c)
                    ASSERT_NEAR(p[c], q[c], 1e-5f) << x << "," << y << " channel " << c;
            }
        EXPECT_GT(compared, nn->r.image.width * nn->r.image.height / 2);
    }
}

TEST(ReyesNearestSampler, HiderParameterAndOptionChooseIt) {
    const std::string hider = "Hider \"hidden\" \"string micropolygonsampling\" \"nearest\"\n";
    Loaded l = load(hider + tiltedQuad(1));
    EXPECT_EQ(l.scene.image.micropolygonSampling, "nearest");
    RenderSettings rs;
    RenderOptions o;
    applyRenderOptions(l.scene, o, rs);
    EXPECT_EQ(rs.micropolygonSampling, MicropolygonSampling::Nearest);
    o.micropolygonSampling = "bbox";  // the option overrides the scene
    applyRenderOptions(l.scene, o, rs);
    EXPECT_EQ(rs.micropolygonSampling, MicropolygonSampling::BoundingBox);
    o.micropolygonSampling = "nearestneighbour";
    EXPECT_THROW(applyRenderOptions(l.scene, o, rs), std::invalid_argument);
    const std::string msg = expectError("Hider \"hidden\" \"string micropolygonsampling\" \"nn\"\n", 1);
    EXPECT_TRUE(contains(msg, "\"micropolygonsampling\" must be \"bbox\" or \"nearest\"")) << msg;
}

// The CLI: a bad value is a usage error (exit 2); the stats say which sampler ran.
TEST(ReyesNearestSampler, CliOptionIsCheckedAndReported) {
    const std::string rib = writeRib(tiltedQuad(1), "nn_cli.rib");
    const std::string out = (testScratchDir() / "nn_cli.png").string();
    const std::string stats = (testScratchDir() / "nn_cli.json").string();
    std::string said;
    EXPECT_EQ(runTesseraIn({}, "render " + rib + " -o " + out + " --micropolygon-sampling nn", &said), 2);
    EXPECT_TRUE(contains(said, "--micropolygon-sampling")) << said;
    ASSERT_EQ(runTesseraIn(
                  {}, "render " + rib + " -o " + out + " --micropolygon-sampling nearest --stats " + stats),
              0);
    std::ifstream f(stats);
    const nlohmann::json j = nlohmann::json::parse(f);
    EXPECT_EQ(j.at("micropolygon_sampling").get<std::string>(), "nearest");
    EXPECT_GT(j.at("empty_pixels").get<uint64_t>(), 0u);
}

}  // namespace tessera::test::micropolygon_sampling_tests
