#include "io/rib_geometry.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/basis.h"
#include "core/hash.h"
#include "core/nurbs.h"
#include "core/subdivision.h"
#include "io/subdiv_osd.h"
#include "shading/texture.h"

namespace tessera::rib {

namespace {

bool sameMaterial(const Material& a, const Material& b) {
    return a == b;  // every field (glossy's samples and spread too)
}

bool isBezier(const Basis& b) {
    Basis z = bezierBasis();
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            if (b.m[i][j] != z.m[i][j]) return false;
    return true;
}

uint32_t materialIndex(const PrimitiveContext& c, const Material& m) {
    Scene& scene = c.scene;
    if (c.materials) return c.materials->indexOf(scene, m);
    for (size_t i = 0; i < scene.materials.size(); ++i)
        if (sameMaterial(scene.materials[i], m)) return uint32_t(i);
    scene.materials.push_back(m);
    return uint32_t(scene.materials.size() - 1);
}

// Huge coordinates or transformations can overflow single precision: reject them rather than render NaNs.
// (An exponent of all ones is an infinity or a NaN: tested on the bits of all 48 numbers at once, a loop the
// compiler vectorizes.)
void checkFinite(const BezierPatch& b, int line, const Diagnostics& diag) {
    static_assert(sizeof(b.cp) == 48 * sizeof(float), "control points are 16 packed x, y, z");
    uint32_t words[48];
    std::memcpy(words, b.cp, sizeof(words));
    uint32_t notFinite = 0;
    for (uint32_t w : words) notFinite |= uint32_t((w & 0x7f800000u) == 0x7f800000u);
    if (notFinite)
        diag.fail(line, "control point out of range after transformation (overflows single precision)");
}

// Reads one primitive request: Patch and PatchMesh (RI spec 3.2, sec. 5.2), NuPatch (sec. 5.3),
// SubdivisionMesh (sec. 5.6).
class PrimitiveReader {
  public:
    PrimitiveReader(const PrimitiveContext& c, const Request& r)
        : state_(c.state),
          decls_(c.decls),
          diag_(c.diag),
          camera_(c.scene.camera),
          subdivLevel_(c.subdivLevel),
          rasterWidth_(c.rasterWidth),
          rasterHeight_(c.rasterHeight) {
        shape_.request = r.name;
        shape_.line = r.line;
    }

    PrimitiveShape& shape() { return shape_; }

    void requireWorld(const Request& r) const {
        if (!state_.inWorld()) diag_.fail(r.line, r.name + " outside WorldBegin/WorldEnd");
    }

    // Vertex positions from "P" (or "Pw" with w == 1); nullopt if the primitive must be skipped.
    std::optional<std::vector<Vec3>> positions(const Request& r, const std::vector<Param>& ps, size_t n,
                                               const std::string& what) {
        std::optional<std::vector<Vec3>> out;
        for (const Param& p : ps) {
            const std::vector<double>& v = p.value->nums;
            if (p.name == "P") {
                if (!p.value->numeric() || v.size() != 3 * n)
                    diag_.fail(p.line, what + ": \"P\" needs " + std::to_string(3 * n) + " numbers (" +
                                           std::to_string(n) + " points), got " +
                                           std::to_string(p.value->size()));
                out.emplace();
                out->reserve(n);
                for (size_t i = 0; i < n; ++i)
                    out->push_back({float(v[3 * i]), float(v[3 * i + 1]), float(v[3 * i + 2])});
            } else if (p.name == "Pw") {
                if (!p.value->numeric() || v.size() != 4 * n)
                    diag_.fail(p.line, what + ": \"Pw\" needs " + std::to_string(4 * n) + " numbers (" +
                                           std::to_string(n) + " homogeneous points), got " +
                                           std::to_string(p.value->size()));
                out.emplace();
                out->reserve(n);
                for (size_t i = 0; i < n; ++i) {
                    if (std::fabs(v[4 * i + 3] - 1.0) > 1e-9)
                        diag_.fail(p.line,
                                   what + ": rational patches are not supported (\"Pw\" with w != 1)");
                    out->push_back({float(v[4 * i]), float(v[4 * i + 1]), float(v[4 * i + 2])});
                }
            } else if (p.name == "Pz") {
                diag_.warnOnce("Pz", p.line,
                               what + ": \"Pz\" height fields are not supported; primitive skipped");
                return std::nullopt;
            } else if (!isTexCoordParam(p.name) &&
                       !((p.name == "Cs" || p.name == "N") && polygonValuesRead_)) {
                warnIgnoredParam(p, r.name, diag_);
            }
        }
        if (!out) diag_.fail(r.line, what + ": missing the position parameter \"P\"");
        return out;
    }

    static bool isTexCoordParam(const std::string& name) {
        return name == "st" || name == "s" || name == "t";
    }

    // The varying s, t values of "st" or "s" and "t" (RI spec 3.2, sec. 5: `n` values, one per patch
    // corner, interpolated bilinearly); nullopt when the primitive gives none. Any other storage class is
    // warned about and ignored.
    std::optional<std::vector<Vec2>> varyingTexCoords(const Request& r, const std::vector<Param>& ps,
                                                      size_t n, const std::string& what) {
        const Param *st = nullptr, *s = nullptr, *t = nullptr;
        for (const Param& p : ps) {
            if (!isTexCoordParam(p.name)) continue;
            const std::string cls = p.decl ? p.decl->cls : "";
            const int per = p.name == "st" ? 2 : 1;
            if ((cls != "varying" && cls != "facevarying") || !p.decl || p.decl->type != "float" ||
                p.decl->arraySize != per || !p.value->numeric()) {
                diag_.warnOnce("stclass:" + p.name, p.line,
                               what + ": \"" + p.name + "\" is used as \"varying float" +
                                   (per == 2 ? "[2]" : "") + "\" only; ignored");
                continue;
            }
            if (p.value->nums.size() != n * size_t(per))
                diag_.fail(p.line, what + ": \"" + p.name + "\" needs " + std::to_string(n * size_t(per)) +
                                       " numbers (" + std::to_string(n) + " varying values), got " +
                                       std::to_string(p.value->nums.size()));
            (p.name == "st" ? st : p.name == "s" ? s : t) = &p;
        }
        if (!st && !s && !t) return std::nullopt;
        if (st && (s || t))
            diag_.warnOnce("stboth", r.line, what + ": both \"st\" and \"s\"/\"t\" given; \"st\" is used");
        std::vector<Vec2> out(n);
        for (size_t i = 0; i < n; ++i) {
            if (st) {
                out[i] = {float(st->value->nums[2 * i]), float(st->value->nums[2 * i + 1])};
                continue;
            }
            out[i] = {s ? float(s->value->nums[i]) : 0.f, t ? float(t->value->nums[i]) : 0.f};
        }
        for (const Vec2& v : out)
            if (!std::isfinite(v.x) || !std::isfinite(v.y) || std::fabs(v.x) > 1e30f ||
                std::fabs(v.y) > 1e30f)
                diag_.fail(r.line, what + ": texture coordinates must be finite numbers");
        return out;
    }
    // The default s, t at global parameter (u, v): TextureCoordinates' bilinear map of the unit square.
    Vec2 defaultTexCoords(double u, double v) const {
        return texCoordsAt(state_.attributes().textureCoordinates, float(u), float(v));
    }
    bool hasDefaultTexCoords() const {
        const PatchTexCoords& tc = state_.attributes().textureCoordinates;
        const PatchTexCoords id;
        for (int k = 0; k < 4; ++k)
            if (tc.st[k].x != id.st[k].x || tc.st[k].y != id.st[k].y) return false;
        return true;
    }

    void addPatch(const Vec3 g[16], bool bicubic) {
        BezierPatch b;
        if (!bicubic) {
            // Degree elevation of the bilinear patch: its bicubic Bezier control net samples the
            // bilinear map at thirds, which is exact (linear precision of Bernstein polynomials).
            for (int v = 0; v < 4; ++v)
                for (int u = 0; u < 4; ++u) {
                    float s = u / 3.f, t = v / 3.f;
                    Vec3 lo = u == 3 ? g[1] : (u == 0 ? g[0] : lerp(g[0], g[1], s));
                    Vec3 hi = u == 3 ? g[3] : (u == 0 ? g[2] : lerp(g[2], g[3], s));
                    b.at(u, v) = v == 0 ? lo : (v == 3 ? hi : lerp(lo, hi, t));
                }
        } else if (isBezier(state_.attributes().uBasis) && isBezier(state_.attributes().vBasis)) {
            for (int k = 0; k < 16; ++k) b.cp[k] = g[k];
        } else {
            b = toBezier(g, state_.attributes().uBasis, state_.attributes().vBasis);
        }
        shape_.patches.push_back(b);
    }

    // The number of points in the request's "P" (or "Pw") parameter, looked for from argument `start`
    // (0 if it has none: positions() then reports the missing "P").
    size_t pointCount(const Request& r, size_t start) const {
        for (size_t i = start; i + 1 < r.args.size(); ++i) {
            const Value& name = r.args[i];
            if (name.kind != Value::Kind::String || (name.strs[0] != "P" && name.strs[0] != "Pw")) continue;
            const size_t per = name.strs[0] == "P" ? 3 : 4;
            const Value& v = r.args[i + 1];
            if (!v.numeric() || v.nums.size() % per != 0 || v.nums.empty())
                diag_.fail(v.line, r.name + ": \"" + name.strs[0] + "\" needs a multiple of " +
                                       std::to_string(per) + " numbers, got " + describe(v));
            return v.nums.size() / per;
        }
        return 0;
    }

    // A polygon corner: its point (index into "P", and into vertex/varying values) and its place in the
    // request's vertex list (the index of its facevarying values).
    struct Corner {
        int point = 0, fv = 0;
    };
    // Per-corner s, t of the polygon primitives: one value per point (vertex/varying) or per corner
    // (facevarying); empty: the default (none stored).
    struct PolygonTexCoords {
        std::vector<Vec2> st;
        bool faceVarying = false;
        Vec2 at(const Corner& c) const { return st[size_t(faceVarying ? c.fv : c.point)]; }
    };
    PolygonTexCoords polygonTexCoords_;
    // "Cs" and "N" of the polygon primitives (RI spec 3.2, sec. 5.1 and 5.6): one value for all (constant),
    // per polygon (uniform), per point (vertex, varying) or per corner (facevarying); class None: not given.
    // polygonValuesRead_: the primitive's "Cs" and "N" were looked at (positions() does not warn about them).
    struct PolygonValues {
        enum class Class { None, Constant, Uniform, Vertex, FaceVarying } cls = Class::None;
        std::vector<Vec3> v;
        bool given() const { return cls != Class::None; }
        bool perCorner() const { return cls == Class::Vertex || cls == Class::FaceVarying; }
        Vec3 at(const Corner& c, size_t polygon) const {
            switch (cls) {
                case Class::Constant:
                    return v[0];
                case Class::Uniform:
                    return v[polygon];
                case Class::Vertex:
                    return v[size_t(c.point)];
                default:
                    return v[size_t(c.fv)];
            }
        }
    };
    PolygonValues polygonColors_, polygonNormals_;
    bool polygonValuesRead_ = false;
    size_t polygonIndex_ = 0;  // the polygon whose pieces are being added

