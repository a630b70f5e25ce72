// The built-in shaders a RIB file can name in Surface and LightSource (RI spec 3.2, appendix A, plus
// Tessera's mirror and glass), each with one table of the parameters it takes: the parameter's name,
// its type and the field it sets. Adding a shader parameter is adding a row; the row also declares the
// name (as "uniform float", "uniform color" or "uniform point"), so its values are type-checked.
#pragma once
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "io/rib_params.h"
#include "scene/scene.h"

namespace tessera::rib {

enum class ShaderParamType { Float, Color, Point };

// One parameter of a shader: RIB name, type, and the member of `Target` it sets.
template <class Target>
struct ShaderParam {
    const char* name;
    ShaderParamType type;
    float Target::*scalar = nullptr;  // for Float
    Vec3 Target::*triple = nullptr;   // for Color and Point

    constexpr ShaderParam(const char* n, float Target::*member)
        : name(n), type(ShaderParamType::Float), scalar(member) {}
    constexpr ShaderParam(const char* n, ShaderParamType t, Vec3 Target::*member)
        : name(n), type(t), triple(member) {}
};

// The declaration a row implies, e.g. "uniform color" (RI spec 3.2, appendix A: shader parameters
// are uniform).
Decl declarationOf(ShaderParamType type);

struct SurfaceShader {
    const char* name;
    MaterialType type;
    std::span<const ShaderParam<Material>> params;
};

// The parameters of the standard light shaders as written in RIB, before they become a Light
// (RI spec 3.2, appendix A defaults: intensity 1, lightcolor 1, from (0,0,0), to (0,0,1)).
struct LightShaderParams {
    float intensity = 1;
    Color lightcolor{1, 1, 1};
    Vec3 from{0, 0, 0};
    Vec3 to{0, 0, 1};
    // spotlight: radians(30), radians(5), 2
    float coneangle = 0.5235988f, conedeltaangle = 0.0872665f, beamdistribution = 2.f;
    float samples = 16;  // arealight: shadow rays per shading point (Light::samples)
    float width = 1;     // shadowspot, shadowdistant, shadowpoint: the shadow lookup's filter scale
};

// Which shadow-map file names a light shader reads (string parameters, read by the reader itself).
enum class ShadowNames { None, One, Cube };

// The string parameters naming shadow maps: "shadowname" (shadowspot, shadowdistant), and shadowpoint's
// six faces in Light::shadowFiles order (+x, -x, +y, -y, +z, -z).
inline constexpr const char* kShadowNameParam = "shadowname";
inline constexpr const char* kCubeShadowNameParams[6] = {"sfpx", "sfnx", "sfpy", "sfny", "sfpz", "sfnz"};

struct LightShader {
    const char* name;
    LightType type;
    std::span<const ShaderParam<LightShaderParams>> params;
    ShadowNames shadowNames = ShadowNames::None;
};

std::span<const SurfaceShader> surfaceShaders();
std::span<const LightShader> lightShaders();
// nullptr for a shader Tessera does not have.
const SurfaceShader* findSurfaceShader(std::string_view name);
const LightShader* findLightShader(std::string_view name);

// Declares every table row's name with its type (called once per load, before any Declare).
void declareShaderParams(Declarations& decls);

// Sets `target`'s fields from the parameter list through `rows`; a parameter without a row is warned
// about once as an ignored parameter of `what` (e.g. `Surface "matte"`).
template <class Target>
void applyShaderParams(std::span<const ShaderParam<Target>> rows, const Request& r,
                       const std::vector<Param>& params, Target& target, const std::string& what,
                       Diagnostics& diag);

}  // namespace tessera::rib
