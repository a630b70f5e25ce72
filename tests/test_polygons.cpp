// RIB Polygon, GeneralPolygon, PointsPolygons and PointsGeneralPolygons (RI spec 3.2, sec. 5.1), read as
// bilinear patches (convex quadrilaterals) and triangles of an ear-clipping triangulation (holes bridged
// into the outer loop): coverage against the exact polygon (point in polygon), meshes without pinholes in
// both engines, texture coordinates, and the reader's errors.
#include <gtest/gtest.h>

#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "render/render.h"
#include "rib_test_util.h"
#include "test_util.h"

namespace tessera::test::polygons_tests {
namespace {

struct P2 {
    double x, y;
};

// Crossing-number point-in-polygon test (independent of the reader's triangulation).
bool insidePolygon(const std::vector<P2>& poly, double x, double y) {
    bool in = false;
    for (size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++)
        if ((poly[i].y > y) != (poly[j].y > y) &&
            x < (poly[j].x - poly[i].x) * (y - poly[i].y) / (poly[j].y - poly[i].y) + poly[i].x)
            in = !in;
    return in;
}

std::string polygonRib(const std::vector<P2>& poly, double z) {
    std::ostringstream rib;
    rib << "Polygon \"P\" [";
    for (const P2& p : poly) rib << " " << p.x << " " << p.y << " " << z;
    rib << " ]";
    return rib.str();
}

// `s` rendered by `engine` ("reyes" or "rt") on 2 threads.
Image renderIn(const Scene& s, const char* engine) {
    RenderSettings rs;
    rs.engine = engine;
    rs.threads = 2;
    return render(s, rs).image;
}

// Renders `s` in both engines and checks every pixel whose 3x3 neighbourhood the exact coverage `truth`
// says is fully inside (outside) is covered (empty), and the covered area against the exact one.
void expectCoverage(const Scene& s, const std::vector<double>& truth, int res, double areaTolerance = 0.01) {
    double truthSum = 0;
    for (double t : truth) truthSum += t;
    for (const char* engine : {"reyes", "rt"}) {
        SCOPED_TRACE(engine);
        const Image img = renderIn(s, engine);
        double sum = 0;
        int wrong = 0;
        for (int y = 0; y < res; ++y)
            for (int x = 0; x < res; ++x) {
                const float a = alphaAt(img, x, y);
                sum += a;
                bool allIn = true, allOut = true;
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dx = -1; dx <= 1; ++dx) {
                        const double t = truth[size_t(std::clamp(y + dy, 0, res - 1)) * res +
                                               std::clamp(x + dx, 0, res - 1)];
                        allIn = allIn && t == 1.0;
                        allOut = allOut && t == 0.0;
                    }
                wrong += (allIn && a < 0.999f) || (allOut && a > 0.f);
            }
        EXPECT_EQ(wrong, 0);
        EXPECT_NEAR(sum, truthSum, areaTolerance * truthSum) << "area";
    }
}

TEST(Polygons, ConcavePolygonsCoverExactlyTheirArea) {
    std::vector<std::vector<P2>> shapes;
    shapes.push_back({{-1, -1}, {1, -1}, {1, -0.3}, {-0.2, -0.3}, {-0.2, 1}, {-1, 1}});  // an L
    std::vector<P2> star;
    for (int k = 0; k < 10; ++k) {
        const double a = k * 3.14159265358979 / 5, r = k % 2 ? 0.5 : 1.3;
        star.push_back({r * std::cos(a), r * std::sin(a)});
    }
    shapes.push_back(star);
    shapes.push_back({{-1.2, -1}, {1.2, -1}, {1.2, 1}, {-1.2, 1}});  // a convex quadrilateral: one patch
    const int res = 64;
    for (size_t si = 0; si < shapes.size(); ++si) {
        const std::vector<P2>& poly = shapes[si];
        Scene s = load(topView(polygonRib(poly, 0.3), res)).scene;
        EXPECT_EQ(s.patches.size(), si == 2 ? 1u : poly.size() - 2);  // n - 2 triangles
        SCOPED_TRACE("shape " + std::to_string(si));
        expectCoverage(s, exactCoverage(s, [&](double x, double y) { return insidePolygon(poly, x, y); }),
                       res);
    }
}

// A wavy PointsPolygons grid of quads, triangles and pentagons sharing their vertices: watertight in
// both engines (no pinholes, everything inside the outline covered).
TEST(Polygons, PointsPolygonsMeshHasNoPinholes) {
    const int n = 8;
    std::string P, nverts, verts;
    auto id = [&](int i, int j) { return std::to_string(j * (n + 1) + i); };
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) {
            const double x = -1.3 + 2.6 * i / n, y = -1.3 + 2.6 * j / n;
            for (double c : {x, y, 0.3 * std::sin(2 * x + 3 * y)}) P.append(" ").append(std::to_string(c));
        }
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            const std::string a = id(i, j), b = id(i + 1, j), c = id(i + 1, j + 1), d = id(i, j + 1);
            if ((i + j) % 3 == 0) {  // two triangles
                nverts += " 3 3";
                verts += " " + a + " " + b + " " + c + " " + a + " " + c + " " + d;
            } else {
                nverts += " 4";
                verts += " " + a + " " + b + " " + c + " " + d;
            }
        }
    for (float rate : {1.f, 8.f}) {
        Scene s = load(topView("ShadingRate " + std::to_string(rate) + "\nPointsPolygons [" + nverts + "] [" +
                                   verts + "] \"P\" [" + P + "] \"N\" [" + P + "]",
                               96))
                      .scene;
        for (const char* engine : {"reyes", "rt"}) {
            SCOPED_TRACE(std::string(engine) + " rate " + std::to_string(rate));
            const Image img = renderIn(s, engine);
            EXPECT_EQ(countPinholes(img), 0);
            int uncovered = 0;
            for (int y = 8; y < 88; ++y)  // [-1.25, 1.25]^2: inside the mesh's outline
                for (int x = 8; x < 88; ++x) uncovered += alphaAt(img, x, y) < 0.999f;
            EXPECT_EQ(uncovered, 0);
        }
    }
}

