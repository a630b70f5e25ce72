// Non-rational NURBS surfaces (RI spec 3.2, sec. 5.3, RiNuPatch) and their exact conversion to bicubic
// Bezier patches.
//
// Conversion: Boehm's knot insertion (W. Boehm, "Inserting new knots into B-spline curves", CAD 12(4),
// 1980; Piegl & Tiller, "The NURBS Book", 2nd ed., algorithm A5.1) raises every breakpoint inside the
// parameter range [min, max] to multiplicity `degree`, which splits the surface into polynomial (Bezier)
// pieces without changing it. Orders 2 and 3 are then degree-elevated exactly to cubics (The NURBS Book,
// sec. 5.5). All arithmetic is in double precision; the result is rounded to float once at the end.
#pragma once
#include <stdexcept>
#include <string>
#include <vector>

#include "core/bezier.h"

namespace tessera {

// A tensor-product NURBS surface with all weights 1. Control points are row-major, u fastest:
// cp[j * nu + i] (the RIB layout of "P" in NuPatch).
struct NurbsSurface {
    int nu = 0, nv = 0;                             // control points per direction
    int uorder = 4, vorder = 4;                     // order = degree + 1
    std::vector<double> uknot, vknot;               // nu + uorder and nv + vorder values, non-decreasing
    double umin = 0, umax = 1, vmin = 0, vmax = 1;  // parameter range to keep (RiNuPatch umin umax ...)
    std::vector<Vec3> cp;
};

// Thrown for an invalid surface (knot vector length, decreasing knots, range outside the knot vector,
// unsupported order, wrong point count). The message names the problem; readers add file:line.
class NurbsError : public std::invalid_argument {
  public:
    using std::invalid_argument::invalid_argument;
};

// Checks the surface; throws NurbsError with a message such as "uknot has 8 values, expected 9 (nu +
// uorder)".
void validateNurbs(const NurbsSurface& s);

// Exact conversion to bicubic Bezier patches, one per non-empty knot span inside [umin,umax] x [vmin,vmax].
// Patch order: u spans in the outer loop, v spans in the inner loop (the order of Micropolis' killeroo
// conversion). Each patch's u and v follow the surface's u and v. Supported orders: 2, 3, 4.
std::vector<BezierPatch> nurbsToBezier(const NurbsSurface& s);

// Direct evaluation by the Cox-de Boor recurrence (for tests and diagnostics). u, v must lie inside the
// knot domain [knot[order-1], knot[n]].
Vec3 evalNurbs(const NurbsSurface& s, double u, double v);

// Number of Bezier patches nurbsToBezier() will produce (without converting).
size_t nurbsPatchCount(const NurbsSurface& s);

}  // namespace tessera
