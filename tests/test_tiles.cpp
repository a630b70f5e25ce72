// Crop windows and farm tiles (docs/inputs.md): the RI 3.2 pixel rule, the near-square split, and end to
// end through the command line: tiles assembled with `tessera assemble` equal the single render bit for
// bit (both engines, the default Gaussian filter whose footprint crosses tile borders), a crop equals the
// same pixels of the full render, the EXR windows, and the mistakes assemble and the options refuse.
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "film/crop.h"
#include "io/image_io.h"
#include "test_support.h"

namespace tessera::test::tiles_tests {

namespace fs = std::filesystem;

namespace {

int runTessera(const std::string& args, std::string* output = nullptr) {
    const fs::path log = test::testScratchDir() / "tessera.log";
    const int status =
        std::system((std::string(TESSERA_BINARY) + " " + args + " > '" + log.string() + "' 2>&1").c_str());
    if (output) {
        std::ifstream f(log);
        output->assign(std::istreambuf_iterator<char>(f), {});
    }
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// Two overlapping planes at depths 5 and 7 (different colours, a light that makes shading vary across the
// image) so that edges fall inside tiles and on their borders.
std::string writeScene(const std::string& name, const std::string& extra = "") {
    return test::writeTestFile(
        name, "Format 64 48 1\nPixelSamples 2 2\nProjection \"perspective\" \"fov\" 40\n" + extra +
                  "WorldBegin\nLightSource \"pointlight\" 1 \"from\" [-3 4 0] \"intensity\" 40\n"
                  "LightSource \"ambientlight\" 2 \"intensity\" 0.1\n"
                  "AttributeBegin\nColor [1 0.5 0.2]\nSurface \"plastic\"\n"
                  "Patch \"bilinear\" \"P\" [-20 -20 7  20 -20 7  -20 20 7  20 20 7]\nAttributeEnd\n"
                  "AttributeBegin\nColor [0.2 0.6 1]\nSurface \"matte\"\n"
                  "Patch \"bilinear\" \"P\" [-1.3 -0.9 5  0.7 -1.2 5  -1.1 0.8 5  0.9 1.1 5]\nAttributeEnd\n"
                  "WorldEnd\n");
}

// Every channel of an EXR as raw 32-bit values over the display window (half channels read as half into
// the low bytes, so comparing them compares the stored bits); pixels outside the data window stay 0xffffffff.
struct Raw {
    int width = 0, height = 0;
    std::map<std::string, std::vector<uint32_t>> channels;
};
Raw readRaw(const std::string& path) {
    Imf::InputFile file(path.c_str());
    const Imath::Box2i disp = file.header().displayWindow(), data = file.header().dataWindow();
    Raw r;
    r.width = disp.max.x - disp.min.x + 1, r.height = disp.max.y - disp.min.y + 1;
    Imf::FrameBuffer fb;
    for (auto it = file.header().channels().begin(); it != file.header().channels().end(); ++it) {
        std::vector<uint32_t>& v = r.channels[it.name()];
        v.assign(size_t(r.width) * r.height, 0xffffffffu);
        fb.insert(it.name(),
                  Imf::Slice(it.channel().type, reinterpret_cast<char*>(v.data()), 4, 4 * size_t(r.width)));
    }
    file.setFrameBuffer(fb);
    file.readPixels(data.min.y, data.max.y);
    return r;
}

TEST(Tiles, CropWindowFollowsTheRiRoundingRule) {
    // RI 3.2 sec. 4.1.1: ceil(xres * xmin) .. ceil(xres * xmax) - 1.
    Rect r = cropWindowPixels(64, 48, 0.25, 0.5, 0.1, 1.0);
    EXPECT_EQ(r.x0, 16);
    EXPECT_EQ(r.x1, 32);
    EXPECT_EQ(r.y0, 5);  // ceil(4.8)
    EXPECT_EQ(r.y1, 48);
    r = cropWindowPixels(10, 10, 0.0, 0.05, 0.0, 1.0);  // no pixel centre... ceil(0.5) - 1 = 0: pixel 0
    EXPECT_EQ(r.width(), 1);
    r = cropWindowPixels(10, 10, 0.01, 0.05, 0.0, 1.0);  // ceil(0.1) = 1 .. ceil(0.5) - 1 = 0: empty
    EXPECT_EQ(r.width(), 0);
    // Windows that share an edge at any fraction share no pixel and miss none.
    for (int res : {7, 64, 101})
        for (double cut : {0.1, 0.3333333, 0.5, 0.77}) {
            const Rect a = cropWindowPixels(res, res, 0, cut, 0, 1),
                       b = cropWindowPixels(res, res, cut, 1, 0, 1);
            EXPECT_EQ(a.x0, 0);
            EXPECT_EQ(a.x1, b.x0) << res << " " << cut;
            EXPECT_EQ(b.x1, res);
        }
}

TEST(Tiles, SplitIsNearSquareAndCoversEveryPixelOnce) {
    int cols, rows;
    ASSERT_TRUE(tileGrid(64, 48, 4, cols, rows));
    EXPECT_EQ(cols * 10 + rows, 22);
    ASSERT_TRUE(tileGrid(64, 48, 6, cols, rows));
    EXPECT_EQ(cols * 10 + rows, 32);  // 21-22 x 24 beats 32 x 16
    ASSERT_TRUE(tileGrid(640, 480, 64, cols, rows));
    EXPECT_EQ(cols * 100 + rows, 808);
    ASSERT_TRUE(tileGrid(100, 10, 4, cols, rows));
    EXPECT_EQ(cols * 10 + rows, 41);
    EXPECT_FALSE(tileGrid(3, 3, 16, cols, rows));
    EXPECT_TRUE(tileOf(Rect{0, 0, 3, 3}, 0, 16).width() == 0);
    const Rect base{5, 3, 42, 26};
    for (int n = 1; n <= 24; ++n) {
        std::vector<int> hits(size_t(base.width()) * base.height(), 0);
        for (int i = 0; i < n; ++i) {
            const Rect t = tileOf(base, i, n);
            ASSERT_GT(t.width(), 0) << n;
            for (int y = t.y0; y < t.y1; ++y)
                for (int x = t.x0; x < t.x1; ++x) ++hits[size_t(y - base.y0) * base.width() + (x - base.x0)];
        }
        for (int h : hits) ASSERT_EQ(h, 1) << n;
    }
}

TEST(Tiles, AssembledTilesEqualTheSingleRenderBitForBitInBothEngines) {
    const std::string rib = writeScene("scene.rib");
    const fs::path dir = test::testScratchDir();
    for (const char* engine : {"reyes", "rt"}) {
        const std::string common = rib + " -q --threads 2 --aov z,N,id --engine " + std::string(engine);
        const std::string full = (dir / (std::string(engine) + "_full.exr")).string();
        std::string out;
        ASSERT_EQ(runTessera("render " + common + " -o " + full, &out), 0) << out;
        std::string tiles;
        const int n = 6;  // 3 x 2 tiles of 21-22 x 24 pixels: uneven widths
        for (int i = 0; i < n; ++i) {
            const std::string t =
                (dir / (std::string(engine) + "_tile" + std::to_string(i) + ".exr")).string();
            ASSERT_EQ(runTessera("render " + common + " --tile " + std::to_string(i) + "/" +
                                     std::to_string(n) + " -o " + t,
                                 &out),
                      0)
                << out;
            tiles += " " + t;
        }
        // A tile's EXR: its data window inside the full display window, and its place in the split.
        const ExrInfo t4 = readExrInfo((dir / (std::string(engine) + "_tile4.exr")).string());
        EXPECT_EQ(t4.displayX0, 0);
        EXPECT_EQ(t4.displayX1, 63);
        EXPECT_EQ(t4.displayY1, 47);
        EXPECT_EQ(t4.dataX0, 21);
        EXPECT_EQ(t4.dataX1, 41);
        EXPECT_EQ(t4.dataY0, 24);
        EXPECT_EQ(t4.dataY1, 47);
        EXPECT_EQ(t4.tileIndex, 4);
        EXPECT_EQ(t4.tileCount, 6);
        EXPECT_EQ(t4.sceneHash.size(), 16u);
        const std::string joined = (dir / (std::string(engine) + "_joined.exr")).string();
        ASSERT_EQ(runTessera("assemble" + tiles + " -o " + joined, &out), 0) << out;
        const ExrInfo whole = readExrInfo(joined);
        EXPECT_EQ(whole.tileIndex, 0);  // the assembled image: the one tile of a one-tile split
        EXPECT_EQ(whole.tileCount, 1);

        const Raw a = readRaw(full), b = readRaw(joined);
        ASSERT_EQ(a.channels.size(), 9u);  // R G B A, Z, N.X N.Y N.Z, id
        ASSERT_EQ(b.width, 64);
        ASSERT_EQ(b.height, 48);
        for (const auto& [name, values] : a.channels) {
            ASSERT_TRUE(b.channels.count(name)) << name;
            int differing = 0;
            for (size_t i = 0; i < values.size(); ++i) differing += values[i] != b.channels.at(name)[i];
            EXPECT_EQ(differing, 0) << engine << " channel " << name;
        }
        // The image is not trivially uniform (the comparison could not fail otherwise).
        const std::vector<uint32_t>& red = a.channels.at("R");
        EXPECT_NE(red[size_t(24) * 64 + 30], red[size_t(2) * 64 + 2]);
    }
}

TEST(Tiles, ACropEqualsTheSamePixelsOfTheFullRender) {
    const std::string rib = writeScene("scene.rib");
    // The same window from the RIB: CropWindow 0.3 0.7 0.2 0.6 -> pixels x 20..44, y 10..28 (ceil rule).
    const std::string cropped = writeScene("cropped.rib", "CropWindow 0.3 0.7 0.2 0.6\n");
    const fs::path dir = test::testScratchDir();
    for (const char* engine : {"reyes", "rt"}) {
        const std::string e = std::string(" -q --threads 2 --engine ") + engine;
        const std::string full = (dir / "full.exr").string(), crop = (dir / "crop.exr").string(),
                          ribCrop = (dir / "ribcrop.exr").string();
        std::string out;
        ASSERT_EQ(runTessera("render " + rib + e + " -o " + full, &out), 0) << out;
        ASSERT_EQ(runTessera("render " + rib + e + " --crop 0.3,0.7,0.2,0.6 -o " + crop, &out), 0) << out;
        ASSERT_EQ(runTessera("render " + cropped + e + " -o " + ribCrop, &out), 0) << out;
        const ExrInfo info = readExrInfo(crop);
        EXPECT_EQ(info.displayX1, 63);
        EXPECT_EQ(info.displayY1, 47);
        EXPECT_EQ(info.dataX0, 20);  // ceil(64 * 0.3) = ceil(19.2)
        EXPECT_EQ(info.dataX1, 44);  // ceil(64 * 0.7) - 1 = 45 - 1
        EXPECT_EQ(info.dataY0, 10);  // ceil(9.6)
        EXPECT_EQ(info.dataY1, 28);  // ceil(28.8) - 1
        const Raw f = readRaw(full), c = readRaw(crop), rc = readRaw(ribCrop);
        int differing = 0, inside = 0;
        for (const auto& [name, values] : f.channels)
            for (int y = 0; y < 48; ++y)
                for (int x = 0; x < 64; ++x) {
                    const size_t i = size_t(y) * 64 + x;
                    const bool in = x >= 20 && x <= 44 && y >= 10 && y <= 28;
                    inside += in;
                    const uint32_t expect = in ? values[i] : 0xffffffffu;  // outside: not in the file
                    differing += c.channels.at(name)[i] != expect;
                    differing += rc.channels.at(name)[i] != expect;
                }
        EXPECT_EQ(differing, 0) << engine;
        EXPECT_EQ(inside, 4 * 25 * 19);
    }
    // PNG: the cropped pixels only.
    const std::string png = (dir / "crop.png").string();
    ASSERT_EQ(runTessera("render " + rib + " -q --threads 2 --crop 0.3,0.7,0.2,0.6 -o " + png), 0);
    const Image img = readPng(png);
    EXPECT_EQ(img.width, 25);
    EXPECT_EQ(img.height, 19);
}

TEST(Tiles, LocalFarmScriptEqualsTheSingleRender) {
    // scripts/render_tiles.sh: N tiles in parallel (xargs -P), then assemble.
    const std::string rib = writeScene("scene.rib");
    const fs::path dir = test::testScratchDir();
    const std::string full = (dir / "full.exr").string(), farm = (dir / "farm.exr").string();
    std::string out;
    ASSERT_EQ(runTessera("render " + rib + " -q --threads 1 --engine rt -o " + full, &out), 0) << out;
    const std::string script = std::string(TESSERA_SOURCE_DIR) + "/scripts/render_tiles.sh";
    const int status = std::system(("TESSERA='" + std::string(TESSERA_BINARY) + "' TESSERA_JOBS=2 " + script +
                                    " " + rib + " 4 " + farm + " --engine rt > /dev/null 2>&1")
                                       .c_str());
    ASSERT_EQ(WIFEXITED(status) ? WEXITSTATUS(status) : -1, 0);
    const Raw a = readRaw(full), b = readRaw(farm);
    for (const auto& [name, values] : a.channels) EXPECT_EQ(values, b.channels.at(name)) << name;
}

TEST(Tiles, AssembleAndTheOptionsRefuseBadInput) {
    const std::string rib = writeScene("scene.rib"), other = writeScene("other.rib", "Exposure 2 1\n");
    const fs::path dir = test::testScratchDir();
    auto tile = [&](const std::string& scene, int i, int n, const std::string& name) {
        const std::string path = (dir / name).string();
        std::string out;
        EXPECT_EQ(runTessera("render " + scene + " -q --threads 2 --tile " + std::to_string(i) + "/" +
                                 std::to_string(n) + " -o " + path,
                             &out),
                  0)
            << out;
        return path;
    };
    const std::string t0 = tile(rib, 0, 4, "t0.exr"), t1 = tile(rib, 1, 4, "t1.exr"),
                      t2 = tile(rib, 2, 4, "t2.exr"), t3 = tile(rib, 3, 4, "t3.exr"),
                      x3 = tile(other, 3, 4, "x3.exr"), h1 = tile(rib, 1, 2, "h1.exr");
    const std::string joined = (dir / "joined.exr").string();
    const std::pair<std::string, std::string> mistakes[] = {
        {t0 + " " + t1 + " " + t2, "tile 3 of 4 is missing"},
        {t0 + " " + t1 + " " + t2 + " " + t3 + " " + t1, "tile 1 given twice"},
        {t0 + " " + t1 + " " + t2 + " " + x3, "tile of another render"},
        {t0 + " " + t1 + " " + h1, "2-tile split"},
        {t0 + " " + (dir / "nonexistent.exr").string(), "no such tile file"},
        {t0 + " " + rib, "cannot read as OpenEXR"},
    };
    std::string out;
    for (const auto& [args, message] : mistakes) {
        EXPECT_EQ(runTessera("assemble " + args + " -o " + joined, &out), 2) << args << ": " << out;
        EXPECT_NE(out.find(message), std::string::npos) << args << ": " << out;
    }
    EXPECT_FALSE(fs::exists(joined));
    EXPECT_EQ(runTessera("assemble " + t0 + " " + t1 + " " + t2 + " " + t3 + " -o " + joined, &out), 0)
        << out;
    EXPECT_TRUE(fs::exists(joined));
    // Options: each a clear message and exit 2, no image written.
    const std::string never = (dir / "never.exr").string();
    const std::pair<const char*, const char*> options[] = {
        {"--crop 0.5,0.2,0,1", "needs 0 <= xmin < xmax <= 1"},
        {"--crop 0,1,0", "four numbers"},
        {"--crop a,b,c,d", "four numbers"},
        {"--crop 0,1.5,0,1", "needs 0 <= xmin"},
        {"--crop 0.001,0.002,0,1", "holds no pixel"},
        {"--tile 4/4", "0 <= I < N"},
        {"--tile 1/0", "0 <= I < N"},
        {"--tile -1/4", "0 <= I < N"},
        {"--tile 2", "is not I/N"},
        {"--tile 0/10007", "do not fit"},
        {"--aov albedoo", "unknown AOV 'albedoo'"},
    };
    for (const auto& [args, message] : options) {
        EXPECT_EQ(runTessera("render " + rib + " " + args + " -o " + never, &out), 2) << args << ": " << out;
        EXPECT_NE(out.find(message), std::string::npos) << args << ": " << out;
    }
    EXPECT_FALSE(fs::exists(never));
    // The RIB's CropWindow: checked where it stands.
    const std::string bad = writeScene("bad.rib", "CropWindow 0.5 0.4 0 1\n");
    EXPECT_EQ(runTessera("render " + bad + " -o " + never, &out), 2);
    EXPECT_NE(out.find("bad.rib:4: error: CropWindow: needs xmin < xmax"), std::string::npos) << out;
}

}  // namespace

namespace {
// Tiles of different frames of one multi-frame RIB share the file and the options: the frame is part of
// what `assemble` checks, so they are refused, while the tiles of one frame assemble.
TEST(Tiles, TilesOfDifferentFramesOfOneFileDoNotAssemble) {
    const fs::path dir = test::testScratchDir();
    const std::string frame =
        "Format 32 24 1\nWorldBegin\nLightSource \"distantlight\" 1\nSphere 1 -1 1 360\nWorldEnd\n";
    const std::string rib = test::writeTestFile(
        "two_frames.rib", "FrameBegin 1\nTranslate 0 0 4\n" + frame +
                              "FrameEnd\nFrameBegin 2\nTranslate 0 0 6\n" + frame + "FrameEnd\n");
    auto tile = [&](int frameNumber, int index) {
        const std::string out =
            (dir / ("f" + std::to_string(frameNumber) + "_" + std::to_string(index) + ".exr")).string();
        EXPECT_EQ(runTessera("render " + rib + " --frames " + std::to_string(frameNumber) + " --tile " +
                             std::to_string(index) + "/2 -q -o " + out),
                  0);
        return out;
    };
    const std::string a0 = tile(1, 0), a1 = tile(1, 1), b1 = tile(2, 1);
    std::string output;
    EXPECT_EQ(runTessera("assemble " + a0 + " " + b1 + " -o " + (dir / "mixed.exr").string(), &output), 2);
    EXPECT_NE(output.find("tile of another render"), std::string::npos) << output;
    EXPECT_FALSE(fs::exists(dir / "mixed.exr"));
    EXPECT_EQ(runTessera("assemble " + a0 + " " + a1 + " -o " + (dir / "one.exr").string(), &output), 0)
        << output;
}
}  // namespace

namespace {

// The "shadows" object of a --stats file.
nlohmann::json shadowStats(const std::string& statsPath) {
    std::ifstream f(statsPath);
    return nlohmann::json::parse(f).at("shadows");
}

std::string fileBytes(const fs::path& path) {
    std::ifstream f(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(f), {});
}

std::vector<fs::path> cachedMaps(const fs::path& dir) {
    std::vector<fs::path> maps;
    for (const auto& e : fs::directory_iterator(dir))
        if (e.path().extension() == ".tsm") maps.push_back(e.path());
    std::sort(maps.begin(), maps.end());
    return maps;
}

// A farm's shadow maps (--shadow-map-cache, --shadow-maps-only): one job renders the point light's six
// cube faces, every tile reads them (no depth pass of its own) and the assembled image equals the single
// render bit for bit; the maps read are the ones used (a cache of empty maps removes the shadow); a changed
// scene or a damaged file is a miss that renders and rewrites the map; the options' mistakes exit 2.
TEST(Tiles, ShadowMapCacheRendersTheMapsOnceForEveryTile) {
    const std::string rib = writeScene("scene.rib");
    const fs::path dir = test::testScratchDir(), cache = dir / "maps";
    const std::string common = rib + " -q --threads 2 --shadows on";
    std::string out;
    const std::string full = (dir / "full.exr").string();
    ASSERT_EQ(runTessera("render " + common + " -o " + full, &out), 0) << out;

    const std::string prepass = (dir / "prepass.json").string();
    ASSERT_EQ(runTessera("render " + common + " --shadow-map-cache " + cache.string() +
                             " --shadow-maps-only --stats " + prepass,
                         &out),
              0)
        << out;
    EXPECT_EQ(shadowStats(prepass)["cache"]["misses"], 6);  // the point light's cube map
    EXPECT_EQ(shadowStats(prepass)["cache"]["hits"], 0);
    EXPECT_EQ(cachedMaps(cache).size(), 6u);
    EXPECT_FALSE(fs::exists(dir / "scene.png"));  // no image

    std::string tiles;
    for (int i = 0; i < 4; ++i) {
        const std::string t = (dir / ("tile" + std::to_string(i) + ".exr")).string();
        const std::string stats = (dir / ("tile" + std::to_string(i) + ".json")).string();
        ASSERT_EQ(runTessera("render " + common + " --shadow-map-cache " + cache.string() + " --tile " +
                                 std::to_string(i) + "/4 -o " + t + " --stats " + stats,
                             &out),
                  0)
            << out;
        const nlohmann::json s = shadowStats(stats);
        EXPECT_EQ(s["cache"]["hits"], 6) << "tile " << i;
        EXPECT_EQ(s["cache"]["misses"], 0) << "tile " << i;
        EXPECT_EQ(s["maps"][0]["micropolygons"], 0) << "tile " << i << " rendered a depth pass";
        tiles += " " + t;
    }
    const std::string joined = (dir / "joined.exr").string();
    ASSERT_EQ(runTessera("assemble" + tiles + " -o " + joined, &out), 0) << out;
    const Raw a = readRaw(full), b = readRaw(joined);
    for (const auto& [name, values] : a.channels) EXPECT_EQ(values, b.channels.at(name)) << name;

    // The tiles read the maps from the files: replaced by maps that see nothing (infinite depth), the
    // shadow is gone and the image brightens where it was.
    const std::vector<fs::path> maps = cachedMaps(cache);
    const uintmax_t wholeSize = fs::file_size(maps[0]);
    for (const fs::path& m : maps) {
        std::string bytes = fileBytes(m);
        ASSERT_GT(bytes.size(), 16u);
        const float inf = std::numeric_limits<float>::infinity();
        for (size_t o = 16; o + 4 <= bytes.size(); o += 4) std::memcpy(&bytes[o], &inf, 4);
        std::ofstream(m, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
    }
    const std::string unshadowed = (dir / "unshadowed.exr").string();
    ASSERT_EQ(
        runTessera("render " + common + " --shadow-map-cache " + cache.string() + " -o " + unshadowed, &out),
        0)
        << out;
    const Image lit = readExr(unshadowed), shadowed = readExr(full);
    double brighter = 0;
    for (size_t i = 0; i < lit.rgba.size(); i += 4) brighter += std::max(0.f, lit.rgba[i] - shadowed.rgba[i]);
    EXPECT_GT(brighter, 1.0) << "the cached maps were not the ones used";

    // A damaged file (cut short) is a miss: rendered again and rewritten whole.
    fs::resize_file(maps[0], 100);
    const std::string again = (dir / "again.json").string();
    ASSERT_EQ(runTessera("render " + common + " --shadow-map-cache " + cache.string() +
                             " --shadow-maps-only --stats " + again,
                         &out),
              0)
        << out;
    EXPECT_EQ(shadowStats(again)["cache"]["misses"], 1);
    EXPECT_EQ(shadowStats(again)["cache"]["hits"], 5);
    EXPECT_EQ(fs::file_size(maps[0]), wholeSize);
    // Another scene (the small plane moved) shares no map with this one.
    std::string text = fileBytes(rib);
    const size_t at = text.find("-1.3 -0.9 5");
    ASSERT_NE(at, std::string::npos);
    const std::string other = test::writeTestFile("moved.rib", text.replace(at, 4, "-1.2"));
    const std::string otherStats = (dir / "other.json").string();
    ASSERT_EQ(runTessera("render " + other + " -q --shadows on --shadow-map-cache " + cache.string() +
                             " --shadow-maps-only --stats " + otherStats,
                         &out),
              0)
        << out;
    EXPECT_EQ(shadowStats(otherStats)["cache"]["misses"], 6);
    EXPECT_EQ(cachedMaps(cache).size(), 12u);

    // Mistakes: exit 2 with a message, nothing written.
    const std::string never = (dir / "never.exr").string();
    const std::pair<std::string, const char*> mistakes[] = {
        {"--shadow-maps-only", "give it"},
        {"--shadow-maps-only --engine rt --shadow-map-cache " + cache.string(), "makes no maps"},
        {"--shadow-maps-only -o " + never + " --shadow-map-cache " + cache.string(), "writes no image"},
        {"--shadow-map-cache " + rib + " -o " + never, "names a file, not a folder"},
    };
    for (const auto& [args, message] : mistakes) {
        EXPECT_EQ(runTessera("render " + rib + " " + args, &out), 2) << args << ": " << out;
        EXPECT_NE(out.find(message), std::string::npos) << args << ": " << out;
    }
    EXPECT_FALSE(fs::exists(never));
}

}  // namespace

}  // namespace tessera::test::tiles_tests
