#include "io/rib_lexer.h"

#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>

#include "io/diagnostics.h"

namespace tessera {

namespace {

bool isDelimiter(char c) {
    return std::isspace(static_cast<unsigned char>(c)) || c == '[' || c == ']' || c == '"' || c == '#';
}
bool isIdentStart(char c) {
    return std::isalpha(static_cast<unsigned char>(c)) || c == '_';
}
bool isIdentChar(char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_';
}
bool isDigit(char c) {
    return c >= '0' && c <= '9';
}

// "nan", "inf", "infinity" with an optional sign: words a careless exporter writes for bad floats.
bool isNonFiniteWord(std::string s) {
    if (!s.empty() && (s[0] == '+' || s[0] == '-')) s.erase(0, 1);
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
    return s == "nan" || s == "inf" || s == "infinity";
}

}  // namespace

std::string describe(const Token& t) {
    switch (t.type) {
        case TokenType::Request:
            return "request '" + printable(t.text) + "'";
        case TokenType::Number: {
            // The shortest digits that read back as the same double (`12` for 12, `0.5` for .50).
            char digits[32];
            const auto end = std::to_chars(digits, digits + sizeof digits, t.number).ptr;
            return "number '" + std::string(digits, end) + "'";
        }
        case TokenType::String:
            return "string \"" + printable(t.text) + "\"";
        case TokenType::ArrayBegin:
            return "'['";
        case TokenType::ArrayEnd:
            return "']'";
        case TokenType::Other:
            return "token '" + printable(t.text) + "'";
        case TokenType::End:
            return "end of file";
    }
    return "token";
}

RibLexer::RibLexer(std::string text, std::string file) : text_(std::move(text)), file_(std::move(file)) {
    eofLine_ = 1 + static_cast<int>(std::count(text_.begin(), text_.end(), '\n'));
    // A final newline ends the last line rather than starting a new (empty) one.
    if (!text_.empty() && text_.back() == '\n') --eofLine_;
}

RibLexer::RibLexer(std::shared_ptr<const LexedFile> lexed, std::string file)
    : file_(std::move(file)), eofLine_(lexed->eofLine), replay_(std::move(lexed)) {}

void RibLexer::fail(int line, const std::string& message) const {
    throw InputError(file_, line, message);
}

const Token& RibLexer::peek() {
    if (replay_) return replay_->tokens[std::min(replayPos_, replay_->tokens.size() - 1)];
    if (!peeked_) peeked_ = lex();
    return *peeked_;
}

void RibLexer::skip() {
    if (replay_)
        ++replayPos_;
    else if (peeked_)
        peeked_.reset();
    else
        lex();
}

Token RibLexer::next() {
    if (peeked_) {
        Token t = std::move(*peeked_);
        peeked_.reset();
        return t;
    }
    return lex();
}

Token RibLexer::lex() {
    if (replay_) {  // the last token (End) repeats
        const std::vector<Token>& t = replay_->tokens;
        return t[std::min(replayPos_++, t.size() - 1)];
    }
    Token t = lexText();
    if (record_) record_->tokens.push_back(t);
    return t;
}

Token RibLexer::lexText() {
    // Skip whitespace and comments (# to end of line; ## structure comments are comments too).
    while (pos_ < text_.size()) {
        char c = text_[pos_];
        if (c == '\n') {
            ++line_;
            ++pos_;
        } else if (std::isspace(static_cast<unsigned char>(c))) {
            ++pos_;
        } else if (c == '#') {
            while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
        } else {
            break;
        }
    }
    Token t;
    t.line = line_;
    if (pos_ >= text_.size()) {
        t.type = TokenType::End;
        t.line = eofLine_;
        return t;
    }
    char c = text_[pos_];
    if (c == '[' || c == ']') {
        ++pos_;
        t.type = c == '[' ? TokenType::ArrayBegin : TokenType::ArrayEnd;
        t.text = std::string(1, c);
        return t;
    }
    if (c == '"') return lexString(line_);

    size_t start = pos_;
    if (isIdentStart(c)) {
        while (pos_ < text_.size() && isIdentChar(text_[pos_])) ++pos_;
        if (pos_ >= text_.size() || isDelimiter(text_[pos_])) {
            t.type = TokenType::Request;
            t.text = text_.substr(start, pos_ - start);
            if (isNonFiniteWord(t.text))
                fail(t.line, "invalid number '" + t.text + "': NaN and infinity are not allowed");
            return t;
        }
    } else if (isDigit(c) || c == '.' || c == '+' || c == '-') {
        // [+-]? (digits [. digits?] | . digits) ([eE] [+-]? digits)?
        size_t p = pos_;
        const bool negative = text_[p] == '-';
        if (text_[p] == '+' || text_[p] == '-') ++p;
        // The digits as an integer while it stays exact (at most 15 of them: below 2^53), and how many
        // follow the point, for the fast path below.
        size_t digits = 0, fractionDigits = 0;
        uint64_t mantissa = 0;
        while (p < text_.size() && isDigit(text_[p]))
            mantissa = mantissa * 10 + uint64_t(text_[p++] - '0'), ++digits;
        if (p < text_.size() && text_[p] == '.') {
            ++p;
            while (p < text_.size() && isDigit(text_[p]))
                mantissa = mantissa * 10 + uint64_t(text_[p++] - '0'), ++digits, ++fractionDigits;
        }
        bool hasExponent = false;
        if (digits > 0 && p < text_.size() && (text_[p] == 'e' || text_[p] == 'E')) {
            size_t q = p + 1;
            if (q < text_.size() && (text_[q] == '+' || text_[q] == '-')) ++q;
            if (q < text_.size() && isDigit(text_[q])) {
                while (q < text_.size() && isDigit(text_[q])) ++q;
                p = q;
                hasExponent = true;
            }
        }
        if (digits > 0 && (p >= text_.size() || isDelimiter(text_[p]))) {
            t.type = TokenType::Number;
            pos_ = p;
            // Clinger's fast path (1990): an integer below 2^53 and a power of ten up to 1e22 are exact
            // doubles, so one IEEE division rounds their quotient correctly, the same double from_chars
            // gives. Most RIB numbers qualify; the rest (exponents, long digit strings) go to from_chars.
            static constexpr double kPowersOfTen[] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,
                                                      1e8,  1e9,  1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
                                                      1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};
            if (!hasExponent && digits <= 15) {
                const double magnitude = double(mantissa) / kPowersOfTen[fractionDigits];
                t.number = negative ? -magnitude : magnitude;
                return t;
            }
            // from_chars rejects a leading '+'.
            const char* first = text_.data() + start + (text_[start] == '+' ? 1 : 0);
            auto [end, ec] = std::from_chars(first, text_.data() + p, t.number);
            // Everything downstream is single precision: larger magnitudes would become infinities.
            if (ec != std::errc() || end != text_.data() + p || !std::isfinite(t.number) ||
                std::fabs(t.number) > std::numeric_limits<float>::max())
                fail(t.line, "invalid number '" + text_.substr(start, p - start) + "': out of range");
            return t;
        }
    }
    // Anything else up to the next delimiter is one opaque token; control characters and bytes >= 0x7f
    // outside strings and comments mean binary data (binary RIB, an image, a compressed file...).
    pos_ = start;
    while (pos_ < text_.size() && !isDelimiter(text_[pos_])) {
        unsigned char b = static_cast<unsigned char>(text_[pos_]);
        if (b < 0x20 || b >= 0x7f) {
            static const char* hex = "0123456789abcdef";
            fail(t.line, std::string("binary data (byte 0x") + hex[b >> 4] + hex[b & 15] +
                             "): not a RIB text file (binary RIB is not supported)");
        }
        ++pos_;
    }
    t.type = TokenType::Other;
    t.text = text_.substr(start, pos_ - start);
    if (isNonFiniteWord(t.text))
        fail(t.line, "invalid number '" + t.text + "': NaN and infinity are not allowed");
    return t;
}

