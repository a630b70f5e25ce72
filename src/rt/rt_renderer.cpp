#include "rt/rt_renderer.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <memory>
#include <mutex>

#include "rt/binning.h"
#include "rt/ray_list.h"

namespace tessera {
namespace {

using namespace rt;
using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// Per-hit shading inputs.
struct HitInfo {
    Vec3 P, N, I;
};

// Per tile in flight: the tile's samples, its ray lists and shading scratch, and its trace service.
struct Workspace {
    Workspace(const RtAccel& acc, TraceServiceOptions opt) : trace(acc, opt) {}
    TraceService trace;
    SampleTile tile;
    RayList rays, next, shadow;
    std::vector<RayHit> hits;
    std::vector<uint8_t> shadowBlocked;  // per shadow ray: occluded
    std::vector<HitInfo> info;
    std::vector<uint32_t> shadowIdx;
    std::vector<Color> contrib;
    std::vector<uint8_t> secondaryFlags;
    std::vector<Vec3> secO, secD;
    std::vector<Color> secW;
    CameraSamples camera;
    std::vector<ShadowRun> shadowRuns;
    double shadeMs = 0, filterMs = 0;
};

struct Frame {
    const Scene& scene;
    const RtAccel& acc;
    std::vector<ShadingLight> lights;
    int maxDepth;
};

// ---- Shading: from hits to colour, shadow rays and secondary rays ------------------------------------
// (the only place that reads materials and lights; shadeLocal is the same code as Reyes)

// The shading inputs of each hit of `ws.rays`: position, unit normal (orientation applied), unit incident
// direction.
void hitGeometry(const RtAccel& acc, Workspace& ws) {
    const RayList& rays = ws.rays;
    const size_t n = rays.size();
    ws.info.resize(n);
    for (size_t r = 0; r < n; ++r) {
        const RayHit& rh = ws.hits[r];
        if (!rh.hit) continue;
        HitInfo& hi = ws.info[r];
        hi.P = rh.h.p;
        hi.N = hitNormal(acc, rh.patch, rh.h);
        hi.I = normalize(rays.d[r]);
    }
}

// The shadow rays of the hits, one per non-ambient light with N.L > 0, from the face-forward side, light by
// light (one run per light, for the shadow binning); shadowIdx[r * lights + l]: ray r's ray towards
// light l (kNone: none).
void makeShadowRays(const Frame& fr, Workspace& ws) {
    const RtAccel& acc = fr.acc;
    const size_t n = ws.rays.size();
    const size_t nL = fr.lights.size();
    ws.shadowIdx.assign(n * nL, kNone);
    ws.shadow.clear();
    ws.shadowRuns.clear();
    ws.shadow.reserve(n * std::max<size_t>(nL, 1));
    for (size_t l = 0; l < nL; ++l) {
        const ShadingLight& light = fr.lights[l];
        if (light.type == LightType::Ambient) continue;
        const size_t runBegin = ws.shadow.size();
        for (size_t r = 0; r < n; ++r) {
            const RayHit& rh = ws.hits[r];
            if (!rh.hit) continue;
            const Material& m = fr.scene.materials[acc.material[rh.patch]];
            if (m.type == MaterialType::Constant) continue;
            const HitInfo& hi = ws.info[r];
            const Vec3 Nf = faceForward(hi.N, hi.I);
            Vec3 L;
            Color Cl;
            float dist;
            if (!lightIncidence(light, hi.P, L, Cl, dist)) continue;
            if (dot(Nf, L) <= 0.f) continue;
            const Vec3 o = hi.P + Nf * acc.offset;
            float tmax = dist;
            if (light.type != LightType::Distant) {
                // Aimed from the offset origin, so that the ray's line passes through the light (the
                // shadow binning projects from the light).
                const Vec3 toLight = light.position - o;
                const float len = length(toLight);
                if (len > 0.f && std::isfinite(len)) L = toLight / len, tmax = len;
                if (!(dot(Nf, L) > 0.f)) continue;
            }
            if (std::isfinite(tmax)) tmax -= acc.offset;
            ws.shadowIdx[r * nL + l] = uint32_t(ws.shadow.size());
            ws.shadow.push(o, L, 0.f, tmax, uint32_t(r), Color{}, rh.patch, kShadow, 0, Vec2{rh.h.u, rh.h.v},
                           Nf);
        }
        if (ws.shadow.size() > runBegin)
            ws.shadowRuns.push_back(
                {runBegin, ws.shadow.size(), light.type != LightType::Distant, light.position});
    }
}

// Colour of each hit (shadeLocal with the shadow rays' visibility, times the ray weight) into contrib, and
// its reflection (secondary slot 2r, flag 1) and refraction (slot 2r + 1, flag 2) rays up to maxDepth.
void shadeHits(const Frame& fr, Workspace& ws) {
    const RtAccel& acc = fr.acc;
    const RayList& rays = ws.rays;
    const size_t n = rays.size();
    const size_t nL = fr.lights.size();
    ws.contrib.assign(n, Color{});
    ws.secondaryFlags.assign(n, 0);
    ws.secO.resize(2 * n);
    ws.secD.resize(2 * n);
    ws.secW.resize(2 * n);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 256), [&](const tbb::blocked_range<size_t>& range) {
        for (size_t r = range.begin(); r != range.end(); ++r) {
            const RayHit& rh = ws.hits[r];
            if (!rh.hit) continue;
            const HitInfo& hi = ws.info[r];
            const Material& m = fr.scene.materials[acc.material[rh.patch]];
            auto visible = [&](size_t l, Vec3, Vec3, float) -> float {
                const uint32_t s = ws.shadowIdx[r * nL + l];
                return (s != kNone && ws.shadowBlocked[s]) ? 0.f : 1.f;
            };
            const Color w = rays.weight[r];
            ws.contrib[r] = w * shadeLocal(m, hi.P, hi.N, hi.I, fr.lights, visible);
            if (rays.depth[r] >= fr.maxDepth) continue;
            const Vec3 Nf = faceForward(hi.N, hi.I);
            if (m.type == MaterialType::Mirror) {
                const Color wr = w * m.Cs * m.Kr;
                if (maxComponent(wr) > 1e-4f) {
                    ws.secondaryFlags[r] |= 1;
                    ws.secO[2 * r] = hi.P + Nf * acc.offset;
                    ws.secD[2 * r] = reflectDir(hi.I, Nf);
                    ws.secW[2 * r] = wr;
                }
            } else if (m.type == MaterialType::Glass) {
                // hi.N is the outward normal (orientation attributes applied).
                Vec3 T;
                float F;
                const bool refr = refractDir(hi.I, hi.N, m.eta, T, F);
                const Color wr = w * (m.Kr * F);
                if (maxComponent(wr) > 1e-4f) {
                    ws.secondaryFlags[r] |= 1;
                    ws.secO[2 * r] = hi.P + Nf * acc.offset;
                    ws.secD[2 * r] = reflectDir(hi.I, Nf);
                    ws.secW[2 * r] = wr;
                }
                const Color wt = w * m.Cs * (m.Kt * (1.f - F));
                if (refr && maxComponent(wt) > 1e-4f) {
                    ws.secondaryFlags[r] |= 2;
                    ws.secO[2 * r + 1] = hi.P - Nf * acc.offset;
                    ws.secD[2 * r + 1] = T;
                    ws.secW[2 * r + 1] = wt;
                }
            }
        }
    });
}

