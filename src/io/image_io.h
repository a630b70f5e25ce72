// Image files: PNG (8-bit RGBA, straight alpha) and OpenEXR (half RGBA, linear, premultiplied, plus the
// image's planes as further channels: the AOVs).
// Files are written to a temporary name beside the target and renamed when complete, so a failed
// render never leaves a partial file and never clobbers a good one.
#pragma once
#include <string>
#include <vector>

#include "core/transform.h"
#include "film/film.h"
#include "scene/camera.h"

namespace tessera {

// What an OpenEXR header tells a compositor about the render (the standard attributes worldToCamera and
// worldToNDC, as Nuke and other readers take them, and the software's name).
struct ExrMetadata {
    bool hasCamera = false;
    Mat4 worldToCamera, worldToNDC;  // column vectors (our convention); written transposed for Imath
    std::string software;
    double renderMs = -1;  // < 0: not written
    // Crop windows and farm tiles (docs/inputs.md): the full image the pixels belong to (the EXR display
    // window; 0: the image itself), and what `tessera assemble` checks tiles by: a hash of the scene and
    // the options that change pixels, and the tile's place in its split (count 0: not a tile).
    int displayWidth = 0, displayHeight = 0;
    std::string sceneHash;
    int tileIndex = 0, tileCount = 0;
};

struct OutputEncoding {
    float gain = 1.f, gamma = 1.f;  // RI Exposure: out = (gain * c)^(1/gamma)
    bool srgb = false;              // sRGB transfer instead (scenes without a RIB)
    const ExrMetadata* exr = nullptr;
};

// Throws std::runtime_error with a message naming the file on failure.
// The header's camera: worldToCamera, and worldToNDC with NDC x, y in [0, 1] from the top-left corner of the
// image (RenderMan's NDC) and depth 0 at the near plane, 1 at the far plane; software and time left unset.
ExrMetadata cameraExrMetadata(const Camera& cam);

void writeImage(const std::string& path, const Image& image, const OutputEncoding& enc);
void writePng(const std::string& path, const Image& image, const OutputEncoding& enc);
// RGBA as half; the planes as float channels ("z" as Z, "N" as N.X, N.Y, N.Z, "id" as a uint channel, any
// other plane under its name). PNG has no room for planes: writeImage refuses an image with planes there.
void writeExr(const std::string& path, const Image& image, const ExrMetadata* meta = nullptr);

// Readers used by the tests and the benchmark tools: PNG returns straight RGBA in [0,1];
// EXR returns the stored (premultiplied, linear) RGBA.
Image readPng(const std::string& path);
Image readExr(const std::string& path);

// What an EXR header says about the image (tests and `tessera assemble`): the display and data windows
// (inclusive corners, as OpenEXR stores them), the channels in the file's order and the tile attributes.
struct ExrInfo {
    int displayX0 = 0, displayY0 = 0, displayX1 = -1, displayY1 = -1;
    int dataX0 = 0, dataY0 = 0, dataX1 = -1, dataY1 = -1;
    std::vector<std::string> channels;  // "name:type" (type half, float, uint)
    std::string sceneHash;              // "" when the file has none
    int tileIndex = 0, tileCount = 0;
};
ExrInfo readExrInfo(const std::string& path);

// `tessera assemble`: joins the EXR tiles of one render into `output`, after checking that they belong
// together (same scene hash, display window and channels; every tile of the split present once; no
// overlap). Throws InputError naming the offending file; the output is written only when all is well.
void assembleExrTiles(const std::vector<std::string>& tiles, const std::string& output);

// Depth maps (RIB Display "zfile" / "shadow", MakeShadow; docs/inputs.md): OpenEXR with one float channel Z,
// camera-space depth (infinity where nothing was hit), row-major top row first, the standard worldToCamera
// and worldToNDC attributes of the view that made it, and "tesseraDepthMap" saying what it is: "zfile"
// (a Display's depth pass) or "shadow" (MakeShadow's output, what shadow lookups read).
struct DepthMap {
    int width = 0, height = 0;
    std::vector<float> depth;  // width * height
    Mat4 worldToCamera, worldToNDC;
    std::string kind = "zfile";
};
// Written atomically (temporary file, rename); throws std::runtime_error naming the file.
void writeDepthMap(const std::string& path, const DepthMap& map);
// Throws std::runtime_error with a message naming the file: missing or unreadable, not OpenEXR, or an
// OpenEXR that is not a depth map (no single Z channel or no camera matrices).
DepthMap readDepthMap(const std::string& path);

// True if the extension is one writeImage understands (.png, .exr).
bool isSupportedImageExtension(const std::string& path);

// "" when .exr files can be read and written, otherwise why not: OpenEXR is a module loaded on the first
// .exr (io/exr_module.h), and this loads it, so that a run that will write one can check before rendering.
std::string exrSupportError();

}  // namespace tessera
