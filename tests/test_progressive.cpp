// Progressive rendering (issue 14): --passes N renders the samples per pixel in N independent passes and
// averages them; --write-partial writes the average after every pass and keeps it on Ctrl-C.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "io/image_io.h"
#include "test_support.h"

namespace tessera::test::progressive_tests {

namespace fs = std::filesystem;

namespace {

// An area light above a matte floor with a sphere between them: soft shadows, one light sample per camera
// sample (the direct integrator's noise is the light's).
const char* kScene =
    "Format 40 40 1\nPixelSamples 1 1\nProjection \"perspective\" \"fov\" [50]\nTranslate 0 0 8\n"
    "Rotate -120 1 0 0\nWorldBegin\n"
    "AttributeBegin AreaLightSource \"arealight\" 1 \"intensity\" [6] \"samples\" [1]\n"
    "Patch \"bilinear\" \"P\" [-1 -1 4  -1 1 4  1 -1 4  1 1 4] AttributeEnd\n"
    "Surface \"matte\" AttributeBegin Translate 0 0 1.2 Sphere 1 -1 1 360 AttributeEnd\n"
    "Patch \"bilinear\" \"P\" [-6 -6 0 6 -6 0 -6 6 0 6 6 0]\nWorldEnd\n";

double rmse(const Image& a, const Image& b) {
    double ss = 0;
    for (size_t i = 0; i < a.rgba.size(); ++i) ss += double(a.rgba[i] - b.rgba[i]) * (a.rgba[i] - b.rgba[i]);
    return std::sqrt(ss / double(a.rgba.size()));
}

}  // namespace

// Four passes of 16 spp against one render of 64: both are 64-spp estimates, so their errors against a
// 1024-spp reference are alike (the passes' own scrambles lose a little stratification), and half the
// error of one 16-spp pass.
TEST(Progressive, PassesAverageToAnEstimateAsGoodAsOneRenderOfAllTheirSamples) {
    const fs::path dir = tessera::test::testScratchDir();
    std::ofstream(dir / "s.rib") << kScene;
    std::string out;
    const std::string common = "render s.rib --engine rt -q --light-samples 1 ";
    ASSERT_EQ(runTesseraIn(dir, common + "--spp 1024 -o ref.exr", &out), 0) << out;
    ASSERT_EQ(runTesseraIn(dir, common + "--spp 64 -o one.exr", &out), 0) << out;
    ASSERT_EQ(runTesseraIn(dir, common + "--spp 64 --passes 4 -o four.exr --stats four.json", &out), 0)
        << out;
    ASSERT_EQ(runTesseraIn(dir, common + "--spp 16 -o quarter.exr", &out), 0) << out;
    const Image ref = readExr((dir / "ref.exr").string());
    const double one = rmse(readExr((dir / "one.exr").string()), ref);
    const double four = rmse(readExr((dir / "four.exr").string()), ref);
    const double quarter = rmse(readExr((dir / "quarter.exr").string()), ref);
    std::cout << "RMSE against 1024 spp: 64 spp in one pass " << one << ", in 4 passes " << four
              << ", 16 spp " << quarter << "\n";
    EXPECT_LT(four, 1.3 * one);
    EXPECT_GT(four, 0.7 * one);
    EXPECT_LT(four, 0.7 * quarter);  // the passes do add up
    std::ifstream stats(dir / "four.json");
    const std::string text((std::istreambuf_iterator<char>(stats)), {});
    EXPECT_NE(text.find("\"passes\": 4"), std::string::npos) << text;
    EXPECT_NE(text.find("\"spp\": 64"), std::string::npos) << text;
}

TEST(Progressive, BadPassCountsAreRefused) {
    const fs::path dir = tessera::test::testScratchDir();
    std::ofstream(dir / "s.rib") << kScene;
    std::string out;
    EXPECT_EQ(runTesseraIn(dir, "render s.rib --engine rt -q --spp 16 --passes 3 -o x.exr", &out), 2);
    EXPECT_NE(out.find("--passes 3 does not divide the 16 samples per pixel"), std::string::npos) << out;
    EXPECT_EQ(runTesseraIn(dir, "render s.rib --engine rt -q --spp 16 --write-partial -o x.exr", &out), 2);
    EXPECT_NE(out.find("--write-partial"), std::string::npos) << out;
    EXPECT_FALSE(fs::exists(dir / "x.exr"));
}

// Ctrl-C after the first pass was written: exit 130, the image holds the finished passes and says so.
TEST(Progressive, WritePartialKeepsTheFinishedPassesWhenInterrupted) {
    const fs::path dir = tessera::test::testScratchDir();
    std::ofstream(dir / "s.rib") << kScene;
    // 256 passes of 4 spp (each pass rebuilds the frame: far longer than the wait for the first file).
    const std::string script =
        "cd '" + dir.string() + "' && (" + std::string(TESSERA_BINARY) +
        " render s.rib --engine rt --spp 1024 --passes 256 --write-partial -o part.exr > log.txt 2>&1 & "
        "P=$!; i=0; while [ ! -f part.exr ] && kill -0 $P 2>/dev/null && [ $i -lt 12000 ]; do sleep 0.01; "
        "i=$((i+1)); done; "
        "kill -INT $P; wait $P; echo $? > rc.txt)";
    ASSERT_EQ(std::system(script.c_str()), 0);
    std::ifstream rcFile(dir / "rc.txt"), logFile(dir / "log.txt");
    int rc = -1;
    rcFile >> rc;
    const std::string log((std::istreambuf_iterator<char>(logFile)), {});
    EXPECT_EQ(rc, 130) << log;
    EXPECT_NE(log.find("part.exr kept"), std::string::npos) << log;
    EXPECT_NE(log.find("of 256 passes"), std::string::npos) << log;
    const Image img = readExr((dir / "part.exr").string());
    EXPECT_EQ(img.width, 40);
    double lit = 0;
    for (size_t i = 0; i < img.rgba.size(); i += 4) lit += img.rgba[i];
    EXPECT_GT(lit, 0.0);  // a real image of the finished passes
    EXPECT_FALSE(fs::exists(dir / "part.exr.tmp"));
}

}  // namespace tessera::test::progressive_tests
