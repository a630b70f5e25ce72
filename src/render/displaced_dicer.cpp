#include "render/displaced_dicer.h"

#include <algorithm>
#include <cmath>

#include "reyes/displace.h"
#include "reyes/grid.h"
#include "reyes/pipeline.h"
#include "reyes/split.h"
#include "scene/weld.h"

namespace tessera {
namespace {

// A patch whose grids would hold more vertices than this is diced again at twice the micropolygon side
// (an edge reaching across the eye plane measures up to the rate cap): its shared edges may then no longer
// match its neighbours' (documented in docs/rt.md).
constexpr size_t kMaxVerticesPerPatch = size_t(1) << 22;

class ReyesDisplacedDicer final : public DisplacedDicer {
  public:
    ReyesDisplacedDicer(const Scene& scene, const RenderSettings& settings, const FrameSetup& frame)
        : scene_(scene), textures_(frame.textures), view_(frame.camera) {
        const Camera& cam = frame.camera;
        // As renderReyes: camera space, moving patches at shutter open, shared edges welded.
        patches_ = patchesInCameraSpace(scene, cam.cameraFromWorld);
        const FrameMotion& motion = frame.motion;
        if (motion.blurred()) {
            moving_.assign(patches_.size(), 0);
            for (size_t i = 0; i < patches_.size(); ++i)
                if (motion.moving(i)) patches_[i] = motion.patchKeys(i)[0], moving_[i] = 1;
        }
        weldSharedEdges(patches_, defaultWeldTolerance(patches_));
        quadrics_ = quadricsInSpace(scene, cam.cameraFromWorld);
        displacement_ = makeDisplacementFrame(scene, frame.textures.get(), patches_,
                                              float(cam.cameraFromWorld.maxStretch()));
        view_.patches = patches_.data();
        view_.quadrics = quadrics_.data();
        view_.projector = frame.projector;
        if (displacement_.any()) view_.displacement = &displacement_;
        view_.maxGridEdge = std::max(1, settings.maxGridEdge);
        // The same displacement-aware splitting as Reyes' (paper 001), so both engines see one surface.
        view_.displacementSplit = settings.displacementSplit;
        view_.cull = false;
        // Shared displaced edges between patches of different ShadingRate: measured alike by both (split.h).
        sides_.resize(scene.attributes.size());
        for (size_t i = 0; i < sides_.size(); ++i)
            sides_[i] = std::sqrt(std::max(scene.attributes[i].shadingRate, 1e-4f));
        view_.patchSide = sides_.data();
        view_.cullX0 = view_.cullY0 = -1e30f, view_.cullX1 = view_.cullY1 = 1e30f;
    }
    bool any() const { return displacement_.any(); }
    bool displaced(uint32_t patch) const override {
        return displacement_.displaced(patch) && (moving_.empty() || !moving_[patch]);
    }
    float radius(uint32_t patch) const override { return displacement_.radius[patch]; }
    BezierPatch basePatch(uint32_t patch) const override { return patches_[patch]; }
    void dice(uint32_t patch, MicroGrid& out, bool uvOnly) const override {
        const PatchAttributes& attr = scene_.attributes[patch];
        float side = std::sqrt(std::max(attr.shadingRate, 1e-4f));
        std::vector<Piece> pieces;
        for (;;) {
            pieces.clear();
            SplitCounters c;
            splitSurface(view_, attr, patch, side, pieces, c);
            size_t verts = 0;
            for (const Piece& p : pieces) verts += size_t(pieceGridU(p) + 1) * size_t(pieceGridV(p) + 1);
            if (verts <= kMaxVerticesPerPatch) break;
            side *= 2.f;
        }
        out = MicroGrid();
        std::vector<Vec3> P, N;
        std::vector<Vec2> uv;
        for (const Piece& piece : pieces) {
            int nu, nv;
            dicePieceVertices(view_, piece, attr.flipNormal, nu, nv, P, N, uv, uvOnly);
            const uint32_t base = uint32_t(out.uv.size());
            if (!uvOnly) {
                out.P.insert(out.P.end(), P.begin(), P.end());
                out.N.insert(out.N.end(), N.begin(), N.end());
            }
            out.uv.insert(out.uv.end(), uv.begin(), uv.end());
            // Two triangles per micropolygon, wound (u, then v) like dP/du x dP/dv.
            for (int j = 0; j < nv; ++j)
                for (int i = 0; i < nu; ++i) {
                    const uint32_t v00 = base + uint32_t(j * (nu + 1) + i), v10 = v00 + 1;
                    const uint32_t v01 = v00 + uint32_t(nu + 1), v11 = v01 + 1;
                    out.tri.insert(out.tri.end(), {v00, v10, v11, v00, v11, v01});
                }
        }
    }

  private:
    const Scene& scene_;
    std::shared_ptr<const Textures> textures_;  // what displacement_ looks up (kept past the FrameSetup)
    PatchArray patches_;
    std::vector<PlacedQuadric> quadrics_;
    std::vector<float> sides_;  // per patch, sqrt of its shading rate (ReyesView::patchSide)
    std::vector<uint8_t> moving_;
    DisplacementFrame displacement_;
    ReyesView view_;
};

}  // namespace

std::unique_ptr<DisplacedDicer> makeReyesDisplacedDicer(const Scene& scene, const RenderSettings& settings,
                                                        const FrameSetup& frame) {
    bool any = false;
    for (const PatchAttributes& a : scene.attributes)
        any = any || (a.displacement >= 0 && a.kind == SurfaceKind::BicubicBezier);
    if (!any) return nullptr;
    auto dicer = std::make_unique<ReyesDisplacedDicer>(scene, settings, frame);
    if (!dicer->any()) return nullptr;
    return dicer;
}

}  // namespace tessera
