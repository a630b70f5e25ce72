// RIB retained geometry (ObjectBegin / ObjectEnd / ObjectInstance, RI spec 3.2, "Retained Geometry") and
// Option "searchpath" "archive" for ReadArchive: an instanced object renders as the geometry written out at
// each instance (both engines, the same image), handles by number and by string, transformations and
// attributes at the instance, and the errors naming the line.
#include <gtest/gtest.h>

#include <string>

#include "render/render.h"
#include "rib_test_util.h"
#include "test_util.h"

namespace tessera::test::rib_objects_tests {
namespace {

// A small object: a GeneralPolygon with a hole, a bilinear patch and a sphere, with a translation inside.
const char* kObjectBody =
    "GeneralPolygon [4 4] \"P\" [-0.5 -0.5 0  0.5 -0.5 0  0.5 0.5 0  -0.5 0.5 0 "
    " -0.2 -0.2 0  -0.2 0.2 0  0.2 0.2 0  0.2 -0.2 0]\n"
    "AttributeBegin\nTranslate 0.1 0 0.2\nColor [0.2 0.9 0.3]\n"
    "Patch \"bilinear\" \"P\" [-0.3 -0.3 0  0.3 -0.3 0  -0.3 0.3 0.1  0.3 0.3 0.1]\nAttributeEnd\n"
    "Sphere 0.15 -0.15 0.15 360\n";

std::string sceneWith(const std::string& world, const std::string& before = "") {
    return "Format 64 48 1\nPixelSamples 2 2\nProjection \"perspective\" \"fov\" [40]\nTranslate 0 0 4\n" +
           before +
           "WorldBegin\nLightSource \"distantlight\" 1 \"from\" [0 0 -1] \"to\" [0 0 0]\n"
           "LightSource \"ambientlight\" 2 \"intensity\" [0.2]\nSurface \"plastic\"\n" +
           world + "WorldEnd\n";
}

// The instances: two transforms and colours, the object by handle `h`; written out: the same geometry
// inside attribute blocks.
std::string instances(const std::string& h) {
    return "AttributeBegin\nTranslate -0.7 0 0\nRotate 30 0 1 0\nColor [0.9 0.2 0.2]\nObjectInstance " + h +
           "\nAttributeEnd\nAttributeBegin\nTranslate 0.7 0.1 0\nScale 0.8 0.8 0.8\nObjectInstance " + h +
           "\nAttributeEnd\n";
}
std::string writtenOut() {
    return "AttributeBegin\nTranslate -0.7 0 0\nRotate 30 0 1 0\nColor [0.9 0.2 0.2]\nAttributeBegin\n" +
           std::string(kObjectBody) +
           "AttributeEnd\nAttributeEnd\nAttributeBegin\nTranslate 0.7 0.1 0\nScale 0.8 0.8 0.8\n"
           "AttributeBegin\n" +
           kObjectBody + "AttributeEnd\nAttributeEnd\n";
}

void expectSameScene(const Scene& a, const Scene& b) {
    ASSERT_EQ(a.patches.size(), b.patches.size());
    for (size_t i = 0; i < a.patches.size(); ++i)
        for (int k = 0; k < 16; ++k) EXPECT_TRUE(a.patches[i].cp[k] == b.patches[i].cp[k]) << i << " " << k;
    ASSERT_EQ(a.attributes.size(), b.attributes.size());
    for (size_t i = 0; i < a.attributes.size(); ++i)
        EXPECT_TRUE(a.materials[a.attributes[i].material] == b.materials[b.attributes[i].material]) << i;
    ASSERT_EQ(a.quadrics.size(), b.quadrics.size());
}

// `a` has the instances, `b` the geometry written out. Bit for bit, with the ray tracer's instancing off
// (with it, the instances' patches test their prototype's boxes with the ray moved into its frame, which
// rounds differently: tests/test_rt_instancing.cpp compares those images to a tolerance).
void expectSameImages(const Scene& a, const Scene& b) {
    for (const char* engine : {"reyes", "rt"}) {
        SCOPED_TRACE(engine);
        RenderSettings rs;
        rs.engine = engine;
        rs.threads = 2;
        rs.instancing = false;
        const Image ia = render(a, rs).image, ib = render(b, rs).image;
        ASSERT_EQ(ia.width, ib.width);
        double covered = 0;
        int differ = 0;
        for (int y = 0; y < ia.height; ++y)
            for (int x = 0; x < ia.width; ++x) {
                covered += alphaAt(ia, x, y);
                for (int c = 0; c < 4; ++c) differ += ia.pixel(x, y)[c] != ib.pixel(x, y)[c];
            }
        EXPECT_EQ(differ, 0);
        EXPECT_GT(covered, 100.0);  // the objects are in view
    }
}

TEST(RibObjects, InstancesRenderAsTheGeometryWrittenOut) {
    const Scene out = load(sceneWith(writtenOut())).scene;
    // By number (RI 3.2) and by string (later PRMan); the CTM at ObjectBegin plays no part.
    for (const auto& [def, h] : std::vector<std::pair<std::string, std::string>>{
             {"ObjectBegin 3\n", "3"}, {"ObjectBegin \"tree\"\n", "\"tree\""}}) {
        SCOPED_TRACE(def);
        const Scene inst = load(sceneWith("TransformBegin\nTranslate 5 5 5\n" + def + kObjectBody +
                                          "ObjectEnd\nTransformEnd\n" + instances(h)))
                               .scene;
        EXPECT_EQ(inst.patches.size(), out.patches.size());
        expectSameScene(inst, out);
        expectSameImages(inst, out);
    }
    // Defined before WorldBegin (in the options), instanced in the world.
    const Scene early =
        load(sceneWith(instances("1"), "ObjectBegin 1\n" + std::string(kObjectBody) + "ObjectEnd\n")).scene;
    expectSameScene(early, out);
}

TEST(RibObjects, HandlesAndNesting) {
    // A number and a string that reads the same are two handles; a handle defined again is replaced;
    // an instance inside a definition is the object as it was then.
    Loaded l =
        load(sceneWith("ObjectBegin 1\nSphere 1 -1 1 360\nObjectEnd\n"
                       "ObjectBegin \"1\"\nSphere 1 -1 1 360\nSphere 2 -2 2 360\nObjectEnd\n"
                       "ObjectBegin 2\nObjectInstance 1\nTranslate 0 0 1\nObjectInstance \"1\"\nObjectEnd\n"
                       "ObjectBegin 1\nDisk 0 1 360\nDisk 0 1 360\nDisk 0 1 360\nObjectEnd\n"
                       "ObjectInstance 2\n"));
    EXPECT_EQ(l.scene.quadrics.size(), 3u);  // 1 (the old object 1) + 2
    for (const SceneQuadric& q : l.scene.quadrics) EXPECT_EQ(q.q.kind, QuadricKind::Sphere);
    EXPECT_FLOAT_EQ(l.scene.quadrics[1].worldFromObject.point({0, 0, 0}).z,
                    l.scene.quadrics[0].worldFromObject.point({0, 0, 0}).z + 1.f);
}

TEST(RibObjects, InstancesAreRecordedForTheEngines) {
    // Per top-level ObjectInstance: its surfaces, its object and its placement (Scene::instances); one nested
    // in a definition is part of the outer copy, and an instance under a moving transform is not recorded.
    Loaded l =
        load(sceneWith("ObjectBegin 1\nPatch \"bilinear\" \"P\" [0 0 0 1 0 0 0 1 0 1 1 0]\nObjectEnd\n"
                       "ObjectBegin \"two\"\nObjectInstance 1\nDisk 0 1 360\nObjectEnd\n"
                       "ObjectInstance \"two\"\nAttributeBegin\nTranslate 0 0 3\nObjectInstance 1\n"
                       "AttributeEnd\nAttributeBegin\nMotionBegin [0 1]\nTranslate 0 0 0\n"
                       "Translate 1 0 0\nMotionEnd\nObjectInstance 1\nAttributeEnd\n",
                       "Shutter 0 1\n"));
    ASSERT_EQ(l.scene.instances.size(), 2u);
    const SurfaceInstance &a = l.scene.instances[0], &b = l.scene.instances[1];
    EXPECT_EQ(a.first, 0u);
    EXPECT_EQ(a.count, 2u);  // the nested patch and the disk
    EXPECT_EQ(b.first, 2u);
    EXPECT_EQ(b.count, 1u);
    EXPECT_NE(a.object, b.object);
    EXPECT_EQ(l.scene.patches.size(), 4u);  // and the moving patch, a plain copy
    EXPECT_FLOAT_EQ(b.objectToWorld.point({0, 0, 0}).z, 3.f);
    EXPECT_FLOAT_EQ(a.objectToWorld.point({0, 0, 0}).z, 0.f);
}

TEST(RibObjects, BadInputFailsNamingTheLine) {
    auto world = [](const std::string& body) { return "WorldBegin\n" + body; };
    EXPECT_TRUE(contains(expectError(world("ObjectInstance 7\nWorldEnd\n"), 2), "no object with handle 7"));
    EXPECT_TRUE(
        contains(expectError(world("ObjectBegin 1\nSphere 1 -1 1 360\nObjectEnd\nObjectInstance \"a\"\n"), 5),
                 "no object with handle \"a\""));
    EXPECT_TRUE(contains(expectError(world("ObjectBegin 1\nObjectBegin 2\n"), 3), "nested ObjectBegin"));
    EXPECT_TRUE(contains(expectError(world("ObjectEnd\n"), 2), "ObjectEnd without a matching ObjectBegin"));
    EXPECT_TRUE(contains(expectError(world("ObjectBegin 1\nSphere 1 -1 1 360\n"), 3),
                         "end of file inside the object"));
    EXPECT_TRUE(contains(expectError(world("ObjectBegin 1\nLightSource \"pointlight\" 1\n"), 3),
                         "not allowed inside an object definition"));
    EXPECT_TRUE(contains(expectError(world("ObjectBegin 1\nAttributeEnd\n"), 3),
                         "without a matching AttributeBegin"));
    EXPECT_TRUE(contains(expectError(world("ObjectBegin 1\nAttributeBegin\nObjectEnd\n"), 4), "still open"));
    EXPECT_TRUE(contains(expectError(world("ObjectBegin 1.5\n"), 2), "integer or a string"));
    EXPECT_TRUE(contains(expectError("ObjectBegin 1\nSphere 1 -1 1 360\nObjectEnd\nObjectInstance 1\n", 4),
                         "outside WorldBegin"));
    // Instances in a motion block are rejected (no moving instances).
    EXPECT_TRUE(contains(expectError("Shutter 0 1\n" + world("ObjectBegin 1\nSphere 1 -1 1 360\nObjectEnd\n"
                                                             "MotionBegin [0 1]\nObjectInstance 1\n"),
                                     7),
                         "not allowed inside a motion block"));
    // An error inside the definition is reported at the definition's line when instanced.
    EXPECT_TRUE(contains(expectError(world("ObjectBegin 1\nPolygon \"P\" [0 0 0 1 0 0 1 1]\nObjectEnd\n"
                                           "ObjectInstance 1\n"),
                                     3),
                         "multiple of 3"));
}

TEST(RibObjects, ArchiveSearchPath) {
    const std::filesystem::path dir = testScratchDir() / "archsearch";
    writeFile(dir / "lib" / "part.rib", "Sphere 1 -1 1 360\n");
    writeFile(dir / "other" / "part2.rib", "Disk 0 1 360\n");
    const std::string head = "WorldBegin\n";
    // Relative directories are relative to the file that sets the path; "&" is the previous path.
    auto loadIn = [&](const std::string& text) {
        const std::string path = writeFile(dir / "scene.rib", text);
        Loaded l;
        l.scene = loadScene(path, [&](const std::string& w) { l.warnings.push_back(w); });
        return l;
    };
    Loaded a = loadIn("Option \"searchpath\" \"archive\" \"nowhere:lib\"\n" + head +
                      "ReadArchive \"part.rib\"\nWorldEnd\n");
    EXPECT_EQ(a.scene.quadrics.size(), 1u);
    Loaded b =
        loadIn("Option \"searchpath\" \"archive\" \"lib\"\nOption \"searchpath\" \"archive\" \"other:&\"\n" +
               head + "ReadArchive \"part.rib\"\nReadArchive \"part2.rib\"\nWorldEnd\n");
    EXPECT_EQ(b.scene.quadrics.size(), 2u);
    // Without "@" (or "&" of a path that has it) the file's own directory is not searched.
    const std::string missing =
        writeFile(dir / "scene.rib", "Option \"searchpath\" \"archive\" \"lib:other\"\n" + head +
                                         "ReadArchive \"scene2.rib\"\nWorldEnd\n");
    writeFile(dir / "scene2.rib", "Sphere 1 -1 1 360\n");
    const std::string msg = errorOfFile(missing);
    EXPECT_EQ(msg.rfind(missing + ":3: error:", 0), 0u) << msg;
    EXPECT_TRUE(contains(msg, "not found in the archive search path")) << msg;
    EXPECT_TRUE(contains(msg, (dir / "lib").string() + ":" + (dir / "other").string())) << msg;
    Loaded c = loadIn("Option \"searchpath\" \"archive\" \"lib:@\"\n" + head +
                      "ReadArchive \"scene2.rib\"\nWorldEnd\n");
    EXPECT_EQ(c.scene.quadrics.size(), 1u);
    // "shader" is accepted (kept, unused: the shaders are built in).
    Loaded d = loadIn("Option \"searchpath\" \"shader\" \"shaders:&\"\n" + head +
                      "ReadArchive \"lib/part.rib\"\nWorldEnd\n");
    EXPECT_EQ(d.scene.quadrics.size(), 1u);
}

}  // namespace
}  // namespace tessera::test::rib_objects_tests
