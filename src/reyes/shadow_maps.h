// Shadow maps rendered by the Reyes pipeline (paper 001 sec. 3.5: "interleave passes computing a shadow map
// by reyes rendering from the light position ... only split, dice and sample; there is no need to shade and
// composite"): for every light that casts shadows, before the frame's own pass, a depth pass of the
// scene from the light through the same split, dice and sample stages (reyes/pipeline.h), one sample at
// each texel's centre, nearest depth. Distant lights get an orthographic map fitted to the scene's bound,
// spot lights a perspective one around their cone (a cube map when the cone is wider than 60 degrees),
// point lights a cube map of six faces. The maps are rendered once per light and frame and answer the
// frame's visibility queries with percentage-closer filtered lookups (shading/shadow_map.h).
// With RenderSettings::shadowMapCacheDir, a map is first looked for in that folder under a key of the
// scene (the app's key and the surfaces' control points), the light's view and the map's parameters, and
// written there after it is rendered: the tiles of a farm render the maps once instead of once each.
#pragma once
#include <atomic>
#include <memory>
#include <span>
#include <vector>

#include "core/buffer_allocator.h"
#include "engine/settings.h"
#include "engine/visibility.h"
#include "shading/shadow_map.h"
#include "shading/texture.h"

namespace tessera {

// A depth pass: what was rendered and how long it took.
struct DepthPassStats {
    uint64_t pieces = 0, grids = 0, micropolygons = 0, sampleTests = 0;
    double ms = 0;
};

// Renders the depth map seen by `lightCamera` (a square image of lightCamera.width texels): the scene's
// patches at shutter open, split and diced at `shadingRate` texels of area per micropolygon, both sides,
// nearest depth at each texel centre (infinity where nothing is seen). Row-major, top row first.
// `textures`: the frame's (displacement textures; nullptr: none). A 2048 x 2048 map is 16 MB: on huge
// pages, each texel written once by its bucket (a serial fill and its 4 KB faults were 46 ms of Killeroo's
// 160 ms map).
using DepthBuffer = std::vector<float, DefaultInitAllocator<float>>;
DepthBuffer renderDepthMap(const Scene& scene, const Camera& lightCamera, float shadingRate,
                           const RenderSettings& settings, DepthPassStats& stats,
                           const Textures* textures = nullptr);

class ShadowMaps final : public LightVisibility {
  public:
    // Renders the maps of the lights whose ShadingLight casts shadows (`lights`: the frame's lights, in the
    // order of scene.lights), for lookups from `shadingCamera`'s camera space. Lights whose shadows are
    // ray traced (ShadingLight::tracedShadows) get no map: `rays` answers their queries.
    ShadowMaps(const Scene& scene, const RenderSettings& settings, const Camera& shadingCamera,
               std::span<const ShadingLight> lights, const Textures* textures = nullptr,
               const LightVisibility* rays = nullptr);
    void answer(const VisibilityQuery& query, LightSamples& samples) const override;
    void writeStats(nlohmann::json& shadows) const override;

    // Visibility of light `light` at shading-space point P with normal N (1 for a light without a map).
    float visibility(size_t light, Vec3 P, Vec3 N) const;
    // The map of a light (nullptr: it casts no shadows), for tests and tools.
    const ShadowMapLookup* lookup(size_t light) const;
    double renderMs() const { return renderMs_; }

  private:
    struct Map {
        LightType type;
        std::vector<DepthBuffer> depth;  // per face
        std::vector<ShadowMapFace> faces;
        ShadowMapLookup lookup;
        ShadowMapParams params;
        float texelWorld = 0;  // orthographic maps: the world size of a texel
        DepthPassStats stats;
    };
    std::vector<std::unique_ptr<Map>> maps_;  // per light
    const LightVisibility* rays_ = nullptr;
    double renderMs_ = 0;
    std::string cacheDir_;
    uint64_t cacheHits_ = 0, cacheMisses_ = 0, cacheWriteFailures_ = 0;
    mutable std::atomic<uint64_t> lookups_{0};
};

}  // namespace tessera
