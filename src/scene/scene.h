// The scene both engines render: camera, image options, lights, materials and bicubic Bezier patches
// in world space. Filled by the readers in src/io; read-only for the engines.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "core/bezier.h"
#include "scene/camera.h"

namespace tessera {

enum class FilterType { Box, Triangle, Gaussian, CatmullRom };

struct ImageOptions {
    int pixelSamplesX = 2, pixelSamplesY = 2;  // RI default PixelSamples 2 2
    FilterType filter = FilterType::Gaussian;  // RI default gaussian 2 x 2
    float filterWidthX = 2.f, filterWidthY = 2.f;
    float exposureGain = 1.f, exposureGamma = 1.f;  // RI default: linear
    bool srgbOutput = false;                         // used for scenes without a RIB (.bpt)
    std::string displayName;                         // RIB Display name ("" if none)
};

enum class LightType { Ambient, Distant, Point };

struct Light {
    LightType type = LightType::Distant;
    Color color{1, 1, 1};  // intensity * lightcolor
    Vec3 from{0, 0, 0};    // world space (point lights, distant lights)
    Vec3 to{0, 0, 1};      // world space (distant lights shine from -> to)
};

enum class MaterialType { Matte, Plastic, Metal, Constant, Mirror, Glass };

// Parameters of the RI standard surface shaders (RI spec 3.2, appendix A), plus mirror and glass.
struct Material {
    MaterialType type = MaterialType::Matte;
    Color Cs{1, 1, 1};  // Color
    Color Os{1, 1, 1};  // Opacity (only opaque is rendered for now)
    float Ka = 1.f, Kd = 1.f, Ks = 0.5f, roughness = 0.1f;
    Color specularColor{1, 1, 1};
    float Kr = 1.f, Kt = 1.f, eta = 1.5f;
};

// Per-primitive attributes the renderers need.
struct PatchAttributes {
    uint32_t material = 0;
    uint32_t object = 0;        // object id (one per RIB primitive call / .bpt file)
    float shadingRate = 1.f;    // pixels of area per micropolygon
    bool twoSided = true;       // Sides 2
    bool flipNormal = false;    // orientation disagrees with dPdu x dPdv
};

struct Scene {
    Camera camera;
    ImageOptions image;
    std::vector<Light> lights;
    std::vector<Material> materials;
    std::vector<BezierPatch> patches;           // world space
    std::vector<PatchAttributes> attributes;    // one per patch
    uint32_t objectCount = 0;
    std::string sourcePath;

    Bounds3 worldBounds() const;
};

enum class UpAxis { X, Y, Z };

// The up axis of a model whose format does not fix one (docs/inputs.md, "Default framing"): a model
// stands on the ground plane through the origin, so an axis on which the control points start at 0 while
// they extend on both sides of 0 along the two other axes is up; otherwise y when y is the tallest extent
// (standing figures from polygon modellers), else z (Newell's teapot set, CAD and RenderMan worlds).
UpAxis chooseUpAxis(const std::vector<BezierPatch>& patches);

// For inputs without a camera (.bpt, OBJ, Micropolis): a camera looking at the model from the front-right
// and 25 degrees above, with `up` vertical, far enough that the whole bounding sphere of the control points
// (centred on their box) lies inside the frame for any image aspect (the 30-degree field of view spans
// the shorter axis); plus an ambient, a key and a fill light so that any patch file renders something
// sensible. "Front" is -y for z up, +z for y up and -z for x up.
void frameSceneDefault(Scene& scene, int width, int height, UpAxis up = UpAxis::Z);

// The sphere frameSceneDefault fits in view: centre of the control points' box, radius to the farthest
// control point (the patches lie in their control hulls, so inside it).
void defaultFramingSphere(const Scene& scene, Vec3& centre, float& radius);

const char* upAxisName(UpAxis up);  // "x", "y", "z"

}  // namespace tessera

namespace tessera {
// Defaults of the RI standard shaders (RI spec 3.2, appendix A) for a material type.
Material defaultMaterial(MaterialType type);
}  // namespace tessera
