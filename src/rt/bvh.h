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

struct Bvh {
    std::vector<BvhNode> nodes;
    std::vector<uint32_t> prims;  // patch ids, leaves reference contiguous ranges
    int maxDepth = 0;
    size_t memoryBytes() const { return nodes.size() * sizeof(BvhNode) + prims.size() * sizeof(uint32_t); }
};

// Binned SAH (16 bins per axis over the centroid bounds), at most `maxLeafSize` patches per leaf.
void buildBvh(std::span<const Bounds3> primBounds, Bvh& bvh, int maxLeafSize = 4);

}  // namespace tessera
