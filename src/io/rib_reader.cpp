#include "io/rib_reader.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <unordered_map>
#include <vector>

#include "core/basis.h"
#include "core/nurbs.h"
#include "core/subdivision.h"
#include "io/rib_lexer.h"

namespace tessera {

namespace {

// ---------------------------------------------------------------------------------------------
// Request arguments and parameter lists (RI spec 3.2, sec. 3: "token-value pairs").

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

struct Request {
    std::string name;
    int line = 0;
    std::vector<Value> args;
};

// A parameter type as written in Declare or an inline declaration: "[class] type['[' n ']']".
struct Decl {
    std::string cls = "uniform";  // constant uniform varying vertex facevarying facevertex
    std::string type;             // float integer string color point vector normal hpoint matrix
    int arraySize = 1;

    int components() const {
        if (type == "color" || type == "point" || type == "vector" || type == "normal") return 3;
        if (type == "hpoint") return 4;
        if (type == "matrix") return 16;
        return 1;  // float integer string
    }
};

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

struct Param {
    std::string name;          // without any inline declaration
    std::optional<Decl> decl;  // nullopt: never declared
    const Value* value = nullptr;
    int line = 0;
};

// How many elements a parameter of each storage class holds on the current primitive.
using ClassCounts = std::function<size_t(const std::string& cls)>;

// ---------------------------------------------------------------------------------------------
// Graphics state (RI spec 3.2, sec. 4).

enum class Block { Frame, World, Attribute, Transform };

const char* blockName(Block b) {
    switch (b) {
        case Block::Frame:
            return "FrameBegin";
        case Block::World:
            return "WorldBegin";
        case Block::Attribute:
            return "AttributeBegin";
        case Block::Transform:
            return "TransformBegin";
    }
    return "";
}

struct Attributes {
    // The RI default surface is "defaultsurface"; matte is the closest standard shader.
    Material surface = defaultMaterial(MaterialType::Matte);
    float shadingRate = 1.f;
    bool twoSided = true;      // RI default: Sides 2
    bool rightHanded = false;  // Orientation "rh"/"inside"; the initial "outside" counts as "lh"
    Basis uBasis = bezierBasis(), vBasis = bezierBasis();
    std::string identifier;
};

struct Saved {
    Block block;
    std::string file;
    int line;
    Mat4 ctm;
    Attributes attrs;
};

bool sameMaterial(const Material& a, const Material& b) {
    return a.type == b.type && a.Cs == b.Cs && a.Os == b.Os && a.Ka == b.Ka && a.Kd == b.Kd && a.Ks == b.Ks &&
           a.roughness == b.roughness && a.specularColor == b.specularColor && a.Kr == b.Kr && a.Kt == b.Kt &&
           a.eta == b.eta;
}

bool isBezier(const Basis& b) {
    Basis z = bezierBasis();
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            if (b.m[i][j] != z.m[i][j]) return false;
    return true;
}

constexpr int kMaxArchiveDepth = 32;

class RibReader {
  public:
    RibReader(Scene& scene, const WarningSink& warn) : scene_(scene), warn_(warn) { initTables(); }

    void run(const std::string& path) { runText(readInputFile(path), path); }
    void runText(std::string text, const std::string& path) {
        RibLexer lex(std::move(text), path);
        lex_ = &lex;
        if (lex.peek().type == TokenType::End) fail(lex.eofLine(), "empty file: no RIB requests");
        parse(lex, 0);
        if (!stack_.empty()) {
            const Saved& s = stack_.back();
            fail(lex.eofLine(), std::string("end of file inside ") + blockName(s.block) +
                                    " block opened at " + s.file + ":" + std::to_string(s.line));
        }
        if (scene_.patches.empty())
            fail(lex.eofLine(),
                 "no geometry: the file has no Patch, PatchMesh, NuPatch or SubdivisionMesh primitives");
        if (scene_.lights.empty())
            warnAt(lex.eofLine(), "no light sources: only \"constant\" surfaces will be visible");
    }

  private:
    using Handler = void (RibReader::*)(const Request&);

    // ---- diagnostics -------------------------------------------------------------------------
    [[noreturn]] void fail(int line, const std::string& message) const {
        throw InputError(lex_->file(), line, message);
    }
    void warnAt(int line, const std::string& message) {
        if (warn_) warn_(formatWarning(lex_->file(), line, message));
    }
    // One warning per key for the whole load (e.g. per unknown request name).
    void warnOnce(const std::string& key, int line, const std::string& message) {
        if (warned_.insert(key).second) warnAt(line, message);
    }

    // ---- parsing -----------------------------------------------------------------------------
    void parse(RibLexer& lex, int depth) {
        while (true) {
            Token t = lex.next();
            if (t.type == TokenType::End) return;
            if (t.type != TokenType::Request) fail(t.line, "expected a RIB request, found " + describe(t));
            Request r{t.text, t.line, {}};
            auto h = handlers_.find(r.name);
            bool known = h != handlers_.end();
            collectArgs(lex, r, /*tolerant=*/!known || skipUntil_.has_value());
            if (skipUntil_) {  // inside a frame or world we do not load
                if (r.name == *skipUntil_) skipUntil_.reset();
                continue;
            }
            if (!known) {
                warnOnce("request:" + r.name, r.line,
                         "unknown or unsupported request '" + r.name + "' ignored");
                continue;
            }
            if (r.name == "ReadArchive") {
                readArchive(r, depth);
                continue;
            }
            requestLine_ = r.line;
            (this->*(h->second))(r);
        }
    }

    // Arguments run up to the next request. Unknown requests are skipped tolerantly: their
    // arguments may hold anything (e.g. the `-x` of a stray shell line).
    void collectArgs(RibLexer& lex, Request& r, bool tolerant) {
        while (true) {
            const Token& p = lex.peek();
            switch (p.type) {
                case TokenType::Request:
                case TokenType::End:
                    return;
                case TokenType::Number:
                    r.args.push_back({Value::Kind::Number, {p.number}, {}, p.line});
                    break;
                case TokenType::String:
                    r.args.push_back({Value::Kind::String, {}, {p.text}, p.line});
                    break;
                case TokenType::ArrayBegin: {
                    Token open = lex.next();
                    if (!collectArray(lex, r, open, tolerant)) return;
                    continue;
                }
                case TokenType::ArrayEnd:
                case TokenType::Other:
                    if (!tolerant)
                        fail(p.line, "unexpected " + describe(p) + " in the arguments of " + r.name);
                    break;
            }
            lex.next();
        }
    }

