// Catmull-Clark -> bicubic patches: regular faces are the exact B-spline patches, approximated faces stay
// close to the limit surface, and patches sharing an edge have bit-identical boundary control points.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <random>
#include <string>

#include "core/subdivision.h"
#include "film/image_compare.h"
#include "io/obj_reader.h"
#include "io/rib_lexer.h"
#include "io/scene_loader.h"
#include "io/subdiv_osd.h"
#include "render/render.h"
#include "test_support.h"
#include "test_util.h"

namespace tessera::test::subdivision_tests {

namespace fs = std::filesystem;

namespace {

SubdivMesh makeMesh(std::vector<Vec3> pts, std::vector<std::vector<int>> faces) {
    SubdivMesh m;
    m.points = std::move(pts);
    for (auto& f : faces) {
        m.faceSizes.push_back(int(f.size()));
        m.faceVerts.insert(m.faceVerts.end(), f.begin(), f.end());
    }
    return m;
}

SubdivMesh cube() {
    return makeMesh(
        {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1}, {-1, -1, 1}, {1, -1, 1}, {1, 1, 1}, {-1, 1, 1}},
        {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4}, {1, 2, 6, 5}, {2, 3, 7, 6}, {3, 0, 4, 7}});
}

SubdivMesh tetrahedron() {  // Aqsis subdiv1.rib: 4 triangles
    return makeMesh({{77.3773f, 0, 0}, {-38.6887f, 67.0107f, 0}, {-38.6887f, -67.0107f, 0}, {0, 0, 72.4387f}},
                    {{0, 1, 3}, {1, 2, 3}, {2, 0, 3}, {2, 1, 0}});
}

// A torus of nu x nv quads: every vertex has valence 4, so every face is regular.
SubdivMesh torus(int nu, int nv) {
    std::vector<Vec3> pts;
    std::vector<std::vector<int>> faces;
    for (int j = 0; j < nv; ++j)
        for (int i = 0; i < nu; ++i) {
            float a = 2 * 3.14159265f * i / nu, b = 2 * 3.14159265f * j / nv;
            float r = 3 + std::cos(b) + 0.1f * std::sin(3.f * a);
            pts.push_back({r * std::cos(a), r * std::sin(a), std::sin(b) + 0.2f * std::cos(2.f * a)});
        }
    auto id = [&](int i, int j) { return ((j + nv) % nv) * nu + (i + nu) % nu; };
    for (int j = 0; j < nv; ++j)
        for (int i = 0; i < nu; ++i)
            faces.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)});
    return makeMesh(pts, faces);
}

// An open, bumpy n x n grid of quads (boundary, corners of valence 2).
SubdivMesh openGrid(int n) {
    std::vector<Vec3> pts;
    std::vector<std::vector<int>> faces;
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i)
            pts.push_back({float(i), float(j), 0.3f * std::sin(1.7f * i + 0.9f * j)});
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i)
            faces.push_back(
                {j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i});
    return makeMesh(pts, faces);
}

// A closed mesh with valence 3, 5 and 6 vertices and non-quads: a pentagonal bipyramid-like shape made of
// a pentagon ring of quads capped by triangles and a pentagon.
SubdivMesh mixedMesh() {
    std::vector<Vec3> pts;
    for (int k = 0; k < 5; ++k) {
        float a = 2 * 3.14159265f * k / 5;
        pts.push_back({2 * std::cos(a), 2 * std::sin(a), -1});
    }
    for (int k = 0; k < 5; ++k) {
        float a = 2 * 3.14159265f * (k + 0.3f) / 5;
        pts.push_back({1.6f * std::cos(a), 1.6f * std::sin(a), 1});
    }
    pts.push_back({0, 0, 2.2f});
    std::vector<std::vector<int>> faces;
    faces.push_back({4, 3, 2, 1, 0});  // bottom pentagon (seen from below: counter-clockwise)
    for (int k = 0; k < 5; ++k) faces.push_back({k, (k + 1) % 5, 5 + (k + 1) % 5, 5 + k});
    for (int k = 0; k < 5; ++k) faces.push_back({5 + k, 5 + (k + 1) % 5, 10});
    return makeMesh(pts, faces);
}

Bounds3 meshBounds(const SubdivMesh& m) {
    Bounds3 b;
    for (Vec3 p : m.points) b.extend(p);
    return b;
}

// The refined mesh the converter patched (same numbering as SubdivResult::patchFace).
SubdivMesh refinedTo(const SubdivMesh& m, int level) {
    SubdivMesh r = m;
    for (int i = 0; i < level; ++i) r = refineMesh(r);
    return r;
}

struct LimitSample {
    uint32_t face;  // face of the patched level
    float u, v;
    Vec3 p;  // exact limit position
};

// Refines the patched level `extra` more times, following each face's (u, v) corners, and returns the exact
// limit positions of the refined vertices with their parameters on the patched faces.
std::vector<LimitSample> limitSamples(const SubdivMesh& patched, int extra) {
    struct Track {
        uint32_t root;
        Vec2 uv[4];
    };
    std::vector<Track> track;
    for (size_t f = 0; f < patched.faceSizes.size(); ++f)
        track.push_back({uint32_t(f), {{0, 0}, {1, 0}, {1, 1}, {0, 1}}});
    SubdivMesh m = patched;
    for (int s = 0; s < extra; ++s) {
        std::vector<Track> next;
        for (const Track& t : track) {
            Vec2 c{0.25f * (t.uv[0].x + t.uv[1].x + t.uv[2].x + t.uv[3].x),
                   0.25f * (t.uv[0].y + t.uv[1].y + t.uv[2].y + t.uv[3].y)};
            for (int k = 0; k < 4; ++k) {
                Vec2 a = t.uv[k], b = t.uv[(k + 1) % 4], d = t.uv[(k + 3) % 4];
                next.push_back(
                    {t.root, {a, {(a.x + b.x) / 2, (a.y + b.y) / 2}, c, {(a.x + d.x) / 2, (a.y + d.y) / 2}}});
            }
        }
        track = std::move(next);
        m = refineMesh(m);
    }
    std::vector<Vec3> limit = limitPositions(m);
    std::vector<LimitSample> out;
    for (size_t f = 0; f < track.size(); ++f)
        for (int k = 0; k < 4; ++k) {
            int v = m.faceVerts[4 * f + size_t(k)];
            out.push_back({track[f].root, track[f].uv[k].x, track[f].uv[k].y, limit[size_t(v)]});
        }
    return out;
}

// Closest point on the patch to p, by Gauss-Newton from (u, v), clamped to the domain.
float distanceToPatch(const BezierPatch& patch, Vec3 p, float u, float v) {
    for (int it = 0; it < 20; ++it) {
        SurfacePoint s = evalPatchDeriv(patch, u, v);
        Vec3 r = s.p - p;
        float a = dot(s.dpdu, s.dpdu), b = dot(s.dpdu, s.dpdv), c = dot(s.dpdv, s.dpdv);
        float gu = dot(r, s.dpdu), gv = dot(r, s.dpdv), det = a * c - b * b;
        if (!(std::fabs(det) > 1e-20f)) break;
        u = std::clamp(u - (c * gu - b * gv) / det, 0.f, 1.f);
        v = std::clamp(v - (a * gv - b * gu) / det, 0.f, 1.f);
    }
    return length(evalPatch(patch, u, v) - p);
}

struct ErrorReport {
    double exactMax = 0;        // parametric error of exact patches (relative to the bounding-box diagonal)
    double approxMax = 0;       // distance of limit points to the approximating patch (relative)
    double approxParamMax = 0;  // parametric error of approximated patches (relative)
    size_t exactSamples = 0, approxSamples = 0;
};

ErrorReport compareWithLimit(const SubdivMesh& mesh, const SubdivResult& r, int extra) {
    SubdivMesh patched = refinedTo(mesh, r.level);
    std::map<uint32_t, size_t> patchOf;
    for (size_t i = 0; i < r.patchFace.size(); ++i) patchOf[r.patchFace[i]] = i;
    double diag = length(meshBounds(mesh).diagonal());
    ErrorReport e;
    for (const LimitSample& s : limitSamples(patched, extra)) {
        auto it = patchOf.find(s.face);
        if (it == patchOf.end()) continue;  // a hole
        const BezierPatch& p = r.patches[it->second];
        double param = length(evalPatch(p, s.u, s.v) - s.p) / diag;
        if (r.patchExact[it->second]) {
            e.exactMax = std::max(e.exactMax, param);
            ++e.exactSamples;
        } else {
            e.approxParamMax = std::max(e.approxParamMax, param);
            e.approxMax = std::max(e.approxMax, double(distanceToPatch(p, s.p, s.u, s.v)) / diag);
            ++e.approxSamples;
        }
    }
    return e;
}

