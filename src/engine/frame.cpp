#include "engine/frame.h"

#include <limits>

namespace tessera {

FrameSetup::FrameSetup(const Scene& scene, const RenderSettings& settings)
    : filter(makeFilter(scene.image)),
      nx(std::max(1, scene.image.pixelSamplesX)),
      ny(std::max(1, scene.image.pixelSamplesY)),
      region(renderRegion(scene.camera, settings)),
      projector(scene.camera) {
    for (const Light& l : scene.lights) lights.push_back(prepareLight(l, scene.camera.cameraFromWorld));
}

Image FrameSetup::makeImage(const RenderSettings& settings) const {
    Image img(region);
    img.addPlanes(settings.channels, settings.aovs);
    return img;
}

void FrameSetup::resetTile(SampleTile& tile, Rect pixels, const RenderSettings& settings) const {
    tile.reset(pixels, nx, ny, settings.seed, std::numeric_limits<float>::infinity(), settings.channels,
               settings.aovs);
}

}  // namespace tessera
