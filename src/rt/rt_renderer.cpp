#include "rt/rt_renderer.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <functional>

#include "engine/frame.h"
#include "engine/tile_loop.h"
#include "rt/area_lights.h"
#include "rt/binning.h"
#include "rt/ray_list.h"
#include "rt/shadow_rays.h"
#include "shading/gloss.h"
#include "shading/hemisphere.h"
#include "shading/path_bsdf.h"
#include "shading/surface.h"
#include "shading/texture.h"

namespace tessera {
namespace {

using namespace rt;

// Per tile in flight: the tile's samples, its ray lists and shading scratch, and its trace service.
struct Workspace {
    Workspace(const RtAccel& acc, TraceServiceOptions opt) : trace(acc, opt) {}
    TraceService trace;
    SampleTile tile;
    RayList rays, next, shadow;
    std::vector<RayHit> hits;
    std::vector<uint8_t> shadowBlocked;  // per shadow ray: occluded
    // The generation's hits as one shading batch (structure of arrays, hit k is ray hitRay[k]).
    std::vector<uint32_t> hitRay, hitMaterial;
    std::vector<Vec3> hitP, hitN, hitI;
    std::vector<Color> hitTexture;      // per hit: its texture colour (white when untextured)
    std::vector<Color> hitVertexColor;  // per hit: its per-vertex colour (white where none)
    // --adaptive's presample: per sample, the attributes of its first secondary hit (object kNoObject:
    // none); empty otherwise (nothing is recorded).
    std::vector<HitAttributes> secondary;
    LightSamples lightSamples;
    std::vector<uint32_t> shadowIdx;      // [hit * lights + light]: its shadow ray (kNone: none)
    std::vector<uint8_t> shadowedLights;  // per hit: lights in shadow (the film's shadow-count channel)
    std::vector<Color> radiance;          // per hit: the local response
    CameraSamples camera;
    std::vector<ShadowRun> shadowRuns;
    std::vector<RayHit> occlusionHits;  // ambient occlusion with distance-weighted shades
    // --adaptive: the presample tile (one ray per pixel centre), the target's active subpixels (4 per
    // pixel) and, per sample of the 16-sample tile, whether it is traced.
    SampleTile presample;
    std::vector<uint8_t> activeSubpixels, tracedSamples;
    std::vector<PresampleAttributes> presampleAttributes;
    uint64_t adaptivePixels = 0, adaptiveActive = 0;
    // Area lights (direct integrator): per hit its samples [hit * areaSlots + slot], each slot's shadow
    // ray (kNone: none) and whether it was blocked.
    std::vector<LightSample> areaSamples;
    std::vector<uint32_t> areaRay;
    RayList areaShadow;
    std::vector<uint8_t> areaBlocked;
    // Path tracer: per ray of `rays` / `next` the solid-angle density of the BSDF sample that made it (0:
    // a camera ray or a delta lobe, whose emission hits count fully); per shadow ray its hit.
    std::vector<float> rayPdf, nextPdf;
    std::vector<uint32_t> shadowHit;
    double shadeMs = 0, filterMs = 0;
};

struct Frame {
    const Scene& scene;
    const RtAccel& acc;
    std::span<const ShadingLight> lights;
    int maxDepth;
    const Projector& projector;
    const Textures* textures;  // nullptr: the scene has none
    const AreaLights& areaLights;
    uint32_t seed;
    int lightSamples;  // --light-samples (0: each area light's own)
    int rouletteDepth;
    GlossModel gloss;
};

// The per-pixel seed and sample index of tile sample s (the shared sampler's coordinates, film/sampler.h).
void sampleCoordinates(const SampleTile& tile, uint32_t s, uint32_t seed, uint32_t& pseed, uint32_t& index) {
    const size_t pixel = s / size_t(tile.spp);
    const int tw = tile.region.width();
    pseed =
        pixelSeed(tile.region.x0 + int(pixel % size_t(tw)), tile.region.y0 + int(pixel / size_t(tw)), seed);
    index = tile.sampleIndex[s];
}

// A camera ray's hit in its sample: covered, at depth t, and its pixel hit by some sample.
void markCameraHit(SampleTile& tile, uint32_t s, float t) {
    tile.a[s] = 1.f;
    tile.z[s] = t;
    tile.pixelHit[s / size_t(tile.spp)] = 1;
}
// Whether hit k of the batch is textured (the film's has-texture channel): textures on bicubic patches
// only, as Reyes.
bool hitTextured(const Frame& fr, const SurfacePoints& pts, size_t k, uint32_t patch) {
    return fr.scene.materials[pts.materialOf(k)].texture >= 0 &&
           fr.scene.attributes[patch].kind == SurfaceKind::BicubicBezier;
}

// The surface AOVs of camera hit k (sample s), when the film carries them: albedo, camera-space P, Cs.
void setSurfaceAovs(const Frame& fr, const SurfacePoints& pts, size_t k, uint32_t s, SampleTile& tile,
                    const Workspace& ws) {
    if (!tile.wantsSurfaceAovs()) return;
    const Material m = pts.materialAt(fr.scene.materials, k);
    const Color Ct = pts.textureOf(k);
    tile.setSurfaceAovs(s, surfaceAlbedo(m, Ct), ws.hits[ws.hitRay[k]].h.p, m.Cs * Ct);  // P on the surface
}

// Radiance an area light's surface sends along a ray that hit it at `rh` from direction d: Le on the
// front side, 0 behind; `cosine` receives |cos| at the light (for the density conversions).
Color areaEmission(const Frame& fr, const RayHit& rh, Vec3 d, float& cosine, int& light) {
    light = fr.areaLights.lightOfSurface(rh.patch);
    cosine = 0.f;
    if (light < 0) return Color{0, 0, 0};
    const Vec3 n = normalize(orientedGeometricNormal(fr.acc, rh.patch, rh.h));
    cosine = -dot(n, normalize(d));
    return cosine > 0.f ? fr.areaLights.light(size_t(light)).Le : Color{0, 0, 0};
}

// ---- Shading through src/shading: hits -> light samples -> shadow rays -> radiance + traced lobes ------

// The generation's hits as a shading batch: position, unit normal (orientation applied), unit incident
// direction, material; and the texture colour of textured surfaces at the hit's s, t (filtered over the
// raster pixel the hit's footprint covers as seen from the camera: the footprint Reyes filters over too).
SurfacePoints hitBatch(const Frame& fr, Workspace& ws) {
    const RtAccel& acc = fr.acc;
    const RayList& rays = ws.rays;
    ws.hitRay.clear();
    for (size_t r = 0; r < rays.size(); ++r)
        if (ws.hits[r].hit) ws.hitRay.push_back(uint32_t(r));
    const size_t n = ws.hitRay.size();
    ws.hitP.resize(n), ws.hitN.resize(n), ws.hitI.resize(n), ws.hitMaterial.resize(n);
    for (size_t k = 0; k < n; ++k) {
        const uint32_t r = ws.hitRay[k];
        const RayHit& rh = ws.hits[r];
        ws.hitP[k] = rh.h.p;
        ws.hitN[k] = hitNormal(acc, rh.patch, rh.h, rays.time[r]);
        // User normals: shadow and secondary rays leave from the smooth surface they describe (scene.h,
        // terminatorSafePoint); the P AOV keeps the hit.
        if (const PatchVertexValues* vv = acc.vertexValuesAt(rh.patch);
            vv && vv->hasN && !acc.displaced.displaced(rh.patch))
            ws.hitP[k] = terminatorSafePoint(*vv, acc.patches[rh.patch], rh.h.u, rh.h.v, rh.h.p,
                                             orientedGeometricNormal(acc, rh.patch, rh.h));
        ws.hitI[k] = normalize(rays.d[r]);
        ws.hitMaterial[k] = acc.material[rh.patch];
    }
    SurfacePoints pts{n, ws.hitP.data(), ws.hitN.data(), ws.hitI.data(), ws.hitMaterial.data()};
    if (fr.textures) {
        ws.hitTexture.resize(n);
        for (size_t k = 0; k < n; ++k) {
            const RayHit& rh = ws.hits[ws.hitRay[k]];
            const Material& m = fr.scene.materials[ws.hitMaterial[k]];
            // Textures on bicubic patches only (as Reyes: quadrics have no s, t yet).
            if (m.texture < 0 || fr.scene.attributes[rh.patch].kind != SurfaceKind::BicubicBezier) {
                ws.hitTexture[k] = {1, 1, 1};
                continue;
            }
            // The texture coordinates follow the hit's (u,v) on the patch (at shutter open for the
            // footprint's derivatives).
            const SurfacePoint sp = evalPatchDeriv(acc.patches[rh.patch], rh.h.u, rh.h.v);
            ws.hitTexture[k] =
                surfaceTextureColor(*fr.textures, m, fr.projector, texCoordsOf(fr.scene, rh.patch), rh.h.p,
                                    sp.dpdu, sp.dpdv, Vec2{rh.h.u, rh.h.v});
        }
        pts.textureColor = ws.hitTexture.data();
    }
    if (!acc.vertexValues.empty()) {  // per-vertex colours (polygons' "Cs"), as Reyes' dicer
        ws.hitVertexColor.resize(n);
        for (size_t k = 0; k < n; ++k) {
            const RayHit& rh = ws.hits[ws.hitRay[k]];
            const PatchVertexValues* vv = acc.vertexValuesAt(rh.patch);
            ws.hitVertexColor[k] = vv && vv->hasCs ? bilinearCorners(vv->Cs, rh.h.u, rh.h.v) : Color{1, 1, 1};
        }
        pts.vertexColor = ws.hitVertexColor.data();
    }
    return pts;
}

// The visibility queries of the light samples as shadow rays (rt/shadow_rays.h), each from its hit.
void makeShadowRays(const Frame& fr, const SurfacePoints& pts, Workspace& ws) {
    rt::makeShadowRays(
        fr.acc, fr.lights, pts, ws.lightSamples,
        [&](size_t k) {
            const uint32_t r = ws.hitRay[k];
            const RayHit& rh = ws.hits[r];
            return ShadowOrigin{rh.patch, Vec2{rh.h.u, rh.h.v}, ws.rays.time[r], r};  // the parent's time
        },
        ws.shadow, ws.shadowRuns, ws.shadowIdx);
}

// The shadow rays' answers as the light samples' visibility, and the count of lights in shadow per hit.
void applyVisibility(const SurfacePoints& pts, Workspace& ws) {
    ws.shadowedLights.resize(pts.count);
    applyShadowRays(ws.shadowIdx, ws.shadowBlocked, ws.lightSamples, pts.count, ws.shadowedLights.data());
}

// Area lights in the direct integrator (docs/light_transport.md): per hit and area light, `samples`
// points over the light from the sampler's light pair (index sample x N + j: for a power-of-two N an
// aligned block of a (0,2)-sequence, so stratified), each a LightSample with Cl = Le cos_l / (pi d^2 pdf
// N). RI's diffuse() sum over them is then E / pi, which is the Lambertian response of the path tracer, so
// the two integrators agree on matte surfaces. Shadow rays answer their visibility; the surface's RI
// response over the samples, and the emission of a light surface hit from its front, add to the hit's
// radiance.
void addAreaLighting(const Frame& fr, const SurfacePoints& pts, Workspace& ws) {
    const AreaLights& al = fr.areaLights;
    const RayList& rays = ws.rays;
    const size_t n = pts.count;
    if (al.empty()) return;
    for (size_t k = 0; k < n; ++k) {  // emission (no MIS here: the direct integrator has no diffuse bounce)
        const uint32_t r = ws.hitRay[k];
        float cosine;
        int light;
        ws.radiance[k] += areaEmission(fr, ws.hits[r], rays.d[r], cosine, light);
    }
    std::vector<uint32_t> count(al.size()), offset(al.size());
    size_t slots = 0;
    for (size_t a = 0; a < al.size(); ++a) {
        count[a] = uint32_t(fr.lightSamples > 0 ? fr.lightSamples : al.light(a).samples);
        offset[a] = uint32_t(slots);
        slots += count[a];
    }
    ws.areaSamples.assign(n * slots, LightSample{});
    ws.areaRay.assign(n * slots, kNone);
    ws.areaShadow.clear();
    const SampleTile& tile = ws.tile;
    for (size_t k = 0; k < n; ++k) {
        const Material m = pts.materialAt(fr.scene.materials, k);
        if (!surfaceUsesLights(m.type)) continue;
        const uint32_t r = ws.hitRay[k], s = rays.owner[r];
        const RayHit& rh = ws.hits[r];
        uint32_t pseed, index;
        sampleCoordinates(tile, s, fr.seed, pseed, index);
        const Vec3 Nf = faceForward(pts.N[k], pts.I[k]);
        const Vec3 o = pts.P[k] + Nf * fr.acc.offset;
        for (size_t a = 0; a < al.size(); ++a) {
            const AreaLights::Light& light = al.light(a);
            const uint32_t N = count[a];
            const uint32_t lightSeed = hash32(pseed + 0x632be5abu * uint32_t(a + 1));  // lights decorrelated
            for (uint32_t j = 0; j < N; ++j) {
                const Sample2D uv = sample2D(lightSeed, index * N + j, kDimLightU);
                const AreaLightSample ls = al.sample(fr.acc, a, uv.u, uv.v);
                if (!(ls.pdfArea > 0.f)) continue;
                const Vec3 toLight = ls.p - o;
                const float d2 = dot(toLight, toLight), d = std::sqrt(d2);
                if (!(d > 0.f)) continue;
                const Vec3 L = toLight / d;
                const float cosLight = -dot(ls.n, L);
                if (!(cosLight > 0.f) || !(dot(Nf, L) > 0.f)) continue;
                const size_t slot = k * slots + offset[a] + j;
                LightSample& sample = ws.areaSamples[slot];
                sample.L = L, sample.dist = d, sample.valid = true;
                sample.Cl = light.Le * (cosLight / (3.14159265f * d2 * ls.pdfArea * float(N)));
                if (!light.castsShadows) continue;
                // Ends short of the light's surface, which must not shadow its own samples.
                const float tmax = d - std::max(4.f * fr.acc.offset, 1e-3f * d);
                ws.areaRay[slot] = uint32_t(ws.areaShadow.size());
                ws.areaShadow.push(o, L, 0.f, tmax, s, Color{}, rh.patch, kShadow, 0, Vec2{rh.h.u, rh.h.v},
                                   Nf, rays.time[r]);
            }
        }
    }
    ws.trace.occluded(ws.areaShadow, ws.areaBlocked);
    for (size_t k = 0; k < n; ++k) {
        Material m = pts.materialAt(fr.scene.materials, k);
        if (!surfaceUsesLights(m.type)) continue;
        // A glossy surface's reflection rays see the light's surface: no highlight from it on top.
        if (m.type == MaterialType::Glossy) m.Ks = 0.f;
        const LightSample* samples = ws.areaSamples.data() + k * slots;
        const uint32_t* ray = ws.areaRay.data() + k * slots;
        ws.radiance[k] += shadeSurfaceLights(
            m, pts.N[k], pts.I[k], slots, [&](size_t l) -> const LightSample& { return samples[l]; },
            [&](size_t l) { return ray[l] != kNone && ws.areaBlocked[ray[l]] ? 0.f : 1.f; },
            pts.textureOf(k));
        // The shadow-count channel: an area light counts as one light in shadow where most of its
        // samples are blocked.
        for (size_t a = 0; a < al.size(); ++a) {
            uint32_t blocked = 0;
            for (uint32_t j = 0; j < count[a]; ++j) {
                const uint32_t rr = ray[offset[a] + j];
                blocked += rr != kNone && ws.areaBlocked[rr];
            }
            if (2 * blocked > count[a]) ++ws.shadowedLights[k];
        }
    }
}

// ---- end of shading ----------------------------------------------------------------------------------

// The glossy reflection rays of hit k (ray r) into `ws.next` (shading/gloss.h): a camera hit traces the
// material's "samples" rays, stratified by the sampler's BSDF pair (index x n + j: a power-of-two n is an
// aligned block of the (0,2)-sequence); later hits one ray each (paper 002 sec. 5.3.5), from a pair
// decorrelated by the ray's position in its generation.
void addGlossRays(const Frame& fr, const SurfacePoints& pts, size_t k, uint32_t r, Workspace& ws) {
    const RayList& rays = ws.rays;
    const RayHit& rh = ws.hits[r];
    const uint32_t s = rays.owner[r];
    const Material m = pts.materialAt(fr.scene.materials, k);
    const Vec3 Nf = faceForward(pts.N[k], pts.I[k]);
    uint32_t pseed, index;
    sampleCoordinates(ws.tile, s, fr.seed, pseed, index);
    const bool camera = rays.kind[r] == kPrimary;
    const int n = camera ? std::clamp(int(m.glossSamples), 1, 4096) : 1;
    if (!camera) pseed = hash32(pseed ^ hash32(r * 0x9e3779b9u + uint32_t(rays.depth[r])));
    for (int j = 0; j < n; ++j) {
        const Sample2D u = sample2D(pseed, camera ? index * uint32_t(n) + uint32_t(j) : index, kDimBsdfU);
        const GlossRay g = glossyReflection(m, fr.gloss, pts.N[k], pts.I[k], u.u, u.v, n);
        if (!g.valid) continue;
        const Color weight = rays.weight[r] * g.weight;
        if (!(maxComponent(weight) > 1e-4f / float(n))) continue;
        ws.next.push(pts.P[k] + Nf * fr.acc.offset, g.direction, 0.f, std::numeric_limits<float>::infinity(),
                     s, weight, rh.patch, kReflection, uint8_t(rays.depth[r] + 1), Vec2{rh.h.u, rh.h.v}, Nf,
                     rays.time[r]);
    }
}

// --adaptive's presample: the attributes of a sample's first secondary hit (paper 004, L141: the hit of
// the reflection or refraction ray of the camera ray's surface), once per sample; the ray of hit k must be
// a traced lobe (a mirror or glass bounce of the direct integrator, a delta bounce of the path tracer).
void recordSecondaryHit(const Frame& fr, const SurfacePoints& pts, size_t k, Workspace& ws) {
    const uint32_t r = ws.hitRay[k], s = ws.rays.owner[r];
    if (ws.secondary.empty() || ws.rays.depth[r] != 1 || ws.secondary[s].object != kNoObject) return;
    if (ws.rays.kind[r] != kReflection && ws.rays.kind[r] != kRefraction) return;
    const uint32_t patch = ws.hits[r].patch;
    ws.secondary[s] = HitAttributes{fr.scene.attributes[patch].object, faceForward(pts.N[k], pts.I[k]),
                                    uint8_t(std::min<int>(ws.shadowedLights[k], 255)),
                                    uint8_t(hitTextured(fr, pts, k, patch))};
}

// Accumulates the hits' radiance into the tile in ray order (deterministic), writes the film's attributes
// of camera-ray hits and the next generation (the traced lobes) to `ws.next`.
void accumulate(const Frame& fr, const SurfacePoints& pts, Workspace& ws) {
    const RayList& rays = ws.rays;
    SampleTile& tile = ws.tile;
    ws.next.clear();
    for (size_t k = 0; k < pts.count; ++k) {
        const uint32_t r = ws.hitRay[k];
        const uint32_t s = rays.owner[r];
        const RayHit& rh = ws.hits[r];
        const Vec3 Nf = faceForward(pts.N[k], pts.I[k]);
        if (rays.kind[r] == kPrimary) {
            markCameraHit(tile, s, rh.h.t);
            if (tile.channels) {
                tile.setAttributes(s, fr.scene.attributes[rh.patch].object, Nf, ws.shadowedLights[k],
                                   hitTextured(fr, pts, k, rh.patch));
                setSurfaceAovs(fr, pts, k, s, tile, ws);
            }
        } else {
            // Of a glass surface's two rays the one traced first (reflection), the same in every run.
            recordSecondaryHit(fr, pts, k, ws);
        }
        const Color w = rays.weight[r];
        const Color c = w * ws.radiance[k];
        tile.r[s] += c.x;
        tile.g[s] += c.y;
        tile.b[s] += c.z;
        if (rays.depth[r] >= fr.maxDepth) continue;
        const Material m = pts.materialAt(fr.scene.materials, k);
        TracedLobe lobes[2];
        const int nLobes = tracedLobes(m, pts.I[k], pts.N[k], w, 1e-4f, lobes);
        for (int j = 0; j < nLobes; ++j) {
            const bool t = lobes[j].transmitted;
            ws.next.push(pts.P[k] + Nf * (t ? -fr.acc.offset : fr.acc.offset), lobes[j].direction, 0.f,
                         std::numeric_limits<float>::infinity(), s, lobes[j].weight, rh.patch,
                         t ? kRefraction : kReflection, uint8_t(rays.depth[r] + 1), Vec2{rh.h.u, rh.h.v},
                         t ? -Nf : Nf, rays.time[r]);
        }
        if (m.type == MaterialType::Glossy) addGlossRays(fr, pts, k, r, ws);
    }
}

// One wavefront generation: shade the hits of `ws.rays` (light samples, their shadow rays, the surfaces),
// accumulate colour into the tile and write the next generation (reflection, refraction) to `ws.next`.
void shadeGeneration(const Frame& fr, Workspace& ws) {
    auto ts = EngineClock::now();
    const SurfacePoints pts = hitBatch(fr, ws);
    sampleLights(fr.lights, fr.scene.materials, pts, ws.lightSamples);
    makeShadowRays(fr, pts, ws);
    ws.shadeMs += msSince(ts);
    ws.trace.occluded(ws.shadow, ws.shadowRuns, ws.shadowBlocked);
    ts = EngineClock::now();
    applyVisibility(pts, ws);
    ws.radiance.resize(pts.count);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, pts.count, 256),
                      [&](const tbb::blocked_range<size_t>& range) {
                          shadeSurfaces(fr.scene.materials, pts, ws.lightSamples, range.begin(), range.end(),
                                        ws.radiance.data());
                      });
    ws.shadeMs += msSince(ts);
    addAreaLighting(fr, pts, ws);  // traces its own shadow rays
    ts = EngineClock::now();
    accumulate(fr, pts, ws);
    ws.shadeMs += msSince(ts);
}

