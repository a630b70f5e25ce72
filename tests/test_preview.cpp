// Live preview (issue 17): --display-server HOST:PORT and RIB Display "framebuffer" stream the buckets to
// a tev viewer. A fake tev server on 127.0.0.1 decodes the packets as tev does (src/Ipc.cpp of
// github.com/Tom94/tev) and assembles the image, which must equal the EXR the same render writes.
#include <arpa/inet.h>
#include <fmt/core.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "io/display_client.h"
#include "io/image_io.h"
#include "test_support.h"

namespace tessera::test::preview_tests {

namespace fs = std::filesystem;

namespace {

// What the fake viewer saw.
struct ViewerLog {
    std::string imageName;
    int width = 0, height = 0;
    std::vector<std::string> channels;
    std::vector<float> rgba;  // width * height * 4, NaN where no update came
    int creates = 0, updates = 0, badPackets = 0;
    std::vector<std::string> problems;
};

// Reads the fields of one packet in tev's order; `ok` false once a read runs past the end.
struct PacketReader {
    const char* p;
    const char* end;
    bool ok = true;
    template <class T>
    T get() {
        T v{};
        if (end - p < ptrdiff_t(sizeof(T))) return ok = false, v;
        std::memcpy(&v, p, sizeof(T));
        p += sizeof(T);
        return v;
    }
    std::string string() {
        const char* z = static_cast<const char*>(std::memchr(p, 0, size_t(end - p)));
        if (!z) return ok = false, std::string();
        std::string s(p, z);
        p = z + 1;
        return s;
    }
};

void decode(const std::vector<char>& packet, ViewerLog& log) {
    PacketReader r{packet.data() + 4, packet.data() + packet.size()};
    const uint8_t type = r.get<uint8_t>();
    if (type == tev::kCreateImage) {
        r.get<uint8_t>();  // grab focus
        log.imageName = r.string();
        log.width = r.get<int32_t>(), log.height = r.get<int32_t>();
        const int n = r.get<int32_t>();
        log.channels.clear();
        for (int c = 0; c < n && r.ok; ++c) log.channels.push_back(r.string());
        if (!r.ok || r.p != r.end || log.width <= 0 || log.height <= 0) ++log.badPackets;
        log.rgba.assign(size_t(std::max(0, log.width)) * std::max(0, log.height) * 4, NAN);
        ++log.creates;
        return;
    }
    if (type != tev::kUpdateImageV3) {
        log.problems.push_back("unexpected packet type " + std::to_string(type));
        return;
    }
    r.get<uint8_t>();
    const std::string name = r.string();
    const int n = r.get<int32_t>();
    std::vector<std::string> names;
    for (int c = 0; c < n && r.ok; ++c) names.push_back(r.string());
    const int x = r.get<int32_t>(), y = r.get<int32_t>(), w = r.get<int32_t>(), h = r.get<int32_t>();
    std::vector<int64_t> offset(size_t(std::max(n, 0))), stride(size_t(std::max(n, 0)));
    for (auto& o : offset) o = r.get<int64_t>();
    for (auto& s : stride) s = r.get<int64_t>();
    ++log.updates;
    if (!r.ok || name != log.imageName || names != log.channels || x < 0 || y < 0 || w <= 0 || h <= 0 ||
        x + w > log.width || y + h > log.height) {
        ++log.badPackets;
        return;
    }
    const size_t floats = size_t(r.end - r.p) / sizeof(float);
    std::vector<float> data(floats);
    std::memcpy(data.data(), r.p, floats * sizeof(float));
    for (int c = 0; c < n; ++c) {
        if (size_t(offset[c] + (int64_t(w) * h - 1) * stride[c]) >= floats) {
            ++log.badPackets;
            return;
        }
        for (int i = 0; i < w * h; ++i)
            log.rgba[(size_t(y + i / w) * log.width + (x + i % w)) * 4 + c] = data[offset[c] + i * stride[c]];
    }
}

// A one-connection tev server on 127.0.0.1: port 0 picks a free one.
class FakeTev {
  public:
    explicit FakeTev(int port = 0) {
        fd_ = socket(AF_INET, SOCK_STREAM, 0);
        const int one = 1;
        setsockopt(fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_port = htons(uint16_t(port));
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        if (bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 || listen(fd_, 1) != 0) {
            close(fd_);
            fd_ = -1;
            return;
        }
        socklen_t len = sizeof a;
        getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len);
        port_ = ntohs(a.sin_port);
        thread_ = std::thread([this] { serve(); });
    }
    ~FakeTev() { stop(); }
    bool listening() const { return fd_ >= 0; }
    int port() const { return port_; }
    // Waits for the client to close its connection, then returns what came.
    const ViewerLog& log() {
        if (thread_.joinable()) thread_.join();
        return log_;
    }
    void stop() {
        if (fd_ >= 0) shutdown(fd_, SHUT_RDWR);
        if (thread_.joinable()) thread_.join();
        if (fd_ >= 0) close(fd_);
        fd_ = -1;
    }