// Every patch edge whose end points are shared with another patch edge must carry bit-identical control
// points (in either direction). Returns the number of shared edges; counts mismatches in `bad`.
size_t checkWatertight(const std::vector<BezierPatch>& patches, size_t& bad, size_t& open) {
    auto bits = [](Vec3 v) {
        uint32_t b[3];
        std::memcpy(b, &v, sizeof b);
        return std::array<uint32_t, 3>{b[0], b[1], b[2]};
    };
    std::map<std::pair<std::array<uint32_t, 3>, std::array<uint32_t, 3>>, std::vector<std::array<Vec3, 4>>>
        edges;
    for (const BezierPatch& p : patches)
        for (int e = 0; e < 4; ++e) {
            Vec3 c[4];
            patchEdge(p, e, c);
            auto a = bits(c[0]), b = bits(c[3]);
            std::array<Vec3, 4> cv{c[0], c[1], c[2], c[3]};
            if (b < a) {
                std::swap(a, b);
                cv = {c[3], c[2], c[1], c[0]};
            }
            edges[{a, b}].push_back(cv);
        }
    size_t shared = 0;
    bad = open = 0;
    for (auto& [key, list] : edges) {
        if (list.size() == 1) {
            ++open;
            continue;
        }
        ++shared;
        for (size_t i = 1; i < list.size(); ++i)
            if (std::memcmp(list[i].data(), list[0].data(), sizeof(Vec3) * 4) != 0) ++bad;
    }
    return shared;
}

// Uniform cubic B-spline basis.
void bspline3(float t, float b[4]) {
    float s = 1 - t;
    b[0] = s * s * s / 6;
    b[1] = (3 * t * t * t - 6 * t * t + 4) / 6;
    b[2] = (-3 * t * t * t + 3 * t * t + 3 * t + 1) / 6;
    b[3] = t * t * t / 6;
}

}  // namespace

TEST(Subdivision, RegularFacesAreExactBSplinePatches) {
    const int nu = 8, nv = 6;
    SubdivMesh m = torus(nu, nv);
    SubdivResult r = subdivToBezier(m);
    EXPECT_EQ(r.level, 0);  // nothing to refine
    ASSERT_EQ(r.patches.size(), size_t(nu * nv));
    EXPECT_EQ(r.exactCount, r.patches.size());
    double diag = length(meshBounds(m).diagonal()), worst = 0;
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> U(0, 1);
    for (size_t p = 0; p < r.patches.size(); ++p) {
        int f = int(r.patchFace[p]), i0 = f % nu, j0 = f / nu;
        for (int s = 0; s < 30; ++s) {
            float u = U(rng), v = U(rng);
            float bu[4], bv[4];
            bspline3(u, bu);
            bspline3(v, bv);
            Vec3 ref;
            for (int b = 0; b < 4; ++b)
                for (int a = 0; a < 4; ++a) {
                    int i = (i0 - 1 + a + nu) % nu, j = (j0 - 1 + b + nv) % nv;
                    ref += m.points[size_t(j * nu + i)] * (bu[a] * bv[b]);
                }
            worst = std::max(worst, double(length(evalPatch(r.patches[p], u, v) - ref)) / diag);
        }
    }
    EXPECT_LT(worst, 1e-6);
    size_t bad, open;
    EXPECT_EQ(checkWatertight(r.patches, bad, open), size_t(2 * nu * nv));
    EXPECT_EQ(bad, 0u);
    EXPECT_EQ(open, 0u);
}

TEST(Subdivision, RefineCountsAndLimitOfRegularGrid) {
    SubdivMesh c = cube();
    SubdivMesh r1 = refineMesh(c);
    EXPECT_EQ(r1.faceSizes.size(), 24u);
    EXPECT_EQ(r1.points.size(), 8u + 12u + 6u);
    SubdivMesh t1 = refineMesh(tetrahedron());
    EXPECT_EQ(t1.faceSizes.size(), 12u);
    EXPECT_EQ(subdivToBezier(tetrahedron()).level, 2);
    EXPECT_EQ(subdivToBezier(cube()).level, 1);
    for (int k : t1.faceSizes) EXPECT_EQ(k, 4);
}

// Exact patches must match the limit surface to float precision; approximated ones within a tolerance.
// Measured (docs/inputs.md), max distance / diagonal: cube 5.3e-4, tetrahedron 7.8e-5, mixed 1.4e-4, Big Guy
// 2.2e-4.
TEST(Subdivision, PatchesFollowTheLimitSurface) {
    struct Case {
        const char* name;
        SubdivMesh mesh;
        double tolerance;  // distance limit surface -> approximating patch, relative to the bbox diagonal
    };
    SubdivMesh grid = openGrid(5);
    std::vector<Case> cases = {{"cube", cube(), 0.01},
                               {"tetrahedron", tetrahedron(), 0.01},
                               {"mixed", mixedMesh(), 0.01},
                               {"torus", torus(8, 6), 1e-6},
                               {"open grid", grid, 1e-6}};
    for (const Case& c : cases) {
        SubdivResult r = subdivToBezier(c.mesh);
        ErrorReport e = compareWithLimit(c.mesh, r, 4);
        EXPECT_GT(e.exactSamples + e.approxSamples, 0u) << c.name;
        EXPECT_LT(e.exactMax, 2e-6) << c.name;
        EXPECT_LT(e.approxMax, c.tolerance) << c.name;
        size_t bad, open;
        checkWatertight(r.patches, bad, open);
        EXPECT_EQ(bad, 0u) << c.name;
        std::printf(
            "[ limit    ] %-12s level %d: %zu exact (max %.2e), %zu approximated (max distance %.2e, "
            "parametric %.2e) of the diagonal\n",
            c.name, r.level, r.exactCount, e.exactMax, r.approxCount, e.approxMax, e.approxParamMax);
    }
}

TEST(Subdivision, ClosedMeshesAreWatertight) {
    for (const SubdivMesh& m : {cube(), tetrahedron(), mixedMesh()}) {
        SubdivResult r = subdivToBezier(m);
        size_t bad, open;
        size_t shared = checkWatertight(r.patches, bad, open);
        EXPECT_EQ(shared, 2 * r.patches.size());  // closed quad mesh: E = 2F
        EXPECT_EQ(open, 0u);
        EXPECT_EQ(bad, 0u);
    }
}

TEST(Subdivision, InterpolateBoundaryKeepsCornersAndBoundaryCurves) {
    SubdivMesh g = openGrid(4);
    SubdivResult r = subdivToBezier(g);
    // The four valence-2 corners are interpolated: each is a corner of some patch.
    for (int corner : {0, 4, 20, 24}) {
        bool found = false;
        for (const BezierPatch& p : r.patches)
            for (int k : {0, 3, 12, 15}) found |= p.cp[k] == g.points[size_t(corner)];
        EXPECT_TRUE(found) << "corner vertex " << corner;
    }
    // The boundary is the uniform cubic B-spline of the boundary polygon: at a regular boundary vertex the
    // limit is (a + 4v + b) / 6.
    Vec3 a = g.points[1], v = g.points[2], b = g.points[3];
    Vec3 lim = (a + v * 4.f + b) / 6.f;
    float best = 1e9f;
    for (const BezierPatch& p : r.patches)
        for (int k : {0, 3, 12, 15}) best = std::min(best, length(p.cp[k] - lim));
    EXPECT_LT(best, 1e-5f);
    // Without interpolation (RenderMan default), faces touching the boundary are dropped.
    g.boundary = BoundaryMode::None;
    SubdivResult none = subdivToBezier(g);
    EXPECT_EQ(none.patches.size(), 4u);  // the inner 2 x 2 faces, regular, unrefined
    EXPECT_EQ(none.level, 0);
}

TEST(Subdivision, CreasesCornersAndHoles) {
    SubdivMesh c = cube();
    SubdivResult smooth = subdivToBezier(c);
    // A crease loop around the top face.
    SubdivMesh creased = c;
    for (int k = 0; k < 4; ++k) creased.creases.push_back({4 + k, 4 + (k + 1) % 4, 10.f});
    SubdivResult cr = subdivToBezier(creased);
    ASSERT_EQ(cr.patches.size(), smooth.patches.size());
    // The crease curve interpolates the crease polygon's B-spline: the top edges bulge less than smooth.
    float topSmooth = -1e9f, topCrease = -1e9f;
    for (const BezierPatch& p : smooth.patches)
        for (Vec3 q : p.cp) topSmooth = std::max(topSmooth, q.z);
    for (const BezierPatch& p : cr.patches)
        for (Vec3 q : p.cp) topCrease = std::max(topCrease, q.z);
    EXPECT_GT(topCrease, topSmooth);  // a sharp crease keeps the top closer to the control cage (z = 1)
    size_t bad, open;
    checkWatertight(cr.patches, bad, open);
    EXPECT_EQ(bad, 0u);
    // Corner tag: the vertex is interpolated.
    SubdivMesh cornered = c;
    cornered.corners.push_back({6, 10.f});
    SubdivResult co = subdivToBezier(cornered);
    bool found = false;
    for (const BezierPatch& p : co.patches)
        for (int k : {0, 3, 12, 15}) found |= p.cp[k] == c.points[6];
    EXPECT_TRUE(found);
    // Hole: the face's patches disappear (4 children after one step).
    SubdivMesh holed = c;
    holed.holes.push_back(1);
    EXPECT_EQ(subdivToBezier(holed).patches.size(), smooth.patches.size() - 4);
    // Semi-sharp creases are reported.
    SubdivMesh semi = c;
    semi.creases.push_back({4, 5, 2.f});
    EXPECT_FALSE(subdivToBezier(semi).warnings.empty());
}

