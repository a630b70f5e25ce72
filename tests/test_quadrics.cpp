// The seven RI quadrics (core/quadric.h) in both engines, against independent truth: the implicit
// equations and their gradients (kernels), the silhouettes' exact 2D shapes (coverage of an orthographic
// top view, brute-force per pixel), Reyes against the ray tracer, and the reader's handling of bad input.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>
#include <string>

#include "core/quadric.h"
#include "film/image_compare.h"
#include "render/render.h"
#include "rib_test_util.h"
#include "scene/camera.h"
#include "test_util.h"

namespace tessera::test::quadrics_tests {
namespace {

constexpr double kPi = 3.14159265358979323846;

Quadric sphere(float r, float z0, float z1, float thetaDeg) {
    Quadric q;
    q.kind = QuadricKind::Sphere;
    q.radius = r, q.zMin = z0, q.zMax = z1;
    q.angle0 = std::asin(z0 / r), q.angle1 = std::asin(z1 / r);
    q.thetaMax = float(thetaDeg * kPi / 180), q.closedU = std::fabs(thetaDeg) >= 360;
    return q;
}

// Implicit function F (F = 0 on the surface) and the RI "outward" direction (away from the z axis; for the
// disk +z) at a point, per kind, written from the RI spec's definitions and independent of core/quadric.h.
struct Implicit {
    std::function<double(Vec3)> F;
    std::function<Vec3(Vec3)> outward;
};

Vec3 gradient(const std::function<double(Vec3)>& F, Vec3 p) {
    const float h = 1e-3f;
    auto d = [&](Vec3 e) { return float((F(p + e * h) - F(p - e * h)) / (2 * h)); };
    return normalize(Vec3{d({1, 0, 0}), d({0, 1, 0}), d({0, 0, 1})});
}

Vec3 awayFromAxis(Vec3 p) {
    return Vec3{p.x, p.y, 0.f};
}

struct KindCase {
    const char* name;
    Quadric q;
    Implicit f;
};

std::vector<KindCase> kindCases() {
    std::vector<KindCase> c;
    auto full = [](Quadric q) {
        q.thetaMax = float(2 * kPi), q.closedU = true;
        return q;
    };
    c.push_back({"sphere",
                 sphere(1.3f, -1.3f, 1.3f, 360),
                 {[](Vec3 p) { return double(dot(p, p)) - 1.69; }, [](Vec3 p) { return p; }}});
    Quadric cyl;
    cyl.kind = QuadricKind::Cylinder, cyl.radius = 0.7f, cyl.zMin = -0.5f, cyl.zMax = 1.f;
    c.push_back({"cylinder", full(cyl), {[](Vec3 p) { return p.x * p.x + p.y * p.y - 0.49; }, awayFromAxis}});
    Quadric cone;
    cone.kind = QuadricKind::Cone, cone.height = 2.f, cone.radius = 0.8f;
    c.push_back({"cone",
                 full(cone),
                 {[](Vec3 p) {
                      const double r = 0.8 * (1 - p.z / 2.0);
                      return p.x * p.x + p.y * p.y - r * r;
                  },
                  [](Vec3 p) {
                      return Vec3{p.x, p.y, 0.f} + Vec3{0, 0, 0.32f * length(awayFromAxis(p))};
                  }}});
    Quadric disk;
    disk.kind = QuadricKind::Disk, disk.height = 0.4f, disk.radius = 1.1f;
    c.push_back({"disk", full(disk), {[](Vec3 p) { return p.z - 0.4; }, [](Vec3) { return Vec3{0, 0, 1}; }}});
    Quadric par;
    par.kind = QuadricKind::Paraboloid, par.radius = 1.f, par.zMin = 0.f, par.zMax = 2.f;
    c.push_back({"paraboloid",
                 full(par),
                 {[](Vec3 p) { return p.x * p.x + p.y * p.y - 0.5 * p.z; },
                  [](Vec3 p) {
                      return Vec3{p.x, p.y, -0.25f};
                  }}});
    Quadric hyp;
    hyp.kind = QuadricKind::Hyperboloid, hyp.point1 = {1, -0.5f, -1}, hyp.point2 = {0.5f, 1, 1};
    c.push_back({"hyperboloid",
                 full(hyp),
                 {[](Vec3 p) {
                      // rho^2 along the segment at this z (v = (z + 1) / 2).
                      const double v = (p.z + 1) / 2, x = 1 - 0.5 * v, y = -0.5 + 1.5 * v;
                      return p.x * p.x + p.y * p.y - (x * x + y * y);
                  },
                  [](Vec3 p) { return awayFromAxis(p); }}});
    Quadric tor;
    tor.kind = QuadricKind::Torus, tor.radius = 1.f, tor.minorRadius = 0.3f, tor.angle0 = 0.f,
    tor.angle1 = float(2 * kPi), tor.closedV = true;
    c.push_back({"torus",
                 full(tor),
                 {[](Vec3 p) {
                      const double rr = std::sqrt(p.x * p.x + p.y * p.y) - 1.0;
                      return rr * rr + p.z * p.z - 0.09;
                  },
                  [](Vec3 p) {  // away from the tube's centre circle
                      const Vec3 a = normalize(awayFromAxis(p));
                      return p - a;
                  }}});
    return c;
}

// Points of the closed form lie on the implicit surface; the normal is the implicit gradient on the RI
// outward side; a ray aimed at a point finds it again with the same (u,v).
TEST(QuadricKernels, ClosedFormMatchesTheImplicitSurfaceNormalsAndRayHits) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> uni(0.02f, 0.98f);
    for (const KindCase& kc : kindCases()) {
        SCOPED_TRACE(kc.name);
        for (int i = 0; i < 200; ++i) {
            const float u = uni(rng), v = uni(rng);
            const SurfacePoint sp = evalQuadric(kc.q, u, v);
            EXPECT_NEAR(kc.f.F(sp.p), 0.0, 2e-5) << "u " << u << " v " << v;
            const Vec3 n = quadricNormal(kc.q, u, v), g = gradient(kc.f.F, sp.p);
            const float side = dot(g, kc.f.outward(sp.p)) >= 0 ? 1.f : -1.f;
            EXPECT_GT(dot(n, g * side), 0.9999f) << "u " << u << " v " << v;
            // A ray from outside the box through the point.
            const Vec3 dir = normalize(Vec3{0.3f, -0.5f, 0.8f} + n * 0.5f);
            const Vec3 o = sp.p + dir * 6.f;
            QuadricHit hits[4];
            const int nh = intersectQuadric(kc.q, o, -dir, 0.f, 100.f, hits);
            bool found = false;
            for (int h = 0; h < nh; ++h)
                if (std::fabs(hits[h].t - 6.f) < 1e-4f) {
                    found = true;
                    EXPECT_NEAR(hits[h].u, u, 2e-4f);
                    EXPECT_NEAR(hits[h].v, v, 2e-4f);
                }
            EXPECT_TRUE(found) << "u " << u << " v " << v << " hits " << nh;
            // Boxes of (u,v) rectangles hold the rectangle's points.
            const Bounds3 b = quadricBounds(kc.q, u - 0.02f, u + 0.02f, v - 0.02f, v + 0.02f);
            const Vec3 pc = evalQuadric(kc.q, u + 0.01f, v - 0.015f).p;
            EXPECT_TRUE(pc.x >= b.lo.x && pc.x <= b.hi.x && pc.y >= b.lo.y && pc.y <= b.hi.y &&
                        pc.z >= b.lo.z && pc.z <= b.hi.z);
        }
    }
}

// The poles of a sphere are single points with the axis as their normal, and the seam u = 1 of a full
// sweep is the same points as u = 0 (bit-identical: Reyes' crack-freeness relies on it).
TEST(QuadricKernels, SpherePolesAndSeamAreExact) {
    const Quadric q = sphere(2.f, -2.f, 2.f, 360);
    for (float u : {0.f, 0.3f, 0.77f, 1.f}) {
        EXPECT_EQ(evalQuadric(q, u, 0.f).p, (Vec3{0, 0, -2}));
        EXPECT_EQ(evalQuadric(q, u, 1.f).p, (Vec3{0, 0, 2}));
        EXPECT_NEAR(quadricNormal(q, u, 0.f).z, -1.f, 1e-6f);
        EXPECT_NEAR(quadricNormal(q, u, 1.f).z, 1.f, 1e-6f);
    }
    for (float v : {0.1f, 0.5f, 0.9f}) EXPECT_EQ(evalQuadric(q, 0.f, v).p, evalQuadric(q, 1.f, v).p);
    // Negative thetamax turns the sphere inside out (RI spec 5.4).
    const Quadric inside = sphere(2.f, -2.f, 2.f, -360);
    const SurfacePoint sp = evalQuadric(inside, 0.3f, 0.4f);
    EXPECT_LT(dot(quadricNormal(inside, 0.3f, 0.4f), sp.p), 0.f);
}

// ---- coverage against the exact silhouette --------------------------------------------------------

// Angle of (x, y) in [0, 360) degrees.
double angleDeg(double x, double y) {
    double a = std::atan2(y, x) * 180 / kPi;
    return a < 0 ? a + 360 : a;
}

struct CoverageCase {
    const char* name;
    std::string rib;
    std::function<bool(double, double)> inside;  // world (x, y) covered by the projection
};

std::vector<CoverageCase> coverageCases() {
    auto rho = [](double x, double y) { return std::sqrt(x * x + y * y); };
    std::vector<CoverageCase> c;
    c.push_back({"sphere 300", "Sphere 1.2 -1.2 1.2 300",
                 [=](double x, double y) { return rho(x, y) <= 1.2 && angleDeg(x, y) <= 300; }});
    c.push_back({"sphere -300 (negative sweep)", "Sphere 1.2 -1.2 1.2 -300",
                 [=](double x, double y) { return rho(x, y) <= 1.2 && angleDeg(x, y) >= 60; }});
    c.push_back({"sphere cap, zmin > zmax", "Sphere 1.2 1.2 0.5 360",
                 [=](double x, double y) { return rho(x, y) <= std::sqrt(1.44 - 0.25); }});
    c.push_back({"cylinder on its side", "Rotate 90 1 0 0\nCylinder 0.6 -1 1 360",
                 [](double x, double y) { return std::fabs(x) <= 0.6 && std::fabs(y) <= 1; }});
    c.push_back({"cone 250", "Cone 1 1.3 250",
                 [=](double x, double y) { return rho(x, y) <= 1.3 && angleDeg(x, y) <= 250; }});
    c.push_back({"disk, negative radius", "Disk 0.2 -1.1 270", [=](double x, double y) {
                     // points at phi + 180 degrees for phi in [0, 270]
                     const double a = angleDeg(x, y);
                     return rho(x, y) <= 1.1 && (a >= 180 || a <= 90);
                 }});
    c.push_back({"paraboloid 200", "Paraboloid 1.3 0.25 1 200", [=](double x, double y) {
                     const double r = rho(x, y);
                     return r >= 1.3 * 0.5 && r <= 1.3 && angleDeg(x, y) <= 200;
                 }});
    c.push_back({"hyperboloid", "Hyperboloid 1 0 -0.5  0 1 0.5  360", [=](double x, double y) {
                     const double r = rho(x, y);
                     return r >= std::sqrt(0.5) && r <= 1;
                 }});
    c.push_back({"torus", "Torus 0.9 0.4 0 360 360", [=](double x, double y) {
                     const double r = rho(x, y);
                     return r >= 0.5 && r <= 1.3;
                 }});
    c.push_back({"torus, half tube", "Torus 0.9 0.4 90 270 180", [=](double x, double y) {
                     // the inner half of the tube (psi in [90, 270]) swept over y >= 0
                     const double r = rho(x, y);
                     return r >= 0.5 && r <= 0.9 && y >= 0;
                 }});
    return c;
}

// A case's scene at `res` pixels, its exact per-pixel coverage and their sum (the exact area in pixels).
struct CoverageTruth {
    Scene scene;
    std::vector<double> coverage;
    double area = 0;
};
CoverageTruth coverageTruth(const CoverageCase& cc, int res) {
    CoverageTruth t;
    t.scene = load(topView(cc.rib, res)).scene;
    t.coverage = exactCoverage(t.scene, cc.inside);
    for (double c : t.coverage) t.area += c;
    return t;
}
Image renderWithEngine(const Scene& s, const char* engine) {
    RenderSettings rs;
    rs.engine = engine;
    rs.threads = 2;
    return render(s, rs).image;
}

TEST(QuadricCoverage, BothEnginesCoverTheExactSilhouette) {
    const int res = 64;
    for (const CoverageCase& cc : coverageCases()) {
        const CoverageTruth t = coverageTruth(cc, res);
        const std::vector<double>& truth = t.coverage;
        const double truthSum = t.area;
        for (const char* engine : {"reyes", "rt"}) {
            SCOPED_TRACE(std::string(cc.name) + " " + engine);
            const Image img = renderWithEngine(t.scene, engine);
            double sum = 0;
            int wrongInside = 0, wrongOutside = 0;
            for (int y = 0; y < res; ++y)
                for (int x = 0; x < res; ++x) {
                    const float a = alphaAt(img, x, y);
                    sum += a;
                    // Pixels whose whole neighbourhood is inside (outside) must be covered (empty).
                    bool allIn = true, allOut = true;
                    for (int dy = -1; dy <= 1; ++dy)
                        for (int dx = -1; dx <= 1; ++dx) {
                            const int xx = std::clamp(x + dx, 0, res - 1),
                                      yy = std::clamp(y + dy, 0, res - 1);
                            allIn = allIn && truth[size_t(yy) * res + xx] == 1.0;
                            allOut = allOut && truth[size_t(yy) * res + xx] == 0.0;
                        }
                    wrongInside += allIn && a < 0.999f;
                    wrongOutside += allOut && a > 0.f;
                }
            EXPECT_EQ(wrongInside, 0);
            EXPECT_EQ(wrongOutside, 0);
            EXPECT_NEAR(sum, truthSum, 0.01 * truthSum) << "area";
        }
    }
}

// The same silhouettes a few pixels across, seen along the axis: the u edges of a sphere are its poles
// and a disk's is its centre, so the split must measure the inside of a piece (a sphere of 10 pixels
// once diced into one sliver of zero-area micropolygons and vanished).
TEST(QuadricCoverage, SmallQuadricsSeenAlongTheirAxisKeepTheirArea) {
    for (int res : {8, 12, 16, 24})
        for (const CoverageCase& cc : coverageCases()) {
            const CoverageTruth t = coverageTruth(cc, res);
            const double truthSum = t.area;
            for (const char* engine : {"reyes", "rt"}) {
                SCOPED_TRACE(std::string(cc.name) + " " + engine + " " + std::to_string(res) + " px");
                const Image img = renderWithEngine(t.scene, engine);
                double sum = 0;
                for (int y = 0; y < res; ++y)
                    for (int x = 0; x < res; ++x) sum += alphaAt(img, x, y);
                // Micropolygons are chords a pixel long: at 8 pixels a torus tube of 1.2 pixels loses 7%.
                EXPECT_NEAR(sum, truthSum, 0.1 * truthSum + 0.5) << "area in pixels";
            }
        }
}

// A full sphere seen at a pole and along its seam, at several sizes and shading rates: no pinholes.
TEST(QuadricCoverage, FullSphereHasNoPinholesAtThePolesOrTheSeam) {
    for (const char* orient : {"", "Rotate 90 1 0 0\n", "Rotate 90 1 0 0\nRotate 90 0 0 1\n"})
        for (float rate : {0.5f, 1.f, 4.f, 16.f}) {
            const std::string body =
                "ShadingRate " + std::to_string(rate) + "\n" + orient + "Sphere 1.4 -1.4 1.4 360";
            Scene s = load(topView(body, 80)).scene;
            RenderSettings rs;
            rs.engine = "reyes";
            rs.threads = 2;
            const Image img = render(s, rs).image;
            EXPECT_EQ(countPinholes(img), 0) << orient << " rate " << rate;
            // The pole / seam region at the centre is fully covered.
            for (int y = 30; y < 50; ++y)
                for (int x = 30; x < 50; ++x)
                    ASSERT_GE(alphaAt(img, x, y), 0.999f) << x << "," << y << " " << orient;
        }
}

// Both engines' shading normals (the film's normal channel) against the implicit surface's gradient at
// the visible point, found by marching the pixel's ray down against the implicit function.
TEST(QuadricNormals, BothEnginesGiveTheAnalyticNormal) {
    const std::vector<KindCase> kinds = kindCases();
    const struct {
        const char* rib;
        int kind;     // index in kindCases()
        float zTop;   // the march starts here: the top of the surface (the cone's implicit form goes on)
        float minNz;  // pixels whose normal is steeper mix normals across the pixel: not compared
        float minDot = 0.998f;  // cos of the largest angle allowed (3.6 degrees)
    } cases[] = {{"Sphere 1.3 -1.3 1.3 360", 0, 1.4f, 0.5f},
                 {"Cone 2 0.8 360", 2, 1.999f, 0.3f},
                 // At the apex the normal turns 37 degrees across the first ring of micropolygons (about
                 // a pixel): Reyes' interpolated normal is within 4 degrees there.
                 {"Paraboloid 1 0 2 360", 4, 2.f, 0.3f, 0.997f},
                 {"Torus 1 0.3 0 360 360", 6, 0.4f, 0.5f}};
    const int res = 48;
    for (const auto& c : cases) {
        const std::function<double(Vec3)>& F = kinds[c.kind].f.F;
        Scene s = load(topView(c.rib, res)).scene;
        const Projector pr(s.camera);
        const Mat4 worldFromCamera = s.camera.cameraFromWorld.inverse();
        for (const char* engine : {"reyes", "rt"}) {
            SCOPED_TRACE(std::string(c.rib) + " " + engine);
            RenderSettings rs;
            rs.engine = engine;
            rs.threads = 2;
            rs.output.channels = kChannelNormal;
            const Image img = render(s, rs).image;
            const ImagePlane* N = img.plane("N");
            ASSERT_NE(N, nullptr);
            int compared = 0;
            for (int y = 0; y < res; ++y)
                for (int x = 0; x < res; ++x) {
                    if (alphaAt(img, x, y) < 1.f) continue;
                    const Vec3 top = worldFromCamera.point(pr.fromRaster(x + 0.5f, y + 0.5f));
                    // March down from the top to the first sign change, then bisect.
                    float z0 = c.zTop, z1 = c.zTop;
                    const double f0 = F({top.x, top.y, z0});
                    bool found = false;
                    for (float z = c.zTop; z > -3.f; z -= 0.01f)
                        if ((F({top.x, top.y, z}) < 0) != (f0 < 0)) {
                            z1 = z, z0 = z + 0.01f, found = true;
                            break;
                        }
                    if (!found) continue;
                    for (int it = 0; it < 40; ++it) {
                        const float zm = 0.5f * (z0 + z1);
                        ((F({top.x, top.y, zm}) < 0) == (f0 < 0) ? z0 : z1) = zm;
                    }
                    Vec3 g = gradient(F, {top.x, top.y, 0.5f * (z0 + z1)});
                    g = normalize(s.camera.cameraFromWorld.vector(g));
                    if (std::fabs(g.z) < c.minNz) continue;
                    if (c.kind == 2 && std::hypot(top.x, top.y) < 0.15f) continue;  // the cone's apex
                    if (g.z > 0.f) g = -g;  // facing the viewer, as the channel is
                    const size_t i = img.index(x, y) * 3;
                    const Vec3 n = normalize(Vec3{N->values[i], N->values[i + 1], N->values[i + 2]});
                    EXPECT_GT(dot(n, g), c.minDot) << x << "," << y;
                    ++compared;
                }
            EXPECT_GT(compared, 150);
        }
    }
}

// Ray-traced effects on quadrics, seen from straight above: a sphere lit from a slanted light shadows the
// floor disk beside it; a mirror sphere reflects the lit floor near its rim (its centre looks up into the
// black sky); a glass sphere shows the floor through it.
TEST(QuadricEngines, ShadowsMirrorAndGlassWorkOnQuadrics) {
    const std::string rib = R"(Format 64 64 1
PixelSamples 2 2
Projection "orthographic"
ScreenWindow -2 2 -2 2
Translate 0 0 5
Rotate 180 1 0 0
WorldBegin
LightSource "ambientlight" 1 "intensity" [ 0.05 ]
Attribute "light" "shadows" [ "on" ]
LightSource "distantlight" 2 "intensity" [ 1 ] "from" [ 3 3 10 ] "to" [ 0 0 0 ]
Surface "matte"
Disk 0 2 360
AttributeBegin Translate 0.9 0.9 1 Sphere 0.5 -0.5 0.5 360 AttributeEnd
AttributeBegin Translate -0.9 -0.9 1 Surface "glass" Sphere 0.5 -0.5 0.5 360 AttributeEnd
AttributeBegin Translate 0.9 -0.9 0.6 Surface "mirror" Sphere 0.5 -0.5 0.5 360 AttributeEnd
WorldEnd
)";
    Scene s = load(rib).scene;
    RenderSettings rs;
    rs.engine = "rt";
    rs.threads = 2;
    const Image img = render(s, rs).image;
    for (int y = 0; y < 64; ++y)
        for (int x = 0; x < 64; ++x)
            for (int c = 0; c < 4; ++c) ASSERT_TRUE(std::isfinite(img.pixel(x, y)[c]));
    const Projector pr(s.camera);
    auto red = [&](float wx, float wy, float wz) {
        const Vec3 r = pr.toRaster(s.camera.cameraFromWorld.point({wx, wy, wz}));
        return img.pixel(int(r.x), int(r.y))[0];
    };
    const float lit = red(-0.9f, 0.9f, 0.f);  // open floor
    EXPECT_GT(lit, 0.7f);
    // The light comes from (3, 3, 10): the opaque sphere's shadow falls towards (-x, -y) of it.
    EXPECT_LT(red(0.9f - 0.55f, 0.9f - 0.55f, 0.f), 0.2f * lit) << "the sphere's shadow on the disk";
    // Mirror: the rim (normal tilted ~60 degrees) sees the floor, the centre the sky.
    const float rim = red(0.9f - 0.44f, -0.9f, 1.1f), centre = red(0.9f, -0.9f, 1.1f);
    EXPECT_GT(rim, centre + 0.2f) << "rim " << rim << " centre " << centre;
    // Glass: the sphere's centre shows what is behind it (refraction), not a lit matte surface: the same
    // scene with a matte sphere there differs.
    std::string matte = rib;
    matte.replace(matte.find("Surface \"glass\""), 16, "Surface \"matte\"");
    Scene ms = load(matte).scene;
    const Image mimg = render(ms, rs).image;
    const Vec3 g = pr.toRaster(s.camera.cameraFromWorld.point({-0.9f, -0.9f, 1.5f}));
    EXPECT_GT(std::fabs(img.pixel(int(g.x), int(g.y))[0] - mimg.pixel(int(g.x), int(g.y))[0]), 0.2f);
}

