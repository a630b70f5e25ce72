// The RI surfaces read as physically based BSDFs for the path tracer (--integrator path,
// docs/light_transport.md): a Lambertian lobe of albedo Kd * Cs (times the texture colour), a GGX
// microfacet lobe of albedo at most Ks * specularcolor (Walter et al. 2007, with Smith's masking; the RI
// roughness mapped through the Blinn-Phong exponent the RI specular() uses, alpha = sqrt(2 / (e + 2)),
// Walter et al. sec. 5.2), the ideal mirror and the Fresnel dielectric of the Whitted path. Plain
// functions over plain values, shared with a GPU backend later.
//
// Energy: when Kd * Cs + Ks * specularcolor exceeds 1 in a channel, both lobes are scaled down to sum to
// 1 there (RI's plastic has no such bound; a path tracer needs it to converge).
#pragma once
#include <algorithm>
#include <cmath>

#include "core/hostdevice.h"
#include "core/vec.h"
#include "scene/scene.h"
#include "shading/bsdf.h"
#include "shading/hemisphere.h"

namespace tessera {

enum class PathLobes : uint8_t {
    None,       // constant: emits Os * Cs, reflects nothing
    Smooth,     // diffuse and/or glossy (matte, plastic, paintedplastic, metal, shinymetal)
    Mirror,     // delta reflection
    Dielectric  // delta reflection and refraction
};

struct PathBsdf {
    PathLobes lobes = PathLobes::Smooth;
    Color diffuse;  // Lambertian albedo
    Color glossy;   // microfacet lobe weight
    float alpha = 0.1f;
    float diffuseProbability = 1.f;  // of sampling the diffuse lobe (by the lobes' luminance)
    Color emission;                  // constant surfaces: Os * Cs
    Color mirror;                    // Kr * Cs
    float Kr = 1.f, Kt = 1.f, eta = 1.5f;
    Color transmit;  // Kt * Cs
};

TESSERA_HD float pathLuminance(Color c) {
    return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z;
}

// GGX alpha of an RI roughness: the Blinn-Phong exponent of RI specular() (bsdf.h) mapped as Walter et
// al. 2007, eq. 29's Beckmann correspondence, alpha = sqrt(2 / (e + 2)).
TESSERA_HD float ggxAlphaOfRoughness(float roughness) {
    return std::max(1e-3f, std::sqrt(2.f / (specularExponent(roughness) + 2.f)));
}

TESSERA_HD PathBsdf pathBsdfOf(const Material& m, Color Ct = Color{1, 1, 1}) {
    PathBsdf b;
    switch (m.type) {
        case MaterialType::Constant:
            b.lobes = PathLobes::None;
            b.emission = m.Os * m.Cs;
            return b;
        case MaterialType::Mirror:
            b.lobes = PathLobes::Mirror;
            b.mirror = m.Cs * std::min(m.Kr, 1.f);
            return b;
        case MaterialType::Glass:
            b.lobes = PathLobes::Dielectric;
            b.Kr = std::min(m.Kr, 1.f), b.Kt = std::min(m.Kt, 1.f), b.eta = m.eta;
            b.transmit = m.Cs * b.Kt;
            return b;
        case MaterialType::Matte:
            b.diffuse = m.Cs * m.Kd;
            break;
        case MaterialType::Metal:
        case MaterialType::ShinyMetal:
            b.glossy = m.Cs * m.Ks;
            break;
        case MaterialType::PaintedPlastic:
            b.diffuse = m.Cs * Ct * m.Kd;
            b.glossy = m.specularColor * m.Ks;
            break;
        case MaterialType::Plastic:
        case MaterialType::Glossy:
        default:
            b.diffuse = m.Cs * m.Kd;
            b.glossy = m.specularColor * m.Ks;
            break;
    }
    b.lobes = PathLobes::Smooth;
    auto clampColor = [](Color c) {
        return Color{std::max(c.x, 0.f), std::max(c.y, 0.f), std::max(c.z, 0.f)};
    };
    b.diffuse = clampColor(b.diffuse), b.glossy = clampColor(b.glossy);
    const float sum =
        std::max({b.diffuse.x + b.glossy.x, b.diffuse.y + b.glossy.y, b.diffuse.z + b.glossy.z});
    if (sum > 1.f) b.diffuse = b.diffuse / sum, b.glossy = b.glossy / sum;
    b.alpha = ggxAlphaOfRoughness(m.roughness);
    const float ld = pathLuminance(b.diffuse), lg = pathLuminance(b.glossy);
    b.diffuseProbability = ld + lg > 0.f ? ld / (ld + lg) : 1.f;
    return b;
}

// Whether a surface has a lobe that next-event estimation can evaluate (not delta, not black).
TESSERA_HD bool pathHasSmoothLobes(const PathBsdf& b) {
    return b.lobes == PathLobes::Smooth && (maxComponent(b.diffuse) > 0.f || maxComponent(b.glossy) > 0.f);
}

// GGX normal distribution D(h) with cos(theta_h) = c (Walter et al. 2007, eq. 33).
TESSERA_HD float ggxD(float c, float alpha) {
    if (c <= 0.f) return 0.f;
    const float a2 = alpha * alpha, c2 = c * c;
    const float d = c2 * (a2 - 1.f) + 1.f;
    return a2 / (3.14159265f * d * d);
}
// Smith's masking for GGX at cos(theta) = c (Walter et al. 2007, eq. 34).
TESSERA_HD float ggxG1(float c, float alpha) {
    if (c <= 0.f) return 0.f;
    const float a2 = alpha * alpha;
    return 2.f * c / (c + std::sqrt(a2 + (1.f - a2) * c * c));
}

// f(wo, wi) of the smooth lobes (wo towards the viewer, wi towards the light, both unit, Nf facing wo).
TESSERA_HD Color pathBsdfEval(const PathBsdf& b, Vec3 Nf, Vec3 wo, Vec3 wi) {
    const float ci = dot(Nf, wi), co = dot(Nf, wo);
    if (b.lobes != PathLobes::Smooth || ci <= 0.f || co <= 0.f) return Color{0, 0, 0};
    Color f = b.diffuse * (1.f / 3.14159265f);
    if (maxComponent(b.glossy) > 0.f) {
        const Vec3 h = normalize(wi + wo);
        const float D = ggxD(dot(Nf, h), b.alpha);
        f += b.glossy * (D * ggxG1(ci, b.alpha) * ggxG1(co, b.alpha) / (4.f * ci * co));
    }
    return f;
}

// The solid-angle density with which pathBsdfSample picks wi.
TESSERA_HD float pathBsdfPdf(const PathBsdf& b, Vec3 Nf, Vec3 wo, Vec3 wi) {
    const float ci = dot(Nf, wi), co = dot(Nf, wo);
    if (b.lobes != PathLobes::Smooth || ci <= 0.f || co <= 0.f) return 0.f;
    float pdf = b.diffuseProbability * ci * (1.f / 3.14159265f);
    if (b.diffuseProbability < 1.f) {
        const Vec3 h = normalize(wi + wo);
        const float ch = dot(Nf, h);
        const float oh = dot(wo, h);
        if (oh > 0.f) pdf += (1.f - b.diffuseProbability) * ggxD(ch, b.alpha) * ch / (4.f * oh);
    }
    return pdf;
}

struct PathBsdfSample {
    Vec3 wi;
    Color weight;     // f cos / pdf (delta lobes: their reflectance or transmittance)
    float pdf = 0.f;  // solid angle; 0 for delta lobes
    bool delta = false;
    bool transmitted = false;
    bool valid = false;
};

// A direction for the next bounce from three uniform numbers. I: unit incident direction (towards the
// surface); N: unit oriented normal (glass: outward). Samples below the surface are invalid (the path ends
// there: never a direction inside an opaque surface).
TESSERA_HD PathBsdfSample pathBsdfSample(const PathBsdf& b, Vec3 N, Vec3 I, float uLobe, float u1, float u2) {
    PathBsdfSample s;
    const Vec3 Nf = faceForward(N, I);
    const Vec3 wo = -I;
    switch (b.lobes) {
        case PathLobes::None:
            return s;
        case PathLobes::Mirror:
            s.wi = reflectDir(I, Nf);
            s.weight = b.mirror;
            s.delta = s.valid = maxComponent(b.mirror) > 0.f;
            return s;
        case PathLobes::Dielectric: {
            Vec3 T;
            float F;
            const bool refracts = refractDir(I, N, b.eta, T, F);
            // Reflect with probability F (1 at total internal reflection), refract otherwise: the
            // weights are then Kr and Kt * Cs.
            if (!refracts || uLobe < F) {
                s.wi = reflectDir(I, Nf);
                s.weight = Color{b.Kr, b.Kr, b.Kr};
            } else {
                s.wi = T;
                s.weight = b.transmit;
                s.transmitted = true;
            }
            s.delta = s.valid = maxComponent(s.weight) > 0.f;
            return s;
        }
        case PathLobes::Smooth:
            break;
    }
    if (!pathHasSmoothLobes(b)) return s;
    const Frame3 frame = frameAbout(Nf);
    if (uLobe < b.diffuseProbability) {
        s.wi = frame.toWorld(cosineHemisphere(u1, u2));
    } else {
        // h from D(h) cos(theta_h) (Walter et al. 2007, eqs. 35-36), wi its reflection of wo.
        const float a2 = b.alpha * b.alpha;
        const float c2 = (1.f - u1) / (1.f + (a2 - 1.f) * u1);
        const float c = std::sqrt(std::max(0.f, c2)), sn = std::sqrt(std::max(0.f, 1.f - c2));
        const float phi = 6.2831853f * u2;
        const Vec3 h = frame.toWorld(Vec3{sn * std::cos(phi), sn * std::sin(phi), c});
        s.wi = h * (2.f * dot(wo, h)) - wo;
    }
    const float ci = dot(Nf, s.wi);
    if (!(ci > 0.f)) return s;
    s.pdf = pathBsdfPdf(b, Nf, wo, s.wi);
    if (!(s.pdf > 0.f)) return s;
    s.weight = pathBsdfEval(b, Nf, wo, s.wi) * (ci / s.pdf);
    s.valid = maxComponent(s.weight) > 0.f;
    return s;
}

// The power heuristic with exponent 2 (Veach 1997, sec. 9.2.4) of a sample drawn from density pa against
// another strategy's pb.
TESSERA_HD float powerHeuristic(float pa, float pb) {
    const float a = pa * pa, b = pb * pb;
    return a + b > 0.f ? a / (a + b) : 0.f;
}

}  // namespace tessera
