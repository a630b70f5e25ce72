// Errors and warnings from the scene readers, in the compiler-style form `file:line: error: what`.
#pragma once
#include <functional>
#include <stdexcept>
#include <string>
#include <string_view>

#include "scene/scene.h"  // the input limits kMaxImageSize, kMaxPixelSamples

namespace tessera {

// Thrown for any malformed input; what() is the full `file:line: error: message` text.
class InputError : public std::runtime_error {
  public:
    InputError(std::string file, int line, const std::string& message)
        : std::runtime_error(format(file, line, message)), file_(std::move(file)), line_(line) {}
    const std::string& file() const { return file_; }
    int line() const { return line_; }
    static std::string format(const std::string& file, int line, const std::string& message) {
        return line > 0 ? file + ":" + std::to_string(line) + ": error: " + message
                        : file + ": error: " + message;
    }

  private:
    std::string file_;
    int line_;
};

// `s` for an error message: bytes outside printable ASCII as \xNN, at most `max` characters then "...".
inline std::string printable(std::string_view s, size_t max = 40) {
    static const char* hex = "0123456789abcdef";
    std::string out;
    for (size_t i = 0; i < s.size() && i < max; ++i) {
        unsigned char c = static_cast<unsigned char>(s[i]);
        if (c >= 0x20 && c < 0x7f) {
            out += char(c);
        } else {
            out += "\\x";
            out += hex[c >> 4];
            out += hex[c & 15];
        }
    }
    if (s.size() > max) out += "...";
    return out;
}

// Receives `file:line: warning: message` lines; the CLI prints them to stderr.
using WarningSink = std::function<void(const std::string&)>;

inline std::string formatWarning(const std::string& file, int line, const std::string& message) {
    return file + ":" + std::to_string(line) + ": warning: " + message;
}

}  // namespace tessera
