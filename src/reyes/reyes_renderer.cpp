#include "reyes/reyes_renderer.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <mutex>

#include "reyes/grid.h"
#include "reyes/rasterize.h"
#include "reyes/split.h"
#include "scene/weld.h"

namespace tessera {
namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// A diced grid shared by the buckets its piece overlaps: created by the first bucket that needs it,
// freed by the last one, so only grids near the buckets in flight are alive.
struct GridSlot {
    std::once_flag once;
    std::unique_ptr<Grid> grid;
    std::atomic<int> refs{0};
};

struct ThreadCounters {
    uint64_t grids = 0, micropolygons = 0, sampleTests = 0;
    double diceMs = 0, sampleMs = 0, filterMs = 0;
    SampleTile tile;
};

}  // namespace

RenderResult renderReyes(const Scene& scene, const RenderSettings& settings) {
    const auto tStart = Clock::now();
    RenderResult result;
    const Camera& cam = scene.camera;
    const int W = cam.width, H = cam.height;
    result.image = Image(W, H);
    const PixelFilter filter = makeFilter(scene.image);
    const int nx = std::max(1, scene.image.pixelSamplesX), ny = std::max(1, scene.image.pixelSamplesY);

    // Bound: patches to camera space (affine: transform the control points), lights likewise.
    std::vector<BezierPatch> patches(scene.patches.size());
    tbb::parallel_for(size_t(0), patches.size(), [&](size_t i) {
        for (int k = 0; k < 16; ++k) patches[i].cp[k] = cam.cameraFromWorld.point(scene.patches[i].cp[k]);
    });
    // Shared edges must be bit-identical for crack-free dicing: weld what matches only up to rounding.
    const auto tWeld = Clock::now();
    const WeldResult weld = weldSharedEdges(patches, defaultWeldTolerance(patches));
    const double weldMs = msSince(tWeld);
    std::vector<ShadingLight> lights;
    for (const Light& l : scene.lights) lights.push_back(prepareLight(l, cam.cameraFromWorld));

    ReyesView view(cam);
    view.patches = patches.data();
    view.maxGridEdge = std::max(1, settings.maxGridEdge);
    const int rx = filter.radiusX(), ry = filter.radiusY();
    view.cullX0 = float(-rx - 1);
    view.cullY0 = float(-ry - 1);
    view.cullX1 = float(W + rx + 1);
    view.cullY1 = float(H + ry + 1);

    // Split: every patch into diceable pieces, in parallel, kept in patch order for determinism.
    const auto tSplit = Clock::now();
    std::vector<std::vector<Piece>> perPatch(patches.size());
    std::atomic<uint64_t> splits{0}, pieceCulls{0}, patchesCulled{0};
    tbb::parallel_for(size_t(0), patches.size(), [&](size_t i) {
        // Ctrl-C during a long split: skip the remaining patches (the bucket loop then reports it).
        if (settings.cancel && settings.cancel->load(std::memory_order_relaxed)) return;
        SplitCounters c;
        float side = std::sqrt(std::max(scene.attributes[i].shadingRate, 1e-4f));
        splitPatch(view, uint32_t(i), side, perPatch[i], c);
        splits += c.splits;
        pieceCulls += c.culled;
        if (c.patchCulled) ++patchesCulled;
    });
    std::vector<Piece> pieces;
    for (auto& v : perPatch) pieces.insert(pieces.end(), v.begin(), v.end());
    perPatch.clear();
    perPatch.shrink_to_fit();
    const double splitMs = msSince(tSplit);

    // Bucket the pieces by their raster bound (grown by the filter radius): CSR lists in piece order.
    const int bs = std::max(4, settings.bucketSize);
    const int nbx = (W + bs - 1) / bs, nby = (H + bs - 1) / bs, nb = nbx * nby;
    auto bucketRange = [&](const Piece& p, int& bx0, int& by0, int& bx1, int& by1) {
        bx0 = std::clamp(int(std::floor((p.x0 - rx - 1) / bs)), 0, nbx - 1);
        bx1 = std::clamp(int(std::floor((p.x1 + rx + 1) / bs)), 0, nbx - 1);
        by0 = std::clamp(int(std::floor((p.y0 - ry - 1) / bs)), 0, nby - 1);
        by1 = std::clamp(int(std::floor((p.y1 + ry + 1) / bs)), 0, nby - 1);
    };
    std::vector<uint32_t> bucketStart(nb + 1, 0);
    for (const Piece& p : pieces) {
        int bx0, by0, bx1, by1;
        bucketRange(p, bx0, by0, bx1, by1);
        for (int by = by0; by <= by1; ++by)
            for (int bx = bx0; bx <= bx1; ++bx) ++bucketStart[by * nbx + bx + 1];
    }
    for (int b = 0; b < nb; ++b) bucketStart[b + 1] += bucketStart[b];
    std::vector<uint32_t> bucketPieces(bucketStart[nb]);
    std::vector<GridSlot> slots(pieces.size());
    {
        std::vector<uint32_t> fill(bucketStart.begin(), bucketStart.end() - 1);
        for (uint32_t pi = 0; pi < pieces.size(); ++pi) {
            int bx0, by0, bx1, by1;
            bucketRange(pieces[pi], bx0, by0, bx1, by1);
            for (int by = by0; by <= by1; ++by)
                for (int bx = bx0; bx <= bx1; ++bx) bucketPieces[fill[by * nbx + bx]++] = pi;
            slots[pi].refs.store((bx1 - bx0 + 1) * (by1 - by0 + 1), std::memory_order_relaxed);
        }
    }

    // Dice, shade, sample and filter, bucket by bucket. Workers take buckets in scanline order so the
    // grids alive at any moment are those near one row of buckets.
    tbb::enumerable_thread_specific<ThreadCounters> counters;
    std::atomic<int> nextBucket{0}, doneBuckets{0};
    std::atomic<bool> cancelled{false};
    const uint32_t seed = settings.seed;
    auto renderBucket = [&](int b, ThreadCounters& tc) {
        const int bx = b % nbx, by = b / nbx;
        Rect target{bx * bs, by * bs, std::min(W, (bx + 1) * bs), std::min(H, (by + 1) * bs)};
        Rect region{std::max(0, target.x0 - rx), std::max(0, target.y0 - ry), std::min(W, target.x1 + rx),
                    std::min(H, target.y1 + ry)};
        const uint32_t begin = bucketStart[b], end = bucketStart[b + 1];
        if (begin == end) {  // nothing here: the image is already transparent black
            return;
        }
        auto t0 = Clock::now();
        tc.tile.reset(region, nx, ny, seed, std::numeric_limits<float>::infinity(), settings.sampler);
        for (uint32_t k = begin; k < end; ++k) {
            const uint32_t pi = bucketPieces[k];
            GridSlot& slot = slots[pi];
            std::call_once(slot.once, [&] {
                auto td = Clock::now();
                const Piece& piece = pieces[pi];
                const PatchAttributes& attr = scene.attributes[piece.patch];
                ShadeInputs in{&scene.materials[attr.material], attr.twoSided, attr.flipNormal, lights};
                slot.grid = std::make_unique<Grid>();
                diceAndShade(view, piece, in, *slot.grid);
                ++tc.grids;
                tc.micropolygons += uint64_t(slot.grid->nu) * slot.grid->nv;
                tc.diceMs += msSince(td);
            });
            auto ts = Clock::now();
            tc.sampleTests += rasterizeGrid(*slot.grid, tc.tile, view.projector.nearClip);
            tc.sampleMs += msSince(ts);
            if (slot.refs.fetch_sub(1, std::memory_order_acq_rel) == 1) slot.grid.reset();
        }
        auto tf = Clock::now();
        reconstruct(tc.tile, filter, target, result.image);
        tc.filterMs += msSince(tf);
        (void)t0;
    };

    const auto tBuckets = Clock::now();
    const int workers = tbb::this_task_arena::max_concurrency();
    tbb::parallel_for(0, workers, [&](int) {
        ThreadCounters& tc = counters.local();
        for (;;) {
            if (settings.cancel && settings.cancel->load(std::memory_order_relaxed)) {
                cancelled = true;
                break;
            }
            int b = nextBucket.fetch_add(1);
            if (b >= nb) break;
            renderBucket(b, tc);
            int done = ++doneBuckets;
            if (settings.progress) settings.progress(done, nb);
        }
    }, tbb::static_partitioner());
    const double bucketMs = msSince(tBuckets);

    ThreadCounters total;
    for (const ThreadCounters& tc : counters) {
        total.grids += tc.grids;
        total.micropolygons += tc.micropolygons;
        total.sampleTests += tc.sampleTests;
        total.diceMs += tc.diceMs;
        total.sampleMs += tc.sampleMs;
        total.filterMs += tc.filterMs;
    }
    result.cancelled = cancelled.load();
    nlohmann::json& s = result.stats;
    s["engine"] = "reyes";
    s["patches_in"] = scene.patches.size();
    s["patches_culled"] = patchesCulled.load();
    s["pieces_culled"] = pieceCulls.load();
    s["splits"] = splits.load();
    s["welded_corners"] = weld.cornersMoved;
    s["welded_edges"] = weld.edgesWelded;
    s["pieces"] = pieces.size();
    s["grids"] = total.grids;
    s["micropolygons"] = total.micropolygons;
    s["sample_tests"] = total.sampleTests;
    s["buckets"] = nb;
    s["bucket_size"] = bs;
    s["stage_ms"] = {{"weld", weldMs},
                     {"split", splitMs},
                     {"buckets_wall", bucketMs},
                     {"dice_shade_cpu", total.diceMs},
                     {"sample_cpu", total.sampleMs},
                     {"filter_cpu", total.filterMs}};
    s["engine_ms"] = msSince(tStart);
    return result;
}

}  // namespace tessera
