#include "render/render.h"

#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <stdexcept>

#include "reyes/reyes_renderer.h"
#include "rt/rt_renderer.h"

namespace tessera {

RenderResult render(const Scene& scene, const RenderSettings& settings) {
    int threads = settings.threads > 0 ? settings.threads : tbb::info::default_concurrency();
    tbb::task_arena arena(threads);
    RenderResult result;
    arena.execute([&] {
        if (settings.engine == "reyes") {
            result = renderReyes(scene, settings);
        } else if (settings.engine == "rt") {
            result = renderRt(scene, settings);
        } else {
            throw std::invalid_argument("unknown engine '" + settings.engine + "' (use reyes or rt)");
        }
    });
    result.stats["threads"] = threads;
    const Camera& cam = viewCamera(scene, settings);
    result.stats["width"] = cam.width;
    result.stats["height"] = cam.height;
    result.stats["spp"] = scene.image.pixelSamplesX * scene.image.pixelSamplesY;
    return result;
}

}  // namespace tessera
