// tessera_sampler_rmse SCENE ENGINE WxH THREADS REF_SPP "SPP..." "SEED..." (bench/sampler_rmse.sh)
// Renders SCENE in process and compares in float (no half-float EXR quantisation, which is about the
// size of a 64-spp error): a reference with the jittered sampler (seed 1000), a second one (seed 2000)
// for the reference's own noise, then every spp x sampler x seed. One line per image on stdout:
//   SPP SAMPLER SEED {"rmse": ..., "rmse_silhouette": ..., "rmse_interior": ..., ...}
// RMSE of premultiplied RGB clamped to [0,1] over all pixels, and split into silhouette pixels (reference
// coverage not all 1 in the 3x3 neighbourhood) and covered interior pixels (background pixels skipped).
#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "io/scene_loader.h"
#include "render/render.h"

using namespace tessera;

namespace {

nlohmann::json compare(const Image& a, const Image& ref) {
    double se[3] = {0, 0, 0};  // all, silhouette, interior
    size_t count[3] = {0, 0, 0};
    for (int y = 0; y < ref.height; ++y)
        for (int x = 0; x < ref.width; ++x) {
            bool covered = true, empty = true;
            for (int qy = std::max(0, y - 1); qy <= std::min(ref.height - 1, y + 1); ++qy)
                for (int qx = std::max(0, x - 1); qx <= std::min(ref.width - 1, x + 1); ++qx) {
                    covered = covered && ref.pixel(qx, qy)[3] > 0.999f;  // filter sums round
                    empty = empty && ref.pixel(qx, qy)[3] < 0.001f;
                }
            double e2 = 0;
            for (int c = 0; c < 3; ++c) {
                const double e =
                    std::clamp(a.pixel(x, y)[c], 0.f, 1.f) - std::clamp(ref.pixel(x, y)[c], 0.f, 1.f);
                e2 += e * e;
            }
            se[0] += e2, ++count[0];
            if (empty) continue;
            const int k = covered ? 2 : 1;
            se[k] += e2, ++count[k];
        }
    auto rmse = [&](int k) { return count[k] ? std::sqrt(se[k] / (3.0 * count[k])) : 0.0; };
    return {{"rmse", rmse(0)},
            {"rmse_silhouette", rmse(1)},
            {"rmse_interior", rmse(2)},
            {"silhouette_pixels", count[1]},
            {"interior_pixels", count[2]}};
}

std::vector<int> ints(const std::string& s) {
    std::vector<int> v;
    std::istringstream in(s);
    for (int x; in >> x;) v.push_back(x);
    return v;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 8) {
        fmt::print(stderr,
                   "usage: tessera_sampler_rmse SCENE ENGINE WxH THREADS REF_SPP \"SPP...\" \"SEED...\"\n");
        return 2;
    }
    try {
        Scene scene = loadScene(argv[1], [](const std::string&) {});
        if (std::sscanf(argv[3], "%dx%d", &scene.camera.width, &scene.camera.height) != 2) return 2;
        RenderSettings settings;
        settings.engine = argv[2];
        settings.threads = std::stoi(argv[4]);
        auto renderWith = [&](int spp, SamplerKind sampler, uint32_t seed) {
            splitSamplesPerPixel(spp, scene.image.pixelSamplesX, scene.image.pixelSamplesY);
            settings.sampler = sampler;
            settings.seed = seed;
            return render(scene, settings).image;
        };
        const int refSpp = std::stoi(argv[5]);
        const Image ref = renderWith(refSpp, SamplerKind::Jittered, 1000);
        const Image ref2 = renderWith(refSpp, SamplerKind::Jittered, 2000);
        fmt::print("{} reference2 2000 {}\n", refSpp, compare(ref2, ref).dump());
        std::fflush(stdout);
        for (int spp : ints(argv[6]))
            for (SamplerKind sampler : {SamplerKind::Sobol, SamplerKind::Jittered})
                for (int seed : ints(argv[7])) {
                    const Image img = renderWith(spp, sampler, uint32_t(seed));
                    fmt::print("{} {} {} {}\n", spp, sampler == SamplerKind::Sobol ? "sobol" : "jittered",
                               seed, compare(img, ref).dump());
                    std::fflush(stdout);
                }
    } catch (const std::exception& e) {
        fmt::print(stderr, "tessera_sampler_rmse: {}\n", e.what());
        return 1;
    }
    return 0;
}
