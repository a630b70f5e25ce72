#include "io/image_io.h"

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
#include <png.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>

#include "core/buffer_allocator.h"
#include "io/diagnostics.h"

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

namespace {

// The PNG image data (the zlib stream of the filtered scanlines) compressed in parallel, as pigz does: the
// rows are cut into fixed blocks (the same cut for any thread count, so the same file), each block is raw
// deflate on its own (no dictionary from the block before) ending on a byte boundary with a sync flush,
// the last with the final block; their concatenation is one valid deflate stream, inside the zlib header
// and the Adler-32 of the whole data (adler32_combine). RFC 1950, 1951; PNG spec. 10-11. Each row gets the
// Sub filter (one cheap filter instead of libpng's adaptive search).
std::vector<uint8_t> compressedPngData(const uint8_t* rgba, int width, int height, int level) {
    const size_t rowBytes = size_t(width) * 4, lineBytes = rowBytes + 1;
    constexpr size_t kBlockBytes = size_t(1) << 17;  // 128 KB of filtered data a block
    const size_t rowsPerBlock = std::max<size_t>(1, kBlockBytes / lineBytes);
    const size_t blocks = (size_t(height) + rowsPerBlock - 1) / rowsPerBlock;
    struct Block {
        std::vector<uint8_t, DefaultInitAllocator<uint8_t, false>> out;  // no zero fill before deflate writes
        uLong adler = 0;
        size_t rawBytes = 0;
        bool ok = false;
    };
    std::vector<Block> block(blocks);
    tbb::parallel_for(size_t(0), blocks, [&](size_t b) {
        const size_t y0 = b * rowsPerBlock, y1 = std::min(size_t(height), y0 + rowsPerBlock);
        std::vector<uint8_t, DefaultInitAllocator<uint8_t, false>> lines((y1 - y0) * lineBytes);
        for (size_t y = y0; y < y1; ++y) {  // filter type 1 (Sub): each byte minus the one 4 bytes before
            uint8_t* line = &lines[(y - y0) * lineBytes];
            const uint8_t* row = &rgba[y * rowBytes];
            // (A local bound: the bytes written could alias a captured one, which stops vectorization.)
            const size_t n = rowBytes, head = std::min<size_t>(4, n);
            line[0] = 1;
            for (size_t i = 0; i < head; ++i) line[1 + i] = row[i];
            for (size_t i = head; i < n; ++i) line[1 + i] = uint8_t(row[i] - row[i - 4]);
        }
        Block& out = block[b];
        out.rawBytes = lines.size();
        out.adler = adler32(adler32(0L, Z_NULL, 0), lines.data(), uInt(lines.size()));
        z_stream z{};
        if (deflateInit2(&z, level, Z_DEFLATED, -15, 8, Z_DEFAULT_STRATEGY) != Z_OK) return;
        out.out.resize(deflateBound(&z, uLong(lines.size())) + 16);
        z.next_in = lines.data();
        z.avail_in = uInt(lines.size());
        z.next_out = out.out.data();
        z.avail_out = uInt(out.out.size());
        const int flush = b + 1 == blocks ? Z_FINISH : Z_SYNC_FLUSH;
        const int rc = deflate(&z, flush);
        out.ok = (flush == Z_FINISH ? rc == Z_STREAM_END : rc == Z_OK) && z.avail_in == 0;
        out.out.resize(out.out.size() - z.avail_out);
        deflateEnd(&z);
    });
    // zlib header: deflate, 32 KB window (CMF 0x78); FLEVEL 1 (levels 2 to 5, as zlib writes it) and the
    // check bits that make CMF * 256 + FLG a multiple of 31.
    const uint8_t cmf = 0x78, flevel = level <= 1 ? 0 : level <= 5 ? 1 : level == 6 ? 2 : 3;
    uint8_t flg = uint8_t(flevel << 6);
    flg = uint8_t(flg + (31 - (cmf * 256 + flg) % 31) % 31);
    std::vector<uint8_t> data{cmf, flg};
    uLong adler = adler32(0L, Z_NULL, 0);
    for (const Block& b : block) {
        if (!b.ok) throw std::runtime_error("zlib deflate failed");
        data.insert(data.end(), b.out.begin(), b.out.end());
        adler = adler32_combine(adler, b.adler, z_off_t(b.rawBytes));
    }
    for (int k = 3; k >= 0; --k) data.push_back(uint8_t(adler >> (8 * k)));
    return data;
}

}  // namespace

