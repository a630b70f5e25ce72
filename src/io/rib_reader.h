// Reader for the subset of the RenderMan Interface Bytestream (RI spec 3.2) that describes bicubic
// and bilinear patch scenes: camera and image options, transforms, attributes, the standard light
// and surface shaders, Patch and PatchMesh in any basis, Declare and ReadArchive.
#pragma once
#include <string>
#include <vector>

#include "io/diagnostics.h"
#include "scene/scene.h"

namespace tessera {

// The raster size the scene will be rendered at when the caller overrides the file's Format (the CLI's
// --res, the Python module's res=): a SubdivisionMesh's automatic refinement level follows the mesh's size
// in that image, not in the Format's (docs/subdivision.md). The whole frame's size: a crop window or tile
// does not change it. {0, 0}: the file's own Format. The scene's camera keeps the file's resolution (the
// caller applies its override, render_options.h applySceneOverrides).
struct RasterOverride {
    int width = 0, height = 0;
    bool given() const { return width > 0 && height > 0; }
};

// Reads the RIB file at `path` (plain or gzipped) into `scene`. Throws InputError for malformed input
// or a file without patches; unsupported requests and parameters are reported once each to `warn`.
// Object ids (PatchAttributes::object): one per attribute block (AttributeBegin ... AttributeEnd, each
// ObjectInstance), or per Attribute "identifier" "name" (scene.objectCount counts them).
void readRib(const std::string& path, Scene& scene, const WarningSink& warn, RasterOverride raster = {});

// Multi-frame RIB (RI spec 3.2, sec. 4.1.1): as readRib, loading the frame opened by the
// `frameOrdinal`-th FrameBegin (0-based) with the options and attributes given outside frames before it;
// the other frames and everything after this frame's FrameEnd are skipped.
void readRibFrame(const std::string& path, int frameOrdinal, Scene& scene, const WarningSink& warn,
                  RasterOverride raster = {});

// The FrameBegin blocks of a RIB file in order (lexed only, ReadArchive not followed): the frame number
// each gives and its line. Throws InputError if the file cannot be read.
struct RibFrame {
    int number = 0;
    int line = 0;
};
std::vector<RibFrame> ribFrames(const std::string& path);

// As readRib, for RIB text already in memory (plain, not gzipped): `path` names it in errors and is the
// base of relative ReadArchive names. Used by the fuzz targets.
void readRibText(std::string text, const std::string& path, Scene& scene, const WarningSink& warn,
                 RasterOverride raster = {});

// How much archive text the readers may record on an archive's first read, in all (the rest are
// recorded on their second read; default 64 MB). The tests set 0 to exercise the second-read path.
// Returns the previous value.
size_t setArchiveFirstReadRecordBytes(size_t bytes);

}  // namespace tessera
