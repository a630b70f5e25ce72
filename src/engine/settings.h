// What every engine takes and gives: the settings of a render, the view (camera and film region), the
// output spec (channels wanted) and the result. Below both engines; the dispatcher (src/render) sits above.
#pragma once
#include <atomic>
#include <cstdint>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "film/adaptive.h"
#include "film/blur_pattern.h"
#include "film/film.h"
#include "scene/scene.h"
#include "shading/gloss.h"

namespace tessera {

// What a render looks at: a camera (nullptr: the scene's; a shadow-map pass gives the light's) and the film
// region to render (crop window, farm tile): a half-open raster rectangle, empty = the whole image.
struct RenderView {
    const Camera* camera = nullptr;
    Rect region;
};

// What a render writes: the film's attribute channels (FilmChannel bits) and further AOVs; each becomes an
// image plane of the result.
struct OutputSpec {
    uint32_t channels = 0;
    std::vector<std::string> aovs;
};

// Motion blur and depth of field (docs/motion.md): whether to render them, and how camera samples are
// spread over time and the lens (film/blur_pattern.h).
struct BlurSettings {
    bool enabled = true;  // false (--no-blur): pinhole camera, everything at shutter open
    BlurSampling sampling = BlurSampling::BoundingBox;
    int tileSize = 4;       // interleaved: K
    int permutations = 64;  // interleaved: P
    // Reyes, bounding-box scheme: cut a micropolygon's blurred bound by time and lens strata so that each
    // piece is tested only against the samples whose (t, lens) lie in its stratum (same hits, fewer
    // tests); the interleaved scheme's samples are rasterized the same way (same hits as moving the grid
    // once per tile sample, about 5x faster). Off: the paper's single extended bound and per-pass
    // interleaving (for the benchmarks).
    bool strataBounds = true;
};

// What the ray tracer computes for a camera sample (docs/light_transport.md): `Direct` is the
// Whitted-style integrator (lights with shadow rays, mirror and glass lobes); `AmbientOcclusion` the
// unoccluded fraction of the hemisphere at the first hit, as a grey image; `Path` the unidirectional path
// tracer (next-event estimation with multiple importance sampling at every bounce, Russian roulette).
enum class Integrator : uint8_t { Direct, AmbientOcclusion, Path };
inline const char* integratorName(Integrator i) {
    return i == Integrator::AmbientOcclusion ? "ao" : i == Integrator::Path ? "path" : "direct";
}

// Ambient occlusion (paper 002, sec. 5.3.1): O = (1/pi) integral of V(w) cos(theta) over the hemisphere.
struct AmbientOcclusionSettings {
    int samples = 64;                                            // hemisphere rays per camera hit
    float maxDistance = std::numeric_limits<float>::infinity();  // occluders farther away do not count
    // Paper 002's variant: uniform directions (cos theta = the second random number), each weighted by its
    // cosine, and a ray's shade attenuated by its hit distance (t / maxDistance) instead of 0 or 1. Off:
    // cosine-weighted directions and binary visibility (lower variance for the same integral).
    bool paperWeighting = false;
};

// Selective and adaptive supersampling (paper 004; docs/adaptive.md), ray tracer only: one presample ray
// per pixel centre, the subpixel test on its colour and primary-hit attributes, four stratified rays per
// active subpixel. Replaces the scene's PixelSamples and pixel filter for the colour (the paper's box
// weighting per pixel); the attribute planes come from the presample.
struct AdaptiveSettings {
    bool enabled = false;  // --adaptive
    AdaptiveThresholds thresholds;
    // --adaptive-focus: the paper's "fairy focused" mode (L209): the attributes count only where one of
    // these objects (PatchAttributes::object, the id AOV) is the pixel's or a neighbour's, primary or
    // secondary hit; elsewhere the colour alone decides. Empty: everywhere.
    std::vector<uint32_t> focusObjects;
    // --adaptive-interpolate: inactive subpixels take the bilinear interpolation of the presample colours
    // at their centres instead of the pixel's centre colour (the paper's option, L215).
    bool interpolate = false;
};

// Which lights cast shadows (--shadows): each light's own choice (Light::castsShadows, from the RIB's
// Attribute "light" "shadows"), or all of them, or none. The same rule for both engines.
enum class ShadowOverride { Scene, On, Off };

inline bool lightCastsShadows(const Light& light, ShadowOverride o) {
    if (light.type == LightType::Ambient) return false;
    return o == ShadowOverride::Scene ? light.castsShadows : o == ShadowOverride::On;
}
inline const char* shadowOverrideName(ShadowOverride o) {
    return o == ShadowOverride::On ? "on" : o == ShadowOverride::Off ? "off" : "scene";
}

// How Reyes answers the visibility queries of lights that cast shadows (--reyes-shadows): its own shadow
// maps, or shadow rays from the ray tracer's trace service (to check a Reyes image against the ray tracer's).
enum class ReyesShadows { Map, Raytrace };
inline const char* reyesShadowsName(ReyesShadows m) {
    return m == ReyesShadows::Raytrace ? "raytrace" : "map";
}

// How Reyes samples the micropolygons of unblurred grids (--micropolygon-sampling; paper 000 sec. 3.2):
// every film sample inside a micropolygon's bounding box is tested (BoundingBox), or only the one sample
// nearest its middle point (Nearest: the paper's nearest-neighbour sampler, which leaves holes where a
// micropolygon covers more than one sample; kept to measure them, docs/textures.md). Blurred grids and
// shadow-map passes always use the bounding box.
enum class MicropolygonSampling : uint8_t { BoundingBox, Nearest };
inline const char* micropolygonSamplingName(MicropolygonSampling m) {
    return m == MicropolygonSampling::Nearest ? "nearest" : "bbox";
}

// RenderSettings::subpatchDepth: the ray tracer picks the depth per frame (autoSubpatchDepth, rt/accel.h).
constexpr int kAutoSubpatchDepth = -1;

struct RenderSettings {
    std::string engine = "reyes";  // "reyes" or "rt"
    int threads = 0;               // 0: all hardware threads
    uint32_t seed = 0;             // sample pattern seed
    int bucketSize = 32;           // pixels per bucket side
    int maxGridEdge = 16;          // Reyes: micropolygons per grid edge before splitting
    MicropolygonSampling micropolygonSampling = MicropolygonSampling::BoundingBox;  // Reyes
    // Reyes, displaced surfaces (paper 001 sec. 3.1): split an edge until the projected variation of its
    // displacement (from the min/max mip map of the texture) is at most this many micropolygon sides, at
    // most kMaxDisplacementSplitDepth halvings deep; 0: off (edges are measured undisplaced).
    float displacementSplit = 4.f;
    // Reyes: displace along the exact, shared normals (paper 000 sec. 3.1); false only for the benchmarks
    // (--displacement-normals grid: the paper's approximate baseline, which can crack).
    bool exactDisplacementNormals = true;
    SamplerKind sampler = SamplerKind::Sobol;  // camera sample pattern (film/sampler.h)
    // Ray tracer
    Integrator integrator = Integrator::Direct;
    AmbientOcclusionSettings ao;
    AdaptiveSettings adaptive;
    int subpatchDepth = kAutoSubpatchDepth;
    // Displaced patches' micro-grids (rt/displaced.h): built up front when they fit, else lazily and kept
    // within this many MiB.
    int displacementCacheMb = 512;
    int maxDepth = 4;  // direct: traced lobes per path; path: bounces
    // Area lights: shadow rays per shading point of the direct integrator (0: each light's own "samples").
    int lightSamples = 0;
    // Path tracer: Russian roulette from this bounce on (survival by the path's throughput).
    int rouletteDepth = 3;
    // Direct integrator: the glossy surfaces' reflection rays (shading/gloss.h, --gloss).
    GlossModel gloss = GlossModel::Paper;
    bool cullBackfaces = false;
    // Camera and shadow rays may find their candidates by binning the boxes in a projection plane instead
    // of one traversal per ray (same candidates); the renderer uses it where it pays (few subpatch leaves
    // per sample). Off: always per ray (tests, benchmarks).
    bool rayBinning = true;
    // rt: the surfaces of RIB ObjectInstances of one object share the first instance's subpatch trees (rays
    // are moved into its frame); off: every instance builds its own (tests, benchmarks).
    bool instancing = true;
    // rt: the candidate stages drop the (ray, leaf) pairs whose ray misses the leaf's slab inside its box
    // (rt/subpatch_tree.h LeafSlab4), in frames where that pays (TraceService::leafSlabsPay); off: every leaf
    // box hit is a Newton candidate (tests, benchmarks).
    bool leafSlabs = true;
    ShadowOverride shadows = ShadowOverride::Scene;
    ReyesShadows reyesShadows = ReyesShadows::Map;
    // Reyes shadow maps shared by the processes of a farm (--shadow-map-cache, reyes/shadow_maps.h): a
    // folder, and a key of the scene and options they belong to (the app's scene hash); "" = no cache.
    std::string shadowMapCacheDir, shadowMapCacheKey;
    RenderView view;
    OutputSpec output;
    BlurSettings blur;
    // Progress: called from worker threads with (work done, total work) after each bucket; the units are
    // the engine's estimate of its work (samples traced, micropolygons sampled), so the fraction grows
    // steadily over the render. Must be thread-safe.
    std::function<void(uint64_t, uint64_t)> progress;
    // Live preview (--display-server): called from worker threads after each bucket with the image and the
    // bucket's pixels, which are final by then (other buckets may be writing theirs: read only these).
    // Must be thread-safe.
    std::function<void(const Image&, const Rect&)> bucketDone;
    // Set to true (e.g. by a SIGINT handler) to stop the render early: no bucket starts after it is seen.
    const std::atomic<bool>* cancel = nullptr;
};

struct RenderResult {
    Image image;           // the film region (origin at the region's corner)
    nlohmann::json stats;  // engine counters; the CLI adds timing and memory
    bool cancelled = false;
    std::vector<std::string> warnings;  // said once per render (e.g. effects an engine does not render)
    // --adaptive: the refined subpixels of the image, (2 width) x (2 height), row-major, 1 = refined.
    std::vector<uint8_t> refinedSubpixels;
};

// The camera a render uses: the view's, else the scene's.
inline const Camera& viewCamera(const Scene& scene, const RenderSettings& s) {
    return s.view.camera ? *s.view.camera : scene.camera;
}

// The raster rectangle a render covers: the view's region clipped to the image, or the whole image.
inline Rect renderRegion(const Camera& cam, const RenderSettings& s) {
    const Rect whole{0, 0, cam.width, cam.height};
    const Rect& r = s.view.region;
    if (r.width() <= 0 || r.height() <= 0) return whole;
    return Rect{std::clamp(r.x0, 0, cam.width), std::clamp(r.y0, 0, cam.height),
                std::clamp(r.x1, 0, cam.width), std::clamp(r.y1, 0, cam.height)};
}

}  // namespace tessera