TEST(Subdivision, TopologyErrors) {
    auto faceOf = [](const SubdivMesh& m) {
        try {
            subdivToBezier(m);
        } catch (const SubdivError& e) {
            return e.face();
        }
        return -2;
    };
    SubdivMesh m = cube();
    m.faceVerts[5] = 99;  // face 1 uses a missing vertex
    EXPECT_EQ(faceOf(m), 1);
    m = cube();
    m.faceVerts[9] = m.faceVerts[8];  // face 2 repeats a vertex
    EXPECT_EQ(faceOf(m), 2);
    // A fin: three faces on one edge.
    m = makeMesh({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}}, {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}});
    EXPECT_EQ(faceOf(m), 2);
    // Flipped face: the shared edge runs the same way twice.
    m = makeMesh({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, -1, 0}}, {{0, 1, 2}, {0, 1, 3}});
    EXPECT_EQ(faceOf(m), 1);
    m = cube();
    m.faceSizes[0] = 2;
    EXPECT_THROW(subdivToBezier(m), SubdivError);
}

TEST(Subdivision, BigGuyObjIsWatertightAndClose) {
    std::string path = std::string(TESSERA_SHARED_DATA) + "/bigguy/obj/bigguy.obj";
    if (!fs::exists(path)) GTEST_SKIP() << "shared data not found";
    ObjMesh obj = parseObj(readInputFile(path), path, {});
    EXPECT_EQ(obj.mesh.points.size(), 1452u);
    EXPECT_EQ(obj.mesh.faceSizes.size(), 1450u);
    SubdivResult r = subdivToBezier(obj.mesh);
    EXPECT_EQ(r.level, 1);
    EXPECT_EQ(r.patches.size(), 4u * 1450u);
    // Faces at the 196 extraordinary vertices (valence 3:108, 5:76, 6:12) are approximated, after one step.
    EXPECT_EQ(r.approxCount, size_t(108 * 3 + 76 * 5 + 12 * 6));
    size_t bad, open;
    EXPECT_EQ(checkWatertight(r.patches, bad, open), 2 * r.patches.size());
    EXPECT_EQ(bad, 0u);
    EXPECT_EQ(open, 0u);
    ErrorReport e = compareWithLimit(obj.mesh, r, 3);
    EXPECT_LT(e.exactMax, 2e-6);
    EXPECT_LT(e.approxMax, 1e-3);
    std::printf(
        "[ limit    ] bigguy level %d: %zu exact (max %.2e), %zu approximated (max distance %.2e, "
        "parametric %.2e) of the diagonal\n",
        r.level, r.exactCount, e.exactMax, r.approxCount, e.approxMax, e.approxParamMax);
}

// ---- RIB SubdivisionMesh ----------------------------------------------------------------------

namespace {

std::string writeRibFile(const std::string& text) {
    return tessera::test::writeTestFile("scene.rib", text);
}

const char* kCubeMesh = "[4 4 4 4 4 4] [0 3 2 1 4 5 6 7 0 1 5 4 1 2 6 5 2 3 7 6 3 0 4 7]";
const char* kCubeP = "\"P\" [-1 -1 -1 1 -1 -1 1 1 -1 -1 1 -1 -1 -1 1 1 -1 1 1 1 1 -1 1 1]";

}  // namespace

TEST(SubdivisionRib, CubeTagsAndErrors) {
    std::string head = "WorldBegin\nLightSource \"ambientlight\" 1\n";
    Scene s = loadScene(
        writeRibFile(head + "SubdivisionMesh \"catmull-clark\" " + kCubeMesh + " " + kCubeP + "\nWorldEnd\n"),
        {});
    // No camera view of the mesh (the eye is inside the cube): the default level, 2.
    EXPECT_EQ(s.patches.size(), 6u * 16);
    EXPECT_EQ(s.objectCount, 1u);
    // Tags: a hole and a crease; an unknown tag warns.
    std::vector<std::string> warnings;
    s = loadScene(writeRibFile(head + "SubdivisionMesh \"catmull-clark\" " + kCubeMesh +
                               " [\"hole\" \"crease\" \"stitch\"] [1 0 2 1 0 0] [1 4 5] [10] " + kCubeP +
                               "\nWorldEnd\n"),
                  [&](const std::string& w) { warnings.push_back(w); });
    EXPECT_EQ(s.patches.size(), 5u * 16);
    bool stitch = false;
    for (const std::string& w : warnings)
        stitch |= w.find("\"stitch\" is not supported") != std::string::npos;
    EXPECT_TRUE(stitch);
    // Unsupported scheme: warned and skipped.
    warnings.clear();
    EXPECT_THROW(loadScene(writeRibFile(head + "SubdivisionMesh \"loop\" [3 3 3 3] [0 1 2 0 2 3 0 3 1 1 3 2] "
                                               "\"P\" [0 0 0 1 0 0 0 1 0 0 0 1]\nWorldEnd\n"),
                           [&](const std::string& w) { warnings.push_back(w); }),
                 InputError);  // no geometry left
    ASSERT_FALSE(warnings.empty());
    EXPECT_NE(warnings[0].find("\"loop\" is not supported"), std::string::npos);
    // Errors name the request's line.
    auto lineOf = [&](const std::string& text) {
        try {
            loadScene(writeRibFile(text), {});
        } catch (const InputError& e) {
            return e.line();
        }
        return 0;
    };
    EXPECT_EQ(
        lineOf(head +
               "\nSubdivisionMesh \"catmull-clark\" [4 4] [0 1 2 3 0 1 2] \"P\" [0 0 0 1 0 0 1 1 0 0 1 0]\n"
               "WorldEnd\n"),
        4);
    EXPECT_EQ(lineOf(head +
                     "SubdivisionMesh \"catmull-clark\" [3 3 3] [0 1 2 0 1 3 0 1 4] \"P\" [0 0 0 1 0 0 0 1 0 "
                     "0 -1 0 0 0 1]\nWorldEnd\n"),
              3);  // non-manifold edge
    EXPECT_EQ(
        lineOf(head + "SubdivisionMesh \"catmull-clark\" [4] [0 1 2 3] \"P\" [0 0 0 1 0 0]\nWorldEnd\n"), 3);
}

TEST(SubdivisionRib, AqsisRegressionScenesLoad) {
    const std::string dir = std::string(TESSERA_SHARED_DATA) + "/rib/aqsis-regression/RIBs/Subdivision/";
    if (!fs::exists(dir)) GTEST_SKIP() << "shared data not found";
    struct Expect {
        const char* file;
        size_t patches;
    };
    // The level comes from each mesh's size on screen (docs/subdivision.md). subdiv1: 4 triangles, 12 quads
    // after one step, level 4; subdiv2: 96 triangles, level 2; subdiv3: 9 quads with interpolateboundary,
    // level 4.
    for (Expect e : {Expect{"subdiv1.rib", 12 * 64}, Expect{"subdiv2.rib", 96 * 3 * 4},
                     Expect{"subdiv3.rib", 9 * 256}}) {
        Scene s = loadScene(dir + e.file, {});
        EXPECT_EQ(s.patches.size(), e.patches) << e.file;
        size_t bad, open;
        size_t shared = checkWatertight(s.patches, bad, open);
        EXPECT_EQ(bad, 0u) << e.file;
        if (std::string(e.file) != "subdiv3.rib") {  // closed meshes
            EXPECT_EQ(open, 0u) << e.file;
            EXPECT_EQ(shared, 2 * s.patches.size()) << e.file;
        }
    }
}

// ---- OpenSubdiv converter (io/subdiv_osd.h) against OpenSubdiv's limit surface (Bfr) ---------------

namespace {

// The cube with all 12 edges creased at `sharpness` (0: no crease tags).
SubdivMesh creasedCube(float sharpness) {
    SubdivMesh m = cube();
    if (sharpness > 0)
        for (auto [a, b] : std::vector<std::pair<int, int>>{{0, 1},
                                                            {1, 2},
                                                            {2, 3},
                                                            {3, 0},
                                                            {4, 5},
                                                            {5, 6},
                                                            {6, 7},
                                                            {7, 4},
                                                            {0, 4},
                                                            {1, 5},
                                                            {2, 6},
                                                            {3, 7}})
            m.creases.push_back({a, b, sharpness});
    return m;
}

// The limit point at cube corner (1, 1, 1): the patch corner closest to it.
Vec3 cornerPoint(const SubdivResult& r) {
    Vec3 best{0, 0, 0};
    for (const BezierPatch& p : r.patches)
        for (int k : {0, 3, 12, 15})
            if (length(p.cp[k] - Vec3{1, 1, 1}) < length(best - Vec3{1, 1, 1})) best = p.cp[k];
    return best;
}

void expectClosedAndWatertight(const SubdivResult& r, const std::string& what) {
    size_t bad, open;
    EXPECT_EQ(checkWatertight(r.patches, bad, open), 2 * r.patches.size()) << what;
    EXPECT_EQ(bad, 0u) << what;
    EXPECT_EQ(open, 0u) << what;
}

}  // namespace

