// Compile check (CTest DeviceKernelsCompileWithNvcc): the kernels both engines share (sampler, light
// samples, surface shading, traced lobes, thin-lens disk map, hemisphere warps, shadow-map lookups) build as
// CUDA device code, warning-free.
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
