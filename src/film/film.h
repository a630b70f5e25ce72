// The film shared by both engines: sample positions (film/sampler.h), a per-bucket sample tile
// (position, depth, premultiplied colour and coverage per subpixel sample) and reconstruction of
// pixels from samples with the pixel filter.
#pragma once
#include <cstdint>
#include <vector>

#include "core/random.h"
#include "core/vec.h"
#include "film/filter.h"
#include "film/sampler.h"

namespace tessera {

// Final image: linear, premultiplied RGBA, row-major, top row first.
struct Image {
    int width = 0, height = 0;
    std::vector<float> rgba;
    Image() = default;
    Image(int w, int h) : width(w), height(h), rgba(size_t(w) * h * 4, 0.f) {}
    float* pixel(int x, int y) { return &rgba[(size_t(y) * width + x) * 4]; }
    const float* pixel(int x, int y) const { return &rgba[(size_t(y) * width + x) * 4]; }
};

// Sub-pixel fixed point used by the rasterizer: positions snap to 1/256 pixel so that edge functions are
// exact integers and shared micropolygon edges never leave gaps (the GPU rasterization convention).
constexpr int kSubpixelBits = 8;
constexpr float kSubpixelScale = float(1 << kSubpixelBits);
static_assert(kSubpixelBits == 8, "filmSamplesFixed (sampler.h) writes 1/256-pixel offsets");

// SamplerKind::Jittered (the original pattern): stratified jittered sample s (0 .. nx*ny-1) of pixel
// (px,py): stratum (s % nx, s / nx) of the pixel, jittered by a hash of (pixel, sample, seed). Positions
// lie on the 1/256-pixel fixed-point lattice that the rasterizer uses, so both engines see exactly the
// same sample positions.
inline void samplePositionFixed(int px, int py, int s, int nx, int ny, uint32_t seed, int32_t& x, int32_t& y) {
    // One hash per (pixel, sample): cheap enough to recompute per bucket, no tables to share.
    const uint32_t h = hash32((uint32_t(px) * 73856093u) ^ (uint32_t(py) * 19349663u) ^ (uint32_t(s) * 83492791u) ^
                              (seed * 2654435761u));
    const int32_t jx = int32_t(h & 0xff), jy = int32_t((h >> 8) & 0xff);
    x = (px << kSubpixelBits) + ((s % nx) * 256 + jx) / nx;
    y = (py << kSubpixelBits) + ((s / nx) * 256 + jy) / ny;
}
inline Vec2 samplePosition(int px, int py, int s, int nx, int ny, uint32_t seed) {
    int32_t x, y;
    samplePositionFixed(px, py, s, nx, ny, seed, x, y);
    return {float(x) / kSubpixelScale, float(y) / kSubpixelScale};
}

// Split N samples per pixel into an nx x ny stratified pattern, as square as N allows (16 -> 4x4,
// 8 -> 2x4, a prime -> 1xN).
inline void splitSamplesPerPixel(int n, int& nx, int& ny) {
    nx = 1;
    for (int d = 1; d * d <= n; ++d)
        if (n % d == 0) nx = d;
    ny = n / nx;
}

struct Rect {
    int x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // half-open [x0,x1) x [y0,y1)
    int width() const { return x1 - x0; }
    int height() const { return y1 - y0; }
};

// Samples of a rectangle of pixels (a bucket plus the filter margin), structure of arrays.
// Sample index = (pixel row within tile * tile width + pixel column) * spp + s.
struct SampleTile {
    Rect region;
    int nx = 1, ny = 1, spp = 1;
    std::vector<int32_t> sx, sy;        // fixed-point raster positions
    std::vector<uint32_t> sampleIndex;  // per slot: its sample index for the other dimensions (sampler.h)
    std::vector<float> z, r, g, b, a;
    std::vector<uint8_t> pixelHit;  // per pixel: any sample covered (lets reconstruction skip background)

    // (Re)initialise for a region without reallocating when the size fits. Slot s of every pixel lies in
    // stratum (s % nx, s / nx) with either sampler; a pixel's positions depend only on (pixel, seed).
    // Dimension d of slot i: sampleDimension(pixelSeed(px, py, seed), sampleIndex[i], d).
    void reset(Rect region, int nx, int ny, uint32_t seed, float farZ, SamplerKind sampler);
    size_t sampleCount() const { return sx.size(); }
};

// Filter the tile's samples into the pixels of `out` inside `target` (which must lie inside the tile's
// region shrunk by the filter radius, or touch the image border).
void reconstruct(const SampleTile& tile, const PixelFilter& filter, Rect target, Image& out);

}  // namespace tessera
