// Bottom level of the ray tracer's two-level hierarchy: under every patch a complete binary tree of
// subpatch bounding boxes made by alternating u/v de Casteljau splits at 1/2 (level k splits u when k is
// even, v when k is odd). Only the boxes are kept, with implicit indexing: node i has children 2i+1 (low
// half) and 2i+2 (high half); leaves are nodes 2^D-1 .. 2^(D+1)-2.
// A leaf that a ray hits gives Newton's initial guess: the centre of the leaf's (u,v) rectangle.
#pragma once
#include <algorithm>
#include <bit>
#include <cstdint>
#include <memory>
#include <span>
#include <type_traits>
#include <utility>
#include <vector>

#include "core/bezier.h"
#include "core/buffer_allocator.h"
#include "core/quadric.h"
#include "engine/motion.h"

namespace tessera {

// Deepest subpatch tree (buildSubpatchForest clamps to it).
constexpr int kMaxSubpatchDepth = 12;

// The four grandchildren 4i+3 .. 4i+6 of a node i at an even level, structure of arrays, for one 4-wide
// slab test (the traversal goes two levels per step; the odd levels are only needed for the backface bits).
// Quantized to 8 bits in a frame (its node's box), as Embree's compressed nodes (Benthin et al. 2018),
// but counted from both ends: on axis a, grandchild c spans [frameLo[a] + lo[a][c] * step(a),
// frameHi[a] - hi[a][c] * step(a)], step = (frameHi - frameLo) / 255, rounded outward when stored
// (quantizeQuad) so that the decoded box holds the exact one whether the decode fuses the multiply-add or
// not. Both ends of the frame decode exactly, so a decoded box lies inside its parent's (the binning stages
// rely on it to find the traversal's candidates) and holds its own: 48 bytes instead of 96 of floats (the
// quads are 98% of the forest: Big Guy 47 of 48 MB).
struct alignas(16) SubpatchQuad {
    float frameLo[3], frameHi[3];
    uint8_t lo[3][4], hi[3][4];  // [axis][grandchild]: steps up from frameLo, down from frameHi
    float step(int a) const { return (frameHi[a] - frameLo[a]) * (1.f / 255.f); }
    float decodeLo(int a, uint8_t v) const { return frameLo[a] + float(v) * step(a); }
    float decodeHi(int a, uint8_t v) const { return frameHi[a] - float(v) * step(a); }
    Bounds3 box(int c) const {
        Bounds3 b;
        for (int a = 0; a < 3; ++a) b.lo[a] = decodeLo(a, lo[a][c]), b.hi[a] = decodeHi(a, hi[a][c]);
        return b;
    }
};
static_assert(sizeof(SubpatchQuad) == 48);

// Stores the four boxes b[0..3] in q (see SubpatchQuad) in the frame `frame` (their parent's box, grown
// to hold them if they stick out): each decoded box holds its box.
void quantizeQuad(const Bounds3* b, const Bounds3& frame, SubpatchQuad& q);

// Bernstein change of basis from a patch to one leaf sub-patch: leaf coefficient (row j, column i) =
// sum over (j', i') of mv[j][j'] * patch(j', i') * mu[i'][i] (so the rows of `mu` are 4-vectors over the
// leaf's u index). Shared by all patches; used for the ray-frame hull test before Newton.
struct alignas(16) LeafBasis {
    float mu[4][4];          // mu[i'][i]: weight of patch column i' in leaf column i
    float mv[4][4];          // mv[j][j']: weight of patch row j' in leaf row j
    float mvSplat[4][4][4];  // mv[j][j'] in all four lanes (the SSE test multiplies whole rows by it)
};

// The slabs of four consecutive leaves of a tree (leaves 4g .. 4g + 3: one leaf-level quad's grandchildren),
// structure of arrays. Lane i: every point P of leaf 4g + i has lo[i] <= n.P <= hi[i], n = (n[0][i],
// n[1][i], n[2][i]) a unit vector near the leaf's normal (from its control net), the bounds its control
// points' (convex hull property) grown by the boxes' rounding margin, four Newton tolerances of the patch
// (newtonTolerance: a root Newton accepts lies that close to the surface) and 6% of the leaf box's diagonal
// (kSlabGrowth in subpatch_tree.cpp: Newton needs the starts of leaves a ray passes that near, at shared
// edges and on grazing rays). A nearly flat leaf's slab is thin:
// a ray that crosses the leaf's box but not the slab while inside it (past a silhouette, or over the surface
// at a box's corner) cannot meet the leaf, and the candidate stages drop it (slabKeep4, rt/simd_kernels.h).
// An open lane (n = 0, lo = -inf, hi = +inf) keeps every ray: moving, displaced and quadric surfaces, and the
// padding of trees with fewer than four leaves.
struct alignas(16) LeafSlab4 {
    float n[3][4];
    float lo[4], hi[4];
};

// A tree's boxes are stored once: levels 2, 4, ... in its quads (what the wavefront traversal tests), the
// root per tree, and for an odd depth the leaves (the level below the last quads). An odd inner level is
// not stored: every inner box is the union of its children's, so nodeBox makes it from the two in the
// quad below. (All 2^(depth+1) - 1 boxes beside the quads were 3 of 5 KB per patch at depth 6.)
struct SubpatchForest {
    int depth = 6;
    uint32_t nodesPerPatch = 127;  // 2^(depth+1) - 1: the node numbering (`backfacing` has one per node)
    std::vector<Bounds3> roots;    // per tree, its root box (enlarged, as every box)
    std::vector<Bounds3, DefaultInitAllocator<Bounds3>> oddLeaves;  // odd depth: per tree, its 2^depth leaves
    std::vector<uint8_t> backfacing;   // optional, one per node: every point faces away from the eye at 0
    std::vector<Vec2> leafCentre;      // per leaf (shared by all patches): centre of its (u,v) rectangle
    std::vector<LeafBasis> leafBasis;  // per leaf (shared by all patches)
    // Per tree, slabGroupsPerTree() groups of its leaves' slabs (LeafSlab4); empty: none (every ray kept).
    std::vector<LeafSlab4, DefaultInitAllocator<LeafSlab4>> leafSlabs;
    // Per leaf, its four quarters (index 4 * leaf + q; q bit 0: high u half, bit 1: high v half).
    std::vector<LeafBasis> quarterBasis;
    // Per patch, quadsPerPatch = (4^floor(depth/2) - 1) / 3 grandchild groups: node i at level 2k has
    // group (4^k - 1) / 3 + i - (4^k - 1): the boxes of levels 2, 4, ..., four per 4-wide test.
    std::vector<SubpatchQuad, DefaultInitAllocator<SubpatchQuad>> quads;
    uint32_t quadsPerPatch = 21;
    // With `backfacing`, per quad: bit i set when grandchild i or its parent (the odd level in between)
    // is backfacing, i.e. the traversal's cull test of the four grandchildren as one 4-bit mask.
    std::vector<uint8_t> quadBack;
    // Motion blur: per moving patch, its leaf boxes at every knot of the timeline (the tree holds their
    // unions), at [(FrameMotion::firstKey[patch] + knot) * leaves + leaf]. Control points move linearly
    // between knots, so the lerp of a leaf's boxes at the two knots around a time holds the leaf then
    // (min of lerps >= lerp of mins): the Newton stage tests it per candidate (knotLeafBox).
    std::vector<Bounds3> knotLeaves;
    // Motion blur, time slabs (a temporal split of the swept bounds, as the MSBVH of Gruenschloss et al.
    // 2011): the timeline's segments grouped into `slabCount` runs of knots; per moving patch and slab, its
    // quads bound it over that slab's knots only, so a ray at a time of the slab tests boxes swept over a
    // fraction of the shutter. `slabOfSegment[k]`: the slab of timeline segment k; slab s spans knots
    // slabKnots[s] .. slabKnots[s + 1]. Moving patch i's quads for slab s start at
    // slabQuads[(slabPatch[i] * slabCount + s) * quadsPerPatch], its root box at slabRoots[slabPatch[i] *
    // slabCount + s]. slabCount 0: no slabs (a static frame), quadTree(patch, slab) = quadTree(patch).
    int slabCount = 0;
    std::vector<uint8_t> slabOfSegment;
    std::vector<uint32_t> slabKnots;
    std::vector<uint32_t> slabPatch;  // per patch: its index among the moving patches, or kNoSlabs
    std::vector<SubpatchQuad, DefaultInitAllocator<SubpatchQuad>> slabQuads;
    std::vector<Bounds3> slabRoots;
    static constexpr uint32_t kNoSlabs = 0xffffffffu;

