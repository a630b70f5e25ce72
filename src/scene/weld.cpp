#include "scene/weld.h"

#include <cmath>
#include <cstdint>
#include <unordered_map>

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

bool near(Vec3 a, Vec3 b, float tol) {
    return std::fabs(a.x - b.x) <= tol && std::fabs(a.y - b.y) <= tol && std::fabs(a.z - b.z) <= tol;
}

}  // namespace

float defaultWeldTolerance(const std::vector<BezierPatch>& patches) {
    Bounds3 b;
    for (const auto& p : patches) b.extend(hullBounds(p));
    if (b.empty()) return 0.f;
    float d = length(b.diagonal());
    return std::isfinite(d) ? d * 1e-5f : 0.f;
}

void applyWeldPlan(const WeldPlan& plan, std::vector<BezierPatch>& patches) {
    for (const WeldCopy& c : plan) patches[c.dstPatch].cp[c.dstCp] = patches[c.srcPatch].cp[c.srcCp];
}

WeldResult weldSharedEdges(std::vector<BezierPatch>& patches, float tol, WeldPlan* plan) {
    WeldResult result;
    if (!(tol > 0.f)) return result;
    const float cell = tol * 4.f;
    auto keyOf = [&](Vec3 p) {
        return CellKey{int64_t(std::floor(p.x / cell)), int64_t(std::floor(p.y / cell)),
                       int64_t(std::floor(p.z / cell))};
    };
    // 1. Corners: the first corner seen in a cell (or a neighbouring cell) is the representative.
    struct Rep {
        Vec3 p;
        uint32_t patch;
        uint8_t cp;
    };
    std::unordered_map<CellKey, std::vector<Rep>, CellHash> reps;
    reps.reserve(patches.size() * 2);
    static const int kCorners[4] = {0, 3, 12, 15};
    for (uint32_t pi = 0; pi < patches.size(); ++pi) {
        BezierPatch& patch = patches[pi];
        for (int c : kCorners) {
            Vec3& p = patch.cp[c];
            if (!isFinite(p)) continue;
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
            // The point's own cell first (the common case), then the 26 neighbours.
            search(k);
            for (int64_t dx = -1; dx <= 1 && !found; ++dx)
                for (int64_t dy = -1; dy <= 1 && !found; ++dy)
                    for (int64_t dz = -1; dz <= 1 && !found; ++dz)
                        if (dx || dy || dz) search({k.x + dx, k.y + dy, k.z + dz});
            if (found) {
                if (plan) plan->push_back({pi, found->patch, uint8_t(c), found->cp});
                if (!(found->p == p)) {
                    p = found->p;
                    ++result.cornersMoved;
                }
            } else {
                reps[k].push_back({p, pi, uint8_t(c)});
            }
        }
    }
    // 2. Edges: key by their (now exactly shared) end corners, in canonical order.
    struct EdgeRef {
        uint32_t patch;
        int edge;
    };
    struct PairHash {
        size_t operator()(const std::pair<CellKey, CellKey>& k) const {
            CellHash h;
            return h(k.first) * 31 + h(k.second);
        }
    };
    auto lexLess = [](Vec3 a, Vec3 b) {
        if (a.x != b.x) return a.x < b.x;
        if (a.y != b.y) return a.y < b.y;
        return a.z < b.z;
    };
    std::unordered_map<std::pair<CellKey, CellKey>, std::vector<EdgeRef>, PairHash> edges;
    edges.reserve(patches.size() * 3);
    for (uint32_t pi = 0; pi < patches.size(); ++pi) {
        for (int e = 0; e < 4; ++e) {
            BezierPatch& patch = patches[pi];
            Vec3 a = patch.cp[edgeIndex(e, 0)], b = patch.cp[edgeIndex(e, 3)];
            if (!isFinite(a) || !isFinite(b)) continue;
            if (lexLess(b, a)) std::swap(a, b);
            auto key = std::make_pair(keyOf(a), keyOf(b));
            auto& list = edges[key];
            bool welded = false;
            for (const EdgeRef& other : list) {
                const BezierPatch& q = patches[other.patch];
                Vec3 qa = q.cp[edgeIndex(other.edge, 0)], qd = q.cp[edgeIndex(other.edge, 3)];
                Vec3 pa = patch.cp[edgeIndex(e, 0)], pd = patch.cp[edgeIndex(e, 3)];
                bool same = qa == pa && qd == pd, reversed = qa == pd && qd == pa;
                for (int dir = 0; dir < 2 && !welded; ++dir) {
                    if (!(dir == 0 ? same : reversed)) continue;
                    bool match = true;
                    for (int k = 1; k <= 2 && match; ++k)
                        match = near(patch.cp[edgeIndex(e, k)],
                                     q.cp[edgeIndex(other.edge, dir == 0 ? k : 3 - k)], tol);
                    if (!match) continue;
                    bool changed = false;
                    for (int k = 1; k <= 2; ++k) {
                        const int srcCp = edgeIndex(other.edge, dir == 0 ? k : 3 - k);
                        if (plan)
                            plan->push_back({pi, other.patch, uint8_t(edgeIndex(e, k)), uint8_t(srcCp)});
                        Vec3 src = q.cp[srcCp];
                        Vec3& dst = patch.cp[edgeIndex(e, k)];
                        changed |= !(dst == src);
                        dst = src;
                    }
                    if (changed) ++result.edgesWelded;
                    welded = true;
                }
                if (welded) break;
            }
            if (!welded) list.push_back({pi, e});
        }
    }
    return result;
}

}  // namespace tessera
