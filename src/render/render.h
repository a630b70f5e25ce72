// The entry point shared by the CLI, tests and benchmarks: render a Scene with one of the engines. The
// dispatcher sits above both engines; what they share (settings, result, tile loop) is in src/engine.
#pragma once
#include "engine/settings.h"

namespace tessera {

// Throws std::invalid_argument for an unknown engine name.
RenderResult render(const Scene& scene, const RenderSettings& settings);

}  // namespace tessera
