// The ray-tracing engine: rays intersect the bicubic patches directly (two-level hierarchy + Newton).
// Rendering runs as a data-parallel wavefront per image tile: ray list -> traversal emits candidates
// (ray, patch, u0, v0) -> Newton over the candidates -> closest hit per ray -> shading -> shadow,
// reflection and refraction ray lists -> repeat to RenderSettings::maxDepth. A scalar per-ray path
// (traceRayScalar) is kept as the reference for tests.
#pragma once
#include <cstdint>
#include <span>
#include <vector>

#include "engine/settings.h"
#include "rt/bvh.h"
#include "rt/intersect.h"
#include "rt/subpatch_tree.h"
#include "scene/shading.h"

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

struct TraceOptions {
    bool anyHit = false;                // shadow rays: stop at the first hit
    bool respectSides = false;          // one-sided patches are invisible from behind (camera rays)
    bool cullBackfaces = false;         // skip subpatches marked back-facing (camera rays, --cull-backfaces)
    uint32_t ignorePatch = UINT32_MAX;  // reject hits on this patch with t < ignoreT (self-intersection)
    float ignoreT = 0.f;
};

struct RayHit {
    bool hit = false;
    uint32_t patch = UINT32_MAX;
    PatchHit h;
};

// Scalar reference: closest (or any) hit along the ray, BVH then each patch's subpatch tree.
bool traceRayScalar(const RtAccel& acc, const Ray& ray, const TraceOptions& opt, RayHit& out);

// Unit shading normal at a hit (geometric, orientation flipped per the patch attributes).
Vec3 hitNormal(const RtAccel& acc, uint32_t patch, const PatchHit& h);

// Whether a hit is acceptable under the options (sides, self-intersection).
bool acceptHit(const RtAccel& acc, const Ray& ray, const TraceOptions& opt, uint32_t patch,
               const PatchHit& h);

// Secondary directions: reflectDir and refractDir live in shading/bsdf.h.

// The traversal's subpatch kernels use AVX2 where the CPU has it (chosen at run time; same results as the
// SSE2 kernels). allow = false forces the SSE2 kernels (tests), true allows AVX2 again; returns whether
// AVX2 kernels will run.
bool rtUseAvx2(bool allow);

// The wavefront path (the renderer's traversal and Newton stages) over a batch of rays, serially in
// the caller's thread: the same answers as traceRayScalar, for tests and tools.
void traceBatch(const RtAccel& acc, std::span<const Ray> rays, const TraceOptions& opt,
                std::vector<RayHit>& hits);

RenderResult renderRt(const Scene& scene, const RenderSettings& settings);

}  // namespace tessera
