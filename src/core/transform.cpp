#include "core/transform.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "core/cpu.h"
#if defined(__x86_64__)
#include <immintrin.h>
#endif

namespace tessera {

namespace {
#if defined(__x86_64__)
// One output coordinate of four points: ((a x + b y) + c z) + d, as the scalar loop evaluates it.
__attribute__((target("avx2"), always_inline)) inline __m128 affineRow(__m256d a, __m256d b, __m256d c,
                                                                       __m256d d, __m256d x, __m256d y,
                                                                       __m256d z) {
    return _mm256_cvtpd_ps(_mm256_add_pd(
        _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(a, x), _mm256_mul_pd(b, y)), _mm256_mul_pd(c, z)), d));
}

static_assert(sizeof(Vec3) == 3 * sizeof(float), "affinePointsAvx2 reads and writes packed x, y, z");

// Mat4::points' affine loop four points at a time: the same double operations in the same order (no FMA:
// the target is AVX2 alone), converted to float with the same rounding, so the same bits. A quarter of a
// RIB patch's loading cost on 24 Big Guys went to the scalar loop.
__attribute__((target("avx2"))) size_t affinePointsAvx2(const double (&m)[4][4], const Vec3* in, Vec3* out,
                                                        size_t n) {
    const __m256d m00 = _mm256_set1_pd(m[0][0]), m01 = _mm256_set1_pd(m[0][1]), m02 = _mm256_set1_pd(m[0][2]),
                  m03 = _mm256_set1_pd(m[0][3]);
    const __m256d m10 = _mm256_set1_pd(m[1][0]), m11 = _mm256_set1_pd(m[1][1]), m12 = _mm256_set1_pd(m[1][2]),
                  m13 = _mm256_set1_pd(m[1][3]);
    const __m256d m20 = _mm256_set1_pd(m[2][0]), m21 = _mm256_set1_pd(m[2][1]), m22 = _mm256_set1_pd(m[2][2]),
                  m23 = _mm256_set1_pd(m[2][3]);
    size_t i = 0;
    for (; i + 4 <= n; i += 4) {
        // Three loads of the 12 floats a = (x0 y0 z0 x1), b = (y1 z1 x2 y2), c = (z2 x3 y3 z3), shuffled
        // into x, y and z of the four points (and back in the same way below).
        const float* f = &in[i].x;
        const __m128 a = _mm_loadu_ps(f), b = _mm_loadu_ps(f + 4), c = _mm_loadu_ps(f + 8);
        const __m128 x = _mm_blend_ps(_mm_shuffle_ps(a, b, _MM_SHUFFLE(2, 2, 3, 0)),
                                      _mm_shuffle_ps(c, c, _MM_SHUFFLE(1, 1, 1, 1)), 0b1000);
        const __m128 aabb = _mm_shuffle_ps(a, b, _MM_SHUFFLE(3, 0, 1, 1));  // a1 a1 b0 b3
        const __m128 y = _mm_blend_ps(_mm_shuffle_ps(aabb, aabb, _MM_SHUFFLE(3, 3, 2, 0)),
                                      _mm_shuffle_ps(c, c, _MM_SHUFFLE(2, 2, 2, 2)), 0b1000);
        const __m128 z =
            _mm_shuffle_ps(_mm_shuffle_ps(a, b, _MM_SHUFFLE(1, 1, 2, 2)), c, _MM_SHUFFLE(3, 0, 2, 0));
        const __m256d px = _mm256_cvtps_pd(x), py = _mm256_cvtps_pd(y), pz = _mm256_cvtps_pd(z);
        const __m128 ox = affineRow(m00, m01, m02, m03, px, py, pz);
        const __m128 oy = affineRow(m10, m11, m12, m13, px, py, pz);
        const __m128 oz = affineRow(m20, m21, m22, m23, px, py, pz);
        const __m128 xyLow = _mm_unpacklo_ps(ox, oy),
                     xyHigh = _mm_unpackhi_ps(ox, oy);  // x0 y0 x1 y1, x2 y2 x3 y3
        float* o = &out[i].x;
        _mm_storeu_ps(o, _mm_shuffle_ps(xyLow, _mm_shuffle_ps(oz, xyLow, _MM_SHUFFLE(2, 2, 0, 0)),
                                        _MM_SHUFFLE(2, 0, 1, 0)));
        _mm_storeu_ps(o + 4, _mm_shuffle_ps(_mm_shuffle_ps(xyLow, oz, _MM_SHUFFLE(1, 1, 3, 3)), xyHigh,
                                            _MM_SHUFFLE(1, 0, 2, 0)));
        const __m128 zzxy = _mm_shuffle_ps(oz, xyHigh, _MM_SHUFFLE(3, 2, 3, 2));  // z2 z3 x3 y3
        _mm_storeu_ps(o + 8, _mm_shuffle_ps(zzxy, zzxy, _MM_SHUFFLE(1, 3, 2, 0)));
    }
    return i;
}
#endif
}  // namespace