// Sharpness 0, 1.5, 2 and infinity: the patches follow Bfr's limit surface of the control cube, position
// and normal, with the tolerances measured (docs/subdivision.md) and some margin; exact (regular) patches
// to float precision. Independent checks: the smooth corner is the Catmull-Clark limit mask's point, the
// infinitely sharp corner is the control point, and the corner moves out with the sharpness: sharpness 2
// rounds the box (the bug the hand-written converter had: it rendered a hard box).
TEST(SubdivisionOsd, CreasedCubeFollowsTheBfrLimitSurface) {
    const float inf = std::numeric_limits<float>::infinity();
    double lastCorner = 0;
    for (float sharp : {0.f, 1.5f, 2.f, inf}) {
        SCOPED_TRACE("sharpness " + std::to_string(sharp));
        const SubdivMesh m = creasedCube(sharp);
        const SubdivLimit limit(m);
        // The automatic level (2 here: no camera, sharpness at most 2) and level 4. Tolerances: the
        // measured errors (printed) with some margin; the approximated patches are the 3 faces at each of
        // the 8 valence-3 corners.
        struct Tolerance {
            int level;
            double position, normalDeg;
        };
        for (Tolerance tol : {Tolerance{-1, 4e-3, 8.0}, Tolerance{4, 1e-3, 3.0}}) {
            OsdSubdivOptions o;
            o.level = tol.level;
            const SubdivResult r = subdivideOsd(m, o);
            if (tol.level < 0) {
                EXPECT_EQ(r.level, kDefaultSubdivLevel);
            }
            EXPECT_EQ(r.patches.size(), 6u << (2 * r.level));
            const SubdivDeviation d = subdivDeviation(m, r, limit, 9);
            EXPECT_EQ(d.samples, r.patches.size() * 81);
            EXPECT_LT(d.maxPositionExact / d.diagonal, 1e-6);
            EXPECT_LT(d.maxNormalDegExact, 0.01);
            EXPECT_LT(d.relativePosition(), tol.position);
            EXPECT_LT(d.maxNormalDeg, tol.normalDeg);
            std::printf(
                "[ bfr      ] cube sharpness %g level %d: %zu exact, %zu approximated; max position %.2e "
                "of the diagonal, normal %.3f deg\n",
                sharp, r.level, r.exactCount, r.approxCount, d.relativePosition(), d.maxNormalDeg);
            expectClosedAndWatertight(r, "sharpness " + std::to_string(sharp));
        }
        const SubdivResult r = subdivideOsd(m);
        const Vec3 c = cornerPoint(r);
        if (sharp == 0) {
            // The hand-written limit mask (after one step: all quads).
            EXPECT_LT(length(c - limitPositions(refineMesh(m))[6]), 1e-5f);
        }
        if (!std::isfinite(sharp)) {
            EXPECT_LT(length(c - Vec3{1, 1, 1}), 1e-6f);
        }
        if (sharp == 2) {
            EXPECT_GT(length(c - Vec3{1, 1, 1}), 0.05f);  // rounded, not a hard box
        }
        EXPECT_GT(length(c), lastCorner);
        lastCorner = length(c);
        if (sharp == 2) {
            // The test can fail: the hand-written converter (semi-sharp treated as infinitely sharp) is far
            // from the limit surface.
            const SubdivResult old = subdivToBezier(m);
            EXPECT_GT(subdivDeviation(m, old, limit, 9).relativePosition(), 0.01);
        }
    }
}

// PRMan's "creasemethod" "chaikin": a crease chain whose sharpness varies along it (the cube's top ring at
// 1, 3, 1, 3) is subdivided by Chaikin's rule, which averages the sharpness along the chain; the patches
// follow Bfr's limit surface under that rule (as tight as the uniform rule's), the surface differs from the
// uniform rule's, and the RIB tag with PRMan's string arguments selects it.
TEST(SubdivisionOsd, ChaikinCreaseMethodFollowsItsLimitSurface) {
    SubdivMesh m = cube();
    const int ring[4][2] = {{4, 5}, {5, 6}, {6, 7}, {7, 4}};
    for (int e = 0; e < 4; ++e) m.creases.push_back({ring[e][0], ring[e][1], e % 2 ? 3.f : 1.f});
    SubdivMesh chaikin = m;
    chaikin.chaikinCreases = true;
    const SubdivResult uniform = subdivideOsd(m), blended = subdivideOsd(chaikin);
    ASSERT_EQ(uniform.patches.size(), blended.patches.size());
    const SubdivDeviation d = subdivDeviation(chaikin, blended, SubdivLimit(chaikin), 9);
    EXPECT_LT(d.relativePosition(), 4e-3);
    EXPECT_LT(d.maxNormalDeg, 8.0);
    std::printf("[ bfr      ] chaikin cube level %d: max position %.2e of the diagonal, normal %.3f deg\n",
                blended.level, d.relativePosition(), d.maxNormalDeg);
    float apart = 0;
    for (size_t i = 0; i < uniform.patches.size(); ++i)
        for (int k = 0; k < 16; ++k)
            apart = std::max(apart, length(uniform.patches[i].cp[k] - blended.patches[i].cp[k]));
    EXPECT_GT(apart, 1e-3f) << "Chaikin's rule changes the surface where the sharpness varies";
    expectClosedAndWatertight(blended, "chaikin");
    // The RIB tag (PRMan's form: 3 counts per tag and a stringargs array) selects the rule.
    const std::string rib =
        std::string("WorldBegin\nSubdivisionMesh \"catmull-clark\" ") + kCubeMesh +
        " [\"crease\" \"crease\" \"crease\" \"crease\" \"creasemethod\"]"
        " [2 1 0  2 1 0  2 1 0  2 1 0  0 0 1] [4 5 5 6 6 7 7 4] [1 3 1 3] [\"chaikin\"] " +
        kCubeP + "\nWorldEnd\n";
    const Scene s = loadScene(writeRibFile(rib), {});
    ASSERT_EQ(s.patches.size(), blended.patches.size());
    float fromRib = 0;
    for (size_t i = 0; i < s.patches.size(); ++i)
        for (int k = 0; k < 16; ++k)
            fromRib = std::max(fromRib, length(s.patches[i].cp[k] - blended.patches[i].cp[k]));
    EXPECT_LT(fromRib, 1e-5f);
    // An unknown method warns and keeps the uniform rule.
    std::vector<std::string> warnings;
    std::string bad = rib;
    bad.replace(bad.find("[\"chaikin\"]"), 11, "[\"smooth\"]");
    loadScene(writeRibFile(bad), [&](const std::string& w) { warnings.push_back(w); });
    ASSERT_FALSE(warnings.empty());
    EXPECT_NE(warnings[0].find("creasemethod"), std::string::npos) << warnings[0];
}

// A level below the sharpness (only when asked for: the automatic level resolves them) leaves semi-sharp
// features unresolved: Bfr evaluates them with its own refinement and the fitted patches follow it
// roughly (measured 2.0e-2 of the diagonal at level 1 for sharpness 2.5), still watertight.
TEST(SubdivisionOsd, UnresolvedSemiSharpCreasesStayClose) {
    const SubdivMesh m = creasedCube(2.5f);
    OsdSubdivOptions o;
    o.level = 1;
    const SubdivResult r = subdivideOsd(m, o);
    EXPECT_EQ(r.level, 1);
    const SubdivDeviation d = subdivDeviation(m, r, SubdivLimit(m), 9);
    EXPECT_LT(d.relativePosition(), 3e-2);
    expectClosedAndWatertight(r, "level 1");
}

