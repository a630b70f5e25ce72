// tessera: the command-line driver. `tessera render SCENE`, `tessera info SCENE`, `tessera convert`.
#include <fcntl.h>
#include <fmt/core.h>
#include <sys/resource.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <optional>
#include <vector>

#include "core/hash.h"
#include "film/crop.h"
#include "io/diagnostics.h"
#include "io/image_io.h"
#include "io/rib_reader.h"
#include "io/rib_writer.h"
#include "io/scene_loader.h"
#include "preview.h"
#include "progress.h"
#include "render/aovs.h"
#include "render/render.h"
#include "render/render_options.h"
#include "rt/subpatch_tree.h"

#ifndef TESSERA_VERSION
#define TESSERA_VERSION "unknown"
#endif
#ifndef TESSERA_BUILD_TYPE
#define TESSERA_BUILD_TYPE "unknown"
#endif

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

// The render command's arguments: the render options shared with the Python module (render_options.h),
// then what only the command line has (files, progress, tiles, passes).
struct RenderArgs : RenderOptions {
    std::string scene, output, res, stats, format = "auto", up;
    bool quiet = false, progressLines = false;
    // Motion blur and depth of field overrides of the camera (docs/motion.md): "" = the scene's.
    std::string shutter, dof;
    int passes = 1;             // progressive: the samples per pixel in this many passes
    bool writePartial = false;  // write the image after every pass, and keep it when interrupted
    std::string aovs;           // --aov z,N,id,...
    std::string frames;         // --frames N or A-B: RIB frame numbers (docs/inputs.md, multi-frame RIB)
    std::string adaptiveMap;    // --adaptive-map FILE.png (docs/adaptive.md)
    // Crop windows and farm tiles (docs/inputs.md): --crop xmin,xmax,ymin,ymax in NDC, --tile I/N.
    std::string crop, tile;
    std::string
        displayServer;  // live preview: HOST:PORT of a tev viewer ("": none, or the RIB's framebuffer)
    std::string shadowMapCache;   // a folder where Reyes keeps its shadow maps for the other tiles of a farm
    bool shadowMapsOnly = false;  // make the shadow maps into the cache and no image (a farm's first job)
};

// The OpenEXR header: the camera's matrices (io/image_io.h), this program's name and the render time.
ExrMetadata exrMetadata(const Camera& cam, double renderMs) {
    ExrMetadata m = cameraExrMetadata(cam);
    m.software = "tessera " TESSERA_VERSION;
    m.renderMs = renderMs;
    return m;
}

std::optional<UpAxis> parseUp(const std::string& up) {
    if (up.empty()) return std::nullopt;
    if (up == "x") return UpAxis::X;
    if (up == "y") return UpAxis::Y;
    return UpAxis::Z;  // CLI11 allowed only x, y, z
}

// Output paths are checked before the scene is loaded, so that a mistake costs no render: the directory
// must exist and take a new file (a probe file is created beside the target and removed again, which is
// what writing the temporary file and renaming it needs). Returns "" or what is wrong.
std::string whyNotWritable(const std::string& path) {
    fs::path p(path);
    std::error_code ec;
    if (p.filename().empty() || fs::is_directory(p, ec)) return "is a directory, not a file name";
    fs::path dir = p.parent_path();
    if (dir.empty()) dir = ".";
    if (!fs::exists(dir, ec)) return fmt::format("the directory '{}' does not exist", dir.string());
    if (!fs::is_directory(dir, ec)) return fmt::format("'{}' is not a directory", dir.string());
    std::string probe = (dir / fmt::format(".{}.probe{}", p.filename().string(), getpid())).string();
    int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL, 0644);
    if (fd < 0) return fmt::format("cannot create a file in '{}': {}", dir.string(), std::strerror(errno));
    ::close(fd);
    ::unlink(probe.c_str());
    return "";
}

void checkWritableOrFail(const std::string& path, const char* what) {
    std::string why = whyNotWritable(path);
    if (!why.empty()) fail(fmt::format("{}: error: cannot write the {} there: {}", path, what, why));
}

// An OpenEXR file to be written: checked before the render that the OpenEXR module loads (io/image_io.h).
void checkExrOrFail(const std::string& path) {
    const std::string why = exrSupportError();
    if (!why.empty()) fail(fmt::format("{}: error: {}", path, why));
}

// Writes `text` to a temporary file beside `path` and returns its name; the caller renames it into place.
std::string writeTemporary(const std::string& path, const std::string& text) {
    fs::path p(path);
    std::string tmp = (p.parent_path() / fmt::format(".{}.tmp{}", p.filename().string(), getpid())).string();
    std::ofstream f(tmp, std::ios::binary);
    f << text;
    f.close();
    if (!f) {
        std::error_code ec;
        fs::remove(tmp, ec);
        throw std::runtime_error(path + ": cannot write");
    }
    return tmp;
}

Scene loadOrFail(const std::string& path, bool quiet, const std::string& formatName = "auto",
                 std::optional<UpAxis> up = std::nullopt, std::optional<int> ribFrameOrdinal = std::nullopt,
                 RasterOverride raster = {}) {
    std::optional<SceneFormat> format = parseSceneFormat(formatName);
    if (!format)
        fail(fmt::format("error: unknown --format '{}' (auto, rib, bpt, obj, micropolis)", formatName));
    try {
        if (ribFrameOrdinal) {
            Scene scene;
            readRibFrame(
                path, *ribFrameOrdinal, scene,
                [quiet](const std::string& w) {
                    if (!quiet) fmt::print(stderr, "{}\n", w);
                },
                raster);
            return scene;
        }
        return loadScene(
            path,
            [quiet](const std::string& w) {
                if (!quiet) fmt::print(stderr, "{}\n", w);
            },
            *format, up, raster);
    } catch (const InputError& e) {
        fail(e.what());
    } catch (const std::exception& e) {
        fail(path + ": error: " + e.what());
    }
}

