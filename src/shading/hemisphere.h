// Directions over the hemisphere about a normal, from two sample dimensions in [0,1)^2: the warps the
// light-transport integrators share (ambient occlusion now; diffuse bounces of the path tracer next).
// Plain inline functions over plain data, for a CUDA backend as well.
#pragma once
#include <cmath>

#include "core/hostdevice.h"
#include "core/vec.h"
#include "scene/camera.h"  // squareToDisk

namespace tessera {

// An orthonormal basis (t, b, n) for a unit normal n, branch-free except for the sign (Duff et al.,
// "Building an Orthonormal Basis, Revisited", JCGT 6(1), 2017).
struct Frame3 {
    Vec3 t, b, n;
    TESSERA_HD Vec3 toWorld(Vec3 local) const { return t * local.x + b * local.y + n * local.z; }
};
TESSERA_HD Frame3 frameAbout(Vec3 n) {
    const float sign = std::copysign(1.f, n.z);
    const float a = -1.f / (sign + n.z), b = n.x * n.y * a;
    return {{1.f + sign * n.x * n.x * a, sign * b, -sign * n.x}, {b, sign + n.y * n.y * a, -n.y}, n};
}

// Cosine-weighted direction in the local frame (z up), pdf cos(theta) / pi: the concentric disk lifted to
// the hemisphere (Malley's method), which keeps the sampler's 2D stratification.
TESSERA_HD Vec3 cosineHemisphere(float u, float v) {
    const Vec2 d = squareToDisk(u, v);
    const float z = std::sqrt(std::fmax(0.f, 1.f - d.x * d.x - d.y * d.y));
    return {d.x, d.y, z};
}

// Uniform direction over the local hemisphere, pdf 1 / (2 pi): cos(theta) = v, as paper 002 (sec. 5.3.1)
// takes its second random number "as the distance along the normal".
TESSERA_HD Vec3 uniformHemisphere(float u, float v) {
    const float z = v, r = std::sqrt(std::fmax(0.f, 1.f - z * z)), phi = 6.2831853f * u;
    return {r * std::cos(phi), r * std::sin(phi), z};
}

}  // namespace tessera
