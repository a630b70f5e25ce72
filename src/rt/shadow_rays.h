// Shadow rays for the visibility queries of a shading batch's light samples: what the integrator traces
// for its hits and what Reyes' ray-traced shadows (rt/ray_visibility.h) trace for its grid vertices, so that
// both engines ask the same question of the same trace service.
#pragma once
#include <cmath>
#include <span>
#include <vector>

#include "rt/accel.h"
#include "rt/binning.h"
#include "rt/ray_list.h"
#include "shading/surface.h"

namespace tessera::rt {

// Where shadow rays of a point start from: its patch and (u,v) on it (the self-intersection guard; kNone
// and x < 0: unknown), its shutter time and the owner the ray list records.
struct ShadowOrigin {
    uint32_t patch = kNone;
    Vec2 uv{-1.f, -1.f};
    float time = 0.f;
    uint32_t owner = 0;
};

// Direction and length of the shadow ray of `sample` from the offset origin o: towards a point or spot
// light it is aimed from o, so that the ray's line passes through the light (the shadow binning projects
// from the light); it stops `offset` short of the light.
inline void aimShadowRay(const ShadingLight& light, const LightSample& sample, Vec3 o, float offset, Vec3& L,
                         float& tmax) {
    L = sample.L;
    tmax = sample.dist;
    if (isPositional(light.type)) {
        const Vec3 toLight = light.position - o;
        const float len = length(toLight);
        if (len > 0.f && std::isfinite(len)) L = toLight / len, tmax = len;
    }
    if (std::isfinite(tmax)) tmax -= offset;
}

// The queries as shadow rays, light by light (one ShadowRun per light that has rays, for the shadow
// binning), from the face-forward side of the surface offset by acc.offset. shadowIdx[point * lights +
// light]: the sample's ray (kNone: none). originOf(k) -> ShadowOrigin of point k.
template <class OriginOf>
void makeShadowRays(const RtAccel& acc, std::span<const ShadingLight> lights, const SurfacePoints& pts,
                    const LightSamples& ls, OriginOf&& originOf, RayList& rays, std::vector<ShadowRun>& runs,
                    std::vector<uint32_t>& shadowIdx) {
    const size_t n = pts.count, nL = ls.lights;
    shadowIdx.assign(n * nL, kNone);
    rays.clear();
    runs.clear();
    rays.reserve(n * std::max<size_t>(nL, 1));
    for (size_t l = 0; l < nL; ++l) {
        const size_t runBegin = rays.size();
        for (size_t k = 0; k < n; ++k) {
            if (!ls.needsVisibility[ls.index(k, l)]) continue;
            const LightSample& sample = ls.sample[ls.index(k, l)];
            const Vec3 Nf = faceForward(pts.N[k], pts.I[k]);
            const Vec3 o = pts.P[k] + Nf * acc.offset;
            Vec3 L;
            float tmax;
            aimShadowRay(lights[l], sample, o, acc.offset, L, tmax);
            if (isPositional(lights[l].type) && !(dot(Nf, L) > 0.f)) continue;
            const ShadowOrigin from = originOf(k);
            shadowIdx[k * nL + l] = uint32_t(rays.size());
            rays.push(o, L, 0.f, tmax, from.owner, Color{}, from.patch, kShadow, 0, from.uv, Nf, from.time);
        }
        if (rays.size() > runBegin)
            runs.push_back({runBegin, rays.size(), isPositional(lights[l].type), lights[l].position});
    }
}

// The shadow rays' answers as the light samples' visibility (0 where blocked). `shadowedLights` (may be
// nullptr): per point, the number of lights in shadow (the film's shadow-count channel), counting also
// the lights whose visibility sampleLights took from maps read from files.
inline void applyShadowRays(const std::vector<uint32_t>& shadowIdx, const std::vector<uint8_t>& blocked,
                            LightSamples& ls, size_t points, uint8_t* shadowedLights) {
    const size_t nL = ls.lights;
    for (size_t k = 0; k < points; ++k) {
        if (shadowedLights) shadowedLights[k] = 0;
        for (size_t l = 0; l < nL; ++l) {
            const uint32_t s = shadowIdx[k * nL + l];
            if (s != kNone && blocked[s]) ls.visibility[k * nL + l] = 0.f;
            // In shadow where more than half of the light is blocked (shadow-map lights are filtered).
            if (shadowedLights && ls.visibility[k * nL + l] < 0.5f) ++shadowedLights[k];
        }
    }
}

}  // namespace tessera::rt