    // Reads "Cs" (type color) or "N" (type normal) of a polygon primitive with `npolygons` polygons,
    // `npoints` points and `ncorners` corners into `out`. A value of another type or class is warned about
    // and ignored; a wrong count or a non-finite number is an error at its line.
    void readPolygonValues(const std::vector<Param>& ps, const std::string& name, const std::string& type,
                           size_t npolygons, size_t npoints, size_t ncorners, const std::string& what,
                           PolygonValues& out) {
        polygonValuesRead_ = true;
        out = PolygonValues{};
        for (const Param& p : ps) {
            if (p.name != name) continue;
            const std::string cls = p.decl ? p.decl->cls : "";
            using C = PolygonValues::Class;
            const C c = cls == "constant"                             ? C::Constant
                        : cls == "uniform"                            ? C::Uniform
                        : cls == "vertex" || cls == "varying"         ? C::Vertex
                        : cls == "facevarying" || cls == "facevertex" ? C::FaceVarying
                                                                      : C::None;
            if (!p.decl || p.decl->type != type || p.decl->arraySize != 1 || !p.value->numeric() ||
                c == C::None) {
                diag_.warnOnce(
                    name + ":" + what, p.line,
                    what + ": \"" + name + "\" is used as a " + type +
                        " of class constant, uniform, vertex, varying or facevarying only; ignored");
                continue;
            }
            const size_t n = c == C::Constant  ? 1
                             : c == C::Uniform ? npolygons
                             : c == C::Vertex  ? npoints
                                               : ncorners;
            if (p.value->nums.size() != 3 * n)
                diag_.fail(p.line, what + ": \"" + name + "\" needs " + std::to_string(3 * n) + " numbers (" +
                                       std::to_string(n) + " " + cls + " values), got " +
                                       std::to_string(p.value->nums.size()));
            out.cls = c;
            out.v.clear();
            for (size_t i = 0; i < n; ++i) {
                const Vec3 x{float(p.value->nums[3 * i]), float(p.value->nums[3 * i + 1]),
                             float(p.value->nums[3 * i + 2])};
                if (!isFinite(x)) diag_.fail(p.line, what + ": \"" + name + "\" must be finite numbers");
                out.v.push_back(x);
            }
        }
    }
    void readPolygonValues(const std::vector<Param>& ps, size_t npolygons, size_t npoints, size_t ncorners,
                           const std::string& what) {
        readPolygonValues(ps, "Cs", "color", npolygons, npoints, ncorners, what, polygonColors_);
        readPolygonValues(ps, "N", "normal", npolygons, npoints, ncorners, what, polygonNormals_);
    }

    // One bilinear piece of a polygon with the s, t of its corners g[0..3] (when the primitive has them).
    void addPolygonPiece(const std::vector<Vec3>& pts, const Corner (&k)[4]) {
        const Vec3 g[4] = {pts[size_t(k[0].point)], pts[size_t(k[1].point)], pts[size_t(k[2].point)],
                           pts[size_t(k[3].point)]};
        // Degree elevation as addPatch's, but every edge point is (2 near + far) / 3 of its edge's two
        // ends, which does not depend on the direction the edge is walked: a polygon sharing the edge
        // (reversed) gets the same four points bit for bit, in both engines (no weld needed).
        // (A collapsed edge stays a point; 2 near is exact, so a fused multiply-add rounds the same.)
        auto third = [](Vec3 nearEnd, Vec3 farEnd) {
            return nearEnd == farEnd ? nearEnd : (nearEnd * 2.f + farEnd) / 3.f;
        };
        BezierPatch b;
        for (int u = 0; u < 4; u += 3)
            for (int v = 0; v < 4; v += 3) b.at(u, v) = g[(u ? 1 : 0) + (v ? 2 : 0)];
        for (int v = 0; v < 4; v += 3) {  // the u edges (v = 0: g0 g1, v = 3: g2 g3)
            const Vec3 a = g[v ? 2 : 0], c = g[v ? 3 : 1];
            b.at(1, v) = third(a, c);
            b.at(2, v) = third(c, a);
        }
        for (int u = 0; u < 4; u += 3) {  // the v edges (u = 0: g0 g2, u = 3: g1 g3)
            const Vec3 a = g[u ? 1 : 0], c = g[u ? 3 : 2];
            b.at(u, 1) = third(a, c);
            b.at(u, 2) = third(c, a);
        }
        for (int u = 1; u < 3; ++u)  // inside: the bilinear map at thirds, between the u edges
            for (int v = 1; v < 3; ++v) b.at(u, v) = lerp(b.at(u, 0), b.at(u, 3), v / 3.f);
        shape_.patches.push_back(b);
        PrimitiveShape::PolygonPiece piece{};
        for (int q = 0; q < 4; ++q) piece.point[q] = k[q].point, piece.fv[q] = k[q].fv;
        piece.polygon = polygonIndex_;
        shape_.polygonPieces.push_back(piece);
        // A colour per polygon or for all: a material per colour (addPrimitive); per corner, and normals:
        // the piece's vertex values.
        if (polygonColors_.given() && !polygonColors_.perCorner())
            shape_.colors.push_back(polygonColors_.at(k[0], polygonIndex_));
        if (polygonNormals_.given() || polygonColors_.perCorner()) {
            PatchVertexValues vv;
            vv.hasN = polygonNormals_.given();
            vv.hasCs = polygonColors_.perCorner();
            for (int q = 0; q < 4; ++q) {
                if (vv.hasN) vv.N[q] = polygonNormals_.at(k[q], polygonIndex_);
                if (vv.hasCs) vv.Cs[q] = polygonColors_.at(k[q], polygonIndex_);
            }
            shape_.vertexValues.push_back(vv);
        }
        if (!polygonTexCoords_.st.empty()) {
            PatchTexCoords tc;
            for (int q = 0; q < 4; ++q) tc.st[q] = polygonTexCoords_.at(k[q]);
            shape_.texCoords.push_back(tc);
        }
    }

    // One polygon, its outer loop first and then its holes (corners index pts), as bilinear Bezier pieces:
    // a convex quadrilateral without holes is one bilinear patch (v0 v1 v3 v2: dP/du x dP/dv follows the
    // vertex order, as RI's polygon normal); any other polygon is projected onto the plane of its outer
    // loop's Newell normal (so nearly planar polygons work), its holes are bridged into the outer loop
    // (each from a vertex to the nearest outer vertex it sees), and the one loop is cut into triangles by
    // ear clipping, each a bilinear patch with its last edge collapsed (a, b, c, c). Corners are the
    // request's points, so polygons sharing an edge share its end points and (addPolygonPiece) its edge
    // control points bit for bit. An outer loop with fewer than 3 distinct vertices or no area:
    // warned and skipped; a degenerate hole or one outside the outer loop: warned and ignored.
    void addPolygon(int line, const std::vector<Vec3>& pts, const std::vector<std::vector<Corner>>& loopsIn,
                    const std::string& what) {
        // Consecutive corners at the same position are one corner.
        auto clean = [&](const std::vector<Corner>& in) {
            std::vector<Corner> out;
            for (const Corner& c : in)
                if (out.empty() || !(pts[size_t(c.point)] == pts[size_t(out.back().point)])) out.push_back(c);
            while (out.size() > 1 && pts[size_t(out.front().point)] == pts[size_t(out.back().point)])
                out.pop_back();
            return out;
        };
        auto newell = [&](const std::vector<Corner>& loop) {  // twice the vector area
            Vec3 n{0, 0, 0};
            for (size_t i = 0; i < loop.size(); ++i) {
                const Vec3 a = pts[size_t(loop[i].point)], b = pts[size_t(loop[(i + 1) % loop.size()].point)];
                n += Vec3{(a.y - b.y) * (a.z + b.z), (a.z - b.z) * (a.x + b.x), (a.x - b.x) * (a.y + b.y)};
            }
            return n;
        };
        auto extentOf = [&](const std::vector<Corner>& loop) {
            float e = 0.f;
            for (const Corner& c : loop)
                e = std::max(e, length(pts[size_t(c.point)] - pts[size_t(loop[0].point)]));
            return e;
        };
        std::vector<Corner> outer = clean(loopsIn[0]);
        const Vec3 nrm = newell(outer);
        const float extent = extentOf(outer);
        if (outer.size() < 3 || !(length(nrm) > 1e-10f * extent * extent)) {
            diag_.warnOnce("degeneratepolygon", line,
                           what + ": a polygon with fewer than 3 distinct vertices or no area is skipped");
            return;
        }
        // The plane's 2D frame (e1, e2, n right-handed): the outer loop runs counter-clockwise in it.
        const Vec3 n = nrm / length(nrm);
        const Vec3 e1 = normalize(std::fabs(n.x) > 0.5f ? cross(n, Vec3{0, 1, 0}) : cross(n, Vec3{1, 0, 0}));
        const Vec3 e2 = cross(n, e1);
        auto flat = [&](const Corner& c) {
            const Vec3 p = pts[size_t(c.point)];
            return Vec2{float(double(dot(p, e1))), float(double(dot(p, e2)))};
        };
        auto cross2 = [](Vec2 a, Vec2 b) { return double(a.x) * b.y - double(a.y) * b.x; };
        auto sub = [](Vec2 a, Vec2 b) { return Vec2{a.x - b.x, a.y - b.y}; };
        auto area2 = [&](const std::vector<Corner>& loop) {
            double a = 0;
            for (size_t i = 0; i < loop.size(); ++i)
                a += cross2(flat(loop[i]), flat(loop[(i + 1) % loop.size()]));
            return a;
        };

        std::vector<std::vector<Corner>> holes;
        for (size_t h = 1; h < loopsIn.size(); ++h) {
            std::vector<Corner> hole = clean(loopsIn[h]);
            const double a = hole.size() < 3 ? 0.0 : area2(hole);
            const float he = extentOf(hole);
            if (!(std::fabs(a) > 1e-10 * double(he) * he)) {
                diag_.warnOnce("degeneratehole", line,
                               what + ": a hole with fewer than 3 distinct vertices or no area is ignored");
                continue;
            }
            if (a > 0) std::reverse(hole.begin(), hole.end());  // holes run clockwise
            holes.push_back(std::move(hole));
        }

        if (holes.empty() && outer.size() == 4) {
            auto turn = [&](const Corner& a, const Corner& b, const Corner& c) {
                return cross2(sub(flat(b), flat(a)), sub(flat(c), flat(b)));
            };
            bool convex = true;
            for (size_t i = 0; i < 4; ++i)
                convex = convex && turn(outer[i], outer[(i + 1) % 4], outer[(i + 2) % 4]) > 0;
            if (convex) {
                const Corner k[4] = {outer[0], outer[1], outer[3], outer[2]};
                addPolygonPiece(pts, k);
                return;
            }
        }

        // Proper crossing of segments pq and ab (touching at an end point does not count).
        auto crosses = [&](Vec2 p, Vec2 q, Vec2 a, Vec2 b) {
            const double d1 = cross2(sub(q, p), sub(a, p)), d2 = cross2(sub(q, p), sub(b, p)),
                         d3 = cross2(sub(b, a), sub(p, a)), d4 = cross2(sub(b, a), sub(q, a));
            return ((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0));
        };
        // Bridges, holes in decreasing order of their largest x (Eberly's order).
        std::vector<Corner> ring = outer;
        std::vector<float> maxX(holes.size());
        for (size_t h = 0; h < holes.size(); ++h) {
            maxX[h] = -std::numeric_limits<float>::infinity();
            for (const Corner& c : holes[h]) maxX[h] = std::max(maxX[h], flat(c).x);
        }
        std::vector<size_t> order(holes.size());
        for (size_t h = 0; h < order.size(); ++h) order[h] = h;
        std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return maxX[a] > maxX[b]; });
        std::vector<bool> merged(holes.size(), false);
        bool holeOutside = false;
        for (size_t oi = 0; oi < order.size(); ++oi) {
            const std::vector<Corner>& hole = holes[order[oi]];
            size_t mi = 0;  // the hole's rightmost vertex
            for (size_t i = 1; i < hole.size(); ++i)
                if (flat(hole[i]).x > flat(hole[mi]).x) mi = i;
            const Vec2 m = flat(hole[mi]);
            // The nearest ring vertex that m sees: no ring or hole edge crosses the bridge, and the bridge
            // leaves that vertex into the polygon's inside (a vertex may appear twice after a bridge).
            std::vector<size_t> cand(ring.size());
            for (size_t i = 0; i < ring.size(); ++i) cand[i] = i;
            auto dist2 = [&](size_t i) {
                const Vec2 d = sub(flat(ring[i]), m);
                return double(d.x) * d.x + double(d.y) * d.y;
            };
            std::stable_sort(cand.begin(), cand.end(),
                             [&](size_t a, size_t b) { return dist2(a) < dist2(b); });
            size_t pick = ring.size();
            for (size_t i : cand) {
                const Vec2 p = flat(ring[i]);
                const Vec2 a = flat(ring[(i + ring.size() - 1) % ring.size()]),
                           b = flat(ring[(i + 1) % ring.size()]);
                const Vec2 d = sub(m, p);
                const double c1 = cross2(sub(b, p), d), c2 = cross2(d, sub(a, p));
                const bool convexCorner = cross2(sub(p, a), sub(b, p)) > 0;
                if (!(convexCorner ? (c1 > 0 && c2 > 0) : (c1 > 0 || c2 > 0))) continue;
                bool blocked = false;
                for (size_t j = 0; j < ring.size() && !blocked; ++j)
                    blocked = crosses(m, p, flat(ring[j]), flat(ring[(j + 1) % ring.size()]));
                for (size_t h = 0; h < holes.size() && !blocked; ++h) {
                    if (merged[h]) continue;
                    for (size_t j = 0; j < holes[h].size() && !blocked; ++j)
                        blocked = crosses(m, p, flat(holes[h][j]), flat(holes[h][(j + 1) % holes[h].size()]));
                }
                if (!blocked) {
                    pick = i;
                    break;
                }
            }
            merged[order[oi]] = true;
            // Is m inside the ring at all? (Crossing number; a hole outside the outer loop is ignored.)
            bool inside = false;
            for (size_t i = 0, j = outer.size() - 1; i < outer.size(); j = i++) {
                const Vec2 a = flat(outer[i]), b = flat(outer[j]);
                if ((a.y > m.y) != (b.y > m.y) && m.x < (b.x - a.x) * (m.y - a.y) / (b.y - a.y) + a.x)
                    inside = !inside;
            }
            if (pick == ring.size() || !inside) {
                holeOutside = true;
                continue;
            }
            std::vector<Corner> next(ring.begin(), ring.begin() + long(pick) + 1);
            for (size_t k = 0; k <= hole.size(); ++k) next.push_back(hole[(mi + k) % hole.size()]);
            next.insert(next.end(), ring.begin() + long(pick), ring.end());
            ring = std::move(next);
        }
        if (holeOutside)
            diag_.warnOnce(
                "holeoutside", line,
                what + ": a hole that is not inside the outer loop (or that crosses it) is ignored");

