#include "reyes/split.h"

#include <algorithm>
#include <cmath>

#include "reyes/displace.h"
#include "scene/scene.h"

namespace tessera {
namespace {

constexpr int32_t kMaxEdgeRate = 1 << 20;  // cap for edges that reach towards the eye plane
constexpr int kMaxSplitDepth = 40;
constexpr int kRateSamples = 8;
// Lattice of a collapsed edge: a power of two, so that halving cuts stay on it for 16 levels.
constexpr int32_t kCollapsedLattice = 1 << 16;
// A source edge shorter than this on screen is one point for splitting (no visible crack can open).
constexpr float kCollapsedPixels = 1e-3f;

bool lexLess(Vec3 p, Vec3 q) {
    if (p.x != q.x) return p.x < q.x;
    if (p.y != q.y) return p.y < q.y;
    return p.z < q.z;
}

// Raster position used only to measure lengths; points nearer than the view's length plane (the near
// plane unless the view sets one further out) are pulled onto it.
Vec3 rasterForLength(const ReyesView& view, Vec3 p) {
    p.z = std::max(p.z, std::max(view.projector.nearClip, view.lengthNearZ));
    return view.projector.toRaster(p);
}

int32_t rateFromLength(float pixels, float side) {
    float t = std::ceil(pixels / side);
    if (!(t >= 1.f)) return 1;
    return t > float(kMaxEdgeRate) ? kMaxEdgeRate : int32_t(t);
}

// Projected polyline length of a source edge, in pixels.
template <class PointAt>
float measureLength(const ReyesView& view, PointAt&& pointAt) {
    float len = 0;
    Vec3 prev = rasterForLength(view, pointAt(0.f));
    for (int i = 1; i <= kRateSamples; ++i) {
        Vec3 cur = rasterForLength(view, pointAt(float(i) / kRateSamples));
        float dx = cur.x - prev.x, dy = cur.y - prev.y;
        len += std::sqrt(dx * dx + dy * dy);
        prev = cur;
    }
    return len;
}

// Lattice of a source edge of projected length `pixels`.
void setEdgeLattice(PieceEdge& edge, float pixels, float side) {
    edge.collapsed = pixels < kCollapsedPixels;
    edge.total = edge.collapsed ? kCollapsedLattice : rateFromLength(pixels, side);
    edge.k0 = 0;
    edge.k1 = edge.total;
}

// Edge lengths of surfaces that are not displaced: as measured.
struct NoDisplacement {
    template <class PointAt>
    float operator()(float pixels, int, Vec2, Vec2, float, float, PointAt&&, float) const {
        return pixels;
    }
};

// Displacement-aware splitting (paper 001 sec. 3.1). A displaced patch's edge is measured as at least
// n micropolygon sides long, n the segments that keep each segment's projected displacement variation
// (edge-width: max - min of Km * texture over the segment, from the min/max mip map at the level of its
// texel extent) within view.displacementSplit sides: the part of the edge is halved while its variation
// is larger, at most kMaxDisplacementSplitDepth times and not below one texel (the finest entry). The
// existing criterion (ceil(length / side) segments, split above maxGridEdge) then does the rest, so the
// threshold is folded into it. A patch boundary takes the larger variation of the two displaced patches
// that share it, each in its own s, t, in the edge's canonical parameter: both sides measure the same
// (crack-free), and the shared points move by their mean, whose variation is no larger.
struct EdgeDisplacement {
    const ReyesView& view;
    uint32_t patch;

