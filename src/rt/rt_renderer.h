// The ray-tracing engine: rays intersect the bicubic patches directly (two-level hierarchy + Newton).
// Rendering runs as a data-parallel wavefront per image tile: ray list -> traversal emits candidates
// (ray, patch, u0, v0) -> Newton over the candidates -> closest hit per ray -> shading -> shadow,
// reflection and refraction ray lists -> repeat to RenderSettings::maxDepth. A scalar per-ray path
// (traceRayScalar) is kept as the reference for tests.
//
// Layout: rt/accel.h (the scene prepared for tracing), rt/trace_service.h (trace / occluded over ray
// lists: rt/traversal.h, rt/binning.h, rt/newton_stage.h, kernels in rt/simd_kernels.h), and this file's
// integrator (camera rays, shading, secondary rays, tiles, statistics).
#pragma once
#include "render/render.h"
#include "rt/accel.h"
#include "rt/trace_service.h"
#include "rt/traversal.h"
#include "scene/shading.h"

namespace tessera {

// Secondary directions. I: unit incident direction, N: unit normal (either side).
Vec3 reflectDir(Vec3 I, Vec3 N);
// Refraction through a surface of relative index eta (outside 1, inside eta; N points outside).
// Returns false on total internal reflection; F receives the Fresnel reflectance.
bool refractDir(Vec3 I, Vec3 N, float eta, Vec3& T, float& F);

RenderResult renderRt(const Scene& scene, const RenderSettings& settings);

}  // namespace tessera
