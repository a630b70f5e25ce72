#include <gtest/gtest.h>

#include <bit>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "core/basis.h"
#include "core/bezier.h"
#include "core/transform.h"

namespace tessera::test::bezier_tests {

namespace {
BezierPatch randomPatch(std::mt19937& rng) {
    std::uniform_real_distribution<float> d(-2.f, 2.f);
    BezierPatch p;
    for (auto& c : p.cp) c = {d(rng), d(rng), d(rng)};
    return p;
}
float dist(Vec3 a, Vec3 b) {
    return length(a - b);
}
}  // namespace

TEST(Bezier, FlatBilinearPatchIsExact) {
    // A flat square with evenly spaced control points is the identity map (linear precision).
    BezierPatch p;
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 4; ++u) p.at(u, v) = {u / 3.f, v / 3.f, 0.f};
    for (float u : {0.f, 0.25f, 0.7f, 1.f})
        for (float v : {0.f, 0.5f, 0.9f}) {
            SurfacePoint s = evalPatchDeriv(p, u, v);
            EXPECT_NEAR(s.p.x, u, 1e-6);
            EXPECT_NEAR(s.p.y, v, 1e-6);
            EXPECT_NEAR(s.dpdu.x, 1, 1e-5);
            EXPECT_NEAR(s.dpdv.y, 1, 1e-5);
            EXPECT_NEAR(s.dpdu.y, 0, 1e-5);
        }
}

TEST(Bezier, SplitMatchesEvaluation) {
    std::mt19937 rng(1);
    for (int trial = 0; trial < 50; ++trial) {
        BezierPatch p = randomPatch(rng);
        float t = std::uniform_real_distribution<float>(0.1f, 0.9f)(rng);
        BezierPatch lo, hi;
        splitPatchU(p, t, lo, hi);
        for (float u : {0.f, 0.3f, 1.f})
            for (float v : {0.f, 0.6f, 1.f}) {
                EXPECT_LT(dist(evalPatch(lo, u, v), evalPatch(p, u * t, v)), 1e-5f);
                EXPECT_LT(dist(evalPatch(hi, u, v), evalPatch(p, t + u * (1 - t), v)), 1e-5f);
            }
        splitPatchV(p, t, lo, hi);
        for (float u : {0.f, 0.3f, 1.f})
            for (float v : {0.f, 0.6f, 1.f}) {
                EXPECT_LT(dist(evalPatch(lo, u, v), evalPatch(p, u, v * t)), 1e-5f);
                EXPECT_LT(dist(evalPatch(hi, u, v), evalPatch(p, u, t + v * (1 - t))), 1e-5f);
            }
        BezierPatch s = subPatch(p, 0.2f, 0.7f, 0.4f, 0.9f);
        for (float u : {0.f, 0.5f, 1.f})
            for (float v : {0.f, 0.25f, 1.f})
                EXPECT_LT(dist(evalPatch(s, u, v), evalPatch(p, 0.2f + 0.5f * u, 0.4f + 0.5f * v)), 2e-5f);
    }
}

TEST(Bezier, DerivativesMatchFiniteDifferences) {
    std::mt19937 rng(2);
    const float h = 1e-3f;
    for (int trial = 0; trial < 50; ++trial) {
        BezierPatch p = randomPatch(rng);
        float u = std::uniform_real_distribution<float>(0.05f, 0.95f)(rng);
        float v = std::uniform_real_distribution<float>(0.05f, 0.95f)(rng);
        SurfacePoint s = evalPatchDeriv(p, u, v);
        Vec3 fu = (evalPatch(p, u + h, v) - evalPatch(p, u - h, v)) / (2 * h);
        Vec3 fv = (evalPatch(p, u, v + h) - evalPatch(p, u, v - h)) / (2 * h);
        EXPECT_LT(dist(s.dpdu, fu), 5e-3f * (1 + length(fu)));
        EXPECT_LT(dist(s.dpdv, fv), 5e-3f * (1 + length(fv)));
    }
}

// The two-step evaluation (rows at u, then v) that the Reyes dicer reuses down a grid column, and that
// evalPatchDeriv is made of, gives the points of evalPatch (a separate one-step loop) bit for bit, so
// reusing it changes no image; its derivatives are checked by DerivativesMatchFiniteDifferences.
TEST(Bezier, RowsAtUGiveTheOneStepBits) {
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    auto same = [](Vec3 a, Vec3 b) { return std::memcmp(&a, &b, sizeof(Vec3)) == 0; };
    int compared = 0;
    for (int trial = 0; trial < 200; ++trial) {
        const BezierPatch p = randomPatch(rng);
        const float u = trial % 10 == 0 ? float(trial % 20 == 0) : unit(rng);  // the domain's ends too
        PatchRowsAtU rows;
        patchRowsAtU(p, u, rows);
        for (int k = 0; k < 8; ++k) {
            const float v = k == 0 ? 0.f : k == 1 ? 1.f : unit(rng);
            const Vec3 onePass = evalPatch(p, u, v);
            EXPECT_TRUE(same(onePass, evalPatchAt(rows, v))) << "u " << u << " v " << v;
            EXPECT_TRUE(same(onePass, evalPatchDerivAt(rows, v).p)) << "u " << u << " v " << v;
            EXPECT_TRUE(same(onePass, evalPatchDeriv(p, u, v).p)) << "u " << u << " v " << v;
            ++compared;
        }
    }
    EXPECT_EQ(compared, 1600);
}

