// Entry points of the scene readers: RIB (plain or gzipped), .bpt patch files, Wavefront OBJ control meshes
// (Catmull-Clark) and the Micropolis indexed-vertex text format.
#pragma once
#include <optional>
#include <string>
#include <string_view>

#include "io/diagnostics.h"
#include "io/rib_reader.h"
#include "scene/scene.h"

namespace tessera {

enum class SceneFormat { Auto, Rib, Bpt, Obj, Micropolis };

// "auto", "rib", "bpt", "obj", "micropolis" (for a --format option); nullopt if unknown.
std::optional<SceneFormat> parseSceneFormat(std::string_view name);
const char* sceneFormatName(SceneFormat format);

// The format `loadScene` would use for `path` with SceneFormat::Auto: by extension (.rib/.rib.gz, .bpt,
// .obj), else by content (Micropolis indexed-vertex text, OBJ statements), else RIB.
SceneFormat detectSceneFormat(const std::string& path);

// The up axis a camera-less input of `format` gets when --up does not say: OBJ is y-up by convention;
// .bpt and Micropolis files do not fix one, so chooseUpAxis() decides from the control points.
UpAxis defaultUpAxis(SceneFormat format, const std::vector<BezierPatch>& patches);

// Load a scene. Throws InputError (diagnostics.h) with "file:line: error: what" for malformed input;
// warnings go to `warn`. Inputs without a camera (.bpt, OBJ, Micropolis) are framed automatically
// (frameSceneDefault with `up`, else defaultUpAxis) and get default lights and a plastic material; `up` is
// ignored for RIB, which has its own camera. `format` overrides the detection. `raster`: the resolution the
// caller will render at where it overrides the RIB Format (what subdivision meshes are refined for,
// RasterOverride in rib_reader.h); the other formats convert without a camera and ignore it.
Scene loadScene(const std::string& path, const WarningSink& warn, SceneFormat format = SceneFormat::Auto,
                std::optional<UpAxis> up = std::nullopt, RasterOverride raster = {});
Scene loadRib(const std::string& path, const WarningSink& warn, RasterOverride raster = {});
Scene loadBpt(const std::string& path, const WarningSink& warn, std::optional<UpAxis> up = std::nullopt);
Scene loadObj(const std::string& path, const WarningSink& warn, std::optional<UpAxis> up = std::nullopt);
Scene loadMicropolis(const std::string& path, const WarningSink& warn,
                     std::optional<UpAxis> up = std::nullopt);

}  // namespace tessera
