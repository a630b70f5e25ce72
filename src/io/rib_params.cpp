#include "io/rib_params.h"

#include <cctype>
#include <cstdlib>
#include <set>

namespace tessera::rib {

int Decl::components() const {
    if (type == "color" || type == "point" || type == "vector" || type == "normal") return 3;
    if (type == "hpoint") return 4;
    if (type == "matrix") return 16;
    return 1;  // float integer string bool
}

std::optional<Decl> parseDecl(const std::string& text) {
    static const std::set<std::string> classes = {"constant", "uniform",     "varying",
                                                  "vertex",   "facevarying", "facevertex"};
    static const std::set<std::string> types = {"float",  "integer", "int",    "string", "color", "point",
                                                "vector", "normal",  "hpoint", "matrix", "bool"};
    // Normalise "float[2]" / "float [ 2 ]" to words.
    std::string s;
    for (char c : text) s += (c == '[' || c == ']') ? ' ' : c;
    std::vector<std::string> words;
    size_t i = 0;
    while (i < s.size()) {
        while (i < s.size() && std::isspace(static_cast<unsigned char>(s[i]))) ++i;
        size_t j = i;
        while (j < s.size() && !std::isspace(static_cast<unsigned char>(s[j]))) ++j;
        if (j > i) words.push_back(s.substr(i, j - i));
        i = j;
    }
    Decl d;
    size_t w = 0;
    if (w < words.size() && classes.count(words[w])) d.cls = words[w++];
    if (w >= words.size() || !types.count(words[w])) return std::nullopt;
    d.type = words[w++] == "int" ? "integer" : words[w - 1];
    if (w < words.size()) {
        char* end = nullptr;
        long n = std::strtol(words[w].c_str(), &end, 10);
        if (*end != 0 || n < 1 || n > (1 << 20)) return std::nullopt;
        d.arraySize = static_cast<int>(n);
        ++w;
    }
    if (w != words.size()) return std::nullopt;
    return d;
}

Declarations::Declarations() {
    // Predeclared variables and standard shader parameters (RI spec 3.2, sec. 3 and appendix A).
    const std::pair<const char*, const char*> builtin[] = {
        {"P", "vertex point"},          {"Pw", "vertex hpoint"},         {"Pz", "vertex float"},
        {"N", "varying normal"},        {"Np", "uniform normal"},        {"Cs", "varying color"},
        {"Os", "varying color"},        {"s", "varying float"},          {"t", "varying float"},
        {"st", "varying float[2]"},     {"Ka", "uniform float"},         {"Kd", "uniform float"},
        {"Ks", "uniform float"},        {"roughness", "uniform float"},  {"Kr", "uniform float"},
        {"Kt", "uniform float"},        {"eta", "uniform float"},        {"specularcolor", "uniform color"},
        {"intensity", "uniform float"}, {"lightcolor", "uniform color"}, {"from", "uniform point"},
        {"to", "uniform point"},        {"fov", "uniform float"},        {"name", "uniform string"},
        {"jitter", "uniform integer"},  // Hider "hidden" (PRMan, Aqsis)
    };
    for (auto [name, decl] : builtin) declared_[name] = *parseDecl(decl);
}

std::optional<Decl> Declarations::find(const std::string& name) const {
    auto it = declared_.find(name);
    if (it == declared_.end()) return std::nullopt;
    return it->second;
}

std::vector<Param> parseParams(const Request& r, size_t start, const Declarations& decls,
                               const Diagnostics& diag, const ClassCounts& counts) {
    std::vector<Param> out;
    for (size_t i = start; i < r.args.size(); i += 2) {
        const Value& nameV = r.args[i];
        if (nameV.kind != Value::Kind::String)
            diag.fail(nameV.line, r.name + ": expected a parameter name, found " + describe(nameV));
        Param p;
        p.line = nameV.line;
        const std::string& full = nameV.strs[0];
        size_t sp = full.find_last_of(" \t");
        if (sp != std::string::npos) {  // inline declaration, e.g. "uniform float Kd"
            p.name = full.substr(sp + 1);
            p.decl = parseDecl(full.substr(0, sp));
            if (!p.decl || p.name.empty())
                diag.fail(p.line, r.name + ": invalid inline declaration \"" + full + "\"");
        } else {
            p.name = full;
            p.decl = decls.find(full);
        }
        if (i + 1 >= r.args.size())
            diag.fail(p.line, r.name + ": missing value for parameter \"" + p.name + "\"");
        p.value = &r.args[i + 1];
        if (p.decl) {
            const Decl& d = *p.decl;
            bool wantString = d.type == "string";
            bool emptyArray = p.value->isArray() && p.value->size() == 0;
            if (!emptyArray && wantString == p.value->numeric())
                diag.fail(p.value->line, r.name + ": parameter \"" + p.name + "\" (" + d.type + ") needs " +
                                             (wantString ? "strings" : "numbers") + ", found " +
                                             describe(*p.value));
            size_t elems = counts ? counts(d.cls) : 1;
            size_t want = elems * static_cast<size_t>(d.components() * d.arraySize);
            if (p.value->size() != want) {
                std::string type = d.cls + " " + d.type;
                // (Appended piecewise: `"[" + std::to_string()` trips a false -Wrestrict in g++ 12.)
                if (d.arraySize > 1) type.append("[").append(std::to_string(d.arraySize)).append("]");
                diag.fail(p.value->line, r.name + ": parameter \"" + p.name + "\" needs " +
                                             std::to_string(want) + " values (" + std::to_string(elems) +
                                             " x " + type + "), got " + std::to_string(p.value->size()));
            }
        }
        out.push_back(std::move(p));
    }
    return out;
}

float paramFloat(const Request& r, const Param& p, const Diagnostics& diag) {
    if (!p.value->numeric() || p.value->nums.size() != 1)
        diag.fail(p.line,
                  r.name + ": parameter \"" + p.name + "\" needs 1 number, found " + describe(*p.value));
    return float(p.value->nums[0]);
}

Vec3 paramTriple(const Request& r, const Param& p, const Diagnostics& diag) {
    if (!p.value->numeric() || p.value->nums.size() != 3)
        diag.fail(p.line,
                  r.name + ": parameter \"" + p.name + "\" needs 3 numbers, found " + describe(*p.value));
    return {float(p.value->nums[0]), float(p.value->nums[1]), float(p.value->nums[2])};
}

std::string paramString(const Request& r, const Param& p, const Diagnostics& diag) {
    if (p.value->numeric() || p.value->strs.size() != 1)
        diag.fail(p.line,
                  r.name + ": parameter \"" + p.name + "\" needs 1 string, found " + describe(*p.value));
    return p.value->strs[0];
}

void warnIgnoredParam(const Param& p, const std::string& what, Diagnostics& diag) {
    diag.warnOnce("param:" + what + ":" + p.name, p.line,
                  what + ": parameter \"" + p.name + "\" is " + (p.decl ? "not supported" : "not declared") +
                      " and is ignored");
}

}  // namespace tessera::rib
