#include "io/subdiv_osd.h"

#include <opensubdiv/bfr/refinerSurfaceFactory.h>
#include <opensubdiv/bfr/surface.h>
#include <opensubdiv/far/primvarRefiner.h>
#include <opensubdiv/far/topologyDescriptor.h>
#include <opensubdiv/far/topologyRefinerFactory.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <string>
#include <tuple>
#include <unordered_set>
#include <vector>

namespace tessera {

namespace {

using namespace OpenSubdiv;
using Far::Index;
using Refiner = Far::TopologyRefiner;
using Factory = Far::TopologyRefinerFactory<Far::TopologyDescriptor>;

// A point for Far::PrimvarRefinerReal<double>.
struct P3 {
    double x = 0, y = 0, z = 0;
    void Clear() { x = y = z = 0; }
    void AddWithWeight(const P3& p, double w) {
        x += w * p.x;
        y += w * p.y;
        z += w * p.z;
    }
};

// Texture coordinates for Far::PrimvarRefinerReal<double>.
struct P2 {
    double x = 0, y = 0;
    void Clear() { x = y = 0; }
    void AddWithWeight(const P2& p, double w) {
        x += w * p.x;
        y += w * p.y;
    }
};

Sdc::Options::FVarLinearInterpolation fvarInterpolation(FaceVaryingBoundary b) {
    switch (b) {
        case FaceVaryingBoundary::LinearAll:
            return Sdc::Options::FVAR_LINEAR_ALL;
        case FaceVaryingBoundary::Smooth:
            return Sdc::Options::FVAR_LINEAR_NONE;
        case FaceVaryingBoundary::LinearBoundaries:
            return Sdc::Options::FVAR_LINEAR_BOUNDARIES;
        default:
            return Sdc::Options::FVAR_LINEAR_CORNERS_PLUS1;
    }
}

// RenderMan's rules in OpenSubdiv's terms. Crease method: uniform (OpenSubdiv's default, which is PRMan's
// default "normal" creasing) or Chaikin (PRMan's opt-in tag "creasemethod" "chaikin"). Triangles:
// Catmull-Clark's own rule (TRI_SUB_CATMARK), as PRMan does.
Sdc::Options sdcOptions(BoundaryMode mode, bool chaikin,
                        FaceVaryingBoundary fvar = FaceVaryingBoundary::CornersPlus1) {
    Sdc::Options o;
    o.SetFVarLinearInterpolation(fvarInterpolation(fvar));
    o.SetVtxBoundaryInterpolation(mode == BoundaryMode::None
                                      ? Sdc::Options::VTX_BOUNDARY_NONE
                                      : (mode == BoundaryMode::EdgesOnly
                                             ? Sdc::Options::VTX_BOUNDARY_EDGE_ONLY
                                             : Sdc::Options::VTX_BOUNDARY_EDGE_AND_CORNER));
    o.SetCreasingMethod(chaikin ? Sdc::Options::CREASE_CHAIKIN : Sdc::Options::CREASE_UNIFORM);
    o.SetTriangleSubdivision(Sdc::Options::TRI_SUB_CATMARK);
    return o;
}

// OpenSubdiv's infinite sharpness is 10 (Sdc::Crease::SHARPNESS_INFINITE); RIB files write larger values or
// "infinity" for a hard crease.
float osdSharpness(float s) {
    return std::isfinite(s) ? std::clamp(s, 0.f, 10.f) : (s > 0 ? 10.f : 0.f);
}

// The data a TopologyDescriptor points to.
struct Topology {
    std::vector<int> faceSizes, faceVerts, creasePairs, cornerVerts, holes;
    std::vector<float> creaseWeights, cornerWeights;
    // One face-varying channel (smooth "facevertex" texture coordinates): a value index per face corner.
    std::vector<int> fvarIndices;
    int fvarValues = 0;
    FaceVaryingBoundary fvarBoundary = FaceVaryingBoundary::CornersPlus1;
};

std::unique_ptr<Refiner> makeRefiner(int numVertices, const Topology& t, BoundaryMode mode, bool chaikin) {
    Far::TopologyDescriptor d;
    d.numVertices = numVertices;
    d.numFaces = int(t.faceSizes.size());
    d.numVertsPerFace = t.faceSizes.data();
    d.vertIndicesPerFace = t.faceVerts.data();
    d.numCreases = int(t.creaseWeights.size());
    d.creaseVertexIndexPairs = t.creasePairs.data();
    d.creaseWeights = t.creaseWeights.data();
    d.numCorners = int(t.cornerWeights.size());
    d.cornerVertexIndices = t.cornerVerts.data();
    d.cornerWeights = t.cornerWeights.data();
    d.numHoles = int(t.holes.size());
    d.holeIndices = t.holes.data();
    Far::TopologyDescriptor::FVarChannel channel;
    if (!t.fvarIndices.empty()) {
        channel.numValues = t.fvarValues;
        channel.valueIndices = t.fvarIndices.data();
        d.numFVarChannels = 1;
        d.fvarChannels = &channel;
    }
    std::unique_ptr<Refiner> r(
        Factory::Create(d, Factory::Options(Sdc::SCHEME_CATMARK, sdcOptions(mode, chaikin, t.fvarBoundary))));
    if (!r) throw SubdivError("OpenSubdiv could not build the mesh's topology");
    return r;
}

// The descriptor's data. A crease between vertices that no face edge joins is left out (OpenSubdiv would
// print a warning of its own) and, with `warnings`, reported.
Topology topologyOf(const SubdivMesh& m, std::vector<std::string>* warnings = nullptr) {
    Topology t;
    t.faceSizes = m.faceSizes;
    t.faceVerts = m.faceVerts;
    std::unordered_set<uint64_t> edges;
    auto key = [](int a, int b) {
        return (uint64_t(uint32_t(std::min(a, b))) << 32) | uint32_t(std::max(a, b));
    };
    for (size_t f = 0, o = 0; f < m.faceSizes.size(); o += size_t(m.faceSizes[f++]))
        for (int i = 0; i < m.faceSizes[f]; ++i)
            edges.insert(key(m.faceVerts[o + size_t(i)], m.faceVerts[o + size_t((i + 1) % m.faceSizes[f])]));
    size_t notEdges = 0;
    for (const SubdivCrease& c : m.creases) {
        if (!(osdSharpness(c.sharpness) > 0)) continue;
        if (!edges.count(key(c.v0, c.v1))) {
            if (notEdges++ == 0 && warnings)
                warnings->push_back("crease (" + std::to_string(c.v0) + ", " + std::to_string(c.v1) +
                                    ") is not an edge of the mesh; such creases are ignored");
            continue;
        }
        t.creasePairs.insert(t.creasePairs.end(), {c.v0, c.v1});
        t.creaseWeights.push_back(osdSharpness(c.sharpness));
    }
    for (const SubdivCorner& c : m.corners) {
        if (!(osdSharpness(c.sharpness) > 0)) continue;
        t.cornerVerts.push_back(c.vertex);
        t.cornerWeights.push_back(osdSharpness(c.sharpness));
    }
    t.holes = m.holes;
    std::sort(t.holes.begin(), t.holes.end());
    t.holes.erase(std::unique(t.holes.begin(), t.holes.end()), t.holes.end());
    return t;
}

// Faces with a surface: not holes and, without boundary interpolation (RenderMan's default), not touching
// the boundary (those only shape their neighbours).
std::vector<char> renderedFaces(const SubdivMesh& m, const Refiner& r) {
    const Far::TopologyLevel& L = r.GetLevel(0);
    std::vector<char> out(size_t(L.GetNumFaces()), 1);
    for (int h : m.holes) out[size_t(h)] = 0;
    if (m.boundary == BoundaryMode::None)
        for (int f = 0; f < L.GetNumFaces(); ++f)
            for (int v : L.GetFaceVertices(f))
                if (L.IsVertexBoundary(v)) out[size_t(f)] = 0;
    return out;
}

// Cubic Bernstein basis and its derivative at x, in double.
void bernstein(double x, double b[4], double d[4]) {
    const double y = 1 - x;
    b[0] = y * y * y, b[1] = 3 * x * y * y, b[2] = 3 * x * x * y, b[3] = x * x * x;
    d[0] = -3 * y * y, d[1] = 3 * y * y - 6 * x * y, d[2] = 6 * x * y - 3 * x * x, d[3] = 3 * x * x;
}

// The inner control points of an approximated (irregular) face: least squares on the limit surface's
// cross-boundary derivatives at the quarter points of each edge (what the normal along the edge depends
// on, so both patches of an edge follow the limit tangent plane there) and, with less weight, its twists
// at the corners. The boundary control points are already set. For a polynomial surface every condition
// is met, so a regular face would come out exact too.
struct InnerFit {
    struct Condition {
        double s, t;
        bool du, dv;  // which derivative: du only, dv only or both (the twist)
        double weight;
    };
    std::vector<Condition> conditions;
    double inverse[4][4];  // of the normal equations
    static constexpr int kInner[4][2] = {{1, 1}, {2, 1}, {2, 2}, {1, 2}};
    static constexpr double kTwistWeightRegular = 0.1, kTwistWeightExtraordinary = 1e-3;

