// Subdivision surfaces against OpenSubdiv's limit surface (docs/subdivision.md): converts a Catmull-Clark
// control mesh (an OBJ file) with the hand-written converter (core/subdivision.h, what Tessera used before
// OpenSubdiv) and with the OpenSubdiv converter (io/subdiv_osd.h) at levels 1..4, samples every patch on
// a grid and prints, as JSON, the largest position error (relative to the mesh's bounding-box diagonal)
// and normal error (degrees) against Bfr's limit surface.
// Usage: tessera_subdiv_error [MESH.obj] [--samples N]   (default: ../shared/data/bigguy/obj/bigguy.obj)
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "core/subdivision.h"
#include "io/obj_reader.h"
#include "io/subdiv_osd.h"

using namespace tessera;

namespace {

nlohmann::json report(const SubdivResult& r, const SubdivDeviation& d, double seconds) {
    return {{"level", r.level},
            {"patches", r.patches.size()},
            {"exact_patches", r.exactCount},
            {"approximate_patches", r.approxCount},
            {"samples", d.samples},
            {"max_position_error_rel_diagonal", d.relativePosition()},
            {"max_normal_error_deg", d.maxNormalDeg},
            {"normal_error_deg_99_9_percentile", d.normalDeg999},
            {"max_position_error_rel_diagonal_exact_patches",
             d.diagonal > 0 ? d.maxPositionExact / d.diagonal : 0},
            {"max_normal_error_deg_exact_patches", d.maxNormalDegExact},
            {"worst_normal_at",
             {{"patch", d.worstNormalPatch},
              {"exact", r.patchExact.empty() ? 0 : int(r.patchExact[d.worstNormalPatch])},
              {"s", d.worstNormalST[0]},
              {"t", d.worstNormalST[1]}}},
            {"convert_seconds", seconds}};
}

}  // namespace

int main(int argc, char** argv) {
    std::string path = "../shared/data/bigguy/obj/bigguy.obj";
    int samples = 9;
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        if (a == "--samples" && i + 1 < argc)
            samples = std::max(2, std::atoi(argv[++i]));
        else if (a == "-h" || a == "--help") {
            std::puts("usage: tessera_subdiv_error [MESH.obj] [--samples N]");
            return 0;
        } else
            path = a;
    }
    std::ifstream in(path);
    if (!in) {
        std::cerr << "tessera_subdiv_error: cannot read " << path << "\n";
        return 2;
    }
    std::stringstream text;
    text << in.rdbuf();
    const ObjMesh obj = parseObj(text.str(), path, nullptr);
    const SubdivLimit limit(obj.mesh, 10);
    using Clock = std::chrono::steady_clock;
    auto timed = [](auto&& f) {
        const auto t0 = Clock::now();
        SubdivResult r = f();
        return std::make_pair(std::move(r), std::chrono::duration<double>(Clock::now() - t0).count());
    };
    nlohmann::json out;
    out["mesh"] = path;
    out["faces"] = obj.mesh.faceSizes.size();
    out["vertices"] = obj.mesh.points.size();
    out["samples_per_patch_side"] = samples;
    out["reference"] = "OpenSubdiv Bfr::Surface on the control mesh, approximation level 10";
    {
        auto [r, sec] = timed([&] { return subdivToBezier(obj.mesh); });
        const SubdivDeviation d = subdivDeviation(obj.mesh, r, limit, samples);
        out["diagonal"] = d.diagonal;
        out["hand_written"] = report(r, d, sec);
    }
    for (int level = 1; level <= 4; ++level) {
        OsdSubdivOptions o;
        o.level = level;
        auto [r, sec] = timed([&] { return subdivideOsd(obj.mesh, o); });
        out["opensubdiv"].push_back(report(r, subdivDeviation(obj.mesh, r, limit, samples), sec));
    }
    std::cout << out.dump(2) << "\n";
    return 0;
}
