// Area lights in the ray tracer (RI AreaLightSource, docs/light_transport.md): the emitting surfaces of
// each area light in the accel's space, points sampled on them, and the density of that sampling at any
// point of them (for multiple importance sampling). An area light emits radiance Le = intensity *
// lightcolor from the front side of its surfaces (the side the oriented normal faces), uniformly in
// direction (a Lambertian emitter, as pbrt's diffuse area light).
//
// Sampling: a surface of the light with probability proportional to its area, then (u,v) uniform on it;
// the density over area at a point is P(surface) / |dP/du x dP/dv|, exact for any patch or quadric (the
// areas only steer the choice, so their quadrature error costs variance, not bias).
#pragma once
#include <cstdint>
#include <vector>

#include "core/vec.h"
#include "rt/accel.h"
#include "scene/scene.h"

namespace tessera::rt {

struct AreaLightSurfacePoint {
    Vec3 p;
    Vec3 n;              // unit, oriented: the emitting side
    float jacobian = 0;  // |dP/du x dP/dv| at the point (area per unit of (u,v))
};

// A point of surface `patch` of the accel at (u,v).
AreaLightSurfacePoint areaLightPointAt(const RtAccel& acc, uint32_t patch, float u, float v);

struct AreaLightSample {
    Vec3 p, n;           // the point and its emitting normal
    uint32_t patch = 0;  // the surface it lies on
    Vec2 uv;
    float pdfArea = 0;  // density over the light's area (0: the sample is unusable)
};

class AreaLights {
  public:
    struct Light {
        uint32_t sceneLight = 0;  // index into Scene::lights (and the frame's ShadingLight list)
        Color Le;                 // emitted radiance
        int samples = 1;          // direct integrator: shadow rays per shading point
        bool castsShadows = true;
        uint32_t first = 0, count = 0;  // its surfaces: surface_[first, first + count)
        float area = 0;
    };

    AreaLights() = default;
    // The area lights of the scene that have surfaces in `acc`; `castsShadows[l]` per scene light (the
    // frame's decision, --shadows included).
    AreaLights(const Scene& scene, const RtAccel& acc, const std::vector<uint8_t>& castsShadows);

    bool empty() const { return lights_.empty(); }
    size_t size() const { return lights_.size(); }
    const Light& light(size_t i) const { return lights_[i]; }
    // The index among these lights of the one that surface `patch` belongs to, or -1.
    int lightOfSurface(uint32_t patch) const {
        return patch < lightOfSurface_.size() ? lightOfSurface_[patch] : -1;
    }
    // A point on light `i` from three uniform numbers (u0 picks the surface and is reused, rescaled, as u).
    AreaLightSample sample(const RtAccel& acc, size_t i, float u0, float u1) const;
    // The density over area with which sample() picks the point at (u,v) of surface `patch` of light `i`.
    float pdfArea(const RtAccel& acc, size_t i, uint32_t patch, float u, float v) const;
    // The probability with which the path tracer picks light `i` for next-event estimation (by power).
    float selectionProbability(size_t i) const { return selection_[i]; }
    // The light for a uniform number (by power), and u rescaled to [0,1) for reuse.
    size_t select(float& u) const;

  private:
    std::vector<Light> lights_;
    std::vector<uint32_t> surface_;  // surfaces of every light, grouped by light
    std::vector<float> surfaceCdf_;  // per grouped surface: cumulative area fraction within its light
    std::vector<float> surfaceProb_;
    std::vector<int> lightOfSurface_;   // per accel surface
    std::vector<float> probOfSurface_;  // per accel surface: P(surface | its light)
    std::vector<float> selection_, selectionCdf_;
};

}  // namespace tessera::rt
