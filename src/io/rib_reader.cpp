// The RIB request dispatcher: reads requests and their arguments from the lexer, maps each request
// name to its handler through one table, and lets the handlers update the graphics state
// (rib_graphics_state.h), read parameter lists (rib_params.h, rib_shaders.h) and convert primitives
// (rib_geometry.h).
#include "io/rib_reader.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <optional>
#include <string_view>
#include <unordered_map>

#include "io/rib_geometry.h"
#include "io/rib_graphics_state.h"
#include "io/rib_lexer.h"
#include "io/rib_params.h"
#include "io/rib_request.h"
#include "io/rib_shaders.h"
#include "shading/registry.h"

namespace tessera {

namespace {

using namespace rib;

constexpr int kMaxArchiveDepth = 32;

class RibReader {
  public:
    RibReader(Scene& scene, const WarningSink& warn) : scene_(scene), diag_(warn) {
        declareShaderParams(decls_);
    }

    void run(const std::string& path) { runText(readInputFile(path), path); }
    void runText(std::string text, const std::string& path) {
        RibLexer lex(std::move(text), path);
        lex_ = &lex;
        diag_.setFile(path);
        if (lex.peek().type == TokenType::End) diag_.fail(lex.eofLine(), "empty file: no RIB requests");
        parse(lex);
        if (const GraphicsState::Saved* s = state_.innermostBlock())
            diag_.fail(lex.eofLine(), std::string("end of file inside ") + blockName(s->block) +
                                          " block opened at " + s->file + ":" + std::to_string(s->line));
        if (scene_.patches.empty())
            diag_.fail(
                lex.eofLine(),
                "no geometry: the file has no Patch, PatchMesh, NuPatch or SubdivisionMesh primitives");
        if (scene_.lights.empty())
            diag_.warn(lex.eofLine(), "no light sources: only \"constant\" surfaces will be visible");
    }

  private:
    using Handler = void (RibReader::*)(const Request&, const Arguments&);

    // ---- parsing -----------------------------------------------------------------------------
    void parse(RibLexer& lex) {
        while (true) {
            Token t = lex.next();
            if (t.type == TokenType::End) return;
            if (t.type != TokenType::Request)
                diag_.fail(t.line, "expected a RIB request, found " + describe(t));
            Request r{t.text, t.line, {}};
            Handler h = handler(r.name);
            collectArgs(lex, r, /*tolerant=*/!h || skipUntil_.has_value());
            if (skipUntil_) {  // inside a frame or world we do not load
                if (r.name == *skipUntil_) skipUntil_.reset();
                continue;
            }
            if (!h) {
                diag_.warnOnce("request:" + r.name, r.line,
                               "unknown or unsupported request '" + r.name + "' ignored");
                continue;
            }
            (this->*h)(r, Arguments(r, diag_));
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
                        diag_.fail(p.line, "unexpected " + describe(p) + " in the arguments of " + r.name);
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
                    diag_.fail(t.line, "expected ']' to close the array opened on line " +
                                           std::to_string(open.line) + ", found " + describe(t));
                case TokenType::End:
                    if (tolerant) return false;
                    diag_.fail(t.line,
                               "end of file inside the array opened on line " + std::to_string(open.line));
                case TokenType::ArrayBegin:
                case TokenType::Other:
                    if (!tolerant) diag_.fail(t.line, "unexpected " + describe(t) + " inside an array");
                    break;
            }
            if (hasNum && hasStr && !tolerant) diag_.fail(t.line, "array mixes numbers and strings");
            lex.next();
        }
    }

    // ---- structure (RI spec 3.2, sec. 4.1 and 4.3.2) ------------------------------------------
    void version(const Request&, const Arguments&) {}
    void frameBegin(const Request& r, const Arguments&) {
        if (framesSeen_ > 0) {
            diag_.warnOnce("frames", r.line, "more than one frame: only the first frame is loaded");
            skipUntil_ = "FrameEnd";
            return;
        }
        ++framesSeen_;
        state_.begin(Block::Frame, diag_.file(), r.line);
    }
    void frameEnd(const Request& r, const Arguments&) { state_.end(Block::Frame, r, diag_); }
    void worldBegin(const Request& r, const Arguments&) {
        if (worldsSeen_ > 0) {
            diag_.warnOnce("worlds", r.line, "more than one world block: only the first is loaded");
            skipUntil_ = "WorldEnd";
            return;
        }
        ++worldsSeen_;
        state_.beginWorld(r, scene_.camera, diag_);
    }
    void worldEnd(const Request& r, const Arguments&) { state_.end(Block::World, r, diag_); }
    void attributeBegin(const Request& r, const Arguments&) {
        state_.begin(Block::Attribute, diag_.file(), r.line);
    }
    void attributeEnd(const Request& r, const Arguments&) { state_.end(Block::Attribute, r, diag_); }
    void transformBegin(const Request& r, const Arguments&) {
        state_.begin(Block::Transform, diag_.file(), r.line);
    }
    void transformEnd(const Request& r, const Arguments&) { state_.end(Block::Transform, r, diag_); }