// ---- Path tracing ----------------------------------------------------------------------------------------

// Sampler dimensions of a path vertex at `depth`: four (0,2) pairs per bounce from kDimFirstFree: the area
// light point, the BSDF direction, (light choice, lobe choice), (Russian roulette, unused).
constexpr uint32_t kPathDimsPerBounce = 8;

// One wavefront generation of the path tracer (--integrator path, docs/light_transport.md), for the hits
// of `ws.rays`:
//  1. emission the rays see: an area light's front side (weighted by the power heuristic against light
//     sampling when the ray came from a smooth lobe: Veach 1997, ch. 9) and constant surfaces;
//  2. next-event estimation at every vertex with a smooth lobe: a shadow ray to every delta light (point,
//     spot, distant: RI Cl as irradiance x pi, so that a Lambertian surface gets RI diffuse()'s Kd Cs Cl
//     cos), and to one point of one area light picked by power (MIS with the BSDF's density);
//  3. the BSDF's sample continues the path (`ws.next`, its density in `ws.nextPdf`), with Russian roulette
//     by throughput from Frame::rouletteDepth on; none past --max-depth bounces.
// Ambient lights add nothing: the path tracer computes the indirect light they stand in for.
void shadePathGeneration(const Frame& fr, Workspace& ws) {
    auto ts = EngineClock::now();
    const SurfacePoints pts = hitBatch(fr, ws);
    const RayList& rays = ws.rays;
    SampleTile& tile = ws.tile;
    const AreaLights& al = fr.areaLights;
    const RtAccel& acc = fr.acc;
    constexpr float kPi = 3.14159265f;
    ws.next.clear();
    ws.nextPdf.clear();
    ws.shadow.clear();
    ws.shadowHit.clear();
    ws.shadowedLights.assign(pts.count, 0);
    auto add = [&](uint32_t s, Color c) {
        if (!(isFinite(c))) return;  // a degenerate density: drop the sample rather than poison the pixel
        tile.r[s] += c.x, tile.g[s] += c.y, tile.b[s] += c.z;
    };
    for (size_t k = 0; k < pts.count; ++k) {
        const uint32_t r = ws.hitRay[k], s = rays.owner[r];
        const RayHit& rh = ws.hits[r];
        const Material m = pts.materialAt(fr.scene.materials, k);
        const int depth = rays.depth[r];
        const Color w = rays.weight[r];
        const Vec3 I = pts.I[k], N = pts.N[k], Nf = faceForward(N, I), wo = -I;
        if (rays.kind[r] == kPrimary) {
            markCameraHit(tile, s, rh.h.t);
        }
        const PathBsdf b = pathBsdfOf(m, pts.textureOf(k));
        // 1. Emission.
        float cosE;
        int li;
        const Color Le = areaEmission(fr, rh, rays.d[r], cosE, li);
        if (maxComponent(Le) > 0.f) {
            float mis = 1.f;
            if (ws.rayPdf[r] > 0.f) {
                const float dist = rh.h.t * length(rays.d[r]);
                const float pl = al.selectionProbability(size_t(li)) *
                                 al.pdfArea(acc, size_t(li), rh.patch, rh.h.u, rh.h.v) * dist * dist / cosE;
                mis = powerHeuristic(ws.rayPdf[r], pl);
            }
            add(s, w * Le * mis);
        }
        if (b.lobes == PathLobes::None) {
            add(s, w * b.emission);
            continue;
        }
        uint32_t pseed, index;
        sampleCoordinates(tile, s, fr.seed, pseed, index);
        const uint32_t base = kDimFirstFree + kPathDimsPerBounce * uint32_t(depth);
        const Vec3 o = pts.P[k] + Nf * acc.offset;
        auto shadowRay = [&](Vec3 L, float tmax, Color c, uint32_t light) {
            if (!(maxComponent(c) > 0.f)) return;
            if (!fr.lights[light].castsShadows) {
                // Shadows from maps read from files (or none): no ray.
                const ShadowMapLookup* map = fr.lights[light].shadowMap;
                add(s, map ? c * shadowMapVisibility(*map, pts.P[k], pts.N[k]) : c);
                return;
            }
            ws.shadow.push(o, L, 0.f, tmax, s, c, rh.patch, kShadow, 0, Vec2{rh.h.u, rh.h.v}, Nf,
                           rays.time[r]);
            ws.shadowHit.push_back(uint32_t(k));
        };
        // 2. Next-event estimation.
        if (pathHasSmoothLobes(b)) {
            for (size_t l = 0; l < fr.lights.size(); ++l) {
                const ShadingLight& light = fr.lights[l];
                if (light.type == LightType::Ambient || light.type == LightType::Area) continue;
                const LightSample ls = sampleLight(light, pts.P[k]);
                if (!ls.valid) continue;
                Vec3 L;
                float tmax;
                aimShadowRay(light, ls, o, acc.offset, L, tmax);
                const float cosR = dot(Nf, L);
                if (!(cosR > 0.f)) continue;
                shadowRay(L, tmax, w * pathBsdfEval(b, Nf, wo, L) * ls.Cl * (cosR * kPi), uint32_t(l));
            }
            if (!al.empty()) {
                float uSelect = sampleDimension(pseed, index, base + 4);
                const size_t a = al.select(uSelect);
                const Sample2D uv = sample2D(pseed, index, base);
                const AreaLightSample ls = al.sample(acc, a, uv.u, uv.v);
                const Vec3 toLight = ls.p - o;
                const float d2 = dot(toLight, toLight), d = std::sqrt(d2);
                if (ls.pdfArea > 0.f && d > 0.f) {
                    const Vec3 L = toLight / d;
                    const float cosL = -dot(ls.n, L), cosR = dot(Nf, L);
                    if (cosL > 0.f && cosR > 0.f) {
                        const float pl = al.selectionProbability(a) * ls.pdfArea * d2 / cosL;
                        // At the last vertex no BSDF sample follows to complete the pair: the light
                        // takes the whole share, so a truncated path stays a clean partial sum.
                        const float mis =
                            depth >= fr.maxDepth ? 1.f : powerHeuristic(pl, pathBsdfPdf(b, Nf, wo, L));
                        const Color c = w * pathBsdfEval(b, Nf, wo, L) * al.light(a).Le * (cosR * mis / pl);
                        shadowRay(L, d - std::max(4.f * acc.offset, 1e-3f * d), c, al.light(a).sceneLight);
                    }
                }
            }
        }
        // 3. The next bounce.
        if (depth >= fr.maxDepth) continue;
        const Sample2D ub = sample2D(pseed, index, base + 2);
        const PathBsdfSample bs =
            pathBsdfSample(b, N, I, sampleDimension(pseed, index, base + 5), ub.u, ub.v);
        if (!bs.valid) continue;
        Color wn = w * bs.weight;
        if (depth + 1 >= fr.rouletteDepth) {
            const float q = std::min(0.95f, maxComponent(wn));
            if (!(sampleDimension(pseed, index, base + 6) < q)) continue;
            wn = wn / q;
        }
        const Vec3 side = bs.transmitted ? -Nf : Nf;
        ws.next.push(pts.P[k] + side * acc.offset, bs.wi, 0.f, std::numeric_limits<float>::infinity(), s, wn,
                     rh.patch, bs.transmitted ? kRefraction : kReflection, uint8_t(depth + 1),
                     Vec2{rh.h.u, rh.h.v}, side, rays.time[r]);
        ws.nextPdf.push_back(bs.delta ? 0.f : bs.pdf);
    }
    ws.shadeMs += msSince(ts);
    ws.trace.occluded(ws.shadow, ws.shadowBlocked);
    ts = EngineClock::now();
    for (size_t j = 0; j < ws.shadow.size(); ++j) {
        if (!ws.shadowBlocked[j])
            add(ws.shadow.owner[j], ws.shadow.weight[j]);
        else
            ws.shadowedLights[ws.shadowHit[j]] =
                uint8_t(std::min(255, ws.shadowedLights[ws.shadowHit[j]] + 1));
    }
    if (tile.channels)
        for (size_t k = 0; k < pts.count; ++k) {
            const uint32_t r = ws.hitRay[k];
            if (rays.kind[r] != kPrimary) {
                // A sampled diffuse or glossy bounce is noise, not the paper's secondary hit: only a delta
                // (mirror, glass) bounce's hit is recorded; of glass, the lobe the path sampled.
                if (ws.rayPdf[r] == 0.f) recordSecondaryHit(fr, pts, k, ws);
                continue;
            }
            const RayHit& rh = ws.hits[r];
            tile.setAttributes(rays.owner[r], fr.scene.attributes[rh.patch].object,
                               faceForward(pts.N[k], pts.I[k]), ws.shadowedLights[k],
                               hitTextured(fr, pts, k, rh.patch));
            setSurfaceAovs(fr, pts, k, rays.owner[r], tile, ws);
        }
    ws.shadeMs += msSince(ts);
}

