// The stages every Reyes pass shares, the camera's image (reyes_renderer.cpp) and the lights' depth maps
// (shadow_maps.cpp, paper 001 sec. 3.5: "only split, dice and sample"): patches to the pass camera's
// space with shared edges welded, split and cull into pieces, the pieces binned into buckets, and the cache
// that dices each piece once for all the buckets that need it.
#pragma once
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

// A diced grid shared by the buckets its piece overlaps: diced by the first bucket that needs it, freed by
// the last one, so only grids near the buckets in flight are alive.
class GridCache {
  public:
    explicit GridCache(const BucketedPieces& binned) : slots_(binned.spans.size()) {
        for (size_t i = 0; i < slots_.size(); ++i)
            slots_[i].refs.store(binned.spans[i], std::memory_order_relaxed);
    }
    // The grid of piece `pi`; the first caller fills it with dice(Grid&), the others wait for it (if
    // dice throws, the next caller dices). The grid stays valid until this bucket's release(pi).
    // A three-state flag, not std::call_once: its slow path (pthread_once) was 3% of 24 Big Guys.
    template <class Dice>
    const Grid& acquire(uint32_t pi, Dice&& dice) {
        Slot& slot = slots_[pi];
        uint8_t state = slot.state.load(std::memory_order_acquire);
        while (state != kReady) {
            if (state == kEmpty &&
                slot.state.compare_exchange_strong(state, kDicing, std::memory_order_acquire)) {
                try {
                    slot.grid = std::make_unique<Grid>();
                    dice(*slot.grid);
                } catch (...) {
                    slot.grid.reset();
                    slot.state.store(kEmpty, std::memory_order_release);
                    slot.state.notify_all();
                    throw;
                }
                slot.state.store(kReady, std::memory_order_release);
                slot.state.notify_all();
                break;
            }
            if (state == kDicing) slot.state.wait(kDicing, std::memory_order_acquire);
            state = slot.state.load(std::memory_order_acquire);
        }
        return *slot.grid;
    }
    void release(uint32_t pi) {
        Slot& slot = slots_[pi];
        if (slot.refs.fetch_sub(1, std::memory_order_acq_rel) == 1) slot.grid.reset();
    }

  private:
    static constexpr uint8_t kEmpty = 0, kDicing = 1, kReady = 2;
    struct Slot {
        std::atomic<uint8_t> state{kEmpty};
        std::unique_ptr<Grid> grid;
        std::atomic<int> refs{0};
    };
    std::vector<Slot> slots_;
};

}  // namespace tessera
