#include "scene/weld.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <tuple>
#include <unordered_map>

#include "core/buffer_allocator.h"

namespace tessera {
namespace {

// Index of control point k (0..3) along boundary curve e (same order as patchEdge()).
int edgeIndex(int e, int k) {
    switch (e) {
        case 0:
            return k;
        case 1:
            return k * 4 + 3;
        case 2:
            return 12 + k;
        default:
            return k * 4;
    }
}

struct CellKey {
    int64_t x, y, z;
    bool operator==(const CellKey&) const = default;
};
struct CellHash {
    size_t operator()(const CellKey& k) const {
        return size_t(k.x * 73856093) ^ size_t(k.y * 19349663) ^ size_t(k.z * 83492791);
    }
};

// Whether v, in cell `key` of side `side` along its axis, lies within `margin` of the cell's lower and of
// its upper side (offset from float(key) * side, as both uses compute it).
void nearSides(float v, int64_t key, float side, float margin, bool& lower, bool& upper) {
    const float offset = v - float(key) * side;
    lower = offset < margin;
    upper = offset > side - margin;
}

bool near(Vec3 a, Vec3 b, float tol) {
    return std::fabs(a.x - b.x) <= tol && std::fabs(a.y - b.y) <= tol && std::fabs(a.z - b.z) <= tol;
}

}  // namespace

float defaultWeldTolerance(std::span<const BezierPatch> patches) {
    Bounds3 b;
    for (const auto& p : patches) b.extend(hullBounds(p));
    if (b.empty()) return 0.f;
    float d = length(b.diagonal());
    return std::isfinite(d) ? d * 1e-5f : 0.f;
}

void applyWeldPlan(const WeldPlan& plan, std::span<BezierPatch> patches) {
    for (const WeldCopy& c : plan) patches[c.dstPatch].cp[c.dstCp] = patches[c.srcPatch].cp[c.srcCp];
}

WeldResult weldSharedEdges(std::span<BezierPatch> patches, float tol, WeldPlan* plan) {
    WeldResult result;
    if (!(tol > 0.f)) return result;
    // Corner ids (patch * 4 + corner) and a flag share 32 bits below.
    if (patches.size() >= (size_t(1) << 29))
        throw std::length_error("weldSharedEdges: more than 2^29 patches");
    const float cell = tol * 4.f;
    auto keyOf = [&](Vec3 p) {
        return CellKey{int64_t(std::floor(p.x / cell)), int64_t(std::floor(p.y / cell)),
                       int64_t(std::floor(p.z / cell))};
    };
    // 1. Corners, in patch order: a corner within tol of an earlier representative snaps onto it (the
    // first found: own cell first, then the neighbour cells it can reach), else it becomes one.
    struct Rep {
        Vec3 p;
        uint32_t patch;
        uint8_t cp;
    };
    static const int kCorners[4] = {0, 3, 12, 15};
    // Each corner's representative (patch * 4 + corner; itself when it is one, kNoCorner when not finite):
    // the edge pass groups edges by their two corners' representatives.
    constexpr uint32_t kNoCorner = 0xffffffffu;
    std::vector<uint32_t, DefaultInitAllocator<uint32_t>> repOf(patches.size() * 4);
    auto repId = [](const Rep& r) { return r.patch * 4u + (r.cp & 3u ? 1u : 0u) + (r.cp >= 12 ? 2u : 0u); };
    // That pass over corners `ids` (patch * 4 + corner, ascending) with its own table of representatives.
    // Corner c of patch pi (at p) takes representative r: recorded in the plan; 1 when p moved.
    // p: the corner's position (a copy; the patch is written only when the corner moves).
    auto snapOnto = [&](const Rep& r, uint32_t pi, int c, Vec3 p, WeldPlan* out) -> size_t {
        if (out) out->push_back({pi, r.patch, uint8_t(c), r.cp});
        if (r.p == p) return 0;
        patches[pi].cp[c] = r.p;
        return 1;
    };
    const float blockSide = cell * 16.f;
    // A corner as the corner pass sorts it, 32 bytes: its block in 32 bits per axis, clamped (a clamped
    // corner is never "inside": it goes to the pass in patch order), its id with its "inside" flag in the
    // lowest bit, and its position, so that the pass reads the corners in their sorted order instead of
    // from the patches (a cache miss each: the closed blocks' pass took 17 of 70 ms of welding 24 Big Guys).
    // Each corner is snapped once and only its own snap moves it, so the copy is the patch's value then.
    struct CornerItem {
        int32_t bx, by, bz;
        uint32_t idInside;  // (patch * 4 + corner) * 2 + inside
        Vec3 p;
        uint32_t id() const { return idInside >> 1; }
        bool inside() const { return idInside & 1u; }
        bool sameBlock(const CornerItem& o) const { return bx == o.bx && by == o.by && bz == o.bz; }
        bool operator<(const CornerItem& o) const {
            return std::tie(bx, by, bz, idInside) < std::tie(o.bx, o.by, o.bz, o.idInside);
        }
    };
    // A block of a few corners (24 Big Guys: 73 K closed blocks of 4 on average) is searched linearly: a
    // hash table per block cost more in allocation than the search and did not scale with threads. The
    // representative taken is the one the table's search finds first: in the point's own cell, else in the
    // first neighbour cell of its (dx, dy, dz) loop; within a cell the earliest made.
    constexpr size_t kLinearCorners = 32;
    auto snapFew = [&](const CornerItem* items, size_t count, WeldPlan* out) {
        size_t moved = 0;
        struct CellRep {
            Rep rep;
            CellKey key;
        };
        CellRep reps[kLinearCorners];
        size_t nReps = 0;
        for (size_t n = 0; n < count; ++n) {
            const uint32_t id = items[n].id(), pi = id / 4;
            const int c = kCorners[id % 4];
            const Vec3 p = items[n].p;
            const CellKey k = keyOf(p);
            const Rep* found = nullptr;
            int bestRank = 27;
            for (size_t r = 0; r < nReps; ++r) {
                const CellKey& rk = reps[r].key;
                const int64_t dx = rk.x - k.x, dy = rk.y - k.y, dz = rk.z - k.z;
                if (dx < -1 || dx > 1 || dy < -1 || dy > 1 || dz < -1 || dz > 1) continue;
                const int rank = (dx || dy || dz) ? int((dx + 1) * 9 + (dy + 1) * 3 + (dz + 1)) : -1;
                if (rank < bestRank && near(reps[r].rep.p, p, tol)) bestRank = rank, found = &reps[r].rep;
            }
            if (found)
                moved += snapOnto(*found, pi, c, p, out), repOf[id] = repId(*found);
            else
                reps[nReps++] = {{p, pi, uint8_t(c)}, k};
        }
        return moved;
    };
    auto snapCorners = [&](const CornerItem* items, size_t count, WeldPlan* out) {
        if (count <= kLinearCorners) return snapFew(items, count, out);
        size_t moved = 0;
        std::unordered_map<CellKey, std::vector<Rep>, CellHash> reps;
        reps.reserve(count);
        for (size_t n = 0; n < count; ++n) {
            const uint32_t id = items[n].id(), pi = id / 4;
            const int c = kCorners[id % 4];
            const Vec3 p = items[n].p;
            CellKey k = keyOf(p);
            const Rep* found = nullptr;
            auto search = [&](CellKey cellKey) {
                auto it = reps.find(cellKey);
                if (it == reps.end()) return;
                for (const Rep& r : it->second)
                    if (near(r.p, p, tol)) {
                        found = &r;
                        return;
                    }
            };
            // The point's own cell first (the common case), then those of the 26 neighbours that a point
            // within tol can lie in: along each axis, the lower neighbour only when p is near the cell's
            // lower side, the upper one only when near its upper side. "Near" is 1.5 tol, not tol, so
            // that the float rounding of keyOf (about 1e-7 of the coordinate, against tol = 1e-5 of the
            // scene's size) never hides a cell; the cells skipped hold no point within tol, so the same
            // representative is found as when searching all 26.
            search(k);
            auto reach = [&](float v, int64_t kv, int64_t& lo, int64_t& hi) {
                bool lower, upper;
                nearSides(v, kv, cell, 1.5f * tol, lower, upper);
                lo = lower ? -1 : 0, hi = upper ? 1 : 0;
            };
            int64_t x0, x1, y0, y1, z0, z1;
            reach(p.x, k.x, x0, x1), reach(p.y, k.y, y0, y1), reach(p.z, k.z, z0, z1);
            for (int64_t dx = x0; dx <= x1 && !found; ++dx)
                for (int64_t dy = y0; dy <= y1 && !found; ++dy)
                    for (int64_t dz = z0; dz <= z1 && !found; ++dz)
                        if (dx || dy || dz) search({k.x + dx, k.y + dy, k.z + dz});
            if (found)
                moved += snapOnto(*found, pi, c, p, out), repOf[id] = repId(*found);
            else
                reps[k].push_back({p, pi, uint8_t(c)});
        }
        return moved;
    };
    // In parallel by blocks of 16 x 16 x 16 cells: a block whose corners all lie more than 1.5 tol inside
    // it has no corner within tol of one outside, so the pass over its corners alone decides them exactly
    // as the pass over all corners does; the corners of the other blocks take one pass in patch order.
    // (24 Big Guys: 343 K corners.)
    // (A scope of its own: its scratch arrays are freed before the edge pass makes its own.)
    {
        // The corners are grouped by block through buckets keyed by a hash of the block (about 4 corners a
        // bucket), in two levels so that no pass scatters items across the whole array: the buckets come
        // in 256 runs of consecutive buckets; the corners are written from the patches straight into their
        // runs (counted per chunk of patches, then placed, both in parallel); then each run, a few KB, is
        // put in bucket order through a copy, each bucket sorted by block and id, and its closed blocks
        // welded while they are in cache. The blocks come in the buckets' order, the same for any thread
        // count. (Before: an in-place permutation straight into 130 K buckets, each swap a cache and TLB
        // miss, 85% of the weld's serial time on 24 Big Guys.)
        // The item array (several MB) is on huge pages (core/buffer_allocator.h) and not zero-filled.
        const size_t nCornerSlots = patches.size() * 4;
        size_t buckets = 1;
        int bucketBits = 0;
        while (buckets * 4 < nCornerSlots) buckets *= 2, ++bucketBits;
        auto bucketOf = [&](const CornerItem& c) {
            uint64_t h = uint64_t(uint32_t(c.bx)) * 0x9E3779B97F4A7C15ull;
            h = (h ^ uint32_t(c.by)) * 0xC2B2AE3D27D4EB4Full;
            h = (h ^ uint32_t(c.bz)) * 0x165667B19E3779F9ull;
            return size_t((h ^ (h >> 29)) & (buckets - 1));
        };
        const int runShift = std::max(0, bucketBits - 8);
        const size_t runs = buckets >> runShift, runBuckets = size_t(1) << runShift;
        // Corner ci of patch pi as an item; false when it is not finite (it takes part in no weld).
        auto cornerItem = [&](size_t pi, int ci, CornerItem& item) {
            const Vec3 p = patches[pi].cp[kCorners[ci]];
            if (!isFinite(p)) return false;
            bool inside = true;
            auto axis = [&](float v) {
                constexpr double kMax = 2147483647.0;
                const double cellIndex = std::floor(double(v / blockSide));
                const int32_t key = int32_t(std::clamp(cellIndex, -kMax, kMax));
                bool lower, upper;
                nearSides(v, key, blockSide, 1.5f * tol, lower, upper);
                inside = inside && !lower && !upper && std::abs(cellIndex) < kMax;
                return key;
            };
            item.bx = axis(p.x), item.by = axis(p.y), item.bz = axis(p.z);
            item.idInside = uint32_t(pi * 4 + size_t(ci)) * 2u + (inside ? 1u : 0u);
            item.p = p;
            return true;
        };
        constexpr size_t kChunkPatches = 2048;
        const size_t chunks = (patches.size() + kChunkPatches - 1) / kChunkPatches;
        std::vector<uint32_t> cursor(chunks * runs, 0);  // per chunk and run: its count, then its cursor
        tbb::parallel_for(size_t(0), chunks, [&](size_t k) {
            uint32_t* count = cursor.data() + k * runs;
            for (size_t pi = k * kChunkPatches; pi < std::min(patches.size(), (k + 1) * kChunkPatches); ++pi)
                for (int ci = 0; ci < 4; ++ci) {
                    CornerItem item;
                    const bool finite = cornerItem(pi, ci, item);
                    repOf[pi * 4 + size_t(ci)] = finite ? uint32_t(pi * 4 + size_t(ci)) : kNoCorner;
                    if (finite) ++count[bucketOf(item) >> runShift];
                }
        });
        std::vector<uint32_t> runStart(runs + 1);
        uint32_t total = 0;
        for (size_t r = 0; r < runs; ++r) {
            runStart[r] = total;
            for (size_t k = 0; k < chunks; ++k) {
                const uint32_t n = cursor[k * runs + r];
                cursor[k * runs + r] = total;
                total += n;
            }
        }
        runStart[runs] = total;
        std::vector<CornerItem, DefaultInitAllocator<CornerItem>> corners(total);
        tbb::parallel_for(size_t(0), chunks, [&](size_t k) {
            uint32_t* next = cursor.data() + k * runs;
            for (size_t pi = k * kChunkPatches; pi < std::min(patches.size(), (k + 1) * kChunkPatches); ++pi)
                for (int ci = 0; ci < 4; ++ci) {
                    CornerItem item;
                    if (cornerItem(pi, ci, item)) corners[next[bucketOf(item) >> runShift]++] = item;
                }
        });
        // Each run: into bucket order, each bucket sorted, then its blocks. A closed block is welded now; the
        // others' corners go to `runRest`, for the pass in patch order.
        std::vector<WeldPlan> runPlans(plan ? runs : 0);
        std::vector<std::vector<CornerItem>> runRest(runs);
        std::atomic<size_t> cornersMoved{0};
        tbb::parallel_for(size_t(0), runs, [&](size_t run) {
            CornerItem* first = corners.data() + runStart[run];
            const size_t count = runStart[run + 1] - runStart[run];
            std::vector<uint32_t> bucketStart(runBuckets + 1, 0);
            if (runShift > 0) {
                const std::vector<CornerItem> copy(first, first + count);
                for (const CornerItem& c : copy) ++bucketStart[(bucketOf(c) & (runBuckets - 1)) + 1];
                for (size_t b = 0; b < runBuckets; ++b) bucketStart[b + 1] += bucketStart[b];
                std::vector<uint32_t> next(bucketStart.begin(), bucketStart.end() - 1);
                for (const CornerItem& c : copy) first[next[bucketOf(c) & (runBuckets - 1)]++] = c;
            } else {
                bucketStart[1] = uint32_t(count);
            }
            for (size_t b = 0; b < runBuckets; ++b)
                if (bucketStart[b + 1] - bucketStart[b] > 1)
                    std::sort(first + bucketStart[b], first + bucketStart[b + 1]);
            size_t moved = 0;
            for (size_t g = 0; g < count;) {
                size_t gEnd = g + 1;
                bool closed = first[g].inside();
                for (; gEnd < count && first[gEnd].sameBlock(first[g]); ++gEnd)
                    closed = closed && first[gEnd].inside();
                if (closed)
                    moved += snapCorners(first + g, gEnd - g, plan ? &runPlans[run] : nullptr);
                else
                    runRest[run].insert(runRest[run].end(), first + g, first + gEnd);
                g = gEnd;
            }
            cornersMoved += moved;
        });
        std::vector<CornerItem> rest;
        for (const auto& r : runRest) rest.insert(rest.end(), r.begin(), r.end());
        std::sort(rest.begin(), rest.end(),
                  [](const CornerItem& a, const CornerItem& b) { return a.idInside < b.idInside; });
        cornersMoved += snapCorners(rest.data(), rest.size(), plan);
        if (plan)
            for (const WeldPlan& p : runPlans) plan->insert(plan->end(), p.begin(), p.end());
        result.cornersMoved = cornersMoved.load();
    }
    // 2. Edges: keyed by their (now exactly shared) end corners. An edge welds onto the first earlier edge
    // of its key that matches; a weld writes only the edge's two inner control points, which belong to no
    // other edge, and reads only edges of the same key. So the keys are independent: each key's edges are
    // welded in patch order, the keys in parallel (24 Big Guys: 343 K edges), with the same result as one
    // pass in patch order. The key is the pair of the end corners' representatives from the corner pass
    // (lower first): two corners have the same position exactly when they have the same representative
    // (representatives lie more than tol apart, and every corner within tol of one took its position), so
    // this groups the edges as their exact end positions do (-0 and +0 alike), and the grouping is a
    // counting sort by the lower corner, stable (patch order kept), then a sort of each bucket's few edges
    // by the upper one (before: a sort of 28-byte position keys, 60% of the weld's instructions).
    struct EdgeItem {
        uint32_t hi, id;  // the upper representative; patch * 4 + edge
        uint32_t patch() const { return id / 4; }
        int edge() const { return int(id % 4); }
    };
    static constexpr int kEdgeCorners[4][2] = {{0, 1}, {1, 3}, {2, 3}, {0, 2}};  // as edgeIndex(e, 0 / 3)
    const size_t nCorners = patches.size() * 4;
    std::vector<uint32_t> bucketStart(nCorners + 1, 0);  // edges by lower representative
    auto edgeReps = [&](size_t pi, int e, uint32_t& lo, uint32_t& hi) {
        const uint32_t a = repOf[pi * 4 + size_t(kEdgeCorners[e][0])],
                       b = repOf[pi * 4 + size_t(kEdgeCorners[e][1])];
        lo = std::min(a, b), hi = std::max(a, b);
        return a != kNoCorner && b != kNoCorner;
    };
    for (size_t pi = 0; pi < patches.size(); ++pi)
        for (int e = 0; e < 4; ++e) {
            uint32_t lo, hi;
            if (edgeReps(pi, e, lo, hi)) ++bucketStart[lo + 1];
        }
    for (size_t c = 0; c < nCorners; ++c) bucketStart[c + 1] += bucketStart[c];
    std::vector<EdgeItem, DefaultInitAllocator<EdgeItem>> items(bucketStart[nCorners]);
    {
        std::vector<uint32_t> next(bucketStart.begin(), bucketStart.end() - 1);
        for (size_t pi = 0; pi < patches.size(); ++pi)
            for (int e = 0; e < 4; ++e) {
                uint32_t lo, hi;
                if (edgeReps(pi, e, lo, hi)) items[next[lo]++] = {hi, uint32_t(pi * 4 + size_t(e))};
            }
    }
    // Buckets in fixed ranges (the plan's order does not depend on the thread count).
    constexpr size_t kBucketsPerRange = 4096;
    const size_t ranges = (nCorners + kBucketsPerRange - 1) / kBucketsPerRange;
    std::vector<WeldPlan> groupPlans(plan ? ranges : 0);
    std::atomic<size_t> edgesWelded{0};
    tbb::parallel_for(size_t(0), ranges, [&](size_t range) {
        std::vector<const EdgeItem*> list;  // the group's edges that did not weld, in patch order
        size_t welds = 0;
        const size_t b0 = range * kBucketsPerRange, b1 = std::min(nCorners, b0 + kBucketsPerRange);
        for (size_t bucket = b0; bucket < b1; ++bucket) {
            EdgeItem* first = items.data() + bucketStart[bucket];
            EdgeItem* last = items.data() + bucketStart[bucket + 1];
            // By upper representative, patch order kept (a bucket holds the few edges at one corner).
            if (last - first <= 32) {
                for (EdgeItem* it = first + 1; it < last; ++it)
                    for (EdgeItem* j = it; j > first && j[-1].hi > j->hi; --j) std::swap(j[-1], *j);
            } else {  // a corner shared by many edges (a pole of many patches)
                std::sort(first, last, [](const EdgeItem& x, const EdgeItem& y) {
                    return x.hi != y.hi ? x.hi < y.hi : x.id < y.id;
                });
            }
            for (EdgeItem* g = first; g < last;) {
                EdgeItem* gEnd = g + 1;
                while (gEnd < last && gEnd->hi == g->hi) ++gEnd;
                list.clear();
                for (const EdgeItem* item = g; item < gEnd; ++item) {
                    const uint32_t pi = item->patch();
                    const int e = item->edge();
                    BezierPatch& patch = patches[pi];
                    bool welded = false;
                    for (const EdgeItem* other : list) {
                        const BezierPatch& q = patches[other->patch()];
                        Vec3 qa = q.cp[edgeIndex(other->edge(), 0)], qd = q.cp[edgeIndex(other->edge(), 3)];
                        Vec3 pa = patch.cp[edgeIndex(e, 0)], pd = patch.cp[edgeIndex(e, 3)];
                        bool same = qa == pa && qd == pd, reversed = qa == pd && qd == pa;
                        for (int dir = 0; dir < 2 && !welded; ++dir) {
                            if (!(dir == 0 ? same : reversed)) continue;
                            bool match = true;
                            for (int k = 1; k <= 2 && match; ++k)
                                match = near(patch.cp[edgeIndex(e, k)],
                                             q.cp[edgeIndex(other->edge(), dir == 0 ? k : 3 - k)], tol);
                            if (!match) continue;
                            bool changed = false;
                            for (int k = 1; k <= 2; ++k) {
                                const int srcCp = edgeIndex(other->edge(), dir == 0 ? k : 3 - k);
                                if (plan)
                                    groupPlans[range].push_back(
                                        {pi, other->patch(), uint8_t(edgeIndex(e, k)), uint8_t(srcCp)});
                                Vec3 src = q.cp[srcCp];
                                Vec3& dst = patch.cp[edgeIndex(e, k)];
                                changed |= !(dst == src);
                                dst = src;
                            }
                            if (changed) ++welds;
                            welded = true;
                        }
                        if (welded) break;
                    }
                    if (!welded) list.push_back(item);
                }
                g = gEnd;
            }
        }
        edgesWelded += welds;
    });
    result.edgesWelded = edgesWelded.load();
    if (plan)
        for (const WeldPlan& p : groupPlans) plan->insert(plan->end(), p.begin(), p.end());
    return result;
}

}  // namespace tessera
