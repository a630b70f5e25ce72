#include "rt/rt_renderer.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <memory>
#include <mutex>

#include "rt/newton_lanes.h"
#if defined(__SSE2__)
#include <immintrin.h>
#endif

// The subpatch traversal has AVX2 kernels (two quads per 8-wide test), compiled for AVX2 with a target
// attribute whatever the build flags and chosen at run time when the CPU has it; SSE2 otherwise.
#if defined(__GNUC__) && defined(__x86_64__) && defined(__SSE2__)
#define TESSERA_RT_AVX2 1
#define TESSERA_AVX2 __attribute__((target("avx2")))
#else
#define TESSERA_RT_AVX2 0
#endif

namespace tessera {
namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

enum Kind : uint8_t { kPrimary = 0, kShadow = 1, kReflection = 2, kRefraction = 3, kKinds = 4 };
const char* const kKindNames[kKinds] = {"primary", "shadow", "reflection", "refraction"};
constexpr uint32_t kNone = UINT32_MAX;
constexpr size_t kChunk = 128;  // rays per parallel work item
constexpr int kHistBins = 18;   // Newton iteration counts 0..17

// Ray list, structure of arrays.
struct RayList {
    std::vector<Vec3> o, d;
    std::vector<float> tmin, tmax;
    std::vector<uint32_t> owner;   // primary/secondary: sample index in the tile; shadow: unused
    std::vector<Color> weight;     // throughput to the sample
    std::vector<uint32_t> ignore;  // originating patch (self-intersection guard)
    std::vector<Vec2> ignoreUV;    // (u,v) of the ray's origin on `ignore` (x < 0: unknown)
    // Secondary rays: the unit normal n the origin was offset along (o = P + offset n, with d.n > 0), so
    // the ray stays on the far side of the plane through o orthogonal to n; zero when unknown.
    std::vector<Vec3> originN;
    std::vector<uint8_t> kind, depth;
    size_t size() const { return o.size(); }
    void resize(size_t n) {
        o.resize(n), d.resize(n), tmin.resize(n), tmax.resize(n), owner.resize(n), weight.resize(n);
        ignore.resize(n), ignoreUV.resize(n), originN.resize(n), kind.resize(n), depth.resize(n);
    }
    void reserve(size_t n) {
        o.reserve(n), d.reserve(n), tmin.reserve(n), tmax.reserve(n), owner.reserve(n), weight.reserve(n);
        ignore.reserve(n), ignoreUV.reserve(n), originN.reserve(n), kind.reserve(n), depth.reserve(n);
    }
    void clear() {
        o.clear(), d.clear(), tmin.clear(), tmax.clear(), owner.clear(), weight.clear(), ignore.clear();
        ignoreUV.clear(), originN.clear(), kind.clear(), depth.clear();
    }
    void push(Vec3 o_, Vec3 d_, float t0, float t1, uint32_t own, Color w, uint32_t ign, uint8_t k,
              uint8_t dep, Vec2 uv = {-1.f, -1.f}, Vec3 n = {0.f, 0.f, 0.f}) {
        o.push_back(o_), d.push_back(d_), tmin.push_back(t0), tmax.push_back(t1), owner.push_back(own);
        weight.push_back(w), ignore.push_back(ign), ignoreUV.push_back(uv), originN.push_back(n);
        kind.push_back(k), depth.push_back(dep);
    }
};

// Traversal output: Newton's starting points, grouped by ray (segments sorted by box entry distance).
struct Candidate {
    uint32_t ray, patch, leaf;  // leaf: 0 .. 2^depth - 1 (its centre is Newton's start)
    float tEnter;
};

struct Counters {
    uint64_t rays[kKinds] = {}, hits[kKinds] = {};
    uint64_t candidates = 0, newtonRuns = 0, newtonIterations = 0, boxTests = 0, hullCulled = 0;
    uint64_t shadowListsBinned = 0,
             shadowListsTraversed = 0;  // shadow ray lists by how candidates were found
    std::array<uint64_t, kHistBins> hist{};
    double traversalMs = 0, newtonMs = 0, shadeMs = 0, filterMs = 0;
    void add(const Counters& c) {
        for (int k = 0; k < kKinds; ++k) rays[k] += c.rays[k], hits[k] += c.hits[k];
        candidates += c.candidates, newtonRuns += c.newtonRuns, newtonIterations += c.newtonIterations;
        boxTests += c.boxTests, hullCulled += c.hullCulled;
        shadowListsBinned += c.shadowListsBinned, shadowListsTraversed += c.shadowListsTraversed;
        for (int i = 0; i < kHistBins; ++i) hist[i] += c.hist[i];
        traversalMs += c.traversalMs, newtonMs += c.newtonMs, shadeMs += c.shadeMs, filterMs += c.filterMs;
    }
};

// One ray's candidates cand[begin, end) sorted by box entry distance, stably (insertion sort: segments are
// short and nearly sorted).
inline void sortSegmentByEntry(Candidate* cand, size_t begin, size_t end) {
    for (size_t i = begin + 1; i < end; ++i) {
        if (!(cand[i - 1].tEnter > cand[i].tEnter)) continue;
        const Candidate x = cand[i];
        size_t j = i;
        while (j > begin && cand[j - 1].tEnter > x.tEnter) {
            cand[j] = cand[j - 1];
            --j;
        }
        cand[j] = x;
    }
}

struct Chunk {
    // Written through a raw pointer by the traversal (grown without zeroing), read by index.
    std::vector<Candidate, DefaultInitAllocator<Candidate>> cand;
    std::vector<uint32_t> segEnd;  // per ray of the chunk: end of its candidates
    Counters c;                    // counters of this chunk (merged in chunk order)
};

// Per-hit shading inputs.
struct HitInfo {
    Vec3 P, N, I;
};

struct CameraBinning {
    const Projector* proj = nullptr;
    const SampleTile* tile = nullptr;
    std::vector<uint32_t> rayOfSample;  // per tile sample: its ray in the camera ray list (kNone: none)
    // Per tile sample (padded by 4): raster position, and its camera ray's origin (x, y; z is 0) and
    // reciprocal direction (safeInverse).
    std::vector<float> sampleX, sampleY, originX, originY, invX, invY, invZ;
    std::vector<Candidate> found;       // scratch: candidates in the order found
    std::vector<uint32_t> start, next;  // scratch: grouping by ray
};

struct ParallelBinning {
    std::vector<uint32_t> cellStart, cellOf;  // grid: rays of cell c are sorted[cellStart[c], cellStart[c+1])
    std::vector<uint32_t> sat;                // summed-area table of rays per cell, (g+1) x (g+1)
    std::vector<std::vector<float>> minStart;  // per level of a min pyramid over the cells: earliest start
    // Per sorted ray (padded by 4): its index and its point, origin, interval, originating patch.
    std::vector<uint32_t> ray, ignore;
    std::vector<float> px, py, ox, oy, oz, ix, iy, iz, tmin, tmax;  // point, origin, 1/direction, interval
};

// The shadow rays towards one light: a contiguous run of the shadow list.
struct ShadowRun {
    size_t begin, end;
    bool point;  // point light at `position` (else distant: the rays share one direction)
    Vec3 position;
};

struct Workspace {
    SampleTile tile;
    RayList rays, next, shadow;
    std::vector<Chunk> chunks;
    std::vector<RayHit> hits, shadowHits;
    std::vector<HitInfo> info;
    std::vector<uint32_t> shadowIdx;
    std::vector<Color> contrib;
    std::vector<uint8_t> secondaryFlags;
    std::vector<Vec3> secO, secD;
    std::vector<Color> secW;
    CameraBinning bin;
    ParallelBinning parallel;
    std::vector<ShadowRun> shadowRuns;
    Counters c;
};

TraceOptions optionsFor(uint8_t kind, uint32_t ignore, float offset, bool cull) {
    TraceOptions o;
    o.anyHit = kind == kShadow;
    o.respectSides = kind == kPrimary;
    o.cullBackfaces = kind == kPrimary && cull;
    o.ignorePatch = ignore;
    o.ignoreT = 8.f * offset;
    return o;
}

// Stack for the 4-wide BVH: each level pushes at most 3 more nodes than it pops.
constexpr int kBvh4Stack = 3 * 64 + 1;

// A ray for the 4-wide BVH test (origin, reciprocal direction and interval in all four lanes).
struct Ray4 {
#if defined(__SSE2__)
    __m128 ox, oy, oz, ix, iy, iz, t0, t1;
    Ray4() = default;
    Ray4(Vec3 o, Vec3 inv, float tmin, float tmax)
        : ox(_mm_set1_ps(o.x)),
          oy(_mm_set1_ps(o.y)),
          oz(_mm_set1_ps(o.z)),
          ix(_mm_set1_ps(inv.x)),
          iy(_mm_set1_ps(inv.y)),
          iz(_mm_set1_ps(inv.z)),
          t0(_mm_set1_ps(tmin)),
          t1(_mm_set1_ps(tmax)) {}
#else
    Vec3 o, inv;
    float tmin, tmax;
    Ray4() = default;
    Ray4(Vec3 o_, Vec3 inv_, float tmin_, float tmax_) : o(o_), inv(inv_), tmin(tmin_), tmax(tmax_) {}
#endif
};

#if defined(__SSE2__)
using F4 = __m128;
#else
struct F4 {
    float v[4];
};
#endif

// Slab test of four boxes in structure-of-arrays form (16-byte aligned): bit i set when the ray hits box
// i, with the entry and exit distances in lanes i of te, tx (same values as rayBoxInterval: no NaNs can
// occur, so the min/max are order independent).
inline int rayBox4Soa(const float (&lo)[3][4], const float (&hi)[3][4], const Ray4& r, F4& te, F4& tx) {
#if defined(__SSE2__)
    const __m128 x0 = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(lo[0]), r.ox), r.ix);
    const __m128 x1 = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(hi[0]), r.ox), r.ix);
    const __m128 y0 = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(lo[1]), r.oy), r.iy);
    const __m128 y1 = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(hi[1]), r.oy), r.iy);
    const __m128 z0 = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(lo[2]), r.oz), r.iz);
    const __m128 z1 = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(hi[2]), r.oz), r.iz);
    te = _mm_max_ps(_mm_max_ps(_mm_min_ps(x0, x1), _mm_min_ps(y0, y1)), _mm_max_ps(_mm_min_ps(z0, z1), r.t0));
    tx = _mm_min_ps(_mm_min_ps(_mm_max_ps(x0, x1), _mm_max_ps(y0, y1)), _mm_min_ps(_mm_max_ps(z0, z1), r.t1));
    return _mm_movemask_ps(_mm_cmple_ps(te, tx));
#else
    int mask = 0;
    for (int i = 0; i < 4; ++i) {
        Bounds3 b;
        b.lo = {lo[0][i], lo[1][i], lo[2][i]};
        b.hi = {hi[0][i], hi[1][i], hi[2][i]};
        if (rayBoxInterval(b, r.o, r.inv, r.tmin, r.tmax, te.v[i], tx.v[i])) mask |= 1 << i;
    }
    return mask;
#endif
}

// Lanes i of `mask` whose exit distance is not below `selfT` (the self-intersection cut: !(tx < selfT)).
inline int exitNotBelow(int mask, F4 tx, float selfT) {
#if defined(__SSE2__)
    return mask & _mm_movemask_ps(_mm_cmpnlt_ps(tx, _mm_set1_ps(selfT)));
#else
    for (int i = 0; i < 4; ++i)
        if (tx.v[i] < selfT) mask &= ~(1 << i);
    return mask;
#endif
}

// The hit lanes of a subpatch quad whose exit distance is not below selfT (lanes of selfT4; the
// self-intersection cut !(tx < selfT)), with the entry distances in te.
inline int quadHits(const SubpatchQuad& q, const Ray4& r, F4 selfT4, F4& te) {
#if defined(__SSE2__)
    const __m128 x0 = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(q.lo[0]), r.ox), r.ix);
    const __m128 x1 = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(q.hi[0]), r.ox), r.ix);
    const __m128 y0 = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(q.lo[1]), r.oy), r.iy);
    const __m128 y1 = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(q.hi[1]), r.oy), r.iy);
    const __m128 z0 = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(q.lo[2]), r.oz), r.iz);
    const __m128 z1 = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(q.hi[2]), r.oz), r.iz);
    te = _mm_max_ps(_mm_max_ps(_mm_min_ps(x0, x1), _mm_min_ps(y0, y1)), _mm_max_ps(_mm_min_ps(z0, z1), r.t0));
    const __m128 tx =
        _mm_min_ps(_mm_min_ps(_mm_max_ps(x0, x1), _mm_max_ps(y0, y1)), _mm_min_ps(_mm_max_ps(z0, z1), r.t1));
    return _mm_movemask_ps(_mm_andnot_ps(_mm_cmplt_ps(tx, selfT4), _mm_cmple_ps(te, tx)));
#else
    F4 tx;
    const int mask = rayBox4Soa(q.lo, q.hi, r, te, tx);
    return exitNotBelow(mask, tx, selfT4.v[0]);
#endif
}

inline F4 splatF4(float x) {
#if defined(__SSE2__)
    return _mm_set1_ps(x);
#else
    return F4{{x, x, x, x}};
#endif
}

