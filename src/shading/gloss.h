// Glossy reflection for the direct (Whitted) integrator: the traced part of Surface "glossy" as a few
// reflection rays per hit (docs/light_transport.md). Two models, chosen per render (--gloss):
// - paper (default): paper 002 sec. 5.3.5, R_i = normalize(R + s (p u + q v)) with (p, q) in the square
//   [-1, 1]^2, u and v perpendicular to the mirror direction R, each ray weighted Ks specularcolor / n.
//   The paper lets a ray point below the surface; here it is folded back about the tangent plane, so no
//   ray leaves into the surface and the reflected energy stays Ks specularcolor.
// - microfacet: the path tracer's GGX lobe (path_bsdf.h) importance-sampled, weight f cos / pdf; rays
//   below the surface are lost, as the microfacet model loses them (energy below Ks at grazing angles).
// Plain functions over plain values, shared with a GPU backend later.
#pragma once
#include <cmath>

#include "core/hostdevice.h"
#include "core/vec.h"
#include "shading/bsdf.h"
#include "shading/hemisphere.h"
#include "shading/path_bsdf.h"

namespace tessera {

enum class GlossModel : uint8_t { Paper, Microfacet };

// The paper's spread s of a glossy material: its "spread", else the GGX alpha of its roughness.
TESSERA_HD float glossSpread(const Material& m) {
    return m.spread >= 0.f ? m.spread : ggxAlphaOfRoughness(m.roughness);
}

struct GlossRay {
    Vec3 direction;
    Color weight;  // of the whole reflection, for one ray of `count` (already divided by count)
    bool valid = false;
};

// Reflection ray j of `count` at a point seen along I (unit, towards the surface) with outward normal N,
// from the sampler's pair (u1, u2) in [0, 1)^2.
TESSERA_HD GlossRay glossyReflection(const Material& m, GlossModel model, Vec3 N, Vec3 I, float u1, float u2,
                                     int count) {
    GlossRay g;
    const Vec3 Nf = faceForward(N, I);
    const Color Ks = m.specularColor * m.Ks;
    if (!(maxComponent(Ks) > 0.f) || count < 1) return g;
    if (model == GlossModel::Paper) {
        const Vec3 R = reflectDir(I, Nf);
        const Frame3 f = frameAbout(R);
        const float s = glossSpread(m), p = 2.f * u1 - 1.f, q = 2.f * u2 - 1.f;
        Vec3 d = normalize(R + (f.t * p + f.b * q) * s);
        const float c = dot(d, Nf);
        if (c < 0.f) d = d - Nf * (2.f * c);  // folded above the surface
        if (!(dot(d, Nf) > 1e-6f)) d = normalize(d + Nf * 1e-4f);
        g.direction = d;
        g.weight = Ks / float(count);
        g.valid = true;
        return g;
    }
    PathBsdf b;
    b.lobes = PathLobes::Smooth;
    b.glossy = Ks;
    b.alpha = ggxAlphaOfRoughness(m.roughness);
    b.diffuseProbability = 0.f;
    const PathBsdfSample s = pathBsdfSample(b, N, I, 1.f, u1, u2);
    if (!s.valid) return g;
    g.direction = s.wi;
    g.weight = s.weight / float(count);
    g.valid = true;
    return g;
}

}  // namespace tessera
