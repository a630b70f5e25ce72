#include "scene/scene.h"

#include <algorithm>
#include <cmath>

namespace tessera {

Bounds3 Scene::worldBounds() const {
    Bounds3 b;
    for (const BezierPatch& p : patches) b.extend(hullBounds(p));
    return b;
}

namespace {

Bounds3 controlPointBounds(const std::vector<BezierPatch>& patches) {
    Bounds3 b;
    for (const BezierPatch& p : patches)
        for (const Vec3& q : p.cp) b.extend(q);
    return b;
}

// World directions (right, up, towards the viewer) for each up axis; right x up = towards, so the frame is
// right-handed like the world.
void viewFrame(UpAxis up, Vec3& right, Vec3& upDir, Vec3& towards) {
    switch (up) {
        case UpAxis::X:
            right = {0, 1, 0}, upDir = {1, 0, 0}, towards = {0, 0, -1};
            break;
        case UpAxis::Y:
            right = {1, 0, 0}, upDir = {0, 1, 0}, towards = {0, 0, 1};
            break;
        case UpAxis::Z:
            right = {1, 0, 0}, upDir = {0, 0, 1}, towards = {0, -1, 0};
            break;
    }
}

}  // namespace

const char* upAxisName(UpAxis up) {
    switch (up) {
        case UpAxis::X:
            return "x";
        case UpAxis::Y:
            return "y";
        case UpAxis::Z:
            return "z";
    }
    return "z";
}

UpAxis chooseUpAxis(const std::vector<BezierPatch>& patches) {
    Bounds3 b = controlPointBounds(patches);
    if (b.empty()) return UpAxis::Z;
    const Vec3 d = b.diagonal();
    const float size = maxComponent(d);
    if (!(size > 0) || !std::isfinite(size)) return UpAxis::Z;
    // Standing on the ground plane: starts at 0 (within 1% of the model's size) along this axis, and
    // reaches both sides of 0 along the other two (the model sits over the origin).
    const float tol = 0.01f * size;
    auto straddles = [&](int a) { return b.lo[a] < -tol && b.hi[a] > tol; };
    int standing = -1, count = 0;
    for (int a = 0; a < 3; ++a)
        if (std::fabs(b.lo[a]) <= tol && d[a] > tol && straddles((a + 1) % 3) && straddles((a + 2) % 3)) {
            standing = a;
            ++count;
        }
    if (count == 1) return standing == 0 ? UpAxis::X : (standing == 1 ? UpAxis::Y : UpAxis::Z);
    return d.y >= d.x && d.y >= d.z ? UpAxis::Y : UpAxis::Z;
}

void defaultFramingSphere(const Scene& scene, Vec3& centre, float& radius) {
    Bounds3 b = controlPointBounds(scene.patches);
    if (b.empty()) b = Bounds3{{-1, -1, -1}, {1, 1, 1}};
    centre = b.center();
    radius = 0;
    for (const BezierPatch& p : scene.patches)
        for (const Vec3& q : p.cp) radius = std::max(radius, length(q - centre));
    if (!(radius > 0) || !std::isfinite(radius)) radius = 1;
}

void frameSceneDefault(Scene& scene, int width, int height, UpAxis upAxis) {
    Vec3 c;
    float radius = 1;
    defaultFramingSphere(scene, c, radius);
    Camera& cam = scene.camera;
    cam.width = width;
    cam.height = height;
    cam.fovDegrees = 30.f;
    cam.hasScreenWindow = false;
    cam.frameAspect = 0;
    cam.perspective = true;
    // The eye: front-right of the model and 25 degrees above it.
    Vec3 right, up, towards;
    viewFrame(upAxis, right, up, towards);
    const Vec3 offset = normalize(right * 0.53f + towards * 0.82f + up * 0.4f);
    // The sphere is inside the view cone when sin(half angle) >= radius / distance. The cone of the half
    // field of view of the shorter image axis lies inside the frame; 5% of that angle is left as margin.
    const float halfFov = 0.5f * cam.fovDegrees * 3.14159265f / 180.f;
    const float dist = radius / std::sin(0.95f * halfFov);
    const Vec3 eye = c + offset * dist;
    const Vec3 zc = -offset;  // camera +z: into the screen
    // Right-handed world to left-handed camera: right = forward x up, up = right x forward.
    const Vec3 xc = normalize(cross(zc, up));
    const Vec3 yc = cross(xc, zc);
    Mat4 m;
    const Vec3 axes[3] = {xc, yc, zc};
    for (int r = 0; r < 3; ++r) {
        m.m[r][0] = axes[r].x;
        m.m[r][1] = axes[r].y;
        m.m[r][2] = axes[r].z;
        m.m[r][3] = -dot(axes[r], eye);
    }
    cam.cameraFromWorld = m;
    cam.nearClip = std::max(dist - radius, dist * 1e-3f) * 0.5f;
    cam.farClip = (dist + radius) * 2.f;
    scene.image.srgbOutput = true;
    scene.lights.clear();
    scene.lights.push_back({LightType::Ambient, {0.08f, 0.08f, 0.08f}, {}, {}});
    scene.lights.push_back(
        {LightType::Distant, {0.9f, 0.88f, 0.85f}, eye + xc * dist * -0.6f + yc * dist * 0.8f, c});
    scene.lights.push_back({LightType::Distant, {0.25f, 0.27f, 0.3f}, eye + xc * dist, c});
    // Both distant lights cast shadows: what the ray tracer always did for these inputs (docs/inputs.md).
    for (Light& l : scene.lights) l.castsShadows = l.type != LightType::Ambient;
}

}  // namespace tessera

