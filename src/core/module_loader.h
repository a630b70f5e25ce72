// Optional parts of Tessera built as shared modules and loaded with dlopen on first use: OpenImageIO for
// textures (shading/texture_module.h) and OpenEXR for .exr images (io/exr_module.h). Linked into the
// executable, their libraries cost every run their dynamic relocation before main (OIIO's ~260 libraries
// 0.1-0.8 s, OpenEXR and Imath about 2 ms), whether the scene uses them or not.
//
// A module exports one extern "C" function returning a table of plain functions whose first field is a
// uint32_t version; no vtables or type_info cross the seam, so a module needs no symbols from the
// executable (which exports none).
#pragma once
#include <cstdint>
#include <string>

namespace tessera {

struct ModuleSpec {
    const char* file;       // the module's file name, e.g. "libtessera_exr.so"
    const char* envVar;     // an environment variable whose value, a path, is the only place tried
    const char* builtPath;  // where the build tree put it (for binaries in subdirectories); may be nullptr
    const char* entry;      // the exported function that returns the table
    uint32_t version;       // the table's version this executable was built with
    const char* what;       // the start of the message when it cannot be loaded, e.g. "textures need
                            // Tessera's OpenImageIO module"
};

// Loads the module (never unloaded: the libraries behind them keep threads and statics that outlive any
// one render) and returns its table, or nullptr with `error` listing each place tried and why it failed.
// Places: $envVar when it is set (the user's choice, and then the only one); otherwise, in turn, the
// executable's directory (the build tree's top), ../lib/tessera beside it (an install) and builtPath.
const void* loadModule(const ModuleSpec& spec, std::string& error);

// A module's table as its caller keeps it (once per process, in a function-local static): the table, or
// nullptr and why it could not be loaded.
template <class Api>
struct LoadedModule {
    const Api* api = nullptr;
    std::string error;
};
template <class Api>
LoadedModule<Api> loadModuleAs(const ModuleSpec& spec) {
    LoadedModule<Api> m;
    m.api = static_cast<const Api*>(loadModule(spec, m.error));
    return m;
}

}  // namespace tessera
