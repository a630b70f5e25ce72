#include "scene/scene.h"

#include <cmath>

namespace tessera {

Bounds3 Scene::worldBounds() const {
    Bounds3 b;
    for (const BezierPatch& p : patches) b.extend(hullBounds(p));
    return b;
}

void frameSceneDefault(Scene& scene, int width, int height, UpAxis upAxis) {
    Bounds3 b = scene.worldBounds();
    if (b.empty()) b = Bounds3{{-1, -1, -1}, {1, 1, 1}};
    Vec3 c = b.center();
    float radius = 0.5f * length(b.diagonal());
    if (!(radius > 0)) radius = 1;
    Camera& cam = scene.camera;
    cam.width = width;
    cam.height = height;
    cam.fovDegrees = 30.f;
    // Viewing direction: towards the model's front from the right and above.
    const bool zUp = upAxis == UpAxis::Z;
    Vec3 dir = zUp ? normalize(Vec3{-0.55f, 0.75f, -0.38f}) : normalize(Vec3{-0.45f, -0.3f, -0.84f});
    // The bounding sphere of the box is conservative (about 1.3x for typical models): pull in a little.
    float dist = radius / std::sin(0.5f * cam.fovDegrees * 3.14159265f / 180.f) * 0.85f;
    Vec3 eye = c - dir * dist;
    Vec3 up = zUp ? Vec3{0, 0, 1} : Vec3{0, 1, 0};
    Vec3 zc = dir;                          // camera +z: into the screen
    // Right-handed world to left-handed camera: right = forward x up, up = right x forward.
    Vec3 xc = normalize(cross(zc, up));
    Vec3 yc = cross(xc, zc);
    Mat4 m;
    const Vec3 axes[3] = {xc, yc, zc};
    for (int r = 0; r < 3; ++r) {
        m.m[r][0] = axes[r].x;
        m.m[r][1] = axes[r].y;
        m.m[r][2] = axes[r].z;
        m.m[r][3] = -dot(axes[r], eye);
    }
    cam.cameraFromWorld = m;
    cam.nearClip = dist * 1e-3f;
    cam.farClip = dist * 100.f;
    scene.image.srgbOutput = true;
    scene.lights.clear();
    scene.lights.push_back({LightType::Ambient, {0.08f, 0.08f, 0.08f}, {}, {}});
    scene.lights.push_back({LightType::Distant, {0.9f, 0.88f, 0.85f}, eye + xc * dist * -0.6f + yc * dist * 0.8f, c});
    scene.lights.push_back({LightType::Distant, {0.25f, 0.27f, 0.3f}, eye + xc * dist, c});
}

}  // namespace tessera
