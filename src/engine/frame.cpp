#include "engine/frame.h"

#include <algorithm>
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
    auto files = std::make_shared<FileShadowMaps>();
    files->faces.resize(scene.lights.size());
    files->lookups.resize(scene.lights.size());
    const Mat4 worldFromShading = camera.cameraFromWorld.inverse();
    for (size_t i = 0; i < scene.lights.size(); ++i) {
        const Light& l = scene.lights[i];
        lights.push_back(prepareLight(l, camera.cameraFromWorld));
        ShadingLight& s = lights.back();
        s.castsShadows = lightCastsShadows(l, settings.shadows);
        if (s.castsShadows && l.shadowSource == ShadowSource::RayTraced) s.tracedShadows = true;
        if (!s.castsShadows || l.shadowSource != ShadowSource::File) continue;
        // A map read from a file: looked up by sampleLights, no visibility queries.
        s.castsShadows = false;
        ShadowMapLookup& lookup = files->lookups[i];
        const bool cube = l.type == LightType::Point;
        for (int f = 0; f < (cube ? 6 : 1); ++f) {
            ShadowMapFace& face = files->faces[i][size_t(f)];
            const int32_t index = l.shadowFiles[size_t(f)];
            if (index < 0 || size_t(index) >= scene.shadowMapFiles.size()) continue;  // an empty face: lit
            const ShadowMapFile& file = scene.shadowMapFiles[size_t(index)];
            // The reader checked the matrices (io/rib_reader.cpp); a face it could not read stays empty.
            if (fileShadowMapFace(file.worldToCamera, file.worldToNDC, file.width, file.height,
                                  worldFromShading, face)
                    .empty())
                face.depth = file.depth.data();
        }
        lookup.faces = files->faces[i].data();
        lookup.faceCount = cube ? 6 : 1;
        if (cube)
            lookup.cubeFromShading =
                affineFrameOf(Mat4::translate(-l.from.x, -l.from.y, -l.from.z) * worldFromShading);
        lookup.bias = std::max(l.shadowMap.bias, 0.f);
        lookup.filterWidth = std::clamp(l.shadowMap.filterWidth * l.shadowWidth, 1.f, 64.f);
        s.shadowMap = &lookup;
    }
    fileShadowMaps = std::move(files);
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