    // ---- options (RI spec 3.2, sec. 4.1): frame-wide, written straight into the scene ----------
    void format(const Request& r, const Arguments& args) {
        auto v = args.numbers(3, "xresolution yresolution pixelaspectratio");
        if (v[0] < 1 || v[1] < 1 || v[0] != std::floor(v[0]) || v[1] != std::floor(v[1]) || !(v[2] > 0))
            diag_.fail(
                r.line,
                "Format: the resolution must be positive integers and the pixel aspect ratio positive");
        if (v[0] > kMaxImageSize || v[1] > kMaxImageSize) {
            char res[64];
            std::snprintf(res, sizeof res, "%.15gx%.15g", v[0], v[1]);
            diag_.fail(r.line, std::string("Format: resolution ") + res + " exceeds the limit of " +
                                   std::to_string(kMaxImageSize) + " pixels per axis");
        }
        scene_.camera.width = int(v[0]);
        scene_.camera.height = int(v[1]);
        scene_.camera.pixelAspect = float(v[2]);
    }
    void frameAspectRatio(const Request& r, const Arguments& args) {
        double a = args.numbers(1, "aspect")[0];
        if (!(a > 0)) diag_.fail(r.line, "FrameAspectRatio must be positive");
        scene_.camera.frameAspect = float(a);
    }
    void screenWindow(const Request& r, const Arguments& args) {
        auto v = args.numbers(4, "left right bottom top");
        if (v[0] == v[1] || v[2] == v[3]) diag_.fail(r.line, "ScreenWindow has zero width or height");
        for (int i = 0; i < 4; ++i) scene_.camera.screenWindow[i] = float(v[i]);
        scene_.camera.hasScreenWindow = true;
    }
    void clipping(const Request& r, const Arguments& args) {
        auto v = args.numbers(2, "near far");
        if (!(v[0] > 0) || !(v[1] > v[0])) diag_.fail(r.line, "Clipping needs 0 < near < far");
        scene_.camera.nearClip = float(v[0]);
        scene_.camera.farClip = float(std::min(v[1], 1e30));
    }
    void projection(const Request& r, const Arguments& args) {
        args.atLeast(1, "name ...parameterlist...");
        const std::string& name = args.string(0);
        auto ps = parseParams(r, 1, decls_, diag_);
        if (name == "perspective") {
            scene_.camera.perspective = true;
            for (const Param& p : ps) {
                if (p.name != "fov") {
                    warnIgnoredParam(p, "Projection", diag_);
                    continue;
                }
                float fov = paramFloat(r, p, diag_);
                if (!(fov > 0 && fov < 180))
                    diag_.fail(p.line, "Projection: fov must be in (0, 180) degrees");
                scene_.camera.fovDegrees = fov;
            }
        } else if (name == "orthographic") {
            scene_.camera.perspective = false;
        } else {
            diag_.warnOnce("projection:" + name, r.line,
                           "projection \"" + name + "\" is not supported; ignored");
            return;
        }
        // RI spec 4.1.1: transformations before Projection define screen space, and the CTM is reset.
        if (!state_.transform().isIdentity())
            diag_.warn(r.line, "transformations before Projection are ignored");
        state_.transform() = Transform();
    }
    void pixelSamples(const Request& r, const Arguments& args) {
        auto v = args.numbers(2, "xsamples ysamples");
        if (!(v[0] > 0 && v[1] > 0)) diag_.fail(r.line, "PixelSamples must be positive");
        if (std::max(1.0, std::round(v[0])) * std::max(1.0, std::round(v[1])) > kMaxPixelSamples)
            diag_.fail(r.line,
                       "PixelSamples: more than " + std::to_string(kMaxPixelSamples) + " samples per pixel");
        scene_.image.pixelSamplesX = std::max(1, int(std::lround(v[0])));
        scene_.image.pixelSamplesY = std::max(1, int(std::lround(v[1])));
    }
    void pixelFilter(const Request& r, const Arguments& args) {
        args.count(3, "filter xwidth ywidth");
        const std::string& name = args.string(0);
        double xw = args.number(1), yw = args.number(2);
        if (!(xw > 0 && yw > 0)) diag_.fail(r.line, "PixelFilter widths must be positive");
        static const std::map<std::string, FilterType> filters = {{"box", FilterType::Box},
                                                                  {"triangle", FilterType::Triangle},
                                                                  {"gaussian", FilterType::Gaussian},
                                                                  {"catmull-rom", FilterType::CatmullRom}};
        auto it = filters.find(name);
        if (it == filters.end()) {
            diag_.warnOnce("filter:" + name, r.line,
                           "pixel filter \"" + name + "\" is not supported; keeping the previous one");
            return;
        }
        scene_.image.filter = it->second;
        scene_.image.filterWidthX = float(xw);
        scene_.image.filterWidthY = float(yw);
    }
    void exposure(const Request& r, const Arguments& args) {
        auto v = args.numbers(2, "gain gamma");
        if (!(v[0] > 0 && v[1] > 0)) diag_.fail(r.line, "Exposure gain and gamma must be positive");
        scene_.image.exposureGain = float(v[0]);
        scene_.image.exposureGamma = float(v[1]);
    }
    void display(const Request& r, const Arguments& args) {
        args.atLeast(3, "name type mode ...parameterlist...");
        const std::string& name = args.string(0);
        args.string(1);
        args.string(2);
        parseParams(r, 3, decls_, diag_);  // syntax check only; display parameters do not affect the scene
        // RI spec 4.1.4: a name starting with '+' adds a secondary display; we keep the primary.
        if (!name.empty() && name[0] == '+') {
            diag_.warnOnce("display+", r.line, "secondary displays ('+" + name.substr(1) + "') are ignored");
            return;
        }
        scene_.image.displayName = name;
    }
    void option(const Request& r, const Arguments& args) {
        args.atLeast(1, "name ...parameterlist...");
        const std::string& name = args.string(0);
        parseParams(r, 1, decls_, diag_);
        if (name == "searchpath") return;  // shaders are built in; search paths are meaningless here
        diag_.warnOnce("option:" + name, r.line, "Option \"" + name + "\" is not supported; ignored");
    }

