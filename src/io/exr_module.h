// The seam between Tessera and OpenEXR (io/image_io.h's .exr functions). OpenEXR, Imath and their
// libraries cost every run about 2 ms of loading and relocation before main (docs/benchmarks/fixed_costs.md,
// "Session 26"), though most renders write PNG; so the OpenEXR side lives in a module
// (modules/exr_openexr.cpp, built as libtessera_exr.so) that image_io.cpp loads (core/module_loader.h) the
// first time a run reads or writes an .exr.
//
// Plain functions over plain data (views of the image, the header structs of image_io.h): no vtables,
// type_info or exceptions cross the seam. Each returns false with `error` set (OpenEXR's message, without
// the file name, which the caller adds).
#pragma once
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "io/image_io.h"

namespace tessera {

// Bumped whenever a field of ExrModuleApi changes meaning; the loader refuses another version.
inline constexpr uint32_t kExrModuleVersion = 1;

struct ExrPlaneView {
    const std::string* name;
    int components;
    bool integer, color;
    const float* values;  // width * height * components (not integer)
    const uint32_t* ids;  // width * height (integer)
};

// An image's pixels as writeExr takes them: premultiplied linear RGBA floats, row-major from (x0, y0).
struct ExrImageView {
    int width, height, x0, y0;
    const float* rgba;
    const ExrPlaneView* planes;
    size_t planeCount;
};

struct ExrModuleApi {
    uint32_t version;
    // writeExr's file (RGBA half, planes float or uint, ZIP) at `path`, the header from `meta` if any.
    bool (*writeImage)(const char* path, const ExrImageView& image, const ExrMetadata* meta,
                       std::string& error);
    // readExr: the stored RGBA of the data window.
    bool (*readImage)(const char* path, int& width, int& height, int& x0, int& y0, std::vector<float>& rgba,
                      std::string& error);
    bool (*readInfo)(const char* path, ExrInfo& info, std::string& error);
    bool (*writeDepthMap)(const char* path, const DepthMap& map, std::string& error);
    // Fills `map` from a depth map; false when the file cannot be read or is not one.
    bool (*readDepthMap)(const char* path, DepthMap& map, std::string& error);
    // assembleExrTiles' pixel step, after the headers were checked: reads every tile's pixels into one
    // image covering box (inclusive corners) and writes it to `path` with tile 0's header. A read error
    // names its tile in `errorFile`; a write error leaves it empty.
    bool (*assemble)(const std::vector<std::string>& tiles, int boxX0, int boxY0, int boxX1, int boxY1,
                     const char* path, std::string& errorFile, std::string& error);
};

}  // namespace tessera

// The one symbol the module exports: its ExrModuleApi (as a pointer to void, core/module_loader.h).
extern "C" const void* tessera_exr_module();
inline constexpr const char* kExrModuleEntry = "tessera_exr_module";
