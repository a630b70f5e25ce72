// Reflection models of the surfaces: the RI diffuse and specular terms, ideal mirror reflection and
// refraction with the Fresnel reflectance. Plain functions over plain values (shared by both engines and,
// later, a GPU backend).
#pragma once
#include <algorithm>
#include <cmath>

#include "core/hostdevice.h"
#include "core/vec.h"

namespace tessera {

// faceforward(N, I): N turned to face against the incident direction I.
TESSERA_HD Vec3 faceForward(Vec3 N, Vec3 I) {
    return dot(N, I) < 0 ? N : -N;
}

// Exponent of the RI specular() lobe max(0, N.H)^e. The spec writes e = 1/roughness, but PRMan, BMRT and
// Aqsis all use e = 1/(roughness/8) (BMRT's and Aqsis' shader sources; the RenderMan Companion's plastic
// images); we follow the renderers so that RIBs written for them look the same here.
TESSERA_HD float specularExponent(float roughness) {
    return 8.f / std::max(roughness, 1e-4f);
}

// One light's contribution to the RI specular() sum, before Cl: max(0, Nf.H)^e, H = normalize(L + V).
TESSERA_HD float specularLobe(Vec3 Nf, Vec3 V, Vec3 L, float exponent) {
    const Vec3 H = normalize(L + V);
    const float nh = dot(Nf, H);
    return nh > 0.f ? powf(nh, exponent) : 0.f;
}

// Mirror direction of I about N (unit vectors; N on either side).
TESSERA_HD Vec3 reflectDir(Vec3 I, Vec3 N) {
    return normalize(I - N * (2.f * dot(I, N)));
}

// Refraction through a surface of relative index eta (outside 1, inside eta; N points outside). Returns
// false on total internal reflection (F = 1); F receives the unpolarised Fresnel reflectance of a
// dielectric (Hecht, Optics, ch. 4).
TESSERA_HD bool refractDir(Vec3 I, Vec3 N, float eta, Vec3& T, float& F) {
    float cosi = -dot(I, N);
    float n1 = 1.f, n2 = eta;
    Vec3 n = N;
    if (cosi < 0.f) {  // leaving the medium
        cosi = -cosi;
        n = -N;
        const float t = n1;  // swap by hand: std::swap is not a device function
        n1 = n2;
        n2 = t;
    }
    const float r = n1 / n2;
    const float sin2t = r * r * std::max(0.f, 1.f - cosi * cosi);
    if (sin2t >= 1.f) {
        F = 1.f;
        return false;
    }
    const float cost = std::sqrt(1.f - sin2t);
    const float rs = (n1 * cosi - n2 * cost) / (n1 * cosi + n2 * cost);
    const float rp = (n1 * cost - n2 * cosi) / (n1 * cost + n2 * cosi);
    F = 0.5f * (rs * rs + rp * rp);
    T = normalize(I * r + n * (r * cosi - cost));
    return true;
}

}  // namespace tessera