inline void storeF4(float out[4], F4 v) {
#if defined(__SSE2__)
    _mm_storeu_ps(out, v);
#else
    for (int i = 0; i < 4; ++i) out[i] = v.v[i];
#endif
}

// Order of the hit lanes of a 4-wide box test by entry distance (stable: ties by lane index), from a table
// indexed by the hit mask (bits 0-3) and six pair comparisons: bits 4-7 for the pairs (0,1), (1,2),
// (2,3), (0,2) and bits 8-9 for (0,3), (1,3); the bit of a pair (a, b), a < b, is set when key[b] <
// key[a] (b goes first). Patterns no four numbers can produce still give indices in range.
struct HitOrder {
    uint8_t order[4];   // the hit lanes by rank (entries >= the hit count: 0)
    uint8_t offset[4];  // per lane: 16 * its rank (64 for a lane not hit): a byte offset into Candidate[]
};
constexpr int kHitOrderSize = 1 << 10;
constexpr std::array<HitOrder, kHitOrderSize> makeHitOrderTable() {
    std::array<HitOrder, kHitOrderSize> t{};
    constexpr int pa[6] = {0, 1, 2, 0, 0, 1}, pb[6] = {1, 2, 3, 2, 3, 3};
    for (int idx = 0; idx < kHitOrderSize; ++idx) {
        const int mask = idx & 15;
        bool bFirst[4][4] = {};  // bFirst[a][b], a < b: lane b before lane a
        for (int p = 0; p < 6; ++p) bFirst[pa[p]][pb[p]] = (idx >> (4 + p)) & 1;
        HitOrder& h = t[size_t(idx)];
        for (int i = 0; i < 4; ++i) {
            h.order[i] = 0;
            h.offset[i] = 64;
        }
        int k = 0;
        for (int i = 0; i < 4; ++i) k += (mask >> i) & 1;
        for (int i = 0; i < 4; ++i) {
            if (!((mask >> i) & 1)) continue;
            int rank = 0;
            for (int j = 0; j < 4; ++j) {
                if (j == i || !((mask >> j) & 1)) continue;
                rank += j < i ? !bFirst[j][i] : bFirst[i][j];
            }
            rank = rank < k - 1 ? rank : k - 1;
            h.order[rank] = uint8_t(i);
            h.offset[i] = uint8_t(16 * rank);
        }
    }
    return t;
}
constexpr std::array<HitOrder, kHitOrderSize> kHitOrder = makeHitOrderTable();

// The six pair comparisons of `key` that index the table (bits 4-9 of the index).
inline int pairBits(F4 key) {
#if defined(__SSE2__)
    const __m128 a = _mm_shuffle_ps(key, key, _MM_SHUFFLE(2, 3, 2, 1));  // k1 k2 k3 k2
    const __m128 b = _mm_shuffle_ps(key, key, _MM_SHUFFLE(0, 2, 1, 0));  // k0 k1 k2 k0
    const int p1 = _mm_movemask_ps(_mm_cmplt_ps(a, b));
    const int p2 = _mm_movemask_ps(_mm_cmplt_ps(_mm_shuffle_ps(key, key, _MM_SHUFFLE(3, 3, 3, 3)), key)) & 3;
    return (p1 | p2 << 4) << 4;
#else
    const float* k = key.v;
    const int p = (k[1] < k[0]) | (k[2] < k[1]) << 1 | (k[3] < k[2]) << 2 | (k[2] < k[0]) << 3 |
                  (k[3] < k[0]) << 4 | (k[3] < k[1]) << 5;
    return p << 4;
#endif
}

// The table entry for the hit lanes `mask` (at most 4 bits) ordered by `key` (no NaNs in the hit lanes).
inline const HitOrder& hitOrder(int mask, F4 key) {
    return kHitOrder[size_t(mask | pairBits(key))];
}

#if TESSERA_RT_AVX2
// quadHits for two items at once (lanes 0-3: quad a with ray a, lanes 4-7: quad b with ray b): the same
// operations lane by lane, so the same results; returns the 8-bit hit mask.
TESSERA_AVX2 inline __m256 cat2(__m128 lo, __m128 hi) {
    return _mm256_insertf128_ps(_mm256_castps128_ps256(lo), hi, 1);
}
TESSERA_AVX2 inline __m256 slab2(const float* a, const float* b, __m128 oa, __m128 ob, __m128 ia, __m128 ib) {
    return _mm256_mul_ps(_mm256_sub_ps(cat2(_mm_load_ps(a), _mm_load_ps(b)), cat2(oa, ob)), cat2(ia, ib));
}
TESSERA_AVX2 inline int quadHits2(const SubpatchQuad& qa, const Ray4& ra, __m128 sa, const SubpatchQuad& qb,
                                  const Ray4& rb, __m128 sb, __m256& te) {
    const __m256 x0 = slab2(qa.lo[0], qb.lo[0], ra.ox, rb.ox, ra.ix, rb.ix);
    const __m256 x1 = slab2(qa.hi[0], qb.hi[0], ra.ox, rb.ox, ra.ix, rb.ix);
    const __m256 y0 = slab2(qa.lo[1], qb.lo[1], ra.oy, rb.oy, ra.iy, rb.iy);
    const __m256 y1 = slab2(qa.hi[1], qb.hi[1], ra.oy, rb.oy, ra.iy, rb.iy);
    const __m256 z0 = slab2(qa.lo[2], qb.lo[2], ra.oz, rb.oz, ra.iz, rb.iz);
    const __m256 z1 = slab2(qa.hi[2], qb.hi[2], ra.oz, rb.oz, ra.iz, rb.iz);
    te = _mm256_max_ps(_mm256_max_ps(_mm256_min_ps(x0, x1), _mm256_min_ps(y0, y1)),
                       _mm256_max_ps(_mm256_min_ps(z0, z1), cat2(ra.t0, rb.t0)));
    const __m256 tx = _mm256_min_ps(_mm256_min_ps(_mm256_max_ps(x0, x1), _mm256_max_ps(y0, y1)),
                                    _mm256_min_ps(_mm256_max_ps(z0, z1), cat2(ra.t1, rb.t1)));
    return _mm256_movemask_ps(
        _mm256_andnot_ps(_mm256_cmp_ps(tx, cat2(sa, sb), _CMP_LT_OS), _mm256_cmp_ps(te, tx, _CMP_LE_OS)));
}

// hitOrder of both halves of quadHits2.
TESSERA_AVX2 inline void hitOrder2(int mask, __m256 key, const HitOrder*& ha, const HitOrder*& hb) {
    const __m256 a = _mm256_shuffle_ps(key, key, _MM_SHUFFLE(2, 3, 2, 1));
    const __m256 b = _mm256_shuffle_ps(key, key, _MM_SHUFFLE(0, 2, 1, 0));
    const int p1 = _mm256_movemask_ps(_mm256_cmp_ps(a, b, _CMP_LT_OS));
    const int p2 = _mm256_movemask_ps(
        _mm256_cmp_ps(_mm256_shuffle_ps(key, key, _MM_SHUFFLE(3, 3, 3, 3)), key, _CMP_LT_OS));
    ha = &kHitOrder[size_t((mask & 15) | (p1 & 15) << 4 | (p2 & 3) << 8)];
    hb = &kHitOrder[size_t((mask >> 4) | (p1 >> 4) << 4 | (p2 & 0x30) << 4)];
}
#endif

// Number of bits of a 4-bit mask (no popcnt instruction in the baseline x86-64 build).
constexpr uint8_t kPop4[16] = {0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4};

// Per 4-bit hit mask: the byte offset of each lane's candidate when the hit lanes are written in lane order
// (16 * the number of hit lanes before it; 64, a scratch slot, for a lane not hit).
struct LaneOffsets {
    uint8_t offset[4];
};
constexpr std::array<LaneOffsets, 16> makeLaneOffsets() {
    std::array<LaneOffsets, 16> t{};
    for (int mask = 0; mask < 16; ++mask)
        for (int i = 0, k = 0; i < 4; ++i)
            t[size_t(mask)].offset[i] = uint8_t((mask >> i) & 1 ? 16 * k++ : 64);
    return t;
}
constexpr std::array<LaneOffsets, 16> kLaneOffsets = makeLaneOffsets();

// The candidates of four leaves (leaf numbers leaf0 .. leaf0 + 3, entry distances te): lane i goes to
// byte offset h.offset[i] of out.
inline void storeCandidates4(Candidate* out, const LaneOffsets& h, const uint32_t* rayPatch, uint32_t leaf0,
                             F4 te) {
    static_assert(sizeof(Candidate) == 16 && offsetof(Candidate, leaf) == 8 &&
                  offsetof(Candidate, tEnter) == 12);
    char* base = reinterpret_cast<char*>(out);
#if defined(__SSE2__)
    const __m128 rp =
        _mm_castsi128_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(rayPatch)));  // ray patch
    const __m128 leaf =
        _mm_castsi128_ps(_mm_add_epi32(_mm_set1_epi32(int(leaf0)), _mm_setr_epi32(0, 1, 2, 3)));
    const __m128 lo = _mm_unpacklo_ps(leaf, te),
                 hi = _mm_unpackhi_ps(leaf, te);  // (l0 t0 l1 t1), (l2 t2 l3 t3)
    _mm_storeu_ps(reinterpret_cast<float*>(base + h.offset[0]), _mm_movelh_ps(rp, lo));
    _mm_storeu_ps(reinterpret_cast<float*>(base + h.offset[1]),
                  _mm_shuffle_ps(rp, lo, _MM_SHUFFLE(3, 2, 1, 0)));
    _mm_storeu_ps(reinterpret_cast<float*>(base + h.offset[2]), _mm_movelh_ps(rp, hi));
    _mm_storeu_ps(reinterpret_cast<float*>(base + h.offset[3]),
                  _mm_shuffle_ps(rp, hi, _MM_SHUFFLE(3, 2, 1, 0)));
#else
    for (int i = 0; i < 4; ++i) {
        const Candidate c{rayPatch[0], rayPatch[1], leaf0 + uint32_t(i), te.v[i]};
        std::memcpy(base + h.offset[i], &c, sizeof c);
    }
#endif
}

// The four children of a 4-wide BVH node (bits >= count cleared).
inline int rayBox4(const Bvh4Node& nd, const Ray4& r, F4& te, F4& tx) {
    return rayBox4Soa(nd.lo, nd.hi, r, te, tx) & ((1 << nd.count) - 1);
}

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
    uint32_t ray;  // index in the chunk
    float te;      // entry distance of the root box
    float selfT;
};
static_assert(sizeof(PatchPair) == 64);

// Per-thread scratch of the traversal, reused from chunk to chunk.
struct TraverseScratch {
    std::vector<Ray4> ray4;
    std::vector<PatchPair> pairs;
    std::vector<uint32_t, DefaultInitAllocator<uint32_t>> items, next;
    std::vector<uint32_t> count;  // candidates per ray of the chunk
};

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
};

inline uint32_t innerLevelTail(const LevelIn& in, uint32_t j, uint32_t* next, uint32_t nNext) {
    for (; j < in.n; ++j) {
        const uint32_t it = in.items[j], quad = it & kItemQuadMask;
        const PatchPair& pp = in.pairs[it >> kItemQuadBits];
        F4 te4;
        int mask = quadHits(pp.quads[quad], in.ray4[pp.ray], pp.selfT4, te4);
        if (pp.qback) mask &= ~int(pp.qback[quad]);
        storeItems4(next + nNext, hitOrder(mask, te4), (it & ~kItemQuadMask) + 4 * quad + 1);
        nNext += kPop4[mask];
    }
    return nNext;
}

