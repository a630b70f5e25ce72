#include "shading/shadow_map.h"

#include <cmath>

namespace tessera {

std::string fileShadowMapFace(const Mat4& worldToCamera, const Mat4& worldToNDC, int width, int height,
                              const Mat4& worldFromShading, ShadowMapFace& face) {
    if (width <= 0 || height <= 0) return "the depth map has no texels";
    if (std::fabs(worldToCamera.det3()) < 1e-12) return "its worldToCamera matrix is singular";
    // The view's projection: camera space to NDC.
    Mat4 c = worldToNDC * worldToCamera.inverse();
    for (int r = 0; r < 4; ++r)
        for (int k = 0; k < 4; ++k)
            if (!std::isfinite(c.m[r][k])) return "its worldToNDC matrix is not finite";
    const double w2 = c.m[3][2], w3 = c.m[3][3];
    const double scale = std::fabs(c.m[0][0]) + std::fabs(c.m[1][1]);
    auto small = [&](double v, double ref) { return std::fabs(v) <= 1e-6 * ref; };
    const bool perspective = std::fabs(w2) > std::fabs(w3);
    // Normalise the homogeneous row to w = z (perspective) or w = 1 (orthographic).
    const double norm = perspective ? w2 : w3;
    if (!(std::fabs(norm) > 0)) return "its worldToNDC matrix is not a camera projection";
    for (int r = 0; r < 4; ++r)
        for (int k = 0; k < 4; ++k) c.m[r][k] /= norm;
    const double ref = scale / std::fabs(norm);
    if (!small(c.m[3][0], ref) || !small(c.m[3][1], ref) || !small(perspective ? c.m[3][3] : c.m[3][2], ref))
        return "its worldToNDC matrix is neither a perspective nor an orthographic projection";
    // x and y each depend on their own axis (and, as the off-centre term, on z or 1) only.
    const int offset = perspective ? 2 : 3, other = perspective ? 3 : 2;
    if (!small(c.m[0][1], ref) || !small(c.m[1][0], ref) || !small(c.m[0][other], ref) ||
        !small(c.m[1][other], ref))
        return "its projection is skewed or rotated about the view axis, which Tessera does not read";
    if (!(std::fabs(c.m[0][0]) > 0) || !(std::fabs(c.m[1][1]) > 0))
        return "its projection maps the image to a line";
    face.lightFromShading = affineFrameOf(worldToCamera * worldFromShading);
    face.perspective = perspective;
    face.sx = float(width * c.m[0][0]);
    face.ox = float(width * c.m[0][offset]);
    face.sy = float(height * c.m[1][1]);
    face.oy = float(height * c.m[1][offset]);
    face.width = width;
    face.height = height;
    face.depth = nullptr;
    return "";
}

}  // namespace tessera