std::string loopPoints(const std::vector<P2>& poly, double z, double tilt = 0) {
    std::string out;
    for (const P2& p : poly)
        for (double c : {p.x, p.y, z + tilt * p.x * p.y}) out.append(" ").append(std::to_string(c));
    return out;
}

// A concave outer loop (a star) with two holes, one of them concave, as a GeneralPolygon: it covers
// exactly the star minus the holes (crossing-number truth, independent of the triangulation). Holes are
// given in either orientation; a variant lies in a slightly curved (nearly planar) surface.
TEST(Polygons, GeneralPolygonWithHolesCoversExactlyItsArea) {
    std::vector<P2> star;
    for (int k = 0; k < 12; ++k) {
        const double a = k * 3.14159265358979 / 6, r = k % 2 ? 0.75 : 1.35;
        star.push_back({r * std::cos(a), r * std::sin(a)});
    }
    const std::vector<P2> square = {{-0.45, -0.2}, {-0.05, -0.2}, {-0.05, 0.2}, {-0.45, 0.2}};  // ccw
    const std::vector<P2> ell = {{0.1, 0.3},  {0.1, -0.4}, {0.5, -0.4},
                                 {0.5, -0.2}, {0.3, -0.2}, {0.3, 0.3}};  // cw
    const int res = 72;
    for (double tilt : {0.0, 0.02}) {
        SCOPED_TRACE("tilt " + std::to_string(tilt));
        const std::string rib = "GeneralPolygon [" + std::to_string(star.size()) + " 4 6] \"P\" [" +
                                loopPoints(star, 0.3, tilt) + loopPoints(square, 0.3, tilt) +
                                loopPoints(ell, 0.3, tilt) + " ]";
        Loaded l = load(topView(rib, res));
        EXPECT_TRUE(l.warnings.empty() || !contains(l.warnings.front(), "polygon")) << l.warnings.front();
        // Triangles of a polygon with h holes and n vertices in all: n + 2h - 2.
        EXPECT_EQ(l.scene.patches.size(), star.size() + 4 + 6 + 2 * 2 - 2);
        const std::vector<double> truth = exactCoverage(l.scene, [&](double x, double y) {
            return insidePolygon(star, x, y) && !insidePolygon(square, x, y) && !insidePolygon(ell, x, y);
        });
        expectCoverage(l.scene, truth, res);
    }
}

