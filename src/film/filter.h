// Pixel reconstruction filters of the RenderMan Interface (RI spec 3.2, sec. 4.1.2, RiPixelFilter):
// box, triangle, gaussian and catmull-rom, all separable, so a 2D weight is w(x) * w(y).
#pragma once
#include <vector>

#include "scene/scene.h"

namespace tessera {

struct PixelFilter {
    FilterType type = FilterType::Gaussian;
    float widthX = 2.f, widthY = 2.f;
    // Neighbouring pixels on each side whose samples can reach a pixel centre: ceil(width/2 - 1/2).
    int radiusX() const;
    int radiusY() const;
    // 1D weight at offset d (pixels) from the pixel centre for the given full width.
    static float weight1D(FilterType type, float d, float width);
    float weightX(float d) const { return weight1D(type, d, widthX); }
    float weightY(float d) const { return weight1D(type, d, widthY); }

    // Weights tabulated per fixed-point offset (sample positions are quantised to 1/256 pixel, so the
    // table is exact): tableX[offset + tableBiasX] for offset = sample - pixel centre in 1/256 pixels.
    std::vector<float> tableX, tableY;
    int tableBiasX = 0, tableBiasY = 0;
    float tabulatedX(int offset) const { return tableX[offset + tableBiasX]; }
    float tabulatedY(int offset) const { return tableY[offset + tableBiasY]; }
};

PixelFilter makeFilter(const ImageOptions& opts);

}  // namespace tessera