    // Returns false if a tolerant scan stopped at a request inside the array.
    bool collectArray(RibLexer& lex, Request& r, const Token& open, bool tolerant) {
        Value v{Value::Kind::NumberArray, {}, {}, open.line};
        bool hasNum = false, hasStr = false;
        while (true) {
            const Token& t = lex.peek();
            switch (t.type) {
                case TokenType::ArrayEnd:
                    lex.next();
                    if (hasStr) v.kind = Value::Kind::StringArray;
                    r.args.push_back(std::move(v));
                    return true;
                case TokenType::Number:
                    hasNum = true;
                    v.nums.push_back(t.number);
                    break;
                case TokenType::String:
                    hasStr = true;
                    v.strs.push_back(t.text);
                    break;
                case TokenType::Request:
                    if (tolerant) return false;
                    fail(t.line, "expected ']' to close the array opened on line " +
                                     std::to_string(open.line) + ", found " + describe(t));
                case TokenType::End:
                    if (tolerant) return false;
                    fail(t.line, "end of file inside the array opened on line " + std::to_string(open.line));
                case TokenType::ArrayBegin:
                case TokenType::Other:
                    if (!tolerant) fail(t.line, "unexpected " + describe(t) + " inside an array");
                    break;
            }
            if (hasNum && hasStr && !tolerant) fail(t.line, "array mixes numbers and strings");
            lex.next();
        }
    }

    // ---- argument access ---------------------------------------------------------------------
    void argCount(const Request& r, size_t n, const char* usage) const {
        if (r.args.size() != n)
            fail(r.line, r.name + " expects " + std::to_string(n) + " arguments (" + usage + "), got " +
                             std::to_string(r.args.size()));
    }
    void minArgs(const Request& r, size_t n, const char* usage) const {
        if (r.args.size() < n)
            fail(r.line, r.name + " expects at least " + std::to_string(n) + " arguments (" + usage +
                             "), got " + std::to_string(r.args.size()));
    }
    double number(const Request& r, size_t i) const {
        const Value& v = r.args.at(i);
        if (!v.numeric() || v.nums.size() != 1)
            fail(v.line,
                 r.name + ": argument " + std::to_string(i + 1) + " must be a number, found " + describe(v));
        return v.nums[0];
    }
    int integer(const Request& r, size_t i) const {
        double d = number(r, i);
        if (d != std::floor(d) || std::fabs(d) > 1e9)
            fail(r.args[i].line, r.name + ": argument " + std::to_string(i + 1) + " must be an integer");
        return static_cast<int>(d);
    }
    const std::string& string(const Request& r, size_t i) const {
        const Value& v = r.args.at(i);
        if (v.numeric() || v.strs.size() != 1)
            fail(v.line,
                 r.name + ": argument " + std::to_string(i + 1) + " must be a string, found " + describe(v));
        return v.strs[0];
    }
    // Exactly n numbers, given either one by one or as one array (both are valid RIB).
    std::vector<double> numbers(const Request& r, size_t n, const char* usage) const {
        std::vector<double> out;
        for (const Value& v : r.args) {
            if (!v.numeric()) fail(v.line, r.name + " expects numbers (" + usage + "), found " + describe(v));
            out.insert(out.end(), v.nums.begin(), v.nums.end());
        }
        if (out.size() != n)
            fail(r.line, r.name + " expects " + std::to_string(n) + " numbers (" + usage + "), got " +
                             std::to_string(out.size()));
        return out;
    }

    std::optional<Decl> lookupDecl(const std::string& name) const {
        auto it = declared_.find(name);
        if (it == declared_.end()) return std::nullopt;
        return it->second;
    }

    // Token-value pairs from argument `start` on. Values of declared parameters are checked
    // against their type: per element `counts(class)` elements of decl.components() numbers.
    std::vector<Param> params(const Request& r, size_t start, const ClassCounts& counts = nullptr) const {
        std::vector<Param> out;
        for (size_t i = start; i < r.args.size(); i += 2) {
            const Value& nameV = r.args[i];
            if (nameV.kind != Value::Kind::String)
                fail(nameV.line, r.name + ": expected a parameter name, found " + describe(nameV));
            Param p;
            p.line = nameV.line;
            const std::string& full = nameV.strs[0];
            size_t sp = full.find_last_of(" \t");
            if (sp != std::string::npos) {  // inline declaration, e.g. "uniform float Kd"
                p.name = full.substr(sp + 1);
                p.decl = parseDecl(full.substr(0, sp));
                if (!p.decl || p.name.empty())
                    fail(p.line, r.name + ": invalid inline declaration \"" + full + "\"");
            } else {
                p.name = full;
                p.decl = lookupDecl(full);
            }
            if (i + 1 >= r.args.size())
                fail(p.line, r.name + ": missing value for parameter \"" + p.name + "\"");
            p.value = &r.args[i + 1];
            if (p.decl) {
                const Decl& d = *p.decl;
                bool wantString = d.type == "string";
                bool emptyArray = p.value->isArray() && p.value->size() == 0;
                if (!emptyArray && wantString == p.value->numeric())
                    fail(p.value->line, r.name + ": parameter \"" + p.name + "\" (" + d.type + ") needs " +
                                            (wantString ? "strings" : "numbers") + ", found " +
                                            describe(*p.value));
                size_t elems = counts ? counts(d.cls) : 1;
                size_t want = elems * static_cast<size_t>(d.components() * d.arraySize);
                if (p.value->size() != want)
                    fail(p.value->line, r.name + ": parameter \"" + p.name + "\" needs " +
                                            std::to_string(want) + " values (" + std::to_string(elems) +
                                            " x " + d.cls + " " + d.type +
                                            (d.arraySize > 1 ? "[" + std::to_string(d.arraySize) + "]" : "") +
                                            "), got " + std::to_string(p.value->size()));
            }
            out.push_back(std::move(p));
        }
        return out;
    }

    // Typed reads of a parameter whose declaration is unknown or was checked by params().
    float paramFloat(const Request& r, const Param& p) const {
        if (!p.value->numeric() || p.value->nums.size() != 1)
            fail(p.line,
                 r.name + ": parameter \"" + p.name + "\" needs 1 number, found " + describe(*p.value));
        return float(p.value->nums[0]);
    }
    Vec3 paramTriple(const Request& r, const Param& p) const {
        if (!p.value->numeric() || p.value->nums.size() != 3)
            fail(p.line,
                 r.name + ": parameter \"" + p.name + "\" needs 3 numbers, found " + describe(*p.value));
        return {float(p.value->nums[0]), float(p.value->nums[1]), float(p.value->nums[2])};
    }
    std::string paramString(const Request& r, const Param& p) const {
        if (p.value->numeric() || p.value->strs.size() != 1)
            fail(p.line,
                 r.name + ": parameter \"" + p.name + "\" needs 1 string, found " + describe(*p.value));
        return p.value->strs[0];
    }
    void ignoredParam(const Param& p, const std::string& what) {
        warnOnce("param:" + what + ":" + p.name, p.line,
                 what + ": parameter \"" + p.name + "\" is " + (p.decl ? "not supported" : "not declared") +
                     " and is ignored");
    }

    bool inWorld() const {
        for (const Saved& s : stack_)
            if (s.block == Block::World) return true;
        return false;
    }

    // ---- structure (RI spec 3.2, sec. 4.1 and 4.3.2) ------------------------------------------
    void push(Block b, const Request& r) { stack_.push_back({b, lex_->file(), r.line, ctm_, attrs_}); }
    Saved pop(Block b, const Request& r) {
        if (stack_.empty()) fail(r.line, r.name + " without a matching " + blockName(b));
        const Saved& top = stack_.back();
        if (top.block != b)
            fail(r.line, r.name + " does not match " + blockName(top.block) + " at " + top.file + ":" +
                             std::to_string(top.line));
        Saved s = top;
        stack_.pop_back();
        return s;
    }