// ---- Ambient occlusion ---------------------------------------------------------------------------------

// Paper 002, sec. 5.3.1: O = (1/pi) integral over the hemisphere of V(w) cos(theta) dw at each camera hit,
// by `samples` rays from the face-forward side. Ray j of a camera sample takes Sobol' index
// (sample index x samples + j) of the hemisphere pair: for a power-of-two count each hit's rays are an
// aligned block of a (0,2)-sequence, stratified in both dimensions, and a pixel's hits together are one
// larger net. The estimate is written as a grey sample (alpha 1 where the camera ray hit) and, when the film
// has an "occlusion" AOV, there too. Both sides of every surface block the rays.
void shadeOcclusion(const Frame& fr, const AmbientOcclusionSettings& ao, uint32_t seed, Workspace& ws) {
    auto ts = EngineClock::now();
    const SurfacePoints pts = hitBatch(fr, ws);
    SampleTile& tile = ws.tile;
    const RayList& rays = ws.rays;
    const size_t n = pts.count, N = size_t(std::max(1, ao.samples));
    const bool finite = std::isfinite(ao.maxDistance);
    const float tmax = finite ? std::max(0.f, ao.maxDistance - fr.acc.offset) : INFINITY;
    ws.shadow.clear();
    ws.shadow.reserve(n * N);
    for (size_t k = 0; k < n; ++k) {
        const uint32_t r = ws.hitRay[k], s = rays.owner[r];
        const RayHit& rh = ws.hits[r];
        uint32_t pseed, index;
        sampleCoordinates(tile, s, seed, pseed, index);
        const uint32_t first = index * uint32_t(N);
        const Vec3 Nf = faceForward(pts.N[k], pts.I[k]);
        const Frame3 frame = frameAbout(Nf);
        const Vec3 o = pts.P[k] + Nf * fr.acc.offset;
        for (size_t j = 0; j < N; ++j) {
            const Sample2D uv = sample2D(pseed, first + uint32_t(j), kDimHemisphereU);
            const Vec3 local =
                ao.paperWeighting ? uniformHemisphere(uv.u, uv.v) : cosineHemisphere(uv.u, uv.v);
            ws.shadow.push(o, frame.toWorld(local), 0.f, tmax, r, Color{local.z, 0.f, 0.f}, rh.patch,
                           kOcclusion, 0, Vec2{rh.h.u, rh.h.v}, Nf,
                           rays.time[r]);  // weight.x: cos(theta), for the paper's sum
        }
    }
    ws.shadeMs += msSince(ts);
    if (ao.paperWeighting)
        ws.trace.trace(ws.shadow, ws.occlusionHits);  // the shade needs the hit distance
    else
        ws.trace.occluded(ws.shadow, ws.shadowBlocked);
    ts = EngineClock::now();
    const int aov = [&] {
        for (size_t a = 0; a < tile.aovNames.size(); ++a)
            if (tile.aovNames[a] == "occlusion") return int(a);
        return -1;
    }();
    for (size_t k = 0; k < n; ++k) {
        const uint32_t r = ws.hitRay[k], s = rays.owner[r];
        const RayHit& rh = ws.hits[r];
        double open = 0.0;
        for (size_t j = k * N; j < (k + 1) * N; ++j) {
            if (!ao.paperWeighting) {
                open += ws.shadowBlocked[j] ? 0.0 : 1.0;
                continue;
            }
            // Uniform directions, pdf 1 / (2 pi): the estimate of (1/pi) integral V cos is 2 cos(theta) x
            // shade.
            // The hit's distance from the surface point itself, not from the offset origin.
            const RayHit& h = ws.occlusionHits[j];
            const double d =
                h.hit ? double(length(ws.shadow.d[j] * h.h.t + ws.shadow.originN[j] * fr.acc.offset)) : 0.0;
            const double shade = !h.hit ? 1.0 : finite ? std::min(1.0, d / ao.maxDistance) : 0.0;
            open += 2.0 * double(ws.shadow.weight[j].x) * shade;
        }
        const float value = float(open / double(N));
        tile.r[s] = tile.g[s] = tile.b[s] = value;
        markCameraHit(tile, s, rh.h.t);
        if (tile.channels) {
            tile.setAttributes(s, fr.scene.attributes[rh.patch].object, faceForward(pts.N[k], pts.I[k]), 0,
                               false);
            setSurfaceAovs(fr, pts, k, s, tile, ws);
        }
        if (aov >= 0) tile.aovValues[size_t(aov)][s] = value;
    }
    ws.shadeMs += msSince(ts);
}

