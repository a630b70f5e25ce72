#include "render/render_options.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <initializer_list>
#include <stdexcept>

#include "film/blur_pattern.h"
#include "render/aovs.h"
#include "rt/subpatch_tree.h"

namespace tessera {
namespace {

void requireOneOf(const char* option, const std::string& value, std::initializer_list<const char*> names) {
    std::string list;
    for (const char* n : names) {
        if (value == n) return;
        list += list.empty() ? n : std::string(", ") + n;
    }
    throw std::invalid_argument(std::string(option) + " must be one of " + list + ", got '" + value + "'");
}

}  // namespace

void parseAdaptiveThresholds(const std::string& text, AdaptiveThresholds& t) {
    struct Name {
        const char* name;
        float AdaptiveThresholds::*field;
    };
    static const Name names[] = {
        {"col", &AdaptiveThresholds::color},           {"poid", &AdaptiveThresholds::objectId},
        {"psn", &AdaptiveThresholds::normal},          {"psc", &AdaptiveThresholds::shadow},
        {"pte", &AdaptiveThresholds::texture},         {"soid", &AdaptiveThresholds::secondaryObjectId},
        {"ssn", &AdaptiveThresholds::secondaryNormal}, {"ssc", &AdaptiveThresholds::secondaryShadow},
        {"ste", &AdaptiveThresholds::secondaryTexture}};
    size_t at = 0;
    while (at <= text.size()) {
        const size_t comma = std::min(text.find(',', at), text.size());
        const std::string item = text.substr(at, comma - at);
        const size_t eq = item.find('=');
        const std::string name = item.substr(0, eq);
        const Name* found = nullptr;
        for (const Name& n : names)
            if (name == n.name) found = &n;
        if (eq == std::string::npos || !found)
            throw std::invalid_argument(
                "adaptive thresholds: '" + item +
                "' is not NAME=VALUE with NAME one of col, poid, psn, psc, pte, soid, "
                "ssn, ssc, ste");
        const std::string value = item.substr(eq + 1);
        char* end = nullptr;
        errno = 0;
        const double v = std::strtod(value.c_str(), &end);
        if (value.empty() || *end != '\0' || errno != 0 || !std::isfinite(v) || v < 0)
            throw std::invalid_argument("adaptive thresholds: " + name + " must be a number >= 0, got '" +
                                        value + "'");
        t.*(found->field) = float(v);
        at = comma + 1;
    }
}

std::vector<uint32_t> parseObjectIds(const std::string& text) {
    std::vector<uint32_t> ids;
    size_t at = 0;
    while (at <= text.size()) {
        const size_t comma = std::min(text.find(',', at), text.size());
        const std::string item = text.substr(at, comma - at);
        char* end = nullptr;
        errno = 0;
        const long long v = std::strtoll(item.c_str(), &end, 10);
        if (item.empty() || *end != '\0' || errno != 0 || v < 0 || v >= 0xffffffffll)
            throw std::invalid_argument("adaptive focus: '" + item +
                                        "' is not an object id (an integer >= 0)");
        ids.push_back(uint32_t(v));
        at = comma + 1;
    }
    return ids;
}

void applyRenderOptions(const Scene& scene, const RenderOptions& o, RenderSettings& s) {
    requireOneOf("engine", o.engine, {"reyes", "rt"});
    if (!o.sampler.empty()) requireOneOf("sampler", o.sampler, {"sobol", "jittered", "centred"});
    requireOneOf("shadows", o.shadows, {"on", "off", "scene"});
    requireOneOf("reyes shadows", o.reyesShadows, {"map", "raytrace"});
    requireOneOf("integrator", o.integrator, {"direct", "path", "ao"});
    requireOneOf("ao weighting", o.aoWeighting, {"cosine", "paper"});
    requireOneOf("gloss", o.gloss, {"paper", "microfacet"});
    if (!o.blurSampling.empty())
        requireOneOf("blur sampling", o.blurSampling, {"simple", "interleaved", "bbox"});
    if (!o.micropolygonSampling.empty())
        requireOneOf("micropolygon sampling", o.micropolygonSampling, {"bbox", "nearest"});
    if (!(o.displacementSplit < 0 || (o.displacementSplit >= 0 && std::isfinite(o.displacementSplit))))
        throw std::invalid_argument("displacement split must be a number >= 0 (0 = off)");
    requireOneOf("displacement normals", o.displacementNormals, {"exact", "grid"});
    if (o.threads < 0) throw std::invalid_argument("threads must be >= 0 (0 = all cores)");
    if (o.bucketSize < 4 || o.bucketSize > 1024) throw std::invalid_argument("bucket size must be 4..1024");
    if (o.integrator != "direct" && o.engine != "rt")
        throw std::invalid_argument("integrator " + o.integrator + " is ray traced: use it with engine rt");
    if (o.adaptive && o.engine != "rt")
        throw std::invalid_argument("adaptive sampling is ray traced: use it with engine rt");
    if (o.adaptive && o.spp > 0)
        throw std::invalid_argument("adaptive sampling chooses the samples per pixel itself: give no spp");
    if (o.adaptiveThresholdGiven && !(o.adaptiveThreshold >= 0 && std::isfinite(o.adaptiveThreshold)))
        throw std::invalid_argument("adaptive threshold must be a number >= 0");
    if (!o.adaptive && (!o.adaptiveThresholds.empty() || !o.adaptiveFocus.empty() || o.adaptiveInterpolate))
        throw std::invalid_argument("adaptive thresholds, focus and interpolation need adaptive sampling");

    s.engine = o.engine;
    s.threads = o.threads;
    s.seed = o.seed;
    // The sampler asked for, else the scene's Hider "jitter" [0] (strata centres), else Sobol'.
    s.sampler = o.sampler == "jittered"                      ? SamplerKind::Jittered
                : o.sampler == "centred"                     ? SamplerKind::Centred
                : o.sampler == "sobol" || scene.image.jitter ? SamplerKind::Sobol
                                                             : SamplerKind::Centred;
    s.bucketSize = o.bucketSize;
    if (o.subpatchDepth != kAutoSubpatchDepth && (o.subpatchDepth < 0 || o.subpatchDepth > kMaxSubpatchDepth))
        throw std::invalid_argument("subpatch depth must be auto or an integer from 0 to " +
                                    std::to_string(kMaxSubpatchDepth) + ", got " +
                                    std::to_string(o.subpatchDepth));
    s.subpatchDepth = o.subpatchDepth;
    s.displacementCacheMb = o.displacementCacheMb;
    // Bounces: 4 traced lobes for the direct integrator; 16 for the path tracer, whose Russian roulette
    // ends most paths far earlier (the cap only bounds mirror-and-glass chains).
    s.maxDepth = o.maxDepth >= 0 ? o.maxDepth : o.integrator == "path" ? 16 : 4;
    s.lightSamples = o.lightSamples;
    s.cullBackfaces = o.cullBackfaces;
    s.rayBinning = !o.noRayBinning;
    s.instancing = !o.noInstancing;
    s.leafSlabs = !o.noLeafSlabs;
    s.maxGridEdge = o.maxGridEdge;
    const std::string mpSampling =
        !o.micropolygonSampling.empty() ? o.micropolygonSampling : scene.image.micropolygonSampling;
    s.micropolygonSampling =
        mpSampling == "nearest" ? MicropolygonSampling::Nearest : MicropolygonSampling::BoundingBox;
    if (o.displacementSplit >= 0) s.displacementSplit = float(o.displacementSplit);
    s.exactDisplacementNormals = o.displacementNormals == "exact";
    s.gloss = o.gloss == "microfacet" ? GlossModel::Microfacet : GlossModel::Paper;
    s.integrator = o.integrator == "ao"     ? Integrator::AmbientOcclusion
                   : o.integrator == "path" ? Integrator::Path
                                            : Integrator::Direct;
    s.ao.samples = o.aoSamples;
    if (o.aoDistance > 0) s.ao.maxDistance = float(o.aoDistance);
    s.ao.paperWeighting = o.aoWeighting == "paper";
    s.adaptive.enabled = o.adaptive;
    if (!o.adaptiveThresholds.empty()) parseAdaptiveThresholds(o.adaptiveThresholds, s.adaptive.thresholds);
    if (o.adaptiveThresholdGiven) s.adaptive.thresholds.color = float(o.adaptiveThreshold);
    if (!o.adaptiveFocus.empty()) s.adaptive.focusObjects = parseObjectIds(o.adaptiveFocus);
    s.adaptive.interpolate = o.adaptiveInterpolate;
    s.shadows = o.shadows == "on"    ? ShadowOverride::On
                : o.shadows == "off" ? ShadowOverride::Off
                                     : ShadowOverride::Scene;
    s.reyesShadows = o.reyesShadows == "raytrace" ? ReyesShadows::Raytrace : ReyesShadows::Map;
    // Blur: the options, else the scene's Hider "hidden" parameters, else the defaults of BlurSettings.
    s.blur.enabled = !o.noBlur;
    const std::string sampling = !o.blurSampling.empty() ? o.blurSampling : scene.image.blurSampling;
    if (sampling == "simple") s.blur.sampling = BlurSampling::Simple;
    if (sampling == "interleaved") s.blur.sampling = BlurSampling::Interleaved;
    if (sampling == "bbox") s.blur.sampling = BlurSampling::BoundingBox;
    s.blur.tileSize = o.blurTile > 0                 ? o.blurTile
                      : scene.image.blurTileSize > 0 ? scene.image.blurTileSize
                                                     : s.blur.tileSize;
    s.blur.permutations = o.blurPermutations > 0             ? o.blurPermutations
                          : scene.image.blurPermutations > 0 ? scene.image.blurPermutations
                                                             : s.blur.permutations;
    const int spp = scene.image.pixelSamplesX * scene.image.pixelSamplesY;
    if (s.blur.enabled && s.blur.sampling == BlurSampling::Interleaved &&
        int64_t(spp) * s.blur.tileSize * s.blur.tileSize > 65536)
        throw std::invalid_argument(
            "interleaved blur sampling needs samples per pixel x tile size^2 <= 65536, got " +
            std::to_string(spp) + " x " + std::to_string(s.blur.tileSize) +
            "^2 (lower the samples per pixel or the blur tile size)");
}

std::optional<std::vector<double>> parseNumberList(const std::string& text, size_t n) {
    std::vector<double> out;
    for (const std::string& part : splitCommas(text)) {
        char* stop = nullptr;
        errno = 0;
        const double v = std::strtod(part.c_str(), &stop);
        if (part.empty() || *stop != '\0' || errno == ERANGE || !std::isfinite(v)) return std::nullopt;
        out.push_back(v);
    }
    if (out.size() != n) return std::nullopt;
    return out;
}

std::optional<std::pair<int, int>> parseResolution(const std::string& text) {
    int w = 0, h = 0;
    char x = 0, extra = 0;
    if (std::sscanf(text.c_str(), "%d%c%d%c", &w, &x, &h, &extra) != 3 || (x != 'x' && x != 'X'))
        return std::nullopt;
    return std::pair{w, h};
}

void applySceneOverrides(Scene& scene, const RenderOptions& o) {
    const auto size = [](int w, int h) { return std::to_string(w) + "x" + std::to_string(h); };
    if (o.width != 0 || o.height != 0) {
        if (o.width < 1 || o.height < 1 || o.width > kMaxImageSize || o.height > kMaxImageSize)
            throw std::invalid_argument("resolution " + size(o.width, o.height) + " outside 1.." +
                                        std::to_string(kMaxImageSize) + " per axis");
        scene.camera.width = o.width;
        scene.camera.height = o.height;
    }
    if (scene.camera.width < 1 || scene.camera.height < 1 || scene.camera.width > kMaxImageSize ||
        scene.camera.height > kMaxImageSize)
        throw std::invalid_argument("resolution " + size(scene.camera.width, scene.camera.height) +
                                    " outside 1.." + std::to_string(kMaxImageSize) + " per axis");
    if (o.spp != 0) {
        if (o.spp < 1 || o.spp > kMaxPixelSamples)
            throw std::invalid_argument("samples per pixel must be between 1 and " +
                                        std::to_string(kMaxPixelSamples));
        splitSamplesPerPixel(o.spp, scene.image.pixelSamplesX, scene.image.pixelSamplesY);
    }
    if (o.shadingRate != 0) {
        if (!(o.shadingRate > 0) || !std::isfinite(o.shadingRate))
            throw std::invalid_argument("shading rate must be > 0");
        for (auto& attr : scene.attributes) attr.shadingRate = float(o.shadingRate);
    }
    if (o.shutter) {
        const std::vector<double>& t = *o.shutter;
        if (t.size() != 2 || !std::isfinite(t[0]) || !std::isfinite(t[1]))
            throw std::invalid_argument("shutter needs two numbers: open, close");
        if (t[1] < t[0]) throw std::invalid_argument("shutter: close is before open");
        setShutter(scene, float(t[0]), float(t[1]));  // keys outside the interval are clamped
    }
    if (o.dof) {
        const std::vector<double>& d = *o.dof;
        if (d.size() != 3)
            throw std::invalid_argument("dof needs three numbers: fstop, focallength, focaldistance");
        if (!(d[0] > 0 && d[1] > 0 && d[2] > 0 && std::isfinite(d[0] + d[1] + d[2])))
            throw std::invalid_argument("dof: fstop, focal length and focal distance must be positive");
        scene.camera.fStop = float(d[0]);
        scene.camera.focalLength = float(d[1]);
        scene.camera.focalDistance = float(d[2]);
    }
}

void describeRender(nlohmann::json& stats, const Scene& scene, const RenderSettings& s) {
    {  // which lights cast shadows (the engines may add their own counters under "shadows")
        nlohmann::json& sh = stats["shadows"];
        if (!sh.is_object()) sh = nlohmann::json::object();
        int casting = 0;
        for (const Light& l : scene.lights) casting += lightCastsShadows(l, s.shadows);
        sh["mode"] = shadowOverrideName(s.shadows);
        if (s.engine == "reyes") sh["reyes_shadows"] = reyesShadowsName(s.reyesShadows);
        sh["casting_lights"] = casting;
    }
    {  // what the blur was asked for (the engines may add their own counters under "blur")
        nlohmann::json& b = stats["blur"];
        if (!b.is_object()) b = nlohmann::json::object();
        const MotionSummary ms = motionSummary(scene);
        b["enabled"] = s.blur.enabled;
        b["sampling"] = blurSamplingName(s.blur.sampling);
        b["tile_size"] = s.blur.tileSize;
        b["permutations"] = s.blur.permutations;
        b["shutter"] = {scene.camera.shutterOpen, scene.camera.shutterClose};
        b["lens_radius"] = scene.camera.lensRadius();
        b["moving_patches"] = ms.movingPatches;
        b["camera_keys"] = ms.cameraKeys;
    }
}

}  // namespace tessera
