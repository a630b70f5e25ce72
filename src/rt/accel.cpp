#include "rt/accel.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <stdexcept>
#include <string>

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

Affine3 affineOf(const Mat4& m) {
    Affine3 a;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 4; ++c) a.m[r][c] = float(m.m[r][c]);
    return a;
}

// Instancing: which patches of Scene::instances can use the subpatch tree of the same patch of their
// object's first instance (the prototype). A patch qualifies when both it and its prototype patch are
// static, undisplaced bicubic patches and its control points (in the accel's space) are the prototype's
// moved by the instance's placement to within a fraction of the leaf boxes' margin (enlargedHull), so the
// prototype's boxes, tested with the ray in the prototype's frame, hold it. Anything else (a Basis or
// displacement that differs per instance, a count that differs) keeps its own tree. Sets acc.placementOf,
// acc.placements and, per shared patch, its prototype patch in `protoPatch`.
void findSharedPatches(const Scene& scene, const Mat4& toSpace, const RtDisplacementOptions* displacement,
                       RtAccel& acc, std::vector<uint32_t>& protoPatch) {
    const size_t n = acc.patches.size();
    const DisplacedDicer* dicer = displacement ? displacement->dicer.get() : nullptr;
    auto eligible = [&](uint32_t i) {
        return scene.attributes[i].kind == SurfaceKind::BicubicBezier && !(dicer && dicer->displaced(i));
    };
    const Mat4 fromSpace = toSpace.inverse();
    std::map<uint32_t, size_t> prototypeOf;  // object -> its first instance
    acc.placementOf.assign(n, RtAccel::kOwnTree);
    protoPatch.assign(n, RtAccel::kOwnTree);
    for (size_t k = 0; k < scene.instances.size(); ++k) {
        const SurfaceInstance& in = scene.instances[k];
        if (size_t(in.first) + in.count > n) continue;
        const auto [it, first] = prototypeOf.emplace(in.object, k);
        if (first) continue;
        const SurfaceInstance& proto = scene.instances[it->second];
        if (proto.count != in.count) continue;
        const Mat4 place = toSpace * in.objectToWorld * proto.objectToWorld.inverse() * fromSpace;
        const double det = place.det3();
        bool affine = std::isfinite(det) && std::fabs(det) > 1e-12;
        for (int c = 0; c < 3; ++c) affine = affine && std::fabs(place.m[3][c]) < 1e-9;
        if (!affine || std::fabs(place.m[3][3] - 1.0) > 1e-9) continue;
        uint32_t placement = RtAccel::kOwnTree;
        for (uint32_t j = 0; j < in.count; ++j) {
            const uint32_t i = in.first + j, q = proto.first + j;
            if (!eligible(i) || !eligible(q) || protoPatch[q] != RtAccel::kOwnTree) continue;
            const BezierPatch& mine = acc.patches[i];
            const Bounds3 hull = hullBounds(mine);
            float mag = 0.f;
            for (int a = 0; a < 3; ++a) mag = std::max({mag, std::fabs(hull.lo[a]), std::fabs(hull.hi[a])});
            const float tol = 1e-6f * maxComponent(hull.diagonal()) + 2e-7f * mag;
            bool same = true;
            for (int c = 0; c < 16 && same; ++c) {
                const Vec3 moved = place.point(acc.patches[q].cp[c]), d = moved - mine.cp[c];
                same = std::max({std::fabs(d.x), std::fabs(d.y), std::fabs(d.z)}) <= tol;
            }
            if (!same) continue;
            if (placement == RtAccel::kOwnTree) {
                placement = uint32_t(acc.placements.size());
                acc.placements.push_back({affineOf(place.inverse()), affineOf(place)});
            }
            acc.placementOf[i] = placement;
            protoPatch[i] = q;
        }
    }
    if (acc.placements.empty()) acc.placementOf.clear(), protoPatch.clear();
}

// The box of `b` moved by an affine map (its eight corners').
Bounds3 placedBox(const Affine3& a, const Bounds3& b) {
    Bounds3 r;
    for (int c = 0; c < 8; ++c)
        r.extend(
            affinePoint(a, Vec3{c & 1 ? b.hi.x : b.lo.x, c & 2 ? b.hi.y : b.lo.y, c & 4 ? b.hi.z : b.lo.z}));
    return r;
}
}  // namespace

int autoSubpatchDepth(const Scene& scene, const Camera& cam, double samplesPerPixel,
                      double* samplesPerPatch) {
    // Thresholds on the weighted median samples per patch, from the sweeps in docs/rt.md ("Subpatch depth
    // per frame": time at 800x600 and 1600x1200, callgrind at 1 and 4 spp): depth 2 below kShallow, 6 from
    // kDeep, else 4.
    constexpr double kShallow = 512, kDeep = 4096;
    const Projector proj(cam);
    const size_t n = scene.patches.size();
    // About 2048 patches, evenly spread over the list (a median needs no more; all 11532 of Killeroo cost
    // 19 M instructions, 1% of its 800x600 frame).
    const size_t stride = std::max<size_t>(1, n / 2048);
    std::vector<double> covered;
    covered.reserve(n / stride + 1);
    const float w = float(cam.width), h = float(cam.height);
    for (size_t i = 0; i < n; i += stride) {
        Bounds3 b;
        for (const Vec3& p : scene.patches[i].cp) b.extend(cam.cameraFromWorld.point(p));
        float x0, x1, y0, y1;
        if (!proj.rasterBounds(b, x0, x1, y0, y1)) continue;  // reaches behind the eye
        x0 = std::max(x0, 0.f), x1 = std::min(x1, w), y0 = std::max(y0, 0.f), y1 = std::min(y1, h);
        if (!(x0 < x1 && y0 < y1)) continue;  // out of view
        covered.push_back(double(x1 - x0) * double(y1 - y0) * samplesPerPixel);
    }
    if (samplesPerPatch) *samplesPerPatch = 0;
    if (covered.empty()) return 6;
    // The median weighted by the samples: half of the samples fall on patches covering at least this
    // many (a large floor under small figures keeps deep trees for the floor's rays).
    std::sort(covered.begin(), covered.end());
    double total = 0, below = 0;
    for (double c : covered) total += c;
    double median = covered.back();
    for (double c : covered)
        if ((below += c) >= 0.5 * total) {
            median = c;
            break;
        }
    if (samplesPerPatch) *samplesPerPatch = median;
    return median < kShallow ? 2 : median < kDeep ? 4 : 6;
}

