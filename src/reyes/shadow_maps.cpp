#include "reyes/shadow_maps.h"

#include <tbb/enumerable_thread_specific.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <optional>
#include <thread>

#include "core/hash.h"
#include "engine/clock.h"
#include "reyes/displace.h"
#include "reyes/pipeline.h"
#include "reyes/rasterize.h"

namespace tessera {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
// Spot cones wider than this get a cube map: a single perspective map would waste most texels at its
// rim (tan grows without bound towards 90 degrees).
constexpr float kMaxSpotMapHalfAngle = 60.f * std::numbers::pi_v<float> / 180.f;

// A rigid world-to-light transform: rows x, y, z (z along the light's view), origin at `eye`.
Mat4 lightFromWorld(Vec3 eye, Vec3 z) {
    z = normalize(z);
    const Vec3 up = std::fabs(z.y) < 0.9f ? Vec3{0, 1, 0} : Vec3{1, 0, 0};
    const Vec3 x = normalize(cross(up, z)), y = cross(z, x);
    Mat4 m;
    const Vec3 axes[3] = {x, y, z};
    for (int r = 0; r < 3; ++r) {
        m.m[r][0] = axes[r].x, m.m[r][1] = axes[r].y, m.m[r][2] = axes[r].z;
        m.m[r][3] = -double(dot(axes[r], eye));
    }
    return m;
}

// Texels kept free at a map's rim so that a lookup's filter box at the fitted edge stays on the map.
int rimTexels(const ShadowMapParams& p) {
    return int(std::ceil(0.5f * p.filterWidth)) + 1;
}

Camera squareCamera(int size, const Mat4& cameraFromWorld) {
    Camera c;
    c.width = c.height = size;
    c.cameraFromWorld = cameraFromWorld;
    return c;
}

// A perspective face whose field of view is 2 atan(tanHalf), widened by the rim texels.
Camera perspectiveFace(const ShadowMapParams& p, const Mat4& cameraFromWorld, float tanHalf,
                       float sceneSize) {
    Camera c = squareCamera(p.resolution, cameraFromWorld);
    const float widened = tanHalf * float(p.resolution) / float(std::max(1, p.resolution - 2 * rimTexels(p)));
    c.fovDegrees = 2.f * std::atan(widened) * 180.f / std::numbers::pi_v<float>;
    c.nearClip = 1e-5f * sceneSize;
    c.farClip = 1e30f;
    return c;
}

}  // namespace

