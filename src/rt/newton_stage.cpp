#include "rt/newton_stage.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <memory>

#include "rt/newton_lanes.h"
#if defined(__SSE2__)
#include <immintrin.h>
#endif

namespace tessera::rt {

void newtonList(const RtAccel& acc, const RayList& rays, std::vector<Chunk>& chunks,
                std::vector<RayHit>& hits, bool cull, bool anyHit) {
    const size_t n = rays.size();
    const size_t nChunks = (n + kChunk - 1) / kChunk;
    // Only the flag: the rest of a RayHit is written when the ray gets one, and read only then.
    hits.resize(n);
    for (RayHit& h : hits) h.hit = false;
    float hu, hv, du, dv;
    leafHalfSize(acc.forest.depth, hu, hv);
    rootRuleReach(acc.forest.depth, du, dv);
    const Vec2* leafCentre = acc.forest.leafCentre.data();
    const LeafBasis* leafBasis = acc.forest.leafBasis.data();
    const LeafBasis* quarterBasis = acc.forest.quarterBasis.data();
    const bool motion = acc.movingPatches > 0;
    // The Newton tolerance of a patch for a ray from o (as newtonTolerance).
    auto newtonEps = [](const PatchSoa& ps, Vec3 o) {
        const float mag = std::max({ps.boxMagnitude, std::fabs(o.x), std::fabs(o.y), std::fabs(o.z)});
        return 2e-6f * mag + 1e-6f * ps.boxExtent + 1e-30f;
    };

    // The ray a lane is working on.
    struct LaneRay {
        uint32_t r = kNone;         // ray index (kNone: the lane looks for the next ray)
        uint32_t cur = 0, end = 0;  // cursor in the chunk's candidates, end of the ray's segment
        Ray ray;
        TraceOptions opt;
        const LaneRayFrame* frame = nullptr;  // the ray's planes, origin and direction for projectIntoLane
        float eps = 0.f, bestU = 0.f, bestV = 0.f;
        uint32_t projected = kNone, bestPatch = kNone;
        // Last converged root (accepted or not) per patch run, for the duplicate-start test. (A secondary
        // ray's own origin counts as such a root too: the candidate stages already left out the leaves
        // it holds, OriginLeafRule in rt/traversal.h.)
        uint32_t rootPatch = kNone;
        float rootU = 0.f, rootV = 0.f;
        int attempt = 0;  // 0: leaf centre; 1..4: quarter centres (originating patch only)
        // Originating patch: its control points' heights (X - o).n over the plane through the origin
        // orthogonal to originN (only when the ray leaves that plane: d.n > 0).
        Vec3 originN;
        bool selfPlane = false;
        bool heightsDone = false;  // selfPlane, selfHeight and selfEps are set for this ray
        float selfHeight[16];
        float selfEps = 0.f;        // the originating patch's Newton tolerance
        float selfLim = 0.f;        // heights below this cannot hold an accepted root (see belowPlane)
        bool bestHasDeriv = false;  // bestSp holds the surface at the best root (from the sides test)
        SurfacePoint bestSp;
        Vec3 bestNs;                 // a displaced micro-grid hit's shading normal (zero otherwise)
        uint32_t meshPatch = kNone;  // the displaced patch whose grid `mesh` holds
        std::shared_ptr<const DisplacedMesh> mesh;
        ProjectedPatch<float> pp;  // lane column's copy, valid when ppValid (see `projection`)
        bool ppValid = false;
        alignas(16) float depth[16];  // the control points' distances along the ray (t units)
        // Motion blur: the ray's time and, when the projected patch moves, that patch at the ray's time
        // (the Newton stage intersects it; static patches read the accel's copy).
        float time = 0.f;
        int segK = 0;  // the time's segment of the timeline and the weight in it
        float segW = 0.f;
        Vec3 inv;                 // 1 / d, for the per-time leaf box test
        bool movedPatch = false;  // the projected patch moves: movedSoa holds it at the ray's time
        PatchSoa movedSoa;
    };

    tbb::parallel_for(size_t(0), nChunks, [&](size_t ci) {
        Chunk& ch = chunks[ci];
        const size_t r0 = ci * kChunk;
        const uint32_t nRays = uint32_t(ch.segEnd.size());
        uint64_t runs = 0, iterTotal = 0, culled = 0, timeCulled = 0;
        NewtonLanes lanes;
        LaneRay lane[kNewtonLanes];
        uint32_t nextRay = 0;

        // The frames of the chunk's rays that have candidates, in ray order (beginRay takes them so),
        // eight at a time: their square roots and divisions cost a fraction of the scalar ones.
        alignas(32) float rayO[3][kChunk], rayD[3][kChunk];
        LaneRayFrame frames[kChunk];
        int nFrames = 0;
        for (uint32_t i = 0; i < nRays; ++i) {
            if ((i == 0 ? 0 : ch.segEnd[i - 1]) == ch.segEnd[i]) continue;
            const Vec3 o = rays.o[r0 + i], d = rays.d[r0 + i];
            rayO[0][nFrames] = o.x, rayO[1][nFrames] = o.y, rayO[2][nFrames] = o.z;
            rayD[0][nFrames] = d.x, rayD[1][nFrames] = d.y, rayD[2][nFrames] = d.z;
            ++nFrames;
        }
        static_assert(kChunk % 8 == 0);
        const int framesPadded = (nFrames + 7) & ~7;
        for (int k = nFrames; k < framesPadded; ++k)
            for (int a = 0; a < 3; ++a) rayO[a][k] = 0.f, rayD[a][k] = a == 2 ? 1.f : 0.f;
        makeLaneRayFrames(rayO[0], rayO[1], rayO[2], rayD[0], rayD[1], rayD[2], framesPadded, frames);
        int nextFrame = 0;

        // The patch projected on the ray's planes (as projectPatch) straight into the lane's column; the
        // Newton tolerance as newtonTolerance. The ray's copy of the projection (s.pp) is gathered from
        // the column only where a hull or domain test needs it.
        auto projectLane = [&newtonEps](const PatchSoa& ps, LaneRay& s, NewtonLanes& L, int l) {
            projectIntoLane(L, l, *s.frame, ps.x, ps.y, ps.z, s.depth);
            s.ppValid = false;
            s.eps = newtonEps(ps, s.ray.o);
        };
        auto projection = [&](LaneRay& s, int l) -> const ProjectedPatch<float>& {
            if (!s.ppValid) {
                for (int k = 0; k < 16; ++k) s.pp.a1[k] = lanes.a1[k][l], s.pp.a2[k] = lanes.a2[k][l];
                s.ppValid = true;
            }
            return s.pp;
        };
        auto finishRay = [&](LaneRay& s) {
            if (s.bestPatch != kNone && anyHit) {
                hits[s.r].hit = true;  // an any-hit query reads only the flag (TraceService::occluded)
            } else if (s.bestPatch != kNone) {
                RayHit& best = hits[s.r];
                SurfacePoint sp;
                if (s.bestHasDeriv) {
                    sp = s.bestSp;
                } else if (acc.moving(s.bestPatch)) {
                    BezierPatch moved;
                    if (s.projected == s.bestPatch)
                        soaToPatch(s.movedSoa, moved);
                    else
                        patchAtTime(acc, s.bestPatch, s.time, moved);
                    sp = evalPatchDeriv(moved, s.bestU, s.bestV);
                } else {
                    sp = evalPatchDeriv(acc.patches[s.bestPatch], s.bestU, s.bestV);
                }
                best.hit = true;
                best.patch = s.bestPatch;
                best.h.hit = true;
                best.h.t = s.ray.tmax;
                best.h.u = s.bestU;
                best.h.v = s.bestV;
                best.h.p = sp.p;
                best.h.dpdu = sp.dpdu;
                best.h.dpdv = sp.dpdv;
                best.h.ns = s.bestNs;
            }
            s.r = kNone;
        };
        auto beginRay = [&](LaneRay& s) -> bool {
            for (; nextRay < nRays; ++nextRay) {
                const uint32_t begin = nextRay == 0 ? 0 : ch.segEnd[nextRay - 1];
                if (begin == ch.segEnd[nextRay]) continue;
                const size_t r = r0 + nextRay;
                s.r = uint32_t(r);
                s.cur = begin;
                s.end = ch.segEnd[nextRay++];
                s.ray = Ray{rays.o[r], rays.d[r], rays.tmin[r], rays.tmax[r]};
                s.opt = optionsFor(rays.kind[r], rays.ignore[r], acc.offset, cull);
                s.time = rays.time[r];
                if (motion) acc.motion.segment(s.time, s.segK, s.segW), s.inv = safeInverse(s.ray.d);
                if (anyHit) s.opt.anyHit = true;
                s.frame = &frames[nextFrame++];
                s.projected = kNone, s.bestPatch = kNone, s.bestHasDeriv = false, s.bestNs = Vec3{};
                s.originN = rays.originN[r];
                s.selfPlane = false, s.heightsDone = false;
                s.rootPatch = kNone;
                return true;
            }
            return false;
        };
        // Finds lane l's next Newton start (finishing rays and taking new ones as needed) and starts it;
        // false when the chunk has no work left for the lane.
        auto startNext = [&](int l) -> bool {
            LaneRay& s = lane[l];
            for (;;) {
                if (s.r == kNone && !beginRay(s)) return false;
                if (s.cur >= s.end) {
                    finishRay(s);
                    continue;
                }
                const Candidate& c = ch.cand[s.cur];
                if (c.tEnter > s.ray.tmax) {
                    finishRay(s);
                    continue;
                }
                // A moving patch's leaf box swept over the shutter may be much larger than the leaf at
                // the ray's time: test the box at that time (lerp of the knots' boxes, exact) first.
                if (motion && acc.moving(c.patch)) {
                    float te;
                    if (!rayBox(knotLeafBox(acc.forest, acc.motion.firstKey[c.patch], s.segK, s.segW, c.leaf),
                                s.ray.o, s.inv, s.ray.tmin, s.ray.tmax, te)) {
                        ++timeCulled;
                        ++s.cur;
                        continue;
                    }
                }
                // Hits of the closed-form and triangle paths (quadrics, displaced micro-grids): not the
                // origin's own surface too close, not the back face of a one-sided surface.
                auto accept = [&](const PatchHit& ph) {
                    if (c.patch == s.opt.ignorePatch && ph.t < s.opt.ignoreT) return false;
                    if (s.opt.respectSides && !acc.twoSided[c.patch] &&
                        dot(orientedGeometricNormal(acc, c.patch, ph), s.ray.d) > 0.f)
                        return false;  // back face of a one-sided surface
                    return true;
                };
                if (const PlacedQuadric* pq = acc.quadric(c.patch)) {
                    // A quadric: the analytic hits inside this leaf's (u,v) rectangle, no Newton start.
                    float u0, u1, v0, v1;
                    subpatchLeafRect(acc.forest.depth, c.leaf, u0, u1, v0, v1);
                    PatchHit h;
                    if (intersectQuadricSurface(*pq, s.ray, u0, u1, v0, v1, accept, h)) {
                        s.bestPatch = c.patch, s.bestU = h.u, s.bestV = h.v;
                        s.bestHasDeriv = true;
                        s.bestSp = SurfacePoint{h.p, h.dpdu, h.dpdv};
                        s.bestNs = Vec3{};
                        s.ray.tmax = h.t;
                        if (s.opt.anyHit) s.cur = s.end - 1;  // shadow rays stop at the first hit
                    }
                    ++s.cur;
                    continue;
                }
                if (acc.displaced.displaced(c.patch)) {
                    // A displaced patch: the triangles of its micro-grid in this leaf (rt/displaced.h), the
                    // grid held by the lane while its ray stays on the patch (built now if not resident).
                    if (s.meshPatch != c.patch) s.mesh = acc.displaced.mesh(c.patch), s.meshPatch = c.patch;
                    const DisplacedMesh* dm = s.mesh.get();
                    PatchHit h;
                    if (intersectDisplacedLeaf(*dm, c.leaf, s.ray, makeWatertightRay(s.ray), accept, h)) {
                        s.bestPatch = c.patch, s.bestU = h.u, s.bestV = h.v;
                        s.bestHasDeriv = true;
                        s.bestSp = SurfacePoint{h.p, h.dpdu, h.dpdv};
                        s.bestNs = h.ns;
                        s.ray.tmax = h.t;
                        if (s.opt.anyHit) s.cur = s.end - 1;  // shadow rays stop at the first hit
                    }
                    ++s.cur;
                    continue;
                }
                const Vec2 c0 = leafCentre[c.leaf];
                if (c.patch == s.rootPatch && std::fabs(s.rootU - c0.x) <= du &&
                    std::fabs(s.rootV - c0.y) <= dv) {
                    ++s.cur;
                    continue;
                }
                // Leaves of the originating patch below the plane through the origin (the ray only moves
                // away from it: exact, by the convex hull of the leaf's Bernstein coefficients; this removes
                // the starts that would converge back to the origin on convex and flat parts) cannot hold a
                // root; nor can leaves below the height the ray reaches at the self-intersection distance
                // (selfLim), since roots before it are rejected. The test is repeated on the leaf's quarters
                // (its net split by de Casteljau: they bulge 4x less) when the whole leaf's net reaches
                // above. It reads the control points' heights, not the projection, so it runs before the
                // patch is projected: a ray whose candidates on its own patch all fail it never projects
                // that patch.
                auto belowPlane = [&](uint32_t leaf) {
                    float coef[16];
                    leafCoefficients(s.selfHeight, leafBasis[leaf], coef);
                    return maxCoefficient(coef) < s.selfLim || quartersMaxCoefficient(coef) < s.selfLim;
                };
                const bool ownPatch = c.patch == s.opt.ignorePatch;
                if (ownPatch && !s.heightsDone) {
                    s.heightsDone = true;
                    if (dot(s.originN, s.ray.d) > 0.f) {
                        const bool moving = motion && acc.moving(c.patch);
                        PatchSoa atTime;  // a moving patch at the ray's time (paper 002, sec. 5.3.3)
                        if (moving) patchSoaAt(acc, c.patch, s.segK, s.segW, atTime);
                        const PatchSoa& ps = moving ? atTime : acc.patchSoa[c.patch];
                        const Vec3 o = s.ray.o, nrm = s.originN;
#if defined(__SSE2__)
                        const __m128 ox = _mm_set1_ps(o.x), oy = _mm_set1_ps(o.y), oz = _mm_set1_ps(o.z),
                                     nx = _mm_set1_ps(nrm.x), ny = _mm_set1_ps(nrm.y),
                                     nz = _mm_set1_ps(nrm.z);
                        for (int k = 0; k < 16; k += 4) {  // the scalar sums below, 4 points at a time
                            const __m128 h =
                                _mm_add_ps(_mm_add_ps(_mm_mul_ps(_mm_sub_ps(_mm_load_ps(ps.x + k), ox), nx),
                                                      _mm_mul_ps(_mm_sub_ps(_mm_load_ps(ps.y + k), oy), ny)),
                                           _mm_mul_ps(_mm_sub_ps(_mm_load_ps(ps.z + k), oz), nz));
                            _mm_storeu_ps(s.selfHeight + k, h);
                        }
#else
                        for (int k = 0; k < 16; ++k)
                            s.selfHeight[k] =
                                (ps.x[k] - o.x) * nrm.x + (ps.y[k] - o.y) * nrm.y + (ps.z[k] - o.z) * nrm.z;
#endif
                        s.selfPlane = true;
                        s.selfEps = newtonEps(ps, s.ray.o);  // the patch's Newton tolerance
                        // On the ray the height is t (d.n); a root on this patch counts only from
                        // t = ignoreT, so from that height (less 4 tolerances for rounding).
                        s.selfLim = s.opt.ignoreT * dot(s.ray.d, nrm) - 4.f * s.selfEps;
                    }
                }
                if (ownPatch && s.selfPlane && belowPlane(c.leaf)) {
                    ++culled;
                    ++s.cur;
                    continue;
                }
                if (c.patch != s.projected) {
                    const PatchSoa* soa = &acc.patchSoa[c.patch];
                    s.movedPatch = motion && acc.moving(c.patch);
                    if (s.movedPatch) {  // the patch at the ray's time (paper 002, sec. 5.3.3)
                        patchSoaAt(acc, c.patch, s.segK, s.segW, s.movedSoa);
                        soa = &s.movedSoa;
                    }
                    projectLane(*soa, s, lanes, l);
                    s.projected = c.patch;
                }
                // On the ray's originating patch, leaves next to its origin converge to the origin itself
                // (rejected as self-intersection): there the ray-frame hull test of the leaf sub-patch
                // (exact: a leaf whose hull stays off the ray cannot hold a root) removes most of them. On
                // other patches it costs more than the Newton runs it saves (measured, docs/rt.md).
                if (ownPatch && !leafMayHit(projection(s, l), leafBasis[c.leaf], 4.f * s.eps)) {
                    ++culled;
                    ++s.cur;
                    continue;
                }
                s.attempt = 0;
                lanes.start(l, c0.x, c0.y, s.eps);
                return true;
            }
        };
        // Lane l's start has finished: take its root (or retry), then move the lane on. Returns whether
        // the lane still has work.
        auto finishStart = [&](int l) -> bool {
            LaneRay& s = lane[l];
            const Candidate& c = ch.cand[s.cur];
            const int iters = int(lanes.evals[l]);
            ++runs;
            iterTotal += uint32_t(iters);
            ++ch.c.hist[std::min(iters, kHistBins - 1)];
            float uc = 0.f, vc = 0.f;
            const bool found = lanes.status[l] == kLaneConverged &&
                               acceptRootDomainWith<float>(
                                   [&]() -> const ProjectedPatch<float>& { return projection(s, l); }, s.eps,
                                   lanes.u[l], lanes.v[l], 1e-4f, uc, vc);
            if (!found && c.patch == s.opt.ignorePatch) {
                // On the originating patch, where the hull test removed the neighbouring starts that could
                // also reach a root of this leaf, a failed start (a fold, a seam root just outside the
                // domain) is retried from the centres of the leaf's quarters whose own hull passes the test.
                for (int q = s.attempt; q < 4; ++q) {  // quarter q: bit 0 high u, bit 1 high v
                    if (!leafMayHit(projection(s, l), quarterBasis[4 * c.leaf + q], 4.f * s.eps)) continue;
                    const Vec2 c0 = leafCentre[c.leaf];
                    s.attempt = q + 1;
                    lanes.start(l, c0.x + (q & 1 ? 0.5f : -0.5f) * hu, c0.y + (q & 2 ? 0.5f : -0.5f) * hv,
                                s.eps);
                    return true;
                }
            }
            if (found) {
                s.rootPatch = c.patch, s.rootU = uc, s.rootV = vc;
                float bu[4], bv[4];
                bernstein3(uc, bu);
                bernstein3(vc, bv);
                float t = 0.f;
                for (int j = 0; j < 4; ++j)
                    t += bv[j] * (s.depth[4 * j] * bu[0] + s.depth[4 * j + 1] * bu[1] +
                                  s.depth[4 * j + 2] * bu[2] + s.depth[4 * j + 3] * bu[3]);
                bool ok =
                    t > s.ray.tmin && t < s.ray.tmax && !(c.patch == s.opt.ignorePatch && t < s.opt.ignoreT);
                bool haveDeriv = false;
                if (ok && s.opt.respectSides && !acc.twoSided[c.patch]) {
                    if (s.movedPatch) {
                        BezierPatch moved;
                        soaToPatch(s.movedSoa, moved);
                        s.bestSp = evalPatchDeriv(moved, uc, vc);
                    } else {
                        s.bestSp = evalPatchDeriv(acc.patches[c.patch], uc, vc);
                    }
                    haveDeriv = true;
                    Vec3 N = cross(s.bestSp.dpdu, s.bestSp.dpdv);
                    if (acc.flip[c.patch]) N = -N;
                    ok = dot(N, s.ray.d) <= 0.f;  // back face of a one-sided surface: rejected
                }
                if (ok) {
                    s.bestPatch = c.patch, s.bestU = uc, s.bestV = vc, s.bestHasDeriv = haveDeriv;
                    s.bestNs = Vec3{};
                    s.ray.tmax = t;
                    if (s.opt.anyHit) s.cur = s.end - 1;  // shadow rays stop at the first hit
                }
            }
            ++s.cur;
            return startNext(l);
        };

        unsigned active = 0;
        for (int l = 0; l < kNewtonLanes; ++l) {
            for (int k = 0; k < 16; ++k) lanes.a1[k][l] = lanes.a2[k][l] = 0.f;
            lanes.start(l, 0.5f, 0.5f, 0.f);
            if (startNext(l)) active |= 1u << l;
        }
        while (active) {
            for (unsigned done = newtonLanesStep(lanes) & active; done; done &= done - 1) {
                const int l = __builtin_ctz(done);
                if (!finishStart(l)) active &= ~(1u << l);
            }
        }
        ch.c.newtonRuns = runs;
        ch.c.hullCulled = culled;
        ch.c.timeCulled = timeCulled;
        ch.c.newtonIterations = iterTotal;
    });
}

}  // namespace tessera::rt