// ---- end of shading ----------------------------------------------------------------------------------

// Accumulates the contributions into the tile in ray order (deterministic) and writes the next generation
// (reflection, refraction rays) to `ws.next`.
void accumulate(Workspace& ws) {
    const RayList& rays = ws.rays;
    const size_t n = rays.size();
    SampleTile& tile = ws.tile;
    ws.next.clear();
    for (size_t r = 0; r < n; ++r) {
        const uint32_t s = rays.owner[r];
        if (rays.kind[r] == kPrimary && ws.hits[r].hit) {
            tile.a[s] = 1.f;
            tile.z[s] = ws.hits[r].h.t;
            tile.pixelHit[s / size_t(tile.spp)] = 1;
        }
        if (!ws.hits[r].hit) continue;
        tile.r[s] += ws.contrib[r].x;
        tile.g[s] += ws.contrib[r].y;
        tile.b[s] += ws.contrib[r].z;
        const uint8_t f = ws.secondaryFlags[r];
        if (f & 1)
            ws.next.push(ws.secO[2 * r], ws.secD[2 * r], 0.f, std::numeric_limits<float>::infinity(), s,
                         ws.secW[2 * r], ws.hits[r].patch, kReflection, uint8_t(rays.depth[r] + 1),
                         Vec2{ws.hits[r].h.u, ws.hits[r].h.v}, faceForward(ws.info[r].N, ws.info[r].I));
        if (f & 2)
            ws.next.push(ws.secO[2 * r + 1], ws.secD[2 * r + 1], 0.f, std::numeric_limits<float>::infinity(),
                         s, ws.secW[2 * r + 1], ws.hits[r].patch, kRefraction, uint8_t(rays.depth[r] + 1),
                         Vec2{ws.hits[r].h.u, ws.hits[r].h.v}, -faceForward(ws.info[r].N, ws.info[r].I));
    }
}

