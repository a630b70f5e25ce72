// Lights prepared for shading and the one light-sampling call both engines use: for a shading point it
// gives the direction to the light, the radiance arriving, the distance and what a visibility query needs
// (RI spec 3.2, appendix A: ambientlight, distantlight, pointlight, spotlight).
#pragma once
#include <cmath>
#include <limits>

#include "core/hostdevice.h"
#include "core/transform.h"
#include "scene/scene.h"
#include "shading/shadow_map.h"

namespace tessera {

// Whether a light is at a position (point, spot): its shadow rays end there. Area lights are sampled
// over their surfaces by the ray tracer (rt/area_lights.h); sampleLight() gives them nothing.
TESSERA_HD bool isPositional(LightType t) {
    return t == LightType::Point || t == LightType::Spot;
}

// A light in one space (camera space for Reyes, the accel's space for the ray tracer).
struct ShadingLight {
    LightType type = LightType::Distant;
    Color color;     // intensity * lightcolor
    Vec3 position;   // point and spot lights
    Vec3 direction;  // distant and spot lights: unit vector the light travels along (from -> to)
    // Spotlight: cos(coneangle) and cos(coneangle - conedeltaangle) for the smoothstep, beam exponent.
    float cosOuter = -1.f, cosInner = -1.f, beamDistribution = 0.f;
    // Whether its light samples ask the engine for visibility (shadows); engines set it from the light and
    // RenderSettings::shadows (FrameSetup).
    bool castsShadows = false;
    // Its shadows are ray traced whatever the engine (the RI shadowname "raytrace"): Reyes answers its
    // queries with shadow rays even where it renders maps for the other lights.
    bool tracedShadows = false;
    // Its shadows come from depth maps read from files (Light::shadowFiles; the frame owns them):
    // sampleLights looks them up and the light asks no visibility queries (castsShadows is false).
    const ShadowMapLookup* shadowMap = nullptr;
};

inline ShadingLight prepareLight(const Light& l, const Mat4& toSpace) {
    ShadingLight s;
    s.type = l.type;
    s.color = l.color;
    s.position = toSpace.point(l.from);
    s.direction = normalize(toSpace.vector(l.to - l.from));
    s.castsShadows = l.castsShadows && l.type != LightType::Ambient;
    if (l.type == LightType::Spot) {
        s.cosOuter = std::cos(l.coneAngle);
        s.cosInner = std::cos(std::max(0.f, l.coneAngle - l.coneDeltaAngle));
        s.beamDistribution = l.beamDistribution;
    }
    return s;
}

// What the light gives a shading point. `valid` is false when no light arrives (behind a spotlight's
// cone, at the light's position); ambient lights have L = 0 and are never occluded. A visibility query of a
// point or spot light ends at the light's position (ShadingLight::position); kept out of the sample, which
// the ray tracer stores per hit and light.
struct LightSample {
    Vec3 L;            // unit direction from P to the light
    Color Cl;          // radiance arriving at P, before visibility
    float dist = 0.f;  // to the light (infinity for distant lights)
    bool valid = false;
    bool ambient = false;
};

// RI smoothstep(e0, e1, x).
TESSERA_HD float smoothStep(float e0, float e1, float x) {
    if (x <= e0) return 0.f;
    if (x >= e1) return 1.f;
    const float t = (x - e0) / (e1 - e0);
    return t * t * (3.f - 2.f * t);
}

// The light incidence at P: the single place where a light's direction, falloff and cone are evaluated.
TESSERA_HD LightSample sampleLight(const ShadingLight& l, Vec3 P) {
    LightSample s;
    switch (l.type) {
        case LightType::Ambient:
            s.Cl = l.color;
            s.valid = s.ambient = true;
            return s;
        case LightType::Area:  // sampled over its surfaces by the ray tracer (rt/area_lights.h)
            return s;
        case LightType::Distant:
            s.L = -l.direction;
            s.Cl = l.color;
            s.dist = std::numeric_limits<float>::infinity();
            s.valid = true;
            return s;
        case LightType::Point:
        case LightType::Spot: {
            const Vec3 d = l.position - P;
            const float d2 = dot(d, d);
            if (!(d2 > 0)) return s;
            s.dist = std::sqrt(d2);
            s.L = d / s.dist;
            s.Cl = l.color / d2;  // RI pointlight / spotlight: intensity * lightcolor / (L.L)
            if (l.type == LightType::Spot) {
                // RI spotlight: cosangle = L.A (from the light), atten = cosangle^beamdistribution *
                // smoothstep(cos(coneangle), cos(coneangle - conedeltaangle), cosangle).
                const float cosAngle = -dot(s.L, l.direction);
                if (cosAngle < l.cosOuter) return s;
                s.Cl *= powf(std::max(cosAngle, 0.f), l.beamDistribution) *
                        smoothStep(l.cosOuter, l.cosInner, cosAngle);
            }
            s.valid = true;
            return s;
        }
    }
    return s;
}

}  // namespace tessera
