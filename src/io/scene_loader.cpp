#include "io/scene_loader.h"

#include <algorithm>
#include <cctype>
#include <cmath>

#include "io/bpt_reader.h"
#include "io/micropolis_reader.h"
#include "io/obj_reader.h"
#include "io/rib_lexer.h"
#include "io/rib_reader.h"
#include "shading/registry.h"

namespace tessera {

namespace {

std::string lowercase(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
    return s;
}

bool endsWith(const std::string& s, std::string_view suffix) {
    return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// First statement of an OBJ file: a lowercase OBJ keyword followed by a blank.
bool looksLikeObj(const std::string& text) {
    size_t pos = 0;
    while (pos < text.size()) {
        size_t eol = text.find('\n', pos);
        if (eol == std::string::npos) eol = text.size();
        std::string_view line(text.data() + pos, eol - pos);
        pos = eol + 1;
        size_t i = line.find_first_not_of(" \t\r");
        if (i == std::string_view::npos || line[i] == '#') continue;
        line = line.substr(i);
        for (std::string_view k : {"v", "vt", "vn", "f", "o", "g", "s", "usemtl", "mtllib"})
            if (line.size() > k.size() && line.substr(0, k.size()) == k &&
                (line[k.size()] == ' ' || line[k.size()] == '\t'))
                return true;
        return false;
    }
    return false;
}

// Patches without a scene around them: one object, one plastic material, a synthesised camera.
Scene patchScene(const std::string& path, std::vector<BezierPatch> patches, SceneFormat format,
                 std::optional<UpAxis> up) {
    Scene scene;
    scene.sourcePath = path;
    scene.patches = std::move(patches);
    scene.materials.push_back(defaultMaterial(MaterialType::Plastic));
    scene.attributes.assign(scene.patches.size(), PatchAttributes{});
    scene.objectCount = 1;
    frameSceneDefault(scene, 800, 600, up ? *up : defaultUpAxis(format, scene.patches));
    return scene;
}

}  // namespace

std::optional<SceneFormat> parseSceneFormat(std::string_view name) {
    std::string n = lowercase(std::string(name));
    if (n == "auto") return SceneFormat::Auto;
    if (n == "rib") return SceneFormat::Rib;
    if (n == "bpt") return SceneFormat::Bpt;
    if (n == "obj") return SceneFormat::Obj;
    if (n == "micropolis") return SceneFormat::Micropolis;
    return std::nullopt;
}

const char* sceneFormatName(SceneFormat format) {
    switch (format) {
        case SceneFormat::Auto:
            return "auto";
        case SceneFormat::Rib:
            return "rib";
        case SceneFormat::Bpt:
            return "bpt";
        case SceneFormat::Obj:
            return "obj";
        case SceneFormat::Micropolis:
            return "micropolis";
    }
    return "auto";
}

SceneFormat detectSceneFormat(const std::string& path) {
    std::string lower = lowercase(path);
    if (endsWith(lower, ".bpt")) return SceneFormat::Bpt;
    if (endsWith(lower, ".obj")) return SceneFormat::Obj;
    if (endsWith(lower, ".rib") || endsWith(lower, ".rib.gz") || endsWith(lower, ".gz"))
        return SceneFormat::Rib;
    if (endsWith(lower, ".mscene"))
        throw InputError(path, 0,
                         "binary Micropolis .mscene scenes (Cap'n Proto) are not supported; use the text "
                         "indexed-vertex files or the RIB/NURBS form of the model");
    // Unknown or no extension: look at the content.
    std::string text;
    try {
        text = readInputFile(path);
    } catch (const InputError&) {
        return SceneFormat::Rib;  // the RIB reader reports the unreadable file
    }
    if (looksLikeMicropolis(text)) return SceneFormat::Micropolis;
    if (looksLikeObj(text)) return SceneFormat::Obj;
    return SceneFormat::Rib;
}

Scene loadRib(const std::string& path, const WarningSink& warn, RasterOverride raster) {
    Scene scene;
    readRib(path, scene, warn, raster);
    return scene;
}

UpAxis defaultUpAxis(SceneFormat format, const std::vector<BezierPatch>& patches) {
    if (format == SceneFormat::Obj) return UpAxis::Y;  // polygon modellers and OBJ exporters are y-up
    return chooseUpAxis(patches);
}

Scene loadBpt(const std::string& path, const WarningSink& /*warn*/, std::optional<UpAxis> up) {
    // A .bpt file is one object with one material; the camera and lights are synthesised.
    return patchScene(path, parseBpt(readInputFile(path), path), SceneFormat::Bpt, up);
}

Scene loadObj(const std::string& path, const WarningSink& warn, std::optional<UpAxis> up) {
    return patchScene(path, objToPatches(readInputFile(path), path, warn), SceneFormat::Obj, up);
}

Scene loadMicropolis(const std::string& path, const WarningSink& /*warn*/, std::optional<UpAxis> up) {
    return patchScene(path, parseMicropolis(readInputFile(path), path), SceneFormat::Micropolis, up);
}

Scene loadScene(const std::string& path, const WarningSink& warn, SceneFormat format,
                std::optional<UpAxis> up, RasterOverride raster) {
    if (format == SceneFormat::Auto) format = detectSceneFormat(path);
    switch (format) {
        case SceneFormat::Bpt:
            return loadBpt(path, warn, up);
        case SceneFormat::Obj:
            return loadObj(path, warn, up);
        case SceneFormat::Micropolis:
            return loadMicropolis(path, warn, up);
        default:
            // The RIB reader itself inflates gzip input by its magic bytes.
            return loadRib(path, warn, raster);
    }
}

}  // namespace tessera
