#include "reyes/rasterize_blur.h"

#include <algorithm>
#include <cmath>

namespace tessera {
namespace {

// Knot segment of normalised time u (FrameMotion::segment on the knot list).
inline void knotSegment(const std::vector<float>& knots, int gridKnots, float u, int& k, float& w) {
    const int last = gridKnots - 1;
    if (last <= 0) {
        k = 0, w = 0.f;
        return;
    }
    if (last == 1) {  // two knots: 0 and 1
        k = 0, w = std::min(1.f, std::max(0.f, u));
        return;
    }
    if (u <= 0.f) {
        k = 0, w = 0.f;
        return;
    }
    if (u >= 1.f) {
        k = last - 1, w = 1.f;
        return;
    }
    k = 0;
    while (k + 1 < last && knots[k + 1] <= u) ++k;
    w = (u - knots[k]) / (knots[k + 1] - knots[k]);
}

// Raster coordinate to fixed point for moved vertices, after the same clamp as rasterToFixed. Every moved vertex goes through this one function, so shared
// vertices of neighbouring micropolygons stay bit-identical.
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

inline int64_t fillBias(int64_t ax, int64_t ay, int64_t bx, int64_t by) {
    const int64_t dy = by - ay, dx = bx - ax;
    return (dy > 0 || (dy == 0 && dx < 0)) ? 0 : 1;
}

// A moved quad's two triangles (0,1,2) and (0,2,3) set up once, for the passes of the simple and
// interleaved schemes in which many samples meet the same moved quad.
struct QuadSetup {
    int64_t A[2][3], B[2][3], C[2][3];
    float invArea[2];
    bool swapped[2], valid[2];
};
inline QuadSetup setupQuad(const MovedQuad& q) {
    QuadSetup t;
    static constexpr int kTri[2][3] = {{0, 1, 2}, {0, 2, 3}};
    for (int tri = 0; tri < 2; ++tri) {
        const int* c = kTri[tri];
        int64_t xs[3] = {q.X[c[0]], q.X[c[1]], q.X[c[2]]}, ys[3] = {q.Y[c[0]], q.Y[c[1]], q.Y[c[2]]};
        int64_t area = (xs[1] - xs[0]) * (ys[2] - ys[0]) - (xs[2] - xs[0]) * (ys[1] - ys[0]);
        t.valid[tri] = area != 0;
        t.swapped[tri] = area < 0;
        if (area < 0) {
            std::swap(xs[1], xs[2]);
            std::swap(ys[1], ys[2]);
            area = -area;
        }
        for (int e = 0; e < 3; ++e) {
            const int a = (e + 1) % 3, b = (e + 2) % 3;
            t.A[tri][e] = -(ys[b] - ys[a]);
            t.B[tri][e] = xs[b] - xs[a];
            t.C[tri][e] = -(t.A[tri][e] * xs[a] + t.B[tri][e] * ys[a]) -
                          (((ys[b] - ys[a]) > 0 || ((ys[b] - ys[a]) == 0 && (xs[b] - xs[a]) < 0)) ? 0 : 1);
        }
        t.invArea[tri] = t.valid[tri] ? 1.f / float(area) : 0.f;
    }
    return t;
}

template <bool kAttributes>
inline bool testSampleSetup(const Grid& g, const int vid[4], const MovedQuad& q, const QuadSetup& t, size_t i,
                            SampleTile& tile, float nearZ);

// Test a sample against triangle (c0, c1, c2) of a moved quad with the same exact edge functions and
// top-left fill rule as the sharp rasterizer; on a hit returns the barycentric weights of the corners.
inline bool insideTriangle(const MovedQuad& q, int c0, int c1, int c2, int64_t sx, int64_t sy, float& l0,
                           float& l1, float& l2) {
    int64_t xs[3] = {q.X[c0], q.X[c1], q.X[c2]}, ys[3] = {q.Y[c0], q.Y[c1], q.Y[c2]};
    int64_t area = (xs[1] - xs[0]) * (ys[2] - ys[0]) - (xs[2] - xs[0]) * (ys[1] - ys[0]);
    if (area == 0) return false;
    bool swapped = false;
    if (area < 0) {
        std::swap(xs[1], xs[2]);
        std::swap(ys[1], ys[2]);
        area = -area;
        swapped = true;
    }
    int64_t wgt[3];
    for (int e = 0; e < 3; ++e) {
        const int a = (e + 1) % 3, b = (e + 2) % 3;
        const int64_t A = -(ys[b] - ys[a]), B = xs[b] - xs[a];
        const int64_t C = -(A * xs[a] + B * ys[a]) - fillBias(xs[a], ys[a], xs[b], ys[b]);
        wgt[e] = A * sx + B * sy + C;
        if (wgt[e] < 0) return false;
    }
    const float inv = 1.f / float(area);
    float w1 = float(wgt[1]) * inv, w2 = float(wgt[2]) * inv;
    if (swapped) std::swap(w1, w2);
    l1 = w1, l2 = w2, l0 = 1.f - w1 - w2;
    return true;
}

template <bool kAttributes>
inline void writeHit(const Grid& g, const int vid[4], const int c[3], const float l[3], float z, size_t i,
                     SampleTile& tile) {
    const int a = vid[c[0]], b = vid[c[1]], d = vid[c[2]];
    tile.z[i] = z;
    tile.r[i] = l[0] * g.R[a] + l[1] * g.R[b] + l[2] * g.R[d];
    tile.g[i] = l[0] * g.G[a] + l[1] * g.G[b] + l[2] * g.G[d];
    tile.b[i] = l[0] * g.B[a] + l[1] * g.B[b] + l[2] * g.B[d];
    tile.a[i] = 1.f;
    if constexpr (kAttributes) {
        Vec3 N;
        if (!g.NX.empty())
            N = normalize(Vec3{l[0] * g.NX[a] + l[1] * g.NX[b] + l[2] * g.NX[d],
                               l[0] * g.NY[a] + l[1] * g.NY[b] + l[2] * g.NY[d],
                               l[0] * g.NZ[a] + l[1] * g.NZ[b] + l[2] * g.NZ[d]});
        tile.setAttributes(i, g.objectId, N, 0, false);
    }
}

// Test sample i (at fixed-point sx, sy) against a moved quad: the two triangles (0,1,2) and (0,2,3).
// `facing0` is the sign of the quad's raster area at shutter open for one-sided culling: a one-sided
// micropolygon that turned its back to the camera (area sign flipped while it was back-facing) is skipped.
template <bool kAttributes>
inline bool testSample(const Grid& g, const int vid[4], const MovedQuad& q, size_t i, SampleTile& tile,
                       float nearZ) {
    const int64_t sx = tile.sx[i], sy = tile.sy[i];
    if (sx < q.minX || sx > q.maxX || sy < q.minY || sy > q.maxY) return false;
    static constexpr int kTri[2][3] = {{0, 1, 2}, {0, 2, 3}};
    for (const auto& c : kTri) {
        float l[3];
        if (!insideTriangle(q, c[0], c[1], c[2], sx, sy, l[0], l[1], l[2])) continue;
        const float z = l[0] * q.Z[c[0]] + l[1] * q.Z[c[1]] + l[2] * q.Z[c[2]];
        if (z < tile.z[i] && z >= nearZ) writeHit<kAttributes>(g, vid, c, l, z, i, tile);
        return true;
    }
    return false;
}

template <bool kAttributes>
inline bool testSampleSetup(const Grid& g, const int vid[4], const MovedQuad& q, const QuadSetup& t, size_t i,
                            SampleTile& tile, float nearZ) {
    const int64_t sx = tile.sx[i], sy = tile.sy[i];
    if (sx < q.minX || sx > q.maxX || sy < q.minY || sy > q.maxY) return false;
    static constexpr int kTri[2][3] = {{0, 1, 2}, {0, 2, 3}};
    for (int tri = 0; tri < 2; ++tri) {
        if (!t.valid[tri]) continue;
        const int64_t w0 = t.A[tri][0] * sx + t.B[tri][0] * sy + t.C[tri][0];
        const int64_t w1 = t.A[tri][1] * sx + t.B[tri][1] * sy + t.C[tri][1];
        const int64_t w2 = t.A[tri][2] * sx + t.B[tri][2] * sy + t.C[tri][2];
        if ((w0 | w1 | w2) < 0) continue;
        float l1 = float(w1) * t.invArea[tri], l2 = float(w2) * t.invArea[tri];
        if (t.swapped[tri]) std::swap(l1, l2);
        const float l[3] = {1.f - l1 - l2, l1, l2};
        const int* c = kTri[tri];
        const float z = l[0] * q.Z[c[0]] + l[1] * q.Z[c[1]] + l[2] * q.Z[c[2]];
        if (z < tile.z[i] && z >= nearZ) writeHit<kAttributes>(g, vid, c, l, z, i, tile);
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

// Raster bound (float) of a vertex over the time interval [ua, ub] and the lens cell [lx0,lx1]x[ly0,ly1]
// (unit-disk coordinates): the positions at both ends and at every knot inside (the path is straight
// between knots), each grown by the shift range of the lens cell at its depth.
struct Bound2 {
    float x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
    bool valid = true;
};
inline void extendVertexBound(const Grid& g, int v, const std::vector<float>& knots, float ua, float ub, float lx0,
                              float lx1, float ly0, float ly1, float sx, float sy, Bound2& bd) {
    const size_t n = size_t(g.vertexCount());
    auto add = [&](float x, float y, float c, bool valid) {
        if (!valid) {
            bd.valid = false;
            return;
        }
        const float ax = c * sx, ay = c * sy;
        bd.x0 = std::min(bd.x0, x + std::min(lx0 * ax, lx1 * ax)), bd.x1 = std::max(bd.x1, x + std::max(lx0 * ax, lx1 * ax));
        bd.y0 = std::min(bd.y0, y + std::min(ly0 * ay, ly1 * ay)), bd.y1 = std::max(bd.y1, y + std::max(ly0 * ay, ly1 * ay));
    };
    auto addAt = [&](float u) {
        int k;
        float w;
        knotSegment(knots, g.knots, u, k, w);
        if (g.knots == 1) {
            add(g.knotX[v], g.knotY[v], g.knotC[v], g.knotValid[v]);
            return;
        }
        const size_t a = size_t(k) * n + v, b = a + n;
        add(g.knotX[a] + w * (g.knotX[b] - g.knotX[a]), g.knotY[a] + w * (g.knotY[b] - g.knotY[a]),
            g.knotC[a] + w * (g.knotC[b] - g.knotC[a]), g.knotValid[a] & g.knotValid[b]);
    };
    addAt(ua);
    if (g.knots > 1) {
        for (int kn = 1; kn + 1 < g.knots; ++kn)
            if (knots[kn] > ua && knots[kn] < ub) {
                const size_t a = size_t(kn) * n + v;
                add(g.knotX[a], g.knotY[a], g.knotC[a], g.knotValid[a]);
            }
        addAt(ub);
    }
}

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
            knotSegment(knots, g.knots, pat.time[n], k, w);
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
                    if (!interleaved) {
                        for (int py = sp.py0; py <= sp.py1; ++py)
                            for (int px = sp.px0; px <= sp.px1; ++px) {
                                ++tests;
                                if (testSampleSetup<kAttributes>(g, vid, q, setup, sampleIndex(px, py, n), tile, nearZ))
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
                            if (testSampleSetup<kAttributes>(g, vid, q, setup, sampleIndex(px, py, slot), tile, nearZ))
                                tile.pixelHit[size_t(py - reg.y0) * tw + (px - reg.x0)] = 1;
                        }
                }
        }
        return tests;
    }

