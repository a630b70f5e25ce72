#include "core/nurbs.h"

#include <algorithm>
#include <cmath>

namespace tessera {

namespace {

// A B-spline curve whose "points" have `dim` coordinates each (a whole row or column of a surface is one
// point, so one insertion pass refines every row at once).
struct Curve {
    std::vector<double> knots;
    std::vector<double> pts;  // (n + 1) * dim
    int dim = 3;
    int degree = 3;
    int count() const { return int(pts.size()) / dim; }
};

int multiplicity(const std::vector<double>& T, double t) {
    auto range = std::equal_range(T.begin(), T.end(), t);
    return int(range.second - range.first);
}

// Boehm's algorithm: insert the knot t once (The NURBS Book, A5.1 with r = 1). t lies in the domain
// [T[p], T[n+1]) or is a knot of multiplicity < p + 1 there, so every denominator below is positive.
void insertKnot(Curve& c, double t) {
    const int p = c.degree, dim = c.dim, n = c.count() - 1;
    const std::vector<double>& T = c.knots;
    const int k = int(std::upper_bound(T.begin(), T.end(), t) - T.begin()) - 1;  // T[k] <= t < T[k+1]
    const int s = multiplicity(T, t);
    std::vector<double> q(size_t(n + 2) * dim);
    for (int i = 0; i <= n + 1; ++i) {
        double* out = &q[size_t(i) * dim];
        if (i <= k - p) {
            std::copy_n(&c.pts[size_t(i) * dim], dim, out);
        } else if (i <= k - s) {
            double a = (t - T[i]) / (T[i + p] - T[i]);
            const double* pi = &c.pts[size_t(i) * dim];
            const double* pm = &c.pts[size_t(i - 1) * dim];
            for (int d = 0; d < dim; ++d) out[d] = a * pi[d] + (1 - a) * pm[d];
        } else {
            std::copy_n(&c.pts[size_t(i - 1) * dim], dim, out);
        }
    }
    c.pts = std::move(q);
    c.knots.insert(c.knots.begin() + k + 1, t);
}

// Breakpoints of the kept range: lo, hi and every distinct knot strictly between them.
std::vector<double> breakpoints(const std::vector<double>& T, double lo, double hi) {
    std::vector<double> b{lo};
    for (double t : T)
        if (t > lo && t < hi && t != b.back()) b.push_back(t);
    b.push_back(hi);
    return b;
}

// Cubic Bezier segments (4 points of c.dim coordinates each) of the curve restricted to [lo, hi].
std::vector<std::vector<double>> bezierSegments(Curve c, double lo, double hi) {
    const int p = c.degree, dim = c.dim;
    std::vector<double> bp = breakpoints(c.knots, lo, hi);
    // Raise every breakpoint to multiplicity p: the control points of each span are then its Bezier points.
    for (double t : bp)
        for (int m = multiplicity(c.knots, t); m < p; ++m) insertKnot(c, t);
    std::vector<std::vector<double>> segs;
    for (size_t s = 0; s + 1 < bp.size(); ++s) {
        const std::vector<double>& T = c.knots;
        int k = int(std::upper_bound(T.begin(), T.end(), bp[s]) - T.begin()) - 1;
        const double* P = &c.pts[size_t(k - p) * dim];  // P[k-p .. k]
        std::vector<double> seg(size_t(4) * dim);
        for (int d = 0; d < dim; ++d) {
            double b[4];
            if (p == 3) {
                for (int i = 0; i < 4; ++i) b[i] = P[i * dim + d];
            } else if (p == 2) {  // exact degree elevation 2 -> 3
                double q0 = P[d], q1 = P[dim + d], q2 = P[2 * dim + d];
                b[0] = q0, b[1] = (q0 + 2 * q1) / 3, b[2] = (2 * q1 + q2) / 3, b[3] = q2;
            } else {  // p == 1: a line, elevated 1 -> 3
                double q0 = P[d], q1 = P[dim + d];
                b[0] = q0, b[1] = (2 * q0 + q1) / 3, b[2] = (q0 + 2 * q1) / 3, b[3] = q1;
            }
            for (int i = 0; i < 4; ++i) seg[size_t(i) * dim + d] = b[i];
        }
        segs.push_back(std::move(seg));
    }
    return segs;
}

void validateDirection(const char* dir, int n, int order, const std::vector<double>& T, double& lo,
                       double& hi) {
    std::string d(dir);
    if (order < 2 || order > 4)
        throw NurbsError(d + "order " + std::to_string(order) +
                         " is not supported (orders 2, 3 and 4 are converted exactly to bicubic patches)");
    if (n < order)
        throw NurbsError("n" + d + " = " + std::to_string(n) + " control points is fewer than the " + d +
                         "order " + std::to_string(order));
    if (T.size() != size_t(n) + size_t(order))
        throw NurbsError(d + "knot has " + std::to_string(T.size()) + " values, expected " +
                         std::to_string(n + order) + " (n" + d + " + " + d + "order)");
    for (double t : T)
        if (!std::isfinite(t)) throw NurbsError(d + "knot contains a non-finite value");
    for (size_t i = 1; i < T.size(); ++i)
        if (T[i] < T[i - 1])
            throw NurbsError(d + "knot is decreasing at index " + std::to_string(i) + " (" +
                             std::to_string(T[i - 1]) + " then " + std::to_string(T[i]) + ")");
    for (double t : T)
        if (multiplicity(T, t) > order)
            throw NurbsError(d + "knot value " + std::to_string(t) + " has multiplicity " +
                             std::to_string(multiplicity(T, t)) + ", more than the " + d + "order " +
                             std::to_string(order));
    const double a = T[size_t(order) - 1], b = T[size_t(n)];
    if (!(a < b)) throw NurbsError(d + "knot vector has an empty parameter domain");
    if (!std::isfinite(lo) || !std::isfinite(hi) || !(lo < hi))
        throw NurbsError(d + "min must be less than " + d + "max");
    // Tolerate rounding in the range as written by exporters; anything further out is an error.
    const double eps = 1e-9 * std::max(1.0, b - a);
    if (lo < a - eps || hi > b + eps)
        throw NurbsError(d + "min/" + d + "max [" + std::to_string(lo) + ", " + std::to_string(hi) +
                         "] lies outside the knot domain [" + std::to_string(a) + ", " + std::to_string(b) +
                         "]");
    lo = std::max(lo, a);
    hi = std::min(hi, b);
    if (!(lo < hi)) throw NurbsError(d + "min must be less than " + d + "max");
}

// Basis functions N_{k-p..k, p}(t) at t (The NURBS Book, A2.2); returns the span index k.
int basisFunctions(const std::vector<double>& T, int n, int p, double t, double N[8]) {
    int k;
    if (t >= T[size_t(n) + 1]) {
        k = n;  // the end of the domain belongs to the last non-empty span
        while (k > p && T[size_t(k)] == T[size_t(k) + 1]) --k;
    } else {
        k = int(std::upper_bound(T.begin(), T.end(), t) - T.begin()) - 1;
        k = std::clamp(k, p, n);
    }
    double left[8], right[8];
    N[0] = 1;
    for (int j = 1; j <= p; ++j) {
        left[j] = t - T[size_t(k + 1 - j)];
        right[j] = T[size_t(k + j)] - t;
        double saved = 0;
        for (int r = 0; r < j; ++r) {
            double tmp = N[r] / (right[r + 1] + left[j - r]);
            N[r] = saved + right[r + 1] * tmp;
            saved = left[j - r] * tmp;
        }
        N[j] = saved;
    }
    return k;
}

}  // namespace

void validateNurbs(const NurbsSurface& s) {
    double ulo = s.umin, uhi = s.umax, vlo = s.vmin, vhi = s.vmax;
    validateDirection("u", s.nu, s.uorder, s.uknot, ulo, uhi);
    validateDirection("v", s.nv, s.vorder, s.vknot, vlo, vhi);
    if (s.cp.size() != size_t(s.nu) * size_t(s.nv))
        throw NurbsError("expected " + std::to_string(size_t(s.nu) * size_t(s.nv)) +
                         " control points (nu x nv), got " + std::to_string(s.cp.size()));
    for (const Vec3& p : s.cp)
        if (!isFinite(p)) throw NurbsError("a control point is not finite");
}

size_t nurbsPatchCount(const NurbsSurface& s) {
    validateNurbs(s);
    double ulo = s.umin, uhi = s.umax, vlo = s.vmin, vhi = s.vmax;
    validateDirection("u", s.nu, s.uorder, s.uknot, ulo, uhi);
    validateDirection("v", s.nv, s.vorder, s.vknot, vlo, vhi);
    return (breakpoints(s.uknot, ulo, uhi).size() - 1) * (breakpoints(s.vknot, vlo, vhi).size() - 1);
}

std::vector<BezierPatch> nurbsToBezier(const NurbsSurface& s) {
    validateNurbs(s);
    double ulo = s.umin, uhi = s.umax, vlo = s.vmin, vhi = s.vmax;
    validateDirection("u", s.nu, s.uorder, s.uknot, ulo, uhi);
    validateDirection("v", s.nv, s.vorder, s.vknot, vlo, vhi);

    // u direction first: point i of the curve is column i of the grid (all nv rows, 3 numbers each).
    Curve cu;
    cu.knots = s.uknot;
    cu.degree = s.uorder - 1;
    cu.dim = 3 * s.nv;
    cu.pts.resize(size_t(s.nu) * cu.dim);
    for (int j = 0; j < s.nv; ++j)
        for (int i = 0; i < s.nu; ++i) {
            const Vec3& p = s.cp[size_t(j) * s.nu + i];
            double* o = &cu.pts[size_t(i) * cu.dim + size_t(j) * 3];
            o[0] = p.x, o[1] = p.y, o[2] = p.z;
        }
    std::vector<std::vector<double>> uSegs = bezierSegments(std::move(cu), ulo, uhi);

    std::vector<BezierPatch> out;
    for (const std::vector<double>& useg : uSegs) {
        // v direction: point j holds row j of the 4 Bezier columns of this u span (4 x 3 numbers).
        Curve cv;
        cv.knots = s.vknot;
        cv.degree = s.vorder - 1;
        cv.dim = 12;
        cv.pts.resize(size_t(s.nv) * 12);
        for (int j = 0; j < s.nv; ++j)
            for (int c = 0; c < 4; ++c)
                for (int d = 0; d < 3; ++d)
                    cv.pts[size_t(j) * 12 + size_t(c) * 3 + d] =
                        useg[size_t(c) * 3 * s.nv + size_t(j) * 3 + d];
        for (const std::vector<double>& vseg : bezierSegments(std::move(cv), vlo, vhi)) {
            BezierPatch b;
            for (int r = 0; r < 4; ++r)
                for (int c = 0; c < 4; ++c) {
                    const double* q = &vseg[size_t(r) * 12 + size_t(c) * 3];
                    b.at(c, r) = {float(q[0]), float(q[1]), float(q[2])};
                }
            out.push_back(b);
        }
    }
    return out;
}

Vec3 evalNurbs(const NurbsSurface& s, double u, double v) {
    const int pu = s.uorder - 1, pv = s.vorder - 1;
    double Nu[8], Nv[8];
    int ku = basisFunctions(s.uknot, s.nu - 1, pu, u, Nu);
    int kv = basisFunctions(s.vknot, s.nv - 1, pv, v, Nv);
    double x = 0, y = 0, z = 0;
    for (int b = 0; b <= pv; ++b)
        for (int a = 0; a <= pu; ++a) {
            const Vec3& p = s.cp[size_t(kv - pv + b) * s.nu + size_t(ku - pu + a)];
            double w = Nu[a] * Nv[b];
            x += w * p.x, y += w * p.y, z += w * p.z;
        }
    return {float(x), float(y), float(z)};
}

}  // namespace tessera
