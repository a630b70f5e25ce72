// The seven RenderMan quadrics (RI spec 3.2, sec. 5.4): Sphere, Cylinder, Cone, Disk, Paraboloid,
// Hyperboloid and Torus, as closed-form surfaces over their own (u,v) in [0,1]^2. Plain kernels over plain
// data (TESSERA_HD) shared by both engines: evaluation with derivatives and the normal (Reyes' dicer and
// the ray tracer's hit), a conservative box of any (u,v) rectangle (Reyes' split, the ray tracer's
// subpatch boxes) and the analytic ray intersection clipped to zmin/zmax/thetamax.
//
// Every quadric is a profile point p(v) = (px, py, pz) in the xz half-plane (py != 0 only for the
// hyperboloid) swept about z by phi = u * thetamax:
//   P(u,v) = (px cos phi - py sin phi, px sin phi + py cos phi, pz),  dP/du = thetamax (-Py, Px, 0).
// The RI parametrisations of the profile (sec. 5.4, the figures' formulas):
//   Sphere      theta = thetamin + v (thetamaxlat - thetamin), thetamin = asin(zmin/r): (r cos, 0, r sin)
//   Cylinder    (r, 0, zmin + v (zmax - zmin))
//   Cone        (r (1 - v), 0, v height)
//   Disk        (r (1 - v), 0, height)
//   Paraboloid  z = zmin + v (zmax - zmin): (rmax sqrt(z / zmax), 0, z)
//   Hyperboloid point1 + v (point2 - point1)
//   Torus       psi = phimin + v (phimax - phimin): (major + minor cos psi, 0, minor sin psi)
// The geometric normal is dP/du x dP/dv (RI spec sec. 5): negative thetamax (or a parameter that reverses
// u or v, such as zmin > zmax) turns the surface inside out, as the spec says.
#pragma once
#include <cmath>
#include <cstdint>

#include "core/bezier.h"
#include "core/hostdevice.h"
#include "core/vec.h"

namespace tessera {

enum class QuadricKind : uint8_t { Sphere, Cylinder, Cone, Disk, Paraboloid, Hyperboloid, Torus };

inline constexpr float kQuadricPi = 3.14159265358979f;
inline constexpr float kQuadricTwoPi = 6.28318530717959f;

// An affine map in single precision (rows: x, y, z; column 3: translation), for the kernels.
struct Affine3 {
    float m[3][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}};
};
TESSERA_HD Vec3 affinePoint(const Affine3& a, Vec3 p) {
    return {a.m[0][0] * p.x + a.m[0][1] * p.y + a.m[0][2] * p.z + a.m[0][3],
            a.m[1][0] * p.x + a.m[1][1] * p.y + a.m[1][2] * p.z + a.m[1][3],
            a.m[2][0] * p.x + a.m[2][1] * p.y + a.m[2][2] * p.z + a.m[2][3]};
}
TESSERA_HD Vec3 affineVector(const Affine3& a, Vec3 v) {
    return {a.m[0][0] * v.x + a.m[0][1] * v.y + a.m[0][2] * v.z,
            a.m[1][0] * v.x + a.m[1][1] * v.y + a.m[1][2] * v.z,
            a.m[2][0] * v.x + a.m[2][1] * v.y + a.m[2][2] * v.z};
}

// One quadric's RI parameters (angles in radians) in its object space.
struct Quadric {
    QuadricKind kind = QuadricKind::Sphere;
    float radius = 1.f;            // sphere, cylinder, cone, disk radius; paraboloid rmax; torus major radius
    float minorRadius = 0.f;       // torus
    float zMin = 0.f, zMax = 0.f;  // sphere (clamped to [-|r|, |r|]), cylinder, paraboloid
    float height = 0.f;            // cone, disk
    float angle0 = 0.f, angle1 = 0.f;  // sphere: latitudes asin(zmin/r), asin(zmax/r); torus: phimin, phimax
    Vec3 point1, point2;               // hyperboloid
    float thetaMax = kQuadricTwoPi;    // sweep about z, signed
    // |thetamax| = 360 degrees (u = 0 and u = 1 are one seam) / the torus' minor circle is closed.
    bool closedU = true, closedV = false;
};

