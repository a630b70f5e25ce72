#include "film/film.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <type_traits>
#include <utility>
#if defined(__GNUC__) && defined(__x86_64__)
#include <immintrin.h>
#define TESSERA_FILM_AVX2 1
#endif

#include "core/cpu.h"

namespace tessera {

namespace {

#if TESSERA_FILM_AVX2
// The film's 32-bit hashes (core/random.h, film/sampler.h) in 8 lanes.
#define TESSERA_AVX2_INLINE __attribute__((target("avx2"), always_inline)) inline
TESSERA_AVX2_INLINE __m256i mulLanes(__m256i a, uint32_t c) {
    return _mm256_mullo_epi32(a, _mm256_set1_epi32(int(c)));
}
TESSERA_AVX2_INLINE __m256i hash32Lanes(__m256i v) {
    v = _mm256_xor_si256(v, _mm256_srli_epi32(v, 16));
    v = mulLanes(v, 0x7feb352dU);
    v = _mm256_xor_si256(v, _mm256_srli_epi32(v, 15));
    v = mulLanes(v, 0x846ca68bU);
    return _mm256_xor_si256(v, _mm256_srli_epi32(v, 16));
}
TESSERA_AVX2_INLINE __m256i laineKarrasLanes(__m256i v, __m256i seed) {
    v = _mm256_add_epi32(v, seed);
    v = _mm256_xor_si256(v, mulLanes(v, 0x6c50b47cu));
    v = _mm256_xor_si256(v, mulLanes(v, 0xb82f1e52u));
    v = _mm256_xor_si256(v, mulLanes(v, 0xc7afe638u));
    return _mm256_xor_si256(v, mulLanes(v, 0x8d22f6e6u));
}
// ((v & mask) << shift) | ((v >> shift) & mask): one step of a bit reversal.
TESSERA_AVX2_INLINE __m256i swapBitsLanes(__m256i v, uint32_t mask, int shift) {
    const __m256i m = _mm256_set1_epi32(int(mask));
    return _mm256_or_si256(_mm256_slli_epi32(_mm256_and_si256(v, m), shift),
                           _mm256_and_si256(_mm256_srli_epi32(v, shift), m));
}
#undef TESSERA_AVX2_INLINE

// filmSamplesFixed for a tile whose lattice has fewer than 8 strata a pixel, all powers of two (1, 2 or 4
// samples: the ray tracer's usual 4), 8 samples at a time: lane L takes sample L % spp of the (L / spp)-th
// pixel of the group, and the pixel's seeds, the two Laine-Karras permutations, the bit reversal and the
// stratum slot are the scalar loop's 32-bit integer operations in vector lanes (so the same bits); the
// points then go to their slots one by one. Per pixel, the scalar loop spends about 90 instructions a
// sample on these hashes, where a tile of 16 samples a pixel takes the chunked 16-bit path instead.
// Pixels past the last full group of the row take the scalar loop.
__attribute__((target("avx2"))) void tilePositionsFewAvx2(const FilmPattern& fp, Rect reg, int32_t* x,
                                                          int32_t* y, uint32_t* index) {
    const int spp = fp.nx * fp.ny, perGroup = 8 / spp;
    const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    const __m256i sample = _mm256_and_si256(lane, _mm256_set1_epi32(spp - 1));
    const __m256i pixelOfLane = _mm256_srli_epi32(lane, fp.lx + fp.ly);  // log2(spp) = lx + ly
    alignas(32) uint32_t sobolIndex[8];
    for (int l = 0; l < 8; ++l) sobolIndex[l] = sobolBits1Reversed(uint32_t(l & (spp - 1)));
    const __m256i sobol = _mm256_load_si256(reinterpret_cast<const __m256i*>(sobolIndex));
    const __m256i lowByte = _mm256_set1_epi32(0xff);
    const uint32_t scrambleX = 0x9e3779b9u * (2 * kDimFilmX + 1),
                   scrambleY = 0x9e3779b9u * (2 * kDimFilmY + 1);
    alignas(32) int32_t ox[8], oy[8], slot[8];
    size_t row = 0;  // first slot of the row's first pixel
    const size_t rowSlots = size_t(reg.width()) * size_t(spp);
    for (int py = reg.y0; py < reg.y1; ++py, row += rowSlots) {
        int px = reg.x0;
        for (; px + perGroup <= reg.x1; px += perGroup) {
            const __m256i pixelX = _mm256_add_epi32(_mm256_set1_epi32(px), pixelOfLane);
            const __m256i key =
                _mm256_xor_si256(_mm256_or_si256(_mm256_set1_epi32(int((uint32_t(py) & 0xffffu) << 16)),
                                                 _mm256_and_si256(pixelX, _mm256_set1_epi32(0xffff))),
                                 _mm256_set1_epi32(int(fp.seedHash)));
            const __m256i ps = hash32Lanes(key);
            const __m256i seedX = hash32Lanes(_mm256_add_epi32(ps, _mm256_set1_epi32(int(scrambleX))));
            const __m256i seedY = hash32Lanes(_mm256_add_epi32(ps, _mm256_set1_epi32(int(scrambleY))));
            const __m256i lowX = _mm256_and_si256(laineKarrasLanes(sample, seedX), lowByte);
            const __m256i lowY = _mm256_and_si256(laineKarrasLanes(sobol, seedY), lowByte);
            __m256i both = _mm256_or_si256(lowX, _mm256_slli_epi32(lowY, 8));  // reverseBitsInBytes
            both = swapBitsLanes(both, 0x0f0f0f0fu, 4);
            both = swapBitsLanes(both, 0x33333333u, 2);
            both = swapBitsLanes(both, 0x55555555u, 1);
            const __m256i offX = _mm256_and_si256(both, lowByte), offY = _mm256_srli_epi32(both, 8);
            const __m256i stratum =
                _mm256_or_si256(_mm256_slli_epi32(_mm256_srli_epi32(offY, 8 - fp.ly), fp.lx),
                                _mm256_srli_epi32(offX, 8 - fp.lx));
            _mm256_store_si256(reinterpret_cast<__m256i*>(ox),
                               _mm256_add_epi32(offX, _mm256_slli_epi32(pixelX, 8)));
            _mm256_store_si256(reinterpret_cast<__m256i*>(oy), offY);
            _mm256_store_si256(reinterpret_cast<__m256i*>(slot), stratum);
            const size_t first = row + size_t(px - reg.x0) * size_t(spp);
            const int32_t y0 = py << 8;
            for (int l = 0; l < 8; ++l) {
                const size_t at = first + size_t(l & ~(spp - 1)) + size_t(slot[l]);
                x[at] = ox[l];
                y[at] = y0 + oy[l];
                index[at] = uint32_t(l & (spp - 1));
            }
        }
        for (; px < reg.x1; ++px) {
            const size_t at = row + size_t(px - reg.x0) * size_t(spp);
            filmSamplesFixed(fp, px, py, x + at, y + at, index + at);
        }
    }
}
#endif

}  // namespace

void SampleTile::reset(Rect reg, int nx_, int ny_, uint32_t seed, float farZ, SamplerKind sampler,
                       uint32_t channels_, const std::vector<std::string>& aovNames_) {
    region = reg;
    nx = nx_;
    ny = ny_;
    spp = nx * ny;
    strataPositionsBuilt = false;
    strataWrites = false;
    size_t pixels = size_t(reg.width()) * reg.height();
    size_t n = pixels * spp;
    sx.resize(n);
    sy.resize(n);
    sampleIndex.resize(n);
    farDepth = farZ;
    pixelFillPending = deferPixelFill;
    if (deferPixelFill) {
        for (std::vector<float>* v : {&z, &r, &g, &b, &a}) v->resize(n);
    } else {
        z.assign(n, farZ);
        r.assign(n, 0.f);
        g.assign(n, 0.f);
        b.assign(n, 0.f);
        a.assign(n, 0.f);
    }
    pixelHit.assign(pixels, 0);
    channels = channels_;
    auto sized = [&](auto& v, uint32_t bit, auto value) {
        if (has(bit))
            v.assign(n, value);
        else
            v.clear();
    };
    sized(objectId, kChannelObjectId, kNoObject);
    sized(normalX, kChannelNormal, 0.f);
    sized(normalY, kChannelNormal, 0.f);
    sized(normalZ, kChannelNormal, 0.f);
    sized(shadowCount, kChannelShadowCount, uint8_t(0));
    sized(hasTexture, kChannelHasTexture, uint8_t(0));
    sized(albedo, kChannelAlbedo, Vec3{0, 0, 0});
    sized(position, kChannelPosition, Vec3{0, 0, 0});
    sized(surfaceColor, kChannelSurfaceColor, Vec3{0, 0, 0});
    aovNames = aovNames_;
    aovValues.resize(aovNames.size());
    for (auto& v : aovValues) v.assign(n, 0.f);
    size_t i = 0;
    if (sampler == SamplerKind::Sobol) {
        const FilmPattern pattern = filmPattern(nx, ny, seed);
#if TESSERA_FILM_AVX2
        if (pattern.lx >= 0 && pattern.ly >= 0 && spp < 8 && filmAvx2Active()) {
            tilePositionsFewAvx2(pattern, reg, sx.data(), sy.data(), sampleIndex.data());
            return;
        }
#endif
        if (spp == 1) {
            for (int py = reg.y0; py < reg.y1; ++py)
                for (int px = reg.x0; px < reg.x1; ++px, ++i)
                    filmSampleSingleFixed(pattern, px, py, sx[i], sy[i]);
            std::fill(sampleIndex.begin(), sampleIndex.end(), 0u);
            return;
        }
        for (int py = reg.y0; py < reg.y1; ++py)
            for (int px = reg.x0; px < reg.x1; ++px, i += spp)
                filmSamplesFixed(pattern, px, py, &sx[i], &sy[i], &sampleIndex[i]);
        return;
    }
    for (int py = reg.y0; py < reg.y1; ++py)
        for (int px = reg.x0; px < reg.x1; ++px)
            for (int s = 0; s < spp; ++s, ++i) {
                if (sampler == SamplerKind::Centred) {
                    sx[i] = (px << kSubpixelBits) + ((s % nx) * 2 + 1) * (1 << (kSubpixelBits - 1)) / nx;
                    sy[i] = (py << kSubpixelBits) + ((s / nx) * 2 + 1) * (1 << (kSubpixelBits - 1)) / ny;
                } else {
                    samplePositionFixed(px, py, s, nx, ny, seed, sx[i], sy[i]);
                }
                sampleIndex[i] = uint32_t(s);
            }
}

namespace {

// Calls visit(pixelOrder, strataOrder, rowLength) for each pixel's row of nx slots: slots syi * nx ..
// syi * nx + nx - 1 of pixel (px, py) start at pixelOrder in the pixel-ordered arrays and are strata
// (px * nx .. px * nx + nx - 1, py * ny + syi), contiguous from strataOrder in stratum order. The row
// length is a template argument for the usual lattices, so that a copy of a row is a fixed-size move (a
// runtime nx left it a scalar loop of about 18 instructions a sample).
template <class Visit>
void forEachSlotRow(int tw, int th, int nx, int ny, Visit&& visit) {
    auto rows = [&]<int kNx>(std::integral_constant<int, kNx>) {
        const int rowLength = kNx > 0 ? kNx : nx;
        const size_t pixelSamples = size_t(rowLength) * size_t(ny), width = size_t(tw);
        size_t k = 0;
        for (int py = 0; py < th; ++py)
            for (int syi = 0; syi < ny; ++syi) {
                size_t s0 = size_t(py) * width * pixelSamples + size_t(syi * rowLength);
                for (int px = 0; px < tw; ++px, s0 += pixelSamples, k += size_t(rowLength))
                    visit(s0, k, std::integral_constant<int, kNx>{}, rowLength);
            }
    };
    switch (nx) {
        case 2:
            rows(std::integral_constant<int, 2>{});
            break;
        case 4:
            rows(std::integral_constant<int, 4>{});
            break;
        case 8:
            rows(std::integral_constant<int, 8>{});
            break;
        default:
            rows(std::integral_constant<int, 0>{});
    }
}

// Copies one row of slots (length kNx when it is not 0, else rowLength).
template <int kNx, class T>
inline void copySlots(T* __restrict to, const T* __restrict from, int rowLength) {
    std::memcpy(to, from, sizeof(T) * size_t(kNx > 0 ? kNx : rowLength));
}

}  // namespace

void SampleTile::buildStrataOrder() {
    const int tw = region.width(), th = region.height(), w = tw * nx, h = th * ny;
    const size_t n = sampleCount();
    strataX.resize(n + 8);  // no fill when the size is kept: every slot is written below
    strataY.resize(n + 8);
    strataColumn.resize(size_t(w));
    strataRow.resize(size_t(h));
    for (int ox = 0; ox < w; ++ox) strataColumn[size_t(ox)] = {ox / nx, ox % nx};
    for (int oy = 0; oy < h; ++oy) strataRow[size_t(oy)] = {(oy / ny) * tw, (oy % ny) * nx};
    // Stratum (px * nx + sxi, py * ny + syi) holds slot syi * nx + sxi of pixel (px, py).
    forEachSlotRow(tw, th, nx, ny,
                   [&]<int kNx>(size_t s0, size_t k, std::integral_constant<int, kNx>, int len) {
                       copySlots<kNx>(strataX.data() + k, sx.data() + s0, len);
                       copySlots<kNx>(strataY.data() + k, sy.data() + s0, len);
                   });
    for (size_t i = n; i < n + 8; ++i) strataX[i] = strataY[i] = 0;
    strataPositionsBuilt = true;
}

void SampleTile::enterStrataOrder() {
    if (strataWrites) return;
    if (!hasStrataOrder()) buildStrataOrder();
    const size_t n = sampleCount();
    for (std::vector<float>* v : {&strataZ, &strataR, &strataG, &strataB, &strataA}) v->resize(n + 8);
    strataCovered.assign(n + 8, 0);
    if (pixelFillPending) {  // reset's fill, straight into stratum order; leaveStrataOrder writes every slot
        std::fill(strataZ.begin(), strataZ.end(), farDepth);
        for (std::vector<float>* v : {&strataR, &strataG, &strataB, &strataA})
            std::fill(v->begin(), v->end(), 0.f);
        pixelFillPending = false;
    } else {
        forEachSlotRow(region.width(), region.height(), nx, ny,
                       [&]<int kNx>(size_t s0, size_t k, std::integral_constant<int, kNx>, int len) {
                           copySlots<kNx>(strataZ.data() + k, z.data() + s0, len);
                           copySlots<kNx>(strataR.data() + k, r.data() + s0, len);
                           copySlots<kNx>(strataG.data() + k, g.data() + s0, len);
                           copySlots<kNx>(strataB.data() + k, b.data() + s0, len);
                           copySlots<kNx>(strataA.data() + k, a.data() + s0, len);
                       });
    }
    strataWrites = true;
}

void SampleTile::leaveStrataOrder() {
    if (pixelFillPending) {  // nothing rasterized in stratum order: reset's deferred fill
        std::fill(z.begin(), z.end(), farDepth);
        for (std::vector<float>* v : {&r, &g, &b, &a}) std::fill(v->begin(), v->end(), 0.f);
        pixelFillPending = false;
    }
    if (!strataWrites) return;
    const size_t spp_ = size_t(spp);
    forEachSlotRow(region.width(), region.height(), nx, ny,
                   [&]<int kNx>(size_t s0, size_t k, std::integral_constant<int, kNx>, int len) {
                       copySlots<kNx>(z.data() + s0, strataZ.data() + k, len);
                       copySlots<kNx>(r.data() + s0, strataR.data() + k, len);
                       copySlots<kNx>(g.data() + s0, strataG.data() + k, len);
                       copySlots<kNx>(b.data() + s0, strataB.data() + k, len);
                       copySlots<kNx>(a.data() + s0, strataA.data() + k, len);
                       int32_t covered = 0;
                       for (int i = 0; i < (kNx > 0 ? kNx : len); ++i)
                           covered |= strataCovered[k + size_t(i)];
                       if (covered) pixelHit[s0 / spp_] = 1;
                   });
    strataWrites = false;
}

void SampleTile::setBlur(const BlurPattern* pattern) {
    blur = pattern && pattern->active() ? pattern : nullptr;
    if (!blur) {
        time.clear();
        lens.clear();
        return;
    }
    const size_t n = sampleCount();
    time.resize(n);
    lens.resize(n);
    size_t i = 0;
    if (blur->scheme == BlurSampling::BoundingBox) {
        // Per pixel: its seeds once (BlurPattern::sampleAt for every sample would hash them per sample).
        for (int py = region.y0; py < region.y1; ++py)
            for (int px = region.x0; px < region.x1; ++px) {
                const TimeLensSeeds seeds = timeLensSeeds(pixelSeed(px, py, blur->seed));
                blur->pixelSamplesAt(seeds, &sampleIndex[i], spp, &time[i], &lens[i]);
                i += size_t(spp);
            }
        return;
    }
    for (int py = region.y0; py < region.y1; ++py)
        for (int px = region.x0; px < region.x1; ++px)
            for (int s = 0; s < spp; ++s, ++i) blur->sampleAt(px, py, s, sampleIndex[i], time[i], lens[i]);
}

void Image::addPlanes(uint32_t channels, const std::vector<std::string>& aovNames) {
    const size_t n = size_t(width) * height;
    auto add = [&](const std::string& name, int components, bool integer, float background,
                   bool color = false) {
        ImagePlane p;
        p.name = name;
        p.components = components;
        p.integer = integer;
        p.color = color;
        if (integer)
            p.ids.assign(n, kNoObject);
        else
            p.values.assign(n * components, background);
        planes.push_back(std::move(p));
    };
    if (channels & kChannelObjectId) add("id", 1, true, 0.f);
    if (channels & kChannelDepth) add("z", 1, false, std::numeric_limits<float>::infinity());
    if (channels & kChannelNormal) add("N", 3, false, 0.f);
    if (channels & kChannelShadowCount) add("shadows", 1, false, 0.f);
    if (channels & kChannelHasTexture) add("textured", 1, false, 0.f);
    if (channels & kChannelAlbedo) add("albedo", 3, false, 0.f, true);
    if (channels & kChannelPosition) add("P", 3, false, 0.f);
    if (channels & kChannelSurfaceColor) add("Cs", 3, false, 0.f, true);
    for (const std::string& a : aovNames) add(a, 1, false, 0.f);
}

const ImagePlane* Image::plane(const std::string& name) const {
    for (const ImagePlane& p : planes)
        if (p.name == name) return &p;
    return nullptr;
}
ImagePlane* Image::plane(const std::string& name) {
    for (ImagePlane& p : planes)
        if (p.name == name) return &p;
    return nullptr;
}

size_t nearestSampleToCentre(const SampleTile& tile, int px, int py) {
    const size_t first =
        (size_t(py - tile.region.y0) * tile.region.width() + (px - tile.region.x0)) * tile.spp;
    const int64_t cx = (int64_t(px) << kSubpixelBits) + (1 << (kSubpixelBits - 1));
    const int64_t cy = (int64_t(py) << kSubpixelBits) + (1 << (kSubpixelBits - 1));
    size_t best = first;
    int64_t bestD = INT64_MAX;
    for (size_t i = first; i < first + size_t(tile.spp); ++i) {
        const int64_t dx = tile.sx[i] - cx, dy = tile.sy[i] - cy, d = dx * dx + dy * dy;
        if (d < bestD) bestD = d, best = i;
    }
    return best;
}

namespace {

// The samples within the pixel filter's reach (radii rx, ry, which the callers take from the filter once
// per tile) of pixel (px, py): `rows` rows of `length` contiguous samples, the first starting at sample
// `first` and each row `stride` after the one before; (cx, cy) the pixel centre in fixed point. The window
// that colour and the filtered planes share.
struct ReachWindow {
    size_t first, length, stride;
    int rows, cx, cy;
};
inline ReachWindow reachWindow(const SampleTile& tile, int rx, int ry, int px, int py) {
    const Rect& reg = tile.region;
    const int qx0 = std::max(px - rx, reg.x0), qx1 = std::min(px + rx, reg.x1 - 1);
    const int qy0 = std::max(py - ry, reg.y0), qy1 = std::min(py + ry, reg.y1 - 1);
    ReachWindow w;
    w.stride = size_t(reg.width()) * size_t(tile.spp);
    w.first = size_t(qy0 - reg.y0) * w.stride + size_t(qx0 - reg.x0) * size_t(tile.spp);
    w.length = size_t(qx1 - qx0 + 1) * size_t(tile.spp);
    w.rows = qy1 - qy0 + 1;
    w.cx = (px << kSubpixelBits) + (1 << (kSubpixelBits - 1));
    w.cy = (py << kSubpixelBits) + (1 << (kSubpixelBits - 1));
    return w;
}

// Calls visit(i, w) for every sample i of the window, w its tabulated filter weight.
template <class Visit>
inline void forEachSampleInReach(const SampleTile& tile, const PixelFilter& filter, int rx, int ry, int px,
                                 int py, Visit&& visit) {
    const ReachWindow win = reachWindow(tile, rx, ry, px, py);
    for (int row = 0; row < win.rows; ++row) {
        const size_t begin = win.first + size_t(row) * win.stride, end = begin + win.length;
        for (size_t i = begin; i < end; ++i)
            visit(i, filter.tabulatedX(tile.sx[i] - win.cx) * filter.tabulatedY(tile.sy[i] - win.cy));
    }
}

// The planes beside RGBA for the pixels of `target`: nearest-sample planes (id, depth, has-texture) from the
// pixel's sample nearest its centre; filtered planes (normal, shadow count, AOVs) with the pixel filter over
// covered samples (weights times coverage, so background does not dilute them).
void reconstructPlanes(const SampleTile& tile, const PixelFilter& filter, Rect target, Image& out) {
    const int rx = filter.radiusX(), ry = filter.radiusY();
    ImagePlane* id = tile.has(kChannelObjectId) ? out.plane("id") : nullptr;
    ImagePlane* depth = out.plane("z");
    ImagePlane* textured = tile.has(kChannelHasTexture) ? out.plane("textured") : nullptr;
    ImagePlane* normal = tile.has(kChannelNormal) ? out.plane("N") : nullptr;
    ImagePlane* shadows = tile.has(kChannelShadowCount) ? out.plane("shadows") : nullptr;
    // The surface AOVs: three filtered components each, at acc[4 + aovs ...] after the AOV planes.
    ImagePlane* surface[3] = {tile.has(kChannelAlbedo) ? out.plane("albedo") : nullptr,
                              tile.has(kChannelPosition) ? out.plane("P") : nullptr,
                              tile.has(kChannelSurfaceColor) ? out.plane("Cs") : nullptr};
    const std::vector<Vec3>* surfaceValues[3] = {&tile.albedo, &tile.position, &tile.surfaceColor};
    const bool anySurface = surface[0] || surface[1] || surface[2];
    std::vector<std::pair<ImagePlane*, const std::vector<float>*>> aovs;
    for (size_t k = 0; k < tile.aovNames.size(); ++k)
        if (ImagePlane* p = out.plane(tile.aovNames[k])) aovs.push_back({p, &tile.aovValues[k]});
    const bool filtered = normal || shadows || !aovs.empty() || anySurface;
    if (!id && !depth && !textured && !filtered) return;
    const size_t surfaceAt = 4 + aovs.size();
    std::vector<float> acc(surfaceAt + 9);
    for (int py = target.y0; py < target.y1; ++py) {
        for (int px = target.x0; px < target.x1; ++px) {
            const size_t pix = out.index(px, py);
            const size_t near = nearestSampleToCentre(tile, px, py);
            const bool covered = tile.a[near] > 0.f;
            if (id) id->ids[pix] = tile.objectId[near];
            if (depth) depth->values[pix] = covered ? tile.z[near] : std::numeric_limits<float>::infinity();
            if (textured) textured->values[pix] = covered ? float(tile.hasTexture[near]) : 0.f;
            if (!filtered) continue;
            std::fill(acc.begin(), acc.end(), 0.f);
            float sw = 0.f;
            forEachSampleInReach(tile, filter, rx, ry, px, py, [&](size_t i, float filterWeight) {
                if (!(tile.a[i] > 0.f)) return;
                const float w = filterWeight * tile.a[i];
                sw += w;
                if (normal) {
                    acc[0] += w * tile.normalX[i];
                    acc[1] += w * tile.normalY[i];
                    acc[2] += w * tile.normalZ[i];
                }
                if (shadows) acc[3] += w * float(tile.shadowCount[i]);
                for (size_t k = 0; k < aovs.size(); ++k) acc[4 + k] += w * (*aovs[k].second)[i];
                for (int q = 0; q < 3; ++q)
                    if (surface[q]) {
                        const Vec3 v = (*surfaceValues[q])[i];
                        acc[surfaceAt + 3 * q] += w * v.x, acc[surfaceAt + 3 * q + 1] += w * v.y,
                            acc[surfaceAt + 3 * q + 2] += w * v.z;
                    }
            });
            if (!(sw != 0.f)) continue;
            if (normal) {
                const Vec3 N = normalize(Vec3{acc[0], acc[1], acc[2]});
                normal->values[pix * 3] = N.x, normal->values[pix * 3 + 1] = N.y,
                                     normal->values[pix * 3 + 2] = N.z;
            }
            if (shadows) shadows->values[pix] = acc[3] / sw;
            for (size_t k = 0; k < aovs.size(); ++k) aovs[k].first->values[pix] = acc[4 + k] / sw;
            for (int q = 0; q < 3; ++q)
                if (surface[q])
                    for (int j = 0; j < 3; ++j)
                        surface[q]->values[pix * 3 + j] = acc[surfaceAt + 3 * q + j] / sw;
        }
    }
}

}  // namespace

namespace {

std::atomic<bool> gFilmAvx2Allowed{true};

// A pixel's filtered colour, coverage and weight: sums[0..4] = sum of w r, w g, w b, w a and w over the
// samples in reach (forEachSampleInReach's window, w its filter weight). Summed in eight lanes, lane j taking
// the samples j, j + 8, ... of each row of the window, and the lanes then added as (0+4, 1+5, 2+6, 3+7),
// (0+2, 1+3), 0+1: the order the AVX2 path adds in, so both give the same bits.
struct LaneSums {
    float v[5][8] = {};
};
inline void reduceLanes(const LaneSums& l, float sums[5]) {
    for (int c = 0; c < 5; ++c) {
        const float* x = l.v[c];
        const float a0 = x[0] + x[4], a1 = x[1] + x[5], a2 = x[2] + x[6], a3 = x[3] + x[7];
        sums[c] = (a0 + a2) + (a1 + a3);
    }
}
inline void addSample(LaneSums& l, int lane, float w, const SampleTile& tile, size_t i) {
    l.v[0][lane] += w * tile.r[i];
    l.v[1][lane] += w * tile.g[i];
    l.v[2][lane] += w * tile.b[i];
    l.v[3][lane] += w * tile.a[i];
    l.v[4][lane] += w;
}

// A pixel's RGBA from its sums: the colour divided by the weight, the alpha clamped to [0, 1].
inline void writePixel(float* o, const float sums[5]) {
    const float k = sums[4] != 0.f ? 1.f / sums[4] : 0.f;
    o[0] = sums[0] * k;
    o[1] = sums[1] * k;
    o[2] = sums[2] * k;
    o[3] = std::clamp(sums[3] * k, 0.f, 1.f);
}

void pixelSumsScalar(const SampleTile& tile, const PixelFilter& filter, int rx, int ry, int px, int py,
                     float sums[5]) {
    const ReachWindow win = reachWindow(tile, rx, ry, px, py);
    LaneSums l;
    for (int row = 0; row < win.rows; ++row) {
        const size_t begin = win.first + size_t(row) * win.stride, end = begin + win.length;
        for (size_t i = begin; i < end; ++i)
            addSample(l, int((i - begin) & 7u),
                      filter.tabulatedX(tile.sx[i] - win.cx) * filter.tabulatedY(tile.sy[i] - win.cy), tile,
                      i);
    }
    reduceLanes(l, sums);
}

#if TESSERA_FILM_AVX2
// table[from[j] + offset] for j < n, into to[j] (8 at a time by gathers, the rest one by one).
__attribute__((target("avx2"))) void tabulateAvx2(const std::vector<float>& table, const int32_t* from,
                                                  int offset, size_t n, float* to) {
    const __m256i bias = _mm256_set1_epi32(offset);
    size_t j = 0;
    for (; j + 8 <= n; j += 8) {
        const __m256i o =
            _mm256_add_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(from + j)), bias);
        _mm256_storeu_ps(to + j, _mm256_i32gather_ps(table.data(), o, 4));
    }
    for (; j < n; ++j) to[j] = table[size_t(from[j] + offset)];
}

