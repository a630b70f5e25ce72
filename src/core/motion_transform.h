// Interpolating transformation keys of a motion block (RI spec 3.2, sec. 6, MotionBegin/MotionEnd) so
// that a rotation stays a rotation: each affine key is decomposed as M = T R S (translation, rotation,
// symmetric stretch; K. Shoemake and T. Duff, "Matrix animation and polar decomposition", Graphics
// Interface 1992), and the parts are interpolated separately: translation and stretch linearly, rotation
// by quaternion slerp along the shorter arc. pbrt-v4's AnimatedTransform does the same.
#pragma once
#include <vector>

#include "core/transform.h"

namespace tessera {

struct DecomposedTransform {
    double translation[3] = {0, 0, 0};
    double rotation[4] = {0, 0, 0, 1};  // unit quaternion (x, y, z, w)
    Mat4 stretch;                       // symmetric 3x3 in the upper-left block (sign carries a reflection)
    bool projective = false;            // the bottom row is not (0 0 0 1): not decomposable, lerp instead
    Mat4 original;
};

DecomposedTransform decompose(const Mat4& m);
Mat4 compose(const DecomposedTransform& d);
// Transform at weight w in [0,1] between two decomposed keys (w = 0 and w = 1 reproduce the keys).
Mat4 interpolate(const DecomposedTransform& a, const DecomposedTransform& b, double w);
// Angle in radians of the rotation from key a to key b (after the shorter-arc choice).
double rotationAngle(const DecomposedTransform& a, const DecomposedTransform& b);

// One key of a moving transformation.
struct TransformKey {
    double time = 0;
    Mat4 matrix;
};

// The transform of a key list at `time` (keys sorted by time; clamped outside their range; one key:
// constant).
Mat4 transformAt(const std::vector<TransformKey>& keys, double time);

// Inserts keys so that no segment rotates by more than `maxAngleRadians`: between keys the scene's motion
// is linear in the control points (one model for both engines, scene/scene.h), so a rotation is followed
// by chords; at 2 degrees the chord leaves the arc by at most r * (1 - cos 1 deg) = 1.5e-4 r.
std::vector<TransformKey> refineTransformKeys(const std::vector<TransformKey>& keys, double maxAngleRadians);

constexpr double kMaxMotionSegmentRadians = 2.0 * 3.14159265358979323846 / 180.0;

}  // namespace tessera