    size_t treeCount() const { return roots.size(); }
    // The box of node `node` of tree `patch` (see above: an odd inner level is its children's union).
    Bounds3 nodeBox(uint32_t patch, uint32_t node) const {
        if (node == 0) return roots[patch];
        const int level = int(std::bit_width(node + 1u)) - 1;
        if (level == depth && (depth & 1)) return oddLeaves[(size_t(patch) << depth) + (node - firstLeaf())];
        // An even level 2k >= 2: lane (e - 3) % 4 of its grandparent g's quad, g - 2 (4^(k-1) - 1) / 3.
        // An odd inner level: the union of lanes c, c + 1 there for its first child e = 2 node + 1.
        const bool odd = level & 1;
        const uint32_t e = odd ? 2 * node + 1 : node, g = (e - 3) >> 2, lane = (e - 3) & 3;
        const int gLevel = odd ? level - 1 : level - 2;
        const SubpatchQuad& q = quads[size_t(patch) * quadsPerPatch + g - 2 * ((1u << gLevel) - 1u) / 3];
        Bounds3 b;
        for (int a = 0; a < 3; ++a) {
            b.lo[a] = q.decodeLo(a, odd ? std::min(q.lo[a][lane], q.lo[a][lane + 1]) : q.lo[a][lane]);
            b.hi[a] = q.decodeHi(a, odd ? std::min(q.hi[a][lane], q.hi[a][lane + 1]) : q.hi[a][lane]);
        }
        return b;
    }
    uint32_t slabGroupsPerTree() const { return depth >= 2 ? 1u << (depth - 2) : 1u; }
    // The slab groups of tree `tree` (null when the forest has none); leaf l is lane l & 3 of group l >> 2.
    const LeafSlab4* slabGroups(uint32_t tree) const {
        return leafSlabs.empty() ? nullptr : leafSlabs.data() + size_t(tree) * slabGroupsPerTree();
    }
    const uint8_t* backfaceBits(uint32_t patch) const {
        return backfacing.empty() ? nullptr : backfacing.data() + size_t(patch) * nodesPerPatch;
    }
    uint32_t firstLeaf() const { return (1u << depth) - 1; }
    const SubpatchQuad* quadTree(uint32_t patch) const {
        return quads.data() + size_t(patch) * quadsPerPatch;
    }
    // The quads that bound `patch` over time slab `slab` (its swept quads when it does not move).
    const SubpatchQuad* quadTree(uint32_t patch, int slab) const {
        if (slabCount == 0 || slabPatch[patch] == kNoSlabs) return quadTree(patch);
        return slabQuads.data() + (size_t(slabPatch[patch]) * slabCount + slab) * quadsPerPatch;
    }
    // The root box of `patch` over time slab `slab`.
    const Bounds3& rootBox(uint32_t patch, int slab) const {
        if (slabCount == 0 || slabPatch[patch] == kNoSlabs) return roots[patch];
        return slabRoots[size_t(slabPatch[patch]) * slabCount + slab];
    }
    const uint8_t* quadBackBits(uint32_t patch) const {
        return quadBack.empty() ? nullptr : quadBack.data() + size_t(patch) * quadsPerPatch;
    }
    size_t memoryBytes() const {
        return (roots.size() + oddLeaves.size()) * sizeof(Bounds3) + backfacing.size() +
               leafCentre.size() * sizeof(Vec2) + quads.size() * sizeof(SubpatchQuad) + quadBack.size() +
               leafSlabs.size() * sizeof(LeafSlab4) +
               (leafBasis.size() + quarterBasis.size()) * sizeof(LeafBasis) +
               knotLeaves.size() * sizeof(Bounds3) + slabQuads.size() * sizeof(SubpatchQuad) +
               slabRoots.size() * sizeof(Bounds3) + slabPatch.size() * sizeof(uint32_t);
    }
};

// The box holding leaf `leaf` of a moving patch at weight w of timeline segment k (its keys start at
// `firstKey`): the lerp of the leaf's boxes at knots k and k + 1.
inline Bounds3 knotLeafBox(const SubpatchForest& f, uint32_t firstKey, int k, float w, uint32_t leaf) {
    const uint32_t leaves = 1u << f.depth;
    const Bounds3& a = f.knotLeaves[size_t(firstKey + k) * leaves + leaf];
    const Bounds3& b = f.knotLeaves[size_t(firstKey + k + 1) * leaves + leaf];
    Bounds3 r;
    r.lo = lerp(a.lo, b.lo, w), r.hi = lerp(a.hi, b.hi, w);
    return r;
}

// Parameter rectangle of leaf `leaf` (0 .. 2^depth-1) of a tree of the given depth.
void subpatchLeafRect(int depth, uint32_t leaf, float& u0, float& u1, float& v0, float& v1);

// Box of the control hull grown by a relative and absolute margin, so that rays through shared patch
// edges hit the boxes on both sides despite rounding.
Bounds3 enlargedHull(const BezierPatch& p);

// Build the trees of all patches (parallel over patches), and the leaves' slabs (LeafSlab4) unless
// `leafSlabs` is false. With `backfaceFromOrigin`, also mark nodes
// whose subpatch faces away from the origin everywhere (conservative: Bernstein bound of the normal;
// `flip[i]` reverses patch i's orientation). With `motion`, the boxes of a patch that moves are the unions
// of its trees at every knot: control points move linearly between knots, and so do a subpatch's (they
// are fixed linear combinations of the patch's), so the union of the knots' hulls holds the subpatch at
// every time of the shutter (paper 002, sec. 5.3.3: bounds swept over the shutter). Moving patches get no
// back-facing marks (their orientation changes over the shutter).
// `quadrics` (empty, or one per patch): where an entry is not null, that surface is the quadric and its
// boxes are the quadric's own boxes of each node's (u,v) rectangle (quadricBounds, in the patches' space),
// never back-facing; its entry in `patches` only holds its place.
// `maxSlabs` (with `motion`): at most this many time slabs (1: none, the boxes swept over the whole
// shutter only); fewer when the slabs' quads would pass `slabBudgetBytes`.
constexpr int kDefaultTimeSlabs = 16;
constexpr size_t kTimeSlabBudgetBytes = size_t(512) << 20;
void buildSubpatchForest(std::span<const BezierPatch> patches, int depth, SubpatchForest& forest,
                         bool backfaceFromOrigin = false, std::span<const uint8_t> flip = {},
                         const FrameMotion* motion = nullptr, int maxSlabs = kDefaultTimeSlabs,
                         size_t slabBudgetBytes = kTimeSlabBudgetBytes,
                         std::span<const PlacedQuadric* const> quadrics = {}, bool leafSlabs = true);

// Replace the boxes of `patch`'s tree with ones built from its leaf boxes (`leaves`: 2^depth of them, in
// leaf order; an inner node is the union of its children), clear its back-facing marks and open its
// leaves' slabs: a displaced patch's leaves bound its micro-grid's triangles (rt/displaced.h). Static
// patches only (no time slabs).
void setSubpatchLeafBoxes(SubpatchForest& forest, uint32_t patch, std::span<const Bounds3> leaves);

}  // namespace tessera
