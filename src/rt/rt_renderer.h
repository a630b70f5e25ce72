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
#include "engine/settings.h"
#include "rt/accel.h"
#include "rt/trace_service.h"
#include "rt/traversal.h"
#include "shading/bsdf.h"

namespace tessera {

// `dicer` (nullptr: none): makes the frame's dicer of displaced patches (rt/displaced.h; the render layer's
// render/displaced_dicer.h), which are then traced as micro-grids; without it they are traced undisplaced.
RenderResult renderRt(const Scene& scene, const RenderSettings& settings,
                      const DisplacedDicerFactory* dicer = nullptr);

}  // namespace tessera
