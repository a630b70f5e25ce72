#include "reyes/pipeline.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>

namespace tessera {

PatchArray patchesInCameraSpace(const Scene& scene, const Mat4& cameraFromWorld) {
    PatchArray patches(scene.patches.size());  // every patch written below
    tbb::parallel_for(size_t(0), patches.size(), [&](size_t i) {
        cameraFromWorld.points(scene.patches[i].cp, patches[i].cp, 16);
    });
    return patches;
}

std::vector<PlacedQuadric> quadricsInSpace(const Scene& scene, const Mat4& toSpace) {
    std::vector<PlacedQuadric> out;
    out.reserve(scene.quadrics.size());
    for (const SceneQuadric& q : scene.quadrics) out.push_back(placeQuadric(q, toSpace));
    return out;
}

PieceList splitPatches(const ReyesView& view, const Scene& scene, float shadingRateOverride,
                       const std::atomic<bool>* cancel, SplitStats& stats) {
    const size_t n = scene.patches.size();
    // Every patch's micropolygon side, for the edges that displaced neighbours share (ReyesView::patchSide).
    std::vector<float> sides(n);
    for (size_t i = 0; i < n; ++i) {
        const float rate = shadingRateOverride > 0.f ? shadingRateOverride : scene.attributes[i].shadingRate;
        sides[i] = std::sqrt(std::max(rate, 1e-4f));
    }
    ReyesView withSides = view;
    withSides.patchSide = sides.data();
    std::atomic<uint64_t> splits{0}, pieceCulls{0}, patchesCulled{0};
    // Fixed chunks of patches, each split into its own list, then the lists copied into place in parallel:
    // the pieces stay in patch order (determinism), without a vector per patch or a serial concatenation
    // (24 Big Guys: 85,680 patches; the serial copy and its page faults were half the split stage).
    constexpr size_t kChunk = 64;
    const size_t chunks = (n + kChunk - 1) / kChunk;
    std::vector<std::vector<Piece>> perChunk(chunks);
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
        for (size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) {
            // Ctrl-C during a long split: skip the remaining patches (the bucket loop then reports it).
            if (cancel && cancel->load(std::memory_order_relaxed)) return;
            SplitCounters counters;
            splitSurface(withSides, scene.attributes[i], uint32_t(i), sides[i], perChunk[c], counters);
            splits += counters.splits;
            pieceCulls += counters.culled;
            if (counters.patchCulled) ++patchesCulled;
        }
    });
    std::vector<size_t> offset(chunks + 1, 0);
    for (size_t c = 0; c < chunks; ++c) offset[c + 1] = offset[c] + perChunk[c].size();
    PieceList pieces(offset[chunks]);  // not filled here: the copies below write every piece
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
        std::copy(perChunk[c].begin(), perChunk[c].end(), pieces.begin() + std::ptrdiff_t(offset[c]));
        std::vector<Piece>().swap(perChunk[c]);
    });
    stats.splits = splits.load();
    stats.pieceCulls = pieceCulls.load();
    stats.patchesCulled = patchesCulled.load();
    return pieces;
}

BucketedPieces binPieces(std::span<const Piece> pieces, const BucketLayout& layout, int marginX, int marginY,
                         int samplesPerPixel) {
    const int nb = layout.count();
    auto bucketRange = [&](const Piece& p, int& bx0, int& by0, int& bx1, int& by1) {
        layout.overlapped(p.x0 - marginX, p.y0 - marginY, p.x1 + marginX, p.y1 + marginY, bx0, by0, bx1, by1);
    };
    BucketedPieces out;
    out.start.assign(nb + 1, 0);
    for (const Piece& p : pieces) {
        int bx0, by0, bx1, by1;
        bucketRange(p, bx0, by0, bx1, by1);
        for (int by = by0; by <= by1; ++by)
            for (int bx = bx0; bx <= bx1; ++bx) ++out.start[by * layout.countX + bx + 1];
    }
    for (int b = 0; b < nb; ++b) out.start[b + 1] += out.start[b];
    out.pieces.resize(out.start[nb]);
    out.spans.resize(pieces.size());
    out.work.assign(nb, 0);
    std::vector<uint32_t> fill(out.start.begin(), out.start.end() - 1);
    for (uint32_t pi = 0; pi < pieces.size(); ++pi) {
        int bx0, by0, bx1, by1;
        bucketRange(pieces[pi], bx0, by0, bx1, by1);
        const int spanned = (bx1 - bx0 + 1) * (by1 - by0 + 1);
        const uint64_t share =
            uint64_t(pieceGridU(pieces[pi])) * uint64_t(pieceGridV(pieces[pi])) / uint64_t(spanned) + 1;
        for (int by = by0; by <= by1; ++by)
            for (int bx = bx0; bx <= bx1; ++bx) {
                const int b = by * layout.countX + bx;
                out.pieces[fill[b]++] = pi;
                out.work[b] += share;
            }
        out.spans[pi] = spanned;
    }
    for (int b = 0; b < nb; ++b) {
        const Rect t = layout.target(b);
        out.work[b] += uint64_t(t.width()) * t.height() * samplesPerPixel / 16 + 1;
    }
    return out;
}

