// The binning stages: the same candidates as the per-ray traversal (rt/traversal.h), found per box for
// many rays at once. Camera rays of a tile by screen-space binning; shadow rays light by light by binning
// in the light's projection (parallel for distant lights, central for point lights). Both descend the
// BVH and the subpatch trees once, culling boxes by their projected rectangles.
#pragma once
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "rt/accel.h"
#include "rt/ray_list.h"
#include "scene/camera.h"

namespace tessera::rt {

// A rectangle of pixels [x0, x1) x [y0, y1).
struct PixelRect {
    int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
    int width() const { return x1 - x0; }
};

// The camera rays of a grid of samples, as the screen-space binning reads them: the samples of `region`
// row by row, `spp` per pixel, each with its ray in the ray list (kNone: none) and, per sample (padded by
// 4), its raster position and its camera ray's origin (x, y; z is 0) and reciprocal direction
// (safeInverse). The rays' interval is [proj.nearClip, proj.farClip].
struct CameraSamples {
    const Projector* proj = nullptr;
    PixelRect region;
    int spp = 1;
    std::vector<uint32_t> rayOfSample;
    std::vector<float> sampleX, sampleY, originX, originY, invX, invY, invZ, dirX, dirY, dirZ;
};

// The shadow rays towards one light: a contiguous run of the shadow list.
struct ShadowRun {
    size_t begin, end;
    bool point;  // point light at `position` (else distant: the rays share one direction)
    Vec3 position;
};

struct ParallelBinning {
    std::vector<uint32_t> cellStart, cellOf;  // grid: rays of cell c are sorted[cellStart[c], cellStart[c+1])
    std::vector<uint32_t> sat;                // summed-area table of rays per cell, (g+1) x (g+1)
    std::vector<std::vector<float>> minStart;  // per level of a min pyramid over the cells: earliest start
    // Per sorted ray (padded by 4): its index and its point, origin, interval, originating patch.
    std::vector<uint32_t> ray, ignore;
    std::vector<float> px, py, ox, oy, oz, ix, iy, iz, dx, dy, dz, tmin,
        tmax;  // point, origin, 1/d, d, interval
};

// Scratch of the binning stages, reused from list to list.
struct BinningScratch {
    CandidateVector found;              // candidates in the order found
    CandidateVector roots;              // (ray, patch) pairs left to the per-ray subpatch descent
    std::vector<uint32_t> start, next;  // grouping by ray
    ParallelBinning parallel;
};

// Camera rays (`rays`, described by `cs`): their candidates into `chunks`, as traverseList would give
// them (ties in entry distance may keep another order). `cull`: skip back-facing subpatches.
void binCameraRays(const RtAccel& acc, const RayList& rays, const CameraSamples& cs, BinningScratch& bin,
                   std::vector<Chunk>& chunks, bool cull);

// Shadow rays, light by light (`runs` cover the list): their candidates into `chunks`, unordered within a
// ray (shadow rays stop at any hit). False, with `chunks` untouched, when a point light's rays surround
// it (no central projection holds them all): the caller then traverses per ray.
bool binShadowRays(const RtAccel& acc, const RayList& rays, std::span<const ShadowRun> runs,
                   BinningScratch& bin, std::vector<Chunk>& chunks);

}  // namespace tessera::rt
