// The frame's motion in camera space, prepared once per render for both engines: the shutter timeline
// (normalised shutter time u in [0,1], the camera sample's time dimension) and, for every patch that moves
// in camera space (its own keys or a moving camera), its camera-space control points at each knot of the
// timeline. Between knots the control points move linearly (the scene's motion model, scene/scene.h), so
// Reyes can move grid vertices linearly per segment and the ray tracer interpolates the patch at a ray's
// time, and the two see the same surface at every time.
#pragma once
#include <cstdint>
#include <vector>

#include "core/bezier.h"
#include "scene/scene.h"

namespace tessera {

// Segment of the timeline knots[0 .. count) holding normalised time u: position = lerp(knot k, knot k + 1,
// w), clamped to the first and last knot. One knot (a static timeline, or a grid that does not move) gives
// k = 0, w = 0.
inline void timelineSegment(const float* knots, int count, float u, int& k, float& w) {
    const int last = count - 1;
    if (last <= 0 || u <= 0.f) {
        k = 0, w = 0.f;
        return;
    }
    if (u >= 1.f) {
        k = last - 1, w = 1.f;
        return;
    }
    if (last == 1) {  // knots 0 and 1: w = u
        k = 0, w = u;
        return;
    }
    k = 0;
    while (k + 1 < last && knots[k + 1] <= u) ++k;
    w = (u - knots[k]) / (knots[k + 1] - knots[k]);
}

struct FrameMotion {
    static constexpr uint32_t kStatic = 0xffffffffu;
    std::vector<float> knots{0.f};   // increasing normalised shutter times; knots[0] = 0; one knot: no motion
    std::vector<uint32_t> firstKey;  // per patch: index into `keys` of its first knot, or kStatic
    std::vector<BezierPatch> keys;   // camera space, knots.size() per moving patch

    int knotCount() const { return int(knots.size()); }
    bool blurred() const { return knots.size() > 1; }
    bool moving(size_t patch) const { return !firstKey.empty() && firstKey[patch] != kStatic; }
    // The camera-space patch at each knot (knotCount() of them); only for moving patches.
    const BezierPatch* patchKeys(size_t patch) const { return &keys[firstKey[patch]]; }
    // Segment of the timeline holding normalised time u (timelineSegment).
    void segment(float u, int& k, float& w) const { timelineSegment(knots.data(), knotCount(), u, k, w); }
    // Camera-space control points of a moving patch at normalised time u.
    BezierPatch patchAt(size_t patch, float u) const;
};

// `blur` false (--no-blur) or a shutter of zero length: everything at shutter open, one knot. Knot 0 of
// a moving patch is its shutter-open position, i.e. Scene::patches in camera space.
FrameMotion prepareFrameMotion(const Scene& scene, const Camera& camera, bool blur);

}  // namespace tessera
