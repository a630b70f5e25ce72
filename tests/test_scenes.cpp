// Every shipped scene renders with both engines: finite pixels, a sensible amount of coverage, and no
// pinholes (a see-through pixel whose eight neighbours are all covered) inside the silhouettes.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "io/image_io.h"
#include "io/scene_loader.h"
#include "render/render.h"
#include "test_support.h"
#include "test_util.h"

namespace tessera::test::scenes_tests {

namespace fs = std::filesystem;

struct SceneCase {
    const char* name;
    const char* engine;
    double minCoverage;  // fraction of the frame the model covers at least
};

// Readable and stable CTest names (the default printer shows the struct's bytes, pointers included).
[[maybe_unused]] void PrintTo(const SceneCase& c, std::ostream* os) {
    *os << c.name << " " << c.engine;
}

class ShippedScenes : public ::testing::TestWithParam<SceneCase> {};

TEST_P(ShippedScenes, RendersWithoutPinholes) {
    const SceneCase c = GetParam();
    Scene s =
        loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/" + c.name + ".rib", [](const std::string&) {});
    // Small frames keep the suite fast; keep the scene's aspect ratio.
    const double aspect = double(s.camera.width) / s.camera.height;
    s.camera.height = 180;
    s.camera.width = int(std::lround(180 * aspect));
    s.image.pixelSamplesX = s.image.pixelSamplesY = 2;
    RenderSettings rs;
    rs.engine = c.engine;
    rs.threads = 2;
    RenderResult r = render(s, rs);
    double coverage = 0;
    for (int y = 0; y < r.image.height; ++y)
        for (int x = 0; x < r.image.width; ++x) {
            const float* p = r.image.pixel(x, y);
            for (int k = 0; k < 4; ++k) ASSERT_TRUE(std::isfinite(p[k])) << x << "," << y;
            coverage += p[3];
        }
    coverage /= double(r.image.width) * r.image.height;
    EXPECT_GT(coverage, c.minCoverage) << c.name << " with " << c.engine;
    EXPECT_EQ(countPinholes(r.image), 0) << c.name << " with " << c.engine << ", coverage " << coverage;
}

INSTANTIATE_TEST_SUITE_P(
    BothEngines, ShippedScenes,
    ::testing::Values(SceneCase{"teapot", "reyes", 0.2}, SceneCase{"teapot", "rt", 0.2},
                      SceneCase{"killeroo", "reyes", 0.15}, SceneCase{"killeroo", "rt", 0.15},
                      SceneCase{"bigguy", "reyes", 0.25}, SceneCase{"bigguy", "rt", 0.25},
                      SceneCase{"killeroo2", "reyes", 0.1}, SceneCase{"killeroo2", "rt", 0.1},
                      SceneCase{"bigguy9", "reyes", 0.2}, SceneCase{"bigguy9", "rt", 0.2},
                      SceneCase{"bigguy24", "reyes", 0.1}, SceneCase{"bigguy24", "rt", 0.1},
                      SceneCase{"bigguy_box", "reyes", 0.6}, SceneCase{"bigguy_box", "rt", 0.6}),
    [](const ::testing::TestParamInfo<SceneCase>& info) {
        return std::string(info.param.name) + "_" + info.param.engine;
    });

// ---- every file directly in scenes/ is a scene (archives live in scenes/archives/) ------------------

namespace {

int runCli(const std::string& args, std::string* output = nullptr, const fs::path& cwd = {}) {
    fs::path log = tessera::test::testScratchDir() / "cli.log";
    std::string cmd = (cwd.empty() ? "" : "cd '" + cwd.string() + "' && ") + std::string(TESSERA_BINARY) +
                      " " + args + " > '" + log.string() + "' 2>&1";
    int status = std::system(cmd.c_str());
    if (output) {
        std::ifstream f(log);
        std::stringstream ss;
        ss << f.rdbuf();
        *output = ss.str();
    }
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace

namespace {
// Every regular file directly in scenes/ (the archives live in scenes/archives/), sorted.
std::vector<std::string> shippedSceneFiles() {
    const fs::path dir = fs::path(TESSERA_SOURCE_DIR) / "scenes";
    std::vector<std::string> files;
    for (const auto& e : fs::directory_iterator(dir))
        if (e.is_regular_file() && e.path().filename() != "README.md") files.push_back(e.path().filename());
    std::sort(files.begin(), files.end());
    return files;
}
}  // namespace

TEST(ShippedScenes, TheFolderHoldsScenesAndTheirArchives) {
    EXPECT_GE(shippedSceneFiles().size(), 7u);
    EXPECT_TRUE(fs::is_directory(fs::path(TESSERA_SOURCE_DIR) / "scenes" / "archives"));
}

// Through the CLI as a user would, cheaply (64x48, 1 sample per pixel): each file of scenes/ renders with
// both engines and covers part of the frame. One test per file (the list is read when the tests are
// listed, so a new scene gets its test), so that CTest spreads them over its jobs.
class ShippedSceneFile : public ::testing::TestWithParam<std::string> {};

TEST_P(ShippedSceneFile, RendersWithBothEngines) {
    const fs::path f = fs::path(TESSERA_SOURCE_DIR) / "scenes" / GetParam();
    const fs::path dir = tessera::test::testScratchDir();
    const fs::path out = dir / "scene.exr";
    // A multi-frame file (the shadow workflow): every frame in order first, in the scratch directory where
    // they write their products (depth maps, shadow maps), then the last frame again into `out`.
    int frames = 0;
    {
        std::ifstream in(f);
        for (std::string line; std::getline(in, line);) frames += line.rfind("FrameBegin", 0) == 0;
    }
    for (const char* engine : {"reyes", "rt"}) {
        std::string output, last;
        const std::string common =
            "render '" + f.string() + "' --engine " + engine + " --res 64x48 --spp 1 -q";
        if (frames > 1) {
            ASSERT_EQ(runCli(common, &output, dir), 0)
                << f.filename() << " with " << engine << ": " << output;
            last = " --frames " + std::to_string(frames);
        }
        int code = runCli(common + last + " -o '" + out.string() + "'", &output, dir);
        ASSERT_EQ(code, 0) << f.filename() << " with " << engine << ": " << output;
        Image img = readExr(out.string());
        double coverage = tessera::test::alphaSum(img) / (64.0 * 48.0);
        EXPECT_GT(coverage, 0.02) << f.filename() << " with " << engine;
        fs::remove(out);
    }
}

INSTANTIATE_TEST_SUITE_P(Files, ShippedSceneFile, ::testing::ValuesIn(shippedSceneFiles()),
                         [](const ::testing::TestParamInfo<std::string>& info) {
                             std::string name = info.param;
                             for (char& c : name)
                                 if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
                             return name;
                         });

// ---- default framing of inputs without a camera ----------------------------------------------------

namespace {

// One cubic Bezier segment of a profile in (radius, height), as 4 control points of a straight line.
struct Segment {
    float r0, h0, r1, h1;
};

// A surface of revolution about `up` (0 = x, 1 = y, 2 = z) through the origin: each profile segment
// becomes 4 patches (exact quarter circles in the two other axes). Returns .bpt text.
std::string revolvedBpt(const std::vector<Segment>& profile, int up,
                        std::vector<int>* segmentOfPatch = nullptr) {
    std::ostringstream o;
    o << profile.size() * 4 << "\n";
    for (size_t s = 0; s < profile.size(); ++s)
        for (int q = 0; q < 4; ++q) {
            o << "3 3\n";
            for (int v = 0; v < 4; ++v)
                for (int u = 0; u < 4; ++u) {
                    float x, y;
                    test::quarterCirclePoint(u, q, x, y);
                    const Segment& g = profile[s];
                    float radius = g.r0 + (g.r1 - g.r0) * v / 3.f, height = g.h0 + (g.h1 - g.h0) * v / 3.f;
                    float p[3];
                    p[up] = height;
                    p[(up + 1) % 3] = radius * x;
                    p[(up + 2) % 3] = radius * y;
                    o << p[0] << " " << p[1] << " " << p[2] << "\n";
                }
            if (segmentOfPatch) segmentOfPatch->push_back(int(s));
        }
    return o.str();
}

// A teacup modelled y-up, standing on y = 0: outer radius 4, height 4.5, walls 0.3 thick.
const float kCupR = 4.f, kCupH = 4.5f, kCupT = 0.3f;
std::vector<Segment> cupProfile() {
    return {{0, 0, kCupR, 0},                              // 0 bottom
            {kCupR, 0, kCupR, kCupH},                      // 1 outer wall
            {kCupR, kCupH, kCupR - kCupT, kCupH},          // 2 rim
            {kCupR - kCupT, kCupH, kCupR - kCupT, kCupT},  // 3 inner wall
            {kCupR - kCupT, kCupT, 0, kCupT}};             // 4 inner floor
}

Vec3 eyeOf(const Camera& c) {
    return c.cameraFromWorld.inverse().point({0, 0, 0});
}

// Every control point and 2000 points of the framing sphere project inside the frame, in front of the
// eye; the model's projection spans at least `minSpan` of the shorter image side.
void expectWholeSphereInFrame(const Scene& s, double minSpan) {
    Vec3 centre;
    float radius = 0;
    defaultFramingSphere(s, centre, radius);
    // Independent of how the sphere was computed: every control point lies inside it.
    for (const BezierPatch& p : s.patches)
        for (const Vec3& q : p.cp) ASSERT_LE(length(q - centre), radius * (1 + 1e-5f));
    Projector proj(s.camera);
    const float W = float(s.camera.width), H = float(s.camera.height);
    auto inside = [&](Vec3 world, const char* what) {
        Vec3 c = s.camera.cameraFromWorld.point(world);
        ASSERT_GT(c.z, s.camera.nearClip) << what;
        ASSERT_LT(c.z, s.camera.farClip) << what;
        Vec3 r = proj.toRaster(c);
        EXPECT_GE(r.x, 0.f) << what;
        EXPECT_LE(r.x, W) << what;
        EXPECT_GE(r.y, 0.f) << what;
        EXPECT_LE(r.y, H) << what;
    };
    const float golden = 2.39996323f;
    for (int i = 0; i < 2000; ++i) {  // Fibonacci sphere
        float z = 1 - 2 * (i + 0.5f) / 2000, rr = std::sqrt(1 - z * z), a = golden * i;
        inside(centre + Vec3{rr * std::cos(a), rr * std::sin(a), z} * radius, "sphere point");
    }
    float x0 = 1e30f, x1 = -1e30f, y0 = 1e30f, y1 = -1e30f;
    for (const BezierPatch& p : s.patches)
        for (const Vec3& q : p.cp) {
            inside(q, "control point");
            Vec3 r = proj.toRaster(s.camera.cameraFromWorld.point(q));
            x0 = std::min(x0, r.x), x1 = std::max(x1, r.x), y0 = std::min(y0, r.y), y1 = std::max(y1, r.y);
        }
    EXPECT_GT(std::max(x1 - x0, y1 - y0), minSpan * std::min(W, H)) << "the model is not lost in the frame";
}

// Rendered: nothing touches the frame's edge.
void expectNothingOnTheBorder(const Scene& s, double minCoverage = 0.05) {
    RenderSettings rs;
    rs.threads = 2;
    RenderResult r = render(s, rs);
    ASSERT_GT(tessera::test::alphaSum(r.image), minCoverage * r.image.width * r.image.height);
    for (int x = 0; x < r.image.width; ++x) {
        EXPECT_EQ(tessera::test::alphaAt(r.image, x, 0), 0.f) << x;
        EXPECT_EQ(tessera::test::alphaAt(r.image, x, r.image.height - 1), 0.f) << x;
    }
    for (int y = 0; y < r.image.height; ++y) {
        EXPECT_EQ(tessera::test::alphaAt(r.image, 0, y), 0.f) << y;
        EXPECT_EQ(tessera::test::alphaAt(r.image, r.image.width - 1, y), 0.f) << y;
    }
}

Scene loadQuiet(const std::string& path, std::optional<UpAxis> up = std::nullopt) {
    return loadScene(
        path, [](const std::string&) {}, SceneFormat::Auto, up);
}

}  // namespace

// The cup stands on y = 0: y is up, the eye is above the rim, and the inside of the cup is what the camera
// sees through the opening (the inner patches, coloured red, cover a good part of the image).
TEST(DefaultFraming, YUpCupShowsItsOpeningFromAbove) {
    std::vector<int> segment;
    const std::string path = tessera::test::writeTestFile("cup.bpt", revolvedBpt(cupProfile(), 1, &segment));
    ASSERT_EQ(chooseUpAxis(loadQuiet(path).patches), UpAxis::Y);
    Scene s = loadQuiet(path);
    const Vec3 eye = eyeOf(s.camera);
    EXPECT_GT(eye.y, kCupH) << "above the rim, so the opening faces the camera";
    Vec3 centre;
    float radius;
    defaultFramingSphere(s, centre, radius);
    EXPECT_GT(eye.y, centre.y);
    // The image's vertical is the world's y: the camera's up vector projects onto +y.
    const Mat4 w = s.camera.cameraFromWorld.inverse();
    EXPECT_GT(w.vector({0, 1, 0}).y, 0.5f);
    expectWholeSphereInFrame(s, 0.4);

    // Inner wall and floor red, the rest green, unlit colours.
    s.camera.width = 160;
    s.camera.height = 120;
    s.materials.assign(2, defaultMaterial(MaterialType::Constant));
    s.materials[0].Cs = {0, 1, 0};
    s.materials[1].Cs = {1, 0, 0};
    for (size_t i = 0; i < s.patches.size(); ++i) s.attributes[i].material = segment[i] >= 3 ? 1 : 0;
    RenderSettings rs;
    rs.threads = 2;
    RenderResult r = render(s, rs);
    int red = 0, covered = 0;
    for (int y = 0; y < r.image.height; ++y)
        for (int x = 0; x < r.image.width; ++x) {
            const float* p = r.image.pixel(x, y);
            if (p[3] < 0.99f) continue;
            ++covered;
            red += p[0] > 0.9f && p[1] < 0.1f;
        }
    ASSERT_GT(covered, 1000);
    EXPECT_GT(red, covered / 10) << "the inside of the cup is visible through its opening";
    expectNothingOnTheBorder(s);

    // The same cup framed as if z were up (the old rule for .bpt) is seen from below the rim.
    EXPECT_LT(eyeOf(loadQuiet(path, UpAxis::Z).camera).y, kCupH);
}

// A long thin spoon-like model, z up (standing on z = 0), long along x: nothing is cut off at 4:3, at a
// wide and at a tall aspect ratio (the field of view spans the shorter axis).
TEST(DefaultFraming, LongModelIsNeverCutOff) {
    std::string bpt;
    {
        std::vector<BezierPatch> bowl = tessera::test::octantSphere(1.f, {0, 0, 0});
        std::ostringstream o;
        o << bowl.size() << "\n";
        for (const BezierPatch& p : bowl) {
            o << "3 3\n";
            for (const Vec3& q : p.cp)
                o << q.x * 9.f << " " << q.y * 1.2f << " " << (q.z + 1.f) * 0.4f << "\n";
        }
        bpt = o.str();
    }
    const std::string path = tessera::test::writeTestFile("spoon.bpt", bpt);
    Scene s = loadQuiet(path);
    EXPECT_EQ(chooseUpAxis(s.patches), UpAxis::Z);
    EXPECT_GT(eyeOf(s.camera).z, 0.4f) << "above the centre";
    for (auto [w, h] : {std::pair{800, 600}, std::pair{900, 200}, std::pair{200, 900}}) {
        SCOPED_TRACE(std::to_string(w) + "x" + std::to_string(h));
        s.camera.width = w;
        s.camera.height = h;
        expectWholeSphereInFrame(s, 0.4);
    }
    s.camera.width = 200;
    s.camera.height = 60;
    expectNothingOnTheBorder(s, 0.005);  // a thin model in a wide frame: the sphere is far larger than it
}

// The up override: the same cup with --up x or z puts that axis up in the image.
TEST(DefaultFraming, UpOverrideIsHonoured) {
    const std::string path = tessera::test::writeTestFile("cup.bpt", revolvedBpt(cupProfile(), 1));
    for (UpAxis up : {UpAxis::X, UpAxis::Y, UpAxis::Z}) {
        Scene s = loadQuiet(path, up);
        const Vec3 upWorld = s.camera.cameraFromWorld.inverse().vector({0, 1, 0});
        const int a = up == UpAxis::X ? 0 : (up == UpAxis::Y ? 1 : 2);
        EXPECT_GT(upWorld[a], 0.5f) << upAxisName(up);
        expectWholeSphereInFrame(s, 0.4);
    }
}

// The shipped camera-less models keep sensible views: the up axis of each, the eye above the centre along
// it, the whole model in the frame at a good size and nothing on the border.
TEST(DefaultFraming, ShippedModelsKeepSensibleViews) {
    const std::string data = TESSERA_SHARED_DATA;
    struct Case {
        std::string path;
        UpAxis up;
    };
    for (const Case& c :
         {Case{data + "/teapot/teapot.bpt", UpAxis::Z}, Case{data + "/teapot/micropolis/teapot", UpAxis::Z},
          Case{data + "/bigguy/obj/bigguy.obj", UpAxis::Y},
          Case{data + "/bigguy/micropolis/bigguy", UpAxis::Y}}) {
        SCOPED_TRACE(c.path);
        if (!fs::exists(c.path)) GTEST_SKIP() << "shared data not present: " << c.path;
        Scene s = loadQuiet(c.path);
        EXPECT_EQ(defaultUpAxis(detectSceneFormat(c.path), s.patches), c.up);
        Vec3 centre;
        float radius;
        defaultFramingSphere(s, centre, radius);
        const int a = c.up == UpAxis::Y ? 1 : 2;
        EXPECT_GT(eyeOf(s.camera)[a], centre[a]);
        expectWholeSphereInFrame(s, 0.5);
        s.camera.width = 120;
        s.camera.height = 90;
        s.image.pixelSamplesX = s.image.pixelSamplesY = 1;
        expectNothingOnTheBorder(s);
    }
}

// The up-axis rule on boxes of control points.
TEST(DefaultFraming, UpAxisRule) {
    auto box = [](Vec3 lo, Vec3 hi) {
        BezierPatch p;
        for (int i = 0; i < 16; ++i) p.cp[i] = lo;
        p.cp[15] = hi;
        return std::vector<BezierPatch>{p};
    };
    EXPECT_EQ(chooseUpAxis(box({-3, -2, 0}, {3.5f, 2, 3.2f})), UpAxis::Z);         // teapot: stands on z = 0
    EXPECT_EQ(chooseUpAxis(box({-4, 0, -4}, {4, 4.5f, 4})), UpAxis::Y);            // y-up cup
    EXPECT_EQ(chooseUpAxis(box({0, -1, -1}, {5, 1, 1})), UpAxis::X);               // x-up
    EXPECT_EQ(chooseUpAxis(box({-2.7f, -3, -2.2f}, {2.7f, 3, 2.2f})), UpAxis::Y);  // centred, tallest along y
    EXPECT_EQ(chooseUpAxis(box({-9, -1, -0.4f}, {9, 1, 0.4f})), UpAxis::Z);        // centred, flat: z
    EXPECT_EQ(chooseUpAxis(box({0, 0, 0}, {2, 1, 1})), UpAxis::Z);  // a corner at the origin: no rule applies
    EXPECT_EQ(chooseUpAxis(box({-4, 0, -4}, {4, 4.5f, 4})), UpAxis::Y);
    EXPECT_EQ(defaultUpAxis(SceneFormat::Obj, box({-3, -2, 0}, {3.5f, 2, 3.2f})), UpAxis::Y)
        << "OBJ is y-up by convention, whatever the data";
}

}  // namespace tessera::test::scenes_tests