    // Variation (camera-space units) of patch q's displacement over its (u,v) segment p0 -> p1, and the
    // segment's largest extent in texels.
    float variation(uint32_t q, Vec2 p0, Vec2 p1, float& texels) const {
        const DisplacementFrame& f = *view.displacement;
        texels = 0.f;
        if (!f.displaced(q) || !f.textures) return 0.f;
        const DisplacementShader& d = f.scene->displacements[size_t(f.shader[q])];
        if (d.type != DisplacementType::Bumpy || d.texture < 0) return 0.f;  // offset: constant
        const MinMaxMip& mip = f.textures->minMaxMip(uint32_t(d.texture));
        if (mip.empty()) return 0.f;
        // s, t is bilinear in (u,v): over the segment's (u,v) rectangle its extremes are at the corners.
        const PatchTexCoords tc = texCoordsOf(*f.scene, q);
        const float u0 = std::min(p0.x, p1.x), u1 = std::max(p0.x, p1.x);
        const float v0 = std::min(p0.y, p1.y), v1 = std::max(p0.y, p1.y);
        float s0 = 1e30f, s1 = -1e30f, t0 = 1e30f, t1 = -1e30f;
        for (const Vec2 uv : {Vec2{u0, v0}, Vec2{u1, v0}, Vec2{u0, v1}, Vec2{u1, v1}}) {
            const Vec2 st = texCoordsAt(tc, uv.x, uv.y);
            s0 = std::min(s0, st.x), s1 = std::max(s1, st.x), t0 = std::min(t0, st.y),
            t1 = std::max(t1, st.y);
        }
        texels = std::max((s1 - s0) * float(mip.width()), (t1 - t0) * float(mip.height()));
        float lo, hi;
        if (!minMaxInST(mip, s0, s1, t0, t1, lo, hi)) return 0.f;
        return std::fabs(d.Km) * (hi - lo);
    }

    // Segments part [s0, s1] of a source edge (patch boundary `boundary`, or -1: an interior line of this
    // patch) from (u,v) a (s = 0) to b needs; pointAt(s) its camera-space point.
    template <class PointAt>
    int segments(int boundary, Vec2 a, Vec2 b, float s0, float s1, PointAt&& pointAt, int depth,
                 float side) const {
        const DisplacementFrame& f = *view.displacement;
        auto uvAt = [](Vec2 p, Vec2 q, float s) {
            return Vec2{p.x * (1.f - s) + q.x * s, p.y * (1.f - s) + q.y * s};
        };
        float texels = 0.f;
        float dv = variation(patch, uvAt(a, b, s0), uvAt(a, b, s1), texels);
        float radius = f.radius[patch];
        if (boundary >= 0) {
            const int32_t nb = f.edgeNeighbour[size_t(patch) * 4 + size_t(boundary)];
            if (nb >= 0) {
                Vec3 cp[4];
                Vec2 qa, qb;
                canonicalBoundary(view.patches[uint32_t(nb) / 4], nb % 4, cp, qa, qb);
                float qt = 0.f;
                dv = std::max(dv, variation(uint32_t(nb) / 4, uvAt(qa, qb, s0), uvAt(qa, qb, s1), qt));
                texels = std::max(texels, qt);
                radius = std::max(radius, f.radius[uint32_t(nb) / 4]);
            }
        }
        if (!(dv > 0.f)) return 1;
        // Camera-space units to pixels at the segment's nearest depth (less the displacement radius).
        const Projector& pr = view.projector;
        float perUnit = std::max(std::fabs(pr.sx), std::fabs(pr.sy));
        if (pr.perspective) {
            float z = std::min({pointAt(s0).z, pointAt(0.5f * (s0 + s1)).z, pointAt(s1).z});
            z -= radius;
            perUnit /= std::max(z, std::max(pr.nearClip, view.lengthNearZ));
        }
        if (dv * perUnit <= view.displacementSplit * side || depth >= kMaxDisplacementSplitDepth ||
            texels <= 1.f)
            return 1;
        const float sm = 0.5f * (s0 + s1);
        return segments(boundary, a, b, s0, sm, pointAt, depth + 1, side) +
               segments(boundary, a, b, sm, s1, pointAt, depth + 1, side);
    }

