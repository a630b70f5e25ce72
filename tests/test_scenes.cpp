// Every shipped scene renders with both engines: finite pixels, a sensible amount of coverage, and no
// pinholes (a see-through pixel whose eight neighbours are all covered) inside the silhouettes.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "io/scene_loader.h"
#include "render/render.h"
#include "test_util.h"

using namespace tessera;
using tessera::test::countPinholes;

namespace {

struct SceneCase {
    const char* name;
    const char* engine;
    double minCoverage;  // fraction of the frame the model covers at least
};

class ShippedScenes : public ::testing::TestWithParam<SceneCase> {};

}  // namespace

TEST_P(ShippedScenes, RendersWithoutPinholes) {
    const SceneCase c = GetParam();
    Scene s = loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/" + c.name + ".rib", [](const std::string&) {});
    // Small frames keep the suite fast; keep the scene's aspect ratio.
    const double aspect = double(s.camera.width) / s.camera.height;
    s.camera.height = 180;
    s.camera.width = int(std::lround(180 * aspect));
    s.image.pixelSamplesX = s.image.pixelSamplesY = 2;
    RenderSettings rs;
    rs.engine = c.engine;
    rs.threads = 2;
    RenderResult r = render(s, rs);
    double coverage = 0;
    for (int y = 0; y < r.image.height; ++y)
        for (int x = 0; x < r.image.width; ++x) {
            const float* p = r.image.pixel(x, y);
            for (int k = 0; k < 4; ++k) ASSERT_TRUE(std::isfinite(p[k])) << x << "," << y;
            coverage += p[3];
        }
    coverage /= double(r.image.width) * r.image.height;
    EXPECT_GT(coverage, c.minCoverage) << c.name << " with " << c.engine;
    EXPECT_EQ(countPinholes(r.image), 0) << c.name << " with " << c.engine << ", coverage " << coverage;
}

INSTANTIATE_TEST_SUITE_P(
    BothEngines, ShippedScenes,
    ::testing::Values(SceneCase{"teapot", "reyes", 0.2}, SceneCase{"teapot", "rt", 0.2},
                      SceneCase{"killeroo", "reyes", 0.15}, SceneCase{"killeroo", "rt", 0.15},
                      SceneCase{"bigguy", "reyes", 0.25}, SceneCase{"bigguy", "rt", 0.25},
                      SceneCase{"killeroo2", "reyes", 0.1}, SceneCase{"killeroo2", "rt", 0.1},
                      SceneCase{"bigguy9", "reyes", 0.2}, SceneCase{"bigguy9", "rt", 0.2},
                      SceneCase{"bigguy24", "reyes", 0.1}, SceneCase{"bigguy24", "rt", 0.1},
                      SceneCase{"bigguy_box", "reyes", 0.6}, SceneCase{"bigguy_box", "rt", 0.6}),
    [](const ::testing::TestParamInfo<SceneCase>& info) {
        return std::string(info.param.name) + "_" + info.param.engine;
    });
