// Welding of shared patch edges. The crack-free dicing of the Reyes engine (and exact seams in the ray
// tracer) rely on neighbouring patches having bit-identical control points along a shared edge. Models
// converted from other bases (B-spline patch meshes, NURBS) share edges only up to rounding; this pass makes
// them exactly equal again.
#pragma once
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "core/bezier.h"

namespace tessera {

struct WeldResult {
    size_t cornersMoved = 0;  // patch corners snapped onto a coincident corner of another patch
    size_t edgesWelded = 0;   // edges whose inner control points were copied from a matching edge
};

// One control point made equal to another: patches[dstPatch].cp[dstCp] = patches[srcPatch].cp[srcCp].
struct WeldCopy {
    uint32_t dstPatch, srcPatch;
    uint8_t dstCp, srcCp;
};
// Every identification a weld made, in order (also those that found the points already equal): replayed
// on the same patches at another time of a motion blur, it makes the same control points identical there.
using WeldPlan = std::vector<WeldCopy>;

// Corners closer than `tolerance` are unified; then every boundary curve whose two end corners and two
// inner control points match another patch's curve (in either direction) within `tolerance` takes that
// curve's exact control points. Deterministic: the first patch in order provides the values.
WeldResult weldSharedEdges(std::span<BezierPatch> patches, float tolerance, WeldPlan* plan = nullptr);

// Replays a weld's identifications (the patches must be the same ones, e.g. at another motion knot).
void applyWeldPlan(const WeldPlan& plan, std::span<BezierPatch> patches);

// A tolerance relative to the size of the model: 1e-5 of the bounding box diagonal.
float defaultWeldTolerance(std::span<const BezierPatch> patches);

}  // namespace tessera
