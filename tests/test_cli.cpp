// End to end through the command-line tool: images, statistics, info and error handling.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>
#include <vector>

#include "../apps/tessera/progress.h"
#include "io/image_io.h"

namespace tessera::test::cli_tests {

namespace fs = std::filesystem;

namespace {

struct CommandResult {
    int exitCode;
    std::string output;  // stdout + stderr
};

// Runs tessera with `args` in `cwd` (when given), with `env` ("NAME=value ...") prefixed.
CommandResult run(const std::string& args, const std::string& cwd = "", const std::string& env = "") {
    fs::path log = fs::temp_directory_path() / ("tessera_cli_" + std::to_string(getpid()) + ".log");
    std::string cmd = (cwd.empty() ? "" : "cd '" + cwd + "' && ") + env + (env.empty() ? "" : " ") +
                      std::string(TESSERA_BINARY) + " " + args + " > '" + log.string() + "' 2>&1";
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
    CommandResult r =
        run("render " + kTeapot + " -o " + png + " --res 200x150 --stats " + stats + " --quiet");
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
    for (const char* key :
         {"engine", "width", "height", "spp", "threads", "patches_in", "patches_culled", "splits", "grids",
          "micropolygons", "sample_tests", "load_ms", "render_ms", "peak_rss_mb"})
        EXPECT_TRUE(j.contains(key)) << key;
    EXPECT_GT(j["load_ms"].get<double>(), 0.0);
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
    std::ofstream(bad)
        << "WorldBegin\nAttributeBegin\nPatch \"bicubic\" \"P\" [0 0 0]\nAttributeEnd\nWorldEnd\n";
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

TEST(Cli, ShadowsOptionOverridesTheLightsAndRejectsOtherValues) {
    fs::path dir = tempDir() / "shadows";
    fs::create_directories(dir);
    const std::string out = (dir / "t.png").string(), stats = (dir / "t.json").string();
    CommandResult r = run("render " + kTeapot + " --res 40x30 --shadows maybe -o " + out);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_NE(r.output.find("--shadows"), std::string::npos) << r.output;
    r = run("render " + kTeapot + " --res 40x30 --reyes-shadows rays -o " + out);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_NE(r.output.find("--reyes-shadows"), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(out));
    // teapot.rib: its key light casts shadows, the two fill lights do not.
    for (auto [mode, casting] : {std::pair{"scene", 1}, {"on", 3}, {"off", 0}}) {
        r = run("render " + kTeapot + " --engine rt --res 40x30 --quiet --shadows " + mode + " -o " + out +
                " --stats " + stats);
        ASSERT_EQ(r.exitCode, 0) << r.output;
        std::ifstream f(stats);
        const nlohmann::json j = nlohmann::json::parse(f);
        EXPECT_EQ(j["shadows"]["mode"], mode);
        EXPECT_EQ(j["shadows"]["casting_lights"], casting) << mode;
        EXPECT_EQ(j["rays"]["shadow"].get<uint64_t>() > 0, casting > 0) << mode;
    }
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
    const std::string bpt = std::string(TESSERA_TEST_DATA) + "/teapot.bpt";
    const std::string rib = (dir / "teapot.rib").string();
    ASSERT_EQ(run("convert " + bpt + " -o " + rib).exitCode, 0);
    CommandResult info = run("info " + rib);
    EXPECT_NE(info.output.find("patches:  32"), std::string::npos) << info.output;
    const std::string a = (dir / "a.exr").string(), b = (dir / "b.exr").string();
    ASSERT_EQ(run("render " + bpt + " --res 160x120 -q -o " + a).exitCode, 0);
    ASSERT_EQ(run("render " + rib + " --res 160x120 -q -o " + b).exitCode, 0);
    Image ia = readExr(a), ib = readExr(b);
    double maxDiff = 0;
    for (size_t i = 0; i < ia.rgba.size(); ++i)
        maxDiff = std::max(maxDiff, double(std::fabs(ia.rgba[i] - ib.rgba[i])));
    EXPECT_LT(maxDiff, 2e-3) << "same geometry, camera, lights and material after the round trip";
    EXPECT_EQ(run("convert " + bpt + " -o " + (dir / "x.png").string()).exitCode, 2);
    fs::remove_all(dir);
}

// --res is known before the scene is read: a SubdivisionMesh is refined for the size it has in the image
// rendered (docs/subdivision.md). The cube is level 2 (6 x 16 patches) in the file's 200 x 200 and level 3
// (6 x 64) at 1600 x 1600; `info --res` reports what `render --res` renders, and a crop window does not
// change it.
TEST(Cli, ResChoosesTheSubdivisionLevel) {
    fs::path dir = tempDir() / "subdivres";
    fs::create_directories(dir);
    const std::string rib = (dir / "cube.rib").string();
    std::ofstream(rib) << "Format 200 200 1\nProjection \"perspective\" \"fov\" 40\nTranslate 0 0 30\n"
                          "WorldBegin\nLightSource \"ambientlight\" 1\nSubdivisionMesh \"catmull-clark\" "
                          "[4 4 4 4 4 4] [0 3 2 1 4 5 6 7 0 1 5 4 1 2 6 5 2 3 7 6 3 0 4 7] \"P\" "
                          "[-1 -1 -1 1 -1 -1 1 1 -1 -1 1 -1 -1 -1 1 1 -1 1 1 1 1 -1 1 1]\nWorldEnd\n";
    CommandResult info = run("info " + rib);
    EXPECT_NE(info.output.find("patches:  96\n"), std::string::npos) << info.output;
    info = run("info " + rib + " --res 1600x1600");
    EXPECT_NE(info.output.find("patches:  384\n"), std::string::npos) << info.output;
    EXPECT_NE(info.output.find("camera:   1600x1600"), std::string::npos) << info.output;
    EXPECT_EQ(run("info " + rib + " --res 0x5").exitCode, 2);
    const std::string out = (dir / "c.png").string(), stats = (dir / "c.json").string();
    ASSERT_EQ(run("render " + rib + " --res 1600x1600 --crop 0.45,0.55,0.45,0.55 -q -o " + out + " --stats " +
                  stats)
                  .exitCode,
              0);
    const nlohmann::json s = nlohmann::json::parse(std::ifstream(stats));
    EXPECT_EQ(s.value("patches_in", 0), 384) << s.dump();
    fs::remove_all(dir);
}

// ---- first run: version, help, mistakes caught before the render, progress ------------------------

TEST(Cli, VersionNamesTheVersionAndBuildType) {
    CommandResult r = run("--version");
    EXPECT_EQ(r.exitCode, 0) << r.output;
    EXPECT_NE(r.output.find("tessera 0."), std::string::npos) << r.output;
    EXPECT_NE(r.output.find(" build)"), std::string::npos) << r.output;
}

TEST(Cli, RenderHelpListsEveryInputFormatAndTheDefaults) {
    CommandResult r = run("render --help");
    EXPECT_EQ(r.exitCode, 0) << r.output;
    for (const char* format : {"RIB", ".rib.gz", ".bpt", "OBJ", "Micropolis"})
        EXPECT_NE(r.output.find(format), std::string::npos) << format << "\n" << r.output;
    for (const char* option :
         {"--engine TEXT:{reyes,rt}=reyes", "--bucket-size INT:(4..1024)=32", "--max-grid INT:(1..256)=16",
          "--subpatch-depth INT:auto|(0..12)=auto", "--max-depth INT:(0..64)", "default 4", "16 (path",
          "--threads INT:(0..4096)=0", "--format", "--up", "--progress"})
        EXPECT_NE(r.output.find(option), std::string::npos) << option << "\n" << r.output;
}

TEST(Cli, UnknownCommandIsNamed) {
    CommandResult r = run("rendr " + kTeapot);
    EXPECT_EQ(r.exitCode, 2);
    EXPECT_NE(r.output.find("unknown command 'rendr'"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("did you mean 'render'"), std::string::npos) << r.output;
    r = run("");
    EXPECT_EQ(r.exitCode, 2) << r.output;
}

TEST(Cli, RangeErrorsPrintReadableNumbers) {
    for (const char* args : {"--shading-rate 0", "--shading-rate -1", "--threads -1", "--spp 0", "--spp 2.5",
                             "--bucket-size 2", "--max-depth 100"}) {
        CommandResult r =
            run("render " + kTeapot + " -q -o " + (tempDir() / "never.png").string() + " " + args);
        EXPECT_EQ(r.exitCode, 2) << args << ": " << r.output;
        EXPECT_NE(r.output.find("must be"), std::string::npos) << args << ": " << r.output;
        // No number longer than 8 digits (CLI11's own checks print DBL_MAX in full).
        size_t run = 0, longest = 0;
        for (char c : r.output) {
            run = std::isdigit(static_cast<unsigned char>(c)) ? run + 1 : 0;
            longest = std::max(longest, run);
        }
        EXPECT_LE(longest, 8u) << args << ": " << r.output;
    }
    fs::remove_all(tempDir());
}

TEST(Cli, UpAppliesOnlyToInputsWithoutACamera) {
    // One bump patch standing on z = 0, centred on the z axis: z is up by the data.
    const std::string bpt = (tempDir() / "bump.bpt").string();
    {
        std::ofstream f(bpt);
        f << "1\n3 3\n";
        for (int k = 0; k < 16; ++k)
            f << (k % 4) - 1.5 << " " << (k / 4) - 1.5 << " " << ((k % 4) % 3 && (k / 4) % 3) << "\n";
    }
    CommandResult r = run("info " + bpt);
    EXPECT_NE(r.output.find("framing:  default camera, up z (chosen from the data)"), std::string::npos)
        << r.output;
    r = run("info " + bpt + " --up y");
    EXPECT_NE(r.output.find("up y (--up)"), std::string::npos) << r.output;
    r = run("render " + kTeapot + " --up y -q -o " + (tempDir() / "never.png").string());
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_NE(r.output.find("has its own camera"), std::string::npos) << r.output;
    r = run("render " + bpt + " --up w -q -o " + (tempDir() / "never.png").string());
    EXPECT_EQ(r.exitCode, 2) << r.output;
    fs::remove_all(tempDir());
}

// --progress: "progress N%" lines on stderr, N strictly increasing from 0 to 100, nothing else on them.
TEST(Cli, ProgressLinesArePrintedOncePerPercent) {
    fs::path dir = tempDir() / "progress";
    fs::create_directories(dir);
    for (const char* engine : {"reyes", "rt"}) {
        CommandResult r = run("render " + kTeapot + " --res 320x240 --spp 1 -q --progress --bucket-size 8 " +
                              "--engine " + engine + " -o " + (dir / "p.png").string());
        ASSERT_EQ(r.exitCode, 0) << r.output;
        std::istringstream lines(r.output);
        std::string line;
        std::vector<int> percents;
        while (std::getline(lines, line)) {
            int p = -1;
            char pct = 0, extra = 0;
            if (std::sscanf(line.c_str(), "progress %d%c%c", &p, &pct, &extra) == 2 && pct == '%')
                percents.push_back(p);
            else
                ADD_FAILURE() << "unexpected line '" << line << "'";
        }
        ASSERT_GE(percents.size(), 2u) << r.output;
        EXPECT_EQ(percents.front(), 0);
        EXPECT_EQ(percents.back(), 100);
        for (size_t i = 1; i < percents.size(); ++i) EXPECT_GT(percents[i], percents[i - 1]) << r.output;
    }
    fs::remove_all(dir);
}

// Every exit status the CLI uses is listed in the README.
TEST(Cli, ReadmeListsEveryExitStatus) {
    std::ifstream f(std::string(TESSERA_SOURCE_DIR) + "/README.md");
    std::stringstream ss;
    ss << f.rdbuf();
    const std::string readme = ss.str();
    size_t at = readme.find("Exit status");
    ASSERT_NE(at, std::string::npos);
    // The list item: up to the next item or paragraph, line breaks read as blanks.
    std::string line = readme.substr(at, std::min(readme.find("\n- ", at), readme.find("\n\n", at)) - at);
    std::replace(line.begin(), line.end(), '\n', ' ');
    for (const char* status : {"0 ", "1 ", "2 ", "130 "})
        EXPECT_NE(line.find(status), std::string::npos) << status << " missing from: " << line;
}

// ---- the time-left estimate and the percent steps, fed with made-up clocks -------------------------

// Constant work rate after 2 s of set-up (what the engines do before their first tile): the estimate is
// the true time left from the second report on, and it only goes down. The naive elapsed * (1 - f) / f
// would count the set-up as work and start 2 s * (1 - f) / f too high.
TEST(ProgressEstimate, SetUpTimeDoesNotInflateTheEstimate) {
    tessera::cli::TimeLeftEstimate e;
    const double setup = 2.0, rate = 1000.0;  // units per second
    const int64_t total = 10000;
    double previous = 1e30;
    for (int64_t done = 100; done <= total; done += 100) {
        const double t = setup + done / rate;
        e.update(t, done, total);
        std::optional<double> left = e.secondsLeft(t);
        if (done == 100) {
            EXPECT_FALSE(left.has_value()) << "one report gives no rate";
            continue;
        }
        ASSERT_TRUE(left.has_value());
        EXPECT_NEAR(*left, (total - done) / rate, 1e-9) << done;
        EXPECT_LE(*left, previous);
        previous = *left;
    }
    EXPECT_EQ(*e.secondsLeft(setup + total / rate), 0.0);
}

// Uneven work (tiles alternate between cheap and expensive, reports come in bursts): the estimated finish
// time stays within 10% of the true one after the first tenth, and it never moves by more than 5% of the
// total time between two reports, where the naive estimate swings with every expensive tile.
TEST(ProgressEstimate, UnevenWorkGivesASteadyEstimate) {
    tessera::cli::TimeLeftEstimate e;
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> jitter(0.5, 1.5);
    const int tiles = 400;
    std::vector<double> cost(tiles);
    double totalTime = 0;
    for (int i = 0; i < tiles; ++i) totalTime += cost[i] = (i % 8 < 4 ? 1.0 : 3.0) * jitter(rng) * 0.01;
    double t = 0, lastFinish = -1;
    for (int i = 0; i < tiles; ++i) {
        t += cost[i];
        e.update(t, i + 1, tiles);
        std::optional<double> left = e.secondsLeft(t);
        if (!left || i < tiles / 10) continue;
        const double finish = t + *left;
        EXPECT_NEAR(finish, totalTime, 0.1 * totalTime) << "tile " << i;
        if (lastFinish >= 0) {
            EXPECT_LT(std::fabs(finish - lastFinish), 0.05 * totalTime) << "tile " << i;
        }
        lastFinish = finish;
    }
}

TEST(ProgressEstimate, PercentStepsAreWholeIncreasingAndOnce) {
    tessera::cli::PercentSteps steps;
    steps.markReported(0);
    std::vector<int> seen;
    const int64_t total = int64_t(16384) * 16384 * 1024;  // more samples than an int holds
    for (int64_t done = 0; done <= total; done += total / 997)
        if (std::optional<int> p = steps.step(done, total)) seen.push_back(*p);
    if (std::optional<int> p = steps.step(total, total)) seen.push_back(*p);
    ASSERT_EQ(seen.size(), 100u);
    for (int i = 0; i < 100; ++i) EXPECT_EQ(seen[i], i + 1);
    EXPECT_FALSE(steps.step(total / 2, total).has_value()) << "never backwards";
    EXPECT_FALSE(steps.step(total, total).has_value()) << "100% once";
}

TEST(Cli, AmbientOcclusionRendersAGreyImageAndChecksItsOptions) {
    fs::path dir = tempDir();
    const std::string out = (dir / "ao.png").string(), stats = (dir / "ao.json").string();
    CommandResult r =
        run("render " + kTeapot +
            " --engine rt --integrator ao --ao-samples 8 --ao-distance 2 --res 64x48 --spp 1 -q -o " + out +
            " --stats " + stats);
    ASSERT_EQ(r.exitCode, 0) << r.output;
    const nlohmann::json s = nlohmann::json::parse(std::ifstream(stats));
    EXPECT_EQ(s["integrator"], "ao");
    EXPECT_EQ(s["ao"]["samples"], 8);
    EXPECT_EQ(s["rays"]["occlusion"].get<uint64_t>(), 8 * s["hits"]["primary"].get<uint64_t>());
    const Image img = readPng(out);
    size_t grey = 0, covered = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            const float* p = img.pixel(x, y);
            if (p[3] < 1.f) continue;
            ++covered;
            grey += p[0] == p[1] && p[1] == p[2];
        }
    EXPECT_GT(covered, 100u);
    EXPECT_EQ(grey, covered) << "ambient occlusion is grey whatever the surface colour";
    // Each mistake names its option.
    const std::pair<const char*, const char*> mistakes[] = {
        {"--integrator ao", "--integrator"},
        {"--engine rt --integrator nope", "--integrator"},
        {"--engine rt --ao-samples 0", "--ao-samples"},
        {"--engine rt --ao-distance -1", "--ao-distance"},
        {"--engine rt --ao-weighting nope", "--ao-weighting"}};
    for (const auto& [bad, named] : mistakes) {
        r = run("render " + kTeapot + " " + bad + " -o " + (dir / "never.png").string());
        EXPECT_EQ(r.exitCode, 2) << bad << ": " << r.output;
        EXPECT_NE(r.output.find(named), std::string::npos) << bad << ": " << r.output;
    }
    EXPECT_FALSE(fs::exists(dir / "never.png"));
    fs::remove_all(dir);
}

TEST(Cli, AdaptiveWritesItsMapAndRejectsBadOptions) {
    fs::path dir = tempDir();
    const std::string out = (dir / "a.png").string(), map = (dir / "map.png").string(),
                      stats = (dir / "a.json").string();
    CommandResult r =
        run("render " + kTeapot + " --engine rt --adaptive --adaptive-threshold 0.5 --res 64x48 -o " + out +
            " --adaptive-map " + map + " --stats " + stats + " --quiet");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    const Image m = readPng(map);
    EXPECT_EQ(m.width, 128);
    EXPECT_EQ(m.height, 96);
    std::ifstream sf(stats);
    const nlohmann::json s = nlohmann::json::parse(sf);
    EXPECT_GT(s["adaptive"]["active_fraction"].get<double>(), 0.0);
    EXPECT_FLOAT_EQ(s["adaptive"]["thresholds"]["color"].get<float>(), 0.5f);
    fs::remove(out);
    fs::remove(map);
    const std::string base = "render " + kTeapot + " --res 64x48 -o " + out + " ";
    struct Bad {
        std::string args, message;
    };
    const Bad bad[] = {
        {"--adaptive", "--engine rt"},
        {"--engine rt --adaptive-threshold 0.3", "need --adaptive"},
        {"--engine rt --adaptive-map " + map, "need --adaptive"},
        {"--engine rt --adaptive --adaptive-threshold -1", "--adaptive-threshold must be"},
        {"--engine rt --adaptive --adaptive-threshold inf", "--adaptive-threshold must be"},
        {"--engine rt --adaptive --adaptive-map " + (dir / "m.exr").string(), "name it .png"},
        {"--engine rt --adaptive --adaptive-map " + out, "name the same file"},
        {"--engine rt --adaptive --spp 4", "drop --spp"},
    };
    for (const Bad& b : bad) {
        r = run(base + b.args);
        EXPECT_EQ(r.exitCode, 2) << b.args << ": " << r.output;
        EXPECT_NE(r.output.find(b.message), std::string::npos) << b.args << ": " << r.output;
    }
    EXPECT_FALSE(fs::exists(out));
    EXPECT_FALSE(fs::exists(map));
    fs::remove_all(dir);
}

// The executable's own dynamic dependencies as `readelf -d` lists them (ldd would list theirs too).
std::string neededLibraries() {
    const std::string file = "/tmp/tessera_needed_" + std::to_string(getpid());
    const std::string deps = std::string("readelf -d ") + TESSERA_BINARY + " > " + file + " 2>&1";
    EXPECT_EQ(std::system(deps.c_str()), 0);
    std::ifstream f(file);
    std::stringstream needed;
    needed << f.rdbuf();
    fs::remove(file);
    return needed.str();
}

// OpenImageIO lives in a module loaded on first use (shading/texture_module.h): the executable does not
// link it (so a run without textures does not pay for its ~260 libraries), a textured scene loads it, and
// a missing or wrong module is a clear input error (exit 2, no image) rather than a crash.
TEST(Cli, TexturesLoadTheOpenImageIOModuleOnlyWhenNeeded) {
    CommandResult r = run("--version");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    const std::string needed = neededLibraries();
    EXPECT_NE(needed.find("NEEDED"), std::string::npos) << needed;
    EXPECT_EQ(needed.find("OpenImageIO"), std::string::npos) << needed;

    fs::path dir = tempDir();
    const std::string out = (dir / "t.png").string();
    const std::string textured = "render " + std::string(TESSERA_SOURCE_DIR) +
                                 "/scenes/textured_teapot.rib --res 64x48 --quiet -o " + out;
    r = run(textured);
    ASSERT_EQ(r.exitCode, 0) << r.output;
    const Image img = readPng(out);
    EXPECT_EQ(img.width, 64);
    fs::remove(out);
    // A module that is not there, and a file that is not a shared library: exit 2 naming the scene's
    // line, the module and why, and no image.
    const std::string notALibrary = (dir / "not_a_module.so").string();
    std::ofstream(notALibrary) << "not an ELF file\n";
    for (const std::string& module : {(dir / "absent.so").string(), notALibrary}) {
        r = run(textured, "", "TESSERA_TEXTURE_MODULE='" + module + "'");
        EXPECT_EQ(r.exitCode, 2) << r.output;
        EXPECT_NE(r.output.find("textured_teapot.rib:"), std::string::npos) << r.output;
        EXPECT_NE(r.output.find("OpenImageIO module"), std::string::npos) << r.output;
        EXPECT_NE(r.output.find(module + ": "), std::string::npos) << r.output;
        EXPECT_FALSE(fs::exists(out));
    }
    EXPECT_NE(run(textured, "", "TESSERA_TEXTURE_MODULE='" + (dir / "absent.so").string() + "'")
                  .output.find("absent.so: not found"),
              std::string::npos);
    fs::remove_all(dir);
}

// OpenEXR is a module as well (io/exr_module.h): the executable does not link it, a PNG render never loads
// it (it runs with the module's path pointing nowhere), and an .exr output with the module missing fails
// before the render, naming the file, the module and each place tried: exit 2 and no file.
TEST(Cli, ExrFilesLoadTheOpenEXRModuleOnlyWhenNeeded) {
    const std::string needed = neededLibraries();
    EXPECT_NE(needed.find("NEEDED"), std::string::npos) << needed;
    EXPECT_EQ(needed.find("OpenEXR"), std::string::npos) << needed;
    EXPECT_EQ(needed.find("Imath"), std::string::npos) << needed;

    fs::path dir = tempDir();
    const std::string absent = (dir / "absent.so").string();
    const std::string noModule = "TESSERA_EXR_MODULE='" + absent + "'";
    const std::string png = (dir / "t.png").string(), exr = (dir / "t.exr").string();
    const std::string base = "render " + kTeapot + " --res 48x36 --quiet -o ";
    CommandResult r = run(base + png, "", noModule);
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_EQ(readPng(png).width, 48);

    r = run(base + exr, "", noModule);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_NE(r.output.find(exr + ": error: OpenEXR files need Tessera's OpenEXR module"), std::string::npos)
        << r.output;
    EXPECT_NE(r.output.find(absent + ": not found"), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(exr));

    // With the module: the same render writes the .exr, whose pixels match the PNG's.
    r = run(base + exr);
    ASSERT_EQ(r.exitCode, 0) << r.output;
    const Image a = readPng(png), b = readExr(exr);
    ASSERT_EQ(b.width, 48);
    ASSERT_EQ(b.height, 36);
    float maxDiff = 0;
    for (size_t i = 0; i < a.rgba.size(); i += 4)
        maxDiff = std::max(maxDiff, std::abs(a.rgba[i + 3] - b.rgba[i + 3]));
    EXPECT_LT(maxDiff, 1.f / 255 + 1e-3f) << "alpha differs between the PNG and the EXR";

    // assemble checks the module before it reads any tile.
    r = run("assemble " + exr + " -o " + (dir / "joined.exr").string(), "", noModule);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_NE(r.output.find("OpenEXR module"), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(dir / "joined.exr"));
    fs::remove_all(dir);
}

}  // namespace tessera::test::cli_tests
