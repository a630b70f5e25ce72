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
//    far fewer tests.
#pragma once
#include <cstdint>
#include <vector>

#include "film/film.h"
#include "reyes/grid.h"
#include "scene/camera.h"

namespace tessera {

// The samples of a tile grouped by (time stratum, lens cell), per pixel (for the bbox scheme's strata).
struct BlurStrata {
    int timeStrata = 1, lensCells = 1;  // time strata x lensCells x lensCells cells
    std::vector<uint32_t> start;        // per pixel and cell: first entry in `slot` (CSR, one extra end)
    std::vector<uint16_t> slot;
    int cells() const { return timeStrata * lensCells * lensCells; }
    // Choose the strata for a pattern: time only (4 spp fine strata, which each micropolygon groups by its
    // motion), lens only (about sqrt(spp) cells per axis), or both (spp time strata, 2 x 2 lens cells).
    void configure(const BlurPattern& pattern);
    void build(const SampleTile& tile);
};

struct BlurRasterContext {
    const Projector* projector = nullptr;
    const BlurPattern* pattern = nullptr;
    const std::vector<float>* knots = nullptr;  // normalised knot times (FrameMotion::knots)
    bool strataBounds = true;
};

// Rasterize a blurred grid (Grid::blurred). `strata` must be built for the tile when the scheme is bbox
// with strata bounds. Returns the number of sample tests.
uint64_t rasterizeBlurredGrid(const Grid& grid, SampleTile& tile, float nearZ, const BlurRasterContext& ctx,
                              const BlurStrata& strata);

}  // namespace tessera
