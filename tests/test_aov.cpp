// AOVs end to end through the command line (--aov): the OpenEXR channels and header a compositor reads,
// against an analytic scene: two planes facing the eye at depths 5 and 7, objects 0 and 1.
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfMatrixAttribute.h>
#include <ImfStandardAttributes.h>
#include <ImfStringAttribute.h>
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

namespace tessera::test::aov_tests {

namespace fs = std::filesystem;

namespace {

int runTessera(const std::string& args, std::string* output = nullptr) {
    const fs::path log = fs::temp_directory_path() / ("tessera_aov_" + std::to_string(getpid()) + ".log");
    const int status =
        std::system((std::string(TESSERA_BINARY) + " " + args + " > '" + log.string() + "' 2>&1").c_str());
    if (output) {
        std::ifstream f(log);
        output->assign(std::istreambuf_iterator<char>(f), {});
    }
    fs::remove(log);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

constexpr int kW = 64, kH = 48;

// Left half: a plane at z = 5; right half: one at z = 7 (the RIB camera looks down +z). 40-degree view of
// the shorter (vertical) side.
fs::path writeScene(const fs::path& dir) {
    const fs::path rib = dir / "planes.rib";
    std::ofstream(rib)
        << "Format 64 48 1\nPixelSamples 2 2\nProjection \"perspective\" \"fov\" 40\n"
           "WorldBegin\nLightSource \"ambientlight\" 1 \"intensity\" 1\n"
           "AttributeBegin\nPatch \"bilinear\" \"P\" [-20 -20 5  0 -20 5  -20 20 5  0 20 5]\nAttributeEnd\n"
           "AttributeBegin\nPatch \"bilinear\" \"P\" [0 -20 7  20 -20 7  0 20 7  20 20 7]\nAttributeEnd\n"
           "WorldEnd\n";
    return rib;
}

struct Channels {
    std::map<std::string, std::vector<float>> f;
    std::vector<uint32_t> id;
    Imf::Header header;
};
Channels readChannels(const fs::path& exr) {
    Imf::InputFile file(exr.c_str());
    Channels c;
    c.header = file.header();
    const Imath::Box2i dw = file.header().dataWindow();
    const int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1;
    Imf::FrameBuffer fb;
    for (auto it = file.header().channels().begin(); it != file.header().channels().end(); ++it) {
        const std::string name = it.name();
        if (it.channel().type == Imf::UINT) {
            c.id.resize(size_t(w) * h);
            fb.insert(name, Imf::Slice(Imf::UINT, reinterpret_cast<char*>(c.id.data()), 4, 4 * size_t(w)));
        } else {
            std::vector<float>& v = c.f[name];
            v.resize(size_t(w) * h);
            fb.insert(name, Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(v.data()), 4, 4 * size_t(w)));
        }
    }
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
    return c;
}

TEST(Aov, DepthNormalAndIdOfTwoPlanesInBothEngines) {
    const fs::path dir = fs::temp_directory_path() / ("tessera_aov_" + std::to_string(getpid()));
    fs::create_directories(dir);
    const fs::path rib = writeScene(dir);
    for (const char* engine : {"reyes", "rt"}) {
        const fs::path exr = dir / (std::string(engine) + ".exr");
        std::string out;
        ASSERT_EQ(runTessera("render " + rib.string() + " --engine " + engine + " --aov z,N,id -q -o " +
                                 exr.string(),
                             &out),
                  0)
            << out;
        const Channels c = readChannels(exr);
        for (const char* name : {"R", "G", "B", "A", "Z", "N.X", "N.Y", "N.Z"})
            ASSERT_TRUE(c.f.count(name)) << engine << " lacks channel " << name;
        ASSERT_EQ(c.id.size(), size_t(kW * kH)) << engine;
        // Away from the seam at the centre column: depth 5 / 7 exactly (camera-space z of a plane facing the
        // eye), the normal facing the viewer, one id per plane.
        for (int y = 0; y < kH; ++y)
            for (int x = 0; x < kW; ++x) {
                if (std::abs(x + 0.5 - kW / 2.0) < 2) continue;
                const size_t i = size_t(y) * kW + x;
                const bool left = x < kW / 2;
                EXPECT_NEAR(c.f.at("Z")[i], left ? 5.f : 7.f, 1e-3) << engine << " " << x << "," << y;
                EXPECT_NEAR(c.f.at("N.Z")[i], -1.f, 1e-3) << engine << " " << x << "," << y;
                EXPECT_NEAR(c.f.at("N.X")[i], 0.f, 1e-3);
                EXPECT_EQ(c.id[i], left ? 0u : 1u) << engine << " " << x << "," << y;
            }
        // The header: software, and a worldToNDC that puts the view's centre at (0.5, 0.5), its top edge at
        // v = 0 and its right edge at u = 1 (NDC from the image's top-left corner), depth within [0, 1].
        const auto* sw = c.header.findTypedAttribute<Imf::StringAttribute>("software");
        ASSERT_NE(sw, nullptr);
        EXPECT_EQ(sw->value().rfind("tessera", 0), 0u);
        ASSERT_TRUE(Imf::hasWorldToNDC(c.header));
        ASSERT_TRUE(Imf::hasWorldToCamera(c.header));
        const Imath::M44f m = Imf::worldToNDC(c.header);
        auto ndc = [&](float x, float y, float z) {
            Imath::V3f p;
            m.multVecMatrix(Imath::V3f(x, y, z), p);
            return p;
        };
        const float t = 5.f * std::tan(20.f * 3.14159265f / 180.f);
        const Imath::V3f centre = ndc(0, 0, 5), top = ndc(0, t, 5), right = ndc(t * kW / kH, 0, 5);
        EXPECT_NEAR(centre.x, 0.5f, 1e-4) << engine;
        EXPECT_NEAR(centre.y, 0.5f, 1e-4);
        EXPECT_NEAR(top.y, 0.f, 1e-4);
        EXPECT_NEAR(right.x, 1.f, 1e-4);
        EXPECT_GT(centre.z, 0.f);
        EXPECT_LT(centre.z, 1.f);
    }
    fs::remove_all(dir);
}

TEST(Aov, OcclusionPlaneAndBadRequests) {
    const fs::path dir = fs::temp_directory_path() / ("tessera_aov_bad_" + std::to_string(getpid()));
    fs::create_directories(dir);
    const fs::path rib = writeScene(dir);
    const fs::path exr = dir / "ao.exr";
    std::string out;
    ASSERT_EQ(
        runTessera("render " + rib.string() +
                       " --engine rt --integrator ao --ao-samples 4 --aov occlusion -q -o " + exr.string(),
                   &out),
        0)
        << out;
    const Channels c = readChannels(exr);
    ASSERT_TRUE(c.f.count("occlusion"));
    // The nearer plane (left, z = 5) has nothing in front of it: 1. The farther one (right, z = 7) sees the
    // nearer one's half-plane 2 units in front of it on its left: partly occluded, most near the seam.
    const float* ao = c.f.at("occlusion").data();
    const size_t row = size_t(kH / 2) * kW;
    EXPECT_FLOAT_EQ(ao[row + 2], 1.f);
    EXPECT_LT(ao[row + kW / 2 + 2], ao[row + kW - 3]);
    EXPECT_LT(ao[row + kW - 3], 1.f);
    EXPECT_GT(ao[row + kW - 3], 0.5f);
    const std::pair<const char*, const char*> mistakes[] = {
        {"--aov depth", "unknown AOV 'depth'"},
        {"--aov z -o x.png", "OpenEXR"},
        {"--aov occlusion --engine rt", "--integrator ao"},
    };
    for (const auto& [args, message] : mistakes) {
        const std::string o = (dir / "never.exr").string();
        EXPECT_EQ(runTessera("render " + rib.string() + " " + args +
                                 (std::string(args).find("-o ") == std::string::npos ? " -o " + o : ""),
                             &out),
                  2)
            << args << ": " << out;
        EXPECT_NE(out.find(message), std::string::npos) << args << ": " << out;
    }
    EXPECT_FALSE(fs::exists(dir / "never.exr"));
    EXPECT_FALSE(fs::exists("x.png"));
    fs::remove_all(dir);
}

}  // namespace

// The surface AOVs on the two planes (left matte Kd 0.6 Cs (0.2 0.4 0.8), right a mirror): albedo Kd Cs
// and white for the mirror, Cs, camera-space P on the plane (z = 5 or 7, x and y along the pixel's line of
// sight), Ci and a equal to the image's own colour and alpha; colour layers named R, G, B.
TEST(Aov, AlbedoPositionSurfaceColourCiAndAlphaInBothEngines) {
    const fs::path dir = fs::temp_directory_path() / ("tessera_aov_surface_" + std::to_string(getpid()));
    fs::create_directories(dir);
    const fs::path rib = dir / "surface.rib";
    std::ofstream(rib) << "Format 64 48 1\nPixelSamples 2 2\nProjection \"perspective\" \"fov\" 40\n"
                          "WorldBegin\nLightSource \"ambientlight\" 1 \"intensity\" 1\n"
                          "AttributeBegin\nColor [0.2 0.4 0.8]\nSurface \"matte\" \"Kd\" [0.6]\n"
                          "Patch \"bilinear\" \"P\" [-20 -20 5  0 -20 5  -20 20 5  0 20 5]\nAttributeEnd\n"
                          "AttributeBegin\nSurface \"mirror\"\n"
                          "Patch \"bilinear\" \"P\" [0 -20 7  20 -20 7  0 20 7  20 20 7]\nAttributeEnd\n"
                          "WorldEnd\n";
    const float half = std::tan(20.f * 3.14159265f / 180.f);  // the view's half-height at z = 1
    for (const char* engine : {"reyes", "rt"}) {
        const fs::path exr = dir / (std::string(engine) + ".exr");
        std::string out;
        ASSERT_EQ(runTessera("render " + rib.string() + " --engine " + engine +
                                 " --aov albedo,P,Cs,Ci,a -q -o " + exr.string(),
                             &out),
                  0)
            << out;
        const Channels c = readChannels(exr);
        for (const char* name : {"albedo.R", "albedo.G", "albedo.B", "P.X", "P.Y", "P.Z", "Cs.R", "Cs.G",
                                 "Cs.B", "Ci.R", "Ci.G", "Ci.B", "a"})
            ASSERT_TRUE(c.f.count(name)) << engine << " lacks channel " << name;
        for (int y = 2; y < kH - 2; ++y)
            for (int x = 2; x < kW - 2; ++x) {
                if (std::abs(x + 0.5 - kW / 2.0) < 2) continue;
                const size_t i = size_t(y) * kW + x;
                const bool left = x < kW / 2;
                const float z = left ? 5.f : 7.f;
                SCOPED_TRACE(std::string(engine) + " " + std::to_string(x) + "," + std::to_string(y));
                EXPECT_NEAR(c.f.at("albedo.R")[i], left ? 0.12f : 1.f, 1e-4);
                EXPECT_NEAR(c.f.at("albedo.G")[i], left ? 0.24f : 1.f, 1e-4);
                EXPECT_NEAR(c.f.at("albedo.B")[i], left ? 0.48f : 1.f, 1e-4);
                EXPECT_NEAR(c.f.at("Cs.B")[i], left ? 0.8f : 1.f, 1e-4);
                EXPECT_NEAR(c.f.at("P.Z")[i], z, 1e-3);
                // The filtered P of a plane is the plane's point at the filter's centre of weight: within
                // a pixel's width of the pixel centre's line of sight.
                const float px = (2.f * (x + 0.5f) / kH - float(kW) / kH) * half * z;
                const float py = (1.f - 2.f * (y + 0.5f) / kH) * half * z;
                const float pixel = 2.f * half * z / kH;
                EXPECT_NEAR(c.f.at("P.X")[i], px, pixel);
                EXPECT_NEAR(c.f.at("P.Y")[i], py, pixel);
                EXPECT_FLOAT_EQ(c.f.at("a")[i], c.f.at("A")[i]);
                EXPECT_NEAR(c.f.at("Ci.G")[i], c.f.at("G")[i], 2e-3f);  // RGB is half precision
            }
    }
    fs::remove_all(dir);
}

// RIB Display "+name" type mode: secondary displays of the same render, each file the beauty and the
// layers its mode names; the primary keeps only its own (--aov's). Bad modes fail before the render.
TEST(Aov, SecondaryDisplaysWriteTheirOwnLayers) {
    const fs::path dir = fs::temp_directory_path() / ("tessera_aov_displays_" + std::to_string(getpid()));
    fs::create_directories(dir);
    const std::string world =
        "Format 64 48 1\nProjection \"perspective\" \"fov\" 40\nWorldBegin\n"
        "LightSource \"ambientlight\" 1 \"intensity\" 1\nColor [0.2 0.4 0.8]\nSurface \"matte\" \"Kd\" "
        "[0.6]\n"
        "Patch \"bilinear\" \"P\" [-20 -20 5  20 -20 5  -20 20 5  20 20 5]\nWorldEnd\n";
    const fs::path rib = dir / "s.rib";
    std::ofstream(rib) << "Display \"" << (dir / "beauty.exr").string() << "\" \"file\" \"rgba\"\n"
                       << "Display \"+" << (dir / "depth").string() << "\" \"openexr\" \"z\"\n"
                       << "Display \"+" << (dir / "denoise.exr").string() << "\" \"file\" \"albedo,N\"\n"
                       << "Display \"+" << (dir / "preview.png").string() << "\" \"file\" \"rgba\"\n"
                       << world;
    for (const char* engine : {"reyes", "rt"}) {
        SCOPED_TRACE(engine);
        for (const char* f : {"beauty.exr", "depth.exr", "denoise.exr", "preview.png"}) fs::remove(dir / f);
        std::string out;
        ASSERT_EQ(runTessera("render " + rib.string() + " --engine " + engine + " -q", &out), 0) << out;
        const Channels beauty = readChannels(dir / "beauty.exr");
        const Channels depth = readChannels(dir / "depth.exr");
        const Channels denoise = readChannels(dir / "denoise.exr");
        EXPECT_TRUE(fs::exists(dir / "preview.png"));
        EXPECT_EQ(beauty.f.count("Z") + beauty.f.count("N.X") + beauty.f.count("albedo.R"), 0u);
        ASSERT_TRUE(depth.f.count("Z"));
        EXPECT_EQ(depth.f.count("N.X") + depth.f.count("albedo.R"), 0u);
        ASSERT_TRUE(denoise.f.count("albedo.G") && denoise.f.count("N.Z"));
        EXPECT_EQ(denoise.f.count("Z"), 0u);
        for (const Channels* c : {&beauty, &depth, &denoise}) ASSERT_TRUE(c->f.count("R"));
        const size_t centre = size_t(kH / 2) * kW + kW / 2;
        EXPECT_NEAR(depth.f.at("Z")[centre], 5.f, 1e-3);
        EXPECT_NEAR(denoise.f.at("albedo.G")[centre], 0.24f, 1e-4);
        EXPECT_NEAR(denoise.f.at("N.Z")[centre], -1.f, 1e-3);
        EXPECT_EQ(beauty.f.at("G"), depth.f.at("G"));  // one render
    }
    // Bad modes: the file's line, exit 2, nothing written.
    auto fails = [&](const std::string& display, const std::string& expect) {
        const fs::path bad = dir / "bad.rib";
        std::ofstream(bad) << "Display \"" << (dir / "b.exr").string() << "\" \"file\" \"rgba\"\n"
                           << display << "\n"
                           << world;
        std::string out;
        EXPECT_EQ(runTessera("render " + bad.string() + " -q", &out), 2) << out;
        EXPECT_NE(out.find(bad.string() + ":2: error: Display"), std::string::npos) << out;
        EXPECT_NE(out.find(expect), std::string::npos) << out;
        EXPECT_FALSE(fs::exists(dir / "b.exr"));
    };
    fails("Display \"+x.exr\" \"file\" \"bogus\"", "unknown mode 'bogus'");
    fails("Display \"+x.png\" \"file\" \"z\"", "needs an OpenEXR file");
    fs::remove_all(dir);
}

}  // namespace tessera::test::aov_tests
