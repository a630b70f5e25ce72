// The RIB request dispatcher: reads requests and their arguments from the lexer, maps each request
// name to its handler through one table, and lets the handlers update the graphics state
// (rib_graphics_state.h), read parameter lists (rib_params.h, rib_shaders.h) and convert primitives
// (rib_geometry.h).
#include "io/rib_reader.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string_view>
#include <unordered_map>
#include <utility>

#include "io/image_io.h"
#include "io/rib_geometry.h"
#include "io/rib_graphics_state.h"
#include "io/rib_lexer.h"
#include "io/rib_params.h"
#include "io/rib_request.h"
#include "io/rib_shaders.h"
#include "shading/registry.h"
#include "shading/shadow_map.h"
#include "shading/texture.h"

namespace tessera {

namespace {
std::atomic<size_t> gFirstReadRecordBytes{size_t(64) << 20};
}  // namespace

size_t setArchiveFirstReadRecordBytes(size_t bytes) {
    return gFirstReadRecordBytes.exchange(bytes);
}

namespace {

using namespace rib;

constexpr int kMaxArchiveDepth = 32;
// A skipUntil_ target no request is named: skip to the end of the file.
constexpr const char* kNeverARequest = "";

class RibReader {
  public:
    // frameOrdinal: which FrameBegin block to load (0 = the first); nullopt: the first, warning that
    // later frames are ignored.
    RibReader(Scene& scene, const WarningSink& warn, std::optional<int> frameOrdinal = std::nullopt,
              RasterOverride raster = {})
        : scene_(scene), diag_(warn), frameOrdinal_(frameOrdinal), raster_(raster) {
        declareShaderParams(decls_);
    }

    void run(const std::string& path) { runText(readInputFile(path), path); }
    void runText(std::string text, const std::string& path) {
        RibLexer lex(std::move(text), path);
        currentFile_ = path;
        diag_.setFile(path);
        if (lex.peek().type == TokenType::End) diag_.fail(lex.eofLine(), "empty file: no RIB requests");
        parse(lex);
        if (const GraphicsState::Saved* s = state_.innermostBlock())
            diag_.fail(lex.eofLine(), std::string("end of file inside ") + blockName(s->block) +
                                          " block opened at " + s->file + ":" + std::to_string(s->line));
        if (scene_.patches.empty())
            diag_.fail(
                lex.eofLine(),
                "no geometry: the file has no Patch, PatchMesh, NuPatch, SubdivisionMesh, polygon or quadric "
                "primitives");
        if (!scene_.quadrics.empty() && scene_.camera.moving() && scene_.camera.hasShutter())
            diag_.warn(lex.eofLine(),
                       "the camera moves: quadrics do not move yet and are rendered as seen at "
                       "shutter open (no blur)");
        if (scene_.lights.empty())
            diag_.warn(lex.eofLine(), "no light sources: only \"constant\" surfaces will be visible");
    }

  private:
    using Handler = void (RibReader::*)(const Request&, const Arguments&);

    // ---- parsing -----------------------------------------------------------------------------
    // The requests of one archive as the parser collected them, with their handlers, to be run again on
    // later reads of the file without lexing or collecting anything (readArchive).
    struct ArchiveRequest {
        Request request;
        Handler handler;
    };
    struct RecordedArchive {
        std::vector<ArchiveRequest> requests;
        int eofLine = 1;
        // False when a request was collected tolerantly because the reader was skipping (a frame not
        // loaded): a later read that does not skip must collect the same tokens strictly.
        bool replayable = true;
    };

    // Parses `lex` to its end, running each request; with `record`, keeps the requests there as well.
    void parse(RibLexer& lex, RecordedArchive* record = nullptr) {
        while (true) {
            Token t = lex.next();
            if (t.type == TokenType::End) {
                if (record) record->eofLine = lex.eofLine();
                endOfFile(lex.eofLine());
                return;
            }
            if (t.type != TokenType::Request)
                diag_.fail(t.line, "expected a RIB request, found " + describe(t));
            Request r{std::move(t.text), t.line, {}};
            Handler h = handler(r.name);
            const bool skipping = skipUntil_.has_value();
            collectArgs(lex, r, /*tolerant=*/!h || skipping);
            if (!record) {
                dispatch(r, h);
                continue;
            }
            if (skipping) record->replayable = false;
            record->requests.push_back({std::move(r), h});
            dispatch(record->requests.back().request, h);  // nested reads record into their own files
        }
    }
    // Runs a recorded file's requests as parse ran them.
    void replay(const RecordedArchive& file) {
        for (const ArchiveRequest& rr : file.requests) {
            replayedRequest_ = &rr.request;
            dispatch(rr.request, rr.handler);
        }
        replayedRequest_ = nullptr;
        endOfFile(file.eofLine);
    }
    void dispatch(const Request& r, Handler h) {
        if (skipUntil_) {  // inside a frame or world we do not load
            if (r.name == *skipUntil_) skipUntil_.reset();
            return;
        }
        if (defining_ && r.name != "ObjectEnd" && r.name != "ReadArchive") {
            recordObjectRequest(r, h);
            return;
        }
        execute(r, h);
    }
    // A motion block or an object definition must close in the file that opened it.
    void endOfFile(int eofLine) {
        if (motion_)
            diag_.fail(eofLine, "end of file inside the motion block opened at " + motion_->file + ":" +
                                    std::to_string(motion_->line));
        if (defining_ && defining_->archiveDepth == archiveDepth_)
            diag_.fail(eofLine, "end of file inside the object definition (ObjectBegin) opened at " +
                                    defining_->object->file + ":" + std::to_string(defining_->object->line));
    }
    // One request, in a motion block or not.
    void execute(const Request& r, Handler h) {
        if (motion_ && r.name != "MotionEnd") {
            motionRequest(r, h);
            return;
        }
        if (!h) {
            diag_.warnOnce("request:" + r.name, r.line,
                           "unknown or unsupported request '" + r.name + "' ignored");
            return;
        }
        (this->*h)(r, Arguments(r, diag_));
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
            lex.skip();
        }
    }