TEST(Bezier, CollapsedEdgeHasFiniteNormal) {
    // A patch whose v=0 edge collapses to a point (like the teapot's lid pole).
    BezierPatch p;
    for (int v = 0; v < 4; ++v)
        for (int u = 0; u < 4; ++u) {
            float r = v / 3.f, a = u / 3.f * 1.5f;
            p.at(u, v) = {r * std::cos(a), r * std::sin(a), 1.f - r * r};
        }
    Vec3 n = normalize(patchNormal(p, 0.5f, 0.f));
    EXPECT_TRUE(isFinite(n));
    EXPECT_GT(std::abs(n.z), 0.9f);  // the pole's tangent plane is horizontal
}

TEST(Basis, ConversionsReproduceTheCurve) {
    // Any basis converted to Bezier must evaluate to T * M * G.
    std::mt19937 rng(3);
    for (const char* name : {"bezier", "b-spline", "catmull-rom", "hermite", "power"}) {
        Basis b = *basisByName(name);
        Vec3 g[16];
        std::uniform_real_distribution<float> d(-1.f, 1.f);
        for (auto& c : g) c = {d(rng), d(rng), d(rng)};
        BezierPatch bez = toBezier(g, b, b);
        for (float u : {0.f, 0.3f, 1.f})
            for (float v : {0.f, 0.8f}) {
                double tu[4] = {u * u * u, u * u, u, 1}, tv[4] = {v * v * v, v * v, v, 1};
                double wu[4] = {0, 0, 0, 0}, wv[4] = {0, 0, 0, 0};
                for (int i = 0; i < 4; ++i)
                    for (int k = 0; k < 4; ++k) {
                        wu[i] += tu[k] * b.m[k][i];
                        wv[i] += tv[k] * b.m[k][i];
                    }
                Vec3 ref;
                for (int j = 0; j < 4; ++j)
                    for (int i = 0; i < 4; ++i) ref += g[j * 4 + i] * float(wu[i] * wv[j]);
                EXPECT_LT(dist(evalPatch(bez, u, v), ref), 1e-4f) << name;
            }
        // Round trip: a Bezier patch converted with the Bezier basis is unchanged.
        BezierPatch same = toBezier(bez.cp, bezierBasis(), bezierBasis());
        for (int k = 0; k < 16; ++k) EXPECT_LT(dist(same.cp[k], bez.cp[k]), 1e-5f);
    }
}

}  // namespace tessera::test::bezier_tests

namespace tessera::test::bezier_tests {

// Mat4::points transforms affine matrices' points four at a time in AVX2 where the CPU has it: every point
// must be the scalar formula's float, bit for bit, for any count (the tail included) and in place.
TEST(Mat4, AffinePointsEqualTheScalarFormula) {
    std::mt19937 rng(4);
    std::uniform_real_distribution<double> coef(-3.0, 3.0);
    std::uniform_real_distribution<float> coord(-100.f, 100.f);
    for (int trial = 0; trial < 50; ++trial) {
        Mat4 m;
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 4; ++c) m.m[r][c] = coef(rng);
        const size_t n = size_t(trial % 20);
        std::vector<Vec3> in(n), out(n);
        for (Vec3& p : in) p = {coord(rng), coord(rng), coord(rng)};
        m.points(in.data(), out.data(), n);
        std::vector<Vec3> inPlace = in;
        m.points(inPlace.data(), inPlace.data(), n);
        for (size_t i = 0; i < n; ++i) {
            const Vec3 p = in[i];
            Vec3 expected{float(m.m[0][0] * p.x + m.m[0][1] * p.y + m.m[0][2] * p.z + m.m[0][3]),
                          float(m.m[1][0] * p.x + m.m[1][1] * p.y + m.m[1][2] * p.z + m.m[1][3]),
                          float(m.m[2][0] * p.x + m.m[2][1] * p.y + m.m[2][2] * p.z + m.m[2][3])};
            for (int k = 0; k < 3; ++k) {
                EXPECT_EQ(std::bit_cast<uint32_t>(out[i][k]), std::bit_cast<uint32_t>(expected[k]))
                    << "trial " << trial << " point " << i << " axis " << k;
                EXPECT_EQ(std::bit_cast<uint32_t>(inPlace[i][k]), std::bit_cast<uint32_t>(expected[k]));
            }
        }
    }
}

// hullBounds takes the control points' bounds with SSE min/max: the same bits as Bounds3::extend point by
// point, for signed zeros, infinities and a NaN (which extend never takes) too.
TEST(Bezier, HullBoundsEqualExtendingPointByPoint) {
    std::mt19937 rng(7);
    const float special[] = {0.f, -0.f, std::numeric_limits<float>::infinity(),
                             -std::numeric_limits<float>::infinity(),
                             std::numeric_limits<float>::quiet_NaN()};
    std::uniform_real_distribution<float> coord(-10.f, 10.f);
    for (int trial = 0; trial < 200; ++trial) {
        BezierPatch p;
        for (Vec3& c : p.cp) {
            c = {coord(rng), coord(rng), coord(rng)};
            for (int k = 0; k < 3; ++k)
                if (rng() % 4 == 0) c[k] = special[rng() % (trial < 100 ? 2 : 5)];
        }
        Bounds3 expected;
        for (const Vec3& c : p.cp) expected.extend(c);
        const Bounds3 b = hullBounds(p);
        for (int k = 0; k < 3; ++k) {
            EXPECT_EQ(std::bit_cast<uint32_t>(b.lo[k]), std::bit_cast<uint32_t>(expected.lo[k])) << trial;
            EXPECT_EQ(std::bit_cast<uint32_t>(b.hi[k]), std::bit_cast<uint32_t>(expected.hi[k])) << trial;
        }
    }
}

}  // namespace tessera::test::bezier_tests
