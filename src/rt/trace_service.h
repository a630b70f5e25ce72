// The trace service: closest-hit and any-hit queries over ray lists, in the acceleration structure's
// space. It picks the candidate stage for each list (screen-space binning for a tile's camera rays and
// light-space binning for shadow rays where binning pays, the per-ray traversal otherwise), then runs the
// Newton stage. It knows nothing of shading, materials or the film: the ray tracer's integrator
// (rt/rt_renderer.cpp) calls it, and so could Reyes for ray-traced shadows (rays in the accel's space).
#pragma once
#include <algorithm>
#include <cstdint>
#include <span>
#include <vector>

#include "rt/accel.h"
#include "rt/binning.h"
#include "rt/ray_list.h"

namespace tessera {

// Scalar reference: closest (or any) hit along the ray, BVH then each patch's subpatch tree.
bool traceRayScalar(const RtAccel& acc, const Ray& ray, const TraceOptions& opt, RayHit& out);

// Whether a hit is acceptable under the options (sides, self-intersection).
bool acceptHit(const RtAccel& acc, const Ray& ray, const TraceOptions& opt, uint32_t patch,
               const PatchHit& h);

// The wavefront path (the trace service's stages, per-ray traversal) over a batch of rays in the caller's
// thread: the same answers as traceRayScalar, for tests and tools.
void traceBatch(const RtAccel& acc, std::span<const Ray> rays, const TraceOptions& opt,
                std::vector<RayHit>& hits);

namespace rt {

// What the trace stages counted, summed over the lists traced.
struct TraceCounters {
    uint64_t rays[kKinds] = {}, hits[kKinds] = {};
    uint64_t candidates = 0, newtonRuns = 0, newtonIterations = 0, boxTests = 0, hullCulled = 0;
    uint64_t timeCulled = 0, rootPairs = 0, slabCulled = 0, originLeafDropped = 0;
    uint64_t shadowListsBinned = 0, shadowListsTraversed = 0;  // shadow lists by how candidates were found
    std::array<uint64_t, kHistBins> hist{};
    double traversalMs = 0, newtonMs = 0;  // CPU time of the candidate and Newton stages
    void add(const TraceCounters& c);
};

struct TraceServiceOptions {
    bool cullBackfaces = false;  // camera rays skip back-facing subpatches (--cull-backfaces)
    bool binning = false;        // use the binning stages where a call allows them (see binningPays)
};

// One per thread (it owns the stages' scratch); many may share one RtAccel. Each ray follows its kind's
// rules (rt/ray_list.h: camera rays respect one-sided patches, shadow rays stop at any hit).
class TraceService {
  public:
    explicit TraceService(const RtAccel& acc, TraceServiceOptions opt = {}) : acc_(&acc), opt_(opt) {}

    // Binning pays unless the subpatch leaves far outnumber the camera samples. With the per-ray descent
    // of small patches (rt/binning.cpp) it is faster up to 2.85 leaves per sample (24 Big Guys, 800x600,
    // 4 spp), as fast at 5.7 and 11.4, slower at 45 and 180 (docs/rt.md).
    static double leavesPerSample(const RtAccel& acc, double samples);
    // The same for `patches` trees of `leavesPerPatch` leaves (before the accel is built).
    static double leavesPerSample(size_t patches, double leavesPerPatch, double samples) {
        return double(patches) * leavesPerPatch / std::max(1.0, samples);
    }
    static bool binningPays(double leavesPerSample) { return leavesPerSample <= 4.0; }
    // Whether the leaves' slabs (SubpatchForest::leafSlabs) pay: building one costs about 350 instructions,
    // and it saves work only on the rays that reach its leaf. Callgrind, 800x600, 4 spp, 1 thread, against
    // no slabs: the teapot (0.001 leaves per sample) -4.8% of the frame's instructions, Killeroo (0.024)
    // -3.1%, Big Guy (0.048) -2.4%, 24 Big Guys (0.18) +1.7% (its build +121 M, its trace -38 M).
    static bool leafSlabsPay(double leavesPerSample) {
        return leavesPerSample <= kLeafSlabsMaxLeavesPerSample;
    }
    static constexpr double kLeafSlabsMaxLeavesPerSample = 0.1;

    // Closest hit per ray (kShadow rays: the first accepted hit). `camera`: the rays are the camera rays
    // of these samples (then binned in screen space if binning is on).
    void trace(const RayList& rays, std::vector<RayHit>& hits, const CameraSamples* camera = nullptr);
    // Whether each ray hits anything (any hit; blocked[r] = 1), traversing per ray.
    void occluded(const RayList& rays, std::vector<uint8_t>& blocked);
    // The same for shadow rays listed light by light (`runs` cover the list): binned in each light's
    // projection if binning is on (counted in shadowListsBinned / shadowListsTraversed).
    void occluded(const RayList& rays, std::span<const ShadowRun> runs, std::vector<uint8_t>& blocked);

    TraceCounters& counters() { return c_; }
    const TraceCounters& counters() const { return c_; }
    // Bytes held by the candidate lists (memory statistics).
    size_t candidateBytes() const;

  private:
    enum class Stage { kPerRay, kCameraBinning, kShadowBinning };
    void traceList(const RayList& rays, std::vector<RayHit>& hits, bool anyHit, Stage how,
                   const CameraSamples* camera, std::span<const ShadowRun> runs);
    static void toBlocked(const std::vector<RayHit>& hits, std::vector<uint8_t>& blocked);

    const RtAccel* acc_;
    TraceServiceOptions opt_;
    std::vector<Chunk> chunks_;
    BinningScratch bin_;
    std::vector<RayHit> anyHits_;
    TraceCounters c_;
};

}  // namespace rt
}  // namespace tessera
