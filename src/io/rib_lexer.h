// Tokenizer for the ASCII RIB encoding (RI spec 3.2, appendix C.1): requests, numbers, strings,
// [ arrays ] and # comments, each token tagged with its line. Binary RIB is not supported.
#pragma once
#include <memory>
#include <optional>
#include <string>
#include <vector>

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
    // Request name, string contents or the raw characters; empty for a number (most of a RIB's tokens: a
    // string per number was a tenth of lexing 24 Big Guys), which error messages print from `number`.
    std::string text;
    double number = 0;
    int line = 0;
};

// Short human-readable form for error messages, e.g. `number '3'` or `end of file`.
std::string describe(const Token& t);

// Every token of a file as lexed, End last (a file that ReadArchive reads again is replayed from them
// instead of lexed again: 24 Big Guys read one 1.9 MB archive 24 times).
struct LexedFile {
    std::vector<Token> tokens;
    int eofLine = 1;
};

class RibLexer {
  public:
    RibLexer(std::string text, std::string file);
    // Replays `lexed` (tokens, lines and the end-of-file line as they were lexed from `file`).
    RibLexer(std::shared_ptr<const LexedFile> lexed, std::string file);
    // From now on, append every token lexed (End included) to `into`, and give it this file's last line.
    void record(LexedFile* into) {
        record_ = into;
        into->eofLine = eofLine_;
    }

    const Token& peek();
    Token next();
    void skip();  // next(), the token dropped
    const std::string& file() const { return file_; }
    // Line of the last line of the input (where end-of-file errors are reported).
    int eofLine() const { return eofLine_; }

  private:
    Token lex();
    Token lexText();
    Token lexString(int line);
    [[noreturn]] void fail(int line, const std::string& message) const;

    std::string text_;
    std::string file_;
    size_t pos_ = 0;
    int line_ = 1;
    int eofLine_ = 1;
    std::optional<Token> peeked_;
    std::shared_ptr<const LexedFile> replay_;
    size_t replayPos_ = 0;
    LexedFile* record_ = nullptr;
};

// Whole file contents; gzip-compressed files (magic bytes 1f 8b) are inflated with zlib.
// Throws InputError (no line) if the file cannot be read.
std::string readInputFile(const std::string& path);

}  // namespace tessera