// ---- Camera rays, tiles, statistics ------------------------------------------------------------------

// Raster rectangle holding the projection of the whole scene (the bounding rectangle of its box's projected
// corners, which contains the projection of the box when the box lies in front of the eye), grown by a
// pixel for rounding: a camera ray outside it cannot hit anything, so it is not traced. With a lens, a
// camera ray from lens point a through the focal-plane point of raster x meets depth z where the eye sees
// x + a (1/z - 1/fd) (raster units), so the rectangle grows by the largest circle of confusion over the
// box's depths (Projector::circleOfConfusion; it is largest at the nearest or farthest depth).
struct SceneRect {
    float x0 = -INFINITY, x1 = INFINITY, y0 = -INFINITY, y1 = INFINITY;
};

SceneRect sceneRect(const RtAccel& acc, const Projector& proj) {
    SceneRect sr;
    float x0, x1, y0, y1;
    if (acc.bounds.empty()) {
        sr.x0 = sr.y0 = INFINITY, sr.x1 = sr.y1 = -INFINITY;  // nothing to hit
    } else if (proj.rasterBounds(acc.bounds, x0, x1, y0, y1) && std::isfinite(x0) && std::isfinite(x1) &&
               std::isfinite(y0) && std::isfinite(y1)) {
        const float coc =
            std::max(proj.circleOfConfusion(acc.bounds.lo.z), proj.circleOfConfusion(acc.bounds.hi.z));
        sr.x0 = x0 - 1.f - coc, sr.x1 = x1 + 1.f + coc, sr.y0 = y0 - 1.f - coc, sr.y1 = y1 + 1.f + coc;
    }
    return sr;
}

