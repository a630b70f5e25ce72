// The ray tracer's acceleration structure: the patches in one space (the renderer uses camera space) with
// both levels of the hierarchy (rt/bvh.h, rt/subpatch_tree.h) and what the Newton stage reads per patch.
#pragma once
#include <cstdint>
#include <vector>

#include "core/transform.h"
#include "rt/bvh.h"
#include "rt/intersect.h"
#include "rt/subpatch_tree.h"
#include "scene/scene.h"

namespace tessera {

// A patch's control points as coordinate arrays (the projection on a ray's planes runs 4 points at a
// time), with what the Newton tolerance needs from its box.
struct alignas(16) PatchSoa {
    float x[16], y[16], z[16];
    float boxMagnitude;  // largest |coordinate| of the patch's root box
    float boxExtent;     // largest side of the root box
};

// Scene prepared for tracing in one space (the renderer uses camera space: eye at the origin).
struct RtAccel {
    std::vector<BezierPatch> patches;
    std::vector<PatchSoa> patchSoa;  // the same patches, for the wavefront's Newton stage
    std::vector<uint8_t> flip, twoSided;
    std::vector<uint32_t> material;
    Bvh bvh;
    SubpatchForest forest;
    Bounds3 bounds;        // of all traced patches (their root boxes)
    float offset = 1e-4f;  // self-intersection offset along the normal for secondary ray origins
    double bvhMs = 0, subpatchMs = 0;
};

// Transform the patches by `toSpace` and build both levels. `cullFromOrigin` also marks subpatches that
// face away from the origin (the eye, in camera space) for --cull-backfaces.
void buildRtAccel(const Scene& scene, const Mat4& toSpace, int subpatchDepth, bool cullFromOrigin,
                  RtAccel& acc);

// Unit shading normal at a hit (geometric, orientation flipped per the patch attributes).
Vec3 hitNormal(const RtAccel& acc, uint32_t patch, const PatchHit& h);

}  // namespace tessera
