// Selective and adaptive supersampling (--adaptive, paper 004; docs/adaptive.md): which subpixels the
// presample's test refines, against analytic edges, and the weighting against fixed 16 spp.
#include <gtest/gtest.h>

#include <cmath>

#include "film/adaptive.h"
#include "render/render.h"
#include "render/render_options.h"
#include "test_util.h"

namespace tessera::test::adaptive_tests {

namespace {

AdaptiveThresholds allThresholds(float t) {
    AdaptiveThresholds a;
    a.color = a.objectId = a.normal = a.shadow = a.texture = t;
    a.secondaryObjectId = a.secondaryNormal = a.secondaryShadow = a.secondaryTexture = t;
    return a;
}

RenderResult renderAdaptive(const Scene& s, const AdaptiveThresholds& t, int threads = 2,
                            std::vector<uint32_t> focus = {}, bool interpolate = false,
                            Integrator integrator = Integrator::Direct) {
    RenderSettings rs;
    rs.integrator = integrator;
    rs.engine = "rt";
    rs.threads = threads;
    rs.adaptive.enabled = true;
    rs.adaptive.thresholds = t;
    rs.adaptive.focusObjects = std::move(focus);
    rs.adaptive.interpolate = interpolate;
    return render(s, rs);
}

bool refined(const RenderResult& r, int x, int y, int q) {
    const int w = 2 * r.image.width;
    return r.refinedSubpixels[size_t(2 * y + q / 2) * size_t(w) + size_t(2 * x + (q & 1))] != 0;
}

size_t refinedCount(const RenderResult& r) {
    size_t n = 0;
    for (uint8_t v : r.refinedSubpixels) n += v;
    return n;
}

}  // namespace

TEST(Adaptive, EachSubpixelIsComparedWithTheThreeNeighboursTowardsItsCorner) {
    // Paper 004, Fig. 4: the upper-left subpixel with W, NW, N; the lower-right with E, SE, S (y down).
    const int expect[4][3][2] = {{{-1, 0}, {-1, -1}, {0, -1}},
                                 {{1, 0}, {1, -1}, {0, -1}},
                                 {{-1, 0}, {-1, 1}, {0, 1}},
                                 {{1, 0}, {1, 1}, {0, 1}}};
    for (int q = 0; q < 4; ++q)
        for (int k = 0; k < 3; ++k) {
            int dx, dy;
            subpixelNeighbour(q, k, dx, dy);
            EXPECT_EQ(dx, expect[q][k][0]) << q << " " << k;
            EXPECT_EQ(dy, expect[q][k][1]) << q << " " << k;
        }
    // Mitchell's contrast: (0.5 - 0.25) / 0.75 = 1/3 against 1.02 tau in green.
    EXPECT_FLOAT_EQ(mitchellContrast(0.5f, 0.25f), 1.f / 3.f);
    EXPECT_TRUE(contrastExceeds({1, 0.5f, 1}, {1, 0.25f, 1}, 0.3f));    // 1/3 >= 0.306
    EXPECT_FALSE(contrastExceeds({1, 0.5f, 1}, {1, 0.25f, 1}, 0.35f));  // 1/3 < 0.357
}

TEST(Adaptive, AFlatColouredPatchRefinesNothing) {
    Scene s = cameraSpaceScene(24, 24, 40.f);
    addPatch(s, flatSquare(100.f, 10.f));  // fills the view: one colour (distant light, flat, one object)
    const RenderResult r = renderAdaptive(s, AdaptiveThresholds{});
    ASSERT_EQ(r.refinedSubpixels.size(), size_t(48 * 48));
    EXPECT_EQ(refinedCount(r), 0u);
    EXPECT_EQ(r.stats["adaptive"]["active_subpixels"].get<uint64_t>(), 0u);
    EXPECT_DOUBLE_EQ(r.stats["adaptive"]["camera_rays_per_pixel"].get<double>(), 1.0);
    const float* c = r.image.pixel(12, 12);
    EXPECT_GT(c[0], 0.1f);
    EXPECT_FLOAT_EQ(c[3], 1.f);
}

TEST(Adaptive, AnObjectIdEdgeRefinesExactlyAlongTheEdge) {
    // Two flat squares of the same material meet at x = 0, the boundary between pixel columns 11 and 12:
    // the same colour on both sides, so only the object-id path (tau_poid = 0) can refine, and exactly the
    // subpixels of columns 11 (right half) and 12 (left half) whose neighbours lie across the edge.
    Scene s = cameraSpaceScene(24, 16, 40.f);
    addPatch(s, planarPatch({-50, -50, 10}, {50, 0, 0}, {0, 100, 0}), 0);
    addPatch(s, planarPatch({0, -50, 10}, {50, 0, 0}, {0, 100, 0}), 1);
    AdaptiveThresholds t = allThresholds(1.f);
    t.objectId = 0.f;
    const RenderResult r = renderAdaptive(s, t);
    for (int y = 0; y < 16; ++y)
        for (int x = 0; x < 24; ++x)
            for (int q = 0; q < 4; ++q) {
                const bool expect = (x == 11 && (q & 1)) || (x == 12 && !(q & 1));
                EXPECT_EQ(refined(r, x, y, q), expect) << x << "," << y << " q" << q;
            }
    // The colour alone (the default tau_col, object ids ignored) sees no edge.
    t = AdaptiveThresholds{};
    t.objectId = 1.f;
    EXPECT_EQ(refinedCount(renderAdaptive(s, t)), 0u);
}

TEST(Adaptive, AnEdgeInsideTheOutermostPixelsIsRefined) {
    // A square covering the view but for the last 0.3 of the rightmost pixel column (its edge at raster
    // x = 23.7, right of that column's centre): every presample sees the square, and only the neighbour
    // beyond the image's edge shows the background. The presample reaches that far, so the right subpixels
    // of column 23 (and nothing else) refine and its alpha falls towards the true coverage 0.7.
    const int w = 24, h = 16;
    Scene s = cameraSpaceScene(w, h, 40.f);
    // RI: the field of view spans the shorter side of the frame.
    const float pixel = 2.f * 10.f * std::tan(20.f * float(M_PI) / 180.f) / float(h);  // at z = 10
    const float edge = (23.7f - 12.f) * pixel;                                         // raster 12: x = 0
    addPatch(s, planarPatch({-50, -50, 10}, {50 + edge, 0, 0}, {0, 100, 0}));
    const RenderResult r = renderAdaptive(s, AdaptiveThresholds{});
    for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x)
            for (int q = 0; q < 4; ++q)
                EXPECT_EQ(refined(r, x, y, q), x == w - 1 && (q & 1)) << x << "," << y << " q" << q;
        EXPECT_FLOAT_EQ(r.image.pixel(w - 2, y)[3], 1.f);
        // Left half from the centre (0.5), right half from 8 jittered samples of coverage 0.4 each.
        EXPECT_GT(r.image.pixel(w - 1, y)[3], 0.55f) << y;
        EXPECT_LT(r.image.pixel(w - 1, y)[3], 0.85f) << y;
    }
}