inline size_t leafLevelTail(const LevelIn& in, uint32_t j, uint32_t leafQuadFirst, Candidate* cand,
                            size_t used, uint32_t* count) {
    for (; j < in.n; ++j) {
        const uint32_t it = in.items[j], quad = it & kItemQuadMask;
        const PatchPair& pp = in.pairs[it >> kItemQuadBits];
        F4 te4;
        int mask = quadHits(pp.quads[quad], in.ray4[pp.ray], pp.selfT4, te4);
        if (pp.qback) mask &= ~int(pp.qback[quad]);
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
TESSERA_AVX2 uint32_t innerLevelAvx2(const LevelIn& in, uint32_t* next) {
    uint32_t j = 0, nNext = 0;
    for (; j + 1 < in.n; j += 2) {
        const uint32_t ia = in.items[j], qa = ia & kItemQuadMask;
        const uint32_t ib = in.items[j + 1], qb = ib & kItemQuadMask;
        const PatchPair& pa = in.pairs[ia >> kItemQuadBits];
        const PatchPair& pb = in.pairs[ib >> kItemQuadBits];
        __m256 te8;
        int mask = quadHits2(pa.quads[qa], in.ray4[pa.ray], pa.selfT4, pb.quads[qb], in.ray4[pb.ray],
                             pb.selfT4, te8);
        if (pa.qback) mask &= ~int(pa.qback[qa]);
        if (pb.qback) mask &= ~(int(pb.qback[qb]) << 4);
        const HitOrder *ha, *hb;
        hitOrder2(mask, te8, ha, hb);
        storeItems4(next + nNext, *ha, (ia & ~kItemQuadMask) + 4 * qa + 1);
        nNext += kPop4[mask & 15];
        storeItems4(next + nNext, *hb, (ib & ~kItemQuadMask) + 4 * qb + 1);
        nNext += kPop4[mask >> 4];
    }
    return innerLevelTail(in, j, next, nNext);
}

TESSERA_AVX2 size_t leafLevelAvx2(const LevelIn& in, uint32_t leafQuadFirst, Candidate* cand, size_t used,
                                  uint32_t* count) {
    uint32_t j = 0;
    for (; j + 1 < in.n; j += 2) {
        const uint32_t ia = in.items[j], qa = ia & kItemQuadMask;
        const uint32_t ib = in.items[j + 1], qb = ib & kItemQuadMask;
        const PatchPair& pa = in.pairs[ia >> kItemQuadBits];
        const PatchPair& pb = in.pairs[ib >> kItemQuadBits];
        __m256 te8;
        int mask = quadHits2(pa.quads[qa], in.ray4[pa.ray], pa.selfT4, pb.quads[qb], in.ray4[pb.ray],
                             pb.selfT4, te8);
        if (pa.qback) mask &= ~int(pa.qback[qa]);
        if (pb.qback) mask &= ~(int(pb.qback[qb]) << 4);
        const int ma = mask & 15, mb = mask >> 4;
        storeCandidates4(cand + used, kLaneOffsets[size_t(ma)], &pa.rayId, 4 * (qa - leafQuadFirst),
                         _mm256_castps256_ps128(te8));
        used += kPop4[ma];
        count[pa.ray] += kPop4[ma];
        storeCandidates4(cand + used, kLaneOffsets[size_t(mb)], &pb.rayId, 4 * (qb - leafQuadFirst),
                         _mm256_extractf128_ps(te8, 1));
        used += kPop4[mb];
        count[pb.ray] += kPop4[mb];
    }
    return leafLevelTail(in, j, leafQuadFirst, cand, used, count);
}
#endif

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
    const uint32_t firstLeaf = forest.firstLeaf();
    const uint32_t depth = uint32_t(forest.depth);
    const float ignoreT = 8.f * acc.offset;
    const uint32_t nQuads = forest.quadsPerPatch;
    // Nodes of level 2 * (depth / 2) in heap numbering are 2^level - 1 + (item quad - nQuads).
    const uint32_t pairNodeBias = (1u << (2 * (depth / 2))) - 1u - nQuads;
    const Bvh4Node* wide = bvh.wide.data();
    thread_local TraverseScratch scratch;
    TraverseScratch& sc = scratch;
    ch.c = Counters();
    uint64_t boxTests = 0;
    const size_t r0 = ci * kChunk, r1 = std::min(n, r0 + kChunk);
    const uint32_t nr = uint32_t(r1 - r0);
    sc.ray4.resize(nr);
    sc.count.assign(nr, 0);
    sc.pairs.clear();

    // BVH: per ray, the patches it visits (depth first; the hit children in order of entry: inner nodes
    // pushed far first, patches listed near first).
    for (uint32_t rl = 0; rl < nr; ++rl) {
        const size_t r = r0 + rl;
        sc.ray4[rl] = Ray4(rays.o[r], safeInverse(rays.d[r]), rays.tmin[r], rays.tmax[r]);
        const Ray4& r4 = sc.ray4[rl];
        const bool cullRay = cull && rays.kind[r] == kPrimary && !forest.backfacing.empty();
        const uint32_t ignore = rays.ignore[r];
        uint32_t stack[kBvh4Stack];
        int sp = 0;
        if (!bvh.wide.empty()) stack[sp++] = 0;
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
                const uint32_t patch = nd.child[i] & ~kBvh4Patch;
                const uint8_t* back = cullRay ? forest.backfaceBits(patch) : nullptr;
                const float selfT = patch == ignore ? ignoreT : -std::numeric_limits<float>::infinity();
                if (tx[i] < selfT || (back && back[0])) continue;
                sc.pairs.push_back({splatF4(selfT), forest.quadTree(patch),
                                    cullRay ? forest.quadBackBits(patch) : nullptr, back, uint32_t(r), patch,
                                    rl, te[i], selfT});
            }
        }
    }

    // Subpatch trees of all pairs, level by level, in batches of pairs; candidates in pair order. All
    // candidates of a batch are written by one level (the leaves' parents).
    const uint32_t nPairs = uint32_t(sc.pairs.size());
    Candidate* cand = nullptr;
    size_t used = 0;
    auto candRoom = [&](size_t more) {  // the vector's size is the room (no zeroing)
        if (ch.cand.capacity() < used + more) ch.cand.reserve(std::max(used + more, 2 * ch.cand.capacity()));
        ch.cand.resize(ch.cand.capacity());
        cand = ch.cand.data();
    };
    for (uint32_t pb = 0; pb < nPairs; pb += kMaxBatchPairs) {
        const uint32_t nb = std::min(kMaxBatchPairs, nPairs - pb);
        const PatchPair* pairs = sc.pairs.data() + pb;
        if (firstLeaf == 0) {
            candRoom(nb);
            for (uint32_t p = 0; p < nb; ++p) {
                cand[used++] = {uint32_t(r0) + pairs[p].ray, pairs[p].patch, 0, pairs[p].te};
                ++sc.count[pairs[p].ray];
            }
            continue;
        }
        if (sc.items.size() < nb) sc.items.resize(nb);
        for (uint32_t p = 0; p < nb; ++p) sc.items[p] = p << kItemQuadBits;
        uint32_t nItems = nb, lvl = 0;
        for (; lvl + 2 <= depth && nItems > 0; lvl += 2) {
            boxTests += 4 * uint64_t(nItems);
            const LevelIn in{sc.items.data(), nItems, pairs, sc.ray4.data()};
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
                used = leafLevelAvx2(in, leafQuadFirst, cand, used, sc.count.data());
            else
#endif
                used = leafLevel(in, leafQuadFirst, cand, used, sc.count.data());
            nItems = 0;
        }
        // Odd depth: the pairs of leaves below the nodes of level depth - 1.
        boxTests += 2 * uint64_t(nItems);
        if (nItems > 0) candRoom(2 * size_t(nItems));
        for (uint32_t j = 0; j < nItems; ++j) {
            const uint32_t it = sc.items[j];
            const PatchPair& pp = pairs[it >> kItemQuadBits];
            const uint32_t m = 2 * ((it & kItemQuadMask) + pairNodeBias) + 1;
            const size_t r = r0 + pp.ray;
            const PairRay pr(rays.o[r], safeInverse(rays.d[r]));
            float tn[2], tf[2];
            const int mask = rayBoxPair(forest.tree(pp.patch) + m, pr, rays.tmin[r], rays.tmax[r], tn, tf);
            const float ta = tn[0], tb = tn[1];
            const bool ha = (mask & 1) && tf[0] >= pp.selfT && !(pp.back && pp.back[m]);
            const bool hb = (mask & 2) && tf[1] >= pp.selfT && !(pp.back && pp.back[m + 1]);
            const bool swap = hb && (!ha || tb < ta);
            const size_t u0 = used;
            if (swap) cand[used++] = {uint32_t(r), pp.patch, m + 1 - firstLeaf, tb};
            if (ha) cand[used++] = {uint32_t(r), pp.patch, m - firstLeaf, ta};
            if (hb && !swap) cand[used++] = {uint32_t(r), pp.patch, m + 1 - firstLeaf, tb};
            sc.count[pp.ray] += uint32_t(used - u0);
        }
    }

    // Per ray: the end of its candidates, sorted by entry distance (stable insertion sort: short,
    // nearly sorted).
    ch.segEnd.resize(nr);
    uint32_t end = 0;
    for (uint32_t rl = 0; rl < nr; ++rl) {
        const uint32_t begin = end;
        end += sc.count[rl];
        ch.segEnd[rl] = end;
        sortSegmentByEntry(cand, begin, end);
    }
    ch.cand.resize(used);
    ch.c.candidates = used;
    ch.c.boxTests = boxTests;
}

void traverseChunkSse2(const RtAccel& acc, const RayList& rays, Chunk& ch, size_t ci, bool cull) {
    traverseChunk<false>(acc, rays, ch, ci, cull);
}
#if TESSERA_RT_AVX2
TESSERA_AVX2 void traverseChunkAvx2(const RtAccel& acc, const RayList& rays, Chunk& ch, size_t ci,
                                    bool cull) {
    traverseChunk<true>(acc, rays, ch, ci, cull);
}
#endif

// Stage 1: traversal of the ray list, chunk by chunk, emitting candidates. Each ray's candidates are
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

// The candidates of a binning stage, found in any order, grouped by ray (counting sort, stable) with each
// ray's candidates sorted by entry distance (stable), in the chunks of kChunk rays the Newton stage
// expects (the traversal's output format). `start`, `next`: scratch.
void groupCandidates(const std::vector<Candidate>& found, size_t n, std::vector<uint32_t>& start,
                     std::vector<uint32_t>& next, std::vector<Chunk>& chunks, uint64_t boxTests,
                     bool sortByEntry = true) {
    const size_t nChunks = (n + kChunk - 1) / kChunk;
    if (chunks.size() < nChunks) chunks.resize(nChunks);
    // start[r]: first candidate of ray r; start[n]: total
    start.assign(n + 1, 0);
    for (const Candidate& c : found) ++start[c.ray + 1];
    for (size_t r = 0; r < n; ++r) start[r + 1] += start[r];
    next.assign(start.begin(), start.end() - 1);
    for (size_t ci = 0; ci < nChunks; ++ci) {
        Chunk& ch = chunks[ci];
        const size_t r0 = ci * kChunk, r1 = std::min(n, r0 + kChunk);
        ch.cand.resize(start[r1] - start[r0]);
        ch.segEnd.resize(r1 - r0);
        for (size_t r = r0; r < r1; ++r) ch.segEnd[r - r0] = start[r + 1] - start[r0];
        ch.c = Counters();
        ch.c.candidates = ch.cand.size();
    }
    if (nChunks > 0) chunks[0].c.boxTests = boxTests;
    for (const Candidate& c : found) {
        const size_t ci = c.ray / kChunk;
        chunks[ci].cand[next[c.ray]++ - start[ci * kChunk]] = c;
    }
    if (!sortByEntry) return;
    for (size_t ci = 0; ci < nChunks; ++ci) {
        Candidate* cd = chunks[ci].cand.data();
        const size_t r0 = ci * kChunk, r1 = std::min(n, r0 + kChunk);
        for (size_t r = r0; r < r1; ++r)
            sortSegmentByEntry(cd, start[r] - start[r0], start[r + 1] - start[r0]);
    }
}

// Camera rays: the traversal stage by screen-space binning. A camera ray passes through its sample's
// raster position, so it can only hit a box whose projection contains that position. The tile's region is
// tested against the projected bounding rectangles of the 4-wide BVH's boxes and of the subpatch boxes,
// top down, and each leaf box is slab-tested (the traversal's arithmetic) only against the rays of the
// samples inside its rectangle. A ray hits a leaf box only if it hits every box above it (they contain
// it), so the candidates are exactly the traversal's, found once per tile and box instead of once per
// ray and box; ties in entry distance keep this stage's order instead of the traversal's.

// Raster rectangle containing the projection of box b, grown for rounding (the rays' own raster
// positions are rounded too); false when the box reaches behind the eye (no finite rectangle).
// For each 4-bit mask, its set lanes in increasing order, then the unset ones (a compress table).
constexpr std::array<std::array<uint8_t, 4>, 16> makeCompressLanes() {
    std::array<std::array<uint8_t, 4>, 16> t{};
    for (int m = 0; m < 16; ++m) {
        int k = 0;
        for (int l = 0; l < 4; ++l)
            if (m & (1 << l)) t[m][k++] = uint8_t(l);
        for (int l = 0; l < 4; ++l)
            if (!(m & (1 << l))) t[m][k++] = uint8_t(l);
    }
    return t;
}
constexpr std::array<std::array<uint8_t, 4>, 16> kCompressLanes = makeCompressLanes();
constexpr uint8_t kPopCount[16] = {0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4};  // no popcnt in x86-64 v1

// Shared by the two binning stages.
// A box's projected rectangle (clipped), as the binning stages pass it down.
struct Rect2 {
    float x0, x1, y0, y1;
};