DepthBuffer renderDepthMap(const Scene& scene, const Camera& lightCamera, float shadingRate,
                           const RenderSettings& settings, DepthPassStats& stats, const Textures* textures) {
    const auto t0 = EngineClock::now();
    const int width = lightCamera.width, height = lightCamera.height;
    // Bound: the patches in the light's space, shared edges welded (cracks would be light leaks).
    PatchArray patches = patchesInCameraSpace(scene, lightCamera.cameraFromWorld);
    weldSharedEdges(patches, defaultWeldTolerance(patches));
    const std::vector<PlacedQuadric> quadrics = quadricsInSpace(scene, lightCamera.cameraFromWorld);
    ReyesView view(lightCamera);
    view.patches = patches.data();
    view.quadrics = quadrics.data();
    // Displaced surfaces cast their displaced shadows (the light's space is rigid: no stretch).
    const DisplacementFrame displacement = makeDisplacementFrame(scene, textures, patches, 1.f);
    if (displacement.any()) view.displacement = &displacement;
    // Geometry nearer to a light than 1% of the scene's size is diced as if it were that far: texels are
    // tiny there, and edges passing beside the light would otherwise be diced at the rate cap.
    if (lightCamera.perspective) {
        const Bounds3 b = scene.worldBounds();
        view.lengthNearZ = b.empty() ? 0.f : 0.01f * length(b.diagonal());
    }
    view.maxGridEdge = std::max(1, settings.maxGridEdge);
    view.cullX0 = -1.f, view.cullY0 = -1.f, view.cullX1 = float(width + 1), view.cullY1 = float(height + 1);
    // Bin and split on demand, as the frame's pass does (no filter: a texel is one sample).
    const BucketLayout layout(Rect{0, 0, width, height}, 64);
    LazyPieces pieces(view, scene, shadingRate, layout, 1, 1, 1);
    DepthBuffer depth(size_t(width) * size_t(height));  // every bucket writes its texels below

    struct Worker {
        uint64_t grids = 0, micropolygons = 0, sampleTests = 0;
    };
    tbb::enumerable_thread_specific<Worker> workers;
    RenderSettings pass = settings;
    pass.progress = nullptr;  // the frame's progress counts the frame's buckets only
    const TileLoopResult loop = runTileLoop(layout, pieces.work(), pass, workers, [&](int b, Worker& w) {
        const Rect t = layout.target(b);
        for (int py = t.y0; py < t.y1; ++py)
            std::fill_n(&depth[size_t(py) * width + t.x0], t.x1 - t.x0, kInf);
        auto dice = [&](const Piece& piece, Grid& g) {
            const PatchAttributes& attr = scene.attributes[piece.patch];
            ShadeInputs in{attr.kind,  &scene.materials[attr.material], true, attr.flipNormal, {},
                           attr.object};
            in.depthOnly = true;
            in.quadric = quadricOf(view, attr);
            diceAndShade(view, piece, in, g);
            ++w.grids;
            w.micropolygons += uint64_t(g.nu) * g.nv;
        };
        // One sample at each texel's centre (where the lookups read the depth), written into the map.
        pieces.forEach(b, dice, [&](const Piece&, const Grid& grid) {
            w.sampleTests += rasterizeGridDepth(grid, t, depth.data(), width, view.projector.nearClip);
        });
    });
    // A cancelled loop skips buckets: their texels were never written.
    if (loop.cancelled) std::fill(depth.begin(), depth.end(), kInf);
    stats.pieces = pieces.pieceCount();
    for (const Worker& w : workers) {
        stats.grids += w.grids;
        stats.micropolygons += w.micropolygons;
        stats.sampleTests += w.sampleTests;
    }
    stats.ms = msSince(t0);
    return depth;
}

