// Image files: PNG encoding (straight alpha, RI Exposure, sRGB) and EXR round trips.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "io/image_io.h"

namespace tessera::test::image_io_tests {

namespace fs = std::filesystem;

namespace {
fs::path tmpFile(const std::string& name) {
    return fs::temp_directory_path() / ("tessera_img_" + std::to_string(getpid()) + "_" + name);
}
Image twoPixels() {
    Image img(2, 1);
    float* a = img.pixel(0, 0);
    a[0] = a[1] = a[2] = 0.25f, a[3] = 1.f;
    float* b = img.pixel(1, 0);  // half coverage, premultiplied colour 0.125 -> straight 0.25
    b[0] = b[1] = b[2] = 0.125f, b[3] = 0.5f;
    return img;
}
}  // namespace

TEST(ImageIo, PngIsStraightAlphaWithExposure) {
    fs::path p = tmpFile("a.png");
    writePng(p, twoPixels(), OutputEncoding{1.f, 1.f, false});
    Image lin = readPng(p);
    EXPECT_NEAR(lin.pixel(0, 0)[0], 0.25f, 1.f / 255);
    EXPECT_NEAR(lin.pixel(1, 0)[0], 0.25f, 1.f / 255) << "un-premultiplied";
    EXPECT_NEAR(lin.pixel(1, 0)[3], 0.5f, 1.f / 255);

    writePng(p, twoPixels(), OutputEncoding{2.f, 2.2f, false});
    Image g = readPng(p);
    EXPECT_NEAR(g.pixel(0, 0)[0], std::pow(0.5f, 1.f / 2.2f), 1.f / 255) << "(gain * c)^(1/gamma)";

    writePng(p, twoPixels(), OutputEncoding{1.f, 1.f, true});
    Image s = readPng(p);
    EXPECT_NEAR(s.pixel(0, 0)[0], 1.055f * std::pow(0.25f, 1.f / 2.4f) - 0.055f, 1.f / 255) << "sRGB";
    fs::remove(p);
}

// The image data is deflated in parallel blocks (about 128 KB of rows each) joined into one zlib stream:
// libpng reads it back exactly (inflate checks the stream's Adler-32, libpng the chunks' CRCs), and the
// file is the same bytes whatever the thread count.
TEST(ImageIo, PngWrittenInParallelBlocksReadsBackExactly) {
    const int w = 300, h = 700;  // 1,201-byte filtered rows: 7 blocks, the last one short
    Image img(w, h);
    auto byteAt = [](int x, int y, int c) { return (x * 7 + y * 13 + c * 101 + (x * y) % 17) % 256; };
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            float* p = img.pixel(x, y);
            for (int c = 0; c < 3; ++c) p[c] = float(byteAt(x, y, c)) / 255.f;
            p[3] = 1.f;
            if (y >= h - 20) p[0] = p[1] = p[2] = 0.f, p[3] = float(byteAt(x, y, 3)) / 255.f;  // alpha only
        }
    const fs::path one = tmpFile("blocks1.png"), two = tmpFile("blocks2.png");
    tbb::task_arena(1).execute([&] { writePng(one, img, OutputEncoding{1.f, 1.f, false}); });
    tbb::task_arena(2).execute([&] { writePng(two, img, OutputEncoding{1.f, 1.f, false}); });
    const Image back = readPng(one);
    ASSERT_EQ(back.width, w);
    ASSERT_EQ(back.height, h);
    int wrong = 0;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int c = 0; c < 4; ++c) {
                const float expected = y >= h - 20 ? (c == 3 ? float(byteAt(x, y, 3)) / 255.f : 0.f)
                                                   : (c == 3 ? 1.f : float(byteAt(x, y, c)) / 255.f);
                wrong += std::fabs(back.pixel(x, y)[c] - expected) > 1e-6f;
            }
    EXPECT_EQ(wrong, 0);
    auto bytes = [](const fs::path& p) {
        std::ifstream in(p, std::ios::binary);
        return std::vector<char>(std::istreambuf_iterator<char>(in), {});
    };
    EXPECT_EQ(bytes(one), bytes(two)) << "the same file on 1 and 2 threads";
    EXPECT_LT(fs::file_size(one), size_t(w) * h * 4);  // compressed
    fs::remove(one);
    fs::remove(two);
}

TEST(ImageIo, ExrRoundTripIsPremultipliedLinear) {
    fs::path p = tmpFile("a.exr");
    writeExr(p, twoPixels());
    Image e = readExr(p);
    ASSERT_EQ(e.width, 2);
    EXPECT_NEAR(e.pixel(1, 0)[0], 0.125f, 1e-3f);
    EXPECT_NEAR(e.pixel(1, 0)[3], 0.5f, 1e-3f);
    fs::remove(p);
}

TEST(ImageIo, UnsupportedExtensionIsRejectedAndNothingIsWritten) {
    fs::path p = tmpFile("a.tif");
    EXPECT_THROW(writeImage(p, twoPixels(), {}), std::runtime_error);
    EXPECT_FALSE(fs::exists(p));
}

TEST(ImageIo, UnwritableDirectoryFailsCleanly) {
    EXPECT_THROW(writePng("/nonexistent-dir/x.png", twoPixels(), {}), std::runtime_error);
}

}  // namespace tessera::test::image_io_tests