    // The length of part [s0, s1] (pixels, as measured) raised to the segments its displacement needs.
    // `edgeSide`: the micropolygon side the edge is measured with (PieceEdge::side, else the patch's).
    template <class PointAt>
    float operator()(float pixels, int boundary, Vec2 a, Vec2 b, float s0, float s1, PointAt&& pointAt,
                     float edgeSide) const {
        if (pixels < kCollapsedPixels) return pixels;  // one point: nothing to split
        const float side = edgeSide;
        const int n = segments(boundary, a, b, s0, s1, pointAt, 0, side);
        // ceil(0.999 n) = n: the lattice then has at least n segments.
        return n > 1 ? std::max(pixels, 0.999f * float(n) * side) : pixels;
    }
};

template <class Displaced>
PieceEdge boundaryEdge(const ReyesView& view, const BezierPatch& patch, int e, float side,
                       const Displaced& displaced) {
    PieceEdge edge;
    Vec3 cp[4];
    canonicalBoundary(patch, e, cp, edge.a, edge.b);
    edge.boundary = int8_t(e);
    auto curveAt = [&](float t) { return evalCurve(cp, t); };
    edge.side = side;
    setEdgeLattice(edge, displaced(measureLength(view, curveAt), e, edge.a, edge.b, 0.f, 1.f, curveAt, side),
                   side);
    // The piece walks every edge in increasing parameter; reversed if the canonical start is the far end.
    static const Vec2 kStart[4] = {{0, 0}, {1, 0}, {0, 1}, {0, 0}};
    edge.reversed = !(edge.a.x == kStart[e].x && edge.a.y == kStart[e].y);
    return edge;
}

// Boundary edge e of a quadric's (u,v) square: canonical endpoints by position as for the patches, so
// the two sides of a closed sweep's seam (u = 0 and u = 1; a closed torus' v = 0 and v = 1) evaluate the
// same lattice points (quadricPhi evaluates u = 1 there as u = 0).
PieceEdge quadricBoundaryEdge(const ReyesView& view, const PlacedQuadric& pq, int e, float side) {
    static const Vec2 kStart[4] = {{0, 0}, {1, 0}, {0, 1}, {0, 0}};
    static const Vec2 kEnd[4] = {{1, 0}, {1, 1}, {1, 1}, {0, 1}};
    PieceEdge edge;
    const Vec3 p0 = quadricPoint(pq, kStart[e]), p1 = quadricPoint(pq, kEnd[e]);
    // Endpoints at one point (a closed sweep's edge): the midpoints decide, so both seam sides agree.
    const Vec3 m = quadricPoint(pq, {0.5f * (kStart[e].x + kEnd[e].x), 0.5f * (kStart[e].y + kEnd[e].y)});
    const Vec3 q1 =
        quadricPoint(pq, {0.75f * kStart[e].x + 0.25f * kEnd[e].x, 0.75f * kStart[e].y + 0.25f * kEnd[e].y});
    const bool reverse = lexLess(p1, p0) || (p1 == p0 && lexLess(m, q1));
    edge.a = reverse ? kEnd[e] : kStart[e];
    edge.b = reverse ? kStart[e] : kEnd[e];
    edge.boundary = int8_t(e);
    edge.reversed = reverse;
    setEdgeLattice(edge,
                   measureLength(view,
                                 [&](float t) {
                                     return quadricPoint(pq, {edge.a.x * (1.f - t) + edge.b.x * t,
                                                              edge.a.y * (1.f - t) + edge.b.y * t});
                                 }),
                   side);
    return edge;
}

// The (u,v) at parameter s of an edge's source line, from canonical endpoint a (s = 0) to b (s = 1).
Vec2 lerpUV(const PieceEdge& e, float s) {
    return {e.a.x * (1.f - s) + e.b.x * s, e.a.y * (1.f - s) + e.b.y * s};
}

// A new interior source edge from (u,v) point p to q, walked p -> q by the piece that owns it.
template <class PointAt, class Displaced>
PieceEdge interiorEdge(const ReyesView& view, PointAt&& surfaceAt, Vec2 p, Vec2 q, float side,
                       const Displaced& displaced) {
    PieceEdge edge;
    bool swap = (q.x < p.x) || (q.x == p.x && q.y < p.y);
    edge.a = swap ? q : p;
    edge.b = swap ? p : q;
    edge.reversed = swap;
    edge.boundary = -1;
    auto lineAt = [&](float t) {
        return surfaceAt(Vec2{edge.a.x * (1.f - t) + edge.b.x * t, edge.a.y * (1.f - t) + edge.b.y * t});
    };
    setEdgeLattice(edge, displaced(measureLength(view, lineAt), -1, edge.a, edge.b, 0.f, 1.f, lineAt, side),
                   side);
    return edge;
}

// The segments of a piece's middle u and v isolines (straight lines of its bilinear (u,v) quad).
template <class PointAt, class Displaced>
void measureInterior(const ReyesView& view, PointAt&& surfaceAt, Piece& piece, float side,
                     const Displaced& displaced) {
    auto lerp = [](Vec2 p, Vec2 q, float t) { return Vec2{p.x + (q.x - p.x) * t, p.y + (q.y - p.y) * t}; };
    auto isoline = [&](Vec2 p, Vec2 q) {
        auto lineAt = [&](float t) { return surfaceAt(lerp(p, q, t)); };
        return rateFromLength(displaced(measureLength(view, lineAt), -1, p, q, 0.f, 1.f, lineAt, side), side);
    };
    const Vec2* c = piece.uv;
    piece.interiorU = isoline(lerp(c[0], c[3], 0.5f), lerp(c[1], c[2], 0.5f));
    piece.interiorV = isoline(lerp(c[0], c[1], 0.5f), lerp(c[3], c[2], 0.5f));
}

// Cut edge e at its lattice midpoint: `first` runs from the piece's start to the cut, `second` onwards.
// An odd count rounds down, or up with roundUp: the piece's two opposite edges round opposite ways, so
// that a piece with one segment on each is cut along its diagonal into two triangles.
void cutEdge(const PieceEdge& e, bool roundUp, int& cutK, PieceEdge& first, PieceEdge& second) {
    int half = (e.segments() + (roundUp ? 1 : 0)) / 2;
    cutK = e.reversed ? e.k1 - half : e.k0 + half;
    first = second = e;
    if (!e.reversed) {
        first.k1 = cutK;
        second.k0 = cutK;
    } else {
        first.k0 = cutK;
        second.k1 = cutK;
    }
}

enum class Verdict { Cull, Split, SplitNear, Dice };

// Raster rectangle of the projected control points of a hull lying in front of the eye.
void hullRaster(const Projector& pr, const Vec3* hull, int count, float& x0, float& y0, float& x1,
                float& y1) {
    x0 = 1e30f, y0 = 1e30f, x1 = -1e30f, y1 = -1e30f;
    for (int i = 0; i < count; ++i) {
        Vec3 r = pr.toRaster(hull[i]);
        x0 = std::min(x0, r.x), x1 = std::max(x1, r.x);
        y0 = std::min(y0, r.y), y1 = std::max(y1, r.y);
    }
}

// The piece's (u,v) bounding rectangle's hull at knot k, into pts (at most 16 points); returns the count.
struct PieceHull {
    const ReyesView& view;
    const BezierPatch* patch = nullptr;      // bicubic Bezier
    const PlacedQuadric* quadric = nullptr;  // quadric kinds (camera space)
    int operator()(int k, uint32_t index, float u0, float u1, float v0, float v1, Vec3 pts[16]) const {
        if (quadric) {
            quadricHullCorners(*quadric, u0, u1, v0, v1, pts);
            return 8;
        }
        const bool whole = u0 == 0.f && u1 == 1.f && v0 == 0.f && v1 == 1.f;
        const BezierPatch& source = k == 0 ? *patch : view.knotPatches[k][index];
        const BezierPatch hull = whole ? source : subPatch(source, u0, u1, v0, v1);
        for (int i = 0; i < 16; ++i) pts[i] = hull.cp[i];
        return 16;
    }
};

Verdict classify(const ReyesView& view, const PieceHull& hullOf, Piece& piece) {
    float u0 = std::min(std::min(piece.uv[0].x, piece.uv[1].x), std::min(piece.uv[2].x, piece.uv[3].x));
    float u1 = std::max(std::max(piece.uv[0].x, piece.uv[1].x), std::max(piece.uv[2].x, piece.uv[3].x));
    float v0 = std::min(std::min(piece.uv[0].y, piece.uv[1].y), std::min(piece.uv[2].y, piece.uv[3].y));
    float v1 = std::max(std::max(piece.uv[0].y, piece.uv[1].y), std::max(piece.uv[2].y, piece.uv[3].y));
    const Projector& pr = view.projector;
    // The quad lies inside its (u,v) bounding rectangle, whose control hull bounds the surface. A moving
    // patch is bounded at every knot of the shutter: between knots its control points move linearly, so
    // the hulls at the knots bound it at all times (and a straight camera-space path projects to a
    // straight raster path).
    const int knots = view.patchMoves(piece.patch) ? view.knotCount() : 1;
    // The view's four side planes through the eye (perspective, pinhole): a hull wholly outside one of
    // them at every knot is out of view even where it reaches behind the eye, which the raster bound
    // cannot tell (a sky sphere around the camera would otherwise be split at the eye plane for ever).
    const bool sidePlanes = pr.perspective && !view.lens;
    float slope[4] = {0, 0, 0, 0};  // x/z and y/z of the cull window's edges: x0, x1, y0, y1
    if (sidePlanes) {
        const float ax = (view.cullX0 - pr.ox) / pr.sx, bx = (view.cullX1 - pr.ox) / pr.sx;
        const float ay = (view.cullY0 - pr.oy) / pr.sy, by = (view.cullY1 - pr.oy) / pr.sy;
        slope[0] = std::min(ax, bx), slope[1] = std::max(ax, bx);
        slope[2] = std::min(ay, by), slope[3] = std::max(ay, by);
    }
    unsigned outsideAll = sidePlanes ? 0xfu : 0u;  // side planes that every knot's hull lies beyond
    bool anyInRange = false, straddles = false;
    float x0 = 1e30f, y0 = 1e30f, x1 = -1e30f, y1 = -1e30f;
    float sharpW = 0, sharpH = 0;
    for (int k = 0; k < knots; ++k) {
        Vec3 hull[16];
        const int count = hullOf(k, piece.patch, u0, u1, v0, v1, hull);
        Bounds3 b;
        for (int i = 0; i < count; ++i) b.extend(hull[i]);
        // Displacement moves points at most `grow` from the surface (reyes/displace.h): the hull's box grown
        // by it bounds the displaced piece.
        const float grow = view.displacement && view.displacement->displaced(piece.patch)
                               ? view.displacement->radius[piece.patch]
                               : 0.f;
        if (grow > 0.f) outsideAll = 0;  // displaced: the hull alone does not bound it
        if (outsideAll) {
            unsigned out = 0xfu;
            for (int i = 0; i < count && out; ++i) {
                const Vec3& q = hull[i];
                out &= (q.x < slope[0] * q.z ? 1u : 0u) | (q.x > slope[1] * q.z ? 2u : 0u) |
                       (q.y < slope[2] * q.z ? 4u : 0u) | (q.y > slope[3] * q.z ? 8u : 0u);
            }
            outsideAll &= out;
        }
        if (grow > 0.f) {
            b.lo = b.lo - Vec3{grow, grow, grow};
            b.hi = b.hi + Vec3{grow, grow, grow};
        }
        if (!(b.hi.z >= pr.nearClip) || !(b.lo.z <= pr.farClip)) continue;
        anyInRange = true;
        if (b.lo.z < pr.nearClip) {
            straddles = true;
            continue;
        }
        float kx0, ky0, kx1, ky1;
        if (grow > 0.f)
            pr.rasterBounds(b, kx0, kx1, ky0, ky1);
        else
            hullRaster(pr, hull, count, kx0, ky0, kx1, ky1);
        if (k == 0) sharpW = kx1 - kx0, sharpH = ky1 - ky0;
        if (view.lens) {
            // Grown by the circle of confusion of the hull's depth range (Projector::lensShift).
            const float c = pr.maxLensCoefficient(b.lo.z, b.hi.z);
            const float gx = c * std::abs(pr.sx), gy = c * std::abs(pr.sy);
            kx0 -= gx, kx1 += gx, ky0 -= gy, ky1 += gy;
        }
        x0 = std::min(x0, kx0), y0 = std::min(y0, ky0), x1 = std::max(x1, kx1), y1 = std::max(y1, ky1);
    }
    if (!view.cull) {  // nothing is culled: split by the rates alone
        int maxSeg = std::max(piece.interiorU, piece.interiorV);
        for (const PieceEdge& e : piece.edge) maxSeg = std::max(maxSeg, e.rate());
        return maxSeg > view.maxGridEdge ? Verdict::Split : Verdict::Dice;
    }
    if (!anyInRange || outsideAll) return Verdict::Cull;
    if (!straddles) {
        if (x1 < view.cullX0 || x0 > view.cullX1 || y1 < view.cullY0 || y0 > view.cullY1)
            return Verdict::Cull;
        piece.x0 = x0, piece.y0 = y0, piece.x1 = x1, piece.y1 = y1;
        piece.blurPixels = std::max(0.f, std::max((x1 - x0) - sharpW, (y1 - y0) - sharpH));
    }
    int maxSeg = std::max(piece.interiorU, piece.interiorV);
    for (const PieceEdge& e : piece.edge) maxSeg = std::max(maxSeg, e.rate());
    if (straddles) return Verdict::SplitNear;
    if (maxSeg > view.maxGridEdge) return Verdict::Split;
    return Verdict::Dice;
}

struct SplitJob {
    Piece piece;
    int depth;
};

}  // namespace

void canonicalBoundary(const BezierPatch& patch, int e, Vec3 cp[4], Vec2& a, Vec2& b) {
    static const Vec2 kStart[4] = {{0, 0}, {1, 0}, {0, 1}, {0, 0}};
    static const Vec2 kEnd[4] = {{1, 0}, {1, 1}, {1, 1}, {0, 1}};
    Vec3 c[4];
    patchEdge(patch, e, c);
    bool reverse = lexLess(c[3], c[0]) || (c[3] == c[0] && lexLess(c[2], c[1]));
    for (int i = 0; i < 4; ++i) cp[i] = reverse ? c[3 - i] : c[i];
    a = reverse ? kEnd[e] : kStart[e];
    b = reverse ? kStart[e] : kEnd[e];
}

void orientedBoundary(const BezierPatch& patch, const PieceEdge& e, Vec3 cp[4]) {
    static const Vec2 kStart[4] = {{0, 0}, {1, 0}, {0, 1}, {0, 0}};
    Vec3 c[4];
    patchEdge(patch, e.boundary, c);
    const bool natural = e.a.x == kStart[e.boundary].x && e.a.y == kStart[e.boundary].y;
    for (int i = 0; i < 4; ++i) cp[i] = natural ? c[i] : c[3 - i];
}

Vec3 latticePosition(const BezierPatch& patch, const PieceEdge& e, int k) {
    if (e.boundary >= 0) {
        Vec3 cp[4];
        Vec2 a, b;
        canonicalBoundary(patch, e.boundary, cp, a, b);
        return evalCurve(cp, e.param(k));
    }
    Vec2 uv = latticeUV(e, k);
    return evalPatch(patch, uv.x, uv.y);
}

namespace {

// Cut edge e for a split: an edge measured above the grid limit at the parametric middle of its
// interval, each half measured again by `measure(e, s0, s1)` (pixels); any other edge at its lattice
// middle (cutEdge). `first` runs from the piece's start corner to the cut. Returns the cut's (u,v).
template <class Measure>
Vec2 cutPieceEdge(const ReyesView& view, const PieceEdge& e, bool roundUp, float side, Measure&& measure,
                  PieceEdge& first, PieceEdge& second) {
    if (!e.collapsed && e.total > view.maxGridEdge && e.k0 == 0 && e.k1 == e.total) {
        const float sm = 0.5f * (e.s0 + e.s1);
        PieceEdge lower = e, upper = e;
        lower.s1 = sm, upper.s0 = sm;
        const float edgeSide = e.side > 0.f ? e.side : side;
        setEdgeLattice(lower, measure(e, e.s0, sm), edgeSide);
        setEdgeLattice(upper, measure(e, sm, e.s1), edgeSide);
        first = e.reversed ? upper : lower;
        second = e.reversed ? lower : upper;
        return latticeUV(lower, lower.total);  // = param sm exactly
    }
    int k;
    cutEdge(e, roundUp, k, first, second);
    return latticeUV(e, k);
}

// Split and cull one surface's (u,v) square into pieces: `root` has its boundary edges, `hullOf` bounds
// a rectangle of it, `surfaceAt` evaluates a point (for interior split lines), `measure(edge, s0, s1)`
// the projected length of part [s0, s1] of an edge's source curve, evaluated exactly as when the edge was
// made (so that pieces sharing it agree).
template <class SurfaceAt, class Measure, class Displaced>
void splitPieces(const ReyesView& view, const Piece& root, const PieceHull& hullOf, SurfaceAt&& surfaceAt,
                 Measure&& measure, const Displaced& displaced, float side, std::vector<Piece>& out,
                 SplitCounters& counters) {
    size_t before = out.size();
    std::vector<SplitJob> stack;
    stack.push_back({root, 0});
    while (!stack.empty()) {
        SplitJob job = stack.back();
        stack.pop_back();
        Piece& p = job.piece;
        measureInterior(view, surfaceAt, p, side, displaced);
        Verdict v = classify(view, hullOf, p);
        if (v == Verdict::Cull) {
            ++counters.culled;
            continue;
        }
        // Split across u (cutting e0 and e2) when that direction needs more segments, else across v; a
        // direction whose two edges hold fewer than two lattice segments between them cannot be cut.
        const int su = pieceGridU(p), sv = pieceGridV(p);
        const bool cutU = p.edge[0].segments() + p.edge[2].segments() >= 2;
        const bool cutV = p.edge[1].segments() + p.edge[3].segments() >= 2;
        const bool acrossU = cutU && (su >= sv || !cutV);
        if (v != Verdict::Dice && (job.depth >= kMaxSplitDepth || std::max(su, sv) <= 1 || !(cutU || cutV))) {
            // No further progress possible. A piece still crossing the eye plane is dropped (the RI
            // "eye split" rule); an oversized one is diced as it is.
            if (v == Verdict::SplitNear) {
                ++counters.culled;
                continue;
            }
            v = Verdict::Dice;
        }
        if (v == Verdict::Dice) {
            out.push_back(p);
            continue;
        }
        ++counters.splits;
        Piece lo = p, hi = p;
        if (acrossU) {
            const Vec2 m0 = cutPieceEdge(view, p.edge[0], false, side, measure, lo.edge[0], hi.edge[0]);
            const Vec2 m2 = cutPieceEdge(view, p.edge[2], true, side, measure, lo.edge[2], hi.edge[2]);
            PieceEdge mid = interiorEdge(view, surfaceAt, m0, m2, side, displaced);
            lo.uv[1] = m0, lo.uv[2] = m2, lo.edge[1] = mid;
            hi.uv[0] = m0, hi.uv[3] = m2, hi.edge[3] = mid;
        } else {
            const Vec2 m3 = cutPieceEdge(view, p.edge[3], false, side, measure, lo.edge[3], hi.edge[3]);
            const Vec2 m1 = cutPieceEdge(view, p.edge[1], true, side, measure, lo.edge[1], hi.edge[1]);
            PieceEdge mid = interiorEdge(view, surfaceAt, m3, m1, side, displaced);
            lo.uv[3] = m3, lo.uv[2] = m1, lo.edge[2] = mid;
            hi.uv[0] = m3, hi.uv[1] = m1, hi.edge[0] = mid;
        }
        // Push hi first so pieces come out in a fixed (depth-first, low-first) order.
        stack.push_back({hi, job.depth + 1});
        stack.push_back({lo, job.depth + 1});
    }
    counters.pieces += out.size() - before;
    counters.patchCulled = out.size() == before;
}

Piece rootPiece(uint32_t index) {
    Piece root;
    root.patch = index;
    root.uv[0] = {0, 0}, root.uv[1] = {1, 0}, root.uv[2] = {1, 1}, root.uv[3] = {0, 1};
    return root;
}

}  // namespace

namespace {

template <class Displaced>
void splitPatchWith(const ReyesView& view, uint32_t patchIndex, float side, const Displaced& displaced,
                    std::vector<Piece>& out, SplitCounters& counters) {
    const BezierPatch& patch = view.patches[patchIndex];
    Piece root = rootPiece(patchIndex);
    for (int e = 0; e < 4; ++e) {
        // A boundary shared with another displaced patch: the smaller of the two sides, which both compute
        // alike (unless a motion or focus factor coarsened this patch's side: then its own).
        float edgeSide = side;
        const DisplacementFrame* f = view.displacement;
        if (f && f->any() && view.patchSide && side == view.patchSide[patchIndex]) {
            const int32_t nb = f->edgeNeighbour[size_t(patchIndex) * 4 + size_t(e)];
            if (nb >= 0) edgeSide = std::min(side, view.patchSide[uint32_t(nb) / 4]);
        }
        root.edge[e] = boundaryEdge(view, patch, e, edgeSide, displaced);
    }
    const PieceHull hull{view, &patch, nullptr};
    auto surfaceAt = [&](Vec2 uv) { return evalPatch(patch, uv.x, uv.y); };
    // Part of an edge's source curve: a boundary through its canonical control points (as boundaryEdge
    // measured it, so the neighbouring patch measures the same), a split line through the patch.
    auto measure = [&](const PieceEdge& e, float s0, float s1) {
        if (e.boundary >= 0) {
            Vec3 cp[4];
            Vec2 a, b;
            canonicalBoundary(patch, e.boundary, cp, a, b);
            auto curveAt = [&](float s) { return evalCurve(cp, s); };
            return displaced(measureLength(view, [&](float t) { return curveAt(s0 + (s1 - s0) * t); }),
                             e.boundary, e.a, e.b, s0, s1, curveAt, e.side > 0.f ? e.side : side);
        }
        auto lineAt = [&](float s) { return surfaceAt(lerpUV(e, s)); };
        return displaced(measureLength(view, [&](float t) { return lineAt(s0 + (s1 - s0) * t); }), -1, e.a,
                         e.b, s0, s1, lineAt, side);
    };
    splitPieces(view, root, hull, surfaceAt, measure, displaced, side, out, counters);
}

}  // namespace

void splitPatch(const ReyesView& view, uint32_t patchIndex, float side, std::vector<Piece>& out,
                SplitCounters& counters) {
    const BezierPatch& patch = view.patches[patchIndex];
    counters.patchCulled = false;
    for (const Vec3& c : patch.cp)
        if (!isFinite(c)) {
            counters.patchCulled = true;
            ++counters.culled;
            return;
        }
    const bool displaced =
        view.displacementSplit > 0.f && view.displacement && view.displacement->displaced(patchIndex);
    if (displaced) {
        splitPatchWith(view, patchIndex, side, EdgeDisplacement{view, patchIndex}, out, counters);
    } else {
        splitPatchWith(view, patchIndex, side, NoDisplacement{}, out, counters);
    }
}

void splitQuadric(const ReyesView& view, const PlacedQuadric& pq, uint32_t index, float side,
                  std::vector<Piece>& out, SplitCounters& counters) {
    counters.patchCulled = false;
    Piece root = rootPiece(index);
    for (int e = 0; e < 4; ++e) root.edge[e] = quadricBoundaryEdge(view, pq, e, side);
    const PieceHull hull{view, nullptr, &pq};
    auto surfaceAt = [&](Vec2 uv) { return quadricPoint(pq, uv); };
    auto measure = [&](const PieceEdge& e, float s0, float s1) {
        return measureLength(view, [&](float t) { return surfaceAt(lerpUV(e, s0 + (s1 - s0) * t)); });
    };
    splitPieces(view, root, hull, surfaceAt, measure, NoDisplacement{}, side, out, counters);
}

void splitSurface(const ReyesView& view, const PatchAttributes& attr, uint32_t index, float micropolygonSide,
                  std::vector<Piece>& out, SplitCounters& counters) {
    // GeometricApproximation "motionfactor" / "focusfactor" (PRMan, Aqsis): blurred geometry is shaded
    // more coarsely, the shading rate growing with the blur: rate * max(1, factor * blur / 16 pixels).
    const float factor =
        std::max(view.patchMoves(index) ? attr.motionFactor : 0.f, view.lens ? attr.focusFactor : 0.f);
    if (factor > 0.f) {
        Piece root;
        root.patch = index;
        root.uv[0] = {0, 0}, root.uv[1] = {1, 0}, root.uv[2] = {1, 1}, root.uv[3] = {0, 1};
        const PieceHull hull{view, &view.patches[index],
                             isQuadric(attr.kind) ? &view.quadrics[attr.shape] : nullptr};
        if (classify(view, hull, root) != Verdict::Cull)
            micropolygonSide *= std::sqrt(std::max(1.f, factor * root.blurPixels / 16.f));
    }
    switch (attr.kind) {
        case SurfaceKind::BicubicBezier:
            splitPatch(view, index, micropolygonSide, out, counters);
            return;
        case SurfaceKind::Sphere:
        case SurfaceKind::Cylinder:
        case SurfaceKind::Cone:
        case SurfaceKind::Disk:
        case SurfaceKind::Paraboloid:
        case SurfaceKind::Hyperboloid:
        case SurfaceKind::Torus:
            splitQuadric(view, view.quadrics[attr.shape], index, micropolygonSide, out, counters);
            return;
    }
}

SurfaceReach surfaceReach(const ReyesView& view, const PatchAttributes& attr, uint32_t index) {
    SurfaceReach reach;
    const bool quadric = isQuadric(attr.kind);
    if (!quadric)
        for (const Vec3& c : view.patches[index].cp)
            if (!isFinite(c)) return reach;  // splitPatch culls it
    Piece root = rootPiece(index);
    const PieceHull hull{view, &view.patches[index], quadric ? &view.quadrics[attr.shape] : nullptr};
    const Verdict v = classify(view, hull, root);
    if (v == Verdict::Cull) return reach;
    if (!view.cull || v == Verdict::SplitNear) {
        reach.kind = SurfaceReach::Anywhere;
        return reach;
    }
    reach.kind = SurfaceReach::Bounded;
    reach.x0 = root.x0, reach.y0 = root.y0, reach.x1 = root.x1, reach.y1 = root.y1;
    return reach;
}

}  // namespace tessera
