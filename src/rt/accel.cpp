#include "rt/accel.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>

namespace tessera {
namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

}  // namespace

void patchAtTime(const RtAccel& acc, uint32_t patch, float u, BezierPatch& out) {
    out = acc.motion.patchAt(patch, u);
}

Vec3 orientedGeometricNormal(const RtAccel& acc, uint32_t patch, const PatchHit& h) {
    Vec3 N;
    if (const PlacedQuadric* pq = acc.quadric(patch))
        evalPlacedQuadric(*pq, h.u, h.v, &N);
    else
        N = cross(h.dpdu, h.dpdv);
    return acc.flip[patch] ? -N : N;
}

Vec3 hitNormal(const RtAccel& acc, uint32_t patch, const PatchHit& h, float time) {
    if (dot(h.ns, h.ns) > 0.f) return h.ns;  // a displaced micro-grid's interpolated normal (oriented)
    if (const PlacedQuadric* pq = acc.quadric(patch)) {
        Vec3 N;
        evalPlacedQuadric(*pq, h.u, h.v, &N);  // the same closed form as Reyes' dicer
        if (!isFinite(N) || dot(N, N) == 0.f) N = Vec3{0, 0, 1};
        return acc.flip[patch] ? -N : N;
    }
    Vec3 N = cross(h.dpdu, h.dpdv);
    const float scale = dot(h.dpdu, h.dpdu) + dot(h.dpdv, h.dpdv);
    if (!(dot(N, N) > 1e-12f * scale * scale))
        N = acc.moving(patch) ? patchNormal(acc.motion.patchAt(patch, time), h.u, h.v)
                              : patchNormal(acc.patches[patch], h.u, h.v);
    N = normalize(N);
    if (!isFinite(N) || dot(N, N) == 0.f) N = Vec3{0, 0, 1};
    if (acc.flip[patch]) N = -N;
    // User normals (polygons' "N") shade, turned to the geometric side (as Reyes' dicer).
    if (const PatchVertexValues* vv = acc.vertexValuesAt(patch); vv && vv->hasN)
        N = vertexNormalAt(*vv, h.u, h.v, N);
    return N;
}

namespace {
// The 4-wide BVH over patches 0 .. n-1 with boxes patchBox(i); patches with a non-finite box (possible in
// scenes built in code; the loaders reject them) are left out, so no ray ever reaches them. `all`, when
// given, gets the union of the boxes.
template <class PatchBox>
void buildPatchBvh(size_t n, PatchBox&& patchBox, Bvh& bvh, Bounds3* all) {
    std::vector<Bounds3> roots, boxes(n);
    std::vector<uint32_t> ids;
    for (size_t i = 0; i < n; ++i) {
        const Bounds3& b = boxes[i] = patchBox(uint32_t(i));
        if (!isFinite(b.lo) || !isFinite(b.hi)) continue;
        roots.push_back(b);
        ids.push_back(uint32_t(i));
        if (all) all->extend(b);
    }
    buildBvh(roots, bvh);
    for (uint32_t& p : bvh.prims) p = ids[p];
    collapseBvh4(bvh, boxes);
}
}  // namespace

