// tessera_blur_bench: motion blur and depth of field timings and errors (bench/blur_tables.sh; the paper's
// Tables 1 and 2 and the teapot frames). Renders in process, in float, so that errors are not
// quantised by an image format:
//   tessera_blur_bench SCENE [--engine reyes|rt] [--res WxH] [--threads N] [--translate X,Y,Z]
//       [--spin DEGREES,AX,AY,AZ] [--dof FSTOP,FOCALLENGTH,FOCALDISTANCE] [--spp "16 25 64"]
//       [--schemes "simple interleaved bbox"] [--tiles "2 3 4"] [--perms "1 64"] [--ref-spp 1024]
//       [--runs 3] [--no-strata] [--sharp] [--no-motion]
// --translate / --spin add a motion over the shutter [0, 1] to every patch (world space; the spin turns
// about the axis through the centre of the scene's bounds): for scenes without their own motion blocks.
// One JSON object per line on stdout: configuration, engine_ms (median over --runs), sample tests, and
// RMSE of premultiplied RGB against the bbox reference at --ref-spp (plus, for interleaved, the error's
// spectral peak at the tile frequency relative to the mean of the error spectrum).
#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <cstring>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "core/motion_transform.h"
#include "io/scene_loader.h"
#include "render/render.h"

using namespace tessera;

namespace {

std::vector<std::string> words(const std::string& s) {
    std::vector<std::string> v;
    std::istringstream in(s);
    for (std::string w; in >> w;) v.push_back(w);
    return v;
}
std::vector<double> numbers(const std::string& s) {
    std::vector<double> v;
    std::string t = s;
    std::replace(t.begin(), t.end(), ',', ' ');
    std::istringstream in(t);
    for (double x; in >> x;) v.push_back(x);
    return v;
}

double rmse(const Image& a, const Image& b) {
    double s = 0;
    size_t n = 0;
    for (size_t i = 0; i < a.rgba.size(); ++i) {
        if (i % 4 == 3) continue;
        const double e = std::clamp(a.rgba[i], 0.f, 1.f) - std::clamp(b.rgba[i], 0.f, 1.f);
        s += e * e, ++n;
    }
    return std::sqrt(s / double(n));
}

// Periodogram of the luminance error at horizontal and vertical frequency 1/K, over the mean periodogram
// (about 1 for white noise; a tile-period pattern stands out).
double tilePeak(const Image& a, const Image& ref, int K) {
    const int w = a.width, h = a.height;
    std::vector<double> e(size_t(w) * h);
    double power = 0;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const float *p = a.pixel(x, y), *q = ref.pixel(x, y);
            const double d = (p[0] - q[0]) * 0.2126 + (p[1] - q[1]) * 0.7152 + (p[2] - q[2]) * 0.0722;
            e[size_t(y) * w + x] = d;
            power += d * d;
        }
    if (power == 0) return 0;
    std::complex<double> fx = 0, fy = 0;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const double d = e[size_t(y) * w + x];
            fx += d * std::polar(1.0, -2 * M_PI * x / K);
            fy += d * std::polar(1.0, -2 * M_PI * y / K);
        }
    // Parseval: the mean of |F(f)|^2 over all w*h frequencies is w*h*mean(e^2) = power.
    return 0.5 * (std::norm(fx) + std::norm(fy)) / power;
}

void addMotion(Scene& s, const std::vector<double>& translate, const std::vector<double>& spin) {
    const Bounds3 b = s.worldBounds();
    const Vec3 c = b.center();
    std::vector<TransformKey> keys{{0.0, Mat4()}, {1.0, Mat4()}};
    if (!translate.empty()) keys[1].matrix = Mat4::translate(translate[0], translate[1], translate[2]);
    if (!spin.empty())
        keys[1].matrix = Mat4::translate(c.x, c.y, c.z) * Mat4::rotate(spin[0], spin[1], spin[2], spin[3]) *
                         Mat4::translate(-c.x, -c.y, -c.z);
    const std::vector<TransformKey> refined = refineTransformKeys(keys, kMaxMotionSegmentRadians);
    s.motionPatches.clear();
    s.motionTimes.clear();
    for (size_t i = 0; i < s.patches.size(); ++i) {
        PatchAttributes& a = s.attributes[i];
        a.motion.first = uint32_t(s.motionPatches.size());
        a.motion.count = uint32_t(refined.size());
        for (const TransformKey& k : refined) {
            BezierPatch p;
            for (int j = 0; j < 16; ++j) p.cp[j] = k.matrix.point(s.patches[i].cp[j]);
            s.motionPatches.push_back(p);
            s.motionTimes.push_back(float(k.time));
        }
    }
    s.camera.shutterOpen = 0.f;
    s.camera.shutterClose = 1.f;
}

void setSpp(Scene& s, int spp) {  // as the CLI's --spp does
    splitSamplesPerPixel(spp, s.image.pixelSamplesX, s.image.pixelSamplesY);
}