void buildRtAccel(const Scene& scene, const Mat4& toSpace, int subpatchDepth, bool cullFromOrigin,
                  RtAccel& acc, const FrameMotion* motion, int maxTimeSlabs,
                  const RtDisplacementOptions* displacement, bool instancing, bool leafSlabs) {
    if (subpatchDepth < 0)  // kAutoSubpatchDepth is the caller's to resolve (autoSubpatchDepth)
        throw std::invalid_argument("buildRtAccel: subpatch depth " + std::to_string(subpatchDepth));
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
    // Instancing: the patches that share a prototype's tree, and the trees to build (the other patches').
    acc.treeOf.clear(), acc.placementOf.clear(), acc.placements.clear(), acc.sharedRoot.clear();
    acc.sharedPatches = 0;
    std::vector<uint32_t> protoPatch;
    if (instancing && !cullFromOrigin && acc.movingPatches == 0 && !scene.instances.empty())
        findSharedPatches(scene, toSpace, displacement, acc, protoPatch);
    if (acc.instanced()) {
        std::vector<BezierPatch> treePatches;
        std::vector<uint8_t> treeFlip;
        std::vector<const PlacedQuadric*> treeQuadric;
        acc.treeOf.resize(n);
        for (size_t i = 0; i < n; ++i) {
            if (protoPatch[i] != RtAccel::kOwnTree) {  // the prototype comes first, so its tree is known
                acc.treeOf[i] = acc.treeOf[protoPatch[i]];
                ++acc.sharedPatches;
                continue;
            }
            acc.treeOf[i] = uint32_t(treePatches.size());
            treePatches.push_back(acc.patches[i]);
            treeFlip.push_back(acc.flip[i]);
            if (!quadricPtr.empty()) treeQuadric.push_back(quadricPtr[i]);
        }
        buildSubpatchForest(treePatches, subpatchDepth, acc.forest, false, treeFlip, nullptr, maxTimeSlabs,
                            kTimeSlabBudgetBytes, treeQuadric, leafSlabs);
    } else {
        buildSubpatchForest(acc.patches, subpatchDepth, acc.forest, cullFromOrigin, acc.flip,
                            acc.movingPatches ? &acc.motion : nullptr, maxTimeSlabs, kTimeSlabBudgetBytes,
                            quadricPtr, leafSlabs);
    }
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
                            displacement->forceLazy, acc.forest, acc.displaced, acc.treeOf);
        acc.displaced.buildMs = msSince(td);
    }
    if (acc.instanced()) {
        acc.sharedRoot.assign(n, Bounds3());
        tbb::parallel_for(size_t(0), n, [&](size_t i) {
            if (const InstancePlacement* pl = acc.placement(uint32_t(i)))
                acc.sharedRoot[i] = placedBox(pl->fromPrototype, acc.forest.roots[acc.tree(uint32_t(i))]);
        });
    }
    acc.patchSoa.resize(n);
    tbb::parallel_for(size_t(0), n, [&](size_t i) {
        PatchSoa& ps = acc.patchSoa[i];
        for (int k = 0; k < 16; ++k)
            ps.x[k] = acc.patches[i].cp[k].x, ps.y[k] = acc.patches[i].cp[k].y,
            ps.z[k] = acc.patches[i].cp[k].z;
        // Newton's tolerance from the patch's own box (a shared patch's hull: close to the root box its own
        // tree would have, which the placed prototype box overestimates when the instance turns).
        const Bounds3 b =
            acc.placement(uint32_t(i)) ? enlargedHull(acc.patches[i]) : acc.rootBox(uint32_t(i));
        float mag = 0.f;
        for (int k = 0; k < 3; ++k) mag = std::max({mag, std::fabs(b.lo[k]), std::fabs(b.hi[k])});
        ps.boxMagnitude = mag;
        ps.boxExtent = maxComponent(b.diagonal());
    });
    auto t1 = Clock::now();
    Bounds3 all;
    buildPatchBvh(
        n, [&](uint32_t i) { return acc.rootBox(i); }, acc.bvh, &all);
    acc.slabBvh.assign(size_t(acc.forest.slabCount), Bvh());  // (their boxes lie in the swept ones)
    tbb::parallel_for(0, acc.forest.slabCount, [&](int s) {
        buildPatchBvh(
            n, [&](uint32_t i) { return acc.forest.rootBox(acc.tree(i), s); }, acc.slabBvh[size_t(s)],
            nullptr);
    });
    acc.bounds = all;
    acc.bvhMs = msSince(t1);
    float mag = 0.f;
    if (!all.empty())
        for (int k = 0; k < 3; ++k) mag = std::max({mag, std::fabs(all.lo[k]), std::fabs(all.hi[k])});
    acc.offset = 2e-5f * mag + 1e-6f;
}

}  // namespace tessera
