// One RIB request as the dispatcher hands it to its handler: the name, the line and the arguments
// (numbers, strings and [ arrays ], RI spec 3.2 appendix C.1), with typed argument access that fails
// with `file:line: error:` messages, and the diagnostics shared by all parts of the RIB reader.
#pragma once
#include <set>
#include <string>
#include <vector>

#include "io/diagnostics.h"

namespace tessera::rib {

// Errors and warnings of one load. Errors name the file being read now (a ReadArchive'd file while it
// is read); warnings with the same key are reported once per load (e.g. per unknown request name).
class Diagnostics {
  public:
    explicit Diagnostics(const WarningSink& warn) : warn_(warn) {}

    // The file whose requests are being read; set by the dispatcher around each (nested) file.
    void setFile(std::string file) { file_ = std::move(file); }
    const std::string& file() const { return file_; }

    [[noreturn]] void fail(int line, const std::string& message) const {
        throw InputError(file_, line, message);
    }
    void warn(int line, const std::string& message) const {
        if (warn_) warn_(formatWarning(file_, line, message));
    }
    void warnOnce(const std::string& key, int line, const std::string& message) {
        if (warned_.insert(key).second) warn(line, message);
    }

  private:
    const WarningSink& warn_;
    std::string file_;
    std::set<std::string> warned_;
};

// One argument of a request: a number, a string or an array of either.
struct Value {
    enum class Kind { Number, String, NumberArray, StringArray };
    Kind kind = Kind::Number;
    std::vector<double> nums;
    std::vector<std::string> strs;
    int line = 0;

    bool isArray() const { return kind == Kind::NumberArray || kind == Kind::StringArray; }
    bool numeric() const { return kind == Kind::Number || kind == Kind::NumberArray; }
    size_t size() const { return numeric() ? nums.size() : strs.size(); }
};

// Short form for error messages, e.g. `an array of 3 numbers`.
std::string describe(const Value& v);

struct Request {
    std::string name;
    int line = 0;
    std::vector<Value> args;
};

// Typed access to a request's positional arguments; every mismatch is an InputError at the
// argument's (or the request's) line.
class Arguments {
  public:
    Arguments(const Request& r, const Diagnostics& diag) : r_(r), diag_(diag) {}

    // Exactly / at least n arguments; `usage` names them in the message.
    void count(size_t n, const char* usage) const;
    void atLeast(size_t n, const char* usage) const;
    double number(size_t i) const;
    int integer(size_t i) const;
    const std::string& string(size_t i) const;
    // Exactly n numbers, given either one by one or as one array (both are valid RIB).
    std::vector<double> numbers(size_t n, const char* usage) const;
    // Argument i as an array of numbers / of integers; `what` names it in the message.
    std::vector<double> numberArray(size_t i, const char* what) const;
    std::vector<int> intArray(size_t i, const char* what) const;

  private:
    const Request& r_;
    const Diagnostics& diag_;
};

}  // namespace tessera::rib
