#include "rt/displaced.h"

#include <algorithm>
#include <cmath>
#include <numeric>

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
