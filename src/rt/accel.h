// The ray tracer's acceleration structure: the patches in one space (the renderer uses camera space) with
// both levels of the hierarchy (rt/bvh.h, rt/subpatch_tree.h) and what the Newton stage reads per patch.
#pragma once
#include <cstdint>
#include <vector>

#include "core/transform.h"
#include "engine/motion.h"
#include "engine/settings.h"
#include "rt/bvh.h"
#include "rt/displaced.h"
#include "rt/intersect.h"
#include "rt/subpatch_tree.h"
#include "scene/scene.h"

namespace tessera {

// A patch's control points as coordinate arrays (the projection on a ray's planes runs 4 points at a
// time), with what the Newton tolerance needs from its box.
struct alignas(16) PatchSoa {
    float x[16], y[16], z[16];
    float boxMagnitude;  // largest |coordinate| of the patch's root box
    float boxExtent;     // largest side of the root box
};

// Where an instance stands relative to its prototype, in the accel's space: instance point =
// fromPrototype applied to the prototype's point; toPrototype is its inverse. A ray is moved into the
// prototype's frame with affinePoint / affineVector (core/quadric.h), its direction not renormalised, so
// a distance t along it is the same point as t along the original ray.
struct InstancePlacement {
    Affine3 toPrototype, fromPrototype;
};

// Scene prepared for tracing in one space (the renderer uses camera space: eye at the origin).
struct RtAccel {
    // Tens of MB on big scenes, written in parallel by the build: on huge pages, not zero-filled first.
    std::vector<BezierPatch, DefaultInitAllocator<BezierPatch>> patches;
    std::vector<PatchSoa, DefaultInitAllocator<PatchSoa>> patchSoa;  // the same, for the Newton stage
    std::vector<uint8_t> flip, twoSided;
    std::vector<uint32_t> material;
    // Quadric surfaces (their kinds' closed form, core/quadric.h): per surface its index in `quadrics`
    // (kNoQuadric for a Bezier patch, whose `patches` entry is its control points; a quadric's entry there
    // only holds its place), and the quadrics in the accel's space. Quadrics do not move.
    static constexpr uint32_t kNoQuadric = 0xffffffffu;
    std::vector<uint32_t> quadricOf;
    std::vector<PlacedQuadric> quadrics;
    const PlacedQuadric* quadric(uint32_t patch) const {
        return quadricOf.empty() || quadricOf[patch] == kNoQuadric ? nullptr : &quadrics[quadricOf[patch]];
    }
    // Per-vertex normals (in the accel's space) and colours (scene.h PatchVertexValues), and per patch
    // its entry (-1: none); both empty when no surface has them.
    std::vector<PatchVertexValues> vertexValues;
    std::vector<int32_t> vertexValuesOf;
    const PatchVertexValues* vertexValuesAt(uint32_t patch) const {
        if (vertexValuesOf.empty() || vertexValuesOf[patch] < 0) return nullptr;
        return &vertexValues[size_t(vertexValuesOf[patch])];
    }
    Bvh bvh;
    SubpatchForest forest;
    // Instancing (docs/rt.md, "Instancing"): the patches of an ObjectInstance that are affine copies of the
    // object's first instance (the prototype) have no subpatch tree of their own. Per patch, `treeOf` is its
    // tree in `forest` (the prototype patch's for a shared one; empty: every patch has its own, tree i) and
    // `placementOf` its entry in `placements` (kOwnTree: its own tree); a ray tests a shared tree's boxes
    // moved into the prototype's frame (InstancePlacement::toPrototype), while Newton runs on the patch's
    // own control points. `sharedRoot`: per patch, the BVH's box of a shared patch (its prototype's root box
    // placed, so it holds every leaf box a ray can reach through it).
    static constexpr uint32_t kOwnTree = 0xffffffffu;
    std::vector<uint32_t> treeOf, placementOf;
    std::vector<InstancePlacement> placements;
    std::vector<Bounds3> sharedRoot;
    size_t sharedPatches = 0;  // patches that use a prototype's tree
    bool instanced() const { return !placements.empty(); }
    uint32_t tree(uint32_t patch) const { return treeOf.empty() ? patch : treeOf[patch]; }
    const InstancePlacement* placement(uint32_t patch) const {
        return placementOf.empty() || placementOf[patch] == kOwnTree ? nullptr
                                                                     : &placements[placementOf[patch]];
    }
    // The root box of a patch in the accel's space (what the BVH holds).
    const Bounds3& rootBox(uint32_t patch) const {
        return placement(patch) ? sharedRoot[patch] : forest.roots[tree(patch)];
    }
    // Displaced patches (rt/displaced.h): their micro-grids, intersected instead of the patch; their
    // subpatch boxes bound the grids' triangles.
    DisplacedGrids displaced;
    Bounds3 bounds;        // of all traced patches (their root boxes)
    float offset = 1e-4f;  // self-intersection offset along the normal for secondary ray origins
    double bvhMs = 0, subpatchMs = 0;
    // Motion blur (paper 002, sec. 5.3.3): the frame's camera-space timeline and, for every patch that
    // moves, its control points at each knot (engine/motion.h). `patches` / `patchSoa` hold knot 0; the
    // subpatch boxes (and so the BVH) of a moving patch bound it over the whole shutter. Empty `firstKey`:
    // nothing moves, and every stage takes its static path.
    FrameMotion motion;
    size_t movingPatches = 0;
    bool moving(uint32_t patch) const { return motion.moving(patch); }
    // Per time slab of the forest (SubpatchForest::slabCount), a BVH over the patches' boxes over that slab:
    // a ray traverses its time's slab (timeSlab), and `bvh` (swept over the whole shutter) serves the rest.
    std::vector<Bvh> slabBvh;
    int timeSlab(float u) const {
        if (forest.slabCount == 0) return 0;
        int k;
        float w;
        motion.segment(u, k, w);
        return forest.slabOfSegment[size_t(k)];
    }
};

// The control points of a moving patch at normalised shutter time u (the lerp of the two knots around u,
// as FrameMotion::patchAt).
void patchAtTime(const RtAccel& acc, uint32_t patch, float u, BezierPatch& out);
// The same at weight w of timeline segment k (FrameMotion::segment), as the Newton stage's coordinate
// arrays (the same arithmetic as lerp, so bit-identical to patchAtTime; the box figures are the patch's
// swept root box's).
inline void patchSoaAt(const RtAccel& acc, uint32_t patch, int k, float w, PatchSoa& out) {
    const BezierPatch& a = acc.motion.keys[acc.motion.firstKey[patch] + k];
    const BezierPatch& b = acc.motion.keys[acc.motion.firstKey[patch] + k + 1];
    for (int c = 0; c < 16; ++c) {
        out.x[c] = a.cp[c].x + (b.cp[c].x - a.cp[c].x) * w;
        out.y[c] = a.cp[c].y + (b.cp[c].y - a.cp[c].y) * w;
        out.z[c] = a.cp[c].z + (b.cp[c].z - a.cp[c].z) * w;
    }
    out.boxMagnitude = acc.patchSoa[patch].boxMagnitude;
    out.boxExtent = acc.patchSoa[patch].boxExtent;
}
inline void soaToPatch(const PatchSoa& s, BezierPatch& out) {
    for (int c = 0; c < 16; ++c) out.cp[c] = {s.x[c], s.y[c], s.z[c]};
}

// Transform the patches by `toSpace` and build both levels. `cullFromOrigin` also marks subpatches that
// face away from the origin (the eye, in camera space) for --cull-backfaces.
// `motion` (in the space of `toSpace`, i.e. camera space for the renderer): the moving patches' keys;
// nullptr or a static timeline: a static accel, bit-identical to one built without it.
// `maxTimeSlabs`: see buildSubpatchForest (1: boxes swept over the whole shutter only).
// `displacement` (nullptr or no dicer: none): the patches its dicer calls displaced (static bicubic patches
// only) are traced as micro-grids (rt/displaced.h), built up front when they fit the budget, lazily
// otherwise.
struct RtDisplacementOptions {
    std::shared_ptr<const DisplacedDicer> dicer;
    size_t budgetBytes = size_t(512) << 20;  // --displacement-cache-mb
    bool forceLazy = false;                  // build lazily even when everything fits (tests)
};
// `subpatchDepth` >= 0 (resolve kAutoSubpatchDepth with autoSubpatchDepth first).
// `instancing`: the patches of Scene::instances that are affine copies of their object's first instance
// share its subpatch trees (RtAccel::treeOf); not with `cullFromOrigin` (the back-facing marks depend on
// where the eye is in the prototype's frame) nor in a frame where anything moves. `leafSlabs`: build the
// leaves' slabs (SubpatchForest::leafSlabs), which the candidate stages test.
void buildRtAccel(const Scene& scene, const Mat4& toSpace, int subpatchDepth, bool cullFromOrigin,
                  RtAccel& acc, const FrameMotion* motion = nullptr, int maxTimeSlabs = kDefaultTimeSlabs,
                  const RtDisplacementOptions* displacement = nullptr, bool instancing = false,
                  bool leafSlabs = true);

// --subpatch-depth auto: a depth for the scene's subpatch trees from how many camera samples its patches
// cover: the patches whose box projects into the image each cover its clipped raster rectangle times
// the samples per pixel, and their median weighted by those samples (`samplesPerPatch` gets it, 0 when
// no patch is in view) picks 2, 4 or 6. Leaves much finer than the rays that reach them cost traversal,
// build time and memory; leaves much coarser cost Newton iterations (paper 002 sec. 3.4 fixes depth 6;
// our sweep is in docs/rt.md, "Subpatch depth per frame").
int autoSubpatchDepth(const Scene& scene, const Camera& cam, double samplesPerPixel,
                      double* samplesPerPatch = nullptr);
// The depth to build with: `requested`, or autoSubpatchDepth's when it is kAutoSubpatchDepth
// (engine/settings.h).
inline int resolveSubpatchDepth(int requested, const Scene& scene, const Camera& cam, double samplesPerPixel,
                                double* samplesPerPatch = nullptr) {
    return requested == kAutoSubpatchDepth ? autoSubpatchDepth(scene, cam, samplesPerPixel, samplesPerPatch)
                                           : requested;
}

// The ray against quadric surface `patch` (analytic, core/quadric.h), restricted to the (u,v) rectangle
// [u0,u1] x [v0,v1] (a subpatch leaf's; a hit on its border counts for both neighbours): the nearest hit
// that `accept` takes, with P on the ray and dP/du, dP/dv from the closed form in the accel's space.
template <class Accept>
bool intersectQuadricSurface(const PlacedQuadric& pq, const Ray& ray, float u0, float u1, float v0, float v1,
                             Accept&& accept, PatchHit& out) {
    const Vec3 o = affinePoint(pq.fromSpace, ray.o), d = affineVector(pq.fromSpace, ray.d);
    QuadricHit hits[4];
    const int n = intersectQuadric(pq.q, o, d, ray.tmin, ray.tmax, hits);
    constexpr float kBorder = 1e-5f;
    for (int i = 0; i < n; ++i) {
        const QuadricHit& qh = hits[i];
        if (qh.u < u0 - kBorder || qh.u > u1 + kBorder || qh.v < v0 - kBorder || qh.v > v1 + kBorder)
            continue;
        const SurfacePoint sp = evalQuadric(pq.q, qh.u, qh.v);
        PatchHit h;
        h.t = qh.t, h.u = qh.u, h.v = qh.v;
        h.p = ray.o + ray.d * qh.t;
        h.dpdu = affineVector(pq.toSpace, sp.dpdu);
        h.dpdv = affineVector(pq.toSpace, sp.dpdv);
        h.hit = true;
        if (accept(h)) {
            out = h;
            return true;
        }
    }
    return false;
}

// The geometric normal at a hit, orientation flipped per the surface's attributes (not normalised for
// patches: dP/du x dP/dv; unit for quadrics, whose closed form has the limit at the poles).
Vec3 orientedGeometricNormal(const RtAccel& acc, uint32_t patch, const PatchHit& h);

// Unit shading normal at a hit (geometric, orientation flipped per the patch attributes); `time`: the
// ray's normalised shutter time (moving patches are evaluated there).
Vec3 hitNormal(const RtAccel& acc, uint32_t patch, const PatchHit& h, float time = 0.f);

}  // namespace tessera