    static void weights(const Condition& c, double w[4][4]) {
        double bu[4], du[4], bv[4], dv[4];
        bernstein(c.s, bu, du);
        bernstein(c.t, bv, dv);
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j) w[i][j] = (c.du ? du[i] : bu[i]) * (c.dv ? dv[j] : bv[j]) * c.weight;
    }

    // irregular: bit c set if corner c is an extraordinary vertex, where the twist Bfr reports is not
    // meaningful (the parameterization is not smooth there). Measured on Big Guy (bench/subdiv_error),
    // twists weighted 0.1 everywhere gave smaller normal errors at levels 2-4 than trusting the regular
    // corners' twists more; kept as a parameter.
    explicit InnerFit(int irregular) {
        for (double q : {0.25, 0.5, 0.75}) {
            conditions.push_back({q, 0, false, true, 1});  // across edge v = 0
            conditions.push_back({1, q, true, false, 1});  // across edge u = 1
            conditions.push_back({q, 1, false, true, 1});
            conditions.push_back({0, q, true, false, 1});
        }
        for (int c = 0; c < 4; ++c)
            conditions.push_back({double(c == 1 || c == 2), double(c >= 2), true, true,
                                  irregular & (1 << c) ? kTwistWeightExtraordinary : kTwistWeightRegular});
        double M[4][8] = {};
        for (const Condition& c : conditions) {
            double w[4][4];
            weights(c, w);
            for (int a = 0; a < 4; ++a)
                for (int b = 0; b < 4; ++b)
                    M[a][b] += w[kInner[a][0]][kInner[a][1]] * w[kInner[b][0]][kInner[b][1]];
        }
        for (int a = 0; a < 4; ++a) M[a][4 + a] = 1;
        for (int col = 0; col < 4; ++col) {  // Gauss-Jordan; M is symmetric positive definite
            const double piv = M[col][col];
            for (int k = 0; k < 8; ++k) M[col][k] /= piv;
            for (int r = 0; r < 4; ++r)
                if (r != col) {
                    const double f = M[r][col];
                    for (int k = 0; k < 8; ++k) M[r][k] -= f * M[col][k];
                }
        }
        for (int a = 0; a < 4; ++a)
            for (int b = 0; b < 4; ++b) inverse[a][b] = M[a][4 + b];
    }

