#include "rt/traversal.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <limits>

#include "rt/simd_kernels.h"

namespace tessera {
namespace rt {
namespace {

// A subpatch traversal item: a (ray, patch) pair of the current batch (bits 12 and up) and a quad of its
// tree (bits 0-11; for an odd depth also a node of the last level above the leaves, past the quads).
constexpr uint32_t kItemQuadBits = 12, kItemQuadMask = (1u << kItemQuadBits) - 1u;
constexpr uint32_t kMaxBatchPairs = 1u << (32 - kItemQuadBits);
static_assert(((1u << (2 * (kMaxSubpatchDepth / 2))) - 1) / 3 <= kItemQuadMask);  // items of every level

// out[0..3] = first + h.order[0..3] (entries past the hit count are scratch).
inline void storeItems4(uint32_t* out, const HitOrder& h, uint32_t first) {
#if defined(__SSE2__)
    int32_t ord;
    std::memcpy(&ord, h.order, 4);
    const __m128i z = _mm_setzero_si128();
    const __m128i o = _mm_unpacklo_epi16(_mm_unpacklo_epi8(_mm_cvtsi32_si128(ord), z), z);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out), _mm_add_epi32(o, _mm_set1_epi32(int(first))));
#else
    for (int i = 0; i < 4; ++i) out[i] = first + h.order[i];
#endif
}

// One patch whose root box a ray hits, and what its subpatch traversal needs.
struct PatchPair {
    F4 selfT4;  // leaves the ray exits before this distance are dropped
    const SubpatchQuad* quads;
    const uint8_t* qback;  // backface bits per quad (primary rays with culling), else null
    const uint8_t* back;   // backface bits per node (same condition)
    uint32_t rayId;        // the ray's index in the list, then the patch: its candidates' first half
    uint32_t patch;
    uint32_t ray;   // index in the chunk
    float te;       // entry distance of the root box
    uint32_t tree;  // the subpatch tree (its leaf slabs)
    uint32_t ray4;  // the ray its boxes are tested with (TraverseScratch::ray4): `ray`, or the ray moved
                    // into the frame of the prototype whose tree an instance's patch shares
};
static_assert(sizeof(PatchPair) == 64);

// Per-thread scratch of the traversal, reused from chunk to chunk.
struct TraverseScratch {
    // The chunk's rays (one per ray, in order), then the rays moved into prototype frames (instancing),
    // with the origin and inverse direction of each for the odd-depth pair step.
    std::vector<Ray4> ray4;
    std::vector<Vec3> boxO, boxInv, boxD;
    std::vector<PatchPair> pairs;
    std::vector<uint32_t, DefaultInitAllocator<uint32_t, false>> items, next;  // scratch: no huge pages
    std::vector<uint32_t> count;  // candidates per ray of the chunk
};
// One per thread, for traverseChunk and rootPairs alike (neither runs inside the other).
thread_local TraverseScratch tScratch;

// One level of the subpatch traversal: the items' quads tested, items[0, n). innerLevel appends the hit
// children of each item to `next` in hit order and returns their number; leafLevel writes the candidates
// of each item in lane order at cand + used (counted per ray in count[]) and returns the new `used`. `next`
// and `cand` need room for 4 entries per item and one more. The AVX2 versions do the same, two items per
// 8-wide test.
struct LevelIn {
    const uint32_t* items;
    uint32_t n;
    const PatchPair* pairs;
    const Ray4* ray4;
    const SubpatchForest* forest;  // its leaf slabs (leafLevel: candidates outside a leaf's slab dropped)
    uint64_t* slabCulled;          // counts them
};

inline uint32_t innerLevelTail(const LevelIn& in, uint32_t j, uint32_t* next, uint32_t nNext) {
    for (; j < in.n; ++j) {
        const uint32_t it = in.items[j], quad = it & kItemQuadMask;
        const PatchPair& pp = in.pairs[it >> kItemQuadBits];
        F4 te4, tx4;
        int mask = quadHits(pp.quads[quad], in.ray4[pp.ray4], pp.selfT4, te4, tx4);
        if (pp.qback) mask &= ~int(pp.qback[quad]);
        storeItems4(next + nNext, hitOrder(mask, te4), (it & ~kItemQuadMask) + 4 * quad + 1);
        nNext += kPop4[mask];
    }
    return nNext;
}

// The lanes of `mask` (leaves 4 g .. 4 g + 3 of the pair's tree) whose slab the pair's ray crosses inside
// their boxes (slabKeep1): all lanes when the forest has no slabs.
inline int leafSlabsKeep(const LevelIn& in, const PatchPair& pp, uint32_t g, int mask, F4 te4, F4 tx4) {
    const LeafSlab4* groups = in.forest->slabGroups(pp.tree);
    if (!groups || !mask) return mask;
#if defined(__SSE2__)
    const int keep = mask & slabKeepGroup(groups[g], in.ray4[pp.ray4], te4, tx4);
#else
    const Ray4& r = in.ray4[pp.ray4];
    int keep = 0;
    for (int i = 0; i < 4; ++i)
        if ((mask >> i & 1) && slabKeep1(groups[g], i, r.o, r.d, r.m, te4.v[i], tx4.v[i])) keep |= 1 << i;
#endif
    *in.slabCulled += kPop4[mask] - kPop4[keep];
    return keep;
}

inline size_t leafLevelTail(const LevelIn& in, uint32_t j, uint32_t leafQuadFirst, Candidate* cand,
                            size_t used, uint32_t* count) {
    for (; j < in.n; ++j) {
        const uint32_t it = in.items[j], quad = it & kItemQuadMask;
        const PatchPair& pp = in.pairs[it >> kItemQuadBits];
        F4 te4, tx4;
        int mask = quadHits(pp.quads[quad], in.ray4[pp.ray4], pp.selfT4, te4, tx4);
        if (pp.qback) mask &= ~int(pp.qback[quad]);
        mask &= leafSlabsKeep(in, pp, quad - leafQuadFirst, mask, te4, tx4);
        storeCandidates4(cand + used, kLaneOffsets[size_t(mask)], &pp.rayId, 4 * (quad - leafQuadFirst), te4);
        used += kPop4[mask];
        count[pp.ray] += kPop4[mask];
    }
    return used;
}

uint32_t innerLevel(const LevelIn& in, uint32_t* next) {
    return innerLevelTail(in, 0, next, 0);
}

size_t leafLevel(const LevelIn& in, uint32_t leafQuadFirst, Candidate* cand, size_t used, uint32_t* count) {
    return leafLevelTail(in, 0, leafQuadFirst, cand, used, count);
}

#if TESSERA_RT_AVX2
// Items j and j + 1 of a level (their patch pairs and quads), for the AVX2 loops' one 8-wide test of both.
struct ItemPair {
    uint32_t ia, qa, ib, qb;
    const PatchPair* pa;
    const PatchPair* pb;
};
inline ItemPair itemPair(const LevelIn& in, uint32_t j) {
    const uint32_t ia = in.items[j], ib = in.items[j + 1];
    return {ia,
            ia & kItemQuadMask,
            ib,
            ib & kItemQuadMask,
            &in.pairs[ia >> kItemQuadBits],
            &in.pairs[ib >> kItemQuadBits]};
}
// The 8-wide test of both items' quads against their rays, back-facing children masked: lanes 0-3 are item
// j's, 4-7 item j + 1's; te8 and tx8 get the entry and exit distances.
TESSERA_AVX2 inline int itemPairHits(const LevelIn& in, const ItemPair& p, __m256& te8, __m256& tx8) {
    const PatchPair &pa = *p.pa, &pb = *p.pb;
    int mask = quadHits2(pa.quads[p.qa], in.ray4[pa.ray4], pa.selfT4, pb.quads[p.qb], in.ray4[pb.ray4],
                         pb.selfT4, te8, tx8);
    if (pa.qback) mask &= ~int(pa.qback[p.qa]);
    if (pb.qback) mask &= ~(int(pb.qback[p.qb]) << 4);
    return mask;
}

TESSERA_AVX2 uint32_t innerLevelAvx2(const LevelIn& in, uint32_t* next) {
    uint32_t j = 0, nNext = 0;
    for (; j + 1 < in.n; j += 2) {
        const ItemPair ip = itemPair(in, j);
        __m256 te8, tx8;
        const int mask = itemPairHits(in, ip, te8, tx8);
        const HitOrder *ha, *hb;
        hitOrder2(mask, te8, ha, hb);
        storeItems4(next + nNext, *ha, (ip.ia & ~kItemQuadMask) + 4 * ip.qa + 1);
        nNext += kPop4[mask & 15];
        storeItems4(next + nNext, *hb, (ip.ib & ~kItemQuadMask) + 4 * ip.qb + 1);
        nNext += kPop4[mask >> 4];
    }
    return innerLevelTail(in, j, next, nNext);
}

TESSERA_AVX2 size_t leafLevelAvx2(const LevelIn& in, uint32_t leafQuadFirst, Candidate* cand, size_t used,
                                  uint32_t* count) {
    uint32_t j = 0;
    for (; j + 1 < in.n; j += 2) {
        const ItemPair ip = itemPair(in, j);
        const PatchPair &pa = *ip.pa, &pb = *ip.pb;
        const uint32_t qa = ip.qa, qb = ip.qb;
        __m256 te8, tx8;
        const int mask = itemPairHits(in, ip, te8, tx8);
        const __m128 tea = _mm256_castps256_ps128(te8), teb = _mm256_extractf128_ps(te8, 1);
        const int ma = (mask & 15) &
                       leafSlabsKeep(in, pa, qa - leafQuadFirst, mask & 15, tea, _mm256_castps256_ps128(tx8));
        const int mb = (mask >> 4) & leafSlabsKeep(in, pb, qb - leafQuadFirst, mask >> 4, teb,
                                                   _mm256_extractf128_ps(tx8, 1));
        storeCandidates4(cand + used, kLaneOffsets[size_t(ma)], &pa.rayId, 4 * (qa - leafQuadFirst), tea);
        used += kPop4[ma];
        count[pa.ray] += kPop4[ma];
        storeCandidates4(cand + used, kLaneOffsets[size_t(mb)], &pb.rayId, 4 * (qb - leafQuadFirst), teb);
        used += kPop4[mb];
        count[pb.ray] += kPop4[mb];
    }
    return leafLevelTail(in, j, leafQuadFirst, cand, used, count);
}
#endif

// The subpatch trees of the pairs sc.pairs (their rays' boxes in sc.ray4, sc.boxO, sc.boxInv, sc.boxD), level
// by level, in batches of pairs: the leaf candidates appended to out from index `used` in pair order (each
// pair's in depth-first order), count[pair.ray] incremented per candidate. `out`'s size is its room (grown
// without zeroing); returns the new number of candidates. All candidates of a batch are written by one
// level (the leaves' parents).
template <bool kAvx2>
[[gnu::always_inline]] inline size_t descendPairs(const RtAccel& acc, const RayList& rays,
                                                  TraverseScratch& sc, CandidateVector& out, size_t used,
                                                  uint32_t* count, uint64_t& boxTests, uint64_t& slabCulled) {
    const SubpatchForest& forest = acc.forest;
    const uint32_t firstLeaf = forest.firstLeaf();
    const uint32_t depth = uint32_t(forest.depth);
    const uint32_t nQuads = forest.quadsPerPatch;
    // Nodes of level 2 * (depth / 2) in heap numbering are 2^level - 1 + (item quad - nQuads).
    const uint32_t pairNodeBias = (1u << (2 * (depth / 2))) - 1u - nQuads;
    Candidate* cand = out.data();
    auto candRoom = [&](size_t more) {  // the vector's size is the room (no zeroing)
        if (out.capacity() < used + more) out.reserve(std::max(used + more, 2 * out.capacity()));
        out.resize(out.capacity());
        cand = out.data();
    };
    const uint32_t nPairs = uint32_t(sc.pairs.size());
    for (uint32_t pb = 0; pb < nPairs; pb += kMaxBatchPairs) {
        const uint32_t nb = std::min(kMaxBatchPairs, nPairs - pb);
        const PatchPair* pairs = sc.pairs.data() + pb;
        if (firstLeaf == 0) {
            candRoom(nb);
            for (uint32_t p = 0; p < nb; ++p) {
                cand[used++] = {pairs[p].rayId, pairs[p].patch, 0, pairs[p].te};
                ++count[pairs[p].ray];
            }
            continue;
        }
        if (sc.items.size() < nb) sc.items.resize(nb);
        for (uint32_t p = 0; p < nb; ++p) sc.items[p] = p << kItemQuadBits;
        uint32_t nItems = nb, lvl = 0;
        for (; lvl + 2 <= depth && nItems > 0; lvl += 2) {
            boxTests += 4 * uint64_t(nItems);
            const LevelIn in{sc.items.data(), nItems, pairs, sc.ray4.data(), &forest, &slabCulled};
            if (lvl + 2 < depth) {
                // Inner level: the hit children in hit order.
                if (sc.next.size() < 4 * size_t(nItems) + 4) sc.next.resize(8 * size_t(nItems) + 4);
#if TESSERA_RT_AVX2
                if constexpr (kAvx2)
                    nItems = innerLevelAvx2(in, sc.next.data());
                else
#endif
                    nItems = innerLevel(in, sc.next.data());
                std::swap(sc.items, sc.next);
                continue;
            }
            // Leaf level: the candidates of a quad in lane order (not sorted: the final stable sort by
            // entry distance gives the same order, as equal distances keep their lane order either way).
            // Quads whose grandchildren are leaves: nQuads - 4^(depth/2 - 1) .. nQuads - 1.
            const uint32_t leafQuadFirst = nQuads - (1u << (depth - 2));
            candRoom(4 * size_t(nItems) + 1);
#if TESSERA_RT_AVX2
            if constexpr (kAvx2)
                used = leafLevelAvx2(in, leafQuadFirst, cand, used, count);
            else
#endif
                used = leafLevel(in, leafQuadFirst, cand, used, count);
            nItems = 0;
        }
        // Odd depth: the pairs of leaves below the nodes of level depth - 1.
        boxTests += 2 * uint64_t(nItems);
        if (nItems > 0) candRoom(2 * size_t(nItems));
        for (uint32_t j = 0; j < nItems; ++j) {
            const uint32_t it = sc.items[j];
            const PatchPair& pp = pairs[it >> kItemQuadBits];
            const uint32_t m = 2 * ((it & kItemQuadMask) + pairNodeBias) + 1;
            const size_t r = pp.rayId;
            const PairRay pr(sc.boxO[pp.ray4], sc.boxInv[pp.ray4]);
            float tn[2], tf[2];
            const int mask =
                rayBoxPair(forest.oddLeaves.data() + (size_t(acc.tree(pp.patch)) << depth) + (m - firstLeaf),
                           pr, rays.tmin[r], rays.tmax[r], tn, tf);
            const float ta = tn[0], tb = tn[1];
            float selfT[4];
            storeF4(selfT, pp.selfT4);
            bool ha = (mask & 1) && tf[0] >= selfT[0] && !(pp.back && pp.back[m]);
            bool hb = (mask & 2) && tf[1] >= selfT[0] && !(pp.back && pp.back[m + 1]);
            if (const LeafSlab4* groups = forest.slabGroups(pp.tree); groups && (ha || hb)) {
                // The two leaves' slabs (slabKeep1), the ray as its boxes are tested.
                const uint32_t leaf = m - firstLeaf;
                const Vec3 o = sc.boxO[pp.ray4], d = sc.boxD[pp.ray4];
                const float rm = slabRayMargin(o);
                const bool ka = !ha || slabKeep1(groups[leaf >> 2], int(leaf & 3), o, d, rm, ta, tf[0]);
                const bool kb =
                    !hb || slabKeep1(groups[(leaf + 1) >> 2], int((leaf + 1) & 3), o, d, rm, tb, tf[1]);
                slabCulled += uint64_t(!ka) + uint64_t(!kb);
                ha = ha && ka, hb = hb && kb;
            }
            const bool swap = hb && (!ha || tb < ta);
            const size_t u0 = used;
            if (swap) cand[used++] = {uint32_t(r), pp.patch, m + 1 - firstLeaf, tb};
            if (ha) cand[used++] = {uint32_t(r), pp.patch, m - firstLeaf, ta};
            if (hb && !swap) cand[used++] = {uint32_t(r), pp.patch, m + 1 - firstLeaf, tb};
            count[pp.ray] += uint32_t(used - u0);
        }
    }

    return used;
}

// Whether the AVX2 kernels run: the CPU has AVX2 and rtUseAvx2 has not turned them off.
std::atomic<bool> gAvx2Allowed{true};
bool cpuHasAvx2() {
#if TESSERA_RT_AVX2
    static const bool has = __builtin_cpu_supports("avx2");
    return has;
#else
    return false;
#endif
}

// One chunk of traverseList (see there), for the SSE2 or the AVX2 kernels: inlined into the two entry
// points below, so that the AVX2 one is compiled for AVX2 throughout.
template <bool kAvx2>
[[gnu::always_inline]] inline void traverseChunk(const RtAccel& acc, const RayList& rays, Chunk& ch,
                                                 size_t ci, bool cull) {
    const size_t n = rays.size();
    const Bvh& bvh = acc.bvh;
    const SubpatchForest& forest = acc.forest;
    const float ignoreT = 8.f * acc.offset;
    const bool slabbed = forest.slabCount > 0;
    TraverseScratch& sc = tScratch;
    ch.c = StageCounters();
    uint64_t boxTests = 0;
    const size_t r0 = ci * kChunk, r1 = std::min(n, r0 + kChunk);
    const uint32_t nr = uint32_t(r1 - r0);
    sc.ray4.resize(nr);
    sc.boxO.resize(nr);
    sc.boxInv.resize(nr);
    sc.boxD.resize(nr);
    sc.count.assign(nr, 0);
    sc.pairs.clear();

    // BVH: per ray, the patches it visits (depth first; the hit children in order of entry: inner nodes
    // pushed far first, patches listed near first).
    for (uint32_t rl = 0; rl < nr; ++rl) {
        const size_t r = r0 + rl;
        sc.boxO[rl] = rays.o[r], sc.boxInv[rl] = safeInverse(rays.d[r]), sc.boxD[rl] = rays.d[r];
        sc.ray4[rl] = Ray4(rays.o[r], sc.boxInv[rl], rays.tmin[r], rays.tmax[r], rays.d[r]);
        const Ray4 r4 = sc.ray4[rl];  // (a copy: the moved rays below may grow the array)
        // Instancing: the ray moved into the frame of the last placement it met (patches of one instance
        // come together in the BVH, so one entry per instance visited, nearly).
        uint32_t lastPlacement = RtAccel::kOwnTree, lastRay4 = rl;
        const bool cullRay = cull && rays.kind[r] == kPrimary && !forest.backfacing.empty();
        const uint32_t ignore = rays.ignore[r];
        // A blurred frame's ray traverses the boxes of its time slab (SubpatchForest::slabCount).
        const int slab = slabbed ? acc.timeSlab(rays.time[r]) : 0;
        const Bvh& top = slabbed ? acc.slabBvh[size_t(slab)] : bvh;
        const Bvh4Node* wide = top.wide.data();
        uint32_t stack[kBvh4Stack];
        int sp = 0;
        if (!top.wide.empty()) stack[sp++] = 0;
        while (sp > 0) {
            const Bvh4Node& nd = wide[stack[--sp]];
            F4 te4, tx4;
            const int mask = rayBox4(nd, r4, te4, tx4);
            boxTests += nd.count;
            if (!mask) continue;
            // The hit inner children and the hit patches, each in order of entry.
            const int pb = pairBits(te4);
            const int inner = mask & int(nd.innerMask), patches = mask & ~int(nd.innerMask);
            if (inner) {
                const HitOrder& h = kHitOrder[size_t(inner | pb)];
                for (int q = kPop4[inner] - 1; q >= 0; --q) stack[sp++] = nd.child[h.order[q]];
            }
            if (!patches) continue;
            float te[4], tx[4];
            storeF4(te, te4);
            storeF4(tx, tx4);
            const HitOrder& h = kHitOrder[size_t(patches | pb)];
            for (int q = 0, k = kPop4[patches]; q < k; ++q) {
                const int i = h.order[q];
                const uint32_t patch = nd.child[i] & ~kBvh4Patch, tree = acc.tree(patch);
                const uint8_t* back = cullRay ? forest.backfaceBits(tree) : nullptr;
                const float selfT = patch == ignore ? ignoreT : -std::numeric_limits<float>::infinity();
                if (tx[i] < selfT || (back && back[0])) continue;
                uint32_t boxRay = rl;
                if (const InstancePlacement* pl = acc.placement(patch)) {
                    const uint32_t placement = acc.placementOf[patch];
                    if (placement != lastPlacement) {
                        const Vec3 o = affinePoint(pl->toPrototype, rays.o[r]);
                        const Vec3 d = affineVector(pl->toPrototype, rays.d[r]), inv = safeInverse(d);
                        lastPlacement = placement, lastRay4 = uint32_t(sc.ray4.size());
                        sc.ray4.emplace_back(o, inv, rays.tmin[r], rays.tmax[r], d);
                        sc.boxO.push_back(o), sc.boxInv.push_back(inv), sc.boxD.push_back(d);
                    }
                    boxRay = lastRay4;
                }
                sc.pairs.push_back({splatF4(selfT), forest.quadTree(tree, slab),
                                    cullRay ? forest.quadBackBits(tree) : nullptr, back, uint32_t(r), patch,
                                    rl, te[i], tree, boxRay});
            }
        }
    }

    // Subpatch trees of all pairs, level by level; candidates in pair order.
    uint64_t slabCulled = 0;
    const size_t used = descendPairs<kAvx2>(acc, rays, sc, ch.cand, 0, sc.count.data(), boxTests, slabCulled);
    Candidate* cand = ch.cand.data();

    // Per ray: its candidates less the one in its origin's leaf (OriginLeafRule), moved up over the
    // dropped ones, and their end, sorted by entry distance (stable insertion sort: short, nearly sorted).
    const OriginLeafRule originLeaf(acc, rays);
    ch.segEnd.resize(nr);
    uint32_t end = 0, kept = 0;
    for (uint32_t rl = 0; rl < nr; ++rl) {
        const uint32_t begin = end, keptBegin = kept;
        end += sc.count[rl];
        if (originLeaf.mayDrop(r0 + rl)) {
            for (uint32_t i = begin; i < end; ++i)
                if (!originLeaf.drops(cand[i])) cand[kept++] = cand[i];
        } else if (kept != begin) {
            for (uint32_t i = begin; i < end; ++i) cand[kept++] = cand[i];
        } else {
            kept = end;
        }
        ch.segEnd[rl] = kept;
        sortSegmentByEntry(cand, keptBegin, kept);
    }
    ch.c.originLeafDropped = used - kept;
    ch.cand.resize(kept);
    ch.c.candidates = kept;
    ch.c.boxTests = boxTests;
    ch.c.slabCulled = slabCulled;
}

constexpr size_t kRootBatch = 1024;

// descendRootPairs (see there) for the SSE2 or the AVX2 kernels.
template <bool kAvx2>
[[gnu::always_inline]] inline void rootPairs(const RtAccel& acc, const RayList& rays,
                                             std::span<const Candidate> roots, bool cull,
                                             CandidateVector& out, uint64_t& boxTests, uint64_t& slabCulled) {
    TraverseScratch& sc = tScratch;
    const SubpatchForest& forest = acc.forest;
    const float ignoreT = 8.f * acc.offset;
    const size_t n = rays.size();
    // Every ray of the list (a tile's camera rays or a light's shadow rays: a few thousand) with its boxes'
    // form, as traverseChunk makes it.
    sc.ray4.resize(n);
    sc.boxO.resize(n);
    sc.boxInv.resize(n);
    sc.boxD.resize(n);
    for (size_t r = 0; r < n; ++r) {
        sc.boxO[r] = rays.o[r], sc.boxInv[r] = safeInverse(rays.d[r]), sc.boxD[r] = rays.d[r];
        sc.ray4[r] = Ray4(rays.o[r], sc.boxInv[r], rays.tmin[r], rays.tmax[r], rays.d[r]);
    }
    sc.count.assign(n, 0);
    const bool canCull = cull && !forest.backfacing.empty();
    // In batches of pairs, so that the level lists and the candidates' room stay small (a tile's camera
    // rays may have 70 k roots on Big Guy; one batch took 280 k candidates' room for 70 k candidates).
    size_t used = out.size();
    for (size_t b = 0; b < roots.size(); b += kRootBatch) {
        sc.pairs.clear();
        for (const Candidate& c : roots.subspan(b, std::min(kRootBatch, roots.size() - b))) {
            const uint32_t r = c.ray, patch = c.patch;
            const bool cullRay = canCull && rays.kind[r] == kPrimary;
            const float selfT = patch == rays.ignore[r] ? ignoreT : -std::numeric_limits<float>::infinity();
            sc.pairs.push_back(
                {splatF4(selfT), forest.quadTree(patch), cullRay ? forest.quadBackBits(patch) : nullptr,
                 cullRay ? forest.backfaceBits(patch) : nullptr, r, patch, r, c.tEnter, acc.tree(patch), r});
        }
        used = descendPairs<kAvx2>(acc, rays, sc, out, used, sc.count.data(), boxTests, slabCulled);
    }
    out.resize(used);
}

void rootPairsSse2(const RtAccel& acc, const RayList& rays, std::span<const Candidate> roots, bool cull,
                   CandidateVector& out, uint64_t& boxTests, uint64_t& slabCulled) {
    rootPairs<false>(acc, rays, roots, cull, out, boxTests, slabCulled);
}
#if TESSERA_RT_AVX2
TESSERA_AVX2 void rootPairsAvx2(const RtAccel& acc, const RayList& rays, std::span<const Candidate> roots,
                                bool cull, CandidateVector& out, uint64_t& boxTests, uint64_t& slabCulled) {
    rootPairs<true>(acc, rays, roots, cull, out, boxTests, slabCulled);
}
#endif

void traverseChunkSse2(const RtAccel& acc, const RayList& rays, Chunk& ch, size_t ci, bool cull) {
    traverseChunk<false>(acc, rays, ch, ci, cull);
}
#if TESSERA_RT_AVX2
TESSERA_AVX2 void traverseChunkAvx2(const RtAccel& acc, const RayList& rays, Chunk& ch, size_t ci,
                                    bool cull) {
    traverseChunk<true>(acc, rays, ch, ci, cull);
}
#endif

}  // namespace

