// The prologue both engines share: the film set-up (filter, samples per pixel, region, image with its
// planes), the camera's projection and the lights in camera space.
#pragma once
#include <array>
#include <memory>
#include <vector>

#include "engine/clock.h"
#include "engine/motion.h"
#include "engine/settings.h"
#include "film/filter.h"
#include "shading/light.h"
#include "shading/texture.h"

namespace tessera {

// The lookups of the lights whose shadows are maps read from files (Light::shadowFiles), in the frame's
// shading space; ShadingLight::shadowMap points into it. The depths stay in the scene.
struct FileShadowMaps {
    std::vector<std::array<ShadowMapFace, 6>> faces;  // per light
    std::vector<ShadowMapLookup> lookups;             // per light (faceCount 0: none)
};

struct FrameSetup {
    EngineClock::time_point start;  // when the engine began (engine_ms)
    const Camera& camera;
    PixelFilter filter;
    int nx = 1, ny = 1;  // samples per pixel: nx x ny strata
    Rect region;         // raster pixels this render writes
    Projector projector;
    std::vector<ShadingLight> lights;  // camera space
    FrameMotion motion;                // the patches' camera-space motion over the shutter
    BlurPattern blur;                  // each sample's time and lens position (inactive: sharp frame)
    // The scene's textures (Scene::textures), opened for this render; nullptr when it has none.
    std::shared_ptr<const Textures> textures;
    std::shared_ptr<const FileShadowMaps> fileShadowMaps;  // what lights[l].shadowMap points into

    FrameSetup(const Scene& scene, const RenderSettings& settings);
    int samplesPerPixel() const { return nx * ny; }
    // An empty result whose image is the region, with the planes the output spec asks for.
    RenderResult startResult(const RenderSettings& settings) const;
    bool blurred() const { return blur.active(); }
    // Reset a tile for the samples of `pixels` with the output spec's channels (and their times and lens
    // positions when the frame blurs).
    void resetTile(SampleTile& tile, Rect pixels, const RenderSettings& settings) const;
};

// The "surfaces" statistic both engines report: the number of surfaces of each kind present, by name.
nlohmann::json surfaceKindStats(const Scene& scene);

}  // namespace tessera
