// The OpenEXR side of io/exr_module.h, built as libtessera_exr.so. Everything here runs inside try blocks:
// OpenEXR reports errors by exception, and none may cross the seam.
#include <ImfArray.h>
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfIntAttribute.h>
#include <ImfMatrixAttribute.h>
#include <ImfOutputFile.h>
#include <ImfRgbaFile.h>
#include <ImfStandardAttributes.h>
#include <ImfStringAttribute.h>

#include <cmath>
#include <exception>
#include <optional>
#include <stdexcept>
#include <utility>

#include "io/exr_module.h"

namespace tessera {
namespace {

Imath::M44f toImath(const Mat4& m) {  // Imath multiplies row vectors: the transpose
    Imath::M44f out;
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) out[r][c] = float(m.m[c][r]);
    return out;
}

Mat4 fromImath(const Imath::M44f& m) {
    Mat4 out;
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) out.m[c][r] = m[r][c];
    return out;
}

constexpr const char* kDepthMapAttribute = "tesseraDepthMap";

// Runs `body`, turning an exception into false and its message.
template <typename F>
bool guarded(std::string& error, F&& body) {
    try {
        body();
        return true;
    } catch (const std::exception& e) {
        error = e.what();
    } catch (...) {
        error = "unknown OpenEXR error";
    }
    return false;
}

bool writeImage(const char* path, const ExrImageView& image, const ExrMetadata* meta, std::string& error) {
    return guarded(error, [&] {
        const int w = image.width, h = image.height;
        // The data window is the image's raster rectangle; the display window the full image it belongs
        // to (a crop window or farm tile lies inside it; OpenEXR's convention).
        const Imath::Box2i dataWindow(Imath::V2i(image.x0, image.y0),
                                      Imath::V2i(image.x0 + w - 1, image.y0 + h - 1));
        Imath::Box2i displayWindow = dataWindow;
        if (meta && meta->displayWidth > 0 && meta->displayHeight > 0)
            displayWindow =
                Imath::Box2i(Imath::V2i(0, 0), Imath::V2i(meta->displayWidth - 1, meta->displayHeight - 1));
        else if (image.x0 != 0 || image.y0 != 0)
            displayWindow = Imath::Box2i(Imath::V2i(0, 0), dataWindow.max);
        Imf::Header header(displayWindow, dataWindow);
        header.compression() = Imf::ZIP_COMPRESSION;
        if (meta) {
            if (!meta->sceneHash.empty())
                header.insert("tesseraSceneHash", Imf::StringAttribute(meta->sceneHash));
            if (meta->tileCount > 0) {
                header.insert("tesseraTileIndex", Imf::IntAttribute(meta->tileIndex));
                header.insert("tesseraTileCount", Imf::IntAttribute(meta->tileCount));
            }
            if (!meta->software.empty()) header.insert("software", Imf::StringAttribute(meta->software));
            if (meta->hasCamera) {
                Imf::addWorldToCamera(header, toImath(meta->worldToCamera));
                Imf::addWorldToNDC(header, toImath(meta->worldToNDC));
            }
            if (meta->renderMs >= 0)
                header.insert("renderTimeMs", Imf::StringAttribute(std::to_string(meta->renderMs)));
        }
        // RGBA: half; the planes: float (uint for ids), unfiltered or filtered as the film made them.
        Imf::Array2D<Imf::Rgba> px(h, w);
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
                const float* p = image.rgba + (size_t(y) * w + x) * 4;
                px[y][x] = Imf::Rgba(p[0], p[1], p[2], p[3]);
            }
        Imf::FrameBuffer fb;
        const size_t rgbaStride = sizeof(Imf::Rgba), rowStride = rgbaStride * size_t(w);
        // OpenEXR addresses a slice by absolute pixel coordinates: shift the bases by the data window.
        const ptrdiff_t origin = ptrdiff_t(image.y0) * w + image.x0;
        char* base = reinterpret_cast<char*>(&px[0][0]) - origin * ptrdiff_t(rgbaStride);
        const char* names[4] = {"R", "G", "B", "A"};
        for (int c = 0; c < 4; ++c) {
            header.channels().insert(names[c], Imf::Channel(Imf::HALF));
            fb.insert(names[c], Imf::Slice(Imf::HALF, base + c * sizeof(half), rgbaStride, rowStride));
        }
        for (size_t k = 0; k < image.planeCount; ++k) {
            const ExrPlaneView& plane = image.planes[k];
            if (plane.integer) {
                header.channels().insert(*plane.name, Imf::Channel(Imf::UINT));
                fb.insert(
                    *plane.name,
                    Imf::Slice(Imf::UINT, reinterpret_cast<char*>(const_cast<uint32_t*>(plane.ids - origin)),
                               sizeof(uint32_t), sizeof(uint32_t) * w));
                continue;
            }
            const size_t comp = size_t(plane.components), stride = sizeof(float) * comp;
            for (size_t c = 0; c < comp; ++c) {
                std::string name = *plane.name == "z" ? "Z" : *plane.name;
                if (comp > 1) {  // appended piece by piece (g++ 12 -Wrestrict false positive)
                    name += '.';
                    if (comp == 3)
                        name += (plane.color ? "RGB" : "XYZ")[c];
                    else
                        name += std::to_string(c);
                }
                header.channels().insert(name, Imf::Channel(Imf::FLOAT));
                fb.insert(name, Imf::Slice(Imf::FLOAT,
                                           reinterpret_cast<char*>(const_cast<float*>(plane.values + c)) -
                                               origin * ptrdiff_t(stride),
                                           stride, stride * w));
            }
        }
        Imf::OutputFile file(path, header);
        file.setFrameBuffer(fb);
        file.writePixels(h);
    });
}

