// tessera_imgdiff A B: PSNR of colour and coverage mismatch between two images (.png or .exr), as JSON.
// With B as the reference, also the colour RMSE split into silhouette pixels (B's coverage in the 3x3
// neighbourhood is not all 1) and covered interior pixels (bench/sampler_rmse.sh).
#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "film/image_compare.h"
#include "io/image_io.h"

using namespace tessera;

static Image load(const std::string& p) {
    return p.size() > 4 && p.substr(p.size() - 4) == ".exr" ? readExr(p) : readPng(p);
}

int main(int argc, char** argv) {
    if (argc != 3) {
        fmt::print(stderr, "usage: tessera_imgdiff A B   (PNG or EXR of the same size)\n");
        return 2;
    }
    try {
        Image a = load(argv[1]), b = load(argv[2]);
        ImageDiff d = compareImages(a, b);
        // Squared colour error (as compareImages: RGB clamped to [0,1]) of silhouette / interior pixels.
        double se[2] = {0, 0};
        size_t count[2] = {0, 0};
        for (int y = 0; y < b.height; ++y)
            for (int x = 0; x < b.width; ++x) {
                bool covered = true;
                for (int qy = std::max(0, y - 1); qy <= std::min(b.height - 1, y + 1); ++qy)
                    for (int qx = std::max(0, x - 1); qx <= std::min(b.width - 1, x + 1); ++qx)
                        covered = covered && b.pixel(qx, qy)[3] >= 1.f;
                bool empty = true;
                for (int qy = std::max(0, y - 1); qy <= std::min(b.height - 1, y + 1); ++qy)
                    for (int qx = std::max(0, x - 1); qx <= std::min(b.width - 1, x + 1); ++qx)
                        empty = empty && b.pixel(qx, qy)[3] <= 0.f;
                if (empty) continue;  // background: no error to speak of
                const int k = covered ? 1 : 0;
                for (int c = 0; c < 3; ++c) {
                    const double e =
                        std::clamp(a.pixel(x, y)[c], 0.f, 1.f) - std::clamp(b.pixel(x, y)[c], 0.f, 1.f);
                    se[k] += e * e;
                }
                ++count[k];
            }
        auto rmse = [&](int k) { return count[k] ? std::sqrt(se[k] / (3.0 * count[k])) : 0.0; };
        nlohmann::json j = {{"a", argv[1]},
                            {"b", argv[2]},
                            {"psnr_db", d.psnrColor},
                            {"alpha_mismatch_fraction", d.alphaMismatch},
                            {"mean_abs_alpha", d.meanAbsAlpha},
                            {"max_abs_color", d.maxAbsColor},
                            {"rmse_silhouette", rmse(0)},
                            {"rmse_interior", rmse(1)},
                            {"silhouette_pixels", count[0]},
                            {"interior_pixels", count[1]}};
        fmt::print("{}\n", j.dump(2));
    } catch (const std::exception& e) {
        fmt::print(stderr, "tessera_imgdiff: {}\n", e.what());
        return 1;
    }
    return 0;
}