// The tile's camera rays, one per sample inside the scene's rectangle (and, with `traced`, only for the
// samples it marks: --adaptive's compacted list of extra samples), written in place: this runs for every
// sample of the frame; and the per-sample arrays of the camera-ray binning.
void makeCameraRays(const Projector& proj, const SceneRect& sr, Workspace& ws,
                    const std::vector<uint8_t>* traced = nullptr) {
    const size_t ns = ws.tile.sampleCount();
    RayList& rl = ws.rays;
    rl.resize(ns);
    CameraSamples& cs = ws.camera;
    cs.proj = &proj;
    cs.region = {ws.tile.region.x0, ws.tile.region.y0, ws.tile.region.x1, ws.tile.region.y1};
    cs.spp = ws.tile.spp;
    for (auto* v : {&cs.sampleX, &cs.sampleY, &cs.originX, &cs.originY, &cs.invX, &cs.invY, &cs.invZ,
                    &cs.dirX, &cs.dirY, &cs.dirZ})
        v->resize(ns + 4);
    cs.rayOfSample.resize(ns + 4);
    size_t m = 0;
    const bool blurred = !ws.tile.time.empty();
    for (size_t i = 0; i < ns + 4; ++i) {
        const float x = i < ns ? float(ws.tile.sx[i]) / kSubpixelScale : NAN;
        const float y = i < ns ? float(ws.tile.sy[i]) / kSubpixelScale : NAN;
        const bool skipped = traced && i < ns && !(*traced)[i];
        if (skipped || !(x >= sr.x0 && x <= sr.x1 && y >= sr.y0 && y <= sr.y1)) {  // sure miss: no ray
            cs.rayOfSample[i] = kNone;
            cs.sampleX[i] = cs.sampleY[i] = NAN;  // never inside a rectangle
            cs.originX[i] = cs.originY[i] = cs.invX[i] = cs.invY[i] = cs.invZ[i] = 0.f;
            cs.dirX[i] = cs.dirY[i] = cs.dirZ[i] = 0.f;
            continue;
        }
        Vec3 o, d;
        if (blurred) {
            // Paper 002, sec. 5.3.4: from the sample's lens point through its focal-plane point (thin
            // lens), scaled to d.z = 1 so that t stays the camera-space depth; at the sample's time.
            const CameraRay cr = generateRay(proj, Vec2{x, y}, ws.tile.lens[i]);
            o = cr.origin, d = cr.direction / cr.direction.z;
            rl.time[m] = ws.tile.time[i];
        } else {
            const float cx = (x - proj.ox) / proj.sx, cy = (y - proj.oy) / proj.sy;
            o = proj.perspective ? Vec3{0, 0, 0} : Vec3{cx, cy, 0};
            d = proj.perspective ? Vec3{cx, cy, 1.f} : Vec3{0, 0, 1.f};
        }
        const Vec3 inv = safeInverse(d);
        rl.o[m] = o, rl.d[m] = d;
        cs.rayOfSample[i] = uint32_t(m);
        cs.sampleX[i] = x, cs.sampleY[i] = y;
        cs.originX[i] = o.x, cs.originY[i] = o.y;
        cs.invX[i] = inv.x, cs.invY[i] = inv.y, cs.invZ[i] = inv.z;
        cs.dirX[i] = d.x, cs.dirY[i] = d.y, cs.dirZ[i] = d.z;
        rl.owner[m++] = uint32_t(i);
    }
    rl.resize(m);
    std::fill(rl.tmin.begin(), rl.tmin.end(), proj.nearClip);
    std::fill(rl.tmax.begin(), rl.tmax.end(), proj.farClip);
    std::fill(rl.weight.begin(), rl.weight.end(), Color{1, 1, 1});
    std::fill(rl.ignore.begin(), rl.ignore.end(), kNone);
    std::fill(rl.ignoreUV.begin(), rl.ignoreUV.end(), Vec2{-1.f, -1.f});
    std::fill(rl.originN.begin(), rl.originN.end(), Vec3{0.f, 0.f, 0.f});
    std::fill(rl.kind.begin(), rl.kind.end(), uint8_t(kPrimary));
    std::fill(rl.depth.begin(), rl.depth.end(), uint8_t(0));
    if (!blurred) std::fill(rl.time.begin(), rl.time.end(), 0.f);
}

// Work per tile for the progress, in sample units: its samples (set-up, filtering), its camera rays
// (samples inside the scene's rectangle) and, weighted by the rays each hit spawns (one per light plus the
// shading), its samples that are likely to hit, estimated from the projected boxes of the patches that
// overlap the tile (capped at the tile's area). Empty sky is cheap and the surfaces are not, so the
// progress fraction follows the trace time rather than the tile count.
std::vector<uint64_t> tileWork(const RtAccel& acc, const Projector& proj, const SceneRect& sr,
                               const BucketLayout& layout, int spp, size_t lights) {
    const int nb = layout.count();
    std::vector<double> covered(nb, 0.0);
    for (uint32_t patch = 0; patch < acc.patches.size(); ++patch) {
        float x0, x1, y0, y1;  // the patch's root box, as the BVH has it
        if (!proj.rasterBounds(acc.rootBox(patch), x0, x1, y0, y1))
            x0 = y0 = -INFINITY, x1 = y1 = INFINITY;  // reaches behind the eye: the whole view
        x0 = std::max(x0, float(layout.region.x0)), x1 = std::min(x1, float(layout.region.x1));
        y0 = std::max(y0, float(layout.region.y0)), y1 = std::min(y1, float(layout.region.y1));
        if (!(x0 < x1 && y0 < y1)) continue;
        int bx0, by0, bx1, by1;
        layout.overlapped(x0, y0, x1, y1, bx0, by0, bx1, by1);
        for (int by = by0; by <= by1; ++by)
            for (int bx = bx0; bx <= bx1; ++bx) {
                const Rect t = layout.target(by * layout.countX + bx);
                const float ix = std::min(float(t.x1), x1) - std::max(float(t.x0), x0);
                const float iy = std::min(float(t.y1), y1) - std::max(float(t.y0), y0);
                if (ix > 0 && iy > 0) covered[by * layout.countX + bx] += double(ix) * iy;
            }
    }
    std::vector<uint64_t> work(nb);
    for (int b = 0; b < nb; ++b) {
        const Rect t = layout.target(b);
        const double area = double(t.width()) * t.height();
        const double ix = std::max(0.f, std::min(float(t.x1), sr.x1) - std::max(float(t.x0), sr.x0));
        const double iy = std::max(0.f, std::min(float(t.y1), sr.y1) - std::max(float(t.y0), sr.y0));
        const double hits = std::min(covered[b], area);
        work[b] = uint64_t((area / 16 + ix * iy + hits * double(2 + lights)) * spp) + 1;
    }
    return work;
}

// Traces the camera samples of `ws.tile` (all, or those `traced` marks) to the end: camera rays, then the
// integrator's generations; colour, alpha, depth and attributes land in the tile.
void traceTile(const Frame& fr, const RenderSettings& settings, const Projector& proj, const SceneRect& sr,
               Workspace& ws, const std::vector<uint8_t>* traced = nullptr) {
    auto ts = EngineClock::now();
    makeCameraRays(proj, sr, ws, traced);
    ws.shadeMs += msSince(ts);
    if (settings.integrator == Integrator::AmbientOcclusion) {
        ws.trace.trace(ws.rays, ws.hits, &ws.camera);
        shadeOcclusion(fr, settings.ao, settings.seed, ws);
    } else if (settings.integrator == Integrator::Path) {
        ws.rayPdf.assign(ws.rays.size(), 0.f);
        for (bool camera = true; ws.rays.size() > 0; camera = false) {
            ws.trace.trace(ws.rays, ws.hits, camera ? &ws.camera : nullptr);
            shadePathGeneration(fr, ws);
            std::swap(ws.rays, ws.next);
            std::swap(ws.rayPdf, ws.nextPdf);
        }
    } else {
        for (bool camera = true; ws.rays.size() > 0; camera = false) {
            ws.trace.trace(ws.rays, ws.hits, camera ? &ws.camera : nullptr);
            shadeGeneration(fr, ws);
            std::swap(ws.rays, ws.next);
        }
    }
}