// ---- both engines on all seven ---------------------------------------------------------------------

const char* kAllSeven = R"(Format 160 120 1
PixelSamples 4 4
Projection "perspective" "fov" [ 40 ]
Transform [ 1 0 0 0  0 0.434299 0.900769 0  0 0.900769 -0.434299 0  0 -0.627321 12.5143 1 ]
WorldBegin
LightSource "ambientlight" 1 "intensity" [ 0.15 ]
LightSource "distantlight" 2 "intensity" [ 0.9 ] "from" [ -6 -8 12 ] "to" [ 0 0 0 ]
Surface "plastic"
Sides 2
AttributeBegin Translate -4.2 1.8 1 Rotate -60 0 0 1 Color [ 0.85 0.3 0.25 ] Sphere 1 -1 1 300 AttributeEnd
AttributeBegin Translate -1.4 1.8 0 Rotate -45 0 0 1 Color [ 0.3 0.6 0.85 ] Cylinder 0.8 0 2 270 AttributeEnd
AttributeBegin Translate 1.4 1.8 0 Color [ 0.9 0.75 0.3 ] Cone 2.2 1 360 AttributeEnd
AttributeBegin Translate 4.2 1.8 0.45 Rotate 20 1 0 0 Color [ 0.55 0.8 0.4 ] Torus 0.8 0.35 0 360 360 AttributeEnd
AttributeBegin Translate -3 -1.6 0 Rotate -60 0 0 1 Color [ 0.75 0.45 0.8 ] Paraboloid 1 0.2 1.8 300 AttributeEnd
AttributeBegin Translate 0 -1.6 0 Color [ 0.35 0.75 0.7 ] Hyperboloid 0.9 -0.4 0  0.4 0.9 1.6  360 AttributeEnd
AttributeBegin Sides 1 Translate 3 -1.6 0.3 Rotate 35 1 0 0 Color [ 0.9 0.55 0.35 ] Disk 0 1 320 AttributeEnd
WorldEnd
)";