// PointsGeneralPolygons: a picture frame (a square with a square hole) and the square that fills the hole,
// sharing the hole's vertices, next to an L with an L-shaped hole; all of it watertight in both engines.
TEST(Polygons, PointsGeneralPolygonsMeshHasNoPinholesAndHolesStayOpen) {
    // Points: outer square 0-3, inner square 4-7 (the frame's hole, filled by polygon 2), then a
    // separate polygon with a hole.
    const std::string P =
        "-1.3 -1.3 0.2  0.2 -1.3 0.2  0.2 0.2 0.2  -1.3 0.2 0.2 "
        "-0.8 -0.8 0.35  -0.3 -0.8 0.35  -0.3 -0.3 0.35  -0.8 -0.3 0.35 "
        "0.4 0.4 0  1.3 0.4 0  1.3 1.3 0  0.4 1.3 0 "
        "0.7 0.7 0  1.0 0.7 0  1.0 1.0 0  0.7 1.0 0";
    const std::string rib =
        "PointsGeneralPolygons [2 1 2] [4 4 4 4 4] [0 1 2 3 4 5 6 7 7 6 5 4 8 9 10 11 12 13 14 15] "
        "\"P\" [" +
        P + "]";
    const int res = 96;
    Loaded l = load(topView(rib, res));
    auto in = [](double x, double y, double x0, double y0, double x1, double y1) {
        return x > x0 && x < x1 && y > y0 && y < y1;
    };
    const std::vector<double> truth = exactCoverage(l.scene, [&](double x, double y) {
        return in(x, y, -1.3, -1.3, 0.2, 0.2) ||
               (in(x, y, 0.4, 0.4, 1.3, 1.3) && !in(x, y, 0.7, 0.7, 1.0, 1.0));
    });
    expectCoverage(l.scene, truth, res);
    for (const char* engine : {"reyes", "rt"})
        EXPECT_EQ(countPinholes(renderIn(l.scene, engine)), 0) << engine;
}

// Polygons of one mesh that share an edge (walked in opposite directions) get bit-identical boundary
// control points for it, before any weld: the ray tracer, which does not weld, sees no crack either.
TEST(Polygons, SharedEdgesAreBitIdentical) {
    std::string P, nverts, verts;
    const int n = 6;
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i)
            for (double c :
                 {0.37 * i + 0.05 * j, 0.29 * j - 0.03 * i * i, 0.11 * std::sin(1.7 * i + 2.3 * j)})
                P.append(" ").append(std::to_string(c));
    auto id = [&](int i, int j) { return std::to_string(j * (n + 1) + i); };
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            const std::string a = id(i, j), b = id(i + 1, j), c = id(i + 1, j + 1), d = id(i, j + 1);
            if ((i + j) % 2 == 0) {
                nverts += " 3 3";
                verts += " " + a + " " + b + " " + c + " " + a + " " + c + " " + d;
            } else {
                nverts += " 4";
                verts += " " + a + " " + b + " " + c + " " + d;
            }
        }
    const Scene s =
        load("WorldBegin\nPointsPolygons [" + nverts + "] [" + verts + "] \"P\" [" + P + "]\nWorldEnd\n")
            .scene;
    // Every boundary curve of every patch (4 control points), and the curves with the same two ends.
    struct Curve {
        Vec3 p[4];
    };
    std::vector<Curve> curves;
    for (const BezierPatch& b : s.patches) {
        Curve c[4];
        for (int k = 0; k < 4; ++k) {
            c[0].p[k] = b.at(k, 0);
            c[1].p[k] = b.at(3, k);
            c[2].p[k] = b.at(3 - k, 3);
            c[3].p[k] = b.at(0, 3 - k);
        }
        for (const Curve& e : c)
            if (!(e.p[0] == e.p[3])) curves.push_back(e);
    }
    int shared = 0, differ = 0;
    for (size_t i = 0; i < curves.size(); ++i)
        for (size_t j = i + 1; j < curves.size(); ++j) {
            const Curve &a = curves[i], &b = curves[j];
            if (!(a.p[0] == b.p[3] && a.p[3] == b.p[0])) continue;
            ++shared;
            for (int k = 0; k < 4; ++k) differ += !(a.p[k] == b.p[3 - k]);
        }
    EXPECT_EQ(shared, 2 * n * (n - 1) + n * n / 2);  // inner grid edges + the triangles' diagonals
    EXPECT_EQ(differ, 0);
}