// The attribute channels the subpixel test reads from the presample.
constexpr uint32_t kAdaptiveChannels =
    kChannelObjectId | kChannelNormal | kChannelShadowCount | kChannelHasTexture;

// --adaptive in a blurred frame: the samples' times and lens points, and which objects move.
struct AdaptiveBlur {
    const BlurPattern* pattern = nullptr;  // nullptr: a sharp frame
    std::vector<uint8_t> movingObjects;    // by object id
};

// --adaptive, one tile (paper 004, sec. 4): `presamplePixels` is `target` grown by the neighbours the test
// reads (and the filter radius where attribute planes are filtered from the presample).
//  1. Presample: one ray through each pixel centre (the paper's start), colour and attributes.
//  2. Subpixel test (film/adaptive.h) for the target's 4 subpixels per pixel; the neighbours of a pixel on
//     the image's edge are presampled one pixel beyond it (the paper clamps, reading its maps as textures).
//  3. Extra samples: a 4x4-stratified tile of the shared sampler over the target; an active subpixel owns
//     the 2x2 strata in its quadrant (4 stratified jittered rays), only those samples are traced, as one
//     compacted ray list per generation through the trace service.
//  4. pixel = centre x (4 - n) / 4 + sum of the extra samples / 16 (colour and alpha).
void renderAdaptiveTile(const Frame& fr, const RenderSettings& settings, const Projector& proj,
                        const SceneRect& sr, const PixelFilter& filter, const AdaptiveBlur& blur, Rect target,
                        Rect presamplePixels, Workspace& ws, RenderResult& result) {
    // 1. Presample at the pixel centres (sample index 0 of each pixel for the other dimensions).
    ws.tile.reset(presamplePixels, 1, 1, settings.seed, std::numeric_limits<float>::infinity(),
                  settings.sampler, settings.output.channels | kAdaptiveChannels, settings.output.aovs);
    for (int py = presamplePixels.y0, i = 0; py < presamplePixels.y1; ++py)
        for (int px = presamplePixels.x0; px < presamplePixels.x1; ++px, ++i) {
            ws.tile.sx[size_t(i)] = (px << kSubpixelBits) + (1 << (kSubpixelBits - 1));
            ws.tile.sy[size_t(i)] = (py << kSubpixelBits) + (1 << (kSubpixelBits - 1));
        }
    ws.tile.setBlur(blur.pattern);  // a blurred frame: each presample at its own time and lens point
    ws.secondary.assign(ws.tile.sampleCount(), HitAttributes{kNoObject, Vec3{}, 0, 0});
    traceTile(fr, settings, proj, sr, ws);
    std::vector<HitAttributes> secondary;
    std::swap(secondary, ws.secondary);  // empty again: the extra samples record nothing
    if (!result.image.planes.empty()) {  // the attribute planes (and a filtered colour, replaced below)
        auto tf = EngineClock::now();
        reconstruct(ws.tile, filter, target, result.image);
        ws.filterMs += msSince(tf);
    }
    std::swap(ws.tile, ws.presample);

    // 2. The subpixel test, over the presample's attributes gathered once per pixel.
    const SampleTile& pre = ws.presample;
    const int pw = presamplePixels.width();
    ws.presampleAttributes.resize(pre.sampleCount());
    for (size_t i = 0; i < pre.sampleCount(); ++i) {
        PresampleAttributes& a = ws.presampleAttributes[i];
        a.color = Color{pre.r[i], pre.g[i], pre.b[i]};
        a.object = pre.objectId[i];
        a.normal = Vec3{pre.normalX[i], pre.normalY[i], pre.normalZ[i]};
        a.shadowCount = pre.shadowCount[i];
        a.textured = pre.hasTexture[i];
        a.secondary = secondary[i];
        a.blurred = blur.pattern && pre.a[i] > 0.f &&
                    ((a.object < blur.movingObjects.size() && blur.movingObjects[a.object]) ||
                     proj.circleOfConfusion(pre.z[i]) > 0.5f);
    }
    auto attributes = [&](int px, int py) -> const PresampleAttributes& {
        return ws.presampleAttributes[size_t(py - presamplePixels.y0) * size_t(pw) +
                                      size_t(px - presamplePixels.x0)];
    };
    const std::vector<uint32_t>& focus = settings.adaptive.focusObjects;
    auto focused = [&](const PresampleAttributes& a) {
        for (uint32_t id : focus)
            if (a.object == id || a.secondary.object == id) return true;
        return false;
    };
    const int tw = target.width(), th = target.height();
    ws.activeSubpixels.assign(size_t(tw) * th * 4, 0);
    const AdaptiveThresholds& thr = settings.adaptive.thresholds;
    uint64_t active = 0;
    for (int py = target.y0; py < target.y1; ++py)
        for (int px = target.x0; px < target.x1; ++px) {
            const PresampleAttributes& c = attributes(px, py);
            for (int q = 0; q < 4; ++q) {
                const PresampleAttributes* n[3];
                for (int k = 0; k < 3; ++k) {
                    int dx, dy;
                    subpixelNeighbour(q, k, dx, dy);
                    n[k] = &attributes(px + dx, py + dy);
                }
                const bool count =
                    focus.empty() || focused(c) || focused(*n[0]) || focused(*n[1]) || focused(*n[2]);
                ws.activeSubpixels[(size_t(py - target.y0) * tw + (px - target.x0)) * 4 + size_t(q)] =
                    subpixelActive(thr, c, n, count);
            }
            uint8_t* quads = &ws.activeSubpixels[(size_t(py - target.y0) * tw + (px - target.x0)) * 4];
            // A blurred frame refines the whole pixel or none of it: the centre presample is one instant
            // and lens point, no estimate of the quadrants it would stand in for.
            if (blur.pattern && (quads[0] | quads[1] | quads[2] | quads[3]))
                quads[0] = quads[1] = quads[2] = quads[3] = 1;
            active += quads[0] + quads[1] + quads[2] + quads[3];
        }
    ws.adaptivePixels += uint64_t(tw) * uint64_t(th);
    ws.adaptiveActive += active;

    // 3. Extra samples: slot s of a 4x4 tile lies in stratum (s % 4, s / 4), i.e. in quadrant
    // ((s % 4) / 2, (s / 4) / 2) of its pixel.
    // A tile with nothing active sets up no 16-sample tile at all (its samples' positions and clearing
    // cost about as much per pixel as the subpixel test).
    if (active > 0) {
        ws.tile.reset(target, 4, 4, settings.seed, std::numeric_limits<float>::infinity(), settings.sampler,
                      0, {});
        ws.tile.setBlur(blur.pattern);
        ws.tracedSamples.assign(ws.tile.sampleCount(), 0);
        for (size_t p = 0; p < size_t(tw) * th; ++p)
            for (int slot = 0; slot < 16; ++slot) {
                const int q = ((slot % 4) / 2) + 2 * ((slot / 4) / 2);
                ws.tracedSamples[p * 16 + size_t(slot)] = ws.activeSubpixels[p * 4 + size_t(q)];
            }
        traceTile(fr, settings, proj, sr, ws, &ws.tracedSamples);
    }

    // 4. The paper's weighting, and the map of refined subpixels.
    const Image& img = result.image;
    const int mapWidth = 2 * img.width;
    for (int py = target.y0; py < target.y1; ++py)
        for (int px = target.x0; px < target.x1; ++px) {
            const size_t p = size_t(py - target.y0) * tw + size_t(px - target.x0);
            const size_t c = size_t(py - presamplePixels.y0) * size_t(pw) + size_t(px - presamplePixels.x0);
            int n = 0;
            for (int q = 0; q < 4; ++q) n += ws.activeSubpixels[p * 4 + size_t(q)];
            const float wc = float(4 - n) / 4.f;
            float rgba[4] = {pre.r[c] * wc, pre.g[c] * wc, pre.b[c] * wc, pre.a[c] * wc};
            if (settings.adaptive.interpolate && n < 4) {
                // Inactive subpixels: the presample interpolated at their centres (colour and alpha).
                auto at = [&](int x, int y) {
                    return size_t(y - presamplePixels.y0) * size_t(pw) + size_t(x - presamplePixels.x0);
                };
                for (float& v : rgba) v = 0.f;
                for (int q = 0; q < 4; ++q) {
                    if (ws.activeSubpixels[p * 4 + size_t(q)]) continue;
                    size_t nbr[3];
                    for (int k = 0; k < 3; ++k) {
                        int dx, dy;
                        subpixelNeighbour(q, k, dx, dy);
                        nbr[k] = at(px + dx, py + dy);
                    }
                    const Color rgb =
                        interpolatedSubpixel(Color{pre.r[c], pre.g[c], pre.b[c]},
                                             Color{pre.r[nbr[0]], pre.g[nbr[0]], pre.b[nbr[0]]},
                                             Color{pre.r[nbr[1]], pre.g[nbr[1]], pre.b[nbr[1]]},
                                             Color{pre.r[nbr[2]], pre.g[nbr[2]], pre.b[nbr[2]]});
                    const float alpha =
                        interpolatedSubpixel(pre.a[c], pre.a[nbr[0]], pre.a[nbr[1]], pre.a[nbr[2]]);
                    rgba[0] += rgb.x / 4.f, rgba[1] += rgb.y / 4.f, rgba[2] += rgb.z / 4.f,
                        rgba[3] += alpha / 4.f;
                }
            }
            for (int slot = 0; slot < 16 && n > 0; ++slot) {
                const size_t s = p * 16 + size_t(slot);
                if (!ws.tracedSamples[s]) continue;
                rgba[0] += ws.tile.r[s] / 16.f, rgba[1] += ws.tile.g[s] / 16.f;
                rgba[2] += ws.tile.b[s] / 16.f, rgba[3] += ws.tile.a[s] / 16.f;
            }
            float* out = result.image.pixel(px, py);
            for (int k = 0; k < 4; ++k) out[k] = rgba[k];
            for (int q = 0; q < 4; ++q) {
                const size_t mx = size_t(2 * (px - img.x0) + (q & 1)), my = size_t(2 * (py - img.y0) + q / 2);
                result.refinedSubpixels[my * size_t(mapWidth) + mx] = ws.activeSubpixels[p * 4 + size_t(q)];
            }
        }
}

}  // namespace

