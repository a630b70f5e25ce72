// What every engine takes and gives: the settings of a render, the view (camera and film region), the
// output spec (channels wanted) and the result. Below both engines; the dispatcher (src/render) sits above.
#pragma once
#include <atomic>
#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "film/film.h"
#include "scene/scene.h"

namespace tessera {

struct RenderSettings {
    std::string engine = "reyes";  // "reyes" or "rt"
    int threads = 0;               // 0: all hardware threads
    uint32_t seed = 0;             // sample pattern seed
    int bucketSize = 32;           // pixels per bucket side
    int maxGridEdge = 16;          // Reyes: micropolygons per grid edge before splitting
    // Ray tracer
    int subpatchDepth = 6;
    int maxDepth = 4;
    bool cullBackfaces = false;
    // Camera and shadow rays may find their candidates by binning the boxes in a projection plane instead
    // of one traversal per ray (same candidates); the renderer uses it where it pays (few subpatch leaves
    // per sample). Off: always per ray (tests, benchmarks).
    bool rayBinning = true;
    // Output spec: the film's attribute channels (FilmChannel bits) and further AOVs wanted; each becomes
    // an image plane of the result.
    uint32_t channels = 0;
    std::vector<std::string> aovs;
    // Film region to render (crop window, farm tile): half-open raster rectangle; empty = the whole image.
    Rect region;
    // Progress: called from worker threads with (work done, total work) after each bucket; the units are
    // the engine's estimate of its work (samples traced, micropolygons sampled), so the fraction grows
    // steadily over the render. Must be thread-safe.
    std::function<void(uint64_t, uint64_t)> progress;
    // Set to true (e.g. by a SIGINT handler) to stop the render early: no bucket starts after it is seen.
    const std::atomic<bool>* cancel = nullptr;
};

struct RenderResult {
    Image image;  // the film region (origin at the region's corner)
    nlohmann::json stats;  // engine counters; the CLI adds timing and memory
    bool cancelled = false;
    std::vector<std::string> warnings;  // said once per render (e.g. effects an engine does not render)
};

// The raster rectangle a render covers: settings.region clipped to the image, or the whole image.
inline Rect renderRegion(const Camera& cam, const RenderSettings& s) {
    const Rect whole{0, 0, cam.width, cam.height};
    if (s.region.width() <= 0 || s.region.height() <= 0) return whole;
    return Rect{std::clamp(s.region.x0, 0, cam.width), std::clamp(s.region.y0, 0, cam.height),
                std::clamp(s.region.x1, 0, cam.width), std::clamp(s.region.y1, 0, cam.height)};
}

}  // namespace tessera