Mat4 Mat4::translate(double x, double y, double z) {
    Mat4 r;
    r.m[0][3] = x;
    r.m[1][3] = y;
    r.m[2][3] = z;
    return r;
}

Mat4 Mat4::scale(double x, double y, double z) {
    Mat4 r;
    r.m[0][0] = x;
    r.m[1][1] = y;
    r.m[2][2] = z;
    return r;
}

Mat4 Mat4::rotate(double degrees, double ax, double ay, double az) {
    Mat4 r;
    double len = std::sqrt(ax * ax + ay * ay + az * az);
    if (len == 0) return r;
    ax /= len;
    ay /= len;
    az /= len;
    double a = degrees * std::numbers::pi / 180.0;
    double c = std::cos(a), s = std::sin(a), t = 1 - c;
    // Rodrigues' rotation formula, column-vector form.
    r.m[0][0] = t * ax * ax + c;
    r.m[0][1] = t * ax * ay - s * az;
    r.m[0][2] = t * ax * az + s * ay;
    r.m[1][0] = t * ax * ay + s * az;
    r.m[1][1] = t * ay * ay + c;
    r.m[1][2] = t * ay * az - s * ax;
    r.m[2][0] = t * ax * az - s * ay;
    r.m[2][1] = t * ay * az + s * ax;
    r.m[2][2] = t * az * az + c;
    return r;
}

Mat4 Mat4::fromRib(const double v[16]) {
    Mat4 r;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) r.m[j][i] = v[i * 4 + j];
    return r;
}

Mat4 Mat4::operator*(const Mat4& b) const {
    Mat4 r;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) {
            double s = 0;
            for (int k = 0; k < 4; ++k) s += m[i][k] * b.m[k][j];
            r.m[i][j] = s;
        }
    return r;
}

double Mat4::maxStretch() const {
    double mtm[3][3] = {}, largest = 0;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            for (int k = 0; k < 3; ++k) mtm[i][j] += m[k][i] * m[k][j];
    for (int i = 0; i < 3; ++i)
        largest = std::max(largest, std::fabs(mtm[i][0]) + std::fabs(mtm[i][1]) + std::fabs(mtm[i][2]));
    return std::sqrt(largest);
}

double Mat4::det3() const {
    return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
           m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
           m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}

double Mat4::determinant() const {
    // Laplace expansion along the first row.
    auto minor3 = [&](int c0, int c1, int c2) {
        return m[1][c0] * (m[2][c1] * m[3][c2] - m[2][c2] * m[3][c1]) -
               m[1][c1] * (m[2][c0] * m[3][c2] - m[2][c2] * m[3][c0]) +
               m[1][c2] * (m[2][c0] * m[3][c1] - m[2][c1] * m[3][c0]);
    };
    return m[0][0] * minor3(1, 2, 3) - m[0][1] * minor3(0, 2, 3) + m[0][2] * minor3(0, 1, 3) -
           m[0][3] * minor3(0, 1, 2);
}

