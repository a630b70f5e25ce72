#include "rt/bvh.h"

#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <array>
#include <limits>

namespace tessera {
namespace {

constexpr int kBins = 16;
// Relative costs for the SAH: one box test vs. descending into a patch's subpatch tree.
constexpr float kTraversalCost = 1.f;
constexpr float kPatchCost = 4.f;

// Subtrees with at least this many patches are built in parallel (tbb::parallel_invoke on the two
// halves, each into its own node array, then concatenated in depth-first order): the result does not
// depend on the number of threads.
constexpr uint32_t kParallelMin = 2048;

struct Builder {
    std::span<const Bounds3> bounds;
    std::vector<Vec3> centroid;
    std::vector<uint32_t>& prims;
    int maxLeaf;

    // Box of the range and the split position (false: make a leaf).
    bool split(uint32_t begin, uint32_t end, Bounds3& box, uint32_t& mid, int& axisOut) {
        Bounds3 cbox;
        box = Bounds3();
        for (uint32_t i = begin; i < end; ++i) {
            box.extend(bounds[prims[i]]);
            cbox.extend(centroid[prims[i]]);
        }
        const uint32_t n = end - begin;
        if (n == 1) return false;

        // Binned SAH over the three axes (one pass over the patches for all three).
        std::array<std::array<Bounds3, kBins>, 3> binBox;
        std::array<std::array<uint32_t, kBins>, 3> binCount{};
        float scale[3];
        for (int axis = 0; axis < 3; ++axis) {
            const float ext = cbox.hi[axis] - cbox.lo[axis];
            scale[axis] = ext > 0.f ? kBins / ext : 0.f;
        }
        for (uint32_t i = begin; i < end; ++i) {
            const uint32_t p = prims[i];
            for (int axis = 0; axis < 3; ++axis) {
                const int b = std::min(kBins - 1, int((centroid[p][axis] - cbox.lo[axis]) * scale[axis]));
                binBox[axis][b].extend(bounds[p]);
                ++binCount[axis][b];
            }
        }
        float bestCost = std::numeric_limits<float>::infinity();
        int bestAxis = -1, bestSplit = 0;
        for (int axis = 0; axis < 3; ++axis) {
            if (!(cbox.hi[axis] - cbox.lo[axis] > 0.f)) continue;
            std::array<float, kBins> rightArea{};
            std::array<uint32_t, kBins> rightCount{};
            Bounds3 acc;
            uint32_t cnt = 0;
            for (int b = kBins - 1; b > 0; --b) {
                acc.extend(binBox[axis][b]);
                cnt += binCount[axis][b];
                rightArea[b] = acc.empty() ? 0.f : acc.surfaceArea();
                rightCount[b] = cnt;
            }
            acc = Bounds3();
            cnt = 0;
            for (int b = 0; b < kBins - 1; ++b) {
                acc.extend(binBox[axis][b]);
                cnt += binCount[axis][b];
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
        int axis = bestAxis;
        if (bestAxis < 0) {
            // All centroids coincide: split in the middle of the list if too many for a leaf.
            if (n <= uint32_t(maxLeaf)) return false;
            mid = begin + n / 2;
            axis = 0;
        } else {
            if (n <= uint32_t(maxLeaf) && leafCost <= splitCost) return false;
            const float lo = cbox.lo[axis], sc = scale[axis];
            auto it = std::partition(prims.begin() + begin, prims.begin() + end, [&](uint32_t p) {
                return std::min(kBins - 1, int((centroid[p][axis] - lo) * sc)) <= bestSplit;
            });
            mid = uint32_t(it - prims.begin());
            if (mid == begin || mid == end) mid = begin + n / 2;
        }
        axisOut = axis;
        return true;
    }

    // Appends the subtree of prims[begin, end) to `out` in depth-first order; returns its depth.
    int build(uint32_t begin, uint32_t end, std::vector<BvhNode>& out) {
        const uint32_t index = uint32_t(out.size());
        out.emplace_back();
        Bounds3 box;
        uint32_t mid = 0;
        int axis = 0;
        const bool inner = split(begin, end, box, mid, axis);
        out[index].box = box;
        if (!inner) {
            out[index].offset = begin;
            out[index].count = uint16_t(end - begin);
            return 0;
        }
        out[index].count = 0;
        out[index].axis = uint16_t(axis);
        int dl, dr;
        if (end - begin >= kParallelMin) {
            std::vector<BvhNode> left, right;
            tbb::parallel_invoke([&] { dl = build(begin, mid, left); }, [&] { dr = build(mid, end, right); });
            append(out, left);
            out[index].offset = uint32_t(out.size());
            append(out, right);
        } else {
            dl = build(begin, mid, out);
            out[index].offset = uint32_t(out.size());
            dr = build(mid, end, out);
        }
        return 1 + std::max(dl, dr);
    }

    static void append(std::vector<BvhNode>& out, const std::vector<BvhNode>& sub) {
        const uint32_t base = uint32_t(out.size());
        for (BvhNode nd : sub) {
            if (nd.count == 0) nd.offset += base;
            out.push_back(nd);
        }
    }
};

}  // namespace

void buildBvh(std::span<const Bounds3> primBounds, Bvh& bvh, int maxLeafSize) {
    bvh.nodes.clear();
    bvh.prims.resize(primBounds.size());
    bvh.maxDepth = 0;
    if (primBounds.empty()) return;
    for (uint32_t i = 0; i < primBounds.size(); ++i) bvh.prims[i] = i;
    Builder b{primBounds, std::vector<Vec3>(primBounds.size()), bvh.prims, std::clamp(maxLeafSize, 1, 255)};
    for (size_t i = 0; i < primBounds.size(); ++i) b.centroid[i] = primBounds[i].center();
    bvh.nodes.reserve(2 * primBounds.size());
    bvh.maxDepth = b.build(0, uint32_t(primBounds.size()), bvh.nodes);
}

namespace {

struct Collapser {
    Bvh& bvh;
    std::span<const Bounds3> patchBox;
    struct Item {
        uint32_t node;   // binary node, or kBvh4Patch | patch
        float area = 0;  // surface area (larger items are opened first)
    };

