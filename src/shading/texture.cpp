#include "shading/texture.h"

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/texture.h>

#include <algorithm>
#include <cmath>
#include <mutex>
#include <stdexcept>

namespace tessera {

namespace {
// OIIO's error text without trailing newlines, or `fallback` when it has none.
std::string oiioError(const std::string& fallback) {
    std::string e = OIIO::geterror();
    while (!e.empty() && (e.back() == '\n' || e.back() == ' ')) e.pop_back();
    return e.empty() ? fallback : e;
}
}  // namespace

struct Textures::Impl {
    struct Entry {
        std::string path;
        OIIO::TextureSystem::TextureHandle* handle = nullptr;
        int channels = 3;
        OIIO::TextureOpt::Wrap wrap = OIIO::TextureOpt::WrapPeriodic;  // the file's own when it names them
        std::once_flag rangeOnce;
        float lo = 0, hi = 0;
    };
    OIIO::TextureSystem* ts = nullptr;
    std::vector<std::unique_ptr<Entry>> entries;

    float lookup(const Entry& e, const TextureLookup& q, int nchannels, float* out, float* dds = nullptr,
                 float* ddt = nullptr) const {
        OIIO::TextureOpt opt;
        opt.swrap = opt.twrap = e.wrap;
        opt.fill = 0.f;
        // The per-thread info of the calling thread (OIIO keeps one per thread and texture system).
        OIIO::TextureSystem::Perthread* thread = ts->get_perthread_info();
        const bool ok = ts->texture(e.handle, thread, opt, q.s, q.t, q.dsdx, q.dtdx, q.dsdy, q.dtdy,
                                    nchannels, out, dds, ddt);
        if (!ok) {
            std::fill(out, out + nchannels, 0.f);
            if (dds) std::fill(dds, dds + nchannels, 0.f);
            if (ddt) std::fill(ddt, ddt + nchannels, 0.f);
        }
        return out[0];
    }
};

Textures::Textures(std::span<const std::string> files) : impl_(std::make_unique<Impl>()) {
    impl_->ts = OIIO::TextureSystem::create(/*shared=*/false);
    OIIO::TextureSystem* ts = impl_->ts;
    // Plain images are tiled and mip-mapped in the cache when first read, so they filter like .tx files.
    ts->attribute("automip", 1);
    ts->attribute("autotile", 64);
    ts->attribute("max_memory_MB", 512.f);
    for (const std::string& f : files) {
        auto e = std::make_unique<Impl::Entry>();
        e->path = f;
        e->handle = ts->get_texture_handle(OIIO::ustring(f));
        if (!e->handle || !ts->good(e->handle)) {
            const std::string why = ts->geterror();
            OIIO::TextureSystem::destroy(ts);
            impl_->ts = nullptr;
            throw std::runtime_error("cannot read texture \"" + f + "\"" + (why.empty() ? "" : ": " + why));
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
        impl_->entries.push_back(std::move(e));
    }
}

Textures::~Textures() {
    if (impl_ && impl_->ts) OIIO::TextureSystem::destroy(impl_->ts);
}

size_t Textures::size() const {
    return impl_->entries.size();
}

Color Textures::color(uint32_t texture, const TextureLookup& q) const {
    const Impl::Entry& e = *impl_->entries[texture];
    float c[3] = {0, 0, 0};
    if (e.channels >= 3) {
        impl_->lookup(e, q, 3, c);
        return {c[0], c[1], c[2]};
    }
    const float g = impl_->lookup(e, q, 1, c);  // grey (and grey + alpha): the first channel
    return {g, g, g};
}

float Textures::value(uint32_t texture, const TextureLookup& q) const {
    float c[1];
    return impl_->lookup(*impl_->entries[texture], q, 1, c);
}

float Textures::value(uint32_t texture, const TextureLookup& q, float& dds, float& ddt) const {
    float c[1], ds[1], dt[1];
    const float v = impl_->lookup(*impl_->entries[texture], q, 1, c, ds, dt);
    dds = ds[0], ddt = dt[0];
    return v;
}

void Textures::range(uint32_t texture, float& lo, float& hi) const {
    Impl::Entry& e = *impl_->entries[texture];
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

Color surfaceTextureColor(const Textures& textures, const Material& m, const Projector& pr,
                          const PatchTexCoords& tc, Vec3 P, Vec3 dPdu, Vec3 dPdv, Vec2 uv, float scale) {
    if (m.texture < 0) return {1, 1, 1};
    Vec2 dstdu, dstdv;
    texCoordDerivs(tc, uv.x, uv.y, dstdu, dstdv);
    const TextureLookup q =
        textureLookup(pr, P, dPdu, dPdv, texCoordsAt(tc, uv.x, uv.y), dstdu, dstdv, scale);
    return textures.color(uint32_t(m.texture), q);
}

std::string textureReadError(const std::string& path) {
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

}  // namespace tessera
