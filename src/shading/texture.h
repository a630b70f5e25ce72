// Textures through OpenImageIO's TextureSystem: filtered, mip-mapped lookups with OIIO's per-thread
// cache, for every format OIIO reads (TIFF, OpenEXR including float, PNG, `.tx` from MakeTexture). A
// plain (untiled, unmipped) image is mip-mapped when it is first read ("automip"). One `Textures` per
// render, shared by every thread; both engines' shading batches look up through it.
//
// Texture coordinates are RenderMan's s, t (RI spec 3.2, sec. 4.2.7 and 5.2): per surface a bilinear map
// of (u,v) given by its four corner values (`PatchTexCoords`); t = 0 is the top row of the image, as in
// RenderMan and OIIO. Filter footprints are the st derivatives per raster pixel (`textureFootprint`),
// computed the same way in both engines so that they look up the same filtered values.
#pragma once
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "core/hostdevice.h"
#include "core/vec.h"
#include "scene/camera.h"
#include "scene/scene.h"
#include "shading/minmax_mip.h"

namespace tessera {

// s, t at (u,v) of a surface: the bilinear (RI "varying") interpolation of its corners.
TESSERA_HD Vec2 texCoordsAt(const PatchTexCoords& tc, float u, float v) {
    const Vec2 lo{tc.st[0].x + (tc.st[1].x - tc.st[0].x) * u, tc.st[0].y + (tc.st[1].y - tc.st[0].y) * u};
    const Vec2 hi{tc.st[2].x + (tc.st[3].x - tc.st[2].x) * u, tc.st[2].y + (tc.st[3].y - tc.st[2].y) * u};
    return {lo.x + (hi.x - lo.x) * v, lo.y + (hi.y - lo.y) * v};
}
// d(s,t)/du and d(s,t)/dv at (u,v).
TESSERA_HD void texCoordDerivs(const PatchTexCoords& tc, float u, float v, Vec2& dstdu, Vec2& dstdv) {
    const Vec2 d0{tc.st[1].x - tc.st[0].x, tc.st[1].y - tc.st[0].y};  // along u at v = 0
    const Vec2 d1{tc.st[3].x - tc.st[2].x, tc.st[3].y - tc.st[2].y};  // along u at v = 1
    dstdu = {d0.x + (d1.x - d0.x) * v, d0.y + (d1.y - d0.y) * v};
    const Vec2 e0{tc.st[2].x - tc.st[0].x, tc.st[2].y - tc.st[0].y};  // along v at u = 0
    const Vec2 e1{tc.st[3].x - tc.st[1].x, tc.st[3].y - tc.st[1].y};  // along v at u = 1
    dstdv = {e0.x + (e1.x - e0.x) * u, e0.y + (e1.y - e0.y) * u};
}

// A texture lookup: where and how wide (st change per raster pixel in x and y).
struct TextureLookup {
    float s = 0, t = 0;
    float dsdx = 0, dtdx = 0, dsdy = 0, dtdy = 0;
};

// The lookup of camera-space point P with surface derivatives dPdu, dPdv and st derivatives dstdu, dstdv,
// seen through the projector: the raster Jacobian d(x,y)/d(u,v) is inverted to d(u,v)/d(x,y), so one
// raster pixel's footprint maps to st (the footprint both engines filter over). `scale` widens it (Reyes
// micropolygons wider than a pixel). Where the surface is seen edge-on (no inverse) the footprint is
// clamped to the whole texture.
TESSERA_HD TextureLookup textureLookup(const Projector& pr, Vec3 P, Vec3 dPdu, Vec3 dPdv, Vec2 st, Vec2 dstdu,
                                       Vec2 dstdv, float scale = 1.f) {
    TextureLookup q;
    q.s = st.x, q.t = st.y;
    // d raster / d P (RI perspective: x = sx X/Z + ox), applied to dPdu and dPdv.
    const float iz = pr.perspective ? 1.f / P.z : 1.f;
    auto dRaster = [&](Vec3 d) -> Vec2 {
        if (!pr.perspective) return {pr.sx * d.x, pr.sy * d.y};
        return {pr.sx * (d.x - P.x * iz * d.z) * iz, pr.sy * (d.y - P.y * iz * d.z) * iz};
    };
    const Vec2 ru = dRaster(dPdu), rv = dRaster(dPdv);  // columns of J = d(x,y)/d(u,v)
    const float det = ru.x * rv.y - rv.x * ru.y;
    const float limit = 1.f;  // st units: at most the whole texture
    if (!(fabsf(det) > 1e-20f)) {
        q.dsdx = q.dtdy = limit;
        return q;
    }
    // J^-1 = [dudx dudy; dvdx dvdy]
    const float dudx = rv.y / det * scale, dudy = -rv.x / det * scale;
    const float dvdx = -ru.y / det * scale, dvdy = ru.x / det * scale;
    auto clampD = [&](float d) { return fminf(fmaxf(d, -limit), limit); };
    q.dsdx = clampD(dstdu.x * dudx + dstdv.x * dvdx);
    q.dtdx = clampD(dstdu.y * dudx + dstdv.y * dvdx);
    q.dsdy = clampD(dstdu.x * dudy + dstdv.x * dvdy);
    q.dtdy = clampD(dstdu.y * dudy + dstdv.y * dvdy);
    return q;
}

struct TextureModuleApi;

// The textures of a scene (Scene::textures), opened once per render. Lookups are thread-safe: each
// thread uses OIIO's per-thread info and the shared tile cache. OIIO itself is loaded on first use
// (texture_module.h): a scene without textures never loads it.
class Textures {
  public:
    // Opens every file (already resolved to a path by the reader); throws std::runtime_error naming the
    // file when one cannot be read, or saying why the OpenImageIO module could not be loaded.
    explicit Textures(std::span<const std::string> files);
    ~Textures();
    Textures(const Textures&) = delete;
    Textures& operator=(const Textures&) = delete;

