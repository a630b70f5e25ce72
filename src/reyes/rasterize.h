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
uint64_t rasterizeGrid(const Grid& grid, SampleTile& tile, float nearZ);

}  // namespace tessera
