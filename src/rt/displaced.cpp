#include "rt/displaced.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <mutex>

namespace tessera {
namespace {

// The subpatch leaf (of a tree of `depth`, subpatch_tree.h: level k halves u when k is even, v when odd)
// whose (u,v) rectangle holds (u,v).
uint32_t leafOf(int depth, float u, float v) {
    uint32_t leaf = 0;
    float u0 = 0.f, du = 1.f, v0 = 0.f, dv = 1.f;
    for (int k = 0; k < depth; ++k) {
        uint32_t bit;
        if ((k & 1) == 0) {
            du *= 0.5f;
            bit = u >= u0 + du ? 1u : 0u;
            u0 += float(bit) * du;
        } else {
            dv *= 0.5f;
            bit = v >= v0 + dv ? 1u : 0u;
            v0 += float(bit) * dv;
        }
        leaf = (leaf << 1) | bit;
    }
    return leaf;
}

// Grow a box so that rays through shared edges and flat (zero-thickness) boxes are not lost to rounding
// in the slab test (as the subpatch boxes, subpatch_tree.h enlargedHull).
Bounds3 grown(Bounds3 b, float margin) {
    const Vec3 m{margin, margin, margin};
    b.lo = b.lo - m, b.hi = b.hi + m;
    return b;
}

struct BuildTri {
    Bounds3 box;
    Vec3 centre;
    uint32_t index;
};

// A median-split BVH over tris[begin, end) (at most 4 triangles per leaf), nodes appended depth first.
uint32_t buildNode(std::vector<BuildTri>& tris, size_t begin, size_t end, float margin,
                   std::vector<TriBvhNode>& nodes) {
    const uint32_t self = uint32_t(nodes.size());
    nodes.emplace_back();
    Bounds3 box, centres;
    for (size_t i = begin; i < end; ++i) box.extend(tris[i].box), centres.extend(tris[i].centre);
    nodes[self].box = grown(box, margin);
    if (end - begin <= 4) {
        nodes[self].index = uint32_t(begin);
        nodes[self].count = uint32_t(end - begin);
        return self;
    }
    const Vec3 d = centres.diagonal();
    const int axis = d.x >= d.y && d.x >= d.z ? 0 : (d.y >= d.z ? 1 : 2);
    const size_t mid = (begin + end) / 2;
    std::nth_element(
        tris.begin() + long(begin), tris.begin() + long(mid), tris.begin() + long(end),
        [axis](const BuildTri& a, const BuildTri& b) { return a.centre[axis] < b.centre[axis]; });
    buildNode(tris, begin, mid, margin, nodes);
    const uint32_t right = buildNode(tris, mid, end, margin, nodes);
    nodes[self].index = right;
    nodes[self].count = 0;
    return self;
}

}  // namespace

WatertightRay makeWatertightRay(const Ray& ray) {
    WatertightRay r;
    const Vec3 a{std::fabs(ray.d.x), std::fabs(ray.d.y), std::fabs(ray.d.z)};
    r.kz = a.x >= a.y && a.x >= a.z ? 0 : (a.y >= a.z ? 1 : 2);
    r.kx = (r.kz + 1) % 3;
    r.ky = (r.kx + 1) % 3;
    if (ray.d[r.kz] < 0.f) std::swap(r.kx, r.ky);  // keep the winding
    r.Sx = ray.d[r.kx] / ray.d[r.kz];
    r.Sy = ray.d[r.ky] / ray.d[r.kz];
    r.Sz = 1.f / ray.d[r.kz];
    r.o = ray.o;
    r.inv = safeInverse(ray.d);
    return r;
}

void buildDisplacedMesh(MicroGrid&& grid, int depth, DisplacedMesh& out, std::vector<Bounds3>& leafBoxes) {
    const uint32_t leaves = 1u << depth;
    const size_t nt = grid.tri.size() / 3;
    Bounds3 all;
    for (const Vec3& p : grid.P) all.extend(p);
    float mag = 0.f;
    if (!all.empty())
        for (int k = 0; k < 3; ++k) mag = std::max({mag, std::fabs(all.lo[k]), std::fabs(all.hi[k])});
    const float margin = all.empty() ? 0.f : 1e-5f * maxComponent(all.diagonal()) + 4e-7f * mag;
    // Triangles by leaf (counting sort), then per leaf its BVH.
    std::vector<uint32_t> leafOfTri(nt), start(leaves + 1, 0);
    std::vector<BuildTri> tris(nt);
    for (size_t t = 0; t < nt; ++t) {
        const Vec3 a = grid.P[grid.tri[3 * t]], b = grid.P[grid.tri[3 * t + 1]],
                   c = grid.P[grid.tri[3 * t + 2]];
        const Vec2 ua = grid.uv[grid.tri[3 * t]], ub = grid.uv[grid.tri[3 * t + 1]],
                   uc = grid.uv[grid.tri[3 * t + 2]];
        leafOfTri[t] = leafOf(depth, (ua.x + ub.x + uc.x) / 3.f, (ua.y + ub.y + uc.y) / 3.f);
        ++start[leafOfTri[t] + 1];
        BuildTri& bt = tris[t];
        bt.box.extend(a), bt.box.extend(b), bt.box.extend(c);
        bt.centre = bt.box.center();
        bt.index = uint32_t(t);
    }
    for (uint32_t l = 0; l < leaves; ++l) start[l + 1] += start[l];
    std::vector<BuildTri> sorted(nt);
    {
        std::vector<uint32_t> fill(start.begin(), start.end() - 1);
        for (size_t t = 0; t < nt; ++t) sorted[fill[leafOfTri[t]]++] = tris[t];
    }
    out.nodes.clear();
    out.leafRoot.assign(leaves, 0xffffffffu);
    leafBoxes.assign(leaves, Bounds3());
    for (uint32_t l = 0; l < leaves; ++l) {
        if (start[l] == start[l + 1]) {
            // No triangle: a point box (an empty box would pass the slab test), which holds nothing.
            const Vec3 p = grid.P.empty() ? Vec3{} : grid.P[0];
            leafBoxes[l].lo = leafBoxes[l].hi = p;
            continue;
        }
        const uint32_t root = buildNode(sorted, start[l], start[l + 1], margin, out.nodes);
        out.leafRoot[l] = root;
        leafBoxes[l] = out.nodes[root].box;
    }
    out.tri.resize(3 * nt);
    for (size_t t = 0; t < nt; ++t)
        for (int k = 0; k < 3; ++k) out.tri[3 * t + k] = grid.tri[3 * size_t(sorted[t].index) + k];
    out.P = std::move(grid.P);
    out.N = std::move(grid.N);
    out.uv = std::move(grid.uv);
    out.P.shrink_to_fit(), out.N.shrink_to_fit(), out.uv.shrink_to_fit(), out.nodes.shrink_to_fit();
}

}  // namespace tessera

