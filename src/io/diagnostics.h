// Errors and warnings from the scene readers, in the compiler-style form `file:line: error: what`.
#pragma once
#include <functional>
#include <stdexcept>
#include <string>

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

// Receives `file:line: warning: message` lines; the CLI prints them to stderr.
using WarningSink = std::function<void(const std::string&)>;

inline std::string formatWarning(const std::string& file, int line, const std::string& message) {
    return file + ":" + std::to_string(line) + ": warning: " + message;
}

}  // namespace tessera
