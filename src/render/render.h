// The entry point shared by the CLI, tests and benchmarks: render a Scene with one of the engines.
#pragma once
#include <atomic>
#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>

#include "film/film.h"
#include "scene/scene.h"

namespace tessera {

struct RenderSettings {
    std::string engine = "reyes";  // "reyes" or "rt"
    int threads = 0;               // 0: all hardware threads
    uint32_t seed = 0;             // sample pattern seed
    int bucketSize = 32;           // pixels per bucket side
    int maxGridEdge = 16;          // Reyes: micropolygons per grid edge before splitting
    SamplerKind sampler = SamplerKind::Sobol;
    // Ray tracer
    int subpatchDepth = 6;
    int maxDepth = 4;
    bool cullBackfaces = false;
    // Camera and shadow rays may find their candidates by binning the boxes in a projection plane instead
    // of one traversal per ray (same candidates); the renderer uses it where it pays (few subpatch leaves
    // per sample). Off: always per ray (tests, benchmarks).
    bool rayBinning = true;
    // Progress: called with (buckets done, total) from worker threads; must be thread-safe.
    std::function<void(int, int)> progress;
    // Set to true (e.g. by a SIGINT handler) to stop the render early.
    const std::atomic<bool>* cancel = nullptr;
};

struct RenderResult {
    Image image;
    nlohmann::json stats;  // engine counters; the CLI adds timing and memory
    bool cancelled = false;
};

// Throws std::invalid_argument for an unknown engine name.
RenderResult render(const Scene& scene, const RenderSettings& settings);

}  // namespace tessera