namespace {

// A cached depth map: "TSHM", version, width, height, then width * height floats (host byte order: the
// cache is for the machines of one farm).
constexpr char kCacheMagic[4] = {'T', 'S', 'H', 'M'};
constexpr uint32_t kCacheVersion = 1;

std::filesystem::path cacheFile(const std::string& dir, uint64_t key) {
    char name[40];
    std::snprintf(name, sizeof name, "shadow-%016llx.tsm", static_cast<unsigned long long>(key));
    return std::filesystem::path(dir) / name;
}

// The map of `key` if the folder has a whole one of that size; nullopt otherwise (a miss).
std::optional<DepthBuffer> readCachedMap(const std::filesystem::path& file, int width, int height) {
    std::ifstream f(file, std::ios::binary);
    if (!f) return std::nullopt;
    char magic[4];
    uint32_t version = 0;
    int32_t w = 0, h = 0;
    f.read(magic, 4);
    f.read(reinterpret_cast<char*>(&version), 4);
    f.read(reinterpret_cast<char*>(&w), 4);
    f.read(reinterpret_cast<char*>(&h), 4);
    if (!f || std::memcmp(magic, kCacheMagic, 4) != 0 || version != kCacheVersion || w != width ||
        h != height)
        return std::nullopt;
    DepthBuffer depth(size_t(w) * size_t(h));
    f.read(reinterpret_cast<char*>(depth.data()), std::streamsize(depth.size() * sizeof(float)));
    if (!f || f.peek() != std::char_traits<char>::eof()) return std::nullopt;
    return depth;
}

// Written to a temporary name and renamed: concurrent tiles writing the same map leave one whole file.
bool writeCachedMap(const std::filesystem::path& file, std::span<const float> depth, int width, int height) {
    std::error_code ec;
    std::filesystem::create_directories(file.parent_path(), ec);
    std::string tmpName(1, '.');  // appended piecewise: "." + string trips g++ 12's -Wrestrict
    tmpName.append(file.filename().string()).append(".tmp").append(std::to_string(getpid()));
    tmpName.append("-").append(std::to_string(std::hash<std::thread::id>{}(std::this_thread::get_id())));
    const std::filesystem::path tmp = file.parent_path() / tmpName;
    {
        std::ofstream f(tmp, std::ios::binary);
        const int32_t w = width, h = height;
        f.write(kCacheMagic, 4);
        f.write(reinterpret_cast<const char*>(&kCacheVersion), 4);
        f.write(reinterpret_cast<const char*>(&w), 4);
        f.write(reinterpret_cast<const char*>(&h), 4);
        f.write(reinterpret_cast<const char*>(depth.data()), std::streamsize(depth.size() * sizeof(float)));
        f.close();
        if (!f) {
            std::filesystem::remove(tmp, ec);
            return false;
        }
    }
    std::filesystem::rename(tmp, file, ec);
    if (ec) std::filesystem::remove(tmp, ec);
    return !ec;
}

// What a depth pass depends on besides the light's view: the app's key (scene file and options) and the
// surfaces themselves (archives and procedural input included), at shutter open.
uint64_t sceneCacheKey(const Scene& scene, const RenderSettings& settings) {
    Fnv1a64 h;
    h.bytes(settings.shadowMapCacheKey.data(), settings.shadowMapCacheKey.size());
    static_assert(sizeof(BezierPatch) == 16 * 3 * sizeof(float));  // no padding to hash
    h.bytes(scene.patches.data(), scene.patches.size() * sizeof(BezierPatch));
    for (const SceneQuadric& sq : scene.quadrics) {  // field by field: Quadric has padding
        const Quadric& q = sq.q;
        h.value(q.kind), h.value(q.radius), h.value(q.minorRadius), h.value(q.zMin), h.value(q.zMax);
        h.value(q.height), h.value(q.angle0), h.value(q.angle1), h.value(q.point1), h.value(q.point2);
        h.value(q.thetaMax), h.value(q.closedU), h.value(q.closedV), h.value(sq.worldFromObject);
    }
    for (const PatchAttributes& a : scene.attributes) h.value(a.displacement), h.value(a.displacementBound);
    for (const DisplacementShader& d : scene.displacements)
        h.value(d.type), h.value(d.Km), h.value(d.texture);
    h.value(scene.camera.shutterOpen);
    h.value(settings.maxGridEdge);
    return h.h;
}

uint64_t faceCacheKey(uint64_t sceneKey, const Camera& c, float shadingRate) {
    Fnv1a64 h;
    h.value(sceneKey);
    const Projector pr(c);
    h.value(c.cameraFromWorld);
    h.value(c.width), h.value(c.height), h.value(pr.perspective);
    h.value(pr.sx), h.value(pr.sy), h.value(pr.ox), h.value(pr.oy), h.value(pr.nearClip), h.value(pr.farClip);
    h.value(shadingRate);
    return h.h;
}

}  // namespace