    void version(const Request&) {}
    void frameBegin(const Request& r) {
        if (framesSeen_ > 0) {
            warnOnce("frames", r.line, "more than one frame: only the first frame is loaded");
            skipUntil_ = "FrameEnd";
            return;
        }
        ++framesSeen_;
        push(Block::Frame, r);
    }
    void frameEnd(const Request& r) {
        Saved s = pop(Block::Frame, r);
        ctm_ = s.ctm;
        attrs_ = s.attrs;
    }
    void worldBegin(const Request& r) {
        if (worldsSeen_ > 0) {
            warnOnce("worlds", r.line, "more than one world block: only the first is loaded");
            skipUntil_ = "WorldEnd";
            return;
        }
        ++worldsSeen_;
        // RI spec 4.1.1: the CTM at WorldBegin is the world-to-camera transformation.
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j)
                if (!std::isfinite(ctm_.m[i][j]))
                    fail(r.line, "WorldBegin: the camera transformation is not finite (overflow)");
        scene_.camera.cameraFromWorld = ctm_;
        named_["camera"] = ctm_.inverse();
        push(Block::World, r);
        ctm_ = Mat4::identity();
        named_["world"] = ctm_;
    }
    void worldEnd(const Request& r) {
        Saved s = pop(Block::World, r);
        ctm_ = s.ctm;
        attrs_ = s.attrs;
    }
    void attributeBegin(const Request& r) { push(Block::Attribute, r); }
    void attributeEnd(const Request& r) {
        Saved s = pop(Block::Attribute, r);
        ctm_ = s.ctm;
        attrs_ = s.attrs;
    }
    void transformBegin(const Request& r) { push(Block::Transform, r); }
    void transformEnd(const Request& r) { ctm_ = pop(Block::Transform, r).ctm; }

    // ---- options (RI spec 3.2, sec. 4.1) --------------------------------------------------------
    void format(const Request& r) {
        auto v = numbers(r, 3, "xresolution yresolution pixelaspectratio");
        if (v[0] < 1 || v[1] < 1 || v[0] != std::floor(v[0]) || v[1] != std::floor(v[1]) || !(v[2] > 0))
            fail(r.line,
                 "Format: the resolution must be positive integers and the pixel aspect ratio positive");
        if (v[0] > kMaxImageSize || v[1] > kMaxImageSize) {
            char res[64];
            std::snprintf(res, sizeof res, "%.15gx%.15g", v[0], v[1]);
            fail(r.line, std::string("Format: resolution ") + res + " exceeds the limit of " +
                             std::to_string(kMaxImageSize) + " pixels per axis");
        }
        scene_.camera.width = int(v[0]);
        scene_.camera.height = int(v[1]);
        scene_.camera.pixelAspect = float(v[2]);
    }
    void frameAspectRatio(const Request& r) {
        double a = numbers(r, 1, "aspect")[0];
        if (!(a > 0)) fail(r.line, "FrameAspectRatio must be positive");
        scene_.camera.frameAspect = float(a);
    }
    void screenWindow(const Request& r) {
        auto v = numbers(r, 4, "left right bottom top");
        if (v[0] == v[1] || v[2] == v[3]) fail(r.line, "ScreenWindow has zero width or height");
        for (int i = 0; i < 4; ++i) scene_.camera.screenWindow[i] = float(v[i]);
        scene_.camera.hasScreenWindow = true;
    }
    void clipping(const Request& r) {
        auto v = numbers(r, 2, "near far");
        if (!(v[0] > 0) || !(v[1] > v[0])) fail(r.line, "Clipping needs 0 < near < far");
        scene_.camera.nearClip = float(v[0]);
        scene_.camera.farClip = float(std::min(v[1], 1e30));
    }
    void projection(const Request& r) {
        minArgs(r, 1, "name ...parameterlist...");
        const std::string& name = string(r, 0);
        auto ps = params(r, 1);
        if (name == "perspective") {
            scene_.camera.perspective = true;
            for (const Param& p : ps) {
                if (p.name != "fov") {
                    ignoredParam(p, "Projection");
                    continue;
                }
                float fov = paramFloat(r, p);
                if (!(fov > 0 && fov < 180)) fail(p.line, "Projection: fov must be in (0, 180) degrees");
                scene_.camera.fovDegrees = fov;
            }
        } else if (name == "orthographic") {
            scene_.camera.perspective = false;
        } else {
            warnOnce("projection:" + name, r.line, "projection \"" + name + "\" is not supported; ignored");
            return;
        }
        // RI spec 4.1.1: transformations before Projection define screen space, and the CTM is reset.
        bool identity = true;
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j) identity &= ctm_.m[i][j] == (i == j ? 1.0 : 0.0);
        if (!identity) warnAt(r.line, "transformations before Projection are ignored");
        ctm_ = Mat4::identity();
    }
    void pixelSamples(const Request& r) {
        auto v = numbers(r, 2, "xsamples ysamples");
        if (!(v[0] > 0 && v[1] > 0)) fail(r.line, "PixelSamples must be positive");
        if (std::max(1.0, std::round(v[0])) * std::max(1.0, std::round(v[1])) > kMaxPixelSamples)
            fail(r.line, "PixelSamples: more than " + std::to_string(kMaxPixelSamples) + " samples per pixel");
        scene_.image.pixelSamplesX = std::max(1, int(std::lround(v[0])));
        scene_.image.pixelSamplesY = std::max(1, int(std::lround(v[1])));
    }
    void pixelFilter(const Request& r) {
        argCount(r, 3, "filter xwidth ywidth");
        const std::string& name = string(r, 0);
        double xw = number(r, 1), yw = number(r, 2);
        if (!(xw > 0 && yw > 0)) fail(r.line, "PixelFilter widths must be positive");
        static const std::map<std::string, FilterType> filters = {{"box", FilterType::Box},
                                                                  {"triangle", FilterType::Triangle},
                                                                  {"gaussian", FilterType::Gaussian},
                                                                  {"catmull-rom", FilterType::CatmullRom}};
        auto it = filters.find(name);
        if (it == filters.end()) {
            warnOnce("filter:" + name, r.line,
                     "pixel filter \"" + name + "\" is not supported; keeping the previous one");
            return;
        }
        scene_.image.filter = it->second;
        scene_.image.filterWidthX = float(xw);
        scene_.image.filterWidthY = float(yw);
    }
    void exposure(const Request& r) {
        auto v = numbers(r, 2, "gain gamma");
        if (!(v[0] > 0 && v[1] > 0)) fail(r.line, "Exposure gain and gamma must be positive");
        scene_.image.exposureGain = float(v[0]);
        scene_.image.exposureGamma = float(v[1]);
    }
    void display(const Request& r) {
        minArgs(r, 3, "name type mode ...parameterlist...");
        const std::string& name = string(r, 0);
        string(r, 1);
        string(r, 2);
        params(r, 3);  // syntax check only; display parameters do not affect the scene
        // RI spec 4.1.4: a name starting with '+' adds a secondary display; we keep the primary.
        if (!name.empty() && name[0] == '+') {
            warnOnce("display+", r.line, "secondary displays ('+" + name.substr(1) + "') are ignored");
            return;
        }
        scene_.image.displayName = name;
    }
    void option(const Request& r) {
        minArgs(r, 1, "name ...parameterlist...");
        const std::string& name = string(r, 0);
        params(r, 1);
        if (name == "searchpath") return;  // shaders are built in; search paths are meaningless here
        warnOnce("option:" + name, r.line, "Option \"" + name + "\" is not supported; ignored");
    }

