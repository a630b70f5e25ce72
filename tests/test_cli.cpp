// End to end through the command-line tool: images, statistics, info and error handling.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "io/image_io.h"

namespace fs = std::filesystem;
using namespace tessera;

namespace {

struct CommandResult {
    int exitCode;
    std::string output;  // stdout + stderr
};

CommandResult run(const std::string& args, const std::string& cwd = "") {
    fs::path log = fs::temp_directory_path() / ("tessera_cli_" + std::to_string(getpid()) + ".log");
    std::string cmd = (cwd.empty() ? "" : "cd '" + cwd + "' && ") + std::string(TESSERA_BINARY) + " " + args +
                      " > '" + log.string() + "' 2>&1";
    int status = std::system(cmd.c_str());
    std::ifstream f(log);
    std::stringstream ss;
    ss << f.rdbuf();
    fs::remove(log);
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, ss.str()};
}

fs::path tempDir() {
    fs::path d = fs::temp_directory_path() / ("tessera_cli_" + std::to_string(getpid()));
    fs::create_directories(d);
    return d;
}

const std::string kTeapot = std::string(TESSERA_SOURCE_DIR) + "/scenes/teapot.rib";

}  // namespace

TEST(Cli, RendersTeapotToPngAndExr) {
    fs::path dir = tempDir();
    std::string png = (dir / "teapot.png").string(), exr = (dir / "teapot.exr").string();
    std::string stats = (dir / "stats.json").string();
    CommandResult r = run("render " + kTeapot + " -o " + png + " --res 200x150 --stats " + stats + " --quiet");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_EQ(r.output.find('\r'), std::string::npos) << "no progress bar when stderr is not a terminal";
    r = run("render " + kTeapot + " -o " + exr + " --res 200x150 --quiet");
    ASSERT_EQ(r.exitCode, 0) << r.output;

    Image p = readPng(png), e = readExr(exr);
    ASSERT_EQ(p.width, 200);
    ASSERT_EQ(p.height, 150);
    ASSERT_EQ(e.width, 200);
    double coverage = 0, maxAlphaDiff = 0, colourSum = 0;
    for (int y = 0; y < 150; ++y)
        for (int x = 0; x < 200; ++x) {
            const float* a = p.pixel(x, y);
            const float* b = e.pixel(x, y);
            for (int c = 0; c < 4; ++c) ASSERT_TRUE(std::isfinite(b[c]));
            coverage += a[3];
            colourSum += a[0] + a[1] + a[2];
            maxAlphaDiff = std::max(maxAlphaDiff, double(std::fabs(a[3] - b[3])));
            // EXR is premultiplied: no colour where there is no coverage.
            if (b[3] == 0.f) {
                ASSERT_EQ(b[0] + b[1] + b[2], 0.f);
            }
        }
    coverage /= 200.0 * 150.0;
    EXPECT_GT(coverage, 0.2) << "the teapot fills a good part of the frame";
    EXPECT_LT(coverage, 0.8);
    EXPECT_GT(colourSum, 1000.0) << "lit, not black";
    EXPECT_LT(maxAlphaDiff, 1.0 / 255.0 + 1e-3) << "PNG and EXR coverage agree";

    std::ifstream sf(stats);
    nlohmann::json j = nlohmann::json::parse(sf);
    for (const char* key : {"engine", "width", "height", "spp", "threads", "patches_in", "patches_culled", "splits",
                            "grids", "micropolygons", "sample_tests", "render_ms", "peak_rss_mb"})
        EXPECT_TRUE(j.contains(key)) << key;
    EXPECT_EQ(j["patches_in"].get<int>(), 32);
    EXPECT_EQ(j["spp"].get<int>(), 16);
    EXPECT_GT(j["micropolygons"].get<int>(), 10000);
    fs::remove_all(dir);
}

TEST(Cli, DefaultOutputIsTheRibDisplayName) {
    fs::path dir = tempDir() / "display";
    fs::create_directories(dir);
    CommandResult r = run("render " + kTeapot + " --res 64x48 --quiet", dir.string());
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_TRUE(fs::exists(dir / "teapot.png"));
    fs::remove_all(dir);
}

