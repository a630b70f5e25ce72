// The Reyes engine: bound, split, dice, shade, sample, filter; buckets in parallel with oneTBB.
#pragma once
#include "engine/settings.h"
#include "engine/visibility.h"

namespace tessera {

// `visibility`: who answers the visibility queries of lights that cast shadows (the dispatcher passes the
// ray tracer's shadow rays for --reyes-shadows raytrace); nullptr: Reyes' own shadow maps.
RenderResult renderReyes(const Scene& scene, const RenderSettings& settings,
                         const LightVisibility* visibility = nullptr);

}  // namespace tessera
