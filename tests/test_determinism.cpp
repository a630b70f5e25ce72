// Determinism (issue 5): the same scene, options and seed give bit-identical images whatever --threads is
// and from one run to the next, for both engines, through the command-line tool (EXR pixel arrays).
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <string>

#include "io/image_io.h"

namespace tessera::test::determinism_tests {

namespace fs = std::filesystem;

namespace {

const std::string kTeapot = std::string(TESSERA_SOURCE_DIR) + "/scenes/teapot.rib";

fs::path scratch() {
    fs::path d = fs::temp_directory_path() / ("tessera_determinism_" + std::to_string(getpid()));
    fs::create_directories(d);
    return d;
}

Image renderExr(const std::string& options, const std::string& name) {
    fs::path out = scratch() / (name + ".exr");
    std::string cmd =
        std::string(TESSERA_BINARY) + " render " + kTeapot + " -q -o " + out.string() + " " + options;
    int status = std::system(cmd.c_str());
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << cmd;
    Image img = readExr(out.string());
    fs::remove(out);
    return img;
}

// Bit-identical, including the sign of zeros and NaN payloads (there must be none).
void expectIdentical(const Image& a, const Image& b, const std::string& what) {
    ASSERT_EQ(a.width, b.width) << what;
    ASSERT_EQ(a.height, b.height) << what;
    ASSERT_EQ(a.rgba.size(), b.rgba.size()) << what;
    size_t differ = 0, first = 0;
    for (size_t i = 0; i < a.rgba.size(); ++i)
        if (std::memcmp(&a.rgba[i], &b.rgba[i], sizeof(float)) != 0 && differ++ == 0) first = i;
    EXPECT_EQ(differ, 0u) << what << ": first difference at pixel " << first / 4 % a.width << ","
                          << first / 4 / a.width << " channel " << first % 4 << ": " << a.rgba[first]
                          << " vs " << b.rgba[first];
}

}  // namespace

class Determinism : public ::testing::TestWithParam<std::string> {};

TEST_P(Determinism, SameImageForAnyThreadCountAndAcrossRuns) {
    const std::string opts = "--engine " + GetParam() + " --res 160x120 --spp 4 --seed 7 --bucket-size 16";
    Image one = renderExr(opts + " --threads 1", "t1");
    Image two = renderExr(opts + " --threads 2", "t2a");
    Image again = renderExr(opts + " --threads 2", "t2b");
    expectIdentical(one, two, "--threads 1 vs --threads 2");
    expectIdentical(two, again, "two runs with --threads 2");
    // More threads than cores still schedules the same work.
    expectIdentical(one, renderExr(opts + " --threads 5", "t5"), "--threads 1 vs --threads 5");
    // The seed does matter (so the comparison above is not vacuous).
    Image other =
        renderExr("--engine " + GetParam() + " --res 160x120 --spp 4 --seed 8 --bucket-size 16", "seed8");
    bool anyDifference = false;
    for (size_t i = 0; i < one.rgba.size() && !anyDifference; ++i)
        anyDifference = one.rgba[i] != other.rgba[i];
    EXPECT_TRUE(anyDifference) << "--seed changes the sample pattern";
    fs::remove_all(scratch());
}

INSTANTIATE_TEST_SUITE_P(Engines, Determinism, ::testing::Values("reyes", "rt"),
                         [](const auto& info) { return info.param; });

}  // namespace tessera::test::determinism_tests
