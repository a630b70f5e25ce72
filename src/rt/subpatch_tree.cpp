#include "rt/subpatch_tree.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace tessera {
namespace {

// True when every normal dPdu x dPdv of the patch (times `sign`) has a positive dot product with every
// point of its hull box, i.e. the subpatch faces away from the origin everywhere. dPdu x dPdv is a
// degree (5,5) polynomial whose Bernstein coefficients are non-negative combinations of the cross products
// a_{i1,j1} x b_{i2,j2} of the derivative nets, so testing those cross products is conservative.
bool facesAwayFromOrigin(const BezierPatch& p, const Bounds3& box, float sign) {
    Vec3 a[3][4], b[4][3];  // a: dPdu net (u: 3, v: 4), b: dPdv net (u: 4, v: 3)
    for (int j = 0; j < 4; ++j)
        for (int i = 0; i < 3; ++i) a[i][j] = (p.at(i + 1, j) - p.at(i, j)) * sign;
    for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 4; ++i) b[i][j] = p.at(i, j + 1) - p.at(i, j);
    for (int i1 = 0; i1 < 3; ++i1)
        for (int j1 = 0; j1 < 4; ++j1)
            for (int i2 = 0; i2 < 4; ++i2)
                for (int j2 = 0; j2 < 3; ++j2) {
                    Vec3 c = cross(a[i1][j1], b[i2][j2]);
                    // min over the box of dot(P, c)
                    float m = 0;
                    for (int k = 0; k < 3; ++k) m += std::min(c[k] * box.lo[k], c[k] * box.hi[k]);
                    if (!(m > 0.f)) return false;
                }
    return true;
}

void buildNode(const BezierPatch& p, int level, int depth, uint32_t node, Bounds3* boxes, uint8_t* back,
               float sign) {
    boxes[node] = enlargedHull(p);
    if (level == depth) {
        if (back) back[node] = facesAwayFromOrigin(p, boxes[node], sign);
        return;
    }
    BezierPatch lo, hi;
    if ((level & 1) == 0)
        splitPatchU(p, 0.5f, lo, hi);
    else
        splitPatchV(p, 0.5f, lo, hi);
    buildNode(lo, level + 1, depth, 2 * node + 1, boxes, back, sign);
    buildNode(hi, level + 1, depth, 2 * node + 2, boxes, back, sign);
    if (back) back[node] = back[2 * node + 1] & back[2 * node + 2];
}

}  // namespace

void subpatchLeafRect(int depth, uint32_t leaf, float& u0, float& u1, float& v0, float& v1) {
    float du = 1.f, dv = 1.f;
    u0 = v0 = 0.f;
    for (int k = 0; k < depth; ++k) {
        uint32_t bit = (leaf >> (depth - 1 - k)) & 1u;
        if ((k & 1) == 0) {
            du *= 0.5f;
            u0 += float(bit) * du;
        } else {
            dv *= 0.5f;
            v0 += float(bit) * dv;
        }
    }
    u1 = u0 + du;
    v1 = v0 + dv;
}

Bounds3 enlargedHull(const BezierPatch& p) {
    Bounds3 b = hullBounds(p);
    float mag = 0.f;
    for (int k = 0; k < 3; ++k) mag = std::max({mag, std::fabs(b.lo[k]), std::fabs(b.hi[k])});
    const float ext = maxComponent(b.diagonal());
    const float eps = 1e-5f * ext + 4e-7f * mag + 1e-30f;
    b.lo -= Vec3{eps, eps, eps};
    b.hi += Vec3{eps, eps, eps};
    return b;
}

void buildSubpatchForest(std::span<const BezierPatch> patches, int depth, SubpatchForest& f,
                         bool backfaceFromOrigin, std::span<const uint8_t> flip) {
    depth = std::clamp(depth, 0, 12);
    f.depth = depth;
    f.nodesPerPatch = (2u << depth) - 1u;
    f.boxes.resize(patches.size() * f.nodesPerPatch);
    f.backfacing.clear();
    if (backfaceFromOrigin) f.backfacing.assign(f.boxes.size(), 0);
    const uint32_t leaves = 1u << depth;
    f.leafCentre.resize(leaves);
    for (uint32_t l = 0; l < leaves; ++l) {
        float u0, u1, v0, v1;
        subpatchLeafRect(depth, l, u0, u1, v0, v1);
        f.leafCentre[l] = {0.5f * (u0 + u1), 0.5f * (v0 + v1)};
    }
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, patches.size(), 16), [&](const tbb::blocked_range<size_t>& r) {
            for (size_t i = r.begin(); i != r.end(); ++i) {
                uint8_t* back = backfaceFromOrigin ? f.backfacing.data() + i * f.nodesPerPatch : nullptr;
                float sign = (!flip.empty() && flip[i]) ? -1.f : 1.f;
                buildNode(patches[i], 0, depth, 0, f.boxes.data() + i * f.nodesPerPatch, back, sign);
            }
        });
}

}  // namespace tessera