// reconstruct's colour for the pixels of `target` with reach (a pixel without: transparent black),
// pixelSumsScalar's sums eight samples at a time with the same bits. A sample's weight is tabX(dx) *
// tabY(dy), separable (filter.h), and each factor is shared: a sample's X factor toward pixel column px is
// the same for all 2 ry + 1 rows of target pixels it reaches, its Y factor toward row py the same for all
// 2 rx + 1 columns. So each target row first tabulates the factors it needs: the Y factors of the tile rows
// in its reach toward it (rowY), and the X factors of each tile row toward every target column, kept in a
// ring of 2 ry + 1 tile rows (a row's are tabulated once, when the first target row reaches it). The sums
// then load both factors instead of gathering them from the tables per window sample: (2 rx + 1) + (2 ry
// + 1) table gathers a sample instead of 2 (2 rx + 1)(2 ry + 1).
__attribute__((target("avx2"))) void reconstructColourAvx2(const SampleTile& tile, const PixelFilter& filter,
                                                           Rect target, const uint8_t* reach, Image& out) {
    const Rect& reg = tile.region;
    const int rx = filter.radiusX(), ry = filter.radiusY();
    const int tw = reg.width(), spp = tile.spp, targetWidth = target.width();
    const int windowRows = 2 * ry + 1;
    const size_t rowSamples = size_t(tw) * size_t(spp);
    const size_t xStride = size_t(2 * rx + 1) * size_t(spp);  // a target pixel's window row, at most
    const size_t xRingRow = size_t(targetWidth) * xStride;
    thread_local std::vector<float> rowY, ringX;
    thread_local std::vector<int> ringRow;
    rowY.resize(size_t(windowRows) * rowSamples + 8);
    ringX.resize(size_t(windowRows) * xRingRow + 8);
    ringRow.assign(size_t(windowRows), INT32_MIN);
    const int32_t* sx = tile.sx.data();
    const int32_t* sy = tile.sy.data();
    for (int py = target.y0; py < target.y1; ++py) {
        const uint8_t* rowReach = reach + size_t(py - reg.y0) * tw + (target.x0 - reg.x0);
        bool anyReach = false;
        for (int x = 0; x < targetWidth; ++x) anyReach |= rowReach[x] != 0;
        float* o = out.pixel(target.x0, py);
        if (!anyReach) {
            std::fill(o, o + 4 * size_t(targetWidth), 0.f);
            continue;
        }
        const int qy0 = std::max(py - ry, reg.y0), qy1 = std::min(py + ry, reg.y1 - 1);
        const int cy = (py << kSubpixelBits) + (1 << (kSubpixelBits - 1));
        for (int qy = qy0; qy <= qy1; ++qy) {
            const size_t rowStart = size_t(qy - reg.y0) * rowSamples;
            tabulateAvx2(filter.tableY, sy + rowStart, filter.tableBiasY - cy, rowSamples,
                         rowY.data() + size_t(qy - qy0) * rowSamples);
            float* ring = ringX.data() + size_t((qy - reg.y0) % windowRows) * xRingRow;
            int& ringHolds = ringRow[size_t((qy - reg.y0) % windowRows)];
            if (ringHolds == qy) continue;
            ringHolds = qy;
            for (int px = target.x0; px < target.x1; ++px) {
                const int qx0 = std::max(px - rx, reg.x0), qx1 = std::min(px + rx, reg.x1 - 1);
                const int cx = (px << kSubpixelBits) + (1 << (kSubpixelBits - 1));
                tabulateAvx2(filter.tableX, sx + rowStart + size_t(qx0 - reg.x0) * spp,
                             filter.tableBiasX - cx, size_t(qx1 - qx0 + 1) * spp,
                             ring + size_t(px - target.x0) * xStride);
            }
        }
        for (int px = target.x0; px < target.x1; ++px, o += 4) {
            if (!rowReach[px - target.x0]) {
                o[0] = o[1] = o[2] = o[3] = 0.f;
                continue;
            }
            const int qx0 = std::max(px - rx, reg.x0), qx1 = std::min(px + rx, reg.x1 - 1);
            const size_t length = size_t(qx1 - qx0 + 1) * size_t(spp),
                         columnOffset = size_t(qx0 - reg.x0) * spp;
            __m256 acc[5] = {_mm256_setzero_ps(), _mm256_setzero_ps(), _mm256_setzero_ps(),
                             _mm256_setzero_ps(), _mm256_setzero_ps()};
            for (int qy = qy0; qy <= qy1; ++qy) {
                const float* wy = rowY.data() + size_t(qy - qy0) * rowSamples + columnOffset;
                const float* wx = ringX.data() + size_t((qy - reg.y0) % windowRows) * xRingRow +
                                  size_t(px - target.x0) * xStride;
                const size_t begin = size_t(qy - reg.y0) * rowSamples + columnOffset;
                const float *r = tile.r.data() + begin, *g = tile.g.data() + begin,
                            *b = tile.b.data() + begin, *a = tile.a.data() + begin;
                size_t j = 0;
                for (; j + 8 <= length; j += 8) {
                    const __m256 w = _mm256_mul_ps(_mm256_loadu_ps(wx + j), _mm256_loadu_ps(wy + j));
                    acc[0] = _mm256_add_ps(acc[0], _mm256_mul_ps(w, _mm256_loadu_ps(r + j)));
                    acc[1] = _mm256_add_ps(acc[1], _mm256_mul_ps(w, _mm256_loadu_ps(g + j)));
                    acc[2] = _mm256_add_ps(acc[2], _mm256_mul_ps(w, _mm256_loadu_ps(b + j)));
                    acc[3] = _mm256_add_ps(acc[3], _mm256_mul_ps(w, _mm256_loadu_ps(a + j)));
                    acc[4] = _mm256_add_ps(acc[4], w);
                }
                if (j < length) {
                    // The row's last samples on lanes 0 .. length - j - 1, as the scalar loop adds them; the
                    // other lanes load zeros and add +0, which leaves every sum as it is (a sum that starts
                    // at +0 is never -0 under round-to-nearest).
                    const __m256i live = _mm256_cmpgt_epi32(_mm256_set1_epi32(int(length - j)),
                                                            _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
                    const __m256 w =
                        _mm256_mul_ps(_mm256_maskload_ps(wx + j, live), _mm256_maskload_ps(wy + j, live));
                    acc[0] = _mm256_add_ps(acc[0], _mm256_mul_ps(w, _mm256_maskload_ps(r + j, live)));
                    acc[1] = _mm256_add_ps(acc[1], _mm256_mul_ps(w, _mm256_maskload_ps(g + j, live)));
                    acc[2] = _mm256_add_ps(acc[2], _mm256_mul_ps(w, _mm256_maskload_ps(b + j, live)));
                    acc[3] = _mm256_add_ps(acc[3], _mm256_mul_ps(w, _mm256_maskload_ps(a + j, live)));
                    acc[4] = _mm256_add_ps(acc[4], w);
                }
            }
            LaneSums l;
            for (int c = 0; c < 5; ++c) _mm256_storeu_ps(l.v[c], acc[c]);
            float sums[5];
            reduceLanes(l, sums);
            writePixel(o, sums);
        }
    }
}
#endif

}  // namespace

