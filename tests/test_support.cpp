#include "test_support.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <iterator>

namespace tessera::test {
namespace fs = std::filesystem;

namespace {
fs::path processRoot() {
    return fs::temp_directory_path() / ("tessera_tests_" + std::to_string(::getpid()));
}

class ScratchCleanup : public ::testing::Environment {
  public:
    void TearDown() override {
        std::error_code ec;
        fs::remove_all(processRoot(), ec);
    }
};
[[maybe_unused]] ::testing::Environment* const kScratchCleanup =
    ::testing::AddGlobalTestEnvironment(new ScratchCleanup);
}  // namespace

fs::path testScratchDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    fs::path d =
        processRoot() / (info ? std::string(info->test_suite_name()) + "." + info->name() : "global");
    fs::create_directories(d);
    return d;
}

std::string writeTestFile(const std::string& name, const std::string& text) {
    fs::path p = testScratchDir() / name;
    fs::create_directories(p.parent_path());
    std::ofstream(p, std::ios::binary) << text;
    return p.string();
}

}  // namespace tessera::test

namespace tessera::test {

int runTesseraIn(const fs::path& cwd, const std::string& args, std::string* output) {
    static int calls = 0;
    const fs::path log = testScratchDir() / ("run_" + std::to_string(++calls) + ".log");
    const std::string cmd = (cwd.empty() ? std::string() : "cd '" + cwd.string() + "' && ") +
                            std::string(TESSERA_BINARY) + " " + args + " > '" + log.string() + "' 2>&1";
    const int status = std::system(cmd.c_str());
    if (output) {
        std::ifstream f(log);
        output->assign(std::istreambuf_iterator<char>(f), {});
    }
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace tessera::test