// The object-space quadric with where it is: object to the engine's space and back.
struct PlacedQuadric {
    Quadric q;
    Affine3 toSpace, fromSpace;
};

struct QuadricProfile {
    Vec3 p, dp;  // profile point and its v derivative, before the sweep
};

TESSERA_HD QuadricProfile quadricProfile(const Quadric& q, float v) {
    QuadricProfile r;
    switch (q.kind) {
        case QuadricKind::Sphere: {
            const float th =
                v <= 0.f ? q.angle0 : (v >= 1.f ? q.angle1 : q.angle0 + v * (q.angle1 - q.angle0));
            // At a pole the profile meets the axis exactly (cos(float(pi/2)) is not 0), so every vertex
            // of a pole row is the same point.
            const float c = std::fabs(th) >= 0.5f * kQuadricPi ? 0.f : std::cos(th), s = std::sin(th);
            const float dth = q.angle1 - q.angle0;
            r.p = {q.radius * c, 0.f, q.radius * s};
            r.dp = {-q.radius * s * dth, 0.f, q.radius * c * dth};
            break;
        }
        case QuadricKind::Cylinder:
            r.p = {q.radius, 0.f, q.zMin + v * (q.zMax - q.zMin)};
            r.dp = {0.f, 0.f, q.zMax - q.zMin};
            break;
        case QuadricKind::Cone:
            r.p = {q.radius * (1.f - v), 0.f, v * q.height};
            r.dp = {-q.radius, 0.f, q.height};
            break;
        case QuadricKind::Disk:
            r.p = {q.radius * (1.f - v), 0.f, q.height};
            r.dp = {-q.radius, 0.f, 0.f};
            break;
        case QuadricKind::Paraboloid: {
            const float z = v <= 0.f ? q.zMin : (v >= 1.f ? q.zMax : q.zMin + v * (q.zMax - q.zMin));
            const float w = std::sqrt(std::fmax(z / q.zMax, 0.f));
            r.p = {q.radius * w, 0.f, z};
            // d rho / dz = rmax / (2 zmax w); infinite at the apex (the normal falls back there).
            r.dp = {w > 0.f ? q.radius * (q.zMax - q.zMin) / (2.f * q.zMax * w) : 0.f, 0.f, q.zMax - q.zMin};
            break;
        }
        case QuadricKind::Hyperboloid:
            r.p = v <= 0.f ? q.point1 : (v >= 1.f ? q.point2 : q.point1 + (q.point2 - q.point1) * v);
            r.dp = q.point2 - q.point1;
            break;
        case QuadricKind::Torus: {
            const float dpsi = q.angle1 - q.angle0;
            const float psi =
                v <= 0.f || (v >= 1.f && q.closedV) ? q.angle0 : (v >= 1.f ? q.angle1 : q.angle0 + v * dpsi);
            const float c = std::cos(psi), s = std::sin(psi);
            r.p = {q.radius + q.minorRadius * c, 0.f, q.minorRadius * s};
            r.dp = {-q.minorRadius * s * dpsi, 0.f, q.minorRadius * c * dpsi};
            break;
        }
    }
    return r;
}

// Sweep angle of u; a closed sweep's u = 1 is evaluated as u = 0 (bit-identical seam).
TESSERA_HD float quadricPhi(const Quadric& q, float u) {
    if (u <= 0.f || (u >= 1.f && q.closedU)) return 0.f;
    return u >= 1.f ? q.thetaMax : u * q.thetaMax;
}

// Position and derivatives at (u,v), object space.
TESSERA_HD SurfacePoint evalQuadric(const Quadric& q, float u, float v) {
    const QuadricProfile pr = quadricProfile(q, v);
    const float phi = quadricPhi(q, u);
    const float c = phi == 0.f ? 1.f : std::cos(phi), s = phi == 0.f ? 0.f : std::sin(phi);
    SurfacePoint sp;
    sp.p = {pr.p.x * c - pr.p.y * s, pr.p.x * s + pr.p.y * c, pr.p.z};
    sp.dpdu = {-sp.p.y * q.thetaMax, sp.p.x * q.thetaMax, 0.f};
    sp.dpdv = {pr.dp.x * c - pr.dp.y * s, pr.dp.x * s + pr.dp.y * c, pr.dp.z};
    return sp;
}