        // Ear clipping: an ear is a convex corner whose triangle holds no other remaining vertex (corners at
        // the same position as the ear's, the two ends of a bridge, do not count).
        auto turn = [&](const Corner& a, const Corner& b, const Corner& c) {
            return cross2(sub(flat(b), flat(a)), sub(flat(c), flat(b)));
        };
        auto inTriangle = [&](Vec2 q, Vec2 a, Vec2 b, Vec2 c) {
            return cross2(sub(b, a), sub(q, a)) >= 0 && cross2(sub(c, b), sub(q, b)) >= 0 &&
                   cross2(sub(a, c), sub(q, c)) >= 0;
        };
        bool cleanCut = true;
        while (ring.size() > 3) {
            bool clipped = false;
            for (size_t k = 0; k < ring.size() && !clipped; ++k) {
                const size_t ia = (k + ring.size() - 1) % ring.size(), ic = (k + 1) % ring.size();
                const Corner a = ring[ia], b = ring[k], c = ring[ic];
                if (!(turn(a, b, c) > 0)) continue;
                const Vec2 fa = flat(a), fb = flat(b), fc = flat(c);
                bool empty = true;
                for (size_t m = 0; m < ring.size() && empty; ++m) {
                    if (m == ia || m == k || m == ic) continue;
                    const Vec2 q = flat(ring[m]);
                    if ((q.x == fa.x && q.y == fa.y) || (q.x == fb.x && q.y == fb.y) ||
                        (q.x == fc.x && q.y == fc.y))
                        continue;
                    empty = !inTriangle(q, fa, fb, fc);
                }
                if (!empty) continue;
                const Corner piece[4] = {a, b, c, c};
                addPolygonPiece(pts, piece);
                ring.erase(ring.begin() + long(k));
                clipped = true;
            }
            if (!clipped) {  // self-intersecting or numerically flat: a fan of what is left
                if (std::fabs(area2(ring)) <= 1e-9 * double(extent) * extent) {  // flat leftovers (bridges)
                    ring.clear();
                    break;
                }
                cleanCut = false;
                for (size_t k = 1; k + 1 < ring.size(); ++k) {
                    if (!(std::fabs(turn(ring[0], ring[k], ring[k + 1])) > 0)) continue;
                    const Corner piece[4] = {ring[0], ring[k], ring[k + 1], ring[k + 1]};
                    addPolygonPiece(pts, piece);
                }
                ring.clear();
            }
        }
        if (ring.size() == 3 && turn(ring[0], ring[1], ring[2]) > 0) {
            const Corner piece[4] = {ring[0], ring[1], ring[2], ring[2]};
            addPolygonPiece(pts, piece);
        }
        if (!cleanCut)
            diag_.warnOnce(
                "selfintersectingpolygon", line,
                what + ": a polygon that crosses itself was split as a fan (it may not render as intended)");
    }

    // The topology a deformation key must share with the others: words and a hash of `extra` numbers.
    void setTopology(std::string words, const std::vector<double>& extra = {}) {
        shape_.topology = std::move(words);
        Fnv1a64 h;  // over the words and the numbers' bytes
        h.bytes(shape_.topology.data(), shape_.topology.size());
        h.bytes(extra.data(), extra.size() * sizeof(double));
        shape_.topologyHash = h.h;
    }

    bool patchType(const Request& r, const std::string& type) const {
        if (type == "bicubic") return true;
        if (type != "bilinear")
            diag_.fail(r.args[0].line,
                       r.name + ": type must be \"bicubic\" or \"bilinear\", found \"" + type + "\"");
        return false;
    }

    void patch(const Request& r) {
        Arguments args(r, diag_);
        args.atLeast(1, "type ...parameterlist...");
        bool bicubic = patchType(r, args.string(0));
        size_t nv = bicubic ? 16 : 4;
        auto ps = parseParams(r, 1, decls_, diag_, [&](const std::string& cls) -> size_t {
            if (cls == "vertex" || cls == "facevertex") return nv;
            if (cls == "varying" || cls == "facevarying") return 4;
            return 1;
        });
        requireWorld(r);
        std::string what = "Patch \"" + args.string(0) + "\"";
        setTopology(what);
        auto pts = positions(r, ps, nv, what);
        if (!pts) return skip();
        // s, t: the four varying corner values, or TextureCoordinates (default s = u, t = v).
        if (auto st = varyingTexCoords(r, ps, 4, what)) {
            PatchTexCoords tc;
            for (int k = 0; k < 4; ++k) tc.st[k] = (*st)[k];
            shape_.texCoords.push_back(tc);
        } else if (!hasDefaultTexCoords()) {
            shape_.texCoords.push_back(state_.attributes().textureCoordinates);
        }
        Vec3 g[16];
        if (bicubic) {
            for (int k = 0; k < 16; ++k) g[k] = (*pts)[k];
        } else {
            for (int k = 0; k < 4; ++k) g[k] = (*pts)[k];
        }
        addPatch(g, bicubic);
    }
    void skip() { shape_.skipped = true; }

    // A later key of a deformation block with the first key's topology: the first key's pieces, at this
    // key's points (true), so that the keys' patches correspond.
    const PrimitiveShape* firstKey_ = nullptr;
    void setFirstKey(const PrimitiveShape* first) { firstKey_ = first; }
    bool reuseFirstKeyPieces(const std::vector<Vec3>& pts) {
        if (!firstKey_ || firstKey_->skipped || firstKey_->request != shape_.request ||
            firstKey_->topology != shape_.topology || firstKey_->topologyHash != shape_.topologyHash)
            return false;
        for (const PrimitiveShape::PolygonPiece& p : firstKey_->polygonPieces) {
            Corner k[4];
            for (int q = 0; q < 4; ++q) {
                if (p.point[q] < 0 || size_t(p.point[q]) >= pts.size()) return false;
                k[q] = {p.point[q], p.fv[q]};
            }
            polygonIndex_ = p.polygon;
            addPolygonPiece(pts, k);
        }
        return true;
    }

    // The s, t of a polygon primitive ("st" or "s" and "t"; vertex or varying: one per point, facevarying:
    // one per corner), into polygonTexCoords_; nothing: the pieces keep the default s = u, t = v. Other
    // storage classes are warned about and ignored.
    void readPolygonTexCoords(const Request& r, const std::vector<Param>& ps, size_t npoints, size_t ncorners,
                              const std::string& what) {
        const Param *st = nullptr, *s = nullptr, *t = nullptr;
        bool faceVarying = false;
        for (const Param& p : ps) {
            if (!isTexCoordParam(p.name)) continue;
            const std::string cls = p.decl ? p.decl->cls : "";
            const int per = p.name == "st" ? 2 : 1;
            const bool fv = cls == "facevarying" || cls == "facevertex";
            if ((cls != "varying" && cls != "vertex" && !fv) || !p.decl || p.decl->type != "float" ||
                p.decl->arraySize != per || !p.value->numeric()) {
                diag_.warnOnce("stclass:" + p.name, p.line,
                               what + ": \"" + p.name +
                                   "\" is used as a vertex, varying or facevarying \"float" +
                                   (per == 2 ? "[2]" : "") + "\" only; ignored");
                continue;
            }
            const size_t n = fv ? ncorners : npoints;
            if (p.value->nums.size() != n * size_t(per))
                diag_.fail(p.line, what + ": \"" + p.name + "\" needs " + std::to_string(n * size_t(per)) +
                                       " numbers (" + std::to_string(n) + " " + cls + " values), got " +
                                       std::to_string(p.value->nums.size()));
            if ((st || s || t) && fv != faceVarying)
                diag_.fail(p.line, what + ": \"s\" and \"t\" must have the same storage class");
            faceVarying = fv;
            (p.name == "st" ? st : p.name == "s" ? s : t) = &p;
        }
        if (!st && !s && !t) return;
        if (st && (s || t))
            diag_.warnOnce("stboth", r.line, what + ": both \"st\" and \"s\"/\"t\" given; \"st\" is used");
        const size_t n = faceVarying ? ncorners : npoints;
        PolygonTexCoords& out = polygonTexCoords_;
        out.faceVarying = faceVarying;
        out.st.resize(n);
        for (size_t i = 0; i < n; ++i) {
            if (st)
                out.st[i] = {float(st->value->nums[2 * i]), float(st->value->nums[2 * i + 1])};
            else
                out.st[i] = {s ? float(s->value->nums[i]) : 0.f, t ? float(t->value->nums[i]) : 0.f};
            if (!std::isfinite(out.st[i].x) || !std::isfinite(out.st[i].y) ||
                std::fabs(out.st[i].x) > 1e30f || std::fabs(out.st[i].y) > 1e30f)
                diag_.fail(r.line, what + ": texture coordinates must be finite numbers");
        }
    }

    // The loop sizes of a general polygon (nvertices of GeneralPolygon, or one polygon's share of
    // PointsGeneralPolygons' nvertices), checked: every loop needs 3 vertices.
    void checkLoops(const Request& r, const std::vector<int>& sizes, size_t arg,
                    const std::string& what) const {
        for (size_t i = 0; i < sizes.size(); ++i)
            if (sizes[i] < 3)
                diag_.fail(r.args[arg].line, what + ": loop " + std::to_string(i) + " has " +
                                                 std::to_string(sizes[i]) +
                                                 " vertices; a loop needs at least 3");
    }

