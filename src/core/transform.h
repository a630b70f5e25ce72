// 4x4 transforms in double precision (composed from many RIB requests, so keep the error down).
// Convention: column vectors, p' = M * p. RIB matrices (row-vector convention) are transposed on input.
#pragma once
#include <cstddef>
#include "core/vec.h"

namespace tessera {

struct Mat4 {
    double m[4][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}};

    static Mat4 identity() { return {}; }
    static Mat4 translate(double x, double y, double z);
    static Mat4 scale(double x, double y, double z);
    // Rotation by `degrees` about `axis`, right-handed sense as in RiRotate (RI spec 3.2, sec. 4.3).
    static Mat4 rotate(double degrees, double ax, double ay, double az);
    // From 16 numbers in RIB order (row-major, row vectors: translation in elements 12..14).
    static Mat4 fromRib(const double v[16]);

    Mat4 operator*(const Mat4& b) const;
    Mat4 inverse() const;  // general inverse; returns identity-scaled garbage only if singular (check det)
    double determinant() const;
    double det3() const;  // determinant of the upper-left 3x3 (handedness)
    // An upper bound on how much the linear part stretches a vector: sqrt of a Gershgorin bound on the
    // eigenvalues of M^T M (exact for rotations with uniform scale).
    double maxStretch() const;

    Vec3 point(Vec3 p) const;   // with homogeneous divide
    // point() of n points. For an affine matrix (last row 0 0 0 1) the divide is left out: point() skips
    // it too, as w is exactly 1 for a finite point, so the results are the same (for a non-finite one
    // point() gives NaN, this the infinity; both fail a finiteness check).
    void points(const Vec3* in, Vec3* out, size_t n) const;
    Vec3 vector(Vec3 v) const;  // no translation
    // Normals transform with the inverse transpose; callers pass this matrix's inverse.
    static Vec3 normalWithInverse(const Mat4& inv, Vec3 n);
};

}  // namespace tessera
