// Bad input gets a clear error and nothing else (issue 5, docs/errors.md): every class of malformed
// scene is rejected by loadScene() with an InputError "file:line: error: ...", and by the CLI with that
// message, exit status 2 and no output file (an existing image is left untouched). Also: Ctrl-C.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <thread>

#include "io/diagnostics.h"
#include "io/image_io.h"
#include "io/scene_loader.h"
#include "render/render.h"

// posix_spawn passes the test process's environment on (POSIX declares no header for it).
extern char** environ;

namespace tessera::test::errors_tests {

namespace fs = std::filesystem;

namespace {

const std::string kTeapot = std::string(TESSERA_SOURCE_DIR) + "/scenes/teapot.rib";

// A unit square in the world, for scenes that must otherwise be valid.
const char* kSquare = "Patch \"bilinear\" \"P\" [-1 -1 0 1 -1 0 -1 1 0 1 1 0]\n";
const char* kHeader = "Format 32 24 1\nProjection \"perspective\" \"fov\" 45\nTranslate 0 0 5\n";

std::string valid(const std::string& world, const std::string& options = "") {
    return kHeader + options + "WorldBegin\nLightSource \"ambientlight\" 1\n" + world + "WorldEnd\n";
}

fs::path scratch() {
    fs::path d = fs::temp_directory_path() / ("tessera_errors_" + std::to_string(getpid()));
    fs::create_directories(d);
    return d;
}

fs::path writeFile(const std::string& name, const std::string& text) {
    fs::path p = scratch() / name;
    fs::create_directories(p.parent_path());
    std::ofstream(p, std::ios::binary) << text;
    return p;
}

struct CommandResult {
    int exitCode;
    std::string output;
};

CommandResult runCli(const std::string& args) {
    fs::path log = scratch() / "cli.log";
    std::string cmd = std::string(TESSERA_BINARY) + " " + args + " > '" + log.string() + "' 2>&1";
    int status = std::system(cmd.c_str());
    std::ifstream f(log);
    std::stringstream ss;
    ss << f.rdbuf();
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, ss.str()};
}

bool hasTempFiles(const fs::path& dir) {
    for (const auto& e : fs::directory_iterator(dir))
        if (e.path().filename().string().find(".tmp") != std::string::npos) return true;
    return false;
}

// loadScene must throw an InputError at `line` (0: any line) whose message contains `what`; the CLI must
// print the same `file:line: error:` message, exit with 2 and leave no output and no temporary file.
void expectRejected(const fs::path& file, int line, const std::string& what) {
    SCOPED_TRACE(file.string());
    std::string message;
    try {
        loadScene(file.string(), nullptr);
        ADD_FAILURE() << "loadScene accepted " << file;
    } catch (const InputError& e) {
        message = e.what();
        EXPECT_EQ(e.file().empty(), false);
        if (line > 0) {
            EXPECT_EQ(e.line(), line) << message;
        }
        EXPECT_NE(message.find(what), std::string::npos) << "message: " << message << "\nwanted: " << what;
        EXPECT_EQ(message.find('\n'), std::string::npos) << "one line: " << message;
    } catch (const std::exception& e) {
        ADD_FAILURE() << "not an InputError: " << e.what();
    }

    fs::path outDir = scratch() / ("out_" + file.stem().string());
    fs::create_directories(outDir);
    fs::path out = outDir / "image.png";
    CommandResult r = runCli("render '" + file.string() + "' -o '" + out.string() + "' --quiet");
    EXPECT_EQ(r.exitCode, 2) << r.output;
    std::string prefix = line > 0 ? file.string() + ":" + std::to_string(line) + ": error: " : file.string();
    EXPECT_NE(r.output.find(prefix), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("error: "), std::string::npos) << r.output;
    EXPECT_NE(r.output.find(what), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(out)) << "no output for rejected input";
    EXPECT_FALSE(hasTempFiles(outDir));
    fs::remove_all(outDir);
}

void expectRejected(const std::string& name, const std::string& text, int line, const std::string& what) {
    expectRejected(writeFile(name, text), line, what);
}

}  // namespace

