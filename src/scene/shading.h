// Transitional: the shading now lives in src/shading (light.h, bsdf.h, surface.h, registry.h). This header
// keeps the per-point entry points that the ray tracer's integrator used until it moves onto the batch
// calls; it is removed with that move.
#pragma once
#include <span>

#include "shading/bsdf.h"
#include "shading/light.h"
#include "shading/registry.h"
#include "shading/surface.h"

namespace tessera {

// Direction to the light (unit), the light's colour arriving at P and the distance to it.
inline bool lightIncidence(const ShadingLight& l, Vec3 P, Vec3& L, Color& Cl, float& dist) {
    const LightSample s = sampleLight(l, P);
    if (!s.valid || s.ambient) return false;
    L = s.L;
    Cl = s.Cl;
    dist = s.dist;
    return true;
}

// Colour leaving P towards the eye; visible(lightIndex, P, L, dist) -> transmission in [0,1].
template <class Visibility>
Color shadeLocal(const Material& m, Vec3 P, Vec3 N, Vec3 I, std::span<const ShadingLight> lights,
                 Visibility&& visible) {
    constexpr size_t kMaxLights = 64;
    LightSample samples[kMaxLights];
    float vis[kMaxLights];
    const size_t n = std::min(lights.size(), kMaxLights);
    for (size_t l = 0; l < n; ++l) {
        samples[l] = sampleLight(lights[l], P);
        vis[l] = (samples[l].valid && !samples[l].ambient) ? visible(l, P, samples[l].L, samples[l].dist) : 1.f;
    }
    return shadeSurfacePoint(m, N, I, samples, vis, n);
}

}  // namespace tessera
