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

// A vertex at time segment (k, w): camera-space position.
inline Vec3 vertexAt(const Grid& g, int v, int k, float w) {
    const size_t n = size_t(g.vertexCount());
    if (g.knots == 1) return g.knotP[v];
    const Vec3 a = g.knotP[size_t(k) * n + v], b = g.knotP[size_t(k + 1) * n + v];
    return lerp(a, b, w);
}

// A micropolygon's corners moved to one (time, lens point), in fixed point, with their depths.
struct MovedQuad {
    int64_t X[4], Y[4];
    float Z[4];
    int64_t minX, maxX, minY, maxY;
    bool valid;
};

inline MovedQuad moveQuad(const Grid& g, const int vid[4], int k, float w, Vec2 lens, const Projector& pr,
                          float nearZ) {
    MovedQuad q;
    q.valid = true;
    q.minX = q.minY = INT64_MAX;
    q.maxX = q.maxY = INT64_MIN;
    for (int c = 0; c < 4; ++c) {
        const Vec3 P = vertexAt(g, vid[c], k, w);
        if (pr.perspective && !(P.z >= nearZ)) {
            q.valid = false;
            return q;
        }
        const Vec3 r = pr.toRaster(P);
        const Vec2 s = pr.lensShift(P.z, lens);
        q.X[c] = rasterToFixed(r.x + s.x);
        q.Y[c] = rasterToFixed(r.y + s.y);
        q.Z[c] = P.z;
        q.minX = std::min(q.minX, q.X[c]), q.maxX = std::max(q.maxX, q.X[c]);
        q.minY = std::min(q.minY, q.Y[c]), q.maxY = std::max(q.maxY, q.Y[c]);
    }
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
inline void extendVertexBound(const Grid& g, int v, const std::vector<float>& knots, float ua, float ub,
                              float lx0, float lx1, float ly0, float ly1, const Projector& pr, bool& valid,
                              float& x0, float& x1, float& y0, float& y1) {
    auto add = [&](const Vec3& P) {
        if (pr.perspective && !(P.z > pr.nearClip)) {
            valid = false;
            return;
        }
        const Vec3 r = pr.toRaster(P);
        float sx0 = 0, sx1 = 0, sy0 = 0, sy1 = 0;
        if (pr.hasLens() && pr.perspective) {
            const float kz = pr.lensRadius * (1.f / pr.focalDistance - 1.f / P.z);
            const float ax = kz * pr.sx, ay = kz * pr.sy;
            sx0 = std::min(lx0 * ax, lx1 * ax), sx1 = std::max(lx0 * ax, lx1 * ax);
            sy0 = std::min(ly0 * ay, ly1 * ay), sy1 = std::max(ly0 * ay, ly1 * ay);
        }
        x0 = std::min(x0, r.x + sx0), x1 = std::max(x1, r.x + sx1);
        y0 = std::min(y0, r.y + sy0), y1 = std::max(y1, r.y + sy1);
    };
    int k;
    float w;
    knotSegment(knots, g.knots, ua, k, w);
    add(vertexAt(g, v, k, w));
    if (g.knots > 1) {
        const size_t n = size_t(g.vertexCount());
        for (int kn = 1; kn + 1 < g.knots; ++kn)
            if (knots[kn] > ua && knots[kn] < ub) add(g.knotP[size_t(kn) * n + v]);
        knotSegment(knots, g.knots, ub, k, w);
        add(vertexAt(g, v, k, w));
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
    uint64_t tests = 0;
    auto sampleIndex = [&](int px, int py, int slot) {
        return (size_t(py - reg.y0) * tw + size_t(px - reg.x0)) * spp + size_t(slot);
    };
    for (int j = 0; j < g.nv; ++j) {
        for (int i = 0; i < g.nu; ++i) {
            const int a = j * stride + i;
            const int vid[4] = {a, a + 1, a + stride + 1, a + stride};
            const bool front0 = g.front[vid[0]] | g.front[vid[1]] | g.front[vid[2]] | g.front[vid[3]];
            int64_t sign0 = 1;
            if (!g.twoSided) {
                // Orientation at shutter open from the sharp fixed-point corners.
                const int64_t X0 = g.X[vid[0]], Y0 = g.Y[vid[0]];
                sign0 = (g.X[vid[1]] - X0) * (g.Y[vid[2]] - Y0) - (g.X[vid[2]] - X0) * (g.Y[vid[1]] - Y0);
                if (sign0 == 0) sign0 = 1;
            }
            auto moved = [&](float u, Vec2 lens) {
                int k;
                float w;
                knotSegment(knots, g.knots, u, k, w);
                return moveQuad(g, vid, k, w, lens, pr, nearZ);
            };
            switch (pat.scheme) {
                case BlurSampling::Simple: {
                    for (int s = 0; s < spp; ++s) {
                        const MovedQuad q = moved(pat.time[s], pat.lensPoint[s]);
                        if (!q.valid || !facesCamera(g.twoSided, front0, sign0, q)) continue;
                        const Span sp = pixelSpan(reg, q.minX, q.maxX, q.minY, q.maxY);
                        if (sp.empty()) continue;
                        for (int py = sp.py0; py <= sp.py1; ++py)
                            for (int px = sp.px0; px <= sp.px1; ++px) {
                                const size_t si = sampleIndex(px, py, s);
                                ++tests;
                                if (testSample<kAttributes>(g, vid, q, si, tile, nearZ))
                                    tile.pixelHit[size_t(py - reg.y0) * tw + (px - reg.x0)] = 1;
                            }
                    }
                    break;
                }
                case BlurSampling::Interleaved: {
                    const int K = pat.tileSize, KK = K * K, N = pat.tileSamples();
                    for (int n = 0; n < N; ++n) {
                        const MovedQuad q = moved(pat.time[n], pat.lensPoint[n]);
                        if (!q.valid || !facesCamera(g.twoSided, front0, sign0, q)) continue;
                        const Span sp = pixelSpan(reg, q.minX, q.maxX, q.minY, q.maxY);
                        if (sp.empty()) continue;
                        for (int ty = sp.py0 / K; ty <= sp.py1 / K; ++ty)
                            for (int tx = sp.px0 / K; tx <= sp.px1 / K; ++tx) {
                                const int qn = pat.perm[size_t(pat.tilePermutation(tx, ty)) * N + n];
                                const int inTile = qn % KK, slot = qn / KK;
                                const int px = tx * K + inTile % K, py = ty * K + inTile / K;
                                if (px < sp.px0 || px > sp.px1 || py < sp.py0 || py > sp.py1) continue;
                                const size_t si = sampleIndex(px, py, slot);
                                ++tests;
                                if (testSample<kAttributes>(g, vid, q, si, tile, nearZ))
                                    tile.pixelHit[size_t(py - reg.y0) * tw + (px - reg.x0)] = 1;
                            }
                    }
                    break;
                }
                case BlurSampling::BoundingBox: {
                    const bool cut = ctx.strataBounds && !strata.start.empty();
                    const int T = cut ? strata.timeStrata : 1, L = cut ? strata.lensCells : 1;
                    const int cells = T * L * L;
                    for (int cell = 0; cell < cells; ++cell) {
                        const int tb = cell / (L * L), lc = cell % (L * L);
                        const float ua = float(tb) / T, ub = float(tb + 1) / T;
                        const float lx0 = -1.f + 2.f * float(lc % L) / L, lx1 = -1.f + 2.f * float(lc % L + 1) / L;
                        const float ly0 = -1.f + 2.f * float(lc / L) / L, ly1 = -1.f + 2.f * float(lc / L + 1) / L;
                        bool valid = true;
                        float x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
                        for (int c = 0; c < 4 && valid; ++c)
                            extendVertexBound(g, vid[c], knots, ua, ub, lx0, lx1, ly0, ly1, pr, valid, x0, x1, y0,
                                              y1);
                        // A corner behind the near plane at some time: bound by the samples' own moves
                        // (each moved quad is checked below); use the whole tile.
                        Span sp;
                        if (!valid) {
                            sp = {reg.x0, reg.x1 - 1, reg.y0, reg.y1 - 1};
                        } else {
                            sp = pixelSpan(reg, int64_t(std::floor(x0 * kSubpixelScale)),
                                           int64_t(std::ceil(x1 * kSubpixelScale)),
                                           int64_t(std::floor(y0 * kSubpixelScale)),
                                           int64_t(std::ceil(y1 * kSubpixelScale)));
                        }
                        if (sp.empty()) continue;
                        const int64_t bx0 = int64_t(std::floor(x0 * kSubpixelScale)) - 1,
                                      bx1 = int64_t(std::ceil(x1 * kSubpixelScale)) + 1,
                                      by0 = int64_t(std::floor(y0 * kSubpixelScale)) - 1,
                                      by1 = int64_t(std::ceil(y1 * kSubpixelScale)) + 1;
                        for (int py = sp.py0; py <= sp.py1; ++py)
                            for (int px = sp.px0; px <= sp.px1; ++px) {
                                const size_t pix = size_t(py - reg.y0) * tw + (px - reg.x0);
                                auto visit = [&](int slot) {
                                    const size_t si = pix * spp + size_t(slot);
                                    if (valid && (tile.sx[si] < bx0 || tile.sx[si] > bx1 || tile.sy[si] < by0 ||
                                                  tile.sy[si] > by1))
                                        return;
                                    ++tests;
                                    const MovedQuad q = moved(tile.time[si], tile.lens[si]);
                                    if (!q.valid || !facesCamera(g.twoSided, front0, sign0, q)) return;
                                    if (testSample<kAttributes>(g, vid, q, si, tile, nearZ)) tile.pixelHit[pix] = 1;
                                };
                                if (cut) {
                                    const size_t c0 = pix * cells + cell;
                                    for (uint32_t e = strata.start[c0]; e < strata.start[c0 + 1]; ++e)
                                        visit(strata.slot[e]);
                                } else {
                                    for (int s = 0; s < spp; ++s) visit(s);
                                }
                            }
                    }
                    break;
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
        timeStrata = std::max(1, p.spp / 4);
        lensCells = p.spp >= 4 ? 2 : 1;
    } else if (p.motion) {
        timeStrata = p.spp;
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
