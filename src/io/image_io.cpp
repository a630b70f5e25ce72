#include "io/image_io.h"

#include <ImfArray.h>
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfMatrixAttribute.h>
#include <ImfOutputFile.h>
#include <ImfRgbaFile.h>
#include <ImfStandardAttributes.h>
#include <ImfStringAttribute.h>
#include <png.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <stdexcept>

namespace tessera {
namespace fs = std::filesystem;

namespace {

std::string extensionOf(const std::string& path) {
    std::string e = fs::path(path).extension().string();
    std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return e;
}

// A temporary path beside the target, unique per process.
std::string tempPathFor(const std::string& path) {
    fs::path p(path);
    std::string name = ".";  // built up in steps: `"." + string` trips a g++ 12 -Wrestrict false positive
    name += p.filename().string();
    name += ".tmp" + std::to_string(getpid());
    return (p.parent_path() / name).string();
}

// Runs `write(tmp)` then renames tmp over `path`; removes tmp on any failure.
template <class F>
void writeAtomically(const std::string& path, F&& write) {
    std::string tmp = tempPathFor(path);
    try {
        write(tmp);
        std::error_code ec;
        fs::rename(tmp, path, ec);
        if (ec) throw std::runtime_error(path + ": cannot write: " + ec.message());
    } catch (...) {
        std::error_code ec;
        fs::remove(tmp, ec);
        throw;
    }
}

float encode(float c, const OutputEncoding& enc) {
    if (!(c > 0.f)) return 0.f;  // also maps NaN to 0
    if (enc.srgb) return c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.f / 2.4f) - 0.055f;
    c *= enc.gain;
    return enc.gamma == 1.f ? c : std::pow(c, 1.f / enc.gamma);
}

uint8_t quantize(float v) {
    // lround(v * 255) clamped to [0, 255], without the library call (it runs per channel of every pixel):
    // clamped first (NaN -> 0), then rounded half up, which is exact in double.
    const float x = v * 255.f;
    if (!(x > 0.f)) return 0;
    if (x >= 255.f) return 255;
    return uint8_t(double(x) + 0.5);
}

}  // namespace

bool isSupportedImageExtension(const std::string& path) {
    std::string e = extensionOf(path);
    return e == ".png" || e == ".exr";
}

void writeImage(const std::string& path, const Image& image, const OutputEncoding& enc) {
    std::string e = extensionOf(path);
    if (e == ".png") {
        if (!image.planes.empty())
            throw std::runtime_error(path + ": AOVs need an OpenEXR output (.exr): PNG holds RGBA only");
        return writePng(path, image, enc);
    }
    if (e == ".exr") return writeExr(path, image, enc.exr);
    throw std::runtime_error(path + ": unsupported output format '" + e + "' (use .png or .exr)");
}

void writePng(const std::string& path, const Image& image, const OutputEncoding& enc) {
    // Straight alpha: un-premultiply, then apply the exposure / transfer curve to the colour.
    std::vector<uint8_t> bytes(size_t(image.width) * image.height * 4);
    for (size_t i = 0; i < size_t(image.width) * image.height; ++i) {
        const float* p = &image.rgba[i * 4];
        float a = std::clamp(p[3], 0.f, 1.f);
        float k = a > 0.f ? 1.f / a : 0.f;
        for (int c = 0; c < 3; ++c) bytes[i * 4 + c] = quantize(encode(p[c] * k, enc));
        bytes[i * 4 + 3] = quantize(a);
    }
    writeAtomically(path, [&](const std::string& tmp) {
        FILE* f = std::fopen(tmp.c_str(), "wb");
        if (!f) throw std::runtime_error(path + ": cannot open for writing");
        std::unique_ptr<FILE, int (*)(FILE*)> guard(f, &std::fclose);
        png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
        png_infop info = png ? png_create_info_struct(png) : nullptr;
        if (!png || !info) throw std::runtime_error(path + ": libpng initialisation failed");
        if (setjmp(png_jmpbuf(png))) {
            png_destroy_write_struct(&png, &info);
            throw std::runtime_error(path + ": PNG write failed");
        }
        png_init_io(png, f);
        // Fast settings: one cheap row filter instead of the adaptive search, moderate zlib effort.
        png_set_compression_level(png, 3);
        png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_SUB);
        png_set_IHDR(png, info, image.width, image.height, 8, PNG_COLOR_TYPE_RGBA, PNG_INTERLACE_NONE,
                     PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
        if (enc.srgb) png_set_sRGB(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
        png_write_info(png, info);
        for (int y = 0; y < image.height; ++y) png_write_row(png, &bytes[size_t(y) * image.width * 4]);
        png_write_end(png, nullptr);
        png_destroy_write_struct(&png, &info);
        if (std::fflush(f) != 0) throw std::runtime_error(path + ": write failed");
    });
}

namespace {
Imath::M44f toImath(const Mat4& m) {  // Imath multiplies row vectors: the transpose
    Imath::M44f out;
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) out[r][c] = float(m.m[c][r]);
    return out;
}
}  // namespace