// The geometric normal dP/du x dP/dv at (u,v), unit length, object space. Where the sweep meets the axis
// (sphere poles, cone apex, disk centre, paraboloid apex) dP/du vanishes: there the limit of the normal
// from inside the domain is taken (for a profile in the xz plane, thetamax * px (dpz, 0, -dpx) swept by
// phi, with px's sign just inside the domain).
TESSERA_HD Vec3 quadricNormal(const Quadric& q, float u, float v) {
    const SurfacePoint sp = evalQuadric(q, u, v);
    Vec3 n = cross(sp.dpdu, sp.dpdv);
    const float scale = dot(sp.dpdu, sp.dpdu) + dot(sp.dpdv, sp.dpdv);
    if (dot(n, n) > 1e-12f * scale * scale) return normalize(n);
    const float vin = v < 0.5f ? v + 1e-3f : v - 1e-3f;
    if (q.kind == QuadricKind::Hyperboloid) return normalize(cross(evalQuadric(q, u, vin).dpdu, sp.dpdv));
    QuadricProfile pr = quadricProfile(q, v);
    if (q.kind == QuadricKind::Paraboloid && pr.dp.x == 0.f)  // the apex: dP/dv turns radial
        pr.dp = {q.radius * (q.zMax - q.zMin) / q.zMax >= 0.f ? 1.f : -1.f, 0.f, 0.f};
    const float side = quadricProfile(q, vin).p.x * q.thetaMax;
    const float phi = quadricPhi(q, u), c = std::cos(phi), s = std::sin(phi);
    const Vec3 m{pr.dp.z * c, pr.dp.z * s, -pr.dp.x};
    return normalize(side < 0.f ? -m : m);
}

// Range of cos and sin over the angle interval [a, b] (a <= b).
TESSERA_HD void cosSinRange(float a, float b, float& c0, float& c1, float& s0, float& s1) {
    if (b - a >= kQuadricTwoPi) {
        c0 = s0 = -1.f, c1 = s1 = 1.f;
        return;
    }
    const float ca = std::cos(a), cb = std::cos(b), sa = std::sin(a), sb = std::sin(b);
    c0 = std::fmin(ca, cb), c1 = std::fmax(ca, cb), s0 = std::fmin(sa, sb), s1 = std::fmax(sa, sb);
    // Extremes at multiples of pi/2 inside (a, b): k pi/2 with k = 0: cos max, 1: sin max, 2: cos min, 3: sin
    // min.
    const float quarter = 0.5f * kQuadricPi;
    for (int k = int(std::ceil(a / quarter)); float(k) * quarter < b; ++k) {
        switch (((k % 4) + 4) % 4) {
            case 0:
                c1 = 1.f;
                break;
            case 1:
                s1 = 1.f;
                break;
            case 2:
                c0 = -1.f;
                break;
            default:
                s0 = -1.f;
                break;
        }
    }
}

// Product of the intervals [a0, a1] and [b0, b1].
TESSERA_HD void intervalProduct(float a0, float a1, float b0, float b1, float& lo, float& hi) {
    const float p0 = a0 * b0, p1 = a0 * b1, p2 = a1 * b0, p3 = a1 * b1;
    lo = std::fmin(std::fmin(p0, p1), std::fmin(p2, p3));
    hi = std::fmax(std::fmax(p0, p1), std::fmax(p2, p3));
}