void traverseList(const RtAccel& acc, const RayList& rays, std::vector<Chunk>& chunks, bool cull) {
    const size_t n = rays.size();
    const size_t nChunks = (n + kChunk - 1) / kChunk;
    if (chunks.size() < nChunks) chunks.resize(nChunks);
#if TESSERA_RT_AVX2
    if (cpuHasAvx2() && gAvx2Allowed.load(std::memory_order_relaxed)) {
        tbb::parallel_for(size_t(0), nChunks,
                          [&](size_t ci) { traverseChunkAvx2(acc, rays, chunks[ci], ci, cull); });
        return;
    }
#endif
    tbb::parallel_for(size_t(0), nChunks,
                      [&](size_t ci) { traverseChunkSse2(acc, rays, chunks[ci], ci, cull); });
}

void descendRootPairs(const RtAccel& acc, const RayList& rays, std::span<const Candidate> roots, bool cull,
                      CandidateVector& out, uint64_t& boxTests, uint64_t& slabCulled) {
#if TESSERA_RT_AVX2
    if (cpuHasAvx2() && gAvx2Allowed.load(std::memory_order_relaxed))
        return rootPairsAvx2(acc, rays, roots, cull, out, boxTests, slabCulled);
#endif
    rootPairsSse2(acc, rays, roots, cull, out, boxTests, slabCulled);
}

}  // namespace rt

bool rtUseAvx2(bool allow) {
    rt::gAvx2Allowed.store(allow, std::memory_order_relaxed);
    return allow && rt::cpuHasAvx2();
}

}  // namespace tessera
