#include "film/film.h"

#include <algorithm>
#include <cmath>

namespace tessera {

void SampleTile::reset(Rect reg, int nx_, int ny_, uint32_t seed, float farZ, SamplerKind sampler) {
    region = reg;
    nx = nx_;
    ny = ny_;
    spp = nx * ny;
    size_t pixels = size_t(reg.width()) * reg.height();
    size_t n = pixels * spp;
    sx.resize(n);
    sy.resize(n);
    sampleIndex.resize(n);
    z.assign(n, farZ);
    r.assign(n, 0.f);
    g.assign(n, 0.f);
    b.assign(n, 0.f);
    a.assign(n, 0.f);
    pixelHit.assign(pixels, 0);
    size_t i = 0;
    if (sampler == SamplerKind::Sobol) {
        for (int py = reg.y0; py < reg.y1; ++py)
            for (int px = reg.x0; px < reg.x1; ++px, i += spp)
                filmSamplesFixed(px, py, nx, ny, seed, &sx[i], &sy[i], &sampleIndex[i]);
        return;
    }
    for (int py = reg.y0; py < reg.y1; ++py)
        for (int px = reg.x0; px < reg.x1; ++px)
            for (int s = 0; s < spp; ++s, ++i) {
                samplePositionFixed(px, py, s, nx, ny, seed, sx[i], sy[i]);
                sampleIndex[i] = uint32_t(s);
            }
}

void reconstruct(const SampleTile& tile, const PixelFilter& filter, Rect target, Image& out) {
    const int rx = filter.radiusX(), ry = filter.radiusY();
    const int tw = tile.region.width(), th = tile.region.height();
    const int spp = tile.spp;
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
    for (int py = target.y0; py < target.y1; ++py) {
        for (int px = target.x0; px < target.x1; ++px) {
            float* o = out.pixel(px, py);
            if (!reach[size_t(py - tile.region.y0) * tw + (px - tile.region.x0)]) {
                o[0] = o[1] = o[2] = o[3] = 0.f;
                continue;
            }
            const int qx0 = std::max(px - rx, tile.region.x0), qx1 = std::min(px + rx, tile.region.x1 - 1);
            const int qy0 = std::max(py - ry, tile.region.y0), qy1 = std::min(py + ry, tile.region.y1 - 1);
            const int cx = (px << kSubpixelBits) + (1 << (kSubpixelBits - 1));
            const int cy = (py << kSubpixelBits) + (1 << (kSubpixelBits - 1));
            float sr = 0, sg = 0, sb = 0, sa = 0, sw = 0;
            for (int qy = qy0; qy <= qy1; ++qy) {
                // The samples of one row of the window are contiguous: one loop over all of them.
                const size_t begin = (size_t(qy - tile.region.y0) * tw + (qx0 - tile.region.x0)) * spp;
                const size_t end = begin + size_t(qx1 - qx0 + 1) * spp;
                for (size_t i = begin; i < end; ++i) {
                    const float w = filter.tabulatedX(tile.sx[i] - cx) * filter.tabulatedY(tile.sy[i] - cy);
                    sr += w * tile.r[i];
                    sg += w * tile.g[i];
                    sb += w * tile.b[i];
                    sa += w * tile.a[i];
                    sw += w;
                }
            }
            const float k = sw != 0.f ? 1.f / sw : 0.f;
            o[0] = sr * k;
            o[1] = sg * k;
            o[2] = sb * k;
            o[3] = std::clamp(sa * k, 0.f, 1.f);
        }
    }
}

}  // namespace tessera
