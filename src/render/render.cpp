#include "render/render.h"

#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <stdexcept>

#include "engine/clock.h"
#include "render/displaced_dicer.h"
#include "reyes/reyes_renderer.h"
#include "rt/ray_visibility.h"
#include "rt/rt_renderer.h"

namespace tessera {
namespace {

bool anyDisplaced(const Scene& scene) {
    for (const PatchAttributes& a : scene.attributes)
        if (a.displacement >= 0) return true;
    return false;
}

// Reyes with --reyes-shadows raytrace: the ray tracer's accel over the scene in the camera space Reyes
// shades in (at shutter open, where Reyes shades moving geometry), and its shadow rays as Reyes' answers
// to the visibility queries of the lights that cast shadows.
// Displaced patches are traced as the micro-grids Reyes dices (render/displaced_dicer.h), so the shadows
// are those of the displaced surfaces.
RenderResult renderReyesWithRayTracedShadows(const Scene& scene, const RenderSettings& settings) {
    const auto t0 = EngineClock::now();
    RtAccel acc;
    RtDisplacementOptions displacement;
    if (anyDisplaced(scene))
        displacement.dicer = makeReyesDisplacedDicer(scene, settings, FrameSetup(scene, settings));
    displacement.budgetBytes = size_t(std::max(1, settings.displacementCacheMb)) << 20;
    // Shadow rays start at the micropolygons' vertices: about one per pixel at shading rate 1, which the
    // auto depth takes as its samples per pixel.
    const Camera& cam = viewCamera(scene, settings);
    const int subpatchDepth = resolveSubpatchDepth(settings.subpatchDepth, scene, cam, 1.0);
    buildRtAccel(scene, cam.cameraFromWorld, subpatchDepth, false, acc, nullptr, kDefaultTimeSlabs,
                 &displacement, settings.instancing);
    const double buildMs = msSince(t0);
    // Per-ray traversal: a grid's lists of shadow rays are too short for the shadow binning to pay.
    const RayTracedVisibility visibility(acc, rt::TraceServiceOptions{false, false});
    RenderResult result = renderReyes(scene, settings, &visibility);
    result.stats["shadows"]["accel_build_ms"] = buildMs;
    return result;
}

// Whether Reyes needs the ray tracer's shadow rays: for every light that casts shadows under
// --reyes-shadows raytrace, and for the lights whose shadowname is "raytrace" always.
bool reyesTracesShadows(const Scene& scene, const RenderSettings& settings) {
    for (const Light& l : scene.lights) {
        if (!lightCastsShadows(l, settings.shadows)) continue;
        if (l.shadowSource == ShadowSource::RayTraced) return true;
        if (settings.reyesShadows == ReyesShadows::Raytrace && l.shadowSource != ShadowSource::File)
            return true;
    }
    return false;
}

}  // namespace

RenderResult render(const Scene& scene, const RenderSettings& settings) {
    if (settings.adaptive.enabled && settings.engine != "rt")
        throw std::invalid_argument("--adaptive is ray traced: use it with --engine rt");
    int threads = settings.threads > 0 ? settings.threads : tbb::info::default_concurrency();
    tbb::task_arena arena(threads);
    RenderResult result;
    arena.execute([&] {
        if (settings.engine == "reyes") {
            if (reyesTracesShadows(scene, settings))
                result = renderReyesWithRayTracedShadows(scene, settings);
            else
                result = renderReyes(scene, settings);
        } else if (settings.engine == "rt") {
            // Displaced patches: micro-grids diced by Reyes' code (render/displaced_dicer.h).
            const DisplacedDicerFactory dicer = [&](const FrameSetup& frame) {
                return makeReyesDisplacedDicer(scene, settings, frame);
            };
            result = renderRt(scene, settings, &dicer);
        } else {
            throw std::invalid_argument("unknown engine '" + settings.engine + "' (use reyes or rt)");
        }
    });
    // RI Imager "background": Ci += (1 - alpha) * background, alpha = 1 (premultiplied colour), on the
    // pixels the engines wrote; the attribute planes are left as rendered.
    if (scene.image.hasBackground) {
        Image& img = result.image;
        const Color bg = scene.image.background;
        for (int y = img.y0; y < img.y0 + img.height; ++y)
            for (int x = img.x0; x < img.x0 + img.width; ++x) {
                float* p = img.pixel(x, y);
                const float open = 1.f - p[3];
                p[0] += open * bg.x, p[1] += open * bg.y, p[2] += open * bg.z, p[3] = 1.f;
            }
        result.stats["background"] = {bg.x, bg.y, bg.z};
    }
    result.stats["threads"] = threads;
    const Camera& cam = viewCamera(scene, settings);
    result.stats["width"] = cam.width;
    result.stats["height"] = cam.height;
    result.stats["spp"] = scene.image.pixelSamplesX * scene.image.pixelSamplesY;
    return result;
}

}  // namespace tessera
