// The camera sample shared by both engines: a stateless Owen-scrambled Sobol' sampler. For (pixel seed,
// sample index, dimension) it returns the same well-distributed value on any thread, bucket or backend
// (header-only, plain integer code, no tables on the hot path: meant for CUDA kernels too; not yet
// compiled with nvcc).
//
// Construction (B. Burley, "Practical Hash-based Owen Scrambling", JCGT 9(4), 2020):
//  - Sobol' generator matrices: dimension 0 is van der Corput (bit reversal), dimensions 1.. come from
//    the primitive polynomials and initial direction numbers of S. Joe and F. Y. Kuo, "Constructing
//    Sobol sequences with better two-dimensional projections" (2008), file new-joe-kuo-6.21201.
//  - Nested uniform (Owen) scrambling of each dimension with the Laine-Karras style hash (Burley 2020):
//    on bit-reversed values, `x += seed; x ^= x * even` never lets a bit depend on a less significant
//    digit of the sample, so it is a valid Owen scramble and keeps every (t,m,s)-net property.
//  - Index shuffling (Burley sec. 4): the sample index itself is Owen-scrambled per pixel and group of
//    dimensions (all groups but the first, see sampleGroup). The first 2^m shuffled indices are one aligned
//    block of 2^m Sobol' indices, which is again a net: every prefix of a pixel's samples stays stratified
//    while the groups are decorrelated.
//  - Padding (as in Burley 2020 and pbrt-v4's padded/ZSobol samplers): only film x, y and time share one
//    Sobol' point (matrices 0, 1, 2). Every later pair of dimensions (lens, light, BSDF, ...) uses matrices
//    0 and 1 again with its own index shuffle, because 0 and 1 are the only pair of the first 13 matrices
//    that is a (0,2)-sequence (e.g. matrices 3 and 4 have t = 2 at 16 points); so every named pair is a
//    (0,m,2)-net and every single dimension a (0,m,1)-net for each power-of-two prefix.
#pragma once
#include <cstdint>

#include "core/hostdevice.h"
#include "core/random.h"

