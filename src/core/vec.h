// Small value types for geometry: plain structs, no hidden state, usable from any backend.
#pragma once
#include <algorithm>
#include <cmath>
#include <limits>

#include "core/hostdevice.h"

namespace tessera {

struct Vec2 {
    float x = 0, y = 0;
};

struct Vec3 {
    float x = 0, y = 0, z = 0;
    constexpr Vec3() = default;
    constexpr Vec3(float x_, float y_, float z_) : x(x_), y(y_), z(z_) {}
    constexpr float operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
    TESSERA_HD float& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
    constexpr Vec3 operator+(Vec3 b) const { return {x + b.x, y + b.y, z + b.z}; }
    constexpr Vec3 operator-(Vec3 b) const { return {x - b.x, y - b.y, z - b.z}; }
    constexpr Vec3 operator-() const { return {-x, -y, -z}; }
    constexpr Vec3 operator*(float s) const { return {x * s, y * s, z * s}; }
    constexpr Vec3 operator*(Vec3 b) const { return {x * b.x, y * b.y, z * b.z}; }
    constexpr Vec3 operator/(float s) const { return {x / s, y / s, z / s}; }
    TESSERA_HD Vec3& operator+=(Vec3 b) { x += b.x; y += b.y; z += b.z; return *this; }
    TESSERA_HD Vec3& operator-=(Vec3 b) { x -= b.x; y -= b.y; z -= b.z; return *this; }
    TESSERA_HD Vec3& operator*=(float s) { x *= s; y *= s; z *= s; return *this; }
    constexpr bool operator==(const Vec3&) const = default;
};
TESSERA_HD constexpr Vec3 operator*(float s, Vec3 v) { return v * s; }
TESSERA_HD constexpr float dot(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
TESSERA_HD constexpr Vec3 cross(Vec3 a, Vec3 b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
TESSERA_HD float length(Vec3 a) { return std::sqrt(dot(a, a)); }
TESSERA_HD Vec3 normalize(Vec3 a) {
    float l = length(a);
    return l > 0 ? a / l : a;
}
TESSERA_HD Vec3 vmin(Vec3 a, Vec3 b) { return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)}; }
TESSERA_HD Vec3 vmax(Vec3 a, Vec3 b) { return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)}; }
TESSERA_HD Vec3 lerp(Vec3 a, Vec3 b, float t) { return a + (b - a) * t; }
TESSERA_HD bool isFinite(Vec3 a) { return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z); }
TESSERA_HD float maxComponent(Vec3 a) { return std::max(a.x, std::max(a.y, a.z)); }

// RGB colour shares the vector type; the name documents intent at use sites.
using Color = Vec3;

struct Bounds3 {
    Vec3 lo{std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
            std::numeric_limits<float>::infinity()};
    Vec3 hi{-std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
            -std::numeric_limits<float>::infinity()};
    void extend(Vec3 p) { lo = vmin(lo, p); hi = vmax(hi, p); }
    void extend(const Bounds3& b) { lo = vmin(lo, b.lo); hi = vmax(hi, b.hi); }
    bool empty() const { return lo.x > hi.x || lo.y > hi.y || lo.z > hi.z; }
    Vec3 center() const { return (lo + hi) * 0.5f; }
    Vec3 diagonal() const { return hi - lo; }
    float surfaceArea() const {
        Vec3 d = diagonal();
        return 2.f * (d.x * d.y + d.y * d.z + d.z * d.x);
    }
};

}  // namespace tessera
