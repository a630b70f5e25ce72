#include "io/obj_reader.h"

#include <charconv>
#include <cmath>
#include <limits>
#include <set>
#include <string_view>

#include "io/subdiv_osd.h"

namespace tessera {

namespace {

bool isSpace(char c) {
    return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v';
}

std::vector<std::string_view> words(std::string_view s) {
    std::vector<std::string_view> out;
    size_t i = 0;
    while (i < s.size()) {
        while (i < s.size() && isSpace(s[i])) ++i;
        size_t j = i;
        while (j < s.size() && !isSpace(s[j])) ++j;
        if (j > i) out.push_back(s.substr(i, j - i));
        i = j;
    }
    return out;
}

bool parseDouble(std::string_view w, double& v) {
    if (!w.empty() && w[0] == '+') w.remove_prefix(1);
    auto [end, ec] = std::from_chars(w.data(), w.data() + w.size(), v);
    // Within single precision, which the patches use: 1e39 would become infinity.
    return ec == std::errc() && end == w.data() + w.size() && std::isfinite(v) &&
           std::fabs(v) <= std::numeric_limits<float>::max();
}

bool parseInt(std::string_view w, long& v) {
    if (!w.empty() && w[0] == '+') w.remove_prefix(1);
    auto [end, ec] = std::from_chars(w.data(), w.data() + w.size(), v);
    return ec == std::errc() && end == w.data() + w.size();
}

}  // namespace

ObjMesh parseObj(const std::string& text, const std::string& file, const WarningSink& warn) {
    ObjMesh out;
    SubdivMesh& m = out.mesh;
    m.boundary = BoundaryMode::EdgesAndCorners;
    std::set<std::string> warned;
    // Positive indices may point forward (some exporters write faces first); they are checked at the end.
    std::vector<std::pair<int, long>> forward;  // (face-vertex slot, line)
    size_t pos = 0;
    int line = 0;
    std::string logical;
    int logicalLine = 0;
    while (pos <= text.size()) {
        size_t eol = text.find('\n', pos);
        if (eol == std::string::npos) eol = text.size();
        std::string_view raw(text.data() + pos, eol - pos);
        ++line;
        bool last = eol >= text.size();
        pos = eol + 1;
        size_t hash = raw.find('#');
        if (hash != std::string_view::npos) raw = raw.substr(0, hash);
        while (!raw.empty() && isSpace(raw.back())) raw.remove_suffix(1);
        if (logical.empty()) logicalLine = line;
        if (!raw.empty() && raw.back() == '\\') {  // line continuation
            logical.append(raw.substr(0, raw.size() - 1));
            logical.push_back(' ');
            if (!last) continue;
        } else {
            logical.append(raw);
        }
        std::vector<std::string_view> w = words(logical);
        const int ln = logicalLine;
        auto fail = [&](const std::string& msg) { throw InputError(file, ln, msg); };
        if (!w.empty()) {
            std::string_view key = w[0];
            if (key == "v") {
                if (w.size() < 4)
                    fail("a vertex needs 3 coordinates (v x y z), found " + std::to_string(w.size() - 1));
                // v x y z, v x y z w, or the common extension v x y z r g b (vertex colour, ignored).
                if (w.size() != 4 && w.size() != 5 && w.size() != 7)
                    fail("a vertex has 3, 4 (x y z w) or 6 (x y z r g b) numbers, found " +
                         std::to_string(w.size() - 1));
                double c[4] = {0, 0, 0, 1};
                for (size_t i = 1; i < w.size(); ++i) {
                    double d;
                    if (!parseDouble(w[i], d))
                        fail("expected a number in the vertex, found '" + std::string(w[i]) + "'");
                    if (i <= 3 || (i == 4 && w.size() == 5)) c[i - 1] = d;
                }
                if (c[3] != 1.0 && warned.insert("w").second && warn)
                    warn(formatWarning(file, ln, "vertex weights (v x y z w) are ignored"));
                m.points.push_back({float(c[0]), float(c[1]), float(c[2])});
            } else if (key == "f" || key == "fo") {
                if (w.size() < 4)
                    fail("a face needs at least 3 vertices, found " + std::to_string(w.size() - 1));
                for (size_t i = 1; i < w.size(); ++i) {
                    std::string_view ref = w[i];
                    std::string_view vi = ref.substr(0, ref.find('/'));
                    // Check the vt / vn parts are numbers too (their values are not used).
                    size_t slash = ref.find('/');
                    while (slash != std::string_view::npos) {
                        size_t nextSlash = ref.find('/', slash + 1);
                        std::string_view part = ref.substr(slash + 1, nextSlash == std::string_view::npos
                                                                          ? std::string_view::npos
                                                                          : nextSlash - slash - 1);
                        long dummy;
                        if (!part.empty() && !parseInt(part, dummy))
                            fail("bad vertex reference '" + std::string(ref) + "' in a face");
                        slash = nextSlash;
                    }
                    long idx;
                    if (!parseInt(vi, idx)) fail("bad vertex reference '" + std::string(ref) + "' in a face");
                    long n = long(m.points.size());
                    if (idx == 0) fail("vertex index 0 in a face (OBJ indices start at 1)");
                    if (idx < 0) {
                        if (idx < -n)  // not -idx > n: -LONG_MIN overflows
                            fail("relative vertex index " + std::to_string(idx) +
                                 " reaches before the first vertex (" + std::to_string(n) +
                                 " defined so far)");
                        idx = n + idx;
                    } else {
                        if (idx > n) forward.push_back({int(m.faceVerts.size()), ln});
                        idx -= 1;
                    }
                    if (idx > 2000000000L) fail("vertex index " + std::string(vi) + " is too large");
                    m.faceVerts.push_back(int(idx));
                }
                m.faceSizes.push_back(int(w.size() - 1));
                out.faceLine.push_back(ln);
            } else if (key == "vt" || key == "vn" || key == "vp" || key == "o" || key == "g" || key == "s" ||
                       key == "usemtl" || key == "mtllib") {
                // Texture coordinates, normals, grouping and materials do not change the surface.
            } else if (warned.insert(std::string(key)).second && warn) {
                warn(formatWarning(file, ln,
                                   "OBJ statement '" + std::string(key) + "' is not supported; ignored"));
            }
        }
        logical.clear();
        if (last) break;
    }
    for (auto [slot, ln] : forward)
        if (m.faceVerts[size_t(slot)] >= int(m.points.size()))
            throw InputError(file, int(ln),
                             "vertex index " + std::to_string(m.faceVerts[size_t(slot)] + 1) +
                                 " is out of range (" + std::to_string(m.points.size()) +
                                 " vertices in the file)");
    if (m.faceSizes.empty()) throw InputError(file, line > 1 ? line - 1 : 1, "no faces (f) in the OBJ file");
    return out;
}

std::vector<BezierPatch> objToPatches(const std::string& text, const std::string& file,
                                      const WarningSink& warn, SubdivResult* stats) {
    ObjMesh obj = parseObj(text, file, warn);
    SubdivResult r;
    try {
        r = subdivideOsd(obj.mesh);  // no camera yet: kDefaultSubdivLevel
    } catch (const SubdivError& e) {
        int ln = e.face() >= 0 && size_t(e.face()) < obj.faceLine.size() ? obj.faceLine[size_t(e.face())] : 0;
        throw InputError(file, ln, e.what());
    }
    for (const std::string& w : r.warnings)
        if (warn) warn(formatWarning(file, 0, w));
    std::vector<BezierPatch> patches = std::move(r.patches);
    if (stats) {
        r.patches.clear();
        *stats = std::move(r);
    }
    return patches;
}

}  // namespace tessera
