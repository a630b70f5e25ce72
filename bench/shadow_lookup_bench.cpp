// tessera_shadow_lookup_bench: the cost of a shadow-map lookup (shading/shadow_map.h), the fast filter
// (shadowMapFaceVisibility) against the filter written texel by texel (shadowMapFaceVisibilityEachTexel),
// timed alternately in one run on the same lookups, so that their ratio holds on a noisy machine (issue 18,
// docs/benchmarks/fixed_costs.md "Session 29"). A 2048 x 2048 map of depths 10 .. 10.3; 1 M lookups walk
// it row by row as a grid's shading points do, with normals tilted at random; orthographic and perspective
// faces. Prints one JSON object and writes it to bench/results/shadow_lookup.json (or the path given).
//   tessera_shadow_lookup_bench [--runs N] [--width W] [--out FILE]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/random.h"
#include "shading/shadow_map.h"

using namespace tessera;

int main(int argc, char** argv) {
    int runs = 5;
    float filterWidth = 2.f;
    std::string out = std::string(TESSERA_SOURCE_DIR) + "/bench/results/shadow_lookup.json";
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a == "--runs" && i + 1 < argc)
            runs = std::max(1, std::atoi(argv[++i]));
        else if (a == "--width" && i + 1 < argc)
            filterWidth = float(std::atof(argv[++i]));
        else if (a == "--out" && i + 1 < argc)
            out = argv[++i];
        else {
            std::fprintf(stderr, "usage: tessera_shadow_lookup_bench [--runs N] [--width W] [--out FILE]\n");
            return 2;
        }
    }
    const int size = 2048;
    std::vector<float> depth(size_t(size) * size);
    uint32_t draw = 7u;
    auto uniform = [&]() { return hashToUnit(hash32(draw++)); };
    for (float& d : depth) d = 10.f + 0.3f * uniform();
    nlohmann::json result = {{"map", size}, {"filter_width", filterWidth}, {"runs", runs}};
    for (const bool perspective : {false, true}) {
        ShadowMapFace f;
        f.perspective = perspective;
        f.width = f.height = size;
        f.depth = depth.data();
        f.sx = perspective ? 1024.f : 256.f, f.sy = -f.sx, f.ox = f.oy = 1024.f;
        const size_t n = size_t(1) << 20;
        std::vector<Vec3> P(n), N(n);
        const float span = perspective ? 9.f : 3.9f;  // inside the map
        for (size_t i = 0; i < n; ++i) {
            const float a = float(i % 1024) / 1024.f, b = float(i / 1024) / 1024.f;
            P[i] = {(2.f * a - 1.f) * span, (2.f * b - 1.f) * span, 10.f + 0.1f * uniform()};
            N[i] = {uniform() - 0.5f, uniform() - 0.5f, -1.f};
        }
        std::vector<double> fastNs, eachNs;
        size_t differ = 0;
        for (int r = 0; r < runs; ++r) {
            float sumFast = 0.f, sumEach = 0.f;
            const auto t0 = std::chrono::steady_clock::now();
            for (size_t i = 0; i < n; ++i) sumFast += shadowMapFaceVisibility(f, P[i], N[i], 1.f, filterWidth);
            const auto t1 = std::chrono::steady_clock::now();
            for (size_t i = 0; i < n; ++i)
                sumEach += shadowMapFaceVisibilityEachTexel(f, P[i], N[i], 1.f, filterWidth);
            const auto t2 = std::chrono::steady_clock::now();
            fastNs.push_back(std::chrono::duration<double, std::nano>(t1 - t0).count() / double(n));
            eachNs.push_back(std::chrono::duration<double, std::nano>(t2 - t1).count() / double(n));
            differ += std::memcmp(&sumFast, &sumEach, sizeof(float)) != 0;
        }
        std::sort(fastNs.begin(), fastNs.end());
        std::sort(eachNs.begin(), eachNs.end());
        result[perspective ? "perspective" : "orthographic"] = {
            {"fast_ns_min", fastNs.front()},
            {"fast_ns_median", fastNs[fastNs.size() / 2]},
            {"each_texel_ns_min", eachNs.front()},
            {"each_texel_ns_median", eachNs[eachNs.size() / 2]},
            {"speedup_median", eachNs[eachNs.size() / 2] / fastNs[fastNs.size() / 2]},
            {"sums_differ", differ}};
    }
    std::printf("%s\n", result.dump(2).c_str());
    std::ofstream(out) << result.dump(2) << "\n";
    return 0;
}
