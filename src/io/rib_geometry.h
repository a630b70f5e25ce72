// The RIB primitives (RI spec 3.2, sec. 5): Patch and PatchMesh in any basis, NuPatch and
// SubdivisionMesh, each converted to bicubic Bezier patches in world space and added to the scene
// with the attributes of the current graphics state. One object id per request.
#pragma once
#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

#include "io/rib_graphics_state.h"
#include "io/rib_params.h"
#include "io/rib_request.h"
#include "scene/scene.h"

namespace tessera::rib {

// Scene::materials by value: the index of each distinct material in constant time. A linear search per
// primitive made loading quadratic in the number of distinct materials (80,000 patches of their own
// Color took 4.6 s). Materials are equal as Material::operator== says (a NaN field never matches, so
// such a material is added anew each time, as the search did); the first of equal ones is found.
class MaterialTable {
  public:
    uint32_t indexOf(Scene& scene, const Material& m);

  private:
    struct Hash {
        size_t operator()(const Material& m) const;
    };
    std::unordered_map<Material, uint32_t, Hash> index_;
    size_t indexed_ = 0;          // scene.materials[0, indexed_) are in index_
    uint32_t last_ = UINT32_MAX;  // the index last returned
};

// Whether a transformation into camera space mirrors a primitive (its handedness decides which side is
// outside, RI spec 3.2, sec. 4.2.4), remembered for the last transformation: consecutive primitives mostly
// share it, and the 4x4 product behind the answer was a sixth of loading one Patch. The matrices are
// compared bit for bit, so the answer is always the product's.
class OrientationCache {
  public:
    bool mirrored(const Mat4& cameraFromWorld, const Mat4& worldFromObject);

  private:
    bool valid_ = false, mirrored_ = false;
    Mat4 camera_, object_;
};

// What a primitive request reads and where its patches go.
struct PrimitiveContext {
    Scene& scene;
    const GraphicsState& state;
    const Declarations& decls;
    Diagnostics& diag;
    // SubdivisionMesh: the refinement level to use (deformation keys after the first take the first's, so
    // all keys have the same patches); -1: from the mesh's size on screen.
    int subdivLevel = -1;
    // The raster size the image will be rendered at when the caller overrides the Format (RasterOverride in
    // rib_reader.h); 0: the camera's own. What the automatic subdivision level is chosen for.
    int rasterWidth = 0, rasterHeight = 0;
    // The reader's index of scene.materials (nullptr: a linear search).
    MaterialTable* materials = nullptr;
    // The reader's last orientation answer (nullptr: computed each time).
    OrientationCache* orientation = nullptr;
};

// The object-space Bezier patches of one primitive request, before the CTM is applied: what a motion
// block collects once per time key (deformation blur, RI spec 3.2, sec. 6).
struct PrimitiveShape {
    std::string request;  // "Patch", "PatchMesh", ...
    int line = 0;
    bool skipped = false;  // not rendered (warned): e.g. "Pz" or an unsupported subdivision scheme
    std::vector<BezierPatch> patches;
    // The s, t of each patch (RI "st" / "s" "t" varying primitive variables, or TextureCoordinates);
    // empty: every patch has the default s = u, t = v.
    std::vector<PatchTexCoords> texCoords;
    // The colour (RI "Cs") of each patch where the primitive gives one per polygon (uniform) or one for all
    // (constant); empty: the graphics state's Color.
    std::vector<Color> colors;
    // Per-vertex "N" and "Cs" of each patch (polygons; N in object space); empty: none.
    std::vector<PatchVertexValues> vertexValues;
    // Polygons: each piece's four corners (points of "P", places in the vertex list) and its polygon, so
    // that the later keys of a deformation block are cut the same way as the first.
    struct PolygonPiece {
        int point[4], fv[4];
        size_t polygon;
    };
    std::vector<PolygonPiece> polygonPieces;
    // What the keys of a deformation block must share, in words (e.g. `PatchMesh "bicubic" 7
    // "nonperiodic" 4 "nonperiodic"`) and as a hash that also covers vertex indices, knots and tags.
    std::string topology;
    uint64_t topologyHash = 0;
    int subdivLevel = 0;  // SubdivisionMesh: the refinement level it was converted at
};

bool isPrimitiveRequest(const std::string& name);
// Sphere, Cylinder, Cone, Disk, Paraboloid, Hyperboloid, Torus (RI spec 3.2, sec. 5.4).
bool isQuadricRequest(const std::string& name);
// Adds one quadric (r.name) to the scene as its own surface kind, with the attributes and the CTM of the
// graphics state. A moving CTM is taken at shutter open, with one warning (quadrics do not move).
// Degenerate parameters that RI defines as an empty surface (radius, height range or sweep of 0) add
// nothing and warn; malformed ones (wrong counts, non-finite values, a paraboloid crossing z = 0) fail.
void addQuadric(const Request& r, const PrimitiveContext& c);
// Reads Patch, PatchMesh, NuPatch, SubdivisionMesh, Polygon, GeneralPolygon, PointsPolygons or
// PointsGeneralPolygons (r.name) without adding it to the scene. Polygons become bilinear patches (a convex
// quadrilateral without holes) or degenerate bilinear patches (the triangles of an ear-clipping
// triangulation, holes bridged into the outer loop), exact for planar polygons; their "st" / "s" "t"
// (vertex, varying or facevarying) become the pieces' texture coordinates.
// `firstKey`: the first key of the deformation block this request is a later key of (nullptr: none);
// polygons with its topology are cut into its pieces rather than triangulated again, so that every key's
// pieces match even where ear clipping would choose other ears for the moved points.
PrimitiveShape readPrimitiveShape(const Request& r, const PrimitiveContext& c,
                                  const PrimitiveShape* firstKey = nullptr);
// Adds one primitive to the scene with the attributes and the CTM of the graphics state. `keys` holds one
// shape (no deformation) or one per time of `times` (a deformation block; the caller has checked that
// their topologies match). A moving CTM and/or deformation keys give every patch keys in
// Scene::motionPatches at the union of the deformation times and the CTM's sample times (at most 2
// degrees of turn per segment); Scene::patches holds each patch at shutter open; patches whose keys are
// all equal are stored as static. One object id per call.
void addPrimitive(const std::vector<PrimitiveShape>& keys, const std::vector<double>& times,
                  const PrimitiveContext& c);

}  // namespace tessera::rib
