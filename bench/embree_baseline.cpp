// embree_baseline: the triangle-based alternative a user would otherwise pick. Tessellates every patch
// into triangles fine enough that the geometric error stays under a screen-space bound, builds an Embree
// BVH and traces the same camera rays (same sample positions, same pixel filter, same RI shading, hard
// shadows) as Tessera's engines. Prints and saves JSON: triangles, memory, build and trace time, rays/s.
//
//   embree_baseline SCENE [--res WxH] [--spp N] [--max-error-px E] [--threads N] [--no-shadows]
//                   [-o IMAGE] [--json OUT.json] [--runs N] [--sampler sobol|jittered]
#include <embree3/rtcore.h>
#include <fmt/core.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "film/film.h"
#include "io/image_io.h"
#include "io/scene_loader.h"
#include "shading/surface.h"

using namespace tessera;
using Clock = std::chrono::steady_clock;

namespace {

double msSince(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

// Bound on |P - bilinear interpolation| over a parameter cell of size h: h^2/8 * (Muu + 2 Muv + Mvv),
// with second-derivative bounds from the control net (de Boor, "A Practical Guide to Splines").
float secondDerivativeBound(const BezierPatch& p) {
    float muu = 0, mvv = 0, muv = 0;
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 2; ++u) muu = std::max(muu, length(p.at(u + 2, v) - p.at(u + 1, v) * 2.f + p.at(u, v)));
    for (int v = 0; v < 2; ++v)
        for (int u = 0; u < 4; ++u) mvv = std::max(mvv, length(p.at(u, v + 2) - p.at(u, v + 1) * 2.f + p.at(u, v)));
    for (int v = 0; v < 3; ++v)
        for (int u = 0; u < 3; ++u)
            muv = std::max(muv, length(p.at(u + 1, v + 1) - p.at(u + 1, v) - p.at(u, v + 1) + p.at(u, v)));
    return 6.f * muu + 2.f * 9.f * muv + 6.f * mvv;
}

struct Mesh {
    std::vector<float> pos;      // xyz per vertex (world space)
    std::vector<float> nrm;      // exact patch normal per vertex
    std::vector<uint32_t> tri;   // 3 indices per triangle
    std::vector<uint32_t> triPatch;
};

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2) {
        fmt::print(stderr, "usage: embree_baseline SCENE [--res WxH] [--spp N] [--max-error-px E] [--threads N] "
                           "[--no-shadows] [-o IMAGE] [--json OUT] [--runs N] [--sampler sobol|jittered]\n");
        return 2;
    }
    std::string scenePath = argv[1], output, jsonOut, res;
    int spp = 1, threads = 0, runs = 3;
    float maxErrorPx = 0.1f;
    bool shadows = true;
    SamplerKind sampler = SamplerKind::Sobol;  // the renderer's default, so the images compare
    for (int i = 2; i < argc; ++i) {
        std::string a = argv[i];
        auto next = [&] { return i + 1 < argc ? std::string(argv[++i]) : std::string(); };
        if (a == "--res") res = next();
        else if (a == "--spp") spp = std::max(1, std::stoi(next()));
        else if (a == "--max-error-px") maxErrorPx = std::stof(next());
        else if (a == "--threads") threads = std::stoi(next());
        else if (a == "--no-shadows") shadows = false;
        else if (a == "-o") output = next();
        else if (a == "--json") jsonOut = next();
        else if (a == "--runs") runs = std::max(1, std::stoi(next()));
        else if (a == "--sampler") sampler = next() == "jittered" ? SamplerKind::Jittered : SamplerKind::Sobol;
        else {
            fmt::print(stderr, "embree_baseline: unknown option {}\n", a);
            return 2;
        }
    }
    std::unique_ptr<tbb::global_control> gc;
    if (threads > 0) gc = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, threads);

    Scene scene;
    try {
        scene = loadScene(scenePath, [](const std::string&) {});
    } catch (const std::exception& e) {
        fmt::print(stderr, "{}\n", e.what());
        return 2;
    }
    if (!res.empty() && std::sscanf(res.c_str(), "%dx%d", &scene.camera.width, &scene.camera.height) != 2) return 2;
    int nx = 1, ny = 1;
    splitSamplesPerPixel(spp, nx, ny);
    const Camera& cam = scene.camera;
    const Projector proj(cam);
    const Mat4 worldFromCamera = cam.cameraFromWorld.inverse();
    const Vec3 eye = worldFromCamera.point({0, 0, 0});

    // Tessellate: per patch, the uniform rate whose bilinear error, projected at the patch's nearest
    // depth, stays under maxErrorPx.
    auto tTess = Clock::now();
    Mesh mesh;
    for (uint32_t pi = 0; pi < scene.patches.size(); ++pi) {
        const BezierPatch& p = scene.patches[pi];
        float zmin = 1e30f;
        for (const Vec3& c : p.cp) zmin = std::min(zmin, cam.cameraFromWorld.point(c).z);
        zmin = std::max(zmin, cam.nearClip);
        float worldError = maxErrorPx * zmin / std::fabs(proj.sx);
        int n = int(std::ceil(std::sqrt(secondDerivativeBound(p) / (8.f * worldError))));
        n = std::clamp(n, 1, 256);
        uint32_t base = uint32_t(mesh.pos.size() / 3);
        for (int j = 0; j <= n; ++j)
            for (int i = 0; i <= n; ++i) {
                Vec3 pos = evalPatch(p, float(i) / n, float(j) / n);
                Vec3 nn = normalize(patchNormal(p, float(i) / n, float(j) / n));
                if (scene.attributes[pi].flipNormal) nn = -nn;
                mesh.pos.insert(mesh.pos.end(), {pos.x, pos.y, pos.z});
                mesh.nrm.insert(mesh.nrm.end(), {nn.x, nn.y, nn.z});
            }
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i) {
                uint32_t a = base + j * (n + 1) + i, b = a + 1, c = a + n + 2, d = a + n + 1;
                mesh.tri.insert(mesh.tri.end(), {a, b, c, a, c, d});
                mesh.triPatch.push_back(pi);
                mesh.triPatch.push_back(pi);
            }
    }
    const double tessMs = msSince(tTess);
    const size_t triangles = mesh.tri.size() / 3;

    // Build.
    static std::atomic<int64_t> embreeBytes{0}, embreePeak{0};
    RTCDevice device = rtcNewDevice(threads > 0 ? fmt::format("threads={}", threads).c_str() : nullptr);
    rtcSetDeviceMemoryMonitorFunction(
        device,
        [](void*, ssize_t bytes, bool) {
            int64_t now = embreeBytes += bytes;
            int64_t peak = embreePeak.load();
            while (now > peak && !embreePeak.compare_exchange_weak(peak, now)) {
            }
            return true;
        },
        nullptr);
    auto tBuild = Clock::now();
    RTCScene rscene = rtcNewScene(device);
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, mesh.pos.data(), 0,
                               3 * sizeof(float), mesh.pos.size() / 3);
    rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, mesh.tri.data(), 0,
                               3 * sizeof(uint32_t), triangles);
    rtcCommitGeometry(geom);
    rtcAttachGeometry(rscene, geom);
    rtcReleaseGeometry(geom);
    rtcCommitScene(rscene);
    const double buildMs = msSince(tBuild);

    std::vector<ShadingLight> lights;
    for (const Light& l : scene.lights) lights.push_back(prepareLight(l, Mat4{}));  // world space

    // Trace: tiles of 32x32 pixels, same samples and filter as the Tessera engines.
    const PixelFilter filter = makeFilter(scene.image);
    const int W = cam.width, H = cam.height, bs = 32, nbx = (W + bs - 1) / bs, nby = (H + bs - 1) / bs;
    Image image(W, H);
    std::vector<double> traceTimes;
    std::atomic<uint64_t> primary{0}, shadow{0}, hits{0};
    for (int run = 0; run < runs; ++run) {
        primary = shadow = hits = 0;
        auto tTrace = Clock::now();
        tbb::parallel_for(0, nbx * nby, [&](int b) {
            const int bx = b % nbx, by = b / nbx;
            Rect target{bx * bs, by * bs, std::min(W, (bx + 1) * bs), std::min(H, (by + 1) * bs)};
            const int rx = filter.radiusX(), ry = filter.radiusY();
            Rect region{std::max(0, target.x0 - rx), std::max(0, target.y0 - ry), std::min(W, target.x1 + rx),
                        std::min(H, target.y1 + ry)};
            SampleTile tile;
            tile.reset(region, nx, ny, 0, std::numeric_limits<float>::infinity(), sampler);
            RTCIntersectContext ctx;
            uint64_t nPrimary = 0, nShadow = 0, nHits = 0;
            for (size_t i = 0; i < tile.sampleCount(); ++i) {
                float sx = tile.sx[i] / kSubpixelScale, sy = tile.sy[i] / kSubpixelScale;
                Vec3 dcam{(sx - proj.ox) / proj.sx, (sy - proj.oy) / proj.sy, 1.f};
                Vec3 dir = normalize(worldFromCamera.vector(dcam));
                RTCRayHit rh{};
                rh.ray.org_x = eye.x, rh.ray.org_y = eye.y, rh.ray.org_z = eye.z;
                rh.ray.dir_x = dir.x, rh.ray.dir_y = dir.y, rh.ray.dir_z = dir.z;
                rh.ray.tnear = 0.f;
                rh.ray.tfar = std::numeric_limits<float>::infinity();
                rh.ray.mask = 0xffffffff;
                rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
                rtcInitIntersectContext(&ctx);
                rtcIntersect1(rscene, &ctx, &rh);
                ++nPrimary;
                if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) continue;
                ++nHits;
                const uint32_t* t = &mesh.tri[size_t(rh.hit.primID) * 3];
                float u = rh.hit.u, v = rh.hit.v, w = 1.f - u - v;
                auto nv = [&](uint32_t k) { return Vec3{mesh.nrm[k * 3], mesh.nrm[k * 3 + 1], mesh.nrm[k * 3 + 2]}; };
                Vec3 N = normalize(nv(t[0]) * w + nv(t[1]) * u + nv(t[2]) * v);
                Vec3 P = eye + dir * rh.ray.tfar;
                const PatchAttributes& attr = scene.attributes[mesh.triPatch[rh.hit.primID]];
                const Material& m = scene.materials[attr.material];
                Vec3 Ng = normalize(Vec3{rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z});
                Vec3 offset = (dot(Ng, dir) < 0 ? Ng : -Ng) * (1e-3f * std::max(1.f, length(P - eye)));
                // The same light samples and surface shading as Tessera's engines (src/shading); the
                // visibility queries are answered by Embree's occlusion rays.
                LightSample samples[64];
                float vis[64];
                const size_t nL = std::min<size_t>(lights.size(), 64);
                const Vec3 Nf = faceForward(N, dir);
                for (size_t li = 0; li < nL; ++li) {
                    samples[li] = sampleLight(lights[li], P);
                    vis[li] = 1.f;
                    const LightSample& ls = samples[li];
                    if (!shadows || !ls.valid || ls.ambient || dot(Nf, ls.L) <= 0.f) continue;
                    RTCRay sr{};
                    Vec3 o = P + offset;
                    sr.org_x = o.x, sr.org_y = o.y, sr.org_z = o.z;
                    sr.dir_x = ls.L.x, sr.dir_y = ls.L.y, sr.dir_z = ls.L.z;
                    sr.tnear = 0.f;
                    sr.tfar = std::isfinite(ls.dist) ? ls.dist * 0.9999f : std::numeric_limits<float>::infinity();
                    sr.mask = 0xffffffff;
                    RTCIntersectContext sctx;
                    rtcInitIntersectContext(&sctx);
                    rtcOccluded1(rscene, &sctx, &sr);
                    ++nShadow;
                    vis[li] = sr.tfar < 0.f ? 0.f : 1.f;
                }
                Color c = shadeSurfacePoint(m, N, dir, samples, vis, nL);
                tile.r[i] = c.x, tile.g[i] = c.y, tile.b[i] = c.z, tile.a[i] = 1.f;
                tile.z[i] = rh.ray.tfar;
                tile.pixelHit[i / tile.spp] = 1;
            }
            reconstruct(tile, filter, target, image);
            primary += nPrimary;
            shadow += nShadow;
            hits += nHits;
        });
        traceTimes.push_back(msSince(tTrace));
    }
    std::sort(traceTimes.begin(), traceTimes.end());
    const double traceMs = traceTimes[traceTimes.size() / 2];
    rtcReleaseScene(rscene);
    rtcReleaseDevice(device);

    nlohmann::json j;
    j["engine"] = "embree-triangles";
    j["scene"] = scenePath;
    j["width"] = W, j["height"] = H, j["spp"] = nx * ny;
    j["max_error_px"] = maxErrorPx;
    j["triangles"] = triangles;
    j["vertices"] = mesh.pos.size() / 3;
    j["mesh_bytes"] = mesh.pos.size() * 4 + mesh.nrm.size() * 4 + mesh.tri.size() * 4 + mesh.triPatch.size() * 4;
    j["embree_bytes_peak"] = embreePeak.load();
    j["tessellate_ms"] = tessMs;
    j["build_ms"] = buildMs;
    j["trace_ms_median"] = traceMs;
    j["runs"] = runs;
    j["rays"] = {{"primary", primary.load()}, {"shadow", shadow.load()}};
    j["hits"] = hits.load();
    j["mrays_per_s"] = (primary.load() + shadow.load()) / (traceMs * 1e3);
    fmt::print("{}\n", j.dump(2));
    if (!jsonOut.empty()) std::ofstream(jsonOut) << j.dump(2) << "\n";
    if (!output.empty()) writeImage(output, image, {scene.image.exposureGain, scene.image.exposureGamma, scene.image.srgbOutput});
    return 0;
}