    // values[k]: the limit surface's derivative named by conditions[k].
    void apply(BezierPatch& p, const std::vector<std::array<double, 3>>& values) const {
        double rhs[4][3] = {};
        for (size_t k = 0; k < conditions.size(); ++k) {
            double w[4][4];
            weights(conditions[k], w);
            double r[3] = {values[k][0] * conditions[k].weight, values[k][1] * conditions[k].weight,
                           values[k][2] * conditions[k].weight};
            for (int i = 0; i < 4; ++i)
                for (int j = 0; j < 4; ++j) {
                    if ((i == 1 || i == 2) && (j == 1 || j == 2)) continue;
                    const Vec3 b = p.at(i, j);
                    r[0] -= w[i][j] * b.x, r[1] -= w[i][j] * b.y, r[2] -= w[i][j] * b.z;
                }
            for (int a = 0; a < 4; ++a) {
                const double wa = w[kInner[a][0]][kInner[a][1]];
                for (int x = 0; x < 3; ++x) rhs[a][x] += wa * r[x];
            }
        }
        for (int a = 0; a < 4; ++a) {
            double q[3] = {};
            for (int b = 0; b < 4; ++b)
                for (int x = 0; x < 3; ++x) q[x] += inverse[a][b] * rhs[b][x];
            p.at(kInner[a][0], kInner[a][1]) = {float(q[0]), float(q[1]), float(q[2])};
        }
    }
};

// Control point (u index, v index) of patch corner c (0: (0,0), 1: (1,0), 2: (1,1), 3: (0,1)).
std::array<int, 2> cornerIndex(int c) {
    return {c == 1 || c == 2 ? 3 : 0, c >= 2 ? 3 : 0};
}
// Inner control point k (0, 1) of side s of a patch, walking from corner s to corner s + 1.
std::array<int, 2> sideIndex(int s, int k) {
    switch (s) {
        case 0:
            return {1 + k, 0};
        case 1:
            return {3, 1 + k};
        case 2:
            return {2 - k, 3};
        default:
            return {0, 2 - k};
    }
}

using Param = std::array<Vec2, 4>;
Vec2 mid(Vec2 a, Vec2 b) {
    return {(a.x + b.x) * 0.5f, (a.y + b.y) * 0.5f};
}

}  // namespace

int subdivLevelFor(const SubdivMesh& mesh, float rasterSize) {
    int level = kDefaultSubdivLevel;
    if (rasterSize > 0 && std::isfinite(rasterSize) && !mesh.faceSizes.empty()) {
        // A control face covers about rasterSize / sqrt(faces) pixels; each level halves it.
        const double facePixels = rasterSize / std::sqrt(double(mesh.faceSizes.size()));
        level = int(std::ceil(std::log2(std::max(facePixels / 8.0, 1.0))));
        level = std::clamp(level, 2, 4);
    }
    float sharp = 0;
    for (const SubdivCrease& c : mesh.creases)
        if (osdSharpness(c.sharpness) < 10) sharp = std::max(sharp, osdSharpness(c.sharpness));
    for (const SubdivCorner& c : mesh.corners)
        if (osdSharpness(c.sharpness) < 10) sharp = std::max(sharp, osdSharpness(c.sharpness));
    level = std::max(level, std::min(int(std::ceil(sharp)), kMaxSubdivLevel));
    return level;
}