namespace tessera {

struct DisplacedGrids::Slot {
    std::atomic<std::shared_ptr<const DisplacedMesh>> mesh;
    std::mutex building;
    std::atomic<uint64_t> lastUse{0};
    size_t bytes = 0;  // of its grid when built (estimated from the (u,v) pass until then)
};

struct DisplacedGrids::Shared {
    std::mutex evicting;
    std::atomic<uint64_t> clock{0}, builds{0}, evictions{0};
    std::atomic<size_t> resident{0}, peak{0};
};

DisplacedGrids::DisplacedGrids() = default;
DisplacedGrids::~DisplacedGrids() = default;
DisplacedGrids::DisplacedGrids(DisplacedGrids&&) noexcept = default;
DisplacedGrids& DisplacedGrids::operator=(DisplacedGrids&&) noexcept = default;

size_t DisplacedGrids::residentBytes() const {
    return shared_ ? shared_->resident.load() : 0;
}
size_t DisplacedGrids::peakBytes() const {
    return shared_ ? shared_->peak.load() : 0;
}
uint64_t DisplacedGrids::builds() const {
    return shared_ ? shared_->builds.load() : 0;
}
uint64_t DisplacedGrids::evictions() const {
    return shared_ ? shared_->evictions.load() : 0;
}

std::shared_ptr<const DisplacedMesh> DisplacedGrids::mesh(uint32_t patch) const {
    if (slotOf_.empty() || slotOf_[patch] == kNone) return nullptr;
    const uint32_t s = slotOf_[patch];
    Slot& slot = slots_[s];
    if (lazy_)
        slot.lastUse.store(shared_->clock.fetch_add(1, std::memory_order_relaxed), std::memory_order_relaxed);
    std::shared_ptr<const DisplacedMesh> m = slot.mesh.load(std::memory_order_acquire);
    if (m) return m;
    return build(s);
}

std::shared_ptr<const DisplacedMesh> DisplacedGrids::build(uint32_t s) const {
    Slot& slot = slots_[s];
    std::shared_ptr<const DisplacedMesh> m;
    {
        const std::lock_guard<std::mutex> lock(slot.building);
        m = slot.mesh.load(std::memory_order_acquire);
        if (m) return m;
        MicroGrid grid;
        dicer_->dice(patchOf_[s], grid);
        auto mesh = std::make_shared<DisplacedMesh>();
        std::vector<Bounds3> leaves;
        buildDisplacedMesh(std::move(grid), depth_, *mesh, leaves);
        slot.bytes = mesh->bytes();
        m = mesh;
        slot.mesh.store(m, std::memory_order_release);
    }
    Shared& sh = *shared_;
    sh.builds.fetch_add(1, std::memory_order_relaxed);
    const size_t now = sh.resident.fetch_add(slot.bytes) + slot.bytes;
    // Over the budget: drop the least recently used other grids until under it (readers keep theirs).
    if (now > budget_) {
        const std::lock_guard<std::mutex> lock(sh.evicting);
        std::vector<std::pair<uint64_t, uint32_t>> resident;
        for (uint32_t o = 0; o < slotCount_; ++o)
            if (o != s && slots_[o].mesh.load(std::memory_order_relaxed))
                resident.push_back({slots_[o].lastUse.load(std::memory_order_relaxed), o});
        std::sort(resident.begin(), resident.end());
        for (const auto& [use, o] : resident) {
            if (sh.resident.load() <= budget_) break;
            Slot& victim = slots_[o];
            const std::lock_guard<std::mutex> vlock(victim.building);
            if (victim.mesh.exchange(nullptr)) {
                sh.resident.fetch_sub(victim.bytes);
                sh.evictions.fetch_add(1, std::memory_order_relaxed);
            }
        }
    }
    size_t peak = sh.peak.load();
    const size_t cur = sh.resident.load();
    while (cur > peak && !sh.peak.compare_exchange_weak(peak, cur)) {
    }
    return m;
}

void buildDisplacedGrids(std::span<const uint32_t> which, std::shared_ptr<const DisplacedDicer> dicer,
                         int depth, size_t budgetBytes, bool forceLazy, SubpatchForest& forest,
                         DisplacedGrids& out, std::span<const uint32_t> treeOf) {
    out = DisplacedGrids();
    if (which.empty()) return;
    const size_t n = which.size();
    const uint32_t leaves = 1u << depth;
    out.slotOf_.assign(treeOf.empty() ? forest.treeCount() : treeOf.size(),
                       DisplacedGrids::kNone);
    auto treeIndex = [&](uint32_t patch) { return treeOf.empty() ? patch : treeOf[patch]; };
    out.patchOf_.assign(which.begin(), which.end());
    for (size_t m = 0; m < n; ++m) out.slotOf_[which[m]] = uint32_t(m);
    out.slotCount_ = n;
    out.budget_ = budgetBytes;
    out.dicer_ = dicer;
    out.depth_ = depth;
    out.slots_ = std::make_unique<DisplacedGrids::Slot[]>(n);
    out.shared_ = std::make_unique<DisplacedGrids::Shared>();
    // The (u,v) pass (no evaluation): per patch its size and, per leaf, the (u,v) rectangle its triangles
    // span (a triangle belongs to the leaf of its centroid, as buildDisplacedMesh sorts them).
    std::vector<std::vector<float>> leafRect(n);  // per leaf u0 u1 v0 v1
    std::vector<size_t> estimate(n);
    std::vector<uint64_t> tris(n), verts(n);
    tbb::parallel_for(size_t(0), n, [&](size_t m) {
        MicroGrid g;
        dicer->dice(which[m], g, /*uvOnly=*/true);
        const size_t nt = g.tri.size() / 3;
        tris[m] = nt, verts[m] = g.uv.size();
        estimate[m] =
            g.uv.size() * (2 * sizeof(Vec3) + sizeof(Vec2)) + nt * (12 + sizeof(TriBvhNode) / 2) + leaves * 4;
        std::vector<float>& r = leafRect[m];
        r.assign(4 * size_t(leaves), 0.f);
        for (uint32_t l = 0; l < leaves; ++l)
            r[4 * l] = r[4 * l + 2] = 2.f, r[4 * l + 1] = r[4 * l + 3] = -1.f;
        for (size_t t = 0; t < nt; ++t) {
            const Vec2 a = g.uv[g.tri[3 * t]], b = g.uv[g.tri[3 * t + 1]], c = g.uv[g.tri[3 * t + 2]];
            const uint32_t l = leafOf(depth, (a.x + b.x + c.x) / 3.f, (a.y + b.y + c.y) / 3.f);
            float* q = &r[4 * l];
            q[0] = std::min({q[0], a.x, b.x, c.x}), q[1] = std::max({q[1], a.x, b.x, c.x});
            q[2] = std::min({q[2], a.y, b.y, c.y}), q[3] = std::max({q[3], a.y, b.y, c.y});
        }
    });
    size_t total = 0;
    for (size_t m = 0; m < n; ++m) total += estimate[m], out.triangles += tris[m], out.vertices += verts[m];
    out.bytesAll = total;
    out.lazy_ = forceLazy || total > budgetBytes;
    if (!out.lazy_) {
        // Everything fits: built now, and the subpatch boxes are the triangles' own.
        tbb::parallel_for(size_t(0), n, [&](size_t m) {
            MicroGrid grid;
            dicer->dice(which[m], grid);
            auto mesh = std::make_shared<DisplacedMesh>();
            std::vector<Bounds3> boxes;
            buildDisplacedMesh(std::move(grid), depth, *mesh, boxes);
            setSubpatchLeafBoxes(forest, treeIndex(which[m]), boxes);
            out.slots_[m].bytes = mesh->bytes();
            out.slots_[m].mesh.store(std::move(mesh));
        });
        size_t bytes = 0;
        for (size_t m = 0; m < n; ++m) bytes += out.slots_[m].bytes;
        out.bytesAll = bytes;
        out.shared_->resident = bytes;
        out.shared_->peak = bytes;
        out.shared_->builds = n;
        return;
    }
    // Lazily: conservative leaf boxes. A leaf's triangles lie in the convex hull of their vertices, each
    // within the displacement radius of the patch surface at a (u,v) of the leaf's rectangle, whose
    // sub-patch's control hull holds it.
    tbb::parallel_for(size_t(0), n, [&](size_t m) {
        const BezierPatch p = dicer->basePatch(which[m]);  // as diced (welded)
        const float grow = dicer->radius(which[m]);
        std::vector<Bounds3> boxes(leaves);
        const Vec3 anchor = p.cp[0];
        for (uint32_t l = 0; l < leaves; ++l) {
            const float* q = &leafRect[m][4 * l];
            if (q[0] > q[1]) {
                boxes[l].lo = boxes[l].hi = anchor;  // no triangle: a point box, which holds nothing
                continue;
            }
            Bounds3 b = enlargedHull(subPatch(p, std::max(0.f, q[0]), std::min(1.f, q[1]),
                                              std::max(0.f, q[2]), std::min(1.f, q[3])));
            float mag = 0.f;
            for (int k = 0; k < 3; ++k) mag = std::max({mag, std::fabs(b.lo[k]), std::fabs(b.hi[k])});
            b = grown(b, grow * 1.001f + 1e-6f * mag);
            boxes[l] = b;
        }
        setSubpatchLeafBoxes(forest, treeIndex(which[m]), boxes);
        out.slots_[m].bytes = estimate[m];
    });
}

}  // namespace tessera
