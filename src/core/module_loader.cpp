#include "core/module_loader.h"

#include <dlfcn.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <vector>

namespace tessera {

namespace {
// The directory of the running executable ("" when /proc is not mounted).
std::string executableDir() {
    std::error_code ec;
    const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
    return ec ? std::string() : exe.parent_path().string();
}
}  // namespace

const void* loadModule(const ModuleSpec& spec, std::string& error) {
    std::vector<std::string> candidates;
    const char* env = std::getenv(spec.envVar);
    if (env && *env) {
        candidates.emplace_back(env);
    } else {
        if (const std::string dir = executableDir(); !dir.empty()) {
            candidates.push_back(dir + "/" + spec.file);
            candidates.push_back(dir + "/../lib/tessera/" + spec.file);
        }
        if (spec.builtPath) candidates.emplace_back(spec.builtPath);
    }
    std::string tried;
    for (size_t i = 0; i < candidates.size(); ++i) {
        const std::string& path = candidates[i];
        if (std::find(candidates.begin(), candidates.begin() + ptrdiff_t(i), path) !=
            candidates.begin() + ptrdiff_t(i))
            continue;  // the build tree's path is often the executable's directory
        std::error_code ec;
        if (!std::filesystem::exists(path, ec)) {
            tried += "\n  " + path + ": not found";
            continue;
        }
        void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
        if (!handle) {
            const char* why = dlerror();
            tried += "\n  " + path + ": " + (why ? why : "dlopen failed");
            continue;
        }
        using Entry = const void* (*)();
        auto entry = reinterpret_cast<Entry>(dlsym(handle, spec.entry));
        const void* api = entry ? entry() : nullptr;
        if (!api || *static_cast<const uint32_t*>(api) != spec.version) {
            tried += "\n  " + path + ": not a " + spec.entry + " module of this version of Tessera";
            dlclose(handle);
            continue;
        }
        return api;
    }
    error = std::string(spec.what) + " (" + spec.file + "), which could not be loaded; tried:" + tried;
    return nullptr;
}

}  // namespace tessera
