// Image files: PNG (8-bit RGBA, straight alpha) and OpenEXR (half RGBA, linear, premultiplied).
// Files are written to a temporary name beside the target and renamed when complete, so a failed
// render never leaves a partial file and never clobbers a good one.
#pragma once
#include <string>

#include "film/film.h"

namespace tessera {

struct OutputEncoding {
    float gain = 1.f, gamma = 1.f;  // RI Exposure: out = (gain * c)^(1/gamma)
    bool srgb = false;              // sRGB transfer instead (scenes without a RIB)
};

// Throws std::runtime_error with a message naming the file on failure.
void writeImage(const std::string& path, const Image& image, const OutputEncoding& enc);
void writePng(const std::string& path, const Image& image, const OutputEncoding& enc);
void writeExr(const std::string& path, const Image& image);

// Readers used by the tests and the benchmark tools: PNG returns straight RGBA in [0,1];
// EXR returns the stored (premultiplied, linear) RGBA.
Image readPng(const std::string& path);
Image readExr(const std::string& path);

// True if the extension is one writeImage understands (.png, .exr).
bool isSupportedImageExtension(const std::string& path);

}  // namespace tessera
