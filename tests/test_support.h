// Scratch files for tests: one directory per test under a per-process root that is removed when the
// test program ends, so parallel test processes never share files and nothing is left behind.
#pragma once
#include <filesystem>
#include <string>

namespace tessera::test {

// <tmp>/tessera_tests_<pid>/<Suite>.<Test>/, created on first use.
std::filesystem::path testScratchDir();

// Writes `text` (bytes as given) to testScratchDir()/name and returns the path.
std::string writeTestFile(const std::string& name, const std::string& text);

// Runs the tessera executable with `args` in directory `cwd` (empty: the current one); its stdout and
// stderr go to `output` if given. Returns the exit status (-1 if it did not exit).
int runTesseraIn(const std::filesystem::path& cwd, const std::string& args, std::string* output = nullptr);

}  // namespace tessera::test
