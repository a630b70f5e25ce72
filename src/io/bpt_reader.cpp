#include "io/bpt_reader.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <limits>

#include "io/diagnostics.h"

namespace tessera {

namespace {

// Whitespace-separated words with the line each starts on.
class WordReader {
  public:
    WordReader(const std::string& text, const std::string& file) : text_(text), file_(file) {}

    // Next word; `what` says what was expected, for the truncation error.
    std::string_view next(const char* what) {
        while (pos_ < text_.size() && std::isspace(static_cast<unsigned char>(text_[pos_]))) {
            if (text_[pos_] == '\n') ++line_;
            ++pos_;
        }
        if (pos_ >= text_.size()) {
            wordLine_ = lastLine();
            fail(std::string("unexpected end of file: expected ") + what);
        }
        size_t start = pos_;
        lastStart_ = start;
        while (pos_ < text_.size() && !std::isspace(static_cast<unsigned char>(text_[pos_]))) ++pos_;
        wordLine_ = line_;
        return std::string_view(text_).substr(start, pos_ - start);
    }

    double number(const char* what) {
        std::string_view w = next(what);
        double v = 0;
        std::string_view s = w.size() > 1 && w[0] == '+' ? w.substr(1) : w;
        auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
        if (ec != std::errc() || end != s.data() + s.size())
            fail("expected " + std::string(what) + ", found '" + printable(w) + "'");
        if (!std::isfinite(v))
            fail("invalid number '" + std::string(w) + "': NaN and infinity are not allowed");
        return v;
    }

    long integer(const char* what) {
        double v = number(what);
        if (v != std::floor(v) || std::fabs(v) > 1e15)
            fail(std::string("expected ") + what + ", found '" +
                 printable(std::string_view(text_).substr(lastStart_, pos_ - lastStart_)) + "'");
        return static_cast<long>(v);
    }

    bool atEnd() {
        while (pos_ < text_.size() && std::isspace(static_cast<unsigned char>(text_[pos_]))) {
            if (text_[pos_] == '\n') ++line_;
            ++pos_;
        }
        return pos_ >= text_.size();
    }

    int line() const { return wordLine_; }
    [[noreturn]] void fail(const std::string& message) const { throw InputError(file_, wordLine_, message); }

  private:
    int lastLine() const {
        int n = 1;
        for (char c : text_) n += c == '\n';
        return !text_.empty() && text_.back() == '\n' ? n - 1 : n;
    }

    const std::string& text_;
    const std::string& file_;
    size_t pos_ = 0, lastStart_ = 0;
    int line_ = 1;
    int wordLine_ = 1;
};

}  // namespace

std::vector<BezierPatch> parseBpt(const std::string& text, const std::string& file) {
    WordReader in(text, file);
    if (in.atEnd()) throw InputError(file, 1, "empty file: expected the patch count");
    long count = in.integer("the patch count");
    if (count < 0) in.fail("negative patch count " + std::to_string(count));
    if (count == 0) in.fail("no patches (patch count is 0)");
    std::vector<BezierPatch> patches;
    // A patch takes at least 100 characters ("3 3" and 48 numbers): never reserve for more than the text holds.
    patches.reserve(static_cast<size_t>(std::min(count, static_cast<long>(text.size() / 100 + 1))));
    for (long i = 0; i < count; ++i) {
        long du = in.integer("the u degree");
        int degreeLine = in.line();
        long dv = in.integer("the v degree");
        if (du != 3 || dv != 3)
            throw InputError(file, degreeLine,
                             "patch " + std::to_string(i + 1) + " has degree " + std::to_string(du) + " " +
                                 std::to_string(dv) + "; only bicubic (3 3) patches are supported");
        BezierPatch p;
        for (Vec3& c : p.cp) {
            double x = in.number("a coordinate"), y = in.number("a coordinate"),
                   z = in.number("a coordinate");
            const double fmax = std::numeric_limits<float>::max();
            if (std::fabs(x) > fmax || std::fabs(y) > fmax || std::fabs(z) > fmax)
                in.fail("coordinate out of range (larger than single precision allows)");
            c = {float(x), float(y), float(z)};
        }
        patches.push_back(p);
    }
    if (!in.atEnd()) {
        in.next("");
        in.fail("trailing data after " + std::to_string(count) + " patches (wrong patch count?)");
    }
    return patches;
}

}  // namespace tessera
