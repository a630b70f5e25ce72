#include "reyes/rasterize_blur.h"

#include <algorithm>
#include <cmath>

#include "engine/motion.h"
#include "reyes/edge_functions.h"

namespace tessera {
namespace {

// Raster coordinate to fixed point for moved vertices, after the same clamp as rasterToFixed. Every moved
// vertex goes through this one function, so shared vertices of neighbouring micropolygons stay bit-identical.
inline int64_t blurredToFixed(float v) {
    constexpr float kLimit = float(1 << 20) * kSubpixelScale;
    const float f = std::min(kLimit, std::max(-kLimit, v * kSubpixelScale));
    return int64_t(f + (f >= 0.f ? 0.5f : -0.5f));  // float rounding, truncating conversion: no libm call
}

// A vertex moved to time segment (k, w) and lens point `lens`: fixed-point raster position and depth.
struct MovedVertex {
    int64_t X, Y;
    float Z;
    bool valid;
};
inline MovedVertex moveVertex(const Grid& g, size_t v, int k, float w, Vec2 lens, float sx, float sy) {
    MovedVertex m;
    float x, y, z, c;
    if (g.knots == 1) {
        m.valid = g.knotValid[v];
        x = g.knotX[v], y = g.knotY[v], z = g.knotZ[v], c = g.knotC[v];
    } else {
        const size_t n = size_t(g.vertexCount()), a = size_t(k) * n + v, b = a + n;
        m.valid = g.knotValid[a] & g.knotValid[b];
        x = g.knotX[a] + w * (g.knotX[b] - g.knotX[a]);
        y = g.knotY[a] + w * (g.knotY[b] - g.knotY[a]);
        z = g.knotZ[a] + w * (g.knotZ[b] - g.knotZ[a]);
        c = g.knotC[a] + w * (g.knotC[b] - g.knotC[a]);
    }
    m.X = blurredToFixed(x + lens.x * c * sx);
    m.Y = blurredToFixed(y + lens.y * c * sy);
    m.Z = z;
    return m;
}

// A micropolygon's corners moved to one (time, lens point), in fixed point, with their depths.
struct MovedQuad {
    int64_t X[4], Y[4];
    float Z[4];
    int64_t minX, maxX, minY, maxY;
    bool valid;
};

inline void finishQuad(MovedQuad& q) {
    q.minX = std::min({q.X[0], q.X[1], q.X[2], q.X[3]}), q.maxX = std::max({q.X[0], q.X[1], q.X[2], q.X[3]});
    q.minY = std::min({q.Y[0], q.Y[1], q.Y[2], q.Y[3]}), q.maxY = std::max({q.Y[0], q.Y[1], q.Y[2], q.Y[3]});
}

inline MovedQuad moveQuad(const Grid& g, const int vid[4], int k, float w, Vec2 lens, const Projector& pr) {
    MovedQuad q;
    q.valid = true;
    for (int c = 0; c < 4; ++c) {
        const MovedVertex m = moveVertex(g, size_t(vid[c]), k, w, lens, pr.sx, pr.sy);
        q.valid &= m.valid;
        q.X[c] = m.X, q.Y[c] = m.Y, q.Z[c] = m.Z;
    }
    finishQuad(q);
    return q;
}

// Signed doubled area of corners (0, 1, 2) of a moved quad.
inline int64_t signedArea(const MovedQuad& q) {
    return (q.X[1] - q.X[0]) * (q.Y[2] - q.Y[0]) - (q.X[2] - q.X[0]) * (q.Y[1] - q.Y[0]);
}

// The moved quad's triangles (0,1,2) and (0,2,3).
constexpr int kQuadTriangles[2][3] = {{0, 1, 2}, {0, 2, 3}};
inline TriangleEdges quadTriangle(const MovedQuad& q, int tri) {
    const int* c = kQuadTriangles[tri];
    return setupTriangleEdges(q.X[c[0]], q.Y[c[0]], q.X[c[1]], q.Y[c[1]], q.X[c[2]], q.Y[c[2]]);
}

// Both triangles set up once, for the passes of the simple and interleaved schemes in which many samples
// meet the same moved quad.
struct QuadSetup {
    TriangleEdges tri[2];
};
inline QuadSetup setupQuad(const MovedQuad& q) {
    return {{quadTriangle(q, 0), quadTriangle(q, 1)}};
}

// Test sample i against a moved quad with the sharp rasterizer's edge functions (edge_functions.h) and the
// depth of the moved corners. `edges(tri)` gives triangle tri's edges: precomputed (QuadSetup) or set up on
// demand (the bbox scheme, where each sample meets its own moved quad and the second triangle is often not
// needed).
template <bool kAttributes, class Edges>
inline bool testMovedSample(const Grid& g, const int vid[4], const MovedQuad& q, size_t i, SampleTile& tile,
                            float nearZ, Edges&& edges) {
    const int64_t sx = tile.sx[i], sy = tile.sy[i];
    if (sx < q.minX || sx > q.maxX || sy < q.minY || sy > q.maxY) return false;
    for (int tri = 0; tri < 2; ++tri) {
        const TriangleEdges& t = edges(tri);
        float l0, l1, l2;
        if (!t.valid || !insideTriangle(t, sx, sy, l0, l1, l2)) continue;
        if (t.swapped) std::swap(l1, l2);  // back to the corners' order
        l0 = 1.f - l1 - l2;
        const int* c = kQuadTriangles[tri];
        const float z = l0 * q.Z[c[0]] + l1 * q.Z[c[1]] + l2 * q.Z[c[2]];
        if (z < tile.z[i] && z >= nearZ)
            writeSampleHit<kAttributes>(g, vid[c[0]], vid[c[1]], vid[c[2]], l0, l1, l2, z, i, tile);
        return true;
    }
    return false;
}

// One-sided culling of a moved micropolygon: it is drawn when it faces the camera at the sample's time.
// At shutter open `front0` says whether it faces the camera with raster area sign `sign0`; when the sign
// flips it has turned over.
inline bool facesCamera(bool twoSided, bool front0, int64_t sign0, const MovedQuad& q) {
    if (twoSided) return true;
    const int64_t s = signedArea(q);
    const bool same = (s > 0) == (sign0 > 0);
    return front0 ? same : !same;
}

struct Span {
    int px0, px1, py0, py1;  // inclusive pixel range inside the tile region
    bool empty() const { return px0 > px1 || py0 > py1; }
};
inline Span pixelSpan(const Rect& reg, int64_t minX, int64_t maxX, int64_t minY, int64_t maxY) {
    Span s;
    s.px0 = int(std::max<int64_t>(reg.x0, minX >> kSubpixelBits));
    s.px1 = int(std::min<int64_t>(reg.x1 - 1, maxX >> kSubpixelBits));
    s.py0 = int(std::max<int64_t>(reg.y0, minY >> kSubpixelBits));
    s.py1 = int(std::min<int64_t>(reg.y1 - 1, maxY >> kSubpixelBits));
    return s;
}

struct Bound2 {
    float x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
    bool valid = true;
};

template <bool kAttributes>
uint64_t rasterizeImpl(const Grid& g, SampleTile& tile, float nearZ, const BlurRasterContext& ctx,
                       const BlurStrata& strata) {
    const Projector& pr = *ctx.projector;
    const BlurPattern& pat = *ctx.pattern;
    const std::vector<float>& knots = *ctx.knots;
    const Rect& reg = tile.region;
    const int stride = g.nu + 1, spp = tile.spp, tw = reg.width();
    const int vertices = g.vertexCount();
    uint64_t tests = 0;
    auto sampleIndex = [&](int px, int py, int slot) {
        return (size_t(py - reg.y0) * tw + size_t(px - reg.x0)) * spp + size_t(slot);
    };
    // Facing at shutter open of each micropolygon (one-sided culling, see facesCamera).
    auto openFacing = [&](const int vid[4], bool& front0, int64_t& sign0) {
        front0 = g.front[vid[0]] | g.front[vid[1]] | g.front[vid[2]] | g.front[vid[3]];
        sign0 = 1;
        if (!g.twoSided) {
            const int64_t X0 = g.X[vid[0]], Y0 = g.Y[vid[0]];
            sign0 = (g.X[vid[1]] - X0) * (g.Y[vid[2]] - Y0) - (g.X[vid[2]] - X0) * (g.Y[vid[1]] - Y0);
            if (sign0 == 0) sign0 = 1;
        }
    };

    if (pat.scheme != BlurSampling::BoundingBox) {
        // Simple and interleaved: every micropolygon of the grid takes the same (t, lens) per pass, so the
        // whole grid is moved once per pass (each vertex shared by four micropolygons) and then sampled.
        thread_local std::vector<MovedVertex> moved;
        moved.resize(vertices);
        const bool interleaved = pat.scheme == BlurSampling::Interleaved;
        const int K = pat.tileSize, KK = K * K, passes = interleaved ? pat.tileSamples() : spp;
        for (int n = 0; n < passes; ++n) {
            int k;
            float w;
            timelineSegment(knots.data(), g.knots, pat.time[n], k, w);
            const Vec2 lens = pat.lensPoint[n];
            int64_t gx0 = INT64_MAX, gx1 = INT64_MIN, gy0 = INT64_MAX, gy1 = INT64_MIN;
            for (int v = 0; v < vertices; ++v) {
                moved[v] = moveVertex(g, size_t(v), k, w, lens, pr.sx, pr.sy);
                gx0 = std::min(gx0, moved[v].X), gx1 = std::max(gx1, moved[v].X);
                gy0 = std::min(gy0, moved[v].Y), gy1 = std::max(gy1, moved[v].Y);
            }
            if (pixelSpan(reg, gx0, gx1, gy0, gy1).empty()) continue;  // the grid misses this tile now
            for (int j = 0; j < g.nv; ++j)
                for (int i = 0; i < g.nu; ++i) {
                    const int a = j * stride + i;
                    const int vid[4] = {a, a + 1, a + stride + 1, a + stride};
                    MovedQuad q;
                    q.valid = true;
                    for (int c = 0; c < 4; ++c) {
                        const MovedVertex& m = moved[vid[c]];
                        q.valid &= m.valid;
                        q.X[c] = m.X, q.Y[c] = m.Y, q.Z[c] = m.Z;
                    }
                    if (!q.valid) continue;
                    finishQuad(q);
                    const Span sp = pixelSpan(reg, q.minX, q.maxX, q.minY, q.maxY);
                    if (sp.empty()) continue;
                    bool front0;
                    int64_t sign0;
                    openFacing(vid, front0, sign0);
                    if (!facesCamera(g.twoSided, front0, sign0, q)) continue;
                    const QuadSetup setup = setupQuad(q);
                    const auto setupEdges = [&setup](int t) -> const TriangleEdges& { return setup.tri[t]; };
                    if (!interleaved) {
                        for (int py = sp.py0; py <= sp.py1; ++py)
                            for (int px = sp.px0; px <= sp.px1; ++px) {
                                ++tests;
                                if (testMovedSample<kAttributes>(g, vid, q, sampleIndex(px, py, n), tile,
                                                                 nearZ, setupEdges))
                                    tile.pixelHit[size_t(py - reg.y0) * tw + (px - reg.x0)] = 1;
                            }
                        continue;
                    }
                    const int N = passes;
                    for (int ty = sp.py0 / K; ty <= sp.py1 / K; ++ty)
                        for (int tx = sp.px0 / K; tx <= sp.px1 / K; ++tx) {
                            const int qn = pat.perm[size_t(pat.tilePermutation(tx, ty)) * N + n];
                            const int inTile = qn % KK, slot = qn / KK;
                            const int px = tx * K + inTile % K, py = ty * K + inTile / K;
                            if (px < sp.px0 || px > sp.px1 || py < sp.py0 || py > sp.py1) continue;
                            ++tests;
                            if (testMovedSample<kAttributes>(g, vid, q, sampleIndex(px, py, slot), tile,
                                                             nearZ, setupEdges))
                                tile.pixelHit[size_t(py - reg.y0) * tw + (px - reg.x0)] = 1;
                        }
                }
        }
        return tests;
    }

    // Bounding box: per micropolygon, one bound per (time group, lens cell) (one for the whole shutter
    // and lens without strata bounds), then each sample in it at its own (t, lens). The tile's samples are
    // sorted into fine time strata (BlurStrata); the grid groups them so that its fastest vertex moves
    // about one pixel per group: a slow grid takes few groups (few bounds), a fast one many (few samples per
    // bound).
    const bool cut = ctx.strataBounds && !strata.start.empty();
    const int T = cut ? strata.timeStrata : 1, L = cut ? strata.lensCells : 1;
    const int LL = L * L, cellsPerPixel = T * LL;
    const size_t nv = size_t(vertices);
    const float motion = g.motionPixels;
    const bool allValid = g.allKnotsValid;
    // Cost model: a group costs a bound (about two sample tests' worth of work) and the samples in its bound
    // number about spp (1 + motion / groups) per covered pixel, so the total is least near
    // groups = sqrt(spp * motion / 2) (measured with callgrind on the moving teapot, docs/motion.md).
    const int wanted = std::clamp(int(std::ceil(std::sqrt(0.5f * float(spp) * motion))), 1, T);
    const int group = std::max(1, T / wanted), groups = (T + group - 1) / group;
    const bool lensOn = pr.hasLens() && pr.perspective;
    // A micropolygon's box and lens-coefficient range at each knot. Between two knots every corner moves
    // linearly, and the minimum of linear functions is concave (the maximum convex), so the box at time t
    // lies inside the linear interpolation of the two knot boxes: a group's bound is the union of the
    // interpolated boxes at its ends and of the knot boxes inside it, with no per-corner work.
    struct KnotBox {
        float x0, x1, y0, y1, c0, c1;
    };
    auto lerpBox = [](const KnotBox& p, const KnotBox& q, float w) {
        return KnotBox{p.x0 + w * (q.x0 - p.x0), p.x1 + w * (q.x1 - p.x1), p.y0 + w * (q.y0 - p.y0),
                       p.y1 + w * (q.y1 - p.y1), p.c0 + w * (q.c0 - p.c0), p.c1 + w * (q.c1 - p.c1)};
    };
    thread_local std::vector<KnotBox> knotBox;
    knotBox.resize(size_t(g.knots));
    // The groups' ends on the knot timeline.
    thread_local std::vector<int> endKnot;
    thread_local std::vector<float> endWeight;
    endKnot.resize(size_t(groups) + 1), endWeight.resize(size_t(groups) + 1);
    for (int e = 0; e <= groups; ++e)
        timelineSegment(knots.data(), g.knots, float(std::min(T, e * group)) / T, endKnot[e], endWeight[e]);
    for (int j = 0; j < g.nv; ++j) {
        for (int i = 0; i < g.nu; ++i) {
            const int a = j * stride + i;
            const int vid[4] = {a, a + 1, a + stride + 1, a + stride};
            KnotBox all{INFINITY, -INFINITY, INFINITY, -INFINITY, INFINITY, -INFINITY};
            for (int kn = 0; kn < g.knots; ++kn) {
                KnotBox kb{INFINITY, -INFINITY, INFINITY, -INFINITY, INFINITY, -INFINITY};
                for (int c = 0; c < 4; ++c) {
                    const size_t at = size_t(kn) * nv + vid[c];
                    kb.x0 = std::min(kb.x0, g.knotX[at]), kb.x1 = std::max(kb.x1, g.knotX[at]);
                    kb.y0 = std::min(kb.y0, g.knotY[at]), kb.y1 = std::max(kb.y1, g.knotY[at]);
                    kb.c0 = std::min(kb.c0, g.knotC[at]), kb.c1 = std::max(kb.c1, g.knotC[at]);
                }
                knotBox[kn] = kb;
                all.x0 = std::min(all.x0, kb.x0), all.x1 = std::max(all.x1, kb.x1);
                all.y0 = std::min(all.y0, kb.y0), all.y1 = std::max(all.y1, kb.y1);
                all.c0 = std::min(all.c0, kb.c0), all.c1 = std::max(all.c1, kb.c1);
            }
            // Quick reject: the bound over the whole shutter and lens misses this tile; most visits of a
            // blurred grid's buckets end here.
            {
                const float cmax = std::max(std::abs(all.c0), std::abs(all.c1));
                const float gx = cmax * std::abs(pr.sx), gy = cmax * std::abs(pr.sy);
                if (allValid && (all.x1 + gx < float(reg.x0) - 1.f || all.x0 - gx > float(reg.x1) + 1.f ||
                                 all.y1 + gy < float(reg.y0) - 1.f || all.y0 - gy > float(reg.y1) + 1.f))
                    continue;
            }
            bool front0;
            int64_t sign0;
            openFacing(vid, front0, sign0);
            for (int gi = 0; gi < groups; ++gi) {
                const int j0 = gi * group, j1 = std::min(T, j0 + group);
                KnotBox box;
                if (g.knots == 1) {
                    box = knotBox[0];
                } else {
                    const int ka = endKnot[gi], kb = endKnot[gi + 1];
                    const KnotBox p = lerpBox(knotBox[ka], knotBox[ka + 1], endWeight[gi]);
                    const KnotBox q = lerpBox(knotBox[kb], knotBox[kb + 1], endWeight[gi + 1]);
                    box = KnotBox{std::min(p.x0, q.x0), std::max(p.x1, q.x1), std::min(p.y0, q.y0),
                                  std::max(p.y1, q.y1), std::min(p.c0, q.c0), std::max(p.c1, q.c1)};
                    for (int kn = ka + 1; kn <= kb; ++kn) {
                        const KnotBox& m = knotBox[kn];
                        box = KnotBox{std::min(box.x0, m.x0), std::max(box.x1, m.x1), std::min(box.y0, m.y0),
                                      std::max(box.y1, m.y1), std::min(box.c0, m.c0), std::max(box.c1, m.c1)};
                    }
                }
                const float x0 = box.x0, x1 = box.x1, y0 = box.y0, y1 = box.y1, c0 = box.c0, c1 = box.c1;
                for (int lc = 0; lc < LL; ++lc) {
                    const float lx0 = -1.f + 2.f * float(lc % L) / L,
                                lx1 = -1.f + 2.f * float(lc % L + 1) / L;
                    const float ly0 = -1.f + 2.f * float(lc / L) / L,
                                ly1 = -1.f + 2.f * float(lc / L + 1) / L;
                    Bound2 bd;
                    bd.valid = allValid;
                    // x + l c sx >= min x + min (l c sx) over the corners (likewise for the maxima).
                    bd.x0 = x0, bd.x1 = x1, bd.y0 = y0, bd.y1 = y1;
                    if (lensOn) {
                        const float xs[4] = {lx0 * c0 * pr.sx, lx0 * c1 * pr.sx, lx1 * c0 * pr.sx,
                                             lx1 * c1 * pr.sx};
                        const float ys[4] = {ly0 * c0 * pr.sy, ly0 * c1 * pr.sy, ly1 * c0 * pr.sy,
                                             ly1 * c1 * pr.sy};
                        bd.x0 += std::min({xs[0], xs[1], xs[2], xs[3]}),
                            bd.x1 += std::max({xs[0], xs[1], xs[2], xs[3]});
                        bd.y0 += std::min({ys[0], ys[1], ys[2], ys[3]}),
                            bd.y1 += std::max({ys[0], ys[1], ys[2], ys[3]});
                    }
                    // A corner behind the near plane at some time: the moved quad of each sample decides.
                    const int64_t bx0 = bd.valid ? int64_t(bd.x0 * kSubpixelScale) - 2 : INT64_MIN / 4,
                                  bx1 = bd.valid ? int64_t(bd.x1 * kSubpixelScale) + 2 : INT64_MAX / 4,
                                  by0 = bd.valid ? int64_t(bd.y0 * kSubpixelScale) - 2 : INT64_MIN / 4,
                                  by1 = bd.valid ? int64_t(bd.y1 * kSubpixelScale) + 2 : INT64_MAX / 4;
                    const Span sp = pixelSpan(reg, bx0, bx1, by0, by1);
                    if (sp.empty()) continue;
                    for (int py = sp.py0; py <= sp.py1; ++py)
                        for (int px = sp.px0; px <= sp.px1; ++px) {
                            const size_t pix = size_t(py - reg.y0) * tw + (px - reg.x0);
                            auto visit = [&](int slot) {
                                const size_t si = pix * spp + size_t(slot);
                                if (tile.sx[si] < bx0 || tile.sx[si] > bx1 || tile.sy[si] < by0 ||
                                    tile.sy[si] > by1)
                                    return;
                                ++tests;
                                int k;
                                float w;
                                timelineSegment(knots.data(), g.knots, tile.time[si], k, w);
                                const MovedQuad q = moveQuad(g, vid, k, w, tile.lens[si], pr);
                                if (!q.valid || !facesCamera(g.twoSided, front0, sign0, q)) return;
                                TriangleEdges onDemand;
                                if (testMovedSample<kAttributes>(g, vid, q, si, tile, nearZ,
                                                                 [&](int t) -> const TriangleEdges& {
                                                                     return onDemand = quadTriangle(q, t);
                                                                 }))
                                    tile.pixelHit[pix] = 1;
                            };
                            if (!cut) {
                                for (int sl = 0; sl < spp; ++sl) visit(sl);
                                continue;
                            }
                            const size_t base = pix * cellsPerPixel + lc;
                            if (LL == 1) {  // the group's fine strata are one run of the pixel's list
                                for (uint32_t e = strata.start[base + j0]; e < strata.start[base + j1]; ++e)
                                    visit(strata.slot[e]);
                                continue;
                            }
                            for (int tb = j0; tb < j1; ++tb) {
                                const size_t c0i = base + size_t(tb) * LL;
                                for (uint32_t e = strata.start[c0i]; e < strata.start[c0i + 1]; ++e)
                                    visit(strata.slot[e]);
                            }
                        }
                }
            }
        }
    }
    return tests;
}

}  // namespace

void BlurStrata::configure(const BlurPattern& p) {
    timeStrata = 1, lensCells = 1;
    if (p.motion && p.lens) {
        timeStrata = std::min(256, p.spp);
        lensCells = p.spp >= 4 ? 2 : 1;
    } else if (p.motion) {
        timeStrata = std::min(256, 4 * p.spp);  // fine strata; micropolygons group them (rasterizeImpl)
    } else if (p.lens) {
        lensCells = std::max(1, int(std::floor(std::sqrt(float(p.spp)) + 1e-4f)));
    }
}

void BlurStrata::build(const SampleTile& tile) {
    const int C = cells(), spp = tile.spp, L = lensCells;
    const size_t pixels = size_t(tile.region.width()) * tile.region.height();
    start.assign(pixels * C + 1, 0);
    slot.resize(pixels * spp);
    auto cellOf = [&](size_t si) {
        const int tb = std::min(timeStrata - 1, int(tile.time[si] * timeStrata));
        const int lx = std::clamp(int((tile.lens[si].x + 1.f) * 0.5f * L), 0, L - 1);
        const int ly = std::clamp(int((tile.lens[si].y + 1.f) * 0.5f * L), 0, L - 1);
        return (tb * L + ly) * L + lx;
    };
    for (size_t p = 0; p < pixels; ++p)
        for (int s = 0; s < spp; ++s) ++start[p * C + cellOf(p * spp + s) + 1];
    for (size_t c = 0; c < pixels * C; ++c) start[c + 1] += start[c];
    std::vector<uint32_t> fill(start.begin(), start.end() - 1);
    for (size_t p = 0; p < pixels; ++p)
        for (int s = 0; s < spp; ++s) slot[fill[p * C + cellOf(p * spp + s)]++] = uint16_t(s);
}

uint64_t rasterizeBlurredGrid(const Grid& grid, SampleTile& tile, float nearZ, const BlurRasterContext& ctx,
                              const BlurStrata& strata) {
    return tile.channels ? rasterizeImpl<true>(grid, tile, nearZ, ctx, strata)
                         : rasterizeImpl<false>(grid, tile, nearZ, ctx, strata);
}

}  // namespace tessera
