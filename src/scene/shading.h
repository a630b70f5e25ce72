// Local illumination of the RI standard surface shaders (RI spec 3.2, appendix A: matte, metal, plastic,
// constant) with the standard light shaders (ambientlight, distantlight, pointlight). Both engines call
// this; the ray tracer passes a visibility callback for shadows, the Reyes engine none.
#pragma once
#include <cmath>
#include <span>

#include "scene/scene.h"

namespace tessera {

// A light prepared for shading in one space (camera space for Reyes, world space for the ray tracer).
struct ShadingLight {
    LightType type;
    Color color;
    Vec3 position;   // point lights
    Vec3 direction;  // distant lights: unit vector the light travels along (from -> to)
};

inline ShadingLight prepareLight(const Light& l, const Mat4& toSpace) {
    ShadingLight s{l.type, l.color, toSpace.point(l.from), normalize(toSpace.vector(l.to - l.from))};
    return s;
}

// Direction to the light (unit), the light's colour arriving at P and the distance to it.
inline bool lightIncidence(const ShadingLight& l, Vec3 P, Vec3& L, Color& Cl, float& dist) {
    if (l.type == LightType::Distant) {
        L = -l.direction;
        Cl = l.color;
        dist = std::numeric_limits<float>::infinity();
        return true;
    }
    if (l.type == LightType::Point) {
        Vec3 d = l.position - P;
        float d2 = dot(d, d);
        if (!(d2 > 0)) return false;
        dist = std::sqrt(d2);
        L = d / dist;
        Cl = l.color / d2;  // RI pointlight: intensity * lightcolor / (L.L)
        return true;
    }
    return false;
}

// faceforward(N, I): N turned to face against the incident direction I.
inline Vec3 faceForward(Vec3 N, Vec3 I) { return dot(N, I) < 0 ? N : -N; }

// Colour leaving P towards the eye. N: unit normal (any side), I: unit direction from the eye to P.
// visible(lightIndex, P, L, dist) -> transmission in [0,1] (shadows); return 1 for no shadows.
template <class Visibility>
Color shadeLocal(const Material& m, Vec3 P, Vec3 N, Vec3 I, std::span<const ShadingLight> lights,
                 Visibility&& visible) {
    if (m.type == MaterialType::Constant) return m.Os * m.Cs;
    Vec3 Nf = faceForward(N, I);
    Vec3 V = -I;
    Color ambient, diffuse, specular;
    const float exponent = 1.f / std::max(m.roughness, 1e-4f);
    for (size_t i = 0; i < lights.size(); ++i) {
        const ShadingLight& l = lights[i];
        if (l.type == LightType::Ambient) {
            ambient += l.color;
            continue;
        }
        Vec3 L;
        Color Cl;
        float dist;
        if (!lightIncidence(l, P, L, Cl, dist)) continue;
        float nl = dot(Nf, L);
        if (nl <= 0.f) continue;
        float vis = visible(i, P, L, dist);
        if (vis <= 0.f) continue;
        Cl *= vis;
        diffuse += Cl * nl;
        // RI specular(): sum Cl * max(0, N.H)^(1/roughness), H = normalize(L + V).
        Vec3 H = normalize(L + V);
        float nh = dot(Nf, H);
        if (nh > 0.f) specular += Cl * std::pow(nh, exponent);
    }
    switch (m.type) {
        case MaterialType::Matte: return m.Os * m.Cs * (ambient * m.Ka + diffuse * m.Kd);
        case MaterialType::Metal: return m.Os * m.Cs * (ambient * m.Ka + specular * m.Ks);
        case MaterialType::Plastic:
        default:
            return m.Os * (m.Cs * (ambient * m.Ka + diffuse * m.Kd) + m.specularColor * specular * m.Ks);
    }
}

inline Color shadeLocal(const Material& m, Vec3 P, Vec3 N, Vec3 I, std::span<const ShadingLight> lights) {
    return shadeLocal(m, P, N, I, lights, [](size_t, Vec3, Vec3, float) { return 1.f; });
}

}  // namespace tessera
