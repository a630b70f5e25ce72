#include "core/subdivision.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <unordered_map>
#include <unordered_set>

#include "core/basis.h"

namespace tessera {

namespace {

// Double-precision point: refinement and the patch masks run in double, rounded to float once.
struct D3 {
    double x = 0, y = 0, z = 0;
    D3() = default;
    D3(double a, double b, double c) : x(a), y(b), z(c) {}
    explicit D3(Vec3 v) : x(v.x), y(v.y), z(v.z) {}
    D3 operator+(D3 b) const { return {x + b.x, y + b.y, z + b.z}; }
    D3 operator-(D3 b) const { return {x - b.x, y - b.y, z - b.z}; }
    D3 operator*(double s) const { return {x * s, y * s, z * s}; }
    D3& operator+=(D3 b) {
        x += b.x, y += b.y, z += b.z;
        return *this;
    }
    Vec3 f() const { return {float(x), float(y), float(z)}; }
};
double dot(D3 a, D3 b) {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}
D3 cross(D3 a, D3 b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

uint64_t edgeKey(int a, int b) {
    if (a > b) std::swap(a, b);
    return (uint64_t(uint32_t(a)) << 32) | uint32_t(b);
}

// One level of the mesh, in the form the refinement and the patch builder share.
struct Level {
    std::vector<D3> p;
    std::vector<int> fOff{0};  // face f: fv[fOff[f] .. fOff[f+1])
    std::vector<int> fv;
    std::vector<char> hole;               // per face
    std::vector<char> cornerTag;          // per vertex
    std::unordered_set<uint64_t> crease;  // tagged sharp edges (boundary edges are sharp implicitly)
    BoundaryMode mode = BoundaryMode::EdgesAndCorners;
    // Where each face lies on the input mesh (SubdivResult::patchBaseFace/patchSubFace/patchUV); sub = -2:
    // an input face other than a quad, not yet split into sub-faces.
    struct Param {
        int base = 0, sub = -1;
        std::array<Vec2, 4> uv{};
    };
    std::vector<Param> param;

    int faces() const { return int(fOff.size()) - 1; }
    int size(int f) const { return fOff[f + 1] - fOff[f]; }
    int vert(int f, int i) const {
        int n = size(f);
        return fv[size_t(fOff[f] + ((i % n) + n) % n)];
    }
};

enum class VType : uint8_t { Smooth, Crease, Corner };

// Half-edge connectivity. Half-edge h = fOff[f] + i runs from vertex i of face f to vertex i + 1.
struct Topo {
    std::vector<int> heFace, twin, heEdge;
    std::vector<std::array<int, 2>> edgeV;   // endpoints, in the direction of the edge's first half-edge
    std::vector<std::array<int, 2>> edgeHe;  // its half-edges (second -1 on the boundary)
    std::vector<char> edgeSharp;
    std::unordered_map<uint64_t, int> edgeId;
    std::vector<int> ringOff, ring;  // outgoing half-edges of each vertex, in order around it
    std::vector<char> boundary;
    std::vector<VType> type;
    std::vector<int> sharpCount;
    std::vector<std::array<int, 2>> creaseNbr;  // the two neighbours along sharp edges (crease vertices)

    const Level* L = nullptr;
    int next(int h) const {
        int f = heFace[size_t(h)], b = L->fOff[size_t(f)], n = L->size(f);
        return b + (h - b + 1) % n;
    }
    int prev(int h) const {
        int f = heFace[size_t(h)], b = L->fOff[size_t(f)], n = L->size(f);
        return b + (h - b + n - 1) % n;
    }
    int from(int h) const { return L->fv[size_t(h)]; }
    int to(int h) const { return L->fv[size_t(next(h))]; }
    int valence(int v) const { return ringOff[size_t(v) + 1] - ringOff[size_t(v)]; }
};

// Builds the connectivity; throws SubdivError for non-manifold input. `origFace` maps a face to the input
// face it descends from (for error messages).
Topo buildTopo(const Level& L, const std::vector<int>* origFace = nullptr) {
    Topo T;
    T.L = &L;
    const int nf = L.faces(), nv = int(L.p.size());
    const size_t nh = L.fv.size();
    auto faceOf = [&](int f) { return origFace ? (*origFace)[size_t(f)] : f; };
    T.heFace.resize(nh);
    for (int f = 0; f < nf; ++f)
        for (int h = L.fOff[size_t(f)]; h < L.fOff[size_t(f) + 1]; ++h) T.heFace[size_t(h)] = f;
    T.twin.assign(nh, -1);
    T.heEdge.assign(nh, -1);
    std::unordered_map<uint64_t, int> directed;
    directed.reserve(nh * 2);
    T.edgeId.reserve(nh);
    for (size_t h = 0; h < nh; ++h) {
        int a = T.from(int(h)), b = T.to(int(h));
        uint64_t dk = (uint64_t(uint32_t(a)) << 32) | uint32_t(b);
        if (!directed.emplace(dk, int(h)).second)
            throw SubdivError("edge (" + std::to_string(a) + ", " + std::to_string(b) +
                                  ") is used twice in the same direction: non-manifold, or faces with "
                                  "inconsistent orientation",
                              faceOf(T.heFace[h]));
        auto [it, fresh] = T.edgeId.emplace(edgeKey(a, b), int(T.edgeV.size()));
        if (fresh) {
            T.edgeV.push_back({a, b});
            T.edgeHe.push_back({int(h), -1});
        } else {
            auto& he = T.edgeHe[size_t(it->second)];
            if (he[1] != -1)
                throw SubdivError("edge (" + std::to_string(a) + ", " + std::to_string(b) +
                                      ") is shared by more than two faces (non-manifold)",
                                  faceOf(T.heFace[h]));
            he[1] = int(h);
            T.twin[h] = he[0];
            T.twin[size_t(he[0])] = int(h);
        }
        T.heEdge[h] = it->second;
    }
    const size_t ne = T.edgeV.size();
    T.edgeSharp.resize(ne);
    for (size_t e = 0; e < ne; ++e)
        T.edgeSharp[e] = T.edgeHe[e][1] == -1 || L.crease.count(edgeKey(T.edgeV[e][0], T.edgeV[e][1])) > 0;

    // Vertex rings.
    std::vector<int> outCount(size_t(nv), 0), start(size_t(nv), -1);
    for (size_t h = 0; h < nh; ++h) {
        int v = T.from(int(h));
        ++outCount[size_t(v)];
        if (T.twin[h] == -1) {
            if (start[size_t(v)] != -1 && T.twin[size_t(start[size_t(v)])] == -1)
                throw SubdivError(
                    "vertex " + std::to_string(v) + " joins separate fans of faces (non-manifold vertex)",
                    faceOf(T.heFace[h]));
            start[size_t(v)] = int(h);
        } else if (start[size_t(v)] == -1) {
            start[size_t(v)] = int(h);
        }
    }
    T.ringOff.assign(size_t(nv) + 1, 0);
    for (int v = 0; v < nv; ++v) T.ringOff[size_t(v) + 1] = T.ringOff[size_t(v)] + outCount[size_t(v)];
    T.ring.resize(nh);
    T.boundary.assign(size_t(nv), 0);
    for (int v = 0; v < nv; ++v) {
        if (start[size_t(v)] < 0) continue;
        int h = start[size_t(v)], k = 0, o = T.ringOff[size_t(v)];
        T.boundary[size_t(v)] = T.twin[size_t(h)] == -1;
        do {
            if (k == outCount[size_t(v)]) break;
            T.ring[size_t(o + k++)] = h;
            h = T.twin[size_t(T.prev(h))];
        } while (h != -1 && h != start[size_t(v)]);
        if (k != outCount[size_t(v)] || (h != -1 && h != start[size_t(v)]))
            throw SubdivError(
                "vertex " + std::to_string(v) + " joins separate fans of faces (non-manifold vertex)",
                faceOf(T.heFace[size_t(start[size_t(v)])]));
    }

    // Vertex types from the sharp edges around each vertex.
    T.sharpCount.assign(size_t(nv), 0);
    T.creaseNbr.assign(size_t(nv), {-1, -1});
    for (size_t e = 0; e < ne; ++e) {
        if (!T.edgeSharp[e]) continue;
        for (int s = 0; s < 2; ++s) {
            int v = T.edgeV[e][size_t(s)], w = T.edgeV[e][size_t(1 - s)];
            int& c = T.sharpCount[size_t(v)];
            if (c < 2) T.creaseNbr[size_t(v)][size_t(c)] = w;
            ++c;
        }
    }
    T.type.assign(size_t(nv), VType::Smooth);
    for (int v = 0; v < nv; ++v) {
        int s = T.sharpCount[size_t(v)];
        bool corner = L.cornerTag[size_t(v)] || s >= 3 ||
                      (T.boundary[size_t(v)] && T.valence(v) == 1 && L.mode == BoundaryMode::EdgesAndCorners);
        T.type[size_t(v)] = corner ? VType::Corner : (s == 2 ? VType::Crease : VType::Smooth);
    }
    return T;
}

// RenderMan "no interpolateboundary": faces touching the boundary are not part of the surface.
void markBoundaryHoles(Level& L, const Topo& T) {
    if (L.mode != BoundaryMode::None) return;
    for (int f = 0; f < L.faces(); ++f)
        for (int i = 0; i < L.size(f); ++i)
            if (T.boundary[size_t(L.vert(f, i))]) L.hole[size_t(f)] = 1;
}

// One Catmull-Clark step (see refineMesh() for the numbering).
Level refine(const Level& L, const Topo& T) {
    const int nv = int(L.p.size()), ne = int(T.edgeV.size()), nf = L.faces();
    Level N;
    N.mode = L.mode;
    N.p.resize(size_t(nv + ne + nf));
    for (int f = 0; f < nf; ++f) {
        D3 s;
        for (int i = 0; i < L.size(f); ++i) s += L.p[size_t(L.vert(f, i))];
        N.p[size_t(nv + ne + f)] = s * (1.0 / L.size(f));
    }
    for (int e = 0; e < ne; ++e) {
        D3 a = L.p[size_t(T.edgeV[size_t(e)][0])], b = L.p[size_t(T.edgeV[size_t(e)][1])];
        if (T.edgeSharp[size_t(e)]) {
            N.p[size_t(nv + e)] = (a + b) * 0.5;
        } else {
            D3 f0 = N.p[size_t(nv + ne + T.heFace[size_t(T.edgeHe[size_t(e)][0])])];
            D3 f1 = N.p[size_t(nv + ne + T.heFace[size_t(T.edgeHe[size_t(e)][1])])];
            N.p[size_t(nv + e)] = (a + b + f0 + f1) * 0.25;
        }
    }
    for (int v = 0; v < nv; ++v) {
        D3 p = L.p[size_t(v)];
        int n = T.valence(v);
        if (n == 0 || T.type[size_t(v)] == VType::Corner) {
            N.p[size_t(v)] = p;
        } else if (T.type[size_t(v)] == VType::Crease) {
            N.p[size_t(v)] =
                (L.p[size_t(T.creaseNbr[size_t(v)][0])] + p * 6.0 + L.p[size_t(T.creaseNbr[size_t(v)][1])]) *
                (1.0 / 8.0);
        } else {  // smooth (interior): (Q + 2R + (n - 3) v) / n
            D3 Q, R;
            for (int k = 0; k < n; ++k) {
                int h = T.ring[size_t(T.ringOff[size_t(v)] + k)];
                Q += N.p[size_t(nv + ne + T.heFace[size_t(h)])];
                R += (p + L.p[size_t(T.to(h))]) * 0.5;
            }
            N.p[size_t(v)] = (Q * (1.0 / n) + R * (2.0 / n) + p * (n - 3.0)) * (1.0 / n);
        }
    }
    N.fv.reserve(L.fv.size() * 4);
    N.fOff.reserve(L.fv.size() + 1);
    for (int f = 0; f < nf; ++f) {
        int b = L.fOff[size_t(f)], k = L.size(f);
        for (int c = 0; c < k; ++c) {
            int h = b + c, hp = b + (c + k - 1) % k;
            N.fv.insert(N.fv.end(),
                        {L.fv[size_t(h)], nv + T.heEdge[size_t(h)], nv + ne + f, nv + T.heEdge[size_t(hp)]});
            N.fOff.push_back(int(N.fv.size()));
            N.hole.push_back(L.hole[size_t(f)]);
            const Level::Param& pp = L.param[size_t(f)];
            Level::Param cp{pp.base, pp.sub, {Vec2{0, 0}, Vec2{1, 0}, Vec2{1, 1}, Vec2{0, 1}}};
            if (pp.sub == -2) {
                cp.sub = c;
            } else {
                auto mid = [](Vec2 a, Vec2 b) { return Vec2{(a.x + b.x) * 0.5f, (a.y + b.y) * 0.5f}; };
                const Vec2 a = pp.uv[size_t(c)], n = pp.uv[size_t((c + 1) % 4)],
                           p = pp.uv[size_t((c + 3) % 4)];
                const Vec2 centre = mid(mid(pp.uv[0], pp.uv[2]), mid(pp.uv[1], pp.uv[3]));
                cp.uv = {a, mid(a, n), centre, mid(p, a)};
            }
            N.param.push_back(cp);
        }
    }
    N.cornerTag.assign(N.p.size(), 0);
    std::copy(L.cornerTag.begin(), L.cornerTag.end(), N.cornerTag.begin());
    for (int e = 0; e < ne; ++e) {
        const auto& ev = T.edgeV[size_t(e)];
        if (T.edgeHe[size_t(e)][1] != -1 && L.crease.count(edgeKey(ev[0], ev[1]))) {
            N.crease.insert(edgeKey(ev[0], nv + e));
            N.crease.insert(edgeKey(nv + e, ev[1]));
        }
    }
    return N;
}

// Exact limit position of vertex v (all faces around a smooth vertex must be quads).
D3 limitPosition(const Level& L, const Topo& T, int v) {
    D3 p = L.p[size_t(v)];
    int n = T.valence(v);
    if (n == 0 || T.type[size_t(v)] == VType::Corner) return p;
    if (T.type[size_t(v)] == VType::Crease)
        return (L.p[size_t(T.creaseNbr[size_t(v)][0])] + p * 4.0 + L.p[size_t(T.creaseNbr[size_t(v)][1])]) *
               (1.0 / 6.0);
    D3 s = p * double(n) * double(n);
    for (int k = 0; k < n; ++k) {
        int h = T.ring[size_t(T.ringOff[size_t(v)] + k)];
        s += L.p[size_t(T.to(h))] * 4.0;
        s += L.p[size_t(L.fv[size_t(T.next(T.next(h)))])];  // diagonal of the quad
    }
    return s * (1.0 / (double(n) * (n + 5)));
}

// Unit normal of the limit tangent plane at a smooth interior vertex (Halstead, Kass, DeRose 1993 tangent
// masks); zero if degenerate.
D3 limitNormal(const Level& L, const Topo& T, int v) {
    const int n = T.valence(v);
    const double pi = std::numbers::pi;
    const double An = 1 + std::cos(2 * pi / n) + std::cos(pi / n) * std::sqrt(2 * (9 + std::cos(2 * pi / n)));
    D3 t1, t2;
    for (int j = 0; j < n; ++j) {
        int h = T.ring[size_t(T.ringOff[size_t(v)] + j)];
        D3 e = L.p[size_t(T.to(h))], d = L.p[size_t(L.fv[size_t(T.next(T.next(h)))])];
        double c0 = std::cos(2 * pi * j / n), c1 = std::cos(2 * pi * (j + 1) / n);
        double s0 = std::sin(2 * pi * j / n), s1 = std::sin(2 * pi * (j + 1) / n);
        t1 += e * (An * c0) + d * (c0 + c1);
        t2 += e * (An * s0) + d * (s0 + s1);
    }
    D3 N = cross(t1, t2);
    double len = std::sqrt(dot(N, N));
    return len > 0 ? N * (1.0 / len) : D3{};
}

bool isQuadRing(const Level& L, const Topo& T, int v) {
    for (int k = T.ringOff[size_t(v)]; k < T.ringOff[size_t(v) + 1]; ++k)
        if (L.size(T.heFace[size_t(T.ring[size_t(k)])]) != 4) return false;
    return true;
}

bool regularVertex(const Level& L, const Topo& T, int v) {
    return !T.boundary[size_t(v)] && T.valence(v) == 4 && T.sharpCount[size_t(v)] == 0 &&
           T.type[size_t(v)] == VType::Smooth && isQuadRing(L, T, v);
}

bool regularFace(const Level& L, const Topo& T, int f) {
    if (L.size(f) != 4) return false;
    for (int i = 0; i < 4; ++i)
        if (!regularVertex(L, T, L.vert(f, i))) return false;
    return true;
}

// Level 0 from the input mesh, with its validation.
Level fromMesh(const SubdivMesh& m, std::vector<std::string>* warnings) {
    Level L;
    L.mode = m.boundary;
    const int nv = int(m.points.size());
    L.p.reserve(m.points.size());
    for (size_t i = 0; i < m.points.size(); ++i) {
        if (!isFinite(m.points[i]))
            throw SubdivError("vertex " + std::to_string(i) + " has a non-finite coordinate");
        L.p.emplace_back(m.points[i]);
    }
    if (m.faceSizes.empty()) throw SubdivError("the mesh has no faces");
    size_t total = 0;
    for (size_t f = 0; f < m.faceSizes.size(); ++f) {
        int k = m.faceSizes[f];
        if (k < 3)
            throw SubdivError("face " + std::to_string(f) + " has " + std::to_string(k) +
                                  " vertices; a face needs at least 3",
                              int(f));
        if (total + size_t(k) > m.faceVerts.size())
            throw SubdivError("the face sizes need more vertex indices than the " +
                                  std::to_string(m.faceVerts.size()) + " given",
                              int(f));
        for (int i = 0; i < k; ++i) {
            int v = m.faceVerts[total + size_t(i)];
            if (v < 0 || v >= nv)
                throw SubdivError("face " + std::to_string(f) + " uses vertex " + std::to_string(v) +
                                      ", outside 0.." + std::to_string(nv - 1),
                                  int(f));
            for (int j = 0; j < i; ++j)
                if (m.faceVerts[total + size_t(j)] == v)
                    throw SubdivError(
                        "face " + std::to_string(f) + " uses vertex " + std::to_string(v) + " twice", int(f));
            L.fv.push_back(v);
        }
        total += size_t(k);
        L.fOff.push_back(int(total));
    }
    if (total != m.faceVerts.size())
        throw SubdivError("the face sizes add up to " + std::to_string(total) + " vertex indices, but " +
                          std::to_string(m.faceVerts.size()) + " are given");
    L.hole.assign(m.faceSizes.size(), 0);
    for (size_t f = 0; f < m.faceSizes.size(); ++f)
        L.param.push_back(
            {int(f), m.faceSizes[f] == 4 ? -1 : -2, {Vec2{0, 0}, Vec2{1, 0}, Vec2{1, 1}, Vec2{0, 1}}});
    for (int h : m.holes) {
        if (h < 0 || size_t(h) >= m.faceSizes.size())
            throw SubdivError("hole face " + std::to_string(h) + " does not exist");
        L.hole[size_t(h)] = 1;
    }
    L.cornerTag.assign(m.points.size(), 0);
    bool semiSharp = false;
    for (const SubdivCorner& c : m.corners) {
        if (c.vertex < 0 || c.vertex >= nv)
            throw SubdivError("corner vertex " + std::to_string(c.vertex) + " does not exist");
        if (c.sharpness <= 0) continue;
        semiSharp |= c.sharpness < 10;
        L.cornerTag[size_t(c.vertex)] = 1;
    }
    for (const SubdivCrease& c : m.creases) {
        if (c.v0 < 0 || c.v0 >= nv || c.v1 < 0 || c.v1 >= nv)
            throw SubdivError("crease vertex " + std::to_string(c.v0 < 0 || c.v0 >= nv ? c.v0 : c.v1) +
                              " does not exist");
        if (c.sharpness <= 0) continue;
        semiSharp |= c.sharpness < 10;
        L.crease.insert(edgeKey(c.v0, c.v1));
    }
    if (semiSharp && warnings)
        warnings->push_back(
            "semi-sharp creases or corners (sharpness below 10) are treated as infinitely sharp");
    return L;
}

SubdivMesh toMesh(const Level& L) {
    SubdivMesh m;
    m.boundary = L.mode;
    m.points.reserve(L.p.size());
    for (const D3& p : L.p) m.points.push_back(p.f());
    for (int f = 0; f < L.faces(); ++f) {
        m.faceSizes.push_back(L.size(f));
        if (L.hole[size_t(f)]) m.holes.push_back(f);
    }
    m.faceVerts = L.fv;
    for (size_t v = 0; v < L.cornerTag.size(); ++v)
        if (L.cornerTag[v]) m.corners.push_back({int(v), 10.f});
    for (uint64_t k : L.crease) m.creases.push_back({int(k >> 32), int(k & 0xffffffffu), 10.f});
    return m;
}

// Patch assembly at the final level.
class PatchBuilder {
  public:
    PatchBuilder(const Level& L, const Topo& T) : L_(L), T_(T) {}

    void build(SubdivResult& out) {
        const int nv = int(L_.p.size());
        // Corners: limit positions, once per vertex.
        limit_.resize(size_t(nv));
        normal_.assign(size_t(nv), D3{});
        for (int v = 0; v < nv; ++v) {
            if (T_.valence(v) == 0) continue;
            limit_[size_t(v)] = limitPosition(L_, T_, v);
            if (T_.type[size_t(v)] == VType::Smooth && T_.sharpCount[size_t(v)] == 0 &&
                !T_.boundary[size_t(v)] && T_.valence(v) != 4 && T_.valence(v) >= 3)
                normal_[size_t(v)] = limitNormal(L_, T_, v);
        }
        // Boundary curves: once per edge of a rendered face.
        const size_t ne = T_.edgeV.size();
        curve_.resize(ne);
        std::vector<char> done(ne, 0);
        for (int f = 0; f < L_.faces(); ++f) {
            if (L_.hole[size_t(f)]) continue;
            for (int h = L_.fOff[size_t(f)]; h < L_.fOff[size_t(f) + 1]; ++h) {
                int e = T_.heEdge[size_t(h)];
                if (done[size_t(e)]) continue;
                done[size_t(e)] = 1;
                int a = T_.edgeV[size_t(e)][0], b = T_.edgeV[size_t(e)][1];
                curve_[size_t(e)] = {limit_[size_t(a)].f(), edgePoint(e, a, b).f(), edgePoint(e, b, a).f(),
                                     limit_[size_t(b)].f()};
            }
        }
        for (int f = 0; f < L_.faces(); ++f) {
            if (L_.hole[size_t(f)]) continue;
            bool exact = regularFace(L_, T_, f);
            BezierPatch p = exact ? bsplinePatch(f) : accPatch(f);
            setBoundary(f, p);
            out.patches.push_back(p);
            out.patchFace.push_back(uint32_t(f));
            out.patchExact.push_back(exact ? 1 : 0);
            const Level::Param& pp = L_.param[size_t(f)];
            out.patchBaseFace.push_back(uint32_t(pp.base));
            out.patchSubFace.push_back(pp.sub);
            out.patchUV.push_back(pp.uv);
            ++(exact ? out.exactCount : out.approxCount);
        }
    }

  private:
    // Loop-Schaefer interior point at corner c of quad f.
    D3 interiorPoint(int f, int c) const {
        int v = L_.vert(f, c);
        int n = (T_.type[size_t(v)] == VType::Smooth && !T_.boundary[size_t(v)]) ? T_.valence(v) : 4;
        return (L_.p[size_t(v)] * double(n) +
                (L_.p[size_t(L_.vert(f, c + 1))] + L_.p[size_t(L_.vert(f, c - 1))]) * 2.0 +
                L_.p[size_t(L_.vert(f, c + 2))]) *
               (1.0 / (n + 5));
    }

    // Corner index of vertex v in face f.
    int cornerOf(int f, int v) const {
        for (int i = 0; i < L_.size(f); ++i)
            if (L_.vert(f, i) == v) return i;
        return 0;
    }

    // Edge control point next to vertex a on edge e = (a, b).
    D3 edgePoint(int e, int a, int b) const {
        if (T_.edgeSharp[size_t(e)]) return (L_.p[size_t(a)] * 2.0 + L_.p[size_t(b)]) * (1.0 / 3.0);
        int f0 = T_.heFace[size_t(T_.edgeHe[size_t(e)][0])], f1 = T_.heFace[size_t(T_.edgeHe[size_t(e)][1])];
        D3 q = (interiorPoint(f0, cornerOf(f0, a)) + interiorPoint(f1, cornerOf(f1, a))) * 0.5;
        const D3& N = normal_[size_t(a)];
        if (N.x != 0 || N.y != 0 || N.z != 0) q = q - N * dot(q - limit_[size_t(a)], N);
        return q;
    }

    // Exact B-spline patch of a regular face from its 4 x 4 neighbourhood.
    BezierPatch bsplinePatch(int f) const {
        static const int origin[4][2] = {{1, 1}, {2, 1}, {2, 2}, {1, 2}};
        static const int axisA[4][2] = {{1, 0}, {0, 1}, {-1, 0}, {0, -1}};
        static const int axisB[4][2] = {{0, 1}, {-1, 0}, {0, -1}, {1, 0}};
        // Ring positions (alpha, beta) of e_0, d_0, e_1, d_1, ... around a valence-4 vertex.
        static const int ringPos[8][2] = {{1, 0},  {1, 1},   {0, 1},  {-1, 1},
                                          {-1, 0}, {-1, -1}, {0, -1}, {1, -1}};
        Vec3 g[16];
        for (int c = 0; c < 4; ++c) {
            int v = L_.vert(f, c), h0 = L_.fOff[size_t(f)] + c;
            int o = T_.ringOff[size_t(v)], k0 = 0;
            while (T_.ring[size_t(o + k0)] != h0) ++k0;
            auto put = [&](int a, int b, Vec3 p) {
                int i = origin[c][0] + a * axisA[c][0] + b * axisB[c][0];
                int j = origin[c][1] + a * axisA[c][1] + b * axisB[c][1];
                g[j * 4 + i] = p;
            };
            put(0, 0, L_.p[size_t(v)].f());
            for (int j = 0; j < 4; ++j) {
                int h = T_.ring[size_t(o + (k0 + j) % 4)];
                put(ringPos[2 * j][0], ringPos[2 * j][1], L_.p[size_t(T_.to(h))].f());
                put(ringPos[2 * j + 1][0], ringPos[2 * j + 1][1],
                    L_.p[size_t(L_.fv[size_t(T_.next(T_.next(h)))])].f());
            }
        }
        return toBezier(g, bsplineBasis(), bsplineBasis());
    }

    BezierPatch accPatch(int f) const {
        BezierPatch p;
        static const int inner[4][2] = {{1, 1}, {2, 1}, {2, 2}, {1, 2}};
        for (int c = 0; c < 4; ++c) p.at(inner[c][0], inner[c][1]) = interiorPoint(f, c).f();
        return p;
    }

    // Copies the shared boundary curves (corners and edge points) into the patch.
    void setBoundary(int f, BezierPatch& p) const {
        for (int s = 0; s < 4; ++s) {
            int h = L_.fOff[size_t(f)] + s;
            int e = T_.heEdge[size_t(h)];
            const std::array<Vec3, 4>& cv = curve_[size_t(e)];
            bool forward = T_.edgeV[size_t(e)][0] == T_.from(h);
            for (int k = 0; k < 4; ++k) {
                Vec3 q = cv[size_t(forward ? k : 3 - k)];
                switch (s) {
                    case 0:
                        p.at(k, 0) = q;
                        break;
                    case 1:
                        p.at(3, k) = q;
                        break;
                    case 2:
                        p.at(3 - k, 3) = q;
                        break;
                    default:
                        p.at(0, 3 - k) = q;
                        break;
                }
            }
        }
    }

    const Level& L_;
    const Topo& T_;
    std::vector<D3> limit_, normal_;
    std::vector<std::array<Vec3, 4>> curve_;
};

}  // namespace

SubdivResult subdivToBezier(const SubdivMesh& mesh, const SubdivOptions& options) {
    SubdivResult out;
    if (options.refineSteps < -1 || options.refineSteps > 4)
        throw SubdivError("refineSteps must be -1 (automatic) or 0..4");
    Level L = fromMesh(mesh, &out.warnings);
    Topo T = buildTopo(L);
    markBoundaryHoles(L, T);
    int steps = options.refineSteps;
    bool allQuads = true;
    for (int f = 0; f < L.faces(); ++f) allQuads &= L.size(f) == 4;
    if (steps < 0) {
        // Regular meshes need no refinement. One step isolates the extraordinary vertices of a quad mesh;
        // after one step a non-quad face leaves quads with two extraordinary corners (its centre and an
        // original vertex), so meshes with other polygons get a second step.
        steps = 0;
        for (int f = 0; f < L.faces() && steps == 0; ++f)
            if (!L.hole[size_t(f)] && !regularFace(L, T, f)) steps = 1;
        if (steps == 1 && !allQuads) steps = 2;
    } else if (steps == 0 && !allQuads) {
        throw SubdivError("refineSteps 0 needs a mesh of quads only; this mesh has other polygons");
    }
    for (int s = 0; s < steps; ++s) {
        L = refine(L, T);
        T = buildTopo(L);
    }
    out.level = steps;
    PatchBuilder(L, T).build(out);
    return out;
}

void validateSubdivMesh(const SubdivMesh& mesh) {
    Level L = fromMesh(mesh, nullptr);
    buildTopo(L);
}

SubdivMesh refineMesh(const SubdivMesh& mesh) {
    Level L = fromMesh(mesh, nullptr);
    Topo T = buildTopo(L);
    markBoundaryHoles(L, T);
    return toMesh(refine(L, T));
}

std::vector<Vec3> limitPositions(const SubdivMesh& mesh) {
    Level L = fromMesh(mesh, nullptr);
    Topo T = buildTopo(L);
    std::vector<Vec3> out(L.p.size());
    for (int v = 0; v < int(L.p.size()); ++v) {
        if (T.type[size_t(v)] == VType::Smooth && T.valence(v) > 0 && !isQuadRing(L, T, v))
            throw SubdivError("limitPositions needs quads around every smooth vertex");
        out[size_t(v)] = limitPosition(L, T, v).f();
    }
    return out;
}

}  // namespace tessera
