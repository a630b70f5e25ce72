// The `tessera` Python module (pybind11): load a scene from a file or RIB text, render it with either
// engine under the same option words as the CLI (render/render_options.h), and get the image and AOVs as
// numpy arrays and the statistics as a dict. An app beside the CLI: it uses the io and render layers and
// adds no rendering of its own. Example in the README ("Python").
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "film/crop.h"
#include "io/diagnostics.h"
#include "io/image_io.h"
#include "io/rib_reader.h"
#include "io/scene_loader.h"
#include "render/aovs.h"
#include "render/render.h"
#include "render/render_options.h"

namespace py = pybind11;
using namespace tessera;

namespace {

// A loaded scene and what loading it said. Renders copy it, so one Scene renders under many options.
struct PyScene {
    std::shared_ptr<const Scene> scene;
    std::string path;
    std::vector<std::string> warnings;
};

// One render: the image (the film region: the whole image, a crop window or a tile), its planes and the
// statistics, with what writing it as a file needs (the camera, the output encoding).
struct PyResult {
    Image image;
    nlohmann::json stats;
    std::vector<std::string> warnings;
    std::vector<uint8_t> refined;  // adaptive: (2 height) x (2 width) subpixels, 1 = refined
    AovRequest aovs;
    Camera camera;
    OutputEncoding encoding;
    double renderMs = 0;
};

py::object jsonToPython(const nlohmann::json& j) {
    return py::module_::import("json").attr("loads")(j.dump());
}

// A numpy array that owns a copy of `values` (rows x cols x components; components 1: 2-D).
template <typename T, typename Allocator>
py::array_t<T> toArray(const std::vector<T, Allocator>& values, int rows, int cols, int components) {
    std::vector<py::ssize_t> shape{rows, cols};
    if (components > 1) shape.push_back(components);
    py::array_t<T> a(shape);
    std::copy(values.begin(), values.end(), a.mutable_data());
    return a;
}

template <typename T>
T cast(const char* name, py::handle value) {
    try {
        return value.cast<T>();
    } catch (const py::cast_error&) {
        throw py::type_error(std::string("option ") + name + ": wrong type (" +
                             std::string(py::str(py::type::of(value).attr("__name__"))) + ")");
    }
}

// res=(w, h) or 'WxH' (None: not given).
RasterOverride resolutionArg(py::handle v) {
    RasterOverride r;
    if (v.is_none()) return r;
    if (py::isinstance<py::str>(v)) {
        const std::string s = v.cast<std::string>();
        const std::optional<std::pair<int, int>> wh = parseResolution(s);
        if (!wh) throw std::invalid_argument("res '" + s + "' is not WIDTHxHEIGHT");
        std::tie(r.width, r.height) = *wh;
    } else {
        const auto wh = cast<std::vector<int>>("res", v);
        if (wh.size() != 2) throw std::invalid_argument("res needs (width, height)");
        r.width = wh[0], r.height = wh[1];
    }
    if (r.width < 1 || r.height < 1) throw std::invalid_argument("res: width and height must be >= 1");
    return r;
}

// raster: the resolution to load for (res=): subdivision meshes are refined for their size in that image
// and the scene renders at it (docs/subdivision.md).
PyScene loadScenePy(const std::filesystem::path& file, const std::string& format, const std::string& up,
                    std::optional<int> frame = std::nullopt, RasterOverride raster = {}) {
    const std::string path = file.string();
    const std::optional<SceneFormat> f = parseSceneFormat(format);
    if (!f) throw std::invalid_argument("unknown format '" + format + "' (auto, rib, bpt, obj, micropolis)");
    std::optional<UpAxis> axis;
    if (!up.empty()) {
        if (up == "x")
            axis = UpAxis::X;
        else if (up == "y")
            axis = UpAxis::Y;
        else if (up == "z")
            axis = UpAxis::Z;
        else
            throw std::invalid_argument("up must be x, y or z, got '" + up + "'");
    }
    PyScene s;
    s.path = path;
    auto scene = std::make_shared<Scene>();
    {
        py::gil_scoped_release release;
        const WarningSink warn = [&s](const std::string& w) { s.warnings.push_back(w); };
        if (frame) {  // RI FrameBegin n: the frame's ordinal in the file (multi-frame RIB, docs/inputs.md)
            const std::vector<RibFrame> frames = ribFrames(path);
            const auto it = std::find_if(frames.begin(), frames.end(),
                                         [&](const RibFrame& fr) { return fr.number == *frame; });
            if (it == frames.end())
                throw std::invalid_argument(path + ": no FrameBegin " + std::to_string(*frame) +
                                            " in the file");
            readRibFrame(path, int(it - frames.begin()), *scene, warn, raster);
        } else {
            *scene = loadScene(path, warn, *f, axis, raster);
        }
    }
    if (raster.given()) scene->camera.width = raster.width, scene->camera.height = raster.height;
    s.scene = std::move(scene);
    return s;
}

PyScene ribTextScene(const std::string& text, const std::string& path, RasterOverride raster = {}) {
    PyScene s;
    s.path = path;
    auto scene = std::make_shared<Scene>();
    {
        py::gil_scoped_release release;
        readRibText(
            text, path, *scene, [&s](const std::string& w) { s.warnings.push_back(w); }, raster);
    }
    if (raster.given()) scene->camera.width = raster.width, scene->camera.height = raster.height;
    s.scene = std::move(scene);
    return s;
}

// `n` numbers from a sequence (a tuple, a list) or a comma-separated string.
std::vector<double> numbers(const char* name, py::handle value, size_t n) {
    const std::vector<double> v =
        py::isinstance<py::str>(value)
            ? parseNumberList(value.cast<std::string>(), n).value_or(std::vector<double>{})
            : cast<std::vector<double>>(name, value);
    if (v.size() != n)
        throw std::invalid_argument(std::string(name) + " needs " + std::to_string(n) + " numbers");
    for (double x : v)
        if (!std::isfinite(x)) throw std::invalid_argument(std::string(name) + ": numbers must be finite");
    return v;
}

struct Request {
    RenderOptions options;
    std::string aovs;
    std::optional<std::vector<double>> crop;
    py::object progress;  // a callable taking the fraction done, or None
};

// The keyword options of render(): the CLI's long option names with '_' for '-'.
Request parseOptions(const py::kwargs& kw) {
    Request r;
    RenderOptions& o = r.options;
    for (auto item : kw) {
        const std::string key = item.first.cast<std::string>();
        const py::handle v = item.second;
        const char* k = key.c_str();
        if (v.is_none()) continue;  // None: the scene's value
        if (key == "engine")
            o.engine = cast<std::string>(k, v);
        else if (key == "spp")
            o.spp = cast<int>(k, v);
        else if (key == "res") {
            const RasterOverride r = resolutionArg(v);
            o.width = r.width, o.height = r.height;
        } else if (key == "shading_rate")
            o.shadingRate = cast<double>(k, v);
        else if (key == "threads")
            o.threads = cast<int>(k, v);
        else if (key == "seed")
            o.seed = cast<unsigned>(k, v);
        else if (key == "sampler")
            o.sampler = cast<std::string>(k, v);
        else if (key == "shadows")
            o.shadows = cast<std::string>(k, v);
        else if (key == "reyes_shadows")
            o.reyesShadows = cast<std::string>(k, v);
        else if (key == "bucket_size")
            o.bucketSize = cast<int>(k, v);
        else if (key == "subpatch_depth")  // "auto" (the default) or 0 .. 12
            o.subpatchDepth = py::isinstance<py::str>(v) && cast<std::string>(k, v) == "auto"
                                  ? kAutoSubpatchDepth
                                  : cast<int>(k, v);
        else if (key == "displacement_cache_mb")
            o.displacementCacheMb = cast<int>(k, v);
        else if (key == "max_grid")
            o.maxGridEdge = cast<int>(k, v);
        else if (key == "max_depth")
            o.maxDepth = cast<int>(k, v);
        else if (key == "light_samples")
            o.lightSamples = cast<int>(k, v);
        else if (key == "cull_backfaces")
            o.cullBackfaces = cast<bool>(k, v);
        else if (key == "ray_binning")
            o.noRayBinning = !cast<bool>(k, v);
        else if (key == "instancing")
            o.noInstancing = !cast<bool>(k, v);
        else if (key == "leaf_slabs")
            o.noLeafSlabs = !cast<bool>(k, v);
        else if (key == "micropolygon_sampling")
            o.micropolygonSampling = cast<std::string>(k, v);
        else if (key == "displacement_split")
            o.displacementSplit = cast<double>(k, v);
        else if (key == "displacement_normals")
            o.displacementNormals = cast<std::string>(k, v);
        else if (key == "blur")
            o.noBlur = !cast<bool>(k, v);
        else if (key == "blur_sampling")
            o.blurSampling = cast<std::string>(k, v);
        else if (key == "blur_tile")
            o.blurTile = cast<int>(k, v);
        else if (key == "blur_permutations")
            o.blurPermutations = cast<int>(k, v);
        else if (key == "integrator")
            o.integrator = cast<std::string>(k, v);
        else if (key == "ao_weighting")
            o.aoWeighting = cast<std::string>(k, v);
        else if (key == "gloss")
            o.gloss = cast<std::string>(k, v);
        else if (key == "ao_samples")
            o.aoSamples = cast<int>(k, v);
        else if (key == "ao_distance")
            o.aoDistance = cast<double>(k, v);
        else if (key == "adaptive")
            o.adaptive = cast<bool>(k, v);
        else if (key == "adaptive_threshold") {
            o.adaptiveThreshold = cast<double>(k, v);
            o.adaptiveThresholdGiven = true;
        } else if (key == "adaptive_thresholds")
            o.adaptiveThresholds = cast<std::string>(k, v);
        else if (key == "adaptive_focus") {  // "3,7" or [3, 7]
            if (py::isinstance<py::str>(v)) {
                o.adaptiveFocus = cast<std::string>(k, v);
            } else {
                o.adaptiveFocus.clear();
                for (const py::handle item : cast<py::sequence>(k, v))
                    o.adaptiveFocus +=
                        (o.adaptiveFocus.empty() ? "" : ",") + std::to_string(cast<long long>(k, item));
            }
        } else if (key == "adaptive_interpolate")
            o.adaptiveInterpolate = cast<bool>(k, v);
        else if (key == "shutter")
            o.shutter = numbers(k, v, 2);
        else if (key == "dof")
            o.dof = numbers(k, v, 3);
        else if (key == "crop")
            r.crop = numbers(k, v, 4);
        else if (key == "progress") {
            if (!PyCallable_Check(v.ptr())) throw py::type_error("option progress: must be callable");
            r.progress = py::reinterpret_borrow<py::object>(v);
        } else if (key == "aovs") {
            if (py::isinstance<py::str>(v))
                r.aovs = v.cast<std::string>();
            else
                for (const std::string& name : cast<std::vector<std::string>>(k, v))
                    r.aovs += (r.aovs.empty() ? "" : ",") + name;
        } else {
            throw py::type_error("render() got an unknown option '" + key +
                                 "' (see help(tessera.render) for the options)");
        }
    }
    return r;
}

PyResult renderPy(const PyScene& loaded, const py::kwargs& kw) {
    const Request req = parseOptions(kw);
    std::string bad;
    const std::optional<AovRequest> aovs = parseAovs(req.aovs, bad);
    if (!aovs) throw std::invalid_argument("unknown AOV '" + bad + "' (known: " + kAovNames + ")");
    for (const std::string& p : aovs->planes)
        if (p == "occlusion" && req.options.integrator != "ao")
            throw std::invalid_argument("AOV occlusion is made by integrator='ao' (with engine='rt')");

    Scene scene = *loaded.scene;  // the overrides edit a copy
    applySceneOverrides(scene, req.options);
    if (scene.patches.empty()) throw std::invalid_argument(loaded.path + ": the scene has no geometry");

    RenderSettings settings;
    const double* cw = req.crop ? req.crop->data() : scene.image.cropWindow;
    if (req.crop) {
        const auto& c = *req.crop;
        if (!validCropWindow(c.data()))
            throw std::invalid_argument("crop needs 0 <= xmin < xmax <= 1 and 0 <= ymin < ymax <= 1 (NDC)");
    }
    settings.view.region =
        cropWindowPixels(scene.camera.width, scene.camera.height, cw[0], cw[1], cw[2], cw[3]);
    if (settings.view.region.width() <= 0 || settings.view.region.height() <= 0)
        throw std::invalid_argument("the crop window holds no pixel of the image");
    const bool partial = settings.view.region.width() != scene.camera.width ||
                         settings.view.region.height() != scene.camera.height;
    if (req.options.adaptive && partial)
        throw std::invalid_argument("adaptive renders whole images only (no crop or CropWindow)");
    applyRenderOptions(scene, req.options, settings);
    settings.output.channels = aovs->channels;
    settings.output.aovs = aovs->planes;
    // Ctrl-C: the render stops at the next bucket and the interpreter raises KeyboardInterrupt.
    std::atomic<bool> cancel{false};
    settings.cancel = &cancel;
    // Progress: the workers store it; the interpreter's thread hands it to the callable (below).
    std::atomic<uint64_t> workDone{0}, workTotal{0};
    if (req.progress)
        settings.progress = [&workDone, &workTotal](uint64_t d, uint64_t t) {
            workTotal.store(t);
            workDone.store(d);
        };

    PyResult out;
    const auto t0 = std::chrono::steady_clock::now();
    RenderResult r;
    {
        // The render runs on a thread of its own while this one, the interpreter's, looks for Ctrl-C
        // (Python's handler only flags the signal; PyErr_CheckSignals runs it) and calls `progress`.
        py::gil_scoped_release release;
        std::exception_ptr failure;
        std::atomic<bool> done{false};
        std::thread worker([&] {
            try {
                r = render(scene, settings);
            } catch (...) {
                failure = std::current_exception();
            }
            done.store(true);
        });
        bool interrupted = false;
        std::optional<py::error_already_set> callbackError;
        double reported = -1;
        const auto report = [&](double fraction) {
            if (!req.progress || callbackError || fraction <= reported) return;
            reported = fraction;
            try {
                req.progress(fraction);
            } catch (py::error_already_set& e) {  // stop the render, raise it afterwards
                callbackError.emplace(std::move(e));
                cancel.store(true);
            }
        };
        while (!done.load()) {
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
            py::gil_scoped_acquire acquire;
            if (!interrupted && PyErr_CheckSignals() != 0) {
                interrupted = true;
                cancel.store(true);
                PyErr_Clear();
            }
            const uint64_t total = workTotal.load();
            if (total > 0) report(std::min(1.0, double(workDone.load()) / double(total)));
        }
        worker.join();
        if (failure) std::rethrow_exception(failure);
        if (callbackError) {
            py::gil_scoped_acquire acquire;
            throw std::move(*callbackError);
        }
        if (!interrupted && !r.cancelled) {
            py::gil_scoped_acquire acquire;
            report(1.0);
            if (callbackError) throw std::move(*callbackError);
        }
        if (interrupted || r.cancelled) {
            py::gil_scoped_acquire acquire;
            PyErr_SetNone(PyExc_KeyboardInterrupt);
            throw py::error_already_set();
        }
    }
    out.renderMs = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    out.image = std::move(r.image);
    out.stats = std::move(r.stats);
    describeRender(out.stats, scene, settings);
    out.stats["scene"] = loaded.path;
    out.stats["render_ms"] = out.renderMs;
    out.warnings = loaded.warnings;
    out.warnings.insert(out.warnings.end(), r.warnings.begin(), r.warnings.end());
    out.aovs = *aovs;
    out.refined = std::move(r.refinedSubpixels);
    out.camera = scene.camera;
    out.encoding = {scene.image.exposureGain, scene.image.exposureGamma, scene.image.srgbOutput, nullptr};
    return out;
}

// The AOVs as arrays by the names asked for: "z", "id" (uint32, 0xffffffff where empty), 3-component
// planes as H x W x 3, "Ci" (premultiplied colour) and "a" (alpha) from the image itself.
py::dict aovArrays(const PyResult& r) {
    py::dict d;
    const Image& img = r.image;
    const auto split = [&](int first, int count) {
        std::vector<float> v(size_t(img.width) * img.height * count);
        for (size_t p = 0; p < size_t(img.width) * img.height; ++p)
            for (int c = 0; c < count; ++c) v[p * count + c] = img.rgba[p * 4 + first + c];
        return toArray(v, img.height, img.width, count);
    };
    for (const std::string& name : r.aovs.names) {
        if (name == "Ci")
            d["Ci"] = split(0, 3);
        else if (name == "a")
            d["a"] = split(3, 1);
        else if (const ImagePlane* p = img.plane(name)) {
            if (p->integer)
                d[name.c_str()] = toArray(p->ids, img.height, img.width, 1);
            else
                d[name.c_str()] = toArray(p->values, img.height, img.width, p->components);
        }
    }
    return d;
}

void writeResult(const PyResult& r, const std::filesystem::path& file) {
    const std::string path = file.string();
    if (!isSupportedImageExtension(path))
        throw std::invalid_argument(path + ": unsupported output format (use .png or .exr)");
    if (!r.aovs.names.empty() && std::filesystem::path(path).extension() != ".exr")
        throw std::invalid_argument(
            path + ": this render has AOVs: they need an OpenEXR file (.exr); a .png holds RGBA only");
    ExrMetadata meta = cameraExrMetadata(r.camera);
    meta.software = std::string("tessera ") + TESSERA_VERSION + " (python)";
    meta.renderMs = r.renderMs;
    meta.displayWidth = r.camera.width, meta.displayHeight = r.camera.height;
    OutputEncoding enc = r.encoding;
    enc.exr = &meta;
    py::gil_scoped_release release;
    Image storage;
    writeImage(path, fileImage(r.image, r.aovs, storage), enc);
}

const char* kRenderDoc = R"(Render a scene and return a Result.

scene: a path (RIB, .bpt, OBJ, Micropolis) or a tessera.Scene; or rib="..." for RIB text.
Options (None or absent: the scene's own value), the CLI's long names with '_' for '-':
  engine='reyes'|'rt', res=(w, h) or 'WxH', spp, shading_rate, threads (0: all cores), seed,
  sampler='sobol'|'jittered'|'centred', shadows='on'|'off'|'scene', reyes_shadows='map'|'raytrace',
  bucket_size, subpatch_depth (0 .. 12 or 'auto'), displacement_cache_mb, max_grid,
  micropolygon_sampling='bbox'|'nearest', displacement_split, displacement_normals='exact'|'grid',
  max_depth, light_samples, cull_backfaces, ray_binning, instancing, leaf_slabs,
  blur (False: --no-blur), blur_sampling='simple'|'interleaved'|'bbox', blur_tile, blur_permutations,
  shutter=(open, close), dof=(fstop, focallength, focaldistance),
  integrator='direct'|'path'|'ao', ao_samples, ao_distance, ao_weighting='cosine'|'paper',
  gloss='paper'|'microfacet', adaptive, adaptive_threshold, adaptive_thresholds='poid=0.05,...',
  adaptive_focus=[ids], adaptive_interpolate,
  aovs=['z', 'N', 'id', 'shadows', 'textured', 'occlusion', 'albedo', 'P', 'Cs', 'Ci', 'a'],
  crop=(xmin, xmax, ymin, ymax) in NDC, progress=callable(fraction done, 0..1; raising in it stops the render).
Raises tessera.InputError for a malformed scene file, ValueError for a bad option value, TypeError for an
unknown option.)";

}  // namespace