// ---- structure --------------------------------------------------------------------------------------

TEST(BadInput, EmptyFile) {
    expectRejected("empty.rib", "", 1, "empty file");
    expectRejected("blank.rib", "\n\n   \n", 0, "empty file");
    expectRejected("comments.rib", "# nothing\n## here\n", 0, "empty file");
    expectRejected("empty.bpt", "", 1, "empty file");
}

TEST(BadInput, TruncatedFile) {
    std::string full = valid(kSquare);
    // Cut inside the point array: the array is reported, at the last line.
    std::string cut = full.substr(0, full.find("1 -1 0 -1"));
    expectRejected("truncated_array.rib", cut, 6, "end of file inside the array opened on line 6");
    // Cut inside a string.
    expectRejected("truncated_string.rib", full.substr(0, full.find("bilinear") + 3), 6,
                   "unterminated string");
    // Cut after a complete request: the open WorldBegin block is reported.
    expectRejected("truncated_block.rib", full.substr(0, full.find("WorldEnd")), 6,
                   "end of file inside WorldBegin block opened at");
    // .bpt: fewer control points than announced.
    expectRejected("truncated.bpt", "1\n3 3\n0 0 0\n1 0 0\n", 4, "unexpected end of file");
}

TEST(BadInput, UnbalancedBeginEnd) {
    expectRejected("unbalanced_end.rib", valid(kSquare) + "AttributeEnd\n", 8,
                   "AttributeEnd without a matching AttributeBegin");
    expectRejected("mismatched.rib", valid(std::string("AttributeBegin\n") + kSquare), 8,
                   "WorldEnd does not match AttributeBegin");
    expectRejected("extra_end.rib", valid(std::string(kSquare) + "WorldEnd\n"), 8,
                   "WorldEnd without a matching WorldBegin");
    expectRejected("unclosed_transform.rib", valid(std::string("TransformBegin\n") + kSquare), 8,
                   "WorldEnd does not match TransformBegin");
    expectRejected("unclosed_attr.rib",
                   std::string(kHeader) + "WorldBegin\nAttributeBegin\n" + kSquare + "AttributeEnd\n", 7,
                   "end of file inside WorldBegin block");
}

TEST(BadInput, WrongTokenTypes) {
    expectRejected("format_string.rib", valid(kSquare, "Format 10 \"ten\" 1\n"), 4, "Format expects numbers");
    expectRejected("patch_number.rib", valid("Patch 3 \"P\" [0 0 0 1 0 0 0 1 0 1 1 0]\n"), 6,
                   "argument 1 must be a string");
    expectRejected("param_name.rib", valid("Patch \"bilinear\" 7 [0 0 0 1 0 0 0 1 0 1 1 0]\n"), 6,
                   "expected a parameter name");
    expectRejected("stray_token.rib", valid(kSquare, "Translate 0 0 -x\n"), 4, "unexpected token '-x'");
    expectRejected("mixed_array.rib", valid("Patch \"bilinear\" \"P\" [0 0 0 \"a\" 0 0 0 1 0 1 1 0]\n"), 6,
                   "array mixes numbers and strings");
    expectRejected("number_as_request.rib", "12 WorldBegin\n", 1,
                   "expected a RIB request, found number '12'");
    // A number is printed as the shortest digits that read back as its value.
    expectRejected("fraction_as_request.rib", "-12.50e0 WorldBegin\n", 1,
                   "expected a RIB request, found number '-12.5'");
    expectRejected("fraction.bpt", "1.5\n", 1, "expected the patch count");
    expectRejected("word.bpt", "one\n", 1, "expected the patch count, found 'one'");
}

