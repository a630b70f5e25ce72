#include "reyes/pipeline.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace tessera {

PatchArray patchesInCameraSpace(const Scene& scene, const Mat4& cameraFromWorld) {
    PatchArray patches(scene.patches.size());  // every patch written below
    tbb::parallel_for(size_t(0), patches.size(), [&](size_t i) {
        for (int k = 0; k < 16; ++k) patches[i].cp[k] = cameraFromWorld.point(scene.patches[i].cp[k]);
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

}  // namespace tessera