TEST(Adaptive, AShadowBoundaryRefinesEvenWhereTheColoursMatch) {
    // A black floor (Kd = 0, no ambient light) at z = 10 under a unit square at z = 8 lit by a point light
    // at (2, 0, 4): in shadow and lit, the floor has the same colour (0), but the shadow count differs
    // across the shadow's outline x in [-1.75, -0.25], y in [-0.75, 0.75] (the square scaled by 6/4).
    Scene s = cameraSpaceScene(100, 100, 40.f);
    s.lights = {{LightType::Point, {36, 36, 36}, {2, 0, 4}, {0, 0, 0}}};
    s.lights[0].castsShadows = true;
    Material black = defaultMaterial(MaterialType::Matte);
    black.Kd = 0.f, black.Ks = 0.f;
    s.materials.push_back(black);
    addPatch(s, planarPatch({-20, -20, 10}, {40, 0, 0}, {0, 40, 0}), 0);
    s.attributes.back().material = 1;
    addPatch(s, planarPatch({-0.5f, -0.5f, 8}, {1, 0, 0}, {0, 1, 0}), 1);
    AdaptiveThresholds t = allThresholds(1.f);
    t.shadow = 0.f;  // only the shadow-count path refines
    const RenderResult r = renderAdaptive(s, t);
    const Projector pr(s.camera);
    // Raster distance of pixel (x, y)'s centre to the shadow's outline on the floor and to the square's
    // silhouette (both lines of the outline; the floor is at z = 10, the square at z = 8).
    auto rasterX = [&](float cx) { return pr.ox + pr.sx * cx; };
    auto rasterY = [&](float cy) { return pr.oy + pr.sy * cy; };
    auto nearOutline = [&](float px, float py, float x0, float x1, float y0, float y1, float z, float m) {
        const float rx0 = rasterX(x0 / z), rx1 = rasterX(x1 / z);
        const float ry0 = std::min(rasterY(y0 / z), rasterY(y1 / z)),
                    ry1 = std::max(rasterY(y0 / z), rasterY(y1 / z));
        const bool inY = py > ry0 - m && py<ry1 + m, inX = px> rx0 - m && px < rx1 + m;
        return (inY && (std::fabs(px - rx0) < m || std::fabs(px - rx1) < m)) ||
               (inX && (std::fabs(py - ry0) < m || std::fabs(py - ry1) < m));
    };
    int edgeRows = 0;
    const float leftEdge = rasterX(-1.75f / 10.f);
    for (int y = 0; y < 100; ++y) {
        const float py = y + 0.5f;
        bool rowHasEdgeRefined = false;
        for (int x = 0; x < 100; ++x) {
            const float px = x + 0.5f;
            const bool nearShadow = nearOutline(px, py, -1.75f, -0.25f, -0.75f, 0.75f, 10.f, 1.5f);
            const bool nearSquare = nearOutline(px, py, -0.5f, 0.5f, -0.5f, 0.5f, 8.f, 1.5f);
            for (int q = 0; q < 4; ++q) {
                if (!refined(r, x, y, q)) continue;
                EXPECT_TRUE(nearShadow || nearSquare) << "refined away from any boundary: " << x << "," << y;
                if (std::fabs(px - leftEdge) < 1.5f) rowHasEdgeRefined = true;
            }
        }
        // Rows well inside the shadow's height: its left edge (far from the square) is refined.
        const float fy = (py - pr.oy) / pr.sy * 10.f;
        if (std::fabs(fy) < 0.6f) {
            ++edgeRows;
            EXPECT_TRUE(rowHasEdgeRefined) << "row " << y;
        }
    }
    EXPECT_GT(edgeRows, 5);
    // The colours there do match: left of the edge (lit) and right of it (in shadow) both black.
    const int yMid = int(pr.oy);
    EXPECT_EQ(r.image.pixel(int(leftEdge) - 3, yMid)[0], 0.f);
    EXPECT_EQ(r.image.pixel(int(leftEdge) + 3, yMid)[0], 0.f);
    // With the shadow count ignored nothing on the floor's shadow edge refines.
    const RenderResult off = renderAdaptive(s, allThresholds(1.f));
    EXPECT_EQ(refinedCount(off), 0u);
}