TEST(BadInput, WrongArrayLengths) {
    expectRejected("short_p.rib", valid("Patch \"bicubic\" \"P\" [0 0 0 1 0 0 0 1 0 1 1 0]\n"), 6,
                   "parameter \"P\" needs 48 values");
    expectRejected("long_p.rib", valid("Patch \"bilinear\" \"P\" [0 0 0 1 0 0 0 1 0 1 1 0 5]\n"), 6,
                   "parameter \"P\" needs 12 values");
    expectRejected("color_len.rib", valid(std::string("Color [1 0]\n") + kSquare), 6,
                   "Color expects 3 numbers");
    expectRejected("matrix_len.rib", valid(kSquare, "ConcatTransform [1 0 0 0 0 1 0 0 0 0 1 0]\n"), 4,
                   "expects 16 numbers");
    expectRejected("cs_len.rib", valid("Patch \"bilinear\" \"P\" [0 0 0 1 0 0 0 1 0 1 1 0] \"Cs\" [1 0 0]\n"),
                   6, "parameter \"Cs\" needs 12 values");
    expectRejected(
        "decl_len.rib",
        valid(std::string("Declare \"k\" \"uniform float[3]\"\nSurface \"matte\" \"k\" [1 2]\n") + kSquare),
        7, "parameter \"k\" needs 3 values");
    // A huge count with a short array is rejected before anything is allocated for it.
    expectRejected("huge_mesh.rib",
                   valid("PatchMesh \"bicubic\" 400000000 \"nonperiodic\" 4 \"nonperiodic\" "
                         "\"P\" [0 0 0]\n"),
                   6, "needs 4800000000 values");
    expectRejected("huge_nupatch.rib",
                   valid("NuPatch 1000000 4 [0 0 0 0 1 1 1 1] 0 1 1000000 4 [0 0 0 0 1 1 1 1] 0 1\n"), 6,
                   "NuPatch");
    expectRejected("huge_decl.rib",
                   valid(std::string("Declare \"k\" \"uniform float[99999999999]\"\n") + kSquare), 6,
                   "invalid declaration");
    expectRejected("huge_count.bpt", "1000000000000\n3 3\n0 0 0\n", 3, "unexpected end of file");
}

TEST(BadInput, UnknownPatchType) {
    expectRejected("biquadratic.rib", valid("Patch \"biquadratic\" \"P\" [0 0 0 1 0 0 0 1 0 1 1 0]\n"), 6,
                   "type must be \"bicubic\" or \"bilinear\", found \"biquadratic\"");
    expectRejected(
        "mesh_type.rib",
        valid("PatchMesh \"cubic\" 2 \"nonperiodic\" 2 \"nonperiodic\" \"P\" [0 0 0 1 0 0 0 1 0 1 1 0]\n"), 6,
        "type must be \"bicubic\" or \"bilinear\"");
    expectRejected(
        "wrap.rib",
        valid("PatchMesh \"bilinear\" 2 \"wrapped\" 2 \"nonperiodic\" \"P\" [0 0 0 1 0 0 0 1 0 1 1 0]\n"), 6,
        "wrap mode must be");
    expectRejected("degree.bpt", "1\n3 2\n", 2, "only bicubic (3 3) patches are supported");
}

// ---- options ----------------------------------------------------------------------------------------

TEST(BadInput, ZeroOrNegativeResolution) {
    expectRejected("format_zero.rib", valid(kSquare, "Format 0 24 1\n"), 4, "Format: the resolution must be");
    expectRejected("format_negative.rib", valid(kSquare, "Format 32 -24 1\n"), 4,
                   "Format: the resolution must be");
    expectRejected("format_fraction.rib", valid(kSquare, "Format 32.5 24 1\n"), 4,
                   "Format: the resolution must be");
    expectRejected("format_aspect.rib", valid(kSquare, "Format 32 24 0\n"), 4, "pixel aspect ratio positive");
}