SubdivResult subdivideOsd(const SubdivMesh& mesh, const OsdSubdivOptions& options) {
    if (options.level != -1 && (options.level < 1 || options.level > kMaxSubdivLevel))
        throw SubdivError("the subdivision level must be -1 (automatic) or 1.." +
                          std::to_string(kMaxSubdivLevel));
    validateSubdivMesh(mesh);
    const int level = options.level > 0 ? options.level : subdivLevelFor(mesh, options.rasterSize);

    // 1. Uniform refinement of the control mesh.
    SubdivResult out;
    out.level = level;
    Topology topo = topologyOf(mesh, &out.warnings);
    const SubdivSmoothTexCoords* smoothST = options.texCoords;
    std::vector<P2> st;  // at the current level: per vertex, or per face-varying value
    if (smoothST) {
        const size_t want = smoothST->perCorner ? mesh.faceVerts.size() : mesh.points.size();
        if (smoothST->values.size() != want)
            throw SubdivError(std::to_string(smoothST->values.size()) + " texture coordinates for " +
                              std::to_string(want) + (smoothST->perCorner ? " face corners" : " vertices"));
        if (smoothST->perCorner) {
            // Corners at one vertex with equal values share a value (continuous there); different values
            // at a vertex are a seam (OpenSubdiv joins corners by value index).
            std::map<std::tuple<int, float, float>, int> valueOf;
            topo.fvarBoundary = smoothST->boundary;
            for (size_t k = 0; k < mesh.faceVerts.size(); ++k) {
                const Vec2 v = smoothST->values[k];
                auto [it, added] = valueOf.try_emplace({mesh.faceVerts[k], v.x, v.y}, int(st.size()));
                if (added) st.push_back({v.x, v.y});
                topo.fvarIndices.push_back(it->second);
            }
            topo.fvarValues = int(st.size());
        } else {
            for (const Vec2& v : smoothST->values) st.push_back({v.x, v.y});
        }
    }
    std::vector<std::vector<P3>> values3;  // options.vertexValues at the current level
    for (const std::vector<Vec3>* v : options.vertexValues) {
        if (!v || v->size() != mesh.points.size())
            throw SubdivError(std::to_string(v ? v->size() : 0) + " vertex values for " +
                              std::to_string(mesh.points.size()) + " vertices");
        values3.emplace_back();
        for (const Vec3& x : *v) values3.back().push_back({x.x, x.y, x.z});
    }
    std::unique_ptr<Refiner> A =
        makeRefiner(int(mesh.points.size()), topo, mesh.boundary, mesh.chaikinCreases);
    const std::vector<char> rendered0 = renderedFaces(mesh, *A);
    Refiner::UniformOptions uniform(level);
    uniform.fullTopologyInLastLevel = true;  // edges of the last level: the shared boundary curves
    A->RefineUniform(uniform);
    std::vector<P3> pts(mesh.points.size());
    for (size_t i = 0; i < pts.size(); ++i) pts[i] = {mesh.points[i].x, mesh.points[i].y, mesh.points[i].z};
    Far::PrimvarRefinerReal<double> primvar(*A);
    // Placement of every face on the control mesh, carried down the levels with the points.
    struct Place {
        int base, sub;
        Param uv;
        bool rendered;
    };
    std::vector<Place> place;
    {
        const Far::TopologyLevel& L0 = A->GetLevel(0);
        for (int f = 0; f < L0.GetNumFaces(); ++f)
            place.push_back({f,
                             L0.GetFaceVertices(f).size() == 4 ? -1 : -2,
                             {Vec2{0, 0}, Vec2{1, 0}, Vec2{1, 1}, Vec2{0, 1}},
                             rendered0[size_t(f)] != 0});
    }
    for (int l = 1; l <= level; ++l) {
        std::vector<P3> next(size_t(A->GetLevel(l).GetNumVertices()));
        primvar.Interpolate(l, pts, next);
        pts.swap(next);
        for (std::vector<P3>& v : values3) {
            std::vector<P3> nextValues(pts.size());
            primvar.Interpolate(l, v, nextValues);
            v.swap(nextValues);
        }
        if (smoothST) {
            std::vector<P2> nextST;
            if (smoothST->perCorner) {
                nextST.resize(size_t(A->GetLevel(l).GetNumFVarValues(0)));
                primvar.InterpolateFaceVarying(l, st, nextST, 0);
            } else {
                nextST.resize(pts.size());
                primvar.Interpolate(l, st, nextST);
            }
            st.swap(nextST);
        }
        const Far::TopologyLevel& P = A->GetLevel(l - 1);
        const Far::TopologyLevel& C = A->GetLevel(l);
        std::vector<Place> childPlace(size_t(C.GetNumFaces()));
        for (int f = 0; f < P.GetNumFaces(); ++f) {
            const Place& pp = place[size_t(f)];
            auto pv = P.GetFaceVertices(f);
            auto pe = P.GetFaceEdges(f);
            const int n = pv.size();
            const Index faceChild = P.GetFaceChildVertex(f);
            for (Index cf : P.GetFaceChildFaces(f)) {
                auto cv = C.GetFaceVertices(cf);
                // The parent corner this child sits at: the one whose vertex child it contains.
                int corner = -1;
                for (int i = 0; i < n && corner < 0; ++i)
                    for (Index v : cv)
                        if (v == P.GetVertexChildVertex(pv[i])) corner = i;
                Place cp{pp.base, pp.sub, {}, pp.rendered};
                Param local;  // parent-space (or sub-face) coordinates of the corner's vertex, edges, centre
                Vec2 atVertex, atNext, atPrev, atCentre;
                if (pp.sub == -2) {
                    cp.sub = corner;
                    atVertex = {0, 0}, atNext = {1, 0}, atCentre = {1, 1}, atPrev = {0, 1};
                } else {
                    const Param& u = pp.uv;
                    atVertex = u[size_t(corner)];
                    atNext = mid(u[size_t(corner)], u[size_t((corner + 1) % 4)]);
                    atPrev = mid(u[size_t(corner)], u[size_t((corner + 3) % 4)]);
                    atCentre = mid(mid(u[0], u[2]), mid(u[1], u[3]));
                }
                for (int k = 0; k < cv.size(); ++k) {
                    const Index v = cv[k];
                    if (v == faceChild)
                        local[size_t(k)] = atCentre;
                    else if (v == P.GetVertexChildVertex(pv[corner]))
                        local[size_t(k)] = atVertex;
                    else if (v == P.GetEdgeChildVertex(pe[corner]))
                        local[size_t(k)] = atNext;
                    else
                        local[size_t(k)] = atPrev;  // the child of the edge before the corner
                }
                cp.uv = local;
                childPlace[size_t(cf)] = cp;
            }
        }
        place.swap(childPlace);
    }

    // Smooth texture coordinates at the limit of every vertex (face-varying value) of the last level: the
    // patch corners' s, t (vertex ones are the same affine combinations of the control values as the
    // limit position is of the control points).
    std::vector<P2> limitST;
    if (smoothST) {
        limitST.resize(st.size());
        if (smoothST->perCorner)
            primvar.LimitFaceVarying(st, limitST, 0);
        else
            primvar.Limit(st, limitST);
    }

    std::vector<std::vector<P3>> limitValues3;
    for (const std::vector<P3>& v : values3) {
        limitValues3.emplace_back(v.size());
        primvar.Limit(v, limitValues3.back());
    }
    out.patchVertexValues.resize(values3.size());

    // 2. The refined level as the base of a second refiner, with the sharpness left at that level.
    const Far::TopologyLevel& L = A->GetLevel(level);
    Topology t2;
    const int nf = L.GetNumFaces();
    for (int f = 0; f < nf; ++f) {
        auto fv = L.GetFaceVertices(f);
        t2.faceSizes.push_back(fv.size());
        t2.faceVerts.insert(t2.faceVerts.end(), fv.begin(), fv.end());
        if (L.IsFaceHole(f)) t2.holes.push_back(f);
    }
    for (int e = 0; e < L.GetNumEdges(); ++e)
        if (L.GetEdgeSharpness(e) > 0) {
            auto ev = L.GetEdgeVertices(e);
            t2.creasePairs.insert(t2.creasePairs.end(), {ev[0], ev[1]});
            t2.creaseWeights.push_back(L.GetEdgeSharpness(e));
        }
    for (int v = 0; v < L.GetNumVertices(); ++v)
        if (L.GetVertexSharpness(v) > 0) {
            t2.cornerVerts.push_back(v);
            t2.cornerWeights.push_back(L.GetVertexSharpness(v));
        }
    std::unique_ptr<Refiner> B = makeRefiner(L.GetNumVertices(), t2, mesh.boundary, mesh.chaikinCreases);
    Bfr::RefinerSurfaceFactory<> factory(*B);

    // Hermite patches, face by face.
    std::vector<int> patchOf(size_t(nf), -1);
    std::vector<double> meshPts(pts.size() * 3), patchPts;
    for (size_t i = 0; i < pts.size(); ++i) {
        meshPts[3 * i] = pts[i].x;
        meshPts[3 * i + 1] = pts[i].y;
        meshPts[3 * i + 2] = pts[i].z;
    }
    const Bfr::Surface<double>::PointDescriptor desc(3);
    Bfr::Surface<double> surface;
    static const std::array<InnerFit, 16> fits = [] {
        std::array<InnerFit, 16> f{InnerFit(0),  InnerFit(1),  InnerFit(2),  InnerFit(3),
                                   InnerFit(4),  InnerFit(5),  InnerFit(6),  InnerFit(7),
                                   InnerFit(8),  InnerFit(9),  InnerFit(10), InnerFit(11),
                                   InnerFit(12), InnerFit(13), InnerFit(14), InnerFit(15)};
        return f;
    }();
    double cornerP[4][3], cornerDu[4][3], cornerDv[4][3];
    std::vector<std::array<double, 3>> values;
    for (int f = 0; f < nf; ++f) {
        if (!place[size_t(f)].rendered || L.IsFaceHole(f)) continue;
        if (!factory.InitVertexSurface(f, &surface)) continue;
        patchPts.resize(size_t(surface.GetNumPatchPoints()) * 3);
        surface.PreparePatchPoints(meshPts.data(), desc, patchPts.data(), desc);
        BezierPatch bp;
        static const int cu[4] = {0, 1, 1, 0}, cv[4] = {0, 0, 1, 1};
        for (int c = 0; c < 4; ++c) {
            const double uv[2] = {double(cu[c]), double(cv[c])};
            double P[3], Du[3], Dv[3], Duu[3], Duv[3], Dvv[3];
            surface.Evaluate(uv, patchPts.data(), desc, P, Du, Dv, Duu, Duv, Dvv);
            for (int x = 0; x < 3; ++x) cornerP[c][x] = P[x], cornerDu[c][x] = Du[x], cornerDv[c][x] = Dv[x];
            const double su = cu[c] ? -1 : 1, sv = cv[c] ? -1 : 1;
            const int i0 = cu[c] ? 3 : 0, j0 = cv[c] ? 3 : 0, i1 = cu[c] ? 2 : 1, j1 = cv[c] ? 2 : 1;
            auto at = [&](double a, double b, double ab) {
                return Vec3{float(P[0] + a * Du[0] + b * Dv[0] + ab * Duv[0]),
                            float(P[1] + a * Du[1] + b * Dv[1] + ab * Duv[1]),
                            float(P[2] + a * Du[2] + b * Dv[2] + ab * Duv[2])};
            };
            bp.at(i0, j0) = at(0, 0, 0);
            bp.at(i1, j0) = at(su / 3, 0, 0);
            bp.at(i0, j1) = at(0, sv / 3, 0);
            bp.at(i1, j1) = at(su / 3, sv / 3, su * sv / 9);
        }
        const bool exact = surface.IsRegular();
        if (!exact) {
            int irregular = 0;
            {
                auto fv = L.GetFaceVertices(f);
                for (int c = 0; c < 4; ++c)
                    if (L.GetVertexEdges(fv[c]).size() != 4 || L.IsVertexBoundary(fv[c]) ||
                        L.GetVertexSharpness(fv[c]) > 0)
                        irregular |= 1 << c;
            }
            const InnerFit& fit = fits[size_t(irregular)];
            // Boundary curves: at an extraordinary vertex the face's parameterization is not smooth, and
            // the derivative Bfr reports there has the right direction (the tangent plane) but no
            // meaningful length. So each curve keeps its end tangent directions and fits their lengths
            // to the limit curve at the quarter points (lengths 1/3: the Hermite curve, exact for a cubic).
            for (int side = 0; side < 4; ++side) {
                const int c0 = side, c1 = (side + 1) % 4;
                auto tangent = [&](int c, std::array<double, 3>& T) {
                    const double sign = side >= 2 ? -1 : 1;
                    for (int x = 0; x < 3; ++x)
                        T[x] = sign * (side % 2 == 0 ? cornerDu[c][x] : cornerDv[c][x]);
                };
                std::array<double, 3> Ta, Tb;
                tangent(c0, Ta);
                tangent(c1, Tb);
                // At an extraordinary end only the direction counts: scaled to the chord, so the fitted
                // length is a fraction of it (1/3 for evenly spaced control points).
                double chord = 0;
                for (int x = 0; x < 3; ++x)
                    chord += (cornerP[c1][x] - cornerP[c0][x]) * (cornerP[c1][x] - cornerP[c0][x]);
                chord = std::sqrt(chord);
                for (auto [T, bit] : {std::pair{&Ta, 1 << c0}, std::pair{&Tb, 1 << c1}}) {
                    const double len = std::sqrt((*T)[0] * (*T)[0] + (*T)[1] * (*T)[1] + (*T)[2] * (*T)[2]);
                    if ((irregular & bit) && len > 0)
                        for (double& x : *T) x *= chord / len;
                }
                double m00 = 0, m01 = 0, m11 = 0, r0 = 0, r1 = 0;
                for (double q : {0.25, 0.5, 0.75}) {
                    const double uv[2] = {side == 0   ? q
                                          : side == 1 ? 1
                                          : side == 2 ? 1 - q
                                                      : 0,
                                          side == 0   ? 0
                                          : side == 1 ? q
                                          : side == 2 ? 1
                                                      : 1 - q};
                    double L[3], b[4], d[4];
                    surface.Evaluate(uv, patchPts.data(), desc, L);
                    bernstein(q, b, d);
                    double r[3];
                    for (int x = 0; x < 3; ++x)
                        r[x] = L[x] - (b[0] + b[1]) * cornerP[c0][x] - (b[2] + b[3]) * cornerP[c1][x];
                    for (int x = 0; x < 3; ++x) {
                        m00 += b[1] * b[1] * Ta[x] * Ta[x];
                        m01 -= b[1] * b[2] * Ta[x] * Tb[x];
                        m11 += b[2] * b[2] * Tb[x] * Tb[x];
                        r0 += b[1] * Ta[x] * r[x];
                        r1 -= b[2] * Tb[x] * r[x];
                    }
                }
                // Only the lengths at extraordinary ends are fitted; elsewhere the derivative is exact.
                const bool fa = irregular & (1 << c0), fb = irregular & (1 << c1);
                double alpha = 1.0 / 3, beta = 1.0 / 3;
                const double det = m00 * m11 - m01 * m01;
                if (fa && fb) {
                    if (det > 1e-12 * (m00 * m11) && det > 0) {
                        alpha = std::clamp((r0 * m11 - r1 * m01) / det, 0.0, 1.0);
                        beta = std::clamp((m00 * r1 - m01 * r0) / det, 0.0, 1.0);
                    }
                } else if (fa && m00 > 0) {
                    alpha = std::clamp((r0 - m01 * beta) / m00, 0.0, 1.0);
                } else if (fb && m11 > 0) {
                    beta = std::clamp((r1 - m01 * alpha) / m11, 0.0, 1.0);
                }
                const auto i1 = sideIndex(side, 0), i2 = sideIndex(side, 1);
                bp.at(i1[0], i1[1]) = {float(cornerP[c0][0] + alpha * Ta[0]),
                                       float(cornerP[c0][1] + alpha * Ta[1]),
                                       float(cornerP[c0][2] + alpha * Ta[2])};
                bp.at(i2[0], i2[1]) = {float(cornerP[c1][0] - beta * Tb[0]),
                                       float(cornerP[c1][1] - beta * Tb[1]),
                                       float(cornerP[c1][2] - beta * Tb[2])};
            }
            values.resize(fit.conditions.size());
            for (size_t k = 0; k < fit.conditions.size(); ++k) {
                const InnerFit::Condition& c = fit.conditions[k];
                const double uv[2] = {c.s, c.t};
                double P[3], Du[3], Dv[3], Duu[3], Duv[3], Dvv[3];
                surface.Evaluate(uv, patchPts.data(), desc, P, Du, Dv, Duu, Duv, Dvv);
                const double* d = c.du && c.dv ? Duv : c.du ? Du : c.dv ? Dv : P;
                values[k] = {d[0], d[1], d[2]};
            }
            fit.apply(bp, values);
        }
        patchOf[size_t(f)] = int(out.patches.size());
        out.patches.push_back(bp);
        out.patchFace.push_back(uint32_t(f));
        out.patchExact.push_back(exact ? 1 : 0);
        ++(exact ? out.exactCount : out.approxCount);
        const Place& pl = place[size_t(f)];
        out.patchBaseFace.push_back(uint32_t(pl.base));
        out.patchSubFace.push_back(pl.sub);
        out.patchUV.push_back(pl.uv);
        if (smoothST) {
            // Patch corner c is face vertex c (Bfr's quad parameterization).
            std::array<Vec2, 4> corners;
            const auto fv = L.GetFaceVertices(f);
            for (int c = 0; c < 4; ++c) {
                const P2& v = limitST[size_t(smoothST->perCorner ? L.GetFaceFVarValues(f, 0)[c] : fv[c])];
                corners[size_t(c)] = {float(v.x), float(v.y)};
            }
            out.patchST.push_back(corners);
        }
        for (size_t k = 0; k < limitValues3.size(); ++k) {
            std::array<Vec3, 4> corners;
            const auto fv = L.GetFaceVertices(f);
            for (int c = 0; c < 4; ++c) {
                const P3& v = limitValues3[k][size_t(fv[c])];
                corners[size_t(c)] = {float(v.x), float(v.y), float(v.z)};
            }
            out.patchVertexValues[k].push_back(corners);
        }
    }

    // 3. Shared boundary curves: every vertex and every edge's inner points from one patch (a regular one
    // if any), copied into all patches that use them.
    std::vector<int> vOwner(size_t(L.GetNumVertices()), -1), eOwner(size_t(L.GetNumEdges()), -1);
    for (int pass = 0; pass < 2; ++pass)  // pass 0: regular patches only
        for (int f = 0; f < nf; ++f) {
            const int p = patchOf[size_t(f)];
            if (p < 0 || (pass == 0 && !out.patchExact[size_t(p)])) continue;
            for (Index v : L.GetFaceVertices(f))
                if (vOwner[size_t(v)] < 0) vOwner[size_t(v)] = f;
            for (Index e : L.GetFaceEdges(f))
                if (eOwner[size_t(e)] < 0) eOwner[size_t(e)] = f;
        }
    for (int f = 0; f < nf; ++f) {
        const int p = patchOf[size_t(f)];
        if (p < 0) continue;
        auto fv = L.GetFaceVertices(f);
        auto fe = L.GetFaceEdges(f);
        BezierPatch& bp = out.patches[size_t(p)];
        for (int c = 0; c < 4; ++c) {
            const int of = vOwner[size_t(fv[c])];
            if (of == f) continue;
            const int oc = L.GetFaceVertices(of).FindIndex(fv[c]);
            const auto a = cornerIndex(c), b = cornerIndex(oc);
            bp.at(a[0], a[1]) = out.patches[size_t(patchOf[size_t(of)])].at(b[0], b[1]);
        }
        for (int s = 0; s < 4; ++s) {
            const int of = eOwner[size_t(fe[s])];
            if (of == f) continue;
            const int os = L.GetFaceEdges(of).FindIndex(fe[s]);
            // The owner walks the edge from its corner os; the same direction as ours if it starts at our
            // corner s.
            const bool same = L.GetFaceVertices(of)[os] == fv[s];
            const BezierPatch& op = out.patches[size_t(patchOf[size_t(of)])];
            for (int k = 0; k < 2; ++k) {
                const auto a = sideIndex(s, k), b = sideIndex(os, same ? k : 1 - k);
                bp.at(a[0], a[1]) = op.at(b[0], b[1]);
            }
        }
    }
    return out;
}