// Visits the leaf boxes of every patch top down, through the 4-wide BVH and then each subpatch tree,
// children in increasing `nearKey(box)` (so each ray's candidates come out nearly sorted), dropping every
// box that `overlaps(box, rect)` rejects (it also yields the box's clipped rectangle) and every subpatch
// node that `skip(patch, node)` rejects; `leaf(patch, node, box, rect)` gets the rest.
template <class NearKey, class Overlaps, class Skip, class Leaf>
void descendCulled(const RtAccel& acc, NearKey&& nearKey, Overlaps&& overlaps, Skip&& skip, Leaf&& leaf) {
    const SubpatchForest& forest = acc.forest;
    const uint32_t firstLeaf = forest.firstLeaf();
    auto visitPatch = [&](uint32_t patch) {
        const Bounds3* tree = forest.tree(patch);
        uint32_t stack[64];
        int sp = 0;
        stack[sp++] = 0;
        while (sp > 0) {
            const uint32_t n = stack[--sp];
            if (skip(patch, n)) continue;
            Rect2 rect;
            if (!overlaps(tree[n], rect)) continue;
            if (n >= firstLeaf) {
                leaf(patch, n, tree[n], rect);
                continue;
            }
            const bool lowFirst = nearKey(tree[2 * n + 1]) <= nearKey(tree[2 * n + 2]);
            stack[sp++] = lowFirst ? 2 * n + 2 : 2 * n + 1;
            stack[sp++] = lowFirst ? 2 * n + 1 : 2 * n + 2;
        }
    };
    uint32_t stack[kBvh4Stack];
    int sp = 0;
    if (!acc.bvh.wide.empty()) stack[sp++] = 0;
    while (sp > 0) {
        const Bvh4Node& nd = acc.bvh.wide[stack[--sp]];
        Bounds3 box[4];
        float key[4];
        uint32_t order[4] = {0, 1, 2, 3};
        for (uint32_t c = 0; c < nd.count; ++c) {
            box[c].lo = {nd.lo[0][c], nd.lo[1][c], nd.lo[2][c]};
            box[c].hi = {nd.hi[0][c], nd.hi[1][c], nd.hi[2][c]};
            key[c] = nearKey(box[c]);
        }
        for (uint32_t i = 1; i < nd.count; ++i)
            for (uint32_t j = i; j > 0 && key[order[j]] < key[order[j - 1]]; --j)
                std::swap(order[j], order[j - 1]);
        // Patches are visited in this order; inner nodes are pushed far first.
        uint32_t inner[4], nInner = 0;
        for (uint32_t k = 0; k < nd.count; ++k) {
            const uint32_t c = order[k];
            Rect2 rect;
            if (!overlaps(box[c], rect)) continue;
            if (nd.child[c] & kBvh4Patch)
                visitPatch(nd.child[c] & ~kBvh4Patch);
            else
                inner[nInner++] = nd.child[c];
        }
        while (nInner > 0) stack[sp++] = inner[--nInner];
    }
}

#if defined(__SSE2__)
// One leaf box against four rays (origin, reciprocal direction and interval per lane), lane for lane
// the arithmetic of rayBoxInterval, with the rays' projected points inside the box's rectangle: the
// lanes that hit (bit mask) and their entry distances.
struct LeafBox4 {
    __m128 lox, loy, loz, hix, hiy, hiz, x0, x1, y0, y1;
    LeafBox4(const Bounds3& b, const Rect2& r)
        : lox(_mm_set1_ps(b.lo.x)),
          loy(_mm_set1_ps(b.lo.y)),
          loz(_mm_set1_ps(b.lo.z)),
          hix(_mm_set1_ps(b.hi.x)),
          hiy(_mm_set1_ps(b.hi.y)),
          hiz(_mm_set1_ps(b.hi.z)),
          x0(_mm_set1_ps(r.x0)),
          x1(_mm_set1_ps(r.x1)),
          y0(_mm_set1_ps(r.y0)),
          y1(_mm_set1_ps(r.y1)) {}
};
inline __m128 leafBox4Hits(const LeafBox4& b, __m128 px, __m128 py, __m128 ox, __m128 oy, __m128 oz,
                           __m128 ix, __m128 iy, __m128 iz, __m128 t0, __m128 t1, __m128& te, __m128& tx) {
    const __m128 ax = _mm_mul_ps(_mm_sub_ps(b.lox, ox), ix), bx = _mm_mul_ps(_mm_sub_ps(b.hix, ox), ix);
    const __m128 ay = _mm_mul_ps(_mm_sub_ps(b.loy, oy), iy), by = _mm_mul_ps(_mm_sub_ps(b.hiy, oy), iy);
    const __m128 az = _mm_mul_ps(_mm_sub_ps(b.loz, oz), iz), bz = _mm_mul_ps(_mm_sub_ps(b.hiz, oz), iz);
    te = _mm_max_ps(_mm_max_ps(_mm_min_ps(ax, bx), _mm_min_ps(ay, by)), _mm_max_ps(_mm_min_ps(az, bz), t0));
    tx = _mm_min_ps(_mm_min_ps(_mm_max_ps(ax, bx), _mm_max_ps(ay, by)), _mm_min_ps(_mm_max_ps(az, bz), t1));
    const __m128 inside = _mm_and_ps(_mm_and_ps(_mm_cmpge_ps(px, b.x0), _mm_cmple_ps(px, b.x1)),
                                     _mm_and_ps(_mm_cmpge_ps(py, b.y0), _mm_cmple_ps(py, b.y1)));
    return _mm_and_ps(_mm_cmple_ps(te, tx), inside);
}
// The candidates of the lanes in `mask` to out[0..], compressed (four written, their count returned).
inline size_t emitLanes(Candidate* out, int mask, __m128 te, const uint32_t* rayOfLane, uint32_t patch,
                        uint32_t leaf) {
    alignas(16) float tev[4];
    _mm_store_ps(tev, te);
    for (int j = 0; j < 4; ++j) {
        const int l = kCompressLanes[mask][j];
        out[j] = {rayOfLane[l], patch, leaf, tev[l]};
    }
    return kPopCount[mask];
}
#endif

inline bool screenRect(const Projector& proj, const Bounds3& b, float& x0, float& x1, float& y0, float& y1) {
    x0 = y0 = INFINITY, x1 = y1 = -INFINITY;
    for (int c = 0; c < 8; ++c) {
        const Vec3 p{c & 1 ? b.hi.x : b.lo.x, c & 2 ? b.hi.y : b.lo.y, c & 4 ? b.hi.z : b.lo.z};
        if (proj.perspective && !(p.z > 0.f)) return false;
        const Vec3 r = proj.toRaster(p);
        x0 = std::min(x0, r.x), x1 = std::max(x1, r.x), y0 = std::min(y0, r.y), y1 = std::max(y1, r.y);
    }
    const float m = 1e-2f + 1e-5f * std::max({std::fabs(x0), std::fabs(x1), std::fabs(y0), std::fabs(y1)});
    x0 -= m, x1 += m, y0 -= m, y1 += m;
    return std::isfinite(x0) && std::isfinite(x1) && std::isfinite(y0) && std::isfinite(y1);
}

void binCameraRays(const RtAccel& acc, const RayList& rays, CameraBinning& bin, std::vector<Chunk>& chunks,
                   bool cull) {
    const Projector& proj = *bin.proj;
    const SampleTile& tile = *bin.tile;
    const Rect reg = tile.region;
    const int tw = reg.width(), spp = tile.spp;
    const float rx0 = float(reg.x0), rx1 = float(reg.x1), ry0 = float(reg.y0), ry1 = float(reg.y1);
    const SubpatchForest& forest = acc.forest;
    const uint32_t firstLeaf = forest.firstLeaf();
    const bool useBack = cull && !forest.backfacing.empty();
    std::vector<Candidate>& found = bin.found;
    found.clear();
    uint64_t boxTests = 0;

    // Whether the rectangle of box b can hold a sample of the tile, and the rectangle clipped to the
    // region (the whole region when the box reaches behind the eye).
    auto overlaps = [&](const Bounds3& b, Rect2& rect) {
        if (!screenRect(proj, b, rect.x0, rect.x1, rect.y0, rect.y1)) {
            rect = {rx0, rx1, ry0, ry1};
            return true;
        }
        rect = {std::max(rect.x0, rx0), std::min(rect.x1, rx1), std::max(rect.y0, ry0),
                std::min(rect.y1, ry1)};
        return rect.x0 <= rect.x1 && rect.y0 <= rect.y1;
    };
    // The rays of the samples inside the rectangle against one leaf box, four samples of a row at a time
    // (per-sample structure of arrays; camera rays start at z = 0).
    const float tmin = proj.nearClip, tmax = proj.farClip;
    auto testLeaf = [&](uint32_t patch, uint32_t node, const Bounds3& box, const Rect2& rect) {
        const int px0 = std::max(reg.x0, int(std::floor(rect.x0))),
                  px1 = std::min(reg.x1 - 1, int(std::floor(rect.x1)));
        const int py0 = std::max(reg.y0, int(std::floor(rect.y0))),
                  py1 = std::min(reg.y1 - 1, int(std::floor(rect.y1)));
        if (px0 > px1 || py0 > py1) return;
        const uint32_t leaf = node - firstLeaf;
        // Room for every sample of the rectangle's rows plus a full group of 4 (trimmed at the end).
        size_t k = found.size();
        found.resize(k + size_t(px1 - px0 + 1) * size_t(py1 - py0 + 1) * size_t(spp) + 4);
#if defined(__SSE2__)
        const LeafBox4 b4(box, rect);
        const __m128 t0 = _mm_set1_ps(tmin), t1 = _mm_set1_ps(tmax), zero = _mm_setzero_ps();
#endif
        for (int py = py0; py <= py1; ++py) {
            const size_t rowBase = (size_t(py - reg.y0) * tw + size_t(px0 - reg.x0)) * spp;
            const size_t rowEnd = rowBase + size_t(px1 - px0 + 1) * spp;
            boxTests += rowEnd - rowBase;
#if defined(__SSE2__)
            for (size_t i = rowBase; i < rowEnd; i += 4) {
                __m128 te, tx;
                const __m128 hit =
                    leafBox4Hits(b4, _mm_loadu_ps(&bin.sampleX[i]), _mm_loadu_ps(&bin.sampleY[i]),
                                 _mm_loadu_ps(&bin.originX[i]), _mm_loadu_ps(&bin.originY[i]), zero,
                                 _mm_loadu_ps(&bin.invX[i]), _mm_loadu_ps(&bin.invY[i]),
                                 _mm_loadu_ps(&bin.invZ[i]), t0, t1, te, tx);
                int mask = _mm_movemask_ps(hit);
                if (rowEnd - i < 4) mask &= (1 << (rowEnd - i)) - 1;
                if (mask) k += emitLanes(found.data() + k, mask, te, &bin.rayOfSample[i], patch, leaf);
            }
#else
            for (size_t i = rowBase; i < rowEnd; ++i) {
                const uint32_t ray = bin.rayOfSample[i];
                const float x = bin.sampleX[i], y = bin.sampleY[i];
                if (ray == kNone || !(x >= rect.x0 && x <= rect.x1 && y >= rect.y0 && y <= rect.y1)) continue;
                float te, tx;
                if (rayBoxInterval(box, rays.o[ray], safeInverse(rays.d[ray]), tmin, tmax, te, tx))
                    found[k++] = {ray, patch, leaf, te};
            }
#endif
        }
        found.resize(k);
    };
    // Nearer boxes (smaller depth) first; back-facing subpatch nodes skipped (--cull-backfaces).
    descendCulled(
        acc, [](const Bounds3& b) { return b.lo.z; }, overlaps,
        [&](uint32_t patch, uint32_t n) {
            const uint8_t* back = useBack ? forest.backfaceBits(patch) : nullptr;
            return back && back[n];
        },
        testLeaf);

    groupCandidates(found, rays.size(), bin.start, bin.next, chunks, boxTests);
}

// Rays that share one direction (shadow rays towards a distant light): the traversal stage by binning
// in the plane orthogonal to the direction. A ray projects to a point there, and it can only hit a box
// whose projection contains that point, so the rays' points are sorted into a grid, the BVH and subpatch
// boxes are culled top down by their projected bounding rectangles against the points' bounds, and each
// leaf box is slab-tested (the traversal's arithmetic, with its self-intersection cut) against the rays
// in the grid cells its rectangle covers. Candidates are the traversal's; appended to `found` unordered.