namespace {
// About the micropolygons a patch dices into, for the progress: the grid its root piece would take
// (pieceGridU x pieceGridV) with each boundary measured by its projected control polygon, which bounds the
// curve's length; the dicing rounds the same way (opposite edges' longer one, both sides counted).
float rootGridEstimate(const ReyesView& view, const BezierPatch& patch, float side) {
    Vec3 r[16];
    for (int k = 0; k < 16; ++k) r[k] = view.projector.toRaster(patch.cp[k]);
    auto polyline = [&](int first, int stride) {
        float len = 0.f;
        for (int k = 0; k < 3; ++k) {
            const Vec3 a = r[first + k * stride], b = r[first + (k + 1) * stride];
            len += std::sqrt((b.x - a.x) * (b.x - a.x) + (b.y - a.y) * (b.y - a.y));
        }
        return len;
    };
    const float u = std::max(polyline(0, 1), polyline(12, 1)) / side;
    const float v = std::max(polyline(0, 4), polyline(3, 4)) / side;
    return std::max(1.f, std::ceil(u)) * std::max(1.f, std::ceil(v));
}
}  // namespace

LazyPieces::LazyPieces(const ReyesView& view, const Scene& scene, float shadingRateOverride,
                       const BucketLayout& layout, int marginX, int marginY, int samplesPerPixel)
    : view_(view), scene_(scene), layout_(layout), marginX_(marginX), marginY_(marginY) {
    const size_t n = scene.patches.size();
    sides_.resize(n);
    for (size_t i = 0; i < n; ++i) {
        const float rate = shadingRateOverride > 0.f ? shadingRateOverride : scene.attributes[i].shadingRate;
        sides_[i] = std::sqrt(std::max(rate, 1e-4f));
    }
    view_.patchSide = sides_.data();
    slots_ = std::make_unique<SurfaceSlot[]>(n);
    // Each surface's buckets, from its root's bound grown by the margins (and by a rounding allowance, so
    // that a piece's bound, computed from a sub-hull in floats, cannot reach a bucket its surface is not
    // binned in; an extra bucket only looks at the surface's pieces and finds none).
    const int nb = layout.count();
    std::vector<uint64_t> share(n, 0);
    tbb::parallel_for(size_t(0), n, [&](size_t i) {
        const SurfaceReach reach = surfaceReach(view_, scene.attributes[i], uint32_t(i));
        SurfaceSlot& slot = slots_[i];
        if (reach.kind == SurfaceReach::Culled) {
            ++culled_, ++surfacesCulled_;
            return;  // an empty span: binned nowhere
        }
        if (reach.kind == SurfaceReach::Anywhere) {
            slot.span = {0, 0, layout.countX - 1, layout.countY - 1};
            share[i] = 1;
            return;
        }
        auto allowance = [](float x) { return 1e-3f + 1e-5f * std::abs(x); };
        int bx0, by0, bx1, by1;
        layout.overlapped(reach.x0 - marginX - allowance(reach.x0), reach.y0 - marginY - allowance(reach.y0),
                          reach.x1 + marginX + allowance(reach.x1), reach.y1 + marginY + allowance(reach.y1),
                          bx0, by0, bx1, by1);
        slot.span = {bx0, by0, bx1, by1};
        // The micropolygons it will make, for the progress (a quadric's: its raster bound's area), the part
        // in the region in proportion to its bound's, shared among its buckets.
        const Rect& r = layout.region;
        const float boundArea = (reach.x1 - reach.x0) * (reach.y1 - reach.y0);
        const float w =
            std::clamp(reach.x1, float(r.x0), float(r.x1)) - std::clamp(reach.x0, float(r.x0), float(r.x1));
        const float h =
            std::clamp(reach.y1, float(r.y0), float(r.y1)) - std::clamp(reach.y0, float(r.y0), float(r.y1));
        const float grid = isQuadric(scene.attributes[i].kind)
                               ? boundArea / (sides_[i] * sides_[i])
                               : rootGridEstimate(view_, view_.patches[i], sides_[i]);
        const float inRegion = boundArea > 0.f ? w * h / boundArea : 0.f;
        const float micropolygons = std::min(1e7f, grid * inRegion);
        share[i] = uint64_t(micropolygons) / uint64_t((bx1 - bx0 + 1) * (by1 - by0 + 1)) + 1;
    });
    // CSR bins in surface order (the order every bucket must meet them in).
    start_.assign(nb + 1, 0);
    for (size_t i = 0; i < n; ++i) {
        const BucketSpan& r = slots_[i].span;
        for (int by = r.by0; by <= r.by1; ++by)
            for (int bx = r.bx0; bx <= r.bx1; ++bx) ++start_[by * layout.countX + bx + 1];
    }
    for (int b = 0; b < nb; ++b) start_[b + 1] += start_[b];
    surfaces_.resize(start_[nb]);
    work_.assign(nb, 0);
    std::vector<uint32_t> fill(start_.begin(), start_.end() - 1);
    for (size_t i = 0; i < n; ++i) {
        const BucketSpan& r = slots_[i].span;
        for (int by = r.by0; by <= r.by1; ++by)
            for (int bx = r.bx0; bx <= r.bx1; ++bx) {
                const int b = by * layout.countX + bx;
                surfaces_[fill[b]++] = uint32_t(i);
                work_[b] += share[i];
            }
        slots_[i].refs.store((r.bx1 - r.bx0 + 1) * (r.by1 - r.by0 + 1), std::memory_order_relaxed);
    }
    for (int b = 0; b < nb; ++b) {
        const Rect t = layout.target(b);
        work_[b] += uint64_t(t.width()) * t.height() * samplesPerPixel / 16 + 1;
    }
}