// The depth plane of a render as a depth map (Display "zfile" / "shadow") seen from its camera.
DepthMap depthMapOf(const Image& image, const ExrMetadata& camera, const std::string& kind) {
    DepthMap map;
    map.width = image.width;
    map.height = image.height;
    const ImagePlane* z = image.plane("z");
    if (!z) throw std::runtime_error("the engine made no depth plane for the depth map");
    map.depth = z->values;
    map.worldToCamera = camera.worldToCamera;
    map.worldToNDC = camera.worldToNDC;
    map.kind = kind;
    return map;
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

// The engines call progress(done, total) from worker threads with the work finished so far. On a terminal:
// a bar with the fraction, the elapsed time and the time left (cli::TimeLeftEstimate); with --progress: one
// line "progress N%" per whole percent reached, for render farm managers and logs.
class Progress {
  public:
    enum class Mode { Off, Bar, Lines };
    explicit Progress(Mode mode) : mode_(mode), start_(std::chrono::steady_clock::now()) {}
    void begin() {
        if (mode_ != Mode::Lines) return;
        std::lock_guard lock(mutex_);
        fmt::print(stderr, "progress 0%\n");
        std::fflush(stderr);
        steps_.markReported(0);
    }
    void update(int64_t done, int64_t total) {
        if (mode_ == Mode::Off) return;
        std::lock_guard lock(mutex_);
        if (mode_ == Mode::Lines) {
            if (std::optional<int> p = steps_.step(done, total)) {
                fmt::print(stderr, "progress {}%\n", *p);
                std::fflush(stderr);
            }
            return;
        }
        if (done < last_) return;
        last_ = done;
        double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
        estimate_.update(elapsed, done, total);
        // Redraw at most ten times a second (and always at the end).
        if (done != total && elapsed - lastDraw_ < 0.1) return;
        lastDraw_ = elapsed;
        const int width = 30;
        const double f = total > 0 ? std::clamp(double(done) / double(total), 0.0, 1.0) : 1.0;
        const int filled = int(f * width);
        std::optional<double> left = estimate_.secondsLeft(elapsed);
        std::string eta = left ? fmt::format("~{:.1f}s left", *left) : std::string("estimating");
        fmt::print(stderr, "\r[{:<{}}] {:3.0f}%  {:.1f}s elapsed  {} ", std::string(filled, '#'), width,
                   f * 100, elapsed, eta);
        if (done == total) fmt::print(stderr, "\n");
    }
    // After a successful render: make sure the last line says 100%.
    void finish() {
        if (mode_ != Mode::Lines) return;
        std::lock_guard lock(mutex_);
        if (steps_.last() < 100) {
            fmt::print(stderr, "progress 100%\n");
            steps_.markReported(100);
        }
    }

  private:
    Mode mode_;
    std::chrono::steady_clock::time_point start_;
    std::mutex mutex_;
    int64_t last_ = -1;
    double lastDraw_ = -1;
    cli::TimeLeftEstimate estimate_;
    cli::PercentSteps steps_;
};

// --adaptive-map: the refined subpixels (2 x 2 per pixel) in white over the image at a quarter of its
// brightness, for looking at where the samples went.
void writeAdaptiveMap(const std::string& path, const RenderResult& result) {
    const Image& img = result.image;
    Image map(2 * img.width, 2 * img.height);
    for (int y = 0; y < map.height; ++y)
        for (int x = 0; x < map.width; ++x) {
            const float* c = img.pixel(img.x0 + x / 2, img.y0 + y / 2);
            float* m = map.pixel(x, y);
            const bool refined = result.refinedSubpixels[size_t(y) * size_t(map.width) + size_t(x)] != 0;
            for (int k = 0; k < 3; ++k) m[k] = refined ? 1.f : 0.25f * std::clamp(c[k], 0.f, 1.f);
            m[3] = 1.f;
        }
    writeImage(path, map, OutputEncoding{});
}

// --tile I/N: tile I (0-based) of an N-tile split; nullopt if the text is not that.
std::optional<std::pair<int, int>> parseTile(const std::string& text) {
    int index = -1, count = 0;
    char slash = 0, extra = 0;
    if (std::sscanf(text.c_str(), "%d%c%d%c", &index, &slash, &count, &extra) != 3 || slash != '/')
        return std::nullopt;
    if (count < 1 || index < 0 || index >= count) return std::nullopt;
    return std::make_pair(index, count);
}

// What `tessera assemble` checks tiles by: FNV-1a (64 bit) over the scene file's bytes and every option
// that changes pixels (not --crop/--tile, -o, --threads, --bucket-size, --stats or the progress flags).
// Files the scene reads (ReadArchive, textures) are not hashed: keep them unchanged while a farm renders.
std::string sceneHash(const RenderArgs& a, const Scene& scene) {
    Fnv1a64 h;
    auto mix = [&h](const std::string& bytes) {
        h.bytes(bytes.data(), bytes.size());
        h.value(uint8_t(0xff));  // separator
    };
    std::ifstream f(a.scene, std::ios::binary);
    mix(std::string(std::istreambuf_iterator<char>(f), {}));
    mix(fmt::format("{}|{}x{}|{}x{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}|{}",
                    a.engine, scene.camera.width, scene.camera.height, scene.image.pixelSamplesX,
                    scene.image.pixelSamplesY, a.shadingRate, a.seed, a.sampler, a.shadows, a.reyesShadows,
                    a.integrator, a.aoSamples, a.aoDistance, a.aoWeighting, a.aovs, a.maxDepth,
                    a.subpatchDepth, a.maxGridEdge, a.cullBackfaces, a.shutter, a.dof, a.noBlur,
                    a.blurSampling, a.blurTile, a.blurPermutations, a.adaptive, a.adaptiveThreshold, a.format,
                    a.up));
    mix(std::to_string(a.lightSamples));
    mix(a.gloss);
    mix(std::to_string(a.passes));
    // Mixed in only when given, so that the hash of every earlier tile is unchanged.
    if (!a.micropolygonSampling.empty()) mix("micropolygon-sampling=" + a.micropolygonSampling);
    if (a.displacementSplit >= 0) mix("displacement-split=" + std::to_string(a.displacementSplit));
    if (a.displacementNormals != "exact") mix("displacement-normals=" + a.displacementNormals);
    if (!a.adaptiveThresholds.empty()) mix("adaptive-thresholds=" + a.adaptiveThresholds);
    if (!a.adaptiveFocus.empty()) mix("adaptive-focus=" + a.adaptiveFocus);
    if (a.adaptiveInterpolate) mix("adaptive-interpolate");
    return fmt::format("{:016x}", h.h);
}

int renderFrame(const RenderArgs& a, std::optional<int> ribFrameOrdinal) {
    // Mistakes first, before anything is loaded: options, then the files the render will write.
    if (a.spp < 0 || a.spp > kMaxSpp) fail(fmt::format("error: --spp must be between 1 and {}", kMaxSpp));
    if (a.writePartial && a.passes < 2)
        fail("error: --write-partial writes the image after each pass: give --passes N (N >= 2)");
    if (a.threads < 0) fail("error: --threads must be >= 0 (0 = all cores)");
    if (a.shadingRate < 0 || !std::isfinite(a.shadingRate)) fail("error: --shading-rate must be > 0");
    if (a.bucketSize < 4 || a.bucketSize > 1024) fail("error: --bucket-size must be between 4 and 1024");
    if (a.engine != "reyes" && a.engine != "rt") fail("error: --engine must be reyes or rt");
    std::string badAov;
    const std::optional<AovRequest> aovs = parseAovs(a.aovs, badAov);
    if (!aovs) fail(fmt::format("error: --aov: unknown AOV '{}' (known: {})", badAov, kAovNames));
    for (const std::string& p : aovs->planes)
        if (p == "occlusion" && a.integrator != "ao")
            fail("error: --aov occlusion is made by --integrator ao (with --engine rt)");
    if (a.integrator != "direct" && a.engine != "rt")
        fail(fmt::format("error: --integrator {} is ray traced: use it with --engine rt", a.integrator));
    if (a.shadows != "on" && a.shadows != "off" && a.shadows != "scene")
        fail(fmt::format("error: --shadows must be on, off or scene, got '{}'", a.shadows));
    if (a.reyesShadows != "map" && a.reyesShadows != "raytrace")
        fail(fmt::format("error: --reyes-shadows must be map or raytrace, got '{}'", a.reyesShadows));
    if (!a.adaptive && (a.adaptiveThresholdGiven || !a.adaptiveMap.empty() || !a.adaptiveThresholds.empty() ||
                        !a.adaptiveFocus.empty() || a.adaptiveInterpolate))
        fail(
            "error: --adaptive-threshold, --adaptive-thresholds, --adaptive-focus, --adaptive-interpolate "
            "and "
            "--adaptive-map need --adaptive");
    if (a.adaptive) {
        if (a.engine != "rt") fail("error: --adaptive is ray traced: use it with --engine rt");
        if (a.spp > 0) fail("error: --adaptive chooses the samples per pixel itself: drop --spp");
        if (a.passes > 1) fail("error: --adaptive renders in one pass: drop --passes");
        if (a.adaptiveThresholdGiven && !(a.adaptiveThreshold >= 0 && std::isfinite(a.adaptiveThreshold)))
            fail(
                fmt::format("error: --adaptive-threshold must be a number >= 0 (0: refine every subpixel, "
                            ">= 1: none by colour), got {}",
                            a.adaptiveThreshold));
        if (!a.adaptiveMap.empty()) {
            if (fs::path(a.adaptiveMap).extension() != ".png")
                fail(fmt::format("{}: error: --adaptive-map writes a PNG: name it .png", a.adaptiveMap));
            checkWritableOrFail(a.adaptiveMap, "adaptive map");
            std::error_code ec;
            if (!a.output.empty() &&
                fs::weakly_canonical(a.adaptiveMap, ec) == fs::weakly_canonical(a.output, ec))
                fail(fmt::format("{}: error: --adaptive-map and -o name the same file", a.adaptiveMap));
        }
    }
    std::optional<std::vector<double>> crop;
    if (!a.crop.empty()) {
        crop = parseNumberList(a.crop, 4);
        if (!crop) fail(fmt::format("error: --crop '{}' is not XMIN,XMAX,YMIN,YMAX (four numbers)", a.crop));
        const std::vector<double>& c = *crop;
        if (!validCropWindow(c.data()))
            fail(fmt::format(
                "error: --crop '{}': needs 0 <= xmin < xmax <= 1 and 0 <= ymin < ymax <= 1 (NDC)", a.crop));
    }
    std::optional<std::pair<int, int>> tile;
    if (!a.tile.empty()) {
        tile = parseTile(a.tile);
        if (!tile)
            fail(fmt::format("error: --tile '{}' is not I/N with 0 <= I < N (tile I of an N-tile split)",
                             a.tile));
        if (a.adaptive) fail("error: --tile and --adaptive cannot be combined yet");
    }
    if (!a.shadowMapCache.empty()) {
        std::error_code ec;
        if (fs::exists(a.shadowMapCache, ec) && !fs::is_directory(a.shadowMapCache, ec))
            fail(fmt::format("{}: error: --shadow-map-cache names a file, not a folder", a.shadowMapCache));
        fs::create_directories(a.shadowMapCache, ec);
        if (ec || access(a.shadowMapCache.c_str(), W_OK) != 0)
            fail(fmt::format("{}: error: --shadow-map-cache: cannot create or write the folder",
                             a.shadowMapCache));
    }
    if (a.shadowMapsOnly) {
        if (a.shadowMapCache.empty())
            fail("error: --shadow-maps-only makes the maps into --shadow-map-cache DIR: give it");
        if (a.engine != "reyes")
            fail(
                "error: --shadow-maps-only: the ray tracer traces its shadows and makes no maps (--engine "
                "reyes)");
        if (!a.output.empty() || a.passes > 1 || a.adaptive)
            fail("error: --shadow-maps-only writes no image: drop -o, --passes and --adaptive");
    }
    if (!a.displayServer.empty()) {
        std::string host;
        int port = 0;
        if (!DisplayClient::parseAddress(a.displayServer, host, port))
            fail(fmt::format("error: --display-server '{}' is not HOST:PORT (port 1..65535)",
                             a.displayServer));
    }
    int resW = 0, resH = 0;
    if (!a.res.empty()) {
        const std::optional<std::pair<int, int>> wh = parseResolution(a.res);
        if (!wh) fail(fmt::format("error: --res '{}' is not WIDTHxHEIGHT", a.res));
        std::tie(resW, resH) = *wh;
        if (resW < 1 || resH < 1 || resW > kMaxResolution || resH > kMaxResolution)
            fail(fmt::format("{}: error: resolution {}x{} outside 1..{} per axis", a.scene, resW, resH,
                             kMaxResolution));
    }
    std::optional<std::vector<double>> shutter, dof;
    if (!a.shutter.empty()) {
        shutter = parseNumberList(a.shutter, 2);
        if (!shutter) fail(fmt::format("error: --shutter '{}' is not OPEN,CLOSE (two numbers)", a.shutter));
        if ((*shutter)[1] < (*shutter)[0])
            fail(fmt::format("error: --shutter '{}': close is before open", a.shutter));
    }
    if (!a.dof.empty()) {
        dof = parseNumberList(a.dof, 3);
        if (!dof)
            fail(fmt::format("error: --dof '{}' is not FSTOP,FOCALLENGTH,FOCALDISTANCE (three numbers)",
                             a.dof));
        if (!((*dof)[0] > 0 && (*dof)[1] > 0 && (*dof)[2] > 0))
            fail(fmt::format("error: --dof '{}': fstop, focal length and focal distance must be positive",
                             a.dof));
    }
    if (!a.output.empty()) {
        if (!isSupportedImageExtension(a.output))
            fail(fmt::format("{}: error: unsupported output format (use .png or .exr)", a.output));
        checkWritableOrFail(a.output, "image");
    }
    if (!a.stats.empty()) {
        checkWritableOrFail(a.stats, "statistics");
        std::error_code ec;
        if (!a.output.empty() && fs::weakly_canonical(a.stats, ec) == fs::weakly_canonical(a.output, ec))
            fail(fmt::format("{}: error: --stats and -o name the same file", a.stats));
    }

    // Ctrl-C from here on: stop cleanly (no output written) and exit 130.
    std::signal(SIGINT, onSigint);
    // --res is known before the scene is read: subdivision meshes are refined for the size they will have
    // in this image (docs/subdivision.md), the whole frame's (--crop and --tile do not change it).
    const auto loadStart = std::chrono::steady_clock::now();
    Scene scene =
        loadOrFail(a.scene, a.quiet, a.format, parseUp(a.up), ribFrameOrdinal, RasterOverride{resW, resH});
    const double loadMs =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - loadStart).count();
    if (gCancel.load()) {
        fmt::print(stderr, "interrupted while loading {}: no image written\n", a.scene);
        return 130;
    }
    // Command-line options override the scene's (render_options.h, shared with the Python module).
    {
        RenderOptions overrides = a;
        overrides.width = resW, overrides.height = resH;
        overrides.shutter = shutter, overrides.dof = dof;
        try {
            applySceneOverrides(scene, overrides);
        } catch (const std::invalid_argument& e) {
            fail(fmt::format("{}: error: {}", a.scene, e.what()));
        }
    }
    if (scene.patches.empty()) fail(fmt::format("{}: error: the scene has no geometry", a.scene));

    // Display "zfile" / "shadow" (RI spec 3.2, sec. 4.1.4): the frame writes a depth map, under the Display
    // name as given (any extension), not an image.
    const bool depthDisplay = scene.image.displayType == "zfile" || scene.image.displayType == "shadow";
    std::string output = a.output;
    if (output.empty() && !a.shadowMapsOnly) {  // named by the scene: checked now, still before the render
        output = depthDisplay ? scene.image.displayName : defaultOutput(scene, a.scene);
        checkWritableOrFail(output, "image");
    }
    if (depthDisplay && !a.output.empty() && fs::path(output).extension() != ".exr")
        fail(fmt::format("{}: error: this frame's Display \"{}\" writes a depth map (OpenEXR): name it .exr",
                         output, scene.image.displayType));
    if (!aovs->names.empty() && (depthDisplay || fs::path(output).extension() != ".exr"))
        fail(fmt::format("error: --aov needs an OpenEXR output (-o NAME.exr): '{}' holds RGBA only", output));
    if (!output.empty() && (depthDisplay || fs::path(output).extension() == ".exr")) checkExrOrFail(output);
    // RIB Display "+name" type mode: further files of this render, each the beauty plus the layers its mode
    // names (--aov's names; "rgba" or "rgb": the beauty alone). Checked now, before the render.
    struct Secondary {
        std::string path;
        AovRequest layers;
    };
    std::vector<Secondary> secondaries;
    AovRequest wanted = *aovs;  // what the render must make: --aov and every secondary display's layers
    for (const ImageOptions::SecondaryDisplay& d : scene.image.secondaryDisplays) {
        const std::string where = fmt::format("{}:{}: error: Display \"+{}\"", a.scene, d.line, d.name);
        std::string bad;
        const bool beauty = d.mode == "rgba" || d.mode == "rgb";
        const std::optional<AovRequest> layers = beauty ? AovRequest{} : parseAovs(d.mode, bad);
        if (!layers) fail(fmt::format("{}: unknown mode '{}' (known: rgba, rgb, {})", where, bad, kAovNames));
        for (const std::string& pl : layers->planes)
            if (pl == "occlusion" && a.integrator != "ao")
                fail(fmt::format("{}: occlusion is made by --integrator ao (with --engine rt)", where));
        fs::path path(d.name);
        if (path.extension().empty()) path += ".exr";
        if (!isSupportedImageExtension(path.string()))
            fail(fmt::format("{}: the file must be .exr or .png", where));
        if (path.extension() == ".png" && !beauty)
            fail(fmt::format("{}: mode '{}' needs an OpenEXR file (.exr): a .png holds RGBA only", where,
                             d.mode));
        checkWritableOrFail(path.string(), "image");
        if (path.extension() == ".exr") checkExrOrFail(path.string());
        wanted.channels |= layers->channels;
        for (const std::string& pl : layers->planes)
            if (std::find(wanted.planes.begin(), wanted.planes.end(), pl) == wanted.planes.end())
                wanted.planes.push_back(pl);
        secondaries.push_back({path.string(), *layers});
    }

    // The film region: the crop window (--crop, else the RIB's CropWindow), then the tile of it.
    RenderSettings settings;
    {
        const double* cw = crop ? crop->data() : scene.image.cropWindow;
        const Rect region =
            cropWindowPixels(scene.camera.width, scene.camera.height, cw[0], cw[1], cw[2], cw[3]);
        if (region.width() <= 0 || region.height() <= 0)
            fail(fmt::format(
                "{}: error: the crop window [{:g}, {:g}] x [{:g}, {:g}] holds no pixel of the {}x{} "
                "image",
                a.scene, cw[0], cw[1], cw[2], cw[3], scene.camera.width, scene.camera.height));
        settings.view.region = region;
        if (tile) {
            int cols, rows;
            if (!tileGrid(region.width(), region.height(), tile->second, cols, rows))
                fail(fmt::format("{}: error: --tile {}: {} tiles do not fit a {}x{} region", a.scene, a.tile,
                                 tile->second, region.width(), region.height()));
            settings.view.region = tileOf(region, tile->first, tile->second);
        }
    }
    // --shadow-maps-only: one pixel, for the maps the frame makes before it (the same for any region).
    if (a.shadowMapsOnly)
        settings.view.region = Rect{settings.view.region.x0, settings.view.region.y0,
                                    settings.view.region.x0 + 1, settings.view.region.y0 + 1};
    const bool partial = settings.view.region.width() != scene.camera.width ||
                         settings.view.region.height() != scene.camera.height || tile;
    if (a.adaptive && partial)
        fail("error: --adaptive renders whole images only (no --crop, --tile or CropWindow)");
    try {
        applyRenderOptions(scene, a, settings);
    } catch (const std::invalid_argument& e) {
        fail(std::string("error: ") + e.what());
    }
    settings.output.channels = wanted.channels | (depthDisplay ? kChannelDepth : 0u);
    settings.output.aovs = wanted.planes;
    if (!a.shadowMapCache.empty()) {
        settings.shadowMapCacheDir = a.shadowMapCache;
        settings.shadowMapCacheKey =
            sceneHash(a, scene) + (ribFrameOrdinal ? fmt::format("-frame{}", *ribFrameOrdinal) : "");
    }
    Progress::Mode mode = a.progressLines                       ? Progress::Mode::Lines
                          : (!a.quiet && isatty(STDERR_FILENO)) ? Progress::Mode::Bar
                                                                : Progress::Mode::Off;
    Progress progress(mode);
    settings.progress = [&progress](auto done, auto total) {
        progress.update(int64_t(done), int64_t(total));
    };
    settings.cancel = &gCancel;

    // Progressive (--passes N): the samples per pixel split into N passes of spp / N, each its own
    // independent estimate (its own scramble seed), averaged as they finish; --write-partial writes the
    // average after every pass, so an interrupted render keeps what converged.
    const int passes = std::max(1, a.passes);
    const int totalSpp = scene.image.pixelSamplesX * scene.image.pixelSamplesY;
    if (passes > 1) {
        if (totalSpp % passes != 0)
            fail(
                fmt::format("error: --passes {} does not divide the {} samples per pixel", passes, totalSpp));
        splitSamplesPerPixel(totalSpp / passes, scene.image.pixelSamplesX, scene.image.pixelSamplesY);
    }
    RenderResult result;
    Image sum;  // passes > 1: the sum of the finished passes' RGBA
    int passesDone = 0;
    // Live preview: --display-server, else a RIB Display "framebuffer" to tev's default address. Each
    // bucket as it finishes; in later passes the average with the passes before it, as written.
    std::optional<cli::LivePreview> preview;
    const std::string displayServer = !a.displayServer.empty()                   ? a.displayServer
                                      : scene.image.displayType == "framebuffer" ? cli::kDefaultDisplayServer
                                                                                 : "";
    if (!displayServer.empty() && !depthDisplay) {
        preview.emplace(
            displayServer, fs::path(output).filename().string(), scene.camera.width, scene.camera.height,
            scene.image.hasBackground ? std::optional<Color>(scene.image.background) : std::nullopt, a.quiet);
        settings.bucketDone = [&preview, &sum, &passesDone](const Image& image, const Rect& r) {
            preview->update(image, r, passesDone > 0 ? &sum : nullptr, passesDone);
        };
    }
    progress.begin();
    auto t0 = std::chrono::steady_clock::now();
    auto average = [&]() {
        Image img = result.image;
        for (size_t i = 0; i < img.rgba.size(); ++i) img.rgba[i] = sum.rgba[i] / float(passesDone);
        return img;
    };
    const uint32_t baseSeed = settings.seed;
    for (int pass = 0; pass < passes; ++pass) {
        RenderResult r;
        settings.seed = baseSeed + uint32_t(pass) * 0x9e3779b9u;  // independent scrambles per pass
        if (passes > 1) {
            const int64_t before = int64_t(pass);
            settings.progress = [&progress, before, passes](auto done, auto total) {
                progress.update(before * int64_t(total) + int64_t(done), int64_t(total) * passes);
            };
        }
        try {
            r = render(scene, settings);
        } catch (const std::invalid_argument& e) {
            fail(std::string("error: ") + e.what());
        } catch (const std::bad_alloc&) {
            fmt::print(stderr, "error: out of memory while rendering {}: no image written\n", a.scene);
            return 1;
        }
        if (r.cancelled) {
            result.cancelled = true;
            break;
        }
        if (pass == 0) {
            result = std::move(r);
            if (passes > 1) sum = result.image;
        } else {
            for (size_t i = 0; i < sum.rgba.size(); ++i) sum.rgba[i] += r.image.rgba[i];
            result.stats = std::move(r.stats);
        }
        ++passesDone;
        if (a.writePartial && pass + 1 < passes) {
            try {
                ExrMetadata meta = exrMetadata(scene.camera, -1.0);
                meta.displayWidth = scene.camera.width, meta.displayHeight = scene.camera.height;
                OutputEncoding enc{scene.image.exposureGain, scene.image.exposureGamma,
                                   scene.image.srgbOutput, &meta};
                writeImage(output, average(), enc);
            } catch (const std::exception& e) {
                fmt::print(stderr, "error: {}\n", e.what());
                return 1;
            }
        }
    }
    if (passesDone > 1) result.image = average();
    settings.seed = baseSeed;
    if (preview) preview->finish();
    double renderMs =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    if (!a.quiet)
        for (const std::string& w : result.warnings) fmt::print(stderr, "warning: {}\n", w);
    if (result.cancelled) {
        if (a.writePartial && passesDone > 0)
            fmt::print(stderr, "\ninterrupted after {:.0f} ms: {} kept {} of {} passes ({} spp)\n", renderMs,
                       output, passesDone, passes, passesDone * totalSpp / passes);
        else
            fmt::print(stderr, "\ninterrupted after {:.0f} ms: no image written\n", renderMs);
        return 130;
    }
    progress.finish();
    if (passes > 1) {
        result.stats["passes"] = passes;
        result.stats["spp"] = totalSpp;
    }

    nlohmann::json& s = result.stats;
    s["scene"] = a.scene;
    s["output"] = output;
    s["load_ms"] = loadMs;  // reading the scene file(s) into the Scene, before render_ms
    s["render_ms"] = renderMs;
    s["peak_rss_mb"] = peakRssMb();
    describeRender(s, scene, settings);
    if (a.shadowMapsOnly) {
        const nlohmann::json& cache = s["shadows"].value("cache", nlohmann::json::object());
        try {
            if (!a.stats.empty()) fs::rename(writeTemporary(a.stats, s.dump(2) + "\n"), a.stats);
        } catch (const std::exception& e) {
            fmt::print(stderr, "error: {}\n", e.what());
            return 1;
        }
        if (!a.quiet)
            fmt::print(stderr, "{}: shadow maps: {} read, {} rendered ({:.0f} ms)\n", a.shadowMapCache,
                       cache.value("hits", 0), cache.value("misses", 0), s["shadows"].value("maps_ms", 0.0));
        if (cache.value("write_failures", 0) > 0) {
            fmt::print(stderr, "{}: error: {} shadow maps could not be written\n", a.shadowMapCache,
                       cache.value("write_failures", 0));
            return 1;
        }
        return 0;
    }
    // The statistics go to a temporary file first and are renamed only once the image is in place, so a
    // failed write leaves neither file changed.
    std::string statsTmp;
    try {
        if (!a.stats.empty()) statsTmp = writeTemporary(a.stats, s.dump(2) + "\n");
        ExrMetadata meta = exrMetadata(scene.camera, renderMs);
        meta.displayWidth = scene.camera.width, meta.displayHeight = scene.camera.height;
        if (partial) {  // what `tessera assemble` checks
            // The frame of a multi-frame RIB too: tiles of different frames must not assemble.
            meta.sceneHash =
                sceneHash(a, scene) + (ribFrameOrdinal ? fmt::format("-frame{}", *ribFrameOrdinal) : "");
            meta.tileIndex = tile ? tile->first : 0;
            meta.tileCount = tile ? tile->second : 1;
        }
        OutputEncoding enc{scene.image.exposureGain, scene.image.exposureGamma, scene.image.srgbOutput,
                           &meta};
        if (depthDisplay) {
            writeDepthMap(output, depthMapOf(result.image, meta, scene.image.displayType));
        } else {
            // The primary output: the beauty and --aov's layers; then each secondary display's file.
            auto writeLayers = [&](const std::string& path, const AovRequest& layers) {
                Image storage;
                writeImage(path, fileImage(result.image, layers, storage), enc);
            };
            writeLayers(output, *aovs);
            for (const Secondary& d : secondaries) writeLayers(d.path, d.layers);
        }
        if (!a.adaptiveMap.empty()) writeAdaptiveMap(a.adaptiveMap, result);
        if (!statsTmp.empty()) fs::rename(statsTmp, a.stats);
    } catch (const std::exception& e) {
        std::error_code ec;
        if (!statsTmp.empty()) fs::remove(statsTmp, ec);
        fmt::print(stderr, "error: {}\n", e.what());
        return 1;
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

// "N" or "A-B" (A <= B): the frame numbers; nullopt if malformed.
std::optional<std::pair<int, int>> parseFrameRange(const std::string& text) {
    int first = 0, last = 0;
    char dash = 0, extra = 0;
    const int n = std::sscanf(text.c_str(), "%d%c%d%c", &first, &dash, &last, &extra);
    if (n == 1) return std::pair{first, first};
    if (n == 3 && dash == '-' && first <= last) return std::pair{first, last};
    return std::nullopt;
}

// Multi-frame RIB (RI spec 3.2, sec. 4.1.1): every frame, or those --frames picks, rendered in file order,
// each read afresh (the options outside frames before it, then its own) and written to its own Display
// name. A frame number the file lacks is an input error once the frames before it are written.
int runRender(const RenderArgs& a) {
    std::optional<SceneFormat> format = parseSceneFormat(a.format);
    bool rib = false;
    try {
        rib = format && (*format == SceneFormat::Rib ||
                         (*format == SceneFormat::Auto && detectSceneFormat(a.scene) == SceneFormat::Rib));
    } catch (const InputError&) {
        // reported by loadOrFail
    }
    std::vector<RibFrame> frames;
    if (rib) try {
            frames = ribFrames(a.scene);
        } catch (const InputError&) {
            return renderFrame(a, std::nullopt);  // loadOrFail reports the unreadable file
        }
    if (a.frames.empty() && frames.size() <= 1) return renderFrame(a, std::nullopt);
    if (!rib) fail(fmt::format("{}: error: --frames picks frames of a multi-frame RIB file", a.scene));
    std::optional<std::pair<int, int>> range = parseFrameRange(a.frames);
    if (!a.frames.empty() && !range)
        fail(fmt::format("error: --frames '{}' is not N or A-B (frame numbers, A <= B)", a.frames));
    if (frames.empty())
        fail(fmt::format("{}: error: --frames {}: the file has no FrameBegin blocks", a.scene, a.frames));
    // The frames to render, by position in the file; a wanted number missing is remembered.
    std::vector<int> ordinals;
    std::optional<int> missing;
    if (!range) {
        for (size_t i = 0; i < frames.size(); ++i) ordinals.push_back(int(i));
    } else {
        for (int n = range->first; n <= range->second && !missing; ++n) {
            const size_t before = ordinals.size();
            for (size_t i = 0; i < frames.size(); ++i)
                if (frames[i].number == n) ordinals.push_back(int(i));
            if (ordinals.size() == before) missing = n;
        }
        std::sort(ordinals.begin(), ordinals.end());  // file order, as RI renders them
    }
    if (ordinals.size() > 1 && (!a.output.empty() || !a.stats.empty()))
        fail(fmt::format(
            "error: -o and --stats name one file: with {} frames each frame writes its own Display name "
            "(pick one with --frames N)",
            ordinals.size()));
    for (int ordinal : ordinals) {
        if (!a.quiet)
            fmt::print(stderr, "frame {} (line {})\n", frames[size_t(ordinal)].number,
                       frames[size_t(ordinal)].line);
        if (const int rc = renderFrame(a, ordinal); rc != 0) return rc;
    }
    if (missing) {
        std::string numbers;
        for (const RibFrame& f : frames) {
            if (!numbers.empty()) numbers += ' ';
            numbers += std::to_string(f.number);
        }
        fail(fmt::format("{}: error: --frames {}: the file has no frame {} (its frames: {})", a.scene,
                         a.frames, *missing, numbers));
    }
    return 0;
}

// --up frames inputs without a camera; a RIB has its own camera, so --up there is a mistake.
void checkUpApplies(const std::string& path, const std::string& formatName, const std::string& up) {
    if (up.empty()) return;
    std::optional<SceneFormat> format = parseSceneFormat(formatName);
    if (!format) return;  // reported by loadOrFail
    try {
        if (*format == SceneFormat::Auto) format = detectSceneFormat(path);
    } catch (const InputError&) {
        return;  // reported by loadOrFail
    }
    if (*format == SceneFormat::Rib)
        fail(fmt::format(
            "{}: error: --up frames inputs without a camera (.bpt, OBJ, Micropolis); this RIB has "
            "its own camera",
            path));
}

int runConvert(const std::string& in, const std::string& out, const std::string& format,
               const std::string& up) {
    if (fs::path(out).extension() != ".rib")
        fail(fmt::format("{}: error: convert writes RIB: name it .rib", out));
    checkUpApplies(in, format, up);
    checkWritableOrFail(out, "RIB");
    Scene scene = loadOrFail(in, false, format, parseUp(up));
    try {
        writeRib(scene, out);
    } catch (const std::exception& e) {
        fmt::print(stderr, "{}\n", e.what());
        return 1;
    }
    fmt::print(stderr, "{}: {} patches{} written\n", out, scene.patches.size() - scene.quadrics.size(),
               scene.quadrics.empty() ? "" : fmt::format(" and {} quadrics", scene.quadrics.size()));
    return 0;
}

int runAssemble(const std::vector<std::string>& tiles, const std::string& out) {
    if (fs::path(out).extension() != ".exr")
        fail(fmt::format("{}: error: assemble writes OpenEXR: name it .exr", out));
    for (const std::string& t : tiles)
        if (!fs::exists(t)) fail(fmt::format("{}: error: no such tile file", t));
    checkWritableOrFail(out, "assembled image");
    checkExrOrFail(out);
    assembleExrTiles(tiles, out);  // InputError: exit 2 (main)
    fmt::print(stderr, "{}: {} tiles assembled\n", out, tiles.size());
    return 0;
}

int runInfo(const std::string& path, const std::string& formatName, const std::string& up,
            const std::string& res) {
    checkUpApplies(path, formatName, up);
    RasterOverride raster;
    if (!res.empty()) {
        const std::optional<std::pair<int, int>> wh = parseResolution(res);
        if (!wh) fail(fmt::format("error: --res '{}' is not WIDTHxHEIGHT", res));
        std::tie(raster.width, raster.height) = *wh;
        if (raster.width < 1 || raster.height < 1 || raster.width > kMaxResolution ||
            raster.height > kMaxResolution)
            fail(fmt::format("{}: error: resolution {}x{} outside 1..{} per axis", path, raster.width,
                             raster.height, kMaxResolution));
    }
    // Loaded for that resolution: subdivision meshes have the patches `render --res` would render.
    Scene scene = loadOrFail(path, false, formatName, parseUp(up), std::nullopt, raster);
    if (raster.given()) scene.camera.width = raster.width, scene.camera.height = raster.height;
    Bounds3 b = scene.worldBounds();
    const Camera& c = scene.camera;
    fmt::print("scene:    {}\n", path);
    fmt::print("patches:  {}\n", scene.patches.size() - scene.quadrics.size());
    if (!scene.quadrics.empty()) {
        // Per quadric kind, in SurfaceKind order: "quadrics: 7 (sphere 1, cylinder 1, ...)".
        const auto count = surfaceKindCounts(scene);
        std::string kinds;
        for (int k = 1; k < kSurfaceKinds; ++k)
            if (count[k])
                kinds += fmt::format("{}{} {}", kinds.empty() ? "" : ", ", surfaceKindName(SurfaceKind(k)),
                                     count[k]);
        fmt::print("quadrics: {} ({})\n", scene.quadrics.size(), kinds);
    }
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
    std::optional<SceneFormat> format = parseSceneFormat(formatName);
    if (format && *format == SceneFormat::Auto) format = detectSceneFormat(path);
    if (format && *format != SceneFormat::Rib) {
        if (std::optional<UpAxis> u = parseUp(up))
            fmt::print("framing:  default camera, up {} (--up)\n", upAxisName(*u));
        else
            fmt::print("framing:  default camera, up {} ({})\n",
                       upAxisName(defaultUpAxis(*format, scene.patches)),
                       *format == SceneFormat::Obj ? "OBJ convention" : "chosen from the data");
    }
    fmt::print("clipping: {:.6g} .. {:.6g}\n", c.nearClip, c.farClip);
    const MotionSummary ms = motionSummary(scene);
    fmt::print("shutter:  {:.6g} .. {:.6g}{}\n", c.shutterOpen, c.shutterClose,
               c.hasShutter() ? "" : " (closed: no motion blur)");
    if (ms.movingPatches > 0 || ms.cameraKeys > 0)
        fmt::print(
            "motion:   {} moving patches ({} keys), camera {}\n", ms.movingPatches, ms.patchKeys,
            ms.cameraKeys > 0 ? fmt::format("moving ({} keys)", ms.cameraKeys) : std::string("static"));
    if (c.lensRadius() > 0)
        fmt::print("lens:     fstop {:.6g}, focal length {:.6g}, focal distance {:.6g}\n", c.fStop,
                   c.focalLength, c.focalDistance);
    fmt::print("samples:  {}x{} per pixel\n", scene.image.pixelSamplesX, scene.image.pixelSamplesY);
    return 0;
}

// A number check whose message prints its bounds as people write them (CLI11's own range checks print the
// limits of double in full, 309 digits).
CLI::Validator inRange(double lo, double hi, bool loExclusive = false, bool integer = false) {
    const char* kind = integer ? "an integer" : "a number";
    std::string what = loExclusive ? fmt::format("{} > {:g} and <= {:g}", kind, lo, hi)
                                   : fmt::format("{} from {:g} to {:g}", kind, lo, hi);
    return CLI::Validator(
        [=](std::string& text) -> std::string {
            char* end = nullptr;
            errno = 0;
            double v = std::strtod(text.c_str(), &end);
            if (text.empty() || *end != '\0' || errno == ERANGE || !std::isfinite(v) || v < lo || v > hi ||
                (loExclusive && v == lo) || (integer && v != std::floor(v)))
                return fmt::format("must be {}, got '{}'", what, text);
            return "";
        },
        loExclusive ? fmt::format("(>{:g}..{:g})", lo, hi) : fmt::format("({:g}..{:g})", lo, hi));
}

CLI::Validator intRange(int lo, int hi) {
    return inRange(lo, hi, false, true);
}

// Edit distance, for "did you mean" on a mistyped command.
size_t editDistance(const std::string& a, const std::string& b) {
    std::vector<size_t> row(b.size() + 1);
    for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
    for (size_t i = 1; i <= a.size(); ++i) {
        size_t diag = row[0];
        row[0] = i;
        for (size_t j = 1; j <= b.size(); ++j) {
            size_t up = row[j];
            row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
            diag = up;
        }
    }
    return row[b.size()];
}

}  // namespace

int main(int argc, char** argv) {
    const std::vector<std::string> commands = {"render", "info", "convert", "assemble"};
    // A first word that is not an option must be a command; name it when it is not one of ours.
    if (argc > 1 && argv[1][0] != '-' &&
        std::find(commands.begin(), commands.end(), std::string(argv[1])) == commands.end()) {
        std::string word = argv[1], hint;
        for (const std::string& c : commands)
            if (editDistance(word, c) <= 2) hint = fmt::format(" (did you mean '{}'?)", c);
        fmt::print(stderr,
                   "error: unknown command '{}'{}; the commands are render, info, convert and assemble (see "
                   "tessera --help)\n",
                   word, hint);
        return 2;
    }

    CLI::App app{"Tessera: a renderer for bicubic Bezier patches (Reyes and ray tracing)"};
    app.require_subcommand(1);
    app.set_version_flag("--version",
                         fmt::format("tessera {} ({} build)", TESSERA_VERSION, TESSERA_BUILD_TYPE));
    app.option_defaults()->always_capture_default();  // --help shows every option's default
    const std::string sceneHelp =
        "Scene file: RIB (.rib, .rib.gz), .bpt patches, OBJ Catmull-Clark control mesh (.obj) or Micropolis "
        "indexed-vertex text (detected by extension, else by content)";
    const std::string formatHelp = "Input format: auto, rib, bpt, obj, micropolis";
    const std::string upHelp =
        "Up axis for inputs without a camera: x, y or z (default: y for OBJ, else chosen from the data; "
        "docs/inputs.md)";
    RenderArgs ra;
    CLI::App* render = app.add_subcommand("render", "Render a scene to .png or .exr");
    render->add_option("scene", ra.scene, sceneHelp)->required();
    render->add_option(
        "-o,--output", ra.output,
        "Output image (.png or .exr); default: the RIB Display name, else SCENE's name with .png");
    render->add_option("--format", ra.format, formatHelp)
        ->check(CLI::IsMember({"auto", "rib", "bpt", "obj", "micropolis"}, CLI::ignore_case));
    render->add_option("--engine", ra.engine, "reyes or rt")->check(CLI::IsMember({"reyes", "rt"}));
    render->add_option("--res", ra.res,
                       "Resolution WIDTHxHEIGHT; default: the scene's Format (800x600 without a RIB)");
    render->add_option("--spp", ra.spp, "Samples per pixel; default (0): the scene's PixelSamples")
        ->check(intRange(1, kMaxSpp));
    render
        ->add_option("--shading-rate", ra.shadingRate,
                     "Micropolygon area in pixels; default (0): the scene's ShadingRate")
        ->check(inRange(0, 1e6, true));
    render->add_option("--threads", ra.threads, "Worker threads (0 = all cores)")->check(intRange(0, 4096));
    render->add_option("--stats", ra.stats, "Write statistics as JSON to this file");
    render->add_option("--seed", ra.seed, "Sample pattern seed");
    render
        ->add_option("--sampler", ra.sampler,
                     "Film samples: sobol (Owen-scrambled Sobol'), jittered or centred (strata centres); "
                     "default: sobol, or centred where the scene's Hider says \"jitter\" [0]")
        ->check(CLI::IsMember({"sobol", "jittered", "centred"}));
    render->add_option("--bucket-size", ra.bucketSize, "Bucket side in pixels")->check(intRange(4, 1024));
    render->add_option("--max-grid", ra.maxGridEdge, "Reyes: micropolygons per grid edge")
        ->check(intRange(1, 256));
    render
        ->add_option("--micropolygon-sampling", ra.micropolygonSampling,
                     "Reyes: test every film sample in a micropolygon's bounding box (bbox) or only the one "
                     "nearest its middle point (nearest: paper 000's sampler, which leaves holes; blurred "
                     "grids use bbox); default: the RIB Hider's \"micropolygonsampling\", else bbox")
        ->check(CLI::IsMember({"bbox", "nearest"}));
    render
        ->add_option("--displacement-split", ra.displacementSplit,
                     "Reyes: split displaced edges until their projected displacement variation (min/max "
                     "mip map of the texture, paper 001) is at most this many micropolygon sides; 0: off "
                     "(default 4)")
        ->check(inRange(0, 1e6))
        ->default_str("4");  // the sentinel -1 means "the default"
    render
        ->add_option("--displacement-normals", ra.displacementNormals,
                     "Reyes: displace along the exact normals shared by neighbouring patches (exact) or, for "
                     "benchmarks only, along each patch's own normal with shading normals from grid "
                     "differences (grid: paper 000's approximate baseline, which can crack)")
        ->check(CLI::IsMember({"exact", "grid"}))
        ->capture_default_str();
    render
        ->add_option("--subpatch-depth", ra.subpatchDepth,
                     "rt: subpatch tree depth, 0 to 12, or auto: 2, 4 or 6 from the samples the patches "
                     "cover on screen (default)")
        ->transform(CLI::Validator(
            [](std::string& text) -> std::string {
                if (text == "auto") {
                    text = std::to_string(kAutoSubpatchDepth);
                    return "";
                }
                std::string bad = intRange(0, kMaxSubpatchDepth)(text);
                return bad.empty() ? ""
                                   : "must be auto or an integer from 0 to " +
                                         std::to_string(kMaxSubpatchDepth) + ", got '" + text + "'";
            },
            "auto|(0.." + std::to_string(kMaxSubpatchDepth) + ")"))
        ->default_str("auto");
    render
        ->add_option("--displacement-cache-mb", ra.displacementCacheMb,
                     "rt: memory for displaced micro-grids, MiB (built up front when they fit, else lazily "
                     "and the least recently used dropped); default 512")
        ->check(intRange(1, 1 << 20));
    render
        ->add_option("--max-depth", ra.maxDepth,
                     "rt: ray bounces; default 4 (direct: mirror and glass lobes), 16 (path, with Russian "
                     "roulette from the third)")
        ->check(intRange(0, 64))
        ->default_str("4|16");  // the sentinel -1 means "by integrator"
    render
        ->add_option("--integrator", ra.integrator,
                     "rt: direct (lights, soft shadows of area lights, mirror, glass), path (path tracing: "
                     "diffuse and glossy interreflection, caustics) or ao (ambient occlusion, a grey image)")
        ->check(CLI::IsMember({"direct", "path", "ao"}))
        ->capture_default_str();
    render
        ->add_option("--passes", ra.passes,
                     "Progressive: render the samples per pixel in N passes of spp/N (independent estimates, "
                     "averaged); N must divide the samples per pixel")
        ->check(intRange(1, 65536));
    render->add_flag("--write-partial", ra.writePartial,
                     "With --passes: write the average after every pass, and keep it when interrupted "
                     "(Ctrl-C)");
    render
        ->add_option("--gloss", ra.gloss,
                     "rt, --integrator direct: Surface \"glossy\" reflection rays: paper (paper 002's "
                     "R + s(pu + qv), folded above the surface) or microfacet (the path tracer's GGX lobe)")
        ->check(CLI::IsMember({"paper", "microfacet"}))
        ->capture_default_str();
    render
        ->add_option("--light-samples", ra.lightSamples,
                     "rt, --integrator direct: shadow rays per shading point for every area light (default: "
                     "each light's \"samples\", 16 unless the RIB says)")
        ->check(intRange(1, 65536));
    render->add_option("--ao-samples", ra.aoSamples, "rt, --integrator ao: hemisphere rays per camera hit")
        ->check(intRange(1, 65536))
        ->capture_default_str();
    render
        ->add_option("--ao-distance", ra.aoDistance,
                     "rt, --integrator ao: occluders farther than this do not count; default: unlimited")
        ->check(inRange(0, 1e30, true));
    render
        ->add_option(
            "--ao-weighting", ra.aoWeighting,
            "rt, --integrator ao: cosine (cosine-weighted rays, 0/1 visibility) or paper "
            "(paper 002: uniform rays weighted by their cosine, shade = hit distance / --ao-distance)")
        ->check(CLI::IsMember({"cosine", "paper"}))
        ->capture_default_str();
    render->add_option("--aov", ra.aovs,
                       std::string("Further channels of an .exr output, comma-separated: ") + kAovNames +
                           " (depth and id unfiltered, the rest filtered like colour)");
    render->add_flag("--adaptive", ra.adaptive,
                     "rt: selective adaptive supersampling (paper 004): 1 ray per pixel, 4 more per subpixel "
                     "whose colour or primary-hit attributes differ from its neighbours' (docs/adaptive.md)");
    CLI::Option* adaptiveThreshold =
        render->add_option("--adaptive-threshold", ra.adaptiveThreshold,
                           "--adaptive: colour threshold tau_col (default 0.3; 0 refines everything)");
    render->add_option("--adaptive-map", ra.adaptiveMap,
                       "--adaptive: write the refined subpixels as a PNG of twice the resolution");
    render->add_option("--adaptive-thresholds", ra.adaptiveThresholds,
                       "--adaptive: paper 004's thresholds by name, e.g. poid=0.05,ssn=0.1 (col, poid, psn, "
                       "psc, pte, soid, ssn, ssc, ste; docs/adaptive.md)");
    render->add_option("--adaptive-focus", ra.adaptiveFocus,
                       "--adaptive: object ids (the id AOV) whose edges the attributes refine; elsewhere "
                       "the colour alone decides");
    render->add_flag("--adaptive-interpolate", ra.adaptiveInterpolate,
                     "--adaptive: inactive subpixels interpolate the presample bilinearly");
    render->add_option("--frames", ra.frames,
                       "Multi-frame RIB: render frame N or frames A-B (FrameBegin numbers); default: all");
    render->add_option("--up", ra.up, upHelp)->check(CLI::IsMember({"x", "y", "z"}));
    render
        ->add_option("--shadows", ra.shadows,
                     "Which lights cast shadows: on (all), off (none) or scene (each light's Attribute "
                     "\"light\" \"shadows\"; RIB default off, the default lights of other inputs on)")
        ->check(CLI::IsMember({"on", "off", "scene"}));
    render
        ->add_option("--reyes-shadows", ra.reyesShadows,
                     "Reyes: shadows from shadow maps rendered by the Reyes pipeline (map) or from the ray "
                     "tracer's shadow rays (raytrace, to compare with --engine rt)")
        ->check(CLI::IsMember({"map", "raytrace"}));
    render->add_flag("--cull-backfaces", ra.cullBackfaces,
                     "rt: cull back-facing subpatches for primary rays");
    render->add_flag("--no-ray-binning", ra.noRayBinning,
                     "rt: per-ray traversal for camera and shadow rays (no binning; same image)");
    render->add_flag("--no-leaf-slabs", ra.noLeafSlabs,
                     "rt: no leaf slab test (every leaf box a ray hits is a Newton candidate; same image to "
                     "rounding)");
    render->add_flag("--no-instancing", ra.noInstancing,
                     "rt: every ObjectInstance builds its own subpatch trees (no sharing; same image to "
                     "rounding)");
    render->add_option("--shutter", ra.shutter,
                       "Shutter interval OPEN,CLOSE in scene time (overrides the RIB Shutter; motion keys "
                       "outside it are clamped)");
    render->add_option("--dof", ra.dof,
                       "Thin lens FSTOP,FOCALLENGTH,FOCALDISTANCE (overrides the RIB DepthOfField)");
    render->add_flag("--no-blur", ra.noBlur,
                     "No motion blur or depth of field: pinhole camera, everything at shutter open");
    render
        ->add_option("--blur-sampling", ra.blurSampling,
                     "Time and lens samples: simple, interleaved or bbox (default: the RIB Hider's "
                     "\"blursampling\", else bbox)")
        ->check(CLI::IsMember({"simple", "interleaved", "bbox"}));
    render
        ->add_option("--blur-tile", ra.blurTile,
                     "Interleaved sampling: tile size K, 2..16 (default: the RIB's \"blurtilesize\", else 4)")
        ->check(intRange(2, 16));
    render
        ->add_option(
            "--blur-permutations", ra.blurPermutations,
            "Interleaved sampling: permutations P, 1..4096 (default: the RIB's \"blurpermutations\", "
            "else 64)")
        ->check(intRange(1, 4096));
    render->add_option("--crop", ra.crop,
                       "Render only the crop window XMIN,XMAX,YMIN,YMAX in NDC (0..1 from the top left; RI "
                       "CropWindow, which it overrides); an .exr keeps the full display window");
    render->add_option("--tile", ra.tile,
                       "Render tile I (0-based) of an N-tile split I/N of the image (or crop window) into "
                       "near-square tiles; join them with tessera assemble");
    render->add_option(
        "--shadow-map-cache", ra.shadowMapCache,
        "Reyes: keep the shadow maps this render makes in folder DIR and read them from there "
        "when another render of the same scene and options (e.g. another farm tile) made them");
    render->add_flag(
        "--shadow-maps-only", ra.shadowMapsOnly,
        "Reyes: render only the shadow maps into --shadow-map-cache DIR, no image (a farm's first "
        "job, so that its tiles read the maps instead of each rendering them)");
    render->add_option("--display-server", ra.displayServer,
                       "Stream the buckets as they finish to a tev viewer at HOST:PORT (the RIB's Display "
                       "\"framebuffer\" streams to 127.0.0.1:14158, tev's default)");
    render->add_flag("--progress", ra.progressLines,
                     "Print 'progress N%' on stderr, one line per whole percent (for logs and render farms)");
    render->add_flag("-q,--quiet", ra.quiet, "No progress bar, warnings or summary");
    std::string infoPath, infoFormat = "auto", infoUp, infoRes;
    CLI::App* info = app.add_subcommand("info", "Print patch count, objects, bounds and camera of a scene");
    info->add_option("scene", infoPath, sceneHelp)->required();
    info->add_option("--format", infoFormat, formatHelp)
        ->check(CLI::IsMember({"auto", "rib", "bpt", "obj", "micropolis"}, CLI::ignore_case));
    info->add_option("--up", infoUp, upHelp)->check(CLI::IsMember({"x", "y", "z"}));
    info->add_option("--res", infoRes,
                     "WIDTHxHEIGHT: the resolution to load for, as render --res (subdivision meshes are "
                     "refined for it, so the patch count is the render's)");
    std::vector<std::string> assembleTiles;
    std::string assembleOut;
    CLI::App* assemble = app.add_subcommand(
        "assemble",
        "Join the .exr tiles of one render (--tile I/N) into one image, checking they belong together");
    assemble->add_option("tiles", assembleTiles, "Tile images (.exr)")->required();
    assemble->add_option("-o,--output", assembleOut, "Output .exr")->required();
    std::string convertIn, convertOut, convertFormat = "auto", convertUp;
    CLI::App* convert = app.add_subcommand("convert", "Write any supported input as a RIB of Bezier patches");
    convert->add_option("input", convertIn, sceneHelp)->required();
    convert->add_option("-o,--output", convertOut, "Output .rib")->required();
    convert->add_option("--format", convertFormat, formatHelp)
        ->check(CLI::IsMember({"auto", "rib", "bpt", "obj", "micropolis"}, CLI::ignore_case));
    convert->add_option("--up", convertUp, upHelp)->check(CLI::IsMember({"x", "y", "z"}));
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        if (e.get_exit_code() == 0) return app.exit(e);  // --help, --version
        app.exit(e);
        return 2;
    }
    ra.adaptiveThresholdGiven = adaptiveThreshold->count() > 0;
    try {
        if (*render) {
            checkUpApplies(ra.scene, ra.format, ra.up);
            return runRender(ra);
        }
        if (*info) return runInfo(infoPath, infoFormat, infoUp, infoRes);
        if (*convert) return runConvert(convertIn, convertOut, convertFormat, convertUp);
        if (*assemble) return runAssemble(assembleTiles, assembleOut);
    } catch (const InputError& e) {
        fail(e.what());
    } catch (const std::exception& e) {  // not the input's fault: out of memory, a failing disk, ...
        fmt::print(stderr, "error: {}\n", e.what());
        return 1;
    }
    return 2;
}
