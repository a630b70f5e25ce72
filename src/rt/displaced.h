// Ray-traced displacement (issue 12, "Ray tracer"; docs/rt.md, "Displaced patches"): a displaced patch is
// not intersected by Newton but as its micro-grid, diced by Reyes' own split, dice and displacement code
// (reyes/split.h, reyes/grid.h dicePieceVertices, reyes/displace.h) at the rate Reyes would use from the
// camera, so both engines render the same surface. The rt layer cannot include Reyes: the render layer
// hands a DisplacedDicer to the accel build (render/displaced_dicer.h).
//
// Per displaced patch, its triangles are grouped by the subpatch leaf that holds their (u,v) centroid; the
// patch's subpatch-tree boxes become the boxes of those groups (setSubpatchLeafBoxes), so the top BVH, the
// traversal and the binning stages find displaced patches unchanged, and each candidate (ray, patch, leaf)
// intersects the leaf's triangles through a small BVH over them. Grid vertices on shared edges are
// bit-identical on both sides (canonical lattice points moved along canonical normals, reyes/displace.h)
// and the ray-triangle test is watertight (Woop, Benthin, Wald, "Watertight Ray/Triangle Intersection",
// JCGT 2013): no ray slips between two triangles that share an edge.
#pragma once
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include "core/vec.h"
#include "rt/intersect.h"
#include "rt/subpatch_tree.h"

namespace tessera {

// One displaced patch diced: vertices (camera space), the displaced surface's unit normals (orientation
// applied) and the vertices' (u,v) on the patch; triangles as 3 vertex indices each, wound so that
// (v1 - v0) x (v2 - v0) points along dP/du x dP/dv (orientation not applied).
struct MicroGrid {
    std::vector<Vec3> P, N;
    std::vector<Vec2> uv;
    std::vector<uint32_t> tri;
};

// Dices displaced patches for the accel (implemented with Reyes' code by the render layer). Thread-safe:
// dice() runs in parallel over patches, and lazily from the trace stages.
class DisplacedDicer {
  public:
    virtual ~DisplacedDicer() = default;
    // Whether the ray tracer intersects `patch` as a displaced micro-grid.
    virtual bool displaced(uint32_t patch) const = 0;
    // How far displacement moves the patch's points, and the undisplaced patch it dices (accel space).
    virtual float radius(uint32_t patch) const = 0;
    virtual BezierPatch basePatch(uint32_t patch) const = 0;
    // The micro-grid of `patch`; `uvOnly`: only the vertices' (u,v) and the triangles (no evaluation, no
    // displacement: cheap), the same (u,v) and triangles as a full dice.
    virtual void dice(uint32_t patch, MicroGrid& out, bool uvOnly = false) const = 0;
};

struct FrameSetup;  // engine/frame.h
// Makes the frame's dicer (nullptr: nothing displaced); renderRt calls it once it has set up the frame.
using DisplacedDicerFactory = std::function<std::unique_ptr<DisplacedDicer>(const FrameSetup&)>;

// A node of a leaf's triangle BVH: inner nodes have count 0, their left child next and their right child
// at `index`; leaves hold triangles index .. index + count - 1.
struct TriBvhNode {
    Bounds3 box;
    uint32_t index = 0, count = 0;
};

struct DisplacedMesh {
    std::vector<Vec3> P, N;
    std::vector<Vec2> uv;
    std::vector<uint32_t> tri;       // 3 indices per triangle, ordered by leaf and then by BVH leaf
    std::vector<TriBvhNode> nodes;   // every subpatch leaf's triangle BVH, one after another
    std::vector<uint32_t> leafRoot;  // per subpatch leaf: its BVH's root node (UINT32_MAX: no triangle)
    size_t bytes() const {
        return P.capacity() * sizeof(Vec3) * 2 + uv.capacity() * sizeof(Vec2) + tri.capacity() * 4 +
               nodes.capacity() * sizeof(TriBvhNode) + leafRoot.capacity() * 4;
    }
};

// The frame's displaced patches and their micro-grids. When all grids fit the memory budget they are built
// up front and the patches' subpatch boxes are the boxes of their triangles; otherwise the boxes are
// conservative (the hull of the (u,v) rectangle a leaf's triangles span, grown by the displacement radius)
// and a patch's grid is built the first time a ray reaches one of its leaves, least recently used grids
// being dropped when the budget is passed (a reader holds its grid through a shared_ptr, so dropping is
// safe while it is in use; a dropped grid is built again, identically, when needed).
class DisplacedGrids {
  public:
    static constexpr uint32_t kNone = 0xffffffffu;
    DisplacedGrids();
    ~DisplacedGrids();
    DisplacedGrids(DisplacedGrids&&) noexcept;
    DisplacedGrids& operator=(DisplacedGrids&&) noexcept;