TEST(Cli, InfoPrintsCountsBoundsAndCamera) {
    CommandResult r = run("info " + kTeapot);
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_NE(r.output.find("patches:  32"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("bounds:"), std::string::npos);
    EXPECT_NE(r.output.find("camera:   800x600"), std::string::npos) << r.output;
}

TEST(Cli, BadInputExitsWithTwoAndAClearMessage) {
    fs::path dir = tempDir();
    fs::path bad = dir / "bad.rib";
    std::ofstream(bad) << "WorldBegin\nAttributeBegin\nPatch \"bicubic\" \"P\" [0 0 0]\nAttributeEnd\nWorldEnd\n";
    std::string out = (dir / "never.png").string();
    CommandResult r = run("render " + bad.string() + " -o " + out);
    EXPECT_EQ(r.exitCode, 2);
    EXPECT_NE(r.output.find(bad.string() + ":3: error:"), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(out)) << "no output for a failed render";

    r = run("render " + (dir / "missing.rib").string());
    EXPECT_EQ(r.exitCode, 2);
    EXPECT_NE(r.output.find("error"), std::string::npos) << r.output;

    r = run("render " + kTeapot + " --res 0x10 -o " + out);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    r = run("render " + kTeapot + " --res 100000x10 -o " + out);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    r = run("render " + kTeapot + " --spp 0 -o " + out);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    r = run("render " + kTeapot + " -o " + (dir / "x.tif").string());
    EXPECT_EQ(r.exitCode, 2) << r.output;
    r = run("render " + kTeapot + " --engine nope");
    EXPECT_EQ(r.exitCode, 2) << r.output;
    r = run("frobnicate");
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_FALSE(fs::exists(out));
    fs::remove_all(dir);
}

TEST(Cli, FailedRenderKeepsThePreviousImage) {
    fs::path dir = tempDir() / "keep";
    fs::create_directories(dir);
    std::string png = (dir / "img.png").string();
    ASSERT_EQ(run("render " + kTeapot + " --res 32x24 -q -o " + png).exitCode, 0);
    auto size = fs::file_size(png);
    fs::path bad = dir / "bad.rib";
    std::ofstream(bad) << "WorldBegin\n\"unterminated\n";
    EXPECT_EQ(run("render " + bad.string() + " -o " + png).exitCode, 2);
    EXPECT_EQ(fs::file_size(png), size);
    for (auto& e : fs::directory_iterator(dir))
        EXPECT_EQ(e.path().filename().string().find(".tmp"), std::string::npos) << "temporary left behind";
    fs::remove_all(dir);
}

TEST(Cli, ConvertWritesARibThatRendersTheSameImage) {
    fs::path dir = tempDir() / "convert";
    fs::create_directories(dir);
    const std::string bpt = std::string(TESSERA_SHARED_DATA) + "/teapot/teapot.bpt";
    const std::string rib = (dir / "teapot.rib").string();
    ASSERT_EQ(run("convert " + bpt + " -o " + rib).exitCode, 0);
    CommandResult info = run("info " + rib);
    EXPECT_NE(info.output.find("patches:  32"), std::string::npos) << info.output;
    const std::string a = (dir / "a.exr").string(), b = (dir / "b.exr").string();
    ASSERT_EQ(run("render " + bpt + " --res 160x120 -q -o " + a).exitCode, 0);
    ASSERT_EQ(run("render " + rib + " --res 160x120 -q -o " + b).exitCode, 0);
    Image ia = readExr(a), ib = readExr(b);
    double maxDiff = 0;
    for (size_t i = 0; i < ia.rgba.size(); ++i) maxDiff = std::max(maxDiff, double(std::fabs(ia.rgba[i] - ib.rgba[i])));
    EXPECT_LT(maxDiff, 2e-3) << "same geometry, camera, lights and material after the round trip";
    EXPECT_EQ(run("convert " + bpt + " -o " + (dir / "x.png").string()).exitCode, 2);
    fs::remove_all(dir);
}
