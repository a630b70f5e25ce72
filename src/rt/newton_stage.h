// The Newton stage: the candidates of a ray list (from rt/traversal.h or rt/binning.h) to the closest (or
// any) hit per ray, eight starts at a time (rt/newton_lanes.h).
#pragma once
#include <vector>

#include "rt/accel.h"
#include "rt/ray_list.h"

namespace tessera::rt {

// Newton over the candidates and the closest hit per ray (a segmented minimum over each ray's
// sorted candidates; candidates whose box starts beyond the best hit so far cannot win and are skipped).
// The starts run kNewtonLanes at a time (rt/newton_lanes.h): each lane works through one ray's candidates
// in order and takes the next ray of the chunk when that ray is done, so a ray's candidates are still
// handled one after another (its early exit stays exact) while the iterations of eight rays share one
// vector step. The projection of a patch on the ray's planes is computed once per (ray, patch) run of
// candidates; a candidate whose leaf rectangle contains a root already found on the same patch for this
// ray is skipped (its start would converge to that root again); the surface derivatives are evaluated
// once per ray, at the closest hit. Results do not depend on which lane a ray runs in.
//
// Each ray follows its kind's rules (optionsFor; `cull`: --cull-backfaces for camera rays); `anyHit` makes
// every ray stop at its first accepted hit and writes only the hits' flags (occlusion queries). Runs tbb
// over the chunks.
void newtonList(const RtAccel& acc, const RayList& rays, std::vector<Chunk>& chunks,
                std::vector<RayHit>& hits, bool cull, bool anyHit = false);

}  // namespace tessera::rt
