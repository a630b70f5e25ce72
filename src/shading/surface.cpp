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
        LightSample* s = out.sample.data() + i * nL;  // no lights: an empty vector, never dereferenced
        if (!surfaceUsesLights(materials[points.materialOf(i)].type)) {
            for (size_t l = 0; l < nL; ++l) s[l] = LightSample{};
            continue;
        }
        const Vec3 Nf = faceForward(points.N[i], points.I[i]);
        for (size_t l = 0; l < nL; ++l) {
            s[l] = sampleLight(lights[l], points.P[i]);
            const bool lit = s[l].valid && !s[l].ambient && dot(Nf, s[l].L) > 0.f;
            out.needsVisibility[i * nL + l] = lights[l].castsShadows && lit;
            // Maps read from files answer here, the same for every engine (shading/shadow_map.h).
            if (lights[l].shadowMap && lit)
                out.visibility[i * nL + l] =
                    shadowMapVisibility(*lights[l].shadowMap, points.P[i], points.N[i]);
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
        Ci[i] = shadeSurfacePoint(points.materialAt(materials, i), points.N[i], points.I[i],
                                  ls.sample.data() + i * nL, ls.visibility.data() + i * nL, nL,
                                  points.textureOf(i));
}

void shadeSurfacesUnoccluded(std::span<const ShadingLight> lights, std::span<const Material> materials,
                             const SurfacePoints& points, Color* Ci) {
    for (size_t i = 0; i < points.count; ++i) {
        const Vec3 P = points.P[i];
        Ci[i] = shadeSurfaceLights(
            points.materialAt(materials, i), points.N[i], points.I[i], lights.size(),
            [&](size_t l) { return sampleLight(lights[l], P); }, [](size_t) { return 1.f; },
            points.textureOf(i));
    }
}

}  // namespace tessera