TEST(QuadricEngines, ReyesAndTheRayTracerAgreeOnAllSeven) {
    Loaded l = load(kAllSeven);
    EXPECT_EQ(l.scene.quadrics.size(), 7u);
    RenderSettings rs;
    rs.threads = 2;
    rs.engine = "reyes";
    const Image reyes = render(l.scene, rs).image;
    rs.engine = "rt";
    const Image rt = render(l.scene, rs).image;
    const ImageDiff d = compareImages(reyes, rt);
    std::printf("all seven quadrics, reyes vs rt: PSNR %.2f dB, alpha mismatch %.5f, mean |alpha| %.5f\n",
                d.psnrColor, d.alphaMismatch, d.meanAbsAlpha);
    EXPECT_GE(d.psnrColor, 40.0);
    EXPECT_LE(d.alphaMismatch, 0.002);
    EXPECT_LE(d.meanAbsAlpha, 0.003);
}

// ---- input -----------------------------------------------------------------------------------------

TEST(QuadricInput, BadParameterListsFailNamingTheLine) {
    const std::string head = "WorldBegin\n";
    EXPECT_TRUE(contains(expectError(head + "Sphere 1 -1 1\nWorldEnd\n", 2), "expects 4 numbers"));
    EXPECT_TRUE(contains(expectError(head + "\nTorus 1 0.2 0 360\nWorldEnd\n", 3), "expects 5 numbers"));
    EXPECT_TRUE(
        contains(expectError(head + "Hyperboloid 1 0 0 0 1 1 360 5\nWorldEnd\n", 2), "expects 7 numbers"));
    EXPECT_TRUE(contains(expectError(head + "Cone 1 \"radius\" 360\nWorldEnd\n", 2), "expects 3 numbers"));
    EXPECT_TRUE(contains(expectError(head + "Paraboloid 1 -1 1 360\nWorldEnd\n", 2), "same side of z = 0"));
    EXPECT_TRUE(contains(expectError(head + "Paraboloid 1 0 0 360\nWorldEnd\n", 2), "zmax must not be 0"));
    EXPECT_TRUE(contains(expectError("Sphere 1 -1 1 360\n", 1), "outside WorldBegin"));
    EXPECT_TRUE(contains(expectError(head + "Scale 0 1 1\nDisk 0 1 360\nWorldEnd\n", 3), "singular"));
}