TEST(BadInput, AbsurdResolution) {
    expectRejected("format_huge.rib", valid(kSquare, "Format 100000 24 1\n"), 4,
                   "Format: resolution 100000x24 exceeds the limit of 16384 pixels per axis");
    expectRejected("format_huge2.rib", valid(kSquare, "Format 16384 16385 1\n"), 4,
                   "exceeds the limit of 16384");
    // The limit itself is accepted (the scene loads; nothing is rendered here).
    fs::path ok = writeFile("format_limit.rib", valid(kSquare, "Format 16384 16384 1\n"));
    Scene s = loadScene(ok.string(), nullptr);
    EXPECT_EQ(s.camera.width, 16384);
}

TEST(BadInput, ResolutionOnTheCommandLine) {
    fs::path dir = scratch() / "res";
    fs::create_directories(dir);
    std::string out = (dir / "x.png").string();
    for (const char* res :
         {"0x10", "10x0", "-5x10", "20000x10", "10x16385", "abc", "10x", "10x10x10", "1e3x10"}) {
        CommandResult r = runCli("render " + kTeapot + " --res=" + res + " -o " + out);
        EXPECT_EQ(r.exitCode, 2) << res << ": " << r.output;
        EXPECT_NE(r.output.find("error"), std::string::npos) << res << ": " << r.output;
        EXPECT_FALSE(fs::exists(out)) << res;
    }
    CommandResult r = runCli("render " + kTeapot + " --res 20000x10 -o " + out);
    EXPECT_NE(r.output.find("outside 1..16384"), std::string::npos) << r.output;
    fs::remove_all(dir);
}

TEST(BadInput, ZeroSamples) {
    expectRejected("pixelsamples_zero.rib", valid(kSquare, "PixelSamples 0 0\n"), 4,
                   "PixelSamples must be positive");
    expectRejected("pixelsamples_negative.rib", valid(kSquare, "PixelSamples 2 -1\n"), 4,
                   "PixelSamples must be positive");
    expectRejected("pixelsamples_huge.rib", valid(kSquare, "PixelSamples 1000 1000\n"), 4,
                   "PixelSamples: more than 1024 samples per pixel");
    expectRejected("shadingrate_zero.rib", valid(std::string("ShadingRate 0\n") + kSquare), 6,
                   "ShadingRate must be positive");
    fs::path dir = scratch() / "spp";
    fs::create_directories(dir);
    std::string out = (dir / "x.png").string();
    for (const char* spp : {"0", "-1", "5000", "two"}) {
        CommandResult r = runCli("render " + kTeapot + " --spp=" + spp + " -o " + out);
        EXPECT_EQ(r.exitCode, 2) << spp << ": " << r.output;
        EXPECT_NE(r.output.find("--spp"), std::string::npos) << spp << ": " << r.output;
        EXPECT_FALSE(fs::exists(out)) << spp;
    }
    CommandResult r = runCli("render " + kTeapot + " --shading-rate 0 -o " + out);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    r = runCli("render " + kTeapot + " --threads=-1 -o " + out);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_FALSE(fs::exists(out));
    fs::remove_all(dir);
}

// ---- numbers ----------------------------------------------------------------------------------------

TEST(BadInput, NanAndInfinity) {
    for (const char* word : {"nan", "NaN", "-nan", "inf", "-Infinity", "INF"}) {
        std::string name =
            std::string("nonfinite_") + (word[0] == '-' ? "minus_" : "") + (word + (word[0] == '-'));
        expectRejected(name + ".rib",
                       valid(std::string("Patch \"bilinear\" \"P\" [0 0 0 1 0 0 0 1 0 1 1 ") + word + "]\n"),
                       6, "NaN and infinity are not allowed");
    }
    expectRejected("nan_option.rib", valid(kSquare, "Exposure nan 1\n"), 4,
                   "NaN and infinity are not allowed");
    expectRejected("nan.bpt", "1\n3 3\n0 0 nan\n", 3, "NaN and infinity are not allowed");
    expectRejected("inf.bpt", "1\n3 3\n0 0 0\n-inf 0 0\n", 4, "NaN and infinity are not allowed");
}

