// Catmull-Clark subdivision surfaces through OpenSubdiv (Pixar, Debian libosd-dev 3.5), converted to the
// bicubic Bezier patches both engines render. docs/subdivision.md has the method and its measured error.
//
// Method:
//  1. The control mesh (core/subdivision.h SubdivMesh: creases and corners of any sharpness, holes,
//     boundary mode) becomes a Far::TopologyRefiner with RenderMan's rules (Sdc::Options: uniform crease
//     method, PRMan's default; boundary interpolation none / edges and corners / edges only from the RIB
//     "interpolateboundary" tag) and is refined uniformly to `level` (all patches meet edge to edge, no
//     T-junctions: the Reyes engine's crack-free guarantee needs identical shared edges).
//  2. Each face of that level is a Bfr::Surface (OpenSubdiv's limit-surface evaluation, on a second
//     refiner whose base mesh is the refined level with its remaining sharpness). Its Bezier patch is the
//     bicubic Hermite interpolant of the limit surface at the face's four corners (position, both first
//     derivatives and the twist). Where the face's limit surface is one regular B-spline patch (Bfr
//     IsRegular: every face away from extraordinary vertices and unresolved semi-sharp features, including
//     boundary and infinitely sharp crease patches) this IS that patch, exactly; around extraordinary
//     vertices it interpolates the exact limit positions and tangent planes at the corners.
//  3. Every vertex position and every edge's two inner control points are then taken from one face (a
//     regular one where possible) and copied into all patches sharing them, so shared boundary curves are
//     bit-identical (watertight).
// OpenSubdiv headers stay in subdiv_osd.cpp (core is device-compilable plain math; io converts at load time).
#pragma once
#include <array>
#include <memory>

#include "core/subdivision.h"

namespace tessera {

// Uniform refinement level without a camera (OBJ control meshes, tests).
constexpr int kDefaultSubdivLevel = 2;
constexpr int kMaxSubdivLevel = 5;

// How a face-varying channel is interpolated at its boundaries and seams: PRMan's SubdivisionMesh tag
// "facevaryinginterpolateboundary" 0..3, with the meaning USD's usdRi gives those values in OpenSubdiv's
// terms (Sdc::Options::FVarLinearInterpolation): 0 linear everywhere (FVAR_LINEAR_ALL: bilinear over each
// face, like "facevarying"), 1 smooth with sharp corners, propagated one face (FVAR_LINEAR_CORNERS_PLUS1,
// PRMan's default), 2 smooth everywhere, seams included (FVAR_LINEAR_NONE), 3 smooth inside, linear along
// boundaries and seams (FVAR_LINEAR_BOUNDARIES).
enum class FaceVaryingBoundary { LinearAll = 0, CornersPlus1 = 1, Smooth = 2, LinearBoundaries = 3 };

// Texture coordinates that follow the surface smoothly: RI "vertex" s, t (one per control point, refined
// with the vertex rules as P is) or PRMan "facevertex" s, t (one per face corner: a face-varying channel
// refined with the smooth rules; the corners at a vertex that have equal values are joined, different values
// make a seam).
struct SubdivSmoothTexCoords {
    bool perCorner = false;  // facevertex (one per entry of SubdivMesh::faceVerts), else vertex
    std::vector<Vec2> values;
    FaceVaryingBoundary boundary = FaceVaryingBoundary::CornersPlus1;  // facevertex only
};

struct OsdSubdivOptions {
    // Uniform refinement level 1..kMaxSubdivLevel; -1 (automatic): subdivLevelFor(mesh, rasterSize).
    int level = -1;
    // Extent in raster pixels of the mesh's projection (the larger side of its bounding rectangle); 0 when
    // not known (no camera at conversion).
    float rasterSize = 0.f;
    // Smooth texture coordinates to carry to SubdivResult::patchST (the limit values at every patch
    // corner); nullptr: none. Validated: a wrong count is a SubdivError.
    const SubdivSmoothTexCoords* texCoords = nullptr;
    // Values per control point refined with the vertex rules, as P is (RI "vertex" Cs and N): their limit
    // values at every patch corner go to SubdivResult::patchVertexValues, in this order. Each needs one
    // value per point (else SubdivError).
    std::vector<const std::vector<Vec3>*> vertexValues;
};

// The automatic level: from the screen size, about 8 pixels or less per refined face edge, level 2..4
// (level 1's normals at extraordinary vertices are worse than the hand-written converter's; without a
// screen size kDefaultSubdivLevel), raised to the largest finite crease/corner sharpness (rounded up,
// at most kMaxSubdivLevel) so semi-sharp features are fully resolved into exact patches.
int subdivLevelFor(const SubdivMesh& mesh, float rasterSize);

// Converts the mesh (validated first: SubdivError for malformed topology, as core's converter reports it).
// SubdivResult::patchFace numbers the faces of the refined level; patchBaseFace/patchSubFace/patchUV say
// where each patch lies on the control mesh (for SubdivLimit).
SubdivResult subdivideOsd(const SubdivMesh& mesh, const OsdSubdivOptions& options = {});

// OpenSubdiv's limit surface of the control mesh (Bfr::Surface on the unrefined mesh, refined to
// `approxLevel` around irregular features): the reference the tests and bench/subdiv_error compare
// patches with. Not thread-safe.
class SubdivLimit {
  public:
    explicit SubdivLimit(const SubdivMesh& mesh, int approxLevel = 8);
    ~SubdivLimit();
    SubdivLimit(const SubdivLimit&) = delete;
    SubdivLimit& operator=(const SubdivLimit&) = delete;

    bool hasLimit(int face) const;
    // Position and unit normal (du x dv; zero where du and dv are nearly parallel) at (s, t) of control face
    // `face`: for a quad its (u, v); for other faces the normalized coordinates of sub-face `subFace` (the
    // quad at corner subFace: (0,0) at that vertex, (1,0) at the middle of the edge to the next vertex, (1,1)
    // at the centre), as SubdivResult::patchUV gives them. False for a hole or a face without limit surface.
    bool evaluate(int face, int subFace, double s, double t, std::array<double, 3>& position,
                  std::array<double, 3>& normal) const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// How far converted patches are from the limit surface: each patch sampled on an n x n grid (corners and
// edges included), its position and geometric normal compared with SubdivLimit at the same parameters
// (normals only where both are defined: not at points where du and dv are nearly parallel).
struct SubdivDeviation {
    double maxPosition = 0;   // largest distance, in object-space units
    double diagonal = 0;      // the control mesh's bounding-box diagonal
    double maxNormalDeg = 0;  // largest angle between the normals, in degrees
    double normalDeg999 = 0;  // the 99.9th percentile of that angle over all samples
    double maxPositionExact = 0, maxNormalDegExact = 0;  // over the patches marked exact only
    size_t samples = 0;
    size_t worstNormalPatch = 0;  // where the largest normal error is
    std::array<double, 2> worstNormalST{};
    double relativePosition() const { return diagonal > 0 ? maxPosition / diagonal : 0; }
};
SubdivDeviation subdivDeviation(const SubdivMesh& mesh, const SubdivResult& result, const SubdivLimit& limit,
                                int n = 5);

}  // namespace tessera
