// tessera: the command-line driver. `tessera render SCENE` and `tessera info SCENE`.
#include <fmt/core.h>
#include <sys/resource.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <optional>

#include "io/diagnostics.h"
#include "io/image_io.h"
#include "io/rib_writer.h"
#include "io/scene_loader.h"
#include "render/render.h"

using namespace tessera;
namespace fs = std::filesystem;

namespace {

constexpr int kMaxResolution = kMaxImageSize;  // per axis; documented in docs/errors.md
constexpr int kMaxSpp = kMaxPixelSamples;
std::atomic<bool> gCancel{false};

extern "C" void onSigint(int) {
    gCancel.store(true);
}

double peakRssMb() {
    rusage ru{};
    getrusage(RUSAGE_SELF, &ru);
    return ru.ru_maxrss / 1024.0;  // Linux reports KiB
}

[[noreturn]] void fail(const std::string& message) {
    fmt::print(stderr, "{}\n", message);
    std::exit(2);
}

struct RenderArgs {
    std::string scene, output, engine = "reyes", res, stats, format = "auto";
    std::string sampler = "sobol";
    int spp = 0, threads = 0, bucketSize = 32, subpatchDepth = 6, maxDepth = 4, maxGridEdge = 16;
    double shadingRate = 0;
    unsigned seed = 0;
    bool quiet = false, cullBackfaces = false, noRayBinning = false;
};

Scene loadOrFail(const std::string& path, bool quiet, const std::string& formatName = "auto") {
    std::optional<SceneFormat> format = parseSceneFormat(formatName);
    if (!format)
        fail(fmt::format("error: unknown --format '{}' (auto, rib, bpt, obj, micropolis)", formatName));
    try {
        return loadScene(
            path,
            [quiet](const std::string& w) {
                if (!quiet) fmt::print(stderr, "{}\n", w);
            },
            *format);
    } catch (const InputError& e) {
        fail(e.what());
    } catch (const std::exception& e) {
        fail(path + ": error: " + e.what());
    }
}

// Default output name: the RIB Display name (with a .png/.exr extension), else SCENE's stem + .png.
std::string defaultOutput(const Scene& scene, const std::string& scenePath) {
    if (!scene.image.displayName.empty()) {
        fs::path d(scene.image.displayName);
        if (!isSupportedImageExtension(d.string())) d.replace_extension(".png");
        return d.string();
    }
    return fs::path(scenePath).filename().replace_extension(".png").string();
}

class ProgressBar {
  public:
    explicit ProgressBar(bool enabled) : enabled_(enabled), start_(std::chrono::steady_clock::now()) {}
    void update(int done, int total) {
        if (!enabled_) return;
        std::lock_guard lock(mutex_);
        if (done < last_) return;
        last_ = done;
        double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
        // Redraw at most ten times a second (and always at the end).
        if (done != total && elapsed - lastDraw_ < 0.1) return;
        lastDraw_ = elapsed;
        double eta = done > 0 ? elapsed * (total - done) / done : 0.0;
        const int width = 30;
        int filled = total > 0 ? done * width / total : width;
        fmt::print(stderr, "\r[{:<{}}] {}/{} buckets  {:.1f}s elapsed  ~{:.1f}s left ",
                   std::string(filled, '#'), width, done, total, elapsed, eta);
        if (done == total) fmt::print(stderr, "\n");
    }