void writePng(const std::string& path, const Image& image, const OutputEncoding& enc) {
    // Straight alpha: un-premultiply, then apply the exposure / transfer curve to the colour.
    // In parallel: the transfer curve's pow per channel was a tenth of the whole 1024 x 1024 teapot frame
    // (issue 18).
    const size_t pixels = size_t(image.width) * image.height;
    // Every byte is written below (in parallel): no serial zero fill first.
    std::vector<uint8_t, DefaultInitAllocator<uint8_t>> bytes(pixels * 4);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, pixels, 16384), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i < r.end(); ++i) {
            const float* p = &image.rgba[i * 4];
            float a = std::clamp(p[3], 0.f, 1.f);
            float k = a > 0.f ? 1.f / a : 0.f;
            for (int c = 0; c < 3; ++c) bytes[i * 4 + c] = quantize(encode(p[c] * k, enc));
            bytes[i * 4 + 3] = quantize(a);
        }
    });
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
        png_set_IHDR(png, info, image.width, image.height, 8, PNG_COLOR_TYPE_RGBA, PNG_INTERLACE_NONE,
                     PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
        if (enc.srgb) png_set_sRGB(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
        png_write_info(png, info);  // signature, IHDR, sRGB
        // The image data compressed in parallel (libpng's own path deflates on one thread: a tenth of the
        // 800x600 Reyes frame's wall time on 2 threads), written as IDAT chunks of up to 1 MB by libpng's
        // chunk writer, then IEND. zlib level 1: on the Sub-filtered Killeroo and 24 Big Guys frames it
        // deflates in 66% and 65% of level 3's time for files 7% and 5% larger (level 6, zlib's default:
        // 2.6x level 3's time, files 10% smaller; docs/benchmarks/fixed_costs.md, session 25).
        const std::vector<uint8_t> idat = compressedPngData(bytes.data(), image.width, image.height, 1);
        constexpr size_t kChunkBytes = size_t(1) << 20;
        for (size_t at = 0; at < idat.size(); at += kChunkBytes)
            png_write_chunk(png, reinterpret_cast<png_const_bytep>("IDAT"), idat.data() + at,
                            std::min(kChunkBytes, idat.size() - at));
        png_write_chunk(png, reinterpret_cast<png_const_bytep>("IEND"), nullptr, 0);
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
            // The data window is the image's raster rectangle; the display window the full image it
            // belongs to (a crop window or farm tile lies inside it; OpenEXR's convention).
            const Imath::Box2i dataWindow(Imath::V2i(image.x0, image.y0),
                                          Imath::V2i(image.x0 + w - 1, image.y0 + h - 1));
            Imath::Box2i displayWindow = dataWindow;
            if (meta && meta->displayWidth > 0 && meta->displayHeight > 0)
                displayWindow = Imath::Box2i(Imath::V2i(0, 0),
                                             Imath::V2i(meta->displayWidth - 1, meta->displayHeight - 1));
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
            // OpenEXR addresses a slice by absolute pixel coordinates: shift the bases by the data window.
            const ptrdiff_t origin = ptrdiff_t(image.y0) * w + image.x0;
            char* base = reinterpret_cast<char*>(&px[0][0]) - origin * ptrdiff_t(rgbaStride);
            const char* names[4] = {"R", "G", "B", "A"};
            for (int c = 0; c < 4; ++c) {
                header.channels().insert(names[c], Imf::Channel(Imf::HALF));
                fb.insert(names[c], Imf::Slice(Imf::HALF, base + c * sizeof(half), rgbaStride, rowStride));
            }
            for (const ImagePlane& plane : image.planes) {
                if (plane.integer) {
                    header.channels().insert(plane.name, Imf::Channel(Imf::UINT));
                    fb.insert(
                        plane.name,
                        Imf::Slice(Imf::UINT,
                                   reinterpret_cast<char*>(const_cast<uint32_t*>(plane.ids.data() - origin)),
                                   sizeof(uint32_t), sizeof(uint32_t) * w));
                    continue;
                }
                const size_t comp = size_t(plane.components), stride = sizeof(float) * comp;
                for (size_t c = 0; c < comp; ++c) {
                    std::string name = plane.name == "z" ? "Z" : plane.name;
                    if (comp > 1) {  // appended piece by piece (g++ 12 -Wrestrict false positive)
                        name += '.';
                        if (comp == 3)
                            name += (plane.color ? "RGB" : "XYZ")[c];
                        else
                            name += std::to_string(c);
                    }
                    header.channels().insert(name, Imf::Channel(Imf::FLOAT));
                    fb.insert(name, Imf::Slice(
                                        Imf::FLOAT,
                                        reinterpret_cast<char*>(const_cast<float*>(plane.values.data() + c)) -
                                            origin * ptrdiff_t(stride),
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
    out.x0 = dw.min.x, out.y0 = dw.min.y;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            float* p = &out.rgba[(size_t(y) * w + x) * 4];
            p[0] = px[y][x].r;
            p[1] = px[y][x].g;
            p[2] = px[y][x].b;
            p[3] = px[y][x].a;
        }
    return out;
}

}  // namespace tessera

namespace tessera {
namespace {

const char* pixelTypeName(Imf::PixelType t) {
    return t == Imf::HALF ? "half" : t == Imf::UINT ? "uint" : "float";
}

ExrInfo infoOf(const Imf::Header& h) {
    ExrInfo info;
    const Imath::Box2i& disp = h.displayWindow();
    const Imath::Box2i& data = h.dataWindow();
    info.displayX0 = disp.min.x, info.displayY0 = disp.min.y, info.displayX1 = disp.max.x,
    info.displayY1 = disp.max.y;
    info.dataX0 = data.min.x, info.dataY0 = data.min.y, info.dataX1 = data.max.x, info.dataY1 = data.max.y;
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
    return info;
}

std::string windowText(int x0, int y0, int x1, int y1) {
    return "(" + std::to_string(x0) + "," + std::to_string(y0) + ")-(" + std::to_string(x1) + "," +
           std::to_string(y1) + ")";
}

}  // namespace

ExrInfo readExrInfo(const std::string& path) {
    try {
        Imf::InputFile file(path.c_str());
        return infoOf(file.header());
    } catch (const std::exception& e) {
        throw InputError(path, 0, std::string("cannot read as OpenEXR: ") + e.what());
    }
}

void assembleExrTiles(const std::vector<std::string>& tiles, const std::string& output) {
    if (tiles.empty()) throw InputError(output, 0, "assemble: no tiles given");
    // 1. Headers: every tile must come from the same render (hash, display window, channels, split).
    std::vector<ExrInfo> infos;
    for (const std::string& t : tiles) infos.push_back(readExrInfo(t));
    const ExrInfo& first = infos[0];
    if (first.sceneHash.empty())
        throw InputError(tiles[0], 0,
                         "assemble: not a tessera tile (no tesseraSceneHash attribute; render it with --tile "
                         "I/N or --crop)");
    const int n = first.tileCount > 0 ? first.tileCount : 1;
    std::vector<int> seen(size_t(n), -1);
    for (size_t i = 0; i < tiles.size(); ++i) {
        const ExrInfo& t = infos[i];
        const std::string& f = tiles[i];
        if (t.sceneHash != first.sceneHash)
            throw InputError(f, 0,
                             "assemble: tile of another render (scene hash " +
                                 (t.sceneHash.empty() ? std::string("missing") : t.sceneHash) + ", " +
                                 tiles[0] + " has " + first.sceneHash + ")");
        if (t.displayX0 != first.displayX0 || t.displayY0 != first.displayY0 ||
            t.displayX1 != first.displayX1 || t.displayY1 != first.displayY1)
            throw InputError(
                f, 0,
                "assemble: display window " + windowText(t.displayX0, t.displayY0, t.displayX1, t.displayY1) +
                    " differs from " + tiles[0] + "'s " +
                    windowText(first.displayX0, first.displayY0, first.displayX1, first.displayY1));
        if (t.channels != first.channels)
            throw InputError(f, 0, "assemble: its channels differ from " + tiles[0] + "'s");
        if ((t.tileCount > 0 ? t.tileCount : 1) != n)
            throw InputError(f, 0,
                             "assemble: tile of a " + std::to_string(std::max(1, t.tileCount)) +
                                 "-tile split, " + tiles[0] + " is of a " + std::to_string(n) +
                                 "-tile split");
        if (t.tileIndex < 0 || t.tileIndex >= n)
            throw InputError(f, 0,
                             "assemble: tile index " + std::to_string(t.tileIndex) + " outside 0.." +
                                 std::to_string(n - 1));
        if (seen[size_t(t.tileIndex)] >= 0)
            throw InputError(f, 0,
                             "assemble: tile " + std::to_string(t.tileIndex) + " given twice (also " +
                                 tiles[size_t(seen[size_t(t.tileIndex)])] + ")");
        seen[size_t(t.tileIndex)] = int(i);
    }
    for (int k = 0; k < n; ++k)
        if (seen[size_t(k)] < 0)
            throw InputError(
                output, 0,
                "assemble: tile " + std::to_string(k) + " of " + std::to_string(n) + " is missing");
    // 2. Geometry: no two data windows overlap, and together they fill their bounding box (the crop
    // window the split covered, or the display window).
    int64_t area = 0;
    Imath::Box2i box;
    for (size_t i = 0; i < infos.size(); ++i) {
        const ExrInfo& a = infos[i];
        box.extendBy(Imath::V2i(a.dataX0, a.dataY0));
        box.extendBy(Imath::V2i(a.dataX1, a.dataY1));
        area += int64_t(a.dataX1 - a.dataX0 + 1) * (a.dataY1 - a.dataY0 + 1);
        for (size_t j = 0; j < i; ++j) {
            const ExrInfo& b = infos[j];
            if (a.dataX0 <= b.dataX1 && b.dataX0 <= a.dataX1 && a.dataY0 <= b.dataY1 && b.dataY0 <= a.dataY1)
                throw InputError(tiles[i], 0,
                                 "assemble: its pixels " +
                                     windowText(a.dataX0, a.dataY0, a.dataX1, a.dataY1) + " overlap " +
                                     tiles[j] + "'s " + windowText(b.dataX0, b.dataY0, b.dataX1, b.dataY1));
        }
    }
    const int64_t boxArea = int64_t(box.max.x - box.min.x + 1) * (box.max.y - box.min.y + 1);
    if (area != boxArea)
        throw InputError(output, 0,
                         "assemble: the tiles leave " + std::to_string(boxArea - area) + " pixels of " +
                             windowText(box.min.x, box.min.y, box.max.x, box.max.y) + " uncovered");
    // 3. Pixels: every channel copied in its stored type (half stays half), so the result equals a single
    // render bit for bit.
    const int W = box.max.x - box.min.x + 1, H = box.max.y - box.min.y + 1;
    std::vector<std::pair<std::string, Imf::PixelType>> channels;
    {
        Imf::InputFile file(tiles[0].c_str());
        for (auto it = file.header().channels().begin(); it != file.header().channels().end(); ++it)
            channels.emplace_back(it.name(), it.channel().type);
    }
    std::vector<std::vector<char>> planes;  // one per channel, W x H of 4 bytes (half uses 2 of them)
    planes.reserve(channels.size());
    for (size_t c = 0; c < channels.size(); ++c) planes.emplace_back(size_t(W) * H * 4);
    auto frameBuffer = [&](Imf::FrameBuffer& fb) {
        const ptrdiff_t origin = ptrdiff_t(box.min.y) * W + box.min.x;
        for (size_t c = 0; c < channels.size(); ++c)
            fb.insert(channels[c].first,
                      Imf::Slice(channels[c].second, planes[c].data() - origin * 4, 4, size_t(W) * 4));
    };
    std::optional<Imf::Header> header;
    for (const std::string& t : tiles) {
        try {
            Imf::InputFile file(t.c_str());
            if (!header) header = file.header();
            Imf::FrameBuffer fb;
            frameBuffer(fb);
            file.setFrameBuffer(fb);
            file.readPixels(file.header().dataWindow().min.y, file.header().dataWindow().max.y);
        } catch (const std::exception& e) {
            throw InputError(t, 0, std::string("assemble: cannot read its pixels: ") + e.what());
        }
    }
    header->dataWindow() = box;
    // The assembled image is the one tile of a one-tile split. (Not Header::erase: OpenEXR 3.1's leaks the
    // attribute, which LeakSanitizer reports; insert over an existing name copies the value in place.)
    header->insert("tesseraTileIndex", Imf::IntAttribute(0));
    header->insert("tesseraTileCount", Imf::IntAttribute(1));
    writeAtomically(output, [&](const std::string& tmp) {
        try {
            Imf::OutputFile file(tmp.c_str(), *header);
            Imf::FrameBuffer fb;
            frameBuffer(fb);
            file.setFrameBuffer(fb);
            file.writePixels(H);
        } catch (const std::exception& e) {
            throw std::runtime_error(output + ": EXR write failed: " + e.what());
        }
    });
}

ExrMetadata cameraExrMetadata(const Camera& cam) {
    ExrMetadata m;
    m.hasCamera = true;
    m.worldToCamera = cam.cameraFromWorld;
    const Projector pr(cam);
    const double W = cam.width, H = cam.height, n = pr.nearClip, f = pr.farClip;
    Mat4 p;
    if (pr.perspective) {  // raster = (x/z sx + ox, y/z sy + oy): divide by w = z
        p.m[0][0] = pr.sx / W, p.m[0][2] = pr.ox / W;
        p.m[1][1] = pr.sy / H, p.m[1][2] = pr.oy / H;
        p.m[2][2] = f / (f - n), p.m[2][3] = -f * n / (f - n);
        p.m[3][2] = 1, p.m[3][3] = 0;
    } else {
        p.m[0][0] = pr.sx / W, p.m[0][3] = pr.ox / W;
        p.m[1][1] = pr.sy / H, p.m[1][3] = pr.oy / H;
        p.m[2][2] = 1 / (f - n), p.m[2][3] = -n / (f - n);
    }
    m.worldToNDC = p * cam.cameraFromWorld;
    return m;
}

}  // namespace tessera
