#include "film/blur_pattern.h"

#include <algorithm>
#include <numeric>
#include <stdexcept>
#if defined(__GNUC__) && defined(__x86_64__)
#include <immintrin.h>
#define TESSERA_FILM_AVX2 1
#endif

#include "core/cpu.h"
#include "core/random.h"
#include "film/film.h"
#include "scene/camera.h"

namespace tessera {

const char* blurSamplingName(BlurSampling s) {
    switch (s) {
        case BlurSampling::Simple:
            return "simple";
        case BlurSampling::Interleaved:
            return "interleaved";
        case BlurSampling::BoundingBox:
            return "bbox";
    }
    return "?";
}

namespace {
// The shared (t, lens) set of the simple and interleaved schemes: a 3D Owen-scrambled Sobol' set of the
// frame (time on its own dimension, the lens as a padded pair), so it is stratified however it is split.
// `stratum` gets each sample's position in the unit square of lens coordinates (before the disk map).
void frameSamples(uint32_t seed, int n, bool motion, bool lens, std::vector<float>& time,
                  std::vector<Vec2>& lensPoint, std::vector<Vec2>* lensSquare = nullptr) {
    const uint32_t frameSeed = pixelSeed(0xfffe, 0xfffe, seed ^ 0xb1a5u);
    time.resize(n);
    lensPoint.resize(n);
    if (lensSquare) lensSquare->resize(n);
    for (int i = 0; i < n; ++i) {
        time[i] = motion ? sampleDimension(frameSeed, uint32_t(i), kDimTime) : 0.f;
        const float u = sampleDimension(frameSeed, uint32_t(i), kDimLensU),
                    v = sampleDimension(frameSeed, uint32_t(i), kDimLensV);
        lensPoint[i] = lens ? squareToDisk(u, v) : Vec2{};
        if (lensSquare) (*lensSquare)[i] = {u, v};
    }
}

uint32_t stepHash(uint32_t i, uint32_t k, uint32_t salt, uint32_t seed) {
    return hash32(i * 0x9e3779b9u ^ hash32(k * 0x85ebca6bu + salt * 0xc2b2ae35u + 0x7e57u * seed + 1u));
}

// Fisher-Yates with one hash per step: the same permutations on every run and thread.
void shuffle(std::vector<int>& v, uint32_t k, uint32_t salt, uint32_t seed) {
    for (int i = int(v.size()) - 1; i > 0; --i)
        std::swap(v[i], v[stepHash(uint32_t(i), k, salt, seed) % uint32_t(i + 1)]);
}
}  // namespace

BlurPattern makeBlurPattern(BlurSampling scheme, bool motion, bool lens, int spp, int imageWidth,
                            int tileSize, int permutations, uint32_t seed) {
    BlurPattern p;
    p.scheme = scheme;
    p.motion = motion;
    p.lens = lens;
    p.spp = std::max(1, spp);
    p.tileSize = std::max(1, tileSize);
    p.permutations = std::max(1, permutations);
    p.tilesPerRow = (std::max(1, imageWidth) + p.tileSize - 1) / p.tileSize;
    p.seed = seed;
    if (!p.active()) return p;
    if (scheme == BlurSampling::Simple) {
        frameSamples(seed, p.spp, motion, lens, p.time, p.lensPoint);
    } else if (scheme == BlurSampling::Interleaved) {
        const int N = p.tileSamples(), KK = p.tileSize * p.tileSize, M = p.spp;
        if (N > 65536) throw std::invalid_argument("interleaved blur sampling: spp * K^2 exceeds 65536");
        std::vector<Vec2> square;
        frameSamples(seed, N, motion, lens, p.time, p.lensPoint, &square);
        // Stratified permutations: the N samples are ranked by time (by lens cell for depth of field
        // alone) and cut into M groups of K^2; every pixel of a tile gets one sample of each group, so its
        // M samples are stratified in time as a pixel's own Sobol' samples would be. The paper's random
        // permutations give each pixel an unstratified subset of the N (twice the noise at 256 spp in
        // MotionBlur.MovingSquareCoverageIsTheTimeAveragedSweep). A permutation shuffles which slot takes
        // which group and which pixel takes which member of a group.
        int ax = 1, ay = 1;
        splitSamplesPerPixel(M, ax, ay);
        std::vector<float> key(N);
        for (int n = 0; n < N; ++n)
            key[n] = motion ? p.time[n]
                            : float(std::min(ay - 1, int(square[n].y * ay)) * ax +
                                    std::min(ax - 1, int(square[n].x * ax))) +
                                  square[n].x * 1e-3f;
        std::vector<int> ranked(N);
        std::iota(ranked.begin(), ranked.end(), 0);
        std::stable_sort(ranked.begin(), ranked.end(), [&](int a, int b) { return key[a] < key[b]; });
        p.perm.resize(size_t(p.permutations) * N);
        p.inverse.resize(p.perm.size());
        std::vector<int> slotOfGroup(M), member(KK);
        for (int k = 0; k < p.permutations; ++k) {
            std::iota(slotOfGroup.begin(), slotOfGroup.end(), 0);
            shuffle(slotOfGroup, uint32_t(k), 0xffffu, seed);
            for (int g = 0; g < M; ++g) {
                std::iota(member.begin(), member.end(), 0);
                shuffle(member, uint32_t(k), uint32_t(g), seed);
                for (int j = 0; j < KK; ++j) {
                    const int n = ranked[g * KK + member[j]];
                    const int q = slotOfGroup[g] * KK + j;
                    p.perm[size_t(k) * N + n] = uint16_t(q);
                    p.inverse[size_t(k) * N + q] = uint16_t(n);
                }
            }
        }
    }
    return p;
}

void BlurPattern::sampleAt(int px, int py, int slot, uint32_t sampleIndex, float& t, Vec2& lensOut) const {
    switch (scheme) {
        case BlurSampling::Simple:
            t = time[slot];
            lensOut = lensPoint[slot];
            return;
        case BlurSampling::Interleaved: {
            const int n = tileSampleOf(px, py, slot);
            t = time[n];
            lensOut = lensPoint[n];
            return;
        }
        case BlurSampling::BoundingBox:
            pixelSampleAt(timeLensSeeds(pixelSeed(px, py, seed)), sampleIndex, t, lensOut);
            return;
    }
}

void BlurPattern::pixelSampleAt(const TimeLensSeeds& seeds, uint32_t sampleIndex, float& t,
                                Vec2& lensOut) const {
    t = motion ? bitsToUnit(timeBits(seeds, sampleIndex)) : 0.f;
    lensOut = Vec2{};
    if (lens) {
        uint32_t u, v;
        lensBits(seeds, sampleIndex, u, v);
        lensOut = squareToDisk(bitsToUnit(u), bitsToUnit(v));
    }
}

#if TESSERA_FILM_AVX2
namespace {
// The sampler's bit operations (sampler.h) on eight 32-bit lanes.
__attribute__((target("avx2"))) inline __m256i reverseBits8(__m256i x) {
    // Bytes reversed in each lane, then the bits of each byte by two nibble lookups.
    const __m256i byteSwap = _mm256_setr_epi8(3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12, 3, 2, 1,
                                              0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12);
    const __m256i reversedLow = _mm256_setr_epi8(
        0x00, 0x80, 0x40, 0xc0, 0x20, 0xa0, 0x60, 0xe0, 0x10, 0x90, 0x50, 0xd0, 0x30, 0xb0, 0x70, 0xf0, 0x00,
        0x80, 0x40, 0xc0, 0x20, 0xa0, 0x60, 0xe0, 0x10, 0x90, 0x50, 0xd0, 0x30, 0xb0, 0x70, 0xf0);
    const __m256i reversedHigh =
        _mm256_setr_epi8(0x0, 0x8, 0x4, 0xc, 0x2, 0xa, 0x6, 0xe, 0x1, 0x9, 0x5, 0xd, 0x3, 0xb, 0x7, 0xf, 0x0,
                         0x8, 0x4, 0xc, 0x2, 0xa, 0x6, 0xe, 0x1, 0x9, 0x5, 0xd, 0x3, 0xb, 0x7, 0xf);
    const __m256i nibble = _mm256_set1_epi8(0x0f);
    x = _mm256_shuffle_epi8(x, byteSwap);
    const __m256i low = _mm256_and_si256(x, nibble), high = _mm256_and_si256(_mm256_srli_epi16(x, 4), nibble);
    return _mm256_or_si256(_mm256_shuffle_epi8(reversedLow, low), _mm256_shuffle_epi8(reversedHigh, high));
}
__attribute__((target("avx2"))) inline __m256i laineKarras8(__m256i x, uint32_t seed) {
    x = _mm256_add_epi32(x, _mm256_set1_epi32(int(seed)));
    for (uint32_t c : {0x6c50b47cu, 0xb82f1e52u, 0xc7afe638u, 0x8d22f6e6u})
        x = _mm256_xor_si256(x, _mm256_mullo_epi32(x, _mm256_set1_epi32(int(c))));
    return x;
}
__attribute__((target("avx2"))) inline __m256i nestedUniformScramble8(__m256i x, uint32_t seed) {
    return reverseBits8(laineKarras8(reverseBits8(x), seed));
}
__attribute__((target("avx2"))) inline __m256i sobolBits1Reversed8(__m256i x) {
    x = _mm256_xor_si256(x, _mm256_and_si256(_mm256_srli_epi32(x, 1), _mm256_set1_epi32(0x55555555)));
    x = _mm256_xor_si256(x, _mm256_and_si256(_mm256_srli_epi32(x, 2), _mm256_set1_epi32(0x33333333)));
    x = _mm256_xor_si256(x, _mm256_and_si256(_mm256_srli_epi32(x, 4), _mm256_set1_epi32(0x0f0f0f0f)));
    x = _mm256_xor_si256(x, _mm256_and_si256(_mm256_srli_epi32(x, 8), _mm256_set1_epi32(0x00ff00ff)));
    return _mm256_xor_si256(x, _mm256_and_si256(_mm256_srli_epi32(x, 16), _mm256_set1_epi32(0x0000ffff)));
}
// sobolBits2: the direction numbers of matrix 2 xor-ed for the set bits of each lane's index.
__attribute__((target("avx2"))) inline __m256i sobolBits2x8(__m256i index, uint32_t maxIndex) {
    __m256i r = _mm256_setzero_si256();
    uint32_t v0 = 1u << 31, v1 = 3u << 30;  // as sobolBits2
    for (int j = 0; j < 32 && (maxIndex >> j); ++j) {
        const __m256i bit = _mm256_and_si256(_mm256_srli_epi32(index, j), _mm256_set1_epi32(1));
        r = _mm256_xor_si256(
            r, _mm256_and_si256(_mm256_sub_epi32(_mm256_setzero_si256(), bit), _mm256_set1_epi32(int(v0))));
        const uint32_t next = v1 ^ v0 ^ (v0 >> 2);
        v0 = v1;
        v1 = next;
    }
    return r;
}
__attribute__((target("avx2"))) inline __m256 bitsToUnit8(__m256i bits) {
    return _mm256_mul_ps(_mm256_cvtepi32_ps(_mm256_srli_epi32(bits, 8)), _mm256_set1_ps(1.f / 16777216.f));
}
// squareToDisk (scene/camera.h), the same float operations lane by lane.
__attribute__((target("avx2"))) inline void squareToDisk8(__m256 u, __m256 v, __m256& dx, __m256& dy) {
    const __m256 one = _mm256_set1_ps(1.f), two = _mm256_set1_ps(2.f), zero = _mm256_setzero_ps();
    const __m256 a = _mm256_sub_ps(_mm256_mul_ps(two, u), one), b = _mm256_sub_ps(_mm256_mul_ps(two, v), one);
    const __m256 signBit = _mm256_set1_ps(-0.f);
    const __m256 aMajor =
        _mm256_cmp_ps(_mm256_andnot_ps(signBit, a), _mm256_andnot_ps(signBit, b), _CMP_GT_OQ);
    const __m256 r = _mm256_blendv_ps(b, a, aMajor);
    const __m256 x = _mm256_mul_ps(_mm256_set1_ps(kQuarterPi), _mm256_div_ps(_mm256_blendv_ps(a, b, aMajor),
                                                                             _mm256_blendv_ps(b, a, aMajor)));
    // sinCosQuarterTurn, the same products and sums in the same order.
    const __m256 z = _mm256_mul_ps(x, x);
    const __m256 s = _mm256_add_ps(
        x, _mm256_mul_ps(
               _mm256_mul_ps(x, z),
               _mm256_add_ps(_mm256_set1_ps(kSin3),
                             _mm256_mul_ps(z, _mm256_add_ps(_mm256_set1_ps(kSin5),
                                                            _mm256_mul_ps(z, _mm256_set1_ps(kSin7)))))));
    const __m256 c = _mm256_add_ps(
        _mm256_sub_ps(one, _mm256_mul_ps(_mm256_set1_ps(0.5f), z)),
        _mm256_mul_ps(
            _mm256_mul_ps(z, z),
            _mm256_add_ps(_mm256_set1_ps(kCos4),
                          _mm256_mul_ps(z, _mm256_add_ps(_mm256_set1_ps(kCos6),
                                                         _mm256_mul_ps(z, _mm256_set1_ps(kCos8)))))));
    const __m256 centre =
        _mm256_and_ps(_mm256_cmp_ps(a, zero, _CMP_EQ_OQ), _mm256_cmp_ps(b, zero, _CMP_EQ_OQ));
    dx = _mm256_blendv_ps(_mm256_blendv_ps(_mm256_mul_ps(r, s), _mm256_mul_ps(r, c), aMajor), zero, centre);
    dy = _mm256_blendv_ps(_mm256_blendv_ps(_mm256_mul_ps(r, c), _mm256_mul_ps(r, s), aMajor), zero, centre);
}

__attribute__((target("avx2"))) void pixelSamplesAvx2(const TimeLensSeeds& seeds, const uint32_t* index,
                                                      int n, bool motion, bool lens, float* t,
                                                      Vec2* lensOut) {
    for (int first = 0; first < n; first += 8) {
        const int count = std::min(8, n - first);
        alignas(32) uint32_t idx[8];
        uint32_t maxIndex = 0;
        for (int l = 0; l < 8; ++l) {  // lanes past count repeat the last index (not stored)
            idx[l] = index[first + std::min(l, count - 1)];
            maxIndex = std::max(maxIndex, idx[l]);
        }
        const __m256i i8 = _mm256_load_si256(reinterpret_cast<const __m256i*>(idx));
        alignas(32) float time[8], lx[8], ly[8];
        if (motion)
            _mm256_store_ps(time,
                            bitsToUnit8(nestedUniformScramble8(sobolBits2x8(i8, maxIndex), seeds.time)));
        if (lens) {  // lensBits
            const __m256i shuffled = nestedUniformScramble8(i8, seeds.lensShuffle);
            const __m256i u = reverseBits8(laineKarras8(shuffled, seeds.lensU));
            const __m256i v = reverseBits8(laineKarras8(sobolBits1Reversed8(shuffled), seeds.lensV));
            __m256 dx, dy;
            squareToDisk8(bitsToUnit8(u), bitsToUnit8(v), dx, dy);
            _mm256_store_ps(lx, dx), _mm256_store_ps(ly, dy);
        }
        for (int l = 0; l < count; ++l) {
            t[first + l] = motion ? time[l] : 0.f;
            lensOut[first + l] = lens ? Vec2{lx[l], ly[l]} : Vec2{};
        }
    }
}
}  // namespace
#endif

void BlurPattern::pixelSamplesAt(const TimeLensSeeds& seeds, const uint32_t* index, int n, float* t,
                                 Vec2* lensOut) const {
#if TESSERA_FILM_AVX2
    if (filmAvx2Active()) {
        pixelSamplesAvx2(seeds, index, n, motion, lens, t, lensOut);
        return;
    }
#endif
    for (int i = 0; i < n; ++i) pixelSampleAt(seeds, index[i], t[i], lensOut[i]);
}

}  // namespace tessera