struct SubdivLimit::Impl {
    std::unique_ptr<Refiner> refiner;
    std::unique_ptr<Bfr::RefinerSurfaceFactory<>> factory;
    std::vector<double> points;
    std::vector<char> rendered;
    // Surfaces by face, built on first use.
    mutable std::vector<std::unique_ptr<Bfr::Surface<double>>> surfaces;
    mutable std::vector<std::vector<double>> patchPoints;
};

SubdivLimit::SubdivLimit(const SubdivMesh& mesh, int approxLevel) : impl_(std::make_unique<Impl>()) {
    validateSubdivMesh(mesh);
    impl_->refiner =
        makeRefiner(int(mesh.points.size()), topologyOf(mesh), mesh.boundary, mesh.chaikinCreases);
    impl_->rendered = renderedFaces(mesh, *impl_->refiner);
    Bfr::SurfaceFactory::Options o;
    o.SetApproxLevelSmooth(approxLevel);
    o.SetApproxLevelSharp(std::max(approxLevel, 6));
    impl_->factory = std::make_unique<Bfr::RefinerSurfaceFactory<>>(*impl_->refiner, o);
    for (const Vec3& p : mesh.points) impl_->points.insert(impl_->points.end(), {p.x, p.y, p.z});
    impl_->surfaces.resize(mesh.faceSizes.size());
    impl_->patchPoints.resize(mesh.faceSizes.size());
}