TEST(BadInput, HugeNumbers) {
    // Beyond double range.
    expectRejected("huge_double.rib", valid("Patch \"bilinear\" \"P\" [0 0 0 1 0 0 0 1 0 1 1 1e999]\n"), 6,
                   "invalid number '1e999': out of range");
    // Beyond single precision, which everything downstream uses.
    expectRejected("huge_float.rib", valid(std::string("Color [1e39 1 1]\n") + kSquare), 6,
                   "invalid number '1e39': out of range");
    // Each number fits, their product does not.
    expectRejected("huge_product.rib",
                   valid(std::string("Scale 1e30 1e30 1e30\n") +
                         "Patch \"bilinear\" \"P\" [0 0 0 1e20 0 0 0 1 0 1 1 0]\n"),
                   7, "control point out of range after transformation");
    expectRejected("huge_int.rib", valid(std::string("Sides 1e20\n") + kSquare), 6, "must be an integer");
    expectRejected("huge.bpt", "1\n3 3\n0 0 1e300\n", 3, "coordinate out of range");
    expectRejected("huge_count.bpt", "1e300\n", 1, "expected the patch count");
}

// ---- files ------------------------------------------------------------------------------------------

TEST(BadInput, MissingFiles) {
    expectRejected(scratch() / "does_not_exist.rib", 0, "cannot open file");
    expectRejected(scratch() / "does_not_exist.bpt", 0, "cannot open file");
    expectRejected("archive_missing.rib", valid("ReadArchive \"no_such_archive.rib\"\n"), 6,
                   "ReadArchive: cannot open");
    // A directory is not a file.
    fs::create_directories(scratch() / "adir.rib");
    expectRejected("archive_dir.rib", valid("ReadArchive \"adir.rib\"\n"), 6, "ReadArchive: cannot open");
}

TEST(BadInput, RecursiveReadArchive) {
    // A file that includes itself, and two that include each other.
    expectRejected("self.rib", "# includes itself\nReadArchive \"self.rib\"\n", 2,
                   "ReadArchive nested more than 32 levels deep (recursive include?)");
    writeFile("pong.rib", "AttributeBegin\nReadArchive \"ping.rib\"\nAttributeEnd\n");
    expectRejected("ping.rib", "ReadArchive \"pong.rib\"\n", 1, "nested more than 32 levels");
    // Errors inside an archive name the archive's file and line.
    fs::path inner = writeFile("inner.rib", "\n\nPatch \"bilinear\" \"P\" [0 0 0]\n");
    fs::path outer = writeFile("outer.rib", valid("ReadArchive \"inner.rib\"\n"));
    try {
        loadScene(outer.string(), nullptr);
        ADD_FAILURE();
    } catch (const InputError& e) {
        EXPECT_EQ(e.file(), inner.string());
        EXPECT_EQ(e.line(), 3);
    }
}

TEST(BadInput, BinaryFiles) {
    // Random bytes (fixed seed), as .rib and as .bpt.
    std::mt19937 rng(5);
    std::string noise(4096, '\0');
    for (char& c : noise) c = char(rng());
    expectRejected("noise.rib", noise, 0, "error: ");
    expectRejected("noise.bpt", noise, 0, "error: ");
    // A PNG renamed .rib: a clear message at line 1, not a crash or garbage.
    fs::path png = scratch() / "image.png";
    Image img(8, 8);
    writePng(png.string(), img, OutputEncoding{});
    std::ifstream f(png, std::ios::binary);
    std::stringstream ss;
    ss << f.rdbuf();
    expectRejected("png_renamed.rib", ss.str(), 1, "binary data (byte 0x89): not a RIB text file");
    expectRejected("png_renamed.bpt", ss.str(), 1, "expected the patch count, found '\\x89PNG'");
    // NUL bytes inside otherwise valid text.
    expectRejected("nul.rib", valid(std::string("Tr\0anslate 0 0 1\n", 17) + kSquare), 6,
                   "binary data (byte 0x00)");
    // Gzip magic followed by garbage.
    expectRejected("bad_gzip.rib", std::string("\x1f\x8b\x08\x00garbage", 11), 0, "gzip");
}