    // Polygon (RI spec 3.2, sec. 5.1): one planar polygon, convex or concave, its vertices in "P".
    // GeneralPolygon nvertices: loops of nvertices[i] points each, the first the outer boundary and the
    // others holes.
    void polygon(const Request& r, bool general) {
        const std::string what = r.name;
        std::vector<int> loopSizes;
        size_t start = 0;
        if (general) {
            Arguments args(r, diag_);
            args.atLeast(1, "nvertices ...parameterlist...");
            loopSizes = args.intArray(0, "nvertices");
            if (!r.args[0].isArray()) diag_.fail(r.line, what + ": nvertices must be an array");
            if (loopSizes.empty()) diag_.fail(r.args[0].line, what + ": no loops");
            checkLoops(r, loopSizes, 0, what);
            start = 1;
        }
        const size_t n = pointCount(r, start);
        if (n == 0) diag_.fail(r.line, what + ": missing the position parameter \"P\"");
        if (general) {
            size_t total = 0;
            for (int k : loopSizes) total += size_t(k);
            if (total != n)
                diag_.fail(r.line, what + ": nvertices adds up to " + std::to_string(total) +
                                       " points, but \"P\" has " + std::to_string(n));
        } else {
            loopSizes = {int(n)};
        }
        auto ps = parseParams(r, start, decls_, diag_, [&](const std::string& cls) -> size_t {
            return cls == "uniform" || cls == "constant" ? 1 : n;
        });
        requireWorld(r);
        std::vector<double> topo(loopSizes.begin(), loopSizes.end());
        setTopology(what + " with " + std::to_string(n) + " vertices", topo);
        readPolygonValues(ps, 1, n, n, what);
        auto pts = positions(r, ps, n, what);
        if (!pts) return skip();
        readPolygonTexCoords(r, ps, n, n, what);
        if (reuseFirstKeyPieces(*pts)) return;
        std::vector<std::vector<Corner>> loops;
        int at = 0;
        for (int k : loopSizes) {
            loops.emplace_back();
            for (int i = 0; i < k; ++i, ++at) loops.back().push_back({at, at});
        }
        addPolygon(r.line, *pts, loops, what);
    }

    // PointsPolygons nvertices vertices (RI spec 3.2, sec. 5.1): polygons sharing vertices, each convex or
    // concave. PointsGeneralPolygons nloops nvertices vertices: polygon i has nloops[i] loops (the first its
    // outer boundary, the others holes), loop j has nvertices[j] vertices. Shared edges give bit-identical
    // patch boundaries up to the weld (no cracks).
    void pointsPolygons(const Request& r, bool general) {
        const std::string what = r.name;
        Arguments args(r, diag_);
        const size_t base = general ? 1 : 0;
        args.atLeast(base + 2, general ? "nloops nvertices vertices ...parameterlist..."
                                       : "nvertices vertices ...parameterlist...");
        std::vector<int> nloops;
        const std::vector<int> nverts = args.intArray(base, "nvertices"),
                               verts = args.intArray(base + 1, "vertices");
        for (size_t i = 0; i <= base + 1; ++i)
            if (!r.args[i].isArray())
                diag_.fail(r.line, what + (general ? ": nloops, nvertices and vertices must be arrays"
                                                   : ": nvertices and vertices must be arrays"));
        if (general) {
            nloops = args.intArray(0, "nloops");
            if (nloops.empty()) diag_.fail(r.args[0].line, what + ": no polygons");
            size_t loops = 0;
            for (size_t f = 0; f < nloops.size(); ++f) {
                if (nloops[f] < 1)
                    diag_.fail(r.args[0].line, what + ": polygon " + std::to_string(f) + " has " +
                                                   std::to_string(nloops[f]) +
                                                   " loops; a polygon needs at least 1");
                loops += size_t(nloops[f]);
            }
            if (loops != nverts.size())
                diag_.fail(r.args[1].line, what + ": nloops adds up to " + std::to_string(loops) +
                                               " loops, but nvertices has " + std::to_string(nverts.size()));
            checkLoops(r, nverts, 1, what);
        } else {
            if (nverts.empty()) diag_.fail(r.args[0].line, what + ": no polygons");
            for (size_t f = 0; f < nverts.size(); ++f)
                if (nverts[f] < 3)
                    diag_.fail(r.args[0].line, what + ": polygon " + std::to_string(f) + " has " +
                                                   std::to_string(nverts[f]) +
                                                   " vertices; a polygon needs at least 3");
            nloops.assign(nverts.size(), 1);
        }
        size_t total = 0;
        for (int k : nverts) total += size_t(k);
        if (total != verts.size())
            diag_.fail(r.args[base + 1].line, what + ": nvertices adds up to " + std::to_string(total) +
                                                  " vertex indices, but vertices has " +
                                                  std::to_string(verts.size()));
        const size_t npoints = pointCount(r, base + 2);
        if (npoints == 0) diag_.fail(r.line, what + ": missing the position parameter \"P\"");
        for (int v : verts)
            if (v < 0 || size_t(v) >= npoints)
                diag_.fail(r.args[base + 1].line, what + ": vertex index " + std::to_string(v) +
                                                      " is out of range: \"P\" has " +
                                                      std::to_string(npoints) + " points (indices 0.." +
                                                      std::to_string(npoints - 1) + ")");
        auto ps = parseParams(r, base + 2, decls_, diag_, [&](const std::string& cls) -> size_t {
            if (cls == "vertex" || cls == "varying") return npoints;
            if (cls == "facevarying" || cls == "facevertex") return verts.size();
            if (cls == "uniform") return nloops.size();
            return 1;
        });
        requireWorld(r);
        std::vector<double> topo(nloops.begin(), nloops.end());
        topo.insert(topo.end(), nverts.begin(), nverts.end());
        topo.insert(topo.end(), verts.begin(), verts.end());
        setTopology(what + " with " + std::to_string(nloops.size()) + " polygons", topo);
        readPolygonValues(ps, nloops.size(), npoints, verts.size(), what);
        auto pts = positions(r, ps, npoints, what);
        if (!pts) return skip();
        readPolygonTexCoords(r, ps, npoints, verts.size(), what);
        if (reuseFirstKeyPieces(*pts)) return;
        size_t at = 0, loop = 0;
        for (size_t f = 0; f < nloops.size(); ++f) {
            const int nl = nloops[f];
            polygonIndex_ = f;
            std::vector<std::vector<Corner>> loops;
            for (int l = 0; l < nl; ++l, ++loop) {
                loops.emplace_back();
                for (int i = 0; i < nverts[loop]; ++i, ++at) loops.back().push_back({verts[at], int(at)});
            }
            addPolygon(r.line, *pts, loops, what);
        }
    }

    // Patches along one direction of a PatchMesh (RI spec 5.2: RiPatchMesh).
    int meshPatches(const Request& r, bool bicubic, int n, bool periodic, int step, const char* dir) const {
        if (!bicubic) {
            if (n < (periodic ? 1 : 2))
                diag_.fail(r.line,
                           std::string("PatchMesh: n") + dir + " = " + std::to_string(n) + " is too small");
            return periodic ? n : n - 1;
        }
        if (periodic) {
            if (n < 1 || n % step != 0)
                diag_.fail(r.line, std::string("PatchMesh: periodic n") + dir + " = " + std::to_string(n) +
                                       " must be a positive multiple of the " + dir + "step " +
                                       std::to_string(step));
            return n / step;
        }
        if (n < 4 || (n - 4) % step != 0)
            diag_.fail(r.line, std::string("PatchMesh: nonperiodic n") + dir + " = " + std::to_string(n) +
                                   " must be 4 + k * " + std::to_string(step) + " (the " + dir + "step)");
        return (n - 4) / step + 1;
    }
    bool wrapArg(const Request& r, size_t i) const {
        const std::string& w = Arguments(r, diag_).string(i);
        if (w == "periodic") return true;
        if (w == "nonperiodic") return false;
        diag_.fail(r.args[i].line,
                   "PatchMesh: wrap mode must be \"periodic\" or \"nonperiodic\", found \"" + w + "\"");
    }

    void patchMesh(const Request& r) {
        Arguments args(r, diag_);
        args.atLeast(5, "type nu uwrap nv vwrap ...parameterlist...");
        bool bicubic = patchType(r, args.string(0));
        int nu = args.integer(1), nv = args.integer(3);
        bool uper = wrapArg(r, 2), vper = wrapArg(r, 4);
        int ustep = bicubic ? state_.attributes().uBasis.step : 1,
            vstep = bicubic ? state_.attributes().vBasis.step : 1;
        int npu = meshPatches(r, bicubic, nu, uper, ustep, "u");
        int npv = meshPatches(r, bicubic, nv, vper, vstep, "v");
        size_t nverts = size_t(nu) * size_t(nv);
        // Varying values sit at the patch corners: one per patch boundary in each direction.
        size_t nvaryings = size_t(npu + (uper ? 0 : 1)) * size_t(npv + (vper ? 0 : 1));
        auto ps = parseParams(r, 5, decls_, diag_, [&](const std::string& cls) -> size_t {
            if (cls == "vertex" || cls == "facevertex") return nverts;
            if (cls == "varying" || cls == "facevarying") return nvaryings;
            if (cls == "uniform") return size_t(npu) * size_t(npv);
            return 1;
        });
        requireWorld(r);
        setTopology("PatchMesh \"" + args.string(0) + "\" " + std::to_string(nu) + " \"" + args.string(2) +
                        "\" " + std::to_string(nv) + " \"" + args.string(4) + "\"",
                    {double(ustep), double(vstep)});
        auto pts = positions(r, ps, nverts, "PatchMesh \"" + args.string(0) + "\"");
        if (!pts) return skip();
        // s, t: varying values at the patch corners (piecewise bilinear over the mesh), or the default
        // over the mesh's (u,v), which goes from 0 to 1 across the whole mesh (RI spec 3.2, sec. 5.2).
        const auto st = varyingTexCoords(r, ps, nvaryings, "PatchMesh \"" + args.string(0) + "\"");
        const bool meshTexCoords = st || !hasDefaultTexCoords() || npu > 1 || npv > 1;
        const int rowLength = npu + (uper ? 0 : 1), columnLength = npv + (vper ? 0 : 1);
        int order = bicubic ? 4 : 2;
        for (int pv = 0; pv < npv; ++pv)
            for (int pu = 0; pu < npu; ++pu) {
                if (meshTexCoords) {
                    PatchTexCoords tc;
                    for (int k = 0; k < 4; ++k) {
                        const int cu = pu + (k & 1), cv = pv + (k >> 1);
                        if (st)
                            tc.st[k] = (*st)[size_t(cv % columnLength) * rowLength + size_t(cu % rowLength)];
                        else
                            tc.st[k] = defaultTexCoords(double(cu) / npu, double(cv) / npv);
                    }
                    shape_.texCoords.push_back(tc);
                }
                Vec3 g[16];
                for (int j = 0; j < order; ++j)
                    for (int i = 0; i < order; ++i) {
                        int u = (pu * ustep + i) % nu, v = (pv * vstep + j) % nv;  // periodic meshes wrap
                        g[j * order + i] = (*pts)[size_t(v) * nu + u];
                    }
                addPatch(g, bicubic);
            }
    }

