#include "engine/motion.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace tessera {

BezierPatch FrameMotion::patchAt(size_t patch, float u) const {
    const BezierPatch* k = patchKeys(patch);
    int s;
    float w;
    segment(u, s, w);
    if (knotCount() == 1) return k[0];
    BezierPatch r;
    for (int c = 0; c < 16; ++c) r.cp[c] = lerp(k[s].cp[c], k[s + 1].cp[c], w);
    return r;
}

FrameMotion prepareFrameMotion(const Scene& scene, const Camera& camera, bool blur) {
    FrameMotion fm;
    if (!blur || !camera.hasShutter()) return fm;
    const double open = camera.shutterOpen, span = camera.shutterClose - camera.shutterOpen;
    // Knots: the shutter's ends and every key time inside it (patches and camera).
    std::vector<float> knots{0.f, 1.f};
    auto addTime = [&](double t) {
        const double u = (t - open) / span;
        if (u > 0 && u < 1) knots.push_back(float(u));
    };
    bool anyMoving = camera.moving();
    if (camera.moving())
        for (const TransformKey& k : camera.motion) addTime(k.time);
    for (const PatchAttributes& a : scene.attributes)
        if (a.motion.moving()) {
            anyMoving = true;
            for (uint32_t k = 0; k < a.motion.count; ++k) addTime(scene.motionTimes[a.motion.first + k]);
        }
    if (!anyMoving) return fm;
    std::sort(knots.begin(), knots.end());
    knots.erase(std::unique(knots.begin(), knots.end()), knots.end());
    fm.knots = knots;
    const size_t n = scene.patches.size(), K = knots.size();
    fm.firstKey.assign(n, FrameMotion::kStatic);
    uint32_t next = 0;
    for (size_t i = 0; i < n; ++i)
        // Quadrics do not move (docs/inputs.md): not even with the camera; they are seen from shutter open.
        if (!isQuadric(scene.attributes[i].kind) &&
            (camera.moving() || scene.attributes[i].motion.moving())) {
            fm.firstKey[i] = next;
            next += uint32_t(K);
        }
    fm.keys.resize(next);
    std::vector<Mat4> cameraAt(K);
    for (size_t k = 0; k < K; ++k) cameraAt[k] = camera.cameraFromWorldAt(open + span * knots[k]);
    tbb::parallel_for(size_t(0), n, [&](size_t i) {
        if (fm.firstKey[i] == FrameMotion::kStatic) return;
        for (size_t k = 0; k < K; ++k) {
            const BezierPatch world = patchAtTime(scene, i, float(open + span * knots[k]));
            BezierPatch& out = fm.keys[fm.firstKey[i] + k];
            for (int c = 0; c < 16; ++c) out.cp[c] = cameraAt[k].point(world.cp[c]);
        }
    });
    return fm;
}

}  // namespace tessera