// Corners of any sharpness, holes, the three boundary modes and non-quad faces, each against Bfr.
TEST(SubdivisionOsd, CornersHolesBoundariesAndTriangles) {
    struct Case {
        std::string name;
        SubdivMesh mesh;
        size_t patches;
        double position, normalDeg;  // tolerances
    };
    std::vector<Case> cases;
    for (float s : {1.5f, 10.f}) {
        SubdivMesh m = cube();
        m.corners.push_back({6, s});
        // An infinitely sharp corner in a smooth surface is a cone point: the patches at it are the
        // furthest off (measured 9.8e-3, 19.7 deg at level 2; sharpness 1.5: 1.9e-3, 7.3 deg).
        cases.push_back(
            {"corner " + std::to_string(s), m, 6 * 16, s < 10 ? 4e-3 : 2e-2, s < 10 ? 12.0 : 30.0});
    }
    {
        SubdivMesh m = cube();
        m.holes.push_back(1);
        cases.push_back({"hole", m, 5 * 16, 1e-3, 2.0});
    }
    for (BoundaryMode mode : {BoundaryMode::EdgesAndCorners, BoundaryMode::EdgesOnly, BoundaryMode::None}) {
        SubdivMesh g = openGrid(4);
        g.boundary = mode;
        // Edges and corners, none: all patches regular, exact. Edges only: the valence-2 corners are
        // irregular (measured 5.5e-5, 0.32 deg).
        const bool exact = mode != BoundaryMode::EdgesOnly;
        cases.push_back({"grid boundary " + std::to_string(int(mode)), g,
                         (mode == BoundaryMode::None ? 4u : 16u) * 16, exact ? 1e-6 : 2e-4,
                         exact ? 0.01 : 1.0});
    }
    cases.push_back({"tetrahedron", tetrahedron(), 12 * 4, 1e-3, 3.0});  // measured 3.7e-4, 1.4 deg
    cases.push_back({"mixed", mixedMesh(), 40 * 4, 2e-3, 3.0});          // measured 1.1e-3, 1.2 deg
    for (const Case& c : cases) {
        SCOPED_TRACE(c.name);
        const SubdivResult r = subdivideOsd(c.mesh);
        EXPECT_EQ(r.patches.size(), c.patches);
        const SubdivDeviation d = subdivDeviation(c.mesh, r, SubdivLimit(c.mesh), 9);
        EXPECT_EQ(d.samples, r.patches.size() * 81);
        EXPECT_LT(d.relativePosition(), c.position);
        EXPECT_LT(d.maxNormalDeg, c.normalDeg);
        std::printf("[ bfr      ] %-22s level %d: max position %.2e of the diagonal, normal %.3f deg\n",
                    c.name.c_str(), r.level, d.relativePosition(), d.maxNormalDeg);
        size_t bad, open;
        checkWatertight(r.patches, bad, open);
        EXPECT_EQ(bad, 0u);
    }
    // The hole's face has no patches; the infinitely sharp corner is interpolated, the 1.5 one is not.
    SubdivMesh holed = cube();
    holed.holes.push_back(1);
    for (uint32_t f : subdivideOsd(holed).patchBaseFace) EXPECT_NE(f, 1u);
    SubdivMesh cornered = cube();
    cornered.corners.push_back({6, 10.f});
    EXPECT_LT(length(cornerPoint(subdivideOsd(cornered)) - Vec3{1, 1, 1}), 1e-6f);
    cornered.corners.back().sharpness = 1.5f;
    EXPECT_GT(length(cornerPoint(subdivideOsd(cornered)) - Vec3{1, 1, 1}), 0.05f);
    // Boundary: edges and corners interpolates the valence-2 corner vertex, edges only does not.
    SubdivMesh g = openGrid(4);
    auto hasCorner = [&](const SubdivResult& r) {
        for (const BezierPatch& p : r.patches)
            for (int k : {0, 3, 12, 15})
                if (length(p.cp[k] - g.points[0]) < 1e-6f) return true;
        return false;
    };
    EXPECT_TRUE(hasCorner(subdivideOsd(g)));
    g.boundary = BoundaryMode::EdgesOnly;
    EXPECT_FALSE(hasCorner(subdivideOsd(g)));
}

TEST(SubdivisionOsd, LevelFromScreenSize) {
    const SubdivMesh c = cube();
    EXPECT_EQ(subdivLevelFor(c, 0.f), kDefaultSubdivLevel);
    EXPECT_EQ(subdivLevelFor(c, 10.f), 2);    // ~4 pixels a control face: at least level 2
    EXPECT_EQ(subdivLevelFor(c, 122.5f), 3);  // 50 pixels a control face: 6.25 at level 3
    EXPECT_EQ(subdivLevelFor(c, 2449.f), 4);  // 1000 pixels: 62.5 at level 4, the most from the screen
    EXPECT_EQ(subdivLevelFor(c, 1e6f), 4);
    EXPECT_EQ(subdivLevelFor(creasedCube(4.5f), 10.f), 5);  // semi-sharp features resolved
    EXPECT_EQ(subdivLevelFor(creasedCube(10.f), 10.f), 2);  // infinitely sharp: nothing to resolve
    OsdSubdivOptions o;
    o.level = kMaxSubdivLevel + 1;
    EXPECT_THROW(subdivideOsd(c, o), SubdivError);
}

TEST(SubdivisionOsd, BigGuyIsWatertightAndCloseToTheLimit) {
    std::string path = std::string(TESSERA_SHARED_DATA) + "/bigguy/obj/bigguy.obj";
    if (!fs::exists(path)) GTEST_SKIP() << "shared data not found";
    ObjMesh obj = parseObj(readInputFile(path), path, {});
    const SubdivResult r = subdivideOsd(obj.mesh);
    EXPECT_EQ(r.level, kDefaultSubdivLevel);
    EXPECT_EQ(r.patches.size(), 1450u * 16);
    EXPECT_EQ(r.approxCount, size_t(108 * 3 + 76 * 5 + 12 * 6));  // the faces at extraordinary vertices
    expectClosedAndWatertight(r, "bigguy");
    const SubdivLimit limit(obj.mesh);
    const SubdivDeviation d = subdivDeviation(obj.mesh, r, limit, 5);
    EXPECT_LT(d.maxPositionExact / d.diagonal, 1e-6);
    EXPECT_LT(d.relativePosition(), 5e-4);
    EXPECT_LT(d.maxNormalDeg, 10.0);
    // Better than the hand-written converter in position.
    EXPECT_LT(d.relativePosition(),
              subdivDeviation(obj.mesh, subdivToBezier(obj.mesh), limit, 5).relativePosition());
}

// Rendered in both engines, Big Guy and a creased cube have no pinholes (box filter: every pixel whose
// samples are all inside the silhouette is fully covered).
TEST(SubdivisionOsd, BigGuyAndCreasedCubeHaveNoPinholesInBothEngines) {
    const std::string bigguy = std::string(TESSERA_SOURCE_DIR) + "/scenes/bigguy.rib";
    const std::string cubeRib = writeRibFile(
        "Format 160 160 1\nPixelSamples 3 3\nPixelFilter \"box\" 1 1\nProjection \"perspective\" \"fov\" 40\n"
        "Translate 0 0 6\nRotate -30 1 0 0\nRotate 35 0 1 0\nWorldBegin\nLightSource \"ambientlight\" 1\n"
        "Surface \"matte\"\nSubdivisionMesh \"catmull-clark\" " +
        std::string(kCubeMesh) +
        " [\"crease\" \"crease\" \"corner\"] [5 1 2 1 1 1] [0 1 2 3 0 4 5 6] [2 10 3] " + kCubeP +
        "\nWorldEnd\n");
    for (const std::string& file : {bigguy, cubeRib}) {
        Scene s = loadScene(file, {});
        s.camera.width = s.camera.height = 160;
        s.image.filter = FilterType::Box;
        s.image.filterWidthX = s.image.filterWidthY = 1;
        s.image.pixelSamplesX = s.image.pixelSamplesY = 3;
        for (const char* engine : {"reyes", "rt"}) {
            SCOPED_TRACE(file + " " + engine);
            RenderSettings rs;
            rs.engine = engine;
            rs.threads = 2;
            const Image img = render(s, rs).image;
            EXPECT_EQ(tessera::test::countPinholes(img, 1.f), 0);
            double covered = 0;
            for (int y = 0; y < img.height; ++y)
                for (int x = 0; x < img.width; ++x) covered += img.pixel(x, y)[3];
            EXPECT_GT(covered, 2000.0);
        }
    }
}

// "st" on a SubdivisionMesh: "facevarying" (per face corner) and "varying" (per vertex) are interpolated
// linearly over each face, as RenderMan does; "facevertex" and "vertex" smoothly. On a flat, evenly spaced
// grid the limit surface is the bilinear map of each face, so s, t at every patch corner must be the
// corner's own x / 4, y / 4 for all four classes.
TEST(SubdivisionRib, FaceVaryingAndVaryingStFollowEachFace) {
    auto append = [](std::string& to, auto x) {  // (not " " + to_string(): a g++ 12 -Wrestrict false alarm)
        to += ' ';
        to += std::to_string(x);
    };
    std::string P, nverts, verts, stVertex, stCorner;
    const int n = 4;
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) {
            append(P, i);
            append(P, j);
            append(P, 0);
            append(stVertex, i / 4.0);
            append(stVertex, j / 4.0);
        }
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            nverts += " 4";
            for (auto [a, b] :
                 std::vector<std::pair<int, int>>{{i, j}, {i + 1, j}, {i + 1, j + 1}, {i, j + 1}}) {
                append(verts, b * (n + 1) + a);
                append(stCorner, a / 4.0);
                append(stCorner, b / 4.0);
            }
        }
    std::string facevarying = "\"facevarying float[2] st\" [", varying = "\"varying float[2] st\" [";
    facevarying += stCorner + "]";
    varying += stVertex + "]";
    // The smooth classes too: the limit of a linear function on a regular planar grid (with the boundary
    // and its corners interpolated) is the same linear function.
    const std::string facevertex = "\"facevertex float[2] st\" [" + stCorner + "]",
                      vertex = "\"vertex float[2] st\" [" + stVertex + "]";
    for (const std::string& st : {facevarying, varying, facevertex, vertex}) {
        SCOPED_TRACE(st.substr(0, 22));
        Scene s = loadScene(
            writeRibFile("WorldBegin\nSubdivisionMesh \"catmull-clark\" [" + nverts + "] [" + verts +
                         "] [\"interpolateboundary\"] [0 0] [] [] \"P\" [" + P + "] " + st + "\nWorldEnd\n"),
            {});
        ASSERT_EQ(s.patches.size(), 16u * 16);
        ASSERT_EQ(s.texCoords.size(), s.patches.size());
        float worst = 0;
        for (size_t i = 0; i < s.patches.size(); ++i) {
            const int cpIndex[4] = {0, 3, 12, 15};  // PatchTexCoords order: (0,0) (1,0) (0,1) (1,1)
            for (int k = 0; k < 4; ++k) {
                const Vec3 c = s.patches[i].cp[cpIndex[k]];
                const Vec2 t = s.texCoords[i].st[k];
                worst = std::max({worst, std::fabs(t.x - c.x / 4), std::fabs(t.y - c.y / 4)});
            }
        }
        EXPECT_LT(worst, 1e-5f);
    }
}

