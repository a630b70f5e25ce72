// The visibility seam (docs/architecture.md, "One shading model", step 2): how an engine that does not
// answer its light samples' visibility queries itself gets them answered. Reyes shades a grid, then hands
// the grid's queries to a LightVisibility: its shadow maps (reyes/shadow_maps.h) or the ray tracer's shadow
// rays (rt/ray_visibility.h, built by the dispatcher in src/render for --reyes-shadows raytrace).
#pragma once
#include <cstdint>
#include <nlohmann/json.hpp>
#include <span>

#include "shading/surface.h"

namespace tessera {

// A batch of shading points whose light samples ask for visibility, in the render's shading space (camera
// space) with its lights. `patch` and `uv` (may be nullptr): the scene patch and (u,v) each point lies on,
// for the self-intersection guard of shadow rays. `time`: the normalised shutter time of the points.
struct VisibilityQuery {
    const SurfacePoints& points;
    std::span<const ShadingLight> lights;
    const uint32_t* patch = nullptr;
    const Vec2* uv = nullptr;
    float time = 0.f;
};

// Answers visibility queries: writes LightSamples::visibility (in [0,1]) of every sample whose
// needsVisibility is set, leaves the others. Called concurrently from the engine's worker threads.
class LightVisibility {
  public:
    virtual ~LightVisibility() = default;
    virtual void answer(const VisibilityQuery& query, LightSamples& samples) const = 0;
    // What it did, for the statistics JSON (merged under "shadows").
    virtual void writeStats(nlohmann::json& shadows) const = 0;
};

}  // namespace tessera