// ---- content ----------------------------------------------------------------------------------------

TEST(BadInput, NoGeometryAndMisplacedGeometry) {
    expectRejected("no_geometry.rib", valid(""), 0, "no geometry");
    expectRejected("outside_world.rib", std::string(kHeader) + kSquare, 4, "outside WorldBegin/WorldEnd");
    expectRejected("zero_patches.bpt", "0\n", 1, "no patches");
    expectRejected("negative_patches.bpt", "-3\n", 1, "negative patch count");
    std::string onePatch = "1\n3 3\n";
    for (int i = 0; i < 16; ++i) onePatch += "0 0 0\n";
    expectRejected("trailing.bpt", onePatch + "0 0 0\n", 19,
                   "trailing data after 1 patches (wrong patch count?)");
}

// ---- output -----------------------------------------------------------------------------------------

TEST(BadInput, FailedRenderNeverTouchesTheOutput) {
    fs::path dir = scratch() / "keep";
    fs::create_directories(dir);
    fs::path png = dir / "img.png", exr = dir / "img.exr";
    ASSERT_EQ(runCli("render " + kTeapot + " --res 16x12 -q -o " + png.string()).exitCode, 0);
    ASSERT_EQ(runCli("render " + kTeapot + " --res 16x12 -q -o " + exr.string()).exitCode, 0);
    auto pngTime = fs::last_write_time(png), exrTime = fs::last_write_time(exr);
    auto pngSize = fs::file_size(png), exrSize = fs::file_size(exr);
    for (const std::string& bad :
         {valid("Patch \"bilinear\" \"P\" [0 0 0]\n"), std::string(""), valid(kSquare, "Format 0 0 1\n")}) {
        fs::path scene = writeFile("keep.rib", bad);
        for (const fs::path& out : {png, exr}) {
            CommandResult r = runCli("render " + scene.string() + " -q -o " + out.string());
            EXPECT_EQ(r.exitCode, 2) << r.output;
        }
    }
    // An output that cannot be written (its directory does not exist): exit 2, nothing created, and
    // reported before the scene is loaded (a scene with an error of its own is not even read).
    fs::path nowhere = dir / "no_such_dir" / "img.png";
    CommandResult r = runCli("render " + kTeapot + " --res 16x12 -q -o " + nowhere.string());
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_NE(r.output.find(nowhere.string() + ": error: cannot write the image there: the directory"),
              std::string::npos)
        << r.output;
    fs::path badScene = writeFile("bad_for_output.rib", valid("Patch \"bilinear\" \"P\" [0 0 0]\n"));
    r = runCli("render " + badScene.string() + " -q -o " + nowhere.string());
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_NE(r.output.find("cannot write the image"), std::string::npos)
        << "checked before loading: " << r.output;
    EXPECT_EQ(r.output.find("bad_for_output.rib:"), std::string::npos) << r.output;
    // Statistics that cannot be written: exit 2 before the render, so no image either.
    fs::path fresh = dir / "fresh.png";
    r = runCli("render " + kTeapot + " --res 16x12 -q -o " + fresh.string() + " --stats " +
               (dir / "no_such_dir" / "s.json").string());
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_NE(r.output.find("cannot write the statistics there"), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(fresh)) << "nothing rendered or written";
    // An output that names a directory.
    r = runCli("render " + kTeapot + " --res 16x12 -q -o " + dir.string() + "/");
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_FALSE(fs::exists(nowhere.parent_path()));
    EXPECT_EQ(fs::last_write_time(png), pngTime);
    EXPECT_EQ(fs::last_write_time(exr), exrTime);
    EXPECT_EQ(fs::file_size(png), pngSize);
    EXPECT_EQ(fs::file_size(exr), exrSize);
    EXPECT_FALSE(hasTempFiles(dir));
    fs::remove_all(dir);
}