bool filmAvx2Active() {
    return cpuHasAvx2() && gFilmAvx2Allowed.load(std::memory_order_relaxed);
}

bool filmUseAvx2(bool allow) {
    gFilmAvx2Allowed.store(allow, std::memory_order_relaxed);
    return allow && cpuHasAvx2();
}

void reconstruct(const SampleTile& tile, const PixelFilter& filter, Rect target, Image& out) {
    if (tile.strataWrites || tile.pixelFillPending)
        throw std::logic_error("reconstruct: the tile's samples are still in stratum order or unfilled");
    if (!out.planes.empty()) reconstructPlanes(tile, filter, target, out);
    const int rx = filter.radiusX(), ry = filter.radiusY();
    const int tw = tile.region.width(), th = tile.region.height();
    static_assert(kSubpixelBits == 8, "filter tables assume 1/256 pixel offsets");
    // Background pixels (no covered sample in reach) stay transparent black and skip the filter. Which
    // pixels have a covered sample in reach: pixelHit dilated by the filter radius, first along rows,
    // then along columns (two passes of ORs instead of a search per pixel).
    thread_local std::vector<uint8_t> rowReach, reach;
    rowReach.assign(size_t(tw) * th, 0);
    reach.assign(size_t(tw) * th, 0);
    for (int y = 0; y < th; ++y) {
        const uint8_t* hit = tile.pixelHit.data() + size_t(y) * tw;
        uint8_t* dst = rowReach.data() + size_t(y) * tw;
        for (int x = 0; x < tw; ++x) {
            uint8_t any = 0;
            for (int q = std::max(0, x - rx); q <= std::min(tw - 1, x + rx); ++q) any |= hit[q];
            dst[x] = any;
        }
    }
    for (int y = 0; y < th; ++y) {
        uint8_t* dst = reach.data() + size_t(y) * tw;
        for (int q = std::max(0, y - ry); q <= std::min(th - 1, y + ry); ++q) {
            const uint8_t* src = rowReach.data() + size_t(q) * tw;
            for (int x = 0; x < tw; ++x) dst[x] |= src[x];
        }
    }
#if TESSERA_FILM_AVX2
    if (filmAvx2Active()) {
        reconstructColourAvx2(tile, filter, target, reach.data(), out);
        return;
    }
#endif
    for (int py = target.y0; py < target.y1; ++py) {
        for (int px = target.x0; px < target.x1; ++px) {
            float* o = out.pixel(px, py);
            if (!reach[size_t(py - tile.region.y0) * tw + (px - tile.region.x0)]) {
                o[0] = o[1] = o[2] = o[3] = 0.f;
                continue;
            }
            float sums[5];
            pixelSumsScalar(tile, filter, rx, ry, px, py, sums);
            writePixel(o, sums);
        }
    }
}

}  // namespace tessera