// "st" on polygons: the pieces' corner s, t are the given values of their corners (vertex/varying: per
// point, facevarying: per corner), checked against a linear function of the corner's position.
TEST(Polygons, TexCoordsFollowTheVertices) {
    auto f = [](Vec3 p) { return Vec2{0.5f * p.x + 0.1f, 0.25f * p.y - 0.2f}; };
    const std::vector<Vec3> pts = {{0, 0, 0}, {2, 0, 0}, {2, 1, 0}, {1, 0.4f, 0}, {0, 1, 0}};  // concave
    std::string P, st, s, t, fvst;
    for (const Vec3& p : pts) {
        P += " " + std::to_string(p.x) + " " + std::to_string(p.y) + " 0";
        st += " " + std::to_string(f(p).x) + " " + std::to_string(f(p).y);
        s += " " + std::to_string(f(p).x);
        t += " " + std::to_string(f(p).y);
    }
    // Facevarying on a PointsPolygons: a triangle and a quad sharing points, values listed per corner.
    for (int i : {0, 1, 3, 3, 2, 4, 0})
        fvst += " " + std::to_string(f(pts[size_t(i)]).x) + " " + std::to_string(f(pts[size_t(i)]).y);
    for (const std::string& rib :
         {"Polygon \"P\" [" + P + "] \"st\" [" + st + "]",
          "Polygon \"P\" [" + P + "] \"varying float s\" [" + s + "] \"vertex float t\" [" + t + "]",
          "PointsPolygons [3 4] [0 1 3 3 2 4 0] \"P\" [" + P + "] \"facevarying float[2] st\" [" + fvst +
              "]"}) {
        SCOPED_TRACE(rib);
        Loaded l = load("WorldBegin\n" + rib + "\nWorldEnd\n");
        ASSERT_EQ(l.scene.texCoords.size(), l.scene.patches.size());
        ASSERT_GE(l.scene.patches.size(), 2u);
        for (size_t i = 0; i < l.scene.patches.size(); ++i)
            for (int k = 0; k < 4; ++k) {
                const Vec3 corner = l.scene.patches[i].cp[(k & 1 ? 3 : 0) + (k & 2 ? 12 : 0)];
                EXPECT_NEAR(l.scene.texCoords[i].st[k].x, f(corner).x, 1e-5);
                EXPECT_NEAR(l.scene.texCoords[i].st[k].y, f(corner).y, 1e-5);
            }
    }
}

// "Cs" per polygon (uniform), for all (constant) or per vertex colours the pieces (the surface with that
// Cs, checked with RI "constant" in both engines).
TEST(Polygons, UniformAndConstantColours) {
    const std::string quads =
        "PointsPolygons [4 4] [0 1 4 3 1 2 5 4] \"P\" [-1.2 -1 0  0 -1 0  1.2 -1 0 "
        " -1.2 1 0  0 1 0  1.2 1 0]";
    const int res = 32;
    struct Case {
        std::string params;
        Color left, right;
    };
    for (const Case& c :
         {Case{" \"uniform color Cs\" [1 0 0  0 0.5 1]", {1, 0, 0}, {0, 0.5f, 1}},
          Case{" \"constant color Cs\" [0.2 0.9 0.4]", {0.2f, 0.9f, 0.4f}, {0.2f, 0.9f, 0.4f}},
          Case{" \"Cs\" [1 0 0  1 0 0  1 0 0  1 0 0  1 0 0  1 0 0]", {1, 0, 0}, {1, 0, 0}},
          Case{" \"facevarying color Cs\" [1 0 0  1 0 0  1 0 0  1 0 0  0 1 0  0 1 0  0 1 0  0 1 0]",
               {1, 0, 0},
               {0, 1, 0}}}) {
        SCOPED_TRACE(c.params);
        Loaded l = load(topView("Surface \"constant\"\nColor [0.6 0.6 0.6]\n" + quads + c.params, res));
        EXPECT_TRUE(l.warnings.empty()) << l.warnings.front();
        for (const char* engine : {"reyes", "rt"}) {
            SCOPED_TRACE(engine);
            const Image img = renderIn(l.scene, engine);
            for (int k = 0; k < 3; ++k) {
                EXPECT_NEAR(img.pixel(8, 16)[k], (&c.left.x)[k], 1e-3);
                EXPECT_NEAR(img.pixel(24, 16)[k], (&c.right.x)[k], 1e-3);
            }
        }
    }
    // Wrong counts name the line.
    EXPECT_TRUE(contains(
        expectError("WorldBegin\n" + quads + "\n\"uniform color Cs\" [1 0 0]\nWorldEnd\n", 3), "Cs"));
}