Mat4 Mat4::inverse() const {
    // Cofactor expansion (the classic MESA gluInvertMatrix layout), in double.
    double a[16], o[16];
    for (int i = 0; i < 16; ++i) a[i] = m[i / 4][i % 4];
    o[0] = a[5] * a[10] * a[15] - a[5] * a[11] * a[14] - a[9] * a[6] * a[15] + a[9] * a[7] * a[14] +
           a[13] * a[6] * a[11] - a[13] * a[7] * a[10];
    o[4] = -a[4] * a[10] * a[15] + a[4] * a[11] * a[14] + a[8] * a[6] * a[15] - a[8] * a[7] * a[14] -
           a[12] * a[6] * a[11] + a[12] * a[7] * a[10];
    o[8] = a[4] * a[9] * a[15] - a[4] * a[11] * a[13] - a[8] * a[5] * a[15] + a[8] * a[7] * a[13] +
           a[12] * a[5] * a[11] - a[12] * a[7] * a[9];
    o[12] = -a[4] * a[9] * a[14] + a[4] * a[10] * a[13] + a[8] * a[5] * a[14] - a[8] * a[6] * a[13] -
            a[12] * a[5] * a[10] + a[12] * a[6] * a[9];
    o[1] = -a[1] * a[10] * a[15] + a[1] * a[11] * a[14] + a[9] * a[2] * a[15] - a[9] * a[3] * a[14] -
           a[13] * a[2] * a[11] + a[13] * a[3] * a[10];
    o[5] = a[0] * a[10] * a[15] - a[0] * a[11] * a[14] - a[8] * a[2] * a[15] + a[8] * a[3] * a[14] +
           a[12] * a[2] * a[11] - a[12] * a[3] * a[10];
    o[9] = -a[0] * a[9] * a[15] + a[0] * a[11] * a[13] + a[8] * a[1] * a[15] - a[8] * a[3] * a[13] -
           a[12] * a[1] * a[11] + a[12] * a[3] * a[9];
    o[13] = a[0] * a[9] * a[14] - a[0] * a[10] * a[13] - a[8] * a[1] * a[14] + a[8] * a[2] * a[13] +
            a[12] * a[1] * a[10] - a[12] * a[2] * a[9];
    o[2] = a[1] * a[6] * a[15] - a[1] * a[7] * a[14] - a[5] * a[2] * a[15] + a[5] * a[3] * a[14] +
           a[13] * a[2] * a[7] - a[13] * a[3] * a[6];
    o[6] = -a[0] * a[6] * a[15] + a[0] * a[7] * a[14] + a[4] * a[2] * a[15] - a[4] * a[3] * a[14] -
           a[12] * a[2] * a[7] + a[12] * a[3] * a[6];
    o[10] = a[0] * a[5] * a[15] - a[0] * a[7] * a[13] - a[4] * a[1] * a[15] + a[4] * a[3] * a[13] +
            a[12] * a[1] * a[7] - a[12] * a[3] * a[5];
    o[14] = -a[0] * a[5] * a[14] + a[0] * a[6] * a[13] + a[4] * a[1] * a[14] - a[4] * a[2] * a[13] -
            a[12] * a[1] * a[6] + a[12] * a[2] * a[5];
    o[3] = -a[1] * a[6] * a[11] + a[1] * a[7] * a[10] + a[5] * a[2] * a[11] - a[5] * a[3] * a[10] -
           a[9] * a[2] * a[7] + a[9] * a[3] * a[6];
    o[7] = a[0] * a[6] * a[11] - a[0] * a[7] * a[10] - a[4] * a[2] * a[11] + a[4] * a[3] * a[10] +
           a[8] * a[2] * a[7] - a[8] * a[3] * a[6];
    o[11] = -a[0] * a[5] * a[11] + a[0] * a[7] * a[9] + a[4] * a[1] * a[11] - a[4] * a[3] * a[9] -
            a[8] * a[1] * a[7] + a[8] * a[3] * a[5];
    o[15] = a[0] * a[5] * a[10] - a[0] * a[6] * a[9] - a[4] * a[1] * a[10] + a[4] * a[2] * a[9] +
            a[8] * a[1] * a[6] - a[8] * a[2] * a[5];
    double det = a[0] * o[0] + a[1] * o[4] + a[2] * o[8] + a[3] * o[12];
    Mat4 r;
    if (det == 0) return r;
    for (int i = 0; i < 16; ++i) r.m[i / 4][i % 4] = o[i] / det;
    return r;
}

Vec3 Mat4::point(Vec3 p) const {
    double x = m[0][0] * p.x + m[0][1] * p.y + m[0][2] * p.z + m[0][3];
    double y = m[1][0] * p.x + m[1][1] * p.y + m[1][2] * p.z + m[1][3];
    double z = m[2][0] * p.x + m[2][1] * p.y + m[2][2] * p.z + m[2][3];
    double w = m[3][0] * p.x + m[3][1] * p.y + m[3][2] * p.z + m[3][3];
    if (w != 1 && w != 0) {
        x /= w;
        y /= w;
        z /= w;
    }
    return {float(x), float(y), float(z)};
}

void Mat4::points(const Vec3* in, Vec3* out, size_t n) const {
    if (!(m[3][0] == 0 && m[3][1] == 0 && m[3][2] == 0 && m[3][3] == 1)) {
        for (size_t i = 0; i < n; ++i) out[i] = point(in[i]);
        return;
    }
    size_t i = 0;
#if defined(__x86_64__)
    if (cpuHasAvx2()) i = affinePointsAvx2(m, in, out, n);
#endif
    for (; i < n; ++i) {
        const Vec3 p = in[i];
        const double x = m[0][0] * p.x + m[0][1] * p.y + m[0][2] * p.z + m[0][3];
        const double y = m[1][0] * p.x + m[1][1] * p.y + m[1][2] * p.z + m[1][3];
        const double z = m[2][0] * p.x + m[2][1] * p.y + m[2][2] * p.z + m[2][3];
        out[i] = {float(x), float(y), float(z)};
    }
}

Vec3 Mat4::vector(Vec3 v) const {
    return {float(m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z),
            float(m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z),
            float(m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z)};
}

Vec3 Mat4::normalWithInverse(const Mat4& inv, Vec3 n) {
    return {float(inv.m[0][0] * n.x + inv.m[1][0] * n.y + inv.m[2][0] * n.z),
            float(inv.m[0][1] * n.x + inv.m[1][1] * n.y + inv.m[2][1] * n.z),
            float(inv.m[0][2] * n.x + inv.m[1][2] * n.y + inv.m[2][2] * n.z)};
}

}  // namespace tessera