// Deformation keys of a SubdivisionMesh share the first key's level even when their sizes on screen would
// choose others (the second key here is 8 times larger): every key has the same patches.
TEST(SubdivisionRib, DeformationKeysShareTheFirstKeysLevel) {
    std::string big = "\"P\" [";
    for (int v = 0; v < 8; ++v)
        for (int k = 0; k < 3; ++k) big += (v >> (k == 0 ? 0 : k == 1 ? 1 : 2)) & 1 ? " 8" : " -8";
    big += "]";
    const std::string mesh = std::string("SubdivisionMesh \"catmull-clark\" ") + kCubeMesh + " ";
    Scene s =
        loadScene(writeRibFile("Format 200 200 1\nProjection \"perspective\" \"fov\" 40\nTranslate 0 0 30\n"
                               "Shutter 0 1\nWorldBegin\nMotionBegin [0 1]\n" +
                               mesh + kCubeP + "\n" + mesh + big + "\nMotionEnd\nWorldEnd\n"),
                  {});
    EXPECT_EQ(s.patches.size(), 6u * 16);  // level 2 from the first key (8 pixels a control face); the
                                           // second alone would be level 4
}

// A crease between vertices no edge joins is ignored with a warning (not OpenSubdiv's own printout).
TEST(SubdivisionOsd, CreaseOffTheMeshIsWarnedAndIgnored) {
    SubdivMesh m = cube();
    m.creases.push_back({0, 6, 10.f});  // a diagonal of the cube
    const SubdivResult r = subdivideOsd(m), smooth = subdivideOsd(cube());
    ASSERT_EQ(r.warnings.size(), 1u);
    EXPECT_NE(r.warnings[0].find("crease (0, 6) is not an edge"), std::string::npos);
    ASSERT_EQ(r.patches.size(), smooth.patches.size());
    for (size_t i = 0; i < r.patches.size(); ++i)
        EXPECT_EQ(std::memcmp(r.patches[i].cp, smooth.patches[i].cp, sizeof r.patches[i].cp), 0);
}

// ---- the level follows the rendered resolution (issue 16) -------------------------------------------

namespace {

// The larger side, in raster pixels of a width x height render, of the projected bounding box of the cube
// of kCubeP seen by `camera` (an independent recomputation of what the reader chooses a level from).
float cubeRasterSize(Camera camera, int width, int height) {
    camera.width = width, camera.height = height;
    Bounds3 b;
    for (int v = 0; v < 8; ++v)
        b.extend(camera.cameraFromWorld.point({v & 1 ? 1.f : -1.f, v & 2 ? 1.f : -1.f, v & 4 ? 1.f : -1.f}));
    float x0, x1, y0, y1;
    EXPECT_TRUE(Projector(camera).rasterBounds(b, x0, x1, y0, y1));
    return std::max(x1 - x0, y1 - y0);
}

int levelOfCubePatches(size_t patches) {
    int level = 0;
    for (size_t n = 6; n < patches; n *= 4) ++level;
    EXPECT_EQ(size_t(6) << (2 * level), patches) << "not 6 * 4^level patches";
    return level;
}

}  // namespace

// A RIB loaded for the resolution it will be rendered at (the CLI's --res, RasterOverride) refines its
// SubdivisionMesh for that size: the cube is 18 pixels wide in the file's 200 x 200 Format (level 2) and
// 147 wide at 1600 x 1600 (level 3). A crop window does not change the level (the full frame counts).
TEST(SubdivisionRib, LevelFollowsTheRenderedResolution) {
    const std::string mesh = std::string("SubdivisionMesh \"catmull-clark\" ") + kCubeMesh + " " + kCubeP;
    for (const std::string crop : {"", "CropWindow 0.4 0.6 0.4 0.6\n"}) {
        SCOPED_TRACE(crop);
        const std::string file = writeRibFile(
            "Format 200 200 1\n" + crop +
            "Projection \"perspective\" \"fov\" 40\nTranslate 0 0 30\nWorldBegin\n" + mesh + "\nWorldEnd\n");
        const Scene fileFormat = loadScene(file, {});
        const Scene at200 = loadScene(file, {}, SceneFormat::Auto, std::nullopt, RasterOverride{200, 200});
        const Scene at1600 = loadScene(file, {}, SceneFormat::Auto, std::nullopt, RasterOverride{1600, 1600});
        EXPECT_EQ(at1600.camera.width, 200)
            << "the camera keeps the file's Format (the caller applies --res)";
        const int level200 = levelOfCubePatches(at200.patches.size());
        const int level1600 = levelOfCubePatches(at1600.patches.size());
        EXPECT_EQ(fileFormat.patches.size(), at200.patches.size());
        EXPECT_EQ(level200, subdivLevelFor(cube(), cubeRasterSize(fileFormat.camera, 200, 200)));
        EXPECT_EQ(level1600, subdivLevelFor(cube(), cubeRasterSize(fileFormat.camera, 1600, 1600)));
        EXPECT_EQ(level200, 2);
        EXPECT_EQ(level1600, 3);
        // Another aspect ratio: the default screen window follows it, as the render's does.
        const Scene wide = loadScene(file, {}, SceneFormat::Auto, std::nullopt, RasterOverride{3200, 800});
        EXPECT_EQ(levelOfCubePatches(wide.patches.size()),
                  subdivLevelFor(cube(), cubeRasterSize(fileFormat.camera, 3200, 800)));
    }
}

// ---- smooth texture coordinates (vertex and facevertex s, t) -----------------------------------------

namespace {

// A linear function of position: subdivision is affine invariant, so vertex s, t that are this function
// of the control points are this function of the limit surface everywhere, in particular at every patch
// corner (whose control point is the limit position there).
Vec2 linearST(Vec3 p) {
    return {0.5f * p.x - 0.25f * p.y + 0.1f, 0.3f * p.z + 0.2f * p.x};
}

// Largest difference between each patch corner's s, t and linearST of the corner's position.
float worstLinearST(const SubdivResult& r) {
    float worst = 0;
    for (size_t i = 0; i < r.patches.size(); ++i)
        for (int c = 0; c < 4; ++c) {
            const Vec3 p = r.patches[i].at(c == 1 || c == 2 ? 3 : 0, c >= 2 ? 3 : 0);
            const Vec2 want = linearST(p), got = r.patchST[i][size_t(c)];
            worst = std::max({worst, std::fabs(got.x - want.x), std::fabs(got.y - want.y)});
        }
    return worst;
}

SubdivSmoothTexCoords linearTexCoords(const SubdivMesh& m, bool perCorner) {
    SubdivSmoothTexCoords t;
    t.perCorner = perCorner;
    if (perCorner)
        for (int v : m.faceVerts) t.values.push_back(linearST(m.points[size_t(v)]));
    else
        for (const Vec3& p : m.points) t.values.push_back(linearST(p));
    return t;
}

}  // namespace

// Vertex s, t are the limit of the control values: on a cube (extraordinary vertices), the mixed mesh (a
// pentagon and triangles) and an open bumpy grid, a linear function of the control points gives the same
// function of the limit position at every patch corner. Face-vertex s, t without seams on a closed mesh
// are the same surface values (no face-varying boundary anywhere) for every boundary rule.
TEST(SubdivisionOsd, VertexTexCoordsAreTheLimitOfTheControlValues) {
    for (const auto& [name, mesh] : std::vector<std::pair<std::string, SubdivMesh>>{
             {"cube", cube()}, {"mixed", mixedMesh()}, {"grid", openGrid(4)}}) {
        SCOPED_TRACE(name);
        for (int level : {1, 2, 3}) {
            OsdSubdivOptions o;
            o.level = level;
            const SubdivSmoothTexCoords st = linearTexCoords(mesh, false);
            o.texCoords = &st;
            const SubdivResult r = subdivideOsd(mesh, o);
            ASSERT_EQ(r.patchST.size(), r.patches.size());
            EXPECT_LT(worstLinearST(r), 2e-5f) << "level " << level;
        }
    }
    const SubdivMesh c = cube();
    const SubdivSmoothTexCoords vertex = linearTexCoords(c, false);
    OsdSubdivOptions o;
    o.texCoords = &vertex;
    const SubdivResult byVertex = subdivideOsd(c, o);
    for (FaceVaryingBoundary b : {FaceVaryingBoundary::LinearAll, FaceVaryingBoundary::CornersPlus1,
                                  FaceVaryingBoundary::Smooth, FaceVaryingBoundary::LinearBoundaries}) {
        SubdivSmoothTexCoords corner = linearTexCoords(c, true);
        corner.boundary = b;
        o.texCoords = &corner;
        const SubdivResult byCorner = subdivideOsd(c, o);
        ASSERT_EQ(byCorner.patchST.size(), byVertex.patchST.size());
        float worst = 0;
        for (size_t i = 0; i < byCorner.patchST.size(); ++i)
            for (int k = 0; k < 4; ++k)
                worst = std::max({worst, std::fabs(byCorner.patchST[i][k].x - byVertex.patchST[i][k].x),
                                  std::fabs(byCorner.patchST[i][k].y - byVertex.patchST[i][k].y)});
        if (b == FaceVaryingBoundary::LinearAll)
            EXPECT_GT(worst, 1e-2f) << "linear everywhere is bilinear per face, not the smooth surface";
        else
            EXPECT_LT(worst, 1e-5f) << "boundary rule " << int(b);
    }
    SubdivSmoothTexCoords wrong = linearTexCoords(c, false);
    wrong.values.pop_back();
    o.texCoords = &wrong;
    EXPECT_THROW(subdivideOsd(c, o), SubdivError);
}