    // ---- attributes (RI spec 3.2, sec. 4.2) -----------------------------------------------------
    void attribute(const Request& r) {
        minArgs(r, 1, "name ...parameterlist...");
        const std::string& name = string(r, 0);
        auto ps = params(r, 1);
        if (name == "identifier") {
            for (const Param& p : ps) {
                if (p.name == "name")
                    attrs_.identifier = paramString(r, p);
                else
                    ignoredParam(p, "Attribute \"identifier\"");
            }
            return;
        }
        warnOnce("attribute:" + name, r.line, "Attribute \"" + name + "\" is not supported; ignored");
    }
    void color(const Request& r) {
        auto v = numbers(r, 3, "r g b");
        attrs_.surface.Cs = {float(v[0]), float(v[1]), float(v[2])};
    }
    void opacity(const Request& r) {
        auto v = numbers(r, 3, "r g b");
        attrs_.surface.Os = {float(v[0]), float(v[1]), float(v[2])};
        if (v[0] != 1 || v[1] != 1 || v[2] != 1)
            warnOnce("opacity", r.line, "only opaque surfaces are rendered; Opacity is ignored");
    }
    void shadingRate(const Request& r) {
        double s = numbers(r, 1, "size")[0];
        if (!(s > 0)) fail(r.line, "ShadingRate must be positive");
        attrs_.shadingRate = float(s);
    }
    void sides(const Request& r) {
        argCount(r, 1, "1 or 2");
        int s = integer(r, 0);
        if (s != 1 && s != 2) fail(r.line, "Sides must be 1 or 2");
        attrs_.twoSided = s == 2;
    }
    void orientation(const Request& r) {
        argCount(r, 1, "\"lh\", \"rh\", \"inside\" or \"outside\"");
        const std::string& o = string(r, 0);
        if (o == "lh" || o == "outside")
            attrs_.rightHanded = false;
        else if (o == "rh" || o == "inside")
            attrs_.rightHanded = true;
        else
            fail(r.args[0].line,
                 "Orientation must be \"lh\", \"rh\", \"inside\" or \"outside\", found \"" + o + "\"");
    }
    void reverseOrientation(const Request& r) {
        argCount(r, 0, "no arguments");
        attrs_.rightHanded = !attrs_.rightHanded;
    }
    void surface(const Request& r) {
        minArgs(r, 1, "name ...parameterlist...");
        const std::string& name = string(r, 0);
        auto ps = params(r, 1);
        static const std::map<std::string, MaterialType> shaders = {
            {"matte", MaterialType::Matte},   {"plastic", MaterialType::Plastic},
            {"metal", MaterialType::Metal},   {"constant", MaterialType::Constant},
            {"mirror", MaterialType::Mirror}, {"glass", MaterialType::Glass}};
        auto it = shaders.find(name);
        if (it == shaders.end()) {
            warnOnce("surface:" + name, r.line,
                     "surface shader \"" + name + "\" is not supported; keeping the previous surface");
            return;
        }
        // RI spec appendix A: the standard shaders' parameters, defaults from defaultMaterial().
        Material m = defaultMaterial(it->second);
        m.Cs = attrs_.surface.Cs;
        m.Os = attrs_.surface.Os;
        for (const Param& p : ps) {
            if (p.name == "Ka")
                m.Ka = paramFloat(r, p);
            else if (p.name == "Kd")
                m.Kd = paramFloat(r, p);
            else if (p.name == "Ks")
                m.Ks = paramFloat(r, p);
            else if (p.name == "roughness")
                m.roughness = paramFloat(r, p);
            else if (p.name == "Kr")
                m.Kr = paramFloat(r, p);
            else if (p.name == "Kt")
                m.Kt = paramFloat(r, p);
            else if (p.name == "eta")
                m.eta = paramFloat(r, p);
            else if (p.name == "specularcolor")
                m.specularColor = paramTriple(r, p);
            else
                ignoredParam(p, "Surface \"" + name + "\"");
        }
        attrs_.surface = m;
    }
    void lightSource(const Request& r) {
        minArgs(r, 2, "shadername handle ...parameterlist...");
        const std::string& name = string(r, 0);
        if (r.args[1].isArray())
            fail(r.args[1].line, "LightSource: the light handle must be a number or a string");
        auto ps = params(r, 2);
        if (!inWorld()) {
            warnAt(r.line, "LightSource before WorldBegin is ignored");
            return;
        }
        Light light;
        if (name == "ambientlight")
            light.type = LightType::Ambient;
        else if (name == "distantlight")
            light.type = LightType::Distant;
        else if (name == "pointlight")
            light.type = LightType::Point;
        else {
            warnOnce("light:" + name, r.line,
                     "light shader \"" + name + "\" is not supported; light ignored");
            return;
        }
        // RI spec appendix A defaults: intensity 1, lightcolor 1, from (0,0,0), to (0,0,1).
        float intensity = 1;
        Color lightColor{1, 1, 1};
        Vec3 from{0, 0, 0}, to{0, 0, 1};
        for (const Param& p : ps) {
            if (p.name == "intensity")
                intensity = paramFloat(r, p);
            else if (p.name == "lightcolor")
                lightColor = paramTriple(r, p);
            else if (p.name == "from" && light.type != LightType::Ambient)
                from = paramTriple(r, p);
            else if (p.name == "to" && light.type == LightType::Distant)
                to = paramTriple(r, p);
            else
                ignoredParam(p, "LightSource \"" + name + "\"");
        }
        light.color = lightColor * intensity;
        // The light's "shader space" is the current object space.
        light.from = ctm_.point(from);
        light.to = ctm_.point(to);
        if (!isFinite(light.color) || !isFinite(light.from) || !isFinite(light.to))
            fail(r.line, "LightSource: intensity, colour or position out of range (overflows single precision)");
        scene_.lights.push_back(light);
    }
    void illuminate(const Request& r) {
        argCount(r, 2, "light onoff");
        integer(r, 1);
        warnOnce("illuminate", r.line, "Illuminate is ignored: every declared light stays on");
    }
    void basis(const Request& r) {
        argCount(r, 4, "ubasis ustep vbasis vstep");
        attrs_.uBasis = basisArg(r, 0);
        attrs_.vBasis = basisArg(r, 2);
    }
    // A basis is a name or 16 numbers. RIB writes the matrix row by row, the layout of Basis::m
    // (RiBSplineBasis in ri.h reads {-1/6, 3/6, -3/6, 1/6, ...} like bsplineBasis()), so no transpose.
    Basis basisArg(const Request& r, size_t i) const {
        const Value& v = r.args[i];
        Basis b{};
        if (v.kind == Value::Kind::String || v.kind == Value::Kind::StringArray) {
            const std::string& name = string(r, i);
            auto named = basisByName(name);
            if (!named) fail(v.line, "Basis: unknown basis \"" + name + "\"");
            b = *named;
        } else if (v.kind == Value::Kind::NumberArray && v.nums.size() == 16) {
            for (int k = 0; k < 16; ++k) b.m[k / 4][k % 4] = v.nums[k];
        } else {
            fail(v.line, "Basis: a basis must be a name or an array of 16 numbers, found " + describe(v));
        }
        int step = integer(r, i + 1);
        if (step < 1) fail(r.args[i + 1].line, "Basis: step must be at least 1");
        b.step = step;
        return b;
    }
    void declare(const Request& r) {
        argCount(r, 2, "name declaration");
        const std::string& name = string(r, 0);
        const std::string& text = string(r, 1);
        auto d = parseDecl(text);
        if (!d) fail(r.args[1].line, "Declare: invalid declaration \"" + text + "\"");
        declared_[name] = *d;
    }

