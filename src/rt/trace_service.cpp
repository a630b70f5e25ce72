#include "rt/trace_service.h"

#include <algorithm>
#include <chrono>

#include "rt/newton_stage.h"
#include "rt/traversal.h"

namespace tessera {
namespace rt {

void TraceCounters::add(const TraceCounters& c) {
    for (int k = 0; k < kKinds; ++k) rays[k] += c.rays[k], hits[k] += c.hits[k];
    candidates += c.candidates, newtonRuns += c.newtonRuns, newtonIterations += c.newtonIterations;
    boxTests += c.boxTests, hullCulled += c.hullCulled, timeCulled += c.timeCulled, rootPairs += c.rootPairs;
    slabCulled += c.slabCulled;
    originLeafDropped += c.originLeafDropped;
    shadowListsBinned += c.shadowListsBinned, shadowListsTraversed += c.shadowListsTraversed;
    for (int i = 0; i < kHistBins; ++i) hist[i] += c.hist[i];
    traversalMs += c.traversalMs, newtonMs += c.newtonMs;
}

double TraceService::leavesPerSample(const RtAccel& acc, double samples) {
    return leavesPerSample(acc.patches.size(), double(acc.forest.firstLeaf() + 1), samples);
}

void TraceService::trace(const RayList& rays, std::vector<RayHit>& hits, const CameraSamples* camera) {
    traceList(rays, hits, false, camera && opt_.binning ? Stage::kCameraBinning : Stage::kPerRay, camera, {});
}

void TraceService::occluded(const RayList& rays, std::vector<uint8_t>& blocked) {
    traceList(rays, anyHits_, true, Stage::kPerRay, nullptr, {});
    toBlocked(anyHits_, blocked);
}

void TraceService::occluded(const RayList& rays, std::span<const ShadowRun> runs,
                            std::vector<uint8_t>& blocked) {
    traceList(rays, anyHits_, true, opt_.binning ? Stage::kShadowBinning : Stage::kPerRay, nullptr, runs);
    toBlocked(anyHits_, blocked);
}

void TraceService::toBlocked(const std::vector<RayHit>& hits, std::vector<uint8_t>& blocked) {
    blocked.resize(hits.size());
    for (size_t r = 0; r < hits.size(); ++r) blocked[r] = hits[r].hit;
}

size_t TraceService::candidateBytes() const {
    size_t bytes = 0;
    for (const Chunk& ch : chunks_) bytes += ch.cand.capacity() * sizeof(Candidate);
    return bytes;
}

// The candidate stage (camera binning, shadow binning, or per ray: also when a point light's rays
// surround it), then Newton, then the counters.
void TraceService::traceList(const RayList& rays, std::vector<RayHit>& hits, bool anyHit, Stage how,
                             const CameraSamples* camera, std::span<const ShadowRun> runs) {
    using Clock = std::chrono::steady_clock;
    const RtAccel& acc = *acc_;
    const bool cull = opt_.cullBackfaces;
    // The binning stages test the subpatch boxes in the accel's space; an instance's patch has its
    // prototype's boxes in the prototype's frame, which only the per-ray traversal moves the ray into.
    if (acc.instanced()) how = Stage::kPerRay;
    auto t0 = Clock::now();
    if (how == Stage::kCameraBinning) {
        binCameraRays(acc, rays, *camera, bin_, chunks_, cull);
    } else {
        bool binned = false;
        if (how == Stage::kShadowBinning) {
            binned = binShadowRays(acc, rays, runs, bin_, chunks_);
            ++(binned ? c_.shadowListsBinned : c_.shadowListsTraversed);
        }
        if (!binned) traverseList(acc, rays, chunks_, cull);
    }
    auto t1 = Clock::now();
    newtonList(acc, rays, chunks_, hits, cull, anyHit);
    c_.traversalMs += std::chrono::duration<double, std::milli>(t1 - t0).count();
    c_.newtonMs += std::chrono::duration<double, std::milli>(Clock::now() - t1).count();
    const size_t nChunks = (rays.size() + kChunk - 1) / kChunk;
    for (size_t ci = 0; ci < nChunks; ++ci) {
        const StageCounters& c = chunks_[ci].c;
        c_.candidates += c.candidates, c_.newtonRuns += c.newtonRuns;
        c_.newtonIterations += c.newtonIterations, c_.boxTests += c.boxTests;
        c_.hullCulled += c.hullCulled, c_.timeCulled += c.timeCulled, c_.rootPairs += c.rootPairs;
        c_.slabCulled += c.slabCulled;
        c_.originLeafDropped += c.originLeafDropped;
        for (int i = 0; i < kHistBins; ++i) c_.hist[i] += c.hist[i];
    }
    for (size_t r = 0; r < rays.size(); ++r) {
        ++c_.rays[rays.kind[r]];
        if (hits[r].hit) ++c_.hits[rays.kind[r]];
    }
}

}  // namespace rt

bool acceptHit(const RtAccel& acc, const Ray& ray, const TraceOptions& opt, uint32_t patch,
               const PatchHit& h) {
    if (patch == opt.ignorePatch && h.t < opt.ignoreT) return false;
    if (opt.respectSides && !acc.twoSided[patch]) {
        if (dot(orientedGeometricNormal(acc, patch, h), ray.d) > 0.f) return false;  // back face, one-sided
    }
    return true;
}

bool traceRayScalar(const RtAccel& acc, const Ray& ray, const TraceOptions& opt, RayHit& out) {
    out = RayHit();
    if (acc.bvh.nodes.empty()) return false;
    Ray r = ray;
    const Vec3 inv = safeInverse(r.d);
    uint32_t stack[64];
    int sp = 0;
    stack[sp++] = 0;
    while (sp > 0) {
        const uint32_t ni = stack[--sp];
        const BvhNode& node = acc.bvh.nodes[ni];
        float te;
        if (!rayBox(node.box, r.o, inv, r.tmin, r.tmax, te)) continue;
        if (node.count == 0) {
            stack[sp++] = node.offset;
            stack[sp++] = ni + 1;
            continue;
        }
        for (uint32_t k = 0; k < node.count; ++k) {
            const uint32_t patch = acc.bvh.prims[node.offset + k];
            PatchHit h;
            const uint8_t* back = opt.cullBackfaces ? acc.forest.backfaceBits(acc.tree(patch)) : nullptr;
            auto accept = [&](const PatchHit& ph) { return acceptHit(acc, r, opt, patch, ph); };
            // The nearest hit so far: the ray ends there (true: an any-hit query is answered).
            auto record = [&](const PatchHit& found) {
                out.hit = true;
                out.patch = patch;
                out.h = found;
                r.tmax = found.t;
                return opt.anyHit;
            };
            if (const PlacedQuadric* pq = acc.quadric(patch)) {
                if (intersectQuadricSurface(*pq, r, 0.f, 1.f, 0.f, 1.f, accept, h) && record(h)) return true;
                continue;
            }
            if (const std::shared_ptr<const DisplacedMesh> dm = acc.displaced.mesh(patch)) {  // leaf by leaf
                const WatertightRay wr = makeWatertightRay(r);
                for (uint32_t leaf = 0; leaf < uint32_t(dm->leafRoot.size()); ++leaf)
                    if (intersectDisplacedLeaf(*dm, leaf, r, wr, accept, h) && record(h)) return true;
                continue;
            }
            if (const InstancePlacement* pl =
                    acc.placement(patch)) {  // the prototype's tree, ray moved there
                const Vec3 boxO = affinePoint(pl->toPrototype, r.o);
                const Vec3 boxInv = safeInverse(affineVector(pl->toPrototype, r.d));
                if (intersectPatchTree<float>(acc.patches[patch], acc.forest, acc.tree(patch),
                                              enlargedHull(acc.patches[patch]), boxO, boxInv, r, h, nullptr,
                                              nullptr, nullptr, accept) &&
                    record(h))
                    return true;
                continue;
            }
            BezierPatch moved;
            if (acc.moving(patch)) patchAtTime(acc, patch, opt.time, moved);  // at the ray's time
            if (intersectPatch<float>(acc.moving(patch) ? moved : acc.patches[patch], acc.forest,
                                      acc.tree(patch), r, h, back, nullptr, nullptr, accept) &&
                record(h))
                return true;
        }
    }
    return out.hit;
}

void traceBatch(const RtAccel& acc, std::span<const Ray> rays, const TraceOptions& opt,
                std::vector<RayHit>& hits) {
    using namespace rt;
    const uint8_t kind = opt.anyHit                                ? kShadow
                         : (opt.respectSides || opt.cullBackfaces) ? kPrimary
                                                                   : kReflection;
    RayList list;
    for (const Ray& r : rays)
        list.push(r.o, r.d, r.tmin, r.tmax, 0, {1, 1, 1}, opt.ignorePatch, kind, 0, {-1.f, -1.f},
                  {0.f, 0.f, 0.f}, opt.time);
    TraceService service(acc, {opt.cullBackfaces, false});
    service.trace(list, hits);
}

}  // namespace tessera