// World (x, y) of pixel (x, y)'s centre in topView's orthographic view (looking down world -z).
Vec3 topViewPixelCentre(const Scene& s, int x, int y) {
    const Projector pr(s.camera);
    return s.camera.cameraFromWorld.inverse().point(pr.fromRaster(x + 0.5f, y + 0.5f));
}

// Per-vertex "Cs" (vertex and facevarying) is interpolated as RI varying values: colours that are an affine
// function f of position give f at every point of any polygon (a bilinear quad, and the triangles of a
// concave polygon with a hole), so every pixel fully inside shows f at its centre (the box filter's mean
// of an affine function), in both engines and under matte too (Cs multiplies the material's response).
TEST(Polygons, VertexColoursInterpolateLinearly) {
    auto f = [](double x, double y) { return Color{float(0.5 + 0.3 * x), float(0.5 - 0.2 * y), 0.3f}; };
    auto colourOf = [&](const std::vector<P2>& pts) {
        std::ostringstream cs;
        for (const P2& p : pts) {
            const Color c = f(p.x, p.y);
            cs << " " << c.x << " " << c.y << " " << c.z;
        }
        return cs.str();
    };
    const std::vector<P2> outer{{-1.3, -1.3}, {1.3, -1.3}, {1.3, 0}, {0, 0}, {0, 1.3}, {-1.3, 1.3}};  // an L
    const std::vector<P2> hole{{-0.9, -0.9}, {-0.9, -0.4}, {-0.4, -0.4}, {-0.4, -0.9}};
    std::vector<P2> all = outer;
    all.insert(all.end(), hole.begin(), hole.end());
    std::ostringstream P;
    for (const P2& p : all) P << " " << p.x << " " << p.y << " 0";
    const std::string general = "GeneralPolygon [6 4] \"P\" [" + P.str() + "] \"Cs\" [" + colourOf(all) + "]";
    // Two quads of a PointsPolygons with facevarying colours: each face its own affine function (f, and f
    // + 0.2 on the right face), so the colour jumps at the shared edge x = 0.
    const std::vector<P2> mesh{{-1.3, -1.3}, {0, -1.3}, {1.3, -1.3}, {-1.3, 1.3}, {0, 1.3}, {1.3, 1.3}};
    const int corners[8] = {0, 1, 4, 3, 1, 2, 5, 4};
    std::ostringstream MP, fv;
    for (const P2& p : mesh) MP << " " << p.x << " " << p.y << " 0";
    for (int k = 0; k < 8; ++k) {
        const Color c =
            f(mesh[size_t(corners[k])].x, mesh[size_t(corners[k])].y) + Color{k >= 4 ? 0.2f : 0.f, 0, 0};
        fv << " " << c.x << " " << c.y << " " << c.z;
    }
    const std::string facevarying = "PointsPolygons [4 4] [0 1 4 3 1 2 5 4] \"P\" [" + MP.str() +
                                    "] \"facevarying color Cs\" [" + fv.str() + "]";
    const int res = 48;
    for (const std::string& surface :
         {std::string("Surface \"constant\""), std::string("Surface \"matte\" \"Kd\" 0")}) {
        for (const std::string& prim : {general, facevarying}) {
            SCOPED_TRACE(surface + " " + prim.substr(0, 20));
            Loaded l = load(topView(surface + "\nColor [0.7 0.7 0.7]\n" + prim, res));
            EXPECT_TRUE(l.warnings.empty());
            for (const char* engine : {"reyes", "rt"}) {
                SCOPED_TRACE(engine);
                const Image img = renderIn(l.scene, engine);
                int checked = 0;
                double worst = 0;
                for (int y = 1; y + 1 < res; ++y)
                    for (int x = 1; x + 1 < res; ++x) {
                        bool inside = true;  // the pixel and its neighbours fully covered, away from x = 0
                        for (int dy = -1; dy <= 1; ++dy)
                            for (int dx = -1; dx <= 1; ++dx)
                                inside = inside && alphaAt(img, x + dx, y + dy) > 0.999f;
                        const Vec3 w = topViewPixelCentre(l.scene, x, y);
                        if (!inside || std::fabs(w.x) < 0.1) continue;
                        Color want = f(w.x, w.y);
                        if (prim == facevarying && w.x > 0) want.x += 0.2f;
                        for (int k = 0; k < 3; ++k)
                            worst = std::max(worst, double(std::fabs(img.pixel(x, y)[k] - (&want.x)[k])));
                        ++checked;
                    }
                EXPECT_GT(checked, res * res / 3);
                EXPECT_LT(worst, 2e-3) << "largest colour error over " << checked << " pixels";
            }
        }
    }
}