// Conservative object-space box of the quadric over [u0,u1] x [v0,v1]: the profile's range of radius
// (signed) and height over [v0,v1] times the range of cos/sin of the swept angle; exact up to rounding
// for the profile kinds (x = rho cos a is a product of independent ranges), grown by a relative margin.
TESSERA_HD Bounds3 quadricBounds(const Quadric& q, float u0, float u1, float v0, float v1) {
    float r0 = 0, r1 = 0, z0 = 0, z1 = 0;  // profile radius and height ranges
    float a0 = 0, a1 = 0;                  // angle offset of the profile point (hyperboloid)
    auto both = [](float a, float b, float& lo, float& hi) { lo = std::fmin(a, b), hi = std::fmax(a, b); };
    const QuadricProfile pa = quadricProfile(q, v0), pb = quadricProfile(q, v1);
    switch (q.kind) {
        case QuadricKind::Sphere:
        case QuadricKind::Torus: {
            const float t0 = q.angle0 + v0 * (q.angle1 - q.angle0),
                        t1 = q.angle0 + v1 * (q.angle1 - q.angle0);
            float c0, c1, s0, s1;
            cosSinRange(std::fmin(t0, t1), std::fmax(t0, t1), c0, c1, s0, s1);
            const float r = q.kind == QuadricKind::Sphere ? q.radius : q.minorRadius;
            const float base = q.kind == QuadricKind::Sphere ? 0.f : q.radius;
            intervalProduct(r, r, c0, c1, r0, r1);
            intervalProduct(r, r, s0, s1, z0, z1);
            r0 += base, r1 += base;
            break;
        }
        case QuadricKind::Hyperboloid: {
            both(pa.p.z, pb.p.z, z0, z1);
            // Distance of the segment's xy projection to the axis: max at an end, min at the foot point.
            const float ax = pa.p.x, ay = pa.p.y, dx = pb.p.x - ax, dy = pb.p.y - ay;
            const float dd = dx * dx + dy * dy;
            const float w = dd > 0.f ? std::fmin(std::fmax(-(ax * dx + ay * dy) / dd, 0.f), 1.f) : 0.f;
            const float fx = ax + w * dx, fy = ay + w * dy;
            const float ra = std::sqrt(ax * ax + ay * ay), rb = std::sqrt(pb.p.x * pb.p.x + pb.p.y * pb.p.y);
            r0 = std::sqrt(fx * fx + fy * fy), r1 = std::fmax(ra, rb);
            if (r0 <= 1e-6f * r1) {
                r0 = 0.f, a0 = 0.f, a1 = kQuadricTwoPi;  // passes the axis: any angle
            } else {
                // The angle along a segment that misses the axis is monotonic and turns less than pi.
                const float aa = std::atan2(ay, ax);
                float ab = std::atan2(pb.p.y, pb.p.x);
                if (ab - aa > kQuadricPi) ab -= kQuadricTwoPi;
                if (aa - ab > kQuadricPi) ab += kQuadricTwoPi;
                both(aa, ab, a0, a1);
            }
            break;
        }
        default:  // cylinder, cone, disk, paraboloid: radius and height monotonic in v
            both(pa.p.x, pb.p.x, r0, r1);
            both(pa.p.z, pb.p.z, z0, z1);
            break;
    }
    const float p0 = u0 * q.thetaMax, p1 = u1 * q.thetaMax;
    float c0, c1, s0, s1;
    cosSinRange(std::fmin(p0, p1) + a0, std::fmax(p0, p1) + a1, c0, c1, s0, s1);
    Bounds3 b;
    intervalProduct(r0, r1, c0, c1, b.lo.x, b.hi.x);
    intervalProduct(r0, r1, s0, s1, b.lo.y, b.hi.y);
    b.lo.z = z0, b.hi.z = z1;
    const float m =
        1e-5f * (std::fmax(std::fabs(r0), std::fabs(r1)) + std::fmax(std::fabs(z0), std::fabs(z1))) + 1e-7f;
    b.lo = b.lo - Vec3{m, m, m}, b.hi = b.hi + Vec3{m, m, m};
    return b;
}

// A ray's hit on a quadric: parameter t along the ray and the (u,v) of the hit.
struct QuadricHit {
    float t, u, v;
};