// One wavefront generation: shade the hits of `ws.rays`, trace their shadow rays, accumulate colour into
// the tile and write the next generation (reflection, refraction) to `ws.next`.
void shadeGeneration(const Frame& fr, Workspace& ws) {
    auto ts = Clock::now();
    hitGeometry(fr.acc, ws);
    makeShadowRays(fr, ws);
    ws.shadeMs += msSince(ts);
    ws.trace.occluded(ws.shadow, ws.shadowRuns, ws.shadowBlocked);
    ts = Clock::now();
    shadeHits(fr, ws);
    accumulate(ws);
    ws.shadeMs += msSince(ts);
}

// ---- Camera rays, tiles, statistics ------------------------------------------------------------------

// Raster rectangle holding the projection of the whole scene (the bounding rectangle of its box's projected
// corners, which contains the projection of the box when the box lies in front of the eye), grown by a
// pixel for rounding: a camera ray outside it cannot hit anything, so it is not traced.
struct SceneRect {
    float x0 = -INFINITY, x1 = INFINITY, y0 = -INFINITY, y1 = INFINITY;
};

SceneRect sceneRect(const RtAccel& acc, const Projector& proj) {
    SceneRect sr;
    if (acc.bounds.empty()) {
        sr.x0 = sr.y0 = INFINITY, sr.x1 = sr.y1 = -INFINITY;  // nothing to hit
    } else {
        bool inFront = true;
        float x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
        for (int c = 0; c < 8; ++c) {
            const Vec3 p{c & 1 ? acc.bounds.hi.x : acc.bounds.lo.x, c & 2 ? acc.bounds.hi.y : acc.bounds.lo.y,
                         c & 4 ? acc.bounds.hi.z : acc.bounds.lo.z};
            if (proj.perspective && !(p.z > 0.f)) inFront = false;
            const Vec3 r = proj.toRaster(p);
            x0 = std::min(x0, r.x), x1 = std::max(x1, r.x), y0 = std::min(y0, r.y), y1 = std::max(y1, r.y);
        }
        if (inFront && std::isfinite(x0) && std::isfinite(x1) && std::isfinite(y0) && std::isfinite(y1))
            sr.x0 = x0 - 1.f, sr.x1 = x1 + 1.f, sr.y0 = y0 - 1.f, sr.y1 = y1 + 1.f;
    }
    return sr;
}

// The tile's camera rays, one per sample inside the scene's rectangle (written in place: this runs for
// every sample of the frame), and the per-sample arrays of the camera-ray binning.
void makeCameraRays(const Projector& proj, const SceneRect& sr, Workspace& ws) {
    const size_t ns = ws.tile.sampleCount();
    RayList& rl = ws.rays;
    rl.resize(ns);
    CameraSamples& cs = ws.camera;
    cs.proj = &proj;
    cs.region = {ws.tile.region.x0, ws.tile.region.y0, ws.tile.region.x1, ws.tile.region.y1};
    cs.spp = ws.tile.spp;
    for (auto* v : {&cs.sampleX, &cs.sampleY, &cs.originX, &cs.originY, &cs.invX, &cs.invY, &cs.invZ})
        v->resize(ns + 4);
    cs.rayOfSample.resize(ns + 4);
    size_t m = 0;
    for (size_t i = 0; i < ns + 4; ++i) {
        const float x = i < ns ? float(ws.tile.sx[i]) / kSubpixelScale : NAN;
        const float y = i < ns ? float(ws.tile.sy[i]) / kSubpixelScale : NAN;
        if (!(x >= sr.x0 && x <= sr.x1 && y >= sr.y0 && y <= sr.y1)) {  // sure miss: no ray
            cs.rayOfSample[i] = kNone;
            cs.sampleX[i] = cs.sampleY[i] = NAN;  // never inside a rectangle
            cs.originX[i] = cs.originY[i] = cs.invX[i] = cs.invY[i] = cs.invZ[i] = 0.f;
            continue;
        }
        const float cx = (x - proj.ox) / proj.sx, cy = (y - proj.oy) / proj.sy;
        const Vec3 o = proj.perspective ? Vec3{0, 0, 0} : Vec3{cx, cy, 0};
        const Vec3 d = proj.perspective ? Vec3{cx, cy, 1.f} : Vec3{0, 0, 1.f};
        const Vec3 inv = safeInverse(d);
        rl.o[m] = o, rl.d[m] = d;
        cs.rayOfSample[i] = uint32_t(m);
        cs.sampleX[i] = x, cs.sampleY[i] = y;
        cs.originX[i] = o.x, cs.originY[i] = o.y;
        cs.invX[i] = inv.x, cs.invY[i] = inv.y, cs.invZ[i] = inv.z;
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
}

}  // namespace