// Face-vertex s, t with a seam: around a torus s runs 0 .. 1 and the faces of the last column give their
// far corners s = 1 where the first column's start at 0 (and t likewise around the tube). The seam keeps
// both values (the patches on either side meet at the same points with s = 0 on one side and 1 on the
// other) and t stays continuous across it; away from the seam s is strictly between 0 and 1.
TEST(SubdivisionOsd, FaceVertexTexCoordsKeepTheirSeams) {
    const int nu = 8, nv = 6;
    const SubdivMesh m = torus(nu, nv);
    for (FaceVaryingBoundary b : {FaceVaryingBoundary::CornersPlus1, FaceVaryingBoundary::Smooth,
                                  FaceVaryingBoundary::LinearBoundaries}) {
        SCOPED_TRACE(int(b));
        SubdivSmoothTexCoords st;
        st.perCorner = true;
        st.boundary = b;
        for (size_t f = 0; f < m.faceSizes.size(); ++f) {
            const int i = int(f) % nu, j = int(f) / nu;
            const int ci[4] = {i, i + 1, i + 1, i}, cj[4] = {j, j, j + 1, j + 1};
            for (int k = 0; k < 4; ++k) st.values.push_back({float(ci[k]) / nu, float(cj[k]) / nv});
        }
        OsdSubdivOptions o;
        o.texCoords = &st;
        const SubdivResult r = subdivideOsd(m, o);
        // s at the seam: the corners whose control point lies on the seam's limit curve (angle 0: y = 0,
        // x > 0; the torus is symmetric about the xz plane only approximately, so select by s itself).
        std::map<std::pair<float, float>, std::vector<Vec2>> atPoint;  // (x, z) of seam corners -> s, t
        size_t seamCorners = 0, inner = 0;
        for (size_t i = 0; i < r.patches.size(); ++i)
            for (int c = 0; c < 4; ++c) {
                const Vec2 v = r.patchST[i][size_t(c)];
                const Vec3 p = r.patches[i].at(c == 1 || c == 2 ? 3 : 0, c >= 2 ? 3 : 0);
                if (v.x < 1e-6f || v.x > 1 - 1e-6f) {
                    ++seamCorners;
                    EXPECT_LT(std::fabs(v.x - std::round(v.x)), 1e-6f);
                    atPoint[{p.x, p.z}].push_back(v);
                } else {
                    ++inner;
                    EXPECT_GT(v.x, 0.f);
                    EXPECT_LT(v.x, 1.f);
                }
            }
        EXPECT_GT(seamCorners, 0u);
        EXPECT_GT(inner, seamCorners);
        for (const auto& [point, values] : atPoint) {
            bool zero = false, one = false;
            for (const Vec2& v : values) {
                (v.x < 0.5f ? zero : one) = true;
                // t is continuous across the s seam (up to its own seam, t = 0 | 1, where they cross)
                const float dt = std::fabs(v.y - values.front().y);
                EXPECT_LT(std::min(dt, std::fabs(1 - dt)), 1e-5f) << "t continuous across the seam";
            }
            EXPECT_TRUE(zero && one) << "both sides of the seam at (" << point.first << ", " << point.second
                                     << ")";
        }
    }
}

namespace {

// The cube with face-corner s, t = linearST of each corner's point, of `cls`, and `tags` ("" or a tag block).
std::string cubeWithST(const std::string& cls, const std::string& tags) {
    std::string st = "\"";
    st += cls;
    st += " float[2] st\" [";
    const SubdivMesh c = cube();
    const bool perCorner = cls == "facevarying" || cls == "facevertex";
    const size_t n = perCorner ? c.faceVerts.size() : c.points.size();
    for (size_t k = 0; k < n; ++k) {
        const Vec2 v = linearST(c.points[size_t(perCorner ? c.faceVerts[k] : int(k))]);
        for (float x : {v.x, v.y}) {  // (not " " + to_string(): a g++ 12 -Wrestrict false alarm)
            st += ' ';
            st += std::to_string(x);
        }
    }
    return std::string("SubdivisionMesh \"catmull-clark\" ") + kCubeMesh + " " + tags + " " + kCubeP + " " +
           st + "]";
}

float worstSTDifference(const Scene& a, const Scene& b) {
    EXPECT_EQ(a.texCoords.size(), b.texCoords.size());
    float worst = 0;
    for (size_t i = 0; i < std::min(a.texCoords.size(), b.texCoords.size()); ++i)
        for (int k = 0; k < 4; ++k)
            worst = std::max({worst, std::fabs(a.texCoords[i].st[k].x - b.texCoords[i].st[k].x),
                              std::fabs(a.texCoords[i].st[k].y - b.texCoords[i].st[k].y)});
    return worst;
}

}  // namespace

// The RIB classes and the "facevaryinginterpolateboundary" tag: "facevertex" s, t with the tag's 0
// (linear everywhere) are the "facevarying" (bilinear) ones; 2 (smooth) are the "vertex" ones, which are
// linearST of the patch corners; a value outside 0..3 is an error naming the line.
TEST(SubdivisionRib, FaceVaryingInterpolateBoundaryTag) {
    auto loadMesh = [](const std::string& mesh) {
        std::vector<std::string> warnings;
        Scene s = loadScene(writeRibFile("WorldBegin\n" + mesh + "\nWorldEnd\n"),
                            [&](const std::string& w) { warnings.push_back(w); });
        for (const std::string& w : warnings)
            EXPECT_EQ(w.find("\"st\""), std::string::npos) << "no warning about st: " << w;
        EXPECT_EQ(s.texCoords.size(), s.patches.size());
        return s;
    };
    const std::string tag = "[\"facevaryinginterpolateboundary\"] [1 0] ";
    const Scene bilinear = loadMesh(cubeWithST("facevarying", ""));
    const Scene linearAll = loadMesh(cubeWithST("facevertex", tag + "[0] []"));
    const Scene smooth = loadMesh(cubeWithST("facevertex", tag + "[2] []"));
    const Scene byDefault = loadMesh(cubeWithST("facevertex", ""));
    const Scene vertex = loadMesh(cubeWithST("vertex", ""));
    EXPECT_LT(worstSTDifference(linearAll, bilinear), 1e-5f);
    EXPECT_LT(worstSTDifference(smooth, vertex), 1e-5f);
    EXPECT_LT(worstSTDifference(byDefault, vertex), 1e-5f);  // no seams, no corners: the smooth surface
    EXPECT_GT(worstSTDifference(smooth, bilinear), 1e-2f);
    float worst = 0;  // vertex s, t: linearST of each patch corner's (limit) point
    const int cpIndex[4] = {0, 3, 12, 15};
    for (size_t i = 0; i < vertex.patches.size(); ++i)
        for (int k = 0; k < 4; ++k) {
            const Vec2 want = linearST(vertex.patches[i].cp[cpIndex[k]]), got = vertex.texCoords[i].st[k];
            worst = std::max({worst, std::fabs(got.x - want.x), std::fabs(got.y - want.y)});
        }
    EXPECT_LT(worst, 2e-5f);
    const std::string bad =
        writeRibFile("WorldBegin\n" + cubeWithST("facevertex", tag + "[7] []") + "\nWorldEnd\n");
    try {
        loadScene(bad, {});
        ADD_FAILURE() << "facevaryinginterpolateboundary 7 loaded";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find(bad + ":2: error:"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("facevaryinginterpolateboundary"), std::string::npos);
    }
}

