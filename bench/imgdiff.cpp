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

int main(int argc, char** argv) {
    if (argc != 3) {
        fmt::print(stderr, "usage: tessera_imgdiff A B   (PNG or EXR of the same size)\n");
        return 2;
    }
    try {
        Image a = load(argv[1]), b = load(argv[2]);
        ImageDiff d = compareImages(a, b);
        nlohmann::json j = {{"a", argv[1]}, {"b", argv[2]}, {"psnr_db", d.psnrColor},
                            {"alpha_mismatch_fraction", d.alphaMismatch}, {"mean_abs_alpha", d.meanAbsAlpha},
                            {"max_abs_color", d.maxAbsColor}};
        fmt::print("{}\n", j.dump(2));
    } catch (const std::exception& e) {
        fmt::print(stderr, "tessera_imgdiff: {}\n", e.what());
        return 1;
    }
    return 0;
}
