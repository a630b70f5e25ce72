// Reyes sample stage: every micropolygon of a grid (two triangles per quad) is tested against every
// subpixel sample inside its screen bounding box, with a depth test per sample.
#pragma once
#include <cstdint>

#include "film/film.h"
#include "reyes/grid.h"

namespace tessera {

// Point-in-triangle tests use exact 64-bit integer edge functions on the fixed-point grid with the
// top-left fill rule, so a sample on an edge shared by two micropolygons belongs to exactly one of them.
// Returns the number of sample tests performed.
// On x86-64 CPUs with AVX2 the inside tests run 8 samples at a time (same samples, same results).
uint64_t rasterizeGrid(const Grid& grid, SampleTile& tile, float nearZ);
// Whether rasterizeGrid may use its AVX2 path (on by default; the tests compare both); returns whether it
// will.
bool reyesUseAvx2(bool allow);
// Whether the AVX2 paths run now (the CPU has AVX2 and reyesUseAvx2 allows it): rasterizeGrid's and the
// blurred rasterizer's candidate filters (rasterize_blur.cpp).
bool reyesAvx2Active();

// Paper 000's nearest-neighbour sampler (sec. 3.2): "only the pixel center, which is nearest to the middle
// point of a micropolygon is considered". Per micropolygon, one sample is tested (inside, then depth):
// among the samples of the pixel holding the micropolygon's middle point (the mean of its four corners),
// the one nearest that point (ties: the lower slot). At one sample per pixel with centred samples that is
// exactly the paper's pixel centre; with N samples per pixel a micropolygon still covers at most one, so
// holes stay unless micropolygons shrink to about 1/N pixel. Returns the number of samples tested.
uint64_t rasterizeGridNearest(const Grid& grid, SampleTile& tile, float nearZ);

// A shadow map's depth pass: one sample at the centre of each texel of `target`, depth only, written
// straight into the map (`depth`: texel (x, y) at depth[y * width + x]) where nearer and not nearer than
// nearZ. The same samples covered and the same depths, bit for bit, as rasterizeGrid on a tile of those
// centres, without its colour, coverage and sample arrays. Returns the number of sample tests: the texel
// centres inside each micropolygon's bound (rasterizeGrid counts every sample of the strata the bound
// overlaps).
uint64_t rasterizeGridDepth(const Grid& grid, Rect target, float* depth, int width, float nearZ);

}  // namespace tessera
