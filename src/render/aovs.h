// AOVs by name (--aov, RIB Display "+name" modes, the Python module's aovs=): which film channels and
// engine planes a list of names asks for, and the image a file holds for it (docs: README "AOVs").
#pragma once
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "film/film.h"

namespace tessera {

// The comma-separated parts of a list ("a,,b" has an empty middle part).
std::vector<std::string> splitCommas(const std::string& text);

struct AovRequest {
    uint32_t channels = 0;            // film channels (kChannel*)
    std::vector<std::string> planes;  // written by an engine under this name (occlusion)
    std::vector<std::string> names;   // as given
    bool ci = false, alpha = false;   // Ci and a: the image's own colour and alpha as layers too
};
inline constexpr const char* kAovNames = "z, N, id, shadows, textured, occlusion, albedo, P, Cs, Ci, a";

// A comma-separated list of kAovNames ("" asks for none); nullopt and `bad` set to the first unknown name.
std::optional<AovRequest> parseAovs(const std::string& list, std::string& bad);

// The image a file holds: RGBA and the planes of `want` (the render may have made more for other files),
// plus Ci and a (the colour, premultiplied, and alpha as named layers) when asked.
Image withLayers(const Image& rendered, const AovRequest& want);
// The image a file holds, without withLayers' copy when that is `rendered` as it is (RGBA, no layers made
// or asked for: 16 MB of page faults at 1024 x 1024 saved): `rendered` itself, else withLayers' image kept
// in `storage`.
const Image& fileImage(const Image& rendered, const AovRequest& want, Image& storage);

}  // namespace tessera
