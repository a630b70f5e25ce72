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

#include "engine/frame.h"
#include "engine/tile_loop.h"
#include "reyes/grid.h"
#include "reyes/rasterize.h"
#include "reyes/rasterize_blur.h"
#include "reyes/split.h"
#include "scene/weld.h"

namespace tessera {
namespace {

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
    BlurStrata strata;
};

}  // namespace

RenderResult renderReyes(const Scene& scene, const RenderSettings& settings,
                         const LightVisibility* visibility) {
    const FrameSetup frame(scene, settings);
    RenderResult result = frame.startResult(settings);
    const Camera& cam = frame.camera;
    for (const Material& m : scene.materials)
        if (surfaceHasTracedLobes(m.type)) {
            // Mirror and glass get their local terms here; the traced part needs the ray tracer.
            result.warnings.push_back(
                "the scene has mirror or glass surfaces: Reyes renders their highlights only; "
                "reflections and refractions need --engine rt");
            break;
        }

    bool shadows = false;
    for (const ShadingLight& l : frame.lights) shadows = shadows || l.castsShadows;
    if (shadows && !visibility)
        result.warnings.push_back(
            "Reyes has no shadow maps yet: lights that cast shadows light everything; "
            "use --reyes-shadows raytrace or --engine rt for shadows");

    // Bound: patches to camera space (affine: transform the control points).
    std::vector<BezierPatch> patches(scene.patches.size());
    tbb::parallel_for(size_t(0), patches.size(), [&](size_t i) {
        for (int k = 0; k < 16; ++k) patches[i].cp[k] = cam.cameraFromWorld.point(scene.patches[i].cp[k]);
    });
    // Shared edges must be bit-identical for crack-free dicing: weld what matches only up to rounding.
    const auto tWeld = EngineClock::now();
    const FrameMotion& motion = frame.motion;
    if (motion.blurred())
        for (size_t i = 0; i < patches.size(); ++i)
            if (motion.moving(i)) patches[i] = motion.patchKeys(i)[0];
    const float weldTolerance = defaultWeldTolerance(patches);
    WeldPlan weldPlan;
    const WeldResult weld = weldSharedEdges(patches, weldTolerance, motion.blurred() ? &weldPlan : nullptr);
    // Blurred frames: the patches at every other knot of the shutter timeline, with the same control points
    // identified as at knot 0 (so shared edges are bit-identical at every knot, and cheaply).
    std::vector<std::vector<BezierPatch>> knotArrays;
    uint64_t movingPatches = 0;
    if (motion.blurred()) {
        knotArrays.resize(motion.knotCount() - 1);
        tbb::parallel_for(1, motion.knotCount(), [&](int k) {
            std::vector<BezierPatch>& arr = knotArrays[k - 1];
            arr = patches;
            for (size_t i = 0; i < patches.size(); ++i)
                if (motion.moving(i)) arr[i] = motion.patchKeys(i)[k];
            applyWeldPlan(weldPlan, arr);
        });
        for (size_t i = 0; i < patches.size(); ++i) movingPatches += motion.moving(i);
    }
    const double weldMs = msSince(tWeld);

    ReyesView view(cam);
    view.patches = patches.data();
    view.projector = frame.projector;
    view.lens = frame.blur.lens;
    if (motion.blurred()) {
        view.knotPatches.push_back(patches.data());
        for (auto& arr : knotArrays) view.knotPatches.push_back(arr.data());
        view.moving = &motion.firstKey;
    }
    const bool blurred = frame.blurred();
    BlurRasterContext blurContext;
    blurContext.projector = &view.projector;
    blurContext.pattern = &frame.blur;
    blurContext.knots = &motion.knots;
    blurContext.strataBounds = settings.blur.strataBounds;
    const bool useStrata =
        blurred && frame.blur.scheme == BlurSampling::BoundingBox && settings.blur.strataBounds;
    view.maxGridEdge = std::max(1, settings.maxGridEdge);
    const int rx = frame.filter.radiusX(), ry = frame.filter.radiusY();
    const Rect& region = frame.region;
    view.cullX0 = float(region.x0 - rx - 1);
    view.cullY0 = float(region.y0 - ry - 1);
    view.cullX1 = float(region.x1 + rx + 1);
    view.cullY1 = float(region.y1 + ry + 1);

    // Split: every patch into diceable pieces, in parallel, kept in patch order for determinism.
    const auto tSplit = EngineClock::now();
    std::vector<std::vector<Piece>> perPatch(patches.size());
    std::atomic<uint64_t> splits{0}, pieceCulls{0}, patchesCulled{0};
    tbb::parallel_for(size_t(0), patches.size(), [&](size_t i) {
        // Ctrl-C during a long split: skip the remaining patches (the bucket loop then reports it).
        if (settings.cancel && settings.cancel->load(std::memory_order_relaxed)) return;
        SplitCounters c;
        float side = std::sqrt(std::max(scene.attributes[i].shadingRate, 1e-4f));
        splitSurface(view, scene.attributes[i], uint32_t(i), side, perPatch[i], c);
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
    const BucketLayout layout(region, std::max(4, settings.bucketSize));
    const int nb = layout.count();
    auto bucketRange = [&](const Piece& p, int& bx0, int& by0, int& bx1, int& by1) {
        layout.overlapped(p.x0 - rx - 1, p.y0 - ry - 1, p.x1 + rx + 1, p.y1 + ry + 1, bx0, by0, bx1, by1);
    };
    std::vector<uint32_t> bucketStart(nb + 1, 0);
    for (const Piece& p : pieces) {
        int bx0, by0, bx1, by1;
        bucketRange(p, bx0, by0, bx1, by1);
        for (int by = by0; by <= by1; ++by)
            for (int bx = bx0; bx <= bx1; ++bx) ++bucketStart[by * layout.countX + bx + 1];
    }
    for (int b = 0; b < nb; ++b) bucketStart[b + 1] += bucketStart[b];
    std::vector<uint32_t> bucketPieces(bucketStart[nb]);
    std::vector<GridSlot> slots(pieces.size());
    // Work per bucket for the progress: the micropolygons of its pieces, each piece shared among the
    // buckets it overlaps, plus the bucket's samples (filtering).
    std::vector<uint64_t> work(nb, 0);
    {
        std::vector<uint32_t> fill(bucketStart.begin(), bucketStart.end() - 1);
        for (uint32_t pi = 0; pi < pieces.size(); ++pi) {
            int bx0, by0, bx1, by1;
            bucketRange(pieces[pi], bx0, by0, bx1, by1);
            const int spanned = (bx1 - bx0 + 1) * (by1 - by0 + 1);
            const uint64_t share =
                uint64_t(pieceGridU(pieces[pi])) * uint64_t(pieceGridV(pieces[pi])) / uint64_t(spanned) + 1;
            for (int by = by0; by <= by1; ++by)
                for (int bx = bx0; bx <= bx1; ++bx) {
                    const int b = by * layout.countX + bx;
                    bucketPieces[fill[b]++] = pi;
                    work[b] += share;
                }
            slots[pi].refs.store(spanned, std::memory_order_relaxed);
        }
        for (int b = 0; b < nb; ++b) {
            const Rect t = layout.target(b);
            work[b] += uint64_t(t.width()) * t.height() * frame.samplesPerPixel() / 16 + 1;
        }
    }

    // Dice, shade, sample and filter, bucket by bucket. Workers take buckets in scanline order so the
    // grids alive at any moment are those near one row of buckets.
    tbb::enumerable_thread_specific<ThreadCounters> counters;
    auto renderBucket = [&](int b, ThreadCounters& tc) {
        const uint32_t begin = bucketStart[b], end = bucketStart[b + 1];
        if (begin == end) return;  // nothing here: the image is already transparent black
        const Rect target = layout.target(b);
        frame.resetTile(tc.tile, layout.samples(b, rx, ry, cam.width, cam.height), settings);
        if (useStrata) {
            tc.strata.configure(frame.blur);
            tc.strata.build(tc.tile);
        }
        for (uint32_t k = begin; k < end; ++k) {
            const uint32_t pi = bucketPieces[k];
            GridSlot& slot = slots[pi];
            std::call_once(slot.once, [&] {
                auto td = EngineClock::now();
                const Piece& piece = pieces[pi];
                const PatchAttributes& attr = scene.attributes[piece.patch];
                ShadeInputs in{attr.kind,
                               &scene.materials[attr.material],
                               attr.twoSided,
                               attr.flipNormal,
                               frame.lights,
                               attr.object,
                               (settings.output.channels & kChannelNormal) != 0,
                               visibility};
                slot.grid = std::make_unique<Grid>();
                diceAndShade(view, piece, in, *slot.grid);
                ++tc.grids;
                tc.micropolygons += uint64_t(slot.grid->nu) * slot.grid->nv;
                tc.diceMs += msSince(td);
            });
            auto ts = EngineClock::now();
            tc.sampleTests += slot.grid->blurred
                                  ? rasterizeBlurredGrid(*slot.grid, tc.tile, view.projector.nearClip,
                                                         blurContext, tc.strata)
                                  : rasterizeGrid(*slot.grid, tc.tile, view.projector.nearClip);
            tc.sampleMs += msSince(ts);
            if (slot.refs.fetch_sub(1, std::memory_order_acq_rel) == 1) slot.grid.reset();
        }
        auto tf = EngineClock::now();
        reconstruct(tc.tile, frame.filter, target, result.image);
        tc.filterMs += msSince(tf);
    };
    const TileLoopResult loop = runTileLoop(layout, work, settings, counters, renderBucket);

    ThreadCounters total;
    for (const ThreadCounters& tc : counters) {
        total.grids += tc.grids;
        total.micropolygons += tc.micropolygons;
        total.sampleTests += tc.sampleTests;
        total.diceMs += tc.diceMs;
        total.sampleMs += tc.sampleMs;
        total.filterMs += tc.filterMs;
    }
    result.cancelled = loop.cancelled;
    nlohmann::json& s = result.stats;
    s["engine"] = "reyes";
    s["patches_in"] = scene.patches.size();
    s["patches_culled"] = patchesCulled.load();
    s["pieces_culled"] = pieceCulls.load();
    s["splits"] = splits.load();
    s["welded_corners"] = weld.cornersMoved;
    s["welded_edges"] = weld.edgesWelded;
    if (blurred)
        s["blur"] = {{"sampling", blurSamplingName(frame.blur.scheme)},
                     {"motion", frame.blur.motion},
                     {"lens", frame.blur.lens},
                     {"knots", motion.knotCount()},
                     {"moving_patches", movingPatches},
                     {"strata_bounds", useStrata}};
    s["pieces"] = pieces.size();
    s["grids"] = total.grids;
    s["micropolygons"] = total.micropolygons;
    s["sample_tests"] = total.sampleTests;
    writeTileLoopStats(layout, loop, s);
    s["stage_ms"] = {{"weld", weldMs},
                     {"split", splitMs},
                     {"buckets_wall", loop.wallMs},
                     {"dice_shade_cpu", total.diceMs},
                     {"sample_cpu", total.sampleMs},
                     {"filter_cpu", total.filterMs}};
    if (shadows && visibility) visibility->writeStats(s["shadows"]);
    s["engine_ms"] = msSince(frame.start);
    return result;
}

}  // namespace tessera
