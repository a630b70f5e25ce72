// Ray tracer with motion blur and depth of field set in code (until the RIB reader parses MotionBegin and
// DepthOfField): renders a scene with every patch moving by a fraction of the scene size over the shutter
// and/or a thin lens focused at the scene centre, and prints the trace statistics as JSON.
//   tessera_rt_motion_bench SCENE [--res WxH] [--spp N] [--threads N] [--move F] [--fstop F]
//                                 [--no-ray-binning] [--no-blur] [-o out.exr]
// --move F: every patch moves by F * (scene size) * (1, 0.3, 0) in world space; --fstop F: lens of focal
// length 0.1 * (scene size) at that f-stop, focused at the scene centre.
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "io/image_io.h"
#include "io/scene_loader.h"
#include "render/render.h"

using namespace tessera;

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr,
                     "usage: %s SCENE [--res WxH] [--spp N] [--threads N] [--move F] [--fstop F] "
                     "[--no-ray-binning] [--no-blur] [-o out.exr]\n",
                     argv[0]);
        return 2;
    }
    Scene s = loadScene(argv[1], [](const std::string& m) { std::fprintf(stderr, "%s\n", m.c_str()); });
    RenderSettings rs;
    rs.engine = "rt";
    float move = 0.f, fstop = 0.f;
    std::string out;
    for (int i = 2; i < argc; ++i) {
        const std::string a = argv[i];
        auto next = [&] { return i + 1 < argc ? argv[++i] : ""; };
        if (a == "--res") {
            std::sscanf(next(), "%dx%d", &s.camera.width, &s.camera.height);
        } else if (a == "--spp") {
            const int n = std::atoi(next());
            int k = 1;
            while ((k + 1) * (k + 1) <= n) ++k;
            s.image.pixelSamplesX = s.image.pixelSamplesY = k;
        } else if (a == "--threads") {
            rs.threads = std::atoi(next());
        } else if (a == "--move") {
            move = float(std::atof(next()));
        } else if (a == "--fstop") {
            fstop = float(std::atof(next()));
        } else if (a == "--no-ray-binning") {
            rs.rayBinning = false;
        } else if (a == "--no-blur") {
            rs.blur.enabled = false;
        } else if (a == "-o") {
            out = next();
        }
    }
    Bounds3 b;
    for (const BezierPatch& p : s.patches)
        for (const Vec3& c : p.cp) b.extend(c);
    const float size = maxComponent(b.diagonal());
    if (move > 0.f) {
        s.camera.shutterOpen = 0.f, s.camera.shutterClose = 1.f;
        const Vec3 delta = Vec3{1.f, 0.3f, 0.f} * (move * size);
        for (size_t i = 0; i < s.patches.size(); ++i) {
            PatchAttributes& a = s.attributes[i];
            a.motion = {uint32_t(s.motionPatches.size()), 2};
            BezierPatch q = s.patches[i];
            for (Vec3& c : q.cp) c += delta;
            s.motionPatches.push_back(s.patches[i]);
            s.motionPatches.push_back(q);
            s.motionTimes.push_back(0.f);
            s.motionTimes.push_back(1.f);
        }
    }
    if (fstop > 0.f) {
        s.camera.fStop = fstop;
        s.camera.focalLength = 0.1f * size;
        s.camera.focalDistance = s.camera.cameraFromWorld.point((b.lo + b.hi) * 0.5f).z;
    }
    RenderResult r = render(s, rs);
    if (!out.empty()) writeExr(out, r.image);
    nlohmann::json j;
    for (const char* k :
         {"trace_ms", "rays_total", "rays", "candidates", "candidates_per_ray", "box_tests", "newton_runs",
          "build_ms", "ray_binning", "blur", "time_culled", "stage_ms", "mrays_per_s"})
        if (r.stats.contains(k)) j[k] = r.stats[k];
    std::printf("%s\n", j.dump().c_str());
    return 0;
}