// RI spec C.1: strings are enclosed in double quotes with C-style escapes; a backslash-newline
// continues the string on the next line.
Token RibLexer::lexString(int line) {
    Token t;
    t.type = TokenType::String;
    t.line = line;
    ++pos_;  // opening quote
    while (true) {
        if (pos_ >= text_.size()) fail(line, "unterminated string");
        char c = text_[pos_++];
        if (c == '"') return t;
        if (c == '\n') {
            // A raw newline inside a string is almost always a missing quote; RIB does not allow it.
            fail(line, "unterminated string");
        }
        if (c != '\\') {
            t.text += c;
            continue;
        }
        if (pos_ >= text_.size()) fail(line, "unterminated string");
        char e = text_[pos_++];
        switch (e) {
            case 'n':
                t.text += '\n';
                break;
            case 'r':
                t.text += '\r';
                break;
            case 't':
                t.text += '\t';
                break;
            case 'b':
                t.text += '\b';
                break;
            case 'f':
                t.text += '\f';
                break;
            case '\n':
                ++line_;
                break;  // line continuation
            default:
                if (e >= '0' && e <= '7') {  // up to three octal digits
                    int v = e - '0';
                    for (int k = 0; k < 2 && pos_ < text_.size() && text_[pos_] >= '0' && text_[pos_] <= '7';
                         ++k)
                        v = v * 8 + (text_[pos_++] - '0');
                    t.text += static_cast<char>(v);
                } else {
                    t.text += e;  // \\ \" \' and unknown escapes stand for the character itself
                }
        }
    }
}

std::string readInputFile(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(path, 0, std::string("cannot open file: ") + std::strerror(errno));
    char magic[2] = {0, 0};
    in.read(magic, 2);
    bool gz = in.gcount() == 2 && static_cast<unsigned char>(magic[0]) == 0x1f &&
              static_cast<unsigned char>(magic[1]) == 0x8b;
    if (!gz) {
        // Straight into a string of the file's size: through an ostringstream the text was copied twice
        // (its growing buffer, then str()), which perf put at 4% of loading 24 Big Guys (issue 18).
        in.clear();
        in.seekg(0, std::ios::end);
        const std::streamoff size = in.tellg();
        in.seekg(0);
        if (size < 0) {  // not seekable (a pipe): read it as a stream
            in.clear();
            std::ostringstream ss;
            ss << in.rdbuf();
            if (in.bad()) throw InputError(path, 0, "read error");
            return ss.str();
        }
        std::string text(size_t(size), '\0');
        in.read(text.data(), size);
        if (in.bad() || in.gcount() != size) throw InputError(path, 0, "read error");
        return text;
    }
    in.close();
    gzFile f = gzopen(path.c_str(), "rb");
    if (!f) throw InputError(path, 0, "cannot open gzip file");
    std::string out;
    char buf[1 << 16];
    int n;
    while ((n = gzread(f, buf, sizeof buf)) > 0) out.append(buf, static_cast<size_t>(n));
    int err = 0;
    std::string msg = n < 0 ? gzerror(f, &err) : "";
    gzclose(f);
    if (n < 0) throw InputError(path, 0, "gzip decompression failed: " + msg);
    return out;
}

}  // namespace tessera
