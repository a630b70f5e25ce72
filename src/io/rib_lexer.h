// Tokenizer for the ASCII RIB encoding (RI spec 3.2, appendix C.1): requests, numbers, strings,
// [ arrays ] and # comments, each token tagged with its line. Binary RIB is not supported.
#pragma once
#include <optional>
#include <string>

namespace tessera {

enum class TokenType {
    Request,     // bare identifier: a request name
    Number,      // integer or float
    String,      // "quoted", escapes resolved
    ArrayBegin,  // [
    ArrayEnd,    // ]
    Other,       // anything else (e.g. `-x`); the reader decides whether it is an error
    End,         // end of input
};

struct Token {
    TokenType type = TokenType::End;
    std::string text;  // request name, string contents or the raw characters
    double number = 0;
    int line = 0;
};

// Short human-readable form for error messages, e.g. `number '3'` or `end of file`.
std::string describe(const Token& t);

class RibLexer {
  public:
    RibLexer(std::string text, std::string file);

    const Token& peek();
    Token next();
    const std::string& file() const { return file_; }
    // Line of the last line of the input (where end-of-file errors are reported).
    int eofLine() const { return eofLine_; }

  private:
    Token lex();
    Token lexString(int line);
    [[noreturn]] void fail(int line, const std::string& message) const;

    std::string text_;
    std::string file_;
    size_t pos_ = 0;
    int line_ = 1;
    int eofLine_ = 1;
    std::optional<Token> peeked_;
};

// Whole file contents; gzip-compressed files (magic bytes 1f 8b) are inflated with zlib.
// Throws InputError (no line) if the file cannot be read.
std::string readInputFile(const std::string& path);

}  // namespace tessera