// u of a point at sweep angle phi (radians, any branch); false when a partial sweep does not reach it.
// Angles within 1e-5 rad short of a full turn count as the u = 0 edge (rounding of atan2 there).
TESSERA_HD bool quadricU(const Quadric& q, double phi, float& u) {
    const double twoPi = 6.283185307179586, T = q.thetaMax, tol = 1e-5;
    double a = std::fmod(phi, twoPi);  // (-2 pi, 2 pi)
    if (T >= 0 && a < 0) a += twoPi;
    if (T < 0 && a > 0) a -= twoPi;  // now a has the sign of thetamax
    double uu = std::fabs(a) >= twoPi - tol ? 0.0 : a / T;
    if (q.closedU) {
        u = uu >= 1.0 ? 0.f : float(std::fmax(uu, 0.0));
        return true;
    }
    if (!(uu <= 1.0 + tol / std::fabs(T))) return false;
    u = float(std::fmin(std::fmax(uu, 0.0), 1.0));
    return true;
}

// (u,v) of an object-space point on the quadric's implicit surface; false if it lies outside the
// quadric's zmin/zmax/thetamax/phimin/phimax range.
TESSERA_HD bool quadricParams(const Quadric& q, const double P[3], float& u, float& v) {
    const double rxy = std::sqrt(P[0] * P[0] + P[1] * P[1]);
    const float tol = 2e-5f;
    double vv = 0;
    switch (q.kind) {
        case QuadricKind::Sphere: {
            const double s = std::fmin(std::fmax(P[2] / double(q.radius), -1.0), 1.0);
            vv = (std::asin(s) - double(q.angle0)) / double(q.angle1 - q.angle0);
            break;
        }
        case QuadricKind::Cylinder:
        case QuadricKind::Paraboloid:
            vv = (P[2] - double(q.zMin)) / double(q.zMax - q.zMin);
            break;
        case QuadricKind::Cone:
            vv = P[2] / double(q.height);
            break;
        case QuadricKind::Disk:
            vv = 1.0 - rxy / std::fabs(double(q.radius));
            break;
        case QuadricKind::Hyperboloid: {
            const double z1 = q.point1.z, z2 = q.point2.z;
            if (z1 != z2) {
                vv = (P[2] - z1) / (z2 - z1);
            } else {
                // Planar: |p1xy + v (p2xy - p1xy)| = rxy, the root in [0,1] (the nearer to the segment).
                const double ax = q.point1.x, ay = q.point1.y, dx = q.point2.x - ax, dy = q.point2.y - ay;
                const double A = dx * dx + dy * dy, B = 2 * (ax * dx + ay * dy),
                             C = ax * ax + ay * ay - rxy * rxy;
                const double disc = B * B - 4 * A * C;
                if (!(A > 0) || disc < 0) return false;
                const double sq = std::sqrt(disc), r1 = (-B - sq) / (2 * A), r2 = (-B + sq) / (2 * A);
                vv = (r1 >= -tol && r1 <= 1 + tol) ? r1 : r2;
            }
            break;
        }
        case QuadricKind::Torus: {
            // (s rxy - major, z) = minor (cos psi, sin psi) with s = +1 or -1 (a negative major radius
            // puts the tube's centre at the opposite angle): the sign that fits.
            const double R = q.radius, r = q.minorRadius;
            const double ea = (rxy - R) * (rxy - R) + P[2] * P[2] - r * r;
            const double eb = (-rxy - R) * (-rxy - R) + P[2] * P[2] - r * r;
            const double s = std::fabs(ea) <= std::fabs(eb) ? 1.0 : -1.0;
            double psi = std::atan2(P[2] / r, (s * rxy - R) / r);
            const double lo = std::fmin(q.angle0, q.angle1);
            const double twoPi = 6.283185307179586;
            while (psi < lo - tol) psi += twoPi;
            while (psi >= lo + twoPi - tol) psi -= twoPi;
            vv = (psi - double(q.angle0)) / double(q.angle1 - q.angle0);
            if (q.closedV && (vv < 0 || vv >= 1)) vv = vv < 0 ? vv + 1 : vv - 1;
            break;
        }
    }
    if (!(vv >= -tol && vv <= 1 + tol)) return false;
    v = float(std::fmin(std::fmax(vv, 0.0), 1.0));
    const QuadricProfile pr = quadricProfile(q, v);
    const double phi = std::atan2(P[1], P[0]) - std::atan2(double(pr.p.y), double(pr.p.x));
    return quadricU(q, phi, u);
}