    size_t size() const;
    // Filtered colour (a one-channel texture gives grey; a two-channel one its first channel).
    Color color(uint32_t texture, const TextureLookup& q) const;
    // Filtered first channel (displacement amplitudes).
    float value(uint32_t texture, const TextureLookup& q) const;
    // The same with its derivatives d/ds and d/dt (for the normals of displaced surfaces).
    float value(uint32_t texture, const TextureLookup& q, float& dds, float& ddt) const;
    // Smallest and largest value of the first channel over the whole texture (its finest level).
    void range(uint32_t texture, float& lo, float& hi) const;
    // The min/max mip map of the first channel (paper 001 sec. 3.1), built on first use from the file's
    // finest level (thread-safe); empty when the texels cannot be read.
    const MinMaxMip& minMaxMip(uint32_t texture) const;

  private:
    struct LazyMip {
        std::once_flag once;
        MinMaxMip mip;
    };
    std::unique_ptr<LazyMip[]> mips_;
    const TextureModuleApi* api_ = nullptr;  // the OpenImageIO module (texture_module.h)
    void* set_ = nullptr;                    // its open textures
    size_t count_ = 0;
};

// The texture colour of a point of a surface with material `m`: Cs's multiplier in paintedplastic (RI
// texture(texturename) at the point's s, t, filtered over one raster pixel times `scale`); white when `m`
// has no texture. P, dPdu, dPdv in the projector's camera space; uv on the surface.
Color surfaceTextureColor(const Textures& textures, const Material& m, const Projector& pr,
                          const PatchTexCoords& tc, Vec3 P, Vec3 dPdu, Vec3 dPdv, Vec2 uv, float scale = 1.f);

// Whether OIIO can read `path` as an image; "" when it can, otherwise OIIO's reason (or why the
// OpenImageIO module could not be loaded).
std::string textureReadError(const std::string& path);

// RI MakeTexture (RI spec 3.2, sec. 8.3): converts `picture` to a tiled, mip-mapped texture `texture`
// with OIIO's make_texture (as `maketx` does), storing the wrap modes ("periodic", "clamp", "black") in
// the file so that lookups use them. Returns "" on success, otherwise the reason.
std::string makeTexture(const std::string& picture, const std::string& texture, const std::string& swrap,
                        const std::string& twrap);

}  // namespace tessera