namespace {
// Two spheres of different objects, one partly hiding the other, in front of a floor.
Scene twoSpheres(int w, int h) {
    Scene s = cameraSpaceScene(w, h, 40.f);
    s.lights.push_back({LightType::Point, {20, 20, 20}, {3, 3, 2}, {0, 0, 0}});
    s.lights.back().castsShadows = true;
    for (const BezierPatch& p : octantSphere(1.f, {-0.5f, 0.f, 6.f})) addPatch(s, p, 0);
    for (const BezierPatch& p : octantSphere(0.8f, {0.7f, 0.3f, 7.f})) addPatch(s, p, 1);
    addPatch(s, planarPatch({-10, -1, 4}, {20, 0, 0}, {0, 0, 20}), 2);  // floor y = -1
    return s;
}
}  // namespace

TEST(Adaptive, ThresholdZeroRefinesEverythingAndEqualsFixed16WithABoxFilter) {
    // Every subpixel active: the centre's weight is 0 and the pixel is the mean of its 16 stratified samples,
    // which is what the fixed 4x4 render at the same seed computes with a one-pixel box filter.
    Scene s = twoSpheres(32, 24);
    const RenderResult a = renderAdaptive(s, allThresholds(0.f));
    EXPECT_EQ(refinedCount(a), size_t(4 * 32 * 24));
    EXPECT_DOUBLE_EQ(a.stats["adaptive"]["active_fraction"].get<double>(), 1.0);
    s.image.pixelSamplesX = s.image.pixelSamplesY = 4;
    RenderSettings rs;
    rs.engine = "rt";
    rs.threads = 2;
    const RenderResult f = render(s, rs);
    ASSERT_EQ(f.image.rgba.size(), a.image.rgba.size());
    double maxDiff = 0;
    for (size_t i = 0; i < a.image.rgba.size(); ++i)
        maxDiff = std::max(maxDiff, double(std::fabs(a.image.rgba[i] - f.image.rgba[i])));
    EXPECT_LT(maxDiff, 1e-5);
}