    // ---- transformations (RI spec 3.2, sec. 4.3): each concatenates on the object side ----------
    void identity(const Request& r) {
        argCount(r, 0, "no arguments");
        ctm_ = Mat4::identity();
    }
    Mat4 matrixArg(const Request& r) const {
        auto v = numbers(r, 16, "a 4x4 matrix");
        return Mat4::fromRib(v.data());
    }
    // Inside the world the CTM maps object to world space, so Transform is relative to the world.
    void transform(const Request& r) { ctm_ = matrixArg(r); }
    void concatTransform(const Request& r) { ctm_ = ctm_ * matrixArg(r); }
    void translate(const Request& r) {
        auto v = numbers(r, 3, "dx dy dz");
        ctm_ = ctm_ * Mat4::translate(v[0], v[1], v[2]);
    }
    void rotate(const Request& r) {
        auto v = numbers(r, 4, "angle dx dy dz");
        if (v[1] == 0 && v[2] == 0 && v[3] == 0) fail(r.line, "Rotate: the axis is the zero vector");
        ctm_ = ctm_ * Mat4::rotate(v[0], v[1], v[2], v[3]);
    }
    void scale(const Request& r) {
        auto v = numbers(r, 3, "sx sy sz");
        ctm_ = ctm_ * Mat4::scale(v[0], v[1], v[2]);
    }
    void coordinateSystem(const Request& r) {
        argCount(r, 1, "name");
        named_[string(r, 0)] = ctm_;
    }
    void coordSysTransform(const Request& r) {
        argCount(r, 1, "name");
        const std::string& name = string(r, 0);
        auto it = named_.find(name);
        if (it == named_.end()) fail(r.line, "CoordSysTransform: unknown coordinate system \"" + name + "\"");
        ctm_ = it->second;
    }

    // ---- geometry (RI spec 3.2, sec. 5.2) -------------------------------------------------------
    uint32_t materialIndex() {
        for (size_t i = 0; i < scene_.materials.size(); ++i)
            if (sameMaterial(scene_.materials[i], attrs_.surface)) return uint32_t(i);
        scene_.materials.push_back(attrs_.surface);
        return uint32_t(scene_.materials.size() - 1);
    }

    // Attributes shared by all patches of one primitive request (one object id per request).
    PatchAttributes primitiveAttributes() {
        PatchAttributes a;
        a.material = materialIndex();
        a.object = scene_.objectCount++;
        a.shadingRate = attrs_.shadingRate;
        a.twoSided = attrs_.twoSided;
        // RI spec 4.2.4: the surface's outside depends on the orientation attribute and on the
        // handedness of the current (object-to-camera) transformation.
        bool mirrored = (scene_.camera.cameraFromWorld * ctm_).det3() < 0;
        a.flipNormal = attrs_.rightHanded != mirrored;
        return a;
    }

    void requireWorld(const Request& r) const {
        if (!inWorld()) fail(r.line, r.name + " outside WorldBegin/WorldEnd");
    }

    // Vertex positions from "P" (or "Pw" with w == 1); nullopt if the primitive must be skipped.
    std::optional<std::vector<Vec3>> positions(const Request& r, const std::vector<Param>& ps, size_t n,
                                               const std::string& what) {
        std::optional<std::vector<Vec3>> out;
        for (const Param& p : ps) {
            const std::vector<double>& v = p.value->nums;
            if (p.name == "P") {
                if (!p.value->numeric() || v.size() != 3 * n)
                    fail(p.line, what + ": \"P\" needs " + std::to_string(3 * n) + " numbers (" +
                                     std::to_string(n) + " points), got " + std::to_string(p.value->size()));
                out.emplace();
                for (size_t i = 0; i < n; ++i)
                    out->push_back({float(v[3 * i]), float(v[3 * i + 1]), float(v[3 * i + 2])});
            } else if (p.name == "Pw") {
                if (!p.value->numeric() || v.size() != 4 * n)
                    fail(p.line, what + ": \"Pw\" needs " + std::to_string(4 * n) + " numbers (" +
                                     std::to_string(n) + " homogeneous points), got " +
                                     std::to_string(p.value->size()));
                out.emplace();
                for (size_t i = 0; i < n; ++i) {
                    if (std::fabs(v[4 * i + 3] - 1.0) > 1e-9)
                        fail(p.line, what + ": rational patches are not supported (\"Pw\" with w != 1)");
                    out->push_back({float(v[4 * i]), float(v[4 * i + 1]), float(v[4 * i + 2])});
                }
            } else if (p.name == "Pz") {
                warnOnce("Pz", p.line, what + ": \"Pz\" height fields are not supported; primitive skipped");
                return std::nullopt;
            } else {
                ignoredParam(p, r.name);
            }
        }
        if (!out) fail(r.line, what + ": missing the position parameter \"P\"");
        return out;
    }

    void addPatch(const Vec3 g[16], bool bicubic, const PatchAttributes& a) {
        BezierPatch b;
        if (!bicubic) {
            // Degree elevation of the bilinear patch: its bicubic Bezier control net samples the
            // bilinear map at thirds, which is exact (linear precision of Bernstein polynomials).
            for (int v = 0; v < 4; ++v)
                for (int u = 0; u < 4; ++u) {
                    float s = u / 3.f, t = v / 3.f;
                    Vec3 lo = u == 3 ? g[1] : (u == 0 ? g[0] : lerp(g[0], g[1], s));
                    Vec3 hi = u == 3 ? g[3] : (u == 0 ? g[2] : lerp(g[2], g[3], s));
                    b.at(u, v) = v == 0 ? lo : (v == 3 ? hi : lerp(lo, hi, t));
                }
        } else if (isBezier(attrs_.uBasis) && isBezier(attrs_.vBasis)) {
            for (int k = 0; k < 16; ++k) b.cp[k] = g[k];
        } else {
            b = toBezier(g, attrs_.uBasis, attrs_.vBasis);
        }
        // Bezier patches are affinely invariant: transforming the control points transforms the surface.
        for (Vec3& c : b.cp) c = ctm_.point(c);
        checkFinite(b);
        scene_.patches.push_back(b);
        scene_.attributes.push_back(a);
    }