// A polygon sphere (nu x nv faces, radius 1 at the origin) as PointsPolygons, with its exact normals as
// vertex "N" or without.
std::string polygonSphere(int nu, int nv, bool normals) {
    std::ostringstream nverts, verts, P, N;
    for (int j = 0; j <= nv; ++j)
        for (int i = 0; i < nu; ++i) {
            const double th = 3.14159265358979 * j / nv, ph = 2 * 3.14159265358979 * i / nu;
            const double x = std::sin(th) * std::cos(ph), y = std::sin(th) * std::sin(ph), z = std::cos(th);
            P << " " << x << " " << y << " " << z;
            N << " " << x << " " << y << " " << z;
        }
    for (int j = 0; j < nv; ++j)
        for (int i = 0; i < nu; ++i) {
            const int a = j * nu + i, b = j * nu + (i + 1) % nu, c = (j + 1) * nu + (i + 1) % nu,
                      d = (j + 1) * nu + i;
            if (j == 0)
                nverts << " 3", verts << " " << a << " " << d << " " << c;
            else if (j == nv - 1)
                nverts << " 3", verts << " " << a << " " << d << " " << b;
            else
                nverts << " 4", verts << " " << a << " " << d << " " << c << " " << b;
        }
    std::string s = "PointsPolygons [" + nverts.str() + "] [" + verts.str() + "] \"P\" [" + P.str() + "]";
    if (normals) s += " \"N\" [" + N.str() + "]";
    return s;
}

// Vertex "N" on polygons shades as the smooth surface they sample: a 24 x 12 polygon sphere with its exact
// normals matches the analytic Lambert shading of the true sphere (matte, one distant light) to a small
// error everywhere inside, several times smaller than the faceted sphere's without "N"; in both engines.
// With shadows on, the lit side is not shadowed by the facets (the terminator: shadows leave from the smooth
// surface, scene.h terminatorSafePoint).
TEST(Polygons, VertexNormalsShadeTheSmoothSurface) {
    const int res = 64;
    const Vec3 L = normalize(Vec3{1, 0.5f, 0.6f});  // towards the light
    const std::string light = "LightSource \"distantlight\" 2 \"from\" [1 0.5 0.6] \"to\" [0 0 0]\n";
    auto scene = [&](bool normals, bool shadows) {
        return load(topView(std::string(shadows ? "Attribute \"light\" \"shadows\" \"on\"\n" : "") + light +
                                "Surface \"matte\" \"Ka\" 0\n" + polygonSphere(24, 12, normals),
                            res));
    };
    for (const char* engine : {"reyes", "rt"}) {
        SCOPED_TRACE(engine);
        double err[2] = {0, 0};
        int n = 0;
        Image smooth, faceted;
        for (int withN = 0; withN < 2; ++withN) {
            Loaded l = scene(withN, false);
            EXPECT_TRUE(l.warnings.empty());
            (withN ? smooth : faceted) = renderIn(l.scene, engine);
        }
        const Loaded ref = scene(true, false);
        for (int y = 0; y < res; ++y)
            for (int x = 0; x < res; ++x) {
                const Vec3 w = topViewPixelCentre(ref.scene, x, y);
                const double r2 = double(w.x) * w.x + double(w.y) * w.y;
                if (r2 > 0.85 * 0.85) continue;  // inside both silhouettes
                const Vec3 nrm{w.x, w.y, float(std::sqrt(1 - r2))};
                const double want = std::max(0.f, dot(nrm, L));
                err[1] += std::fabs(smooth.pixel(x, y)[0] - want);
                err[0] += std::fabs(faceted.pixel(x, y)[0] - want);
                ++n;
            }
        err[0] /= n, err[1] /= n;
        EXPECT_LT(err[1], 0.02) << "mean error with N over " << n << " pixels";
        EXPECT_LT(err[1], 0.3 * err[0]) << "with N " << err[1] << ", without " << err[0];

        // Shadows on: where the true sphere faces the light, nothing changes.
        const Image shadowed = renderIn(scene(true, true).scene, engine);
        int darkened = 0, lit = 0;
        for (int y = 0; y < res; ++y)
            for (int x = 0; x < res; ++x) {
                const Vec3 w = topViewPixelCentre(ref.scene, x, y);
                const double r2 = double(w.x) * w.x + double(w.y) * w.y;
                if (r2 > 0.85 * 0.85) continue;
                const Vec3 nrm{w.x, w.y, float(std::sqrt(1 - r2))};
                if (dot(nrm, L) < 0.08f) continue;
                ++lit;
                darkened += shadowed.pixel(x, y)[0] < smooth.pixel(x, y)[0] - 0.02f;
            }
        EXPECT_GT(lit, 500);
        EXPECT_EQ(darkened, 0) << "of " << lit << " lit pixels";
    }
}