    bool any() const { return !slotOf_.empty(); }
    bool displaced(uint32_t patch) const { return !slotOf_.empty() && slotOf_[patch] != kNone; }
    // The patch's grid (nullptr when not displaced), built now if it is not resident.
    std::shared_ptr<const DisplacedMesh> mesh(uint32_t patch) const;
    bool lazy() const { return lazy_; }
    size_t patchCount() const { return slotCount_; }
    size_t budgetBytes() const { return budget_; }
    // Statistics: the grids' total size (all of them, built once each), resident now and at most.
    uint64_t triangles = 0, vertices = 0;
    size_t bytesAll = 0;
    double buildMs = 0;
    size_t residentBytes() const;
    size_t peakBytes() const;
    uint64_t builds() const;
    uint64_t evictions() const;

  private:
    friend void buildDisplacedGrids(std::span<const uint32_t>, std::shared_ptr<const DisplacedDicer>, int,
                                    size_t, bool, SubpatchForest&, DisplacedGrids&,
                                    std::span<const uint32_t>);
    struct Slot;
    struct Shared;
    std::shared_ptr<const DisplacedMesh> build(uint32_t slot) const;
    std::vector<uint32_t> slotOf_;  // per patch: its slot, or kNone (intersected by Newton)
    std::vector<uint32_t> patchOf_;
    size_t slotCount_ = 0;
    bool lazy_ = false;
    size_t budget_ = 0;
    std::shared_ptr<const DisplacedDicer> dicer_;
    int depth_ = 0;
    std::unique_ptr<Slot[]> slots_;
    std::unique_ptr<Shared> shared_;
};

// Patches `which` (displaced by `dicer`) of a forest of `patchCount` trees: their grids built up front when
// they fit `budgetBytes`, lazily otherwise (`forceLazy`: always lazily, for tests), and their subpatch
// boxes in `forest` set accordingly (setSubpatchLeafBoxes). `treeOf` (empty: tree i is patch i's): per
// patch its tree in `forest` (RtAccel::treeOf; a displaced patch always has its own).
void buildDisplacedGrids(std::span<const uint32_t> which, std::shared_ptr<const DisplacedDicer> dicer,
                         int depth, size_t budgetBytes, bool forceLazy, SubpatchForest& forest,
                         DisplacedGrids& out, std::span<const uint32_t> treeOf = {});

// Sort a diced grid's triangles into the subpatch leaves of a tree of `depth` (by their (u,v) centroids),
// build each leaf's BVH, and return the leaves' boxes (grown a little, so rays through shared edges reach
// both sides; a leaf without triangles gets a point box at its first vertex, which holds nothing).
void buildDisplacedMesh(MicroGrid&& grid, int depth, DisplacedMesh& out, std::vector<Bounds3>& leafBoxes);

// Per-ray constants of the watertight ray-triangle test (Woop et al. 2013, sec. 3).
struct WatertightRay {
    int kx, ky, kz;
    float Sx, Sy, Sz;
    Vec3 o, inv;
};
WatertightRay makeWatertightRay(const Ray& ray);

// The ray against the triangles of subpatch leaf `leaf` of a displaced mesh: the nearest hit in
// (tmin, tmax) that `accept` takes. The hit's (u,v) and shading normal (`ns`) are interpolated from the
// vertices; p is on the ray; dpdu x dpdv is the triangle's unoriented geometric normal.
template <class Accept>
bool intersectDisplacedLeaf(const DisplacedMesh& m, uint32_t leaf, const Ray& ray, const WatertightRay& wr,
                            Accept&& accept, PatchHit& out);

// ---- implementation ---------------------------------------------------------------------------------

// Woop et al. 2013, fig. 1 (single precision, with the double fallback for an edge function that is
// exactly zero): the ray's parameter and the barycentric weights of v0, v1, v2. Edges shared by two
// triangles give the same edge function with opposite signs on both, so a ray through the edge hits one.
inline bool rayTriangleWatertight(const WatertightRay& r, Vec3 v0, Vec3 v1, Vec3 v2, float tmin, float tmax,
                                  float& t, float& b0, float& b1, float& b2) {
    const Vec3 A = v0 - r.o, B = v1 - r.o, C = v2 - r.o;
    const float Ax = A[r.kx] - r.Sx * A[r.kz], Ay = A[r.ky] - r.Sy * A[r.kz];
    const float Bx = B[r.kx] - r.Sx * B[r.kz], By = B[r.ky] - r.Sy * B[r.kz];
    const float Cx = C[r.kx] - r.Sx * C[r.kz], Cy = C[r.ky] - r.Sy * C[r.kz];
    float U = Cx * By - Cy * Bx, V = Ax * Cy - Ay * Cx, W = Bx * Ay - By * Ax;
    if (U == 0.f || V == 0.f || W == 0.f) {
        U = float(double(Cx) * double(By) - double(Cy) * double(Bx));
        V = float(double(Ax) * double(Cy) - double(Ay) * double(Cx));
        W = float(double(Bx) * double(Ay) - double(By) * double(Ax));
    }
    if ((U < 0.f || V < 0.f || W < 0.f) && (U > 0.f || V > 0.f || W > 0.f)) return false;
    const float det = U + V + W;
    if (det == 0.f) return false;
    const float Az = r.Sz * A[r.kz], Bz = r.Sz * B[r.kz], Cz = r.Sz * C[r.kz];
    const float T = U * Az + V * Bz + W * Cz;
    const float inv = 1.f / det;
    t = T * inv;
    if (!(t > tmin && t < tmax)) return false;
    b0 = U * inv, b1 = V * inv, b2 = W * inv;
    return true;
}

template <class Accept>
bool intersectDisplacedLeaf(const DisplacedMesh& m, uint32_t leaf, const Ray& ray, const WatertightRay& wr,
                            Accept&& accept, PatchHit& out) {
    const uint32_t root = m.leafRoot[leaf];
    if (root == 0xffffffffu) return false;
    float tmax = ray.tmax;
    bool found = false;
    uint32_t stack[64];
    int sp = 0;
    stack[sp++] = root;
    while (sp > 0) {
        const TriBvhNode& nd = m.nodes[stack[--sp]];
        float te;
        if (!rayBox(nd.box, wr.o, wr.inv, ray.tmin, tmax, te)) continue;
        if (nd.count == 0) {
            const uint32_t self = uint32_t(&nd - m.nodes.data());
            stack[sp++] = nd.index;
            stack[sp++] = self + 1;
            continue;
        }
        for (uint32_t k = nd.index; k < nd.index + nd.count; ++k) {
            const uint32_t i0 = m.tri[3 * k], i1 = m.tri[3 * k + 1], i2 = m.tri[3 * k + 2];
            float t, b0, b1, b2;
            if (!rayTriangleWatertight(wr, m.P[i0], m.P[i1], m.P[i2], ray.tmin, tmax, t, b0, b1, b2))
                continue;
            PatchHit h;
            h.t = t;
            h.hit = true;
            h.u = b0 * m.uv[i0].x + b1 * m.uv[i1].x + b2 * m.uv[i2].x;
            h.v = b0 * m.uv[i0].y + b1 * m.uv[i1].y + b2 * m.uv[i2].y;
            h.p = ray.o + ray.d * t;
            h.dpdu = m.P[i1] - m.P[i0];
            h.dpdv = m.P[i2] - m.P[i0];
            Vec3 n = m.N[i0] * b0 + m.N[i1] * b1 + m.N[i2] * b2;
            const float len2 = dot(n, n);
            h.ns = len2 > 0.f ? n * (1.f / std::sqrt(len2)) : m.N[i0];
            if (!accept(h)) continue;
            out = h;
            tmax = t;
            found = true;
        }
    }
    return found;
}

}  // namespace tessera
