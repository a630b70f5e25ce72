// Catmull-Clark subdivision surfaces (E. Catmull, J. Clark, "Recursively generated B-spline surfaces on
// arbitrary topological meshes", CAD 10(6), 1978): the control mesh, its validation, and the hand-written
// converter to bicubic Bezier patches.
//
// The readers convert through OpenSubdiv (io/subdiv_osd.h: exact semi-sharp creases, uniform refinement
// to a level from the screen size). The hand-written converter below stays as the baseline that
// bench/subdiv_error measures against OpenSubdiv's limit surface (docs/subdivision.md), and refineMesh()
// and limitPositions() serve the tests as an independent reference for infinitely sharp features.
//
// Method (docs/inputs.md has the user-facing summary):
//  1. Unless every face is already regular, the whole mesh is refined by `refineSteps` Catmull-Clark steps
//     (default 1 for quad meshes, 2 for meshes with other polygons). One step makes every face a quad and
//     leaves at most one extraordinary vertex per face in a quad mesh (two, the face centre and an original
//     vertex, in the children of other polygons; the second step isolates those). The refinement is uniform
//     so that all patches meet edge to edge: T-junctions would break the Reyes engine's crack-free guarantee,
//     which needs shared edges with identical control points.
//  2. Regular faces (a quad whose four vertices are interior, smooth, of valence 4 and surrounded by quads)
//     become the exact bicubic B-spline patch of their 16-point neighbourhood, converted to Bezier form
//     with toBezier(bsplineBasis()).
//  3. Every other face gets the approximation of Loop & Schaefer, "Approximating Catmull-Clark subdivision
//     surfaces with bicubic patches", ACM TOG 27(1), 2008 (ACC-1 geometry patch): corners at the limit
//     positions, interior points from the (n v + 2 e_i + 2 e_i+1 + f_i) / (n + 5) masks, edge points the
//     average of the two interior points beside the edge. Extension used here: at a smooth extraordinary
//     vertex the edge points are projected into the exact limit tangent plane (Halstead et al. 1993
//     tangent masks), so all patches around the vertex share its normal. For a regular vertex these
//     rules reproduce the B-spline patch exactly.
//  4. Every boundary curve (corner, 2 edge points, corner) is computed ONCE per mesh edge and copied into
//     both patches that share it, so shared control points are bit-identical (watertight).
//
// Sharp features: boundary edges (RIB "interpolateboundary", OBJ default) and "crease" edges are
// infinitely sharp: edge points are midpoints, crease vertices use (a + 6v + b) / 8, corners stay put; their
// limit curves are uniform cubic B-splines with interpolated corners, which the patches reproduce exactly.
// Semi-sharp (finite) sharpness is treated as infinitely sharp and reported in the warnings.
#pragma once
#include <array>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/bezier.h"

namespace tessera {

// How the mesh boundary is treated (RIB SubdivisionMesh tag "interpolateboundary").
enum class BoundaryMode {
    None,             // no tag: faces touching the boundary only shape the surface (RenderMan semantics)
    EdgesAndCorners,  // boundary edges are sharp creases; vertices with a single face are sharp corners
    EdgesOnly,        // boundary edges are sharp creases; corners stay smooth along the boundary curve
};

struct SubdivCrease {
    int v0 = 0, v1 = 0;  // an edge of the mesh (either direction)
    float sharpness = 10.f;
};
struct SubdivCorner {
    int vertex = 0;
    float sharpness = 10.f;
};

// A polygonal control mesh: face f has faceSizes[f] vertices, listed counter-clockwise (seen from outside)
// in faceVerts, 0-based.
struct SubdivMesh {
    std::vector<Vec3> points;
    std::vector<int> faceSizes;
    std::vector<int> faceVerts;
    BoundaryMode boundary = BoundaryMode::EdgesAndCorners;
    std::vector<SubdivCrease> creases;
    std::vector<SubdivCorner> corners;
    std::vector<int> holes;  // faces that are not rendered (they still shape their neighbours)
    // Semi-sharp creases by Chaikin's rule (PRMan's tag "creasemethod" "chaikin": a crease's sharpness is
    // averaged along it at each level, so varying sharpness blends) instead of the uniform rule (the
    // default, PRMan's "normal"). OpenSubdiv only; the hand-written converter treats creases as sharp.
    bool chaikinCreases = false;
};

// Malformed topology: index out of range, face with fewer than 3 or repeated vertices, an edge shared by
// more than two faces or twice in the same direction, a vertex joining separate fans of faces.
// `face` is the offending input face (-1 if none) so readers can report its line.
class SubdivError : public std::invalid_argument {
  public:
    SubdivError(const std::string& message, int face = -1) : std::invalid_argument(message), face_(face) {}
    int face() const { return face_; }

