#include "io/rib_request.h"

#include <cmath>

namespace tessera::rib {

std::string describe(const Value& v) {
    switch (v.kind) {
        case Value::Kind::Number:
            return "a number";
        case Value::Kind::String:
            return "string \"" + v.strs[0] + "\"";
        case Value::Kind::NumberArray:
            return "an array of " + std::to_string(v.nums.size()) + " numbers";
        case Value::Kind::StringArray:
            return "an array of " + std::to_string(v.strs.size()) + " strings";
    }
    return "a value";
}

void Arguments::count(size_t n, const char* usage) const {
    if (r_.args.size() != n)
        diag_.fail(r_.line, r_.name + " expects " + std::to_string(n) + " arguments (" + usage + "), got " +
                                std::to_string(r_.args.size()));
}

void Arguments::atLeast(size_t n, const char* usage) const {
    if (r_.args.size() < n)
        diag_.fail(r_.line, r_.name + " expects at least " + std::to_string(n) + " arguments (" + usage +
                                "), got " + std::to_string(r_.args.size()));
}

double Arguments::number(size_t i) const {
    const Value& v = r_.args.at(i);
    if (!v.numeric() || v.nums.size() != 1)
        diag_.fail(v.line, r_.name + ": argument " + std::to_string(i + 1) + " must be a number, found " +
                               describe(v));
    return v.nums[0];
}

int Arguments::integer(size_t i) const {
    double d = number(i);
    if (d != std::floor(d) || std::fabs(d) > 1e9)
        diag_.fail(r_.args[i].line, r_.name + ": argument " + std::to_string(i + 1) + " must be an integer");
    return static_cast<int>(d);
}

const std::string& Arguments::string(size_t i) const {
    const Value& v = r_.args.at(i);
    if (v.numeric() || v.strs.size() != 1)
        diag_.fail(v.line, r_.name + ": argument " + std::to_string(i + 1) + " must be a string, found " +
                               describe(v));
    return v.strs[0];
}

std::vector<double> Arguments::numbers(size_t n, const char* usage) const {
    std::vector<double> out;
    for (const Value& v : r_.args) {
        if (!v.numeric())
            diag_.fail(v.line, r_.name + " expects numbers (" + usage + "), found " + describe(v));
        out.insert(out.end(), v.nums.begin(), v.nums.end());
    }
    if (out.size() != n)
        diag_.fail(r_.line, r_.name + " expects " + std::to_string(n) + " numbers (" + usage + "), got " +
                                std::to_string(out.size()));
    return out;
}

std::vector<double> Arguments::numberArray(size_t i, const char* what) const {
    const Value& v = r_.args.at(i);
    if (!v.numeric())
        diag_.fail(v.line, r_.name + ": " + what + " must be an array of numbers, found " + describe(v));
    return v.nums;
}

std::vector<int> Arguments::intArray(size_t i, const char* what) const {
    std::vector<int> out;
    for (double d : numberArray(i, what)) {
        if (d != std::floor(d) || std::fabs(d) > 2e9)
            diag_.fail(r_.args[i].line,
                       r_.name + ": " + what + " must hold integers, found " + std::to_string(d));
        out.push_back(int(d));
    }
    return out;
}

}  // namespace tessera::rib
