#include "core/motion_transform.h"

#include <algorithm>
#include <cmath>

namespace tessera {
namespace {

// Quaternion of a proper rotation matrix (upper-left 3x3 of r), Shepperd's method.
void matrixToQuaternion(const Mat4& r, double q[4]) {
    const double t = r.m[0][0] + r.m[1][1] + r.m[2][2];
    if (t > 0) {
        const double s = std::sqrt(t + 1.0) * 2;
        q[3] = 0.25 * s;
        q[0] = (r.m[2][1] - r.m[1][2]) / s;
        q[1] = (r.m[0][2] - r.m[2][0]) / s;
        q[2] = (r.m[1][0] - r.m[0][1]) / s;
    } else if (r.m[0][0] > r.m[1][1] && r.m[0][0] > r.m[2][2]) {
        const double s = std::sqrt(1.0 + r.m[0][0] - r.m[1][1] - r.m[2][2]) * 2;
        q[3] = (r.m[2][1] - r.m[1][2]) / s;
        q[0] = 0.25 * s;
        q[1] = (r.m[0][1] + r.m[1][0]) / s;
        q[2] = (r.m[0][2] + r.m[2][0]) / s;
    } else if (r.m[1][1] > r.m[2][2]) {
        const double s = std::sqrt(1.0 + r.m[1][1] - r.m[0][0] - r.m[2][2]) * 2;
        q[3] = (r.m[0][2] - r.m[2][0]) / s;
        q[0] = (r.m[0][1] + r.m[1][0]) / s;
        q[1] = 0.25 * s;
        q[2] = (r.m[1][2] + r.m[2][1]) / s;
    } else {
        const double s = std::sqrt(1.0 + r.m[2][2] - r.m[0][0] - r.m[1][1]) * 2;
        q[3] = (r.m[1][0] - r.m[0][1]) / s;
        q[0] = (r.m[0][2] + r.m[2][0]) / s;
        q[1] = (r.m[1][2] + r.m[2][1]) / s;
        q[2] = 0.25 * s;
    }
    const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (int i = 0; i < 4; ++i) q[i] /= n;
}

Mat4 quaternionToMatrix(const double q[4]) {
    const double x = q[0], y = q[1], z = q[2], w = q[3];
    Mat4 r;
    r.m[0][0] = 1 - 2 * (y * y + z * z);
    r.m[0][1] = 2 * (x * y - z * w);
    r.m[0][2] = 2 * (x * z + y * w);
    r.m[1][0] = 2 * (x * y + z * w);
    r.m[1][1] = 1 - 2 * (x * x + z * z);
    r.m[1][2] = 2 * (y * z - x * w);
    r.m[2][0] = 2 * (x * z - y * w);
    r.m[2][1] = 2 * (y * z + x * w);
    r.m[2][2] = 1 - 2 * (x * x + y * y);
    return r;
}

double quaternionDot(const double a[4], const double b[4]) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
}

}  // namespace

DecomposedTransform decompose(const Mat4& m) {
    DecomposedTransform d;
    d.original = m;
    d.projective = m.m[3][0] != 0 || m.m[3][1] != 0 || m.m[3][2] != 0 || m.m[3][3] != 1;
    for (int i = 0; i < 3; ++i) d.translation[i] = m.m[i][3];
    Mat4 a;  // the linear part
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) a.m[i][j] = m.m[i][j];
    const double sign = a.det3() < 0 ? -1.0 : 1.0;  // a reflection goes into the stretch
    // Polar decomposition by Higham's iteration Q <- (Q + Q^-T) / 2 (Shoemake and Duff 1992).
    Mat4 q = a;
    for (int k = 0; k < 3; ++k)
        for (int j = 0; j < 3; ++j) q.m[k][j] *= sign;
    for (int iter = 0; iter < 100; ++iter) {
        const Mat4 inv = q.inverse();
        double change = 0;
        Mat4 next;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) {
                next.m[i][j] = 0.5 * (q.m[i][j] + inv.m[j][i]);
                change = std::max(change, std::abs(next.m[i][j] - q.m[i][j]));
            }
        q = next;
        if (change < 1e-14) break;
    }
    matrixToQuaternion(q, d.rotation);
    // S = R^-1 A = R^T A.
    Mat4 s;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            double v = 0;
            for (int k = 0; k < 3; ++k) v += q.m[k][i] * a.m[k][j];
            s.m[i][j] = v;
        }
    d.stretch = s;
    return d;
}

