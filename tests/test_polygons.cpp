// RIB Polygon and PointsPolygons (RI spec 3.2, sec. 5.1), read as bilinear patches (convex quadrilaterals)
// and triangles of an ear-clipping triangulation: coverage against the exact polygon (point in polygon),
// meshes without pinholes in both engines, and the reader's errors.
#include <gtest/gtest.h>

#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "render/render.h"
#include "rib_test_util.h"
#include "test_util.h"

namespace tessera::test {
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
        const std::vector<double> truth =
            exactCoverage(s, [&](double x, double y) { return insidePolygon(poly, x, y); });
        double truthSum = 0;
        for (double t : truth) truthSum += t;
        for (const char* engine : {"reyes", "rt"}) {
            SCOPED_TRACE("shape " + std::to_string(si) + " " + engine);
            RenderSettings rs;
            rs.engine = engine;
            rs.threads = 2;
            const Image img = render(s, rs).image;
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
            EXPECT_NEAR(sum, truthSum, 0.01 * truthSum) << "area";
        }
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
            P += " " + std::to_string(x) + " " + std::to_string(y) + " " +
                 std::to_string(0.3 * std::sin(2 * x + 3 * y));
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
            RenderSettings rs;
            rs.engine = engine;
            rs.threads = 2;
            const Image img = render(s, rs).image;
            EXPECT_EQ(countPinholes(img), 0);
            int uncovered = 0;
            for (int y = 8; y < 88; ++y)  // [-1.25, 1.25]^2: inside the mesh's outline
                for (int x = 8; x < 88; ++x) uncovered += alphaAt(img, x, y) < 0.999f;
            EXPECT_EQ(uncovered, 0);
        }
    }
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
}  // namespace tessera::test
