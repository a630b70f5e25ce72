// Helpers shared by the RIB reader's tests (test_rib.cpp, test_motion_input.cpp): scratch RIB files,
// loading with the warnings collected, and the "<file>:<line>: error:" check of a rejected file.
#pragma once
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "io/diagnostics.h"
#include "io/scene_loader.h"
#include "test_support.h"

namespace tessera::test {

inline std::string writeFile(const std::filesystem::path& path, const std::string& text) {
    std::filesystem::create_directories(path.parent_path());
    std::ofstream(path, std::ios::binary) << text;
    return path.string();
}

// `text` as a RIB file in the test's scratch directory.
inline std::string writeRib(const std::string& text, const std::string& name = "scene.rib") {
    return writeFile(testScratchDir() / name, text);
}

struct Loaded {
    Scene scene;
    std::vector<std::string> warnings;
};

inline Loaded load(const std::string& text) {
    Loaded l;
    const std::string path = writeRib(text);
    l.scene = loadScene(path, [&](const std::string& w) { l.warnings.push_back(w); });
    return l;
}

// The error text of loading `path`, or "" if it loads.
inline std::string errorOfFile(const std::string& path) {
    try {
        loadScene(path, [](const std::string&) {});
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

// Asserts that loading `text` fails with "<file>:<line>: error:" and returns the message.
inline std::string expectError(const std::string& text, int line) {
    const std::string path = writeRib(text);
    const std::string msg = errorOfFile(path);
    const std::string prefix = path + ":" + std::to_string(line) + ": error:";
    EXPECT_EQ(msg.rfind(prefix, 0), 0u) << "expected prefix '" << prefix << "', got '" << msg << "'";
    return msg;
}

inline bool contains(const std::string& s, const std::string& part) {
    return s.find(part) != std::string::npos;
}

inline void expectVec(Vec3 a, Vec3 b, float eps = 1e-5f) {
    EXPECT_NEAR(a.x, b.x, eps);
    EXPECT_NEAR(a.y, b.y, eps);
    EXPECT_NEAR(a.z, b.z, eps);
}

}  // namespace tessera::test
