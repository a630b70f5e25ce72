// Shadow maps read from files (issue 13, the RenderMan workflow): a depth pass written by Display "zfile",
// MakeShadow, then the RI standard lights shadowspot, shadowdistant and shadowpoint reading the map by
// "shadowname" (or "raytrace"), in both engines; Hider "jitter" [0] for the depth pass.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "engine/frame.h"
#include "film/image_compare.h"
#include "io/diagnostics.h"
#include "io/image_io.h"
#include "io/rib_reader.h"
#include "io/rib_writer.h"
#include "test_support.h"

namespace tessera::test::shadow_files_tests {

namespace fs = std::filesystem;

namespace {

const WarningSink kQuiet = [](const std::string&) {};

void writeFile(const fs::path& path, const std::string& text) {
    std::ofstream(path) << text;
}

// A unit sphere centred 1.5 above a floor (z = 0), seen from above at an angle.
const char* kWorld =
    "AttributeBegin Translate 0 0 1.5 Surface \"matte\" Sphere 1 -1 1 360 AttributeEnd\n"
    "Surface \"matte\" Patch \"bilinear\" \"P\" [-6 -6 0 6 -6 0 -6 6 0 6 6 0]\n";

// The depth pass of a light at (0, 0, 6) looking down: camera space x' = -x, y' = y, z' = 6 - z.
std::string spotDepthFrame(int number, const std::string& zfile, int resolution = 256) {
    return "FrameBegin " + std::to_string(number) + "\nDisplay \"" + zfile + "\" \"zfile\" \"z\"\nFormat " +
           std::to_string(resolution) + " " + std::to_string(resolution) +
           " 1\nPixelSamples 1 1\nHider \"hidden\" \"jitter\" [0]\nProjection \"perspective\" \"fov\" [60]\n"
           "Scale -1 1 -1\nTranslate 0 0 -6\nWorldBegin\n" +
           std::string(kWorld) + "WorldEnd\nFrameEnd\n";
}

// The picture: an ambient light and `light` (a LightSource line), 96 x 72, seen from above.
std::string pictureFrame(int number, const std::string& display, const std::string& light,
                         const std::string& before = "") {
    return "FrameBegin " + std::to_string(number) + "\n" + before + "Display \"" + display +
           "\" \"file\" \"rgba\"\nFormat 96 72 1\nPixelSamples 3 3\nProjection \"perspective\" \"fov\" [40]\n"
           "Translate 0 0 14\nRotate -140 1 0 0\nWorldBegin\nLightSource \"ambientlight\" 1 \"intensity\" "
           "[0.1]\n" +
           light + "\n" + kWorld + "WorldEnd\nFrameEnd\n";
}

const std::string kSpot = " \"intensity\" [36] \"from\" [0 0 6] \"to\" [0 0 0] \"coneangle\" [0.6]";

double psnr(const fs::path& a, const fs::path& b) {
    return compareImages(readExr(a.string()), readExr(b.string())).psnrColor;
}

// The shadowspot of frame 2 of `rib` as the frame prepares it (camera space), with its map lookup.
struct PreparedFrame {
    Scene scene;
    std::unique_ptr<FrameSetup> frame;
};
PreparedFrame prepare(const fs::path& rib, size_t frameIndex) {
    PreparedFrame p;
    readRibFrame(rib.string(), frameIndex, p.scene, kQuiet);
    RenderSettings rs;
    p.frame = std::make_unique<FrameSetup>(p.scene, rs);
    return p;
}

}  // namespace

// The workflow end to end through the CLI: the map's shadow is there, both engines read the same map and
// agree, and the map agrees with ray-traced hard shadows; "raytrace" as the name traces in both engines.
TEST(ShadowFiles, ShadowspotReadsTheMapOfMakeShadowInBothEngines) {
    const fs::path dir = tessera::test::testScratchDir();
    writeFile(dir / "s.rib",
              spotDepthFrame(1, "spot.z") +
                  pictureFrame(2, "map.exr",
                               "LightSource \"shadowspot\" 2" + kSpot + " \"shadowname\" [\"spot.shad\"]",
                               "MakeShadow \"spot.z\" \"spot.shad\"\n"));
    writeFile(dir / "rays.rib",
              pictureFrame(1, "rays.exr",
                           "LightSource \"shadowspot\" 2" + kSpot + " \"shadowname\" [\"raytrace\"]"));
    writeFile(dir / "none.rib", pictureFrame(1, "none.exr", "LightSource \"spotlight\" 2" + kSpot));
    std::string out;
    ASSERT_EQ(runTesseraIn(dir, "render s.rib -q", &out), 0) << out;
    ASSERT_TRUE(fs::exists(dir / "spot.shad"));
    fs::rename(dir / "map.exr", dir / "reyes_map.exr");
    ASSERT_EQ(runTesseraIn(dir, "render s.rib -q --frames 2 --engine rt -o rt_map.exr", &out), 0) << out;
    ASSERT_EQ(runTesseraIn(dir, "render rays.rib -q --engine rt -o rt_rays.exr", &out), 0) << out;
    ASSERT_EQ(runTesseraIn(dir, "render rays.rib -q -o reyes_rays.exr --stats reyes_rays.json", &out), 0)
        << out;
    ASSERT_EQ(runTesseraIn(dir, "render none.rib -q --engine rt -o rt_none.exr", &out), 0) << out;
    const double engines = psnr(dir / "reyes_map.exr", dir / "rt_map.exr");
    const double mapVsRays = psnr(dir / "rt_map.exr", dir / "rt_rays.exr");
    const double tracedEngines = psnr(dir / "reyes_rays.exr", dir / "rt_rays.exr");
    const double noShadow = psnr(dir / "rt_none.exr", dir / "rt_rays.exr");
    RecordProperty("reyes_vs_rt_same_map_db", std::to_string(engines));
    RecordProperty("map_vs_rays_db", std::to_string(mapVsRays));
    std::cout << "Reyes vs rt, one map: " << engines << " dB; map vs ray-traced: " << mapVsRays
              << " dB; Reyes vs rt, both \"raytrace\": " << tracedEngines
              << " dB; no shadows vs ray-traced: " << noShadow << " dB\n";
    EXPECT_GE(engines, 40.0);
    EXPECT_GE(mapVsRays, 32.0);
    EXPECT_GE(tracedEngines, 36.0);
    EXPECT_LT(noShadow, mapVsRays - 8.0);  // the shadow is a real part of the picture
    // Reyes answered "raytrace" with shadow rays (the trace service), not with a map of its own.
    std::ifstream stats(dir / "reyes_rays.json");
    const nlohmann::json j = nlohmann::json::parse(stats);
    EXPECT_EQ(j["shadows"]["method"], "raytrace");
    EXPECT_GT(j["shadows"]["shadow_rays"].get<double>(), 0.0);
}

// The map's shadow outline against the analytic one: a unit sphere 4.5 below a point light at 6 casts a
// disk of radius 6 tan(asin(1 / 4.5)) on the floor. Along rays from the centre, the lookup is 0 inside,
// 1 outside, and crosses 1/2 within the filter's reach of the analytic radius.
TEST(ShadowFiles, TheMapsShadowOutlineMatchesTheAnalyticProjection) {
    const fs::path dir = tessera::test::testScratchDir();
    writeFile(dir / "s.rib",
              spotDepthFrame(1, "spot.z", 512) +
                  pictureFrame(2, "map.png",
                               "LightSource \"shadowspot\" 2" + kSpot + " \"shadowname\" [\"spot.shad\"]",
                               "MakeShadow \"spot.z\" \"spot.shad\"\n"));
    std::string out;
    ASSERT_EQ(runTesseraIn(dir, "render s.rib -q --frames 1", &out), 0) << out;
    // Frame 2 read in this directory (MakeShadow runs as it is read).
    const fs::path cwd = fs::current_path();
    fs::current_path(dir);
    PreparedFrame p = prepare(dir / "s.rib", 1);
    fs::current_path(cwd);
    ASSERT_EQ(p.scene.lights.size(), 2u);
    EXPECT_EQ(p.scene.lights[1].shadowSource, ShadowSource::File);
    const ShadingLight& light = p.frame->lights[1];
    ASSERT_NE(light.shadowMap, nullptr);
    EXPECT_FALSE(light.castsShadows);  // looked up, never asked as a visibility query
    const double radius = 6.0 * std::tan(std::asin(1.0 / 4.5));
    // A texel at the floor: 2 * 6 tan(30 deg) / 512 world units; the filter box is 2 texels.
    const double texel = 12.0 * std::tan(M_PI / 6) / 512.0;
    const Mat4& toCamera = p.frame->camera.cameraFromWorld;
    const Mat4 normalM = toCamera.inverse();
    const Vec3 N = normalize(Mat4::normalWithInverse(normalM, Vec3{0, 0, 1}));
    double worst = 0;
    for (int k = 0; k < 16; ++k) {
        const double phi = 2 * M_PI * (k + 0.3) / 16;
        auto visibility = [&](double r) {
            const Vec3 P = toCamera.point(Vec3{float(r * std::cos(phi)), float(r * std::sin(phi)), 0.f});
            return shadowMapVisibility(*light.shadowMap, P, N);
        };
        EXPECT_EQ(visibility(0.3), 0.f) << "inside, direction " << k;
        EXPECT_EQ(visibility(radius - 0.8), 0.f) << "inside, direction " << k;
        EXPECT_EQ(visibility(radius + 0.8), 1.f) << "outside, direction " << k;
        EXPECT_EQ(visibility(3.0), 1.f) << "outside, direction " << k;
        // Bisection for the crossing of 1/2 (the lookup rises monotonically across the edge).
        double lo = radius - 0.5, hi = radius + 0.5;
        for (int i = 0; i < 40; ++i) {
            const double mid = 0.5 * (lo + hi);
            (visibility(mid) < 0.5f ? lo : hi) = mid;
        }
        EXPECT_NEAR(lo, radius, 2.0 * texel) << "direction " << k;
        worst = std::max(worst, std::fabs(lo - radius) / texel);
    }
    std::cout << "outline: the lookup crosses 1/2 within " << worst << " texels of the analytic radius\n";
}

// shadowdistant with an orthographic depth pass along the light, and shadowpoint with six 90-degree
// faces around a point light: each agrees with the ray tracer's hard shadows of the same light.
TEST(ShadowFiles, ShadowdistantAndShadowpointReadOrthographicAndCubeMaps) {
    const fs::path dir = tessera::test::testScratchDir();
    // Distant light straight down: an orthographic camera above the scene looking down, 8 x 8 units.
    std::string rib =
        "FrameBegin 1\nDisplay \"sun.z\" \"zfile\" \"z\"\nFormat 512 512 1\nPixelSamples 1 1\n"
        "Hider \"hidden\" \"jitter\" [0]\nProjection \"orthographic\"\nScreenWindow -4 4 -4 4\n"
        "Scale -1 1 -1\nTranslate 0 0 -10\nWorldBegin\n" +
        std::string(kWorld) + "WorldEnd\nFrameEnd\n";
    // Point light at (0, 0, 6): faces +x, -x, +y, -y, +z, -z (camera z along the axis), fov 90.
    const char* faces[6] = {"px", "nx", "py", "ny", "pz", "nz"};
    // Rows x, y, z of each face's camera frame (z = the axis), in RIB's row-vector Transform layout.
    const double axes[6][3][3] = {
        {{0, 0, 1}, {0, 1, 0}, {1, 0, 0}},  {{0, 0, -1}, {0, 1, 0}, {-1, 0, 0}},
        {{1, 0, 0}, {0, 0, 1}, {0, 1, 0}},  {{1, 0, 0}, {0, 0, -1}, {0, -1, 0}},
        {{-1, 0, 0}, {0, 1, 0}, {0, 0, 1}}, {{1, 0, 0}, {0, 1, 0}, {0, 0, -1}},
    };
    const double eye[3] = {0, 0, 6};
    for (int f = 0; f < 6; ++f) {
        std::string m;
        for (int i = 0; i < 3; ++i) {
            for (int j = 0; j < 3; ++j) m += std::to_string(axes[f][j][i]) + " ";
            m += "0 ";
        }
        for (int j = 0; j < 3; ++j) {
            double t = 0;
            for (int i = 0; i < 3; ++i) t -= axes[f][j][i] * eye[i];
            m += std::to_string(t) + " ";
        }
        m += "1";
        rib += "FrameBegin " + std::to_string(2 + f) + "\nDisplay \"point_" + faces[f] +
               ".z\" \"zfile\" \"z\"\nFormat 256 256 1\nPixelSamples 1 1\nHider \"hidden\" \"jitter\" [0]\n"
               "Projection \"perspective\" \"fov\" [90]\nTransform [" +
               m + "]\nWorldBegin\n" + kWorld + "WorldEnd\nFrameEnd\n";
    }
    std::string makes = "MakeShadow \"sun.z\" \"sun.shad\"\n", names;
    for (int f = 0; f < 6; ++f) {
        makes += std::string("MakeShadow \"point_") + faces[f] + ".z\" \"point_" + faces[f] + ".shad\"\n";
        names += std::string(" \"sf") + faces[f] + "\" [\"point_" + faces[f] + ".shad\"]";
    }
    const std::string sun = " \"intensity\" [0.9] \"from\" [0 0 10] \"to\" [0 0 0]";
    const std::string bulb = " \"intensity\" [30] \"from\" [0 0 6]";
    rib += pictureFrame(8, "sun_map.exr",
                        "LightSource \"shadowdistant\" 2" + sun + " \"shadowname\" [\"sun.shad\"]", makes);
    rib += pictureFrame(9, "point_map.exr", "LightSource \"shadowpoint\" 2" + bulb + names);
    rib += pictureFrame(10, "sun_rays.exr",
                        "LightSource \"shadowdistant\" 2" + sun + " \"shadowname\" [\"raytrace\"]");
    rib += pictureFrame(11, "point_rays.exr",
                        "Attribute \"light\" \"shadows\" [\"on\"] LightSource \"pointlight\" 2" + bulb);
    writeFile(dir / "s.rib", rib);
    std::string out;
    ASSERT_EQ(runTesseraIn(dir, "render s.rib -q --engine rt", &out), 0) << out;
    const double sun_db = psnr(dir / "sun_map.exr", dir / "sun_rays.exr");
    const double point_db = psnr(dir / "point_map.exr", dir / "point_rays.exr");
    std::cout << "shadowdistant (orthographic map) vs rays: " << sun_db
              << " dB; shadowpoint (six faces) vs rays: " << point_db << " dB\n";
    EXPECT_GE(sun_db, 32.0);
    EXPECT_GE(point_db, 32.0);
    // Reyes reads the same maps.
    ASSERT_EQ(runTesseraIn(dir, "render s.rib -q --frames 9 -o point_reyes.exr", &out), 0) << out;
    EXPECT_GE(psnr(dir / "point_reyes.exr", dir / "point_map.exr"), 38.0);
}

// Bad input names the file and line, exits 2, and leaves the frames before it written.
TEST(ShadowFiles, MissingOrWrongMapsAndBadNamesAreErrorsAtTheirLine) {
    const fs::path dir = tessera::test::testScratchDir();
    const std::string spot = "LightSource \"shadowspot\" 2" + kSpot;
    auto fails = [&](const std::string& name, const std::string& light, const std::string& expect) {
        writeFile(dir / (name + ".rib"),
                  pictureFrame(1, name + "_first.png", "") + pictureFrame(2, name + ".png", light));
        std::string out;
        EXPECT_EQ(runTesseraIn(dir, "render " + name + ".rib -q", &out), 2) << name << ": " << out;
        EXPECT_NE(out.find(name + ".rib:"), std::string::npos) << out;
        EXPECT_NE(out.find(expect), std::string::npos) << name << ": " << out;
        EXPECT_TRUE(fs::exists(dir / (name + "_first.png"))) << name << ": the earlier frame stays written";
        EXPECT_FALSE(fs::exists(dir / (name + ".png"))) << name;
    };
    fails("missing", spot + " \"shadowname\" [\"nowhere.shad\"]", "shadow map \"nowhere.shad\" not found");
    Image rgba(4, 4);
    writeExr((dir / "picture.exr").string(), rgba);
    fails("rgba", spot + " \"shadowname\" [\"picture.exr\"]", "not a depth map");
    writeFile(dir / "depth.rib", spotDepthFrame(1, "d.z", 16));
    std::string out;
    ASSERT_EQ(runTesseraIn(dir, "render depth.rib -q", &out), 0) << out;
    fails("mixed", "LightSource \"shadowpoint\" 2 \"sfpx\" [\"raytrace\"] \"sfnx\" [\"d.z\"]",
          "the shadow map names mix \"raytrace\" with files");
    fails("width", spot + " \"shadowname\" [\"raytrace\"] \"width\" [0]", "\"width\" must be above 0");
}

// Hider "hidden" "jitter" [0]: one sample at each pixel's centre, so a depth pass's depth is the surface's
// depth at the texel centre that lookups assume (a plane tilted in x: exact to rounding; jittered, not).
TEST(ShadowFiles, HiderJitterOffPutsDepthSamplesAtTexelCentres) {
    const fs::path dir = tessera::test::testScratchDir();
    const std::string body =
        "Format 32 32 1\nPixelSamples 1 1\nProjection \"perspective\" \"fov\" [40]\nWorldBegin\n"
        "Patch \"bilinear\" \"P\" [-4 -4 3  4 -4 7  -4 4 3  4 4 7]\nWorldEnd\n";  // z = 5 + x / 2
    writeFile(dir / "centred.rib",
              "Display \"centred.z\" \"zfile\" \"z\"\nHider \"hidden\" \"jitter\" [0]\n" + body);
    writeFile(dir / "jittered.rib", "Display \"jittered.z\" \"zfile\" \"z\"\n" + body);
    std::string out;
    for (const char* engine : {"reyes", "rt"}) {
        SCOPED_TRACE(engine);
        ASSERT_EQ(runTesseraIn(dir, std::string("render centred.rib -q --engine ") + engine, &out), 0) << out;
        ASSERT_EQ(runTesseraIn(dir, std::string("render jittered.rib -q --engine ") + engine, &out), 0)
            << out;
        double worst[2] = {0, 0};
        for (int k = 0; k < 2; ++k) {
            const DepthMap z = readDepthMap((dir / (k == 0 ? "centred.z" : "jittered.z")).string());
            ShadowMapFace face;
            ASSERT_EQ(fileShadowMapFace(z.worldToCamera, z.worldToNDC, z.width, z.height, Mat4{}, face), "");
            for (int y = 4; y < 28; ++y)
                for (int x = 4; x < 28; ++x) {
                    // The line of sight (a z, b z, z) through the texel centre meets z = 5 + a z / 2.
                    const double a = (x + 0.5 - face.ox) / face.sx;
                    const double expected = 5.0 / (1.0 - 0.5 * a);
                    worst[k] = std::max(worst[k], std::fabs(z.depth[size_t(y) * 32 + x] - expected));
                }
        }
        std::cout << engine << ": worst depth error at texel centres, centred " << worst[0] << ", jittered "
                  << worst[1] << "\n";
        EXPECT_LT(worst[0], 2e-3);
        EXPECT_GT(worst[1], 5 * worst[0]);  // the test tells the two apart
    }
}

// `tessera convert` writes the shadowing lights back with their map names (absolute) and width.
TEST(ShadowFiles, TheRibWriterKeepsShadowspotAndItsMap) {
    const fs::path dir = tessera::test::testScratchDir();
    writeFile(dir / "depth.rib", spotDepthFrame(1, "spot.z", 64));
    writeFile(dir / "p.rib", "MakeShadow \"spot.z\" \"spot.shad\"\n" +
                                 pictureFrame(1, "p.png",
                                              "LightSource \"shadowspot\" 2" + kSpot +
                                                  " \"shadowname\" [\"spot.shad\"] \"width\" [2]"));
    std::string out;
    ASSERT_EQ(runTesseraIn(dir, "render depth.rib -q", &out), 0) << out;
    ASSERT_EQ(runTesseraIn(dir, "convert p.rib -o c.rib", &out), 0) << out;
    Scene back;
    readRibFrame((dir / "c.rib").string(), 0, back, kQuiet);
    const Light* spot = nullptr;
    for (const Light& l : back.lights)
        if (l.type == LightType::Spot) spot = &l;
    ASSERT_NE(spot, nullptr) << out;
    EXPECT_EQ(spot->shadowSource, ShadowSource::File);
    EXPECT_FLOAT_EQ(spot->shadowWidth, 2.f);
    ASSERT_GE(spot->shadowFiles[0], 0);
    EXPECT_TRUE(fs::equivalent(back.shadowMapFiles[size_t(spot->shadowFiles[0])].path, dir / "spot.shad"));
}

}  // namespace tessera::test::shadow_files_tests