bool readImage(const char* path, int& width, int& height, int& x0, int& y0, std::vector<float>& rgba,
               std::string& error) {
    return guarded(error, [&] {
        Imf::RgbaInputFile file(path);
        const Imath::Box2i dw = file.dataWindow();
        const int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1;
        Imf::Array2D<Imf::Rgba> px(h, w);
        file.setFrameBuffer(&px[0][0] - dw.min.x - dw.min.y * w, 1, w);
        file.readPixels(dw.min.y, dw.max.y);
        rgba.resize(size_t(w) * h * 4);
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
                float* p = &rgba[(size_t(y) * w + x) * 4];
                p[0] = px[y][x].r;
                p[1] = px[y][x].g;
                p[2] = px[y][x].b;
                p[3] = px[y][x].a;
            }
        width = w, height = h, x0 = dw.min.x, y0 = dw.min.y;
    });
}

const char* pixelTypeName(Imf::PixelType t) {
    return t == Imf::HALF ? "half" : t == Imf::UINT ? "uint" : "float";
}

bool readInfo(const char* path, ExrInfo& info, std::string& error) {
    return guarded(error, [&] {
        Imf::InputFile file(path);
        const Imf::Header& h = file.header();
        info = ExrInfo{};
        const Imath::Box2i& disp = h.displayWindow();
        const Imath::Box2i& data = h.dataWindow();
        info.displayX0 = disp.min.x, info.displayY0 = disp.min.y, info.displayX1 = disp.max.x,
        info.displayY1 = disp.max.y;
        info.dataX0 = data.min.x, info.dataY0 = data.min.y, info.dataX1 = data.max.x,
        info.dataY1 = data.max.y;
        for (auto it = h.channels().begin(); it != h.channels().end(); ++it) {
            std::string c = it.name();
            c += ':';
            c += pixelTypeName(it.channel().type);
            info.channels.push_back(c);
        }
        if (const auto* a = h.findTypedAttribute<Imf::StringAttribute>("tesseraSceneHash"))
            info.sceneHash = a->value();
        if (const auto* a = h.findTypedAttribute<Imf::IntAttribute>("tesseraTileIndex"))
            info.tileIndex = a->value();
        if (const auto* a = h.findTypedAttribute<Imf::IntAttribute>("tesseraTileCount"))
            info.tileCount = a->value();
    });
}

bool writeDepthMap(const char* path, const DepthMap& map, std::string& error) {
    return guarded(error, [&] {
        Imf::Header header(map.width, map.height);
        header.compression() = Imf::ZIP_COMPRESSION;
        Imf::addWorldToCamera(header, toImath(map.worldToCamera));
        Imf::addWorldToNDC(header, toImath(map.worldToNDC));
        header.insert(kDepthMapAttribute, Imf::StringAttribute(map.kind));
        header.channels().insert("Z", Imf::Channel(Imf::FLOAT));
        Imf::FrameBuffer fb;
        fb.insert("Z", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(const_cast<float*>(map.depth.data())),
                                  sizeof(float), sizeof(float) * size_t(map.width)));
        Imf::OutputFile file(path, header);
        file.setFrameBuffer(fb);
        file.writePixels(map.height);
    });
}

