// libFuzzer target for the .bpt patch file reader.
#include <cstddef>
#include <cstdint>
#include <string>

#include "fuzz_common.h"
#include "io/bpt_reader.h"
#include "io/diagnostics.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace tessera;
    std::vector<BezierPatch> patches;
    try {
        patches = parseBpt(std::string(reinterpret_cast<const char*>(data), size), "fuzz.bpt");
    } catch (const InputError&) {
        return 0;
    }
    if (patches.empty()) fuzz::bug("accepted a file without patches");
    fuzz::checkPatches(patches);
    return 0;
}