RenderResult renderRt(const Scene& scene, const RenderSettings& settings,
                      const DisplacedDicerFactory* dicer) {
    const FrameSetup frame(scene, settings);
    RenderResult result = frame.startResult(settings);
    const Camera& cam = frame.camera;
    const int nx = frame.nx, ny = frame.ny;

    // Build: camera space (eye at the origin), both levels of the hierarchy, and the displaced patches'
    // micro-grids (rt/displaced.h).
    const auto tBuild = EngineClock::now();
    RtAccel acc;
    RtDisplacementOptions displacement;
    if (dicer && *dicer) displacement.dicer = (*dicer)(frame);
    const bool displacedDicer = displacement.dicer != nullptr;
    displacement.budgetBytes = size_t(std::max(1, settings.displacementCacheMb)) << 20;
    double samplesPerPatch = 0;
    const bool autoDepth = settings.subpatchDepth == kAutoSubpatchDepth;
    const int subpatchDepth =
        resolveSubpatchDepth(settings.subpatchDepth, scene, cam, double(nx * ny), &samplesPerPatch);
    // Leaf slabs where they pay (TraceService::leafSlabsPay), from the leaves the trees will have.
    const double cameraSamples = double(cam.width) * double(cam.height) * double(nx * ny);
    const bool leafSlabs =
        settings.leafSlabs && TraceService::leafSlabsPay(TraceService::leavesPerSample(
                                  scene.patches.size(), std::ldexp(1.0, subpatchDepth), cameraSamples));
    buildRtAccel(scene, cam.cameraFromWorld, subpatchDepth, settings.cullBackfaces, acc, &frame.motion,
                 kDefaultTimeSlabs, &displacement, settings.instancing, leafSlabs);
    const double buildMs = msSince(tBuild);
    if (displacedDicer)
        for (size_t i = 0; i < scene.patches.size(); ++i)
            if (acc.moving(uint32_t(i)) && scene.attributes[i].displacement >= 0) {
                result.warnings.push_back(
                    "the scene has displaced surfaces that move: --engine rt traces those undisplaced "
                    "(--engine reyes displaces them)");
                break;
            }
    // Binning (camera and shadow rays) replaces the per-ray BVH walk by one projection of the patches'
    // boxes; patches whose rectangles hold few rays per leaf then go down their trees per ray. It pays
    // unless the leaves far outnumber the samples (TraceService::binningPays: teapot 0.001 ... 24 Big Guys
    // 2.85 leaves per sample, all faster binned).
    const double leavesPerSample = TraceService::leavesPerSample(acc, cameraSamples);
    // The binning stages group the candidates of the boxes swept over the whole shutter; with time slabs
    // (a motion frame of several segments) the per-ray traversal's slab boxes are far tighter (killeroo_spin,
    // 800x600: binning needed 9 GB of candidate lists).
    // The binning stages do not know instances' shared trees (TraceService::traceList).
    const bool binning = settings.rayBinning && TraceService::binningPays(leavesPerSample) &&
                         acc.forest.slabCount == 0 && !acc.instanced();
    const TraceServiceOptions traceOpt{settings.cullBackfaces, binning};
    const Projector& proj = frame.projector;
    std::vector<uint8_t> castsShadows;
    for (const ShadingLight& l : frame.lights) castsShadows.push_back(l.castsShadows);
    const AreaLights areaLights(scene, acc, castsShadows);
    const Frame fr{scene,
                   acc,
                   frame.lights,
                   std::max(0, settings.maxDepth),
                   proj,
                   frame.textures.get(),
                   areaLights,
                   settings.seed,
                   settings.lightSamples,
                   std::max(1, settings.rouletteDepth),
                   settings.gloss};

    // Tiles of at most 64x64 pixels and about 4k samples: the wavefront's ray and candidate lists scale
    // with the samples in a tile, so more samples per pixel means smaller tiles and bounded memory; at 1
    // spp 64 px measured faster than 128 px (the per-tile arrays stay in cache) despite twice the share
    // of duplicated filter-margin rays (6% instead of 3%). At 4 spp, 32 px tiles (4k samples) against
    // 64 px (16k) took the same time or less and cut the peak memory (issue 18: teapot 63 -> 30 MB,
    // Killeroo 100 -> 69 MB at 800x600, 2 threads); 2k samples was slower on the teapot.
    const bool adaptive = settings.adaptive.enabled;
    // --adaptive: tiles sized for its 16-sample tile of extra samples, work as for about 2 samples.
    const int spp = adaptive ? 16 : nx * ny;
    const int bs =
        std::clamp(int(std::lround(64.0 / std::sqrt(double(spp)))), 16, std::max(settings.bucketSize, 64));
    const SceneRect sr = sceneRect(acc, proj);
    const int rx = frame.filter.radiusX(), ry = frame.filter.radiusY();
    const BucketLayout layout(frame.region, bs);
    const bool occlusion = settings.integrator == Integrator::AmbientOcclusion;
    const std::vector<uint64_t> work =
        tileWork(acc, proj, sr, layout, adaptive ? 2 : spp,
                 occlusion ? size_t(std::max(1, settings.ao.samples)) : frame.lights.size());

    // std::cref: the per-thread workspaces refer to the one accel (ETS keeps its arguments by value).
    tbb::enumerable_thread_specific<Workspace> workspaces(std::cref(acc), traceOpt);
    if (adaptive) {
        result.refinedSubpixels.assign(size_t(result.image.width) * result.image.height * 4, 0);
    }
    // --adaptive in a blurred frame: every sample (presample and extra) takes its time and lens point from
    // a bounding-box pattern of 16 samples per pixel, whatever the frame's scheme: the extra samples are
    // the 4x4 tile's, and the presample's are per pixel too. A blurred region's presamples differ between
    // neighbours (each saw another instant or lens point), so the colour test refines it.
    // The objects with a moving patch (camera motion moves them all) mark their presamples blurred.
    const BlurPattern adaptivePattern =
        adaptive && frame.blurred()
            ? makeBlurPattern(BlurSampling::BoundingBox, frame.blur.motion, frame.blur.lens, 16, cam.width,
                              settings.blur.tileSize, settings.blur.permutations, settings.seed)
            : BlurPattern{};
    AdaptiveBlur adaptiveBlur;
    if (adaptivePattern.active()) {
        adaptiveBlur.pattern = &adaptivePattern;
        for (size_t i = 0; i < scene.patches.size(); ++i)
            if (frame.motion.moving(i)) {
                const uint32_t object = scene.attributes[i].object;
                if (object >= adaptiveBlur.movingObjects.size())
                    adaptiveBlur.movingObjects.resize(object + 1, 0);
                adaptiveBlur.movingObjects[object] = 1;
            }
    }
    // The presample's margin: the neighbours of the subpixel test, and the filter's reach where the
    // attribute planes are reconstructed from it.
    const int margin = result.image.planes.empty() ? 1 : std::max({1, rx, ry});
    auto renderTile = [&](int b, Workspace& ws) {
        const Rect target = layout.target(b);
        if (adaptive) {
            // The presample reaches one pixel beyond the image, so that a subpixel on the image's edge is
            // compared with what lies across it (clamping to the edge, as the paper's texture maps do,
            // left every edge within the outermost pixels unrefined: bigguy_box 41.3 dB -> 54.5 dB).
            const Rect t = layout.target(b);
            const Rect presample{std::max(-1, t.x0 - margin), std::max(-1, t.y0 - margin),
                                 std::min(cam.width + 1, t.x1 + margin),
                                 std::min(cam.height + 1, t.y1 + margin)};
            renderAdaptiveTile(fr, settings, proj, sr, frame.filter, adaptiveBlur, target, presample, ws,
                               result);
            return;
        }
        frame.resetTile(ws.tile, layout.samples(b, rx, ry, cam.width, cam.height), settings);
        traceTile(fr, settings, proj, sr, ws);
        auto tf = EngineClock::now();
        reconstruct(ws.tile, frame.filter, target, result.image);
        ws.filterMs += msSince(tf);
    };
    const TileLoopResult loop = runTileLoop(layout, work, settings, workspaces, renderTile, &result.image);
    const double traceMs = loop.wallMs;

    TraceCounters total;
    double shadeMs = 0, filterMs = 0;
    size_t wsBytes = 0;
    for (const Workspace& w : workspaces) {
        total.add(w.trace.counters());
        shadeMs += w.shadeMs, filterMs += w.filterMs;
        wsBytes += w.tile.sampleCount() * 30 + w.rays.o.capacity() * 64 + w.trace.candidateBytes();
    }
    result.cancelled = loop.cancelled;
    nlohmann::json& s = result.stats;
    s["engine"] = "rt";
    s["patches_in"] = scene.patches.size();  // surfaces of every kind
    s["surfaces"] = surfaceKindStats(scene);
    nlohmann::json rays, hits;
    uint64_t totalRays = 0;
    for (int k = 0; k < kKinds; ++k) {
        rays[kKindNames[k]] = total.rays[k];
        hits[kKindNames[k]] = total.hits[k];
        totalRays += total.rays[k];
    }
    s["rays"] = rays;
    s["rays_total"] = totalRays;
    s["hits"] = hits;
    s["candidates"] = total.candidates;
    s["candidates_per_ray"] = totalRays ? double(total.candidates) / double(totalRays) : 0.0;
    s["box_tests"] = total.boxTests;
    s["binning_root_pairs"] = total.rootPairs;  // binned rays that went down a patch's tree per ray
    s["newton_runs"] = total.newtonRuns;
    s["hull_culled"] = total.hullCulled;
    s["slab_culled"] = total.slabCulled;
    s["origin_leaves_dropped"] = total.originLeafDropped;
    s["time_culled"] = total.timeCulled;
    s["shadow_lists"] = {{"binned", total.shadowListsBinned}, {"traversed", total.shadowListsTraversed}};
    s["newton_iterations"] = {
        {"total", total.newtonIterations},
        {"mean", total.newtonRuns ? double(total.newtonIterations) / double(total.newtonRuns) : 0.0},
        {"histogram", total.hist}};
    s["bvh_nodes"] = acc.bvh.nodes.size();
    s["bvh_depth"] = acc.bvh.maxDepth;
    s["subpatch_depth"] = acc.forest.depth;
    if (autoDepth) s["subpatch_depth_auto"] = {{"samples_per_patch", samplesPerPatch}};
    s["subpatch_nodes"] = acc.forest.treeCount() * acc.forest.nodesPerPatch;
    s["subpatch_trees"] = acc.forest.treeCount();
    s["instancing"] = {{"instances", acc.placements.size()}, {"shared_patches", acc.sharedPatches}};
    const size_t np = std::max<size_t>(1, scene.patches.size());
    const size_t instancingBytes =
        acc.treeOf.size() * sizeof(uint32_t) + acc.placementOf.size() * sizeof(uint32_t) +
        acc.placements.size() * sizeof(InstancePlacement) + acc.sharedRoot.size() * sizeof(Bounds3);
    s["memory"] = {{"bvh_bytes", acc.bvh.memoryBytes()},
                   {"subpatch_bytes", acc.forest.memoryBytes()},
                   {"instancing_bytes", instancingBytes},
                   {"patch_bytes", acc.patches.size() * sizeof(BezierPatch)},
                   {"bytes_per_patch",
                    double(acc.bvh.memoryBytes() + acc.forest.memoryBytes() + instancingBytes) / double(np)},
                   {"workspace_bytes", wsBytes},
                   {"displaced_bytes", acc.displaced.peakBytes()}};
    s["build_ms"] = buildMs;
    s["build"] = {
        {"bvh_ms", acc.bvhMs}, {"subpatch_ms", acc.subpatchMs}, {"displaced_ms", acc.displaced.buildMs}};
    if (acc.displaced.any())
        s["displaced"] = {{"patches", acc.displaced.patchCount()},
                          {"triangles", acc.displaced.triangles},
                          {"vertices", acc.displaced.vertices},
                          {"bytes_all", acc.displaced.bytesAll},
                          {"budget_bytes", acc.displaced.budgetBytes()},
                          {"lazy", acc.displaced.lazy()},
                          {"grids_built", acc.displaced.builds()},
                          {"grids_dropped", acc.displaced.evictions()},
                          {"peak_resident_bytes", acc.displaced.peakBytes()},
                          {"build_ms", acc.displaced.buildMs}};
    s["trace_ms"] = traceMs;
    s["mrays_per_s"] = traceMs > 0 ? double(totalRays) / (traceMs * 1e3) : 0.0;
    writeTileLoopStats(layout, loop, s);
    s["cull_backfaces"] = settings.cullBackfaces;
    s["ray_binning"] = binning;
    s["leaf_slabs"] = !acc.forest.leafSlabs.empty();
    s["leaves_per_sample"] = leavesPerSample;
    s["max_depth"] = fr.maxDepth;
    s["integrator"] = integratorName(settings.integrator);
    if (!areaLights.empty()) {
        nlohmann::json al = nlohmann::json::array();
        for (size_t i = 0; i < areaLights.size(); ++i) {
            const AreaLights::Light& l = areaLights.light(i);
            al.push_back({{"light", l.sceneLight},
                          {"surfaces", l.count},
                          {"area", l.area},
                          {"samples", settings.lightSamples > 0 ? settings.lightSamples : l.samples}});
        }
        s["area_lights"] = al;
    }
    if (settings.integrator == Integrator::Path) s["roulette_depth"] = fr.rouletteDepth;
    if (adaptive) {
        uint64_t pixels = 0, active = 0;
        for (const Workspace& w : workspaces) pixels += w.adaptivePixels, active += w.adaptiveActive;
        const AdaptiveThresholds& t = settings.adaptive.thresholds;
        const double px = double(std::max<uint64_t>(1, pixels));
        // Camera rays as the paper counts them: one presample per pixel plus 4 per active subpixel (the
        // presample margins that neighbouring tiles both trace are in rays.primary).
        s["adaptive"] = {{"pixels", pixels},
                         {"active_subpixels", active},
                         {"active_fraction", double(active) / (4.0 * px)},
                         {"camera_rays_per_pixel", (double(pixels) + 4.0 * double(active)) / px},
                         {"rays_per_pixel", double(totalRays) / px},
                         {"thresholds",
                          {{"color", t.color},
                           {"object_id", t.objectId},
                           {"normal", t.normal},
                           {"shadow", t.shadow},
                           {"texture", t.texture < 0.f ? t.color : t.texture},
                           {"secondary_object_id", t.secondaryObjectId},
                           {"secondary_normal", t.secondaryNormal},
                           {"secondary_shadow", t.secondaryShadow},
                           {"secondary_texture", t.secondaryTexture < 0.f ? t.color : t.secondaryTexture},
                           {"normal_cosine", t.normalCosine}}},
                         {"focus_objects", settings.adaptive.focusObjects},
                         {"interpolate", settings.adaptive.interpolate}};
    }
    if (occlusion)
        s["ao"] = {
            {"samples", std::max(1, settings.ao.samples)},
            {"max_distance", std::isfinite(settings.ao.maxDistance) ? nlohmann::json(settings.ao.maxDistance)
                                                                    : nlohmann::json("inf")},
            {"weighting", settings.ao.paperWeighting ? "paper" : "cosine"}};
    if (frame.blurred())  // as Reyes has it (the app adds what was asked for)
        s["blur"] = {{"sampling", blurSamplingName(frame.blur.scheme)},
                     {"motion", frame.blur.motion},
                     {"lens", frame.blur.lens},
                     {"knots", acc.motion.knotCount()},
                     {"moving_patches", acc.movingPatches},
                     {"time_slabs", acc.forest.slabCount},
                     {"lens_radius", proj.lensRadius}};
    s["stage_ms"] = {{"traversal_cpu", total.traversalMs},
                     {"newton_cpu", total.newtonMs},
                     {"shading_cpu", shadeMs},
                     {"filter_cpu", filterMs}};
    s["engine_ms"] = msSince(frame.start);
    return result;
}

}  // namespace tessera
