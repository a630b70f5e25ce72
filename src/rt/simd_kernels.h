// The SIMD kernels of the traversal and binning stages (SSE2, with scalar fallbacks, and AVX2 versions
// compiled with a target attribute): 4-wide slab tests, the hit-order and lane tables, compressed
// candidate writes. Inline in a header so that the hot loops of rt/traversal.cpp and rt/binning.cpp keep
// them inlined.
#pragma once
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "rt/bvh.h"
#include "rt/ray_list.h"
#include "rt/subpatch_tree.h"
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

namespace tessera::rt {

// Stack for the 4-wide BVH: each level pushes at most 3 more nodes than it pops.
inline constexpr int kBvh4Stack = 3 * 64 + 1;

// The part of a leaf slab's margin that depends on the ray (LeafSlab4): four times the origin's share of
// newtonTolerance (2e-6 of its largest coordinate).
inline float slabRayMargin(Vec3 o) {
    return 8e-6f * std::max(std::max(std::fabs(o.x), std::fabs(o.y)), std::fabs(o.z));
}

// A ray for the 4-wide box tests (origin, reciprocal direction and interval in all four lanes), with its
// direction and slab margin for the leaf slab test (slabKeep4).
struct Ray4 {
#if defined(__SSE2__)
    __m128 ox, oy, oz, ix, iy, iz, t0, t1, dx, dy, dz, m;
    Ray4() = default;
    Ray4(Vec3 o, Vec3 inv, float tmin, float tmax, Vec3 d = {0.f, 0.f, 0.f})
        : ox(_mm_set1_ps(o.x)),
          oy(_mm_set1_ps(o.y)),
          oz(_mm_set1_ps(o.z)),
          ix(_mm_set1_ps(inv.x)),
          iy(_mm_set1_ps(inv.y)),
          iz(_mm_set1_ps(inv.z)),
          t0(_mm_set1_ps(tmin)),
          t1(_mm_set1_ps(tmax)),
          dx(_mm_set1_ps(d.x)),
          dy(_mm_set1_ps(d.y)),
          dz(_mm_set1_ps(d.z)),
          m(_mm_set1_ps(slabRayMargin(o))) {}
#else
    Vec3 o, inv;
    float tmin, tmax;
    Vec3 d;
    float m;
    Ray4() = default;
    Ray4(Vec3 o_, Vec3 inv_, float tmin_, float tmax_, Vec3 d_ = {0.f, 0.f, 0.f})
        : o(o_), inv(inv_), tmin(tmin_), tmax(tmax_), d(d_), m(slabRayMargin(o_)) {}
#endif
};

// The leaf slab test (LeafSlab4) of one leaf and one ray: whether the ray (origin o, direction d, slab
// margin m) is within the slab's band somewhere in [te, tx], its interval in the leaf's box (finite). The
// ray's height n.(o + t d) is linear in t, so over the interval it spans [h(te), h(tx)]: the ray meets the
// band iff that range overlaps [lo - m, hi + m] (no division; the heights' rounding is covered by 1e-6 of
// their magnitudes). False means the ray cannot meet the leaf: every point of it lies in the band, and a
// root Newton accepts within the margins.
inline bool slabKeep1(const LeafSlab4& g, int lane, Vec3 o, Vec3 d, float m, float te, float tx) {
    const float nx = g.n[0][lane], ny = g.n[1][lane], nz = g.n[2][lane];
    const float no = nx * o.x + ny * o.y + nz * o.z, nd = nx * d.x + ny * d.y + nz * d.z;
    const float h0 = no + te * nd, h1 = no + tx * nd;
    const float r = m + 1e-6f * (std::fabs(h0) + std::fabs(h1));
    return std::min(h0, h1) <= g.hi[lane] + r && std::max(h0, h1) >= g.lo[lane] - r;
}

#if defined(__SSE2__)
// slabKeep1 four lanes at a time (four leaves and one ray, or one leaf and four rays, as the arguments are
// splatted): the bits of the lanes kept.
inline int slabKeep4(__m128 nx, __m128 ny, __m128 nz, __m128 lo, __m128 hi, __m128 ox, __m128 oy, __m128 oz,
                     __m128 dx, __m128 dy, __m128 dz, __m128 m, __m128 te, __m128 tx) {
    const __m128 no = _mm_add_ps(_mm_add_ps(_mm_mul_ps(nx, ox), _mm_mul_ps(ny, oy)), _mm_mul_ps(nz, oz));
    const __m128 nd = _mm_add_ps(_mm_add_ps(_mm_mul_ps(nx, dx), _mm_mul_ps(ny, dy)), _mm_mul_ps(nz, dz));
    const __m128 h0 = _mm_add_ps(no, _mm_mul_ps(te, nd)), h1 = _mm_add_ps(no, _mm_mul_ps(tx, nd));
    const __m128 sign = _mm_set1_ps(-0.f);
    const __m128 r = _mm_add_ps(
        m, _mm_mul_ps(_mm_set1_ps(1e-6f), _mm_add_ps(_mm_andnot_ps(sign, h0), _mm_andnot_ps(sign, h1))));
    const __m128 keep = _mm_and_ps(_mm_cmple_ps(_mm_min_ps(h0, h1), _mm_add_ps(hi, r)),
                                   _mm_cmpge_ps(_mm_max_ps(h0, h1), _mm_sub_ps(lo, r)));
    return _mm_movemask_ps(keep);
}
// slabRayMargin of four origins.
inline __m128 slabRayMargin4(__m128 ox, __m128 oy, __m128 oz) {
    const __m128 sign = _mm_set1_ps(-0.f);
    return _mm_mul_ps(
        _mm_set1_ps(8e-6f),
        _mm_max_ps(_mm_max_ps(_mm_andnot_ps(sign, ox), _mm_andnot_ps(sign, oy)), _mm_andnot_ps(sign, oz)));
}
// One leaf (lane `lane` of a slab group) against four rays.
inline int slabKeepRays4(const LeafSlab4& g, int lane, __m128 ox, __m128 oy, __m128 oz, __m128 dx, __m128 dy,
                         __m128 dz, __m128 te, __m128 tx) {
    return slabKeep4(_mm_set1_ps(g.n[0][lane]), _mm_set1_ps(g.n[1][lane]), _mm_set1_ps(g.n[2][lane]),
                     _mm_set1_ps(g.lo[lane]), _mm_set1_ps(g.hi[lane]), ox, oy, oz, dx, dy, dz,
                     slabRayMargin4(ox, oy, oz), te, tx);
}
// Four leaves of a slab group against one ray.
inline int slabKeepGroup(const LeafSlab4& g, const Ray4& r, __m128 te, __m128 tx) {
    return slabKeep4(_mm_load_ps(g.n[0]), _mm_load_ps(g.n[1]), _mm_load_ps(g.n[2]), _mm_load_ps(g.lo),
                     _mm_load_ps(g.hi), r.ox, r.oy, r.oz, r.dx, r.dy, r.dz, r.m, te, tx);
}
#endif

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

#if defined(__SSE2__)
// Four bytes as four floats (SSE2 has no pmovzxbd).
inline __m128 bytesToFloats4(const uint8_t* p) {
    int32_t v;
    std::memcpy(&v, p, 4);
    const __m128i z = _mm_setzero_si128();
    return _mm_cvtepi32_ps(_mm_unpacklo_epi16(_mm_unpacklo_epi8(_mm_cvtsi32_si128(v), z), z));
}
// The four boxes' low (high) bounds on axis a, decoded as SubpatchQuad::decodeLo (decodeHi).
inline __m128 quadStep4(const SubpatchQuad& q, int a) {
    return _mm_set1_ps((q.frameHi[a] - q.frameLo[a]) * (1.f / 255.f));
}
inline __m128 decodeLo4(const SubpatchQuad& q, int a) {
    return _mm_add_ps(_mm_set1_ps(q.frameLo[a]), _mm_mul_ps(bytesToFloats4(q.lo[a]), quadStep4(q, a)));
}
inline __m128 decodeHi4(const SubpatchQuad& q, int a) {
    return _mm_sub_ps(_mm_set1_ps(q.frameHi[a]), _mm_mul_ps(bytesToFloats4(q.hi[a]), quadStep4(q, a)));
}
#endif

// The hit lanes of a subpatch quad whose exit distance is not below selfT (lanes of selfT4; the
// self-intersection cut !(tx < selfT)), with the entry and exit distances in te and tx.
inline int quadHits(const SubpatchQuad& q, const Ray4& r, F4 selfT4, F4& te, F4& tx) {
#if defined(__SSE2__)
    const __m128 x0 = _mm_mul_ps(_mm_sub_ps(decodeLo4(q, 0), r.ox), r.ix);
    const __m128 x1 = _mm_mul_ps(_mm_sub_ps(decodeHi4(q, 0), r.ox), r.ix);
    const __m128 y0 = _mm_mul_ps(_mm_sub_ps(decodeLo4(q, 1), r.oy), r.iy);
    const __m128 y1 = _mm_mul_ps(_mm_sub_ps(decodeHi4(q, 1), r.oy), r.iy);
    const __m128 z0 = _mm_mul_ps(_mm_sub_ps(decodeLo4(q, 2), r.oz), r.iz);
    const __m128 z1 = _mm_mul_ps(_mm_sub_ps(decodeHi4(q, 2), r.oz), r.iz);
    te = _mm_max_ps(_mm_max_ps(_mm_min_ps(x0, x1), _mm_min_ps(y0, y1)), _mm_max_ps(_mm_min_ps(z0, z1), r.t0));
    tx = _mm_min_ps(_mm_min_ps(_mm_max_ps(x0, x1), _mm_max_ps(y0, y1)), _mm_min_ps(_mm_max_ps(z0, z1), r.t1));
    return _mm_movemask_ps(_mm_andnot_ps(_mm_cmplt_ps(tx, selfT4), _mm_cmple_ps(te, tx)));
#else
    float lo[3][4], hi[3][4];
    for (int a = 0; a < 3; ++a)
        for (int c = 0; c < 4; ++c)
            lo[a][c] = q.decodeLo(a, q.lo[a][c]), hi[a][c] = q.decodeHi(a, q.hi[a][c]);
    const int mask = rayBox4Soa(lo, hi, r, te, tx);
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
inline constexpr int kHitOrderSize = 1 << 10;
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
inline constexpr std::array<HitOrder, kHitOrderSize> kHitOrder = makeHitOrderTable();

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
// The low (`high` false) or high bounds of quads qa and qb on axis a, decoded as decodeLo4 / decodeHi4 do
// (the same operations per lane), minus the rays' origins oa, ob, times their inverse directions ia, ib.
TESSERA_AVX2 inline __m256 slab2(const SubpatchQuad& qa, const SubpatchQuad& qb, bool high, int a, __m128 oa,
                                 __m128 ob, __m128 ia, __m128 ib) {
    int32_t x, y;
    std::memcpy(&x, high ? qa.hi[a] : qa.lo[a], 4);
    std::memcpy(&y, high ? qb.hi[a] : qb.lo[a], 4);
    const __m256 v = _mm256_cvtepi32_ps(
        _mm256_cvtepu8_epi32(_mm_unpacklo_epi32(_mm_cvtsi32_si128(x), _mm_cvtsi32_si128(y))));
    const __m256 prod = _mm256_mul_ps(v, cat2(quadStep4(qa, a), quadStep4(qb, a)));
    const __m256 bound =
        high ? _mm256_sub_ps(cat2(_mm_set1_ps(qa.frameHi[a]), _mm_set1_ps(qb.frameHi[a])), prod)
             : _mm256_add_ps(cat2(_mm_set1_ps(qa.frameLo[a]), _mm_set1_ps(qb.frameLo[a])), prod);
    return _mm256_mul_ps(_mm256_sub_ps(bound, cat2(oa, ob)), cat2(ia, ib));
}
TESSERA_AVX2 inline int quadHits2(const SubpatchQuad& qa, const Ray4& ra, __m128 sa, const SubpatchQuad& qb,
                                  const Ray4& rb, __m128 sb, __m256& te, __m256& tx) {
    const __m256 x0 = slab2(qa, qb, false, 0, ra.ox, rb.ox, ra.ix, rb.ix);
    const __m256 x1 = slab2(qa, qb, true, 0, ra.ox, rb.ox, ra.ix, rb.ix);
    const __m256 y0 = slab2(qa, qb, false, 1, ra.oy, rb.oy, ra.iy, rb.iy);
    const __m256 y1 = slab2(qa, qb, true, 1, ra.oy, rb.oy, ra.iy, rb.iy);
    const __m256 z0 = slab2(qa, qb, false, 2, ra.oz, rb.oz, ra.iz, rb.iz);
    const __m256 z1 = slab2(qa, qb, true, 2, ra.oz, rb.oz, ra.iz, rb.iz);
    te = _mm256_max_ps(_mm256_max_ps(_mm256_min_ps(x0, x1), _mm256_min_ps(y0, y1)),
                       _mm256_max_ps(_mm256_min_ps(z0, z1), cat2(ra.t0, rb.t0)));
    tx = _mm256_min_ps(_mm256_min_ps(_mm256_max_ps(x0, x1), _mm256_max_ps(y0, y1)),
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
inline constexpr uint8_t kPop4[16] = {0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4};

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
inline constexpr std::array<LaneOffsets, 16> kLaneOffsets = makeLaneOffsets();

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
inline constexpr std::array<std::array<uint8_t, 4>, 16> kCompressLanes = makeCompressLanes();

// A box's projected rectangle (clipped), as the binning stages pass it down.
struct Rect2 {
    float x0, x1, y0, y1;
};

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
// The lanes whose point (px, py) lies in the box's rectangle.
inline __m128 insideRect4(const LeafBox4& b, __m128 px, __m128 py) {
    return _mm_and_ps(_mm_and_ps(_mm_cmpge_ps(px, b.x0), _mm_cmple_ps(px, b.x1)),
                      _mm_and_ps(_mm_cmpge_ps(py, b.y0), _mm_cmple_ps(py, b.y1)));
}
inline __m128 leafBox4Hits(const LeafBox4& b, __m128 px, __m128 py, __m128 ox, __m128 oy, __m128 oz,
                           __m128 ix, __m128 iy, __m128 iz, __m128 t0, __m128 t1, __m128& te, __m128& tx) {
    const __m128 ax = _mm_mul_ps(_mm_sub_ps(b.lox, ox), ix), bx = _mm_mul_ps(_mm_sub_ps(b.hix, ox), ix);
    const __m128 ay = _mm_mul_ps(_mm_sub_ps(b.loy, oy), iy), by = _mm_mul_ps(_mm_sub_ps(b.hiy, oy), iy);
    const __m128 az = _mm_mul_ps(_mm_sub_ps(b.loz, oz), iz), bz = _mm_mul_ps(_mm_sub_ps(b.hiz, oz), iz);
    te = _mm_max_ps(_mm_max_ps(_mm_min_ps(ax, bx), _mm_min_ps(ay, by)), _mm_max_ps(_mm_min_ps(az, bz), t0));
    tx = _mm_min_ps(_mm_min_ps(_mm_max_ps(ax, bx), _mm_max_ps(ay, by)), _mm_min_ps(_mm_max_ps(az, bz), t1));
    return _mm_and_ps(_mm_cmple_ps(te, tx), insideRect4(b, px, py));
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
    return kPop4[mask];
}
#endif

}  // namespace tessera::rt
