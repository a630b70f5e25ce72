// Reyes sampling of blurred grids (motion blur and depth of field; paper 000, sec. 3.3, docs/motion.md):
// a micropolygon is tested against each film sample at that sample's time and lens point, i.e. its four
// corners are moved to the sample's time (linearly between the knots of the shutter timeline, in camera
// space, then projected) and shifted by the sample's lens point times their circle of confusion, and
// the sample is tested against the moved micropolygon with the exact integer edge functions and the
// depth of the moved corners. The three schemes differ in which samples a micropolygon visits:
//  - simple: once per slot index i, moved to (t_i, lens_i), against slot i of the pixels its bound covers;
//  - interleaved: once per tile sample n (N = spp K^2), moved to (t_n, lens_n), against the one sample per
//    K x K tile that the tile's permutation gives n;
//  - bbox: one bound over the whole shutter and lens (every corner at every knot, grown by its circle of
//    confusion), against every sample in it. With strata bounds on, the bound is cut per time stratum and
//    lens cell, and each piece meets only the samples whose (t, lens) lie in its stratum: the same hits,
//    far fewer tests; the candidates are checked four at a time against the bound at their own (t, lens).
//    With strata bounds on, the interleaved scheme's samples take this path too (the same hits as its
//    passes, at a fraction of their cost).
#pragma once
#include <cstdint>
#include <vector>

#include "film/film.h"
#include "reyes/grid.h"
#include "scene/camera.h"

namespace tessera {

// The samples of a tile sorted for the bbox scheme's strata bounds: by pixel row, then by cell (time
// stratum, lens cell), then by column, so that the samples of one row and cell under a bound's column
// range are one contiguous run. Each entry carries what the bound test at the sample's own (t, lens)
// reads (position, time, lens point), so a run is read in order with no indirection.
struct BlurStrata {
    int timeStrata = 1, lensCells = 1;  // time strata x lensCells x lensCells cells
    int x0 = 0, y0 = 0, cols = 0;       // the tile region's corner and width
    // Per (row, cell): cols + 1 entry indices; the samples of the row and cell in columns [a, b] are the
    // entries [start[base + a], start[base + b + 1]), base = (row * cells() + cell) * (cols + 1).
    std::vector<uint32_t> start;
    // Structure of arrays, padded with kRunPadding entries past the last so that the candidate filters
    // can read four (SSE2) or eight (AVX2) at a time past a run's end (the lanes past it are masked off).
    static constexpr size_t kRunPadding = 8;
    std::vector<float> fx, fy, time;  // raster position in pixels, normalised shutter time
    std::vector<float> lensX, lensY;  // lens point
    std::vector<uint32_t> sample;     // index in the tile
    // Per time stratum, the segment of the frame's knot timeline that holds it whole (-1: it straddles a
    // knot), so that a run of one stratum is bounded by one linear motion (the vector filter).
    std::vector<int> stratumSegment;
    std::vector<float> segmentInvDt;  // per segment k, 1 / (knots[k + 1] - knots[k])
    int cells() const { return timeStrata * lensCells * lensCells; }
    size_t runBase(int py, int cell) const {
        return (size_t(py - y0) * cells() + size_t(cell)) * size_t(cols + 1);
    }
    // Choose the strata for a pattern: spp time strata with motion (at most 256), 2 x 2 lens cells with a
    // lens. `knots`: the frame's timeline (FrameMotion::knots).
    void configure(const BlurPattern& pattern, const std::vector<float>& knots);
    void build(const SampleTile& tile);
};

struct BlurRasterContext {
    const Projector* projector = nullptr;
    const BlurPattern* pattern = nullptr;
    const std::vector<float>* knots = nullptr;  // normalised knot times (FrameMotion::knots)
    bool strataBounds = true;
};

// Whether a blurred frame samples through BlurStrata (built per tile) and the bbox rasterizer: the bbox
// scheme, and the interleaved one (its samples each at their own time and lens point: the same hits as
// its per-pass form, which strata bounds off keep), when strata bounds are on.
inline bool blurUsesStrata(BlurSampling scheme, bool strataBounds) {
    return strataBounds && scheme != BlurSampling::Simple;
}

// Rasterize a blurred grid (Grid::blurred). `strata` must be built for the tile when the scheme is bbox
// with strata bounds. Returns the number of sample tests.
uint64_t rasterizeBlurredGrid(const Grid& grid, SampleTile& tile, float nearZ, const BlurRasterContext& ctx,
                              const BlurStrata& strata);

}  // namespace tessera
