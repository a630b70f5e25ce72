// Reader for the indexed-vertex text format of Micropolis (github.com/ginkgo/micropolis, data/teapot and
// data/bigguy; Newell's teapot layout with commas): line 1 the patch count N; N lines of 16
// comma-separated 1-based vertex indices (a row-major 4x4 grid, u = k % 4); the vertex count V; V lines
// `x,y,z`. The files have no extension, so the loader detects the format by content.
#pragma once
#include <string>
#include <vector>

#include "core/bezier.h"

namespace tessera {

// True if the text starts like this format: a line with one integer, then a line of 16 comma-separated
// integers.
bool looksLikeMicropolis(const std::string& text);

// Parses the text; `file` names the source in errors. Throws InputError "file:line: error: ..." for a wrong
// count, a malformed line, an index outside 1..V, or trailing data.
std::vector<BezierPatch> parseMicropolis(const std::string& text, const std::string& file);

}  // namespace tessera
