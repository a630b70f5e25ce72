// Image files: PNG encoding (straight alpha, RI Exposure, sRGB) and EXR round trips.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>

#include "io/image_io.h"

using namespace tessera;
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