ShadowMaps::ShadowMaps(const Scene& scene, const RenderSettings& settings, const Camera& shadingCamera,
                       std::span<const ShadingLight> lights, const Textures* textures,
                       const LightVisibility* rays)
    : rays_(rays), cacheDir_(settings.shadowMapCacheDir) {
    const auto t0 = EngineClock::now();
    const uint64_t sceneKey = cacheDir_.empty() ? 0 : sceneCacheKey(scene, settings);
    const Mat4 worldFromShading = shadingCamera.cameraFromWorld.inverse();
    const Bounds3 bounds = scene.worldBounds();
    const float sceneSize = bounds.empty() ? 1.f : std::max(length(bounds.diagonal()), 1e-6f);
    maps_.resize(lights.size());
    for (size_t l = 0; l < lights.size() && l < scene.lights.size(); ++l) {
        if (!lights[l].castsShadows || lights[l].tracedShadows || bounds.empty()) continue;
        const Light& light = scene.lights[l];
        if (light.type == LightType::Area) continue;  // ray traced only (rt/area_lights.h)
        auto map = std::make_unique<Map>();
        map->type = light.type;
        map->params = light.shadowMap;
        ShadowMapParams& p = map->params;
        std::vector<Camera> faces;
        const Vec3 dir = normalize(light.to - light.from);
        const bool cube = light.type == LightType::Point ||
                          (light.type == LightType::Spot && light.coneAngle > kMaxSpotMapHalfAngle);
        p.resolution = p.resolution > 0 ? std::clamp(p.resolution, 8, 16384) : cube ? 1024 : 2048;
        p.filterWidth = std::clamp(p.filterWidth, 1.f, 64.f);  // the RIB's ranges
        p.bias = std::max(p.bias, 0.f);
        p.shadingRate = std::max(p.shadingRate, 0.01f);
        if (light.type == LightType::Distant) {
            // Orthographic, along the light, fitted to the scene's bound: the bound's corners in a frame
            // looking along the light give the window (square texels) and the depth range.
            const Mat4 rot = lightFromWorld({0, 0, 0}, dir);
            Bounds3 lb;
            for (int c = 0; c < 8; ++c)
                lb.extend(rot.point({c & 1 ? bounds.hi.x : bounds.lo.x, c & 2 ? bounds.hi.y : bounds.lo.y,
                                     c & 4 ? bounds.hi.z : bounds.lo.z}));
            const float extent = std::max({lb.hi.x - lb.lo.x, lb.hi.y - lb.lo.y, 1e-6f * sceneSize});
            const float texel = extent / float(std::max(1, p.resolution - 2 * rimTexels(p)));
            const float half = 0.5f * texel * float(p.resolution);
            const float margin = 0.01f * (lb.hi.z - lb.lo.z) + texel;
            // The eye on the light's side of the bound, so that every depth is positive.
            const Vec3 centre{0.5f * (lb.lo.x + lb.hi.x), 0.5f * (lb.lo.y + lb.hi.y), lb.lo.z - margin};
            Mat4 toLight = Mat4::translate(-centre.x, -centre.y, -centre.z) * rot;
            Camera c = squareCamera(p.resolution, toLight);
            c.perspective = false;
            c.hasScreenWindow = true;
            c.screenWindow[0] = c.screenWindow[2] = -half;
            c.screenWindow[1] = c.screenWindow[3] = half;
            c.nearClip = 0.5f * margin;
            c.farClip = (lb.hi.z - lb.lo.z) + 2.f * margin;
            faces.push_back(c);
            map->texelWorld = texel;
        } else if (!cube) {
            // Spot: one perspective map around the cone.
            faces.push_back(
                perspectiveFace(p, lightFromWorld(light.from, dir), std::tan(light.coneAngle), sceneSize));
        } else {
            // Cube map: six 90-degree faces along the world axes from the light (cubeFaceOf's order).
            const Vec3 axes[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
            for (const Vec3& a : axes)
                faces.push_back(perspectiveFace(p, lightFromWorld(light.from, a), 1.f, sceneSize));
            map->lookup.cubeFromShading = affineFrameOf(
                Mat4::translate(-light.from.x, -light.from.y, -light.from.z) * worldFromShading);
        }
        for (const Camera& c : faces) {
            DepthPassStats st;
            std::optional<DepthBuffer> cached;
            std::filesystem::path file;
            if (!cacheDir_.empty()) {
                file = cacheFile(cacheDir_, faceCacheKey(sceneKey, c, p.shadingRate));
                cached = readCachedMap(file, c.width, c.height);
                ++(cached ? cacheHits_ : cacheMisses_);
            }
            if (cached) {
                map->depth.push_back(std::move(*cached));
            } else {
                map->depth.push_back(renderDepthMap(scene, c, p.shadingRate, settings, st, textures));
                if (!file.empty() && !writeCachedMap(file, map->depth.back(), c.width, c.height))
                    ++cacheWriteFailures_;
            }
            map->stats.pieces += st.pieces, map->stats.grids += st.grids;
            map->stats.micropolygons += st.micropolygons, map->stats.sampleTests += st.sampleTests;
            map->stats.ms += st.ms;
            const Projector pr(c);
            ShadowMapFace f;
            f.lightFromShading = affineFrameOf(c.cameraFromWorld * worldFromShading);
            f.perspective = c.perspective;
            f.sx = pr.sx, f.sy = pr.sy, f.ox = pr.ox, f.oy = pr.oy;
            f.width = f.height = c.width;
            map->faces.push_back(f);
        }
        for (size_t f = 0; f < map->faces.size(); ++f) map->faces[f].depth = map->depth[f].data();
        map->lookup.faces = map->faces.data();
        map->lookup.faceCount = int(map->faces.size());
        map->lookup.bias = p.bias;
        map->lookup.filterWidth = p.filterWidth;
        maps_[l] = std::move(map);
    }
    renderMs_ = msSince(t0);
}

const ShadowMapLookup* ShadowMaps::lookup(size_t light) const {
    return light < maps_.size() && maps_[light] ? &maps_[light]->lookup : nullptr;
}

float ShadowMaps::visibility(size_t light, Vec3 P, Vec3 N) const {
    const ShadowMapLookup* m = lookup(light);
    return m ? shadowMapVisibility(*m, P, N) : 1.f;
}

void ShadowMaps::answer(const VisibilityQuery& q, LightSamples& ls) const {
    uint64_t n = 0;
    bool traced = false;
    for (size_t k = 0; k < q.points.count; ++k)
        for (size_t l = 0; l < ls.lights; ++l) {
            const size_t s = ls.index(k, l);
            if (!ls.needsVisibility[s]) continue;
            const ShadowMapLookup* m = lookup(l);
            if (!m) {
                traced = true;
                continue;
            }
            ls.visibility[s] = shadowMapVisibility(*m, q.points.P[k], q.points.N[k]);
            ls.needsVisibility[s] = 0;  // answered: the rays below skip it
            ++n;
        }
    lookups_.fetch_add(n, std::memory_order_relaxed);
    if (traced && rays_) rays_->answer(q, ls);
}

void ShadowMaps::writeStats(nlohmann::json& s) const {
    static const char* kTypes[] = {"ambient", "distant", "point", "spot", "area"};
    if (rays_) rays_->writeStats(s);  // the lights whose shadows are ray traced
    s["method"] = rays_ ? "map+raytrace" : "map";
    s["maps_ms"] = renderMs_;
    s["lookups"] = lookups_.load();
    if (!cacheDir_.empty())
        s["cache"] = {{"dir", cacheDir_},
                      {"hits", cacheHits_},
                      {"misses", cacheMisses_},
                      {"write_failures", cacheWriteFailures_}};
    nlohmann::json maps = nlohmann::json::array();
    for (size_t l = 0; l < maps_.size(); ++l) {
        if (!maps_[l]) continue;
        const Map& m = *maps_[l];
        nlohmann::json j = {{"light", l},
                            {"type", kTypes[int(m.type)]},
                            {"faces", m.faces.size()},
                            {"resolution", m.params.resolution},
                            {"shading_rate", m.params.shadingRate},
                            {"bias", m.params.bias},
                            {"filter_width", m.params.filterWidth},
                            {"pieces", m.stats.pieces},
                            {"grids", m.stats.grids},
                            {"micropolygons", m.stats.micropolygons},
                            {"sample_tests", m.stats.sampleTests},
                            {"ms", m.stats.ms}};
        if (m.texelWorld > 0) j["texel_size"] = m.texelWorld;
        maps.push_back(j);
    }
    s["maps"] = maps;
}

}  // namespace tessera
