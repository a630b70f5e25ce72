// Entry points of the scene readers: RIB (plain or gzipped) and .bpt patch files.
#pragma once
#include <string>

#include "io/diagnostics.h"
#include "scene/scene.h"

namespace tessera {

// Load a .rib (optionally gzipped: detect by magic bytes, use zlib gzopen/gzread) or .bpt file into a Scene.
// Throws InputError (diagnostics.h) with "file:line: error: what" for malformed input; warnings go to `warn`.
Scene loadScene(const std::string& path, const WarningSink& warn);
Scene loadRib(const std::string& path, const WarningSink& warn);
Scene loadBpt(
    const std::string& path,
    const WarningSink& warn);  // then frameSceneDefault(scene, 800, 600) and a default plastic material

}  // namespace tessera
