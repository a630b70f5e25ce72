// Reader for Wavefront OBJ control meshes, treated as Catmull-Clark subdivision surfaces (boundary edges
// interpolated, as RIB "interpolateboundary"). Read: `v x y z [w]` and `f`/`fo` with v, v/vt, v/vt/vn and
// v//vn references (1-based, negative = relative to the last vertex). Ignored without a word: `vt`, `vn`,
// `vp`, `#` comments, `o`, `g`, `s`, `usemtl`, `mtllib`. Other statements (`l`, `p`, curves) are ignored
// with one warning each.
#pragma once
#include <string>
#include <vector>

#include "core/subdivision.h"
#include "io/diagnostics.h"

namespace tessera {

struct ObjMesh {
    SubdivMesh mesh;
    std::vector<int> faceLine;  // source line of each face, for error messages
};

// Parses OBJ text; `file` names the source in errors. Throws InputError "file:line: error: ..." for a bad
// number, an index of 0 or out of range, a face with fewer than 3 vertices, or a file without faces.
ObjMesh parseObj(const std::string& text, const std::string& file, const WarningSink& warn);

// parseObj + subdivideOsd (io/subdiv_osd.h, at kDefaultSubdivLevel); topology errors (non-manifold edges,
// repeated vertices) are reported at the line of the offending face.
std::vector<BezierPatch> objToPatches(const std::string& text, const std::string& file,
                                      const WarningSink& warn, SubdivResult* stats = nullptr);

}  // namespace tessera
