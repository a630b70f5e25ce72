#include "rt/area_lights.h"

#include <algorithm>
#include <cmath>

namespace tessera::rt {

AreaLightSurfacePoint areaLightPointAt(const RtAccel& acc, uint32_t patch, float u, float v) {
    AreaLightSurfacePoint s;
    SurfacePoint sp;
    Vec3 n;
    if (const PlacedQuadric* pq = acc.quadric(patch)) {
        sp = evalPlacedQuadric(*pq, u, v, &n);
    } else {
        sp = evalPatchDeriv(acc.patches[patch], u, v);
        n = cross(sp.dpdu, sp.dpdv);
    }
    s.p = sp.p;
    s.jacobian = length(cross(sp.dpdu, sp.dpdv));
    const float len = length(n);
    s.n = len > 0.f && std::isfinite(len) ? n / len : Vec3{0, 0, 0};
    if (acc.flip[patch]) s.n = -s.n;
    return s;
}

namespace {
// Area of a surface by the midpoint rule on a 16 x 16 grid of (u,v): only steers which surface a sample
// picks, so a few percent of error costs a little variance and no bias.
float surfaceArea(const RtAccel& acc, uint32_t patch) {
    constexpr int kN = 16;
    double a = 0;
    for (int j = 0; j < kN; ++j)
        for (int i = 0; i < kN; ++i) {
            const float j0 = areaLightPointAt(acc, patch, (i + 0.5f) / kN, (j + 0.5f) / kN).jacobian;
            if (std::isfinite(j0)) a += j0;
        }
    return float(a / (kN * kN));
}
float luminance(Color c) {
    return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z;
}
}  // namespace

AreaLights::AreaLights(const Scene& scene, const RtAccel& acc, const std::vector<uint8_t>& castsShadows) {
    const size_t nSurfaces = std::min(scene.attributes.size(), acc.patches.size());
    std::vector<std::vector<uint32_t>> byLight(scene.lights.size());
    for (uint32_t s = 0; s < nSurfaces; ++s) {
        const int32_t l = scene.attributes[s].areaLight;
        if (l >= 0 && size_t(l) < scene.lights.size() && scene.lights[size_t(l)].type == LightType::Area)
            byLight[size_t(l)].push_back(s);
    }
    lightOfSurface_.assign(acc.patches.size(), -1);
    probOfSurface_.assign(acc.patches.size(), 0.f);
    for (size_t l = 0; l < byLight.size(); ++l) {
        if (byLight[l].empty()) continue;
        const tessera::Light& sceneLight = scene.lights[l];
        AreaLights::Light al;
        al.sceneLight = uint32_t(l);
        al.Le = sceneLight.color;
        al.samples = std::max(1, sceneLight.samples);
        al.castsShadows = l < castsShadows.size() && castsShadows[l];
        al.first = uint32_t(surface_.size());
        std::vector<float> areas;
        for (uint32_t s : byLight[l]) areas.push_back(surfaceArea(acc, s));
        double total = 0;
        for (float a : areas) total += a;
        if (!(total > 0)) continue;  // degenerate: emits nothing measurable
        double run = 0;
        for (size_t k = 0; k < areas.size(); ++k) {
            surface_.push_back(byLight[l][k]);
            run += areas[k];
            surfaceCdf_.push_back(float(run / total));
            surfaceProb_.push_back(float(areas[k] / total));
            lightOfSurface_[byLight[l][k]] = int(lights_.size());
            probOfSurface_[byLight[l][k]] = float(areas[k] / total);
        }
        surfaceCdf_.back() = 1.f;
        al.count = uint32_t(areas.size());
        al.area = float(total);
        lights_.push_back(al);
    }
    // Selection for the path tracer's next-event estimation: by emitted power (area x luminance).
    double power = 0;
    for (const Light& l : lights_) power += double(l.area) * std::max(1e-6f, luminance(l.Le));
    double run = 0;
    for (const Light& l : lights_) {
        const double p = double(l.area) * std::max(1e-6f, luminance(l.Le)) / power;
        selection_.push_back(float(p));
        run += p;
        selectionCdf_.push_back(float(run));
    }
    if (!selectionCdf_.empty()) selectionCdf_.back() = 1.f;
}

size_t AreaLights::select(float& u) const {
    const size_t i =
        size_t(std::upper_bound(selectionCdf_.begin(), selectionCdf_.end(), u) - selectionCdf_.begin());
    const size_t k = std::min(i, lights_.size() - 1);
    const float lo = k == 0 ? 0.f : selectionCdf_[k - 1];
    u = std::clamp((u - lo) / std::max(selection_[k], 1e-30f), 0.f, 0.99999994f);
    return k;
}

AreaLightSample AreaLights::sample(const RtAccel& acc, size_t i, float u0, float u1) const {
    const Light& l = lights_[i];
    const float* cdf = surfaceCdf_.data() + l.first;
    const size_t k = std::min<size_t>(size_t(std::upper_bound(cdf, cdf + l.count, u0) - cdf), l.count - 1);
    const float lo = k == 0 ? 0.f : cdf[k - 1];
    const float prob = surfaceProb_[l.first + k];
    const float u = std::clamp((u0 - lo) / std::max(prob, 1e-30f), 0.f, 1.f);
    AreaLightSample s;
    s.patch = surface_[l.first + k];
    s.uv = {u, u1};
    const AreaLightSurfacePoint sp = areaLightPointAt(acc, s.patch, u, u1);
    s.p = sp.p;
    s.n = sp.n;
    s.pdfArea =
        sp.jacobian > 0.f && std::isfinite(sp.jacobian) && dot(sp.n, sp.n) > 0.f ? prob / sp.jacobian : 0.f;
    return s;
}

float AreaLights::pdfArea(const RtAccel& acc, size_t i, uint32_t patch, float u, float v) const {
    if (lightOfSurface(patch) != int(i)) return 0.f;
    const float j = areaLightPointAt(acc, patch, u, v).jacobian;
    return j > 0.f && std::isfinite(j) ? probOfSurface_[patch] / j : 0.f;
}

}  // namespace tessera::rt
