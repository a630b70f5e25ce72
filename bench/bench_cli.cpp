// tessera_bench: runs `build/tessera render ...` several times and reports medians as JSON.
//
//   tessera_bench --name NAME [--runs N] [--json OUT.json] -- render SCENE [options...]
//
// Each run writes --stats to a temporary file; the record holds the median and minimum of the process
// wall time and of the engine's render_ms, the throughput (micropolygons/s or rays/s when the engine
// reports them) and the peak resident memory. Records are appended to OUT.json (a JSON array).
#include <fmt/core.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace fs = std::filesystem;

static double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    size_t n = v.size();
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

int main(int argc, char** argv) {
    std::string name = "bench", jsonOut, binary = TESSERA_BINARY;
    int runs = 5;
    std::vector<std::string> args;
    int i = 1;
    for (; i < argc; ++i) {
        std::string a = argv[i];
        if (a == "--") {
            ++i;
            break;
        }
        if (a == "--name" && i + 1 < argc) name = argv[++i];
        else if (a == "--runs" && i + 1 < argc) runs = std::max(1, std::atoi(argv[++i]));
        else if (a == "--json" && i + 1 < argc) jsonOut = argv[++i];
        else if (a == "--binary" && i + 1 < argc) binary = argv[++i];
        else {
            fmt::print(stderr, "usage: tessera_bench --name NAME [--runs N] [--json OUT] -- render SCENE [opts]\n");
            return 2;
        }
    }
    for (; i < argc; ++i) args.push_back(argv[i]);
    if (args.empty()) {
        fmt::print(stderr, "tessera_bench: nothing to run (give the tessera arguments after --)\n");
        return 2;
    }
    std::string cmdArgs;
    for (auto& a : args) cmdArgs += " '" + a + "'";
    fs::path stats = fs::temp_directory_path() / fmt::format("tessera_bench_{}.json", getpid());
    fs::path image = fs::temp_directory_path() / fmt::format("tessera_bench_{}.png", getpid());
    bool hasOutput = std::find(args.begin(), args.end(), "-o") != args.end();

    std::vector<double> wall, renderMs, rss;
    nlohmann::json last;
    for (int r = 0; r < runs; ++r) {
        std::string cmd = binary + cmdArgs + " --quiet --stats '" + stats.string() + "'" +
                          (hasOutput ? "" : " -o '" + image.string() + "'");
        auto t0 = std::chrono::steady_clock::now();
        int status = std::system(cmd.c_str());
        double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
            fmt::print(stderr, "tessera_bench: command failed: {}\n", cmd);
            return 1;
        }
        std::ifstream f(stats);
        last = nlohmann::json::parse(f);
        wall.push_back(ms);
        renderMs.push_back(last.value("render_ms", 0.0));
        rss.push_back(last.value("peak_rss_mb", 0.0));
    }
    fs::remove(stats);
    fs::remove(image);

    nlohmann::json rec;
    rec["name"] = name;
    rec["command"] = "tessera" + cmdArgs;
    rec["runs"] = runs;
    rec["wall_ms_median"] = median(wall);
    rec["wall_ms_min"] = *std::min_element(wall.begin(), wall.end());
    rec["render_ms_median"] = median(renderMs);
    rec["render_ms_min"] = *std::min_element(renderMs.begin(), renderMs.end());
    rec["peak_rss_mb_max"] = *std::max_element(rss.begin(), rss.end());
    for (const char* k : {"engine", "width", "height", "spp", "threads", "patches_in", "micropolygons", "grids",
                          "sample_tests", "stage_ms", "rays", "build_ms", "trace_ms"})
        if (last.contains(k)) rec[k] = last[k];
    double seconds = rec["render_ms_median"].get<double>() / 1000.0;
    if (last.contains("micropolygons") && seconds > 0)
        rec["micropolygons_per_s"] = last["micropolygons"].get<double>() / seconds;
    fmt::print("{}\n", rec.dump(2));
    if (!jsonOut.empty()) {
        nlohmann::json all = nlohmann::json::array();
        if (fs::exists(jsonOut)) {
            std::ifstream f(jsonOut);
            try {
                all = nlohmann::json::parse(f);
            } catch (...) {
                all = nlohmann::json::array();
            }
        }
        all.push_back(rec);
        fs::create_directories(fs::path(jsonOut).parent_path().empty() ? "." : fs::path(jsonOut).parent_path());
        std::ofstream(jsonOut) << all.dump(2) << "\n";
    }
    return 0;
}