BlurSampling schemeByName(const std::string& n) {
    if (n == "simple") return BlurSampling::Simple;
    if (n == "interleaved") return BlurSampling::Interleaved;
    return BlurSampling::BoundingBox;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: tessera_blur_bench SCENE [options] (see bench/blur_bench.cpp)\n");
        return 2;
    }
    std::string scenePath = argv[1], engine = "reyes", res = "800x600", sppList = "16", schemes = "bbox",
                tiles = "4", perms = "64";
    std::vector<double> translate, spin, dof;
    int threads = 0, refSpp = 1024, runs = 3;
    bool strata = true, sharp = false, noMotion = false;
    for (int i = 2; i < argc; ++i) {
        const std::string a = argv[i];
        auto next = [&]() -> std::string { return i + 1 < argc ? argv[++i] : ""; };
        if (a == "--engine")
            engine = next();
        else if (a == "--res")
            res = next();
        else if (a == "--threads")
            threads = std::stoi(next());
        else if (a == "--translate")
            translate = numbers(next());
        else if (a == "--spin")
            spin = numbers(next());
        else if (a == "--dof")
            dof = numbers(next());
        else if (a == "--spp")
            sppList = next();
        else if (a == "--schemes")
            schemes = next();
        else if (a == "--tiles")
            tiles = next();
        else if (a == "--perms")
            perms = next();
        else if (a == "--ref-spp")
            refSpp = std::stoi(next());
        else if (a == "--runs")
            runs = std::stoi(next());
        else if (a == "--no-strata")
            strata = false;
        else if (a == "--sharp")
            sharp = true;
        else if (a == "--no-motion")
            noMotion = true;
        else {
            std::fprintf(stderr, "unknown option %s\n", a.c_str());
            return 2;
        }
    }
    Scene scene = loadScene(scenePath, [](const std::string&) {});
    int w = 0, h = 0;
    if (std::sscanf(res.c_str(), "%dx%d", &w, &h) == 2) {
        scene.camera.width = w;
        scene.camera.height = h;
    }
    if (!translate.empty() || !spin.empty()) addMotion(scene, translate, spin);
    if (noMotion) {  // the scene's own motion off: every patch at shutter open, the camera still
        for (PatchAttributes& a : scene.attributes) a.motion = MotionKeys{};
        scene.camera.motion.clear();
    }
    if (dof.size() == 3) {
        scene.camera.fStop = float(dof[0]);
        scene.camera.focalLength = float(dof[1]);
        scene.camera.focalDistance = float(dof[2]);
    }
    auto run = [&](int spp, BlurSampling scheme, int K, int P, bool blur, bool cut, int repeats, Image* out) {
        Scene s = scene;
        setSpp(s, spp);
        RenderSettings rs;
        rs.engine = engine;
        rs.threads = threads;
        rs.blur.enabled = blur;
        rs.blur.sampling = scheme;
        rs.blur.tileSize = K;
        rs.blur.permutations = P;
        rs.blur.strataBounds = cut;
        std::vector<double> ms;
        nlohmann::json stats;
        for (int r = 0; r < repeats; ++r) {
            RenderResult res = render(s, rs);
            ms.push_back(res.stats["engine_ms"].get<double>());
            stats = res.stats;
            if (out && r == repeats - 1) *out = std::move(res.image);
        }
        std::sort(ms.begin(), ms.end());
        nlohmann::json j = {
            {"engine", engine}, {"spp", spp}, {"engine_ms", ms[ms.size() / 2]}, {"engine_ms_all", ms}};
        if (stats.contains("sample_tests")) j["sample_tests"] = stats["sample_tests"];
        if (stats.contains("rays")) j["rays"] = stats["rays"];
        return j;
    };
    Image reference, sharpReference;
    if (refSpp > 0) {
        nlohmann::json j = run(refSpp, BlurSampling::BoundingBox, 4, 64, true, true, 1, &reference);
        j["config"] = "reference";
        std::printf("%s\n", j.dump().c_str());
        std::fflush(stdout);
    }
    if (sharp) {
        if (refSpp > 0) {
            nlohmann::json j = run(refSpp, BlurSampling::BoundingBox, 4, 64, false, true, 1, &sharpReference);
            j["config"] = "sharp_reference";
            std::printf("%s\n", j.dump().c_str());
        }
        for (const std::string& sp : words(sppList)) {
            Image im;
            nlohmann::json j = run(std::stoi(sp), BlurSampling::BoundingBox, 4, 64, false, true, runs, &im);
            j["config"] = "sharp";
            if (refSpp > 0) j["rmse"] = rmse(im, sharpReference);
            std::printf("%s\n", j.dump().c_str());
            std::fflush(stdout);
        }
    }
    for (const std::string& name : words(schemes))
        for (const std::string& sp : words(sppList)) {
            const int spp = std::stoi(sp);
            const BlurSampling scheme = schemeByName(name);
            std::vector<int> Ks{4}, Ps{64};
            if (scheme == BlurSampling::Interleaved) {
                Ks.clear(), Ps.clear();
                for (const std::string& k : words(tiles)) Ks.push_back(std::stoi(k));
                for (const std::string& p : words(perms)) Ps.push_back(std::stoi(p));
            }
            for (int K : Ks)
                for (int P : Ps) {
                    Image im;
                    nlohmann::json j = run(spp, scheme, K, P, true, strata, runs, &im);
                    j["config"] = name;
                    j["strata_bounds"] = strata;
                    if (scheme == BlurSampling::Interleaved) {
                        j["tile"] = K, j["permutations"] = P;
                        if (refSpp > 0) j["tile_peak"] = tilePeak(im, reference, K);
                    }
                    if (refSpp > 0) j["rmse"] = rmse(im, reference);
                    std::printf("%s\n", j.dump().c_str());
                    std::fflush(stdout);
                }
        }
    return 0;
}
