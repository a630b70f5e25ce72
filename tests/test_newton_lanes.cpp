// The 8-lane Newton step (rt/newton_lanes.h) against the scalar newtonIterate it vectorizes: the same
// roots, iteration counts and verdicts, bit for bit, for random rays at the teapot's patches (poles and
// the folded knob included) and random starts inside and outside the leaf grid; AVX2 and SSE2 builds of
// the step agree as well.
#include <gtest/gtest.h>

#include <cstring>
#include <random>

#include "io/scene_loader.h"
#include "rt/intersect.h"
#include "rt/newton_lanes.h"

namespace tessera::test::newton_lanes_tests {

namespace {

struct Start {
    ProjectedPatch<float> pp;
    float eps, u0, v0;
};

// Random (ray, patch, start) triples: rays through a random point of a random teapot patch (so roots
// exist), from random directions, plus starts that miss (shifted rays).
std::vector<Start> makeStarts(int count) {
    const Scene s = loadScene(std::string(TESSERA_TEST_DATA) + "/teapot.bpt", [](const std::string&) {});
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> U(0.f, 1.f), S(-1.f, 1.f);
    std::vector<Start> out;
    for (int k = 0; k < count; ++k) {
        const BezierPatch& p = s.patches[rng() % s.patches.size()];
        const Vec3 target =
            evalPatch(p, U(rng), U(rng)) + Vec3{S(rng), S(rng), S(rng)} * (k % 4 == 3 ? 0.5f : 0.f);
        const Vec3 dir = normalize(Vec3{S(rng), S(rng), S(rng)});
        const Vec3 o = target - dir * 8.f;
        Start st;
        projectPatch(p, makeRayPlanes(o, dir), st.pp);
        Bounds3 box;
        for (const Vec3& c : p.cp) box.extend(c);
        st.eps = newtonTolerance(box, o);
        st.u0 = (float(rng() % 8) + 0.5f) / 8.f;
        st.v0 = (float(rng() % 8) + 0.5f) / 8.f;
        out.push_back(st);
    }
    return out;
}

struct Result {
    bool converged;
    int iterations;
    float u, v;
};

// Runs all starts through the lanes, refilling a lane as soon as its start ends (as the renderer does).
std::vector<Result> runLanes(const std::vector<Start>& starts, unsigned (*step)(NewtonLanes&)) {
    std::vector<Result> res(starts.size());
    NewtonLanes L;
    std::memset(&L, 0, sizeof(L));
    int owner[kNewtonLanes];
    size_t next = 0;
    unsigned active = 0;
    auto fill = [&](int l) {
        if (next >= starts.size()) return false;
        const Start& st = starts[next];
        for (int k = 0; k < 16; ++k) L.a1[k][l] = st.pp.a1[k], L.a2[k][l] = st.pp.a2[k];
        L.start(l, st.u0, st.v0, st.eps);
        owner[l] = int(next++);
        return true;
    };
    for (int l = 0; l < kNewtonLanes; ++l)
        if (fill(l)) active |= 1u << l;
    while (active) {
        for (unsigned done = step(L) & active; done; done &= done - 1) {
            const int l = __builtin_ctz(done);
            res[owner[l]] = {L.status[l] == kLaneConverged, int(L.evals[l]), L.u[l], L.v[l]};
            if (!fill(l)) active &= ~(1u << l);
        }
    }
    return res;
}

}  // namespace

TEST(NewtonLanes, BitIdenticalToScalarNewton) {
    const std::vector<Start> starts = makeStarts(4000);
    const std::vector<Result> lanes = runLanes(starts, newtonLanesStep);
    const std::vector<Result> baseline = runLanes(starts, newtonLanesStepBaseline);
    int converged = 0, failed = 0;
    for (size_t i = 0; i < starts.size(); ++i) {
        float u = starts[i].u0, v = starts[i].v0;
        int it = 0;
        const bool conv = newtonIterate<float>(starts[i].pp, starts[i].eps, u, v, it);
        converged += conv, failed += !conv;
        ASSERT_EQ(lanes[i].converged, conv) << "start " << i;
        ASSERT_EQ(lanes[i].iterations, it) << "start " << i;
        if (conv) {
            // Bitwise: same arithmetic in the same order.
            ASSERT_EQ(std::memcmp(&lanes[i].u, &u, 4), 0)
                << "start " << i << ": " << lanes[i].u << " vs " << u;
            ASSERT_EQ(std::memcmp(&lanes[i].v, &v, 4), 0)
                << "start " << i << ": " << lanes[i].v << " vs " << v;
        }
        ASSERT_EQ(lanes[i].converged, baseline[i].converged) << "AVX2 vs SSE2, start " << i;
        ASSERT_EQ(lanes[i].iterations, baseline[i].iterations) << "AVX2 vs SSE2, start " << i;
        ASSERT_EQ(std::memcmp(&lanes[i].u, &baseline[i].u, 4), 0) << "AVX2 vs SSE2, start " << i;
        ASSERT_EQ(std::memcmp(&lanes[i].v, &baseline[i].v, 4), 0) << "AVX2 vs SSE2, start " << i;
    }
    std::printf("%d converged, %d failed starts\n", converged, failed);
    // Both outcomes must be exercised for the comparison to mean anything.
    EXPECT_GT(converged, 1000);
    EXPECT_GT(failed, 200);
}

// The projection into a lane's columns (AVX2 and SSE2 builds) gives projectPatch's values bit for bit, in
// lane l's column only, and each control point's distance along the ray as the scalar formula.
TEST(NewtonLanes, ProjectIntoLaneEqualsProjectPatch) {
    const Scene s = loadScene(std::string(TESSERA_TEST_DATA) + "/teapot.bpt", [](const std::string&) {});
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> S(-1.f, 1.f);
    int compared = 0;
    for (int k = 0; k < 500; ++k) {
        const BezierPatch& p = s.patches[rng() % s.patches.size()];
        const Vec3 o{4.f * S(rng), 4.f * S(rng), 4.f * S(rng)};
        const Vec3 d = Vec3{S(rng), S(rng), S(rng)} * (k % 2 ? 1.f : 3.f);  // unnormalized too
        const RayPlanes pl = makeRayPlanes(o, d);
        ProjectedPatch<float> pp;
        projectPatch(p, pl, pp);
        alignas(32) float x[16], y[16], z[16];
        for (int i = 0; i < 16; ++i) x[i] = p.cp[i].x, y[i] = p.cp[i].y, z[i] = p.cp[i].z;
        const float invDD = 1.f / dot(d, d);
        const LaneRayFrame f{{pl.n1.x, pl.n1.y, pl.n1.z},
                             pl.d1,
                             {pl.n2.x, pl.n2.y, pl.n2.z},
                             pl.d2,
                             {o.x, o.y, o.z},
                             {d.x, d.y, d.z},
                             invDD};
        for (auto project : {projectIntoLane, projectIntoLaneBaseline}) {
            NewtonLanes L;
            std::memset(&L, 0, sizeof(L));
            const int l = k % kNewtonLanes;
            float depth[16];
            project(L, l, f, x, y, z, depth);
            for (int i = 0; i < 16; ++i) {
                ASSERT_EQ(std::memcmp(&L.a1[i][l], &pp.a1[i], 4), 0) << "patch point " << i << ", ray " << k;
                ASSERT_EQ(std::memcmp(&L.a2[i][l], &pp.a2[i], 4), 0) << "patch point " << i << ", ray " << k;
                const float t = ((x[i] - o.x) * d.x + (y[i] - o.y) * d.y + (z[i] - o.z) * d.z) * invDD;
                ASSERT_EQ(std::memcmp(&depth[i], &t, 4), 0) << "patch point " << i << ", ray " << k;
                for (int m = 0; m < kNewtonLanes; ++m) {  // the other lanes' columns are untouched
                    if (m != l) {
                        ASSERT_TRUE(L.a1[i][m] == 0.f && L.a2[i][m] == 0.f);
                    }
                }
                ++compared;
            }
        }
    }
    EXPECT_EQ(compared, 500 * 2 * 16);
}

TEST(NewtonLanes, RayFramesEqualMakeRayPlanesBitForBit) {
    // makeLaneRayFrames (8 rays at a time) against the frame built from makeRayPlanes ray by ray: random
    // origins and directions (unnormalized, tiny and huge), directions along and between the axes (the
    // major-axis branch and its ties), signed zeros and a zero direction.
    std::mt19937 rng(13);
    std::uniform_real_distribution<float> S(-1.f, 1.f), E(-20.f, 20.f);
    std::vector<Vec3> o, d;
    for (int k = 0; k < 2000; ++k) {
        o.push_back(Vec3{S(rng), S(rng), S(rng)} * std::exp2(E(rng)));
        Vec3 dir{S(rng), S(rng), S(rng)};
        switch (k % 8) {
            case 0:
                dir = dir * std::exp2(E(rng));
                break;
            case 1:
                dir.y = 0.f, dir.z = -0.f;
                break;  // along x
            case 2:
                dir.x = dir.z = 0.f;
                break;  // along y
            case 3:
                dir.y = dir.x;
                break;  // |dx| = |dy|
            case 4:
                dir.z = -dir.x;
                break;  // |dx| = |dz|
            case 5:
                dir = k % 16 == 5 ? Vec3{0.f, 0.f, 0.f} : Vec3{-0.f, 0.f, dir.z};
                break;
            default:
                break;
        }
        d.push_back(dir);
    }
    const int n = int(o.size());  // a multiple of 8
    std::vector<float> ox(n), oy(n), oz(n), dx(n), dy(n), dz(n);
    for (int i = 0; i < n; ++i)
        ox[i] = o[i].x, oy[i] = o[i].y, oz[i] = o[i].z, dx[i] = d[i].x, dy[i] = d[i].y, dz[i] = d[i].z;
    int compared = 0;
    for (auto frames : {makeLaneRayFrames, makeLaneRayFramesBaseline}) {
        std::vector<LaneRayFrame> got(n);
        frames(ox.data(), oy.data(), oz.data(), dx.data(), dy.data(), dz.data(), n, got.data());
        for (int i = 0; i < n; ++i) {
            const RayPlanes pl = makeRayPlanes(o[i], d[i]);
            const LaneRayFrame want{{pl.n1.x, pl.n1.y, pl.n1.z}, pl.d1,
                                    {pl.n2.x, pl.n2.y, pl.n2.z}, pl.d2,
                                    {o[i].x, o[i].y, o[i].z},    {d[i].x, d[i].y, d[i].z},
                                    1.f / dot(d[i], d[i])};
            ASSERT_EQ(std::memcmp(&got[i], &want, sizeof(want)), 0) << "ray " << i;
            ++compared;
        }
    }
    EXPECT_EQ(compared, 2 * n);
}

}  // namespace tessera::test::newton_lanes_tests