  private:
    void serve() {
        pollfd p{fd_, POLLIN, 0};
        if (poll(&p, 1, 60000) <= 0) {  // a client that never comes fails the test instead of hanging it
            log_.problems.push_back("no client connected within 60 s");
            return;
        }
        const int c = accept(fd_, nullptr, nullptr);
        if (c < 0) return;
        std::vector<char> buffer;
        char chunk[65536];
        for (;;) {
            const ssize_t n = read(c, chunk, sizeof chunk);
            if (n <= 0) break;
            buffer.insert(buffer.end(), chunk, chunk + n);
            size_t at = 0;
            while (buffer.size() - at >= 4) {
                uint32_t len;
                std::memcpy(&len, buffer.data() + at, 4);
                if (len < 5) {
                    log_.problems.push_back("packet length " + std::to_string(len));
                    close(c);
                    return;
                }
                if (buffer.size() - at < len) break;
                decode(std::vector<char>(buffer.begin() + at, buffer.begin() + at + len), log_);
                at += len;
            }
            buffer.erase(buffer.begin(), buffer.begin() + at);
        }
        if (!buffer.empty())
            log_.problems.push_back(std::to_string(buffer.size()) + " bytes of a cut packet");
        close(c);
    }
    int fd_ = -1, port_ = 0;
    std::thread thread_;
    ViewerLog log_;
};

// Quadrics over a floor, two lights: a few hundred buckets of 8 pixels.
const char* kScene =
    "Format 96 72 1\nPixelSamples 2 2\nProjection \"perspective\" \"fov\" [40]\nTranslate 0 -0.5 6\n"
    "Rotate -110 1 0 0\nWorldBegin\nLightSource \"distantlight\" 1 \"from\" [1 2 3] \"to\" [0 0 0]\n"
    "LightSource \"ambientlight\" 2 \"intensity\" [0.2]\nSurface \"plastic\"\n"
    "AttributeBegin Color [0.9 0.3 0.2] Translate -0.8 0 0.7 Sphere 0.7 -0.7 0.7 360 AttributeEnd\n"
    "AttributeBegin Color [0.2 0.6 0.9] Translate 0.9 0.3 0 Cylinder 0.4 0 1.2 360 AttributeEnd\n"
    "Patch \"bilinear\" \"P\" [-3 -3 0 3 -3 0 -3 3 0 3 3 0]\nWorldEnd\n";

// The largest difference between the viewer's image and the EXR's pixels (half floats: relative 2^-11),
// and how many viewer pixels no update reached.
void compareWithExr(const ViewerLog& log, const Image& exr, double& maxRelative, int& missing) {
    maxRelative = 0, missing = 0;
    for (int y = 0; y < exr.height; ++y)
        for (int x = 0; x < exr.width; ++x)
            for (int c = 0; c < 4; ++c) {
                const float v = log.rgba[(size_t(y) * log.width + x) * 4 + c];
                if (std::isnan(v)) {
                    ++missing;
                    continue;
                }
                const float e = exr.pixel(x, y)[c];
                maxRelative =
                    std::max(maxRelative, std::abs(double(v) - e) / std::max(1e-3, std::abs(double(e))));
            }
}

}  // namespace

TEST(Preview, PacketsFollowTevsLayout) {
    const std::vector<char> create = tev::createImagePacket("a.exr", 3, 2, {"R", "G"});
    // 4 length + 1 type + 1 focus + "a.exr\0" + 3 int32 + "R\0G\0"
    ASSERT_EQ(create.size(), 4u + 1 + 1 + 6 + 12 + 4);
    uint32_t len;
    std::memcpy(&len, create.data(), 4);
    EXPECT_EQ(len, create.size());
    EXPECT_EQ(create[4], 4);
    const float px[2] = {0.5f, 2.f};
    const std::vector<char> update = tev::updateImagePacket("a.exr", {"R", "G"}, 1, 1, 1, 1, px);
    // + name + int32 n + names + 4 int32 + 2 x 2 int64 + 2 floats
    EXPECT_EQ(update.size(), 4u + 1 + 1 + 6 + 4 + 4 + 16 + 32 + 8);
    EXPECT_EQ(update[4], 6);
    ViewerLog log;
    decode(create, log);
    decode(update, log);
    EXPECT_EQ(log.badPackets, 0);
    EXPECT_EQ(log.rgba[(1 * 3 + 1) * 4 + 0], 0.5f);  // pixel (1,1); the viewer keeps 4 floats a pixel
    EXPECT_EQ(log.rgba[(1 * 3 + 1) * 4 + 1], 2.f);
}

TEST(Preview, DisplayAddressesAreHostAndPort) {
    std::string host;
    int port = 0;
    EXPECT_TRUE(DisplayClient::parseAddress("127.0.0.1:14158", host, port));
    EXPECT_EQ(host, "127.0.0.1");
    EXPECT_EQ(port, 14158);
    EXPECT_TRUE(DisplayClient::parseAddress("[::1]:80", host, port));
    EXPECT_EQ(host, "::1");
    for (const char* bad : {"localhost", ":80", "host:", "host:0", "host:65536", "host:8x", "host:123456"})
        EXPECT_FALSE(DisplayClient::parseAddress(bad, host, port)) << bad;
}

// Both engines, one pass and two (the viewer shows the running average), and an Imager background: the
// viewer's image is the written one, built from many bucket updates.
TEST(Preview, TheViewerAssemblesTheImageTheRenderWrites) {
    const fs::path dir = tessera::test::testScratchDir();
    std::ofstream(dir / "s.rib") << kScene;
    {  // without the floor, so that the background shows
        std::string bg = "Imager \"background\" \"background\" [0 0.1 0.3]\n" + std::string(kScene);
        bg.erase(bg.find("Patch \"bilinear\""), bg.find("WorldEnd") - bg.find("Patch \"bilinear\""));
        std::ofstream(dir / "bg.rib") << bg;
    }
    struct Case {
        const char* scene;
        const char* options;
        int updates;  // one per bucket: Reyes 8 px (12 x 9), the ray tracer 32 px at 4 spp (3 x 3)
    };
    for (const Case& c :
         {Case{"s.rib", "--engine reyes", 108}, Case{"s.rib", "--engine rt", 9},
          Case{"s.rib", "--engine rt --spp 8 --passes 2", 18}, Case{"bg.rib", "--engine reyes", 108}}) {
        SCOPED_TRACE(std::string(c.scene) + " " + c.options);
        FakeTev server;
        ASSERT_TRUE(server.listening());
        std::string out;
        const std::string args =
            fmt::format("render {} {} --bucket-size 8 -o out.exr --display-server 127.0.0.1:{}", c.scene,
                        c.options, server.port());
        ASSERT_EQ(runTesseraIn(dir, args, &out), 0) << out;
        EXPECT_EQ(out.find("warning"), std::string::npos) << out;
        const ViewerLog& log = server.log();
        EXPECT_TRUE(log.problems.empty()) << log.problems.front();
        EXPECT_EQ(log.badPackets, 0);
        EXPECT_EQ(log.creates, 1);
        EXPECT_EQ(log.imageName, "out.exr");
        EXPECT_EQ(log.width, 96);
        EXPECT_EQ(log.height, 72);
        EXPECT_EQ(log.channels, (std::vector<std::string>{"R", "G", "B", "A"}));
        EXPECT_EQ(log.updates, c.updates);
        const Image exr = readExr((dir / "out.exr").string());
        double maxRelative;
        int missing;
        compareWithExr(log, exr, maxRelative, missing);
        std::cout << c.scene << " " << c.options << ": " << log.updates
                  << " updates, max relative difference " << maxRelative << "\n";
        EXPECT_EQ(missing, 0);
        EXPECT_LT(maxRelative, 1e-3);  // the EXR's half floats
    }
}

// A crop window streams its pixels at their place in the display window.
TEST(Preview, ACropIsShownAtItsPlace) {
    const fs::path dir = tessera::test::testScratchDir();
    std::ofstream(dir / "s.rib") << kScene;
    FakeTev server;
    ASSERT_TRUE(server.listening());
    std::string out;
    ASSERT_EQ(runTesseraIn(dir,
                           fmt::format("render s.rib -q --crop 0.25,0.75,0.5,1 -o crop.exr --display-server "
                                       "127.0.0.1:{}",
                                       server.port()),
                           &out),
              0)
        << out;
    const ViewerLog& log = server.log();
    ASSERT_EQ(log.width, 96);
    const Image exr = readExr((dir / "crop.exr").string());
    int shown = 0, missing = 0, outside = 0;
    for (int y = 0; y < log.height; ++y)
        for (int x = 0; x < log.width; ++x) {
            const bool inCrop = x >= 24 && x < 72 && y >= 36;
            const float v = log.rgba[(size_t(y) * log.width + x) * 4];
            if (!inCrop) {
                outside += !std::isnan(v);
            } else if (std::isnan(v)) {
                ++missing;
            } else {
                ++shown;
                EXPECT_NEAR(v, exr.pixel(x, y)[0], 1e-3 * std::max(1.f, std::abs(v)));
            }
        }
    EXPECT_EQ(missing, 0);
    EXPECT_EQ(shown, 48 * 36);
    EXPECT_EQ(outside, 0);
}

// No server: a warning, and the render goes on and writes its image. A malformed address is an error.
TEST(Preview, AViewerThatIsNotListeningIsAWarning) {
    const fs::path dir = tessera::test::testScratchDir();
    std::ofstream(dir / "s.rib") << kScene;
    int freePort;
    {
        FakeTev probe;  // a port that was free a moment ago, closed again
        ASSERT_TRUE(probe.listening());
        freePort = probe.port();
    }
    std::string out;
    ASSERT_EQ(
        runTesseraIn(dir, fmt::format("render s.rib -o a.png --display-server 127.0.0.1:{}", freePort), &out),
        0)
        << out;
    EXPECT_NE(out.find(fmt::format("warning: display server 127.0.0.1:{}", freePort)), std::string::npos)
        << out;
    EXPECT_NE(out.find("the render goes on"), std::string::npos) << out;
    EXPECT_TRUE(fs::exists(dir / "a.png"));
    EXPECT_EQ(runTesseraIn(dir, "render s.rib -o b.png --display-server localhost", &out), 2);
    EXPECT_NE(out.find("--display-server 'localhost' is not HOST:PORT"), std::string::npos) << out;
    EXPECT_FALSE(fs::exists(dir / "b.png"));
}

// RIB Display "name" "framebuffer" "rgba": streamed to tev's default address, 127.0.0.1:14158 (skipped
// where that port is taken, e.g. by a real tev).
TEST(Preview, AFramebufferDisplayStreamsToTevsDefaultAddress) {
    const fs::path dir = tessera::test::testScratchDir();
    std::ofstream(dir / "fb.rib") << std::string(kScene).insert(
        0, "Display \"fb.exr\" \"framebuffer\" \"rgba\"\n");
    FakeTev server(14158);
    if (!server.listening()) GTEST_SKIP() << "port 14158 is in use";
    std::string out;
    ASSERT_EQ(runTesseraIn(dir, "render fb.rib -q", &out), 0) << out;
    const ViewerLog& log = server.log();
    EXPECT_EQ(log.creates, 1);
    EXPECT_EQ(log.imageName, "fb.exr");
    EXPECT_GT(log.updates, 0);
    EXPECT_TRUE(fs::exists(dir / "fb.exr"));  // the file is written as well
}

}  // namespace tessera::test::preview_tests