namespace tessera {

// Which sample positions the film uses: Sobol (default) or the original jittered strata (kept so that
// earlier images can be reproduced and the two compared; docs/sampler.md).
// Sobol: Owen-scrambled Sobol' (the default); Jittered: stratified jitter (film.h); Centred: each
// stratum's centre, no jitter (RIB Hider "hidden" "jitter" [0], what depth passes for shadow maps use:
// a depth is then exactly where the lookups assume it, at a texel's centre).
enum class SamplerKind : uint8_t { Sobol, Jittered, Centred };

// Dimension slots of one camera sample. Film x, y and time are one 3D Sobol' point; each later pair
// (u, v) is its own padded 2D (0,2)-sequence. Per bounce, engines take further pairs from kDimFirstFree.
enum SampleDim : uint32_t {
    kDimFilmX = 0,
    kDimFilmY = 1,
    kDimTime = 2,
    kDimLensU = 3,
    kDimLensV = 4,
    kDimLightU = 5,
    kDimLightV = 6,
    kDimBsdfU = 7,
    kDimBsdfV = 8,
    kDimHemisphereU = 9,
    kDimHemisphereV = 10,
    kDimFirstFree = 11,
};

// ---- Bit tools ----

TESSERA_HD uint32_t reverseBits32(uint32_t x) {
#if defined(__CUDA_ARCH__)
    return __brev(x);
#else
    x = (x << 16) | (x >> 16);
    x = ((x & 0x00ff00ffu) << 8) | ((x >> 8) & 0x00ff00ffu);
    x = ((x & 0x0f0f0f0fu) << 4) | ((x >> 4) & 0x0f0f0f0fu);
    x = ((x & 0x33333333u) << 2) | ((x >> 2) & 0x33333333u);
    x = ((x & 0x55555555u) << 1) | ((x >> 1) & 0x55555555u);
    return x;
#endif
}

// Burley 2020 (after Laine and Karras 2011): a hash in which each output bit depends only on the same and
// lower input bits (addition and multiplication by even constants carry upwards only). Applied to
// bit-reversed values, "lower" means "more significant digit of the sample": a nested uniform scramble.
TESSERA_HD uint32_t laineKarrasPermutation(uint32_t x, uint32_t seed) {
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return x;
}
// Owen scramble of a 32-bit fixed-point value in [0,1) (Burley 2020).
TESSERA_HD uint32_t nestedUniformScramble(uint32_t x, uint32_t seed) {
    return reverseBits32(laineKarrasPermutation(reverseBits32(x), seed));
}

// [0,1) from 32 fixed-point bits, keeping 24 (never rounds up to 1).
TESSERA_HD float bitsToUnit(uint32_t bits) {
    return float(bits >> 8) * (1.f / 16777216.f);
}

// ---- Sobol' generator matrices ----

// Matrices 0..kSobolDimensions-1 as 32 columns each (column j is multiplied by bit j of the index, first
// bit of the result = most significant). A host table for generic use and the tests; the sampler's
// own three matrices are evaluated table-free below.
constexpr int kSobolDimensions = 8;
struct SobolMatrices {
    uint32_t column[kSobolDimensions][32];
};
constexpr SobolMatrices makeSobolMatrices() {
    // Joe-Kuo new-joe-kuo-6.21201, d = 2..8: degree s, coefficients a (of x^(s-1) .. x^1), m_1..m_s.
    constexpr int degree[kSobolDimensions - 1] = {1, 2, 3, 3, 4, 4, 5};
    constexpr uint32_t coeffs[kSobolDimensions - 1] = {0, 1, 1, 2, 1, 4, 2};
    constexpr uint32_t initial[kSobolDimensions - 1][5] = {
        {1}, {1, 3}, {1, 3, 1}, {1, 1, 1}, {1, 1, 3, 3}, {1, 3, 5, 13}, {1, 1, 5, 5, 17}};
    SobolMatrices r{};
    for (int j = 0; j < 32; ++j) r.column[0][j] = 1u << (31 - j);
    for (int d = 1; d < kSobolDimensions; ++d) {
        const int s = degree[d - 1];
        const uint32_t a = coeffs[d - 1];
        uint32_t v[33] = {};  // v[i] = m_i << (32 - i), i = 1..32
        for (int i = 1; i <= 32; ++i) {
            if (i <= s) {
                v[i] = initial[d - 1][i - 1] << (32 - i);
            } else {  // Joe-Kuo recurrence: v_i = a_1 v_{i-1} ^ ... ^ a_{s-1} v_{i-s+1} ^ v_{i-s} ^ (v_{i-s}
                      // >> s)
                v[i] = v[i - s] ^ (v[i - s] >> s);
                for (int k = 1; k < s; ++k)
                    if ((a >> (s - 1 - k)) & 1u) v[i] ^= v[i - k];
            }
            r.column[d][i - 1] = v[i];
        }
    }
    return r;
}
inline constexpr SobolMatrices kSobolMatrices = makeSobolMatrices();

// Unscrambled Sobol' value (32 fixed-point bits) of `index` in matrix `dim` < kSobolDimensions (host).
inline uint32_t sobolBitsTable(uint32_t index, int dim) {
    uint32_t r = 0;
    for (int j = 0; index; index >>= 1, ++j)
        if (index & 1u) r ^= kSobolMatrices.column[dim][j];
    return r;
}

// Table-free matrices 0, 1, 2 (no tables to place in GPU memory).
TESSERA_HD uint32_t sobolBits0(uint32_t index) {
    return reverseBits32(index);
}
// Matrix 1 (x + 1, m_1 = 1) is Pascal's triangle mod 2: index bit j sets result bit i (weight 2^-(i+1))
// iff C(j, i) is odd, iff i is a bit-subset of j (Lucas). So before reversal, bit i of the result is the
// parity of the index bits at supersets of i: a superset-sum transform, 5 shift-xor steps, no loop.
TESSERA_HD uint32_t sobolBits1Reversed(uint32_t index) {
    index ^= (index >> 1) & 0x55555555u;
    index ^= (index >> 2) & 0x33333333u;
    index ^= (index >> 4) & 0x0f0f0f0fu;
    index ^= (index >> 8) & 0x00ff00ffu;
    index ^= (index >> 16) & 0x0000ffffu;
    return index;
}
TESSERA_HD uint32_t sobolBits1(uint32_t index) {
    return reverseBits32(sobolBits1Reversed(index));
}
// Matrix 2 (x^2 + x + 1, m = 1, 3): the direction numbers follow from the recurrence as bits are walked.
TESSERA_HD uint32_t sobolBits2(uint32_t index) {
    uint32_t r = 0, v0 = 1u << 31, v1 = 3u << 30;  // v_1, v_2
    for (; index; index >>= 1) {
        if (index & 1u) r ^= v0;
        const uint32_t next = v1 ^ v0 ^ (v0 >> 2);  // v_i = v_{i-1} ^ v_{i-2} ^ (v_{i-2} >> 2)
        v0 = v1;
        v1 = next;
    }
    return r;
}

// ---- The sampler ----

// Per-pixel seed from (pixel, --seed): all of a pixel's randomisation derives from it. Pixel coordinates
// below 65536 pack injectively into 32 bits and hash32 is a bijection, so no two pixels of an image share
// a seed.
TESSERA_HD uint32_t pixelSeed(int px, int py, uint32_t seed) {
    return hash32(((uint32_t(py) & 0xffffu) << 16 | (uint32_t(px) & 0xffffu)) ^ hash32(seed ^ 0x5eed5eedu));
}

// Dimension -> (group, Sobol' matrix): {film x, film y, time} -> group 0, matrices 0..2; then pairs
// (3,4) -> group 1, (5,6) -> group 2, ... on matrices 0, 1 (padding). Group 0 keeps the natural index
// order and every later group shuffles it with its own seed: what decorrelates two groups is their
// relative permutation, so one shuffle per later group suffices (and the film loop saves one).
TESSERA_HD uint32_t sampleGroup(uint32_t dim) {
    return dim < 3 ? 0 : 1 + (dim - 3) / 2;
}
TESSERA_HD uint32_t sampleMatrix(uint32_t dim) {
    return dim < 3 ? dim : (dim - 3) & 1u;
}
// Derived seeds, one hash each: even multipliers for group shuffles, odd for the value scrambles.
TESSERA_HD uint32_t shuffleSeed(uint32_t pixelSeed, uint32_t group) {
    return hash32(pixelSeed + 0x9e3779b9u * (2 * group));
}
TESSERA_HD uint32_t scrambleSeed(uint32_t pixelSeed, uint32_t dim) {
    return hash32(pixelSeed + 0x9e3779b9u * (2 * dim + 1));
}

// Scrambled value of dimension `dim` of sample `index` of a pixel, as 32 fixed-point bits of [0,1).
TESSERA_HD uint32_t sampleBits(uint32_t pixelSeed, uint32_t index, uint32_t dim) {
    const uint32_t group = sampleGroup(dim);
    const uint32_t shuffled = group ? nestedUniformScramble(index, shuffleSeed(pixelSeed, group)) : index;
    const uint32_t seed = scrambleSeed(pixelSeed, dim);
    // The scramble works on bit-reversed values, and matrices 0 and 1 are bit reversals of cheap
    // transforms, so two reversals cancel: scramble(reverse(y)) = reverse(LK(y)).
    switch (sampleMatrix(dim)) {
        case 0:
            return reverseBits32(laineKarrasPermutation(shuffled, seed));
        case 1:
            return reverseBits32(laineKarrasPermutation(sobolBits1Reversed(shuffled), seed));
        default:
            return nestedUniformScramble(sobolBits2(shuffled), seed);
    }
}
TESSERA_HD float sampleDimension(uint32_t pixelSeed, uint32_t index, uint32_t dim) {
    return bitsToUnit(sampleBits(pixelSeed, index, dim));
}
// The time and lens dimensions of a pixel's samples with the pixel's seeds prepared once (the blurred
// film fills them for every sample of every tile): equal to sampleBits for kDimTime, kDimLensU, kDimLensV,
// with the lens pair's index shuffle computed once for both.
struct TimeLensSeeds {
    uint32_t time, lensShuffle, lensU, lensV;
};
TESSERA_HD TimeLensSeeds timeLensSeeds(uint32_t pixelSeed) {
    return {scrambleSeed(pixelSeed, kDimTime), shuffleSeed(pixelSeed, sampleGroup(kDimLensU)),
            scrambleSeed(pixelSeed, kDimLensU), scrambleSeed(pixelSeed, kDimLensV)};
}
TESSERA_HD uint32_t timeBits(const TimeLensSeeds& s, uint32_t index) {
    return nestedUniformScramble(sobolBits2(index), s.time);
}
TESSERA_HD void lensBits(const TimeLensSeeds& s, uint32_t index, uint32_t& u, uint32_t& v) {
    const uint32_t shuffled = nestedUniformScramble(index, s.lensShuffle);
    u = reverseBits32(laineKarrasPermutation(shuffled, s.lensU));
    v = reverseBits32(laineKarrasPermutation(sobolBits1Reversed(shuffled), s.lensV));
}

// Dimensions (dim, dim + 1); for the named pairs (film, lens, light, ...) a (0,2)-sequence.
struct Sample2D {
    float u = 0, v = 0;
};
TESSERA_HD Sample2D sample2D(uint32_t pixelSeed, uint32_t index, uint32_t dim) {
    return {sampleDimension(pixelSeed, index, dim), sampleDimension(pixelSeed, index, dim + 1)};
}

// 0..8 when n = 2^k <= 256, else -1 (branch-free bit tests: this runs per pixel).
TESSERA_HD int log2PowerOfTwo(int n) {
    if (n <= 0 || n > 256 || (n & (n - 1))) return -1;
    return int((n & 0xaa) != 0) | int((n & 0xcc) != 0) << 1 | int((n & 0xf0) != 0) << 2 | int(n == 256) << 3;
}

// Reverses the bits within each byte of x.
TESSERA_HD uint32_t reverseBitsInBytes(uint32_t x) {
    x = ((x & 0x0f0f0f0fu) << 4) | ((x >> 4) & 0x0f0f0f0fu);
    x = ((x & 0x33333333u) << 2) | ((x >> 2) & 0x33333333u);
    return ((x & 0x55555555u) << 1) | ((x >> 1) & 0x55555555u);
}

// 16-bit forms of the three bit operations above, for the film loop (power-of-two strata, at most 65536
// samples per pixel, so the index fits in 16 bits): the low 16 bits of laineKarrasPermutation depend only on
// the low 16 bits of its input and seed; sobolBits1Reversed's high steps vanish for 16-bit indices.
TESSERA_HD uint16_t laineKarrasLow16(uint16_t x, uint16_t seed) {
    uint32_t v = uint16_t(x + seed);  // 32-bit products truncated: no signed overflow after promotion
    v = (v ^ (v * 0xb47cu)) & 0xffffu;
    v = (v ^ (v * 0x1e52u)) & 0xffffu;
    v = (v ^ (v * 0xe638u)) & 0xffffu;
    v = (v ^ (v * 0xf6e6u)) & 0xffffu;
    return uint16_t(v);
}
TESSERA_HD uint16_t sobolBits1Reversed16(uint16_t index) {
    uint32_t v = index;
    v ^= (v >> 1) & 0x5555u;
    v ^= (v >> 2) & 0x3333u;
    v ^= (v >> 4) & 0x0f0fu;
    v ^= (v >> 8) & 0x00ffu;
    return uint16_t(v);
}
TESSERA_HD uint16_t reverseBitsInBytes16(uint16_t x) {
    uint32_t v = x;
    v = ((v & 0x0f0fu) << 4) | ((v >> 4) & 0x0f0fu);
    v = ((v & 0x3333u) << 2) | ((v >> 2) & 0x3333u);
    return uint16_t(((v & 0x5555u) << 1) | ((v >> 1) & 0x5555u));
}

// Offset in [0,256) inside stratum k of n (n strata per pixel) from 32 bits of [0,1). The rasterizer puts a
// lattice offset o in stratum (o * n) >> 8, so stratum k is [ceil(256k/n), ceil(256(k+1)/n)).
TESSERA_HD int32_t stratumOffset(int k, int n, uint32_t bits) {
    const int lo = (k * 256 + n - 1) / n, hi = ((k + 1) * 256 + n - 1) / n;
    const int w = hi > lo ? hi - lo : 1;
    const int o = lo + int((uint64_t(bits) * uint32_t(w)) >> 32);
    return o < 255 ? o : 255;  // more than 256 strata per pixel cannot all be kept apart
}

// The nx*ny film samples of pixel (px,py), on the rasterizer's 1/256-pixel lattice: slot s lies in
// stratum (s % nx, s / nx) of the pixel, i.e. ((x & 255) * nx) >> 8 == s % nx and likewise for y, and
// index[s] is the sample index whose other dimensions (time, lens, ...) belong to that slot.
//  - nx, ny powers of two (<= 256): the first nx*ny scrambled Sobol' points are a (0,m,2)-net, so exactly
//    one point lies in each stratum; it goes to that stratum's slot. Snapping to 1/256 keeps it there.
//  - otherwise: jittered strata whose in-stratum offsets are dimensions 0, 1 of sample index s (no
//    (0,m,2)-net exists for these counts; the offsets are still stratified as a 1D set each).
// What filmSamplesFixed needs that does not depend on the pixel, prepared once per tile.
struct FilmPattern {
    int nx = 1, ny = 1;
    int lx = 0, ly = 0;     // log2 of nx, ny, or -1 when not a power of two
    uint32_t seedHash = 0;  // the --seed's part of pixelSeed
};
TESSERA_HD FilmPattern filmPattern(int nx, int ny, uint32_t seed) {
    return {nx, ny, log2PowerOfTwo(nx), log2PowerOfTwo(ny), hash32(seed ^ 0x5eed5eedu)};
}

// One sample per pixel (the ray tracer's benchmark frames): sample index 0, whose Sobol' bits are 0 in
// every dimension, so its film offsets are the reversed low bytes of the two Laine-Karras permutations of 0
// (the general loop below with i = 0, written out so that it inlines into the tile's loop).
TESSERA_HD void filmSampleSingleFixed(const FilmPattern& fp, int px, int py, int32_t& x, int32_t& y) {
    const uint32_t ps = hash32(((uint32_t(py) & 0xffffu) << 16 | (uint32_t(px) & 0xffffu)) ^ fp.seedHash);
    const uint32_t lowX = laineKarrasPermutation(0u, scrambleSeed(ps, kDimFilmX)) & 0xffu;
    const uint32_t lowY = laineKarrasPermutation(0u, scrambleSeed(ps, kDimFilmY)) & 0xffu;
    const uint32_t both = reverseBitsInBytes(lowX | lowY << 8);
    x = (px << 8) + int32_t(both & 0xffu);
    y = (py << 8) + int32_t(both >> 8);
}

TESSERA_HD void filmSamplesFixed(const FilmPattern& fp, int px, int py, int32_t* x, int32_t* y,
                                 uint32_t* index) {
    if (fp.nx == 1 && fp.ny == 1) {
        filmSampleSingleFixed(fp, px, py, *x, *y);
        *index = 0;
        return;
    }
    const int nx = fp.nx, ny = fp.ny, lx = fp.lx, ly = fp.ly;
    const uint32_t ps = hash32(((uint32_t(py) & 0xffffu) << 16 | (uint32_t(px) & 0xffffu)) ^ fp.seedHash);
    const uint32_t sx = scrambleSeed(ps, kDimFilmX), sy = scrambleSeed(ps, kDimFilmY);
    const int32_t x0 = px << 8, y0 = py << 8;  // kSubpixelBits = 8 (static_assert in film.h)
    const int spp = nx * ny;
    if (lx >= 0 && ly >= 0 && spp < 8) {  // few samples: one pass (the chunked form's set-up costs more)
        for (int i = 0; i < spp; ++i) {
            const uint32_t lowX = laineKarrasPermutation(uint32_t(i), sx) & 0xffu;
            const uint32_t lowY = laineKarrasPermutation(sobolBits1Reversed(uint32_t(i)), sy) & 0xffu;
            const uint32_t both = reverseBitsInBytes(lowX | lowY << 8);
            const uint32_t ox = both & 0xffu, oy = both >> 8;
            const int slot = int(oy >> (8 - ly)) * nx + int(ox >> (8 - lx));
            x[slot] = x0 + int32_t(ox);
            y[slot] = y0 + int32_t(oy);
            index[slot] = uint32_t(i);
        }
        return;
    }
    if (lx >= 0 && ly >= 0) {
        // The lattice offsets are the top 8 bits of sampleBits(ps, i, kDimFilmX / kDimFilmY), i.e. the
        // reversed low bytes of the scrambles before their final reversal (which only low input bits reach:
        // the Laine-Karras hash carries upwards only). So 16-bit arithmetic gives the same bytes; it runs
        // for every sample of every tile, in chunks the compiler vectorizes (8 lanes per SSE2 register),
        // then the points go to their strata's slots.
        // The stratum slot of each point is computed in the same vector loop (nx = 2^lx: shifts only).
        // Up to 256 samples (16 x 16) the points go to their slots as one packed word each (the offsets
        // and the sample index), unpacked into x, y and index by a loop the compiler vectorizes: the
        // scatter of three words per sample was 40% of this function on a 16-sample frame.
        const uint16_t sx16 = uint16_t(sx), sy16 = uint16_t(sy);
        constexpr int kChunk = 64;
        uint16_t both[kChunk], slotOf[kChunk];
        uint32_t packed[256];
        const bool pack = spp <= 256;
        for (int first = 0; first < spp; first += kChunk) {
            const int count = spp - first < kChunk ? spp - first : kChunk;
            for (int k = 0; k < count; ++k) {
                const uint16_t i = uint16_t(first + k);
                const uint16_t lowX = laineKarrasLow16(i, sx16) & 0xffu;
                const uint16_t lowY = laineKarrasLow16(sobolBits1Reversed16(i), sy16) & 0xffu;
                const uint16_t b = reverseBitsInBytes16(uint16_t(lowX | lowY << 8));
                both[k] = b;
                slotOf[k] = uint16_t(((b >> 8) >> (8 - ly)) << lx | (b & 0xffu) >> (8 - lx));
            }
            if (pack) {
                for (int k = 0; k < count; ++k)
                    packed[slotOf[k]] = uint32_t(both[k]) | uint32_t(first + k) << 16;
                continue;
            }
            for (int k = 0; k < count; ++k) {
                const int slot = slotOf[k];
                x[slot] = x0 + int32_t(both[k] & 0xffu);
                y[slot] = y0 + int32_t(both[k] >> 8);
                index[slot] = uint32_t(first + k);
            }
        }
        if (pack)
            for (int s = 0; s < spp; ++s) {
                x[s] = x0 + int32_t(packed[s] & 0xffu);
                y[s] = y0 + int32_t((packed[s] >> 8) & 0xffu);
                index[s] = packed[s] >> 16;
            }
        return;
    }
    for (int s = 0; s < spp; ++s) {
        const uint32_t bx = reverseBits32(laineKarrasPermutation(uint32_t(s), sx));
        const uint32_t by = reverseBits32(laineKarrasPermutation(sobolBits1Reversed(uint32_t(s)), sy));
        x[s] = x0 + stratumOffset(s % nx, nx, bx);
        y[s] = y0 + stratumOffset(s / nx, ny, by);
        index[s] = uint32_t(s);
    }
}
TESSERA_HD void filmSamplesFixed(int px, int py, int nx, int ny, uint32_t seed, int32_t* x, int32_t* y,
                                 uint32_t* index) {
    filmSamplesFixed(filmPattern(nx, ny, seed), px, py, x, y, index);
}

}  // namespace tessera
