// The stages every Reyes pass shares, the camera's image (reyes_renderer.cpp) and the lights' depth maps
// (shadow_maps.cpp, paper 001 sec. 3.5: "only split, dice and sample"): patches to the pass camera's
// space with shared edges welded, split and cull into pieces, the pieces binned into buckets, and the cache
// that dices each piece once for all the buckets that need it.
#pragma once
#include <tbb/enumerable_thread_specific.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "core/buffer_allocator.h"
#include "engine/tile_loop.h"
#include "reyes/grid.h"
#include "reyes/split.h"
#include "scene/scene.h"
#include "scene/weld.h"

namespace tessera {

// The scene's patches (at shutter open) in the space of `cameraFromWorld` (Bezier patches are affine
// invariant: the control points are transformed).
// The scene's quadrics placed in the space `toSpace` maps world space to (Scene::quadrics order).
std::vector<PlacedQuadric> quadricsInSpace(const Scene& scene, const Mat4& toSpace);
// The quadric a surface's dicing needs (nullptr for the Bezier kind).
inline const PlacedQuadric* quadricOf(const ReyesView& view, const PatchAttributes& attr) {
    return isQuadric(attr.kind) ? &view.quadrics[attr.shape] : nullptr;
}
// A frame's patches (16 MB on 24 Big Guys): written in parallel, on huge pages, not zero-filled first.
using PatchArray = std::vector<BezierPatch, DefaultInitAllocator<BezierPatch>>;
PatchArray patchesInCameraSpace(const Scene& scene, const Mat4& cameraFromWorld);

struct SplitStats {
    uint64_t splits = 0, pieceCulls = 0, patchesCulled = 0;
};

// Split and cull every patch (view.patches, in the pass camera's space) into diceable pieces, in parallel,
// kept in patch order for determinism. Micropolygons of about `shadingRateOverride` pixels of area when it
// is > 0, else each patch's own ShadingRate. Stops splitting when `cancel` is set.
// The pieces of a frame (tens of megabytes on big scenes): filled in parallel, on huge pages.
using PieceList = std::vector<Piece, DefaultInitAllocator<Piece>>;
PieceList splitPatches(const ReyesView& view, const Scene& scene, float shadingRateOverride,
                       const std::atomic<bool>* cancel, SplitStats& stats);

// The pieces binned into the buckets their raster bound (grown by `marginX`, `marginY`: the filter radius
// and a pixel) overlaps: CSR lists in piece order, and the work of each bucket for the progress (the
// micropolygons of its pieces, each shared among the buckets it overlaps, plus its samples).
struct BucketedPieces {
    std::vector<uint32_t> start;   // bucket b's pieces: pieces[start[b] .. start[b + 1])
    std::vector<uint32_t> pieces;  // piece indices
    std::vector<int> spans;        // per piece: how many buckets need it
    std::vector<uint64_t> work;    // per bucket
};
BucketedPieces binPieces(std::span<const Piece> pieces, const BucketLayout& layout, int marginX, int marginY,
                         int samplesPerPixel);

// Fills `slot` once for all callers: the first runs fill(), the others wait for it (if fill throws, the
// next caller fills). A three-state flag, not std::call_once: its slow path (pthread_once) was 3% of 24 Big
// Guys.
namespace detail {
constexpr uint8_t kSlotEmpty = 0, kSlotFilling = 1, kSlotReady = 2;
template <class Fill>
void fillOnce(std::atomic<uint8_t>& state, Fill&& fill) {
    uint8_t s = state.load(std::memory_order_acquire);
    while (s != kSlotReady) {
        if (s == kSlotEmpty && state.compare_exchange_strong(s, kSlotFilling, std::memory_order_acquire)) {
            try {
                fill();
            } catch (...) {
                state.store(kSlotEmpty, std::memory_order_release);
                state.notify_all();
                throw;
            }
            state.store(kSlotReady, std::memory_order_release);
            state.notify_all();
            return;
        }
        if (s == kSlotFilling) state.wait(kSlotFilling, std::memory_order_acquire);
        s = state.load(std::memory_order_acquire);
    }
}
}  // namespace detail

// The frame's surfaces binned by their root bound (surfaceReach) and split on demand: the first bucket that
// needs a surface splits it, the last one frees its pieces and their grids (Aqsis splits per bucket
// likewise). So the pieces alive at a time are those of the surfaces that overlap the buckets in flight (and
// of those begun above them and not yet finished), not every piece of the frame: memory grows with the
// scene's patches (their 16 control points) but not with its pieces and their 4 KB grids (issue 18).
// A bucket sees the pieces that overlap it in piece order: surface order, then the split's own, exactly
// as binning the up-front split (splitPatches + binPieces) orders them (test LazyPieces.*).
class LazyPieces {
  public:
    // Pieces of about `shadingRateOverride` pixels of area when > 0, else each patch's ShadingRate; bins
    // grown by `marginX`, `marginY` (the filter radius and a pixel); `samplesPerPixel` weighs the work.
    LazyPieces(const ReyesView& view, const Scene& scene, float shadingRateOverride,
               const BucketLayout& layout, int marginX, int marginY, int samplesPerPixel);
    ~LazyPieces();
    LazyPieces(const LazyPieces&) = delete;
    LazyPieces& operator=(const LazyPieces&) = delete;

