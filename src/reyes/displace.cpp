#include "reyes/displace.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <map>

namespace tessera {
namespace {

const Vec2 kCornerUV[4] = {{0, 0}, {1, 0}, {0, 1}, {1, 1}};
int cornerIndex(Vec2 uv) {
    return (uv.x > 0.5f ? 1 : 0) + (uv.y > 0.5f ? 2 : 0);
}

// Unit geometric normal (unoriented) at (u,v), with the pole limit at collapsed edges (as grid.cpp).
Vec3 unitNormal(const BezierPatch& patch, const SurfacePoint& sp, float u, float v) {
    Vec3 N = cross(sp.dpdu, sp.dpdv);
    const float scale = dot(sp.dpdu, sp.dpdu) + dot(sp.dpdv, sp.dpdv);
    if (!(dot(N, N) > 1e-12f * scale * scale)) N = patchNormal(patch, u, v);
    return normalize(N);
}

// The shader's amplitude at (u,v) of a displaced patch and its derivatives d/du, d/dv.
float amplitude(const ReyesView& view, const DisplacementFrame& frame, uint32_t patch, Vec2 uv,
                const SurfacePoint& sp, float* du = nullptr, float* dv = nullptr) {
    const DisplacementShader& d = frame.scene->displacements[size_t(frame.shader[patch])];
    if (du) *du = 0.f;
    if (dv) *dv = 0.f;
    if (d.type == DisplacementType::Offset) return d.Km;
    if (d.texture < 0 || !frame.textures) return 0.f;  // RI bumpy without a texture does not move
    const PatchTexCoords tc = texCoordsOf(*frame.scene, patch);
    Vec2 dstdu, dstdv;
    texCoordDerivs(tc, uv.x, uv.y, dstdu, dstdv);
    const TextureLookup q =
        textureLookup(view.projector, sp.p, sp.dpdu, sp.dpdv, texCoordsAt(tc, uv.x, uv.y), dstdu, dstdv);
    float dds = 0, ddt = 0;
    const float value = frame.textures->value(uint32_t(d.texture), q, dds, ddt);
    if (du) *du = d.Km * (dds * dstdu.x + ddt * dstdu.y);
    if (dv) *dv = d.Km * (dds * dstdv.x + ddt * dstdv.y);
    return d.Km * value;
}

// One patch's contribution to a shared point: its oriented unit normal and amplitude at its own (u,v).
void accumulate(const ReyesView& view, const DisplacementFrame& frame, uint32_t patch, Vec2 uv, Vec3& nSum,
                float& dSum, int& count) {
    const BezierPatch& bp = view.patches[patch];
    const SurfacePoint sp = evalPatchDeriv(bp, uv.x, uv.y);
    Vec3 n = unitNormal(bp, sp, uv.x, uv.y);
    if (frame.scene->attributes[patch].flipNormal) n = -n;
    nSum += n;
    dSum += amplitude(view, frame, patch, uv, sp);
    ++count;
}

bool degenerateEdge(const BezierPatch& patch, int e) {
    Vec3 c[4];
    patchEdge(patch, e, c);
    return c[0] == c[1] && c[1] == c[2] && c[2] == c[3];
}

}  // namespace

DisplacementFrame makeDisplacementFrame(const Scene& scene, const Textures* textures,
                                        std::span<const BezierPatch> patches, float cameraStretch) {
    DisplacementFrame f;
    bool any = false;
    for (const PatchAttributes& a : scene.attributes)
        any = any || (a.displacement >= 0 && a.kind == SurfaceKind::BicubicBezier);
    if (!any) return f;
    f.scene = &scene;
    f.textures = textures;
    const size_t n = patches.size();
    f.shader.assign(n, -1);
    f.radius.assign(n, 0.f);
    for (size_t i = 0; i < n && i < scene.attributes.size(); ++i) {
        const PatchAttributes& a = scene.attributes[i];
        // Bicubic patches only: quadrics are not displaced yet (docs/textures.md).
        if (a.displacement < 0 || size_t(a.displacement) >= scene.displacements.size() ||
            a.kind != SurfaceKind::BicubicBezier)
            continue;
        f.shader[i] = a.displacement;
        const DisplacementShader& d = scene.displacements[size_t(a.displacement)];
        // The shader's own bound: |Km| times the largest |value| of the texture (filtered lookups are
        // convex combinations of texels, so they stay in the texture's range).
        float derived = 0.f;
        if (d.type == DisplacementType::Offset) {
            derived = std::fabs(d.Km);
        } else if (d.texture >= 0 && textures) {
            float lo, hi;
            textures->range(uint32_t(d.texture), lo, hi);
            derived = std::fabs(d.Km) * std::max(std::fabs(lo), std::fabs(hi));
        }
        // A given displacementbound is honoured as a minimum; the exact bound of the built-in shaders is
        // used where it is larger, so a too-small bound never clips the surface.
        f.radius[i] = std::max(derived, a.displacementBound * cameraStretch) * 1.0001f;
    }
    // Shared points among displaced patches, keyed by their exact bits (welded: bit-identical).
    using CornerKey = std::array<uint32_t, 3>;
    auto bits = [](Vec3 p) {
        CornerKey k;
        std::memcpy(k.data(), &p, sizeof(Vec3));
        return k;
    };
    std::map<CornerKey, std::vector<uint32_t>> corners;
    std::map<std::array<uint32_t, 12>, std::vector<uint32_t>> edges;
    for (uint32_t i = 0; i < n; ++i) {
        if (f.shader[i] < 0) continue;
        const BezierPatch& p = patches[i];
        const Vec3 c[4] = {p.at(0, 0), p.at(3, 0), p.at(0, 3), p.at(3, 3)};
        for (int k = 0; k < 4; ++k) corners[bits(c[k])].push_back(i * 4 + uint32_t(k));
        for (int e = 0; e < 4; ++e) {
            if (degenerateEdge(p, e)) continue;
            Vec3 cp[4];
            Vec2 a, b;
            canonicalBoundary(p, e, cp, a, b);
            std::array<uint32_t, 12> key;
            std::memcpy(key.data(), cp, sizeof(cp));
            edges[key].push_back(i * 4 + uint32_t(e));
        }
    }
    f.cornerGroup.assign(n * 4, -1);
    f.groupStart.push_back(0);
    for (const auto& [key, members] : corners) {
        if (members.size() < 2) continue;
        const int32_t g = int32_t(f.groupStart.size() - 1);
        for (uint32_t m : members) {
            f.cornerGroup[m] = g;
            f.groupMembers.push_back(m);
        }
        f.groupStart.push_back(uint32_t(f.groupMembers.size()));
    }
    f.edgeNeighbour.assign(n * 4, -1);
    for (const auto& [key, members] : edges)
        if (members.size() == 2) {
            f.edgeNeighbour[members[0]] = int32_t(members[1]);
            f.edgeNeighbour[members[1]] = int32_t(members[0]);
        }
    return f;
}

float displacementAmplitude(const ReyesView& view, const DisplacementFrame& frame, uint32_t patch, Vec2 uv,
                            const SurfacePoint& sp) {
    return amplitude(view, frame, patch, uv, sp);
}

DisplacedVertex displaceVertex(const ReyesView& view, const DisplacementFrame& frame, uint32_t patch,
                               const PieceEdge* owner, int k, Vec2 uv, Vec3 P, bool flip, bool normal) {
    const BezierPatch& bp = view.patches[patch];
    // The canonical direction and amplitude of the point (see displace.h).
    Vec3 nSum;
    float dSum = 0.f;
    int count = 0;
    if (owner && owner->boundary >= 0) {
        const bool degenerate = degenerateEdge(bp, owner->boundary);
        const float w = owner->param(k);  // on the source edge: exactly 0 and 1 at its corners
        if (degenerate || w == 0.f || w == 1.f) {
            const Vec2 cuv = (degenerate || w == 0.f) ? owner->a : owner->b;
            const int32_t g = frame.cornerGroup[size_t(patch) * 4 + size_t(cornerIndex(cuv))];
            if (g >= 0) {
                for (uint32_t m = frame.groupStart[size_t(g)]; m < frame.groupStart[size_t(g) + 1]; ++m) {
                    const uint32_t member = frame.groupMembers[m];
                    accumulate(view, frame, member / 4, kCornerUV[member % 4], nSum, dSum, count);
                }
            }
        } else {
            const int32_t nb = frame.edgeNeighbour[size_t(patch) * 4 + size_t(owner->boundary)];
            if (nb >= 0) {
                const uint32_t q = uint32_t(nb) / 4;
                Vec3 cp[4];
                Vec2 a, b;
                canonicalBoundary(view.patches[q], nb % 4, cp, a, b);
                const Vec2 uvq{a.x * (1.f - w) + b.x * w, a.y * (1.f - w) + b.y * w};
                // In patch (then edge) order, so both sides add the same two terms in the same order.
                const bool neighbourFirst =
                    q < patch || (q == patch && uint32_t(nb) % 4 < uint32_t(owner->boundary));
                if (neighbourFirst) accumulate(view, frame, q, uvq, nSum, dSum, count);
                accumulate(view, frame, patch, uv, nSum, dSum, count);
                if (!neighbourFirst) accumulate(view, frame, q, uvq, nSum, dSum, count);
            }
        }
    }
    // The patch's own normal and amplitude (with derivatives when the displaced normal is wanted). An
    // interior vertex (count 0 so far) uses them directly; shared points keep their canonical sums, whose
    // terms are all computed alike (no derivatives) on both sides.
    const SurfacePoint sp = evalPatchDeriv(bp, uv.x, uv.y);
    const Vec3 n = unitNormal(bp, sp, uv.x, uv.y);
    float du = 0, dv = 0;
    const float d = amplitude(view, frame, patch, uv, sp, normal ? &du : nullptr, normal ? &dv : nullptr);
    const Vec3 no = flip ? -n : n;  // oriented: RI's N, along which P moves
    if (count == 0) nSum = no, dSum = d, count = 1;
    DisplacedVertex out;
    if (!(dot(nSum, nSum) > 1e-12f)) {  // opposite orientations cancelled: the patch's own normal
        nSum = {};
        dSum = 0.f;
        count = 0;
        accumulate(view, frame, patch, uv, nSum, dSum, count);
    }
    out.P = P + normalize(nSum) * (dSum / float(std::max(count, 1)));
    if (!normal) return out;
    // dN/du and dN/dv of the unit normal, from the patch (central differences of the exact normal).
    auto normalAt = [&](float u, float v) {
        const SurfacePoint s = evalPatchDeriv(bp, u, v);
        return unitNormal(bp, s, u, v);
    };
    const float h = 1e-3f;
    const float u0 = std::max(0.f, uv.x - h), u1 = std::min(1.f, uv.x + h);
    const float v0 = std::max(0.f, uv.y - h), v1 = std::min(1.f, uv.y + h);
    const Vec3 nu = (normalAt(u1, uv.y) - normalAt(u0, uv.y)) * (1.f / (u1 - u0));
    const Vec3 nv = (normalAt(uv.x, v1) - normalAt(uv.x, v0)) * (1.f / (v1 - v0));
    const float s = flip ? -1.f : 1.f;
    const Vec3 Pu = sp.dpdu + no * du + nu * (s * d);
    const Vec3 Pv = sp.dpdv + no * dv + nv * (s * d);
    Vec3 N = cross(Pu, Pv);
    const float scale = dot(Pu, Pu) + dot(Pv, Pv);
    N = dot(N, N) > 1e-12f * scale * scale ? normalize(N) : n;
    out.N = flip ? -N : N;
    return out;
}

}  // namespace tessera
