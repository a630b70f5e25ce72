// The film shared by both engines: sample positions (film/sampler.h), a per-bucket sample tile
// (position, depth, premultiplied colour and coverage per subpixel sample) and reconstruction of
// pixels from samples with the pixel filter.
#pragma once
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "core/buffer_allocator.h"
#include "core/random.h"
#include "core/vec.h"
#include "film/blur_pattern.h"
#include "film/filter.h"
#include "film/sampler.h"

namespace tessera {

// Per-sample attributes beyond colour, alpha and depth that a render can ask the film to carry (a bit set:
// the output spec). Adaptive supersampling reads them per sample; AOV outputs read their pixel planes.
enum FilmChannel : uint32_t {
    kChannelObjectId = 1u << 0,     // RI object (primitive call) the sample sees; kNoObject for background
    kChannelNormal = 1u << 1,       // unit shading normal, camera space, facing the viewer
    kChannelShadowCount = 1u << 2,  // number of lights in shadow at the sample's shading point
    kChannelHasTexture = 1u << 3,   // the surface the sample sees is textured
    kChannelDepth = 1u << 4,        // camera-space depth as an image plane (the tile always has it)
    // Surface AOVs (filtered like colour): the diffuse albedo denoisers take (surfaceAlbedo, shading/
    // surface.h), the camera-space position P and the surface colour Cs (times its texture).
    kChannelAlbedo = 1u << 5,
    kChannelPosition = 1u << 6,
    kChannelSurfaceColor = 1u << 7,
};
constexpr uint32_t kSurfaceAovChannels = kChannelAlbedo | kChannelPosition | kChannelSurfaceColor;
constexpr uint32_t kAllFilmChannels = kChannelObjectId | kChannelNormal | kChannelShadowCount |
                                      kChannelHasTexture | kChannelDepth | kSurfaceAovChannels;
constexpr uint32_t kNoObject = 0xffffffffu;

// A pixel plane of the image beside RGBA: filtered (normal, shadow count, AOVs) or taken from the sample
// nearest the pixel centre (object id, depth, has-texture), where averaging would invent values.
struct ImagePlane {
    std::string name;  // "id", "N", "z", "shadows", "textured", or an AOV's name
    int components = 1;
    bool integer = false;       // data in `ids` (object ids), else in `values`
    bool color = false;         // three components named R, G, B in files (else X, Y, Z)
    std::vector<float> values;  // width * height * components
    std::vector<uint32_t> ids;  // width * height
};

struct Rect {
    int x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // half-open [x0,x1) x [y0,y1)
    int width() const { return x1 - x0; }
    int height() const { return y1 - y0; }
};

// Final image: linear, premultiplied RGBA, row-major, top row first, plus the requested planes. It covers
// the raster pixels [x0, x0 + width) x [y0, y0 + height) of the camera (the whole image, a crop window or a
// farm tile); pixel() takes raster coordinates.
struct Image {
    int width = 0, height = 0;
    int x0 = 0, y0 = 0;                               // raster position of the first pixel
    std::vector<float, BufferAllocator<float>> rgba;  // huge pages for large frames (core/buffer_allocator.h)
    std::vector<ImagePlane> planes;
    Image() = default;
    Image(int w, int h) : width(w), height(h), rgba(size_t(w) * h * 4, 0.f) {}
    explicit Image(Rect r)
        : width(r.width()), height(r.height()), x0(r.x0), y0(r.y0), rgba(size_t(width) * height * 4, 0.f) {}
    size_t index(int x, int y) const { return size_t(y - y0) * width + (x - x0); }
    float* pixel(int x, int y) { return &rgba[index(x, y) * 4]; }
    const float* pixel(int x, int y) const { return &rgba[index(x, y) * 4]; }
    // Allocates the planes that `channels` and `aovNames` ask for (background values: id kNoObject,
    // depth infinity, the rest 0).
    void addPlanes(uint32_t channels, const std::vector<std::string>& aovNames = {});
    const ImagePlane* plane(const std::string& name) const;
    ImagePlane* plane(const std::string& name);
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
inline void samplePositionFixed(int px, int py, int s, int nx, int ny, uint32_t seed, int32_t& x,
                                int32_t& y) {
    // One hash per (pixel, sample): cheap enough to recompute per bucket, no tables to share.
    const uint32_t h = hash32((uint32_t(px) * 73856093u) ^ (uint32_t(py) * 19349663u) ^
                              (uint32_t(s) * 83492791u) ^ (seed * 2654435761u));
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

// Samples of a rectangle of pixels (a bucket plus the filter margin), structure of arrays.
// Sample index = (pixel row within tile * tile width + pixel column) * spp + s.
struct SampleTile {
    Rect region;
    int nx = 1, ny = 1, spp = 1;
    std::vector<int32_t> sx, sy;        // fixed-point raster positions
    std::vector<uint32_t> sampleIndex;  // per slot: its sample index for the other dimensions (sampler.h)
    // Blurred frames only (setBlur): each sample's normalised shutter time and lens point on the unit disk,
    // as the frame's BlurPattern assigns them; empty for a sharp frame.
    const BlurPattern* blur = nullptr;
    std::vector<float> time;
    std::vector<Vec2> lens;
    std::vector<float> z, r, g, b, a;
    std::vector<uint8_t> pixelHit;  // per pixel: any sample covered (lets reconstruction skip background)
    // The positions again in stratum order (row of strata, then column, over the whole tile; built by
    // buildStrataOrder once the positions are final, invalidated by reset: a copy, so positions written after
    // it is built would not reach it), padded by 8, and where the lattice's columns and rows lie: the
    // stratum (column, row) is slot row.slot + column.slot of pixel row.pixel + column.pixel. A rasterizer
    // reads a micropolygon's row of strata as contiguous memory.
    struct StrataLine {
        int32_t pixel, slot;
    };
    std::vector<int32_t> strataX, strataY;
    std::vector<StrataLine> strataColumn, strataRow;
    bool strataPositionsBuilt = false;  // (the arrays keep their memory from tile to tile)
    // While `strataWrites` (enterStrataOrder .. leaveStrataOrder): the depth, colour, alpha and coverage
    // live in stratum order, padded by 8, where a rasterizer tests and writes a micropolygon's row of 8
    // strata as vectors (the pixel-ordered arrays would scatter each hit). strataCovered: -1 where a
    // micropolygon covers the stratum's sample (pixelHit's source). Meanwhile z, r, g, b, a and pixelHit
    // are stale: leaveStrataOrder copies them back, and must run before anything else reads or writes them.
    std::vector<float> strataZ, strataR, strataG, strataB, strataA;
    std::vector<int32_t> strataCovered;
    bool strataWrites = false;
    // Set by an engine all of whose pixel-order reads and writes follow a leaveStrataOrder() call (Reyes):
    // reset then leaves z, r, g, b and a unfilled (`pixelFillPending`), and the first enterStrataOrder fills
    // the stratum-ordered arrays instead of copying the fill there, or leaveStrataOrder fills them. A tile
    // rasterized in stratum order from its first grid (the usual case) so writes its depth and colour twice
    // instead of four times. reconstruct refuses a tile whose fill is still pending.
    bool deferPixelFill = false;
    bool pixelFillPending = false;
    float farDepth = 0.f;  // the depth reset filled (or deferred)
    // Per-sample attributes, present only for the FilmChannel bits in `channels` (empty otherwise).
    uint32_t channels = 0;
    std::vector<uint32_t> objectId;
    std::vector<float> normalX, normalY, normalZ;  // shading normal
    std::vector<uint8_t> shadowCount, hasTexture;
    std::vector<Vec3> albedo, position, surfaceColor;  // the surface AOVs (kSurfaceAovChannels)
    std::vector<std::string> aovNames;                 // further channels a display asked for,
    std::vector<std::vector<float>> aovValues;         // one float per sample each

    // (Re)initialise for a region without reallocating when the size fits. Slot s of every pixel lies in
    // stratum (s % nx, s / nx) with either sampler; a pixel's positions depend only on (pixel, seed).
    // Dimension d of slot i: sampleDimension(pixelSeed(px, py, seed), sampleIndex[i], d). `channels`
    // (FilmChannel bits) and `aovNames`: the attribute channels to carry.
    void reset(Rect region, int nx, int ny, uint32_t seed, float farZ, SamplerKind sampler,
               uint32_t channels = 0, const std::vector<std::string>& aovNames = {});
    // After reset: give the samples their times and lens points (nullptr or an inactive pattern: none).
    void setBlur(const BlurPattern* pattern);
    size_t sampleCount() const { return sx.size(); }
    // Fills strataX, strataY, strataColumn and strataRow for the current samples.
    void buildStrataOrder();
    bool hasStrataOrder() const { return strataPositionsBuilt; }
    // Moves the depth, colour and alpha into stratum order (building the positions' order if needed), with
    // no stratum covered yet; and back, marking pixelHit where a stratum was covered. No-ops when already
    // in the asked order, except that leaveStrataOrder does a pending fill (deferPixelFill).
    void enterStrataOrder();
    void leaveStrataOrder();
    bool has(uint32_t channel) const { return (channels & channel) != 0; }
    // Writes the attributes of a covered sample (colour, alpha and depth are written by the engine).
    void setAttributes(size_t i, uint32_t object, Vec3 normal, int shadowedLights, bool textured) {
        if (has(kChannelObjectId)) objectId[i] = object;
        if (has(kChannelNormal)) normalX[i] = normal.x, normalY[i] = normal.y, normalZ[i] = normal.z;
        if (has(kChannelShadowCount)) shadowCount[i] = uint8_t(std::min(shadowedLights, 255));
        if (has(kChannelHasTexture)) hasTexture[i] = textured;
    }
    bool wantsSurfaceAovs() const { return (channels & kSurfaceAovChannels) != 0; }
    // The surface AOVs of a covered sample.
    void setSurfaceAovs(size_t i, Vec3 diffuseAlbedo, Vec3 P, Vec3 Cs) {
        if (has(kChannelAlbedo)) albedo[i] = diffuseAlbedo;
        if (has(kChannelPosition)) position[i] = P;
        if (has(kChannelSurfaceColor)) surfaceColor[i] = Cs;
    }
};

// Filter the tile's samples into the pixels of `out` inside `target` (which must lie inside the tile's
// region shrunk by the filter radius, or touch the image border), and fill the image's planes.
// The colour and coverage are summed in eight lanes (AVX2 where the CPU has it, else the same sums one by
// one: the same bits either way).
void reconstruct(const SampleTile& tile, const PixelFilter& filter, Rect target, Image& out);
// Whether the film's AVX2 paths (reconstruct, BlurPattern::pixelSamplesAt) may run (on by default; the tests
// compare both); returns whether they will.
bool filmUseAvx2(bool allow);
bool filmAvx2Active();

// Index of the sample of pixel (px, py) of the tile nearest the pixel centre (ties: the lower index).
size_t nearestSampleToCentre(const SampleTile& tile, int px, int py);

}  // namespace tessera
