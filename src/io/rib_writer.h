// Writes a Scene as a RIB file of bicubic Bezier patches (`tessera convert IN -o OUT.rib`): camera, image
// options, lights, materials and every patch as `Patch "bicubic" "P" [...]`, readable by our RIB reader and
// by other RenderMan-compatible renderers.
#pragma once
#include <ostream>
#include <string>

#include "scene/scene.h"

namespace tessera {

// Writes to `path` atomically (a temporary file in the same directory, then rename), so an interrupted
// conversion never leaves a truncated RIB. Coordinates are written in the shortest form that reads back
// to the identical float, so shared patch edges stay bit-identical. Throws std::runtime_error
// ("path: error: ...") if the file cannot be written.
void writeRib(const Scene& scene, const std::string& path);

// The same RIB text to a stream.
void writeRib(const Scene& scene, std::ostream& out);

}  // namespace tessera