    bool patchType(const Request& r, const std::string& type) const {
        if (type == "bicubic") return true;
        if (type != "bilinear")
            fail(r.args[0].line,
                 r.name + ": type must be \"bicubic\" or \"bilinear\", found \"" + type + "\"");
        return false;
    }

    void patch(const Request& r) {
        minArgs(r, 1, "type ...parameterlist...");
        bool bicubic = patchType(r, string(r, 0));
        size_t nv = bicubic ? 16 : 4;
        auto ps = params(r, 1, [&](const std::string& cls) -> size_t {
            if (cls == "vertex" || cls == "facevertex") return nv;
            if (cls == "varying" || cls == "facevarying") return 4;
            return 1;
        });
        requireWorld(r);
        std::string what = "Patch \"" + string(r, 0) + "\"";
        auto pts = positions(r, ps, nv, what);
        if (!pts) return;
        Vec3 g[16];
        if (bicubic) {
            for (int k = 0; k < 16; ++k) g[k] = (*pts)[k];
        } else {
            for (int k = 0; k < 4; ++k) g[k] = (*pts)[k];
        }
        addPatch(g, bicubic, primitiveAttributes());
    }

    // Patches along one direction of a PatchMesh (RI spec 5.2: RiPatchMesh).
    int meshPatches(const Request& r, bool bicubic, int n, bool periodic, int step, const char* dir) const {
        if (!bicubic) {
            if (n < (periodic ? 1 : 2))
                fail(r.line, std::string("PatchMesh: n") + dir + " = " + std::to_string(n) + " is too small");
            return periodic ? n : n - 1;
        }
        if (periodic) {
            if (n < 1 || n % step != 0)
                fail(r.line, std::string("PatchMesh: periodic n") + dir + " = " + std::to_string(n) +
                                 " must be a positive multiple of the " + dir + "step " +
                                 std::to_string(step));
            return n / step;
        }
        if (n < 4 || (n - 4) % step != 0)
            fail(r.line, std::string("PatchMesh: nonperiodic n") + dir + " = " + std::to_string(n) +
                             " must be 4 + k * " + std::to_string(step) + " (the " + dir + "step)");
        return (n - 4) / step + 1;
    }
    bool wrapArg(const Request& r, size_t i) const {
        const std::string& w = string(r, i);
        if (w == "periodic") return true;
        if (w == "nonperiodic") return false;
        fail(r.args[i].line,
             "PatchMesh: wrap mode must be \"periodic\" or \"nonperiodic\", found \"" + w + "\"");
    }

    void patchMesh(const Request& r) {
        minArgs(r, 5, "type nu uwrap nv vwrap ...parameterlist...");
        bool bicubic = patchType(r, string(r, 0));
        int nu = integer(r, 1), nv = integer(r, 3);
        bool uper = wrapArg(r, 2), vper = wrapArg(r, 4);
        int ustep = bicubic ? attrs_.uBasis.step : 1, vstep = bicubic ? attrs_.vBasis.step : 1;
        int npu = meshPatches(r, bicubic, nu, uper, ustep, "u");
        int npv = meshPatches(r, bicubic, nv, vper, vstep, "v");
        size_t nverts = size_t(nu) * size_t(nv);
        // Varying values sit at the patch corners: one per patch boundary in each direction.
        size_t nvaryings = size_t(npu + (uper ? 0 : 1)) * size_t(npv + (vper ? 0 : 1));
        auto ps = params(r, 5, [&](const std::string& cls) -> size_t {
            if (cls == "vertex" || cls == "facevertex") return nverts;
            if (cls == "varying" || cls == "facevarying") return nvaryings;
            if (cls == "uniform") return size_t(npu) * size_t(npv);
            return 1;
        });
        requireWorld(r);
        auto pts = positions(r, ps, nverts, "PatchMesh \"" + string(r, 0) + "\"");
        if (!pts) return;
        PatchAttributes a = primitiveAttributes();
        int order = bicubic ? 4 : 2;
        for (int pv = 0; pv < npv; ++pv)
            for (int pu = 0; pu < npu; ++pu) {
                Vec3 g[16];
                for (int j = 0; j < order; ++j)
                    for (int i = 0; i < order; ++i) {
                        int u = (pu * ustep + i) % nu, v = (pv * vstep + j) % nv;  // periodic meshes wrap
                        g[j * order + i] = (*pts)[size_t(v) * nu + u];
                    }
                addPatch(g, bicubic, a);
            }
    }

    // Huge coordinates or transformations can overflow single precision: reject them rather than render NaNs.
    void checkFinite(const BezierPatch& b) const {
        for (const Vec3& c : b.cp)
            if (!std::isfinite(c.x) || !std::isfinite(c.y) || !std::isfinite(c.z))
                fail(requestLine_, "control point out of range after transformation (overflows single precision)");
    }

    // Appends a patch that is already in Bezier form (object space), ignoring the current Basis.
    void addBezier(const BezierPatch& patch, const PatchAttributes& a) {
        BezierPatch b = patch;
        for (Vec3& c : b.cp) c = ctm_.point(c);
        checkFinite(b);
        scene_.patches.push_back(b);
        scene_.attributes.push_back(a);
    }

    std::vector<double> numberArray(const Request& r, size_t i, const char* what) const {
        const Value& v = r.args.at(i);
        if (!v.numeric())
            fail(v.line, r.name + ": " + what + " must be an array of numbers, found " + describe(v));
        return v.nums;
    }
    std::vector<int> intArray(const Request& r, size_t i, const char* what) const {
        std::vector<int> out;
        for (double d : numberArray(r, i, what)) {
            if (d != std::floor(d) || std::fabs(d) > 2e9)
                fail(r.args[i].line, r.name + ": " + what + " must hold integers, found " + std::to_string(d));
            out.push_back(int(d));
        }
        return out;
    }

