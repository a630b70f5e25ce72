// The ray tracer's displaced micro-grids diced by Reyes (rt/displaced.h): the render layer links both
// engines, so it implements the rt's DisplacedDicer with Reyes' split, dice and displacement code.
#pragma once
#include <memory>

#include "engine/frame.h"
#include "rt/displaced.h"

namespace tessera {

// The dicer for a ray-traced frame: the patches in camera space welded as Reyes welds them, the same
// displacement frame, a view from the same camera (shading rates, grid size) that culls nothing (reflections
// and shadows see off-screen and behind-the-eye parts). nullptr when no patch is displaced.
std::unique_ptr<DisplacedDicer> makeReyesDisplacedDicer(const Scene& scene, const RenderSettings& settings,
                                                        const FrameSetup& frame);

}  // namespace tessera