// Real roots of the polynomial c[0] + c[1] x + ... + c[n] x^n (n <= 4) in [lo, hi], increasing: the
// roots of the derivative split [lo, hi] into monotonic pieces, each bisected where its ends differ in
// sign (robust for the torus quartic; a double root that only touches 0 is missed, a tangent ray).
TESSERA_HD int polynomialRoots(const double* c, int n, double lo, double hi, double* roots) {
    while (n > 0 && c[n] == 0.0) --n;
    if (n == 0) return 0;
    if (n == 1) {
        const double x = -c[0] / c[1];
        if (x >= lo && x <= hi) return roots[0] = x, 1;
        return 0;
    }
    double d[4], crit[4];
    for (int i = 1; i <= n; ++i) d[i - 1] = double(i) * c[i];
    const int nc = polynomialRoots(d, n - 1, lo, hi, crit);
    double ends[6];
    int ne = 0;
    ends[ne++] = lo;
    for (int i = 0; i < nc; ++i) ends[ne++] = crit[i];
    ends[ne++] = hi;
    auto eval = [&](double x) {
        double f = c[n];
        for (int i = n - 1; i >= 0; --i) f = f * x + c[i];
        return f;
    };
    int count = 0;
    for (int i = 0; i + 1 < ne; ++i) {
        double a = ends[i], b = ends[i + 1], fa = eval(a), fb = eval(b);
        if (fa == 0.0) {
            if (count == 0 || roots[count - 1] != a) roots[count++] = a;
            continue;
        }
        if ((fa < 0) == (fb < 0)) continue;
        for (int it = 0; it < 80 && b - a > 1e-15 * (std::fabs(a) + std::fabs(b)); ++it) {
            const double m = 0.5 * (a + b), fm = eval(m);
            if ((fm < 0) == (fa < 0))
                a = m, fa = fm;
            else
                b = m;
        }
        roots[count++] = 0.5 * (a + b);
    }
    return count;
}