TEST(Adaptive, HugeThresholdsRefineNothingAndGiveThePresample) {
    const Scene s = twoSpheres(32, 24);
    const RenderResult r = renderAdaptive(s, allThresholds(10.f));
    EXPECT_EQ(refinedCount(r), 0u);
    EXPECT_DOUBLE_EQ(r.stats["adaptive"]["camera_rays_per_pixel"].get<double>(), 1.0);
    // The default thresholds do refine this scene (silhouettes, shadow edges), but not most of it.
    const RenderResult d = renderAdaptive(s, AdaptiveThresholds{});
    const double fraction = d.stats["adaptive"]["active_fraction"].get<double>();
    EXPECT_GT(fraction, 0.02);
    EXPECT_LT(fraction, 0.6);
}

TEST(Adaptive, SameImageForAnyThreadCount) {
    const Scene s = twoSpheres(48, 32);
    const RenderResult one = renderAdaptive(s, AdaptiveThresholds{}, 1);
    const RenderResult two = renderAdaptive(s, AdaptiveThresholds{}, 2);
    const RenderResult four = renderAdaptive(s, AdaptiveThresholds{}, 4);
    EXPECT_GT(refinedCount(one), 0u);
    EXPECT_EQ(one.image.rgba, two.image.rgba);
    EXPECT_EQ(one.image.rgba, four.image.rgba);
    EXPECT_EQ(one.refinedSubpixels, two.refinedSubpixels);
    EXPECT_EQ(one.refinedSubpixels, four.refinedSubpixels);
}

// Secondary-hit attributes (paper 004, L141): a mirror fills the view and reflects two squares of the same
// constant colour but different objects, meeting at x = 0 behind the camera. Every primary hit is the same
// (mirror, normal, no shadow), the colours match, so only the secondary object id can see the reflected
// edge, which lies on the boundary between pixel columns 11 and 12.
TEST(Adaptive, SecondaryHitAttributesRefineAnEdgeSeenOnlyInAMirror) {
    Scene s = cameraSpaceScene(24, 16, 40.f);
    Material mirror = defaultMaterial(MaterialType::Mirror);
    mirror.Ka = mirror.Kd = mirror.Ks = 0.f;  // reflection only
    Material constant = defaultMaterial(MaterialType::Constant);
    constant.Cs = {0.5f, 0.5f, 0.5f};
    s.materials = {mirror, constant};
    addPatch(s, planarPatch({-50, -50, 10}, {100, 0, 0}, {0, 100, 0}), 0);
    addPatch(s, planarPatch({-200, -200, -5}, {200, 0, 0}, {0, 400, 0}), 1);
    addPatch(s, planarPatch({0, -200, -5}, {200, 0, 0}, {0, 400, 0}), 2);
    s.attributes[1].material = s.attributes[2].material = 1;
    // The path tracer records the hit of its mirror (delta) bounce as the direct integrator does.
    for (Integrator integrator : {Integrator::Direct, Integrator::Path}) {
        AdaptiveThresholds t = allThresholds(1.f);
        t.secondaryObjectId = 0.f;
        const RenderResult r = renderAdaptive(s, t, 2, {}, false, integrator);
        for (int x : {5, 18}) EXPECT_NEAR(r.image.pixel(x, 8)[0], 0.5f, 1e-5f);  // the squares' reflections
        for (int y = 0; y < 16; ++y)
            for (int x = 0; x < 24; ++x)
                for (int q = 0; q < 4; ++q) {
                    const bool expect = (x == 11 && (q & 1)) || (x == 12 && !(q & 1));
                    EXPECT_EQ(refined(r, x, y, q), expect) << x << "," << y << " q" << q;
                }
        // The primary object id sees one object: nothing refines.
        t = allThresholds(1.f);
        t.objectId = 0.f;
        EXPECT_EQ(refinedCount(renderAdaptive(s, t, 2, {}, false, integrator)), 0u);
    }
}