    // RiNuPatch (RI spec 3.2, sec. 5.3): non-rational NURBS, converted exactly to Bezier patches.
    void nuPatch(const Request& r) {
        Arguments args(r, diag_);
        args.atLeast(10, "nu uorder uknot umin umax nv vorder vknot vmin vmax ...parameterlist...");
        NurbsSurface s;
        s.nu = args.integer(0);
        s.uorder = args.integer(1);
        s.uknot = args.numberArray(2, "uknot");
        s.umin = args.number(3);
        s.umax = args.number(4);
        s.nv = args.integer(5);
        s.vorder = args.integer(6);
        s.vknot = args.numberArray(7, "vknot");
        s.vmin = args.number(8);
        s.vmax = args.number(9);
        if (s.nu < 1 || s.nv < 1 || s.nu > 1000000 || s.nv > 1000000)
            diag_.fail(r.line, "NuPatch: nu and nv must be positive");
        size_t nverts = size_t(s.nu) * size_t(s.nv);
        size_t segu = size_t(std::max(1, s.nu - s.uorder + 1)),
               segv = size_t(std::max(1, s.nv - s.vorder + 1));
        auto ps = parseParams(r, 10, decls_, diag_, [&](const std::string& cls) -> size_t {
            if (cls == "vertex") return nverts;
            if (cls == "varying" || cls == "facevarying" || cls == "facevertex")
                return (segu + 1) * (segv + 1);
            if (cls == "uniform") return segu * segv;
            return 1;
        });
        requireWorld(r);
        // Check the knots before the points, so that a bad knot vector is reported as such.
        try {
            NurbsSurface k = s;
            // Placeholders for the points "P"/"Pw" hold (params() checked their size): without them,
            // nu * nv alone could ask for terabytes.
            size_t given = 0;
            for (const Param& p : ps)
                if (p.name == "P" || p.name == "Pw") given = p.value->size() / (p.name == "P" ? 3 : 4);
            k.cp.assign(std::min(given, nverts), Vec3{});
            validateNurbs(k);
        } catch (const NurbsError& e) {
            diag_.fail(r.line, std::string("NuPatch: ") + e.what());
        }
        for (const Param& p : ps)
            if (p.name == "Pw" && p.value->numeric() && p.value->nums.size() == 4 * nverts)
                for (size_t i = 0; i < nverts; ++i)
                    if (std::fabs(p.value->nums[4 * i + 3] - 1.0) > 1e-9)
                        diag_.fail(p.line,
                                   "NuPatch: rational NURBS (\"Pw\" with w != 1) are not supported; only "
                                   "non-rational "
                                   "surfaces (all weights 1) convert exactly to bicubic Bezier patches");
        {
            std::vector<double> knots = s.uknot;
            knots.insert(knots.end(), s.vknot.begin(), s.vknot.end());
            knots.insert(knots.end(), {double(s.uorder), double(s.vorder), s.umin, s.umax, s.vmin, s.vmax});
            setTopology("NuPatch " + std::to_string(s.nu) + " x " + std::to_string(s.nv) + " of order " +
                            std::to_string(s.uorder) + " x " + std::to_string(s.vorder),
                        knots);
        }
        auto pts = positions(r, ps, nverts, "NuPatch");
        if (!pts) return skip();
        const auto st = varyingTexCoords(r, ps, (segu + 1) * (segv + 1), "NuPatch");
        s.cp = std::move(*pts);
        std::vector<BezierPatch> patches;
        try {
            patches = nurbsToBezier(s);
        } catch (const NurbsError& e) {
            diag_.fail(r.line, std::string("NuPatch: ") + e.what());
        }
        shape_.patches = std::move(patches);
        nuPatchTexCoords(s, segu, st);
    }

    // The s, t of each Bezier patch of a NuPatch. Its patches are its non-empty knot spans inside
    // [umin,umax] x [vmin,vmax], u spans outer (nurbsToBezier). Varying values sit at the knots
    // uknot[uorder-1 .. nu] (one per span boundary, RI spec 3.2, sec. 5.3) and are interpolated linearly
    // within a span; without them s = u, t = v through TextureCoordinates.
    void nuPatchTexCoords(const NurbsSurface& s, size_t segu, const std::optional<std::vector<Vec2>>& st) {
        if (!st && hasDefaultTexCoords() && s.umin == 0 && s.umax == 1 && s.vmin == 0 && s.vmax == 1 &&
            shape_.patches.size() == 1)
            return;
        // The breakpoints nurbsToBezier splits at: umin, umax and every distinct knot between them.
        auto breaks = [](const std::vector<double>& knot, double lo, double hi) {
            std::vector<double> b{lo};
            for (double k : knot)
                if (k > lo && k < hi && k != b.back()) b.push_back(k);
            b.push_back(hi);
            return b;
        };
        const std::vector<double> bu = breaks(s.uknot, std::max(s.umin, s.uknot[size_t(s.uorder - 1)]),
                                              std::min(s.umax, s.uknot[size_t(s.nu)]));
        const std::vector<double> bv = breaks(s.vknot, std::max(s.vmin, s.vknot[size_t(s.vorder - 1)]),
                                              std::min(s.vmax, s.vknot[size_t(s.nv)]));
        if ((bu.size() - 1) * (bv.size() - 1) != shape_.patches.size()) return;  // cannot happen; keep u, v
        // The varying value at (u, v): bilinear within the knot span that holds it.
        auto varyingAt = [&](double u, double v) -> Vec2 {
            auto locate = [](const std::vector<double>& knot, int order, int n, double x, size_t& i,
                             double& w) {
                i = 0;
                for (int k = 0; k < n - order + 1; ++k)
                    if (knot[size_t(order - 1 + k)] <= x &&
                        knot[size_t(order + k)] > knot[size_t(order - 1 + k)])
                        i = size_t(k);
                const double a = knot[size_t(order - 1) + i], b = knot[size_t(order) + i];
                w = b > a ? std::clamp((x - a) / (b - a), 0.0, 1.0) : 0.0;
            };
            size_t iu, iv;
            double wu, wv;
            locate(s.uknot, s.uorder, s.nu, u, iu, wu);
            locate(s.vknot, s.vorder, s.nv, v, iv, wv);
            auto at = [&](size_t a, size_t b) { return (*st)[b * (segu + 1) + a]; };
            const Vec2 c00 = at(iu, iv), c10 = at(iu + 1, iv), c01 = at(iu, iv + 1), c11 = at(iu + 1, iv + 1);
            const float fu = float(wu), fv = float(wv);
            auto mix = [](Vec2 a, Vec2 b, float w) {
                return Vec2{a.x + (b.x - a.x) * w, a.y + (b.y - a.y) * w};
            };
            return mix(mix(c00, c10, fu), mix(c01, c11, fu), fv);
        };
        for (size_t i = 0; i + 1 < bu.size(); ++i)
            for (size_t j = 0; j + 1 < bv.size(); ++j) {
                PatchTexCoords tc;
                for (int k = 0; k < 4; ++k) {
                    const double u = bu[i + (k & 1)], v = bv[j + (k >> 1)];
                    tc.st[k] = st ? varyingAt(u, v) : defaultTexCoords(u, v);
                }
                shape_.texCoords.push_back(tc);
            }
    }

    static Vec2 lerpValues(Vec2 a, Vec2 b, float w) { return {a.x + (b.x - a.x) * w, a.y + (b.y - a.y) * w}; }
    static Vec3 lerpValues(Vec3 a, Vec3 b, float w) { return a + (b - a) * w; }

    // Values given per face corner or per vertex of a converted SubdivisionMesh, interpolated linearly over
    // each control face (bilinearly; a face other than a quad: over each sub-face quad, with edge midpoints
    // and the centroid), at each patch's four corners ((0,0) (1,0) (0,1) (1,1), as PatchTexCoords and
    // PatchVertexValues hold them) from its place on the control face (SubdivResult::patchUV).
    template <class T>
    static std::vector<std::array<T, 4>> faceLinearCorners(const SubdivMesh& mesh,
                                                           const std::vector<T>& values, bool perCorner,
                                                           const SubdivResult& res) {
        std::vector<size_t> offset(mesh.faceSizes.size() + 1, 0);
        for (size_t f = 0; f < mesh.faceSizes.size(); ++f)
            offset[f + 1] = offset[f] + size_t(mesh.faceSizes[f]);
        auto corner = [&](size_t k) { return perCorner ? values[k] : values[size_t(mesh.faceVerts[k])]; };
        auto mix = [](const T& a, const T& b, float w) { return lerpValues(a, b, w); };
        std::vector<std::array<T, 4>> out;
        for (size_t i = 0; i < res.patches.size(); ++i) {
            const size_t f = res.patchBaseFace[i], o = offset[f];
            const int n = mesh.faceSizes[f];
            T q[4];
            if (res.patchSubFace[i] < 0) {
                for (int k = 0; k < 4; ++k) q[k] = corner(o + size_t(k));
            } else {
                const int c = res.patchSubFace[i];
                T centre = corner(o);
                for (int k = 1; k < n; ++k) centre = mix(centre, corner(o + size_t(k)), 1.f / float(k + 1));
                const T a = corner(o + size_t(c)), next = corner(o + size_t((c + 1) % n)),
                        prev = corner(o + size_t((c + n - 1) % n));
                q[0] = a, q[1] = mix(a, next, 0.5f), q[2] = centre, q[3] = mix(a, prev, 0.5f);
            }
            auto at = [&](Vec2 uv) { return mix(mix(q[0], q[1], uv.x), mix(q[3], q[2], uv.x), uv.y); };
            const auto& uv = res.patchUV[i];
            out.push_back({at(uv[0]), at(uv[1]), at(uv[3]), at(uv[2])});
        }
        return out;
    }

    // The s, t of a SubdivisionMesh ("st" or "s" and "t"): RI "varying" (one per vertex) and "facevarying"
    // (one per face corner) are interpolated linearly over each control face (RI spec 3.2, sec. 5.6);
    // "vertex" (one per vertex) and PRMan's "facevertex" (one per face corner) smoothly, refined with the
    // surface (subdiv_osd.h SubdivSmoothTexCoords). nullopt: none given.
    struct SubdivTexCoordValues {
        std::vector<Vec2> values;
        bool perCorner = false, smooth = false;
    };
    std::optional<SubdivTexCoordValues> readSubdivTexCoords(const Request& r, const std::vector<Param>& ps,
                                                            size_t npoints, size_t ncorners) {
        const std::string what = "SubdivisionMesh";
        const Param *st = nullptr, *s = nullptr, *t = nullptr;
        std::string cls;
        for (const Param& p : ps) {
            if (!isTexCoordParam(p.name)) continue;
            const std::string c = p.decl ? p.decl->cls : "";
            const int per = p.name == "st" ? 2 : 1;
            if ((c != "varying" && c != "facevarying" && c != "vertex" && c != "facevertex") || !p.decl ||
                p.decl->type != "float" || p.decl->arraySize != per || !p.value->numeric()) {
                diag_.warnOnce("stclass:" + p.name, p.line,
                               what + ": \"" + p.name +
                                   "\" is used as a varying, facevarying, vertex or facevertex \"float" +
                                   (per == 2 ? "[2]" : "") + "\" only; ignored");
                continue;
            }
            const size_t n = c == "facevarying" || c == "facevertex" ? ncorners : npoints;
            if (p.value->nums.size() != n * size_t(per))
                diag_.fail(p.line, what + ": \"" + p.name + "\" needs " + std::to_string(n * size_t(per)) +
                                       " numbers (" + std::to_string(n) + " " + c + " values), got " +
                                       std::to_string(p.value->nums.size()));
            if ((st || s || t) && c != cls)
                diag_.fail(p.line, what + ": \"s\" and \"t\" must have the same storage class");
            cls = c;
            (p.name == "st" ? st : p.name == "s" ? s : t) = &p;
        }
        if (!st && !s && !t) return std::nullopt;
        if (st && (s || t))
            diag_.warnOnce("stboth", r.line, what + ": both \"st\" and \"s\"/\"t\" given; \"st\" is used");
        SubdivTexCoordValues out;
        out.perCorner = cls == "facevarying" || cls == "facevertex";
        out.smooth = cls == "vertex" || cls == "facevertex";
        const size_t n = out.perCorner ? ncorners : npoints;
        out.values.resize(n);
        for (size_t i = 0; i < n; ++i) {
            Vec2& v = out.values[i];
            if (st)
                v = {float(st->value->nums[2 * i]), float(st->value->nums[2 * i + 1])};
            else
                v = {s ? float(s->value->nums[i]) : 0.f, t ? float(t->value->nums[i]) : 0.f};
            if (!std::isfinite(v.x) || !std::isfinite(v.y) || std::fabs(v.x) > 1e30f ||
                std::fabs(v.y) > 1e30f)
                diag_.fail(r.line, what + ": texture coordinates must be finite numbers");
        }
        return out;
    }

