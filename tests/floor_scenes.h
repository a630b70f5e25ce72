// The floor scenes of the light-transport tests (ambient occlusion, area lights, the path tracer): a
// floor z = 5 facing the eye, seen through a 40-degree view of a square image, with the closed forms and
// the t statistics they are checked with.
#pragma once
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "test_util.h"

namespace tessera::test {

// A planar polygon (four corners in order).
struct Wall {
    Vec3 corner[4];
};

// The cosine-weighted solid angle over pi of polygon `w` seen whole from point p with normal n (the exact
// occlusion of a wall, the irradiance factor of an area light), i.e. the point-to-polygon form factor, by
// Lambert's formula F = (1 / 2 pi) sum over edges of (angle the edge subtends) x (n . unit normal of the
// plane through p and the edge). The walls are finite (200 and 400 units), which this accounts for.
inline double polygonFormFactor(const Wall& w, Vec3 p, Vec3 n) {
    double f = 0;
    for (int i = 0; i < 4; ++i) {
        const Vec3 a = normalize(w.corner[i] - p), b = normalize(w.corner[(i + 1) % 4] - p);
        const Vec3 c = cross(a, b);
        const double len = length(c);
        if (len < 1e-12) continue;
        f += std::acos(std::clamp(double(dot(a, b)), -1.0, 1.0)) * double(dot(n, c)) / len;
    }
    return std::abs(f) / (2.0 * 3.14159265358979);
}

// The floor point a pixel centre sees (the floor z = 5, 40-degree view of a square image).
inline Vec3 floorPointOf(int px, int py, int size) {
    const float half = std::tan(20.f * 3.14159265f / 180.f);
    const float x = (2.f * (px + 0.5f) / size - 1.f) * half, y = (1.f - 2.f * (py + 0.5f) / size) * half;
    return {x * 5.f, y * 5.f, 5.f};
}

struct Estimate {
    double mean = 0, standardError = 0;
    size_t n = 0;
};
// Mean of (grey value - truth(floor point)) over the pixels whose floor point passes `keep`.
template <class Keep, class Truth>
Estimate errorOver(const Image& img, int size, Keep&& keep, Truth&& truth) {
    std::vector<double> v;
    for (int py = 0; py < size; ++py)
        for (int px = 0; px < size; ++px) {
            const Vec3 p = floorPointOf(px, py, size);
            if (keep(p)) v.push_back(double(img.pixel(px, py)[0]) - truth(p));
        }
    Estimate e;
    e.n = v.size();
    for (double x : v) e.mean += x;
    e.mean /= double(e.n);
    double ss = 0;
    for (double x : v) ss += (x - e.mean) * (x - e.mean);
    e.standardError = std::sqrt(ss / double(e.n - 1) / double(e.n));
    return e;
}
template <class Keep>
Estimate meanOver(const Image& img, int size, Keep&& keep) {
    return errorOver(img, size, keep, [](Vec3) { return 0.0; });
}

// |t| of the mean against the analytic value; 4 standard errors is the bound (a fixed seed: the test is
// deterministic, the bound only says the estimate is consistent with the closed form).
inline void expectMean(const Estimate& e, double truth, const char* what) {
    const double t = (e.mean - truth) / std::max(e.standardError, 1e-12);
    ::testing::Test::RecordProperty(std::string("mean_") + what, std::to_string(e.mean));
    ::testing::Test::RecordProperty(std::string("t_") + what, std::to_string(t));
    EXPECT_GT(e.n, 100u) << what;
    EXPECT_LT(std::abs(t), 4.0) << what << ": mean " << e.mean << " vs " << truth << " (se "
                                << e.standardError << ")";
    EXPECT_NEAR(e.mean, truth, 0.01) << what;
}
}  // namespace tessera::test
