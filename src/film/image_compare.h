// Image comparison metrics used by the cross-engine tests and the benchmark suite.
#pragma once
#include "film/film.h"

namespace tessera {

struct ImageDiff {
    double psnrColor = 0;            // dB over premultiplied RGB clamped to [0,1]; inf if identical
    double alphaMismatch = 0;        // fraction of pixels whose coverage differs by more than the threshold
    double meanAbsAlpha = 0;         // mean |alpha_a - alpha_b|
    double maxAbsColor = 0;          // largest per-channel difference
};

// Both images must have the same size (throws std::invalid_argument otherwise).
ImageDiff compareImages(const Image& a, const Image& b, float alphaThreshold = 0.5f);

}  // namespace tessera
