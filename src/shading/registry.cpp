#include "shading/registry.h"

#include <array>
#include <cmath>

namespace tessera {
namespace {

constexpr std::array kSurfaces = {
    SurfaceShaderInfo{"matte", MaterialType::Matte, false},
    SurfaceShaderInfo{"plastic", MaterialType::Plastic, false},
    SurfaceShaderInfo{"metal", MaterialType::Metal, false},
    SurfaceShaderInfo{"shinymetal", MaterialType::ShinyMetal, false},
    SurfaceShaderInfo{"paintedplastic", MaterialType::PaintedPlastic, false},
    SurfaceShaderInfo{"constant", MaterialType::Constant, false},
    SurfaceShaderInfo{"mirror", MaterialType::Mirror, true},
    SurfaceShaderInfo{"glass", MaterialType::Glass, true},
    SurfaceShaderInfo{"glossy", MaterialType::Glossy, true},
};

constexpr std::array kLights = {
    LightShaderInfo{"ambientlight", LightType::Ambient},
    LightShaderInfo{"distantlight", LightType::Distant},
    LightShaderInfo{"pointlight", LightType::Point},
    LightShaderInfo{"spotlight", LightType::Spot},
    LightShaderInfo{"arealight", LightType::Area},
    // The shadowing lights: the same light, its shadows from map files (Light::shadowSource).
    LightShaderInfo{"shadowdistant", LightType::Distant},
    LightShaderInfo{"shadowspot", LightType::Spot},
    LightShaderInfo{"shadowpoint", LightType::Point},
};

constexpr std::array kDisplacements = {
    DisplacementShaderInfo{"bumpy", DisplacementType::Bumpy},
    DisplacementShaderInfo{"offset", DisplacementType::Offset},
};

template <class Table>
const typename Table::value_type* findIn(const Table& table, std::string_view name) {
    for (const auto& e : table)
        if (e.name == name) return &e;
    return nullptr;
}

}  // namespace

std::span<const SurfaceShaderInfo> surfaceShaders() {
    return kSurfaces;
}
std::span<const LightShaderInfo> lightShaders() {
    return kLights;
}
std::span<const DisplacementShaderInfo> displacementShaders() {
    return kDisplacements;
}

const SurfaceShaderInfo* findSurfaceShader(std::string_view name) {
    return findIn(kSurfaces, name);
}
const LightShaderInfo* findLightShader(std::string_view name) {
    return findIn(kLights, name);
}
const DisplacementShaderInfo* findDisplacementShader(std::string_view name) {
    return findIn(kDisplacements, name);
}

const SurfaceShaderInfo& surfaceShaderInfo(MaterialType type) {
    for (const auto& e : kSurfaces)
        if (e.type == type) return e;
    return kSurfaces[0];
}

Material defaultMaterial(MaterialType type) {
    Material m;
    m.type = type;
    switch (type) {
        case MaterialType::Matte:
            m.Ka = 1, m.Kd = 1;
            break;
        case MaterialType::Plastic:
        case MaterialType::PaintedPlastic:
            m.Ka = 1, m.Kd = 0.5f, m.Ks = 0.5f, m.roughness = 0.1f;
            break;
        case MaterialType::Metal:
            m.Ka = 1, m.Ks = 1, m.roughness = 0.1f;
            break;
        case MaterialType::ShinyMetal:
            m.Ka = 1, m.Ks = 1, m.Kr = 1, m.roughness = 0.1f;
            break;
        case MaterialType::Constant:
            break;
        case MaterialType::Mirror:
            m.Kr = 1;
            m.Ka = 0, m.Kd = 0;
            break;
        case MaterialType::Glass:
            m.Kr = 1, m.Kt = 1, m.eta = 1.5f;
            m.Ka = 0, m.Kd = 0;
            break;
        case MaterialType::Glossy:  // plastic's terms, its Ks the glossy reflection's weight
            m.Ka = 1, m.Kd = 0.5f, m.Ks = 0.5f, m.roughness = 0.1f;
            break;
    }
    return m;
}

Light defaultLight(LightType type) {
    // RI spec appendix A: intensity 1, lightcolor 1, from (0,0,0), to (0,0,1); spotlight coneangle
    // radians(30), conedeltaangle radians(5), beamdistribution 2.
    Light l;
    l.type = type;
    l.color = {1, 1, 1};
    l.from = {0, 0, 0};
    l.to = {0, 0, 1};
    if (type == LightType::Spot) {
        l.coneAngle = 30.f * float(M_PI) / 180.f;
        l.coneDeltaAngle = 5.f * float(M_PI) / 180.f;
        l.beamDistribution = 2.f;
    }
    return l;
}

}  // namespace tessera
