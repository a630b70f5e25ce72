#include "io/rib_shaders.h"

namespace tessera::rib {

namespace {

using SurfaceParam = ShaderParam<Material>;
using LightParam = ShaderParam<LightShaderParams>;
constexpr ShaderParamType kFloat = ShaderParamType::Float;
constexpr ShaderParamType kColor = ShaderParamType::Color;
constexpr ShaderParamType kPoint = ShaderParamType::Point;

// Surface parameters (RI spec 3.2, appendix A; Kr, Kt and eta are Tessera's mirror and glass).
// Defaults come from defaultMaterial(). Every surface takes every one of these, as the reader always
// has: e.g. "Ks" on matte is stored (and is part of the material's identity) though matte ignores it.
constexpr SurfaceParam kKa{"Ka", &Material::Ka};
constexpr SurfaceParam kKd{"Kd", &Material::Kd};
constexpr SurfaceParam kKs{"Ks", &Material::Ks};
constexpr SurfaceParam kRoughness{"roughness", &Material::roughness};
constexpr SurfaceParam kSpecularColor{"specularcolor", kColor, &Material::specularColor};
constexpr SurfaceParam kKr{"Kr", &Material::Kr};
constexpr SurfaceParam kKt{"Kt", &Material::Kt};
constexpr SurfaceParam kEta{"eta", &Material::eta};
constexpr SurfaceParam kGlossSamples{"samples", &Material::glossSamples};
constexpr SurfaceParam kSpread{"spread", &Material::spread};

// Per shader: its own parameters, then (after "also") the others every surface accepts.
constexpr SurfaceParam kMatteParams[] = {kKa, kKd, /* also */ kKs, kRoughness, kSpecularColor, kKr,
                                         kKt, kEta};
constexpr SurfaceParam kPlasticParams[] = {kKa, kKd, kKs, kRoughness, kSpecularColor, /* also */ kKr,
                                           kKt, kEta};
constexpr SurfaceParam kMetalParams[] = {kKa, kKs, kRoughness, /* also */ kKd, kSpecularColor,
                                         kKr, kKt, kEta};
// paintedplastic's "texturename" (a string) is read by the reader's Surface handler (a texture file);
// shinymetal's (an environment map) is warned about and ignored like any parameter without a row.
constexpr SurfaceParam kShinyMetalParams[] = {kKa, kKs, kKr, kRoughness, /* also */ kKd, kSpecularColor,
                                              kKt, kEta};
constexpr SurfaceParam kConstantParams[] = {/* also */ kKa, kKd, kKs, kRoughness,
                                            kSpecularColor, kKr, kKt, kEta};
constexpr SurfaceParam kMirrorParams[] = {kKr,        /* also */ kKa, kKd, kKs,
                                          kRoughness, kSpecularColor, kKt, kEta};
constexpr SurfaceParam kGlassParams[] = {kKr, kKt, kEta,       /* also */ kKa,
                                         kKd, kKs, kRoughness, kSpecularColor};

// glossy: plastic's parameters plus the traced reflection's "samples" and "spread" (docs/light_transport.md).
constexpr SurfaceParam kGlossyParams[] = {kKa,
                                          kKd,
                                          kKs,
                                          kRoughness,
                                          kSpecularColor,
                                          kGlossSamples,
                                          kSpread,
                                          /* also */ kKr,
                                          kKt,
                                          kEta};

constexpr SurfaceShader kSurfaceShaders[] = {
    {"matte", MaterialType::Matte, kMatteParams},
    {"plastic", MaterialType::Plastic, kPlasticParams},
    {"metal", MaterialType::Metal, kMetalParams},
    {"constant", MaterialType::Constant, kConstantParams},
    {"mirror", MaterialType::Mirror, kMirrorParams},
    {"glass", MaterialType::Glass, kGlassParams},
    {"shinymetal", MaterialType::ShinyMetal, kShinyMetalParams},
    {"paintedplastic", MaterialType::PaintedPlastic, kPlasticParams},
    {"glossy", MaterialType::Glossy, kGlossyParams},
};

// Light parameters (RI spec 3.2, appendix A): "from" is the position of point and distant lights,
// "to" only aims distant lights; a light given a parameter it lacks warns and ignores it.
constexpr LightParam kIntensity{"intensity", &LightShaderParams::intensity};
constexpr LightParam kLightColor{"lightcolor", kColor, &LightShaderParams::lightcolor};
constexpr LightParam kFrom{"from", kPoint, &LightShaderParams::from};
constexpr LightParam kTo{"to", kPoint, &LightShaderParams::to};

constexpr LightParam kAmbientParams[] = {kIntensity, kLightColor};
constexpr LightParam kDistantParams[] = {kIntensity, kLightColor, kFrom, kTo};
constexpr LightParam kPointParams[] = {kIntensity, kLightColor, kFrom};
constexpr LightParam kConeAngle{"coneangle", &LightShaderParams::coneangle};
constexpr LightParam kConeDeltaAngle{"conedeltaangle", &LightShaderParams::conedeltaangle};
constexpr LightParam kBeamDistribution{"beamdistribution", &LightShaderParams::beamdistribution};
constexpr LightParam kSpotParams[] = {kIntensity,      kLightColor,      kFrom, kTo, kConeAngle,
                                      kConeDeltaAngle, kBeamDistribution};

// RI arealight (RI spec 3.2, appendix A) with the sample count of BMRT's and PRMan's area lights.
constexpr LightParam kSamples{"samples", &LightShaderParams::samples};
constexpr LightParam kAreaParams[] = {kIntensity, kLightColor, kSamples};

// The RI standard shadowing lights (RI spec 3.2, appendix A; the parameters of PRMan's and Aqsis'
// shaders): the plain light plus "samples" and "width" of the shadow() lookup and, read by the reader,
// the map names. "samples" is accepted and unused: the percentage-closer filter integrates its box
// exactly (shading/shadow_map.h).
constexpr LightParam kShadowWidth{"width", &LightShaderParams::width};
constexpr LightParam kShadowDistantParams[] = {kIntensity, kLightColor, kFrom, kTo, kSamples, kShadowWidth};
constexpr LightParam kShadowPointParams[] = {kIntensity, kLightColor, kFrom, kSamples, kShadowWidth};
constexpr LightParam kShadowSpotParams[] = {
    kIntensity,      kLightColor,       kFrom,    kTo,         kConeAngle,
    kConeDeltaAngle, kBeamDistribution, kSamples, kShadowWidth};

constexpr LightShader kLightShaders[] = {
    {"ambientlight", LightType::Ambient, kAmbientParams},
    {"distantlight", LightType::Distant, kDistantParams},
    {"pointlight", LightType::Point, kPointParams},
    {"spotlight", LightType::Spot, kSpotParams},
    {"arealight", LightType::Area, kAreaParams},
    {"shadowdistant", LightType::Distant, kShadowDistantParams, ShadowNames::One},
    {"shadowspot", LightType::Spot, kShadowSpotParams, ShadowNames::One},
    {"shadowpoint", LightType::Point, kShadowPointParams, ShadowNames::Cube},
};

template <class Shader>
const Shader* findByName(std::span<const Shader> shaders, std::string_view name) {
    for (const Shader& s : shaders)
        if (name == s.name) return &s;
    return nullptr;
}

template <class Target>
void declareRows(std::span<const ShaderParam<Target>> rows, Declarations& decls) {
    for (const ShaderParam<Target>& row : rows) decls.declare(row.name, declarationOf(row.type));
}

}  // namespace

Decl declarationOf(ShaderParamType type) {
    Decl d;
    d.cls = "uniform";
    d.type = type == kFloat ? "float" : (type == kColor ? "color" : "point");
    return d;
}

std::span<const SurfaceShader> surfaceShaders() {
    return kSurfaceShaders;
}
std::span<const LightShader> lightShaders() {
    return kLightShaders;
}

const SurfaceShader* findSurfaceShader(std::string_view name) {
    return findByName(surfaceShaders(), name);
}
const LightShader* findLightShader(std::string_view name) {
    return findByName(lightShaders(), name);
}

void declareShaderParams(Declarations& decls) {
    for (const SurfaceShader& s : surfaceShaders()) declareRows(s.params, decls);
    for (const LightShader& s : lightShaders()) declareRows(s.params, decls);
    Decl name;
    name.type = "string";
    decls.declare("texturename", name);  // paintedplastic, shinymetal, bumpy (RI spec 3.2, appendix A)
    decls.declare(kShadowNameParam, name);
    for (const char* face : kCubeShadowNameParams) decls.declare(face, name);
    Decl background;
    background.cls = "uniform";
    background.type = "color";
    decls.declare("background", background);  // the background imager
}

template <class Target>
void applyShaderParams(std::span<const ShaderParam<Target>> rows, const Request& r,
                       const std::vector<Param>& params, Target& target, const std::string& what,
                       Diagnostics& diag) {
    for (const Param& p : params) {
        const ShaderParam<Target>* row = findByName(rows, p.name);
        if (!row)
            warnIgnoredParam(p, what, diag);
        else if (row->type == kFloat)
            target.*(row->scalar) = paramFloat(r, p, diag);
        else
            target.*(row->triple) = paramTriple(r, p, diag);
    }
}

template void applyShaderParams(std::span<const ShaderParam<Material>>, const Request&,
                                const std::vector<Param>&, Material&, const std::string&, Diagnostics&);
template void applyShaderParams(std::span<const ShaderParam<LightShaderParams>>, const Request&,
                                const std::vector<Param>&, LightShaderParams&, const std::string&,
                                Diagnostics&);

}  // namespace tessera::rib