  private:
    bool enabled_;
    std::chrono::steady_clock::time_point start_;
    std::mutex mutex_;
    int last_ = -1;
    double lastDraw_ = -1;
};

int runRender(const RenderArgs& a) {
    if (a.spp < 0 || a.spp > kMaxSpp) fail(fmt::format("error: --spp must be between 1 and {}", kMaxSpp));
    if (a.threads < 0) fail("error: --threads must be >= 0 (0 = all cores)");
    if (a.shadingRate < 0 || !std::isfinite(a.shadingRate)) fail("error: --shading-rate must be > 0");
    if (a.bucketSize < 4 || a.bucketSize > 1024) fail("error: --bucket-size must be between 4 and 1024");
    if (a.engine != "reyes" && a.engine != "rt") fail("error: --engine must be reyes or rt");
    if (!a.output.empty() && !isSupportedImageExtension(a.output))
        fail(fmt::format("{}: error: unsupported output format (use .png or .exr)", a.output));

    // Ctrl-C from here on: stop cleanly (no output written) and exit 130.
    std::signal(SIGINT, onSigint);
    Scene scene = loadOrFail(a.scene, a.quiet, a.format);
    if (gCancel.load()) {
        fmt::print(stderr, "interrupted while loading {}: no image written\n", a.scene);
        return 130;
    }
    // Command-line options override the scene's.
    if (!a.res.empty()) {
        int w = 0, h = 0;
        char x = 0, extra = 0;
        if (std::sscanf(a.res.c_str(), "%d%c%d%c", &w, &x, &h, &extra) != 3 || (x != 'x' && x != 'X'))
            fail(fmt::format("error: --res '{}' is not WIDTHxHEIGHT", a.res));
        scene.camera.width = w;
        scene.camera.height = h;
    }
    if (scene.camera.width < 1 || scene.camera.height < 1 || scene.camera.width > kMaxResolution ||
        scene.camera.height > kMaxResolution)
        fail(fmt::format("{}: error: resolution {}x{} outside 1..{} per axis", a.scene, scene.camera.width,
                         scene.camera.height, kMaxResolution));
    if (a.spp > 0) splitSamplesPerPixel(a.spp, scene.image.pixelSamplesX, scene.image.pixelSamplesY);
    if (a.shadingRate > 0)
        for (auto& attr : scene.attributes) attr.shadingRate = float(a.shadingRate);
    if (scene.patches.empty()) fail(fmt::format("{}: error: the scene has no geometry", a.scene));

    std::string output = a.output.empty() ? defaultOutput(scene, a.scene) : a.output;

    RenderSettings settings;
    settings.engine = a.engine;
    settings.threads = a.threads;
    settings.seed = a.seed;
    settings.sampler = a.sampler == "jittered" ? SamplerKind::Jittered : SamplerKind::Sobol;
    settings.bucketSize = a.bucketSize;
    settings.subpatchDepth = a.subpatchDepth;
    settings.maxDepth = a.maxDepth;
    settings.cullBackfaces = a.cullBackfaces;
    settings.rayBinning = !a.noRayBinning;
    settings.maxGridEdge = a.maxGridEdge;
    ProgressBar bar(!a.quiet && isatty(STDERR_FILENO));
    settings.progress = [&bar](int done, int total) { bar.update(done, total); };
    settings.cancel = &gCancel;

    auto t0 = std::chrono::steady_clock::now();
    RenderResult result;
    try {
        result = render(scene, settings);
    } catch (const std::invalid_argument& e) {
        fail(std::string("error: ") + e.what());
    }
    double renderMs =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    if (result.cancelled) {
        fmt::print(stderr, "\ninterrupted after {:.0f} ms: no image written\n", renderMs);
        return 130;
    }

    OutputEncoding enc{scene.image.exposureGain, scene.image.exposureGamma, scene.image.srgbOutput};
    try {
        writeImage(output, result.image, enc);
    } catch (const std::exception& e) {
        fmt::print(stderr, "error: {}\n", e.what());
        return 1;
    }

    nlohmann::json& s = result.stats;
    s["scene"] = a.scene;
    s["output"] = output;
    s["render_ms"] = renderMs;
    s["peak_rss_mb"] = peakRssMb();
    if (!a.stats.empty()) {
        std::ofstream f(a.stats);
        if (!f) fail(fmt::format("{}: error: cannot write statistics", a.stats));
        f << s.dump(2) << "\n";
    }
    if (!a.quiet) {
        fmt::print(stderr, "{}: {}x{} {} spp, {} engine, {} threads: {:.1f} ms, peak {:.1f} MB\n", output,
                   scene.camera.width, scene.camera.height, s.value("spp", 0), a.engine,
                   s.value("threads", 0), renderMs, s["peak_rss_mb"].get<double>());
        if (a.engine == "reyes")
            fmt::print(
                stderr, "  patches {} (culled {}), splits {}, grids {}, micropolygons {}, sample tests {}\n",
                s.value("patches_in", 0), s.value("patches_culled", 0), s.value("splits", 0),
                s.value("grids", 0), s.value("micropolygons", 0), s.value("sample_tests", uint64_t(0)));
    }
    return 0;
}

int runConvert(const std::string& in, const std::string& out, const std::string& format) {
    if (fs::path(out).extension() != ".rib")
        fail(fmt::format("{}: error: convert writes RIB: name it .rib", out));
    Scene scene = loadOrFail(in, false, format);
    try {
        writeRib(scene, out);
    } catch (const std::exception& e) {
        fmt::print(stderr, "{}\n", e.what());
        return 1;
    }
    fmt::print(stderr, "{}: {} patches written\n", out, scene.patches.size());
    return 0;
}

int runInfo(const std::string& path, const std::string& format) {
    Scene scene = loadOrFail(path, false, format);
    Bounds3 b = scene.worldBounds();
    const Camera& c = scene.camera;
    fmt::print("scene:    {}\n", path);
    fmt::print("patches:  {}\n", scene.patches.size());
    fmt::print("objects:  {}\n", scene.objectCount);
    fmt::print("lights:   {}\n", scene.lights.size());
    fmt::print("bounds:   ({:.6g}, {:.6g}, {:.6g}) - ({:.6g}, {:.6g}, {:.6g})\n", b.lo.x, b.lo.y, b.lo.z,
               b.hi.x, b.hi.y, b.hi.z);
    Mat4 worldFromCamera = c.cameraFromWorld.inverse();
    Vec3 eye = worldFromCamera.point({0, 0, 0});
    Vec3 dir = normalize(worldFromCamera.vector({0, 0, 1}));
    fmt::print(
        "camera:   {}x{}, {} fov {:.4g}, eye ({:.6g}, {:.6g}, {:.6g}), looking ({:.4g}, {:.4g}, {:.4g})\n",
        c.width, c.height, c.perspective ? "perspective" : "orthographic", c.fovDegrees, eye.x, eye.y, eye.z,
        dir.x, dir.y, dir.z);
    fmt::print("clipping: {:.6g} .. {:.6g}\n", c.nearClip, c.farClip);
    fmt::print("samples:  {}x{} per pixel\n", scene.image.pixelSamplesX, scene.image.pixelSamplesY);
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{"Tessera: a renderer for bicubic Bezier patches (Reyes and ray tracing)"};
    app.require_subcommand(1);
    RenderArgs ra;
    CLI::App* render = app.add_subcommand("render", "Render a .rib or .bpt scene to .png or .exr");
    render->add_option("scene", ra.scene, "Scene file (.rib, .rib.gz or .bpt)")->required();
    render->add_option("-o,--output", ra.output, "Output image (.png or .exr)");
    render->add_option("--format", ra.format, "Input format: auto, rib, bpt, obj, micropolis");
    render->add_option("--engine", ra.engine, "reyes or rt")->check(CLI::IsMember({"reyes", "rt"}));
    render->add_option("--res", ra.res, "Resolution WIDTHxHEIGHT (overrides Format)");
    render->add_option("--spp", ra.spp, "Samples per pixel (overrides PixelSamples)")
        ->check(CLI::Range(1, kMaxSpp));
    render
        ->add_option("--shading-rate", ra.shadingRate, "Micropolygon area in pixels (overrides ShadingRate)")
        ->check(CLI::PositiveNumber);
    render->add_option("--threads", ra.threads, "Worker threads (0 = all cores)")
        ->check(CLI::NonNegativeNumber);
    render->add_option("--stats", ra.stats, "Write statistics as JSON to this file");
    render->add_option("--seed", ra.seed, "Sample pattern seed");
    render->add_option("--sampler", ra.sampler, "Film samples: sobol (Owen-scrambled Sobol') or jittered")
        ->check(CLI::IsMember({"sobol", "jittered"}));
    render->add_option("--bucket-size", ra.bucketSize, "Bucket side in pixels")->check(CLI::Range(4, 1024));
    render->add_option("--max-grid", ra.maxGridEdge, "Reyes: micropolygons per grid edge")
        ->check(CLI::Range(1, 256));
    render->add_option("--subpatch-depth", ra.subpatchDepth, "rt: subpatch tree depth")
        ->check(CLI::Range(0, 12));
    render->add_option("--max-depth", ra.maxDepth, "rt: ray bounces")->check(CLI::Range(0, 64));
    render->add_flag("--cull-backfaces", ra.cullBackfaces,
                     "rt: cull back-facing subpatches for primary rays");
    render->add_flag("--no-ray-binning", ra.noRayBinning,
                     "rt: per-ray traversal for camera and shadow rays (no binning; same image)");
    render->add_flag("-q,--quiet", ra.quiet, "No progress bar, warnings or summary");
    std::string infoPath, infoFormat = "auto";
    CLI::App* info = app.add_subcommand("info", "Print patch count, objects, bounds and camera of a scene");
    info->add_option("scene", infoPath, "Scene file")->required();
    info->add_option("--format", infoFormat, "Input format: auto, rib, bpt, obj, micropolis");
    std::string convertIn, convertOut, convertFormat = "auto";
    CLI::App* convert = app.add_subcommand("convert", "Write any supported input as a RIB of Bezier patches");
    convert->add_option("input", convertIn, "Input scene")->required();
    convert->add_option("-o,--output", convertOut, "Output .rib")->required();
    convert->add_option("--format", convertFormat, "Input format: auto, rib, bpt, obj, micropolis");
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        if (e.get_exit_code() == 0) return app.exit(e);
        app.exit(e);
        return 2;
    }
    if (*render) return runRender(ra);
    if (*info) return runInfo(infoPath, infoFormat);
    if (*convert) return runConvert(convertIn, convertOut, convertFormat);
    return 2;
}
