#include "film/image_compare.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace tessera {

ImageDiff compareImages(const Image& a, const Image& b, float alphaThreshold) {
    if (a.width != b.width || a.height != b.height) throw std::invalid_argument("images differ in size");
    ImageDiff d;
    double se = 0;
    size_t mismatched = 0, pixels = size_t(a.width) * a.height;
    for (size_t i = 0; i < pixels; ++i) {
        const float* p = &a.rgba[i * 4];
        const float* q = &b.rgba[i * 4];
        for (int c = 0; c < 3; ++c) {
            double e = std::clamp(p[c], 0.f, 1.f) - std::clamp(q[c], 0.f, 1.f);
            se += e * e;
            d.maxAbsColor = std::max(d.maxAbsColor, std::fabs(e));
        }
        double da = std::fabs(double(p[3]) - q[3]);
        d.meanAbsAlpha += da;
        if (da > alphaThreshold) ++mismatched;
    }
    double mse = pixels ? se / (3.0 * pixels) : 0.0;
    d.psnrColor = mse > 0 ? 10.0 * std::log10(1.0 / mse) : std::numeric_limits<double>::infinity();
    d.alphaMismatch = pixels ? double(mismatched) / pixels : 0.0;
    d.meanAbsAlpha = pixels ? d.meanAbsAlpha / pixels : 0.0;
    return d;
}

}  // namespace tessera