    // ---- attributes (RI spec 3.2, sec. 4.2) -----------------------------------------------------
    void attribute(const Request& r, const Arguments& args) {
        args.atLeast(1, "name ...parameterlist...");
        const std::string& name = args.string(0);
        auto ps = parseParams(r, 1, decls_, diag_);
        if (name == "identifier") {
            for (const Param& p : ps) {
                if (p.name == "name")
                    state_.attributes().identifier = paramString(r, p, diag_);
                else
                    warnIgnoredParam(p, "Attribute \"identifier\"", diag_);
            }
            return;
        }
        diag_.warnOnce("attribute:" + name, r.line, "Attribute \"" + name + "\" is not supported; ignored");
    }
    void color(const Request&, const Arguments& args) {
        auto v = args.numbers(3, "r g b");
        state_.attributes().surface.Cs = {float(v[0]), float(v[1]), float(v[2])};
    }
    void opacity(const Request& r, const Arguments& args) {
        auto v = args.numbers(3, "r g b");
        state_.attributes().surface.Os = {float(v[0]), float(v[1]), float(v[2])};
        if (v[0] != 1 || v[1] != 1 || v[2] != 1)
            diag_.warnOnce("opacity", r.line, "only opaque surfaces are rendered; Opacity is ignored");
    }
    void shadingRate(const Request& r, const Arguments& args) {
        double s = args.numbers(1, "size")[0];
        if (!(s > 0)) diag_.fail(r.line, "ShadingRate must be positive");
        state_.attributes().shadingRate = float(s);
    }
    void sides(const Request& r, const Arguments& args) {
        args.count(1, "1 or 2");
        int s = args.integer(0);
        if (s != 1 && s != 2) diag_.fail(r.line, "Sides must be 1 or 2");
        state_.attributes().twoSided = s == 2;
    }
    void orientation(const Request& r, const Arguments& args) {
        args.count(1, "\"lh\", \"rh\", \"inside\" or \"outside\"");
        const std::string& o = args.string(0);
        if (o == "lh" || o == "outside")
            state_.attributes().rightHanded = false;
        else if (o == "rh" || o == "inside")
            state_.attributes().rightHanded = true;
        else
            diag_.fail(r.args[0].line,
                       "Orientation must be \"lh\", \"rh\", \"inside\" or \"outside\", found \"" + o + "\"");
    }
    void reverseOrientation(const Request&, const Arguments& args) {
        args.count(0, "no arguments");
        state_.attributes().rightHanded = !state_.attributes().rightHanded;
    }
    // Surface (RI spec 3.2, sec. 4.2.3 and appendix A): a new material of the named shader, its
    // parameters set through the shader's table; the colour and opacity stay those of the state.
    void surface(const Request& r, const Arguments& args) {
        args.atLeast(1, "name ...parameterlist...");
        const std::string& name = args.string(0);
        auto ps = parseParams(r, 1, decls_, diag_);
        const SurfaceShader* shader = rib::findSurfaceShader(name);
        if (!shader) {
            diag_.warnOnce("surface:" + name, r.line,
                           "surface shader \"" + name + "\" is not supported; keeping the previous surface");
            return;
        }
        Material m = defaultMaterial(shader->type);
        m.Cs = state_.attributes().surface.Cs;
        m.Os = state_.attributes().surface.Os;
        applyShaderParams(shader->params, r, ps, m, "Surface \"" + name + "\"", diag_);
        state_.attributes().surface = m;
    }
    // LightSource (RI spec 3.2, sec. 4.2.2): the light's "shader space" is the current object space.
    void lightSource(const Request& r, const Arguments& args) {
        args.atLeast(2, "shadername handle ...parameterlist...");
        const std::string& name = args.string(0);
        if (r.args[1].isArray())
            diag_.fail(r.args[1].line, "LightSource: the light handle must be a number or a string");
        auto ps = parseParams(r, 2, decls_, diag_);
        if (!state_.inWorld()) {
            diag_.warn(r.line, "LightSource before WorldBegin is ignored");
            return;
        }
        const LightShader* shader = rib::findLightShader(name);
        if (!shader) {
            diag_.warnOnce("light:" + name, r.line,
                           "light shader \"" + name + "\" is not supported; light ignored");
            return;
        }
        LightShaderParams params;
        applyShaderParams(shader->params, r, ps, params, "LightSource \"" + name + "\"", diag_);
        Light light;
        light.type = shader->type;
        light.color = params.lightcolor * params.intensity;
        light.from = state_.transform().point(params.from);
        light.to = state_.transform().point(params.to);
        light.coneAngle = params.coneangle;
        light.coneDeltaAngle = params.conedeltaangle;
        light.beamDistribution = params.beamdistribution;
        if (!isFinite(light.color) || !isFinite(light.from) || !isFinite(light.to))
            diag_.fail(
                r.line,
                "LightSource: intensity, colour or position out of range (overflows single precision)");
        scene_.lights.push_back(light);
    }
    void illuminate(const Request& r, const Arguments& args) {
        args.count(2, "light onoff");
        args.integer(1);
        diag_.warnOnce("illuminate", r.line, "Illuminate is ignored: every declared light stays on");
    }
    void basis(const Request& r, const Arguments& args) {
        args.count(4, "ubasis ustep vbasis vstep");
        state_.attributes().uBasis = basisArg(r, args, 0);
        state_.attributes().vBasis = basisArg(r, args, 2);
    }
    // A basis is a name or 16 numbers. RIB writes the matrix row by row, the layout of Basis::m
    // (RiBSplineBasis in ri.h reads {-1/6, 3/6, -3/6, 1/6, ...} like bsplineBasis()), so no transpose.
    Basis basisArg(const Request& r, const Arguments& args, size_t i) const {
        const Value& v = r.args[i];
        Basis b{};
        if (v.kind == Value::Kind::String || v.kind == Value::Kind::StringArray) {
            const std::string& name = args.string(i);
            auto named = basisByName(name);
            if (!named) diag_.fail(v.line, "Basis: unknown basis \"" + name + "\"");
            b = *named;
        } else if (v.kind == Value::Kind::NumberArray && v.nums.size() == 16) {
            for (int k = 0; k < 16; ++k) b.m[k / 4][k % 4] = v.nums[k];
        } else {
            diag_.fail(v.line,
                       "Basis: a basis must be a name or an array of 16 numbers, found " + describe(v));
        }
        int step = args.integer(i + 1);
        if (step < 1) diag_.fail(r.args[i + 1].line, "Basis: step must be at least 1");
        b.step = step;
        return b;
    }
    void declare(const Request& r, const Arguments& args) {
        args.count(2, "name declaration");
        const std::string& name = args.string(0);
        const std::string& text = args.string(1);
        auto d = parseDecl(text);
        if (!d) diag_.fail(r.args[1].line, "Declare: invalid declaration \"" + text + "\"");
        decls_.declare(name, *d);
    }

