// Reyes bound / split: turns each patch into "pieces" small enough to dice into one grid.
//
// Crack prevention (DiagSplit, Fisher et al., "DiagSplit: Parallel, Crack-free, Adaptive Tessellation for
// Micropolygon Rendering", SIGGRAPH Asia 2009): every piece edge lies on an integer lattice of a *source
// edge*, either a boundary curve of the patch or a split line inside it. A source edge's segment count T is
// computed once, from that edge alone (its projected length / micropolygon size), in a canonical direction
// that both patches sharing it agree on. Splitting cuts an edge at a lattice point and hands each half its
// sub-interval, so every vertex ever placed on an edge is one of the T+1 lattice points, evaluated from the
// edge's own data. Neighbours that split or dice differently therefore always meet at identical vertices.
// Splits that cut the two opposite edges at different fractions give non-isoparametric (diagonal) pieces,
// so a piece is a quadrilateral in (u,v), evaluated through the original patch.
#pragma once
#include <algorithm>
#include <cstdint>
#include <vector>

#include "core/bezier.h"
#include "core/quadric.h"
#include "scene/camera.h"

namespace tessera {

// One edge of a piece: the sub-interval [k0,k1] of a lattice 0..total spread uniformly over the parameter
// interval [s0, s1] of a source edge (a patch boundary or a split line, from canonical endpoint a at s = 0
// to b at s = 1). An edge measured at more than the grid limit is never cut on its lattice: it is cut at
// the parametric middle of [s0, s1] and each half is measured again (DiagSplit's rule, Fisher et al.
// 2009), so a lattice adapts to where the edge is long on screen; both pieces that share an edge make the
// same cuts, since each decision depends on the edge alone.
struct PieceEdge {
    Vec2 a, b;                 // canonical endpoints of the source edge, in the patch's (u,v) domain
    float s0 = 0.f, s1 = 1.f;  // the part of the source edge this lattice spans
    int32_t total = 1;         // T: segments of the lattice over [s0, s1]
    int32_t k0 = 0, k1 = 1;
    int8_t boundary = -1;   // 0..3: source is that patch boundary curve (see patchEdge); -1: interior line
    bool reversed = false;  // the piece walks this edge from k1 down to k0
    // The source edge is one point (a sphere's pole, a collapsed patch edge): its lattice is fine
    // (kCollapsedLattice) so that splits can cut it anywhere, and it asks for no micropolygons.
    bool collapsed = false;
    // The micropolygon side its lattice is measured with (0: the piece's). A boundary shared by displaced
    // patches with different ShadingRate takes the smaller of their sides, so that both patches make the
    // same lattice (their texture may jump across the edge: different vertices would open a crack).
    float side = 0.f;
    int segments() const { return k1 - k0; }
    // Micropolygons this edge asks of a grid or a split.
    int rate() const { return collapsed ? std::min(segments(), 1) : segments(); }
    int startK() const { return reversed ? k1 : k0; }
    int endK() const { return reversed ? k0 : k1; }
    // Lattice index of the s-th vertex from the piece's start corner.
    int latticeAt(int s) const { return reversed ? k1 - s : k0 + s; }
    // Source-edge parameter of lattice point k (exactly s0 and s1 at the ends).
    float param(int k) const {
        const float w = float(k) / float(total);
        return s0 * (1.f - w) + s1 * w;
    }
};

// A diceable region of one patch: corners c00, c10, c11, c01 in (u,v) and edges
// e0: c00->c10, e1: c10->c11, e2: c01->c11, e3: c00->c01.
struct Piece {
    uint32_t patch = 0;
    Vec2 uv[4];
    PieceEdge edge[4];
    float x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // raster bound of the control hull (over the shutter and lens)
    float blurPixels = 0;                  // how far the blur spreads it (motion path + CoC diameter)
    // Segments its middle u and v isolines need: a piece whose boundary is short but whose inside is
    // long (a sphere's poles are its u edges, a teapot's lid top collapses an edge to a point) is diced
    // and split by these too, else it becomes one sliver of zero-area micropolygons.
    int32_t interiorU = 1, interiorV = 1;
};

// The grid a piece dices into: nu = max(top, bottom edge segments, middle u isoline), nv likewise (at
// least 1 each). Boundary vertices snap onto their edge's lattice, so a finer inside stays crack-free.
inline int pieceGridU(const Piece& p) {
    return std::max({p.edge[0].rate(), p.edge[2].rate(), p.interiorU, 1});
}
inline int pieceGridV(const Piece& p) {
    return std::max({p.edge[1].rate(), p.edge[3].rate(), p.interiorV, 1});
}

struct DisplacementFrame;  // reyes/displace.h

// Everything split and dice need, read-only during a render. Patches are in camera space.
struct ReyesView {
    const BezierPatch* patches = nullptr;
    // The quadric surfaces in camera space (PatchAttributes::shape indexes them; Scene::quadrics order).
    const PlacedQuadric* quadrics = nullptr;
    // Blurred frames: the patches at each knot of the shutter timeline (engine/motion.h; knot 0 is
    // `patches`), which of them move, and whether the lens blurs. Bounds then cover every knot, grown by
    // the circle of confusion, and grids carry their vertices at every knot.
    std::vector<const BezierPatch*> knotPatches;
    const std::vector<uint32_t>* moving = nullptr;  // FrameMotion::firstKey (kStatic: does not move)
    bool lens = false;
    int knotCount() const { return knotPatches.empty() ? 1 : int(knotPatches.size()); }
    bool patchMoves(uint32_t patch) const {
        return moving && !moving->empty() && (*moving)[patch] != 0xffffffffu;
    }
    Projector projector;
    float micropolygonSide = 1.f;          // sqrt(shading rate), pixels
    float cullX0, cullY0, cullX1, cullY1;  // raster window that can still reach a pixel (image + filter)
    int maxGridEdge = 16;
    // Perspective views: edge lengths are measured as if nothing were nearer than this depth (0: the near
    // plane). A shadow map's view from a point light sets it: walls that pass beside the light would
    // otherwise measure near-infinite edges (DiagSplit fixes an edge's rate from the whole edge) and be
    // diced at the rate cap where they are visible too.
    float lengthNearZ = 0.f;
    // Displaced patches (nullptr or empty: none): bounds grow by each patch's radius, dicing displaces.
    const DisplacementFrame* displacement = nullptr;
    // Per patch, the micropolygon side its split is given (splitPatches: sqrt of its shading rate); with
    // it, an edge shared by two displaced patches is measured with the smaller of their sides (PieceEdge::
    // side). nullptr: each patch measures with its own.
    const float* patchSide = nullptr;
    // Displacement-aware splitting (paper 001 sec. 3.1; 0: off): a displaced patch's edge gets at least
    // the segments that keep each one's projected displacement variation, max - min of Km * texture read
    // from the texture's min/max mip map, within this many micropolygon sides (split.cpp,
    // displacementSegments).
    float displacementSplit = 0.f;
    // false: displace along the undisplaced patch's own normal at each vertex and shade with normals from
    // the displaced grid's differences, as paper 000 does before its fix (sec. 3.1): what the exact,
    // shared normals cost is measured against it (bench/displacement_bench.sh). Shared edges can crack.
    bool exactDisplacementNormals = true;
    // false: keep every piece, off screen, behind the eye or across the eye plane too, split by its rates
    // alone (the ray tracer's displaced micro-grids, rt/displaced.h: reflections and shadows see them).
    bool cull = true;
    explicit ReyesView(const Camera& cam) : projector(cam) {}
};

// The clamp of displacement-aware splitting (paper 001 sec. 3.1: "clamping to a maximal entry"): one
// measurement of an edge halves it at most this often for its displacement (at most 2^6 segments); what is
// still larger after that is covered by the bounding-box sampler.
constexpr int kMaxDisplacementSplitDepth = 6;

struct SplitCounters {
    uint64_t splits = 0, culled = 0, pieces = 0;
    bool patchCulled = false;  // the whole patch produced no piece
};

// Boundary curve `e` of `patch` in canonical order, with its canonical (u,v) endpoints.
// Canonical: the endpoint with the lexicographically smaller position first, so two patches sharing the
// edge (in either direction) evaluate the same points.
void canonicalBoundary(const BezierPatch& patch, int e, Vec3 cp[4], Vec2& a, Vec2& b);

inline Vec2 latticeUV(const PieceEdge& e, int k) {
    const float w = e.param(k);
    // a*(1-w) + b*w is exact at both ends (w = 0, 1), so corners are bit-identical across pieces.
    return {e.a.x * (1.f - w) + e.b.x * w, e.a.y * (1.f - w) + e.b.y * w};
}

// Position of lattice point k of an edge: from the boundary curve's control points or the patch.
Vec3 latticePosition(const BezierPatch& patch, const PieceEdge& e, int k);

// A quadric's point at (u,v) in the view's space, closed form (core/quadric.h). Every vertex of a quadric
// piece, on an edge or inside, is evaluated through it, so equal (u,v) give identical points.
inline Vec3 quadricPoint(const PlacedQuadric& pq, Vec2 uv) {
    return affinePoint(pq.toSpace, evalQuadric(pq.q, uv.x, uv.y).p);
}

// The control points of a boundary edge's curve in the edge's own canonical order (the order chosen when the
// edge was made, i.e. at shutter open), for the same patch at another time: its lattice point k is then
// evalCurve(cp, k / total), identical for both patches sharing the edge even where the motion changes
// which endpoint is lexicographically first.
void orientedBoundary(const BezierPatch& patch, const PieceEdge& e, Vec3 cp[4]);

// Split and cull one surface into diceable pieces, appended to `out`: dispatches on the surface kind.
struct PatchAttributes;
void splitSurface(const ReyesView& view, const PatchAttributes& attr, uint32_t index, float micropolygonSide,
                  std::vector<Piece>& out, SplitCounters& counters);

// Split and cull one quadric (camera space) in its own (u,v) square, appended to `out`.
void splitQuadric(const ReyesView& view, const PlacedQuadric& pq, uint32_t index, float micropolygonSide,
                  std::vector<Piece>& out, SplitCounters& counters);

// Split and cull one bicubic patch into diceable pieces, appended to `out`.
void splitPatch(const ReyesView& view, uint32_t patchIndex, float micropolygonSide, std::vector<Piece>& out,
                SplitCounters& counters);

// Where a surface's pieces can lie on screen, from its root's bound (the classification splitting starts
// with): a piece's control hull lies inside its surface's (de Casteljau's control points are convex
// combinations of the parent's), so its raster bound lies inside the root's. Culled: splitting would make no
// piece; Anywhere: the root crosses the eye plane (or the view culls nothing), so it has no raster bound.
struct SurfaceReach {
    enum Kind : uint8_t { Culled, Bounded, Anywhere } kind = Culled;
    float x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // Bounded: the raster bound (over the shutter and lens)
};
SurfaceReach surfaceReach(const ReyesView& view, const PatchAttributes& attr, uint32_t index);

}  // namespace tessera
