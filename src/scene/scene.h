// The scene both engines render: camera, image options, lights, materials and bicubic Bezier patches
// in world space. Filled by the readers in src/io; read-only for the engines.
#pragma once
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "core/bezier.h"
#include "core/hostdevice.h"
#include "core/quadric.h"
#include "core/transform.h"
#include "scene/camera.h"

namespace tessera {

// Input limits (docs/errors.md): larger values are rejected (by the readers, the CLI, the Python module)
// before anything is allocated for them.
inline constexpr int kMaxImageSize = 16384;    // pixels per axis (RIB Format, --res)
inline constexpr int kMaxPixelSamples = 1024;  // samples per pixel (RIB PixelSamples x * y, --spp)

enum class FilterType { Box, Triangle, Gaussian, CatmullRom };

struct ImageOptions {
    int pixelSamplesX = 2, pixelSamplesY = 2;  // RI default PixelSamples 2 2
    FilterType filter = FilterType::Gaussian;  // RI default gaussian 2 x 2
    float filterWidthX = 2.f, filterWidthY = 2.f;
    float exposureGain = 1.f, exposureGamma = 1.f;  // RI default: linear
    bool srgbOutput = false;                        // used for scenes without a RIB (.bpt)
    std::string displayName;                        // RIB Display name ("" if none)
    // RIB Imager "background" (RI spec 3.2, appendix A): composite over this colour, Ci += (1 - alpha) *
    // background, alpha = 1; applied to the rendered image by render() (render/render.cpp).
    bool hasBackground = false;
    Color background{1, 1, 1};
    // RIB CropWindow xmin xmax ymin ymax in NDC (RI default 0 1 0 1: the whole image); film/crop.h maps it
    // to pixels by the RI 3.2 rounding rule.
    double cropWindow[4] = {0, 1, 0, 1};
    std::string displayType;  // RIB Display type: "file", "zfile"/"shadow" (a depth map), ... ("" if none)
    // RIB Display "+name" type mode (RI spec 3.2, sec. 4.1.4): further files of the same render, each
    // holding the beauty and the layers its mode names (an AOV list, e.g. "z" or "N,albedo"); the CLI
    // checks the modes (apps/tessera, --aov's names).
    struct SecondaryDisplay {
        std::string name, type, mode;
        int line = 0;
    };
    std::vector<SecondaryDisplay> secondaryDisplays;
    // RIB Hider "hidden" "string blursampling" (simple, interleaved, bbox; "" = the renderer's default)
    // and its interleaved tile size and permutation count (0 = default); the CLI overrides them.
    std::string blurSampling;
    int blurTileSize = 0, blurPermutations = 0;
    // RIB Hider "hidden" "jitter" [0]: film samples at their strata's centres (SamplerKind::Centred), as
    // shadow-map depth passes are rendered; the CLI's --sampler overrides it.
    bool jitter = true;
    // RIB Hider "hidden" "string micropolygonsampling" (bbox, nearest; "" = the renderer's default, bbox):
    // Reyes' micropolygon sampler (paper 000 sec. 3.2); the CLI's --micropolygon-sampling overrides it.
    std::string micropolygonSampling;
};

// Area: RI AreaLightSource "arealight" (docs/light_transport.md): the surfaces declared after it in its
// attribute block (PatchAttributes::areaLight) emit radiance `color` from their front side.
enum class LightType { Ambient, Distant, Point, Spot, Area };

// The shadow map Reyes renders for a light that casts shadows (--reyes-shadows map, docs/shading.md).
// RIB: Attribute "shadow" "resolution" / "shadingrate" / "bias" / "filterwidth", taken by each
// LightSource when it is declared.
struct ShadowMapParams {
    // Texels per side of the map (of each face of a cube map); 0: 2048 for one-face maps (distant, spot)
    // and 1024 per cube face (point lights: 6.3 M texels against 4.2 M; docs/shading.md measures both).
    int resolution = 0;
    float shadingRate = 1.f;  // texel area of a micropolygon of the depth pass
    float bias = 1.f;         // depth bias, in texels (world size of a texel at the receiver)
    float filterWidth = 2.f;  // percentage-closer filter box, in texels
    bool operator==(const ShadowMapParams&) const = default;
};

// Where a light's shadows come from when it casts them: the engine's own choice (Reyes: shadow maps it
// renders, or --reyes-shadows raytrace; the ray tracer: shadow rays), depth maps read from files (RI
// shadowspot, shadowdistant, shadowpoint with a "shadowname"), or shadow rays in both engines (the
// shadowname "raytrace", as PRMan reads it).
enum class ShadowSource : uint8_t { Renderer, File, RayTraced };

// A shadow map read from a file (MakeShadow's output, or a Display "zfile"): camera-space depth of the
// view that made it (infinity where nothing was seen), row-major top row first, and that view's
// matrices (io/image_io.h DepthMap). Both engines look it up through shading/shadow_map.h.
struct ShadowMapFile {
    std::string path;
    int width = 0, height = 0;
    std::vector<float> depth;
    Mat4 worldToCamera, worldToNDC;
};

struct Light {
    LightType type = LightType::Distant;
    Color color{1, 1, 1};  // intensity * lightcolor
    Vec3 from{0, 0, 0};    // world space (point lights, distant lights)
    Vec3 to{0, 0, 1};      // world space (distant and spot lights shine from -> to)
    // RI spotlight (radians; RI defaults radians(30), radians(5), 2).
    float coneAngle = 0.5235988f, coneDeltaAngle = 0.0872665f, beamDistribution = 2.f;
    // Whether the light casts shadows (RIB: Attribute "light" "shadows" "on"|"off" when the light is
    // declared, default off as in BMRT and Aqsis; the default lights of inputs without a RIB cast them).
    // The renderer's --shadows on|off overrides it (engine/settings.h). Ambient lights never do.
    bool castsShadows = false;
    ShadowMapParams shadowMap{};
    // Area lights: shadow rays per shading point of the direct integrator (stratified over the light's
    // surface; RIB "samples", the CLI's --light-samples overrides). The path tracer takes one per bounce.
    int samples = 16;
    ShadowSource shadowSource = ShadowSource::Renderer;
    // ShadowSource::File: the maps (indices into Scene::shadowMapFiles; -1: none, that face is lit). One
    // for distant and spot lights; six for point lights, the faces +x, -x, +y, -y, +z, -z of the world
    // axes around `from` (shadowpoint's sfpx ... sfnz), picked by the major axis of the light's direction.
    std::array<int32_t, 6> shadowFiles{-1, -1, -1, -1, -1, -1};
    // The shaders' "width": the percentage-closer filter of a file map is width x shadowMap.filterWidth
    // texels wide.
    float shadowWidth = 1.f;
};

enum class MaterialType {
    Matte,
    Plastic,
    Metal,
    ShinyMetal,
    PaintedPlastic,
    Constant,
    Mirror,
    Glass,
    Glossy
};

// Parameters of the RI standard surface shaders (RI spec 3.2, appendix A), plus mirror and glass.
struct Material {
    MaterialType type = MaterialType::Matte;
    Color Cs{1, 1, 1};  // Color
    Color Os{1, 1, 1};  // Opacity (only opaque is rendered for now)
    float Ka = 1.f, Kd = 1.f, Ks = 0.5f, roughness = 0.1f;
    Color specularColor{1, 1, 1};
    float Kr = 1.f, Kt = 1.f, eta = 1.5f;
    // glossy (docs/light_transport.md): reflection rays per camera hit of the direct integrator (later
    // hits trace one, as paper 002 sec. 5.3.5), and the spread s of the paper's perturbed reflection
    // R + s (p u + q v) (negative: the GGX alpha of `roughness`, the path tracer's lobe width).
    float glossSamples = 4.f, spread = -1.f;
    // paintedplastic's "texturename": index into Scene::textures (-1: none, Cs alone).
    int32_t texture = -1;
    bool operator==(const Material&) const = default;
};

// A surface's RI texture coordinates s, t (RI spec 3.2, sec. 4.2.7 and 5.2): the values at its (u,v)
// corners (0,0), (1,0), (0,1), (1,1), interpolated bilinearly in between (RI "varying"). Default: s = u,
// t = v.
struct PatchTexCoords {
    Vec2 st[4] = {{0, 0}, {1, 0}, {0, 1}, {1, 1}};
};

// A surface's per-vertex shading values (RI "N" and "Cs" of class vertex, varying or facevarying on
// polygons, RI spec 3.2, sec. 5.1): the values at its (u,v) corners (0,0), (1,0), (0,1), (1,1), interpolated
// bilinearly in between as RI interpolates varying values (docs/inputs.md, "Polygons"). N: the user's
// normals (world space in the scene; unnormalised), which replace the surface normal in shading (both
// engines turn them to the side of the oriented geometric normal). Cs: the surface colour, which replaces
// the material's (the reader gives such surfaces a material with Cs = 1 and the engines multiply by this).
struct PatchVertexValues {
    Vec3 N[4]{};
    Color Cs[4]{{1, 1, 1}, {1, 1, 1}, {1, 1, 1}, {1, 1, 1}};
    bool hasN = false, hasCs = false;
};

// The bilinear interpolation of four corner values ((0,0), (1,0), (0,1), (1,1)) at (u,v).
template <class T>
TESSERA_HD T bilinearCorners(const T (&c)[4], float u, float v) {
    return (c[0] * (1 - u) + c[1] * u) * (1 - v) + (c[2] * (1 - u) + c[3] * u) * v;
}

// The shading normal of a surface with user normals at (u,v): their bilinear interpolation, unit, on the
// side of `geometric` (the oriented geometric normal); `geometric` itself where they cancel out.
TESSERA_HD Vec3 vertexNormalAt(const PatchVertexValues& vv, float u, float v, Vec3 geometric) {
    Vec3 n = bilinearCorners(vv.N, u, v);
    const float len2 = dot(n, n);
    if (!(len2 > 1e-20f) || !isFinite(n)) return geometric;
    n = n / std::sqrt(len2);
    return dot(n, geometric) < 0.f ? -n : n;
}

// Where shadow rays and shadow-map lookups leave a surface with user normals: the point P at (u,v) lifted
// towards the smooth surface the normals describe (Hanika 2021, "Hacking the shadow terminator", Ray
// Tracing Gems II, ch. 4, with bilinear weights w_i over the corners p_i): P - sum_i w_i min(0, (P -
// p_i).n_i) n_i, the unit corner normals turned to the side of `geometric`. Without it a coarse mesh shades
// smoothly but shadows itself facet by facet along the terminator. `patch`: the surface in the normals'
// space.
TESSERA_HD Vec3 terminatorSafePoint(const PatchVertexValues& vv, const BezierPatch& patch, float u, float v,
                                    Vec3 P, Vec3 geometric) {
    const Vec3 corner[4] = {patch.cp[0], patch.cp[3], patch.cp[12], patch.cp[15]};
    const float w[4] = {(1 - u) * (1 - v), u * (1 - v), (1 - u) * v, u * v};
    const float side = dot(bilinearCorners(vv.N, u, v), geometric) < 0.f ? -1.f : 1.f;
    Vec3 lifted = P;
    for (int i = 0; i < 4; ++i) {
        const float len2 = dot(vv.N[i], vv.N[i]);
        if (!(len2 > 1e-20f)) continue;
        const Vec3 n = vv.N[i] * (side / std::sqrt(len2));
        const float below = std::min(0.f, dot(P - corner[i], n));
        lifted = lifted - n * (w[i] * below);
    }
    return isFinite(lifted) ? lifted : P;
}

// Displacement shaders (docs/textures.md, "Displacement"): RI bumpy (P += Km * texture(texturename, s, t) *
// normalize(N), RI spec 3.2, appendix A) and Tessera's offset (P += Km * normalize(N): a constant amplitude,
// which RI's standard shaders do not offer). Amplitudes are in camera-space ("current") units, as RI's bumpy.
enum class DisplacementType : uint8_t { Bumpy, Offset };
struct DisplacementShader {
    DisplacementType type = DisplacementType::Bumpy;
    float Km = 1.f;
    int32_t texture = -1;  // index into Scene::textures (-1: none; bumpy then does not move the surface)
    bool operator==(const DisplacementShader&) const = default;
};

// The closed set of surface kinds both engines handle. Reyes' bound/split/dice and the ray tracer's
// bound/traverse/intersect dispatch on this tag at the surface level (a switch, no virtual calls in the
// kernels). Bicubic Bezier patches and the seven RI quadrics (core/quadric.h: closed form in their own
// (u,v), never converted to patches); bilinear patches and polygons are the next entries.
enum class SurfaceKind : uint8_t {
    BicubicBezier,
    Sphere,
    Cylinder,
    Cone,
    Disk,
    Paraboloid,
    Hyperboloid,
    Torus
};
inline constexpr int kSurfaceKinds = 8;

constexpr bool isQuadric(SurfaceKind k) {
    return k != SurfaceKind::BicubicBezier;
}
// The quadric kind of a quadric surface kind (the same order).
constexpr QuadricKind quadricKindOf(SurfaceKind k) {
    return QuadricKind(uint8_t(k) - 1);
}
constexpr SurfaceKind surfaceKindOf(QuadricKind k) {
    return SurfaceKind(uint8_t(k) + 1);
}
// "bicubic", "sphere", ... (statistics, `tessera info`).
const char* surfaceKindName(SurfaceKind k);

// A quadric of the scene: its RI parameters in object space and where the object is.
struct SceneQuadric {
    Quadric q;
    Mat4 worldFromObject;
};

// The quadric in the space `toSpace` maps world space to (camera space for the engines), for the kernels.
PlacedQuadric placeQuadric(const SceneQuadric& sq, const Mat4& toSpace);
// The 8 corners of the quadric's object-space box over (u,v) rectangle [u0,u1] x [v0,v1], in its space:
// their convex hull holds that part of the surface.
void quadricHullCorners(const PlacedQuadric& pq, float u0, float u1, float v0, float v1, Vec3 corners[8]);
// Position, derivatives and unit geometric normal at (u,v) in the quadric's space (normal before the
// orientation flip of PatchAttributes::flipNormal).
SurfacePoint evalPlacedQuadric(const PlacedQuadric& pq, float u, float v, Vec3* normal = nullptr);

// Where a surface's motion keys live: `count` world-space control-point sets Scene::motionPatches[first ...]
// at scene times Scene::motionTimes[first ...] (increasing). count 0 or 1: static (Scene::patches only).
// One model of motion for both engines (docs/motion.md): between two keys the control points move
// linearly, and outside the keys they stay at the nearest key. Transformation blur is turned into such
// keys at load time: the readers evaluate the decomposed, interpolated transform (core/motion_transform.h)
// at enough times that no segment turns more than 2 degrees, so a rotation stays a rotation.
struct MotionKeys {
    uint32_t first = 0, count = 0;
    bool moving() const { return count > 1; }
};

// Per-primitive attributes the renderers need.
struct PatchAttributes {
    SurfaceKind kind = SurfaceKind::BicubicBezier;
    uint32_t shape = 0;  // quadric kinds: index in Scene::quadrics
    MotionKeys motion;
    // The displacement shader (index into Scene::displacements; -1: none) and RI Attribute
    // "displacementbound" "sphere" r "coordinatesystem" space: how far displacement may move a point, in
    // world-space units (the reader converts r from its space; 0: not given, the bound then comes from the
    // shader and its texture's range).
    int32_t displacement = -1;
    float displacementBound = 0.f;
    uint32_t material = 0;
    uint32_t object = 0;      // object id (one per RIB primitive call / .bpt file)
    float shadingRate = 1.f;  // pixels of area per micropolygon
    // RI GeometricApproximation "motionfactor" / "focusfactor" (PRMan, Aqsis): Reyes coarsens the shading
    // of blurred geometry by these factors (0: no coarsening, the default, so images stay comparable).
    float motionFactor = 0.f, focusFactor = 0.f;
    bool twoSided = true;     // Sides 2
    bool flipNormal = false;  // orientation disagrees with dPdu x dPdv
    // The area light (index into Scene::lights) this surface is part of, emitting from its front side (the
    // side its oriented normal faces); -1: none.
    int32_t areaLight = -1;
    // Per-vertex normals and colours (index into Scene::vertexValues; -1: none).
    int32_t vertexValues = -1;
};

// One RIB ObjectInstance (retained geometry): Scene surfaces [first, first + count) are the object's
// surfaces placed by `objectToWorld` (static; instances under a moving transform are not recorded).
// Instances with the same `object` replay the same definition, so their surfaces are transformed copies
// of each other unless the graphics state at the instance changes the geometry (Basis, displacement):
// an engine that shares per-surface structures between instances checks that (rt: docs/rt.md,
// "Instancing"). Instances nested inside an object definition are part of the outer instance's copy.
struct SurfaceInstance {
    uint32_t first = 0, count = 0;
    uint32_t object = 0;  // the definition (ObjectBegin) it replays, numbered in order of definition
    Mat4 objectToWorld;
};

struct Scene {
    Camera camera;
    ImageOptions image;
    std::vector<Light> lights;
    std::vector<Material> materials;
    // One entry per surface, world space: a bicubic patch's control points, or for a quadric the hull of
    // its box (quadricHullCorners twice, so every bound of the patches holds it; never evaluated).
    std::vector<BezierPatch> patches;
    std::vector<PatchAttributes> attributes;  // one per surface
    std::vector<SceneQuadric> quadrics;       // the quadric surfaces' parameters (PatchAttributes::shape)
    // Motion keys of moving patches (empty for static scenes), see MotionKeys. Scene::patches holds every
    // patch at shutter open.
    std::vector<BezierPatch> motionPatches;
    std::vector<float> motionTimes;
    // Texture coordinates per patch (index as `patches`), or empty when every patch has the default s = u,
    // t = v; see texCoordsOf.
    std::vector<PatchTexCoords> texCoords;
    // Per-vertex N and Cs of the surfaces that have them (PatchAttributes::vertexValues). Like the texture
    // coordinates they stay with the patch at every motion key; N is world space at shutter open.
    std::vector<PatchVertexValues> vertexValues;
    // The texture files materials refer to (Material::texture), resolved to paths by the reader.
    std::vector<std::string> textures;
    std::vector<DisplacementShader> displacements;  // PatchAttributes::displacement
    std::vector<ShadowMapFile> shadowMapFiles;      // Light::shadowFiles
    uint32_t objectCount = 0;
    std::vector<SurfaceInstance> instances;  // ObjectInstance requests, in order (none for other inputs)
    std::string sourcePath;