    // The "Cs" and "N" of a converted SubdivisionMesh (polygonColors_, polygonNormals_) on its patches: a
    // colour for all or per control face becomes the patch's colour (a material per colour, addPrimitive);
    // per-vertex ones the patches' PatchVertexValues: smooth ("vertex": the limit values at the patch
    // corners, SubdivResult::patchVertexValues, colours first) or linear over each control face.
    void subdivColorsAndNormals(const SubdivMesh& mesh, const SubdivResult& res, bool smoothCs,
                                bool smoothN) {
        using C = PolygonValues::Class;
        const PolygonValues &cs = polygonColors_, &nv = polygonNormals_;
        const size_t n = res.patches.size();
        if (cs.given() && !cs.perCorner())
            for (size_t i = 0; i < n; ++i)
                shape_.colors.push_back(cs.v[cs.cls == C::Constant ? 0 : size_t(res.patchBaseFace[i])]);
        if (!nv.given() && !cs.perCorner()) return;
        // Corners (0,0) (1,0) (0,1) (1,1) of each patch.
        auto corners = [&](const PolygonValues& values, bool smooth, size_t smoothIndex) {
            std::vector<std::array<Vec3, 4>> out;
            if (smooth) {
                for (const std::array<Vec3, 4>& c : res.patchVertexValues[smoothIndex])
                    out.push_back({c[0], c[1], c[3], c[2]});
            } else if (values.perCorner()) {
                out = faceLinearCorners(mesh, values.v, values.cls == C::FaceVarying, res);
            } else {
                for (size_t i = 0; i < n; ++i) {
                    const Vec3 v = values.v[values.cls == C::Constant ? 0 : size_t(res.patchBaseFace[i])];
                    out.push_back({v, v, v, v});
                }
            }
            return out;
        };
        std::vector<std::array<Vec3, 4>> colorCorners, normalCorners;
        if (cs.perCorner()) colorCorners = corners(cs, smoothCs, 0);
        if (nv.given()) normalCorners = corners(nv, smoothN, smoothCs ? 1 : 0);
        for (size_t i = 0; i < n; ++i) {
            PatchVertexValues vv;
            vv.hasCs = cs.perCorner();
            vv.hasN = nv.given();
            for (int k = 0; k < 4; ++k) {
                if (vv.hasCs) vv.Cs[k] = colorCorners[i][size_t(k)];
                if (vv.hasN) vv.N[k] = normalCorners[i][size_t(k)];
            }
            shape_.vertexValues.push_back(vv);
        }
    }

    // Extent in raster pixels of the projection of points (object space, the CTM at shutter open), 0 if
    // some point is at or behind the eye: what subdivLevelFor() chooses a level from. In the image that
    // will be rendered: the caller's resolution where it overrides the Format (the projection of the
    // whole frame; a crop window does not change it).
    float rasterSize(const std::vector<Vec3>& points) const {
        const Mat4 toCamera = camera_.cameraFromWorld * state_.transform().at(camera_.shutterOpen);
        Bounds3 b;
        for (const Vec3& p : points) b.extend(toCamera.point(p));
        Camera rendered = camera_;
        if (rasterWidth_ > 0 && rasterHeight_ > 0)
            rendered.width = rasterWidth_, rendered.height = rasterHeight_;
        float x0, x1, y0, y1;
        if (points.empty() || !Projector(rendered).rasterBounds(b, x0, x1, y0, y1)) return 0.f;
        const float size = std::max(x1 - x0, y1 - y0);
        return std::isfinite(size) ? size : 0.f;
    }

    // RiSubdivisionMesh (RI spec 3.2, sec. 5.6): Catmull-Clark surfaces, converted through OpenSubdiv by
    // subdivideOsd() (io/subdiv_osd.h) at a level from the mesh's size on screen.
    void subdivisionMesh(const Request& r) {
        Arguments args(r, diag_);
        args.atLeast(3, "scheme nvertices vertices [tags nargs intargs floatargs] ...parameterlist...");
        const std::string& scheme = args.string(0);
        std::vector<int> nverts = args.intArray(1, "nvertices");
        std::vector<int> verts = args.intArray(2, "vertices");
        if (!r.args[1].isArray() || !r.args[2].isArray())
            diag_.fail(r.line, "SubdivisionMesh: nvertices and vertices must be arrays");
        size_t start = 3;
        SubdivMesh mesh;
        mesh.boundary = BoundaryMode::None;  // RenderMan default without "interpolateboundary"
        size_t total = 0;
        for (size_t f = 0; f < nverts.size(); ++f) {
            if (nverts[f] < 3)
                diag_.fail(r.args[1].line, "SubdivisionMesh: face " + std::to_string(f) + " has " +
                                               std::to_string(nverts[f]) +
                                               " vertices; a face needs at least 3");
            total += size_t(nverts[f]);
        }
        if (nverts.empty()) diag_.fail(r.args[1].line, "SubdivisionMesh: no faces");
        if (total != verts.size())
            diag_.fail(r.args[2].line, "SubdivisionMesh: nvertices adds up to " + std::to_string(total) +
                                           " vertex indices, but vertices has " +
                                           std::to_string(verts.size()));
        int maxIndex = -1;
        for (int v : verts) {
            if (v < 0)
                diag_.fail(r.args[2].line, "SubdivisionMesh: negative vertex index " + std::to_string(v));
            maxIndex = std::max(maxIndex, v);
        }
        size_t npoints = size_t(maxIndex) + 1;
        struct Tag {
            std::string name;
            std::vector<int> ints;
            std::vector<double> floats;
            std::vector<std::string> strings;
            int line;
        };
        std::vector<Tag> tags;
        if (r.args.size() > 3 && r.args[3].isArray()) {
            if (r.args.size() < 7)
                diag_.fail(r.line, "SubdivisionMesh: tags need the arrays tags nargs intargs floatargs");
            const Value& tv = r.args[3];
            if (tv.numeric() && !tv.nums.empty())
                diag_.fail(tv.line, "SubdivisionMesh: tags must be an array of strings");
            std::vector<int> nargs = args.intArray(4, "nargs");
            std::vector<int> ints = args.intArray(5, "intargs");
            std::vector<double> floats = args.numberArray(6, "floatargs");
            // PRMan's extension: a string array after floatargs and 3 counts per tag (ints, floats, strings).
            const bool stringArgs = r.args.size() > 7 && r.args[7].isArray() &&
                                    (!r.args[7].numeric() || r.args[7].nums.empty()) &&
                                    nargs.size() == 3 * tv.strs.size();
            const std::vector<std::string> strings = stringArgs ? r.args[7].strs : std::vector<std::string>{};
            const size_t per = stringArgs ? 3 : 2;
            if (nargs.size() != per * tv.strs.size())
                diag_.fail(r.args[4].line, "SubdivisionMesh: nargs needs 2 numbers per tag (" +
                                               std::to_string(2 * tv.strs.size()) +
                                               "; 3 with a stringargs array), got " +
                                               std::to_string(nargs.size()));
            size_t io = 0, fo = 0, so = 0;
            for (size_t t = 0; t < tv.strs.size(); ++t) {
                int ni = nargs[per * t], nf = nargs[per * t + 1], ns = stringArgs ? nargs[per * t + 2] : 0;
                if (ni < 0 || nf < 0 || ns < 0 || io + size_t(ni) > ints.size() ||
                    fo + size_t(nf) > floats.size() || so + size_t(ns) > strings.size())
                    diag_.fail(r.args[4].line,
                               "SubdivisionMesh: nargs for tag \"" + tv.strs[t] +
                                   (stringArgs ? "\" asks for more intargs/floatargs/stringargs than given"
                                               : "\" asks for more intargs/floatargs than given"));
                Tag tag{tv.strs[t],
                        {ints.begin() + long(io), ints.begin() + long(io + size_t(ni))},
                        {floats.begin() + long(fo), floats.begin() + long(fo + size_t(nf))},
                        {strings.begin() + long(so), strings.begin() + long(so + size_t(ns))},
                        tv.line};
                io += size_t(ni);
                fo += size_t(nf);
                so += size_t(ns);
                tags.push_back(std::move(tag));
            }
            start = stringArgs ? 8 : 7;
        }
        auto ps = parseParams(r, start, decls_, diag_, [&](const std::string& cls) -> size_t {
            if (cls == "vertex" || cls == "varying") return npoints;
            if (cls == "facevarying" || cls == "facevertex") return verts.size();
            if (cls == "uniform") return nverts.size();
            return 1;
        });
        requireWorld(r);
        if (scheme != "catmull-clark") {
            diag_.warnOnce("subdiv:" + scheme, r.line,
                           "SubdivisionMesh scheme \"" + scheme +
                               "\" is not supported (only \"catmull-clark\"); "
                               "primitive skipped");
            return skip();
        }
        {
            std::vector<double> topo(nverts.begin(), nverts.end());
            topo.insert(topo.end(), verts.begin(), verts.end());
            for (const Tag& t : tags) {
                topo.push_back(double(t.ints.size()));
                topo.insert(topo.end(), t.ints.begin(), t.ints.end());
                topo.insert(topo.end(), t.floats.begin(), t.floats.end());
            }
            std::string words = "SubdivisionMesh with " + std::to_string(nverts.size()) + " faces and " +
                                std::to_string(npoints) + " vertices";
            for (const Tag& t : tags) words += " \"" + t.name + "\"";
            setTopology(words, topo);
        }
        // "Cs" and "N" (RI spec 3.2, sec. 5): constant, uniform (one per control face), vertex (smooth:
        // refined as P is), varying and facevarying (linear over each control face). PRMan's smooth
        // "facevertex" is interpolated linearly too (warned). Read before positions(), which then does not
        // warn about them.
        readPolygonValues(ps, nverts.size(), npoints, verts.size(), "SubdivisionMesh");
        auto classOf = [&](const std::string& name) {
            std::string cls;
            for (const Param& p : ps)
                if (p.name == name && p.decl) cls = p.decl->cls;
            return cls;
        };
        const bool smoothCs = polygonColors_.cls == PolygonValues::Class::Vertex && classOf("Cs") == "vertex";
        const bool smoothN = polygonNormals_.cls == PolygonValues::Class::Vertex && classOf("N") == "vertex";
        for (const char* name : {"Cs", "N"})
            if (classOf(name) == "facevertex")
                diag_.warnOnce(std::string("subdivfacevertex:") + name, r.line,
                               std::string("SubdivisionMesh: \"") + name +
                                   "\" of class facevertex is interpolated linearly over each face (as "
                                   "facevarying)");
        auto pts = positions(r, ps, npoints, "SubdivisionMesh");
        if (!pts) return skip();
        const auto st = readSubdivTexCoords(r, ps, npoints, verts.size());
        SubdivSmoothTexCoords smoothST;
        mesh.points = std::move(*pts);
        mesh.faceSizes = std::move(nverts);
        mesh.faceVerts = std::move(verts);
        for (const Tag& t : tags) {
            auto checkVertex = [&](int v) {
                if (v < 0 || size_t(v) >= npoints)
                    diag_.fail(t.line, "SubdivisionMesh: tag \"" + t.name + "\" names vertex " +
                                           std::to_string(v) + ", outside 0.." + std::to_string(npoints - 1));
            };
            if (t.name == "interpolateboundary") {
                int mode = t.ints.empty() ? 1 : t.ints[0];
                mesh.boundary = mode == 0
                                    ? BoundaryMode::None
                                    : (mode == 2 ? BoundaryMode::EdgesOnly : BoundaryMode::EdgesAndCorners);
            } else if (t.name == "crease") {
                if (t.ints.size() < 2 || t.floats.empty())
                    diag_.fail(t.line,
                               "SubdivisionMesh: a \"crease\" tag needs at least 2 vertices and 1 sharpness");
                for (int v : t.ints) checkVertex(v);
                for (size_t i = 0; i + 1 < t.ints.size(); ++i)
                    mesh.creases.push_back(
                        {t.ints[i], t.ints[i + 1],
                         float(t.floats.size() == 1 ? t.floats[0]
                                                    : t.floats[std::min(i, t.floats.size() - 1)])});
            } else if (t.name == "corner") {
                if (t.floats.empty())
                    diag_.fail(t.line, "SubdivisionMesh: a \"corner\" tag needs a sharpness");
                for (size_t i = 0; i < t.ints.size(); ++i) {
                    checkVertex(t.ints[i]);
                    mesh.corners.push_back({t.ints[i], float(t.floats[std::min(i, t.floats.size() - 1)])});
                }
            } else if (t.name == "creasemethod") {
                // PRMan: "normal" (the uniform rule, the default) or "chaikin".
                const std::string method = t.strings.empty() ? "" : t.strings[0];
                if (method == "chaikin" || method == "normal")
                    mesh.chaikinCreases = method == "chaikin";
                else
                    diag_.warnOnce("creasemethod", t.line,
                                   "SubdivisionMesh: \"creasemethod\" needs the string \"normal\" or "
                                   "\"chaikin\", got \"" +
                                       method + "\"; the normal (uniform) rule is used");
            } else if (t.name == "facevaryinginterpolateboundary") {
                // PRMan: 0 linear, 1 sharp corners (the default), 2 smooth, 3 linear boundaries
                // (FaceVaryingBoundary in subdiv_osd.h); only smooth ("facevertex") s, t use it.
                const int mode = t.ints.empty() ? 1 : t.ints[0];
                if (mode < 0 || mode > 3)
                    diag_.fail(t.line,
                               "SubdivisionMesh: \"facevaryinginterpolateboundary\" needs 0, 1, 2 or 3, "
                               "got " +
                                   std::to_string(mode));
                smoothST.boundary = FaceVaryingBoundary(mode);
            } else if (t.name == "hole") {
                for (int f : t.ints) {
                    if (f < 0 || size_t(f) >= mesh.faceSizes.size())
                        diag_.fail(t.line, "SubdivisionMesh: \"hole\" names face " + std::to_string(f) +
                                               ", outside 0.." + std::to_string(mesh.faceSizes.size() - 1));
                    mesh.holes.push_back(f);
                }
            } else {
                diag_.warnOnce("subdivtag:" + t.name, t.line,
                               "SubdivisionMesh tag \"" + t.name + "\" is not supported; ignored");
            }
        }
        SubdivResult res;
        try {
            OsdSubdivOptions options;
            options.level = subdivLevel_;
            if (options.level < 0) options.rasterSize = rasterSize(mesh.points);
            if (st && st->smooth) {
                smoothST.perCorner = st->perCorner;
                smoothST.values = st->values;
                options.texCoords = &smoothST;
            }
            if (smoothCs) options.vertexValues.push_back(&polygonColors_.v);
            if (smoothN) options.vertexValues.push_back(&polygonNormals_.v);
            res = subdivideOsd(mesh, options);
        } catch (const SubdivError& e) {
            diag_.fail(r.line, std::string("SubdivisionMesh: ") + e.what());
        }
        for (const std::string& w : res.warnings)
            diag_.warnOnce("subdivwarn:" + w, r.line, "SubdivisionMesh: " + w);
        if (st && st->smooth) {
            // The limit s, t at the patch corners, bilinear in between (PatchTexCoords holds 4 values).
            for (const std::array<Vec2, 4>& c : res.patchST) {
                PatchTexCoords tc;
                tc.st[0] = c[0], tc.st[1] = c[1], tc.st[2] = c[3], tc.st[3] = c[2];
                shape_.texCoords.push_back(tc);
            }
        } else if (st) {
            for (const std::array<Vec2, 4>& c : faceLinearCorners(mesh, st->values, st->perCorner, res)) {
                PatchTexCoords tc;
                for (int k = 0; k < 4; ++k) tc.st[k] = c[size_t(k)];
                shape_.texCoords.push_back(tc);
            }
        }
        subdivColorsAndNormals(mesh, res, smoothCs, smoothN);
        shape_.subdivLevel = res.level;
        shape_.patches = std::move(res.patches);
    }

