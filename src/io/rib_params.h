// Typed parameter lists (RI spec 3.2, sec. 3: "token-value pairs"): inline declarations such as
// "uniform float Kd", names made known by Declare, the predeclared standard names, and the checks
// of each value's type and size against its declaration.
#pragma once
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/vec.h"
#include "io/rib_request.h"

namespace tessera::rib {

// A parameter type as written in Declare or an inline declaration: "[class] type['[' n ']']".
struct Decl {
    std::string cls = "uniform";  // constant uniform varying vertex facevarying facevertex
    std::string type;             // float integer string color point vector normal hpoint matrix bool
    int arraySize = 1;

    // Numbers (or strings) per element of one array entry.
    int components() const;
};

// nullopt for text that is not a declaration (or declares more than 2^20 array entries).
std::optional<Decl> parseDecl(const std::string& text);

// The declared names: the predeclared variables and standard shader parameters (RI spec 3.2, sec. 3
// and appendix A), plus whatever Declare adds. A Declare of a predeclared name replaces it.
class Declarations {
  public:
    Declarations();
    void declare(const std::string& name, const Decl& d) {
        declared_[name] = d;
        ++version_;
    }
    std::optional<Decl> find(const std::string& name) const;
    // Changes with every declare: what was read under one version reads the same under it again.
    uint64_t version() const { return version_; }

  private:
    std::map<std::string, Decl> declared_;
    uint64_t version_ = 0;
};

struct Param {
    std::string name;          // without any inline declaration
    std::optional<Decl> decl;  // nullopt: never declared
    const Value* value = nullptr;
    int line = 0;
};

// How many elements a parameter of each storage class holds on the current primitive
// (RI spec 3.2, sec. 5: e.g. 16 "vertex" and 4 "varying" values on a bicubic patch).
using ClassCounts = std::function<size_t(const std::string& cls)>;

// The token-value pairs of `r` from argument `start` on. Values of declared parameters are checked
// against their declaration: per element `counts(class)` (1 without counts) entries of
// decl.components() * decl.arraySize numbers or strings. Undeclared parameters are not checked here.
std::vector<Param> parseParams(const Request& r, size_t start, const Declarations& decls,
                               const Diagnostics& diag, const ClassCounts& counts = nullptr);

// Typed reads of a parameter whose declaration is unknown or was checked by parseParams().
float paramFloat(const Request& r, const Param& p, const Diagnostics& diag);
Vec3 paramTriple(const Request& r, const Param& p, const Diagnostics& diag);
std::string paramString(const Request& r, const Param& p, const Diagnostics& diag);

// The warning (once per `what` and name) for a parameter the request does not use; `what` names the
// request, e.g. `Surface "matte"`.
void warnIgnoredParam(const Param& p, const std::string& what, Diagnostics& diag);

}  // namespace tessera::rib