// The "fairy focused" mode (paper 004, L209): three strips of objects 0, 1, 2 with the same colour meet at
// the column boundaries 11|12 and 17|18; with the object id as the only refining attribute, a focus on
// object 2 refines the second edge only, on object 0 the first only, and no focus both.
TEST(Adaptive, TheFocusListLimitsTheAttributesToItsObjects) {
    Scene s = cameraSpaceScene(24, 16, 40.f);
    const Projector pr(s.camera);
    const float x18 = (18.f - pr.ox) / pr.sx * 10.f;  // camera x of raster column boundary 18 at z = 10
    addPatch(s, planarPatch({-50, -50, 10}, {50, 0, 0}, {0, 100, 0}), 0);
    addPatch(s, planarPatch({0, -50, 10}, {x18, 0, 0}, {0, 100, 0}), 1);
    addPatch(s, planarPatch({x18, -50, 10}, {50, 0, 0}, {0, 100, 0}), 2);
    AdaptiveThresholds t = allThresholds(1.f);
    t.objectId = 0.f;
    auto edgeColumns = [&](const RenderResult& r) {
        std::vector<int> cols;
        for (int x = 0; x < 24; ++x) {
            int n = 0;
            for (int y = 0; y < 16; ++y)
                for (int q = 0; q < 4; ++q) n += refined(r, x, y, q);
            if (n) {
                EXPECT_EQ(n, 32) << "column " << x << ": half of its subpixels";
                cols.push_back(x);
            }
        }
        return cols;
    };
    EXPECT_EQ(edgeColumns(renderAdaptive(s, t)), (std::vector<int>{11, 12, 17, 18}));
    EXPECT_EQ(edgeColumns(renderAdaptive(s, t, 2, {2})), (std::vector<int>{17, 18}));
    EXPECT_EQ(edgeColumns(renderAdaptive(s, t, 2, {0})), (std::vector<int>{11, 12}));
    EXPECT_EQ(edgeColumns(renderAdaptive(s, t, 2, {7})), (std::vector<int>{}));
}

// The paper's bilinear option (L215): with nothing refined, each subpixel is the presample interpolated at
// its centre, so the pixel is the presample filtered by (1, 6, 1) / 8 in x and in y; with everything
// refined it changes nothing. Checked inside the image: on its edge the filter reads the presample beyond
// it, which the 32x24 render does not have.
TEST(Adaptive, InterpolatedInactiveSubpixelsFilterThePresample) {
    const Scene s = twoSpheres(32, 24);
    const RenderResult pre = renderAdaptive(s, allThresholds(10.f));
    const RenderResult interp = renderAdaptive(s, allThresholds(10.f), 2, {}, true);
    EXPECT_EQ(refinedCount(interp), 0u);
    const int w = 32, h = 24;
    const float k[3] = {1.f / 8, 6.f / 8, 1.f / 8};
    double maxDiff = 0, changed = 0;
    for (int y = 1; y < h - 1; ++y)
        for (int x = 1; x < w - 1; ++x)
            for (int c = 0; c < 4; ++c) {
                double want = 0;
                for (int j = -1; j <= 1; ++j)
                    for (int i = -1; i <= 1; ++i)
                        want += k[i + 1] * k[j + 1] * pre.image.pixel(x + i, y + j)[c];
                maxDiff = std::max(maxDiff, std::fabs(interp.image.pixel(x, y)[c] - want));
                changed = std::max(changed,
                                   double(std::fabs(interp.image.pixel(x, y)[c] - pre.image.pixel(x, y)[c])));
            }
    EXPECT_LT(maxDiff, 1e-5);
    EXPECT_GT(changed, 0.05);  // the spheres' silhouettes are softened
    const RenderResult all = renderAdaptive(s, allThresholds(0.f), 2, {}, true);
    const RenderResult allPlain = renderAdaptive(s, allThresholds(0.f));
    EXPECT_EQ(all.image.rgba, allPlain.image.rgba);
}

TEST(Adaptive, ThresholdAndFocusOptionsParseOrFailNamingTheProblem) {
    AdaptiveThresholds t;
    parseAdaptiveThresholds("poid=0,ssn=0.25,col=0.6,ste=1", t);
    EXPECT_EQ(t.objectId, 0.f);
    EXPECT_EQ(t.secondaryNormal, 0.25f);
    EXPECT_EQ(t.color, 0.6f);
    EXPECT_EQ(t.secondaryTexture, 1.f);
    EXPECT_EQ(t.shadow, 0.06f);  // untouched
    for (const char* bad : {"", "poid", "poid=", "xyz=0.1", "psn=-1", "psn=nan", "psn=0.1,", "psn=1x"})
        EXPECT_THROW(parseAdaptiveThresholds(bad, t), std::invalid_argument) << bad;
    EXPECT_EQ(parseObjectIds("3,0,12"), (std::vector<uint32_t>{3, 0, 12}));
    for (const char* bad : {"", "3,", "-1", "a", "1.5", "99999999999"})
        EXPECT_THROW(parseObjectIds(bad), std::invalid_argument) << bad;
}

}  // namespace tessera::test::adaptive_tests