SubdivLimit::~SubdivLimit() = default;

bool SubdivLimit::hasLimit(int face) const {
    return face >= 0 && size_t(face) < impl_->rendered.size() && impl_->rendered[size_t(face)] &&
           impl_->factory->FaceHasLimitSurface(face);
}

bool SubdivLimit::evaluate(int face, int subFace, double s, double t, std::array<double, 3>& position,
                           std::array<double, 3>& normal) const {
    if (!hasLimit(face)) return false;
    auto& surf = impl_->surfaces[size_t(face)];
    const Bfr::Surface<double>::PointDescriptor desc(3);
    if (!surf) {
        surf = std::make_unique<Bfr::Surface<double>>();
        if (!impl_->factory->InitVertexSurface(face, surf.get())) return false;
        auto& pp = impl_->patchPoints[size_t(face)];
        pp.resize(size_t(surf->GetNumPatchPoints()) * 3);
        surf->PreparePatchPoints(impl_->points.data(), desc, pp.data(), desc);
    }
    double uv[2] = {s, t};
    const Bfr::Parameterization param = surf->GetParameterization();
    if (param.HasSubFaces()) {
        const double st[2] = {s, t};
        param.ConvertNormalizedSubFaceToCoord(std::max(subFace, 0), st, uv);
    }
    double Du[3], Dv[3];
    surf->Evaluate(uv, impl_->patchPoints[size_t(face)].data(), desc, position.data(), Du, Dv);
    const double n[3] = {Du[1] * Dv[2] - Du[2] * Dv[1], Du[2] * Dv[0] - Du[0] * Dv[2],
                         Du[0] * Dv[1] - Du[1] * Dv[0]};
    // Zero where the derivatives are (nearly) parallel: no tangent plane from them (e.g. the corner of a
    // boundary with "edges only" interpolation, where both edges follow one smooth boundary curve).
    const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    const double scale = std::sqrt((Du[0] * Du[0] + Du[1] * Du[1] + Du[2] * Du[2]) *
                                   (Dv[0] * Dv[0] + Dv[1] * Dv[1] + Dv[2] * Dv[2]));
    const bool degenerate = !(len > 1e-6 * scale);
    for (int i = 0; i < 3; ++i) normal[size_t(i)] = degenerate ? 0 : n[i] / len;
    return true;
}

