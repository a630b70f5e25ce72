// Reyes dice + shade: a piece becomes a grid of (nu+1) x (nv+1) shaded vertices in raster space.
#pragma once
#include <cstdint>
#include <span>
#include <vector>

#include "film/film.h"
#include "reyes/split.h"
#include "shading/surface.h"

namespace tessera {

// Shaded grid, structure of arrays. Raster positions are fixed point (see film.h).
struct Grid {
    int nu = 0, nv = 0;
    bool twoSided = true;
    std::vector<int32_t> X, Y;
    std::vector<float> Z, R, G, B;
    std::vector<uint8_t> front;  // vertex faces the camera (for one-sided surfaces)
    // For the film's attribute channels: the object, and (when the film wants normals) the unit shading
    // normal per vertex, facing the viewer.
    uint32_t objectId = 0;
    std::vector<float> NX, NY, NZ;
    int vertexCount() const { return (nu + 1) * (nv + 1); }
};

struct ShadeInputs {
    SurfaceKind kind;
    const Material* material;
    bool twoSided;
    bool flipNormal;
    std::span<const ShadingLight> lights;  // camera space
    uint32_t objectId = 0;
    bool wantNormals = false;  // the film carries a normal channel
};

// Dice `piece` into a grid with about one micropolygon per shading-rate area and shade every vertex.
// Grid interior rates: nu = max(e0, e2) and nv = max(e1, e3) segments; boundary vertices are snapped to
// their edge's own lattice points (stitching), so shared edges are identical on both sides.
void diceAndShade(const ReyesView& view, const Piece& piece, const ShadeInputs& shade, Grid& grid);

}  // namespace tessera