    // RiNuPatch (RI spec 3.2, sec. 5.3): non-rational NURBS, converted exactly to Bezier patches.
    void nuPatch(const Request& r) {
        minArgs(r, 10, "nu uorder uknot umin umax nv vorder vknot vmin vmax ...parameterlist...");
        NurbsSurface s;
        s.nu = integer(r, 0);
        s.uorder = integer(r, 1);
        s.uknot = numberArray(r, 2, "uknot");
        s.umin = number(r, 3);
        s.umax = number(r, 4);
        s.nv = integer(r, 5);
        s.vorder = integer(r, 6);
        s.vknot = numberArray(r, 7, "vknot");
        s.vmin = number(r, 8);
        s.vmax = number(r, 9);
        if (s.nu < 1 || s.nv < 1 || s.nu > 1000000 || s.nv > 1000000)
            fail(r.line, "NuPatch: nu and nv must be positive");
        size_t nverts = size_t(s.nu) * size_t(s.nv);
        size_t segu = size_t(std::max(1, s.nu - s.uorder + 1)), segv = size_t(std::max(1, s.nv - s.vorder + 1));
        auto ps = params(r, 10, [&](const std::string& cls) -> size_t {
            if (cls == "vertex") return nverts;
            if (cls == "varying" || cls == "facevarying" || cls == "facevertex") return (segu + 1) * (segv + 1);
            if (cls == "uniform") return segu * segv;
            return 1;
        });
        requireWorld(r);
        // Check the knots before the points, so that a bad knot vector is reported as such.
        try {
            NurbsSurface k = s;
            // Placeholders for the points "P"/"Pw" hold (params() checked their size): without them,
            // nu * nv alone could ask for terabytes.
            size_t given = 0;
            for (const Param& p : ps)
                if (p.name == "P" || p.name == "Pw") given = p.value->size() / (p.name == "P" ? 3 : 4);
            k.cp.assign(std::min(given, nverts), Vec3{});
            validateNurbs(k);
        } catch (const NurbsError& e) {
            fail(r.line, std::string("NuPatch: ") + e.what());
        }
        for (const Param& p : ps)
            if (p.name == "Pw" && p.value->numeric() && p.value->nums.size() == 4 * nverts)
                for (size_t i = 0; i < nverts; ++i)
                    if (std::fabs(p.value->nums[4 * i + 3] - 1.0) > 1e-9)
                        fail(p.line,
                             "NuPatch: rational NURBS (\"Pw\" with w != 1) are not supported; only non-rational "
                             "surfaces (all weights 1) convert exactly to bicubic Bezier patches");
        auto pts = positions(r, ps, nverts, "NuPatch");
        if (!pts) return;
        s.cp = std::move(*pts);
        std::vector<BezierPatch> patches;
        try {
            patches = nurbsToBezier(s);
        } catch (const NurbsError& e) {
            fail(r.line, std::string("NuPatch: ") + e.what());
        }
        PatchAttributes a = primitiveAttributes();
        for (const BezierPatch& b : patches) addBezier(b, a);
    }

    // RiSubdivisionMesh (RI spec 3.2, sec. 5.6): Catmull-Clark surfaces, converted by subdivToBezier().
    void subdivisionMesh(const Request& r) {
        minArgs(r, 3, "scheme nvertices vertices [tags nargs intargs floatargs] ...parameterlist...");
        const std::string& scheme = string(r, 0);
        std::vector<int> nverts = intArray(r, 1, "nvertices");
        std::vector<int> verts = intArray(r, 2, "vertices");
        if (!r.args[1].isArray() || !r.args[2].isArray())
            fail(r.line, "SubdivisionMesh: nvertices and vertices must be arrays");
        size_t start = 3;
        SubdivMesh mesh;
        mesh.boundary = BoundaryMode::None;  // RenderMan default without "interpolateboundary"
        size_t total = 0;
        for (size_t f = 0; f < nverts.size(); ++f) {
            if (nverts[f] < 3)
                fail(r.args[1].line, "SubdivisionMesh: face " + std::to_string(f) + " has " +
                                         std::to_string(nverts[f]) + " vertices; a face needs at least 3");
            total += size_t(nverts[f]);
        }
        if (nverts.empty()) fail(r.args[1].line, "SubdivisionMesh: no faces");
        if (total != verts.size())
            fail(r.args[2].line, "SubdivisionMesh: nvertices adds up to " + std::to_string(total) +
                                     " vertex indices, but vertices has " + std::to_string(verts.size()));
        int maxIndex = -1;
        for (int v : verts) {
            if (v < 0) fail(r.args[2].line, "SubdivisionMesh: negative vertex index " + std::to_string(v));
            maxIndex = std::max(maxIndex, v);
        }
        size_t npoints = size_t(maxIndex) + 1;
        struct Tag {
            std::string name;
            std::vector<int> ints;
            std::vector<double> floats;
            int line;
        };
        std::vector<Tag> tags;
        if (r.args.size() > 3 && r.args[3].isArray()) {
            if (r.args.size() < 7) fail(r.line, "SubdivisionMesh: tags need the arrays tags nargs intargs floatargs");
            const Value& tv = r.args[3];
            if (tv.numeric() && !tv.nums.empty())
                fail(tv.line, "SubdivisionMesh: tags must be an array of strings");
            std::vector<int> nargs = intArray(r, 4, "nargs");
            std::vector<int> ints = intArray(r, 5, "intargs");
            std::vector<double> floats = numberArray(r, 6, "floatargs");
            if (nargs.size() != 2 * tv.strs.size())
                fail(r.args[4].line, "SubdivisionMesh: nargs needs 2 numbers per tag (" +
                                         std::to_string(2 * tv.strs.size()) + "), got " +
                                         std::to_string(nargs.size()));
            size_t io = 0, fo = 0;
            for (size_t t = 0; t < tv.strs.size(); ++t) {
                int ni = nargs[2 * t], nf = nargs[2 * t + 1];
                if (ni < 0 || nf < 0 || io + size_t(ni) > ints.size() || fo + size_t(nf) > floats.size())
                    fail(r.args[4].line, "SubdivisionMesh: nargs for tag \"" + tv.strs[t] +
                                             "\" asks for more intargs/floatargs than given");
                Tag tag{tv.strs[t], {ints.begin() + long(io), ints.begin() + long(io + size_t(ni))},
                        {floats.begin() + long(fo), floats.begin() + long(fo + size_t(nf))}, tv.line};
                io += size_t(ni);
                fo += size_t(nf);
                tags.push_back(std::move(tag));
            }
            start = 7;
        }
        auto ps = params(r, start, [&](const std::string& cls) -> size_t {
            if (cls == "vertex" || cls == "varying") return npoints;
            if (cls == "facevarying" || cls == "facevertex") return verts.size();
            if (cls == "uniform") return nverts.size();
            return 1;
        });
        requireWorld(r);
        if (scheme != "catmull-clark") {
            warnOnce("subdiv:" + scheme, r.line,
                     "SubdivisionMesh scheme \"" + scheme + "\" is not supported (only \"catmull-clark\"); "
                     "primitive skipped");
            return;
        }
        auto pts = positions(r, ps, npoints, "SubdivisionMesh");
        if (!pts) return;
        mesh.points = std::move(*pts);
        mesh.faceSizes = std::move(nverts);
        mesh.faceVerts = std::move(verts);
        for (const Tag& t : tags) {
            auto checkVertex = [&](int v) {
                if (v < 0 || size_t(v) >= npoints)
                    fail(t.line, "SubdivisionMesh: tag \"" + t.name + "\" names vertex " + std::to_string(v) +
                                     ", outside 0.." + std::to_string(npoints - 1));
            };
            if (t.name == "interpolateboundary") {
                int mode = t.ints.empty() ? 1 : t.ints[0];
                mesh.boundary = mode == 0 ? BoundaryMode::None
                                          : (mode == 2 ? BoundaryMode::EdgesOnly : BoundaryMode::EdgesAndCorners);
            } else if (t.name == "crease") {
                if (t.ints.size() < 2 || t.floats.empty())
                    fail(t.line, "SubdivisionMesh: a \"crease\" tag needs at least 2 vertices and 1 sharpness");
                for (int v : t.ints) checkVertex(v);
                for (size_t i = 0; i + 1 < t.ints.size(); ++i)
                    mesh.creases.push_back({t.ints[i], t.ints[i + 1],
                                            float(t.floats.size() == 1 ? t.floats[0]
                                                                       : t.floats[std::min(i, t.floats.size() - 1)])});
            } else if (t.name == "corner") {
                if (t.floats.empty()) fail(t.line, "SubdivisionMesh: a \"corner\" tag needs a sharpness");
                for (size_t i = 0; i < t.ints.size(); ++i) {
                    checkVertex(t.ints[i]);
                    mesh.corners.push_back({t.ints[i], float(t.floats[std::min(i, t.floats.size() - 1)])});
                }
            } else if (t.name == "hole") {
                for (int f : t.ints) {
                    if (f < 0 || size_t(f) >= mesh.faceSizes.size())
                        fail(t.line, "SubdivisionMesh: \"hole\" names face " + std::to_string(f) +
                                         ", outside 0.." + std::to_string(mesh.faceSizes.size() - 1));
                    mesh.holes.push_back(f);
                }
            } else {
                warnOnce("subdivtag:" + t.name, t.line,
                         "SubdivisionMesh tag \"" + t.name + "\" is not supported; ignored");
            }
        }
        SubdivResult res;
        try {
            res = subdivToBezier(mesh);
        } catch (const SubdivError& e) {
            fail(r.line, std::string("SubdivisionMesh: ") + e.what());
        }
        for (const std::string& w : res.warnings) warnOnce("subdivwarn:" + w, r.line, "SubdivisionMesh: " + w);
        PatchAttributes a = primitiveAttributes();
        for (const BezierPatch& b : res.patches) addBezier(b, a);
    }