TEST(Polygons, VertexValuesBadInput) {
    const std::string w = "WorldBegin\n";
    EXPECT_TRUE(
        contains(expectError(w + "Polygon \"P\" [0 0 0 1 0 0 1 1 0]\n\"N\" [0 0 1 0 0 1]\nWorldEnd\n", 3),
                 "\"N\" needs 9 values"));
    EXPECT_TRUE(contains(expectError(w + "PointsPolygons [3] [0 1 2] \"P\" [0 0 0 1 0 0 1 1 0]\n"
                                         "\"facevarying normal N\" [0 0 1]\nWorldEnd\n",
                                     3),
                         "\"N\" needs 9 values"));
    Loaded l = load(w + "Polygon \"P\" [0 0 0 1 0 0 1 1 0] \"varying float N\" [1 2 3]\nWorldEnd\n");
    ASSERT_FALSE(l.warnings.empty());
    EXPECT_TRUE(contains(l.warnings[0], ":2:") && contains(l.warnings[0], "\"N\" is used as a normal"))
        << l.warnings[0];
    EXPECT_TRUE(l.scene.vertexValues.empty());
}

// Deformation blur of a polygon whose shape changes from concave (a dart: 2 triangles) to convex (a square,
// which alone would be one bilinear patch): the later key is cut into the first key's pieces, so the keys
// correspond; the pieces cover the dart at shutter open and the square at shutter close.
TEST(Polygons, DeformingPolygonKeepsTheFirstKeysPieces) {
    for (const std::string& prim : {std::string("Polygon \"P\" "), std::string("GeneralPolygon [4] \"P\" "),
                                    std::string("PointsPolygons [4] [0 1 2 3] \"P\" ")}) {
        SCOPED_TRACE(prim);
        Loaded l = load("Shutter 0 1\nWorldBegin\nMotionBegin [0 1]\n" + prim +
                        "[0 0 0  2 0 0  0.3 0.3 0  0 2 0]\n" + prim +
                        "[0 0 0  2 0 0  2 2 0  0 2 0]\nMotionEnd\nWorldEnd\n");
        ASSERT_EQ(l.scene.patches.size(), 2u);
        for (float time : {0.f, 1.f}) {
            double area = 0;
            for (size_t i = 0; i < 2; ++i) {
                const BezierPatch b = patchAtTime(l.scene, i, time);
                area += 0.5 * length(cross(b.cp[3] - b.cp[0], b.cp[12] - b.cp[0]));
            }
            EXPECT_NEAR(area, time == 0.f ? 0.6 : 4.0, 1e-5) << time;
        }
    }
}