void buildRtAccel(const Scene& scene, const Mat4& toSpace, int subpatchDepth, bool cullFromOrigin,
                  RtAccel& acc, const FrameMotion* motion, int maxTimeSlabs,
                  const RtDisplacementOptions* displacement) {
    const size_t n = scene.patches.size();
    acc.motion = motion && motion->blurred() ? *motion : FrameMotion();
    acc.movingPatches = 0;
    if (acc.motion.firstKey.size() != n) acc.motion = FrameMotion();  // no moving patch (or a foreign one)
    for (size_t i = 0; i < acc.motion.firstKey.size(); ++i) acc.movingPatches += acc.motion.moving(i);
    acc.patches.resize(n);
    acc.flip.resize(n);
    acc.twoSided.resize(n);
    acc.material.resize(n);
    acc.quadrics.clear();
    acc.quadricOf.assign(n, RtAccel::kNoQuadric);
    for (const SceneQuadric& q : scene.quadrics) acc.quadrics.push_back(placeQuadric(q, toSpace));
    std::vector<const PlacedQuadric*> quadricPtr;
    if (!acc.quadrics.empty()) {
        quadricPtr.assign(n, nullptr);
        for (size_t i = 0; i < n; ++i)
            if (isQuadric(scene.attributes[i].kind)) {
                acc.quadricOf[i] = scene.attributes[i].shape;
                quadricPtr[i] = &acc.quadrics[scene.attributes[i].shape];
            }
    }
    tbb::parallel_for(size_t(0), n, [&](size_t i) {
        // Surface kinds: bicubic Bezier patches (subpatch trees of de Casteljau hulls, Newton) and the
        // quadrics (subpatch trees of quadricBounds, analytic intersection in the Newton stage).
        switch (scene.attributes[i].kind) {
            case SurfaceKind::BicubicBezier:
                if (acc.moving(uint32_t(i)))  // knot 0: shutter open, in the timeline's space
                    acc.patches[i] = acc.motion.patchKeys(i)[0];
                else
                    for (int k = 0; k < 16; ++k) acc.patches[i].cp[k] = toSpace.point(scene.patches[i].cp[k]);
                break;
            case SurfaceKind::Sphere:
            case SurfaceKind::Cylinder:
            case SurfaceKind::Cone:
            case SurfaceKind::Disk:
            case SurfaceKind::Paraboloid:
            case SurfaceKind::Hyperboloid:
            case SurfaceKind::Torus:
                // The place holder: the hull of the quadric's box (the subpatch boxes come from the
                // quadric itself, and the Newton stage intersects it analytically).
                for (int k = 0; k < 16; ++k) acc.patches[i].cp[k] = toSpace.point(scene.patches[i].cp[k]);
                break;
        }
        acc.flip[i] = scene.attributes[i].flipNormal;
        acc.twoSided[i] = scene.attributes[i].twoSided;
        acc.material[i] = scene.attributes[i].material;
    });
    acc.vertexValues = vertexValuesInSpace(scene, toSpace);
    if (!acc.vertexValues.empty()) {
        acc.vertexValuesOf.resize(n);
        for (size_t i = 0; i < n; ++i) acc.vertexValuesOf[i] = scene.attributes[i].vertexValues;
    }
    auto t0 = Clock::now();
    buildSubpatchForest(acc.patches, subpatchDepth, acc.forest, cullFromOrigin, acc.flip,
                        acc.movingPatches ? &acc.motion : nullptr, maxTimeSlabs, kTimeSlabBudgetBytes,
                        quadricPtr);
    acc.subpatchMs = msSince(t0);
    // Displaced patches: their micro-grids (now or lazily) and their subpatch boxes.
    acc.displaced = DisplacedGrids();
    if (displacement && displacement->dicer) {
        const auto td = Clock::now();
        std::vector<uint32_t> which;
        for (uint32_t i = 0; i < n; ++i)
            if (scene.attributes[i].kind == SurfaceKind::BicubicBezier && !acc.moving(i) &&
                displacement->dicer->displaced(i))
                which.push_back(i);
        buildDisplacedGrids(which, displacement->dicer, acc.forest.depth, displacement->budgetBytes,
                            displacement->forceLazy, acc.forest, acc.displaced);
        acc.displaced.buildMs = msSince(td);
    }
    acc.patchSoa.resize(n);
    tbb::parallel_for(size_t(0), n, [&](size_t i) {
        PatchSoa& ps = acc.patchSoa[i];
        for (int k = 0; k < 16; ++k)
            ps.x[k] = acc.patches[i].cp[k].x, ps.y[k] = acc.patches[i].cp[k].y,
            ps.z[k] = acc.patches[i].cp[k].z;
        const Bounds3& b = acc.forest.tree(uint32_t(i))[0];
        float mag = 0.f;
        for (int k = 0; k < 3; ++k) mag = std::max({mag, std::fabs(b.lo[k]), std::fabs(b.hi[k])});
        ps.boxMagnitude = mag;
        ps.boxExtent = maxComponent(b.diagonal());
    });
    auto t1 = Clock::now();
    Bounds3 all;
    buildPatchBvh(
        n, [&](uint32_t i) { return acc.forest.tree(i)[0]; }, acc.bvh, &all);
    acc.slabBvh.assign(size_t(acc.forest.slabCount), Bvh());  // (their boxes lie in the swept ones)
    tbb::parallel_for(0, acc.forest.slabCount, [&](int s) {
        buildPatchBvh(
            n, [&](uint32_t i) { return acc.forest.rootBox(i, s); }, acc.slabBvh[size_t(s)], nullptr);
    });
    acc.bounds = all;
    acc.bvhMs = msSince(t1);
    float mag = 0.f;
    if (!all.empty())
        for (int k = 0; k < 3; ++k) mag = std::max({mag, std::fabs(all.lo[k]), std::fabs(all.hi[k])});
    acc.offset = 2e-5f * mag + 1e-6f;
}

}  // namespace tessera