Mat4 compose(const DecomposedTransform& d) {
    if (d.projective) return d.original;
    Mat4 r = quaternionToMatrix(d.rotation) * d.stretch;
    for (int i = 0; i < 3; ++i) r.m[i][3] = d.translation[i];
    return r;
}

double rotationAngle(const DecomposedTransform& a, const DecomposedTransform& b) {
    const double c = std::min(1.0, std::abs(quaternionDot(a.rotation, b.rotation)));
    return 2.0 * std::acos(c);
}

Mat4 interpolate(const DecomposedTransform& a, const DecomposedTransform& b, double w) {
    if (w <= 0) return a.original;
    if (w >= 1) return b.original;
    if (a.projective || b.projective) {  // no decomposition: linear blend of the matrices
        Mat4 r;
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j) r.m[i][j] = (1 - w) * a.original.m[i][j] + w * b.original.m[i][j];
        return r;
    }
    DecomposedTransform d;
    for (int i = 0; i < 3; ++i) d.translation[i] = (1 - w) * a.translation[i] + w * b.translation[i];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) d.stretch.m[i][j] = (1 - w) * a.stretch.m[i][j] + w * b.stretch.m[i][j];
    // Slerp along the shorter arc.
    double qb[4] = {b.rotation[0], b.rotation[1], b.rotation[2], b.rotation[3]};
    double c = quaternionDot(a.rotation, qb);
    if (c < 0) {
        for (double& v : qb) v = -v;
        c = -c;
    }
    double wa = 1 - w, wb = w;
    if (c < 0.9999995) {
        const double theta = std::acos(c), s = std::sin(theta);
        wa = std::sin((1 - w) * theta) / s;
        wb = std::sin(w * theta) / s;
    }
    double n = 0;
    for (int i = 0; i < 4; ++i) {
        d.rotation[i] = wa * a.rotation[i] + wb * qb[i];
        n += d.rotation[i] * d.rotation[i];
    }
    n = std::sqrt(n);
    for (double& v : d.rotation) v /= n;
    return compose(d);
}

Mat4 transformAt(const std::vector<TransformKey>& keys, double time) {
    if (keys.empty()) return Mat4();
    if (keys.size() == 1 || time <= keys.front().time) return keys.front().matrix;
    if (time >= keys.back().time) return keys.back().matrix;
    size_t k = 1;
    while (keys[k].time < time) ++k;
    const TransformKey &a = keys[k - 1], &b = keys[k];
    const double span = b.time - a.time;
    if (!(span > 0)) return b.matrix;
    return interpolate(decompose(a.matrix), decompose(b.matrix), (time - a.time) / span);
}

std::vector<TransformKey> refineTransformKeys(const std::vector<TransformKey>& keys, double maxAngleRadians) {
    if (keys.size() < 2) return keys;
    std::vector<TransformKey> out{keys.front()};
    for (size_t k = 1; k < keys.size(); ++k) {
        const DecomposedTransform a = decompose(keys[k - 1].matrix), b = decompose(keys[k].matrix);
        const int pieces = std::max(1, int(std::ceil(rotationAngle(a, b) / maxAngleRadians - 1e-9)));
        for (int i = 1; i < pieces; ++i) {
            const double w = double(i) / pieces;
            out.push_back({keys[k - 1].time + w * (keys[k].time - keys[k - 1].time), interpolate(a, b, w)});
        }
        out.push_back(keys[k]);
    }
    return out;
}

}  // namespace tessera
