#include "rt/binning.h"

#include <algorithm>
#include <cmath>

#include "rt/simd_kernels.h"
#include "rt/traversal.h"

namespace tessera::rt {
namespace {

// A patch goes down its tree per ray (descendRootPairs) when its rectangle holds at most this many rays
// per leaf of its tree: there the screen-space descent would test boxes that each cover few rays. Measured
// at 800x600, 4 spp, 2 threads (trace ms, 4 interleaved runs, 2 / 4 / 8 / 16 / all per ray): teapot
// 224 / 201 / 203 / 234 / 313, Killeroo 316 / 297 / 315 / 308 / 345, 24 Big Guys 414 / 326 / 275 / 306 /
// 331; the full screen-space descent (0) 245 / 360 / 911.
constexpr size_t kRootRaysPerLeaf = 8;

// The candidates of a binning stage, found in any order, grouped by ray (counting sort, stable) with each
// ray's candidates sorted by entry distance (stable), in the chunks of kChunk rays the Newton stage
// expects (the traversal's output format). With `originLeaf`, the candidates it drops are removed from
// `found` in the counting pass. `start`, `next`: scratch.
void groupCandidates(CandidateVector& found, size_t n, std::vector<uint32_t>& start,
                     std::vector<uint32_t>& next, std::vector<Chunk>& chunks, uint64_t boxTests,
                     size_t rootPairs, uint64_t slabCulled, const OriginLeafRule* originLeaf,
                     bool sortByEntry = true) {
    const size_t nChunks = (n + kChunk - 1) / kChunk;
    if (chunks.size() < nChunks) chunks.resize(nChunks);
    // start[r]: first candidate of ray r; start[n]: total
    start.assign(n + 1, 0);
    uint64_t originDropped = 0;
    if (originLeaf) {
        size_t kept = 0;
        for (const Candidate& c : found)
            if (!originLeaf->drops(c)) found[kept++] = c, ++start[c.ray + 1];
        originDropped = found.size() - kept;
        found.resize(kept);
    } else {
        for (const Candidate& c : found) ++start[c.ray + 1];
    }
    for (size_t r = 0; r < n; ++r) start[r + 1] += start[r];
    next.assign(start.begin(), start.end() - 1);
    for (size_t ci = 0; ci < nChunks; ++ci) {
        Chunk& ch = chunks[ci];
        const size_t r0 = ci * kChunk, r1 = std::min(n, r0 + kChunk);
        ch.cand.resize(start[r1] - start[r0]);
        ch.segEnd.resize(r1 - r0);
        for (size_t r = r0; r < r1; ++r) ch.segEnd[r - r0] = start[r + 1] - start[r0];
        ch.c = StageCounters();
        ch.c.candidates = ch.cand.size();
    }
    if (nChunks > 0)
        chunks[0].c.boxTests = boxTests, chunks[0].c.rootPairs = rootPairs,
        chunks[0].c.slabCulled = slabCulled, chunks[0].c.originLeafDropped = originDropped;
    for (const Candidate& c : found) {
        const size_t ci = c.ray / kChunk;
        chunks[ci].cand[next[c.ray]++ - start[ci * kChunk]] = c;
    }
    if (!sortByEntry) return;
    for (size_t ci = 0; ci < nChunks; ++ci) {
        Candidate* cd = chunks[ci].cand.data();
        const size_t r0 = ci * kChunk, r1 = std::min(n, r0 + kChunk);
        for (size_t r = r0; r < r1; ++r)
            sortSegmentByEntry(cd, start[r] - start[r0], start[r + 1] - start[r0]);
    }
}

// Visits the leaf boxes of every patch top down, through the 4-wide BVH and then each subpatch tree,
// children in increasing `nearKey(box)` (so each ray's candidates come out nearly sorted), dropping every
// box that `overlaps(box, rect)` rejects (it also yields the box's clipped rectangle) and every subpatch
// node that `skip(patch, node)` rejects; `leaf(patch, node, box, rect)` gets the rest. A patch whose root
// `root(patch, box, rect)` takes (returns true) is not descended.
template <class NearKey, class Overlaps, class Skip, class Root, class Leaf>
void descendCulled(const RtAccel& acc, NearKey&& nearKey, Overlaps&& overlaps, Skip&& skip, Root&& root,
                   Leaf&& leaf) {
    const SubpatchForest& forest = acc.forest;
    const uint32_t firstLeaf = forest.firstLeaf();
    auto visitPatch = [&](uint32_t patch) {
        uint32_t stack[64];
        int sp = 0;
        stack[sp++] = 0;
        while (sp > 0) {
            const uint32_t n = stack[--sp];
            if (skip(patch, n)) continue;
            Rect2 rect;
            const Bounds3 box = forest.nodeBox(patch, n);
            if (!overlaps(box, rect)) continue;
            if (n == 0 && root(patch, box, rect)) continue;
            if (n >= firstLeaf) {
                leaf(patch, n, box, rect);
                continue;
            }
            const bool lowFirst =
                nearKey(forest.nodeBox(patch, 2 * n + 1)) <= nearKey(forest.nodeBox(patch, 2 * n + 2));
            stack[sp++] = lowFirst ? 2 * n + 2 : 2 * n + 1;
            stack[sp++] = lowFirst ? 2 * n + 1 : 2 * n + 2;
        }
    };
    uint32_t stack[kBvh4Stack];
    int sp = 0;
    if (!acc.bvh.wide.empty()) stack[sp++] = 0;
    while (sp > 0) {
        const Bvh4Node& nd = acc.bvh.wide[stack[--sp]];
        Bounds3 box[4];
        float key[4];
        uint32_t order[4] = {0, 1, 2, 3};
        for (uint32_t c = 0; c < nd.count; ++c) {
            box[c].lo = {nd.lo[0][c], nd.lo[1][c], nd.lo[2][c]};
            box[c].hi = {nd.hi[0][c], nd.hi[1][c], nd.hi[2][c]};
            key[c] = nearKey(box[c]);
        }
        for (uint32_t i = 1; i < nd.count; ++i)
            for (uint32_t j = i; j > 0 && key[order[j]] < key[order[j - 1]]; --j)
                std::swap(order[j], order[j - 1]);
        // Patches are visited in this order; inner nodes are pushed far first.
        uint32_t inner[4], nInner = 0;
        for (uint32_t k = 0; k < nd.count; ++k) {
            const uint32_t c = order[k];
            Rect2 rect;
            if (!overlaps(box[c], rect)) continue;
            if (nd.child[c] & kBvh4Patch)
                visitPatch(nd.child[c] & ~kBvh4Patch);
            else
                inner[nInner++] = nd.child[c];
        }
        while (nInner > 0) stack[sp++] = inner[--nInner];
    }
}

// Projector::rasterBounds from the box's extreme corners instead of all eight: raster x is x/z (times sx,
// plus ox), smallest at x = lo.x over the far side (z = hi.z) when lo.x >= 0 and over the near side
// otherwise, largest at x = hi.x likewise (y the same; a negative scale swaps the ends). Each end is the
// expression rasterBounds evaluates at that corner; rounding may leave another corner an ulp beyond it,
// which screenRect's margin covers as it covers the rays' own rounding.
inline bool rasterBoundsFromExtremes(const Projector& proj, const Bounds3& b, float& x0, float& x1, float& y0,
                                     float& y1) {
    float izLoX = 1.f, izHiX = 1.f, izLoY = 1.f, izHiY = 1.f;
    if (proj.perspective) {
        if (!(b.lo.z > 0.f && b.hi.z > 0.f)) return false;  // a corner at or behind the eye
        const float izNear = 1.f / b.lo.z, izFar = 1.f / b.hi.z;
        izLoX = b.lo.x >= 0.f ? izFar : izNear, izHiX = b.hi.x >= 0.f ? izNear : izFar;
        izLoY = b.lo.y >= 0.f ? izFar : izNear, izHiY = b.hi.y >= 0.f ? izNear : izFar;
    }
    const float ax = b.lo.x * izLoX * proj.sx + proj.ox, bx = b.hi.x * izHiX * proj.sx + proj.ox;
    const float ay = b.lo.y * izLoY * proj.sy + proj.oy, by = b.hi.y * izHiY * proj.sy + proj.oy;
    x0 = std::min(ax, bx), x1 = std::max(ax, bx), y0 = std::min(ay, by), y1 = std::max(ay, by);
    return true;
}

// Raster rectangle containing the projection of box b, grown for rounding (the rays' own raster
// positions are rounded too); false when the box reaches behind the eye (no finite rectangle).
inline bool screenRect(const Projector& proj, const Bounds3& b, float& x0, float& x1, float& y0, float& y1) {
    if (!rasterBoundsFromExtremes(proj, b, x0, x1, y0, y1)) return false;
    const float m = 1e-2f + 1e-5f * std::max({std::fabs(x0), std::fabs(x1), std::fabs(y0), std::fabs(y1)});
    x0 -= m, x1 += m, y0 -= m, y1 += m;
    return std::isfinite(x0) && std::isfinite(x1) && std::isfinite(y0) && std::isfinite(y1);
}

// Rays that share one direction (shadow rays towards a distant light): the traversal stage by binning
// in the plane orthogonal to the direction. A ray projects to a point there, and it can only hit a box
// whose projection contains that point, so the rays' points are sorted into a grid, the BVH and subpatch
// boxes are culled top down by their projected bounding rectangles against the points' bounds, and each
// leaf box is slab-tested (the traversal's arithmetic, with its self-intersection cut) against the rays
// in the grid cells its rectangle covers. Candidates are the traversal's; appended to `found` unordered.

bool binParallelRays(const RtAccel& acc, const RayList& rays, size_t r0, size_t r1, ParallelBinning& pb,
                     CandidateVector& found, CandidateVector& roots, uint64_t& boxTests, uint64_t& slabCulled,
                     const Vec3* light = nullptr) {
    const size_t n = r1 - r0;
    if (n == 0) return true;
    // Projection: along the shared direction, or (point light) centrally from the light onto a plane
    // orthogonal to the mean direction from the light to the origins. Every point of a shadow ray lies
    // on the segment from its origin towards the light, so it projects to the origin's point.
    const Vec3 C = light ? *light : Vec3{0, 0, 0};
    Vec3 w;
    if (light) {
        Vec3 sum{0, 0, 0};
        for (size_t r = r0; r < r1; ++r) sum += normalize(rays.o[r] - C);
        w = normalize(sum);
        // Every origin well in front of the light's plane (else: the per-ray traversal).
        for (size_t r = r0; r < r1; ++r) {
            const Vec3 q = rays.o[r] - C;
            if (!(dot(w, q) > 0.05f * length(q))) return false;
        }
    } else {
        w = normalize(rays.d[r0]);
    }
    if (!isFinite(w) || dot(w, w) == 0.f) return false;
    const Vec3 a = std::fabs(w.x) > 0.9f ? Vec3{0, 1, 0} : Vec3{1, 0, 0};
    const Vec3 eu = normalize(cross(a, w)), ev = cross(w, eu);
    auto project = [&](Vec3 x, float& px, float& py) {
        if (light) {
            const Vec3 q = x - C;
            const float iz = 1.f / dot(w, q);
            px = dot(eu, q) * iz, py = dot(ev, q) * iz;
        } else {
            px = dot(eu, x), py = dot(ev, x);
        }
    };
    // Points and their bounds; the grid: about 4 rays per cell.
    float x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
    for (size_t r = r0; r < r1; ++r) {
        float x, y;
        project(rays.o[r], x, y);
        x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
    }
    if (!(std::isfinite(x0) && std::isfinite(x1) && std::isfinite(y0) && std::isfinite(y1))) return false;
    const int g = std::clamp(int(std::sqrt(double(n) / 4.0)), 1, 1024);
    const float cw = std::max((x1 - x0) / float(g), 1e-30f), ch = std::max((y1 - y0) / float(g), 1e-30f);
    auto cellX = [&](float x) { return int(std::clamp((x - x0) / cw, 0.f, float(g - 1))); };
    auto cellY = [&](float y) { return int(std::clamp((y - y0) / ch, 0.f, float(g - 1))); };
    pb.cellStart.assign(size_t(g) * g + 1, 0);
    pb.cellOf.resize(n);
    for (size_t r = r0; r < r1; ++r) {
        float x, y;
        project(rays.o[r], x, y);
        const uint32_t c = uint32_t(cellY(y) * g + cellX(x));
        pb.cellOf[r - r0] = c;
        ++pb.cellStart[c + 1];
    }
    // Summed-area table of the rays per cell: a box whose rectangle covers no ray is culled at once
    // (a tile's points often form separate clusters in the light's view).
    pb.sat.assign(size_t(g + 1) * (g + 1), 0);
    for (int cy = 0; cy < g; ++cy)
        for (int cx = 0; cx < g; ++cx)
            pb.sat[size_t(cy + 1) * (g + 1) + cx + 1] =
                pb.cellStart[size_t(cy) * g + cx + 1] + pb.sat[size_t(cy) * (g + 1) + cx + 1] +
                pb.sat[size_t(cy + 1) * (g + 1) + cx] - pb.sat[size_t(cy) * (g + 1) + cx];
    for (size_t c = 0; c < size_t(g) * g; ++c) pb.cellStart[c + 1] += pb.cellStart[c];
    // Slots 0 .. n - 1 are all written below (the cells' slot ranges partition them); only the padding
    // is set here (the arrays are per-thread scratch: a fill of all of them was a quarter of their cost).
    for (auto* v : {&pb.px, &pb.py, &pb.ox, &pb.oy, &pb.oz, &pb.ix, &pb.iy, &pb.iz, &pb.dx, &pb.dy, &pb.dz,
                    &pb.tmin, &pb.tmax}) {
        v->resize(n + 4);
        std::fill(v->begin() + ptrdiff_t(n), v->end(), 0.f);
    }
    std::fill(pb.px.begin() + ptrdiff_t(n), pb.px.end(), NAN);  // padding: never inside a rectangle
    pb.ray.resize(n + 4), pb.ignore.resize(n + 4);
    std::fill(pb.ray.begin() + ptrdiff_t(n), pb.ray.end(), 0u);
    std::fill(pb.ignore.begin() + ptrdiff_t(n), pb.ignore.end(), kNone);
    {
        std::vector<uint32_t>& next = pb.cellOf;  // reused: cell -> next slot, after reading the cell
        std::vector<uint32_t> slot(pb.cellStart.begin(), pb.cellStart.end() - 1);
        for (size_t r = r0; r < r1; ++r) {
            const uint32_t s = slot[next[r - r0]]++;
            const Vec3 o = rays.o[r], d = rays.d[r];
            const Vec3 inv = safeInverse(d);
            pb.ray[s] = uint32_t(r), pb.ignore[s] = rays.ignore[r];
            project(o, pb.px[s], pb.py[s]);
            pb.ox[s] = o.x, pb.oy[s] = o.y, pb.oz[s] = o.z;
            pb.ix[s] = inv.x, pb.iy[s] = inv.y, pb.iz[s] = inv.z;
            pb.dx[s] = d.x, pb.dy[s] = d.y, pb.dz[s] = d.z;
            pb.tmin[s] = rays.tmin[r], pb.tmax[s] = rays.tmax[r];
        }
    }
    // Where each ray starts along its way (increasing towards the light): a box entirely before the
    // starts of all the rays in its rectangle cannot be hit. Per cell the smallest start, and a min
    // pyramid over the cells (2x2 blocks per level) for rectangles of any size.
    auto startOf = [&](Vec3 p) { return light ? -dot(w, p - C) : dot(w, p); };
    pb.minStart.assign(1, std::vector<float>(size_t(g) * g, INFINITY));
    for (size_t s = 0; s < n; ++s) {
        const uint32_t c = uint32_t(cellY(pb.py[s]) * g + cellX(pb.px[s]));
        float& m = pb.minStart[0][c];
        m = std::min(m, startOf(Vec3{pb.ox[s], pb.oy[s], pb.oz[s]}));
    }
    for (int gk = g; gk > 1;) {
        const int gn = (gk + 1) / 2;
        const std::vector<float>& lower = pb.minStart.back();
        std::vector<float> upper(size_t(gn) * gn, INFINITY);
        for (int y = 0; y < gk; ++y)
            for (int x = 0; x < gk; ++x) {
                float& m = upper[size_t(y / 2) * gn + x / 2];
                m = std::min(m, lower[size_t(y) * gk + x]);
            }
        pb.minStart.push_back(std::move(upper));
        gk = gn;
    }
    auto minStartIn = [&](int cx0, int cx1, int cy0, int cy1) {
        int k = 0;
        while ((cx1 >> k) - (cx0 >> k) > 1 || (cy1 >> k) - (cy0 >> k) > 1) ++k;
        const std::vector<float>& lv = pb.minStart[size_t(k)];
        const int gk = (g + (1 << k) - 1) >> k;
        float m = INFINITY;
        for (int y = cy0 >> k; y <= (cy1 >> k); ++y)
            for (int x = cx0 >> k; x <= (cx1 >> k); ++x) m = std::min(m, lv[size_t(y) * gk + x]);
        return m;
    };
    const Vec3 d = light ? -w : rays.d[r0];  // visit order: nearer boxes along the rays first
    // Point light: the magnitude of the coordinates involved (the light, the origins), for the margins.
    float reach = maxComponent(Vec3{std::fabs(C.x), std::fabs(C.y), std::fabs(C.z)});
    if (light)
        for (size_t r = r0; r < r1; ++r) reach = std::max(reach, length(rays.o[r] - C));
    const float ignoreT = 8.f * acc.offset;
    const SubpatchForest& forest = acc.forest;
    const uint32_t firstLeaf = forest.firstLeaf();

    // The 8 corners of box b: the rectangle of their projections (corners behind the light left out),
    // the range [dlo, dhi] of their depths dot(w, p - C) (point light) or dot(w, p) (distant light: the
    // startOf of each), and how many are not in front of the light. The arithmetic of project() corner by
    // corner (no fused multiply-add), four corners at a time; min and max keep the accumulator where a
    // projection is NaN, as std::min / std::max did.
    struct Corners {
        float rx0, rx1, ry0, ry1, dlo, dhi;
        int behind;
    };
    // Parallel projection (distant light): each of px, py and the depth is linear, so its smallest value
    // over the box is at the corner taking, per axis, lo where the coefficient is positive and hi
    // elsewhere, and its largest at the opposite corner; those two corners' values are the values the
    // corner loop computes for them (same expression). Rounding may put another corner's value an ulp lower
    // or higher; the rectangle's margin (below) covers that as it covers the rays' own projections.
    // Lanes: px (eu), py (ev), depth (w).
#if defined(__SSE2__)
    const __m128 axisX = _mm_setr_ps(eu.x, ev.x, w.x, 0.f), axisY = _mm_setr_ps(eu.y, ev.y, w.y, 0.f),
                 axisZ = _mm_setr_ps(eu.z, ev.z, w.z, 0.f);
    // All bits where the lane's coefficient is positive (its minimum at lo).
    const __m128 posX = _mm_cmpgt_ps(axisX, _mm_setzero_ps()), posY = _mm_cmpgt_ps(axisY, _mm_setzero_ps()),
                 posZ = _mm_cmpgt_ps(axisZ, _mm_setzero_ps());
    auto select = [](__m128 mask, float a, float b) {  // mask ? a : b, lane by lane
        return _mm_or_ps(_mm_and_ps(mask, _mm_set1_ps(a)), _mm_andnot_ps(mask, _mm_set1_ps(b)));
    };
    auto projectParallel = [&](const Bounds3& b) {
        const __m128 lo = _mm_add_ps(_mm_add_ps(_mm_mul_ps(axisX, select(posX, b.lo.x, b.hi.x)),
                                                _mm_mul_ps(axisY, select(posY, b.lo.y, b.hi.y))),
                                     _mm_mul_ps(axisZ, select(posZ, b.lo.z, b.hi.z)));
        const __m128 hi = _mm_add_ps(_mm_add_ps(_mm_mul_ps(axisX, select(posX, b.hi.x, b.lo.x)),
                                                _mm_mul_ps(axisY, select(posY, b.hi.y, b.lo.y))),
                                     _mm_mul_ps(axisZ, select(posZ, b.hi.z, b.lo.z)));
        alignas(16) float l[4], h[4];
        _mm_store_ps(l, lo);
        _mm_store_ps(h, hi);
        return Corners{l[0], h[0], l[1], h[1], l[2], h[2], 0};
    };
#else
    auto projectParallel = [&](const Bounds3& b) {
        auto range = [&](Vec3 a, float& lo, float& hi) {
            lo = dot(a, Vec3{a.x > 0.f ? b.lo.x : b.hi.x, a.y > 0.f ? b.lo.y : b.hi.y,
                             a.z > 0.f ? b.lo.z : b.hi.z});
            hi = dot(a, Vec3{a.x > 0.f ? b.hi.x : b.lo.x, a.y > 0.f ? b.hi.y : b.lo.y,
                             a.z > 0.f ? b.hi.z : b.lo.z});
        };
        Corners k;
        k.behind = 0;
        range(eu, k.rx0, k.rx1);
        range(ev, k.ry0, k.ry1);
        range(w, k.dlo, k.dhi);
        return k;
    };
#endif
    auto projectCorners = [&](const Bounds3& b) {
        if (!light) return projectParallel(b);
        Corners k;
#if defined(__SSE2__)
        const __m128 cx = _mm_setr_ps(b.lo.x, b.hi.x, b.lo.x, b.hi.x),
                     cy = _mm_setr_ps(b.lo.y, b.lo.y, b.hi.y, b.hi.y);
        auto dot4 = [](Vec3 a, __m128 x, __m128 y, __m128 z) {
            return _mm_add_ps(_mm_add_ps(_mm_mul_ps(_mm_set1_ps(a.x), x), _mm_mul_ps(_mm_set1_ps(a.y), y)),
                              _mm_mul_ps(_mm_set1_ps(a.z), z));
        };
        __m128 lx = _mm_set1_ps(INFINITY), hx = _mm_set1_ps(-INFINITY), ly = lx, hy = hx, ld = lx, hd = hx;
        k.behind = 0;
        for (const float z : {b.lo.z, b.hi.z}) {
            __m128 qx = cx, qy = cy, qz = _mm_set1_ps(z);
            if (light) {
                qx = _mm_sub_ps(qx, _mm_set1_ps(C.x));
                qy = _mm_sub_ps(qy, _mm_set1_ps(C.y));
                qz = _mm_sub_ps(qz, _mm_set1_ps(C.z));
            }
            const __m128 depth = dot4(w, qx, qy, qz);
            __m128 px = dot4(eu, qx, qy, qz), py = dot4(ev, qx, qy, qz);
            __m128 front = _mm_castsi128_ps(_mm_set1_epi32(-1));
            if (light) {
                front = _mm_cmpgt_ps(depth, _mm_setzero_ps());
                k.behind += 4 - __builtin_popcount(unsigned(_mm_movemask_ps(front)));
                const __m128 iz = _mm_div_ps(_mm_set1_ps(1.f), depth);
                px = _mm_mul_ps(px, iz), py = _mm_mul_ps(py, iz);
            }
            // _mm_min_ps(a, acc) is (a < acc ? a : acc): std::min(acc, a). Corners behind the light skipped.
            lx = _mm_or_ps(_mm_and_ps(front, _mm_min_ps(px, lx)), _mm_andnot_ps(front, lx));
            hx = _mm_or_ps(_mm_and_ps(front, _mm_max_ps(px, hx)), _mm_andnot_ps(front, hx));
            ly = _mm_or_ps(_mm_and_ps(front, _mm_min_ps(py, ly)), _mm_andnot_ps(front, ly));
            hy = _mm_or_ps(_mm_and_ps(front, _mm_max_ps(py, hy)), _mm_andnot_ps(front, hy));
            ld = _mm_min_ps(depth, ld), hd = _mm_max_ps(depth, hd);
        }
        auto hmin = [](__m128 v) {
            v = _mm_min_ps(v, _mm_shuffle_ps(v, v, _MM_SHUFFLE(1, 0, 3, 2)));
            return _mm_cvtss_f32(_mm_min_ps(v, _mm_shuffle_ps(v, v, _MM_SHUFFLE(2, 3, 0, 1))));
        };
        auto hmax = [](__m128 v) {
            v = _mm_max_ps(v, _mm_shuffle_ps(v, v, _MM_SHUFFLE(1, 0, 3, 2)));
            return _mm_cvtss_f32(_mm_max_ps(v, _mm_shuffle_ps(v, v, _MM_SHUFFLE(2, 3, 0, 1))));
        };
        k.rx0 = hmin(lx), k.rx1 = hmax(hx), k.ry0 = hmin(ly), k.ry1 = hmax(hy);
        k.dlo = hmin(ld), k.dhi = hmax(hd);
#else
        k = {INFINITY, -INFINITY, INFINITY, -INFINITY, INFINITY, -INFINITY, 0};
        for (int c = 0; c < 8; ++c) {
            const Vec3 p{c & 1 ? b.hi.x : b.lo.x, c & 2 ? b.hi.y : b.lo.y, c & 4 ? b.hi.z : b.lo.z};
            const float depth = light ? dot(w, p - C) : dot(w, p);
            k.dlo = std::min(k.dlo, depth), k.dhi = std::max(k.dhi, depth);
            if (light && !(depth > 0.f)) {
                ++k.behind;
                continue;
            }
            float x, y;
            project(p, x, y);
            k.rx0 = std::min(k.rx0, x), k.rx1 = std::max(k.rx1, x);
            k.ry0 = std::min(k.ry0, y), k.ry1 = std::max(k.ry1, y);
        }
#endif
        return k;
    };
    // Projected bounding rectangle of a box, grown for rounding, clipped to the points' bounds.
    auto overlaps = [&](const Bounds3& b, Rect2& rect) {
        const Corners k = projectCorners(b);
        if (k.behind == 8) return false;  // behind the light: no segment towards it gets there
        if (k.behind > 0) {               // around the light's plane: any ray may hit it
            rect = {x0, x1, y0, y1};
            return true;
        }
        float rx0 = k.rx0, rx1 = k.rx1, ry0 = k.ry0, ry1 = k.ry1;
        float m = 1e-5f * std::max({std::fabs(rx0), std::fabs(rx1), std::fabs(ry0), std::fabs(ry1), rx1 - rx0,
                                    ry1 - ry0}) +
                  1e-30f;
        // Central projection: rounding of a ray point at distance h from the light moves its projection by
        // ~ulp(coordinates) / h, largest at the box's nearest corner (h = dlo).
        if (light) m += 1e-6f * reach / k.dlo;
        rx0 -= m, rx1 += m, ry0 -= m, ry1 += m;
        rect = {rx0, rx1, ry0, ry1};
        if (!(std::isfinite(rx0) && std::isfinite(rx1) && std::isfinite(ry0) && std::isfinite(ry1))) {
            rect = {x0, x1, y0, y1};  // (nearly) on the light's plane: any ray may hit it
            return true;
        }
        if (!(rx0 <= x1 && rx1 >= x0 && ry0 <= y1 && ry1 >= y0)) return false;
        const int cx0 = cellX(rx0), cx1 = cellX(rx1), cy0 = cellY(ry0), cy1 = cellY(ry1);
        const size_t G = size_t(g) + 1;
        if (pb.sat[size_t(cy1 + 1) * G + cx1 + 1] - pb.sat[size_t(cy0) * G + cx1 + 1] -
                pb.sat[size_t(cy1 + 1) * G + cx0] + pb.sat[size_t(cy0) * G + cx0] ==
            0)
            return false;  // no ray in the rectangle
        // Box entirely before every start in the rectangle (margin for rounding). startOf is -depth for a
        // point light, depth for a distant one.
        const float reachOfBox = light ? -k.dlo : k.dhi, mag = std::max(std::fabs(k.dlo), std::fabs(k.dhi));
        const float first = minStartIn(cx0, cx1, cy0, cy1);
        return !(reachOfBox < first - (1e-5f * (mag + std::fabs(first)) + 1e-30f));
    };
    // Near side of a box along the direction (visit order, so that candidates come out nearly sorted).
    auto nearDepth = [&](const Bounds3& b) {
        return (d.x > 0 ? b.lo.x : b.hi.x) * d.x + (d.y > 0 ? b.lo.y : b.hi.y) * d.y +
               (d.z > 0 ? b.lo.z : b.hi.z) * d.z;
    };
    // The rays in the cells of `rect` against one box, into `out` as candidates of leaf `leaf`; with
    // `slab` (the leaf's slab group), the rays that do not cross the leaf's slab inside its box dropped.
    auto testBox = [&](CandidateVector& out, uint32_t patch, uint32_t leaf, const Bounds3& box,
                       const Rect2& rect, const LeafSlab4* slab = nullptr) {
        const int cx0 = cellX(rect.x0), cx1 = cellX(rect.x1), cy0 = cellY(rect.y0), cy1 = cellY(rect.y1);
#if defined(__SSE2__)
        const LeafBox4 b4(box, rect);
        const __m128 vself = _mm_set1_ps(ignoreT);
        const __m128i vpatch = _mm_set1_epi32(int32_t(patch));
#endif
        for (int cy = cy0; cy <= cy1; ++cy) {
            const size_t b = pb.cellStart[size_t(cy) * g + cx0], e = pb.cellStart[size_t(cy) * g + cx1 + 1];
            if (b == e) continue;
            boxTests += e - b;
            size_t k = out.size();
            out.resize(k + (e - b) + 4);
#if defined(__SSE2__)
            for (size_t i = b; i < e; i += 4) {
                // Four rays of the covered cells often all lie outside a small box's rectangle: then the
                // slab test is skipped.
                const __m128 px = _mm_loadu_ps(&pb.px[i]), py = _mm_loadu_ps(&pb.py[i]);
                if (!_mm_movemask_ps(insideRect4(b4, px, py))) continue;
                __m128 te, tx;
                const __m128 hit = leafBox4Hits(b4, px, py, _mm_loadu_ps(&pb.ox[i]), _mm_loadu_ps(&pb.oy[i]),
                                                _mm_loadu_ps(&pb.oz[i]), _mm_loadu_ps(&pb.ix[i]),
                                                _mm_loadu_ps(&pb.iy[i]), _mm_loadu_ps(&pb.iz[i]),
                                                _mm_loadu_ps(&pb.tmin[i]), _mm_loadu_ps(&pb.tmax[i]), te, tx);
                // The ray's own patch: boxes it leaves before the self-intersection distance are skipped.
                const __m128 own = _mm_castsi128_ps(_mm_cmpeq_epi32(
                    _mm_loadu_si128(reinterpret_cast<const __m128i*>(&pb.ignore[i])), vpatch));
                const __m128 selfCut = _mm_and_ps(own, _mm_cmplt_ps(tx, vself));
                int mask = _mm_movemask_ps(_mm_andnot_ps(selfCut, hit));
                if (e - i < 4) mask &= (1 << (e - i)) - 1;
                if (mask && slab) {
                    const int kept = mask & slabKeepRays4(*slab, int(leaf & 3), _mm_loadu_ps(&pb.ox[i]),
                                                          _mm_loadu_ps(&pb.oy[i]), _mm_loadu_ps(&pb.oz[i]),
                                                          _mm_loadu_ps(&pb.dx[i]), _mm_loadu_ps(&pb.dy[i]),
                                                          _mm_loadu_ps(&pb.dz[i]), te, tx);
                    slabCulled += kPop4[mask] - kPop4[kept];
                    mask = kept;
                }
                if (mask) k += emitLanes(out.data() + k, mask, te, &pb.ray[i], patch, leaf);
            }
#else
            for (size_t i = b; i < e; ++i) {
                if (!(pb.px[i] >= rect.x0 && pb.px[i] <= rect.x1 && pb.py[i] >= rect.y0 &&
                      pb.py[i] <= rect.y1))
                    continue;
                float te, tx;
                if (!rayBoxInterval(box, {pb.ox[i], pb.oy[i], pb.oz[i]}, {pb.ix[i], pb.iy[i], pb.iz[i]},
                                    pb.tmin[i], pb.tmax[i], te, tx))
                    continue;
                if (pb.ignore[i] == patch && tx < ignoreT) continue;
                const Vec3 o{pb.ox[i], pb.oy[i], pb.oz[i]};
                if (slab && !slabKeep1(*slab, int(leaf & 3), o, {pb.dx[i], pb.dy[i], pb.dz[i]},
                                       slabRayMargin(o), te, tx)) {
                    ++slabCulled;
                    continue;
                }
                out[k++] = {pb.ray[i], patch, leaf, te};
            }
#endif
            out.resize(k);
        }
    };
    // A patch whose rectangle holds few rays compared with its leaves: its rays are tested against its
    // root box here and go down its tree one by one (descendRootPairs), which costs less than projecting
    // its subpatch boxes for them.
    const size_t leaves = size_t(firstLeaf) + 1;
    auto root = [&](uint32_t patch, const Bounds3& box, const Rect2& rect) {
        const int cx0 = cellX(rect.x0), cx1 = cellX(rect.x1), cy0 = cellY(rect.y0), cy1 = cellY(rect.y1);
        const size_t G = size_t(g) + 1;
        const size_t inRect = pb.sat[size_t(cy1 + 1) * G + cx1 + 1] - pb.sat[size_t(cy0) * G + cx1 + 1] -
                              pb.sat[size_t(cy1 + 1) * G + cx0] + pb.sat[size_t(cy0) * G + cx0];
        if (inRect > kRootRaysPerLeaf * leaves) return false;
        testBox(roots, patch, 0, box, rect);
        return true;
    };
    descendCulled(
        acc, nearDepth, overlaps, [](uint32_t, uint32_t) { return false; }, root,
        [&](uint32_t patch, uint32_t node, const Bounds3& box, const Rect2& rect) {
            const uint32_t leaf = node - firstLeaf;
            const LeafSlab4* slabs = forest.slabGroups(patch);  // (binning runs without instancing)
            testBox(found, patch, leaf, box, rect, slabs ? slabs + (leaf >> 2) : nullptr);
        });
    return true;
}

}  // namespace

// Camera rays: the traversal stage by screen-space binning. A camera ray passes through its sample's
// raster position, so it can only hit a box whose projection contains that position. The tile's region is
// tested against the projected bounding rectangles of the 4-wide BVH's boxes and of the subpatch boxes,
// top down, and each leaf box is slab-tested (the traversal's arithmetic) only against the rays of the
// samples inside its rectangle. A ray hits a leaf box only if it hits every box above it (they contain
// it), so the candidates are exactly the traversal's, found once per tile and box instead of once per
// ray and box; ties in entry distance keep this stage's order instead of the traversal's.
void binCameraRays(const RtAccel& acc, const RayList& rays, const CameraSamples& cs, BinningScratch& bin,
                   std::vector<Chunk>& chunks, bool cull) {
    const Projector& proj = *cs.proj;
    const PixelRect reg = cs.region;
    const int tw = reg.width(), spp = cs.spp;
    const float rx0 = float(reg.x0), rx1 = float(reg.x1), ry0 = float(reg.y0), ry1 = float(reg.y1);
    const SubpatchForest& forest = acc.forest;
    const uint32_t firstLeaf = forest.firstLeaf();
    const bool useBack = cull && !forest.backfacing.empty();
    CandidateVector& found = bin.found;
    found.clear();
    bin.roots.clear();
    uint64_t boxTests = 0, slabCulled = 0;

    // Whether the rectangle of box b can hold a sample of the tile, and the rectangle clipped to the
    // region (the whole region when the box reaches behind the eye).
    // With a lens (depth of field, paper 002, sec. 5.3.4) a camera ray starts at lens point a and passes
    // through its sample's focal-plane point: at depth z the eye sees it at the sample's raster position
    // plus a (1/z - 1/fd) (raster units), so a box is hit only by samples within the largest circle of
    // confusion over its depths of its rectangle (|1/z - 1/fd| is largest at its nearest or farthest z).
    const bool lens = proj.hasLens() && proj.perspective;
    auto overlaps = [&](const Bounds3& b, Rect2& rect) {
        if (!screenRect(proj, b, rect.x0, rect.x1, rect.y0, rect.y1)) {
            rect = {rx0, rx1, ry0, ry1};
            return true;
        }
        if (lens) {
            const float k = proj.maxLensCoefficient(b.lo.z, b.hi.z);
            const float gx = k * std::fabs(proj.sx) * 1.0001f + 1e-3f,
                        gy = k * std::fabs(proj.sy) * 1.0001f + 1e-3f;
            rect.x0 -= gx, rect.x1 += gx, rect.y0 -= gy, rect.y1 += gy;
        }
        rect = {std::max(rect.x0, rx0), std::min(rect.x1, rx1), std::max(rect.y0, ry0),
                std::min(rect.y1, ry1)};
        return rect.x0 <= rect.x1 && rect.y0 <= rect.y1;
    };
    // The rays of the samples inside the rectangle against one leaf box, four samples of a row at a time
    // (per-sample structure of arrays; camera rays start at z = 0).
    const float tmin = proj.nearClip, tmax = proj.farClip;
    auto testBox = [&](CandidateVector& out, uint32_t patch, uint32_t leaf, const Bounds3& box,
                       const Rect2& rect, const LeafSlab4* slab = nullptr) {
        const int px0 = std::max(reg.x0, int(std::floor(rect.x0))),
                  px1 = std::min(reg.x1 - 1, int(std::floor(rect.x1)));
        const int py0 = std::max(reg.y0, int(std::floor(rect.y0))),
                  py1 = std::min(reg.y1 - 1, int(std::floor(rect.y1)));
        if (px0 > px1 || py0 > py1) return;
        // Room for every sample of the rectangle's rows plus a full group of 4 (trimmed at the end).
        size_t k = out.size();
        out.resize(k + size_t(px1 - px0 + 1) * size_t(py1 - py0 + 1) * size_t(spp) + 4);
#if defined(__SSE2__)
        const LeafBox4 b4(box, rect);
        const __m128 t0 = _mm_set1_ps(tmin), t1 = _mm_set1_ps(tmax), zero = _mm_setzero_ps();
#endif
        for (int py = py0; py <= py1; ++py) {
            const size_t rowBase = (size_t(py - reg.y0) * tw + size_t(px0 - reg.x0)) * spp;
            const size_t rowEnd = rowBase + size_t(px1 - px0 + 1) * spp;
            boxTests += rowEnd - rowBase;
#if defined(__SSE2__)
            for (size_t i = rowBase; i < rowEnd; i += 4) {
                __m128 te, tx;
                const __m128 hit =
                    leafBox4Hits(b4, _mm_loadu_ps(&cs.sampleX[i]), _mm_loadu_ps(&cs.sampleY[i]),
                                 _mm_loadu_ps(&cs.originX[i]), _mm_loadu_ps(&cs.originY[i]), zero,
                                 _mm_loadu_ps(&cs.invX[i]), _mm_loadu_ps(&cs.invY[i]),
                                 _mm_loadu_ps(&cs.invZ[i]), t0, t1, te, tx);
                int mask = _mm_movemask_ps(hit);
                if (rowEnd - i < 4) mask &= (1 << (rowEnd - i)) - 1;
                if (mask && slab) {
                    const int kept =
                        mask & slabKeepRays4(*slab, int(leaf & 3), _mm_loadu_ps(&cs.originX[i]),
                                             _mm_loadu_ps(&cs.originY[i]), zero, _mm_loadu_ps(&cs.dirX[i]),
                                             _mm_loadu_ps(&cs.dirY[i]), _mm_loadu_ps(&cs.dirZ[i]), te, tx);
                    slabCulled += kPop4[mask] - kPop4[kept];
                    mask = kept;
                }
                if (mask) k += emitLanes(out.data() + k, mask, te, &cs.rayOfSample[i], patch, leaf);
            }
#else
            for (size_t i = rowBase; i < rowEnd; ++i) {
                const uint32_t ray = cs.rayOfSample[i];
                const float x = cs.sampleX[i], y = cs.sampleY[i];
                if (ray == kNone || !(x >= rect.x0 && x <= rect.x1 && y >= rect.y0 && y <= rect.y1)) continue;
                float te, tx;
                if (!rayBoxInterval(box, rays.o[ray], safeInverse(rays.d[ray]), tmin, tmax, te, tx)) continue;
                if (slab && !slabKeep1(*slab, int(leaf & 3), rays.o[ray], rays.d[ray],
                                       slabRayMargin(rays.o[ray]), te, tx)) {
                    ++slabCulled;
                    continue;
                }
                out[k++] = {ray, patch, leaf, te};
            }
#endif
        }
        out.resize(k);
    };
    // A patch whose rectangle holds few samples compared with its leaves: its samples are tested against
    // its root box here and their rays go down its tree one by one (descendRootPairs), which costs less
    // than projecting its subpatch boxes for them (Big Guy at 800x600: about 40 samples per patch
    // against 64 leaves).
    const size_t leaves = size_t(firstLeaf) + 1;
    auto root = [&](uint32_t patch, const Bounds3& box, const Rect2& rect) {
        const float w = std::floor(rect.x1) - std::floor(rect.x0) + 1.f,
                    h = std::floor(rect.y1) - std::floor(rect.y0) + 1.f;
        if (w * h * float(spp) > float(kRootRaysPerLeaf * leaves)) return false;
        testBox(bin.roots, patch, 0, box, rect);
        return true;
    };
    // Nearer boxes (smaller depth) first; back-facing subpatch nodes skipped (--cull-backfaces).
    descendCulled(
        acc, [](const Bounds3& b) { return b.lo.z; }, overlaps,
        [&](uint32_t patch, uint32_t n) {
            const uint8_t* back = useBack ? forest.backfaceBits(patch) : nullptr;
            return back && back[n];
        },
        root,
        [&](uint32_t patch, uint32_t node, const Bounds3& box, const Rect2& rect) {
            const uint32_t leaf = node - firstLeaf;
            const LeafSlab4* slabs = forest.slabGroups(patch);  // (binning runs without instancing)
            testBox(found, patch, leaf, box, rect, slabs ? slabs + (leaf >> 2) : nullptr);
        });
    if (!bin.roots.empty()) descendRootPairs(acc, rays, bin.roots, cull, found, boxTests, slabCulled);

    groupCandidates(found, rays.size(), bin.start, bin.next, chunks, boxTests, bin.roots.size(), slabCulled,
                    nullptr);  // camera rays have no originating patch
}

bool binShadowRays(const RtAccel& acc, const RayList& rays, std::span<const ShadowRun> runs,
                   BinningScratch& bin, std::vector<Chunk>& chunks) {
    bin.found.clear();
    bin.roots.clear();
    uint64_t boxTests = 0, slabCulled = 0;
    bool binned = true;
    for (const ShadowRun& run : runs)
        binned = binned && binParallelRays(acc, rays, run.begin, run.end, bin.parallel, bin.found, bin.roots,
                                           boxTests, slabCulled, run.point ? &run.position : nullptr);
    if (binned && !bin.roots.empty())
        descendRootPairs(acc, rays, bin.roots, false, bin.found, boxTests, slabCulled);
    // Shadow rays stop at any accepted hit: their candidates need no order.
    if (binned) {
        const OriginLeafRule originLeaf(acc, rays);
        groupCandidates(bin.found, rays.size(), bin.start, bin.next, chunks, boxTests, bin.roots.size(),
                        slabCulled, &originLeaf, /*sortByEntry=*/false);
    }
    return binned;
}

}  // namespace tessera::rt
