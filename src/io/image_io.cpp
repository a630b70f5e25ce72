#include "io/image_io.h"

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
#include "core/module_loader.h"
#include "io/diagnostics.h"
#include "io/exr_module.h"

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
// The OpenEXR module (io/exr_module.h), loaded on the first .exr read or written; throws naming `path` when
// it cannot be loaded.
const LoadedModule<ExrModuleApi>& loadedExrModule() {
#ifdef TESSERA_EXR_MODULE_PATH
    const char* builtPath = TESSERA_EXR_MODULE_PATH;
#else
    const char* builtPath = nullptr;
#endif
    static const LoadedModule<ExrModuleApi> loaded =
        loadModuleAs<ExrModuleApi>({"libtessera_exr.so", "TESSERA_EXR_MODULE", builtPath, kExrModuleEntry,
                                    kExrModuleVersion, "OpenEXR files need Tessera's OpenEXR module"});
    return loaded;
}

const ExrModuleApi& exrModule(const std::string& path) {
    const LoadedModule<ExrModuleApi>& loaded = loadedExrModule();
    if (!loaded.api) throw std::runtime_error(path + ": " + loaded.error);
    return *loaded.api;
}
}  // namespace

std::string exrSupportError() {
    return loadedExrModule().error;
}

void writeExr(const std::string& path, const Image& image, const ExrMetadata* meta) {
    const ExrModuleApi& exr = exrModule(path);
    std::vector<ExrPlaneView> planes;
    for (const ImagePlane& p : image.planes)
        planes.push_back({&p.name, p.components, p.integer, p.color, p.values.data(), p.ids.data()});
    const ExrImageView view{image.width,       image.height,  image.x0,     image.y0,
                            image.rgba.data(), planes.data(), planes.size()};
    writeAtomically(path, [&](const std::string& tmp) {
        std::string error;
        if (!exr.writeImage(tmp.c_str(), view, meta, error))
            throw std::runtime_error(path + ": EXR write failed: " + error);
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

void writeDepthMap(const std::string& path, const DepthMap& map) {
    if (map.width < 1 || map.height < 1 || map.depth.size() != size_t(map.width) * map.height)
        throw std::runtime_error(path + ": depth map of the wrong size");
    const ExrModuleApi& exr = exrModule(path);
    writeAtomically(path, [&](const std::string& tmp) {
        std::string error;
        if (!exr.writeDepthMap(tmp.c_str(), map, error))
            throw std::runtime_error(path + ": OpenEXR write failed: " + error);
    });
}

DepthMap readDepthMap(const std::string& path) {
    std::error_code ec;
    if (!fs::is_regular_file(path, ec)) throw std::runtime_error(path + ": no such file");
    DepthMap map;
    std::string error;
    if (!exrModule(path).readDepthMap(path.c_str(), map, error))
        throw std::runtime_error(path + ": " + error);
    return map;
}

Image readExr(const std::string& path) {
    int w = 0, h = 0, x0 = 0, y0 = 0;
    std::vector<float> rgba;
    std::string error;
    if (!exrModule(path).readImage(path.c_str(), w, h, x0, y0, rgba, error))
        throw std::runtime_error(path + ": " + error);
    Image out(w, h);
    out.x0 = x0, out.y0 = y0;
    std::copy(rgba.begin(), rgba.end(), out.rgba.begin());
    return out;
}

}  // namespace tessera

namespace tessera {
namespace {

std::string windowText(int x0, int y0, int x1, int y1) {
    return "(" + std::to_string(x0) + "," + std::to_string(y0) + ")-(" + std::to_string(x1) + "," +
           std::to_string(y1) + ")";
}

}  // namespace

ExrInfo readExrInfo(const std::string& path) {
    ExrInfo info;
    std::string error;
    if (!exrModule(path).readInfo(path.c_str(), info, error))
        throw InputError(path, 0, "cannot read as OpenEXR: " + error);
    return info;
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
    int boxX0 = infos[0].dataX0, boxY0 = infos[0].dataY0, boxX1 = infos[0].dataX1, boxY1 = infos[0].dataY1;
    for (size_t i = 0; i < infos.size(); ++i) {
        const ExrInfo& a = infos[i];
        boxX0 = std::min(boxX0, a.dataX0), boxY0 = std::min(boxY0, a.dataY0);
        boxX1 = std::max(boxX1, a.dataX1), boxY1 = std::max(boxY1, a.dataY1);
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
    const int64_t boxArea = int64_t(boxX1 - boxX0 + 1) * (boxY1 - boxY0 + 1);
    if (area != boxArea)
        throw InputError(output, 0,
                         "assemble: the tiles leave " + std::to_string(boxArea - area) + " pixels of " +
                             windowText(boxX0, boxY0, boxX1, boxY1) + " uncovered");
    // 3. Pixels: every channel copied in its stored type, so the result equals a single render bit for bit.
    const ExrModuleApi& exr = exrModule(output);
    writeAtomically(output, [&](const std::string& tmp) {
        std::string errorFile, error;
        if (exr.assemble(tiles, boxX0, boxY0, boxX1, boxY1, tmp.c_str(), errorFile, error)) return;
        if (!errorFile.empty()) throw InputError(errorFile, 0, "assemble: cannot read its pixels: " + error);
        throw std::runtime_error(output + ": EXR write failed: " + error);
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