bool binParallelRays(const RtAccel& acc, const RayList& rays, size_t r0, size_t r1, ParallelBinning& pb,
                     std::vector<Candidate>& found, uint64_t& boxTests, const Vec3* light = nullptr) {
    const size_t n = r1 - r0;
    if (n == 0) return true;
    // Projection: along the shared direction, or (point light) centrally from the light onto a plane
    // orthogonal to the mean direction from the light to the origins. Every point of a shadow ray lies
    // on the segment from its origin towards the light, so it projects to the origin's point.
    const Vec3 C = light ? *light : Vec3{0, 0, 0};
    Vec3 w;
    if (light) {
        Vec3 sum{0, 0, 0};
        for (size_t r = r0; r < r1; ++r) sum += normalize(rays.o[r] - C);
        w = normalize(sum);
        // Every origin well in front of the light's plane (else: the per-ray traversal).
        for (size_t r = r0; r < r1; ++r) {
            const Vec3 q = rays.o[r] - C;
            if (!(dot(w, q) > 0.05f * length(q))) return false;
        }
    } else {
        w = normalize(rays.d[r0]);
    }
    if (!isFinite(w) || dot(w, w) == 0.f) return false;
    const Vec3 a = std::fabs(w.x) > 0.9f ? Vec3{0, 1, 0} : Vec3{1, 0, 0};
    const Vec3 eu = normalize(cross(a, w)), ev = cross(w, eu);
    auto project = [&](Vec3 x, float& px, float& py) {
        if (light) {
            const Vec3 q = x - C;
            const float iz = 1.f / dot(w, q);
            px = dot(eu, q) * iz, py = dot(ev, q) * iz;
        } else {
            px = dot(eu, x), py = dot(ev, x);
        }
    };
    // Points and their bounds; the grid: about 4 rays per cell.
    float x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
    for (size_t r = r0; r < r1; ++r) {
        float x, y;
        project(rays.o[r], x, y);
        x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
    }
    if (!(std::isfinite(x0) && std::isfinite(x1) && std::isfinite(y0) && std::isfinite(y1))) return false;
    const int g = std::clamp(int(std::sqrt(double(n) / 4.0)), 1, 1024);
    const float cw = std::max((x1 - x0) / float(g), 1e-30f), ch = std::max((y1 - y0) / float(g), 1e-30f);
    auto cellX = [&](float x) { return int(std::clamp((x - x0) / cw, 0.f, float(g - 1))); };
    auto cellY = [&](float y) { return int(std::clamp((y - y0) / ch, 0.f, float(g - 1))); };
    pb.cellStart.assign(size_t(g) * g + 1, 0);
    pb.cellOf.resize(n);
    for (size_t r = r0; r < r1; ++r) {
        float x, y;
        project(rays.o[r], x, y);
        const uint32_t c = uint32_t(cellY(y) * g + cellX(x));
        pb.cellOf[r - r0] = c;
        ++pb.cellStart[c + 1];
    }
    // Summed-area table of the rays per cell: a box whose rectangle covers no ray is culled at once
    // (a tile's points often form separate clusters in the light's view).
    pb.sat.assign(size_t(g + 1) * (g + 1), 0);
    for (int cy = 0; cy < g; ++cy)
        for (int cx = 0; cx < g; ++cx)
            pb.sat[size_t(cy + 1) * (g + 1) + cx + 1] =
                pb.cellStart[size_t(cy) * g + cx + 1] + pb.sat[size_t(cy) * (g + 1) + cx + 1] +
                pb.sat[size_t(cy + 1) * (g + 1) + cx] - pb.sat[size_t(cy) * (g + 1) + cx];
    for (size_t c = 0; c < size_t(g) * g; ++c) pb.cellStart[c + 1] += pb.cellStart[c];
    for (auto* v : {&pb.px, &pb.py, &pb.ox, &pb.oy, &pb.oz, &pb.ix, &pb.iy, &pb.iz, &pb.tmin, &pb.tmax})
        v->assign(n + 4, 0.f);
    std::fill(pb.px.begin() + n, pb.px.end(), NAN);  // padding: never inside a rectangle
    pb.ray.assign(n + 4, 0), pb.ignore.assign(n + 4, kNone);
    {
        std::vector<uint32_t>& next = pb.cellOf;  // reused: cell -> next slot, after reading the cell
        std::vector<uint32_t> slot(pb.cellStart.begin(), pb.cellStart.end() - 1);
        for (size_t r = r0; r < r1; ++r) {
            const uint32_t s = slot[next[r - r0]]++;
            const Vec3 o = rays.o[r];
            const Vec3 inv = safeInverse(rays.d[r]);
            pb.ray[s] = uint32_t(r), pb.ignore[s] = rays.ignore[r];
            project(o, pb.px[s], pb.py[s]);
            pb.ox[s] = o.x, pb.oy[s] = o.y, pb.oz[s] = o.z;
            pb.ix[s] = inv.x, pb.iy[s] = inv.y, pb.iz[s] = inv.z;
            pb.tmin[s] = rays.tmin[r], pb.tmax[s] = rays.tmax[r];
        }
    }
    // Where each ray starts along its way (increasing towards the light): a box entirely before the
    // starts of all the rays in its rectangle cannot be hit. Per cell the smallest start, and a min
    // pyramid over the cells (2x2 blocks per level) for rectangles of any size.
    auto startOf = [&](Vec3 p) { return light ? -dot(w, p - C) : dot(w, p); };
    pb.minStart.assign(1, std::vector<float>(size_t(g) * g, INFINITY));
    for (size_t s = 0; s < n; ++s) {
        const uint32_t c = uint32_t(cellY(pb.py[s]) * g + cellX(pb.px[s]));
        float& m = pb.minStart[0][c];
        m = std::min(m, startOf(Vec3{pb.ox[s], pb.oy[s], pb.oz[s]}));
    }
    for (int gk = g; gk > 1;) {
        const int gn = (gk + 1) / 2;
        const std::vector<float>& lower = pb.minStart.back();
        std::vector<float> upper(size_t(gn) * gn, INFINITY);
        for (int y = 0; y < gk; ++y)
            for (int x = 0; x < gk; ++x) {
                float& m = upper[size_t(y / 2) * gn + x / 2];
                m = std::min(m, lower[size_t(y) * gk + x]);
            }
        pb.minStart.push_back(std::move(upper));
        gk = gn;
    }
    auto minStartIn = [&](int cx0, int cx1, int cy0, int cy1) {
        int k = 0;
        while ((cx1 >> k) - (cx0 >> k) > 1 || (cy1 >> k) - (cy0 >> k) > 1) ++k;
        const std::vector<float>& lv = pb.minStart[size_t(k)];
        const int gk = (g + (1 << k) - 1) >> k;
        float m = INFINITY;
        for (int y = cy0 >> k; y <= (cy1 >> k); ++y)
            for (int x = cx0 >> k; x <= (cx1 >> k); ++x) m = std::min(m, lv[size_t(y) * gk + x]);
        return m;
    };
    const Vec3 d = light ? -w : rays.d[r0];  // visit order: nearer boxes along the rays first
    // Point light: the magnitude of the coordinates involved (the light, the origins), for the margins.
    float reach = maxComponent(Vec3{std::fabs(C.x), std::fabs(C.y), std::fabs(C.z)});
    if (light)
        for (size_t r = r0; r < r1; ++r) reach = std::max(reach, length(rays.o[r] - C));
    const float ignoreT = 8.f * acc.offset;
    const SubpatchForest& forest = acc.forest;
    const uint32_t firstLeaf = forest.firstLeaf();

    // Projected bounding rectangle of a box, grown for rounding, clipped to the points' bounds.
    auto overlaps = [&](const Bounds3& b, Rect2& rect) {
        float rx0 = INFINITY, rx1 = -INFINITY, ry0 = INFINITY, ry1 = -INFINITY;
        int behind = 0;
        for (int c = 0; c < 8; ++c) {
            const Vec3 p{c & 1 ? b.hi.x : b.lo.x, c & 2 ? b.hi.y : b.lo.y, c & 4 ? b.hi.z : b.lo.z};
            if (light && !(dot(w, p - C) > 0.f)) {
                ++behind;
                continue;
            }
            float x, y;
            project(p, x, y);
            rx0 = std::min(rx0, x), rx1 = std::max(rx1, x), ry0 = std::min(ry0, y), ry1 = std::max(ry1, y);
        }
        if (behind == 8) return false;  // behind the light: no segment towards it gets there
        if (behind > 0) {               // around the light's plane: any ray may hit it
            rect = {x0, x1, y0, y1};
            return true;
        }
        float m = 1e-5f * std::max({std::fabs(rx0), std::fabs(rx1), std::fabs(ry0), std::fabs(ry1), rx1 - rx0,
                                    ry1 - ry0}) +
                  1e-30f;
        if (light) {
            // Central projection: rounding of a ray point at distance h from the light moves its projection
            // by ~ulp(coordinates) / h, largest at the box's nearest corner.
            float h = INFINITY;
            for (int c = 0; c < 8; ++c)
                h = std::min(h, dot(w, Vec3{c & 1 ? b.hi.x : b.lo.x, c & 2 ? b.hi.y : b.lo.y,
                                            c & 4 ? b.hi.z : b.lo.z} -
                                           C));
            m += 1e-6f * reach / h;
        }
        rx0 -= m, rx1 += m, ry0 -= m, ry1 += m;
        rect = {rx0, rx1, ry0, ry1};
        if (!(std::isfinite(rx0) && std::isfinite(rx1) && std::isfinite(ry0) && std::isfinite(ry1))) {
            rect = {x0, x1, y0, y1};  // (nearly) on the light's plane: any ray may hit it
            return true;
        }
        if (!(rx0 <= x1 && rx1 >= x0 && ry0 <= y1 && ry1 >= y0)) return false;
        const int cx0 = cellX(rx0), cx1 = cellX(rx1), cy0 = cellY(ry0), cy1 = cellY(ry1);
        const size_t G = size_t(g) + 1;
        if (pb.sat[size_t(cy1 + 1) * G + cx1 + 1] - pb.sat[size_t(cy0) * G + cx1 + 1] -
                pb.sat[size_t(cy1 + 1) * G + cx0] + pb.sat[size_t(cy0) * G + cx0] ==
            0)
            return false;  // no ray in the rectangle
        // Box entirely before every start in the rectangle (margin for rounding).
        float reachOfBox = -INFINITY, mag = 0.f;
        for (int c = 0; c < 8; ++c) {
            const float v =
                startOf(Vec3{c & 1 ? b.hi.x : b.lo.x, c & 2 ? b.hi.y : b.lo.y, c & 4 ? b.hi.z : b.lo.z});
            reachOfBox = std::max(reachOfBox, v), mag = std::max(mag, std::fabs(v));
        }
        const float first = minStartIn(cx0, cx1, cy0, cy1);
        return !(reachOfBox < first - (1e-5f * (mag + std::fabs(first)) + 1e-30f));
    };
    // Near side of a box along the direction (visit order, so that candidates come out nearly sorted).
    auto nearDepth = [&](const Bounds3& b) {
        return (d.x > 0 ? b.lo.x : b.hi.x) * d.x + (d.y > 0 ? b.lo.y : b.hi.y) * d.y +
               (d.z > 0 ? b.lo.z : b.hi.z) * d.z;
    };
    auto testLeaf = [&](uint32_t patch, uint32_t node, const Bounds3& box, const Rect2& rect) {
        const int cx0 = cellX(rect.x0), cx1 = cellX(rect.x1), cy0 = cellY(rect.y0), cy1 = cellY(rect.y1);
        const uint32_t leaf = node - firstLeaf;
#if defined(__SSE2__)
        const LeafBox4 b4(box, rect);
        const __m128 vself = _mm_set1_ps(ignoreT);
        const __m128i vpatch = _mm_set1_epi32(int32_t(patch));
#endif
        for (int cy = cy0; cy <= cy1; ++cy) {
            const size_t b = pb.cellStart[size_t(cy) * g + cx0], e = pb.cellStart[size_t(cy) * g + cx1 + 1];
            if (b == e) continue;
            boxTests += e - b;
            size_t k = found.size();
            found.resize(k + (e - b) + 4);
#if defined(__SSE2__)
            for (size_t i = b; i < e; i += 4) {
                __m128 te, tx;
                const __m128 hit =
                    leafBox4Hits(b4, _mm_loadu_ps(&pb.px[i]), _mm_loadu_ps(&pb.py[i]),
                                 _mm_loadu_ps(&pb.ox[i]), _mm_loadu_ps(&pb.oy[i]), _mm_loadu_ps(&pb.oz[i]),
                                 _mm_loadu_ps(&pb.ix[i]), _mm_loadu_ps(&pb.iy[i]), _mm_loadu_ps(&pb.iz[i]),
                                 _mm_loadu_ps(&pb.tmin[i]), _mm_loadu_ps(&pb.tmax[i]), te, tx);
                // The ray's own patch: boxes it leaves before the self-intersection distance are skipped.
                const __m128 own = _mm_castsi128_ps(_mm_cmpeq_epi32(
                    _mm_loadu_si128(reinterpret_cast<const __m128i*>(&pb.ignore[i])), vpatch));
                const __m128 selfCut = _mm_and_ps(own, _mm_cmplt_ps(tx, vself));
                int mask = _mm_movemask_ps(_mm_andnot_ps(selfCut, hit));
                if (e - i < 4) mask &= (1 << (e - i)) - 1;
                if (mask) k += emitLanes(found.data() + k, mask, te, &pb.ray[i], patch, leaf);
            }
#else
            for (size_t i = b; i < e; ++i) {
                if (!(pb.px[i] >= rect.x0 && pb.px[i] <= rect.x1 && pb.py[i] >= rect.y0 &&
                      pb.py[i] <= rect.y1))
                    continue;
                float te, tx;
                if (!rayBoxInterval(box, {pb.ox[i], pb.oy[i], pb.oz[i]}, {pb.ix[i], pb.iy[i], pb.iz[i]},
                                    pb.tmin[i], pb.tmax[i], te, tx))
                    continue;
                if (pb.ignore[i] == patch && tx < ignoreT) continue;
                found[k++] = {pb.ray[i], patch, leaf, te};
            }
#endif
            found.resize(k);
        }
    };
    descendCulled(
        acc, nearDepth, overlaps, [](uint32_t, uint32_t) { return false; }, testLeaf);
    return true;
}

