#include "engine/frame.h"

#include <limits>

namespace tessera {

FrameSetup::FrameSetup(const Scene& scene, const RenderSettings& settings)
    : start(EngineClock::now()),
      camera(viewCamera(scene, settings)),
      filter(makeFilter(scene.image)),
      nx(std::max(1, scene.image.pixelSamplesX)),
      ny(std::max(1, scene.image.pixelSamplesY)),
      region(renderRegion(camera, settings)),
      projector(camera) {
    for (const Light& l : scene.lights) {
        lights.push_back(prepareLight(l, camera.cameraFromWorld));
        lights.back().castsShadows = lightCastsShadows(l, settings.shadows);
    }
    if (!settings.blur.enabled) projector.lensRadius = 0.f;  // --no-blur: pinhole
    motion = prepareFrameMotion(scene, camera, settings.blur.enabled);
    blur = makeBlurPattern(settings.blur.sampling, motion.blurred(),
                           projector.hasLens() && projector.perspective, nx * ny, camera.width,
                           settings.blur.tileSize, settings.blur.permutations, settings.seed);
    if (!scene.textures.empty()) textures = std::make_shared<const Textures>(scene.textures);
}

RenderResult FrameSetup::startResult(const RenderSettings& settings) const {
    RenderResult result;
    result.image = Image(region);
    result.image.addPlanes(settings.output.channels, settings.output.aovs);
    return result;
}

void FrameSetup::resetTile(SampleTile& tile, Rect pixels, const RenderSettings& settings) const {
    tile.reset(pixels, nx, ny, settings.seed, std::numeric_limits<float>::infinity(), settings.sampler,
               settings.output.channels, settings.output.aovs);
    tile.setBlur(blurred() ? &blur : nullptr);
}

nlohmann::json surfaceKindStats(const Scene& scene) {
    nlohmann::json kinds = nlohmann::json::object();
    const auto kindCount = surfaceKindCounts(scene);
    for (int k = 0; k < kSurfaceKinds; ++k)
        if (kindCount[k]) kinds[surfaceKindName(SurfaceKind(k))] = kindCount[k];
    return kinds;
}

}  // namespace tessera