    // ---- ReadArchive (RI spec 3.2, sec. 8.1) -----------------------------------------------------
    void readArchive(const Request& r, int depth) {
        argCount(r, 1, "filename");
        const std::string& name = string(r, 0);
        namespace fs = std::filesystem;
        fs::path p(name);
        // Relative names are relative to the directory of the including file.
        if (p.is_relative()) p = fs::path(lex_->file()).parent_path() / p;
        std::string path = p.string();
        if (depth + 1 > kMaxArchiveDepth)
            fail(r.line, "ReadArchive nested more than " + std::to_string(kMaxArchiveDepth) +
                             " levels deep (recursive include?)");
        std::error_code ec;
        if (!fs::is_regular_file(p, ec)) fail(r.line, "ReadArchive: cannot open \"" + path + "\"");
        std::string text;
        try {
            text = readInputFile(path);
        } catch (const InputError&) {
            fail(r.line, "ReadArchive: cannot read \"" + path + "\"");
        }
        RibLexer lex(std::move(text), path);
        RibLexer* outer = lex_;
        lex_ = &lex;
        parse(lex, depth + 1);
        lex_ = outer;
    }

    void initTables() {
        handlers_ = {
            {"version", &RibReader::version},
            {"FrameBegin", &RibReader::frameBegin},
            {"FrameEnd", &RibReader::frameEnd},
            {"WorldBegin", &RibReader::worldBegin},
            {"WorldEnd", &RibReader::worldEnd},
            {"AttributeBegin", &RibReader::attributeBegin},
            {"AttributeEnd", &RibReader::attributeEnd},
            {"TransformBegin", &RibReader::transformBegin},
            {"TransformEnd", &RibReader::transformEnd},
            {"Format", &RibReader::format},
            {"FrameAspectRatio", &RibReader::frameAspectRatio},
            {"ScreenWindow", &RibReader::screenWindow},
            {"Clipping", &RibReader::clipping},
            {"Projection", &RibReader::projection},
            {"PixelSamples", &RibReader::pixelSamples},
            {"PixelFilter", &RibReader::pixelFilter},
            {"Exposure", &RibReader::exposure},
            {"Display", &RibReader::display},
            {"Option", &RibReader::option},
            {"Attribute", &RibReader::attribute},
            {"Color", &RibReader::color},
            {"Opacity", &RibReader::opacity},
            {"ShadingRate", &RibReader::shadingRate},
            {"Sides", &RibReader::sides},
            {"Orientation", &RibReader::orientation},
            {"ReverseOrientation", &RibReader::reverseOrientation},
            {"Surface", &RibReader::surface},
            {"LightSource", &RibReader::lightSource},
            {"Illuminate", &RibReader::illuminate},
            {"Basis", &RibReader::basis},
            {"Declare", &RibReader::declare},
            {"Identity", &RibReader::identity},
            {"Transform", &RibReader::transform},
            {"ConcatTransform", &RibReader::concatTransform},
            {"Translate", &RibReader::translate},
            {"Rotate", &RibReader::rotate},
            {"Scale", &RibReader::scale},
            {"CoordinateSystem", &RibReader::coordinateSystem},
            {"CoordSysTransform", &RibReader::coordSysTransform},
            {"Patch", &RibReader::patch},
            {"PatchMesh", &RibReader::patchMesh},
            {"NuPatch", &RibReader::nuPatch},
            {"SubdivisionMesh", &RibReader::subdivisionMesh},
            {"ReadArchive", nullptr},  // handled in parse(): it needs the include depth
        };
        // Predeclared variables and standard shader parameters (RI spec 3.2, sec. 3 and appendix A).
        const std::pair<const char*, const char*> builtin[] = {
            {"P", "vertex point"},          {"Pw", "vertex hpoint"},
            {"Pz", "vertex float"},         {"N", "varying normal"},
            {"Np", "uniform normal"},       {"Cs", "varying color"},
            {"Os", "varying color"},        {"s", "varying float"},
            {"t", "varying float"},         {"st", "varying float[2]"},
            {"Ka", "uniform float"},        {"Kd", "uniform float"},
            {"Ks", "uniform float"},        {"roughness", "uniform float"},
            {"Kr", "uniform float"},        {"Kt", "uniform float"},
            {"eta", "uniform float"},       {"specularcolor", "uniform color"},
            {"intensity", "uniform float"}, {"lightcolor", "uniform color"},
            {"from", "uniform point"},      {"to", "uniform point"},
            {"fov", "uniform float"},       {"name", "uniform string"},
        };
        for (auto [name, decl] : builtin) declared_[name] = *parseDecl(decl);
    }

    Scene& scene_;
    const WarningSink& warn_;
    RibLexer* lex_ = nullptr;
    std::unordered_map<std::string, Handler> handlers_;
    std::map<std::string, Decl> declared_;
    std::map<std::string, Mat4> named_;
    std::set<std::string> warned_;
    std::vector<Saved> stack_;
    Mat4 ctm_;
    Attributes attrs_;
    std::optional<std::string> skipUntil_;
    int framesSeen_ = 0, worldsSeen_ = 0;
    int requestLine_ = 0;  // line of the request being executed
};

}  // namespace

void readRib(const std::string& path, Scene& scene, const WarningSink& warn) {
    scene.sourcePath = path;
    RibReader reader(scene, warn);
    reader.run(path);
}

void readRibText(std::string text, const std::string& path, Scene& scene, const WarningSink& warn) {
    scene.sourcePath = path;
    RibReader reader(scene, warn);
    reader.runText(std::move(text), path);
}

}  // namespace tessera