// Stage 2: Newton over the candidates and the closest hit per ray (a segmented minimum over each ray's
// sorted candidates; candidates whose box starts beyond the best hit so far cannot win and are skipped).
// The starts run kNewtonLanes at a time (rt/newton_lanes.h): each lane works through one ray's candidates
// in order and takes the next ray of the chunk when that ray is done, so a ray's candidates are still
// handled one after another (its early exit stays exact) while the iterations of eight rays share one
// vector step. The projection of a patch on the ray's planes is computed once per (ray, patch) run of
// candidates; a candidate whose leaf rectangle contains a root already found on the same patch for this
// ray is skipped (its start would converge to that root again); the surface derivatives are evaluated
// once per ray, at the closest hit. Results do not depend on which lane a ray runs in.
void newtonList(const RtAccel& acc, const RayList& rays, std::vector<Chunk>& chunks,
                std::vector<RayHit>& hits, bool cull) {
    const size_t n = rays.size();
    const size_t nChunks = (n + kChunk - 1) / kChunk;
    // Only the flag: the rest of a RayHit is written when the ray gets one, and read only then.
    hits.resize(n);
    for (RayHit& h : hits) h.hit = false;
    float hu, hv;
    leafHalfSize(acc.forest.depth, hu, hv);
    // A root within this margin of a leaf counts as inside it (Newton from the leaf centre finds it).
    const float du = 1.01f * hu, dv = 1.01f * hv;
    const Vec2* leafCentre = acc.forest.leafCentre.data();
    const LeafBasis* leafBasis = acc.forest.leafBasis.data();
    const LeafBasis* quarterBasis = acc.forest.quarterBasis.data();

    // The ray a lane is working on.
    struct LaneRay {
        uint32_t r = kNone;         // ray index (kNone: the lane looks for the next ray)
        uint32_t cur = 0, end = 0;  // cursor in the chunk's candidates, end of the ray's segment
        Ray ray;
        TraceOptions opt;
        RayPlanes pl;
        float invDD = 0.f, eps = 0.f, bestU = 0.f, bestV = 0.f;
        uint32_t projected = kNone, bestPatch = kNone;
        // Last converged root (accepted or not) per patch run, for the duplicate-start test. A secondary
        // ray starts (offset) on its originating patch at a known (u,v): that is the root a start near it
        // converges to (rejected by the self-intersection rules), so it seeds the test.
        uint32_t rootPatch = kNone;
        float rootU = 0.f, rootV = 0.f;
        int attempt = 0;  // 0: leaf centre; 1..4: quarter centres (originating patch only)
        // Originating patch: its control points' heights (X - o).n over the plane through the origin
        // orthogonal to originN (only when the ray leaves that plane: d.n > 0).
        Vec3 originN;
        bool selfPlane = false;
        float selfHeight[16];
        bool bestHasDeriv = false;  // bestSp holds the surface at the best root (from the sides test)
        SurfacePoint bestSp;
        ProjectedPatch<float> pp;
        alignas(16) float depth[16];  // the control points' distances along the ray (t units)
    };

    tbb::parallel_for(size_t(0), nChunks, [&](size_t ci) {
        Chunk& ch = chunks[ci];
        const size_t r0 = ci * kChunk;
        const uint32_t nRays = uint32_t(ch.segEnd.size());
        uint64_t runs = 0, iterTotal = 0, culled = 0;
        NewtonLanes lanes;
        LaneRay lane[kNewtonLanes];
        uint32_t nextRay = 0;

        // The patch projected on the ray's planes (as projectPatch, 4 control points at a time) into the
        // lane's column and the ray's own copy; the Newton tolerance as newtonTolerance.
        auto projectLane = [](const PatchSoa& ps, LaneRay& s, NewtonLanes& L, int l) {
            const RayPlanes& pl = s.pl;
#if defined(__SSE2__)
            const __m128 n1x = _mm_set1_ps(pl.n1.x), n1y = _mm_set1_ps(pl.n1.y), n1z = _mm_set1_ps(pl.n1.z),
                         n2x = _mm_set1_ps(pl.n2.x), n2y = _mm_set1_ps(pl.n2.y), n2z = _mm_set1_ps(pl.n2.z),
                         d1 = _mm_set1_ps(pl.d1), d2 = _mm_set1_ps(pl.d2);
            const __m128 ox = _mm_set1_ps(s.ray.o.x), oy = _mm_set1_ps(s.ray.o.y),
                         oz = _mm_set1_ps(s.ray.o.z), dx = _mm_set1_ps(s.ray.d.x),
                         dy = _mm_set1_ps(s.ray.d.y), dz = _mm_set1_ps(s.ray.d.z), idd = _mm_set1_ps(s.invDD);
            for (int q = 0; q < 16; q += 4) {
                const __m128 x = _mm_load_ps(ps.x + q), y = _mm_load_ps(ps.y + q), z = _mm_load_ps(ps.z + q);
                const __m128 a1 = _mm_add_ps(
                    _mm_add_ps(_mm_add_ps(_mm_mul_ps(n1x, x), _mm_mul_ps(n1y, y)), _mm_mul_ps(n1z, z)), d1);
                const __m128 a2 = _mm_add_ps(
                    _mm_add_ps(_mm_add_ps(_mm_mul_ps(n2x, x), _mm_mul_ps(n2y, y)), _mm_mul_ps(n2z, z)), d2);
                _mm_store_ps(s.pp.a1 + q, a1);
                _mm_store_ps(s.pp.a2 + q, a2);
                // Distance along the ray, (P - o).d / d.d: t of a root without evaluating the patch again.
                const __m128 a3 = _mm_mul_ps(_mm_add_ps(_mm_add_ps(_mm_mul_ps(_mm_sub_ps(x, ox), dx),
                                                                   _mm_mul_ps(_mm_sub_ps(y, oy), dy)),
                                                        _mm_mul_ps(_mm_sub_ps(z, oz), dz)),
                                             idd);
                _mm_store_ps(s.depth + q, a3);
            }
#else
            for (int k = 0; k < 16; ++k) {
                s.pp.a1[k] = pl.n1.x * ps.x[k] + pl.n1.y * ps.y[k] + pl.n1.z * ps.z[k] + pl.d1;
                s.pp.a2[k] = pl.n2.x * ps.x[k] + pl.n2.y * ps.y[k] + pl.n2.z * ps.z[k] + pl.d2;
                s.depth[k] = ((ps.x[k] - s.ray.o.x) * s.ray.d.x + (ps.y[k] - s.ray.o.y) * s.ray.d.y +
                              (ps.z[k] - s.ray.o.z) * s.ray.d.z) *
                             s.invDD;
            }
#endif
            for (int k = 0; k < 16; ++k) L.a1[k][l] = s.pp.a1[k], L.a2[k][l] = s.pp.a2[k];
            const Vec3 o = s.ray.o;
            const float mag = std::max({ps.boxMagnitude, std::fabs(o.x), std::fabs(o.y), std::fabs(o.z)});
            s.eps = 2e-6f * mag + 1e-6f * ps.boxExtent + 1e-30f;
        };
        auto finishRay = [&](LaneRay& s) {
            if (s.bestPatch != kNone) {
                RayHit& best = hits[s.r];
                const SurfacePoint sp =
                    s.bestHasDeriv ? s.bestSp : evalPatchDeriv(acc.patches[s.bestPatch], s.bestU, s.bestV);
                best.hit = true;
                best.patch = s.bestPatch;
                best.h.hit = true;
                best.h.t = s.ray.tmax;
                best.h.u = s.bestU;
                best.h.v = s.bestV;
                best.h.p = sp.p;
                best.h.dpdu = sp.dpdu;
                best.h.dpdv = sp.dpdv;
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
                s.pl = makeRayPlanes(s.ray.o, s.ray.d);
                s.invDD = 1.f / dot(s.ray.d, s.ray.d);
                s.projected = kNone, s.bestPatch = kNone, s.bestHasDeriv = false;
                s.originN = rays.originN[r];
                s.selfPlane = false;
                s.rootPatch = kNone;
                if (rays.ignore[r] != kNone && rays.ignoreUV[r].x >= 0.f)
                    s.rootPatch = rays.ignore[r], s.rootU = rays.ignoreUV[r].x, s.rootV = rays.ignoreUV[r].y;
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
                const Vec2 c0 = leafCentre[c.leaf];
                if (c.patch == s.rootPatch && std::fabs(s.rootU - c0.x) <= du &&
                    std::fabs(s.rootV - c0.y) <= dv) {
                    ++s.cur;
                    continue;
                }
                if (c.patch != s.projected) {
                    projectLane(acc.patchSoa[c.patch], s, lanes, l);
                    s.projected = c.patch;
                    if (c.patch == s.opt.ignorePatch && dot(s.originN, s.ray.d) > 0.f) {
                        const PatchSoa& ps = acc.patchSoa[c.patch];
                        const Vec3 o = s.ray.o, nrm = s.originN;
                        for (int k = 0; k < 16; ++k)
                            s.selfHeight[k] =
                                (ps.x[k] - o.x) * nrm.x + (ps.y[k] - o.y) * nrm.y + (ps.z[k] - o.z) * nrm.z;
                        s.selfPlane = true;
                    }
                }
                // On the ray's originating patch, leaves next to its origin converge to the origin itself
                // (rejected as self-intersection): there the ray-frame hull test of the leaf sub-patch
                // (exact: a leaf whose hull stays off the ray cannot hold a root) removes most of them. On
                // other patches it costs more than the Newton runs it saves (measured, docs/rt.md).
                // Leaves of the originating patch below the plane through the origin (the ray only moves
                // away from it: exact, by the convex hull of the leaf's Bernstein coefficients; this
                // removes the starts that would converge back to the origin on convex and flat parts), or
                // whose ray-frame hull stays off the ray, cannot hold a root.
                // The plane test is repeated on the leaf's quarters (their control nets bulge 4x less) when
                // the whole leaf's net reaches above the plane.
                auto belowPlane = [&](uint32_t leaf) {
                    const float lim = -4.f * s.eps;
                    if (leafMaxCoefficient(s.selfHeight, leafBasis[leaf]) < lim) return true;
                    for (int q = 0; q < 4; ++q)
                        if (!(leafMaxCoefficient(s.selfHeight, quarterBasis[4 * leaf + q]) < lim))
                            return false;
                    return true;
                };
                if (c.patch == s.opt.ignorePatch && ((s.selfPlane && belowPlane(c.leaf)) ||
                                                     !leafMayHit(s.pp, leafBasis[c.leaf], 4.f * s.eps))) {
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
                               acceptRootDomain<float>(s.pp, s.eps, lanes.u[l], lanes.v[l], 1e-4f, uc, vc);
            if (!found && c.patch == s.opt.ignorePatch) {
                // On the originating patch, where the hull test removed the neighbouring starts that could
                // also reach a root of this leaf, a failed start (a fold, a seam root just outside the
                // domain) is retried from the centres of the leaf's quarters whose own hull passes the test.
                for (int q = s.attempt; q < 4; ++q) {  // quarter q: bit 0 high u, bit 1 high v
                    if (!leafMayHit(s.pp, quarterBasis[4 * c.leaf + q], 4.f * s.eps)) continue;
                    const Vec2 c0 = leafCentre[c.leaf];
                    s.attempt = q + 1;
                    lanes.start(l, c0.x + (q & 1 ? 0.5f : -0.5f) * hu, c0.y + (q & 2 ? 0.5f : -0.5f) * hv,
                                s.eps);
                    return true;
                }
            }
            if (found) {
                s.rootPatch = c.patch, s.rootU = uc, s.rootV = vc;
                const BezierPatch& patch = acc.patches[c.patch];
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
                    s.bestSp = evalPatchDeriv(patch, uc, vc);
                    haveDeriv = true;
                    Vec3 N = cross(s.bestSp.dpdu, s.bestSp.dpdv);
                    if (acc.flip[c.patch]) N = -N;
                    ok = dot(N, s.ray.d) <= 0.f;  // back face of a one-sided surface: rejected
                }
                if (ok) {
                    s.bestPatch = c.patch, s.bestU = uc, s.bestV = vc, s.bestHasDeriv = haveDeriv;
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
        ch.c.newtonIterations = iterTotal;
    });
}

// How the traversal stage finds a list's candidates: per ray (traverseList), or by binning the camera rays
// of a tile (binCameraRays), or by binning the shadow rays light by light (binParallelRays, runs given by
// Workspace::shadowRuns; per ray after all when a point light's rays surround it).
enum class Candidates { kPerRay, kCameraBinning, kShadowBinning };

void traceList(const RtAccel& acc, const RayList& rays, Workspace& ws, std::vector<RayHit>& hits, bool cull,
               Candidates how = Candidates::kPerRay) {
    auto t0 = Clock::now();
    if (how == Candidates::kCameraBinning) {
        binCameraRays(acc, rays, ws.bin, ws.chunks, cull);
    } else {
        bool binned = false;
        if (how == Candidates::kShadowBinning) {
            ws.bin.found.clear();
            uint64_t boxTests = 0;
            binned = true;
            for (const ShadowRun& run : ws.shadowRuns)
                binned = binned && binParallelRays(acc, rays, run.begin, run.end, ws.parallel, ws.bin.found,
                                                   boxTests, run.point ? &run.position : nullptr);
            // Shadow rays stop at any accepted hit: their candidates need no order.
            if (binned)
                groupCandidates(ws.bin.found, rays.size(), ws.bin.start, ws.bin.next, ws.chunks, boxTests,
                                /*sortByEntry=*/false);
            ++(binned ? ws.c.shadowListsBinned : ws.c.shadowListsTraversed);
        }
        if (!binned) traverseList(acc, rays, ws.chunks, cull);
    }
    auto t1 = Clock::now();
    newtonList(acc, rays, ws.chunks, hits, cull);
    ws.c.traversalMs += std::chrono::duration<double, std::milli>(t1 - t0).count();
    ws.c.newtonMs += msSince(t1);
    const size_t nChunks = (rays.size() + kChunk - 1) / kChunk;
    for (size_t ci = 0; ci < nChunks; ++ci) {
        const Counters& c = ws.chunks[ci].c;
        ws.c.candidates += c.candidates, ws.c.newtonRuns += c.newtonRuns;
        ws.c.newtonIterations += c.newtonIterations, ws.c.boxTests += c.boxTests;
        ws.c.hullCulled += c.hullCulled;
        for (int i = 0; i < kHistBins; ++i) ws.c.hist[i] += c.hist[i];
    }
    for (size_t r = 0; r < rays.size(); ++r) {
        ++ws.c.rays[rays.kind[r]];
        if (hits[r].hit) ++ws.c.hits[rays.kind[r]];
    }
}

struct Frame {
    const Scene& scene;
    const RtAccel& acc;
    std::vector<ShadingLight> lights;
    int maxDepth;
    bool cull;
    bool rayBinning;
};

// One wavefront generation: shade the hits of `ws.rays`, trace their shadow rays, accumulate colour into
// the tile and write the next generation (reflection, refraction) to `ws.next`.
void shadeGeneration(const Frame& fr, Workspace& ws) {
    const RtAccel& acc = fr.acc;
    const RayList& rays = ws.rays;
    const size_t n = rays.size();
    const size_t nL = fr.lights.size();
    auto ts = Clock::now();
    ws.info.resize(n);
    ws.shadowIdx.assign(n * nL, kNone);
    ws.shadow.clear();
    for (size_t r = 0; r < n; ++r) {
        const RayHit& rh = ws.hits[r];
        if (!rh.hit) continue;
        HitInfo& hi = ws.info[r];
        hi.P = rh.h.p;
        hi.N = hitNormal(acc, rh.patch, rh.h);
        hi.I = normalize(rays.d[r]);
    }
    // Shadow rays light by light (runs for the binning stage).
    ws.shadowRuns.clear();
    ws.shadow.reserve(n * std::max<size_t>(nL, 1));
    for (size_t l = 0; l < nL; ++l) {
        const ShadingLight& light = fr.lights[l];
        if (light.type == LightType::Ambient) continue;
        const size_t runBegin = ws.shadow.size();
        for (size_t r = 0; r < n; ++r) {
            const RayHit& rh = ws.hits[r];
            if (!rh.hit) continue;
            const Material& m = fr.scene.materials[acc.material[rh.patch]];
            if (m.type == MaterialType::Constant) continue;
            const HitInfo& hi = ws.info[r];
            const Vec3 Nf = faceForward(hi.N, hi.I);
            Vec3 L;
            Color Cl;
            float dist;
            if (!lightIncidence(light, hi.P, L, Cl, dist)) continue;
            if (dot(Nf, L) <= 0.f) continue;
            const Vec3 o = hi.P + Nf * acc.offset;
            float tmax = dist;
            if (light.type != LightType::Distant) {
                // Aimed from the offset origin, so that the ray's line passes through the light (the
                // shadow binning projects from the light).
                const Vec3 toLight = light.position - o;
                const float len = length(toLight);
                if (len > 0.f && std::isfinite(len)) L = toLight / len, tmax = len;
                if (!(dot(Nf, L) > 0.f)) continue;
            }
            if (std::isfinite(tmax)) tmax -= acc.offset;
            ws.shadowIdx[r * nL + l] = uint32_t(ws.shadow.size());
            ws.shadow.push(o, L, 0.f, tmax, uint32_t(r), Color{}, rh.patch, kShadow, 0, Vec2{rh.h.u, rh.h.v},
                           Nf);
        }
        if (ws.shadow.size() > runBegin)
            ws.shadowRuns.push_back(
                {runBegin, ws.shadow.size(), light.type != LightType::Distant, light.position});
    }
    ws.c.shadeMs += msSince(ts);
    traceList(acc, ws.shadow, ws, ws.shadowHits, fr.cull,
              fr.rayBinning ? Candidates::kShadowBinning : Candidates::kPerRay);

    ts = Clock::now();
    ws.contrib.assign(n, Color{});
    ws.secondaryFlags.assign(n, 0);
    ws.secO.resize(2 * n);
    ws.secD.resize(2 * n);
    ws.secW.resize(2 * n);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 256), [&](const tbb::blocked_range<size_t>& range) {
        for (size_t r = range.begin(); r != range.end(); ++r) {
            const RayHit& rh = ws.hits[r];
            if (!rh.hit) continue;
            const HitInfo& hi = ws.info[r];
            const Material& m = fr.scene.materials[acc.material[rh.patch]];
            auto visible = [&](size_t l, Vec3, Vec3, float) -> float {
                const uint32_t s = ws.shadowIdx[r * nL + l];
                return (s != kNone && ws.shadowHits[s].hit) ? 0.f : 1.f;
            };
            const Color w = rays.weight[r];
            ws.contrib[r] = w * shadeLocal(m, hi.P, hi.N, hi.I, fr.lights, visible);
            if (rays.depth[r] >= fr.maxDepth) continue;
            const Vec3 Nf = faceForward(hi.N, hi.I);
            if (m.type == MaterialType::Mirror) {
                const Color wr = w * m.Cs * m.Kr;
                if (maxComponent(wr) > 1e-4f) {
                    ws.secondaryFlags[r] |= 1;
                    ws.secO[2 * r] = hi.P + Nf * acc.offset;
                    ws.secD[2 * r] = reflectDir(hi.I, Nf);
                    ws.secW[2 * r] = wr;
                }
            } else if (m.type == MaterialType::Glass) {
                // hi.N is the outward normal (orientation attributes applied).
                Vec3 T;
                float F;
                const bool refr = refractDir(hi.I, hi.N, m.eta, T, F);
                const Color wr = w * (m.Kr * F);
                if (maxComponent(wr) > 1e-4f) {
                    ws.secondaryFlags[r] |= 1;
                    ws.secO[2 * r] = hi.P + Nf * acc.offset;
                    ws.secD[2 * r] = reflectDir(hi.I, Nf);
                    ws.secW[2 * r] = wr;
                }
                const Color wt = w * m.Cs * (m.Kt * (1.f - F));
                if (refr && maxComponent(wt) > 1e-4f) {
                    ws.secondaryFlags[r] |= 2;
                    ws.secO[2 * r + 1] = hi.P - Nf * acc.offset;
                    ws.secD[2 * r + 1] = T;
                    ws.secW[2 * r + 1] = wt;
                }
            }
        }
    });
    // Accumulate in ray order (deterministic) and compact the next generation.
    SampleTile& tile = ws.tile;
    ws.next.clear();
    for (size_t r = 0; r < n; ++r) {
        const uint32_t s = rays.owner[r];
        if (rays.kind[r] == kPrimary && ws.hits[r].hit) {
            tile.a[s] = 1.f;
            tile.z[s] = ws.hits[r].h.t;
            tile.pixelHit[s / size_t(tile.spp)] = 1;
        }
        if (!ws.hits[r].hit) continue;
        tile.r[s] += ws.contrib[r].x;
        tile.g[s] += ws.contrib[r].y;
        tile.b[s] += ws.contrib[r].z;
        const uint8_t f = ws.secondaryFlags[r];
        if (f & 1)
            ws.next.push(ws.secO[2 * r], ws.secD[2 * r], 0.f, std::numeric_limits<float>::infinity(), s,
                         ws.secW[2 * r], ws.hits[r].patch, kReflection, uint8_t(rays.depth[r] + 1),
                         Vec2{ws.hits[r].h.u, ws.hits[r].h.v}, faceForward(ws.info[r].N, ws.info[r].I));
        if (f & 2)
            ws.next.push(ws.secO[2 * r + 1], ws.secD[2 * r + 1], 0.f, std::numeric_limits<float>::infinity(),
                         s, ws.secW[2 * r + 1], ws.hits[r].patch, kRefraction, uint8_t(rays.depth[r] + 1),
                         Vec2{ws.hits[r].h.u, ws.hits[r].h.v}, -faceForward(ws.info[r].N, ws.info[r].I));
    }
    ws.c.shadeMs += msSince(ts);
}

}  // namespace

// ---- shared helpers -------------------------------------------------------------------------------

bool rtUseAvx2(bool allow) {
    gAvx2Allowed.store(allow, std::memory_order_relaxed);
    return allow && cpuHasAvx2();
}

Vec3 hitNormal(const RtAccel& acc, uint32_t patch, const PatchHit& h) {
    Vec3 N = cross(h.dpdu, h.dpdv);
    const float scale = dot(h.dpdu, h.dpdu) + dot(h.dpdv, h.dpdv);
    if (!(dot(N, N) > 1e-12f * scale * scale)) N = patchNormal(acc.patches[patch], h.u, h.v);
    N = normalize(N);
    if (!isFinite(N) || dot(N, N) == 0.f) N = Vec3{0, 0, 1};
    return acc.flip[patch] ? -N : N;
}

bool acceptHit(const RtAccel& acc, const Ray& ray, const TraceOptions& opt, uint32_t patch,
               const PatchHit& h) {
    if (patch == opt.ignorePatch && h.t < opt.ignoreT) return false;
    if (opt.respectSides && !acc.twoSided[patch]) {
        Vec3 N = cross(h.dpdu, h.dpdv);
        if (acc.flip[patch]) N = -N;
        if (dot(N, ray.d) > 0.f) return false;  // back face of a one-sided surface
    }
    return true;
}

Vec3 reflectDir(Vec3 I, Vec3 N) {
    return normalize(I - N * (2.f * dot(I, N)));
}

bool refractDir(Vec3 I, Vec3 N, float eta, Vec3& T, float& F) {
    float cosi = -dot(I, N);
    float n1 = 1.f, n2 = eta;
    Vec3 n = N;
    if (cosi < 0.f) {  // leaving the medium
        cosi = -cosi;
        n = -N;
        std::swap(n1, n2);
    }
    const float r = n1 / n2;
    const float sin2t = r * r * std::max(0.f, 1.f - cosi * cosi);
    if (sin2t >= 1.f) {
        F = 1.f;
        return false;
    }
    const float cost = std::sqrt(1.f - sin2t);
    const float rs = (n1 * cosi - n2 * cost) / (n1 * cosi + n2 * cost);
    const float rp = (n1 * cost - n2 * cosi) / (n1 * cost + n2 * cosi);
    F = 0.5f * (rs * rs + rp * rp);
    T = normalize(I * r + n * (r * cosi - cost));
    return true;
}

void buildRtAccel(const Scene& scene, const Mat4& toSpace, int subpatchDepth, bool cullFromOrigin,
                  RtAccel& acc) {
    const size_t n = scene.patches.size();
    acc.patches.resize(n);
    acc.flip.resize(n);
    acc.twoSided.resize(n);
    acc.material.resize(n);
    tbb::parallel_for(size_t(0), n, [&](size_t i) {
        for (int k = 0; k < 16; ++k) acc.patches[i].cp[k] = toSpace.point(scene.patches[i].cp[k]);
        acc.flip[i] = scene.attributes[i].flipNormal;
        acc.twoSided[i] = scene.attributes[i].twoSided;
        acc.material[i] = scene.attributes[i].material;
    });
    auto t0 = Clock::now();
    buildSubpatchForest(acc.patches, subpatchDepth, acc.forest, cullFromOrigin, acc.flip);
    acc.subpatchMs = msSince(t0);
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
    // Patches with non-finite control points (possible in scenes built in code; the loaders reject them)
    // are left out of the BVH, so no ray ever reaches them.
    std::vector<Bounds3> roots;
    std::vector<uint32_t> ids;
    Bounds3 all;
    for (size_t i = 0; i < n; ++i) {
        const Bounds3& b = acc.forest.tree(uint32_t(i))[0];
        if (!isFinite(b.lo) || !isFinite(b.hi)) continue;
        roots.push_back(b);
        ids.push_back(uint32_t(i));
        all.extend(b);
    }
    buildBvh(roots, acc.bvh);
    for (uint32_t& p : acc.bvh.prims) p = ids[p];
    std::vector<Bounds3> patchBox(n);
    for (size_t i = 0; i < n; ++i) patchBox[i] = acc.forest.tree(uint32_t(i))[0];
    collapseBvh4(acc.bvh, patchBox);
    acc.bounds = all;
    acc.bvhMs = msSince(t1);
    float mag = 0.f;
    if (!all.empty())
        for (int k = 0; k < 3; ++k) mag = std::max({mag, std::fabs(all.lo[k]), std::fabs(all.hi[k])});
    acc.offset = 2e-5f * mag + 1e-6f;
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
            const uint8_t* back = opt.cullBackfaces ? acc.forest.backfaceBits(patch) : nullptr;
            auto accept = [&](const PatchHit& ph) { return acceptHit(acc, r, opt, patch, ph); };
            if (intersectPatch<float>(acc.patches[patch], acc.forest, patch, r, h, back, nullptr, nullptr,
                                      accept)) {
                out.hit = true;
                out.patch = patch;
                out.h = h;
                r.tmax = h.t;
                if (opt.anyHit) return true;
            }
        }
    }
    return out.hit;
}

