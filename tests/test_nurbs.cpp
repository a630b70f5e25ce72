// NURBS -> Bezier conversion by knot insertion: the Bezier patches must reproduce the NURBS surface
// evaluated directly (Cox-de Boor), and the RIB NuPatch request must convert and diagnose correctly.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>

#include "core/nurbs.h"
#include "io/scene_loader.h"
#include "test_support.h"

namespace tessera::test::nurbs_tests {

namespace fs = std::filesystem;

namespace {

fs::path testDir() {
    return tessera::test::testScratchDir();
}

std::string writeFile(const std::string& name, const std::string& text) {
    fs::path p = testDir() / name;
    std::ofstream(p, std::ios::binary) << text;
    return p.string();
}

// Random knot vector of n + order values: clamped or not, with some repeated interior knots.
std::vector<double> randomKnots(std::mt19937& rng, int n, int order, bool clamped) {
    std::uniform_real_distribution<double> step(0.2, 1.5);
    std::uniform_int_distribution<int> coin(0, 4);
    std::vector<double> k;
    double t = -1.0;
    while (int(k.size()) < n + order) {
        if (k.empty() || coin(rng) != 0) t += step(rng);  // 1 in 5: repeat the previous knot
        k.push_back(t);
    }
    if (clamped) {
        for (int i = 0; i < order; ++i) k[size_t(i)] = k[size_t(order - 1)];
        for (int i = 0; i < order; ++i) k[k.size() - 1 - size_t(i)] = k[k.size() - size_t(order)];
    }
    // Never more than `order` equal knots.
    for (size_t i = size_t(order); i < k.size(); ++i)
        if (k[i] == k[i - size_t(order)]) k[i] += 0.25;
    std::sort(k.begin(), k.end());
    return k;
}

NurbsSurface randomSurface(std::mt19937& rng, int uorder, int vorder, bool clamped, bool clip);

// A random surface that passes validation (repeated knots can leave an empty domain; draw again then).
NurbsSurface validSurface(std::mt19937& rng, int uorder, int vorder, bool clamped, bool clip) {
    while (true) {
        NurbsSurface s = randomSurface(rng, uorder, vorder, clamped, clip);
        try {
            validateNurbs(s);
            return s;
        } catch (const NurbsError&) {
        }
    }
}

NurbsSurface randomSurface(std::mt19937& rng, int uorder, int vorder, bool clamped, bool clip) {
    std::uniform_int_distribution<int> count(0, 5);
    std::uniform_real_distribution<float> coord(-2.f, 2.f);
    NurbsSurface s;
    s.uorder = uorder;
    s.vorder = vorder;
    s.nu = uorder + count(rng);
    s.nv = vorder + count(rng);
    s.uknot = randomKnots(rng, s.nu, uorder, clamped);
    s.vknot = randomKnots(rng, s.nv, vorder, clamped);
    s.umin = s.uknot[size_t(uorder - 1)];
    s.umax = s.uknot[size_t(s.nu)];
    s.vmin = s.vknot[size_t(vorder - 1)];
    s.vmax = s.vknot[size_t(s.nv)];
    if (clip) {  // keep an inner part of the range, cutting through knot spans
        double du = s.umax - s.umin, dv = s.vmax - s.vmin;
        s.umin += 0.13 * du, s.umax -= 0.21 * du;
        s.vmin += 0.27 * dv, s.vmax -= 0.08 * dv;
    }
    for (int i = 0; i < s.nu * s.nv; ++i) s.cp.push_back({coord(rng), coord(rng), coord(rng)});
    return s;
}

// The breakpoints nurbsToBezier splits [lo, hi] at.
std::vector<double> spans(const std::vector<double>& knots, double lo, double hi) {
    std::vector<double> b{lo};
    for (double t : knots)
        if (t > lo && t < hi && t != b.back()) b.push_back(t);
    b.push_back(hi);
    return b;
}

// Max distance between the Bezier patches and direct NURBS evaluation at random (u, v), relative to the
// control-point bounding box.
double maxRelativeError(std::mt19937& rng, const NurbsSurface& s, int samples) {
    std::vector<BezierPatch> patches = nurbsToBezier(s);
    std::vector<double> bu = spans(s.uknot, s.umin, s.umax), bv = spans(s.vknot, s.vmin, s.vmax);
    EXPECT_EQ(patches.size(), (bu.size() - 1) * (bv.size() - 1));
    EXPECT_EQ(patches.size(), nurbsPatchCount(s));
    Bounds3 box;
    for (Vec3 p : s.cp) box.extend(p);
    double scale = length(box.diagonal());
    std::uniform_real_distribution<double> U(s.umin, s.umax), V(s.vmin, s.vmax);
    double worst = 0;
    for (int i = 0; i < samples; ++i) {
        double u = U(rng), v = V(rng);
        if (i == 0) u = s.umin, v = s.vmin;  // the corners of the kept range too
        if (i == 1) u = s.umax, v = s.vmax;
        size_t su = size_t(std::upper_bound(bu.begin(), bu.end(), u) - bu.begin()) - 1;
        size_t sv = size_t(std::upper_bound(bv.begin(), bv.end(), v) - bv.begin()) - 1;
        su = std::min(su, bu.size() - 2);
        sv = std::min(sv, bv.size() - 2);
        float lu = float((u - bu[su]) / (bu[su + 1] - bu[su])),
              lv = float((v - bv[sv]) / (bv[sv + 1] - bv[sv]));
        Vec3 a = evalPatch(patches[su * (bv.size() - 1) + sv], lu, lv);
        Vec3 b = evalNurbs(s, u, v);
        worst = std::max(worst, double(length(a - b)) / scale);
    }
    return worst;
}

}  // namespace

TEST(Nurbs, BezierExtractionMatchesDeBoorClamped) {
    std::mt19937 rng(1);
    for (int trial = 0; trial < 40; ++trial)
        EXPECT_LT(maxRelativeError(rng, validSurface(rng, 4, 4, true, false), 200), 1e-5)
            << "trial " << trial;
}

TEST(Nurbs, BezierExtractionMatchesDeBoorUnclampedAndClipped) {
    std::mt19937 rng(2);
    for (int trial = 0; trial < 40; ++trial) {
        EXPECT_LT(maxRelativeError(rng, validSurface(rng, 4, 4, false, false), 200), 1e-5)
            << "trial " << trial;
        EXPECT_LT(maxRelativeError(rng, validSurface(rng, 4, 4, trial % 2 == 0, true), 200), 1e-5)
            << "trial " << trial;
    }
}

TEST(Nurbs, LowerOrdersAreDegreeElevatedExactly) {
    std::mt19937 rng(3);
    for (int uo = 2; uo <= 4; ++uo)
        for (int vo = 2; vo <= 4; ++vo)
            for (int trial = 0; trial < 5; ++trial)
                EXPECT_LT(maxRelativeError(rng, validSurface(rng, uo, vo, trial % 2 == 0, trial == 4), 100),
                          1e-5)
                    << "orders " << uo << " " << vo;
}

TEST(Nurbs, SingleSpanIsTheBezierPatch) {
    // Knots 0 0 0 0 1 1 1 1: the NURBS is the Bezier patch of its control points.
    NurbsSurface s;
    s.nu = s.nv = 4;
    s.uknot = s.vknot = {0, 0, 0, 0, 1, 1, 1, 1};
    s.umin = s.vmin = 0;
    s.umax = s.vmax = 1;
    for (int i = 0; i < 16; ++i) s.cp.push_back({float(i % 4), float(i / 4), float((i * 7) % 5)});
    auto patches = nurbsToBezier(s);
    ASSERT_EQ(patches.size(), 1u);
    for (int i = 0; i < 16; ++i) EXPECT_EQ(patches[0].cp[i], s.cp[size_t(i)]);
}

TEST(Nurbs, ValidationMessages) {
    NurbsSurface s;
    s.nu = s.nv = 4;
    s.uknot = s.vknot = {0, 0, 0, 0, 1, 1, 1, 1};
    s.cp.assign(16, Vec3{});
    EXPECT_NO_THROW(validateNurbs(s));
    auto message = [](NurbsSurface t) -> std::string {
        try {
            validateNurbs(t);
        } catch (const NurbsError& e) {
            return e.what();
        }
        return "";
    };
    NurbsSurface t = s;
    t.uknot.pop_back();
    EXPECT_NE(message(t).find("uknot has 7 values, expected 8"), std::string::npos) << message(t);
    t = s;
    t.vknot = {0, 0, 0, 0, 1, 0.5, 1, 1};
    EXPECT_NE(message(t).find("vknot is decreasing"), std::string::npos) << message(t);
    t = s;
    t.cp.pop_back();
    EXPECT_NE(message(t).find("expected 16 control points"), std::string::npos) << message(t);
    t = s;
    t.uorder = 5;
    t.uknot.push_back(1);
    EXPECT_NE(message(t).find("uorder 5 is not supported"), std::string::npos) << message(t);
    t = s;
    t.umax = 2;
    EXPECT_NE(message(t).find("outside the knot domain"), std::string::npos) << message(t);
    t = s;
    t.vmin = t.vmax = 0.5;
    EXPECT_NE(message(t).find("vmin must be less than vmax"), std::string::npos) << message(t);
}

TEST(Nurbs, KillerooGives11532Patches) {
    std::string path = std::string(TESSERA_SHARED_DATA) + "/killeroo/ribtools/killeroo.rib";
    if (!fs::exists(path)) GTEST_SKIP() << "shared data not found: " << path;
    Scene s = loadScene(path, {});
    EXPECT_EQ(s.patches.size(), 11532u);
    EXPECT_EQ(s.objectCount, 1u);  // 89 NuPatch requests in one attribute block: one object
    // SOURCES.md: the Bezier control points' bounding box.
    Bounds3 b;
    for (const BezierPatch& p : s.patches) b.extend(hullBounds(p));
    EXPECT_NEAR(b.lo.x, -35.95221, 1e-3);
    EXPECT_NEAR(b.lo.y, -246.44, 1e-3);
    EXPECT_NEAR(b.lo.z, -140.563, 1e-3);
    EXPECT_NEAR(b.hi.x, 35.88657, 1e-3);
    EXPECT_NEAR(b.hi.y, 151.19011, 1e-3);
    EXPECT_NEAR(b.hi.z, 41.9743, 1e-3);
}

TEST(Nurbs, ShippedKillerooSceneMatchesSharedData) {
    std::string shipped = std::string(TESSERA_SOURCE_DIR) + "/scenes/killeroo.rib";
    if (!fs::exists(shipped)) GTEST_SKIP() << "scenes/killeroo.rib not present";
    Scene s = loadScene(shipped, {});
    EXPECT_EQ(s.patches.size(), 11532u);
    EXPECT_FALSE(s.lights.empty());
}

// ---- RIB NuPatch -----------------------------------------------------------------------------

namespace {

const char* kGrid16 =
    "0 0 0 1 0 0 2 0 0 3 0 0  0 1 0 1 1 1 2 1 1 3 1 0  0 2 0 1 2 1 2 2 1 3 2 0  0 3 0 1 3 0 2 3 0 3 3 0";

std::string nuPatchRib(const std::string& nupatch) {
    return "WorldBegin\nLightSource \"ambientlight\" 1\n" + nupatch + "\nWorldEnd\n";
}

std::string errorOf(const std::string& text, int& line) {
    std::string path = writeFile("scene.rib", text);
    try {
        loadScene(path, {});
    } catch (const InputError& e) {
        line = e.line();
        EXPECT_EQ(e.file(), path);
        return e.what();
    }
    line = 0;
    return "";
}

}  // namespace

TEST(NuPatchRib, BicubicWithPAndPw) {
    std::string pw;
    {
        // Same 16 points with w = 1.
        std::istringstream in(kGrid16);
        float x, y, z;
        while (in >> x >> y >> z)
            pw += std::to_string(x) + " " + std::to_string(y) + " " + std::to_string(z) + " 1 ";
    }
    for (const std::string& param : {std::string("\"P\" [") + kGrid16 + "]", "\"Pw\" [" + pw + "]"}) {
        std::string path = writeFile(
            "scene.rib", nuPatchRib("NuPatch 4 4 [0 0 0 0 1 1 1 1] 0 1 4 4 [0 0 0 0 2 2 2 2] 0 2\n" + param));
        Scene s = loadScene(path, {});
        ASSERT_EQ(s.patches.size(), 1u);
        EXPECT_EQ(s.patches[0].at(1, 1), (Vec3{1, 1, 1}));
        EXPECT_EQ(s.patches[0].at(3, 3), (Vec3{3, 3, 0}));
    }
}

TEST(NuPatchRib, ClippedRangeAndSpans) {
    // 5 x 4 control points, uknot with one interior knot: 2 u spans; vmin/vmax clip to the middle.
    std::string pts;
    for (int j = 0; j < 4; ++j)
        for (int i = 0; i < 5; ++i)
            pts += std::to_string(i) + " " + std::to_string(j) + " " + std::to_string((i * j) % 3) + " ";
    std::string path =
        writeFile("scene.rib",
                  nuPatchRib("NuPatch 5 4 [0 0 0 0 1 2 2 2 2] 0 2 4 4 [0 0 0 0 1 1 1 1] 0.25 0.75 \"P\" [" +
                             pts + "]"));
    Scene s = loadScene(path, {});
    EXPECT_EQ(s.patches.size(), 2u);
    path = writeFile(
        "scene.rib",
        nuPatchRib("NuPatch 5 4 [0 0 0 0 1 2 2 2 2] 0.5 0.9 4 4 [0 0 0 0 1 1 1 1] 0 1 \"P\" [" + pts + "]"));
    s = loadScene(path, {});
    EXPECT_EQ(s.patches.size(), 1u);
}

TEST(NuPatchRib, Errors) {
    int line = 0;
    std::string head = "WorldBegin\nLightSource \"ambientlight\" 1\n";
    // Knot vector of the wrong length.
    std::string msg = errorOf(head + "NuPatch 4 4 [0 0 0 1 1 1 1] 0 1 4 4 [0 0 0 0 1 1 1 1] 0 1 \"P\" [" +
                                  kGrid16 + "]\nWorldEnd\n",
                              line);
    EXPECT_EQ(line, 3) << msg;
    EXPECT_NE(msg.find("uknot has 7 values, expected 8"), std::string::npos) << msg;
    // Decreasing knots.
    msg = errorOf(head + "\nNuPatch 4 4 [0 0 0 0 1 1 1 1] 0 1 4 4 [0 0 0 1 0 1 1 1] 0 1 \"P\" [" + kGrid16 +
                      "]\nWorldEnd\n",
                  line);
    EXPECT_EQ(line, 4) << msg;
    EXPECT_NE(msg.find("vknot is decreasing"), std::string::npos) << msg;
    // Wrong number of points.
    msg = errorOf(
        head + "NuPatch 4 4 [0 0 0 0 1 1 1 1] 0 1 4 4 [0 0 0 0 1 1 1 1] 0 1 \"P\" [0 0 0 1 1 1]\nWorldEnd\n",
        line);
    EXPECT_EQ(line, 3) << msg;
    EXPECT_NE(msg.find("needs 48 values"), std::string::npos) << msg;
    // Rational.
    std::string pw;
    for (int i = 0; i < 16; ++i) pw += std::to_string(i) + " 0 0 " + (i == 5 ? "2 " : "1 ");
    msg = errorOf(head + "NuPatch 4 4 [0 0 0 0 1 1 1 1] 0 1 4 4 [0 0 0 0 1 1 1 1] 0 1\n \"Pw\" [" + pw +
                      "]\nWorldEnd\n",
                  line);
    EXPECT_EQ(line, 4) << msg;
    EXPECT_NE(msg.find("rational NURBS"), std::string::npos) << msg;
    // Unsupported order.
    msg = errorOf(head + "NuPatch 5 5 [0 0 0 0 0 1 1 1 1 1] 0 1 4 4 [0 0 0 0 1 1 1 1] 0 1 \"P\" [" + kGrid16 +
                      " 0 0 0 0 0 0 0 0 0 0 0 0]\nWorldEnd\n",
                  line);
    EXPECT_EQ(line, 3) << msg;
    EXPECT_NE(msg.find("uorder 5 is not supported"), std::string::npos) << msg;
    // Range outside the knot domain.
    msg = errorOf(head + "NuPatch 4 4 [0 0 0 0 1 1 1 1] 0 3 4 4 [0 0 0 0 1 1 1 1] 0 1 \"P\" [" + kGrid16 +
                      "]\nWorldEnd\n",
                  line);
    EXPECT_EQ(line, 3) << msg;
    EXPECT_NE(msg.find("outside the knot domain"), std::string::npos) << msg;
}

}  // namespace tessera::test::nurbs_tests
