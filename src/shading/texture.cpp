#include "shading/texture.h"

#include <cstdlib>
#include <filesystem>
#include <stdexcept>

#include "core/module_loader.h"
#include "shading/texture_module.h"

namespace tessera {

namespace {
const LoadedModule<TextureModuleApi>& textureModule() {
#ifdef TESSERA_TEXTURE_MODULE_PATH
    const char* builtPath = TESSERA_TEXTURE_MODULE_PATH;
#else
    const char* builtPath = nullptr;
#endif
    static const LoadedModule<TextureModuleApi> module = loadModuleAs<TextureModuleApi>(
        {"libtessera_texture_oiio.so", "TESSERA_TEXTURE_MODULE", builtPath, kTextureModuleEntry,
         kTextureModuleVersion, "textures need Tessera's OpenImageIO module"});
    return module;
}

const TextureModuleApi& requireTextureModule() {
    const LoadedModule<TextureModuleApi>& m = textureModule();
    if (!m.api) throw std::runtime_error(m.error);
    return *m.api;
}
}  // namespace

Textures::Textures(std::span<const std::string> files) : count_(files.size()) {
    if (files.empty()) return;  // nothing to look up: OIIO stays unloaded
    api_ = &requireTextureModule();
    std::string error;
    set_ = api_->open(files, error);
    if (!set_) throw std::runtime_error(error);
    mips_ = std::make_unique<LazyMip[]>(files.size());
}

Textures::~Textures() {
    if (set_) api_->close(set_);
}

size_t Textures::size() const {
    return count_;
}

Color Textures::color(uint32_t texture, const TextureLookup& q) const {
    float c[3] = {0, 0, 0};
    if (api_->channels(set_, texture) >= 3) {
        api_->lookup(set_, texture, q, 3, c, nullptr, nullptr);
        return {c[0], c[1], c[2]};
    }
    api_->lookup(set_, texture, q, 1, c, nullptr, nullptr);  // grey (and grey + alpha): the first channel
    return {c[0], c[0], c[0]};
}

float Textures::value(uint32_t texture, const TextureLookup& q) const {
    float c[1];
    api_->lookup(set_, texture, q, 1, c, nullptr, nullptr);
    return c[0];
}

float Textures::value(uint32_t texture, const TextureLookup& q, float& dds, float& ddt) const {
    float c[1], ds[1], dt[1];
    api_->lookup(set_, texture, q, 1, c, ds, dt);
    dds = ds[0], ddt = dt[0];
    return c[0];
}

void Textures::range(uint32_t texture, float& lo, float& hi) const {
    api_->range(set_, texture, lo, hi);
}

const MinMaxMip& Textures::minMaxMip(uint32_t texture) const {
    LazyMip& m = mips_[texture];
    std::call_once(m.once, [&] {
        int w = 0, h = 0, ws = 0, wt = 0;
        std::vector<float> px;
        if (!api_->texels(set_, texture, w, h, px, ws, wt)) return;
        auto wrap = [](int c) {
            return c == 1 ? TexelWrap::Clamp : c == 2 ? TexelWrap::Black : TexelWrap::Periodic;
        };
        m.mip = buildMinMaxMip(w, h, px, wrap(ws), wrap(wt));
    });
    return m.mip;
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
    const LoadedModule<TextureModuleApi>& m = textureModule();
    return m.api ? m.api->readError(path) : m.error;
}

std::string makeTexture(const std::string& picture, const std::string& texture, const std::string& swrap,
                        const std::string& twrap) {
    const LoadedModule<TextureModuleApi>& m = textureModule();
    return m.api ? m.api->makeTexture(picture, texture, swrap, twrap) : m.error;
}

}  // namespace tessera