void writeExr(const std::string& path, const Image& image, const ExrMetadata* meta) {
    writeAtomically(path, [&](const std::string& tmp) {
        try {
            const int w = image.width, h = image.height;
            Imf::Header header(w, h);
            header.compression() = Imf::ZIP_COMPRESSION;
            if (meta) {
                if (!meta->software.empty()) header.insert("software", Imf::StringAttribute(meta->software));
                if (meta->hasCamera) {
                    Imf::addWorldToCamera(header, toImath(meta->worldToCamera));
                    Imf::addWorldToNDC(header, toImath(meta->worldToNDC));
                }
                if (meta->renderMs >= 0)
                    header.insert("renderTimeMs", Imf::StringAttribute(std::to_string(meta->renderMs)));
            }
            // RGBA: half, as before; the planes: float (uint for ids), unfiltered or filtered as the film
            // made them.
            Imf::Array2D<Imf::Rgba> px(h, w);
            for (int y = 0; y < h; ++y)
                for (int x = 0; x < w; ++x) {
                    const float* p = image.pixel(x + image.x0, y + image.y0);
                    px[y][x] = Imf::Rgba(p[0], p[1], p[2], p[3]);
                }
            Imf::FrameBuffer fb;
            const size_t rgbaStride = sizeof(Imf::Rgba), rowStride = rgbaStride * size_t(w);
            char* base = reinterpret_cast<char*>(&px[0][0]);
            const char* names[4] = {"R", "G", "B", "A"};
            for (int c = 0; c < 4; ++c) {
                header.channels().insert(names[c], Imf::Channel(Imf::HALF));
                fb.insert(names[c], Imf::Slice(Imf::HALF, base + c * sizeof(half), rgbaStride, rowStride));
            }
            for (const ImagePlane& plane : image.planes) {
                if (plane.integer) {
                    header.channels().insert(plane.name, Imf::Channel(Imf::UINT));
                    fb.insert(plane.name,
                              Imf::Slice(Imf::UINT,
                                         reinterpret_cast<char*>(const_cast<uint32_t*>(plane.ids.data())),
                                         sizeof(uint32_t), sizeof(uint32_t) * w));
                    continue;
                }
                const size_t comp = size_t(plane.components), stride = sizeof(float) * comp;
                for (size_t c = 0; c < comp; ++c) {
                    std::string name = plane.name == "z" ? "Z" : plane.name;
                    if (comp > 1) {  // appended piece by piece (g++ 12 -Wrestrict false positive)
                        name += '.';
                        if (comp == 3)
                            name += "XYZ"[c];
                        else
                            name += std::to_string(c);
                    }
                    header.channels().insert(name, Imf::Channel(Imf::FLOAT));
                    fb.insert(name,
                              Imf::Slice(Imf::FLOAT,
                                         reinterpret_cast<char*>(const_cast<float*>(plane.values.data() + c)),
                                         stride, stride * w));
                }
            }
            Imf::OutputFile file(tmp.c_str(), header);
            file.setFrameBuffer(fb);
            file.writePixels(h);
        } catch (const std::exception& e) {
            throw std::runtime_error(path + ": EXR write failed: " + e.what());
        }
    });
}

Image readPng(const std::string& path) {
    png_image img{};
    img.version = PNG_IMAGE_VERSION;
    if (!png_image_begin_read_from_file(&img, path.c_str())) throw std::runtime_error(path + ": not a PNG");
    img.format = PNG_FORMAT_RGBA;
    std::vector<uint8_t> buf(PNG_IMAGE_SIZE(img));
    if (!png_image_finish_read(&img, nullptr, buf.data(), 0, nullptr))
        throw std::runtime_error(path + ": PNG read failed");
    Image out(int(img.width), int(img.height));
    for (size_t i = 0; i < buf.size(); ++i) out.rgba[i] = buf[i] / 255.f;
    return out;
}

namespace {
Mat4 fromImath(const Imath::M44f& m) {
    Mat4 out;
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) out.m[c][r] = m[r][c];
    return out;
}
constexpr const char* kDepthMapAttribute = "tesseraDepthMap";
}  // namespace

void writeDepthMap(const std::string& path, const DepthMap& map) {
    if (map.width < 1 || map.height < 1 || map.depth.size() != size_t(map.width) * map.height)
        throw std::runtime_error(path + ": depth map of the wrong size");
    writeAtomically(path, [&](const std::string& tmp) {
        try {
            Imf::Header header(map.width, map.height);
            header.compression() = Imf::ZIP_COMPRESSION;
            Imf::addWorldToCamera(header, toImath(map.worldToCamera));
            Imf::addWorldToNDC(header, toImath(map.worldToNDC));
            header.insert(kDepthMapAttribute, Imf::StringAttribute(map.kind));
            header.channels().insert("Z", Imf::Channel(Imf::FLOAT));
            Imf::FrameBuffer fb;
            fb.insert("Z",
                      Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(const_cast<float*>(map.depth.data())),
                                 sizeof(float), sizeof(float) * size_t(map.width)));
            Imf::OutputFile file(tmp.c_str(), header);
            file.setFrameBuffer(fb);
            file.writePixels(map.height);
        } catch (const std::exception& e) {
            throw std::runtime_error(path + ": OpenEXR write failed: " + e.what());
        }
    });
}

DepthMap readDepthMap(const std::string& path) {
    std::error_code ec;
    if (!fs::is_regular_file(path, ec)) throw std::runtime_error(path + ": no such file");
    try {
        Imf::InputFile file(path.c_str());
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
        DepthMap map;
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
        return map;
    } catch (const std::exception& e) {
        throw std::runtime_error(path + ": " + e.what());
    }
}

Image readExr(const std::string& path) {
    Imf::RgbaInputFile file(path.c_str());
    Imath::Box2i dw = file.dataWindow();
    int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1;
    Imf::Array2D<Imf::Rgba> px(h, w);
    file.setFrameBuffer(&px[0][0] - dw.min.x - dw.min.y * w, 1, w);
    file.readPixels(dw.min.y, dw.max.y);
    Image out(w, h);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            float* p = out.pixel(x, y);
            p[0] = px[y][x].r;
            p[1] = px[y][x].g;
            p[2] = px[y][x].b;
            p[3] = px[y][x].a;
        }
    return out;
}

}  // namespace tessera