// Ctrl-C during a long render: the CLI stops, says so, exits 130 and writes nothing (no image, no
// temporary file); an existing image is kept. No wall-clock bound: the signal is sent once the render has
// demonstrably started (its first "progress N%" line), and promptness is checked deterministically by
// Cancel.NoTileStartsAfterTheFlag. A render that ignored the signal would run for many minutes and hit the
// CTest timeout.
TEST(BadInput, SigintStopsALongRenderCleanly) {
    fs::path dir = scratch() / "sigint";
    fs::create_directories(dir);
    fs::path out = dir / "big.png", log = dir / "stderr.txt";
    std::ofstream(out) << "previous image";
    std::string bin = TESSERA_BINARY, outArg = out.string();
    std::vector<std::string> args = {bin,  "render", kTeapot, "--res",      "4000x3000", "--spp",
                                     "64", "-o",     outArg,  "--progress", "--threads", "2"};
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
                                     0644);
    pid_t pid = 0;
    ASSERT_EQ(posix_spawn(&pid, bin.c_str(), &actions, nullptr, argv.data(), environ), 0);
    posix_spawn_file_actions_destroy(&actions);

    auto readLog = [&] {
        std::ifstream f(log);
        std::stringstream ss;
        ss << f.rdbuf();
        return ss.str();
    };
    // Wait until the render reports work done (1%): loading is over and tiles are being rendered.
    int status = 0;
    bool exited = false;
    while (readLog().find("progress 1%") == std::string::npos) {
        if (waitpid(pid, &status, WNOHANG) == pid) {
            exited = true;
            break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    ASSERT_FALSE(exited) << "the render ended before reporting progress: " << readLog();
    ASSERT_EQ(kill(pid, SIGINT), 0);
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    ASSERT_TRUE(WIFEXITED(status)) << "exits, not killed by the signal";
    EXPECT_EQ(WEXITSTATUS(status), 130);
    std::string text = readLog();
    EXPECT_NE(text.find("interrupted"), std::string::npos) << text;
    EXPECT_NE(text.find("no image written"), std::string::npos) << text;
    EXPECT_EQ(text.find("progress 100%"), std::string::npos) << "stopped before the end: " << text;
    std::ifstream prev(out);
    std::string kept;
    std::getline(prev, kept);
    EXPECT_EQ(kept, "previous image") << "the existing file is untouched";
    EXPECT_FALSE(hasTempFiles(dir));
    fs::remove_all(dir);
}

// Cancellation is prompt, checked without a clock: the cancel flag is raised from the progress callback
// at a known point (after the third tile), and from then on no further tile may start. With one thread no
// further tile is reported at all; with two, at most the one already in flight on the other thread.
class Cancel : public ::testing::TestWithParam<std::string> {};

TEST_P(Cancel, NoTileStartsAfterTheFlag) {
    Scene scene = loadScene(kTeapot, nullptr);
    scene.camera.width = 256;  // 8 x 6 tiles of 32 pixels
    scene.camera.height = 192;
    scene.image.pixelSamplesX = scene.image.pixelSamplesY = 1;
    for (int threads : {1, 2}) {
        SCOPED_TRACE("threads " + std::to_string(threads));
        std::atomic<bool> cancel{false};
        std::atomic<int> calls{0}, callsAfterFlag{0};
        int64_t totalWork = 0;
        RenderSettings rs;
        rs.engine = GetParam();
        rs.threads = threads;
        rs.cancel = &cancel;
        rs.progress = [&](auto done, auto total) {
            totalWork = int64_t(total);
            (void)done;
            if (cancel.load()) {
                ++callsAfterFlag;
                return;
            }
            if (++calls == 3) cancel.store(true);
        };
        RenderResult r = render(scene, rs);
        EXPECT_TRUE(r.cancelled);
        EXPECT_EQ(calls.load(), 3);
        EXPECT_LE(callsAfterFlag.load(), threads - 1) << "tiles started after the cancel flag was raised";
        EXPECT_GT(totalWork, 0);
    }
}

INSTANTIATE_TEST_SUITE_P(BothEngines, Cancel, ::testing::Values("reyes", "rt"));

// ---- OBJ --------------------------------------------------------------------------------------------

TEST(BadInput, ObjFiles) {
    const std::string quad = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n";
    expectRejected("obj_empty.obj", "", 0, "error: ");
    expectRejected("obj_huge.obj", "v 1e39 0 0\n" + quad + "f 2 3 4 5\n", 1,
                   "expected a number in the vertex");
    expectRejected("obj_nan.obj", quad + "v nan 0 0\nf 1 2 3 4\n", 5, "expected a number in the vertex");
    expectRejected("obj_min_index.obj", quad + "f 1 2 -9223372036854775808\n", 5,
                   "reaches before the first vertex");
    expectRejected("obj_zero_index.obj", quad + "f 0 1 2\n", 5, "vertex index 0");
    expectRejected("obj_short_face.obj", quad + "f 1 2\n", 5, "a face needs at least 3 vertices");
    expectRejected("obj_bad_ref.obj", quad + "f 1 2 x\n", 5, "bad vertex reference 'x'");
}

// SubdivisionMesh (issue 16): wrong parameter counts and out-of-range indices name the line of the
// offending array or tag.
TEST(BadInput, SubdivisionMesh) {
    const std::string mesh = "SubdivisionMesh \"catmull-clark\" [4 4 4 4 4 4]\n";     // line 6
    const std::string verts = "[0 3 2 1 4 5 6 7 0 1 5 4 1 2 6 5 2 3 7 6 3 0 4 7]\n";  // line 7
    const std::string P = "\"P\" [-1 -1 -1 1 -1 -1 1 1 -1 -1 1 -1 -1 -1 1 1 -1 1 1 1 1 -1 1 1]\n";
    // Parameter counts.
    expectRejected("subdiv_nverts.rib", valid(mesh + "[0 3 2 1 4 5 6 7]\n" + P), 7,
                   "nvertices adds up to 24");
    expectRejected("subdiv_p.rib", valid(mesh + verts + "\"P\" [-1 -1 -1 1 -1 -1]\n"), 0, "\"P\"");
    expectRejected("subdiv_nargs.rib", valid(mesh + verts + "[\"crease\"] [2]\n[0 1] [2]\n" + P), 8,
                   "nargs needs 2 numbers per tag");
    expectRejected("subdiv_nargs_more.rib", valid(mesh + verts + "[\"crease\"] [3 1]\n[0 1] [2]\n" + P), 8,
                   "asks for more intargs/floatargs than given");
    expectRejected("subdiv_crease_one.rib", valid(mesh + verts + "[\"crease\"] [1 1]\n[0] [2]\n" + P), 8,
                   "needs at least 2 vertices and 1 sharpness");
    // Out-of-range indices.
    expectRejected("subdiv_negative.rib",
                   valid(mesh + "[0 3 2 -1 4 5 6 7 0 1 5 4 1 2 6 5 2 3 7 6 3 0 4 7]\n" + P), 7,
                   "negative vertex index -1");
    expectRejected("subdiv_crease_range.rib", valid(mesh + verts + "[\"crease\"] [2 1]\n[0 99] [2]\n" + P), 8,
                   "names vertex 99, outside 0..7");
    expectRejected("subdiv_corner_range.rib", valid(mesh + verts + "[\"corner\"] [1 1]\n[8] [2]\n" + P), 8,
                   "names vertex 8, outside 0..7");
    expectRejected("subdiv_hole_range.rib", valid(mesh + verts + "[\"hole\"] [1 0]\n[6] []\n" + P), 8,
                   "\"hole\" names face 6, outside 0..5");
    // Topology: an edge used twice in the same direction (a flipped face) names the request's line.
    expectRejected("subdiv_flipped.rib",
                   valid(mesh + "[0 1 2 3 4 5 6 7 0 1 5 4 1 2 6 5 2 3 7 6 3 0 4 7]\n" + P), 6,
                   "used twice in the same direction");
}

}  // namespace tessera::test::errors_tests