    Item itemOf(uint32_t ni) const {
        const BvhNode& nd = bvh.nodes[ni];
        if (nd.count == 1) return {kBvh4Patch | bvh.prims[nd.offset], 0.f};
        return {ni, nd.box.surfaceArea()};
    }

    uint32_t collapse(uint32_t ni) {
        const uint32_t index = uint32_t(bvh.wide.size());
        bvh.wide.emplace_back();
        Item items[4];
        int n = 0;
        auto open = [&](uint32_t b, Item* out) {  // the items directly below binary node b
            const BvhNode& nd = bvh.nodes[b];
            if (nd.count == 0) {
                out[0] = itemOf(b + 1);
                out[1] = itemOf(nd.offset);
                return 2;
            }
            for (uint32_t k = 0; k < nd.count; ++k) out[k] = {kBvh4Patch | bvh.prims[nd.offset + k], 0.f};
            return int(nd.count);
        };
        const BvhNode& root = bvh.nodes[ni];
        if (root.count > 4) {  // cannot happen with maxLeafSize <= 4; keep it as one patch list anyway
            for (uint32_t k = 0; k < 4; ++k) items[n++] = {kBvh4Patch | bvh.prims[root.offset + k], 0.f};
        } else {
            n = open(ni, items);
        }
        for (;;) {
            // Open the largest item that fits.
            int best = -1;
            for (int i = 0; i < n; ++i) {
                if (items[i].node & kBvh4Patch) continue;
                const BvhNode& nd = bvh.nodes[items[i].node];
                const int grows = nd.count == 0 ? 2 : int(nd.count);
                if (n - 1 + grows > 4) continue;
                if (best < 0 || items[i].area > items[best].area) best = i;
            }
            if (best < 0) break;
            Item sub[4];
            const int m = open(items[best].node, sub);
            items[best] = sub[0];
            for (int k = 1; k < m; ++k) items[n++] = sub[k];
        }
        uint32_t child[4] = {};
        Bounds3 box[4];
        for (int i = 0; i < n; ++i) {
            if (items[i].node & kBvh4Patch) {
                child[i] = items[i].node;
                box[i] = patchBox[items[i].node & ~kBvh4Patch];
            } else {
                child[i] = collapse(items[i].node);
                box[i] = bvh.nodes[items[i].node].box;
            }
        }
        Bvh4Node& w = bvh.wide[index];
        w.count = uint32_t(n);
        for (int i = 0; i < 4; ++i) {
            const Bounds3 b = i < n ? box[i] : Bounds3();
            for (int k = 0; k < 3; ++k) w.lo[k][i] = b.lo[k], w.hi[k][i] = b.hi[k];
            w.child[i] = i < n ? child[i] : 0u;
            if (i < n && !(child[i] & kBvh4Patch)) w.innerMask |= 1u << i;
        }
        return index;
    }
};

}  // namespace

void collapseBvh4(Bvh& bvh, std::span<const Bounds3> patchBox) {
    bvh.wide.clear();
    if (bvh.nodes.empty()) return;
    bvh.wide.reserve(bvh.nodes.size() / 2 + 1);
    Collapser c{bvh, patchBox};
    c.collapse(0);
}

}  // namespace tessera
