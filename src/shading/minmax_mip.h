// Min/max mip map of a displacement texture (paper 001 sec. 3.1): "instead of averaging 2x2 pixels, we
// compute the max displacement and the min displacement values of the 2x2 pixels", so that the variation
// of the displacement over any texel rectangle is read at the level matching its extent (log2), a few
// entries, instead of a loop over its texels. Plain data, built once per texture from its finest level.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

namespace tessera {

// How lookups outside [0, 1] wrap (OIIO's modes of the texture's lookups).
enum class TexelWrap : uint8_t { Periodic, Clamp, Black };

struct MinMaxMip {
    struct Level {
        int w = 0, h = 0;
        std::vector<float> lo, hi;  // row-major, w * h
    };
    std::vector<Level> levels;  // levels[0]: the texels; level L+1 entry (i, j) = level L's 2x2 block
    TexelWrap wrapS = TexelWrap::Periodic, wrapT = TexelWrap::Periodic;

    bool empty() const { return levels.empty(); }
    int width() const { return levels.empty() ? 0 : levels[0].w; }
    int height() const { return levels.empty() ? 0 : levels[0].h; }
};

// Builds the pyramid of a w x h single-channel image (row 0 at the top, t = 0). An odd size keeps its last
// row or column unpaired (the coarser entry covers 1 instead of 2), down to 1 x 1.
inline MinMaxMip buildMinMaxMip(int w, int h, const std::vector<float>& texels,
                                TexelWrap ws = TexelWrap::Periodic, TexelWrap wt = TexelWrap::Periodic) {
    MinMaxMip m;
    m.wrapS = ws, m.wrapT = wt;
    if (w < 1 || h < 1 || texels.size() < size_t(w) * size_t(h)) return m;
    m.levels.push_back({w, h, std::vector<float>(texels.begin(), texels.begin() + size_t(w) * h),
                        std::vector<float>(texels.begin(), texels.begin() + size_t(w) * h)});
    while (m.levels.back().w > 1 || m.levels.back().h > 1) {
        const MinMaxMip::Level& f = m.levels.back();
        MinMaxMip::Level c;
        c.w = (f.w + 1) / 2, c.h = (f.h + 1) / 2;
        c.lo.resize(size_t(c.w) * c.h), c.hi.resize(size_t(c.w) * c.h);
        for (int j = 0; j < c.h; ++j)
            for (int i = 0; i < c.w; ++i) {
                float lo = INFINITY, hi = -INFINITY;
                for (int y = 2 * j; y < std::min(2 * j + 2, f.h); ++y)
                    for (int x = 2 * i; x < std::min(2 * i + 2, f.w); ++x) {
                        lo = std::min(lo, f.lo[size_t(y) * f.w + x]);
                        hi = std::max(hi, f.hi[size_t(y) * f.w + x]);
                    }
                c.lo[size_t(j) * c.w + i] = lo, c.hi[size_t(j) * c.w + i] = hi;
            }
        m.levels.push_back(std::move(c));
    }
    return m;
}

// Min and max over the texels [x0, x1] x [y0, y1] (inclusive, inside the finest level), read at level
// L = floor(log2(extent)): the rectangle then meets at most 3 x 3 entries of level L, whose blocks cover it,
// so [lo, hi] bounds the true minimum and maximum of its texels (equals them when it is one aligned block).
inline void minMaxInRect(const MinMaxMip& m, int x0, int x1, int y0, int y1, float& lo, float& hi) {
    const int extent = std::max(x1 - x0 + 1, y1 - y0 + 1);
    int L = 0;
    while ((2 << L) <= extent && L + 1 < int(m.levels.size())) ++L;
    const MinMaxMip::Level& lv = m.levels[size_t(L)];
    for (int j = y0 >> L; j <= (y1 >> L); ++j)
        for (int i = x0 >> L; i <= (x1 >> L); ++i) {
            lo = std::min(lo, lv.lo[size_t(j) * lv.w + i]);
            hi = std::max(hi, lv.hi[size_t(j) * lv.w + i]);
        }
}

// The texel intervals (at most two) an unwrapped texel range [a, b] covers under `wrap` inside 0..n-1;
// `outside`: Black wrap reaches past the border (the lookup then sees 0).
inline int wrapTexelRange(int64_t a, int64_t b, int n, TexelWrap wrap, int out[2][2], bool& outside) {
    if (wrap != TexelWrap::Periodic) {
        outside = outside || (wrap == TexelWrap::Black && (a < 0 || b >= n));
        out[0][0] = int(std::clamp<int64_t>(a, 0, n - 1)), out[0][1] = int(std::clamp<int64_t>(b, 0, n - 1));
        return 1;
    }
    if (b - a + 1 >= n) {
        out[0][0] = 0, out[0][1] = n - 1;
        return 1;
    }
    const int64_t am = ((a % n) + n) % n, bm = am + (b - a);
    if (bm < n) {
        out[0][0] = int(am), out[0][1] = int(bm);
        return 1;
    }
    out[0][0] = int(am), out[0][1] = n - 1;
    out[1][0] = 0, out[1][1] = int(bm - n);
    return 2;
}

// Min and max of the (bilinearly interpolated) texture over the st rectangle [s0, s1] x [t0, t1]: the
// texels whose bilinear footprints reach it (texel centres at (i + 0.5) / w), wrapped as the lookups wrap.
// Returns false for an empty pyramid.
inline bool minMaxInST(const MinMaxMip& m, float s0, float s1, float t0, float t1, float& lo, float& hi) {
    if (m.empty()) return false;
    const int w = m.width(), h = m.height();
    auto texel = [](float s, int n) {
        const double x = double(s) * n - 0.5;
        return int64_t(std::floor(std::clamp(x, -1e9, 1e9)));
    };
    int xs[2][2], ys[2][2];
    bool outside = false;
    const int nx = wrapTexelRange(texel(s0, w), texel(s1, w) + 1, w, m.wrapS, xs, outside);
    const int ny = wrapTexelRange(texel(t0, h), texel(t1, h) + 1, h, m.wrapT, ys, outside);
    lo = INFINITY, hi = -INFINITY;
    for (int b = 0; b < ny; ++b)
        for (int a = 0; a < nx; ++a) minMaxInRect(m, xs[a][0], xs[a][1], ys[b][0], ys[b][1], lo, hi);
    if (outside) lo = std::min(lo, 0.f), hi = std::max(hi, 0.f);
    return true;
}

}  // namespace tessera