Vec3 reflectDir(Vec3 I, Vec3 N) {
    return normalize(I - N * (2.f * dot(I, N)));
}

bool refractDir(Vec3 I, Vec3 N, float eta, Vec3& T, float& F) {
    float cosi = -dot(I, N);
    float n1 = 1.f, n2 = eta;
    Vec3 n = N;
    if (cosi < 0.f) {  // leaving the medium
        cosi = -cosi;
        n = -N;
        std::swap(n1, n2);
    }
    const float r = n1 / n2;
    const float sin2t = r * r * std::max(0.f, 1.f - cosi * cosi);
    if (sin2t >= 1.f) {
        F = 1.f;
        return false;
    }
    const float cost = std::sqrt(1.f - sin2t);
    const float rs = (n1 * cosi - n2 * cost) / (n1 * cosi + n2 * cost);
    const float rp = (n1 * cost - n2 * cosi) / (n1 * cost + n2 * cosi);
    F = 0.5f * (rs * rs + rp * rp);
    T = normalize(I * r + n * (r * cosi - cost));
    return true;
}

RenderResult renderRt(const Scene& scene, const RenderSettings& settings) {
    const auto tStart = Clock::now();
    RenderResult result;
    const Camera& cam = scene.camera;
    const int W = cam.width, H = cam.height;
    result.image = Image(W, H);
    const PixelFilter filter = makeFilter(scene.image);
    const int nx = std::max(1, scene.image.pixelSamplesX), ny = std::max(1, scene.image.pixelSamplesY);

    // Build: camera space (eye at the origin), both levels of the hierarchy.
    const auto tBuild = Clock::now();
    RtAccel acc;
    buildRtAccel(scene, cam.cameraFromWorld, settings.subpatchDepth, settings.cullBackfaces, acc);
    const double buildMs = msSince(tBuild);
    // Binning (camera and shadow rays) pays when the subpatch leaves are few compared with the samples, i.e.
    // boxes cover several samples each: the per-tile descent then replaces many per-ray box tests. With
    // many small leaves the descent costs more than the traversal it replaces (teapot 0.001 and bigguy
    // 0.19 leaves per sample: binning faster; killeroo 0.38: equal; killeroo2 0.77, bigguy9 1.07, bigguy24
    // 2.85: the traversal faster).
    const double leavesPerSample =
        TraceService::leavesPerSample(acc, double(W) * double(H) * double(nx * ny));
    const bool binning = settings.rayBinning && TraceService::binningPays(leavesPerSample);
    const TraceServiceOptions traceOpt{settings.cullBackfaces, binning};
    Frame fr{scene, acc, {}, std::max(0, settings.maxDepth)};
    for (const Light& l : scene.lights) fr.lights.push_back(prepareLight(l, cam.cameraFromWorld));
    const Projector proj(cam);

    // Tiles of at most 64x64 pixels and about 16k samples: the wavefront's ray and candidate lists scale
    // with the samples in a tile, so more samples per pixel means smaller tiles and bounded memory; at 1
    // spp 64 px measured faster than 128 px (the per-tile arrays stay in cache) despite twice the share
    // of duplicated filter-margin rays (6% instead of 3%).
    const int spp = nx * ny;
    const int bs =
        std::clamp(int(std::lround(128.0 / std::sqrt(double(spp)))), 16, std::max(settings.bucketSize, 64));
    const SceneRect sr = sceneRect(acc, proj);
    const int rx = filter.radiusX(), ry = filter.radiusY();
    const int nbx = (W + bs - 1) / bs, nby = (H + bs - 1) / bs, nb = nbx * nby;

    std::mutex poolMutex;
    std::vector<std::unique_ptr<Workspace>> pool, all;
    auto acquire = [&]() -> Workspace* {
        std::lock_guard<std::mutex> lock(poolMutex);
        if (pool.empty()) {
            all.push_back(std::make_unique<Workspace>(acc, traceOpt));
            return all.back().get();
        }
        Workspace* w = pool.back().release();
        pool.pop_back();
        return w;
    };
    auto release = [&](Workspace* w) {
        std::lock_guard<std::mutex> lock(poolMutex);
        pool.emplace_back(w);
    };
    // `all` owns the workspaces; `pool` holds non-owning views of the idle ones.
    auto renderTile = [&](int b) {
        Workspace* wsp = acquire();
        Workspace& ws = *wsp;
        const int bx = b % nbx, by = b / nbx;
        Rect target{bx * bs, by * bs, std::min(W, (bx + 1) * bs), std::min(H, (by + 1) * bs)};
        Rect region{std::max(0, target.x0 - rx), std::max(0, target.y0 - ry), std::min(W, target.x1 + rx),
                    std::min(H, target.y1 + ry)};
        ws.tile.reset(region, nx, ny, settings.seed, std::numeric_limits<float>::infinity());
        auto ts = Clock::now();
        makeCameraRays(proj, sr, ws);
        ws.shadeMs += msSince(ts);
        for (bool camera = true; ws.rays.size() > 0; camera = false) {
            ws.trace.trace(ws.rays, ws.hits, camera ? &ws.camera : nullptr);
            shadeGeneration(fr, ws);
            std::swap(ws.rays, ws.next);
        }
        auto tf = Clock::now();
        reconstruct(ws.tile, filter, target, result.image);
        ws.filterMs += msSince(tf);
        release(wsp);
    };
    // The pool's unique_ptrs must not double-own: keep ownership in `all` only.
    auto cleanup = [&] {
        for (auto& p : pool) p.release();
        pool.clear();
    };

    const auto tTrace = Clock::now();
    std::atomic<int> nextTile{0}, doneTiles{0};
    std::atomic<bool> cancelled{false};
    const int workers = tbb::this_task_arena::max_concurrency();
    tbb::parallel_for(
        0, workers,
        [&](int) {
            for (;;) {
                if (settings.cancel && settings.cancel->load(std::memory_order_relaxed)) {
                    cancelled = true;
                    break;
                }
                int b = nextTile.fetch_add(1);
                if (b >= nb) break;
                renderTile(b);
                int done = ++doneTiles;
                if (settings.progress) settings.progress(done, nb);
            }
        },
        tbb::static_partitioner());
    const double traceMs = msSince(tTrace);
    cleanup();

    TraceCounters total;
    double shadeMs = 0, filterMs = 0;
    size_t wsBytes = 0;
    for (const auto& w : all) {
        total.add(w->trace.counters());
        shadeMs += w->shadeMs, filterMs += w->filterMs;
        wsBytes += w->tile.sampleCount() * 30 + w->rays.o.capacity() * 64 + w->trace.candidateBytes();
    }
    result.cancelled = cancelled.load();
    nlohmann::json& s = result.stats;
    s["engine"] = "rt";
    s["patches_in"] = scene.patches.size();
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
    s["newton_runs"] = total.newtonRuns;
    s["hull_culled"] = total.hullCulled;
    s["shadow_lists"] = {{"binned", total.shadowListsBinned}, {"traversed", total.shadowListsTraversed}};
    s["newton_iterations"] = {
        {"total", total.newtonIterations},
        {"mean", total.newtonRuns ? double(total.newtonIterations) / double(total.newtonRuns) : 0.0},
        {"histogram", total.hist}};
    s["bvh_nodes"] = acc.bvh.nodes.size();
    s["bvh_depth"] = acc.bvh.maxDepth;
    s["subpatch_depth"] = acc.forest.depth;
    s["subpatch_nodes"] = acc.forest.boxes.size();
    const size_t np = std::max<size_t>(1, scene.patches.size());
    s["memory"] = {{"bvh_bytes", acc.bvh.memoryBytes()},
                   {"subpatch_bytes", acc.forest.memoryBytes()},
                   {"patch_bytes", acc.patches.size() * sizeof(BezierPatch)},
                   {"bytes_per_patch", double(acc.bvh.memoryBytes() + acc.forest.memoryBytes()) / double(np)},
                   {"workspace_bytes", wsBytes}};
    s["build_ms"] = buildMs;
    s["build"] = {{"bvh_ms", acc.bvhMs}, {"subpatch_ms", acc.subpatchMs}};
    s["trace_ms"] = traceMs;
    s["mrays_per_s"] = traceMs > 0 ? double(totalRays) / (traceMs * 1e3) : 0.0;
    s["tile_size"] = bs;
    s["tiles"] = nb;
    s["cull_backfaces"] = settings.cullBackfaces;
    s["ray_binning"] = binning;
    s["leaves_per_sample"] = leavesPerSample;
    s["max_depth"] = fr.maxDepth;
    s["stage_ms"] = {{"traversal_cpu", total.traversalMs},
                     {"newton_cpu", total.newtonMs},
                     {"shading_cpu", shadeMs},
                     {"filter_cpu", filterMs}};
    s["engine_ms"] = msSince(tStart);
    return result;
}

}  // namespace tessera