// A textured subdivision mesh (smooth "vertex" s, t) renders alike in both engines: the texture's tiles
// follow the converted s, t the same way (the textured teapot's bar, 35 dB), and the texture shows.
TEST(SubdivisionRib, TexturedMeshRendersAlikeInBothEngines) {
    const std::string texture = std::string(TESSERA_SOURCE_DIR) + "/scenes/textures/tiles.png";
    Scene s =
        loadScene(writeRibFile("Format 160 160 1\nPixelSamples 3 3\nProjection \"perspective\" \"fov\" 35\n"
                               "Translate 0 0 6\nRotate -30 1 0 0\nRotate 35 0 1 0\nWorldBegin\n"
                               "LightSource \"ambientlight\" 1 \"intensity\" 0.3\n"
                               "LightSource \"distantlight\" 2 \"from\" [1 2 -3] \"to\" [0 0 0]\n"
                               "Surface \"paintedplastic\" \"texturename\" \"" +
                               texture + "\" \"Ka\" 1 \"Kd\" 0.8 \"Ks\" 0\n" + cubeWithST("vertex", "") +
                               "\nWorldEnd\n"),
                  {});
    RenderSettings rs;
    rs.threads = 2;
    rs.engine = "reyes";
    const Image reyes = render(s, rs).image;
    rs.engine = "rt";
    const Image rt = render(s, rs).image;
    const ImageDiff d = compareImages(reyes, rt);
    std::printf("textured subdivision cube 160x160 9 spp, Reyes vs rt: PSNR %.2f dB, alpha mismatch %.4f\n",
                d.psnrColor, d.alphaMismatch);
    EXPECT_GE(d.psnrColor, 35.0);
    EXPECT_LT(d.alphaMismatch, 0.01);
    // The texture shows: the covered pixels' red channel varies (tiles and grout), not one shade per face.
    double sum = 0, sum2 = 0, n = 0;
    for (int y = 0; y < rt.height; ++y)
        for (int x = 0; x < rt.width; ++x)
            if (rt.pixel(x, y)[3] > 0.99f) {
                const double r = rt.pixel(x, y)[0];
                sum += r, sum2 += r * r, n += 1;
            }
    ASSERT_GT(n, 1000.0);
    EXPECT_GT(std::sqrt(std::max(0.0, sum2 / n - (sum / n) * (sum / n))), 0.05);
}

// ---- Cs and N on subdivision meshes ----------------------------------------------------------------

namespace {

Vec3 linearColor(Vec3 p) {
    return {0.5f + 0.2f * p.x, 0.5f + 0.15f * p.y - 0.1f * p.z, 0.6f + 0.3f * p.z};
}

// The cube with "Cs" of `cls` (and "N" = the control point itself, class vertex, when `normals`).
std::string cubeWithColors(const std::string& cls, bool normals) {
    const SubdivMesh c = cube();
    std::string cs = "\"";
    cs += cls;
    cs += " color Cs\" [";
    auto add = [](std::string& to, Vec3 v) {  // (not " " + to_string(): a g++ 12 -Wrestrict false alarm)
        for (float x : {v.x, v.y, v.z}) {
            to += ' ';
            to += std::to_string(x);
        }
    };
    if (cls == "uniform")
        for (size_t f = 0; f < c.faceSizes.size(); ++f) add(cs, {0.1f * float(f), 0.5f, 1 - 0.1f * float(f)});
    else if (cls == "constant")
        add(cs, {0.2f, 0.4f, 0.6f});
    else if (cls == "facevarying" || cls == "facevertex")
        for (int v : c.faceVerts) add(cs, linearColor(c.points[size_t(v)]));
    else
        for (const Vec3& p : c.points) add(cs, linearColor(p));
    cs += "]";
    std::string n;
    if (normals) {
        n = " \"vertex normal N\" [";
        for (const Vec3& p : c.points) add(n, p);
        n += "]";
    }
    return std::string("SubdivisionMesh \"catmull-clark\" ") + kCubeMesh + " " + kCubeP + " " + cs + n;
}

Scene loadCube(const std::string& mesh, std::vector<std::string>* warnings = nullptr) {
    return loadScene(writeRibFile("WorldBegin\nLightSource \"ambientlight\" 1\n" + mesh + "\nWorldEnd\n"),
                     [&](const std::string& w) {
                         if (warnings) warnings->push_back(w);
                     });
}

}  // namespace

// Vertex "Cs" and "N" are refined with the surface: a colour that is a linear function of the control
// points is that function of every patch corner's limit position, and normals equal to the control points
// are the corner's limit position (affine invariance). Varying and facevarying colours are linear over each
// control face (the same values either way); uniform and constant ones colour whole patches.
TEST(SubdivisionRib, ColorsAndNormalsFollowTheirClasses) {
    const int cpIndex[4] = {0, 3, 12, 15};  // PatchVertexValues order: (0,0) (1,0) (0,1) (1,1)
    {
        std::vector<std::string> warnings;
        const Scene s = loadCube(cubeWithColors("vertex", true), &warnings);
        EXPECT_TRUE(warnings.empty()) << warnings.front();
        ASSERT_EQ(s.patches.size(), 6u * 16);
        float worstColor = 0, worstNormal = 0;
        for (size_t i = 0; i < s.patches.size(); ++i) {
            ASSERT_GE(s.attributes[i].vertexValues, 0);
            const PatchVertexValues& vv = s.vertexValues[size_t(s.attributes[i].vertexValues)];
            ASSERT_TRUE(vv.hasCs && vv.hasN);
            EXPECT_EQ(s.materials[s.attributes[i].material].Cs, (Color{1, 1, 1}));  // multiplied by vv.Cs
            for (int k = 0; k < 4; ++k) {
                const Vec3 p = s.patches[i].cp[cpIndex[k]], want = linearColor(p);
                worstColor = std::max({worstColor, std::fabs(vv.Cs[k].x - want.x),
                                       std::fabs(vv.Cs[k].y - want.y), std::fabs(vv.Cs[k].z - want.z)});
                worstNormal = std::max(worstNormal, length(vv.N[k] - p));
            }
        }
        EXPECT_LT(worstColor, 1e-5f);
        EXPECT_LT(worstNormal, 1e-5f);
    }
    {
        const Scene varying = loadCube(cubeWithColors("varying", false)),
                    facevarying = loadCube(cubeWithColors("facevarying", false)),
                    smooth = loadCube(cubeWithColors("vertex", false));
        float worst = 0, smoothVsLinear = 0;
        for (size_t i = 0; i < varying.patches.size(); ++i) {
            const PatchVertexValues &a = varying.vertexValues[size_t(varying.attributes[i].vertexValues)],
                                    &b = facevarying
                                             .vertexValues[size_t(facevarying.attributes[i].vertexValues)],
                                    &c = smooth.vertexValues[size_t(smooth.attributes[i].vertexValues)];
            EXPECT_FALSE(a.hasN);
            for (int k = 0; k < 4; ++k) {
                worst = std::max(worst, length(a.Cs[k] - b.Cs[k]));
                smoothVsLinear = std::max(smoothVsLinear, length(a.Cs[k] - c.Cs[k]));
            }
        }
        EXPECT_LT(worst, 1e-6f);
        EXPECT_GT(smoothVsLinear, 1e-2f) << "linear over each face is not the smooth surface";
    }
    {
        const Scene s = loadCube(cubeWithColors("uniform", false));
        ASSERT_EQ(s.patches.size(), 6u * 16);
        for (size_t i = 0; i < s.patches.size(); ++i) {
            const float f = float(i / 16);  // level 2: the 16 patches of control face f, in order
            EXPECT_EQ(s.attributes[i].vertexValues, -1);
            const Color c = s.materials[s.attributes[i].material].Cs;
            EXPECT_NEAR(c.x, 0.1f * f, 1e-6f);
            EXPECT_NEAR(c.z, 1 - 0.1f * f, 1e-6f);
        }
        const Scene k = loadCube(cubeWithColors("constant", false));
        for (size_t i = 0; i < k.patches.size(); ++i)
            EXPECT_EQ(k.materials[k.attributes[i].material].Cs, (Color{0.2f, 0.4f, 0.6f}));
    }
    std::vector<std::string> warnings;
    loadCube(cubeWithColors("facevertex", false), &warnings);
    ASSERT_EQ(warnings.size(), 1u);
    EXPECT_NE(warnings[0].find("facevertex is interpolated linearly"), std::string::npos) << warnings[0];
}

// A subdivision mesh with vertex colours renders alike in both engines.
TEST(SubdivisionRib, VertexColorsRenderAlikeInBothEngines) {
    Scene s =
        loadScene(writeRibFile("Format 160 160 1\nPixelSamples 3 3\nProjection \"perspective\" \"fov\" 35\n"
                               "Translate 0 0 6\nRotate -30 1 0 0\nRotate 35 0 1 0\nWorldBegin\n"
                               "LightSource \"ambientlight\" 1 \"intensity\" 0.3\n"
                               "LightSource \"distantlight\" 2 \"from\" [1 2 -3] \"to\" [0 0 0]\n"
                               "Surface \"matte\"\n" +
                               cubeWithColors("vertex", false) + "\nWorldEnd\n"),
                  {});
    RenderSettings rs;
    rs.threads = 2;
    rs.engine = "reyes";
    const Image reyes = render(s, rs).image;
    rs.engine = "rt";
    const Image rt = render(s, rs).image;
    const ImageDiff d = compareImages(reyes, rt);
    std::printf("vertex-coloured subdivision cube 160x160 9 spp, Reyes vs rt: PSNR %.2f dB\n", d.psnrColor);
    EXPECT_GE(d.psnrColor, 35.0);
    EXPECT_LT(d.alphaMismatch, 0.01);
}

}  // namespace tessera::test::subdivision_tests