  private:
    const GraphicsState& state_;
    const Declarations& decls_;
    Diagnostics& diag_;
    const Camera& camera_;
    int subdivLevel_;
    int rasterWidth_, rasterHeight_;
    PrimitiveShape shape_;
};

}  // namespace

bool isPrimitiveRequest(const std::string& name) {
    return name == "Patch" || name == "PatchMesh" || name == "NuPatch" || name == "SubdivisionMesh" ||
           name == "Polygon" || name == "PointsPolygons" || name == "GeneralPolygon" ||
           name == "PointsGeneralPolygons";
}

PrimitiveShape readPrimitiveShape(const Request& r, const PrimitiveContext& c,
                                  const PrimitiveShape* firstKey) {
    PrimitiveReader reader(c, r);
    reader.setFirstKey(firstKey);
    if (r.name == "Patch")
        reader.patch(r);
    else if (r.name == "PatchMesh")
        reader.patchMesh(r);
    else if (r.name == "NuPatch")
        reader.nuPatch(r);
    else if (r.name == "Polygon" || r.name == "GeneralPolygon")
        reader.polygon(r, r.name == "GeneralPolygon");
    else if (r.name == "PointsPolygons" || r.name == "PointsGeneralPolygons")
        reader.pointsPolygons(r, r.name == "PointsGeneralPolygons");
    else
        reader.subdivisionMesh(r);
    return std::move(reader.shape());
}

bool isQuadricRequest(const std::string& name) {
    return name == "Sphere" || name == "Cylinder" || name == "Cone" || name == "Disk" ||
           name == "Paraboloid" || name == "Hyperboloid" || name == "Torus";
}

namespace {

// Whether object space maps into camera space mirrored (a negative determinant of the linear part).
bool mirrorsIntoCamera(const Mat4& cameraFromWorld, const Mat4& worldFromObject) {
    return (cameraFromWorld * worldFromObject).det3() < 0;
}

// The primitive's attributes from the graphics state (the object id of its attribute block or name); the
// orientation rule of RI spec 4.2.4 at shutter open.
// `worldFromObject`: the CTM at shutter open.
PatchAttributes primitiveAttributes(const PrimitiveContext& c, const Mat4& worldFromObject) {
    Scene& scene = c.scene;
    PatchAttributes a;
    a.material = materialIndex(c, c.state.attributes().surface);
    a.object = c.state.attributes().object.value_or(scene.objectCount);
    scene.objectCount = std::max(scene.objectCount, a.object + 1);
    a.shadingRate = c.state.attributes().shadingRate;
    a.twoSided = c.state.attributes().twoSided;
    a.motionFactor = c.state.attributes().motionFactor;
    a.focusFactor = c.state.attributes().focusFactor;
    a.displacement = c.state.attributes().displacement;
    a.displacementBound = c.state.attributes().displacementBound;
    a.areaLight = c.state.attributes().areaLight;
    const bool mirrored = c.orientation
                              ? c.orientation->mirrored(scene.camera.cameraFromWorld, worldFromObject)
                              : mirrorsIntoCamera(scene.camera.cameraFromWorld, worldFromObject);
    a.flipNormal = c.state.attributes().rightHanded != mirrored;
    return a;
}

}  // namespace

size_t MaterialTable::Hash::operator()(const Material& m) const {
    // Equal materials hash alike: -0 and +0 compare equal, so zeros hash as +0. Word by word (a byte-wise
    // FNV-1a over the 27 fields cost more than the linear search it replaced on few materials).
    uint64_t h = uint64_t(m.type) + 0x9e3779b97f4a7c15ull;
    auto add = [&](uint32_t word) { h = (h ^ word) * 0xff51afd7ed558ccdull, h ^= h >> 32; };
    auto addFloat = [&](float f) { add(f == 0.f ? 0u : std::bit_cast<uint32_t>(f)); };
    for (const Color& col : {m.Cs, m.Os, m.specularColor}) addFloat(col.x), addFloat(col.y), addFloat(col.z);
    for (float f : {m.Ka, m.Kd, m.Ks, m.roughness, m.Kr, m.Kt, m.eta, m.glossSamples, m.spread}) addFloat(f);
    add(uint32_t(m.texture));
    return size_t(h);
}

bool OrientationCache::mirrored(const Mat4& cameraFromWorld, const Mat4& worldFromObject) {
    if (!valid_ || std::memcmp(camera_.m, cameraFromWorld.m, sizeof(camera_.m)) != 0 ||
        std::memcmp(object_.m, worldFromObject.m, sizeof(object_.m)) != 0) {
        camera_ = cameraFromWorld, object_ = worldFromObject;
        mirrored_ = mirrorsIntoCamera(cameraFromWorld, worldFromObject);
        valid_ = true;
    }
    return mirrored_;
}

uint32_t MaterialTable::indexOf(Scene& scene, const Material& m) {
    for (; indexed_ < scene.materials.size(); ++indexed_)  // materials added elsewhere: the first one wins
        index_.try_emplace(scene.materials[indexed_], uint32_t(indexed_));
    // Consecutive primitives mostly share their material: the last answer first.
    if (last_ < scene.materials.size() && scene.materials[last_] == m) return last_;
    if (const auto it = index_.find(m); it != index_.end()) return last_ = it->second;
    scene.materials.push_back(m);
    index_.try_emplace(m, uint32_t(indexed_));
    return last_ = uint32_t(indexed_++);
}

