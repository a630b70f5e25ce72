// Entry points of the scene readers: RIB (plain or gzipped), .bpt patch files, Wavefront OBJ control meshes
// (Catmull-Clark) and the Micropolis indexed-vertex text format.
#pragma once
#include <optional>
#include <string>
#include <string_view>

#include "io/diagnostics.h"
#include "scene/scene.h"

namespace tessera {

enum class SceneFormat { Auto, Rib, Bpt, Obj, Micropolis };

// "auto", "rib", "bpt", "obj", "micropolis" (for a --format option); nullopt if unknown.
std::optional<SceneFormat> parseSceneFormat(std::string_view name);
const char* sceneFormatName(SceneFormat format);

// The format `loadScene` would use for `path` with SceneFormat::Auto: by extension (.rib/.rib.gz, .bpt,
// .obj), else by content (Micropolis indexed-vertex text, OBJ statements), else RIB.
SceneFormat detectSceneFormat(const std::string& path);

// Load a scene. Throws InputError (diagnostics.h) with "file:line: error: what" for malformed input;
// warnings go to `warn`. Inputs without a camera (.bpt, OBJ, Micropolis) are framed automatically and get
// default lights and a plastic material. `format` overrides the detection.
Scene loadScene(const std::string& path, const WarningSink& warn, SceneFormat format = SceneFormat::Auto);
Scene loadRib(const std::string& path, const WarningSink& warn);
Scene loadBpt(
    const std::string& path,
    const WarningSink& warn);  // then frameSceneDefault(scene, 800, 600) and a default plastic material
Scene loadObj(const std::string& path, const WarningSink& warn);
Scene loadMicropolis(const std::string& path, const WarningSink& warn);

}  // namespace tessera
