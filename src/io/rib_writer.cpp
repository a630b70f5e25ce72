#include "io/rib_writer.h"

#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "io/rib_shaders.h"

namespace tessera {

namespace {

// Shortest text that reads back to exactly the same float.
std::string num(float v) {
    if (v == 0) return "0";  // also turns -0 into 0
    char buf[32];
    auto [end, ec] = std::to_chars(buf, buf + sizeof buf, v);
    return std::string(buf, ec == std::errc() ? end : buf);
}
std::string num(double v) {
    char buf[40];
    auto [end, ec] = std::to_chars(buf, buf + sizeof buf, v);
    return std::string(buf, ec == std::errc() ? end : buf);
}
std::string triple(Vec3 v) {
    return num(v.x) + " " + num(v.y) + " " + num(v.z);
}

// RIB string literal (RI spec 3.2, appendix C.1): backslash-escape quotes, backslashes and newlines.
std::string quoted(const std::string& s) {
    std::string out = "\"";
    for (char c : s) {
        if (c == '"' || c == '\\')
            out += '\\', out += c;
        else if (c == '\n')
            out += "\\n";
        else
            out += c;
    }
    return out + "\"";
}

const char* filterName(FilterType f) {
    switch (f) {
        case FilterType::Box:
            return "box";
        case FilterType::Triangle:
            return "triangle";
        case FilterType::CatmullRom:
            return "catmull-rom";
        case FilterType::Gaussian:
        default:
            return "gaussian";
    }
}

void writeSurface(std::ostream& o, const Material& m, const Scene& scene) {
    o << "Color [" << triple(m.Cs) << "]\n";
    o << "Opacity [" << triple(m.Os) << "]\n";
    switch (m.type) {
        case MaterialType::Matte:
            o << "Surface \"matte\" \"Ka\" [" << num(m.Ka) << "] \"Kd\" [" << num(m.Kd) << "]\n";
            break;
        case MaterialType::Metal:
            o << "Surface \"metal\" \"Ka\" [" << num(m.Ka) << "] \"Ks\" [" << num(m.Ks) << "] \"roughness\" ["
              << num(m.roughness) << "]\n";
            break;
        case MaterialType::ShinyMetal:
            o << "Surface \"shinymetal\" \"Ka\" [" << num(m.Ka) << "] \"Ks\" [" << num(m.Ks) << "] \"Kr\" ["
              << num(m.Kr) << "] \"roughness\" [" << num(m.roughness) << "]\n";
            break;
        case MaterialType::Constant:
            o << "Surface \"constant\"\n";
            break;
        case MaterialType::Mirror:
            o << "Surface \"mirror\" \"Kr\" [" << num(m.Kr) << "]\n";
            break;
        case MaterialType::Glass:
            o << "Surface \"glass\" \"Kr\" [" << num(m.Kr) << "] \"Kt\" [" << num(m.Kt) << "] \"eta\" ["
              << num(m.eta) << "]\n";
            break;
        case MaterialType::Glossy:
            o << "Surface \"glossy\" \"Ka\" [" << num(m.Ka) << "] \"Kd\" [" << num(m.Kd) << "] \"Ks\" ["
              << num(m.Ks) << "] \"roughness\" [" << num(m.roughness) << "] \"specularcolor\" ["
              << triple(m.specularColor) << "] \"samples\" [" << num(m.glossSamples) << "] \"spread\" ["
              << num(m.spread) << "]\n";
            break;
        case MaterialType::Plastic:
        case MaterialType::PaintedPlastic:
        default:
            o << "Surface \"" << (m.type == MaterialType::PaintedPlastic ? "paintedplastic" : "plastic")
              << "\" \"Ka\" [" << num(m.Ka) << "] \"Kd\" [" << num(m.Kd) << "] \"Ks\" [" << num(m.Ks)
              << "] \"roughness\" [" << num(m.roughness) << "] \"specularcolor\" [" << triple(m.specularColor)
              << "]";
            // The texture as an absolute path: the written file may live elsewhere.
            if (m.type == MaterialType::PaintedPlastic && m.texture >= 0 &&
                size_t(m.texture) < scene.textures.size())
                o << " \"texturename\" \""
                  << std::filesystem::absolute(scene.textures[size_t(m.texture)]).lexically_normal().string()
                  << "\"";
            o << "\n";
            break;
    }
}

// A quadric request in its own transformation block (its object-to-world matrix, and the orientation
// that makes the reader flip it as it was flipped: RI spec 4.2.4 with that matrix).
void quadric(std::ostream& o, const SceneQuadric& sq, bool rightHanded) {
    const Quadric& q = sq.q;
    constexpr double kDeg = 180.0 / 3.14159265358979323846;
    o << "AttributeBegin\nOrientation \"" << (rightHanded ? "rh" : "lh") << "\"\nConcatTransform [";
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) o << (i + j ? " " : "") << num(sq.worldFromObject.m[j][i]);
    o << "]\n";
    const std::string theta = q.closedU ? (q.thetaMax < 0 ? "-360" : "360") : num(double(q.thetaMax) * kDeg);
    switch (q.kind) {
        case QuadricKind::Sphere:
            o << "Sphere " << num(q.radius) << " " << num(q.zMin) << " " << num(q.zMax) << " " << theta;
            break;
        case QuadricKind::Cylinder:
            o << "Cylinder " << num(q.radius) << " " << num(q.zMin) << " " << num(q.zMax) << " " << theta;
            break;
        case QuadricKind::Cone:
            o << "Cone " << num(q.height) << " " << num(q.radius) << " " << theta;
            break;
        case QuadricKind::Disk:
            o << "Disk " << num(q.height) << " " << num(q.radius) << " " << theta;
            break;
        case QuadricKind::Paraboloid:
            o << "Paraboloid " << num(q.radius) << " " << num(q.zMin) << " " << num(q.zMax) << " " << theta;
            break;
        case QuadricKind::Hyperboloid:
            o << "Hyperboloid " << triple(q.point1) << " " << triple(q.point2) << " " << theta;
            break;
        case QuadricKind::Torus:
            o << "Torus " << num(q.radius) << " " << num(q.minorRadius) << " " << num(double(q.angle0) * kDeg)
              << " " << num(double(q.angle1) * kDeg) << " " << theta;
            break;
    }
    o << "\nAttributeEnd\n";
}

}  // namespace