    // Returns false if a tolerant scan stopped at a request inside the array.
    bool collectArray(RibLexer& lex, Request& r, const Token& open, bool tolerant) {
        Value v{Value::Kind::NumberArray, {}, {}, open.line};
        bool hasNum = false, hasStr = false;
        // Numbers gather in a reused buffer and are copied once at the end: a patch's 48 values pushed
        // one by one grew the array 7 times (allocation was a third of loading 24 Big Guys).
        numberScratch_.clear();
        while (true) {
            const Token& t = lex.peek();
            switch (t.type) {
                case TokenType::ArrayEnd:
                    lex.skip();
                    if (hasStr) v.kind = Value::Kind::StringArray;
                    v.nums.assign(numberScratch_.begin(), numberScratch_.end());
                    r.args.push_back(std::move(v));
                    return true;
                case TokenType::Number:
                    hasNum = true;
                    numberScratch_.push_back(t.number);
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
            lex.skip();
        }
    }

    // ---- structure (RI spec 3.2, sec. 4.1 and 4.3.2) ------------------------------------------
    void version(const Request&, const Arguments&) {}
    // RI spec 3.2, sec. 4.1.1: the options before FrameBegin are the defaults of every frame, those
    // inside a frame are local to it. One reader loads one frame: the requests outside frames up to
    // it, then its own; other frames are skipped whole (the CLI reads the file once per frame).
    void frameBegin(const Request& r, const Arguments&) {
        const int ordinal = framesSeen_++;
        if (ordinal != frameOrdinal_.value_or(0)) {
            if (!frameOrdinal_)
                diag_.warnOnce("frames", r.line, "more than one frame: only the first frame is loaded");
            skipUntil_ = "FrameEnd";
            return;
        }
        state_.begin(Block::Frame, diag_.file(), r.line);
    }
    void frameEnd(const Request& r, const Arguments&) {
        state_.end(Block::Frame, r, diag_);
        // Requests after the chosen frame belong to later frames: not this one's options.
        if (frameOrdinal_) skipUntil_ = std::string(kNeverARequest);
    }
    void worldBegin(const Request& r, const Arguments&) {
        if (worldsSeen_ > 0) {
            diag_.warnOnce("worlds", r.line, "more than one world block: only the first is loaded");
            skipUntil_ = "WorldEnd";
            return;
        }
        ++worldsSeen_;
        // Camera motion blocks come before WorldBegin, possibly before Shutter: their times are checked now.
        for (const MotionBlock& m : cameraMotion_) checkShutterTimes(m);
        if (!cameraMotion_.empty() && !scene_.camera.hasShutter())
            diag_.warnOnce("closedshutter", r.line,
                           "the camera moves but the shutter is closed (Shutter " +
                               fmtNum(scene_.camera.shutterOpen) + " " + fmtNum(scene_.camera.shutterClose) +
                               "): no motion blur, rendered at shutter open");
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
    // CropWindow xmin xmax ymin ymax (RI spec 3.2, sec. 4.1.1): render only this part of the image, given
    // in NDC (0..1 from the top-left corner); the pixels are chosen by film/crop.h.
    void cropWindow(const Request& r, const Arguments& args) {
        auto v = args.numbers(4, "xmin xmax ymin ymax");
        for (double x : v)
            if (!(x >= 0 && x <= 1)) diag_.fail(r.line, "CropWindow: the limits must lie in [0, 1]");
        if (!(v[0] < v[1]) || !(v[2] < v[3]))
            diag_.fail(r.line, "CropWindow: needs xmin < xmax and ymin < ymax");
        for (int i = 0; i < 4; ++i) scene_.image.cropWindow[i] = v[i];
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
    // Imager (RI spec 3.2, sec. 4.1.5): the standard "background" imager (appendix A) composites the image
    // over its "background" colour (default white) and makes it opaque; other imagers are warned about.
    void imager(const Request& r, const Arguments& args) {
        args.atLeast(1, "name ...parameterlist...");
        const std::string& name = args.string(0);
        auto ps = parseParams(r, 1, decls_, diag_);
        if (name != "background") {
            diag_.warnOnce("imager:" + name, r.line, "Imager \"" + name + "\" is not supported; ignored");
            return;
        }
        Color bg{1, 1, 1};
        for (const Param& p : ps) {
            if (p.name == "background")
                bg = paramTriple(r, p, diag_);
            else
                diag_.warn(r.line,
                           "Imager \"background\": parameter \"" + p.name + "\" is not known; ignored");
        }
        if (!isFinite(bg) || bg.x < 0 || bg.y < 0 || bg.z < 0)
            diag_.fail(r.line, "Imager \"background\": the colour must be finite and not negative");
        scene_.image.hasBackground = true;
        scene_.image.background = bg;
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
        const std::string& type = args.string(1);
        const std::string& mode = args.string(2);
        parseParams(r, 3, decls_, diag_);  // syntax check only; display parameters do not affect the scene
        // RI spec 4.1.4: a name starting with '+' adds a secondary display of the same render.
        if (!name.empty() && name[0] == '+') {
            if (name.size() == 1) diag_.fail(r.line, "Display \"+\": a secondary display needs a name");
            if (type == "zfile" || type == "shadow")
                diag_.fail(r.line, "Display \"" + printable(name, 200) +
                                       "\": a depth map is a frame's primary display, not a secondary one");
            scene_.image.secondaryDisplays.push_back({name.substr(1), type, mode, r.line});
            return;
        }
        // A new primary display starts the list afresh (RI: Display without '+' replaces all displays).
        scene_.image.secondaryDisplays.clear();
        scene_.image.displayName = name;
        scene_.image.displayType = type;
    }
    // Options that must come before WorldBegin (RI spec 3.2, sec. 4.1); false: ignore the request (after
    // the world block, warned).
    bool beforeWorld(const Request& r) {
        if (state_.inWorld())
            diag_.fail(r.line, r.name + " is an option (RI spec 3.2, sec. 4.1): give it before WorldBegin");
        if (worldsSeen_ > 0) {
            diag_.warn(r.line, r.name + " after the world block has no effect; ignored");
            return false;
        }
        return true;
    }
    // Shutter open close (RI spec 3.2, sec. 4.1.1): the times the camera sees; RI default 0 0 (no blur).
    void shutter(const Request& r, const Arguments& args) {
        auto v = args.numbers(2, "open close");
        if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || std::fabs(v[0]) > 1e30 || std::fabs(v[1]) > 1e30)
            diag_.fail(r.line, "Shutter: open and close must be finite numbers");
        if (v[1] < v[0])
            diag_.fail(r.line, "Shutter: close (" + fmtNum(v[1]) + ") is before open (" + fmtNum(v[0]) + ")");
        if (!beforeWorld(r)) return;
        scene_.camera.shutterOpen = float(v[0]);
        scene_.camera.shutterClose = float(v[1]);
    }
    // DepthOfField fstop focallength focaldistance (RI spec 3.2, sec. 4.1.1); no arguments: a pinhole.
    void depthOfField(const Request& r, const Arguments& args) {
        Camera& c = scene_.camera;
        if (r.args.empty()) {
            if (!beforeWorld(r)) return;
            c.fStop = std::numeric_limits<float>::infinity();
            return;
        }
        if (r.args.size() != 3 && !(r.args.size() == 1 && r.args[0].isArray()))
            diag_.fail(
                r.line,
                "DepthOfField takes fstop focallength focaldistance, or no arguments for a pinhole camera");
        auto v = args.numbers(3, "fstop focallength focaldistance");
        if (!(v[0] > 0) || !(v[1] > 0 && v[1] < 1e30) || !(v[2] > 0 && v[2] < 1e30))
            diag_.fail(r.line, "DepthOfField: fstop, focallength and focaldistance must be positive (got " +
                                   fmtNum(v[0]) + " " + fmtNum(v[1]) + " " + fmtNum(v[2]) + ")");
        if (!beforeWorld(r)) return;
        c.fStop = float(v[0]);
        c.focalLength = float(v[1]);
        c.focalDistance = float(v[2]);
    }
    // Hider "hidden" (RI spec 3.2, sec. 4.1.5) with our motion-blur parameters (docs/motion.md):
    // "string blursampling" "simple" | "interleaved" | "bbox", "int blurtilesize" K (2..16),
    // "int blurpermutations" P (1..4096); and Reyes' micropolygon sampler (paper 000 sec. 3.2):
    // "string micropolygonsampling" "bbox" | "nearest".
    void hider(const Request& r, const Arguments& args) {
        args.atLeast(1, "type ...parameterlist...");
        const std::string& type = args.string(0);
        auto ps = parseParams(r, 1, decls_, diag_);
        if (type != "hidden") {
            diag_.warnOnce("hider:" + type, r.line,
                           "Hider \"" + type + "\" is not supported; the hidden-surface hider is used");
            return;
        }
        for (const Param& p : ps) {
            if (p.name == "blursampling") {
                std::string v = paramString(r, p, diag_);
                if (v != "simple" && v != "interleaved" && v != "bbox")
                    diag_.fail(p.line,
                               "Hider \"hidden\": \"blursampling\" must be \"simple\", "
                               "\"interleaved\" or \"bbox\", found \"" +
                                   printable(v) + "\"");
                scene_.image.blurSampling = v;
            } else if (p.name == "blurtilesize" || p.name == "blurpermutations") {
                const bool tile = p.name == "blurtilesize";
                const float v = paramFloat(r, p, diag_);
                const int lo = tile ? 2 : 1, hi = tile ? 16 : 4096;
                if (!(v >= lo && v <= hi) || v != std::floor(v))
                    diag_.fail(p.line, "Hider \"hidden\": \"" + p.name + "\" must be an integer from " +
                                           std::to_string(lo) + " to " + std::to_string(hi) + ", found " +
                                           fmtNum(v));
                (tile ? scene_.image.blurTileSize : scene_.image.blurPermutations) = int(v);
            } else if (p.name == "micropolygonsampling") {
                std::string v = paramString(r, p, diag_);
                if (v != "bbox" && v != "nearest")
                    diag_.fail(p.line,
                               "Hider \"hidden\": \"micropolygonsampling\" must be \"bbox\" or "
                               "\"nearest\", found \"" +
                                   printable(v) + "\"");
                scene_.image.micropolygonSampling = v;
            } else if (p.name == "jitter") {
                const float v = paramFloat(r, p, diag_);
                if (v != 0.f && v != 1.f)
                    diag_.fail(p.line, "Hider \"hidden\": \"jitter\" must be 0 or 1, found " + fmtNum(v));
                scene_.image.jitter = v != 0.f;
            } else {
                warnIgnoredParam(p, "Hider \"hidden\"", diag_);
            }
        }
    }
    static std::string fmtNum(double v) {
        char buf[40];
        std::snprintf(buf, sizeof buf, "%.9g", v);
        return buf;
    }
    void option(const Request& r, const Arguments& args) {
        args.atLeast(1, "name ...parameterlist...");
        const std::string& name = args.string(0);
        parseParams(r, 1, decls_, diag_);
        if (name == "searchpath") {
            // "texture": where texture names are looked up (textureIndex); "archive": where ReadArchive looks
            // up relative names; "shader": kept (with "&" expansion) but used for nothing, the shaders
            // being built in; others ("procedural", "display", ...) are meaningless here.
            for (const Param& p : parseParams(r, 1, decls_, diag_)) {
                if (p.name == "texture")
                    textureSearchPath_ = searchPath(paramString(r, p, diag_), textureSearchPath_);
                if (p.name == "archive")
                    archiveSearchPath_ = searchPath(paramString(r, p, diag_), archiveSearchPath_);
                if (p.name == "shader")
                    shaderSearchPath_ = searchPath(paramString(r, p, diag_), shaderSearchPath_);
            }
            return;
        }
        diag_.warnOnce("option:" + name, r.line, "Option \"" + name + "\" is not supported; ignored");
    }

    // ---- textures (RI spec 3.2, sec. 8.3 and 4.1.6) -----------------------------------------------
    // Option "searchpath" "texture" (or "archive", "shader") "dir:dir:...", as PRMan: "&" is the previous
    // path, "@" the default (the directory of the file being read); relative directories are relative to
    // that file's directory.
    std::vector<std::string> searchPath(const std::string& text,
                                        const std::vector<std::string>& previous) const {
        std::vector<std::string> out;
        size_t start = 0;
        while (start <= text.size()) {
            size_t end = text.find(':', start);
            if (end == std::string::npos) end = text.size();
            const std::string dir = text.substr(start, end - start);
            if (dir == "&")
                out.insert(out.end(), previous.begin(), previous.end());
            else if (dir == "@")
                out.push_back(fileDirectory());
            else if (!dir.empty())
                out.push_back(relativeToFile(dir));
            start = end + 1;
        }
        return out;
    }
    std::string fileDirectory() const { return std::filesystem::path(currentFile_).parent_path().string(); }
    // A render product a RIB reads back (MakeShadow's depth file, a light's shadow map): where Display and
    // MakeShadow write them, relative to the current directory as in PRMan, else (a map shipped with the
    // scene) relative to the RIB file. A file in neither place: the current directory's path.
    std::string productPath(const std::string& name) const {
        namespace fs = std::filesystem;
        std::error_code ec;
        if (fs::path(name).is_absolute() || fs::is_regular_file(name, ec)) return name;
        const std::string beside = relativeToFile(name);
        return fs::is_regular_file(beside, ec) ? beside : name;
    }
    std::string relativeToFile(const std::string& name) const {
        namespace fs = std::filesystem;
        fs::path p(name);
        if (p.is_relative()) p = fs::path(currentFile_).parent_path() / p;
        return p.string();
    }
    // The index in Scene::textures of texture `name` (found through the search path, checked readable):
    // a missing or unreadable file is an error at the line that names it (docs/textures.md).
    size_t textureIndex(int line, const std::string& name, const std::string& what) {
        namespace fs = std::filesystem;
        std::vector<std::string> dirs = textureSearchPath_;
        if (dirs.empty()) dirs.push_back(fileDirectory());
        std::string path;
        std::error_code ec;
        if (fs::path(name).is_absolute()) {
            path = name;
        } else {
            for (const std::string& d : dirs) {
                const fs::path candidate = d.empty() ? fs::path(name) : fs::path(d) / name;
                if (fs::is_regular_file(candidate, ec)) {
                    path = candidate.string();
                    break;
                }
            }
        }
        if (path.empty() || !fs::is_regular_file(path, ec)) {
            std::string where;
            for (const std::string& d : dirs) where += (where.empty() ? "" : ":") + (d.empty() ? "." : d);
            diag_.fail(line, what + ": texture file \"" + printable(name, 200) + "\" not found" +
                                 (fs::path(name).is_absolute() ? "" : " (searched " + where + ")"));
        }
        for (size_t i = 0; i < scene_.textures.size(); ++i)
            if (scene_.textures[i] == path) return i;
        const std::string why = textureReadError(path);
        if (!why.empty())
            diag_.fail(line, what + ": cannot read texture file \"" + printable(path, 200) + "\": " + why);
        scene_.textures.push_back(path);
        return scene_.textures.size() - 1;
    }
    // MakeTexture picturename texturename swrap twrap filter swidth twidth ...parameterlist... (RI spec 3.2,
    // sec. 8.3): converts the picture (relative names: to the file being read's directory) to a tiled,
    // mip-mapped texture with OpenImageIO, as RenderMan renderers do when the request is read. The filter
    // is checked; OIIO's make_texture filters its own way.
    void makeTextureRequest(const Request& r, const Arguments& args) {
        args.atLeast(7, "picturename texturename swrap twrap filter swidth twidth ...parameterlist...");
        const std::string& picture = args.string(0);
        const std::string& texture = args.string(1);
        const std::string& swrap = args.string(2);
        const std::string& twrap = args.string(3);
        const std::string& filter = args.string(4);
        const double sw = args.number(5), tw = args.number(6);
        parseParams(r, 7, decls_, diag_);
        for (const std::string* w : {&swrap, &twrap})
            if (*w != "periodic" && *w != "clamp" && *w != "black")
                diag_.fail(r.line,
                           "MakeTexture: wrap mode must be \"periodic\", \"clamp\" or \"black\", found \"" +
                               printable(*w) + "\"");
        static const std::set<std::string> filters = {"box",  "triangle", "gaussian", "catmull-rom",
                                                      "sinc", "disk",     "bessel"};
        if (!filters.count(filter))
            diag_.fail(r.line, "MakeTexture: unknown filter \"" + printable(filter) + "\"");
        if (!(sw > 0) || !(tw > 0)) diag_.fail(r.line, "MakeTexture: swidth and twidth must be positive");
        const std::string in = relativeToFile(picture), out = relativeToFile(texture);
        std::error_code ec;
        if (!std::filesystem::is_regular_file(in, ec))
            diag_.fail(r.line, "MakeTexture: picture file \"" + printable(in, 200) + "\" not found");
        if (const std::string why = textureReadError(in); !why.empty())
            diag_.fail(r.line,
                       "MakeTexture: cannot read picture file \"" + printable(in, 200) + "\": " + why);
        if (const std::string why = makeTexture(in, out, swrap, twrap); !why.empty())
            diag_.fail(r.line, "MakeTexture: cannot write texture \"" + printable(out, 200) + "\": " + why);
    }
    // A shadow map a light shader names (productPath: where MakeShadow writes it, else beside the RIB), read
    // once per frame: a missing file, or one that is not a depth map whose view Tessera can project into, is
    // an error at the parameter's line.
    size_t shadowMapIndex(int line, const std::string& name, const std::string& what) {
        const std::string path = productPath(name);
        for (size_t i = 0; i < scene_.shadowMapFiles.size(); ++i)
            if (scene_.shadowMapFiles[i].path == path) return i;
        std::error_code ec;
        if (!std::filesystem::is_regular_file(path, ec))
            diag_.fail(line,
                       what + ": shadow map \"" + printable(name, 200) +
                           "\" not found (made by MakeShadow from a Display \"zfile\" of an earlier frame?)");
        DepthMap map;
        try {
            map = readDepthMap(path);
        } catch (const std::exception& e) {
            diag_.fail(line, what + ": shadow map: " + e.what());
        }
        ShadowMapFace face;
        if (const std::string why =
                fileShadowMapFace(map.worldToCamera, map.worldToNDC, map.width, map.height, Mat4{}, face);
            !why.empty())
            diag_.fail(line, what + ": shadow map \"" + printable(name, 200) + "\": " + why);
        if (map.kind != "shadow")
            diag_.warnOnce(
                "zfileshadow:" + path, line,
                what + ": \"" + printable(name, 200) +
                    "\" is a Display \"zfile\" depth map, not MakeShadow's output; read as a shadow map");
        ShadowMapFile file;
        file.path = path;
        file.width = map.width;
        file.height = map.height;
        file.depth = std::move(map.depth);
        file.worldToCamera = map.worldToCamera;
        file.worldToNDC = map.worldToNDC;
        scene_.shadowMapFiles.push_back(std::move(file));
        return scene_.shadowMapFiles.size() - 1;
    }
    // MakeShadow picturename texturename ...parameterlist... (RI spec 3.2, sec. 8.3): turns a depth map
    // written by Display "zfile" (or "shadow") into a shadow map when the request is read, as RenderMan
    // renderers do; the format stays OpenEXR (image_io.h, DepthMap), marked "shadow".
    void makeShadowRequest(const Request& r, const Arguments& args) {
        args.atLeast(2, "picturename texturename ...parameterlist...");
        // Written where Display writes (the current directory), read from there or beside the RIB.
        const std::string in = productPath(args.string(0)), out = args.string(1);
        parseParams(r, 2, decls_, diag_);
        std::error_code ec;
        if (!std::filesystem::is_regular_file(in, ec))
            diag_.fail(r.line, "MakeShadow: depth file \"" + printable(in, 200) +
                                   "\" not found (made by Display \"zfile\" in an earlier frame?)");
        DepthMap map;
        try {
            map = readDepthMap(in);
        } catch (const std::exception& e) {
            diag_.fail(r.line, std::string("MakeShadow: ") + e.what());
        }
        map.kind = "shadow";
        try {
            writeDepthMap(out, map);
        } catch (const std::exception& e) {
            diag_.fail(r.line, std::string("MakeShadow: cannot write the shadow map: ") + e.what());
        }
    }
    // TextureCoordinates s1 t1 s2 t2 s3 t3 s4 t4 (RI spec 3.2, sec. 4.2.7).
    void textureCoordinates(const Request& r, const Arguments& args) {
        auto v = args.numbers(8, "s1 t1 s2 t2 s3 t3 s4 t4");
        PatchTexCoords& tc = state_.attributes().textureCoordinates;
        for (int k = 0; k < 4; ++k) {
            if (!std::isfinite(v[2 * k]) || !std::isfinite(v[2 * k + 1]) || std::fabs(v[2 * k]) > 1e30 ||
                std::fabs(v[2 * k + 1]) > 1e30)
                diag_.fail(r.line, "TextureCoordinates: the coordinates must be finite numbers");
            tc.st[k] = {float(v[2 * k]), float(v[2 * k + 1])};
        }
    }

    // ---- attributes (RI spec 3.2, sec. 4.2) -----------------------------------------------------
    // Known: "identifier" "name"; "light" "shadows" "on"|"off" (BMRT, Aqsis: whether lights declared
    // afterwards cast shadows); "shadow" "resolution" "shadingrate" "bias" "filterwidth" (their shadow
    // maps' parameters, docs/shading.md).
    void attribute(const Request& r, const Arguments& args) {
        args.atLeast(1, "name ...parameterlist...");
        const std::string& name = args.string(0);
        auto ps = parseParams(r, 1, decls_, diag_);
        if (name == "identifier") {
            for (const Param& p : ps) {
                if (p.name == "name") {
                    state_.attributes().identifier = paramString(r, p, diag_);
                    state_.attributes().object.reset();  // the primitives that follow: that name's object
                } else
                    warnIgnoredParam(p, "Attribute \"identifier\"", diag_);
            }
            return;
        }
        if (name == "light") {
            for (const Param& p : ps) {
                if (p.name != "shadows") {
                    warnIgnoredParam(p, "Attribute \"light\"", diag_);
                    continue;
                }
                const std::string v = paramString(r, p, diag_);
                if (v != "on" && v != "off")
                    diag_.fail(p.value->line,
                               "Attribute \"light\": \"shadows\" must be \"on\" or \"off\", found \"" +
                                   printable(v) + "\"");
                state_.attributes().lightShadows = v == "on";
            }
            return;
        }
        if (name == "displacementbound") {
            displacementBound(r, ps);
            return;
        }
        if (name == "shadow") {
            // The shadow map of the lights declared from here on: each parameter's range (docs/shading.md).
            struct Field {
                const char* name;
                float lo, hi;
                bool integer;
            };
            static const Field kFields[] = {{"resolution", 8, 16384, true},
                                            {"shadingrate", 0.01f, 1e4f, false},
                                            {"bias", 0, 1e4f, false},
                                            {"filterwidth", 1, 64, false}};
            ShadowMapParams& sm = state_.attributes().shadowMap;
            for (const Param& p : ps) {
                const Field* f = nullptr;
                for (const Field& k : kFields)
                    if (p.name == k.name) f = &k;
                if (!f) {
                    warnIgnoredParam(p, "Attribute \"shadow\"", diag_);
                    continue;
                }
                const float v = paramFloat(r, p, diag_);
                const bool automatic = p.name == "resolution" && v == 0;  // 0: the renderer's default
                if (!automatic && (!(v >= f->lo && v <= f->hi) || (f->integer && v != std::floor(v))))
                    diag_.fail(p.value->line, "Attribute \"shadow\": \"" + p.name + "\" must be " +
                                                  (f->integer ? "an integer" : "a number") + " from " +
                                                  fmtNum(f->lo) + " to " + fmtNum(f->hi) +
                                                  (f->integer ? " (or 0: automatic)" : "") + ", found " +
                                                  fmtNum(v));
                if (p.name == "resolution") sm.resolution = int(v);
                if (p.name == "shadingrate") sm.shadingRate = v;
                if (p.name == "bias") sm.bias = v;
                if (p.name == "filterwidth") sm.filterWidth = v;
            }
            return;
        }
        diag_.warnOnce("attribute:" + name, r.line, "Attribute \"" + name + "\" is not supported; ignored");
    }
    // Attribute "displacementbound" "sphere" r "coordinatesystem" space (PRMan, Aqsis): displacement moves
    // points at most r units of `space` ("object" by default, "shader", "world", "camera", "current" or a
    // named CoordinateSystem); stored in world units, r times the largest stretch of space-to-world.
    void displacementBound(const Request& r, const std::vector<Param>& ps) {
        double radius = -1;
        std::string space = "object";
        for (const Param& p : ps) {
            if (p.name == "sphere") {
                if (!p.value->numeric() || p.value->nums.size() != 1)
                    diag_.fail(p.line, "Attribute \"displacementbound\": \"sphere\" takes one number");
                radius = p.value->nums[0];
                if (!std::isfinite(radius) || radius < 0 || radius > 1e30)
                    diag_.fail(p.line,
                               "Attribute \"displacementbound\": \"sphere\" must be a number >= 0, found " +
                                   fmtNum(radius));
            } else if (p.name == "coordinatesystem") {
                space = paramString(r, p, diag_);
            } else {
                warnIgnoredParam(p, "Attribute \"displacementbound\"", diag_);
            }
        }
        if (radius < 0) diag_.fail(r.line, "Attribute \"displacementbound\": missing \"sphere\" r");
        Mat4 worldFromSpace;
        if (space == "object" || space == "shader")
            worldFromSpace = state_.transform().at(scene_.camera.shutterOpen);
        else if (space == "camera" || space == "current")
            worldFromSpace = scene_.camera.cameraFromWorld.inverse();
        else if (const Transform* named = state_.coordinateSystem(space))
            worldFromSpace = named->at(scene_.camera.shutterOpen);
        else if (space != "world")
            diag_.fail(r.line, "Attribute \"displacementbound\": unknown coordinate system \"" +
                                   printable(space) + "\"");
        const double world = radius * worldFromSpace.maxStretch();
        if (!(world < 1e30))
            diag_.fail(r.line, "Attribute \"displacementbound\": the bound overflows in world space");
        state_.attributes().displacementBound = float(world);
    }
    // GeometricApproximation type value (RI spec 3.2, sec. 4.2.5): "motionfactor" and "focusfactor" (PRMan,
    // Aqsis) coarsen the shading of blurred geometry; "flatness" and others are not used.
    void geometricApproximation(const Request& r, const Arguments& args) {
        args.count(2, "type value");
        const std::string& type = args.string(0);
        const double v = args.number(1);
        if (type == "motionfactor" || type == "focusfactor") {
            if (!(v >= 0 && v < 1e30))
                diag_.fail(r.args[1].line,
                           "GeometricApproximation \"" + type + "\" must be >= 0, got " + fmtNum(v));
            (type == "motionfactor" ? state_.attributes().motionFactor : state_.attributes().focusFactor) =
                float(v);
            return;
        }
        diag_.warnOnce("geomapprox:" + type, r.line,
                       "GeometricApproximation \"" + printable(type) + "\" is not supported; ignored");
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
        // paintedplastic's "texturename" (RI spec 3.2, appendix A): Cs * texture(texturename); "" is none.
        // shinymetal's names an environment map, which is not supported yet (warned as ignored).
        const std::string what = "Surface \"" + name + "\"";
        std::vector<Param> rest;
        for (const Param& p : ps) {
            if (p.name == "texturename" && shader->type == MaterialType::PaintedPlastic) {
                const std::string file = paramString(r, p, diag_);
                if (!file.empty()) m.texture = int32_t(textureIndex(p.line, file, what));
            } else {
                rest.push_back(p);
            }
        }
        applyShaderParams(shader->params, r, rest, m, what, diag_);
        if (m.type == MaterialType::Glossy) {
            if (!(m.glossSamples >= 1.f && m.glossSamples <= 4096.f) ||
                m.glossSamples != std::floor(m.glossSamples))
                diag_.fail(r.line, what + ": \"samples\" must be an integer from 1 to 4096, found " +
                                       fmtNum(m.glossSamples));
            if (!(m.spread <= 10.f))
                diag_.fail(r.line,
                           what + ": \"spread\" must be at most 10 (negative: from \"roughness\"), found " +
                               fmtNum(m.spread));
        }
        state_.attributes().surface = m;
    }
    // Displacement (RI spec 3.2, sec. 4.2.3 and appendix A): "bumpy" "Km" k "texturename" "file" (P += Km *
    // texture * normalize(N)), Tessera's "offset" "Km" d (a constant amplitude; RI has no standard shader for
    // it), "null" (none). Any other name is warned about once and renders undisplaced.
    void displacement(const Request& r, const Arguments& args) {
        args.atLeast(1, "name ...parameterlist...");
        const std::string& name = args.string(0);
        auto ps = parseParams(r, 1, decls_, diag_);
        if (name == "null" || name.empty()) {
            state_.attributes().displacement = -1;
            return;
        }
        const DisplacementShaderInfo* info = tessera::findDisplacementShader(name);
        if (!info) {
            // As an unknown Surface: said once, not silently (RIB files from elsewhere name their own
            // shaders, e.g. the Killeroo's "disp_textured"); the surface is rendered undisplaced.
            std::string known;
            for (const DisplacementShaderInfo& d : displacementShaders())
                known += " \"" + std::string(d.name) + "\"";
            diag_.warnOnce("displacement:" + name, r.line,
                           "displacement shader \"" + printable(name) + "\" is not supported (Tessera has" +
                               known + "); the surfaces that follow are rendered undisplaced");
            state_.attributes().displacement = -1;
            return;
        }
        DisplacementShader d;
        d.type = info->type;
        const std::string what = "Displacement \"" + name + "\"";
        for (const Param& p : ps) {
            if (p.name == "Km") {
                d.Km = paramFloat(r, p, diag_);
                if (!std::isfinite(d.Km) || std::fabs(d.Km) > 1e30f)
                    diag_.fail(p.line, what + ": \"Km\" must be a finite number");
            } else if (p.name == "texturename" && d.type == DisplacementType::Bumpy) {
                const std::string file = paramString(r, p, diag_);
                if (!file.empty()) d.texture = int32_t(textureIndex(p.line, file, what));
            } else {
                warnIgnoredParam(p, what, diag_);
            }
        }
        if (d.type == DisplacementType::Bumpy && d.texture < 0)
            diag_.warnOnce("bumpynotexture", r.line,
                           what +
                               " without a \"texturename\" does not move the surface (RI bumpy); "
                               "Displacement \"offset\" \"Km\" d displaces by a constant d");
        size_t i = 0;
        while (i < scene_.displacements.size() && !(scene_.displacements[i] == d)) ++i;
        if (i == scene_.displacements.size()) scene_.displacements.push_back(d);
        state_.attributes().displacement = int32_t(i);
    }

    // LightSource (RI spec 3.2, sec. 4.2.2): the light's "shader space" is the current object space.
    void lightSource(const Request& r, const Arguments& args) { declareLight(r, args, false); }
    // AreaLightSource (RI spec 3.2, sec. 4.2.2): a light whose geometry is the surfaces declared after it
    // up to the end of the current attribute block; they emit its intensity * lightcolor as radiance.
    void areaLightSource(const Request& r, const Arguments& args) { declareLight(r, args, true); }
    void declareLight(const Request& r, const Arguments& args, bool area) {
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
        if ((shader->type == LightType::Area) != area) {
            diag_.warn(r.line,
                       area ? "AreaLightSource \"" + name +
                                  "\" is not an area light shader (the standard one is \"arealight\"); "
                                  "light ignored"
                            : "LightSource \"" + name +
                                  "\": an area light is declared with AreaLightSource; light ignored");
            return;
        }
        const std::string what = std::string(area ? "AreaLightSource" : "LightSource") + " \"" + name + "\"";
        // The shadowing lights' map names (strings, so not in the shader's table).
        std::array<std::string, 6> mapNames;
        std::array<int, 6> mapLines{};
        std::vector<Param> rest;
        for (const Param& p : ps) {
            int face = -1;
            if (shader->shadowNames == rib::ShadowNames::One && p.name == rib::kShadowNameParam) face = 0;
            for (int f = 0; f < 6 && shader->shadowNames == rib::ShadowNames::Cube; ++f)
                if (p.name == rib::kCubeShadowNameParams[f]) face = f;
            if (face < 0) {
                rest.push_back(p);
                continue;
            }
            mapNames[size_t(face)] = paramString(r, p, diag_);
            mapLines[size_t(face)] = p.line;
        }
        LightShaderParams params;
        applyShaderParams(shader->params, r, rest, params, what, diag_);
        if (!(params.width > 0.f && params.width <= 32.f))
            diag_.fail(r.line, what + ": \"width\" must be above 0 and at most 32");
        if (area && !(params.samples >= 1 && params.samples <= 65536))
            diag_.fail(r.line, "AreaLightSource: \"samples\" must be between 1 and 65536");
        Light light;
        light.type = shader->type;
        light.color = params.lightcolor * params.intensity;
        // Lights do not move: a light under a moving transformation is placed where it is at shutter open.
        const Mat4 m = state_.transform().at(scene_.camera.shutterOpen);
        if (state_.transform().moving())
            diag_.warnOnce(
                "movinglight", r.line,
                "LightSource under a moving transformation: lights do not move, placed at shutter open");
        light.from = m.point(params.from);
        light.to = m.point(params.to);
        light.coneAngle = params.coneangle;
        light.coneDeltaAngle = params.conedeltaangle;
        light.beamDistribution = params.beamdistribution;
        light.castsShadows = state_.attributes().lightShadows && light.type != LightType::Ambient;
        light.shadowMap = state_.attributes().shadowMap;
        light.samples = int(params.samples);
        if (area) {
            light.castsShadows =
                true;  // soft shadows are what an area light is for (--shadows off still rules)
            state_.attributes().areaLight = int32_t(scene_.lights.size());
        }
        // shadowspot, shadowdistant, shadowpoint: a map name makes the light cast shadows from that file
        // ("raytrace": shadow rays in both engines, as PRMan reads it); no name leaves the light to the
        // "shadows" attribute, as for the plain lights.
        bool anyName = false, traced = false, files = false;
        for (size_t f = 0; f < 6; ++f) {
            if (mapNames[f].empty()) continue;
            anyName = true;
            if (mapNames[f] == "raytrace") {
                traced = true;
                continue;
            }
            files = true;
            light.shadowFiles[f] = int32_t(shadowMapIndex(mapLines[f], mapNames[f], what));
        }
        if (traced && files) diag_.fail(r.line, what + ": the shadow map names mix \"raytrace\" with files");
        if (anyName) {
            light.castsShadows = true;
            light.shadowSource = traced ? ShadowSource::RayTraced : ShadowSource::File;
            light.shadowWidth = params.width;
        }
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
    // The matrix of Translate, Rotate, Scale, ConcatTransform or Transform (one key of a motion block).
    Mat4 transformMatrix(const Request& r, const Arguments& args) const {
        if (r.name == "Translate") {
            auto v = args.numbers(3, "dx dy dz");
            return Mat4::translate(v[0], v[1], v[2]);
        }
        if (r.name == "Rotate") {
            auto v = args.numbers(4, "angle dx dy dz");
            if (v[1] == 0 && v[2] == 0 && v[3] == 0)
                diag_.fail(r.line, "Rotate: the axis is the zero vector");
            return Mat4::rotate(v[0], v[1], v[2], v[3]);
        }
        if (r.name == "Scale") {
            auto v = args.numbers(3, "sx sy sz");
            return Mat4::scale(v[0], v[1], v[2]);
        }
        auto v = args.numbers(16, "a 4x4 matrix");  // ConcatTransform, Transform
        return Mat4::fromRib(v.data());
    }
    // Inside the world the CTM maps object to world space, so Transform is relative to the world.
    void transform(const Request& r, const Arguments& args) {
        state_.transform() = Transform(transformMatrix(r, args));
    }
    // ConcatTransform, Translate, Rotate, Scale.
    void concatenate(const Request& r, const Arguments& args) {
        state_.transform().concatenate(transformMatrix(r, args));
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
    PrimitiveContext primitiveContext() {
        state_.primitiveObject(scene_.objectCount);
        return {scene_,
                state_,
                decls_,
                diag_,
                -1,
                raster_.given() ? raster_.width : 0,
                raster_.given() ? raster_.height : 0,
                &materials_,
                &orientation_};
    }
    void primitive(const Request& r, const Arguments&) {
        if (&r == replayedRequest_ && r.name != "SubdivisionMesh") {
            // A replayed request whose shape was read under the same declarations, basis and texture
            // coordinates: the same shape again (ShapeKey), without reading it.
            const ShapeKey key = shapeKey();
            const auto it = replayedShapes_.find(&r);
            if (it != replayedShapes_.end() && it->second.key == key) {
                primitiveContext();  // the primitive's object id, as reading it assigns one
                addPrimitive(it->second.shape, {}, primitiveContext());
                return;
            }
            std::vector<PrimitiveShape> shape;
            shape.push_back(readPrimitiveShape(r, primitiveContext()));
            addPrimitive(shape, {}, primitiveContext());
            replayedShapes_[&r] = {key, std::move(shape)};
            return;
        }
        std::vector<PrimitiveShape> shape;
        shape.push_back(readPrimitiveShape(r, primitiveContext()));
        addPrimitive(shape, {}, primitiveContext());
    }
    // What a primitive's shape (object space, before the CTM: rib_geometry.h) depends on besides its
    // request: the declarations, the basis and texture coordinates of the graphics state and whether the
    // reader is inside the world. SubdivisionMesh also depends on the CTM (it is refined for its size in
    // the image), so it is never reused.
    struct ShapeKey {
        uint64_t declarations = 0;
        Basis uBasis{}, vBasis{};
        PatchTexCoords textureCoordinates;
        bool inWorld = false;
        bool operator==(const ShapeKey& o) const {
            auto sameBasis = [](const Basis& a, const Basis& b) {
                if (a.step != b.step) return false;
                for (int i = 0; i < 4; ++i)
                    for (int j = 0; j < 4; ++j)
                        if (!(a.m[i][j] == b.m[i][j])) return false;
                return true;
            };
            for (int k = 0; k < 4; ++k)
                if (!(textureCoordinates.st[k].x == o.textureCoordinates.st[k].x) ||
                    !(textureCoordinates.st[k].y == o.textureCoordinates.st[k].y))
                    return false;
            return declarations == o.declarations && inWorld == o.inWorld && sameBasis(uBasis, o.uBasis) &&
                   sameBasis(vBasis, o.vBasis);
        }
    };
    ShapeKey shapeKey() const {
        const auto& a = state_.attributes();
        return {decls_.version(), a.uBasis, a.vBasis, a.textureCoordinates, state_.inWorld()};
    }
    struct ReplayedShape {
        ShapeKey key;
        std::vector<PrimitiveShape> shape;
    };
    void quadric(const Request& r, const Arguments&) { addQuadric(r, primitiveContext()); }

    // ---- motion blocks (RI spec 3.2, sec. 6) -----------------------------------------------------
    // MotionBegin [t0 t1 ...] ... MotionEnd: every request in the block gives one key, in the order of the
    // times. Transformations (Translate, Rotate, Scale, ConcatTransform, Transform) make the CTM move
    // (before WorldBegin: the camera); primitives given once per time with the same topology deform.
    struct MotionBlock {
        std::vector<double> times;
        std::string file;
        int line = 0;
        std::string kind;  // the first request's name
        int kindLine = 0;
        size_t count = 0;                              // requests so far
        std::vector<Mat4> matrices;                    // transformation keys
        std::vector<std::array<double, 4>> rotations;  // Rotate keys: angle dx dy dz
        std::vector<PrimitiveShape> shapes;            // deformation keys
    };
    void motionBegin(const Request& r, const Arguments&) {
        MotionBlock m;
        m.file = diag_.file();
        m.line = r.line;
        for (const Value& v : r.args) {
            if (!v.numeric())
                diag_.fail(v.line, "MotionBegin: the times must be numbers, found " + describe(v));
            m.times.insert(m.times.end(), v.nums.begin(), v.nums.end());
        }
        if (m.times.size() < 2)
            diag_.fail(r.line, "MotionBegin needs at least 2 times, got " + std::to_string(m.times.size()));
        if (m.times.size() > kMaxMotionKeys)
            diag_.fail(r.line, "MotionBegin: more than " + std::to_string(kMaxMotionKeys) + " times");
        for (size_t i = 0; i < m.times.size(); ++i) {
            if (!std::isfinite(m.times[i]) || std::fabs(m.times[i]) > 1e30)
                diag_.fail(r.line, "MotionBegin: the times must be finite numbers");
            if (i > 0 && !(float(m.times[i]) > float(m.times[i - 1])))
                diag_.fail(r.line, "MotionBegin: the times must increase, but " + fmtNum(m.times[i]) +
                                       " follows " + fmtNum(m.times[i - 1]));
        }
        if (state_.inWorld()) checkShutterTimes(m);  // Shutter is known (it cannot change in the world)
        motion_ = std::move(m);
    }
    // With an open shutter (close > open) every key must lie inside it. A closed shutter (the RI default
    // 0 0) renders no blur: the keys are kept (--shutter may open it) and the scene is at shutter open,
    // clamped to the keys.
    void checkShutterTimes(const MotionBlock& m) const {
        const Camera& c = scene_.camera;
        if (!c.hasShutter()) return;
        for (double t : m.times)
            if (float(t) < c.shutterOpen || float(t) > c.shutterClose)
                throw InputError(m.file, m.line,
                                 "MotionBegin: time " + fmtNum(t) + " is outside the shutter interval [" +
                                     fmtNum(c.shutterOpen) + ", " + fmtNum(c.shutterClose) + "] (Shutter)");
    }
    static bool isMovingTransform(const std::string& n) {
        return n == "Translate" || n == "Rotate" || n == "Scale" || n == "ConcatTransform" ||
               n == "Transform";
    }
    // RI spec 3.2, sec. 6 lists the requests a motion block may hold: transformations, geometric primitives
    // and shading requests. Of those, moving shading (Color, Opacity, Surface, LightSource) is read at its
    // first key with a warning; ones this reader does not support at all (Skew, Perspective, Sphere, ...)
    // are ignored with the usual warning. Anything else (attribute and transform blocks, options, Identity,
    // ShadingRate, ...) is an error, like a nested MotionBegin.
    void motionRequest(const Request& r, Handler h) {
        MotionBlock& m = *motion_;
        const std::string where =
            " (the motion block opened at " + m.file + ":" + std::to_string(m.line) + ")";
        if (r.name == "MotionBegin") diag_.fail(r.line, "nested MotionBegin" + where + " is still open");
        static const std::set<std::string> shading = {"Color", "Opacity", "Surface", "LightSource",
                                                      "Displacement"};
        static const std::set<std::string> riMoving = {"Skew",           "Perspective",
                                                       "Deformation",    "Displacement",
                                                       "Interior",       "Exterior",
                                                       "Atmosphere",     "AreaLightSource",
                                                       "Bound",          "Detail",
                                                       "Polygon",        "GeneralPolygon",
                                                       "PointsPolygons", "PointsGeneralPolygons",
                                                       "Sphere",         "Cone",
                                                       "Cylinder",       "Hyperboloid",
                                                       "Paraboloid",     "Disk",
                                                       "Torus",          "Points",
                                                       "Curves",         "Blobby",
                                                       "TrimCurve"};
        const bool transform = isMovingTransform(r.name), primitive = isPrimitiveRequest(r.name),
                   shade = shading.count(r.name) > 0, quadric = isQuadricRequest(r.name),
                   unsupported = !h && riMoving.count(r.name) > 0;
        if (!h && !unsupported) {  // not a RI request we know: ignored as anywhere else
            diag_.warnOnce("request:" + r.name, r.line,
                           "unknown or unsupported request '" + r.name + "' ignored");
            return;
        }
        if (!transform && !primitive && !shade && !quadric && !unsupported)
            diag_.fail(r.line, r.name + " is not allowed inside a motion block" + where +
                                   ": RI spec 3.2, sec. 6 allows only transformations, geometric primitives "
                                   "and shading requests there");
        if (m.count == 0) {
            m.kind = r.name;
            m.kindLine = r.line;
        } else if (r.name != m.kind) {
            diag_.fail(r.line, "motion block mixes " + m.kind + " (line " + std::to_string(m.kindLine) +
                                   ") and " + r.name + where +
                                   ": all requests in a motion block must be the same (RI spec 3.2, sec. 6)");
        }
        if (m.count == m.times.size())
            diag_.fail(r.line, "more " + r.name + " requests than the " + std::to_string(m.times.size()) +
                                   " times of MotionBegin" + where);
        ++m.count;
        Arguments args(r, diag_);
        if (transform) {
            m.matrices.push_back(transformMatrix(r, args));
            if (r.name == "Rotate") {
                auto v = args.numbers(4, "angle dx dy dz");
                m.rotations.push_back({v[0], v[1], v[2], v[3]});
            }
        } else if (primitive) {
            PrimitiveContext context = primitiveContext();
            if (!m.shapes.empty() && m.shapes.front().subdivLevel > 0)
                context.subdivLevel = m.shapes.front().subdivLevel;  // the same patches in every key
            PrimitiveShape key =
                readPrimitiveShape(r, context, m.shapes.empty() ? nullptr : &m.shapes.front());
            m.shapes.push_back(std::move(key));
            const PrimitiveShape &a = m.shapes.front(), &b = m.shapes.back();
            if (b.topology != a.topology || b.topologyHash != a.topologyHash ||
                (!a.skipped && !b.skipped && a.patches.size() != b.patches.size()))
                diag_.fail(r.line,
                           "deformation keys must have the same topology" + where + ": key " +
                               std::to_string(m.count) + " is " + b.topology + ", key 1 (line " +
                               std::to_string(a.line) + ") is " + a.topology +
                               (b.topology == a.topology ? " with other vertex indices, knots or tags" : ""));
        } else if (m.count == 1) {
            if (shade)
                diag_.warnOnce(
                    "motion:" + r.name, r.line,
                    r.name + " in a motion block: moving shading is not supported; the first key is used");
            if (quadric)
                diag_.warnOnce("motion:" + r.name, r.line,
                               r.name +
                                   " in a motion block: moving quadrics are not supported; the first key "
                                   "is used");
            if (h)
                (this->*h)(r, args);
            else
                diag_.warnOnce("request:" + r.name, r.line,
                               "unknown or unsupported request '" + r.name + "' ignored");
        }
    }
    void motionEnd(const Request& r, const Arguments& args) {
        args.count(0, "no arguments");
        if (!motion_) diag_.fail(r.line, "MotionEnd without a matching MotionBegin");
        MotionBlock m = std::move(*motion_);
        motion_.reset();
        if (state_.inWorld() && !scene_.camera.hasShutter())
            diag_.warnOnce("closedshutter", r.line,
                           "motion block with a closed shutter (Shutter " +
                               fmtNum(scene_.camera.shutterOpen) + " " + fmtNum(scene_.camera.shutterClose) +
                               "): no motion blur, the scene is rendered at shutter open");
        if (m.count != m.times.size())
            diag_.fail(r.line, "the motion block opened at " + m.file + ":" + std::to_string(m.line) +
                                   " has " + std::to_string(m.times.size()) + " times but " +
                                   std::to_string(m.count) + " requests");
        if (isMovingTransform(m.kind)) {
            std::vector<TransformKey> keys;
            for (size_t i = 0; i < m.times.size(); ++i) {
                // Rotate keys about the same axis interpolate their angle, so that a turn of 180 degrees or
                // more between two keys (Rotate 0 ... Rotate 360) keeps its direction and size: keys every 90
                // degrees in between, which the decomposed interpolation then follows exactly.
                if (i > 0 && !m.rotations.empty()) {
                    const auto &a = m.rotations[i - 1], &b = m.rotations[i];
                    const double la = std::sqrt(a[1] * a[1] + a[2] * a[2] + a[3] * a[3]),
                                 lb = std::sqrt(b[1] * b[1] + b[2] * b[2] + b[3] * b[3]);
                    const bool sameAxis =
                        a[1] / la == b[1] / lb && a[2] / la == b[2] / lb && a[3] / la == b[3] / lb;
                    const double pieces = std::ceil(std::fabs(b[0] - a[0]) / 90.0);
                    if (sameAxis && pieces > 1) {
                        if (pieces + double(keys.size()) > double(kMaxMotionKeys))
                            diag_.fail(r.line, "MotionEnd: the Rotate keys turn by more than " +
                                                   std::to_string(90 * kMaxMotionKeys) + " degrees");
                        for (int k = 1; k < int(pieces); ++k) {
                            const double w = k / pieces;
                            keys.push_back({m.times[i - 1] + w * (m.times[i] - m.times[i - 1]),
                                            Mat4::rotate(a[0] + w * (b[0] - a[0]), a[1], a[2], a[3])});
                        }
                    }
                }
                keys.push_back({m.times[i], m.matrices[i]});
            }
            const Transform moving = Transform::moving(std::move(keys));
            if (!moving.isFinite()) diag_.fail(r.line, "MotionEnd: a transformation key is not finite");
            if (m.kind == "Transform")
                state_.transform() = moving;
            else
                state_.transform().concatenate(moving);
            if (!state_.inWorld() && moving.moving()) cameraMotion_.push_back(std::move(m));
        } else if (isPrimitiveRequest(m.kind)) {
            addPrimitive(m.shapes, m.times, primitiveContext());
        }
    }

    // ---- retained geometry (RI spec 3.2, sec. 5, "Retained Geometry") -----------------------------
    // ObjectBegin handle ... ObjectEnd records the requests of an object; ObjectInstance handle replays them
    // inside an implicit attribute block, under the transformation and attributes current at the instance
    // (RI: "the object inherits the current set of attributes"); transformations and attributes inside the
    // definition are relative to / override those (as PRMan, which resets the graphics state at
    // ObjectBegin). The CTM at ObjectBegin plays no part. Every instance is a copy of the object's surfaces
    // in the scene.
    struct RetainedObject;
    struct RecordedRequest {
        Request request;
        std::string file;
        std::shared_ptr<const RetainedObject> instance;  // ObjectInstance inside a definition, resolved
    };
    struct RetainedObject {
        std::string file;
        int line = 0;
        uint32_t id = 0;  // SurfaceInstance::object
        std::vector<RecordedRequest> requests;
    };
    struct Definition {
        std::string handle;
        std::shared_ptr<RetainedObject> object;
        int archiveDepth = 0;
        std::vector<std::pair<std::string, int>> blocks;  // open AttributeBegin/TransformBegin/MotionBegin
    };
    // The key of an object handle: RI 3.2's sequence number or a later PRMan's string.
    std::string objectHandle(const Request& r) const {
        if (r.args.size() != 1 || r.args[0].isArray())
            diag_.fail(r.line, r.name + " expects one object handle (a number or a string), got " +
                                   std::to_string(r.args.size()) + " arguments");
        const Value& v = r.args[0];
        if (v.numeric()) {
            const double n = v.nums[0];
            if (!(n == std::floor(n)) || std::fabs(n) > 1e9)
                diag_.fail(v.line,
                           r.name + ": the object handle must be an integer or a string, got " + fmtNum(n));
            return std::to_string(long(n));
        }
        return "\"" + v.strs[0] + "\"";
    }
    void objectBegin(const Request& r, const Arguments&) {
        Definition d;
        d.handle = objectHandle(r);
        d.object = std::make_shared<RetainedObject>();
        d.object->file = diag_.file();
        d.object->line = r.line;
        d.object->id = objectDefinitions_++;
        d.archiveDepth = archiveDepth_;
        defining_ = std::move(d);
    }
    void objectEnd(const Request& r, const Arguments& args) {
        args.count(0, "no arguments");
        if (!defining_) diag_.fail(r.line, "ObjectEnd without a matching ObjectBegin");
        if (!defining_->blocks.empty())
            diag_.fail(r.line, "ObjectEnd while " + defining_->blocks.back().first + " (line " +
                                   std::to_string(defining_->blocks.back().second) + ") is still open");
        objects_[defining_->handle] = std::move(defining_->object);  // a handle defined again is replaced
        defining_.reset();
    }
    // Inside a definition: geometry, transformations, attribute and transform blocks, motion blocks and
    // attributes are recorded; Declare and ReadArchive are carried out now; anything else is an error.
    void recordObjectRequest(const Request& r, Handler h) {
        Definition& d = *defining_;
        const std::string where = " (the object definition opened at " + d.object->file + ":" +
                                  std::to_string(d.object->line) + ")";
        if (r.name == "ObjectBegin") diag_.fail(r.line, "nested ObjectBegin" + where + " is still open");
        if (r.name == "Declare") {
            (this->*h)(r, Arguments(r, diag_));
            return;
        }
        static const std::set<std::string> allowed = {"Translate",
                                                      "Rotate",
                                                      "Scale",
                                                      "ConcatTransform",
                                                      "Transform",
                                                      "AttributeBegin",
                                                      "AttributeEnd",
                                                      "TransformBegin",
                                                      "TransformEnd",
                                                      "MotionBegin",
                                                      "MotionEnd",
                                                      "Color",
                                                      "Opacity",
                                                      "Surface",
                                                      "Displacement",
                                                      "ShadingRate",
                                                      "Sides",
                                                      "Orientation",
                                                      "ReverseOrientation",
                                                      "Attribute",
                                                      "Basis",
                                                      "TextureCoordinates",
                                                      "GeometricApproximation",
                                                      "ObjectInstance"};
        if (!h) {
            diag_.warnOnce("request:" + r.name, r.line,
                           "unknown or unsupported request '" + r.name + "' ignored");
            return;
        }
        if (!allowed.count(r.name) && !isPrimitiveRequest(r.name) && !isQuadricRequest(r.name))
            diag_.fail(r.line, r.name + " is not allowed inside an object definition" + where +
                                   ": only geometry, transformations and attributes are retained");
        static const std::map<std::string, std::string> closes = {{"AttributeEnd", "AttributeBegin"},
                                                                  {"TransformEnd", "TransformBegin"},
                                                                  {"MotionEnd", "MotionBegin"}};
        if (r.name == "AttributeBegin" || r.name == "TransformBegin" || r.name == "MotionBegin") {
            if (r.name == "MotionBegin")
                for (const auto& b : d.blocks)
                    if (b.first == "MotionBegin")
                        diag_.fail(r.line, "nested MotionBegin (line " + std::to_string(b.second) +
                                               ") is still open");
            d.blocks.emplace_back(r.name, r.line);
        } else if (auto c = closes.find(r.name); c != closes.end()) {
            if (d.blocks.empty() || d.blocks.back().first != c->second)
                diag_.fail(r.line, r.name + " without a matching " + c->second +
                                       " inside the object definition" + where);
            d.blocks.pop_back();
        }
        RecordedRequest rec{r, diag_.file(), nullptr};
        if (r.name == "ObjectInstance") rec.instance = findObject(r);
        d.object->requests.push_back(std::move(rec));
    }
    std::shared_ptr<const RetainedObject> findObject(const Request& r) const {
        const std::string handle = objectHandle(r);
        auto it = objects_.find(handle);
        if (it == objects_.end())
            diag_.fail(r.line,
                       "ObjectInstance: no object with handle " + handle + " was defined (ObjectBegin)");
        return it->second;
    }
    void objectInstance(const Request& r, const Arguments&) {
        if (!state_.inWorld()) diag_.fail(r.line, "ObjectInstance outside WorldBegin/WorldEnd");
        const std::shared_ptr<const RetainedObject> object = findObject(r);
        // Record which surfaces the instance made and where it stands, so that an engine can share
        // structures between the instances of one object (a moving instance is a plain copy).
        const bool record = instanceDepth_ == 0 && !state_.transform().moving();
        SurfaceInstance placed;
        placed.first = uint32_t(scene_.patches.size());
        placed.object = object->id;
        if (record) placed.objectToWorld = state_.transform().at(0.0);
        instantiate(*object, r);
        placed.count = uint32_t(scene_.patches.size() - placed.first);
        if (record && placed.count > 0) scene_.instances.push_back(placed);
    }
    void instantiate(const RetainedObject& object, const Request& at) {
        if (instanceDepth_ + 1 > kMaxArchiveDepth)
            diag_.fail(at.line, "ObjectInstance nested more than " + std::to_string(kMaxArchiveDepth) +
                                    " levels deep");
        ++instanceDepth_;
        const std::string file = diag_.file();
        state_.begin(Block::Attribute, file, at.line);
        for (const RecordedRequest& rec : object.requests) {
            diag_.setFile(rec.file);
            if (rec.instance && !motion_)
                instantiate(*rec.instance, rec.request);
            else
                execute(rec.request, handler(rec.request.name));
        }
        diag_.setFile(file);
        state_.end(Block::Attribute, Request{"ObjectInstance", at.line, {}}, diag_);
        --instanceDepth_;
    }

    // ---- ReadArchive (RI spec 3.2, sec. 8.1) -----------------------------------------------------
    void readArchive(const Request& r, const Arguments& args) {
        args.count(1, "filename");
        const std::string& name = args.string(0);
        namespace fs = std::filesystem;
        if (archiveDepth_ + 1 > kMaxArchiveDepth)
            diag_.fail(r.line, "ReadArchive nested more than " + std::to_string(kMaxArchiveDepth) +
                                   " levels deep (recursive include?)");
        // Relative names: through Option "searchpath" "archive", by default the directory of the including
        // file; the first directory that holds the file wins.
        std::error_code ec;
        std::string path;
        if (fs::path(name).is_absolute()) {
            path = name;
            if (!fs::is_regular_file(path, ec))
                diag_.fail(r.line, "ReadArchive: cannot open \"" + path + "\"");
        } else if (archiveSearchPath_.empty()) {
            path = relativeToFile(name);
            if (!fs::is_regular_file(path, ec))
                diag_.fail(r.line, "ReadArchive: cannot open \"" + path + "\"");
        } else {
            std::string where;
            for (const std::string& d : archiveSearchPath_) {
                const fs::path candidate = d.empty() ? fs::path(name) : fs::path(d) / name;
                where += (where.empty() ? "" : ":") + (d.empty() ? std::string(".") : d);
                if (path.empty() && fs::is_regular_file(candidate, ec)) path = candidate.string();
            }
            if (path.empty())
                diag_.fail(r.line, "ReadArchive: cannot open \"" + printable(name, 200) +
                                       "\": not found in the archive search path " + where);
        }
        // A file is recorded as it is parsed (on its first read while the budget below allows, else on its
        // second), and replayed from then on: the same requests, so the same scene and messages (the file is
        // taken not to change during one load). Its requests are run again as collected (no lexing, no
        // argument collection: 28% of loading 24 Big Guys from one archive); a file whose recording was
        // skipped in part replays its tokens instead.
        ArchiveReads& reads = archives_[path];
        // Read before the reader moves into the file: a failure is the ReadArchive line's.
        std::string text;
        if (!reads.requests && !reads.tokens) {
            try {
                text = readInputFile(path);
            } catch (const InputError&) {
                diag_.fail(r.line, "ReadArchive: cannot read \"" + path + "\"");
            }
        }
        const std::string outerFile = std::exchange(currentFile_, path);
        diag_.setFile(path);
        ++archiveDepth_;
        if (reads.requests) {
            replay(*reads.requests);
        } else {
            std::optional<RibLexer> lexer;
            std::unique_ptr<LexedFile> tokens;
            std::unique_ptr<RecordedArchive> requests;
            if (reads.tokens) {
                lexer.emplace(reads.tokens, path);
            } else {
                // Recorded on its second read; on its first too while the text of archives recorded on
                // their first read stays within firstReadRecordBytes_ (an archive read only once holds its
                // recording until loading ends for nothing, so their total is bounded).
                // A first read records the requests only: a read that turns out to skip a frame keeps
                // nothing, and the second read records its tokens too (recording the tokens of every
                // archive read once cost Killeroo's load 2%).
                const bool firstRecorded = reads.count == 0 && text.size() <= firstReadRecordBytes_;
                if (firstRecorded) firstReadRecordBytes_ -= text.size();
                lexer.emplace(std::move(text), path);
                if (reads.count > 0) lexer->record((tokens = std::make_unique<LexedFile>()).get());
                if (reads.count > 0 || firstRecorded) requests = std::make_unique<RecordedArchive>();
            }
            ++reads.count;
            parse(*lexer, requests.get());
            // Read to its end: keep what the next read replays.
            if (requests && requests->replayable)
                reads.requests = std::move(requests);
            else if (tokens)
                reads.tokens = std::move(tokens);
        }
        --archiveDepth_;
        currentFile_ = outerFile;
        diag_.setFile(outerFile);
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
            {"CropWindow", &RibReader::cropWindow},
            {"ScreenWindow", &RibReader::screenWindow},
            {"Clipping", &RibReader::clipping},
            {"Projection", &RibReader::projection},
            {"PixelSamples", &RibReader::pixelSamples},
            {"PixelFilter", &RibReader::pixelFilter},
            {"Exposure", &RibReader::exposure},
            {"Imager", &RibReader::imager},
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
            {"Displacement", &RibReader::displacement},
            {"LightSource", &RibReader::lightSource},
            {"AreaLightSource", &RibReader::areaLightSource},
            {"Illuminate", &RibReader::illuminate},
            {"Basis", &RibReader::basis},
            {"Declare", &RibReader::declare},
            {"Identity", &RibReader::identity},
            {"Transform", &RibReader::transform},
            {"ConcatTransform", &RibReader::concatenate},
            {"Translate", &RibReader::concatenate},
            {"Rotate", &RibReader::concatenate},
            {"Scale", &RibReader::concatenate},
            {"Shutter", &RibReader::shutter},
            {"DepthOfField", &RibReader::depthOfField},
            {"Hider", &RibReader::hider},
            {"GeometricApproximation", &RibReader::geometricApproximation},
            {"MotionBegin", &RibReader::motionBegin},
            {"MotionEnd", &RibReader::motionEnd},
            {"CoordinateSystem", &RibReader::coordinateSystem},
            {"CoordSysTransform", &RibReader::coordSysTransform},
            {"Patch", &RibReader::primitive},
            {"PatchMesh", &RibReader::primitive},
            {"NuPatch", &RibReader::primitive},
            {"SubdivisionMesh", &RibReader::primitive},
            {"Polygon", &RibReader::primitive},
            {"PointsPolygons", &RibReader::primitive},
            {"GeneralPolygon", &RibReader::primitive},
            {"PointsGeneralPolygons", &RibReader::primitive},
            {"Sphere", &RibReader::quadric},
            {"Cylinder", &RibReader::quadric},
            {"Cone", &RibReader::quadric},
            {"Disk", &RibReader::quadric},
            {"Paraboloid", &RibReader::quadric},
            {"Hyperboloid", &RibReader::quadric},
            {"Torus", &RibReader::quadric},
            {"ReadArchive", &RibReader::readArchive},
            {"ObjectBegin", &RibReader::objectBegin},
            {"ObjectEnd", &RibReader::objectEnd},
            {"ObjectInstance", &RibReader::objectInstance},
            {"MakeTexture", &RibReader::makeTextureRequest},
            {"MakeShadow", &RibReader::makeShadowRequest},
            {"TextureCoordinates", &RibReader::textureCoordinates},
        };
        auto it = handlers.find(name);
        return it == handlers.end() ? nullptr : it->second;
    }

    Scene& scene_;
    Diagnostics diag_;
    std::string currentFile_;  // the file being read (relative names resolve against its directory)
    Declarations decls_;
    GraphicsState state_;
    std::optional<std::string> skipUntil_;
    std::vector<double> numberScratch_;      // collectArray's numbers, reused from array to array
    std::optional<MotionBlock> motion_;      // the open motion block
    std::vector<MotionBlock> cameraMotion_;  // motion blocks before WorldBegin, checked against the shutter
    int framesSeen_ = 0, worldsSeen_ = 0;
    std::optional<int> frameOrdinal_;
    RasterOverride raster_;  // the resolution the caller will render at (subdivision levels), if given
    int archiveDepth_ = 0;   // ReadArchive nesting of the file being read
    struct ArchiveReads {
        int count = 0;
        // Recorded on the second read: its requests, or (when not replayable) its tokens.
        std::unique_ptr<const RecordedArchive> requests;
        std::shared_ptr<const LexedFile> tokens;
    };
    std::map<std::string, ArchiveReads> archives_;  // by resolved path
    // The recorded request being replayed (nullptr: none), and the shapes of replayed primitive requests
    // (keyed by the recorded request, whose address is fixed once its archive is recorded; a request a
    // nested read parses is not the one replayed, so it is never keyed): 24 Big Guys reads one archive
    // 24 times, and reading its patches' parameters again was 30% of loading it.
    const Request* replayedRequest_ = nullptr;
    rib::MaterialTable materials_;  // scene_.materials by value
    rib::OrientationCache orientation_;
    // What is left of the archive text that may be recorded on its first read (64 MB unless the tests set
    // it). Lexing the 24 Big Guys' archive a second time, to record it, was a fifth of loading that scene.
    size_t firstReadRecordBytes_ = gFirstReadRecordBytes.load(std::memory_order_relaxed);
    std::unordered_map<const Request*, ReplayedShape> replayedShapes_;
    std::optional<Definition> defining_;                                    // the open ObjectBegin
    std::map<std::string, std::shared_ptr<const RetainedObject>> objects_;  // by handle
    uint32_t objectDefinitions_ = 0;
    int instanceDepth_ = 0;
    // Option "searchpath" "texture" and "archive" (empty: the directory of the file that names the texture
    // or the archive); "shader" (kept, unused).
    std::vector<std::string> textureSearchPath_, archiveSearchPath_, shaderSearchPath_;
};

}  // namespace

void readRib(const std::string& path, Scene& scene, const WarningSink& warn, RasterOverride raster) {
    scene.sourcePath = path;
    RibReader reader(scene, warn, std::nullopt, raster);
    reader.run(path);
}

void readRibFrame(const std::string& path, int frameOrdinal, Scene& scene, const WarningSink& warn,
                  RasterOverride raster) {
    scene.sourcePath = path;
    RibReader reader(scene, warn, frameOrdinal, raster);
    reader.run(path);
}

std::vector<RibFrame> ribFrames(const std::string& path) {
    RibLexer lex(readInputFile(path), path);
    std::vector<RibFrame> frames;
    for (Token t = lex.next(); t.type != TokenType::End; t = lex.next()) {
        if (t.type != TokenType::Request || t.text != "FrameBegin") continue;
        RibFrame f{int(frames.size()) + 1, t.line};  // no number given: its position
        if (lex.peek().type == TokenType::Number) f.number = int(lex.next().number);
        frames.push_back(f);
    }
    return frames;
}

void readRibText(std::string text, const std::string& path, Scene& scene, const WarningSink& warn,
                 RasterOverride raster) {
    scene.sourcePath = path;
    RibReader reader(scene, warn, std::nullopt, raster);
    reader.runText(std::move(text), path);
}

}  // namespace tessera