LazyPieces::~LazyPieces() = default;

void LazyPieces::split(uint32_t surface, SurfaceSlot& slot) {
    const auto t0 = std::chrono::steady_clock::now();
    auto sp = std::make_unique<SurfacePieces>();
    SplitCounters counters;
    splitSurface(view_, scene_.attributes[surface], surface, sides_[surface], sp->pieces, counters);
    sp->pieces.shrink_to_fit();
    const size_t count = sp->pieces.size();
    sp->spans.resize(count);
    sp->grids = std::make_unique<GridSlot[]>(count);
    for (size_t i = 0; i < count; ++i) {
        const Piece& p = sp->pieces[i];
        BucketSpan& r = sp->spans[i];
        layout_.overlapped(p.x0 - marginX_, p.y0 - marginY_, p.x1 + marginX_, p.y1 + marginY_, r.bx0, r.by0,
                           r.bx1, r.by1);
        sp->grids[i].refs.store((r.bx1 - r.bx0 + 1) * (r.by1 - r.by0 + 1), std::memory_order_relaxed);
        if (r.bx0 < slot.span.bx0 || r.by0 < slot.span.by0 || r.bx1 > slot.span.bx1 || r.by1 > slot.span.by1)
            ++beyond_;
    }
    splits_ += counters.splits;
    culled_ += counters.culled;
    surfacesCulled_ += counters.patchCulled;
    pieces_ += count;
    const uint64_t alive = alive_ += count;
    uint64_t peak = peak_.load(std::memory_order_relaxed);
    while (alive > peak && !peak_.compare_exchange_weak(peak, alive, std::memory_order_relaxed)) {
    }
    slot.pieces = std::move(sp);
    splitNs_ += uint64_t(
        std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - t0).count());
}

void LazyPieces::release(SurfaceSlot& slot) {
    if (!slot.pieces) return;
    alive_ -= slot.pieces->pieces.size();
    slot.pieces.reset();
}

SplitStats LazyPieces::stats() const {
    SplitStats s;
    s.splits = splits_.load();
    s.pieceCulls = culled_.load();
    s.patchesCulled = surfacesCulled_.load();
    return s;
}

}  // namespace tessera