void writeRib(const Scene& scene, std::ostream& o) {
    const Camera& cam = scene.camera;
    o << "##RenderMan RIB\n";
    o << "# Written by tessera: " << scene.patches.size() - scene.quadrics.size()
      << " bicubic Bezier patches";
    if (!scene.quadrics.empty()) o << " and " << scene.quadrics.size() << " quadrics";
    if (!scene.sourcePath.empty()) {
        std::string src = scene.sourcePath;
        for (char& c : src)
            if (c == '\n' || c == '\r') c = ' ';
        o << " converted from " << src;
    }
    o << "\nversion 3.04\n";
    o << "Format " << cam.width << " " << cam.height << " " << num(cam.pixelAspect) << "\n";
    if (cam.frameAspect > 0) o << "FrameAspectRatio " << num(cam.frameAspect) << "\n";
    if (cam.hasScreenWindow)
        o << "ScreenWindow " << num(cam.screenWindow[0]) << " " << num(cam.screenWindow[1]) << " "
          << num(cam.screenWindow[2]) << " " << num(cam.screenWindow[3]) << "\n";
    o << "Clipping " << num(cam.nearClip) << " " << num(cam.farClip) << "\n";
    const ImageOptions& img = scene.image;
    o << "PixelSamples " << img.pixelSamplesX << " " << img.pixelSamplesY << "\n";
    o << "PixelFilter \"" << filterName(img.filter) << "\" " << num(img.filterWidthX) << " "
      << num(img.filterWidthY) << "\n";
    if (img.srgbOutput && img.exposureGamma == 1.f && img.exposureGain == 1.f)
        o << "# The source had no image options; display gamma 2.2 approximates its sRGB output.\n"
          << "Exposure 1 2.2\n";
    else
        o << "Exposure " << num(img.exposureGain) << " " << num(img.exposureGamma) << "\n";
    if (!img.displayName.empty()) o << "Display " << quoted(img.displayName) << " \"file\" \"rgba\"\n";
    for (const ImageOptions::SecondaryDisplay& d : img.secondaryDisplays)
        o << "Display " << quoted("+" + d.name) << " " << quoted(d.type) << " " << quoted(d.mode) << "\n";
    // Motion blur and depth of field (RI spec 3.2, sec. 4.1.1 and 4.1.5; docs/motion.md).
    if (cam.shutterOpen != 0.f || cam.shutterClose != 0.f)
        o << "Shutter " << num(cam.shutterOpen) << " " << num(cam.shutterClose) << "\n";
    if (cam.lensRadius() > 0.f)
        o << "DepthOfField " << num(cam.fStop) << " " << num(cam.focalLength) << " " << num(cam.focalDistance)
          << "\n";
    if (!img.blurSampling.empty() || img.blurTileSize > 0 || img.blurPermutations > 0 || !img.jitter ||
        !img.micropolygonSampling.empty()) {
        o << "Hider \"hidden\"";
        if (!img.jitter) o << " \"int jitter\" [0]";
        if (!img.micropolygonSampling.empty())
            o << " \"string micropolygonsampling\" " << quoted(img.micropolygonSampling);
        if (!img.blurSampling.empty()) o << " \"string blursampling\" " << quoted(img.blurSampling);
        if (img.blurTileSize > 0) o << " \"int blurtilesize\" [" << img.blurTileSize << "]";
        if (img.blurPermutations > 0) o << " \"int blurpermutations\" [" << img.blurPermutations << "]";
        o << "\n";
    }
    if (cam.perspective)
        o << "Projection \"perspective\" \"fov\" [" << num(cam.fovDegrees) << "]\n";
    else
        o << "Projection \"orthographic\"\n";
    // RIB matrices are row-major for row vectors: element [i*4+j] is our m[j][i].
    auto transform = [&](const Mat4& m) {
        o << "Transform [";
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j) o << (i || j ? " " : "") << num(m.m[j][i]);
        o << "]\n";
    };
    if (cam.motion.size() > 1) {  // a moving camera: its (refined) keys
        o << "MotionBegin [";
        for (size_t k = 0; k < cam.motion.size(); ++k) o << (k ? " " : "") << num(cam.motion[k].time);
        o << "]\n";
        for (const TransformKey& k : cam.motion) transform(k.matrix);
        o << "MotionEnd\n";
    } else {
        transform(cam.cameraFromWorld);
    }
    o << "WorldBegin\n";
    int handle = 1;
    bool shadows = false;       // the RIB default: lights cast no shadows
    ShadowMapParams shadowMap;  // and the default shadow map
    for (const Light& l : scene.lights) {
        if (l.type != LightType::Ambient && l.castsShadows != shadows) {
            shadows = l.castsShadows;
            o << "Attribute \"light\" \"shadows\" [\"" << (shadows ? "on" : "off") << "\"]\n";
        }
        if (l.type != LightType::Ambient && !(l.shadowMap == shadowMap)) {
            shadowMap = l.shadowMap;
            o << "Attribute \"shadow\" \"resolution\" [" << shadowMap.resolution << "] \"shadingrate\" ["
              << num(shadowMap.shadingRate) << "] \"bias\" [" << num(shadowMap.bias) << "] \"filterwidth\" ["
              << num(shadowMap.filterWidth) << "]\n";
        }
        // shadowspot, shadowdistant, shadowpoint: the maps the light reads (absolute paths, so that the
        // written file finds them wherever it is put), or "raytrace".
        const bool shadowing = l.shadowSource != ShadowSource::Renderer;
        std::string names;
        if (shadowing) {
            const bool cube = l.type == LightType::Point;
            for (int f = 0; f < (cube ? 6 : 1); ++f) {
                std::string name = "raytrace";
                if (l.shadowSource == ShadowSource::File) {
                    const int32_t k = l.shadowFiles[size_t(f)];
                    if (k < 0 || size_t(k) >= scene.shadowMapFiles.size()) continue;
                    std::error_code ec;
                    const auto abs = std::filesystem::absolute(scene.shadowMapFiles[size_t(k)].path, ec);
                    name = ec ? scene.shadowMapFiles[size_t(k)].path : abs.string();
                }
                names += std::string(" \"") + (cube ? rib::kCubeShadowNameParams[f] : rib::kShadowNameParam) +
                         "\" " + tessera::quoted(name);
            }
            if (l.shadowWidth != 1.f) names += " \"width\" [" + num(l.shadowWidth) + "]";
        }
        auto lightName = [&](const char* base) {
            std::string n = shadowing ? "shadow" + std::string(base) : std::string(base) + "light";
            return tessera::quoted(n);
        };
        switch (l.type) {
            case LightType::Ambient:
                o << "LightSource \"ambientlight\" " << handle++ << " \"intensity\" [1] \"lightcolor\" ["
                  << triple(l.color) << "]\n";
                break;
            case LightType::Distant:
                o << "LightSource " << lightName("distant") << " " << handle++
                  << " \"intensity\" [1] \"lightcolor\" [" << triple(l.color) << "] \"from\" ["
                  << triple(l.from) << "] \"to\" [" << triple(l.to) << "]" << names << "\n";
                break;
            case LightType::Point:
                o << "LightSource " << lightName("point") << " " << handle++
                  << " \"intensity\" [1] \"lightcolor\" [" << triple(l.color) << "] \"from\" ["
                  << triple(l.from) << "]" << names << "\n";
                break;
            case LightType::Spot:
                o << "LightSource " << lightName("spot") << " " << handle++
                  << " \"intensity\" [1] \"lightcolor\" [" << triple(l.color) << "] \"from\" ["
                  << triple(l.from) << "] \"to\" [" << triple(l.to) << "] \"coneangle\" [" << num(l.coneAngle)
                  << "] \"conedeltaangle\" [" << num(l.coneDeltaAngle) << "] \"beamdistribution\" ["
                  << num(l.beamDistribution) << "]" << names << "\n";
                break;
            case LightType::Area:  // not written yet: its surfaces would need their AreaLightSource blocks
                break;
        }
    }
    // RI spec 4.2.4: our reader flips a patch when Orientation disagrees with the handedness of the
    // object-to-camera transform; in this world block that transform is cameraFromWorld.
    const bool mirrored = cam.cameraFromWorld.det3() < 0;
    const PatchAttributes defaults{};
    size_t i = 0;
    while (i < scene.patches.size()) {
        const PatchAttributes& a = i < scene.attributes.size() ? scene.attributes[i] : defaults;
        o << "AttributeBegin\n";
        if (a.material < scene.materials.size()) writeSurface(o, scene.materials[a.material], scene);
        o << "ShadingRate " << num(a.shadingRate) << "\n";
        o << "Sides " << (a.twoSided ? 2 : 1) << "\n";
        o << "Orientation \"" << ((a.flipNormal != mirrored) ? "rh" : "lh") << "\"\n";
        if (a.motionFactor != 0.f)
            o << "GeometricApproximation \"motionfactor\" " << num(a.motionFactor) << "\n";
        if (a.focusFactor != 0.f)
            o << "GeometricApproximation \"focusfactor\" " << num(a.focusFactor) << "\n";
        // One block per run of patches with the same attributes.
        for (; i < scene.patches.size(); ++i) {
            const PatchAttributes& b = i < scene.attributes.size() ? scene.attributes[i] : defaults;
            if (b.material != a.material || b.object != a.object || b.shadingRate != a.shadingRate ||
                b.twoSided != a.twoSided || b.flipNormal != a.flipNormal ||
                b.motionFactor != a.motionFactor || b.focusFactor != a.focusFactor)
                break;
            auto patch = [&](const BezierPatch& p) {
                o << "Patch \"bicubic\" \"P\" [";
                for (int k = 0; k < 16; ++k) o << (k ? " " : "") << triple(p.cp[k]);
                o << "]";
                if (i < scene.texCoords.size()) {  // s, t as the four varying corner values
                    o << " \"st\" [";
                    for (int k = 0; k < 4; ++k)
                        o << (k ? " " : "") << num(scene.texCoords[i].st[k].x) << " "
                          << num(scene.texCoords[i].st[k].y);
                    o << "]";
                }
                o << "\n";
            };
            if (isQuadric(b.kind) && b.shape < scene.quadrics.size()) {
                const SceneQuadric& q = scene.quadrics[b.shape];
                const bool qMirrored = (cam.cameraFromWorld * q.worldFromObject).det3() < 0;
                quadric(o, q, b.flipNormal != qMirrored);
            } else if (b.motion.moving()) {  // deformation keys, world space (RI spec 3.2, sec. 6)
                o << "MotionBegin [";
                for (uint32_t k = 0; k < b.motion.count; ++k)
                    o << (k ? " " : "") << num(scene.motionTimes[b.motion.first + k]);
                o << "]\n";
                for (uint32_t k = 0; k < b.motion.count; ++k) patch(scene.motionPatches[b.motion.first + k]);
                o << "MotionEnd\n";
            } else {
                patch(scene.patches[i]);
            }
        }
        o << "AttributeEnd\n";
    }
    o << "WorldEnd\n";
}

void writeRib(const Scene& scene, const std::string& path) {
    namespace fs = std::filesystem;
    fs::path target(path);
    fs::path tmp = target;
    tmp += ".tmp" + std::to_string(::getpid());
    {
        std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
        if (!out)
            throw std::runtime_error(path + ": error: cannot create " + tmp.string() + ": " +
                                     std::strerror(errno));
        writeRib(scene, out);
        out.flush();
        if (!out) {
            out.close();
            std::error_code ec;
            fs::remove(tmp, ec);
            throw std::runtime_error(path + ": error: writing failed (disk full?)");
        }
    }
    std::error_code ec;
    fs::rename(tmp, target, ec);
    if (ec) {
        std::error_code ignored;
        fs::remove(tmp, ignored);
        throw std::runtime_error(path +
                                 ": error: cannot rename the temporary file into place: " + ec.message());
    }
}

}  // namespace tessera
