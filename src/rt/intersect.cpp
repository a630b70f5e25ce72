// The intersection routines are templates in intersect.h (float for rendering, double as the reference);
// this file instantiates the two precisions once so that other translation units can share them.
#include "rt/intersect.h"

namespace tessera {

template bool newtonSolve<float>(const BezierPatch&, const RayPlanes&, const Ray&, float, float,
                                 const NewtonParams&, PatchHit&);
template bool newtonSolve<double>(const BezierPatch&, const RayPlanes&, const Ray&, float, float,
                                  const NewtonParams&, PatchHit&);

}  // namespace tessera
