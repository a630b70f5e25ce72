// The OpenImageIO side of textures (shading/texture_module.h): OIIO's TextureSystem for filtered,
// mip-mapped lookups with its per-thread cache, ImageInput to check files, make_texture for MakeTexture.
// Built as the module libtessera_texture_oiio.so, loaded by shading/texture.cpp on first use.
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/texture.h>

#include <algorithm>
#include <memory>
#include <mutex>
#include <vector>

#include "shading/texture.h"
#include "shading/texture_module.h"

namespace tessera {
namespace {

// OIIO's error text without trailing newlines, or `fallback` when it has none.
std::string oiioError(const std::string& fallback) {
    std::string e = OIIO::geterror();
    while (!e.empty() && (e.back() == '\n' || e.back() == ' ')) e.pop_back();
    return e.empty() ? fallback : e;
}

struct TextureEntry {
    std::string path;
    OIIO::TextureSystem::TextureHandle* handle = nullptr;
    int channels = 3;
    OIIO::TextureOpt::Wrap wrap = OIIO::TextureOpt::WrapPeriodic;  // the file's own when it names them
    std::once_flag rangeOnce;
    float lo = 0, hi = 0;
};

struct TextureSet {
    OIIO::TextureSystem* ts = nullptr;
    std::vector<std::unique_ptr<TextureEntry>> entries;
    ~TextureSet() {
        if (ts) OIIO::TextureSystem::destroy(ts);
    }
};

void* openSet(std::span<const std::string> files, std::string& error) {
    auto set = std::make_unique<TextureSet>();
    set->ts = OIIO::TextureSystem::create(/*shared=*/false);
    OIIO::TextureSystem* ts = set->ts;
    // Plain images are tiled and mip-mapped in the cache when first read, so they filter like .tx files.
    ts->attribute("automip", 1);
    ts->attribute("autotile", 64);
    ts->attribute("max_memory_MB", 512.f);
    for (const std::string& f : files) {
        auto e = std::make_unique<TextureEntry>();
        e->path = f;
        e->handle = ts->get_texture_handle(OIIO::ustring(f));
        if (!e->handle || !ts->good(e->handle)) {
            const std::string why = ts->geterror();
            error = "cannot read texture \"" + f + "\"" + (why.empty() ? "" : ": " + why);
            return nullptr;
        }
        int nch = 0;
        if (ts->get_texture_info(e->handle, nullptr, 0, OIIO::ustring("channels"), OIIO::TypeInt, &nch) &&
            nch > 0)
            e->channels = nch;
        // A texture made by MakeTexture carries its wrap modes; a plain image repeats (periodic).
        OIIO::ustring modes;
        if (ts->get_texture_info(e->handle, nullptr, 0, OIIO::ustring("wrapmodes"), OIIO::TypeString,
                                 &modes) &&
            !modes.empty())
            e->wrap = OIIO::TextureOpt::WrapDefault;
        set->entries.push_back(std::move(e));
    }
    return set.release();
}

void closeSet(void* set) {
    delete static_cast<TextureSet*>(set);
}

int channels(const void* set, uint32_t texture) {
    return static_cast<const TextureSet*>(set)->entries[texture]->channels;
}

void lookup(const void* setp, uint32_t texture, const TextureLookup& q, int nchannels, float* out, float* dds,
            float* ddt) {
    const TextureSet& set = *static_cast<const TextureSet*>(setp);
    const TextureEntry& e = *set.entries[texture];
    OIIO::TextureOpt opt;
    opt.swrap = opt.twrap = e.wrap;
    opt.fill = 0.f;
    // The per-thread info of the calling thread (OIIO keeps one per thread and texture system).
    OIIO::TextureSystem::Perthread* thread = set.ts->get_perthread_info();
    const bool ok = set.ts->texture(e.handle, thread, opt, q.s, q.t, q.dsdx, q.dtdx, q.dsdy, q.dtdy,
                                    nchannels, out, dds, ddt);
    if (!ok) {
        std::fill(out, out + nchannels, 0.f);
        if (dds) std::fill(dds, dds + nchannels, 0.f);
        if (ddt) std::fill(ddt, ddt + nchannels, 0.f);
    }
}

void range(const void* setp, uint32_t texture, float& lo, float& hi) {
    TextureEntry& e = *static_cast<const TextureSet*>(setp)->entries[texture];
    std::call_once(e.rangeOnce, [&] {
        OIIO::ImageBuf buf(e.path);
        OIIO::ImageBufAlgo::PixelStats stats;
        if (buf.read(0, 0, 0, 1, true, OIIO::TypeFloat) &&
            (stats = OIIO::ImageBufAlgo::computePixelStats(buf), !stats.min.empty())) {
            e.lo = stats.min[0], e.hi = stats.max[0];
        } else {
            e.lo = e.hi = 0.f;
        }
    });
    lo = e.lo, hi = e.hi;
}

// One wrap mode word of OIIO's "wrapmodes" ("periodic", "clamp", "black", ...) as 0, 1, 2.
int wrapCode(const std::string& word) {
    if (word == "clamp" || word == "mirror") return 1;
    if (word == "black") return 2;
    return 0;  // periodic, default
}

bool texels(const void* setp, uint32_t texture, int& width, int& height, std::vector<float>& out, int& swrap,
            int& twrap) {
    const TextureSet& set = *static_cast<const TextureSet*>(setp);
    const TextureEntry& e = *set.entries[texture];
    OIIO::ImageBuf buf(e.path);
    if (!buf.read(0, 0, 0, 1, true, OIIO::TypeFloat)) return false;
    const OIIO::ROI roi = buf.roi();
    if (roi.width() < 1 || roi.height() < 1) return false;
    std::vector<float> px(size_t(roi.width()) * size_t(roi.height()));
    if (!buf.get_pixels(OIIO::ROI(roi.xbegin, roi.xend, roi.ybegin, roi.yend, 0, 1, 0, 1), OIIO::TypeFloat,
                        px.data()))
        return false;
    width = roi.width(), height = roi.height();
    out = std::move(px);
    swrap = twrap = 0;
    if (e.wrap == OIIO::TextureOpt::WrapDefault) {  // the file names its modes: "s,t" or one for both
        const std::string modes = buf.spec().get_string_attribute("wrapmodes");
        const size_t comma = modes.find(',');
        swrap = wrapCode(modes.substr(0, comma));
        twrap = wrapCode(comma == std::string::npos ? modes : modes.substr(comma + 1));
    }
    return true;
}

std::string readError(const std::string& path) {
    auto in = OIIO::ImageInput::open(path);
    if (!in) return oiioError("not an image OpenImageIO can read");
    const OIIO::ImageSpec& spec = in->spec();
    if (spec.width < 1 || spec.height < 1 || spec.nchannels < 1) return "the image is empty";
    return "";
}

std::string makeTexture(const std::string& picture, const std::string& texture, const std::string& swrap,
                        const std::string& twrap) {
    OIIO::ImageSpec config;
    config.attribute("wrapmodes", swrap + "," + twrap);
    config.tile_width = config.tile_height = 64;
    config.attribute("maketx:highlightcomp", 0);
    if (!OIIO::ImageBufAlgo::make_texture(OIIO::ImageBufAlgo::MakeTxTexture, picture, texture, config))
        return oiioError("OpenImageIO's make_texture failed");
    return "";
}

const TextureModuleApi kApi{
    kTextureModuleVersion, openSet, closeSet, channels, lookup, range, texels, readError, makeTexture};

}  // namespace
}  // namespace tessera

extern "C" __attribute__((visibility("default"))) const void* tessera_texture_module() {
    return &tessera::kApi;
}
