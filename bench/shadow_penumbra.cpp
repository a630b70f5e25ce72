// tessera_shadow_penumbra: the error band of shadow-map shadows against exact hard shadows, as the map's
// resolution and filter width vary (issue 13, docs/benchmarks/shadows.md). A unit sphere 1.5 above a floor
// under a spot light at height 6 (or a distant light straight down) casts a disk of known radius on the
// floor; Reyes' map of the light (reyes/shadow_maps.h, rendered exactly as a frame renders it) is looked
// up along 256 rays from the disk's centre. Per configuration, one JSON line:
//   band_world / band_texels: mean width of the ring where the lookup differs from the exact step by more
//     than 1% (the penumbra error band), in floor units and in map texels at the floor;
//   offset_texels: mean signed distance of the lookup's 1/2 crossing from the exact outline (+: outside);
//   map_ms: time to render the map; and, with --images, PSNR of Reyes with the map against Reyes with
//   ray-traced shadows (--reyes-shadows raytrace) at 320x240.
//   tessera_shadow_penumbra [--light spot|distant] [--res "512 1024 2048"] [--widths "1 2 4"] [--images]
#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "engine/frame.h"
#include "film/image_compare.h"
#include "io/rib_reader.h"
#include "render/render.h"
#include "reyes/shadow_maps.h"

using namespace tessera;

namespace {

std::vector<double> numbers(const std::string& s) {
    std::vector<double> v;
    std::istringstream in(s);
    for (double x; in >> x;) v.push_back(x);
    return v;
}

std::string sceneRib(bool spot, int resolution, double width) {
    const std::string light =
        spot ? "LightSource \"spotlight\" 2 \"intensity\" [36] \"from\" [0 0 6] \"to\" [0 0 0] \"coneangle\" "
               "[0.6]"
             : "LightSource \"distantlight\" 2 \"intensity\" [0.9] \"from\" [0 0 10] \"to\" [0 0 0]";
    return "Format 320 240 1\nPixelSamples 3 3\nProjection \"perspective\" \"fov\" [40]\nTranslate 0 0 14\n"
           "Rotate -140 1 0 0\nWorldBegin\nLightSource \"ambientlight\" 1 \"intensity\" [0.1]\n"
           "Attribute \"light\" \"shadows\" [\"on\"]\nAttribute \"shadow\" \"resolution\" [" +
           std::to_string(resolution) + "] \"filterwidth\" [" + fmt::format("{}", width) + "]\n" + light +
           "\nAttributeBegin Translate 0 0 1.5 Surface \"matte\" Sphere 1 -1 1 360 AttributeEnd\n"
           "Surface \"matte\" Patch \"bilinear\" \"P\" [-6 -6 0 6 -6 0 -6 6 0 6 6 0]\nWorldEnd\n";
}

}  // namespace

int main(int argc, char** argv) {
    std::string lightKind = "spot";
    std::vector<double> resolutions = {512, 1024, 2048}, widths = {1, 2, 4};
    bool images = false;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto next = [&]() -> std::string {
            if (i + 1 >= argc) {
                fmt::print(stderr, "error: {} needs a value\n", a);
                std::exit(2);
            }
            return argv[++i];
        };
        if (a == "--light")
            lightKind = next();
        else if (a == "--res")
            resolutions = numbers(next());
        else if (a == "--widths")
            widths = numbers(next());
        else if (a == "--images")
            images = true;
        else {
            fmt::print(stderr, "error: unknown option {}\n", a);
            return 2;
        }
    }
    if (lightKind != "spot" && lightKind != "distant") {
        fmt::print(stderr, "error: --light must be spot or distant\n");
        return 2;
    }
    const bool spot = lightKind == "spot";
    // The exact shadow: spot at height 6, sphere centre at 1.5: radius 6 tan(asin(1 / 4.5)); a distant
    // light straight down: the sphere's own radius.
    const double exact = spot ? 6.0 * std::tan(std::asin(1.0 / 4.5)) : 1.0;
    for (double res : resolutions)
        for (double width : widths) {
            Scene scene;
            readRibText(sceneRib(spot, int(res), width), "penumbra.rib", scene, [](const std::string&) {});
            RenderSettings rs;
            rs.threads = 2;
            const FrameSetup frame(scene, rs);
            const ShadowMaps maps(scene, rs, frame.camera, frame.lights);
            const ShadowMapLookup* lookup = maps.lookup(1);
            if (!lookup) {
                fmt::print(stderr, "error: no map for the light\n");
                return 1;
            }
            // Texel size at the floor: perspective maps from the face's scale at depth 6, orthographic
            // from the face's scale.
            const ShadowMapFace& face = lookup->faces[0];
            const double texel = (spot ? 6.0 : 1.0) / std::fabs(face.sx);
            const Mat4& toCamera = frame.camera.cameraFromWorld;
            const Vec3 N = normalize(Mat4::normalWithInverse(toCamera.inverse(), Vec3{0, 0, 1}));
            const int rays = 256, steps = 4000;
            const double r0 = std::max(0.0, exact - 12 * texel * width - 0.05), r1 = exact + 12 * texel * width + 0.05;
            double band = 0, offset = 0;
            for (int k = 0; k < rays; ++k) {
                const double phi = 2 * M_PI * (k + 0.5) / rays;
                double wrong = 0, crossing = 0;
                bool crossed = false;
                for (int s = 0; s < steps; ++s) {
                    const double r = r0 + (r1 - r0) * (s + 0.5) / steps;
                    const Vec3 P =
                        toCamera.point(Vec3{float(r * std::cos(phi)), float(r * std::sin(phi)), 0.f});
                    const float v = shadowMapVisibility(*lookup, P, N);
                    const float truth = r < exact ? 0.f : 1.f;
                    if (std::fabs(v - truth) > 0.01f) wrong += (r1 - r0) / steps;
                    if (!crossed && v >= 0.5f) crossed = true, crossing = r;
                }
                band += wrong / rays;
                offset += (crossing - exact) / rays;
            }
            nlohmann::json j = {{"light", lightKind},
                                {"resolution", int(res)},
                                {"filter_width", width},
                                {"texel_world", texel},
                                {"band_world", band},
                                {"band_texels", band / texel},
                                {"offset_texels", offset / texel},
                                {"map_ms", maps.renderMs()}};
            if (images) {
                RenderSettings a = rs, b = rs;
                b.reyesShadows = ReyesShadows::Raytrace;
                const RenderResult withMap = render(scene, a), withRays = render(scene, b);
                j["psnr_db_vs_raytraced"] = compareImages(withMap.image, withRays.image).psnrColor;
            }
            fmt::print("{}\n", j.dump());
            std::fflush(stdout);
        }
    return 0;
}
