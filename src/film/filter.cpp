#include "film/filter.h"

#include <cmath>

namespace tessera {

int PixelFilter::radiusX() const { return std::max(0, int(std::ceil(widthX * 0.5f - 0.5f))); }
int PixelFilter::radiusY() const { return std::max(0, int(std::ceil(widthY * 0.5f - 0.5f))); }

float PixelFilter::weight1D(FilterType type, float d, float width) {
    float half = 0.5f * width;
    float a = std::fabs(d);
    if (a > half) return 0.f;
    switch (type) {
        case FilterType::Box: return 1.f;
        case FilterType::Triangle: return 1.f - a / half;
        case FilterType::Gaussian: {
            // RiGaussianFilter: x' = 2x / width, weight exp(-2 x'^2).
            float x = 2.f * d / width;
            return std::exp(-2.f * x * x);
        }
        case FilterType::CatmullRom: {
            // RiCatmullRomFilter (its support is 4 pixels wide regardless of width scaling).
            float x = a * 4.f / width;
            if (x < 1.f) return (3.f * x * x * x - 5.f * x * x + 2.f) * 0.5f;
            if (x < 2.f) return (-x * x * x + 5.f * x * x - 8.f * x + 4.f) * 0.5f;
            return 0.f;
        }
    }
    return 0.f;
}

PixelFilter makeFilter(const ImageOptions& opts) {
    PixelFilter f;
    f.type = opts.filter;
    f.widthX = std::max(opts.filterWidthX, 1e-3f);
    f.widthY = std::max(opts.filterWidthY, 1e-3f);
    // Offsets reach at most (radius + 1) pixels from a pixel centre.
    auto build = [&](std::vector<float>& table, int& bias, int radius, float width) {
        bias = (radius + 1) * 256;
        table.resize(2 * bias + 1);
        for (int k = -bias; k <= bias; ++k) table[k + bias] = PixelFilter::weight1D(f.type, float(k) / 256.f, width);
    };
    build(f.tableX, f.tableBiasX, f.radiusX(), f.widthX);
    build(f.tableY, f.tableBiasY, f.radiusY(), f.widthY);
    return f;
}

}  // namespace tessera
