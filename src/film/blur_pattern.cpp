#include "film/blur_pattern.h"

#include <algorithm>
#include <numeric>
#include <stdexcept>

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

}  // namespace tessera
