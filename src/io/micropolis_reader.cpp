#include "io/micropolis_reader.h"

#include <charconv>
#include <cmath>
#include <string_view>

#include "io/diagnostics.h"

namespace tessera {

namespace {

bool blank(char c) {
    return c == ' ' || c == '\t' || c == '\r';
}

std::string_view trim(std::string_view s) {
    while (!s.empty() && blank(s.front())) s.remove_prefix(1);
    while (!s.empty() && blank(s.back())) s.remove_suffix(1);
    return s;
}

// Lines of the text with their 1-based numbers.
class Lines {
  public:
    explicit Lines(const std::string& text) : text_(text) {}
    // Next line (trimmed); false at the end of the text.
    bool next(std::string_view& out) {
        if (pos_ >= text_.size()) return false;
        size_t eol = text_.find('\n', pos_);
        if (eol == std::string::npos) eol = text_.size();
        out = trim(std::string_view(text_).substr(pos_, eol - pos_));
        pos_ = eol + 1;
        ++line_;
        return true;
    }
    int line() const { return line_; }

  private:
    const std::string& text_;
    size_t pos_ = 0;
    int line_ = 0;
};

// Splits a line at commas; each field trimmed.
std::vector<std::string_view> fields(std::string_view s) {
    std::vector<std::string_view> out;
    size_t start = 0;
    while (true) {
        size_t c = s.find(',', start);
        out.push_back(
            trim(s.substr(start, c == std::string_view::npos ? std::string_view::npos : c - start)));
        if (c == std::string_view::npos) break;
        start = c + 1;
    }
    return out;
}

bool toLong(std::string_view w, long& v) {
    auto [end, ec] = std::from_chars(w.data(), w.data() + w.size(), v);
    return !w.empty() && ec == std::errc() && end == w.data() + w.size();
}

bool toDouble(std::string_view w, double& v) {
    if (!w.empty() && w[0] == '+') w.remove_prefix(1);
    auto [end, ec] = std::from_chars(w.data(), w.data() + w.size(), v);
    return !w.empty() && ec == std::errc() && end == w.data() + w.size() && std::isfinite(v);
}

}  // namespace

bool looksLikeMicropolis(const std::string& text) {
    Lines lines(text);
    std::string_view a, b;
    if (!lines.next(a) || !lines.next(b)) return false;
    long n;
    if (!toLong(a, n) || n < 1) return false;
    std::vector<std::string_view> f = fields(b);
    if (f.size() != 16) return false;
    for (std::string_view w : f)
        if (!toLong(w, n)) return false;
    return true;
}

std::vector<BezierPatch> parseMicropolis(const std::string& text, const std::string& file) {
    Lines lines(text);
    std::string_view s;
    auto need = [&](const char* what) {
        if (!lines.next(s))
            throw InputError(file, std::max(1, lines.line()),
                             std::string("unexpected end of file: expected ") + what);
    };
    auto fail = [&](const std::string& msg) { throw InputError(file, lines.line(), msg); };

    need("the patch count");
    long np;
    if (!toLong(s, np)) fail("expected the patch count on the first line, found '" + std::string(s) + "'");
    if (np < 1) fail("the patch count must be positive, found " + std::to_string(np));
    if (np > 50000000) fail("implausible patch count " + std::to_string(np));
    std::vector<long> index;
    std::vector<int> indexLine;
    index.reserve(size_t(np) * 16);
    for (long p = 0; p < np; ++p) {
        need("a line of 16 vertex indices");
        std::vector<std::string_view> f = fields(s);
        if (f.size() == 1)
            fail("expected 16 comma-separated vertex indices for patch " + std::to_string(p + 1) + " of " +
                 std::to_string(np) + ", found '" + std::string(s) + "' (patch count too large?)");
        if (f.size() != 16)
            fail("patch " + std::to_string(p + 1) + " has " + std::to_string(f.size()) +
                 " vertex indices; expected 16");
        for (std::string_view w : f) {
            long v;
            if (!toLong(w, v)) fail("expected an integer vertex index, found '" + std::string(w) + "'");
            index.push_back(v);
        }
        indexLine.push_back(lines.line());
    }
    need("the vertex count");
    long nv;
    if (s.find(',') != std::string_view::npos)
        fail("expected the vertex count, found a line with commas (patch count too small?)");
    if (!toLong(s, nv)) fail("expected the vertex count, found '" + std::string(s) + "'");
    if (nv < 1) fail("the vertex count must be positive, found " + std::to_string(nv));
    if (nv > 500000000) fail("implausible vertex count " + std::to_string(nv));
    std::vector<Vec3> verts;
    verts.reserve(size_t(nv));
    for (long i = 0; i < nv; ++i) {
        need("a vertex line x,y,z");
        std::vector<std::string_view> f = fields(s);
        if (f.size() != 3)
            fail("vertex " + std::to_string(i + 1) + " of " + std::to_string(nv) + " has " +
                 std::to_string(f.size()) + " values; expected x,y,z");
        double c[3];
        for (int k = 0; k < 3; ++k)
            if (!toDouble(f[size_t(k)], c[k]))
                fail("expected a number, found '" + std::string(f[size_t(k)]) + "'");
        verts.push_back({float(c[0]), float(c[1]), float(c[2])});
    }
    while (lines.next(s))
        if (!s.empty()) fail("trailing data after " + std::to_string(nv) + " vertices (wrong vertex count?)");
    std::vector<BezierPatch> patches(static_cast<size_t>(np));
    for (size_t p = 0; p < size_t(np); ++p)
        for (int k = 0; k < 16; ++k) {
            long v = index[p * 16 + size_t(k)];
            if (v < 1 || v > nv)
                throw InputError(file, indexLine[p],
                                 "vertex index " + std::to_string(v) + " in patch " + std::to_string(p + 1) +
                                     " is outside 1.." + std::to_string(nv));
            patches[p].cp[k] = verts[size_t(v - 1)];
        }
    return patches;
}

}  // namespace tessera