namespace {

// Point and first derivatives of a bicubic Bezier patch, in double.
void bezierPoint(const BezierPatch& p, double s, double t, double P[3], double Du[3], double Dv[3]) {
    double bu[4], du[4], bv[4], dv[4];
    bernstein(s, bu, du);
    bernstein(t, bv, dv);
    for (int k = 0; k < 3; ++k) P[k] = Du[k] = Dv[k] = 0;
    for (int j = 0; j < 4; ++j)
        for (int i = 0; i < 4; ++i) {
            const Vec3 c = p.at(i, j);
            const double x[3] = {c.x, c.y, c.z};
            for (int k = 0; k < 3; ++k) {
                P[k] += bu[i] * bv[j] * x[k];
                Du[k] += du[i] * bv[j] * x[k];
                Dv[k] += bu[i] * dv[j] * x[k];
            }
        }
}

}  // namespace

SubdivDeviation subdivDeviation(const SubdivMesh& mesh, const SubdivResult& result, const SubdivLimit& limit,
                                int n) {
    SubdivDeviation d;
    std::vector<float> angles;
    Bounds3 b;
    for (const Vec3& p : mesh.points) b.extend(p);
    if (!mesh.points.empty()) {
        const Vec3 e = b.hi - b.lo;
        d.diagonal = std::sqrt(double(e.x) * e.x + double(e.y) * e.y + double(e.z) * e.z);
    }
    for (size_t i = 0; i < result.patches.size(); ++i) {
        const auto& uv = result.patchUV[i];
        const bool exact = i < result.patchExact.size() && result.patchExact[i];
        for (int a = 0; a < n; ++a)
            for (int c = 0; c < n; ++c) {
                const double s = double(a) / (n - 1), t = double(c) / (n - 1);
                // Bilinear placement on the control face.
                const double fs = (1 - s) * (1 - t) * uv[0].x + s * (1 - t) * uv[1].x + s * t * uv[2].x +
                                  (1 - s) * t * uv[3].x;
                const double ft = (1 - s) * (1 - t) * uv[0].y + s * (1 - t) * uv[1].y + s * t * uv[2].y +
                                  (1 - s) * t * uv[3].y;
                std::array<double, 3> P, N;
                if (!limit.evaluate(int(result.patchBaseFace[i]), result.patchSubFace[i], fs, ft, P, N))
                    continue;
                // The patch in double: the error of the conversion, not of float evaluation.
                double q[3], du[3], dv[3];
                bezierPoint(result.patches[i], s, t, q, du, dv);
                const double m[3] = {du[1] * dv[2] - du[2] * dv[1], du[2] * dv[0] - du[0] * dv[2],
                                     du[0] * dv[1] - du[1] * dv[0]};
                const double dx = q[0] - P[0], dy = q[1] - P[1], dz = q[2] - P[2];
                const double dist = std::sqrt(dx * dx + dy * dy + dz * dz);
                const double ml = std::sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]);
                double angle = 0;
                const double dl = std::sqrt((du[0] * du[0] + du[1] * du[1] + du[2] * du[2]) *
                                            (dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2]));
                if (ml > 1e-6 * dl && (N[0] != 0 || N[1] != 0 || N[2] != 0)) {
                    const double cosA = (m[0] * N[0] + m[1] * N[1] + m[2] * N[2]) / ml;
                    angle = std::acos(std::clamp(cosA, -1.0, 1.0)) * 180.0 / 3.14159265358979323846;
                }
                d.maxPosition = std::max(d.maxPosition, dist);
                angles.push_back(float(angle));
                if (angle > d.maxNormalDeg) {
                    d.maxNormalDeg = angle;
                    d.worstNormalPatch = i;
                    d.worstNormalST = {s, t};
                }
                if (exact) {
                    d.maxPositionExact = std::max(d.maxPositionExact, dist);
                    d.maxNormalDegExact = std::max(d.maxNormalDegExact, angle);
                }
                ++d.samples;
            }
    }
    if (!angles.empty()) {
        auto nth = angles.begin() + long(double(angles.size() - 1) * 0.999);
        std::nth_element(angles.begin(), nth, angles.end());
        d.normalDeg999 = *nth;
    }
    return d;
}

}  // namespace tessera