PYBIND11_MODULE(tessera, m) {
    m.doc() = "Tessera: a Reyes and ray-tracing renderer for parametric surfaces";
    m.attr("__version__") = TESSERA_VERSION;
    static py::exception<InputError> inputError(m, "InputError", PyExc_ValueError);
    py::register_exception_translator([](std::exception_ptr p) {
        try {
            if (p) std::rethrow_exception(p);
        } catch (const InputError& e) {
            inputError(e.what());
        }
    });

    py::class_<PyScene>(m, "Scene", "A loaded scene; render() it as often as you like, under any options")
        .def_property_readonly("path", [](const PyScene& s) { return s.path; })
        .def_property_readonly("width", [](const PyScene& s) { return s.scene->camera.width; })
        .def_property_readonly("height", [](const PyScene& s) { return s.scene->camera.height; })
        .def_property_readonly(
            "surfaces", [](const PyScene& s) { return s.scene->patches.size(); },
            "the number of surfaces (patches and quadrics) after conversion")
        .def_property_readonly("lights", [](const PyScene& s) { return s.scene->lights.size(); })
        .def_property_readonly(
            "warnings", [](const PyScene& s) { return s.warnings; }, "what loading the scene warned about")
        .def("render", &renderPy, kRenderDoc)
        .def("__repr__", [](const PyScene& s) {
            return "<tessera.Scene '" + s.path + "' " + std::to_string(s.scene->camera.width) + "x" +
                   std::to_string(s.scene->camera.height) + ", " + std::to_string(s.scene->patches.size()) +
                   " surfaces>";
        });

    py::class_<PyResult>(m, "Result", "One render: image, AOVs, statistics")
        .def_property_readonly(
            "image",
            [](const PyResult& r) { return toArray(r.image.rgba, r.image.height, r.image.width, 4); },
            "H x W x 4 float32: linear, premultiplied RGBA, top row first (before Exposure)")
        .def_property_readonly("aovs", &aovArrays, "the AOVs asked for, by name, as numpy arrays")
        .def_property_readonly(
            "stats", [](const PyResult& r) { return jsonToPython(r.stats); },
            "the statistics, as `tessera render --stats` writes them")
        .def_property_readonly("warnings", [](const PyResult& r) { return r.warnings; })
        .def_property_readonly(
            "refined",
            [](const PyResult& r) -> py::object {
                if (r.refined.empty()) return py::none();
                return toArray(r.refined, 2 * r.image.height, 2 * r.image.width, 1);
            },
            "adaptive=True: which subpixels (2 H x 2 W, uint8, 1 = refined) got extra samples; else None")
        .def_property_readonly(
            "origin", [](const PyResult& r) { return py::make_tuple(r.image.x0, r.image.y0); },
            "the raster position of the first pixel (a crop window's corner)")
        .def_property_readonly("width", [](const PyResult& r) { return r.image.width; })
        .def_property_readonly("height", [](const PyResult& r) { return r.image.height; })
        .def("write", &writeResult, py::arg("path"),
             "Write the image (and the AOVs, to an .exr) as the CLI would: temporary file, then rename");

    m.def(
        "read_image",
        [](const std::filesystem::path& file) {
            const std::string path = file.string();
            Image img;
            {
                py::gil_scoped_release release;
                const std::string ext = std::filesystem::path(path).extension().string();
                if (ext == ".exr")
                    img = readExr(path);
                else if (ext == ".png")
                    img = readPng(path);
                else
                    throw std::invalid_argument(path + ": read_image reads .exr and .png");
            }
            return toArray(img.rgba, img.height, img.width, 4);
        },
        py::arg("path"),
        "The RGBA of an image file as H x W x 4 float32: an EXR's stored (linear, premultiplied) values, a "
        "PNG's "
        "in [0, 1]");
    m.def(
        "load",
        [](const std::filesystem::path& file, const std::string& format, const std::string& up,
           std::optional<int> frame,
           py::object res) { return loadScenePy(file, format, up, frame, resolutionArg(res)); },
        py::arg("path"), py::arg("format") = "auto", py::arg("up") = "", py::arg("frame") = py::none(),
        py::arg("res") = py::none(),
        "Load a scene file (RIB, .bpt, OBJ, Micropolis; format='auto' detects it); frame=n: the RIB frame "
        "of FrameBegin n (default: the first); res=(w, h) or 'WxH': the resolution to render at, which "
        "subdivision meshes are refined for (a later render(res=) does not refine them again)");
    m.def(
        "frames",
        [](const std::filesystem::path& file) {
            std::vector<int> numbers;
            for (const RibFrame& f : ribFrames(file.string())) numbers.push_back(f.number);
            return numbers;
        },
        py::arg("path"), "The frame numbers of a RIB file's FrameBegin blocks, in file order");
    m.def(
        "load_rib",
        [](const std::string& text, const std::string& path, py::object res) {
            return ribTextScene(text, path, resolutionArg(res));
        },
        py::arg("text"), py::arg("path") = "<rib>", py::arg("res") = py::none(),
        "Load a scene from RIB text; `path` names it in messages and is the base of relative file names; "
        "res=: as load()");
    m.def(
        "render",
        [](py::object scene, std::optional<std::string> rib, const py::kwargs& kw) {
            // A path or RIB text is loaded for res= (subdivision meshes refined for that size).
            const RasterOverride raster = kw.contains("res") ? resolutionArg(kw["res"]) : RasterOverride{};
            if (rib) {
                if (!scene.is_none()) throw py::type_error("render(): give a scene or rib=, not both");
                return renderPy(ribTextScene(*rib, "<rib>", raster), kw);
            }
            if (py::isinstance<PyScene>(scene)) return renderPy(scene.cast<const PyScene&>(), kw);
            if (py::isinstance<py::str>(scene) || py::hasattr(scene, "__fspath__"))
                return renderPy(
                    loadScenePy(scene.cast<std::filesystem::path>(), "auto", "", std::nullopt, raster), kw);
            throw py::type_error("render(): scene must be a path, a tessera.Scene, or give rib=\"...\"");
        },
        py::arg("scene") = py::none(), py::arg("rib") = py::none(), kRenderDoc);
}