    // ---- transformations (RI spec 3.2, sec. 4.3): each concatenates on the object side ----------
    void identity(const Request&, const Arguments& args) {
        args.count(0, "no arguments");
        state_.transform() = Transform();
    }
    static Mat4 matrixArg(const Arguments& args) {
        auto v = args.numbers(16, "a 4x4 matrix");
        return Mat4::fromRib(v.data());
    }
    // Inside the world the CTM maps object to world space, so Transform is relative to the world.
    void transform(const Request&, const Arguments& args) { state_.transform() = Transform(matrixArg(args)); }
    void concatTransform(const Request&, const Arguments& args) {
        state_.transform().concatenate(matrixArg(args));
    }
    void translate(const Request&, const Arguments& args) {
        auto v = args.numbers(3, "dx dy dz");
        state_.transform().concatenate(Mat4::translate(v[0], v[1], v[2]));
    }
    void rotate(const Request& r, const Arguments& args) {
        auto v = args.numbers(4, "angle dx dy dz");
        if (v[1] == 0 && v[2] == 0 && v[3] == 0) diag_.fail(r.line, "Rotate: the axis is the zero vector");
        state_.transform().concatenate(Mat4::rotate(v[0], v[1], v[2], v[3]));
    }
    void scale(const Request&, const Arguments& args) {
        auto v = args.numbers(3, "sx sy sz");
        state_.transform().concatenate(Mat4::scale(v[0], v[1], v[2]));
    }
    void coordinateSystem(const Request&, const Arguments& args) {
        args.count(1, "name");
        state_.defineCoordinateSystem(args.string(0));
    }
    void coordSysTransform(const Request& r, const Arguments& args) {
        args.count(1, "name");
        const std::string& name = args.string(0);
        const Transform* named = state_.coordinateSystem(name);
        if (!named) diag_.fail(r.line, "CoordSysTransform: unknown coordinate system \"" + name + "\"");
        state_.transform() = *named;
    }

