// Reyes displacement (paper 000 sec. 3.1, paper 001 sec. 3.1; docs/textures.md, "Displacement"): every diced
// grid vertex moves along the EXACT unit normal of its patch at its (u,v) (from the patch derivatives,
// never from grid differences) by the shader's amplitude (RI bumpy: Km * texture(s, t); offset: Km).
//
// No cracks: a vertex on a patch boundary is moved identically by both patches that share the edge, bit for
// bit. Its base position is already canonical (the boundary curve's lattice point, split.h); its direction
// and amplitude are made canonical too: the unit normals and amplitudes of every displaced patch that
// shares the point (the two patches of an edge; all patches at a corner or a collapsed edge) are summed in
// patch order, each evaluated from its own patch at its own (u,v) of the point, and the direction is the
// normalised sum, the amplitude the mean. Both sides compute the same sums from the same inputs.
//
// Shading normals are those of the displaced surface (RI calculatenormal(P) after P += d N): the cross
// product of P'_u = P_u + d_u N + d N_u and P'_v, evaluated at the vertex's (u,v) exactly (d_u from the
// texture's derivatives, N_u from the patch), the limit of the grid's differences, so they agree across
// piece and patch borders (no seams).
#pragma once
#include <cstdint>
#include <span>
#include <vector>

#include "core/bezier.h"
#include "reyes/split.h"
#include "scene/scene.h"
#include "shading/texture.h"

namespace tessera {

// What displacement needs per frame, in no particular space (the patches come from the view).
struct DisplacementFrame {
    const Scene* scene = nullptr;
    const Textures* textures = nullptr;
    std::vector<int32_t> shader;  // per patch: index into Scene::displacements (-1: not displaced)
    std::vector<float> radius;    // per patch: how far its points may move (camera-space units; 0: none)
    // Points shared by displaced patches: corners (patch * 4 + corner, corners (0,0), (1,0), (0,1),
    // (1,1)) in groups (CSR, members in patch order), and each boundary edge's neighbour (patch * 4 + edge
    // of the displaced patch sharing the whole boundary curve; -1: none).
    std::vector<int32_t> cornerGroup;
    std::vector<uint32_t> groupStart, groupMembers;
    std::vector<int32_t> edgeNeighbour;
    bool any() const { return !shader.empty(); }
    bool displaced(uint32_t patch) const { return !shader.empty() && shader[patch] >= 0; }
};

// The frame's displacement data for `patches` (welded, in any one space where shared points are
// bit-identical); empty (any() false) when no patch is displaced. `cameraStretch`: the largest stretch of
// world-to-camera (bounds are stored in world units). Throws std::runtime_error for a bumpy texture that
// cannot be read.
DisplacementFrame makeDisplacementFrame(const Scene& scene, const Textures* textures,
                                        std::span<const BezierPatch> patches, float cameraStretch);

// A displaced grid vertex: its position and the displaced surface's unit normal (orientation applied).
struct DisplacedVertex {
    Vec3 P, N;
};

// Displace the vertex at `uv` of patch `patch` (of view.patches) with base position P (canonical:
// latticePosition for boundary vertices). `owner`/`k`: the piece edge that owns the vertex and its
// lattice index (nullptr: an interior vertex). `flip`: the patch's orientation flag. `normal`: false when
// only the position is needed (a shadow map's depth pass; N is then left zero).
DisplacedVertex displaceVertex(const ReyesView& view, const DisplacementFrame& frame, uint32_t patch,
                               const PieceEdge* owner, int k, Vec2 uv, Vec3 P, bool flip, bool normal = true);

// Only the shader's amplitude at `uv` of displaced patch `patch` (Km * texture, or Km), unshared: for
// the benchmarks' approximate-normal mode (ReyesView::exactDisplacementNormals false).
float displacementAmplitude(const ReyesView& view, const DisplacementFrame& frame, uint32_t patch, Vec2 uv,
                            const SurfacePoint& sp);

}  // namespace tessera
