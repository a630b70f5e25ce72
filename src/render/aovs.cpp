#include "render/aovs.h"

#include <utility>

namespace tessera {

std::vector<std::string> splitCommas(const std::string& text) {
    std::vector<std::string> parts;
    size_t at = 0;
    while (true) {
        const size_t end = text.find(',', at);
        parts.push_back(text.substr(at, end == std::string::npos ? std::string::npos : end - at));
        if (end == std::string::npos) return parts;
        at = end + 1;
    }
}

std::optional<AovRequest> parseAovs(const std::string& list, std::string& bad) {
    AovRequest r;
    if (list.empty()) return r;
    for (const std::string& name : splitCommas(list)) {
        if (name == "z")
            r.channels |= kChannelDepth;
        else if (name == "N")
            r.channels |= kChannelNormal;
        else if (name == "id")
            r.channels |= kChannelObjectId;
        else if (name == "shadows")
            r.channels |= kChannelShadowCount;
        else if (name == "textured")
            r.channels |= kChannelHasTexture;
        else if (name == "occlusion")
            r.planes.push_back(name);
        else if (name == "albedo")
            r.channels |= kChannelAlbedo;
        else if (name == "P")
            r.channels |= kChannelPosition;
        else if (name == "Cs")
            r.channels |= kChannelSurfaceColor;
        else if (name == "Ci")
            r.ci = true;
        else if (name == "a")
            r.alpha = true;
        else {
            bad = name;
            return std::nullopt;
        }
        r.names.push_back(name);
    }
    return r;
}

const Image& fileImage(const Image& rendered, const AovRequest& want, Image& storage) {
    if (rendered.planes.empty() && want.channels == 0 && want.planes.empty() && !want.ci && !want.alpha)
        return rendered;
    storage = withLayers(rendered, want);
    return storage;
}

Image withLayers(const Image& rendered, const AovRequest& want) {
    Image img = rendered;
    img.planes.clear();
    auto keep = [&](const std::string& name) {
        if (const ImagePlane* p = rendered.plane(name)) img.planes.push_back(*p);
    };
    const std::pair<uint32_t, const char*> named[] = {{kChannelObjectId, "id"},
                                                      {kChannelDepth, "z"},
                                                      {kChannelNormal, "N"},
                                                      {kChannelShadowCount, "shadows"},
                                                      {kChannelHasTexture, "textured"},
                                                      {kChannelAlbedo, "albedo"},
                                                      {kChannelPosition, "P"},
                                                      {kChannelSurfaceColor, "Cs"}};
    for (const auto& [bit, name] : named)
        if (want.channels & bit) keep(name);
    for (const std::string& p : want.planes) keep(p);
    const size_t n = size_t(img.width) * size_t(img.height);
    if (want.ci) {
        ImagePlane ci{"Ci", 3, false, true, std::vector<float>(n * 3), {}};
        for (size_t i = 0; i < n; ++i)
            for (int c = 0; c < 3; ++c) ci.values[i * 3 + size_t(c)] = img.rgba[i * 4 + size_t(c)];
        img.planes.push_back(std::move(ci));
    }
    if (want.alpha) {
        ImagePlane alpha{"a", 1, false, false, std::vector<float>(n), {}};
        for (size_t i = 0; i < n; ++i) alpha.values[i] = img.rgba[i * 4 + 3];
        img.planes.push_back(std::move(alpha));
    }
    return img;
}

}  // namespace tessera
