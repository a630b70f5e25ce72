// The seam between Tessera and OpenImageIO. OIIO and what it links (some 260 shared libraries, bound at
// load time) cost every `tessera` run 0.1-0.8 s of dynamic relocation before main, whether the scene has
// textures or not; so the OIIO side lives in a module (modules/texture_oiio.cpp, built as
// libtessera_texture_oiio.so) that texture.cpp loads (core/module_loader.h) the first time a scene needs
// a texture.
//
// The interface is a table of plain functions over an opaque handle: no vtables or type_info cross the
// seam, so the module needs no symbols from the executable (which exports none) and sanitizer builds
// see no duplicate type identities.
#pragma once
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace tessera {

struct TextureLookup;

// Bumped whenever a field of TextureModuleApi changes meaning; the loader refuses another version.
inline constexpr uint32_t kTextureModuleVersion = 2;

struct TextureModuleApi {
    uint32_t version;
    // Opens every file; nullptr with `error` naming the file when one cannot be read.
    void* (*open)(std::span<const std::string> files, std::string& error);
    void (*close)(void* set);
    // Channels of texture `texture` of an open set (at least 1).
    int (*channels)(const void* set, uint32_t texture);
    // Filtered lookup of the first `nchannels` channels into `out` (and their d/ds, d/dt when not
    // nullptr); zeros where OIIO fails.
    void (*lookup)(const void* set, uint32_t texture, const TextureLookup& q, int nchannels, float* out,
                   float* dds, float* ddt);
    // Smallest and largest first-channel value over the finest level (computed once, thread-safe).
    void (*range)(const void* set, uint32_t texture, float& lo, float& hi);
    // The first channel of the finest level as floats (row 0 at the top) and the lookups' wrap modes in s
    // and t (0 periodic, 1 clamp, 2 black), read through ImageBuf from the file the lookups read; false
    // (and nothing set) when it cannot be read.
    bool (*texels)(const void* set, uint32_t texture, int& width, int& height, std::vector<float>& out,
                   int& swrap, int& twrap);
    // "" when OIIO reads `path` as a non-empty image, otherwise OIIO's reason.
    std::string (*readError)(const std::string& path);
    // RI MakeTexture through OIIO's make_texture; "" on success, otherwise the reason.
    std::string (*makeTexture)(const std::string& picture, const std::string& texture,
                               const std::string& swrap, const std::string& twrap);
};

}  // namespace tessera

// The one symbol the module exports: its TextureModuleApi (core/module_loader.h: every module's entry has
// this one type, so that the loader calls it through its own type).
extern "C" const void* tessera_texture_module();
inline constexpr const char* kTextureModuleEntry = "tessera_texture_module";