TEST(Polygons, GeneralPolygonBadInputFailsNamingTheLine) {
    const std::string w = "WorldBegin\n";
    EXPECT_TRUE(contains(expectError(w + "GeneralPolygon [3 3] \"P\" [0 0 0 1 0 0 1 1 0]\nWorldEnd\n", 2),
                         "nvertices adds up to 6 points, but \"P\" has 3"));
    EXPECT_TRUE(contains(expectError(w + "\nGeneralPolygon [3 2] \"P\" [0 0 0 1 0 0 1 1 0 0 0 0 1 1 1]\n", 3),
                         "loop 1 has 2 vertices"));
    EXPECT_TRUE(contains(expectError(w + "GeneralPolygon 3 \"P\" [0 0 0 1 0 0 1 1 0]\nWorldEnd\n", 2),
                         "must be an array"));
    EXPECT_TRUE(contains(
        expectError(
            w + "PointsGeneralPolygons [1 1] [3 3 3] [0 1 2 0 2 3 0 1 3] \"P\" [0 0 0 1 0 0 1 1 0 0 1 0]\n",
            2),
        "nloops adds up to 2 loops, but nvertices has 3"));
    EXPECT_TRUE(contains(
        expectError(w + "PointsGeneralPolygons [1] [3] [0 1 4] \"P\" [0 0 0 1 0 0 1 1 0 0 1 0]\nWorldEnd\n",
                    2),
        "vertex index 4 is out of range"));
    EXPECT_TRUE(contains(expectError(w + "PointsGeneralPolygons [0] [] [] \"P\" [0 0 0]\nWorldEnd\n", 2),
                         "needs at least 1"));
    // Wrong primitive variable counts, also facevarying ones.
    EXPECT_TRUE(contains(
        expectError(w + "Polygon \"P\" [0 0 0 1 0 0 1 1 0]\n\"st\" [0 0 1 0]\nWorldEnd\n", 3), "st"));
    EXPECT_TRUE(contains(expectError(w + "PointsPolygons [3] [0 1 2] \"P\" [0 0 0 1 0 0 1 1 0]\n"
                                         "\"facevarying float s\" [0 1]\nWorldEnd\n",
                                     3),
                         "s"));
    EXPECT_TRUE(contains(
        expectError(
            w + "PointsPolygons [3] [0 1 2] \"P\" [0 0 0 1 0 0 1 1 0] \"Cs\" [1 0 0 0 1 0]\nWorldEnd\n", 2),
        "Cs"));
}

TEST(Polygons, DegenerateHolesWarnAndAreIgnored) {
    // A hole with no area, and one outside the outer loop: the square is rendered whole (as 2 triangles).
    Loaded l = load(
        "WorldBegin\nGeneralPolygon [4 3 4] \"P\" [0 0 0 4 0 0 4 4 0 0 4 0  1 1 0 2 2 0 3 3 0"
        "  6 1 0 7 1 0 7 2 0 6 2 0]\nWorldEnd\n");
    EXPECT_EQ(l.scene.patches.size(), 2u);
    int degenerate = 0, outside = 0;
    for (const std::string& m : l.warnings) {
        degenerate +=
            contains(m, ":2:") && contains(m, "hole with fewer than 3 distinct vertices or no area");
        outside += contains(m, ":2:") && contains(m, "not inside the outer loop");
    }
    EXPECT_EQ(degenerate, 1);
    EXPECT_EQ(outside, 1);
}

TEST(Polygons, BadInputFailsNamingTheLine) {
    const std::string w = "WorldBegin\n";
    EXPECT_TRUE(
        contains(expectError(w + "PointsPolygons [3] [0 1 3] \"P\" [0 0 0 1 0 0 1 1 0]\nWorldEnd\n", 2),
                 "vertex index 3 is out of range"));
    EXPECT_TRUE(contains(expectError(w + "PointsPolygons [2] [0 1] \"P\" [0 0 0 1 0 0]\nWorldEnd\n", 2),
                         "at least 3"));
    EXPECT_TRUE(
        contains(expectError(w + "PointsPolygons [3 3] [0 1 2] \"P\" [0 0 0 1 0 0 1 1 0]\nWorldEnd\n", 2),
                 "adds up to 6"));
    EXPECT_TRUE(contains(expectError(w + "Polygon \"P\" [0 0 0 1 0 0 1 1]\nWorldEnd\n", 2), "multiple of 3"));
    EXPECT_TRUE(contains(expectError(w + "Polygon \"Cs\" [1 1 1]\nWorldEnd\n", 2), "missing the position"));
}

TEST(Polygons, DegeneratePolygonsWarnAndAreSkipped) {
    Loaded l = load(
        "WorldBegin\nPolygon \"P\" [0 0 0 1 1 1 2 2 2]\nPolygon \"P\" [0 0 0 0 0 0 1 0 0]\n"
        "Polygon \"P\" [0 0 0 1 0 0 1 1 0]\nWorldEnd\n");
    EXPECT_EQ(l.scene.patches.size(), 1u);  // the last one
    int warned = 0;
    for (const std::string& m : l.warnings) warned += contains(m, ":2:") && contains(m, "no area is skipped");
    EXPECT_EQ(warned, 1);
}

}  // namespace
}  // namespace tessera::test::polygons_tests
