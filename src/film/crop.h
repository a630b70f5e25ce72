// Crop windows and farm tiles as raster rectangles of the film (docs/inputs.md "Crop windows and tiles").
// Pure functions over plain data: the RIB reader, the CLI and the tests share them.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdlib>

#include "film/film.h"

namespace tessera {

// A crop window xmin, xmax, ymin, ymax in NDC that --crop and the Python module's crop= accept:
// 0 <= xmin < xmax <= 1 and 0 <= ymin < ymax <= 1.
inline bool validCropWindow(const double* c) {
    return c[0] >= 0 && c[1] <= 1 && c[2] >= 0 && c[3] <= 1 && c[0] < c[1] && c[2] < c[3];
}

// RI spec 3.2, sec. 4.1.1 (CropWindow): the pixels rendered are
//   ceil(xres * xmin) .. ceil(xres * xmax) - 1  (and the same in y), clamped to the image;
// adjacent crop windows that share an edge therefore share no pixel and leave none out.
// Returns the half-open rectangle (empty when the window holds no pixel centre).
inline Rect cropWindowPixels(int xres, int yres, double xmin, double xmax, double ymin, double ymax) {
    auto lo = [](int res, double f) { return std::clamp(int(std::ceil(res * f)), 0, res); };
    return Rect{lo(xres, xmin), lo(yres, ymin), std::max(lo(xres, xmin), lo(xres, xmax)),
                std::max(lo(yres, ymin), lo(yres, ymax))};
}

// The split of a w x h rectangle into n tiles: cols x rows = n with cols <= w and rows <= h, the pair whose
// tiles are nearest to square (|log(tile aspect)| smallest; ties: more columns). False when no pair fits.
inline bool tileGrid(int w, int h, int n, int& cols, int& rows) {
    cols = rows = 0;
    double best = 1e300;
    for (int c = 1; c <= n; ++c) {
        if (n % c != 0) continue;
        const int r = n / c;
        if (c > w || r > h) continue;
        const double err = std::fabs(std::log((double(w) / c) / (double(h) / r)));
        if (err <= best) best = err, cols = c, rows = r;
    }
    return cols > 0;
}

// Tile `index` (0-based, scanline order: left to right, then top to bottom) of `n` over `base`: columns
// split at floor(k * width / cols), rows likewise, so the tiles cover `base` exactly once. Empty when the
// split does not fit (see tileGrid) or the index is out of range.
inline Rect tileOf(const Rect& base, int index, int n) {
    int cols, rows;
    if (n < 1 || index < 0 || index >= n || !tileGrid(base.width(), base.height(), n, cols, rows)) return {};
    const int cx = index % cols, cy = index / cols;
    auto at = [](int origin, int size, int k, int parts) { return origin + int(int64_t(k) * size / parts); };
    return Rect{at(base.x0, base.width(), cx, cols), at(base.y0, base.height(), cy, rows),
                at(base.x0, base.width(), cx + 1, cols), at(base.y0, base.height(), cy + 1, rows)};
}

}  // namespace tessera
