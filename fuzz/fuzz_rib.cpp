// libFuzzer target for the RIB reader (lexer, requests, parameter lists, every primitive).
#include <cstddef>
#include <cstdint>
#include <string>

#include "fuzz_common.h"
#include "io/diagnostics.h"
#include "io/rib_reader.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace tessera;
    Scene scene;
    try {
        // A relative name: ReadArchive in the input resolves against the working directory.
        readRibText(std::string(reinterpret_cast<const char*>(data), size), "fuzz.rib", scene,
                    [](const std::string&) {});
    } catch (const InputError&) {
        return 0;
    }
    fuzz::checkPatches(scene.patches);
    if (scene.patches.empty()) fuzz::bug("accepted a scene without geometry");
    if (scene.patches.size() != scene.attributes.size()) fuzz::bug("patches and attributes differ in count");
    const Camera& c = scene.camera;
    if (c.width < 1 || c.height < 1 || c.width > kMaxImageSize || c.height > kMaxImageSize)
        fuzz::bug("accepted a resolution outside the limits");
    if (scene.image.pixelSamplesX * scene.image.pixelSamplesY > kMaxPixelSamples)
        fuzz::bug("accepted too many pixel samples");
    for (const Light& l : scene.lights)
        if (!isFinite(l.color) || !isFinite(l.from) || !isFinite(l.to))
            fuzz::bug("accepted a non-finite light");
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            if (!std::isfinite(c.cameraFromWorld.m[i][j])) fuzz::bug("accepted a non-finite camera");
    for (const PatchAttributes& a : scene.attributes)
        if (a.material >= scene.materials.size()) fuzz::bug("material index out of range");
    return 0;
}
