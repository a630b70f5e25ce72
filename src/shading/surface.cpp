#include "shading/surface.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

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

#if defined(__SSE2__)
namespace {

// Four points' coordinates, one lane each.
struct Lanes3 {
    __m128 x, y, z;
};

inline __m128 dotLanes(const Lanes3& a, const Lanes3& b) {  // dot()'s (x x + y y) + z z
    return _mm_add_ps(_mm_add_ps(_mm_mul_ps(a.x, b.x), _mm_mul_ps(a.y, b.y)), _mm_mul_ps(a.z, b.z));
}
inline __m128 selectLanes(__m128 mask, __m128 a, __m128 b) {  // a where mask, else b: the bits as they are
    return _mm_or_ps(_mm_and_ps(mask, a), _mm_andnot_ps(mask, b));
}
inline Lanes3 selectLanes(__m128 mask, const Lanes3& a, const Lanes3& b) {
    return {selectLanes(mask, a.x, b.x), selectLanes(mask, a.y, b.y), selectLanes(mask, a.z, b.z)};
}
inline Lanes3 negateLanes(const Lanes3& a) {  // the sign bit flipped, as unary minus
    const __m128 sign = _mm_set1_ps(-0.f);
    return {_mm_xor_ps(a.x, sign), _mm_xor_ps(a.y, sign), _mm_xor_ps(a.z, sign)};
}
inline Lanes3 loadLanes(const Vec3* v) {
    return {_mm_setr_ps(v[0].x, v[1].x, v[2].x, v[3].x), _mm_setr_ps(v[0].y, v[1].y, v[2].y, v[3].y),
            _mm_setr_ps(v[0].z, v[1].z, v[2].z, v[3].z)};
}
inline Lanes3 broadcastLanes(Vec3 v) {
    return {_mm_set1_ps(v.x), _mm_set1_ps(v.y), _mm_set1_ps(v.z)};
}
// sum + Cl * w in the lanes of `active`; the others keep sum.
inline void addLanes(Lanes3& sum, __m128 active, const Lanes3& Cl, __m128 w) {
    sum = selectLanes(active,
                      {_mm_add_ps(sum.x, _mm_mul_ps(Cl.x, w)), _mm_add_ps(sum.y, _mm_mul_ps(Cl.y, w)),
                       _mm_add_ps(sum.z, _mm_mul_ps(Cl.z, w))},
                      sum);
}

// Whether the four-lane form below shades this batch: one untextured material without vertex colours, lit
// by ambient, distant and point lights (area lights give nothing here; spot lights take the scalar form).
bool lanesShade(std::span<const ShadingLight> lights, std::span<const Material> materials,
                const SurfacePoints& points) {
    if (points.material || points.textureColor || points.vertexColor || materials.empty() ||
        !surfaceUsesLights(materials[0].type))
        return false;
    for (const ShadingLight& l : lights)
        if (l.type == LightType::Spot) return false;
    return true;
}

// Points i .. i + 3 of the batch: shadeSurfaceLights with sampleLight and visibility 1, lane by lane the
// same float operations in the same order (so the same bits); powf per lit lane.
void shadeFourUnoccluded(std::span<const ShadingLight> lights, const Material& m, const SurfacePoints& points,
                         size_t i, Color* Ci) {
    const __m128 zero = _mm_setzero_ps();
    const Lanes3 P = loadLanes(points.P + i), N = loadLanes(points.N + i), I = loadLanes(points.I + i);
    const Lanes3 Nf = selectLanes(_mm_cmplt_ps(dotLanes(N, I), zero), N, negateLanes(N));  // faceForward
    const Lanes3 V = negateLanes(I);
    const float exponent = specularExponent(m.roughness);
    const bool specularTerm = surfaceHasSpecular(m.type);
    Lanes3 ambient{zero, zero, zero}, diffuse{zero, zero, zero}, specular{zero, zero, zero};
    for (const ShadingLight& light : lights) {
        Lanes3 L, Cl;
        __m128 valid;
        switch (light.type) {
            case LightType::Ambient:
                ambient = {_mm_add_ps(ambient.x, _mm_set1_ps(light.color.x)),
                           _mm_add_ps(ambient.y, _mm_set1_ps(light.color.y)),
                           _mm_add_ps(ambient.z, _mm_set1_ps(light.color.z))};
                continue;
            case LightType::Distant:
                L = broadcastLanes(-light.direction);
                Cl = broadcastLanes(light.color);
                valid = _mm_castsi128_ps(_mm_set1_epi32(-1));
                break;
            case LightType::Point: {
                const Lanes3 d{_mm_sub_ps(_mm_set1_ps(light.position.x), P.x),
                               _mm_sub_ps(_mm_set1_ps(light.position.y), P.y),
                               _mm_sub_ps(_mm_set1_ps(light.position.z), P.z)};
                const __m128 d2 = dotLanes(d, d);
                valid = _mm_cmpgt_ps(d2, zero);
                const __m128 dist = _mm_sqrt_ps(d2);
                L = {_mm_div_ps(d.x, dist), _mm_div_ps(d.y, dist), _mm_div_ps(d.z, dist)};
                Cl = {_mm_div_ps(_mm_set1_ps(light.color.x), d2), _mm_div_ps(_mm_set1_ps(light.color.y), d2),
                      _mm_div_ps(_mm_set1_ps(light.color.z), d2)};
                break;
            }
            default:  // area lights: sampleLight gives nothing (spot lights never come here)
                continue;
        }
        const __m128 nl = dotLanes(Nf, L);
        const __m128 active = _mm_and_ps(valid, _mm_cmpnle_ps(nl, zero));  // skipped where nl <= 0
        const int lanes = _mm_movemask_ps(active);
        if (!lanes) continue;
        addLanes(diffuse, active, Cl, nl);
        if (!specularTerm) continue;
        // specularLobe: H = normalize(L + V), max(0, Nf.H)^e.
        const Lanes3 h{_mm_add_ps(L.x, V.x), _mm_add_ps(L.y, V.y), _mm_add_ps(L.z, V.z)};
        const __m128 len = _mm_sqrt_ps(dotLanes(h, h));
        const Lanes3 H =
            selectLanes(_mm_cmpgt_ps(len, zero),
                        Lanes3{_mm_div_ps(h.x, len), _mm_div_ps(h.y, len), _mm_div_ps(h.z, len)}, h);
        alignas(16) float nh[4], lobe[4];
        _mm_store_ps(nh, dotLanes(Nf, H));
        for (int k = 0; k < 4; ++k) lobe[k] = (lanes >> k & 1) && nh[k] > 0.f ? powf(nh[k], exponent) : 0.f;
        addLanes(specular, active, Cl, _mm_load_ps(lobe));
    }
    alignas(16) float a[3][4], d[3][4], s[3][4];
    const Lanes3* sums[3] = {&ambient, &diffuse, &specular};
    float(*out[3])[4] = {a, d, s};
    for (int q = 0; q < 3; ++q) {
        _mm_store_ps(out[q][0], sums[q]->x);
        _mm_store_ps(out[q][1], sums[q]->y);
        _mm_store_ps(out[q][2], sums[q]->z);
    }
    for (int k = 0; k < 4; ++k)
        Ci[i + size_t(k)] = combineSurfaceTerms(m, {a[0][k], a[1][k], a[2][k]}, {d[0][k], d[1][k], d[2][k]},
                                                {s[0][k], s[1][k], s[2][k]}, Color{1, 1, 1});
}

}  // namespace
#endif

void shadeSurfacesUnoccluded(std::span<const ShadingLight> lights, std::span<const Material> materials,
                             const SurfacePoints& points, Color* Ci) {
    size_t i = 0;
#if defined(__SSE2__)
    // Four points at a time where the batch allows it (Reyes grids: one material, no shadows), the rest
    // one by one.
    if (lanesShade(lights, materials, points))
        for (; i + 4 <= points.count; i += 4) shadeFourUnoccluded(lights, materials[0], points, i, Ci);
#endif
    for (; i < points.count; ++i) {
        const Vec3 P = points.P[i];
        Ci[i] = shadeSurfaceLights(
            points.materialAt(materials, i), points.N[i], points.I[i], lights.size(),
            [&](size_t l) { return sampleLight(lights[l], P); }, [](size_t) { return 1.f; },
            points.textureOf(i));
    }
}

}  // namespace tessera
