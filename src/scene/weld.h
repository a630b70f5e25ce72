// Welding of shared patch edges. The crack-free dicing of the Reyes engine (and exact seams in the ray
// tracer) rely on neighbouring patches having bit-identical control points along a shared edge. Models
// converted from other bases (B-spline patch meshes, NURBS) share edges only up to rounding; this pass makes
// them exactly equal again.
#pragma once
#include <cstddef>
#include <vector>

#include "core/bezier.h"

namespace tessera {

struct WeldResult {
    size_t cornersMoved = 0;  // patch corners snapped onto a coincident corner of another patch
    size_t edgesWelded = 0;   // edges whose inner control points were copied from a matching edge
};

// Corners closer than `tolerance` are unified; then every boundary curve whose two end corners and two
// inner control points match another patch's curve (in either direction) within `tolerance` takes that
// curve's exact control points. Deterministic: the first patch in order provides the values.
WeldResult weldSharedEdges(std::vector<BezierPatch>& patches, float tolerance);

// A tolerance relative to the size of the model: 1e-5 of the bounding box diagonal.
float defaultWeldTolerance(const std::vector<BezierPatch>& patches);

}  // namespace tessera
