// Reader for the .bpt text format (Ryan Holmes' teapot page): the patch count N, then per patch
// "3 3" (degrees in u and v) and 16 lines "x y z", a row-major 4x4 grid with u fastest.
#pragma once
#include <string>
#include <vector>

#include "core/bezier.h"

namespace tessera {

// Parses .bpt text; `file` names the source in errors (InputError "file:line: error: ...").
std::vector<BezierPatch> parseBpt(const std::string& text, const std::string& file);

}  // namespace tessera