    // Each bucket's estimated work, for the progress (its surfaces' micropolygons shared among the buckets
    // they overlap, plus its samples).
    std::span<const uint64_t> work() const { return work_; }

    // For every piece overlapping bucket b, in piece order: the piece's grid, made by dice(piece, grid) the
    // first time any bucket needs it, handed to visit(piece, grid). The grid is freed after its last bucket.
    template <class Dice, class Visit>
    void forEach(int b, Dice&& dice, Visit&& visit) {
        const int bx = b % layout_.countX, by = b / layout_.countX;
        for (uint32_t k = start_[b]; k < start_[b + 1]; ++k) {
            const uint32_t surface = surfaces_[k];
            SurfaceSlot& slot = slots_[surface];
            detail::fillOnce(slot.state, [&] { split(surface, slot); });
            SurfacePieces& sp = *slot.pieces;
            for (size_t i = 0; i < sp.pieces.size(); ++i) {
                const BucketSpan& r = sp.spans[i];
                if (bx < r.bx0 || bx > r.bx1 || by < r.by0 || by > r.by1) continue;
                GridSlot& g = sp.grids[i];
                detail::fillOnce(g.state, [&] {
                    g.grid = takeSpareGrid();
                    try {
                        dice(sp.pieces[i], *g.grid);
                    } catch (...) {
                        g.grid.reset();
                        throw;
                    }
                });
                visit(static_cast<const Piece&>(sp.pieces[i]), static_cast<const Grid&>(*g.grid));
                if (g.refs.fetch_sub(1, std::memory_order_acq_rel) == 1) keepSpareGrid(std::move(g.grid));
            }
            if (slot.refs.fetch_sub(1, std::memory_order_acq_rel) == 1) release(slot);
        }
    }

    // After the bucket loop: what splitting did (the culls of whole surfaces by their root included).
    SplitStats stats() const;
    uint64_t pieceCount() const { return pieces_.load(); }
    // The most pieces alive at once, and the CPU time the buckets spent splitting.
    uint64_t peakPieces() const { return peak_.load(); }
    double splitCpuMs() const { return double(splitNs_.load()) * 1e-6; }
    // Pieces whose buckets reach beyond their surface's (would be missed there; 0 unless rounding makes a
    // sub-hull's bound poke out of the root's): a check the tests read.
    uint64_t piecesBeyondSurface() const { return beyond_.load(); }

  private:
    struct BucketSpan {
        int32_t bx0 = 0, by0 = 0, bx1 = -1, by1 = -1;
    };
    struct GridSlot {
        std::atomic<uint8_t> state{detail::kSlotEmpty};
        std::atomic<int> refs{0};
        std::unique_ptr<Grid> grid;
    };
    struct SurfacePieces {
        std::vector<Piece> pieces;
        std::vector<BucketSpan> spans;
        std::unique_ptr<GridSlot[]> grids;
    };
    struct SurfaceSlot {
        std::atomic<uint8_t> state{detail::kSlotEmpty};
        std::atomic<int> refs{0};
        BucketSpan span;  // the buckets its bins hold it in
        std::unique_ptr<SurfacePieces> pieces;
    };
    void split(uint32_t surface, SurfaceSlot& slot);
    void release(SurfaceSlot& slot);

    // Freed grids are kept per thread and diced into again (Grid::clearKeepingStorage): a grid's arrays
    // (up to 19) were otherwise allocated and freed per piece, often by different threads, which glibc's
    // allocator serves from locked arenas and fresh pages (issue 18: "reusing per-thread buffers").
    static constexpr size_t kSpareGridsPerThread = 32;
    std::unique_ptr<Grid> takeSpareGrid() {
        std::vector<std::unique_ptr<Grid>>& spare = spareGrids_.local();
        if (spare.empty()) return std::make_unique<Grid>();
        std::unique_ptr<Grid> g = std::move(spare.back());
        spare.pop_back();
        g->clearKeepingStorage();
        return g;
    }
    void keepSpareGrid(std::unique_ptr<Grid> g) {
        std::vector<std::unique_ptr<Grid>>& spare = spareGrids_.local();
        if (spare.size() < kSpareGridsPerThread) spare.push_back(std::move(g));
    }

    ReyesView view_;  // with patchSide = sides_
    const Scene& scene_;
    const BucketLayout layout_;
    const int marginX_, marginY_;
    std::vector<float> sides_;     // per surface: its micropolygon side (ReyesView::patchSide)
    std::vector<uint32_t> start_;  // bucket b's surfaces: surfaces_[start_[b] .. start_[b + 1])
    std::vector<uint32_t> surfaces_;
    std::vector<uint64_t> work_;
    std::unique_ptr<SurfaceSlot[]> slots_;
    std::atomic<uint64_t> splits_{0}, culled_{0}, surfacesCulled_{0}, pieces_{0}, alive_{0}, peak_{0};
    std::atomic<uint64_t> splitNs_{0}, beyond_{0};
    tbb::enumerable_thread_specific<std::vector<std::unique_ptr<Grid>>> spareGrids_;
};

}  // namespace tessera
