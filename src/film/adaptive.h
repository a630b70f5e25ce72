// Selective and adaptive supersampling (paper 004, Jin et al., sec. 4; docs/adaptive.md): the per-subpixel
// test that decides from one presample per pixel (colour and geometry attributes of the primary hit) which
// of a pixel's four subpixels get four extra rays. Plain kernels over plain data (a CUDA backend shares
// them); the ray tracer (rt_renderer.cpp) runs the presample, the test and the extra rays.
#pragma once
#include <cstdint>

#include "core/hostdevice.h"
#include "core/vec.h"

namespace tessera {

// The thresholds of paper 004's Table 1 for the primary hit, each in [0, 1]: 0 always refines where the
// attribute disagrees, 1 (or more) never does. Defaults: tau_poid = 0.05, tau_psn = tau_psc = 0.06 (the
// paper's Table 2 caption); tau_col = 0.3 makes the contrast vector Mitchell's (0.4, 0.3, 0.6);
// tau_pte follows tau_col as the paper's tau_alpha does when negative.
struct AdaptiveThresholds {
    float color = 0.3f;      // tau_col: subpixels whose attributes all agree
    float objectId = 0.05f;  // tau_poid
    float normal = 0.06f;    // tau_psn
    float shadow = 0.06f;    // tau_psc
    float texture = -1.f;    // tau_pte; < 0: the colour threshold
    // Normals "differ if their cross product is less than a preset value" (paper 004, L147; read as the
    // dot product, the cutoff is not given): here when their cosine is below this (about 18 degrees).
    float normalCosine = 0.95f;
};

// What the presample ray of a pixel saw (the geometry attribute map plus the colour reference).
struct PresampleAttributes {
    Color color;              // premultiplied, the colour reference
    uint32_t object = 0;      // RI object (per primitive call, not per patch); kNoObject for background
    Vec3 normal;              // shading normal facing the viewer (0 for background)
    uint8_t shadowCount = 0;  // lights in shadow at the hit
    uint8_t textured = 0;     // a texture shades the hit
};

// Subpixel q (0 upper-left, 1 upper-right, 2 lower-left, 3 lower-right) of a pixel is compared with the
// three neighbouring pixels towards its corner (paper 004, Fig. 4): the upper-left with W, NW, N.
// Offsets (dx, dy) of neighbour k (0..2), y down.
TESSERA_HD void subpixelNeighbour(int q, int k, int& dx, int& dy) {
    const int sx = (q & 1) ? 1 : -1, sy = (q & 2) ? 1 : -1;
    dx = k == 2 ? 0 : sx;  // k: 0 the horizontal, 1 the diagonal, 2 the vertical neighbour
    dy = k == 0 ? 0 : sy;
}

// Mitchell's contrast (I_max - I_min) / (I_max + I_min) of two values (0 where both are 0).
TESSERA_HD float mitchellContrast(float a, float b) {
    const float hi = a > b ? a : b, lo = a > b ? b : a, sum = hi + lo;
    return sum > 0.f ? (hi - lo) / sum : 0.f;
}

// Step 2 (paper 004, sec. 4.2.2): any channel's contrast at least (1.36, 1.02, 2.04) x tau. ">=" so that
// tau = 0 always refines, as the paper states; a contrast never exceeds 1, so tau >= 1 never refines.
TESSERA_HD bool contrastExceeds(Color a, Color b, float tau) {
    return mitchellContrast(a.x, b.x) >= 1.36f * tau || mitchellContrast(a.y, b.y) >= 1.02f * tau ||
           mitchellContrast(a.z, b.z) >= 2.04f * tau;
}

// Step 1: the threshold of a subpixel of pixel `c` with neighbours n[0..2]: the smallest threshold of the
// attributes that disagree with at least one neighbour (the "pessimistic" test), else tau_col. The texture
// flag disagrees whenever the subpixel's own pixel is textured.
TESSERA_HD float subpixelThreshold(const AdaptiveThresholds& t, const PresampleAttributes& c,
                                   const PresampleAttributes* const n[3]) {
    bool object = false, normal = false, shadow = false;
    for (int k = 0; k < 3; ++k) {
        object |= n[k]->object != c.object;
        // Normals compare where both pixels see a surface (background has normal 0; object covers it).
        const bool surfaces = dot(c.normal, c.normal) > 0.f && dot(n[k]->normal, n[k]->normal) > 0.f;
        normal |= surfaces && dot(n[k]->normal, c.normal) < t.normalCosine;
        shadow |= n[k]->shadowCount != c.shadowCount;
    }
    const float texture = t.texture < 0.f ? t.color : t.texture;
    float tau = 2.f;  // above every threshold: "no attribute disagrees"
    if (object && t.objectId < tau) tau = t.objectId;
    if (normal && t.normal < tau) tau = t.normal;
    if (shadow && t.shadow < tau) tau = t.shadow;
    if (c.textured && texture < tau) tau = texture;
    return tau < 2.f ? tau : t.color;
}

// The whole test of subpixel q: step 1 picks the threshold, step 2 compares the colour reference with each
// of the three neighbours ("at least one colour disparity" marks it active).
TESSERA_HD bool subpixelActive(const AdaptiveThresholds& t, const PresampleAttributes& c,
                               const PresampleAttributes* const n[3]) {
    const float tau = subpixelThreshold(t, c, n);
    for (int k = 0; k < 3; ++k)
        if (contrastExceeds(c.color, n[k]->color, tau)) return true;
    return false;
}

}  // namespace tessera
