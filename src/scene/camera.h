// Camera and image options following the RenderMan camera model (RI spec 3.2, ch. 4):
// camera space is left-handed, +x right, +y up, +z into the screen; a perspective projection maps
// the screen window onto the raster.
#pragma once
#include "core/transform.h"

namespace tessera {

struct Camera {
    int width = 640, height = 480;  // Format xres yres
    float pixelAspect = 1.f;
    bool perspective = true;
    float fovDegrees = 90.f;  // Projection "perspective" "fov": the full angle of the shorter screen axis
    bool hasScreenWindow = false;
    float screenWindow[4] = {-1, 1, -1, 1};  // left right bottom top
    float frameAspect = 0.f;                 // FrameAspectRatio, 0 = from the resolution
    float nearClip = 1e-4f, farClip = 1e30f;
    Mat4 cameraFromWorld;  // the CTM at WorldBegin

    float aspect() const { return frameAspect > 0 ? frameAspect : width * pixelAspect / height; }
    // Screen window, the default derived from the frame aspect ratio as the spec prescribes.
    void window(float& l, float& r, float& b, float& t) const;
};

// Everything needed to project camera-space points to raster space, precomputed.
struct Projector {
    float sx, sy, ox, oy;  // raster = (x/z * sx + ox, -y/z * sy + oy) for perspective
    bool perspective;
    float nearClip, farClip;
    explicit Projector(const Camera& c);
    // Raster position of a camera-space point (caller guarantees z > 0 for perspective).
    Vec3 toRaster(Vec3 p) const {
        float iz = perspective ? 1.f / p.z : 1.f;
        return {p.x * iz * sx + ox, p.y * iz * sy + oy, p.z};
    }
};

}  // namespace tessera
