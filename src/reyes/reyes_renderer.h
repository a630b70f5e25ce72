// The Reyes engine: bound, split, dice, shade, sample, filter; buckets in parallel with oneTBB.
#pragma once
#include "engine/settings.h"

namespace tessera {

RenderResult renderReyes(const Scene& scene, const RenderSettings& settings);

}  // namespace tessera
