#include "reyes/grid.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "reyes/displace.h"

namespace tessera {
namespace {

// Index of the edge vertex that grid vertex i (of n) snaps to, for an edge of `segments` segments:
// round(i * segments / n), in integers so both neighbours compute the same thing.
int snapIndex(int i, int n, int segments) {
    return (2 * i * segments + n) / (2 * n);
}

// (1 - s) p + s q, per component (the bilinear map of a piece's (u,v) quad is two of these and one more).
Vec2 lerpUV(Vec2 p, Vec2 q, float s) {
    return {(1 - s) * p.x + s * q.x, (1 - s) * p.y + s * q.y};
}

// Grid vertex (i,j) of a piece diced nu x nv: its (u,v) on the patch and the edge that owns it (nullptr:
// interior) with its lattice index k. Boundary-curve edges win at corners, so a corner on a patch boundary
// is evaluated exactly as the neighbouring patch evaluates it.
Vec2 pieceVertexUV(const Piece& piece, int i, int j, int nu, int nv, const PieceEdge*& owner, int& k) {
    const PieceEdge* e = piece.edge;
    owner = nullptr;
    k = 0;
    auto consider = [&](const PieceEdge& edge, int idx, int n) {
        if (owner && !(owner->boundary < 0 && edge.boundary >= 0)) return;
        owner = &edge;
        k = edge.latticeAt(snapIndex(idx, n, edge.segments()));
    };
    if (j == 0) consider(e[0], i, nu);
    if (j == nv) consider(e[2], i, nu);
    if (i == 0) consider(e[3], j, nv);
    if (i == nu) consider(e[1], j, nv);
    if (owner) return latticeUV(*owner, k);
    // Interior: bilinear map of the piece's (u,v) quad.
    const float s = float(i) / nu, t = float(j) / nv;
    return lerpUV(lerpUV(piece.uv[0], piece.uv[1], s), lerpUV(piece.uv[3], piece.uv[2], s), t);
}

// The canonical control points of a piece's patch-boundary edges, derived once per grid (latticePosition
// derives them again for each vertex it places: half of a small grid's vertices lie on its edges). On an
// edge inside the patch the lattice point is the patch at latticeUV(edge, k), which is the vertex's own
// (u, v), so `atUV` (evalPatchAt / evalPatchDerivAt there: evalPatch's bits, bezier.h) is that point.
struct EdgeCurves {
    Vec3 cp[4][4];
    EdgeCurves(const BezierPatch& patch, const PieceEdge* edges, bool bezier) {
        for (int ed = 0; ed < 4 && bezier; ++ed)
            if (edges[ed].boundary >= 0) {
                Vec2 a, b;
                canonicalBoundary(patch, edges[ed].boundary, cp[ed], a, b);
            }
    }
    // = latticePosition(patch, owner, k) for the owner edges of a vertex at (u, v) = latticeUV(owner, k).
    Vec3 position(const PieceEdge* edges, const PieceEdge& owner, int k, const Vec3& atUV) const {
        return owner.boundary >= 0 ? evalCurve(cp[&owner - edges], owner.param(k)) : atUV;
    }
};

// The grid's vertices in a column mostly share their u (bit for bit): the rows of the control net summed at
// that u are kept per column and reused down it (evalPatchAt / evalPatchDerivAt: the same bits as evalPatch
// / evalPatchDeriv, in about a third of their work).
struct ColumnRows {
    std::vector<PatchRowsAtU> rows;
    std::vector<uint32_t> uBits;  // the u bits rows[i] holds
    void reset(int nu) {
        rows.resize(size_t(nu) + 1);
        uBits.assign(size_t(nu) + 1, 0xffffffffu);  // a NaN: no u has these bits
    }
    const PatchRowsAtU& at(const BezierPatch& patch, int i, float u) {
        uint32_t bits;
        std::memcpy(&bits, &u, sizeof bits);
        if (uBits[size_t(i)] != bits) patchRowsAtU(patch, u, rows[size_t(i)]), uBits[size_t(i)] = bits;
        return rows[size_t(i)];
    }
};

// A shadow map's depth pass (shade.depthOnly): each vertex's raster position and depth only, both sides, no
// colour (a depth grid holds nu, nv, X, Y, Z, twoSided and objectId: rasterizeGridDepth reads no more).
// The positions are diceAndShadeSurface's: the edges' vertices by their owner edge (pieceVertexUV), the
// interior ones by the bilinear map of the piece's (u,v) quad, its terms in s kept per column (the same
// operations as pieceVertexUV's, so the same bits), evaluated through the column's rows of the net.
void diceDepthOnly(const ReyesView& view, const Piece& piece, const ShadeInputs& shade, Grid& grid) {
    const BezierPatch& patch = view.patches[piece.patch];
    const PieceEdge* e = piece.edge;
    const int nu = pieceGridU(piece), nv = pieceGridV(piece);
    grid.nu = nu;
    grid.nv = nv;
    grid.twoSided = true;  // depth maps see both sides, as shadow rays do
    grid.objectId = shade.objectId;
    const int count = (nu + 1) * (nv + 1);
    grid.X.resize(count);
    grid.Y.resize(count);
    grid.Z.resize(count);
    const PlacedQuadric* quadric = shade.quadric;
    const bool displaced = view.displacement && view.displacement->displaced(piece.patch);
    const EdgeCurves edgeCurves(patch, e, /*bezier=*/!quadric);
    thread_local ColumnRows columns;
    columns.reset(nu);
    thread_local std::vector<Vec2> columnAB, columnDC;  // per column: (1 - s) a + s b and (1 - s) d + s c
    columnAB.resize(size_t(nu) + 1);
    columnDC.resize(size_t(nu) + 1);
    for (int i = 0; i <= nu; ++i) {
        const float s = float(i) / nu;
        columnAB[size_t(i)] = lerpUV(piece.uv[0], piece.uv[1], s);
        columnDC[size_t(i)] = lerpUV(piece.uv[3], piece.uv[2], s);
    }
    auto place = [&](int v, int i, Vec2 uv, const PieceEdge* owner, int k) {
        Vec3 P = quadric                         ? quadricPoint(*quadric, uv)
                 : owner && owner->boundary >= 0 ? edgeCurves.position(e, *owner, k, Vec3{})
                                                 : evalPatchAt(columns.at(patch, i, uv.x), uv.y);
        if (displaced)
            P = displaceVertex(view, *view.displacement, piece.patch, owner, k, uv, P, shade.flipNormal,
                               /*normal=*/false)
                    .P;
        const Vec3 r = view.projector.toRaster(P);
        grid.X[v] = rasterToFixed(r.x);
        grid.Y[v] = rasterToFixed(r.y);
        grid.Z[v] = P.z;
    };
    for (int j = 0; j <= nv; ++j) {
        const int row = j * (nu + 1);
        if (j == 0 || j == nv) {
            for (int i = 0; i <= nu; ++i) {
                const PieceEdge* owner = nullptr;
                int k = 0;
                const Vec2 uv = pieceVertexUV(piece, i, j, nu, nv, owner, k);  // sets owner and k
                place(row + i, i, uv, owner, k);
            }
            continue;
        }
        const float t = float(j) / nv;
        for (int i = 0; i <= nu; ++i) {
            if (i == 0 || i == nu) {
                const PieceEdge* owner = nullptr;
                int k = 0;
                const Vec2 uv = pieceVertexUV(piece, i, j, nu, nv, owner, k);  // sets owner and k
                place(row + i, i, uv, owner, k);
                continue;
            }
            place(row + i, i, lerpUV(columnAB[size_t(i)], columnDC[size_t(i)], t), nullptr, 0);
        }
    }
}

// Dice and shade a piece of a bicubic Bezier patch or, with shade.quadric, of a quadric.
void diceAndShadeSurface(const ReyesView& view, const Piece& piece, const ShadeInputs& shade, Grid& grid) {
    if (shade.depthOnly) return diceDepthOnly(view, piece, shade, grid);
    const BezierPatch& patch = view.patches[piece.patch];
    const PieceEdge* e = piece.edge;
    const int nu = pieceGridU(piece), nv = pieceGridV(piece);
    grid.nu = nu;
    grid.nv = nv;
    grid.twoSided = shade.twoSided;
    const int count = (nu + 1) * (nv + 1);
    grid.X.resize(count);
    grid.Y.resize(count);
    grid.Z.resize(count);
    grid.R.resize(count);
    grid.G.resize(count);
    grid.B.resize(count);
    grid.front.resize(count);
    // Dice first (positions, normals, view directions of the whole grid), then shade the grid as one batch.
    thread_local std::vector<Vec3> Ps, Ns, Is;
    thread_local std::vector<Color> Ci, Ct, Cv;
    thread_local std::vector<Vec3> shadowP;  // user normals: where shadow lookups start (terminatorSafePoint)
    // Textures on bicubic patches only (quadrics have no s, t yet).
    const bool textured = shade.textures && shade.material->texture >= 0 && !shade.quadric;
    // Per-vertex values (polygons' "N" and "Cs"): bicubic patches only, as the reader gives them.
    const PatchVertexValues* vv = shade.quadric ? nullptr : shade.vertexValues;
    const bool vertexColoured = vv && vv->hasCs;
    if (textured) Ct.resize(count);
    if (vertexColoured) Cv.resize(count);
    Ps.resize(count);
    Ns.resize(count);
    Is.resize(count);
    Ci.resize(count);
    // Where each vertex came from: its (u,v) (for shadow rays' self-intersection guard), and its edge and
    // lattice point, to evaluate it again at the other knots of a moving patch.
    const PlacedQuadric* quadric = shade.quadric;
    const bool moves = !quadric && view.patchMoves(piece.patch) && view.knotCount() > 1;
    // Displacement (reyes/displace.h): each vertex moves along the exact normal; a moving patch keeps the
    // offsets of shutter open at its other knots.
    const bool displaced = view.displacement && view.displacement->displaced(piece.patch);
    // User normals shade undisplaced surfaces only (displacement moves along the exact normal).
    const bool userNormals = vv && vv->hasN && !displaced;
    if (userNormals) shadowP.resize(count);
    thread_local std::vector<Vec3> offsets;
    if (displaced && moves) offsets.resize(count);
    thread_local std::vector<Vec2> UVs;
    thread_local std::vector<int> owners, lattice;
    UVs.resize(count);
    if (moves) {
        owners.resize(count);
        lattice.resize(count);
    }

    thread_local ColumnRows columns;  // the rows of the net at each column's u
    columns.reset(nu);
    const EdgeCurves edgeCurves(patch, e, /*bezier=*/!shade.quadric);
    for (int j = 0; j <= nv; ++j) {
        for (int i = 0; i <= nu; ++i) {
            const PieceEdge* owner = nullptr;
            int k = 0;
            const Vec2 uv = pieceVertexUV(piece, i, j, nu, nv, owner, k);
            const int v = j * (nu + 1) + i;
            Vec3 P, N;
            SurfacePoint sp{};
            if (quadric) {
                // Closed form: on an edge uv is the lattice point's own (latticeUV), so neighbours agree.
                P = quadricPoint(*quadric, uv);
                evalPlacedQuadric(*quadric, uv.x, uv.y, &N);
            } else {
                sp = evalPatchDerivAt(columns.at(patch, i, uv.x), uv.y);
                P = owner ? edgeCurves.position(e, *owner, k, sp.p) : sp.p;
                N = cross(sp.dpdu, sp.dpdv);
                float scale = dot(sp.dpdu, sp.dpdu) + dot(sp.dpdv, sp.dpdv);
                if (!(dot(N, N) > 1e-12f * scale * scale)) N = patchNormal(patch, uv.x, uv.y);
                N = normalize(N);
            }
            if (shade.flipNormal) N = -N;

            UVs[v] = uv;
            if (moves) {
                owners[v] = owner ? int(owner - e) : -1;
                lattice[v] = k;
            }
            // Texture coordinates follow the vertex's (u,v) on the patch, so they follow every split.
            if (textured)
                Ct[v] = surfaceTextureColor(*shade.textures, *shade.material, view.projector, shade.texCoords,
                                            P, sp.dpdu, sp.dpdv, uv, shade.textureScale);
            if (vertexColoured) Cv[v] = bilinearCorners(vv->Cs, uv.x, uv.y);
            if (displaced && !view.exactDisplacementNormals) {
                const Vec3 d = N * displacementAmplitude(view, *view.displacement, piece.patch, uv, sp);
                if (moves) offsets[v] = d;
                P = P + d;
            } else if (displaced) {
                const DisplacedVertex d =
                    displaceVertex(view, *view.displacement, piece.patch, owner, k, uv, P, shade.flipNormal);
                if (moves) offsets[v] = d.P - P;
                P = d.P;
                N = d.N;
            }
            Ps[v] = P;
            // The user's normals shade; the geometric one decides the side (Sides 1 culling).
            Ns[v] = userNormals ? vertexNormalAt(*vv, uv.x, uv.y, N) : N;
            if (userNormals) shadowP[v] = terminatorSafePoint(*vv, patch, uv.x, uv.y, P, N);
            Is[v] = normalize(P);  // the eye is at the camera-space origin
            Vec3 r = view.projector.toRaster(P);
            grid.X[v] = rasterToFixed(r.x);
            grid.Y[v] = rasterToFixed(r.y);
            grid.Z[v] = P.z;
            grid.front[v] = dot(N, P) < 0.f;
        }
    }
    if (displaced && !view.exactDisplacementNormals) {
        // The approximate mode's shading normals: central differences of the displaced grid (one-sided at
        // its borders), kept on the side of the undisplaced normal.
        const int stride = nu + 1;
        for (int j = 0; j <= nv; ++j)
            for (int i = 0; i <= nu; ++i) {
                const int v = j * stride + i;
                const Vec3 du = Ps[j * stride + std::min(i + 1, nu)] - Ps[j * stride + std::max(i - 1, 0)];
                const Vec3 dv = Ps[std::min(j + 1, nv) * stride + i] - Ps[std::max(j - 1, 0) * stride + i];
                Vec3 n = cross(du, dv);
                if (!(dot(n, n) > 0.f)) continue;
                n = normalize(n);
                Ns[v] = dot(n, Ns[v]) < 0.f ? -n : n;
                grid.front[v] = dot(Ns[v], Ps[v]) < 0.f;
            }
    }
    grid.blurred = moves || view.lens;
    grid.knots = 1;
    if (grid.blurred) {
        grid.knots = moves ? view.knotCount() : 1;
        const size_t n = size_t(grid.knots) * count;
        grid.knotX.resize(n), grid.knotY.resize(n), grid.knotZ.resize(n), grid.knotC.resize(n);
        grid.knotValid.resize(n);
        const Projector& pr = view.projector;
        auto store = [&](size_t at, const Vec3& P) {
            const bool valid = !pr.perspective || P.z >= pr.nearClip;
            const Vec3 r = valid ? pr.toRaster(P) : Vec3{};
            grid.knotX[at] = r.x, grid.knotY[at] = r.y, grid.knotZ[at] = P.z;
            grid.knotC[at] = (valid && pr.hasLens() && pr.perspective) ? pr.lensCoefficient(P.z) : 0.f;
            grid.knotValid[at] = valid;
        };
        for (int v = 0; v < count; ++v) store(size_t(v), Ps[v]);
        for (int kn = 1; kn < grid.knots; ++kn) {
            // The same lattice points and (u,v) on the patch at knot kn: shared edges stay identical, so
            // the blurred grid stays crack-free at every time.
            // Boundary curves in the order fixed at shutter open (orientedBoundary), once per edge.
            const BezierPatch& at = view.knotPatches[kn][piece.patch];
            Vec3 curve[4][4];
            for (int ed = 0; ed < 4; ++ed)
                if (e[ed].boundary >= 0) orientedBoundary(at, e[ed], curve[ed]);
            for (int v = 0; v < count; ++v) {
                Vec3 P;
                if (owners[v] >= 0 && e[owners[v]].boundary >= 0)
                    P = evalCurve(curve[owners[v]], e[owners[v]].param(lattice[v]));
                else if (owners[v] >= 0)
                    P = latticePosition(at, e[owners[v]], lattice[v]);  // an interior line: through the patch
                else
                    P = evalPatch(at, UVs[v].x, UVs[v].y);
                store(size_t(kn) * count + v, displaced ? P + offsets[v] : P);
            }
        }
        // What the blurred rasterizer's bounds need of the whole grid, once per grid (not per bucket).
        grid.motionPixels = 0.f;
        grid.allKnotsValid = true;
        for (int v = 0; v < count; ++v) {
            float path = 0.f;
            for (int kn = 0; kn < grid.knots; ++kn) {
                const size_t at = size_t(kn) * count + v;
                grid.allKnotsValid = grid.allKnotsValid && grid.knotValid[at];
                if (kn > 0) {
                    const size_t prev = at - size_t(count);
                    path += std::abs(grid.knotX[at] - grid.knotX[prev]) +
                            std::abs(grid.knotY[at] - grid.knotY[prev]);
                }
            }
            grid.motionPixels = std::max(grid.motionPixels, path);
        }
    }
    SurfacePoints points;
    points.count = size_t(count);
    points.P = Ps.data();
    points.N = Ns.data();
    points.I = Is.data();
    points.textureColor = textured ? Ct.data() : nullptr;
    points.vertexColor = vertexColoured ? Cv.data() : nullptr;
    const std::span<const Material> material(shade.material, 1);
    bool queries = false, fileMaps = false;
    for (const ShadingLight& l : shade.lights) {
        queries = queries || (shade.visibility && l.castsShadows);
        fileMaps = fileMaps || l.shadowMap;
    }
    if (queries || fileMaps) {
        // The shading module's three steps, the visibility queries answered by shadow maps or rays (maps
        // read from files answer in sampleLights).
        thread_local LightSamples samples;
        sampleLights(shade.lights, material, points, samples);
        if (queries) {
            thread_local std::vector<uint32_t> patchOf;
            patchOf.assign(count, piece.patch);
            SurfacePoints from = points;
            if (userNormals) from.P = shadowP.data();
            shade.visibility->answer(VisibilityQuery{from, shade.lights, patchOf.data(), UVs.data(), 0.f},
                                     samples);
        }
        shadeSurfaces(material, points, samples, Ci.data());
        if (shade.wantShadowCounts) {
            // A light counts as in shadow where more than half of it is blocked (the ray tracer's shadow
            // rays are all or nothing).
            grid.shadowedLights.assign(count, 0);
            for (int v = 0; v < count; ++v)
                for (size_t l = 0; l < samples.lights; ++l) {
                    const size_t i = samples.index(size_t(v), l);
                    grid.shadowedLights[v] += samples.visibility[i] < 0.5f;
                }
        }
    } else {
        // No light casts shadows: every query would answer "visible"; the fused form of sampleLights +
        // shadeSurfaces.
        shadeSurfacesUnoccluded(shade.lights, material, points, Ci.data());
    }
    grid.objectId = shade.objectId;
    grid.textured = textured;
    if (shade.wantNormals) {
        grid.NX.resize(count);
        grid.NY.resize(count);
        grid.NZ.resize(count);
        for (int v = 0; v < count; ++v) {
            const Vec3 Nf = faceForward(Ns[v], Is[v]);
            grid.NX[v] = Nf.x, grid.NY[v] = Nf.y, grid.NZ[v] = Nf.z;
        }
    }
    grid.albedo.clear(), grid.P.clear(), grid.Cs.clear();
    if (shade.wantSurfaceAovs) {
        grid.albedo.resize(count), grid.P.resize(count), grid.Cs.resize(count);
        for (int v = 0; v < count; ++v) {
            const Material m = points.materialAt(material, size_t(v));
            const Color Ctv = points.textureOf(size_t(v));
            grid.albedo[v] = surfaceAlbedo(m, Ctv);
            grid.P[v] = Ps[v];
            grid.Cs[v] = m.Cs * Ctv;
        }
    }
    if (maxComponent(shade.emission) > 0.f)
        for (int v = 0; v < count; ++v)
            if (dot(Ns[v], Is[v]) < 0.f) Ci[v] += shade.emission;  // the front side faces the eye
    for (int v = 0; v < count; ++v) {
        grid.R[v] = Ci[v].x;
        grid.G[v] = Ci[v].y;
        grid.B[v] = Ci[v].z;
    }
}

}  // namespace

void dicePieceVertices(const ReyesView& view, const Piece& piece, bool flipNormal, int& nu, int& nv,
                       std::vector<Vec3>& P, std::vector<Vec3>& N, std::vector<Vec2>& UV, bool uvOnly) {
    const BezierPatch& patch = view.patches[piece.patch];
    nu = pieceGridU(piece), nv = pieceGridV(piece);
    const size_t count = size_t(nu + 1) * size_t(nv + 1);
    UV.resize(count);
    if (!uvOnly) P.resize(count), N.resize(count);
    const bool displaced = view.displacement && view.displacement->displaced(piece.patch);
    for (int j = 0; j <= nv; ++j)
        for (int i = 0; i <= nu; ++i) {
            const PieceEdge* owner = nullptr;
            int k = 0;
            const Vec2 uv = pieceVertexUV(piece, i, j, nu, nv, owner, k);
            const size_t v = size_t(j) * size_t(nu + 1) + size_t(i);
            UV[v] = uv;
            if (uvOnly) continue;
            // As diceAndShadeSurface: canonical lattice positions on edges, the patch's exact normal.
            const SurfacePoint sp = evalPatchDeriv(patch, uv.x, uv.y);
            Vec3 p = owner ? latticePosition(patch, *owner, k) : sp.p;
            Vec3 n = cross(sp.dpdu, sp.dpdv);
            const float scale = dot(sp.dpdu, sp.dpdu) + dot(sp.dpdv, sp.dpdv);
            if (!(dot(n, n) > 1e-12f * scale * scale)) n = patchNormal(patch, uv.x, uv.y);
            n = normalize(n);
            if (flipNormal) n = -n;
            if (displaced) {
                const DisplacedVertex d =
                    displaceVertex(view, *view.displacement, piece.patch, owner, k, uv, p, flipNormal);
                p = d.P, n = d.N;
            }
            P[v] = p, N[v] = n;
        }
}

void diceAndShade(const ReyesView& view, const Piece& piece, const ShadeInputs& shade, Grid& grid) {
    switch (shade.kind) {
        case SurfaceKind::BicubicBezier:
        case SurfaceKind::Sphere:
        case SurfaceKind::Cylinder:
        case SurfaceKind::Cone:
        case SurfaceKind::Disk:
        case SurfaceKind::Paraboloid:
        case SurfaceKind::Hyperboloid:
        case SurfaceKind::Torus:
            // One dicer: the kinds differ only in how a (u,v) is evaluated (shade.quadric).
            diceAndShadeSurface(view, piece, shade, grid);
            return;
    }
}

}  // namespace tessera
