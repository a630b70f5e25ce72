#include "core/nurbs.h"

#include <algorithm>
#include <cmath>

#include "core/cpu.h"

namespace tessera {

namespace {

// A B-spline curve whose "points" have `dim` coordinates each (a whole row or column of a surface is one
// point, so one insertion pass refines every row at once).
struct Curve {
    std::vector<double> knots;
    std::vector<double> pts;  // (n + 1) * dim
    int dim = 3;
    int degree = 3;
};

int multiplicity(const std::vector<double>& T, double t) {
    auto range = std::equal_range(T.begin(), T.end(), t);
    return int(range.second - range.first);
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
// Span [a, b] of knot span k (T[k] <= a < b <= T[k+1]) has the Bezier points of degree p
// b_j = f(a, ..., a, b, ..., b) (p - j times a, j times b), f the span's blossom, evaluated by de Boor's
// algorithm with argument t_r at stage r (Ramshaw 1989; The NURBS Book sec. 5.3): the same points as
// raising every breakpoint to multiplicity p by knot insertion, but span by span from the p + 1 control
// points each depends on, so the work grows linearly with the curve (inserting into the whole curve,
// as before, was quadratic: 11% of a Killeroo frame).
// Segments [s0, s1) of the curve between the breakpoints `bp` (breakpoints(knots, lo, hi)), written flat to
// `out` (4 * c.dim numbers per segment, segment s0 first). Segments are independent: callers split them
// among threads.
[[gnu::always_inline]] inline void bezierSegmentsBody(const Curve& c, const std::vector<double>& bp,
                                                      size_t s0, size_t s1, double* out) {
    const int p = c.degree, dim = c.dim;
    const std::vector<double>& T = c.knots;
    // levels[r]: de Boor's stage r, points i = k - p + r .. k at offsets (i - (k - p)) * dim. b_j's
    // arguments are b_{j-1}'s with the last a made a b, so b_j shares the first p - j stages with b_{j-1}
    // and recomputes only the rest: 16 point updates for a cubic span instead of 24, the same operations
    // in the same order on the same inputs, so the same bits.
    std::vector<double> levels(size_t(p + 1) * size_t(p + 1) * dim), bez(size_t(p + 1) * dim);
    auto level = [&](int r) { return &levels[size_t(r) * size_t(p + 1) * dim]; };
    for (size_t s = s0; s < s1; ++s) {
        const double a = bp[s], b = bp[s + 1];
        const int k = int(std::upper_bound(T.begin(), T.end(), a) - T.begin()) - 1;  // T[k] <= a < T[k+1]
        std::copy_n(&c.pts[size_t(k - p) * dim], size_t(p + 1) * dim, level(0));
        for (int j = 0; j <= p; ++j) {
            for (int r = j == 0 ? 1 : p - j + 1; r <= p; ++r) {
                const double t = r <= p - j ? a : b;
                const double* in = level(r - 1);
                double* next = level(r);
                for (int i = k; i >= k - p + r; --i) {
                    // T[i] <= T[k] < T[k+1] <= T[i + p + 1 - r]: a positive denominator
                    const double alpha = (t - T[size_t(i)]) / (T[size_t(i + p + 1 - r)] - T[size_t(i)]);
                    const size_t o = size_t(i - (k - p)) * dim;
                    for (int e = 0; e < dim; ++e)
                        next[o + e] = (1 - alpha) * in[o - dim + e] + alpha * in[o + e];
                }
            }
            std::copy_n(level(p) + size_t(p) * dim, dim, &bez[size_t(j) * dim]);
        }
        double* seg = out + (s - s0) * size_t(4) * dim;
        for (int e = 0; e < dim; ++e) {
            double q[4];
            for (int i = 0; i <= p; ++i) q[i] = bez[size_t(i) * dim + e];
            double o[4];
            if (p == 3) {
                for (int i = 0; i < 4; ++i) o[i] = q[i];
            } else if (p == 2) {  // exact degree elevation 2 -> 3
                o[0] = q[0], o[1] = (q[0] + 2 * q[1]) / 3, o[2] = (2 * q[1] + q[2]) / 3, o[3] = q[2];
            } else {  // p == 1: a line, elevated 1 -> 3
                o[0] = q[0], o[1] = (2 * q[0] + q[1]) / 3, o[2] = (q[0] + 2 * q[1]) / 3, o[3] = q[1];
            }
            for (int i = 0; i < 4; ++i) seg[size_t(i) * dim + e] = o[i];
        }
    }
}

// The body compiled for AVX2 too (the blend of `dim` numbers per de Boor step in 4 doubles a time: the
// same multiplies and adds, no FMA, so the same bits), chosen where the CPU has it.
__attribute__((target("avx2"))) void bezierSegmentsAvx2(const Curve& c, const std::vector<double>& bp,
                                                        size_t s0, size_t s1, double* out) {
    bezierSegmentsBody(c, bp, s0, s1, out);
}

void bezierSegments(const Curve& c, const std::vector<double>& bp, size_t s0, size_t s1, double* out) {
    if (cpuHasAvx2()) return bezierSegmentsAvx2(c, bp, s0, s1, out);
    bezierSegmentsBody(c, bp, s0, s1, out);
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
    const std::vector<double> bu = breakpoints(s.uknot, ulo, uhi), bv = breakpoints(s.vknot, vlo, vhi);
    const size_t nu = bu.size() - 1, nv = bv.size() - 1;
    // Both passes write their spans flat, one buffer each (not a vector per span).
    const size_t useg = size_t(4) * size_t(cu.dim);
    std::vector<double> uSegs(nu * useg);
    bezierSegments(cu, bu, 0, nu, uSegs.data());

    std::vector<BezierPatch> out(nu * nv);  // one patch per (u, v) span, u spans outer
    {
        Curve cv;
        cv.knots = s.vknot;
        cv.degree = s.vorder - 1;
        cv.dim = 12;
        cv.pts.resize(size_t(s.nv) * 12);
        std::vector<double> vSegs(nv * 48);
        for (size_t us = 0; us < nu; ++us) {
            // v direction: point j holds row j of the 4 Bezier columns of this u span (4 x 3 numbers).
            const double* seg = &uSegs[us * useg];
            for (int j = 0; j < s.nv; ++j)
                for (int c = 0; c < 4; ++c)
                    for (int d = 0; d < 3; ++d)
                        cv.pts[size_t(j) * 12 + size_t(c) * 3 + d] =
                            seg[size_t(c) * 3 * s.nv + size_t(j) * 3 + d];
            bezierSegments(cv, bv, 0, nv, vSegs.data());
            for (size_t vs = 0; vs < nv; ++vs) {
                BezierPatch& b = out[us * nv + vs];
                for (int row = 0; row < 4; ++row)
                    for (int c = 0; c < 4; ++c) {
                        const double* q = &vSegs[vs * 48 + size_t(row) * 12 + size_t(c) * 3];
                        b.at(c, row) = {float(q[0]), float(q[1]), float(q[2])};
                    }
            }
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
