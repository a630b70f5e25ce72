#include "rt/bvh.h"

#include <algorithm>
#include <array>
#include <limits>

namespace tessera {
namespace {

constexpr int kBins = 16;
// Relative costs for the SAH: one box test vs. descending into a patch's subpatch tree.
constexpr float kTraversalCost = 1.f;
constexpr float kPatchCost = 4.f;

struct Builder {
    std::span<const Bounds3> bounds;
    std::vector<Vec3> centroid;
    Bvh& bvh;
    int maxLeaf;

    uint32_t build(uint32_t begin, uint32_t end, int depth) {
        bvh.maxDepth = std::max(bvh.maxDepth, depth);
        const uint32_t index = uint32_t(bvh.nodes.size());
        bvh.nodes.emplace_back();
        Bounds3 box, cbox;
        for (uint32_t i = begin; i < end; ++i) {
            box.extend(bounds[bvh.prims[i]]);
            cbox.extend(centroid[bvh.prims[i]]);
        }
        bvh.nodes[index].box = box;
        const uint32_t n = end - begin;
        auto makeLeaf = [&] {
            bvh.nodes[index].offset = begin;
            bvh.nodes[index].count = uint16_t(n);
            return index;
        };
        if (n == 1) return makeLeaf();

        // Binned SAH over the three axes.
        float bestCost = std::numeric_limits<float>::infinity();
        int bestAxis = -1, bestSplit = 0;
        for (int axis = 0; axis < 3; ++axis) {
            const float lo = cbox.lo[axis], ext = cbox.hi[axis] - lo;
            if (!(ext > 0.f)) continue;
            const float scale = kBins / ext;
            std::array<Bounds3, kBins> binBox;
            std::array<uint32_t, kBins> binCount{};
            for (uint32_t i = begin; i < end; ++i) {
                int b = std::min(kBins - 1, int((centroid[bvh.prims[i]][axis] - lo) * scale));
                binBox[b].extend(bounds[bvh.prims[i]]);
                ++binCount[b];
            }
            std::array<float, kBins> rightArea{};
            std::array<uint32_t, kBins> rightCount{};
            Bounds3 acc;
            uint32_t cnt = 0;
            for (int b = kBins - 1; b > 0; --b) {
                acc.extend(binBox[b]);
                cnt += binCount[b];
                rightArea[b] = acc.empty() ? 0.f : acc.surfaceArea();
                rightCount[b] = cnt;
            }
            acc = Bounds3();
            cnt = 0;
            for (int b = 0; b < kBins - 1; ++b) {
                acc.extend(binBox[b]);
                cnt += binCount[b];
                if (cnt == 0 || rightCount[b + 1] == 0) continue;
                float cost = acc.surfaceArea() * cnt + rightArea[b + 1] * rightCount[b + 1];
                if (cost < bestCost) {
                    bestCost = cost;
                    bestAxis = axis;
                    bestSplit = b;
                }
            }
        }
        const float area = std::max(box.surfaceArea(), 1e-30f);
        const float leafCost = kPatchCost * n;
        const float splitCost = kTraversalCost + kPatchCost * bestCost / area;
        uint32_t mid;
        int axis = bestAxis;
        if (bestAxis < 0) {
            // All centroids coincide: split in the middle of the list if too many for a leaf.
            if (n <= uint32_t(maxLeaf)) return makeLeaf();
            mid = begin + n / 2;
            axis = 0;
        } else {
            if (n <= uint32_t(maxLeaf) && leafCost <= splitCost) return makeLeaf();
            const float lo = cbox.lo[axis], scale = kBins / (cbox.hi[axis] - lo);
            auto it =
                std::stable_partition(bvh.prims.begin() + begin, bvh.prims.begin() + end, [&](uint32_t p) {
                    return std::min(kBins - 1, int((centroid[p][axis] - lo) * scale)) <= bestSplit;
                });
            mid = uint32_t(it - bvh.prims.begin());
            if (mid == begin || mid == end) mid = begin + n / 2;
        }
        build(begin, mid, depth + 1);
        const uint32_t right = build(mid, end, depth + 1);
        bvh.nodes[index].offset = right;
        bvh.nodes[index].count = 0;
        bvh.nodes[index].axis = uint16_t(axis);
        return index;
    }
};

}  // namespace

void buildBvh(std::span<const Bounds3> primBounds, Bvh& bvh, int maxLeafSize) {
    bvh.nodes.clear();
    bvh.prims.resize(primBounds.size());
    bvh.maxDepth = 0;
    if (primBounds.empty()) return;
    for (uint32_t i = 0; i < primBounds.size(); ++i) bvh.prims[i] = i;
    Builder b{primBounds, std::vector<Vec3>(primBounds.size()), bvh, std::clamp(maxLeafSize, 1, 255)};
    for (size_t i = 0; i < primBounds.size(); ++i) b.centroid[i] = primBounds[i].center();
    bvh.nodes.reserve(2 * primBounds.size());
    b.build(0, uint32_t(primBounds.size()), 0);
}

}  // namespace tessera