    // ---- geometry (RI spec 3.2, sec. 5; rib_geometry.h) ----------------------------------------
    PrimitiveContext primitiveContext() { return {scene_, state_, decls_, diag_}; }
    void patch(const Request& r, const Arguments&) { readPatch(r, primitiveContext()); }
    void patchMesh(const Request& r, const Arguments&) { readPatchMesh(r, primitiveContext()); }
    void nuPatch(const Request& r, const Arguments&) { readNuPatch(r, primitiveContext()); }
    void subdivisionMesh(const Request& r, const Arguments&) { readSubdivisionMesh(r, primitiveContext()); }

    // ---- ReadArchive (RI spec 3.2, sec. 8.1) -----------------------------------------------------
    void readArchive(const Request& r, const Arguments& args) {
        args.count(1, "filename");
        const std::string& name = args.string(0);
        namespace fs = std::filesystem;
        fs::path p(name);
        // Relative names are relative to the directory of the including file.
        if (p.is_relative()) p = fs::path(lex_->file()).parent_path() / p;
        std::string path = p.string();
        if (archiveDepth_ + 1 > kMaxArchiveDepth)
            diag_.fail(r.line, "ReadArchive nested more than " + std::to_string(kMaxArchiveDepth) +
                                   " levels deep (recursive include?)");
        std::error_code ec;
        if (!fs::is_regular_file(p, ec)) diag_.fail(r.line, "ReadArchive: cannot open \"" + path + "\"");
        std::string text;
        try {
            text = readInputFile(path);
        } catch (const InputError&) {
            diag_.fail(r.line, "ReadArchive: cannot read \"" + path + "\"");
        }
        RibLexer lex(std::move(text), path);
        RibLexer* outer = lex_;
        lex_ = &lex;
        diag_.setFile(path);
        ++archiveDepth_;
        parse(lex);
        --archiveDepth_;
        lex_ = outer;
        diag_.setFile(outer->file());
    }

    // The request table (RI spec 3.2, appendix C.2 names): nullptr for a request we do not handle.
    static Handler handler(const std::string& name) {
        static const std::unordered_map<std::string_view, Handler> handlers = {
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
            {"ReadArchive", &RibReader::readArchive},
        };
        auto it = handlers.find(name);
        return it == handlers.end() ? nullptr : it->second;
    }

    Scene& scene_;
    Diagnostics diag_;
    RibLexer* lex_ = nullptr;
    Declarations decls_;
    GraphicsState state_;
    std::optional<std::string> skipUntil_;
    int framesSeen_ = 0, worldsSeen_ = 0;
    int archiveDepth_ = 0;  // ReadArchive nesting of the file being read
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
