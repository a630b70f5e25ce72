// The surfaces: RI standard shaders (RI spec 3.2, appendix A: matte, metal, shinymetal, plastic,
// paintedplastic, constant) and the ray tracer's mirror and glass, evaluated over batches of shading
// points in structure-of-arrays form (a Reyes grid, or a list of ray hits). Light meets surface here and
// nowhere else: an engine (1) asks for the light samples of a batch, (2) answers their visibility queries
// (the ray tracer with shadow rays; Reyes with its shadow maps or the ray tracer's shadow rays, through
// engine/visibility.h), (3) shades.
#pragma once
#include <cstdint>
#include <span>
#include <vector>

#include "core/hostdevice.h"
#include "scene/scene.h"
#include "shading/bsdf.h"
#include "shading/light.h"

namespace tessera {

// A batch of shading points in one space. N: unit normal on either side (orientation already applied),
// I: unit direction from the eye (or the ray origin) to P.
struct SurfacePoints {
    size_t count = 0;
    const Vec3* P = nullptr;
    const Vec3* N = nullptr;
    const Vec3* I = nullptr;
    const uint32_t* material = nullptr;  // index into the materials per point; nullptr: all use materials[0]
    // Per point: the texture colour of a textured surface (paintedplastic's texture(texturename)), white
    // for untextured points; nullptr: no point is textured (shading/texture.h, shadeTexture).
    const Color* textureColor = nullptr;
    // Per point: the colour that multiplies the material's Cs (per-vertex "Cs", scene.h PatchVertexValues);
    // nullptr: none.
    const Color* vertexColor = nullptr;
    uint32_t materialOf(size_t i) const { return material ? material[i] : 0u; }
    Color textureOf(size_t i) const { return textureColor ? textureColor[i] : Color{1, 1, 1}; }
    // The material point i is shaded with: its own, Cs times the point's vertex colour.
    Material materialAt(std::span<const Material> materials, size_t i) const {
        Material m = materials[materialOf(i)];
        if (vertexColor) m.Cs = m.Cs * vertexColor[i];
        return m;
    }
};

// The light samples of a batch, [point * lights + light]. A sample with needsVisibility set asks the engine
// whether the segment from P towards the light (to `dist`, or to the light position) is clear; the engine
// writes the transmission in [0,1] to `visibility` (initialised to 1).
struct LightSamples {
    size_t lights = 0;
    std::vector<LightSample> sample;
    std::vector<uint8_t> needsVisibility;
    std::vector<float> visibility;
    size_t index(size_t point, size_t light) const { return point * lights + light; }
};

// Whether a surface is lit at all (constant is not: no light samples, no shadow rays).
// The albedo AOV of a surface (what denoisers such as OpenImageDenoise take as their albedo input): the
// diffuse reflectance Kd Cs (times the texture colour Ct) of the RI diffuse surfaces, Ks Cs of metals,
// white for mirror and glass (perfectly specular: the denoiser's convention), Cs for constant; clamped
// to [0, 1].
TESSERA_HD Color surfaceAlbedo(const Material& m, Color Ct = Color{1, 1, 1}) {
    Color a;
    switch (m.type) {
        case MaterialType::Metal:
        case MaterialType::ShinyMetal:
            a = m.Cs * m.Ks;
            break;
        case MaterialType::Mirror:
        case MaterialType::Glass:
            a = Color{1, 1, 1};
            break;
        case MaterialType::Constant:
            a = m.Cs;
            break;
        default:
            a = m.Cs * Ct * m.Kd;
            break;
    }
    return {std::fmin(std::fmax(a.x, 0.f), 1.f), std::fmin(std::fmax(a.y, 0.f), 1.f),
            std::fmin(std::fmax(a.z, 0.f), 1.f)};
}

TESSERA_HD bool surfaceUsesLights(MaterialType t) {
    return t != MaterialType::Constant;
}
// Whether part of a surface's response is traced (mirror and glass): Reyes shades only the local part.
TESSERA_HD bool surfaceHasTracedLobes(MaterialType t) {
    return t == MaterialType::Mirror || t == MaterialType::Glass || t == MaterialType::Glossy;
}

// Step 1: light samples for every point of the batch. Only lights that cast shadows (ShadingLight::
// castsShadows) ask for visibility, and not where they face the point's back side (Nf.L <= 0); lights
// whose shadows are maps read from files (ShadingLight::shadowMap) get their visibility here.
void sampleLights(std::span<const ShadingLight> lights, std::span<const Material> materials,
                  const SurfacePoints& points, LightSamples& out);

// Step 3: colour leaving each point towards -I (the local part: ambient, diffuse and specular terms; the
// traced lobes of mirror and glass come from tracedLobes()).
void shadeSurfaces(std::span<const Material> materials, const SurfacePoints& points, const LightSamples& ls,
                   Color* Ci);
// The same for points [begin, end) of the batch (Ci indexed like the batch), for parallel loops.
void shadeSurfaces(std::span<const Material> materials, const SurfacePoints& points, const LightSamples& ls,
                   size_t begin, size_t end, Color* Ci);

// Whether a material's response has a specular term (matte's has none: its lobes need not be evaluated).
TESSERA_HD bool surfaceHasSpecular(MaterialType t) {
    return t != MaterialType::Matte && t != MaterialType::Constant;
}

// A material's local response from its summed ambient, diffuse and specular light (RI spec 3.2, appendix
// A's shaders). `Ct` is the point's texture colour (white when untextured).
TESSERA_HD Color combineSurfaceTerms(const Material& m, Color ambient, Color diffuse, Color specular,
                                     Color Ct) {
    switch (m.type) {
        case MaterialType::Matte:
            return m.Os * m.Cs * (ambient * m.Ka + diffuse * m.Kd);
        // shinymetal adds Kr * an environment map; with no textures yet its local part is metal's.
        case MaterialType::Metal:
        case MaterialType::ShinyMetal:
            return m.Os * m.Cs * (ambient * m.Ka + specular * m.Ks);
        // paintedplastic is plastic with Cs * texture(texturename) (RI spec 3.2, appendix A).
        case MaterialType::PaintedPlastic:
            return m.Os * (m.Cs * Ct * (ambient * m.Ka + diffuse * m.Kd) + m.specularColor * specular * m.Ks);
        // Mirror and glass: the RI plastic terms with their own Ka, Kd, Ks (defaults 0, 0, 0.5: a highlight)
        // as the local part; reflection and refraction are traced lobes.
        // Glossy: plastic's terms too; its reflection of everything but the delta lights is traced
        // (glossyReflection), so area lights add no highlight to it (rt/rt_renderer.cpp).
        case MaterialType::Plastic:
        case MaterialType::Mirror:
        case MaterialType::Glass:
        case MaterialType::Glossy:
        default:
            return m.Os * (m.Cs * (ambient * m.Ka + diffuse * m.Kd) + m.specularColor * specular * m.Ks);
    }
}

// The local response of one point, over light samples given by sampleAt(l) and their visibility by
// visibilityAt(l): the one accumulation of the RI ambient, diffuse and specular terms that every path uses.
// `Ct` is the point's texture colour (white when untextured).
template <class SampleAt, class VisibilityAt>
TESSERA_HD Color shadeSurfaceLights(const Material& m, Vec3 N, Vec3 I, size_t lightCount, SampleAt&& sampleAt,
                                    VisibilityAt&& visibilityAt, Color Ct = Color{1, 1, 1}) {
    if (m.type == MaterialType::Constant) return m.Os * m.Cs;
    const Vec3 Nf = faceForward(N, I);
    const Vec3 V = -I;
    const float exponent = specularExponent(m.roughness);
    const bool specularTerm = surfaceHasSpecular(m.type);
    Color ambient, diffuse, specular;
    for (size_t l = 0; l < lightCount; ++l) {
        const LightSample s = sampleAt(l);
        if (!s.valid) continue;
        if (s.ambient) {
            ambient += s.Cl;
            continue;
        }
        const float nl = dot(Nf, s.L);
        if (nl <= 0.f) continue;
        const float vis = visibilityAt(l);
        if (vis <= 0.f) continue;
        const Color Cl = s.Cl * vis;
        diffuse += Cl * nl;
        if (specularTerm) specular += Cl * specularLobe(Nf, V, s.L, exponent);
    }
    return combineSurfaceTerms(m, ambient, diffuse, specular, Ct);
}

// The local response of one point from stored light samples and visibilities (the batch loop, and tests
// that check both engines get the same radiance for the same hit).
TESSERA_HD Color shadeSurfacePoint(const Material& m, Vec3 N, Vec3 I, const LightSample* samples,
                                   const float* visibility, size_t lightCount, Color Ct = Color{1, 1, 1}) {
    return shadeSurfaceLights(
        m, N, I, lightCount, [&](size_t l) -> const LightSample& { return samples[l]; },
        [&](size_t l) { return visibility[l]; }, Ct);
}

// Steps 1-3 fused for a batch whose every visibility query answers "visible" (Reyes when no light casts
// shadows and none reads a shadow-map file): the same light samples and accumulation, without storing
// the samples.
void shadeSurfacesUnoccluded(std::span<const ShadingLight> lights, std::span<const Material> materials,
                             const SurfacePoints& points, Color* Ci);

// A direction the integrator traces further, with the weight its radiance is multiplied by.
struct TracedLobe {
    Vec3 direction;
    Color weight;
    bool transmitted = false;  // starts on the far side of the surface
};

// The traced lobes of a surface at a point, weighted by `w` (the path's weight so far): a mirror
// reflects Kr * Cs; glass reflects Kr * F and transmits Kt * (1 - F) * Cs, F the Fresnel reflectance.
// Lobes whose weight is below `cutoff` are dropped. N is the outward normal. Returns the lobe count (<= 2).
TESSERA_HD int tracedLobes(const Material& m, Vec3 I, Vec3 N, Color w, float cutoff, TracedLobe out[2]) {
    const Vec3 Nf = faceForward(N, I);
    int n = 0;
    if (m.type == MaterialType::Mirror) {
        const Color wr = w * m.Cs * m.Kr;
        if (maxComponent(wr) > cutoff) out[n++] = {reflectDir(I, Nf), wr, false};
    } else if (m.type == MaterialType::Glass) {
        Vec3 T;
        float F;
        const bool refracts = refractDir(I, N, m.eta, T, F);
        const Color wr = w * (m.Kr * F);
        if (maxComponent(wr) > cutoff) out[n++] = {reflectDir(I, Nf), wr, false};
        const Color wt = w * m.Cs * (m.Kt * (1.f - F));
        if (refracts && maxComponent(wt) > cutoff) out[n++] = {T, wt, true};
    }
    return n;
}

}  // namespace tessera