  private:
    int face_;
};

struct SubdivOptions {
    // -1 (automatic): 0 if every face is regular, 2 if the mesh has faces other than quads, else 1.
    // At most 4.
    int refineSteps = -1;
};

struct SubdivResult {
    std::vector<BezierPatch> patches;
    std::vector<uint32_t> patchFace;  // face of the refined mesh (refineMesh() numbering) of each patch
    std::vector<uint8_t> patchExact;  // 1: exact B-spline patch, 0: approximation
    // Where each patch lies on the control mesh: its input face, for a face other than a quad the
    // sub-face (the quad at that corner; -1 for quads), and the (s, t) of the patch's four corners in
    // (0,0) (1,0) (1,1) (0,1) order, in the face's (u, v) or the sub-face's normalized coordinates
    // (io/subdiv_osd.h SubdivLimit::evaluate). Bilinear in between.
    std::vector<uint32_t> patchBaseFace;
    std::vector<int> patchSubFace;
    std::vector<std::array<Vec2, 4>> patchUV;
    // OpenSubdiv converter with smooth texture coordinates (io/subdiv_osd.h SubdivSmoothTexCoords): the
    // limit s, t at each patch's four corners, in (0,0) (1,0) (1,1) (0,1) order; empty otherwise.
    std::vector<std::array<Vec2, 4>> patchST;
    // Its smooth per-vertex values (io/subdiv_osd.h OsdSubdivOptions::vertexValues, e.g. RI "vertex" Cs, N):
    // for each, the limit values at every patch's corners, in the same order.
    std::vector<std::vector<std::array<Vec3, 4>>> patchVertexValues;
    int level = 0;  // refinement steps applied
    size_t exactCount = 0, approxCount = 0;
    std::vector<std::string> warnings;  // e.g. semi-sharp creases treated as sharp
};

// Throws SubdivError for malformed topology or out-of-range indices (what both converters check first).
void validateSubdivMesh(const SubdivMesh& mesh);

// The hand-written converter (steps 1-4 above); throws SubdivError for malformed topology.
SubdivResult subdivToBezier(const SubdivMesh& mesh, const SubdivOptions& options = {});

// One Catmull-Clark step with the sharp rules above. Numbering of the result: the old vertices keep their
// indices (as vertex points), then one edge point per edge, then one face point per face. Face f with k
// vertices becomes k quads in order, child c = (vertex point of v_c, edge point of (v_c, v_c+1), face
// point of f, edge point of (v_c-1, v_c)). Creases, corners and holes are carried to the children; in
// BoundaryMode::None the faces touching the boundary are first marked as holes.
SubdivMesh refineMesh(const SubdivMesh& mesh);

// Exact limit positions of the vertices of an all-quad mesh: smooth vertices by the Catmull-Clark limit
// mask (n^2 v + 4 sum e_j + sum f_j) / (n (n + 5)), crease vertices (a + 4v + b) / 6, corners v.
std::vector<Vec3> limitPositions(const SubdivMesh& mesh);

}  // namespace tessera
