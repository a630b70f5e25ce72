#include "scene/camera.h"

#include <cmath>
#include <numbers>

namespace tessera {

void Camera::window(float& l, float& r, float& b, float& t) const {
    if (hasScreenWindow) {
        l = screenWindow[0];
        r = screenWindow[1];
        b = screenWindow[2];
        t = screenWindow[3];
        return;
    }
    // RI spec: the shorter axis spans [-1, 1].
    float a = aspect();
    if (a >= 1) {
        l = -a, r = a, b = -1, t = 1;
    } else {
        l = -1, r = 1, b = -1 / a, t = 1 / a;
    }
}

Projector::Projector(const Camera& c) {
    float l, r, b, t;
    c.window(l, r, b, t);
    perspective = c.perspective;
    // Perspective: screen = (x, y) / (z * tan(fov/2)).
    float k = perspective ? 1.f / std::tan(0.5f * c.fovDegrees * std::numbers::pi_v<float> / 180.f) : 1.f;
    // raster_x = (screen_x - l) / (r - l) * width ; raster_y = (t - screen_y) / (t - b) * height
    sx = k * c.width / (r - l);
    ox = -l * c.width / (r - l);
    sy = -k * c.height / (t - b);
    oy = t * c.height / (t - b);
    nearClip = c.nearClip;
    farClip = c.farClip;
    lensRadius = c.lensRadius();
    focalDistance = c.focalDistance;
    if (!(focalDistance > 0.f)) lensRadius = 0.f;  // a lens needs a focal plane in front of the eye
}

}  // namespace tessera
