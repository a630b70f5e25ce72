#include "io/scene_loader.h"

#include <algorithm>
#include <cctype>

#include "io/bpt_reader.h"
#include "io/rib_lexer.h"
#include "io/rib_reader.h"

namespace tessera {

Scene loadRib(const std::string& path, const WarningSink& warn) {
    Scene scene;
    readRib(path, scene, warn);
    return scene;
}

Scene loadBpt(const std::string& path, const WarningSink& /*warn*/) {
    Scene scene;
    scene.sourcePath = path;
    scene.patches = parseBpt(readInputFile(path), path);
    // A .bpt file is one object with one material; the camera and lights are synthesised.
    scene.materials.push_back(defaultMaterial(MaterialType::Plastic));
    scene.attributes.assign(scene.patches.size(), PatchAttributes{});
    scene.objectCount = 1;
    frameSceneDefault(scene, 800, 600);
    return scene;
}

Scene loadScene(const std::string& path, const WarningSink& warn) {
    std::string lower = path;
    std::transform(lower.begin(), lower.end(), lower.begin(),
                   [](unsigned char c) { return std::tolower(c); });
    auto endsWith = [&](const char* s) {
        std::string_view suffix(s);
        return lower.size() >= suffix.size() &&
               lower.compare(lower.size() - suffix.size(), suffix.size(), suffix) == 0;
    };
    if (endsWith(".bpt")) return loadBpt(path, warn);
    // Everything else is read as RIB; the RIB reader itself inflates gzip input by its magic bytes.
    return loadRib(path, warn);
}

}  // namespace tessera
