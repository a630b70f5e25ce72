// libFuzzer target for the Wavefront OBJ reader and its Catmull-Clark conversion to Bezier patches.
#include <cstddef>
#include <cstdint>
#include <string>

#include "fuzz_common.h"
#include "io/diagnostics.h"
#include "io/obj_reader.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace tessera;
    std::vector<BezierPatch> patches;
    try {
        patches = objToPatches(std::string(reinterpret_cast<const char*>(data), size), "fuzz.obj",
                               [](const std::string&) {});
    } catch (const InputError&) {
        return 0;
    }
    fuzz::checkPatches(patches);
    return 0;
}