void traceBatch(const RtAccel& acc, std::span<const Ray> rays, const TraceOptions& opt,
                std::vector<RayHit>& hits) {
    Workspace ws;
    const uint8_t kind = opt.anyHit                                ? kShadow
                         : (opt.respectSides || opt.cullBackfaces) ? kPrimary
                                                                   : kReflection;
    for (const Ray& r : rays) ws.rays.push(r.o, r.d, r.tmin, r.tmax, 0, {1, 1, 1}, opt.ignorePatch, kind, 0);
    traceList(acc, ws.rays, ws, hits, opt.cullBackfaces);
}

RenderResult renderRt(const Scene& scene, const RenderSettings& settings) {
    const auto tStart = Clock::now();
    RenderResult result;
    const Camera& cam = scene.camera;
    const int W = cam.width, H = cam.height;
    result.image = Image(W, H);
    const PixelFilter filter = makeFilter(scene.image);
    const int nx = std::max(1, scene.image.pixelSamplesX), ny = std::max(1, scene.image.pixelSamplesY);

    // Build: camera space (eye at the origin), both levels of the hierarchy.
    const auto tBuild = Clock::now();
    RtAccel acc;
    buildRtAccel(scene, cam.cameraFromWorld, settings.subpatchDepth, settings.cullBackfaces, acc);
    const double buildMs = msSince(tBuild);
    // Binning (camera and shadow rays) pays when the subpatch leaves are few compared with the samples, i.e.
    // boxes cover several samples each: the per-tile descent then replaces many per-ray box tests. With
    // many small leaves the descent costs more than the traversal it replaces. Measured crossover (800x600,
    // 4 spp, docs/rt.md): about 0.4 leaves per sample (teapot 0.001 and bigguy 0.19: binning faster;
    // killeroo 0.38: equal; killeroo2 0.77, bigguy9 1.07, bigguy24 2.85: the traversal faster).
    const double leavesPerSample = double(acc.patches.size()) * double(acc.forest.firstLeaf() + 1) /
                                   std::max(1.0, double(W) * double(H) * double(nx * ny));
    const bool binning = settings.rayBinning && leavesPerSample <= 0.4;
    Frame fr{scene, acc, {}, std::max(0, settings.maxDepth), settings.cullBackfaces, binning};
    for (const Light& l : scene.lights) fr.lights.push_back(prepareLight(l, cam.cameraFromWorld));
    const Projector proj(cam);

    // Tiles of at most 64x64 pixels and about 16k samples: the wavefront's ray and candidate lists scale
    // with the samples in a tile, so more samples per pixel means smaller tiles and bounded memory; at 1
    // spp 64 px measured faster than 128 px (the per-tile arrays stay in cache) despite twice the share
    // of duplicated filter-margin rays (6% instead of 3%).
    const int spp = nx * ny;
    const int bs =
        std::clamp(int(std::lround(128.0 / std::sqrt(double(spp)))), 16, std::max(settings.bucketSize, 64));
    // Raster rectangle holding the projection of the whole scene (the bounding rectangle of its box's
    // projected corners, which contains the projection of the box when the box lies in front of the eye),
    // grown by a pixel for rounding: a camera ray outside it cannot hit anything, so it is not traced.
    float sceneX0 = -INFINITY, sceneX1 = INFINITY, sceneY0 = -INFINITY, sceneY1 = INFINITY;
    if (acc.bounds.empty()) {
        sceneX0 = sceneY0 = INFINITY, sceneX1 = sceneY1 = -INFINITY;  // nothing to hit
    } else {
        bool inFront = true;
        float x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
        for (int c = 0; c < 8; ++c) {
            const Vec3 p{c & 1 ? acc.bounds.hi.x : acc.bounds.lo.x, c & 2 ? acc.bounds.hi.y : acc.bounds.lo.y,
                         c & 4 ? acc.bounds.hi.z : acc.bounds.lo.z};
            if (proj.perspective && !(p.z > 0.f)) inFront = false;
            const Vec3 r = proj.toRaster(p);
            x0 = std::min(x0, r.x), x1 = std::max(x1, r.x), y0 = std::min(y0, r.y), y1 = std::max(y1, r.y);
        }
        if (inFront && std::isfinite(x0) && std::isfinite(x1) && std::isfinite(y0) && std::isfinite(y1))
            sceneX0 = x0 - 1.f, sceneX1 = x1 + 1.f, sceneY0 = y0 - 1.f, sceneY1 = y1 + 1.f;
    }
    const int rx = filter.radiusX(), ry = filter.radiusY();
    const int nbx = (W + bs - 1) / bs, nby = (H + bs - 1) / bs, nb = nbx * nby;

    std::mutex poolMutex;
    std::vector<std::unique_ptr<Workspace>> pool, all;
    auto acquire = [&]() -> Workspace* {
        std::lock_guard<std::mutex> lock(poolMutex);
        if (pool.empty()) {
            all.push_back(std::make_unique<Workspace>());
            return all.back().get();
        }
        Workspace* w = pool.back().release();
        pool.pop_back();
        return w;
    };
    auto release = [&](Workspace* w) {
        std::lock_guard<std::mutex> lock(poolMutex);
        pool.emplace_back(w);
    };
    // `all` owns the workspaces; `pool` holds non-owning views of the idle ones.
    auto renderTile = [&](int b) {
        Workspace* wsp = acquire();
        Workspace& ws = *wsp;
        const int bx = b % nbx, by = b / nbx;
        Rect target{bx * bs, by * bs, std::min(W, (bx + 1) * bs), std::min(H, (by + 1) * bs)};
        Rect region{std::max(0, target.x0 - rx), std::max(0, target.y0 - ry), std::min(W, target.x1 + rx),
                    std::min(H, target.y1 + ry)};
        ws.tile.reset(region, nx, ny, settings.seed, std::numeric_limits<float>::infinity(), settings.sampler);
        auto ts = Clock::now();
        // Camera rays, one per sample inside the scene's rectangle (written in place: this runs for every
        // sample of the frame), and the per-sample arrays of the camera-ray binning.
        const size_t ns = ws.tile.sampleCount();
        RayList& rl = ws.rays;
        rl.resize(ns);
        CameraBinning& bin = ws.bin;
        bin.proj = &proj;
        bin.tile = &ws.tile;
        for (auto* v :
             {&bin.sampleX, &bin.sampleY, &bin.originX, &bin.originY, &bin.invX, &bin.invY, &bin.invZ})
            v->resize(ns + 4);
        bin.rayOfSample.resize(ns + 4);
        size_t m = 0;
        for (size_t i = 0; i < ns + 4; ++i) {
            const float x = i < ns ? float(ws.tile.sx[i]) / kSubpixelScale : NAN;
            const float y = i < ns ? float(ws.tile.sy[i]) / kSubpixelScale : NAN;
            if (!(x >= sceneX0 && x <= sceneX1 && y >= sceneY0 && y <= sceneY1)) {  // sure miss: no ray
                bin.rayOfSample[i] = kNone;
                bin.sampleX[i] = bin.sampleY[i] = NAN;  // never inside a rectangle
                bin.originX[i] = bin.originY[i] = bin.invX[i] = bin.invY[i] = bin.invZ[i] = 0.f;
                continue;
            }
            const float cx = (x - proj.ox) / proj.sx, cy = (y - proj.oy) / proj.sy;
            const Vec3 o = proj.perspective ? Vec3{0, 0, 0} : Vec3{cx, cy, 0};
            const Vec3 d = proj.perspective ? Vec3{cx, cy, 1.f} : Vec3{0, 0, 1.f};
            const Vec3 inv = safeInverse(d);
            rl.o[m] = o, rl.d[m] = d;
            bin.rayOfSample[i] = uint32_t(m);
            bin.sampleX[i] = x, bin.sampleY[i] = y;
            bin.originX[i] = o.x, bin.originY[i] = o.y;
            bin.invX[i] = inv.x, bin.invY[i] = inv.y, bin.invZ[i] = inv.z;
            rl.owner[m++] = uint32_t(i);
        }
        rl.resize(m);
        std::fill(rl.tmin.begin(), rl.tmin.end(), proj.nearClip);
        std::fill(rl.tmax.begin(), rl.tmax.end(), proj.farClip);
        std::fill(rl.weight.begin(), rl.weight.end(), Color{1, 1, 1});
        std::fill(rl.ignore.begin(), rl.ignore.end(), kNone);
        std::fill(rl.ignoreUV.begin(), rl.ignoreUV.end(), Vec2{-1.f, -1.f});
        std::fill(rl.originN.begin(), rl.originN.end(), Vec3{0.f, 0.f, 0.f});
        std::fill(rl.kind.begin(), rl.kind.end(), uint8_t(kPrimary));
        std::fill(rl.depth.begin(), rl.depth.end(), uint8_t(0));
        ws.c.shadeMs += msSince(ts);
        for (bool camera = true; ws.rays.size() > 0; camera = false) {
            traceList(acc, ws.rays, ws, ws.hits, fr.cull,
                      camera && binning ? Candidates::kCameraBinning : Candidates::kPerRay);
            shadeGeneration(fr, ws);
            std::swap(ws.rays, ws.next);
        }
        auto tf = Clock::now();
        reconstruct(ws.tile, filter, target, result.image);
        ws.c.filterMs += msSince(tf);
        release(wsp);
    };
    // The pool's unique_ptrs must not double-own: keep ownership in `all` only.
    auto cleanup = [&] {
        for (auto& p : pool) p.release();
        pool.clear();
    };

    const auto tTrace = Clock::now();
    std::atomic<int> nextTile{0}, doneTiles{0};
    std::atomic<bool> cancelled{false};
    const int workers = tbb::this_task_arena::max_concurrency();
    tbb::parallel_for(
        0, workers,
        [&](int) {
            for (;;) {
                if (settings.cancel && settings.cancel->load(std::memory_order_relaxed)) {
                    cancelled = true;
                    break;
                }
                int b = nextTile.fetch_add(1);
                if (b >= nb) break;
                renderTile(b);
                int done = ++doneTiles;
                if (settings.progress) settings.progress(done, nb);
            }
        },
        tbb::static_partitioner());
    const double traceMs = msSince(tTrace);
    cleanup();

    Counters total;
    size_t wsBytes = 0;
    for (const auto& w : all) {
        total.add(w->c);
        wsBytes += w->tile.sampleCount() * 30 + w->rays.o.capacity() * 64;
        for (const Chunk& ch : w->chunks) wsBytes += ch.cand.capacity() * sizeof(Candidate);
    }
    result.cancelled = cancelled.load();
    nlohmann::json& s = result.stats;
    s["engine"] = "rt";
    s["patches_in"] = scene.patches.size();
    nlohmann::json rays, hits;
    uint64_t totalRays = 0;
    for (int k = 0; k < kKinds; ++k) {
        rays[kKindNames[k]] = total.rays[k];
        hits[kKindNames[k]] = total.hits[k];
        totalRays += total.rays[k];
    }
    s["rays"] = rays;
    s["rays_total"] = totalRays;
    s["hits"] = hits;
    s["candidates"] = total.candidates;
    s["candidates_per_ray"] = totalRays ? double(total.candidates) / double(totalRays) : 0.0;
    s["box_tests"] = total.boxTests;
    s["newton_runs"] = total.newtonRuns;
    s["hull_culled"] = total.hullCulled;
    s["shadow_lists"] = {{"binned", total.shadowListsBinned}, {"traversed", total.shadowListsTraversed}};
    s["newton_iterations"] = {
        {"total", total.newtonIterations},
        {"mean", total.newtonRuns ? double(total.newtonIterations) / double(total.newtonRuns) : 0.0},
        {"histogram", total.hist}};
    s["bvh_nodes"] = acc.bvh.nodes.size();
    s["bvh_depth"] = acc.bvh.maxDepth;
    s["subpatch_depth"] = acc.forest.depth;
    s["subpatch_nodes"] = acc.forest.boxes.size();
    const size_t np = std::max<size_t>(1, scene.patches.size());
    s["memory"] = {{"bvh_bytes", acc.bvh.memoryBytes()},
                   {"subpatch_bytes", acc.forest.memoryBytes()},
                   {"patch_bytes", acc.patches.size() * sizeof(BezierPatch)},
                   {"bytes_per_patch", double(acc.bvh.memoryBytes() + acc.forest.memoryBytes()) / double(np)},
                   {"workspace_bytes", wsBytes}};
    s["build_ms"] = buildMs;
    s["build"] = {{"bvh_ms", acc.bvhMs}, {"subpatch_ms", acc.subpatchMs}};
    s["trace_ms"] = traceMs;
    s["mrays_per_s"] = traceMs > 0 ? double(totalRays) / (traceMs * 1e3) : 0.0;
    s["tile_size"] = bs;
    s["tiles"] = nb;
    s["cull_backfaces"] = settings.cullBackfaces;
    s["ray_binning"] = binning;
    s["leaves_per_sample"] = leavesPerSample;
    s["max_depth"] = fr.maxDepth;
    s["stage_ms"] = {{"traversal_cpu", total.traversalMs},
                     {"newton_cpu", total.newtonMs},
                     {"shading_cpu", total.shadeMs},
                     {"filter_cpu", total.filterMs}};
    s["engine_ms"] = msSince(tStart);
    return result;
}

}  // namespace tessera