TEST(QuadricInput, EmptySurfacesWarnAndAddNothing) {
    Loaded l = load(
        "WorldBegin\nSphere 0 -1 1 360\nCylinder 1 0.5 0.5 360\nTorus 1 0.2 0 360 0\n"
        "Disk 0 1 360\nWorldEnd\n");
    EXPECT_EQ(l.scene.quadrics.size(), 1u);  // the disk
    ASSERT_GE(l.warnings.size(), 3u);
    EXPECT_TRUE(contains(l.warnings[0], ":2:") && contains(l.warnings[0], "radius is 0"));
    EXPECT_TRUE(contains(l.warnings[1], ":3:") && contains(l.warnings[1], "zmin equals zmax"));
    EXPECT_TRUE(contains(l.warnings[2], ":4:") && contains(l.warnings[2], "thetamax is 0"));
}

TEST(QuadricInput, ArgumentsAsAnArrayAndParametersAreRead) {
    Loaded l = load("WorldBegin\nSphere [1 -0.5 2 720] \"st\" [0 0 1 0 0 1 1 1]\nWorldEnd\n");
    ASSERT_EQ(l.scene.quadrics.size(), 1u);
    const Quadric& q = l.scene.quadrics[0].q;
    EXPECT_EQ(q.kind, QuadricKind::Sphere);
    EXPECT_FLOAT_EQ(q.zMin, -0.5f);
    EXPECT_FLOAT_EQ(q.zMax, 1.f);  // clamped to the radius
    EXPECT_TRUE(q.closedU);        // thetamax clamped to 360
    EXPECT_EQ(l.scene.attributes[0].kind, SurfaceKind::Sphere);
}

TEST(QuadricInput, MovingQuadricsWarnOnceAndRenderAtShutterOpen) {
    Loaded l = load(
        "Shutter 0 1\nWorldBegin\nMotionBegin [0 1]\nTranslate 0 0 0\nTranslate 1 0 0\nMotionEnd\n"
        "Sphere 1 -1 1 360\nSphere 1 -1 1 360\nMotionBegin [0 1]\nDisk 0 1 360\nDisk 0 2 360\n"
        "MotionEnd\nWorldEnd\n");
    ASSERT_EQ(l.scene.quadrics.size(), 3u);
    int moving = 0, motionBlock = 0;
    for (const std::string& w : l.warnings) {
        moving += contains(w, "rendered at shutter open");
        motionBlock += contains(w, "first key is used");
    }
    EXPECT_EQ(moving, 1);
    EXPECT_EQ(motionBlock, 1);
    EXPECT_FLOAT_EQ(l.scene.quadrics[2].q.radius, 1.f);
    EXPECT_FALSE(l.scene.hasMotion() && l.scene.attributes[0].motion.moving());
}

}  // namespace
}  // namespace tessera::test::quadrics_tests