bool readDepthMap(const char* path, DepthMap& map, std::string& error) {
    return guarded(error, [&] {
        Imf::InputFile file(path);
        const Imf::Header& header = file.header();
        const Imf::ChannelList& channels = header.channels();
        int count = 0;
        for (auto it = channels.begin(); it != channels.end(); ++it) ++count;
        if (count != 1 || !channels.findChannel("Z") || !Imf::hasWorldToCamera(header) ||
            !Imf::hasWorldToNDC(header))
            throw std::runtime_error(
                "not a depth map (it needs exactly one channel Z and the worldToCamera and worldToNDC "
                "matrices, as Display \"zfile\" writes)");
        const Imath::Box2i dw = header.dataWindow();
        map.width = dw.max.x - dw.min.x + 1;
        map.height = dw.max.y - dw.min.y + 1;
        map.depth.assign(size_t(map.width) * map.height, 0.f);
        map.worldToCamera = fromImath(Imf::worldToCamera(header));
        map.worldToNDC = fromImath(Imf::worldToNDC(header));
        if (const auto* kind = header.findTypedAttribute<Imf::StringAttribute>(kDepthMapAttribute))
            map.kind = kind->value();
        Imf::FrameBuffer fb;
        char* base = reinterpret_cast<char*>(map.depth.data()) -
                     (ptrdiff_t(dw.min.x) + ptrdiff_t(dw.min.y) * map.width) * ptrdiff_t(sizeof(float));
        fb.insert("Z", Imf::Slice(Imf::FLOAT, base, sizeof(float), sizeof(float) * size_t(map.width)));
        file.setFrameBuffer(fb);
        file.readPixels(dw.min.y, dw.max.y);
        for (float& d : map.depth)
            if (std::isnan(d)) throw std::runtime_error("not a depth map (NaN depth)");
    });
}

bool assemble(const std::vector<std::string>& tiles, int boxX0, int boxY0, int boxX1, int boxY1,
              const char* path, std::string& errorFile, std::string& error) {
    errorFile.clear();
    const Imath::Box2i box(Imath::V2i(boxX0, boxY0), Imath::V2i(boxX1, boxY1));
    const int W = boxX1 - boxX0 + 1, H = boxY1 - boxY0 + 1;
    // Every channel is copied in its stored type (half stays half), so the result equals a single render
    // bit for bit.
    std::vector<std::pair<std::string, Imf::PixelType>> channels;
    std::vector<std::vector<char>> planes;  // one per channel, W x H of 4 bytes (half uses 2 of them)
    auto frameBuffer = [&](Imf::FrameBuffer& fb) {
        const ptrdiff_t origin = ptrdiff_t(boxY0) * W + boxX0;
        for (size_t c = 0; c < channels.size(); ++c)
            fb.insert(channels[c].first,
                      Imf::Slice(channels[c].second, planes[c].data() - origin * 4, 4, size_t(W) * 4));
    };
    std::optional<Imf::Header> header;
    for (const std::string& t : tiles) {
        const bool ok = guarded(error, [&] {
            Imf::InputFile file(t.c_str());
            if (!header) {
                header = file.header();
                for (auto it = header->channels().begin(); it != header->channels().end(); ++it)
                    channels.emplace_back(it.name(), it.channel().type);
                planes.reserve(channels.size());
                for (size_t c = 0; c < channels.size(); ++c) planes.emplace_back(size_t(W) * H * 4);
            }
            Imf::FrameBuffer fb;
            frameBuffer(fb);
            file.setFrameBuffer(fb);
            file.readPixels(file.header().dataWindow().min.y, file.header().dataWindow().max.y);
        });
        if (!ok) {
            errorFile = t;
            return false;
        }
    }
    return guarded(error, [&] {
        header->dataWindow() = box;
        // The assembled image is the one tile of a one-tile split. (Not Header::erase: OpenEXR 3.1's leaks
        // the attribute, which LeakSanitizer reports; insert over an existing name copies the value in
        // place.)
        header->insert("tesseraTileIndex", Imf::IntAttribute(0));
        header->insert("tesseraTileCount", Imf::IntAttribute(1));
        Imf::OutputFile file(path, *header);
        Imf::FrameBuffer fb;
        frameBuffer(fb);
        file.setFrameBuffer(fb);
        file.writePixels(H);
    });
}

constexpr ExrModuleApi kApi{kExrModuleVersion, writeImage,   readImage, readInfo,
                            writeDepthMap,     readDepthMap, assemble};

}  // namespace
}  // namespace tessera

extern "C" __attribute__((visibility("default"))) const void* tessera_exr_module() {
    return &tessera::kApi;
}