    // Bounding box: per micropolygon, one bound per (time group, lens cell) (one for the whole shutter
    // and lens without strata bounds), then each sample in it at its own (t, lens). The tile's samples are
    // sorted into fine time strata (BlurStrata); a micropolygon groups them so that it moves about one
    // pixel per group: a slow one takes few groups (few bounds), a fast one many (few samples per bound).
    const bool cut = ctx.strataBounds && !strata.start.empty();
    const int T = cut ? strata.timeStrata : 1, L = cut ? strata.lensCells : 1;
    const int LL = L * L, cellsPerPixel = T * LL;
    thread_local std::vector<float> edgeX, edgeY, edgeC;
    thread_local std::vector<uint8_t> edgeValid;
    for (int j = 0; j < g.nv; ++j) {
        for (int i = 0; i < g.nu; ++i) {
            const int a = j * stride + i;
            const int vid[4] = {a, a + 1, a + stride + 1, a + stride};
            const size_t nv = size_t(vertices);
            // Quick reject: the bound over the whole shutter and lens (every corner at every knot, grown
            // by its circle of confusion) misses this tile; most visits of a blurred grid's buckets end here.
            float motion = 0.f;
            {
                Bound2 all;
                for (int c = 0; c < 4; ++c) {
                    for (int kn = 0; kn < g.knots; ++kn) {
                        const size_t at = size_t(kn) * nv + vid[c];
                        if (!g.knotValid[at]) all.valid = false;
                        const float gx = std::abs(g.knotC[at] * pr.sx), gy = std::abs(g.knotC[at] * pr.sy);
                        all.x0 = std::min(all.x0, g.knotX[at] - gx), all.x1 = std::max(all.x1, g.knotX[at] + gx);
                        all.y0 = std::min(all.y0, g.knotY[at] - gy), all.y1 = std::max(all.y1, g.knotY[at] + gy);
                        if (kn > 0) {
                            const size_t prev = at - nv;
                            motion = std::max(motion, std::abs(g.knotX[at] - g.knotX[prev]) +
                                                          std::abs(g.knotY[at] - g.knotY[prev]));
                        }
                    }
                }
                if (all.valid && pixelSpan(reg, int64_t(std::floor(all.x0 * kSubpixelScale)) - 1,
                                           int64_t(std::ceil(all.x1 * kSubpixelScale)) + 1,
                                           int64_t(std::floor(all.y0 * kSubpixelScale)) - 1,
                                           int64_t(std::ceil(all.y1 * kSubpixelScale)) + 1)
                                     .empty())
                    continue;
                if (g.knots > 2) motion *= float(g.knots - 1);  // path length bound over all segments
            }
            // Time groups of `group` fine strata each.
            const int wanted = std::clamp(int(std::ceil(motion)), 1, T);
            const int group = std::max(1, T / wanted), groups = (T + group - 1) / group;
            // The corners at the groups' boundaries (the path is straight between them unless a knot lies
            // inside a group, which extendVertexBound then adds).
            edgeX.resize(size_t(4) * (groups + 1)), edgeY.resize(edgeX.size()), edgeC.resize(edgeX.size());
            edgeValid.resize(edgeX.size());
            const bool innerKnots = g.knots > 2;
            for (int c = 0; c < 4; ++c)
                for (int e = 0; e <= groups; ++e) {
                    int k;
                    float w;
                    knotSegment(knots, g.knots, float(std::min(T, e * group)) / T, k, w);
                    const size_t ka = size_t(k) * nv + vid[c], kb = g.knots > 1 ? ka + nv : ka,
                                 at = size_t(c) * (groups + 1) + e;
                    edgeX[at] = g.knotX[ka] + w * (g.knotX[kb] - g.knotX[ka]);
                    edgeY[at] = g.knotY[ka] + w * (g.knotY[kb] - g.knotY[ka]);
                    edgeC[at] = g.knotC[ka] + w * (g.knotC[kb] - g.knotC[ka]);
                    edgeValid[at] = g.knotValid[ka] & g.knotValid[kb];
                }
            bool front0;
            int64_t sign0;
            openFacing(vid, front0, sign0);
            for (int gi = 0; gi < groups; ++gi) {
                const int j0 = gi * group, j1 = std::min(T, j0 + group);
                const float ua = float(j0) / T, ub = float(j1) / T;
                for (int lc = 0; lc < LL; ++lc) {
                    const float lx0 = -1.f + 2.f * float(lc % L) / L, lx1 = -1.f + 2.f * float(lc % L + 1) / L;
                    const float ly0 = -1.f + 2.f * float(lc / L) / L, ly1 = -1.f + 2.f * float(lc / L + 1) / L;
                    Bound2 bd;
                    if (innerKnots) {
                        for (int c = 0; c < 4; ++c)
                            extendVertexBound(g, vid[c], knots, ua, ub, lx0, lx1, ly0, ly1, pr.sx, pr.sy, bd);
                    } else {
                        for (int c = 0; c < 4; ++c)
                            for (int e = gi; e <= gi + 1; ++e) {
                                const size_t at = size_t(c) * (groups + 1) + e;
                                if (!edgeValid[at]) bd.valid = false;
                                const float ax = edgeC[at] * pr.sx, ay = edgeC[at] * pr.sy;
                                bd.x0 = std::min(bd.x0, edgeX[at] + std::min(lx0 * ax, lx1 * ax));
                                bd.x1 = std::max(bd.x1, edgeX[at] + std::max(lx0 * ax, lx1 * ax));
                                bd.y0 = std::min(bd.y0, edgeY[at] + std::min(ly0 * ay, ly1 * ay));
                                bd.y1 = std::max(bd.y1, edgeY[at] + std::max(ly0 * ay, ly1 * ay));
                            }
                    }
                    // A corner behind the near plane at some time: the moved quad of each sample decides.
                    const int64_t bx0 = bd.valid ? int64_t(std::floor(bd.x0 * kSubpixelScale)) - 1 : INT64_MIN / 4,
                                  bx1 = bd.valid ? int64_t(std::ceil(bd.x1 * kSubpixelScale)) + 1 : INT64_MAX / 4,
                                  by0 = bd.valid ? int64_t(std::floor(bd.y0 * kSubpixelScale)) - 1 : INT64_MIN / 4,
                                  by1 = bd.valid ? int64_t(std::ceil(bd.y1 * kSubpixelScale)) + 1 : INT64_MAX / 4;
                    const Span sp = pixelSpan(reg, bx0, bx1, by0, by1);
                    if (sp.empty()) continue;
                    for (int py = sp.py0; py <= sp.py1; ++py)
                        for (int px = sp.px0; px <= sp.px1; ++px) {
                            const size_t pix = size_t(py - reg.y0) * tw + (px - reg.x0);
                            auto visit = [&](int slot) {
                                const size_t si = pix * spp + size_t(slot);
                                if (tile.sx[si] < bx0 || tile.sx[si] > bx1 || tile.sy[si] < by0 || tile.sy[si] > by1)
                                    return;
                                ++tests;
                                int k;
                                float w;
                                knotSegment(knots, g.knots, tile.time[si], k, w);
                                const MovedQuad q = moveQuad(g, vid, k, w, tile.lens[si], pr);
                                if (!q.valid || !facesCamera(g.twoSided, front0, sign0, q)) return;
                                if (testSample<kAttributes>(g, vid, q, si, tile, nearZ)) tile.pixelHit[pix] = 1;
                            };
                            if (!cut) {
                                for (int sl = 0; sl < spp; ++sl) visit(sl);
                                continue;
                            }
                            for (int tb = j0; tb < j1; ++tb) {
                                const size_t c0 = pix * cellsPerPixel + size_t(tb) * LL + lc;
                                for (uint32_t e = strata.start[c0]; e < strata.start[c0 + 1]; ++e) visit(strata.slot[e]);
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