namespace tessera {

bool Scene::hasMotion() const {
    if (!camera.hasShutter()) return false;
    if (camera.moving()) return true;
    for (const PatchAttributes& a : attributes)
        if (a.motion.moving()) return true;
    return false;
}

BezierPatch patchAtTime(const Scene& scene, size_t i, float time) {
    const MotionKeys& m = scene.attributes[i].motion;
    if (!m.moving()) return scene.patches[i];
    const float* t = &scene.motionTimes[m.first];
    const BezierPatch* k = &scene.motionPatches[m.first];
    if (time <= t[0]) return k[0];
    if (time >= t[m.count - 1]) return k[m.count - 1];
    uint32_t s = 1;
    while (t[s] < time) ++s;
    const float w = (time - t[s - 1]) / (t[s] - t[s - 1]);
    BezierPatch r;
    for (int c = 0; c < 16; ++c) r.cp[c] = lerp(k[s - 1].cp[c], k[s].cp[c], w);
    return r;
}

}  // namespace tessera

namespace tessera {

const char* surfaceKindName(SurfaceKind k) {
    static const char* const kNames[kSurfaceKinds] = {"bicubic", "sphere",     "cylinder",    "cone",
                                                      "disk",    "paraboloid", "hyperboloid", "torus"};
    return kNames[uint8_t(k)];
}

std::array<size_t, kSurfaceKinds> surfaceKindCounts(const Scene& scene) {
    std::array<size_t, kSurfaceKinds> count{};
    for (const PatchAttributes& a : scene.attributes) ++count[uint8_t(a.kind)];
    return count;
}

PlacedQuadric placeQuadric(const SceneQuadric& sq, const Mat4& toSpace) {
    const Mat4 m = toSpace * sq.worldFromObject, inv = m.inverse();
    PlacedQuadric pq;
    pq.q = sq.q;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 4; ++c)
            pq.toSpace.m[r][c] = float(m.m[r][c]), pq.fromSpace.m[r][c] = float(inv.m[r][c]);
    return pq;
}

std::vector<PatchVertexValues> vertexValuesInSpace(const Scene& scene, const Mat4& toSpace) {
    std::vector<PatchVertexValues> out = scene.vertexValues;
    if (out.empty()) return out;
    const Mat4 inv = toSpace.inverse();
    for (PatchVertexValues& vv : out)
        if (vv.hasN)
            for (Vec3& n : vv.N) n = Mat4::normalWithInverse(inv, n);
    return out;
}

void quadricHullCorners(const PlacedQuadric& pq, float u0, float u1, float v0, float v1, Vec3 corners[8]) {
    const Bounds3 b = quadricBounds(pq.q, u0, u1, v0, v1);
    for (int k = 0; k < 8; ++k)
        corners[k] = affinePoint(pq.toSpace,
                                 {k & 1 ? b.hi.x : b.lo.x, k & 2 ? b.hi.y : b.lo.y, k & 4 ? b.hi.z : b.lo.z});
}

SurfacePoint evalPlacedQuadric(const PlacedQuadric& pq, float u, float v, Vec3* normal) {
    const SurfacePoint o = evalQuadric(pq.q, u, v);
    SurfacePoint s;
    s.p = affinePoint(pq.toSpace, o.p);
    s.dpdu = affineVector(pq.toSpace, o.dpdu);
    s.dpdv = affineVector(pq.toSpace, o.dpdv);
    if (normal) {
        // Normals map with the inverse transpose; the result keeps dP/du x dP/dv's side (for a map with
        // negative determinant too, as for the Bezier patches, whose N is the cross product in this space).
        const Vec3 n = quadricNormal(pq.q, u, v);
        const Affine3& f = pq.fromSpace;
        Vec3 w{f.m[0][0] * n.x + f.m[1][0] * n.y + f.m[2][0] * n.z,
               f.m[0][1] * n.x + f.m[1][1] * n.y + f.m[2][1] * n.z,
               f.m[0][2] * n.x + f.m[1][2] * n.y + f.m[2][2] * n.z};
        const float det = dot(cross(affineVector(pq.toSpace, {1, 0, 0}), affineVector(pq.toSpace, {0, 1, 0})),
                              affineVector(pq.toSpace, {0, 0, 1}));
        if (det < 0.f) w = -w;
        *normal = normalize(w);
    }
    return s;
}

void setShutter(Scene& scene, float open, float close) {
    scene.camera.shutterOpen = open;
    scene.camera.shutterClose = close;
    for (size_t i = 0; i < scene.patches.size(); ++i)
        if (scene.attributes[i].motion.moving()) scene.patches[i] = patchAtTime(scene, i, open);
    if (scene.camera.motion.size() > 1) scene.camera.cameraFromWorld = transformAt(scene.camera.motion, open);
}

MotionSummary motionSummary(const Scene& scene) {
    MotionSummary m;
    for (const PatchAttributes& a : scene.attributes)
        if (a.motion.moving()) {
            ++m.movingPatches;
            m.patchKeys += a.motion.count;
        }
    m.cameraKeys = scene.camera.motion.size() > 1 ? scene.camera.motion.size() : 0;
    return m;
}

}  // namespace tessera
