// Reyes dice + shade: a piece becomes a grid of (nu+1) x (nv+1) shaded vertices in raster space.
#pragma once
#include <algorithm>
#include <cstdint>
#include <span>
#include <vector>

#include "engine/visibility.h"
#include "film/film.h"
#include "reyes/split.h"
#include "shading/surface.h"
#include "shading/texture.h"

namespace tessera {

// Raster coordinate to the rasterizer's fixed point, clamped so that edge functions cannot overflow 64 bits;
// rounds half away from zero (as lround, without the library call: it runs per vertex and per blurred
// sample; f +- 0.5 is exact in double, and the conversion truncates).
inline int32_t rasterToFixed(float v) {
    constexpr float kLimit = float(1 << 20) * kSubpixelScale;
    const float f = std::clamp(v * kSubpixelScale, -kLimit, kLimit);
    const double d = f;
    return int32_t(d + (d >= 0 ? 0.5 : -0.5));
}

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
    bool textured = false;  // its surface has a texture (the film's has-texture channel)
    std::vector<float> NX, NY, NZ;
    // When the film carries the surface AOVs: per vertex, the albedo, camera-space P and Cs (times the
    // texture) (empty otherwise).
    std::vector<Vec3> albedo, P, Cs;
    // When the film counts lights in shadow and lights cast shadows: per vertex, the lights more than half
    // blocked (empty: none).
    std::vector<uint8_t> shadowedLights;
    // Blurred frames (`blurred`: the rasterizer must move micropolygons to each sample's time and lens
    // point): per knot of the shutter timeline and vertex (knot-major, knots * vertexCount()), the raster
    // position, the depth, and the lens coefficient c = lensRadius * (1/focaldistance - 1/z), so that a lens
    // point a shifts the vertex by a * c * (sx, sy) pixels (Projector::lensShift). Between knots a vertex
    // moves linearly in raster space (the paper's screen-space motion vectors). `knotValid`: in front of
    // the near plane. Shading is done once, at shutter open.
    int knots = 1;
    std::vector<float> knotX, knotY, knotZ, knotC;
    std::vector<uint8_t> knotValid;
    float motionPixels = 0.f;   // largest raster path of a vertex over the shutter (L1 per segment, summed)
    bool allKnotsValid = true;  // every vertex in front of the near plane at every knot
    bool blurred = false;
    int vertexCount() const { return (nu + 1) * (nv + 1); }

    // Back to a default grid that keeps its arrays' storage, so that dicing into a recycled grid
    // (LazyPieces' spare grids) allocates nothing: every array empty, every other field its default.
    void clearKeepingStorage() {
        Grid fresh;
        forEachArray([&](auto& mine, auto Grid::*member) {
            mine.clear();
            (fresh.*member).swap(mine);
        });
        *this = std::move(fresh);
    }

    // Calls f(array, pointer to member) for every array member; a member added to Grid must be added here
    // too (the static_assert after the struct counts the bytes).
    template <class F>
    void forEachArray(F&& f) {
        f(X, &Grid::X), f(Y, &Grid::Y), f(Z, &Grid::Z), f(R, &Grid::R), f(G, &Grid::G), f(B, &Grid::B);
        f(front, &Grid::front), f(NX, &Grid::NX), f(NY, &Grid::NY), f(NZ, &Grid::NZ);
        f(albedo, &Grid::albedo), f(P, &Grid::P), f(Cs, &Grid::Cs), f(shadowedLights, &Grid::shadowedLights);
        f(knotX, &Grid::knotX), f(knotY, &Grid::knotY), f(knotZ, &Grid::knotZ), f(knotC, &Grid::knotC);
        f(knotValid, &Grid::knotValid);
    }
};
// 19 arrays and the scalars: a new member changes the size; add it to forEachArray, then update this.
static_assert(sizeof(Grid) == 19 * sizeof(std::vector<float>) + 40, "Grid changed: update forEachArray");

struct ShadeInputs {
    SurfaceKind kind;
    const Material* material;
    bool twoSided;
    bool flipNormal;
    std::span<const ShadingLight> lights;  // camera space
    uint32_t objectId = 0;
    bool wantNormals = false;  // the film carries a normal channel
    // Who answers the visibility queries of lights that cast shadows (shadow maps or shadow rays); nullptr:
    // every query answers "visible".
    const LightVisibility* visibility = nullptr;
    // A shadow map's depth pass (paper 001 sec. 3.5: "only split, dice and sample"): positions and depth,
    // both sides, no normals or shading. Static patches only (the pass renders shutter open).
    bool depthOnly = false;
    bool wantShadowCounts = false;  // the film carries the shadow-count channel
    // Quadric kinds: the quadric in camera space (ReyesView::quadrics[shape]); its closed form gives every
    // vertex's position and normal. Quadrics do not move (the reader takes them at shutter open).
    const PlacedQuadric* quadric = nullptr;
    bool wantSurfaceAovs = false;  // the film carries albedo, P or Cs (set by name, after the above)
    // The frame's textures (nullptr: the scene has none), the patch's s, t, and how many raster pixels a
    // texture lookup's footprint spans (the micropolygon side when it is wider than a pixel).
    const Textures* textures = nullptr;
    PatchTexCoords texCoords{};
    float textureScale = 1.f;
    // The patch's per-vertex normals (camera space) and colours (nullptr: none): the shading normal and the
    // colour that multiplies the texture colour, interpolated at each vertex's (u,v).
    const PatchVertexValues* vertexValues = nullptr;
    // Part of an area light (RI AreaLightSource): the radiance its front side emits, added to what the
    // surface reflects. Reyes shows it but does not light with it (area lights are ray traced).
    Color emission{0, 0, 0};
};

// Dice `piece` into a grid with about one micropolygon per shading-rate area and shade every vertex.
// Grid interior rates: nu = max(e0, e2) and nv = max(e1, e3) segments; boundary vertices are snapped to
// their edge's own lattice points (stitching), so shared edges are identical on both sides.
void diceAndShade(const ReyesView& view, const Piece& piece, const ShadeInputs& shade, Grid& grid);

// The vertices `piece` dices into, without shading (the same lattice, snapping and displacement as
// diceAndShade, bicubic patches only): per vertex of the (nu+1) x (nv+1) grid (row-major, u fastest) the
// position, the unit normal (orientation applied; the displaced surface's when displaced) and the (u,v)
// on the patch. The ray tracer's micro-grids of displaced patches (rt/displaced.h). `uvOnly`: the (u,v) only
// (P and N untouched).
void dicePieceVertices(const ReyesView& view, const Piece& piece, bool flipNormal, int& nu, int& nv,
                       std::vector<Vec3>& P, std::vector<Vec3>& N, std::vector<Vec2>& UV,
                       bool uvOnly = false);

}  // namespace tessera
