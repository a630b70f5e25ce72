// The shader registry: surfaces, lights and displacements looked up by name. Readers map a RIB
// `Surface "plastic"` or `LightSource "spotlight"` here to a kind tag and the RI defaults; the engines
// dispatch on the tag (no virtual calls in the kernels). A shading language plugs in by adding entries.
#pragma once
#include <span>
#include <string_view>

#include "scene/scene.h"

namespace tessera {

struct SurfaceShaderInfo {
    std::string_view name;
    MaterialType type;
    bool traced;  // part of its response needs ray tracing (mirror, glass)
};

struct LightShaderInfo {
    std::string_view name;
    LightType type;
};

// Displacement shaders: RI bumpy and Tessera's constant-amplitude offset (scene.h DisplacementType).
struct DisplacementShaderInfo {
    std::string_view name;
    DisplacementType type;
};

std::span<const SurfaceShaderInfo> surfaceShaders();
std::span<const LightShaderInfo> lightShaders();
std::span<const DisplacementShaderInfo> displacementShaders();

// nullptr when the name is not registered.
const SurfaceShaderInfo* findSurfaceShader(std::string_view name);
const LightShaderInfo* findLightShader(std::string_view name);
const DisplacementShaderInfo* findDisplacementShader(std::string_view name);
const SurfaceShaderInfo& surfaceShaderInfo(MaterialType type);

// Defaults of the RI standard shaders (RI spec 3.2, appendix A) for a surface or light kind.
Material defaultMaterial(MaterialType type);
Light defaultLight(LightType type);

}  // namespace tessera
