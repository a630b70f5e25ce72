// tessera_imgdiff A B: PSNR of colour and coverage mismatch between two images (.png or .exr), as JSON.
#include <fmt/core.h>

#include <nlohmann/json.hpp>
#include <string>

#include "film/image_compare.h"
#include "io/image_io.h"

using namespace tessera;

static Image load(const std::string& p) {
    return p.size() > 4 && p.substr(p.size() - 4) == ".exr" ? readExr(p) : readPng(p);
}

// Mean of the premultiplied RGB values (the images' brightness, for bias checks between renderers).
static double meanRgb(const Image& img) {
    double sum = 0;
    for (size_t i = 0; i < img.rgba.size(); i += 4) sum += img.rgba[i] + img.rgba[i + 1] + img.rgba[i + 2];
    return sum / (3.0 * double(img.rgba.size() / 4));
}

int main(int argc, char** argv) {
    if (argc == 4 && std::string(argv[1]) == "--to-png") {  // tessera_imgdiff --to-png IN OUT.png: to look at
        try {
            writeImage(argv[3], load(argv[2]), OutputEncoding{});
        } catch (const std::exception& e) {
            fmt::print(stderr, "tessera_imgdiff: {}\n", e.what());
            return 1;
        }
        return 0;
    }
    if (argc != 3) {
        fmt::print(stderr, "usage: tessera_imgdiff A B   (PNG or EXR of the same size)\n"
                           "       tessera_imgdiff --to-png IN OUT.png\n");
        return 2;
    }
    try {
        Image a = load(argv[1]), b = load(argv[2]);
        ImageDiff d = compareImages(a, b);
        nlohmann::json j = {{"a", argv[1]}, {"b", argv[2]}, {"psnr_db", d.psnrColor},
                            {"alpha_mismatch_fraction", d.alphaMismatch}, {"mean_abs_alpha", d.meanAbsAlpha},
                            {"max_abs_color", d.maxAbsColor}, {"mean_rgb_a", meanRgb(a)},
                            {"mean_rgb_b", meanRgb(b)}};
        fmt::print("{}\n", j.dump(2));
    } catch (const std::exception& e) {
        fmt::print(stderr, "tessera_imgdiff: {}\n", e.what());
        return 1;
    }
    return 0;
}