    Bounds3 worldBounds() const;
    // Whether anything moves within the shutter (a patch with keys or the camera).
    bool hasMotion() const;
};

// How many surfaces of each kind the scene has (SurfaceKind order; statistics, `tessera info`).
std::array<size_t, kSurfaceKinds> surfaceKindCounts(const Scene& scene);

// The texture coordinates of patch `i` (the default s = u, t = v when the scene has none).
inline PatchTexCoords texCoordsOf(const Scene& scene, size_t i) {
    return i < scene.texCoords.size() ? scene.texCoords[i] : PatchTexCoords{};
}

// The per-vertex values of patch `i` (nullptr: none).
inline const PatchVertexValues* vertexValuesOf(const Scene& scene, size_t i) {
    const int32_t k = scene.attributes[i].vertexValues;
    return k >= 0 ? &scene.vertexValues[size_t(k)] : nullptr;
}

// The scene's per-vertex values with their normals in the space `toSpace` maps world space to (camera
// space for the engines; inverse transpose), index as Scene::vertexValues.
std::vector<PatchVertexValues> vertexValuesInSpace(const Scene& scene, const Mat4& toSpace);

// World-space control points of patch `i` at scene time `time` (linear between its keys).
BezierPatch patchAtTime(const Scene& scene, size_t i, float time);

// Overrides the scene's Shutter (tessera render --shutter, the Python module's shutter=): the motion keys
// stay as they are (keys outside the new interval are clamped by the motion model), Scene::patches and the
// camera transform move to the new shutter-open time.
void setShutter(Scene& scene, float open, float close);

// Counts for `tessera info` and the statistics: patches with motion keys, their keys in all, camera keys.
struct MotionSummary {
    size_t movingPatches = 0, patchKeys = 0, cameraKeys = 0;
};
MotionSummary motionSummary(const Scene& scene);

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
// sensible (the key and fill lights cast shadows). "Front" is -y for z up, +z for y up and -z for x up.
void frameSceneDefault(Scene& scene, int width, int height, UpAxis up = UpAxis::Z);

// The sphere frameSceneDefault fits in view: centre of the control points' box, radius to the farthest
// control point (the patches lie in their control hulls, so inside it).
void defaultFramingSphere(const Scene& scene, Vec3& centre, float& radius);

const char* upAxisName(UpAxis up);  // "x", "y", "z"

}  // namespace tessera
