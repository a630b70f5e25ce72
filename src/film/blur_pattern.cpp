#include "film/blur_pattern.h"

#include <algorithm>
#include <numeric>
#include <stdexcept>

#include "core/random.h"
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
void frameSamples(uint32_t seed, int n, bool motion, bool lens, std::vector<float>& time, std::vector<Vec2>& lensPoint) {
    const uint32_t frameSeed = pixelSeed(0xfffe, 0xfffe, seed ^ 0xb1a5u);
    time.resize(n);
    lensPoint.resize(n);
    for (int i = 0; i < n; ++i) {
        time[i] = motion ? sampleDimension(frameSeed, uint32_t(i), kDimTime) : 0.f;
        lensPoint[i] = lens ? squareToDisk(sampleDimension(frameSeed, uint32_t(i), kDimLensU),
                                           sampleDimension(frameSeed, uint32_t(i), kDimLensV))
                            : Vec2{};
    }
}
}  // namespace

BlurPattern makeBlurPattern(BlurSampling scheme, bool motion, bool lens, int spp, int imageWidth, int tileSize,
                            int permutations, uint32_t seed) {
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
        const int N = p.tileSamples();
        if (N > 65536) throw std::invalid_argument("interleaved blur sampling: spp * K^2 exceeds 65536");
        frameSamples(seed, N, motion, lens, p.time, p.lensPoint);
        p.perm.resize(size_t(p.permutations) * N);
        p.inverse.resize(p.perm.size());
        std::vector<uint16_t> order(N);
        for (int k = 0; k < p.permutations; ++k) {
            std::iota(order.begin(), order.end(), uint16_t(0));
            // Fisher-Yates with a hash per step: the same permutations on every run and thread.
            for (int i = N - 1; i > 0; --i) {
                const uint32_t h = hash32(uint32_t(i) * 0x9e3779b9u ^ hash32(uint32_t(k) + 0x7e57u * seed + 1u));
                std::swap(order[i], order[h % uint32_t(i + 1)]);
            }
            for (int n = 0; n < N; ++n) {
                p.perm[size_t(k) * N + n] = order[n];
                p.inverse[size_t(k) * N + order[n]] = uint16_t(n);
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
        case BlurSampling::BoundingBox: {
            const uint32_t ps = pixelSeed(px, py, seed);
            t = motion ? sampleDimension(ps, sampleIndex, kDimTime) : 0.f;
            lensOut = lens ? squareToDisk(sampleDimension(ps, sampleIndex, kDimLensU),
                                          sampleDimension(ps, sampleIndex, kDimLensV))
                           : Vec2{};
            return;
        }
    }
}

}  // namespace tessera
