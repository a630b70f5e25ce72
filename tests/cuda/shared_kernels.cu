// Compile check (CTest DeviceKernelsCompileWithNvcc): the kernels both engines share (sampler, light
// samples, surface shading, traced lobes, thin-lens disk map, hemisphere warps, shadow-map lookups) build as
// CUDA device code, warning-free. Also the quadrics' closed form, bounds and ray intersection.
#include "core/quadric.h"
#include "film/sampler.h"
#include "shading/hemisphere.h"
#include "scene/camera.h"
#include "shading/shadow_map.h"
#include "shading/surface.h"
using namespace tessera;
__global__ void shadeKernel(const ShadingLight* lights, int nL, const Material* m, const Vec3* P, const Vec3* N,
                            const Vec3* I, Color* out, int n, FilmPattern fp) {
    const int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    int32_t x, y;
    filmSampleSingleFixed(fp, i, 0, x, y);
    const Vec2 d = squareToDisk(sampleDimension(1234u, uint32_t(i), kDimLensU), 0.5f);
    const Vec3 p = P[i];
    out[i] = shadeSurfaceLights(*m, N[i], I[i], size_t(nL), [&](size_t l) { return sampleLight(lights[l], p); },
                                [](size_t) { return 1.f; }) * (d.x + float(x + y));
    TracedLobe lobes[2];
    tracedLobes(*m, I[i], N[i], out[i], 1e-4f, lobes);
    const Frame3 f = frameAbout(N[i]);
    out[i] = out[i] * (f.toWorld(cosineHemisphere(d.x, d.y)).z + uniformHemisphere(d.y, d.x).z);
}
__global__ void shadowKernel(ShadowMapLookup map, const Vec3* P, const Vec3* N, float* out, int n) {
    const int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    out[i] = shadowMapVisibility(map, P[i], N[i]);
}
__global__ void quadricKernel(const Quadric* q, const Vec3* o, const Vec3* d, float* out, int n) {
    const int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    QuadricHit hits[4];
    const int nh = intersectQuadric(*q, o[i], d[i], 0.f, 1e30f, hits);
    const SurfacePoint sp = evalQuadric(*q, nh ? hits[0].u : 0.5f, nh ? hits[0].v : 0.5f);
    const Bounds3 b = quadricBounds(*q, 0.f, 0.5f, 0.25f, 1.f);
    out[i] = dot(quadricNormal(*q, 0.5f, 0.5f), sp.p) + b.hi.x;
}
