// Where each camera sample sits in time and on the lens: the three UVT schemes of Sattler and
// Steinberger's Reyes motion blur and depth of field (paper 000, sec. 3.3; docs/motion.md). A scheme only
// decides which (t, lens) each film sample gets; both engines then render that sample (Reyes by moving
// the micropolygon to it, the ray tracer by tracing from the lens at that time), so they agree per scheme.
//  - Simple: sample slot i of every pixel has the same (t_i, lens_i): an accumulation buffer of spp
//    images (ghosting at low sample counts; one micropolygon move per slot).
//  - Interleaved: K x K pixel tiles share N = spp K^2 distinct (t, lens) samples; each tile assigns them
//    to its pixels' slots by one of P permutations, perm = (tilenumber + tile_x + tile_y) mod P with
//    tilenumber = tile_y * ceil(width / K) + tile_x (the paper's eqs. 2 and 3).
//  - BoundingBox: every pixel its own (t, lens) per slot, from the film's Sobol' point (time dimension and
//    the lens pair, film/sampler.h): the same samples for every micropolygon at that pixel.
#pragma once
#include <cstdint>
#include <vector>

#include "core/vec.h"
#include "film/sampler.h"

namespace tessera {

enum class BlurSampling : uint8_t { Simple, Interleaved, BoundingBox };
const char* blurSamplingName(BlurSampling s);  // "simple", "interleaved", "bbox"

struct BlurPattern {
    BlurSampling scheme = BlurSampling::BoundingBox;
    bool motion = false, lens = false;  // which dimensions vary (time; lens position)
    int spp = 1;
    int tileSize = 4;       // interleaved: K
    int permutations = 64;  // interleaved: P
    int tilesPerRow = 1;    // interleaved: ceil(image width / K)
    uint32_t seed = 0;
    // Simple: spp entries (one per slot); interleaved: N = spp K^2 entries (one per tile sample).
    std::vector<float> time;
    std::vector<Vec2> lensPoint;  // on the unit disk
    // Interleaved: perm[p * N + n] = subpixel q of tile sample n under permutation p (pixel q % K^2 of
    // the tile in row-major order, slot q / K^2), inverse[p * N + q] = n.
    std::vector<uint16_t> perm, inverse;

    bool active() const { return motion || lens; }
    int tileSamples() const { return spp * tileSize * tileSize; }
    // Interleaved: the permutation of the tile holding pixel (px, py) (the paper's eq. 3).
    int tilePermutation(int tileX, int tileY) const {
        const int tileNumber = tileY * tilesPerRow + tileX;
        return (tileNumber + tileX + tileY) % permutations;
    }
    // Interleaved: the tile sample that slot `slot` of pixel (px, py) gets.
    int tileSampleOf(int px, int py, int slot) const {
        const int K = tileSize, tx = px / K, ty = py / K;
        const int q = slot * K * K + (py - ty * K) * K + (px - tx * K);
        return inverse[size_t(tilePermutation(tx, ty)) * tileSamples() + q];
    }
    // Normalised time in [0,1) and lens point of a film sample (pixel, slot, its Sobol' sample index).
    void sampleAt(int px, int py, int slot, uint32_t sampleIndex, float& t, Vec2& lensOut) const;
    // BoundingBox: the same for a sample of the pixel whose seeds are `seeds`
    // (timeLensSeeds(pixelSeed(px, py, seed)), prepared once per pixel by the film).
    void pixelSampleAt(const TimeLensSeeds& seeds, uint32_t sampleIndex, float& t, Vec2& lensOut) const;
    // pixelSampleAt for n samples of one pixel (sample indices `index`), eight at a time with AVX2 when the
    // CPU has it (the same bits: integer hashing, and squareToDisk's float operations lane by lane).
    void pixelSamplesAt(const TimeLensSeeds& seeds, const uint32_t* index, int n, float* t,
                        Vec2* lensOut) const;
};

// `motion` / `lens`: whether the frame blurs in time / has a lens. Interleaved needs spp K^2 <= 65536.
BlurPattern makeBlurPattern(BlurSampling scheme, bool motion, bool lens, int spp, int imageWidth,
                            int tileSize, int permutations, uint32_t seed);

}  // namespace tessera