void addQuadric(const Request& r, const PrimitiveContext& c) {
    if (!c.state.inWorld()) c.diag.fail(r.line, r.name + " outside WorldBegin/WorldEnd");
    struct Form {
        const char* name;
        QuadricKind kind;
        size_t count;
        const char* usage;
    };
    static const Form kForms[] = {
        {"Sphere", QuadricKind::Sphere, 4, "radius zmin zmax thetamax"},
        {"Cylinder", QuadricKind::Cylinder, 4, "radius zmin zmax thetamax"},
        {"Cone", QuadricKind::Cone, 3, "height radius thetamax"},
        {"Disk", QuadricKind::Disk, 3, "height radius thetamax"},
        {"Paraboloid", QuadricKind::Paraboloid, 4, "rmax zmin zmax thetamax"},
        {"Hyperboloid", QuadricKind::Hyperboloid, 7, "x1 y1 z1 x2 y2 z2 thetamax"},
        {"Torus", QuadricKind::Torus, 5, "majorradius minorradius phimin phimax thetamax"},
    };
    const Form* form = nullptr;
    for (const Form& f : kForms)
        if (r.name == f.name) form = &f;
    // The leading numbers (one by one or as one array), then the parameter list.
    std::vector<double> a;
    size_t start = 0;
    for (; start < r.args.size() && r.args[start].numeric(); ++start)
        a.insert(a.end(), r.args[start].nums.begin(), r.args[start].nums.end());
    if (a.size() != form->count)
        c.diag.fail(r.line, r.name + " expects " + std::to_string(form->count) + " numbers (" + form->usage +
                                "), got " + std::to_string(a.size()));
    for (size_t i = 0; i < a.size(); ++i)
        if (!std::isfinite(a[i]) || std::fabs(a[i]) > 1e30)
            c.diag.fail(r.line, r.name + ": argument " + std::to_string(i + 1) + " is not a finite number");
    // Vertex and varying values sit at the four corners of the (u,v) square (RI spec 5.4).
    auto ps = parseParams(r, start, c.decls, c.diag, [](const std::string& cls) -> size_t {
        return cls == "vertex" || cls == "varying" || cls == "facevarying" || cls == "facevertex" ? 4 : 1;
    });
    for (const Param& p : ps) warnIgnoredParam(p, r.name, c.diag);

    constexpr double kDeg = 3.14159265358979323846 / 180.0;
    auto empty = [&](const std::string& why) {
        c.diag.warn(r.line, r.name + ": " + why + ": an empty surface (RI spec 5.4), nothing rendered");
    };
    Quadric q;
    q.kind = form->kind;
    const double thetaMax = std::clamp(a.back(), -360.0, 360.0);
    if (thetaMax == 0.0) return empty("thetamax is 0");
    q.thetaMax = float(thetaMax * kDeg);
    q.closedU = std::fabs(thetaMax) >= 360.0;
    switch (form->kind) {
        case QuadricKind::Sphere: {
            // zmin and zmax are clamped to the sphere (as PRMan and Aqsis do); zmin > zmax reverses v.
            if (a[0] == 0.0) return empty("radius is 0");
            const double rr = std::fabs(a[0]);
            const double z0 = std::clamp(a[1], -rr, rr), z1 = std::clamp(a[2], -rr, rr);
            if (z0 == z1) return empty("zmin equals zmax (after clamping to the radius)");
            q.radius = float(a[0]), q.zMin = float(z0), q.zMax = float(z1);
            q.angle0 = float(std::asin(z0 / a[0])), q.angle1 = float(std::asin(z1 / a[0]));
            // The clamped ends at the poles are exactly +-pi/2 in single precision: quadricProfile puts
            // those vertices on the axis.
            break;
        }
        case QuadricKind::Cylinder:
            if (a[0] == 0.0) return empty("radius is 0");
            if (a[1] == a[2]) return empty("zmin equals zmax");
            q.radius = float(a[0]), q.zMin = float(a[1]), q.zMax = float(a[2]);
            break;
        case QuadricKind::Cone:
        case QuadricKind::Disk:
            if (a[1] == 0.0) return empty("radius is 0");
            q.height = float(a[0]), q.radius = float(a[1]);
            // A cone of height 0 is the disk at z = 0, parametrised the same way.
            if (form->kind == QuadricKind::Cone && a[0] == 0.0) q.kind = QuadricKind::Disk;
            break;
        case QuadricKind::Paraboloid:
            if (a[2] == 0.0)
                c.diag.fail(r.line, "Paraboloid: zmax must not be 0 (the radius is rmax sqrt(z / zmax))");
            if (a[0] == 0.0) return empty("rmax is 0");
            if (a[1] == a[2]) return empty("zmin equals zmax");
            if (a[1] / a[2] < 0.0)
                c.diag.fail(r.line, "Paraboloid: zmin (" + std::to_string(a[1]) + ") and zmax (" +
                                        std::to_string(a[2]) + ") must lie on the same side of z = 0");
            q.radius = float(a[0]), q.zMin = float(a[1]), q.zMax = float(a[2]);
            break;
        case QuadricKind::Hyperboloid:
            q.point1 = {float(a[0]), float(a[1]), float(a[2])};
            q.point2 = {float(a[3]), float(a[4]), float(a[5])};
            if (q.point1 == q.point2) return empty("point1 equals point2");
            if (q.point1.z == q.point2.z && q.point1.x * q.point2.y == q.point1.y * q.point2.x &&
                q.point1.x * q.point2.x + q.point1.y * q.point2.y >= 0.f &&
                q.point1.x * q.point1.x + q.point1.y * q.point1.y ==
                    q.point2.x * q.point2.x + q.point2.y * q.point2.y)
                return empty("the segment sweeps no area");
            if (q.point1.x == 0.f && q.point1.y == 0.f && q.point2.x == 0.f && q.point2.y == 0.f)
                return empty("the segment lies on the z axis");
            break;
        case QuadricKind::Torus: {
            if (a[1] == 0.0) return empty("minorradius is 0");
            const double p0 = std::clamp(a[2], -360.0, 360.0), p1 = std::clamp(a[3], -360.0, 360.0);
            if (p0 == p1) return empty("phimin equals phimax");
            q.radius = float(a[0]), q.minorRadius = float(a[1]);
            q.angle0 = float(p0 * kDeg),
            q.angle1 =
                float(std::fabs(p1 - p0) >= 360.0 ? p0 * kDeg + (p1 > p0 ? 2 : -2) * 3.14159265358979323846
                                                  : p1 * kDeg);
            q.closedV = std::fabs(p1 - p0) >= 360.0;
            break;
        }
    }

    Scene& scene = c.scene;
    const Transform& ctm = c.state.transform();
    if (ctm.moving())
        c.diag.warnOnce("quadricmotion", r.line,
                        r.name +
                            " under a moving transformation: quadrics do not move yet; rendered at "
                            "shutter open");
    SceneQuadric sq;
    sq.q = q;
    sq.worldFromObject = ctm.at(scene.camera.shutterOpen);
    if (std::fabs(sq.worldFromObject.det3()) < 1e-30 || !std::isfinite(sq.worldFromObject.det3()))
        c.diag.fail(r.line, r.name + ": the current transformation is singular or not finite");
    PatchAttributes attr = primitiveAttributes(c, sq.worldFromObject);
    attr.kind = surfaceKindOf(q.kind);
    attr.shape = uint32_t(scene.quadrics.size());
    // The surface's slot in Scene::patches: the hull of its box in world space (bounds, framing).
    Vec3 corners[8];
    quadricHullCorners(placeQuadric(sq, Mat4::identity()), 0.f, 1.f, 0.f, 1.f, corners);
    BezierPatch hull;
    for (int k = 0; k < 16; ++k) hull.cp[k] = corners[k % 8];
    checkFinite(hull, r.line, c.diag);
    scene.quadrics.push_back(sq);
    scene.patches.push_back(hull);
    scene.attributes.push_back(attr);
}

void addPrimitive(const std::vector<PrimitiveShape>& keys, const std::vector<double>& times,
                  const PrimitiveContext& c) {
    for (const PrimitiveShape& k : keys)
        if (k.skipped) return;
    Scene& scene = c.scene;
    const Transform& ctm = c.state.transform();
    const double open = scene.camera.shutterOpen;
    const int line = keys.front().line;
    // RI spec 4.2.4: the surface's outside depends on the orientation attribute and on the handedness of
    // the current (object-to-camera) transformation, here at shutter open.
    const Mat4 atOpen = ctm.at(open);
    const PatchAttributes a = primitiveAttributes(c, atOpen);

    // The key times: the deformation keys' and the CTM's (refined to 2 degrees per segment).
    std::optional<std::vector<double>> ctmTimes = ctm.sampleTimes();
    if (!ctmTimes)
        c.diag.fail(line, keys.front().request + ": the moving transformation needs more than " +
                              std::to_string(kMaxMotionKeys) + " keys (at most 2 degrees of turn each)");
    std::vector<double> sample = std::move(*ctmTimes);
    if (keys.size() > 1) sample.insert(sample.end(), times.begin(), times.end());
    std::sort(sample.begin(), sample.end());
    std::vector<float> T;  // as stored: strictly increasing in single precision
    for (double t : sample)
        if (T.empty() || float(t) > T.back()) T.push_back(float(t));
    if (T.size() > kMaxMotionKeys)
        c.diag.fail(line, keys.front().request + ": more than " + std::to_string(kMaxMotionKeys) +
                              " motion keys (deformation and transformation times together)");

    // Bezier patches are affinely invariant: transforming the control points transforms the surface.
    auto transformed = [&](const Mat4& m, const BezierPatch& object) {
        BezierPatch b;
        m.points(object.cp, b.cp, 16);
        checkFinite(b, line, c.diag);
        return b;
    };
    const size_t n = keys.front().patches.size();
    // Texture coordinates do not move: the first key's. Scene::texCoords stays empty while every patch
    // has the default.
    const std::vector<PatchTexCoords>& st = keys.front().texCoords;
    // Colours per patch (a polygon's uniform or constant "Cs"): the surface with that Cs, one material per
    // distinct colour. Colours do not move: the first key's.
    const std::vector<Color>& colors = keys.front().colors;
    std::vector<uint32_t> patchMaterial;
    if (colors.size() == n) {
        std::map<std::array<float, 3>, uint32_t> byColor;
        for (const Color& col : colors) {
            auto [it, added] = byColor.try_emplace({col.x, col.y, col.z}, 0);
            if (added) {
                Material m = c.state.attributes().surface;
                m.Cs = col;
                it->second = materialIndex(c, m);
            }
            patchMaterial.push_back(it->second);
        }
    }
    // Per-vertex values (polygons' "N", per-corner "Cs"): normals to world space at shutter open (inverse
    // transpose); a patch with vertex colours takes the surface with Cs = 1, which the engines multiply by
    // the interpolated colour (scene.h, PatchVertexValues).
    const std::vector<PatchVertexValues>& vertexValues = keys.front().vertexValues;
    std::optional<Mat4> objectFromWorld;  // computed on the first user normal (most primitives have none)
    uint32_t whiteMaterial = 0;
    bool haveWhite = false;
    auto attributesOf = [&](size_t j) {
        PatchAttributes pa = a;
        if (!patchMaterial.empty()) pa.material = patchMaterial[j];
        if (vertexValues.size() == n) {
            PatchVertexValues vv = vertexValues[j];
            if (vv.hasN) {
                if (!objectFromWorld) objectFromWorld = atOpen.inverse();
                for (Vec3& nrm : vv.N) nrm = Mat4::normalWithInverse(*objectFromWorld, nrm);
            }
            if (vv.hasCs) {
                if (!haveWhite) {
                    Material m = c.state.attributes().surface;
                    m.Cs = Color{1, 1, 1};
                    whiteMaterial = materialIndex(c, m);
                    haveWhite = true;
                }
                pa.material = whiteMaterial;
            }
            pa.vertexValues = int32_t(scene.vertexValues.size());
            scene.vertexValues.push_back(vv);
        }
        return pa;
    };
    auto addTexCoords = [&](size_t j) {
        if (st.size() != n && scene.texCoords.empty()) return;
        scene.texCoords.resize(scene.patches.size() - 1);
        scene.texCoords.push_back(st.size() == n ? st[j] : PatchTexCoords{});
    };
    if (T.size() < 2) {
        for (size_t j = 0; j < n; ++j) {
            scene.patches.push_back(transformed(atOpen, keys.front().patches[j]));
            scene.attributes.push_back(attributesOf(j));
            addTexCoords(j);
        }
        return;
    }
    std::vector<Mat4> worldFromObject(T.size());
    for (size_t k = 0; k < T.size(); ++k) worldFromObject[k] = ctm.at(T[k]);
    // Deformation: the object-space control points move linearly between their keys (clamped outside).
    auto objectAt = [&](size_t j, double t) -> BezierPatch {
        if (keys.size() < 2 || t <= times.front()) return keys.front().patches[j];
        if (t >= times.back()) return keys.back().patches[j];
        size_t s = 1;
        while (times[s] < t) ++s;
        const float w = float((t - times[s - 1]) / (times[s] - times[s - 1]));
        BezierPatch p;
        for (int q = 0; q < 16; ++q)
            p.cp[q] = lerp(keys[s - 1].patches[j].cp[q], keys[s].patches[j].cp[q], w);
        return p;
    };
    std::vector<BezierPatch> world(T.size());
    for (size_t j = 0; j < n; ++j) {
        bool same = true;
        for (size_t k = 0; k < T.size(); ++k) {
            world[k] = transformed(worldFromObject[k], objectAt(j, T[k]));
            for (int q = 0; q < 16 && same && k > 0; ++q) same = world[k].cp[q] == world[0].cp[q];
        }
        PatchAttributes pa = attributesOf(j);
        if (!same) {
            pa.motion = {uint32_t(scene.motionPatches.size()), uint32_t(T.size())};
            scene.motionPatches.insert(scene.motionPatches.end(), world.begin(), world.end());
            scene.motionTimes.insert(scene.motionTimes.end(), T.begin(), T.end());
        }
        scene.patches.push_back(world[0]);
        scene.attributes.push_back(pa);
        addTexCoords(j);
        // Scene::patches holds the patch at shutter open (clamped to its keys).
        if (!same) scene.patches.back() = patchAtTime(scene, scene.patches.size() - 1, float(open));
    }
}

}  // namespace tessera::rib
