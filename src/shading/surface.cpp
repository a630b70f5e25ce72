#include "shading/surface.h"

namespace tessera {

void sampleLights(std::span<const ShadingLight> lights, std::span<const Material> materials,
                  const SurfacePoints& points, LightSamples& out) {
    const size_t nL = lights.size(), n = points.count;
    out.lights = nL;
    out.sample.resize(n * nL);
    out.needsVisibility.assign(n * nL, 0);
    out.visibility.assign(n * nL, 1.f);
    for (size_t i = 0; i < n; ++i) {
        LightSample* s = &out.sample[i * nL];
        if (!surfaceUsesLights(materials[points.materialOf(i)].type)) {
            for (size_t l = 0; l < nL; ++l) s[l] = LightSample{};
            continue;
        }
        const Vec3 Nf = faceForward(points.N[i], points.I[i]);
        for (size_t l = 0; l < nL; ++l) {
            s[l] = sampleLight(lights[l], points.P[i]);
            out.needsVisibility[i * nL + l] = s[l].valid && !s[l].ambient && dot(Nf, s[l].L) > 0.f;
        }
    }
}

void shadeSurfaces(std::span<const Material> materials, const SurfacePoints& points, const LightSamples& ls,
                   Color* Ci) {
    shadeSurfaces(materials, points, ls, 0, points.count, Ci);
}

void shadeSurfaces(std::span<const Material> materials, const SurfacePoints& points, const LightSamples& ls,
                   size_t begin, size_t end, Color* Ci) {
    const size_t nL = ls.lights;
    for (size_t i = begin; i < end; ++i)
        Ci[i] = shadeSurfacePoint(materials[points.materialOf(i)], points.N[i], points.I[i], &ls.sample[i * nL],
                                  &ls.visibility[i * nL], nL);
}

}  // namespace tessera
