// The per-ray traversal stage: candidates (Newton starts) of every ray of a list, through the 4-wide BVH
// and then all (ray, patch) pairs of a chunk down their subpatch trees level by level.
#pragma once
#include <cmath>
#include <span>
#include <vector>

#include "rt/accel.h"
#include "rt/intersect.h"
#include "rt/ray_list.h"

namespace tessera {

// The traversal's subpatch kernels use AVX2 where the CPU has it (chosen at run time; same results as the
// SSE2 kernels). allow = false forces the SSE2 kernels (tests), true allows AVX2 again; returns whether
// AVX2 kernels will run.
bool rtUseAvx2(bool allow);

namespace rt {

// Traversal of the ray list, chunk by chunk, emitting candidates. Each ray's candidates are
// emitted in depth-first order (both hierarchies, children near first, ties by index; under a BVH node its
// patches before its inner children), then sorted by entry distance (stable), so leaves come out nearly
// sorted and the order is fixed. Leaves of the ray's originating patch whose box the ray leaves before the
// self-intersection distance are not emitted: every root inside such a leaf would be rejected anyway.
//
// Per ray, the BVH's depth-first traversal lists the patches it visits (plain branches: neighbouring rays
// take the same paths). Then all (ray, patch) pairs of the chunk go down their subpatch trees together,
// level by level, two levels per 4-wide test (the odd level in between only contributes its backface bit:
// a grandchild's box lies inside its parent's, so the hit set is the same), through the quads
// (SubpatchQuad, numbered as a 4-ary heap: the children of quad q are 4q+1..4q+4). The tests of one level
// are independent and their work is branch free: the hit lanes are filtered in the SIMD mask (exit
// distance, precomputed backface bits), and all four outputs are written (the ones past the hit count land
// in scratch slots and are overwritten). Each item's hit children are appended in hit order (a table
// lookup), so every level stays grouped by pair in visit order and in depth-first order within a pair; the
// leaves' candidates of one quad are written in lane order, which the final stable sort by entry distance
// turns into the same order as hit order would. For an odd depth the nodes of the last level above the
// leaves test their two children as a pair. Where the CPU has AVX2, the whole chunk runs AVX2 code (two
// quads per 8-wide test); the results are the same.
//
// `cull`: camera rays skip back-facing subpatches (--cull-backfaces). Runs tbb over chunks of kChunk rays.
void traverseList(const RtAccel& acc, const RayList& rays, std::vector<Chunk>& chunks, bool cull);

// The Newton stage's duplicate-root rule (rt/newton_stage.h) applied where the candidate lists are
// grouped by ray: a secondary ray starts on its originating patch at a known (u,v), so its candidate in
// the leaf that holds that (u,v) (within rootRuleReach) would start Newton on the origin itself, which the
// self-intersection rules reject. Both candidate stages drop it (counted in originLeafDropped), so the
// Newton stage needs no seed for it (camera lists have no origin patch). Quadrics and displaced patches
// (no Newton start) keep theirs.
class OriginLeafRule {
  public:
    OriginLeafRule(const RtAccel& acc, const RayList& rays)
        : acc_(acc),
          ignore_(rays.ignore.data()),
          ignoreUV_(rays.ignoreUV.data()),
          leafCentre_(acc.forest.leafCentre.data()),
          special_(!acc.quadricOf.empty() || acc.displaced.patchCount() > 0) {
        rootRuleReach(acc.forest.depth, du_, dv_);
    }
    bool drops(const Candidate& c) const {
        if (c.patch != ignore_[c.ray]) return false;
        const Vec2 uv = ignoreUV_[c.ray], c0 = leafCentre_[c.leaf];
        return uv.x >= 0.f && std::fabs(uv.x - c0.x) <= du_ && std::fabs(uv.y - c0.y) <= dv_ &&
               !(special_ && (acc_.quadric(c.patch) || acc_.displaced.displaced(c.patch)));
    }
    bool mayDrop(size_t ray) const { return ignore_[ray] != kNone; }

  private:
    const RtAccel& acc_;
    const uint32_t* ignore_;
    const Vec2* ignoreUV_;
    const Vec2* leafCentre_;
    bool special_;  // the accel has quadrics or displaced patches
    float du_, dv_;
};

// The subpatch half of the traversal for (ray, patch) pairs found another way (the binning stages): each
// root candidate names a ray of `rays` whose patch's root box it hits (entry distance tEnter; its leaf is
// not read). Their leaf candidates are appended to `out`, pair by pair, each pair's as traverseList finds
// them below that patch (the same boxes, rules and self-intersection cut). The accel's own trees only:
// no instancing, no time slabs. Runs in the caller's thread. boxTests and slabCulled (leaves dropped by
// their slabs) are incremented.
void descendRootPairs(const RtAccel& acc, const RayList& rays, std::span<const Candidate> roots, bool cull,
                      CandidateVector& out, uint64_t& boxTests, uint64_t& slabCulled);

}  // namespace rt
}  // namespace tessera
