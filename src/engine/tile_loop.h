// The one bucket loop of both engines: buckets of a film region in scanline order, taken by the arena's
// workers one at a time; cancellation checked before every bucket; progress reported as work done;
// wall time measured. Engines supply the per-bucket work estimate and the bucket function.
#pragma once
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <atomic>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <span>

#include "engine/clock.h"
#include "engine/settings.h"
#include "film/film.h"

namespace tessera {

// Square buckets of `size` pixels covering `region`, numbered in scanline order.
struct BucketLayout {
    Rect region;
    int size = 32;
    int countX = 0, countY = 0;
    BucketLayout(Rect r, int bucketSize)
        : region(r),
          size(std::max(1, bucketSize)),
          countX((r.width() + size - 1) / size),
          countY((r.height() + size - 1) / size) {}
    int count() const { return countX * countY; }
    // Pixels bucket b writes.
    Rect target(int b) const {
        const int bx = b % countX, by = b / countX;
        return Rect{region.x0 + bx * size, region.y0 + by * size,
                    std::min(region.x1, region.x0 + (bx + 1) * size),
                    std::min(region.y1, region.y0 + (by + 1) * size)};
    }
    // The pixels whose samples bucket b needs: its target grown by the filter radius, clipped to the image
    // (not to the region, so a crop or farm tile has the same pixels as the whole render).
    Rect samples(int b, int rx, int ry, int width, int height) const {
        const Rect t = target(b);
        return Rect{std::max(0, t.x0 - rx), std::max(0, t.y0 - ry), std::min(width, t.x1 + rx),
                    std::min(height, t.y1 + ry)};
    }
    // Bucket index range [b0, b1] x [c0, c1] overlapped by a raster rectangle (clamped).
    void overlapped(float x0, float y0, float x1, float y1, int& bx0, int& by0, int& bx1, int& by1) const {
        auto col = [&](float x) {
            return std::clamp(int(std::floor((x - region.x0) / size)), 0, countX - 1);
        };
        auto row = [&](float y) {
            return std::clamp(int(std::floor((y - region.y0) / size)), 0, countY - 1);
        };
        bx0 = col(x0), bx1 = col(x1), by0 = row(y0), by1 = row(y1);
    }
};

struct TileLoopResult {
    bool cancelled = false;
    double wallMs = 0;
    int bucketsRendered = 0;
};

// Runs renderBucket(b, workerState) for every bucket; `work[b]` is the bucket's estimated work (empty:
// one unit each) for the progress callback. Deterministic output is the caller's: a bucket writes only its
// target pixels. `image`: where the buckets write their final pixels, handed to the settings' bucketDone
// after each bucket (null: a pass whose buckets make no image pixels, e.g. a shadow map).
template <class Worker, class Fn>
TileLoopResult runTileLoop(const BucketLayout& layout, std::span<const uint64_t> work,
                           const RenderSettings& s, tbb::enumerable_thread_specific<Worker>& workers,
                           Fn&& renderBucket, const Image* image = nullptr) {
    const int nb = layout.count();
    uint64_t totalWork = 0;
    for (int b = 0; b < nb; ++b) totalWork += work.empty() ? 1 : work[b];
    std::atomic<int> next{0}, rendered{0};
    std::atomic<uint64_t> doneWork{0};
    std::atomic<bool> cancelled{false};
    const auto t0 = EngineClock::now();
    const int threads = tbb::this_task_arena::max_concurrency();
    tbb::parallel_for(
        0, threads,
        [&](int) {
            Worker& w = workers.local();
            for (;;) {
                if (s.cancel && s.cancel->load(std::memory_order_relaxed)) {
                    cancelled = true;
                    break;
                }
                const int b = next.fetch_add(1);
                if (b >= nb) break;
                renderBucket(b, w);
                ++rendered;
                const uint64_t done = doneWork += work.empty() ? 1 : work[b];
                if (image && s.bucketDone) s.bucketDone(*image, layout.target(b));
                if (s.progress) s.progress(done, totalWork);
            }
        },
        tbb::static_partitioner());
    return {cancelled.load(), msSince(t0), rendered.load()};
}

// The statistics every engine reports about its bucket loop.
inline void writeTileLoopStats(const BucketLayout& layout, const TileLoopResult& r, nlohmann::json& s) {
    s["buckets"] = layout.count();
    s["buckets_rendered"] = r.bucketsRendered;
    s["bucket_size"] = layout.size;
    s["region"] = {layout.region.x0, layout.region.y0, layout.region.x1, layout.region.y1};
}

}  // namespace tessera
