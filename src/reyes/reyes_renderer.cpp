#include "reyes/reyes_renderer.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <memory>

#include "engine/frame.h"
#include "engine/tile_loop.h"
#include "reyes/displace.h"
#include "reyes/grid.h"
#include "reyes/pipeline.h"
#include "reyes/rasterize.h"
#include "reyes/rasterize_blur.h"
#include "reyes/shadow_maps.h"
#include "reyes/split.h"
#include "scene/weld.h"

namespace tessera {
namespace {

struct ThreadCounters {
    uint64_t grids = 0, micropolygons = 0, gridVertices = 0, sampleTests = 0;
    uint64_t emptySamples = 0, emptyPixels = 0, nearestFallbackGrids = 0;
    // Displaced grids: their micropolygons, the sum of each one's longest side and the longest (pixels).
    uint64_t displacedMicropolygons = 0;
    double displacedSideSum = 0;
    float displacedSideMax = 0.f;
    double setupMs = 0, diceMs = 0, sampleMs = 0, filterMs = 0;  // per thread, summed
    SampleTile tile;
    BlurStrata strata;
};

// Counts the samples of `target` that no micropolygon covered, and the pixels none of whose samples was.
void countEmpty(const SampleTile& tile, const Rect& target, uint64_t& samples, uint64_t& pixels) {
    const int tw = tile.region.width();
    for (int y = target.y0; y < target.y1; ++y)
        for (int x = target.x0; x < target.x1; ++x) {
            const size_t pix = size_t(y - tile.region.y0) * tw + size_t(x - tile.region.x0);
            int empty = 0;
            for (int k = 0; k < tile.spp; ++k) empty += tile.a[pix * tile.spp + size_t(k)] == 0.f;
            samples += uint64_t(empty);
            pixels += empty == tile.spp;
        }
}

// Screen size of a grid's micropolygons: per micropolygon its longest side in pixels, summed into `sum`,
// the largest into `largest`.
void micropolygonSides(const Grid& g, double& sum, float& largest) {
    const int stride = g.nu + 1;
    auto len2 = [&](int p, int q) {
        const int64_t dx = int64_t(g.X[p]) - g.X[q], dy = int64_t(g.Y[p]) - g.Y[q];
        return dx * dx + dy * dy;
    };
    for (int j = 0; j < g.nv; ++j)
        for (int i = 0; i < g.nu; ++i) {
            const int a = j * stride + i, b = a + 1, c = a + stride + 1, d = a + stride;
            const float side =
                std::sqrt(float(std::max({len2(a, b), len2(b, c), len2(c, d), len2(d, a)}))) / kSubpixelScale;
            sum += side;
            largest = std::max(largest, side);
        }
}

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
                "the scene has mirror, glass or glossy surfaces: Reyes renders their highlights only; "
                "reflections and refractions need --engine rt");
            break;
        }

    for (const Light& l : scene.lights)
        if (l.type == LightType::Area) {
            result.warnings.push_back(
                "the scene has area lights: Reyes shows their surfaces but does not light with them; "
                "their light and soft shadows need --engine rt");
            break;
        }

    // Shadows: the caller's shadow rays (`visibility`) answer every light under --reyes-shadows raytrace
    // and the lights whose shadows are ray traced whatever the engine (tracedShadows); the others get a
    // shadow map each, rendered now by this pipeline from the light (once per light and frame, before the
    // frame's buckets). Maps read from files are looked up in sampleLights and ask nothing.
    bool shadows = false, maps = false;
    for (const ShadingLight& l : frame.lights) {
        shadows = shadows || l.castsShadows;
        maps = maps || (l.castsShadows && !l.tracedShadows);
    }
    std::unique_ptr<ShadowMaps> shadowMaps;
    if (maps && (settings.reyesShadows == ReyesShadows::Map || !visibility)) {
        shadowMaps = std::make_unique<ShadowMaps>(scene, settings, cam, frame.lights, frame.textures.get(),
                                                  visibility);
        visibility = shadowMaps.get();
    }

    // Bound: patches to camera space (affine: transform the control points).
    PatchArray patches = patchesInCameraSpace(scene, cam.cameraFromWorld);
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
    std::vector<PatchArray> knotArrays;
    uint64_t movingPatches = 0;
    if (motion.blurred()) {
        knotArrays.resize(motion.knotCount() - 1);
        tbb::parallel_for(1, motion.knotCount(), [&](int k) {
            PatchArray& arr = knotArrays[k - 1];
            arr = patches;
            for (size_t i = 0; i < patches.size(); ++i)
                if (motion.moving(i)) arr[i] = motion.patchKeys(i)[k];
            applyWeldPlan(weldPlan, arr);
        });
        for (size_t i = 0; i < patches.size(); ++i) movingPatches += motion.moving(i);
    }
    const double weldMs = msSince(tWeld);

    const std::vector<PlacedQuadric> quadrics = quadricsInSpace(scene, cam.cameraFromWorld);
    const std::vector<PatchVertexValues> vertexValues = vertexValuesInSpace(scene, cam.cameraFromWorld);
    ReyesView view(cam);
    view.patches = patches.data();
    view.quadrics = quadrics.data();
    view.projector = frame.projector;
    // Displacement (reyes/displace.h): per-patch bounds and the shared points of displaced patches.
    const DisplacementFrame displacement =
        makeDisplacementFrame(scene, frame.textures.get(), patches, float(cam.cameraFromWorld.maxStretch()));
    if (displacement.any()) view.displacement = &displacement;
    view.displacementSplit = settings.displacementSplit;
    view.exactDisplacementNormals = settings.exactDisplacementNormals;
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
    const bool useStrata = blurred && blurUsesStrata(frame.blur.scheme, settings.blur.strataBounds);
    view.maxGridEdge = std::max(1, settings.maxGridEdge);
    const int rx = frame.filter.radiusX(), ry = frame.filter.radiusY();
    const Rect& region = frame.region;
    view.cullX0 = float(region.x0 - rx - 1);
    view.cullY0 = float(region.y0 - ry - 1);
    view.cullX1 = float(region.x1 + rx + 1);
    view.cullY1 = float(region.y1 + ry + 1);

    // Bin every surface by its root bound; each is split when its first bucket comes up and freed after its
    // last (LazyPieces), so only the pieces near the buckets in flight are alive.
    const auto tBin = EngineClock::now();
    const BucketLayout layout(region, std::max(4, settings.bucketSize));
    LazyPieces pieces(view, scene, 0.f, layout, rx + 1, ry + 1, frame.samplesPerPixel());
    const double binMs = msSince(tBin);

    const bool nearest = settings.micropolygonSampling == MicropolygonSampling::Nearest;
    // Dice, shade, sample and filter, bucket by bucket. Workers take buckets in scanline order so the
    // grids alive at any moment are those near one row of buckets.
    tbb::enumerable_thread_specific<ThreadCounters> counters;
    auto renderBucket = [&](int b, ThreadCounters& tc) {
        const Rect target = layout.target(b);
        bool started = false;  // a bucket no piece reaches stays transparent black, untouched
        auto dice = [&](const Piece& piece, Grid& g) {
            auto td = EngineClock::now();
            const PatchAttributes& attr = scene.attributes[piece.patch];
            ShadeInputs in{attr.kind,
                           &scene.materials[attr.material],
                           attr.twoSided,
                           attr.flipNormal,
                           frame.lights,
                           attr.object,
                           (settings.output.channels & kChannelNormal) != 0,
                           visibility,
                           false,
                           (settings.output.channels & kChannelShadowCount) != 0,
                           quadricOf(view, attr)};
            in.wantSurfaceAovs = (settings.output.channels & kSurfaceAovChannels) != 0;
            in.textures = frame.textures.get();
            in.texCoords = texCoordsOf(scene, piece.patch);
            if (attr.vertexValues >= 0) in.vertexValues = &vertexValues[size_t(attr.vertexValues)];
            in.textureScale = std::max(1.f, std::sqrt(attr.shadingRate));
            if (attr.areaLight >= 0 && size_t(attr.areaLight) < scene.lights.size())
                in.emission = scene.lights[size_t(attr.areaLight)].color;
            diceAndShade(view, piece, in, g);
            ++tc.grids;
            tc.micropolygons += uint64_t(g.nu) * g.nv;
            tc.gridVertices += uint64_t(g.vertexCount());
            if (displacement.displaced(piece.patch)) {
                tc.displacedMicropolygons += uint64_t(g.nu) * g.nv;
                micropolygonSides(g, tc.displacedSideSum, tc.displacedSideMax);
            }
            tc.diceMs += msSince(td);
        };
        pieces.forEach(b, dice, [&](const Piece&, const Grid& grid) {
            if (!started) {
                const auto tt = EngineClock::now();
                tc.tile.deferPixelFill = true;  // every pixel-order access below follows leaveStrataOrder
                frame.resetTile(tc.tile, layout.samples(b, rx, ry, cam.width, cam.height), settings);
                if (useStrata) {
                    tc.strata.configure(frame.blur, motion.knots);
                    tc.strata.build(tc.tile);
                }
                tc.setupMs += msSince(tt);
                started = true;
            }
            auto ts = EngineClock::now();
            if (grid.blurred) {
                // The nearest-neighbour sampler has no moving form: blurred grids keep the bounding box.
                tc.nearestFallbackGrids += nearest;
                tc.sampleTests +=
                    rasterizeBlurredGrid(grid, tc.tile, view.projector.nearClip, blurContext, tc.strata);
            } else {
                tc.sampleTests += nearest ? rasterizeGridNearest(grid, tc.tile, view.projector.nearClip)
                                          : rasterizeGrid(grid, tc.tile, view.projector.nearClip);
            }
            tc.sampleMs += msSince(ts);
        });
        if (!started) return;
        tc.tile.leaveStrataOrder();  // the rasterizer's stratum-ordered samples back into pixel order
        countEmpty(tc.tile, target, tc.emptySamples, tc.emptyPixels);
        auto tf = EngineClock::now();
        reconstruct(tc.tile, frame.filter, target, result.image);
        tc.filterMs += msSince(tf);
    };
    const TileLoopResult loop =
        runTileLoop(layout, pieces.work(), settings, counters, renderBucket, &result.image);

    const SplitStats splitStats = pieces.stats();
    ThreadCounters total;
    for (const ThreadCounters& tc : counters) {
        total.grids += tc.grids;
        total.micropolygons += tc.micropolygons;
        total.gridVertices += tc.gridVertices;
        total.emptySamples += tc.emptySamples;
        total.emptyPixels += tc.emptyPixels;
        total.nearestFallbackGrids += tc.nearestFallbackGrids;
        total.displacedMicropolygons += tc.displacedMicropolygons;
        total.displacedSideSum += tc.displacedSideSum;
        total.displacedSideMax = std::max(total.displacedSideMax, tc.displacedSideMax);
        total.sampleTests += tc.sampleTests;
        total.setupMs += tc.setupMs;
        total.diceMs += tc.diceMs;
        total.sampleMs += tc.sampleMs;
        total.filterMs += tc.filterMs;
    }
    result.cancelled = loop.cancelled;
    nlohmann::json& s = result.stats;
    s["engine"] = "reyes";
    s["patches_in"] = scene.patches.size();  // surfaces of every kind
    s["surfaces"] = surfaceKindStats(scene);
    s["patches_culled"] = splitStats.patchesCulled;
    s["pieces_culled"] = splitStats.pieceCulls;
    s["splits"] = splitStats.splits;
    s["welded_corners"] = weld.cornersMoved;
    s["welded_edges"] = weld.edgesWelded;
    if (blurred)
        s["blur"] = {{"sampling", blurSamplingName(frame.blur.scheme)},
                     {"motion", frame.blur.motion},
                     {"lens", frame.blur.lens},
                     {"knots", motion.knotCount()},
                     {"moving_patches", movingPatches},
                     {"strata_bounds", useStrata}};
    s["pieces"] = pieces.pieceCount();
    // Split on demand: the most pieces alive at once (their grids are freed with them), against the frame's.
    s["pieces_peak"] = pieces.peakPieces();
    s["grids"] = total.grids;
    s["micropolygons"] = total.micropolygons;
    s["grid_vertices"] = total.gridVertices;
    s["sample_tests"] = total.sampleTests;
    // Holes of the sampler (paper 000 sec. 4.2): film samples and pixels of the rendered region that no
    // micropolygon covers (of a closed scene that fills the frame, all of them are holes).
    s["micropolygon_sampling"] = micropolygonSamplingName(settings.micropolygonSampling);
    s["empty_samples"] = total.emptySamples;
    s["empty_pixels"] = total.emptyPixels;
    if (nearest) s["nearest_fallback_grids"] = total.nearestFallbackGrids;
    if (displacement.any())
        s["displaced"] = {
            {"micropolygons", total.displacedMicropolygons},
            {"mean_longest_side_px", total.displacedMicropolygons
                                         ? total.displacedSideSum / double(total.displacedMicropolygons)
                                         : 0.0},
            {"max_longest_side_px", total.displacedSideMax},
            {"split_threshold", view.displacementSplit}};
    writeTileLoopStats(layout, loop, s);
    s["stage_ms"] = {{"shadow_maps", shadowMaps ? shadowMaps->renderMs() : 0.0},
                     {"weld", weldMs},
                     {"bin", binMs},
                     {"split_cpu", pieces.splitCpuMs()},
                     {"buckets_wall", loop.wallMs},
                     {"tile_setup_cpu", total.setupMs},
                     {"dice_shade_cpu", total.diceMs},
                     {"sample_cpu", total.sampleMs},
                     {"filter_cpu", total.filterMs}};
    if (shadows && visibility) visibility->writeStats(s["shadows"]);
    s["engine_ms"] = msSince(frame.start);
    return result;
}

}  // namespace tessera