// The ray o + t d (object space) against the quadric: up to four hits with tmin < t < tmax inside the
// quadric's range, sorted by t. Sphere, cylinder, cone, paraboloid and hyperboloid are the surfaces
// x^2 + y^2 = A2 z^2 + A1 z + A0 (a quadratic in t, solved in double in the stable form); the disk (and
// a hyperboloid whose ends share z) is a plane; the torus is the quartic
// (|P|^2 + R^2 - r^2)^2 = 4 R^2 (x^2 + y^2), solved by polynomialRoots from the ray's closest approach.
TESSERA_HD int intersectQuadric(const Quadric& q, Vec3 o, Vec3 d, float tmin, float tmax,
                                QuadricHit hits[4]) {
    const double ox = o.x, oy = o.y, oz = o.z, dx = d.x, dy = d.y, dz = d.z;
    double ts[4];
    int nt = 0;
    bool planar =
        q.kind == QuadricKind::Disk || (q.kind == QuadricKind::Hyperboloid && q.point1.z == q.point2.z);
    if (planar) {
        const double h = q.kind == QuadricKind::Disk ? q.height : q.point1.z;
        if (dz != 0.0) ts[nt++] = (h - oz) / dz;
    } else if (q.kind == QuadricKind::Torus) {
        const double len = std::sqrt(dx * dx + dy * dy + dz * dz);
        if (!(len > 0)) return 0;
        const double ux = dx / len, uy = dy / len, uz = dz / len;
        const double tc = -(ox * ux + oy * uy + oz * uz);  // closest approach to the centre
        const double px = ox + tc * ux, py = oy + tc * uy, pz = oz + tc * uz;
        const double R = q.radius, r = q.minorRadius, reach = std::fabs(R) + std::fabs(r);
        const double pp = px * px + py * py + pz * pz;
        if (pp > 1.0001 * reach * reach) return 0;
        const double K = pp + R * R - r * r, a = ux * ux + uy * uy, b = px * ux + py * uy,
                     c = px * px + py * py;
        const double coef[5] = {K * K - 4 * R * R * c, -8 * R * R * b, 2 * K - 4 * R * R * a, 0.0, 1.0};
        const double half = 1.0001 * std::sqrt(std::fmax(reach * reach - pp, 0.0)) + 1e-6 * reach;
        double s[4];
        const int ns = polynomialRoots(coef, 4, -half, half, s);
        for (int i = 0; i < ns; ++i) ts[nt++] = (tc + s[i]) / len;
    } else {
        double A2 = 0, A1 = 0, A0 = 0;
        switch (q.kind) {
            case QuadricKind::Sphere:
                A2 = -1, A0 = double(q.radius) * q.radius;
                break;
            case QuadricKind::Cylinder:
                A0 = double(q.radius) * q.radius;
                break;
            case QuadricKind::Cone: {  // (r (1 - z/h))^2
                const double r = q.radius, k = r / q.height;
                A2 = k * k, A1 = -2 * r * k, A0 = r * r;
                break;
            }
            case QuadricKind::Paraboloid:
                A1 = double(q.radius) * q.radius / q.zMax;
                break;
            default: {  // hyperboloid: v = (z - z1) / (z2 - z1), rho^2 = |q0 + v q1|^2
                const double z1 = q.point1.z, al = 1.0 / (double(q.point2.z) - z1), be = -z1 * al;
                const double q0x = q.point1.x, q0y = q.point1.y, q1x = double(q.point2.x) - q0x,
                             q1y = double(q.point2.y) - q0y;
                const double c2 = q1x * q1x + q1y * q1y, c1 = 2 * (q0x * q1x + q0y * q1y),
                             c0 = q0x * q0x + q0y * q0y;
                // c2 (al z + be)^2 + c1 (al z + be) + c0
                A2 = c2 * al * al, A1 = 2 * c2 * al * be + c1 * al, A0 = c2 * be * be + c1 * be + c0;
                break;
            }
        }
        const double a = dx * dx + dy * dy - A2 * dz * dz;
        const double b = 2 * (ox * dx + oy * dy - A2 * oz * dz) - A1 * dz;
        const double c = ox * ox + oy * oy - A2 * oz * oz - A1 * oz - A0;
        const double scale = dx * dx + dy * dy + dz * dz;
        if (std::fabs(a) <= 1e-12 * scale) {
            if (b != 0.0) ts[nt++] = -c / b;
        } else {
            const double disc = b * b - 4 * a * c;
            if (disc >= 0) {
                const double qq = -0.5 * (b + (b >= 0 ? std::sqrt(disc) : -std::sqrt(disc)));
                const double t1 = qq / a, t2 = qq != 0.0 ? c / qq : t1;
                ts[nt++] = std::fmin(t1, t2);
                ts[nt++] = std::fmax(t1, t2);
            }
        }
    }
    int n = 0;
    for (int i = 0; i < nt; ++i) {
        const double t = ts[i];
        if (!(t > tmin && t < tmax)) continue;
        const double P[3] = {ox + t * dx, oy + t * dy, oz + t * dz};
        if (planar && q.kind == QuadricKind::Disk &&
            P[0] * P[0] + P[1] * P[1] > double(q.radius) * q.radius * (1 + 4e-5))
            continue;
        float u, v;
        if (!quadricParams(q, P, u, v)) continue;
        hits[n++] = {float(t), u, v};
    }
    for (int i = 1; i < n; ++i)  // sort by t (n <= 4)
        for (int j = i; j > 0 && hits[j].t < hits[j - 1].t; --j) {
            const QuadricHit x = hits[j];
            hits[j] = hits[j - 1], hits[j - 1] = x;
        }
    return n;
}

}  // namespace tessera
