// The words a user renders with (the CLI's flags, the Python module's keywords) and how they become the
// engines' RenderSettings over a scene: one function for both front ends, so the same words render the
// same image. Resolution, samples per pixel, shading rate and the camera's blur overrides edit the Scene;
// the film region and the output spec are the caller's.
#pragma once
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "engine/settings.h"

namespace tessera {

struct RenderOptions {
    // What edits the Scene (applySceneOverrides); 0 / nullopt: the scene's own.
    int width = 0, height = 0;  // resolution
    int spp = 0;                // samples per pixel (split into the nearest x, y strata)
    double shadingRate = 0;
    std::optional<std::vector<double>> shutter;  // open, close
    std::optional<std::vector<double>> dof;      // fstop, focal length, focal distance (thin lens)

    std::string engine = "reyes";  // reyes, rt
    int threads = 0;               // 0: all cores
    unsigned seed = 0;
    std::string sampler;            // sobol, jittered, centred; "": sobol, or centred for Hider "jitter" [0]
    std::string shadows = "scene";  // which lights cast shadows: on, off, scene (each light's attribute)
    std::string reyesShadows = "map";  // how Reyes answers visibility: map (shadow maps) or raytrace
    int bucketSize = 32, subpatchDepth = kAutoSubpatchDepth, maxGridEdge = 16;
    // Reyes (docs/textures.md): the micropolygon sampler, bbox or nearest ("": the scene's Hider
    // "micropolygonsampling", else bbox); and the displacement split threshold in micropolygon sides
    // (negative: the default, 4; 0: no displacement-aware splitting).
    std::string micropolygonSampling;
    double displacementSplit = -1;
    std::string displacementNormals = "exact";  // exact, grid (benchmarks only)
    int displacementCacheMb = 512;              // rt: memory for displaced micro-grids (RenderSettings)
    int maxDepth = -1;                          // -1: 4 for the direct integrator, 16 for the path tracer
    int lightSamples = 0;                       // 0: each area light's own "samples"
    bool cullBackfaces = false, noRayBinning = false, noInstancing = false, noLeafSlabs = false;
    // Motion blur and depth of field (docs/motion.md): "" / 0 = the scene's Hider parameters.
    bool noBlur = false;
    std::string blurSampling;
    int blurTile = 0, blurPermutations = 0;
    // Ray-traced light transport (docs/light_transport.md).
    std::string integrator = "direct";   // direct, path, ao
    std::string aoWeighting = "cosine";  // cosine, paper
    std::string gloss = "paper";         // paper, microfacet (shading/gloss.h)
    int aoSamples = 64;
    double aoDistance = 0;  // 0: unlimited
    // Selective and adaptive supersampling (docs/adaptive.md).
    bool adaptive = false;
    double adaptiveThreshold = 0;
    bool adaptiveThresholdGiven = false;
    // The paper's other thresholds by name, "poid=0.05,ssn=0.1" (parseAdaptiveThresholds), the focus
    // objects "3,7" and the bilinear interpolation of inactive subpixels.
    std::string adaptiveThresholds, adaptiveFocus;
    bool adaptiveInterpolate = false;
};

// "NAME=VALUE,..." with the names of paper 004's Table 1 (col, poid, psn, psc, pte, soid, ssn, ssc, ste)
// into `t`; each value a number >= 0. Throws std::invalid_argument naming what is wrong.
void parseAdaptiveThresholds(const std::string& text, AdaptiveThresholds& t);
// "ID,ID,..." object ids (non-negative integers). Throws std::invalid_argument.
std::vector<uint32_t> parseObjectIds(const std::string& text);

// The text forms of option values, for the CLI and the Python module's strings: `n` comma-separated finite
// numbers ("0,1"), and WIDTHxHEIGHT ("640x480"); nullopt when the text is not that.
std::optional<std::vector<double>> parseNumberList(const std::string& text, size_t n);
std::optional<std::pair<int, int>> parseResolution(const std::string& text);

// Applies the options that edit the scene (resolution, samples per pixel, shading rate, shutter, depth of
// field). Throws std::invalid_argument naming the option for a value out of range, and for a scene whose
// own resolution is outside 1..kMaxImageSize.
void applySceneOverrides(Scene& scene, const RenderOptions& o);

// Fills `s` (all but view and output) from `o` and the scene's own render options (Hider "jitter",
// "blursampling", "blurtilesize", "blurpermutations", "micropolygonsampling"). Throws std::invalid_argument
// for an unknown name or a value out of range, naming the option.
void applyRenderOptions(const Scene& scene, const RenderOptions& o, RenderSettings& s);

// The statistics' record of what was asked for, beside the engines' counters: "shadows" (mode, casting
// lights) and "blur" (sampling scheme, shutter, lens, moving surfaces).
void describeRender(nlohmann::json& stats, const Scene& scene, const RenderSettings& s);

}  // namespace tessera
