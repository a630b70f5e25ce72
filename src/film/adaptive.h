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
    // The same four for the one-bounce secondary hit (the first reflection or refraction hit of the
    // presample ray; paper 004, L141 and Table 1), defaults as the primary ones (the paper's L286).
    float secondaryObjectId = 0.05f;  // tau_soid
    float secondaryNormal = 0.06f;    // tau_ssn
    float secondaryShadow = 0.06f;    // tau_ssc
    float secondaryTexture = -1.f;    // tau_ste; < 0: the colour threshold
    // Normals "differ if their cross product is less than a preset value" (paper 004, L147; read as the
    // dot product, the cutoff is not given): here when their cosine is below this (about 18 degrees).
    float normalCosine = 0.95f;
};

// The geometry attributes of one hit (paper 004's GeometryAttributeMap entry).
struct HitAttributes {
    uint32_t object = 0;      // RI object (per attribute block or name, not per patch); kNoObject: no hit
    Vec3 normal;              // shading normal facing the viewer (0 where nothing was hit)
    uint8_t shadowCount = 0;  // lights in shadow at the hit
    uint8_t textured = 0;     // a texture shades the hit
};

// What the presample ray of a pixel saw (the geometry attribute map plus the colour reference): its primary
// hit's attributes and, where the surface reflects or refracts, those of the first secondary hit (no
// secondary ray: object kNoObject and normal 0 on both sides of a comparison, so they agree).
struct PresampleAttributes : HitAttributes {
    Color color;  // premultiplied, the colour reference
    HitAttributes secondary;
    // Motion blur and depth of field (our extension; the paper has neither): the presample hit a surface
    // that moves over the shutter or lies out of focus (circle of confusion over half a pixel). Its pixel
    // integrates over time or the lens, of which the one presample is a single point: not a reference.
    uint8_t blurred = 0;
};

// Which attributes disagree between a pixel's hit `c` and its neighbours' n[0..2].
struct AttributeDisagreement {
    bool object = false, normal = false, shadow = false;
};
TESSERA_HD AttributeDisagreement attributesDisagree(const AdaptiveThresholds& t, const HitAttributes& c,
                                                    const HitAttributes* const n[3]) {
    AttributeDisagreement d;
    for (int k = 0; k < 3; ++k) {
        d.object |= n[k]->object != c.object;
        // Normals compare where both pixels see a surface (background has normal 0; object covers it).
        const bool surfaces = dot(c.normal, c.normal) > 0.f && dot(n[k]->normal, n[k]->normal) > 0.f;
        d.normal |= surfaces && dot(n[k]->normal, c.normal) < t.normalCosine;
        d.shadow |= n[k]->shadowCount != c.shadowCount;
    }
    return d;
}

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
// attributes, primary and secondary, that disagree with at least one neighbour (the "pessimistic" test),
// else tau_col. The texture flag disagrees whenever the subpixel's own pixel is textured. `attributesCount`
// false: only the colour decides (the paper's "fairy focused" mode outside the focus objects, L209).
TESSERA_HD float subpixelThreshold(const AdaptiveThresholds& t, const PresampleAttributes& c,
                                   const PresampleAttributes* const n[3], bool attributesCount = true) {
    if (!attributesCount) return t.color;
    const HitAttributes* np[3] = {n[0], n[1], n[2]};
    const HitAttributes* ns[3] = {&n[0]->secondary, &n[1]->secondary, &n[2]->secondary};
    const AttributeDisagreement p = attributesDisagree(t, c, np), q = attributesDisagree(t, c.secondary, ns);
    const float texture = t.texture < 0.f ? t.color : t.texture;
    const float secondaryTexture = t.secondaryTexture < 0.f ? t.color : t.secondaryTexture;
    float tau = 2.f;  // above every threshold: "no attribute disagrees"
    auto consider = [&tau](bool disagrees, float threshold) {
        if (disagrees && threshold < tau) tau = threshold;
    };
    consider(p.object, t.objectId);
    consider(p.normal, t.normal);
    consider(p.shadow, t.shadow);
    consider(c.textured, texture);
    consider(q.object, t.secondaryObjectId);
    consider(q.normal, t.secondaryNormal);
    consider(q.shadow, t.secondaryShadow);
    consider(c.secondary.textured, secondaryTexture);
    return tau < 2.f ? tau : t.color;
}

// The whole test of subpixel q: step 1 picks the threshold, step 2 compares the colour reference with each
// of the three neighbours ("at least one colour disparity" marks it active).
TESSERA_HD bool subpixelActive(const AdaptiveThresholds& t, const PresampleAttributes& c,
                               const PresampleAttributes* const n[3], bool attributesCount = true) {
    // A blurred presample on either side: the colours compared would be single points of integrals, so
    // the subpixel refines, unless the colour threshold is at its maximum (nothing refines).
    if ((c.blurred || n[0]->blurred || n[1]->blurred || n[2]->blurred) && t.color < 1.f) return true;
    const float tau = subpixelThreshold(t, c, n, attributesCount);
    for (int k = 0; k < 3; ++k)
        if (contrastExceeds(c.color, n[k]->color, tau)) return true;
    return false;
}

// The paper's option for inactive subpixels (L215): instead of the pixel's centre colour, the bilinear
// interpolation of the presample colours at the subpixel's centre, a quarter pixel from the pixel centre
// towards its corner: 9/16 of the pixel, 3/16 of the horizontal and of the vertical neighbour towards the
// corner and 1/16 of the diagonal one (n[0..2] in subpixelNeighbour's order).
template <class T>
TESSERA_HD T interpolatedSubpixel(T c, T horizontal, T diagonal, T vertical) {
    return c * (9.f / 16.f) + (horizontal + vertical) * (3.f / 16.f) + diagonal * (1.f / 16.f);
}

}  // namespace tessera
