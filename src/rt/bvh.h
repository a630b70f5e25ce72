// Top level of the ray tracer's two-level hierarchy: a BVH over patch bounding boxes, built with a binned
// surface-area heuristic and stored flat in depth-first order (the left child follows its parent; the
// node stores the index of its right child), ready for short-stack traversal.
#pragma once
#include <cstdint>
#include <span>
#include <vector>

#include "core/vec.h"

namespace tessera {

struct BvhNode {
    Bounds3 box;          // 24 bytes
    uint32_t offset = 0;  // interior: index of the right child; leaf: first entry in Bvh::prims
    uint16_t count = 0;   // leaf: number of patches (> 0); interior: 0
    uint16_t axis = 0;    // interior: split axis (visit order by the ray's direction sign)
};
static_assert(sizeof(BvhNode) == 32);

// 4-wide node for traversal (the binary tree collapsed): the boxes of up to four children, structure of
// arrays, tested with one 4-wide slab test. A child is an inner 4-wide node (its index) or a patch
// (kBvh4Patch | patch id, the box being the patch's root box), so the patch boxes are tested together with
// their siblings; slots >= count are empty.
constexpr uint32_t kBvh4Patch = 0x80000000u;
struct alignas(16) Bvh4Node {
    float lo[3][4], hi[3][4];  // [axis][child]
    uint32_t child[4];
    uint32_t count = 0;
    uint32_t innerMask = 0;  // bit i set when child i is an inner node (i < count)
    uint32_t pad_[2] = {};
};
static_assert(sizeof(Bvh4Node) == 128);

struct Bvh {
    std::vector<BvhNode> nodes;
    std::vector<uint32_t> prims;  // patch ids, leaves reference contiguous ranges
    std::vector<Bvh4Node> wide;   // the same tree, 4-wide (collapseBvh4); root at 0
    int maxDepth = 0;
    size_t memoryBytes() const {
        return nodes.size() * sizeof(BvhNode) + prims.size() * sizeof(uint32_t) +
               wide.size() * sizeof(Bvh4Node);
    }
};

// Binned SAH (16 bins per axis over the centroid bounds), at most `maxLeafSize` patches per leaf.
void buildBvh(std::span<const Bounds3> primBounds, Bvh& bvh, int maxLeafSize = 4);

// Collapse the binary tree into bvh.wide: each 4-wide node takes the (up to) four largest descendants of
// a binary node (binary leaves are opened into their patches when they fit). `patchBox[p]` is the box of
// patch p (the ids stored in bvh.prims).
void collapseBvh4(Bvh& bvh, std::span<const Bounds3> patchBox);

}  // namespace tessera
