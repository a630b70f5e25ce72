// The RIB graphics state (RI spec 3.2, sec. 4): the current attributes and transformation, the
// stack of Frame/World/Attribute/Transform blocks that save and restore them, and the named
// coordinate systems. Options (sec. 4.1) are frame-wide and never saved by a block here: the
// dispatcher writes them straight into Scene::camera and Scene::image.
#pragma once
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/basis.h"
#include "core/motion_transform.h"
#include "core/transform.h"
#include "io/rib_request.h"
#include "scene/scene.h"
#include "shading/registry.h"

namespace tessera::rib {

// The current transformation, object to world inside the world block and object to camera before
// it (RI spec 3.2, sec. 4.3). A value type saved and restored whole by the block stack. A motion block
// (sec. 6, MotionBegin/MotionEnd) makes it move: it is kept as the product of its factors, static
// matrices and moving ones (the keys of one motion block each), and evaluated at a time by interpolating
// each moving factor on its own (decomposed, core/motion_transform.h) and multiplying. So a Rotate block
// followed by a static Translate moves the object on the arc of the rotation, not on the chord that
// interpolating the product's keys would give; two moving factors with different times are evaluated at
// the union of their times.
// At most this many times per motion block and keys per moving patch or camera (docs/errors.md): 2048
// degrees of turn at 2 degrees per key; more is an input error, not an allocation.
inline constexpr size_t kMaxMotionKeys = 1025;

class Transform {
  public:
    Transform() : factors_(1) {}  // identity
    explicit Transform(const Mat4& m) : factors_{{m, {}}} {}
    // The transform of one motion block: its keys in time order (at least 2). Keys that are all equal
    // give a static transform.
    static Transform moving(std::vector<TransformKey> keys);

    bool moving() const;
    // The transform at scene time `time` (each moving factor clamped to its own keys).
    Mat4 at(double time) const;
    // The times at which the object-to-world transform must be evaluated so that the control points,
    // moving linearly between them (the scene's motion model), follow it: the union of the factors' key
    // times, with further times so that no segment turns more than `maxAngleRadians` (the sum over the
    // factors, which bounds the turn of their product). Empty for a static transform; nullopt when that
    // takes more than kMaxMotionKeys times.
    std::optional<std::vector<double>> sampleTimes(double maxAngleRadians = kMaxMotionSegmentRadians) const;
    // at() at each of sampleTimes(): the keys of a moving camera, refined (nullopt: too many).
    std::optional<std::vector<TransformKey>> keys(double maxAngleRadians = kMaxMotionSegmentRadians) const;

    // Each transformation request concatenates on the object side: CTM = CTM * m (per key).
    void concatenate(const Mat4& m);
    void concatenate(const Transform& t);
    bool isIdentity() const;
    bool isFinite() const;

  private:
    struct Factor {
        Mat4 matrix;                     // when static
        std::vector<TransformKey> keys;  // when moving (2 or more)
    };
    std::vector<Factor> factors_;  // never empty; no two static factors next to each other
};

// Attributes that primitives take from the graphics state (RI spec 3.2, sec. 4.2).
struct Attributes {
    // The RI default surface is "defaultsurface"; matte is the closest standard shader.
    Material surface = defaultMaterial(MaterialType::Matte);
    float shadingRate = 1.f;
    bool twoSided = true;      // RI default: Sides 2
    bool rightHanded = false;  // Orientation "rh"/"inside"; the initial "outside" counts as "lh"
    Basis uBasis = bezierBasis(), vBasis = bezierBasis();
    std::string identifier;
    // The object id of the primitives declared here (scene.h PatchAttributes::object): one per attribute
    // block (each AttributeBegin, each ObjectInstance), or per Attribute "identifier" "name", whose
    // primitives share an id wherever they are; assigned by the block's first primitive.
    std::optional<uint32_t> object;
    // GeometricApproximation "motionfactor" / "focusfactor" (PRMan, Aqsis; scene.h PatchAttributes).
    float motionFactor = 0.f, focusFactor = 0.f;
    // Attribute "light" "shadows" "on"|"off" (BMRT, Aqsis): whether the lights declared from here on cast
    // shadows; each LightSource takes the value current when it is declared. Default off.
    bool lightShadows = false;
    // Attribute "shadow" "resolution" / "shadingrate" / "bias" / "filterwidth": the shadow map of the
    // lights declared from here on (scene.h ShadowMapParams; docs/shading.md).
    ShadowMapParams shadowMap;
    // TextureCoordinates s1 t1 s2 t2 s3 t3 s4 t4 (RI spec 3.2, sec. 4.2.7): s, t at the corners of the
    // parameter unit square of the primitives that follow (default s = u, t = v).
    PatchTexCoords textureCoordinates;
    // Displacement (RI spec 3.2, sec. 4.2.3; -1: none): index into Scene::displacements, and Attribute
    // "displacementbound" "sphere" r "coordinatesystem" space, r converted to world units (0: not given).
    int32_t displacement = -1;
    float displacementBound = 0.f;
    // AreaLightSource (RI spec 3.2, sec. 4.2.2): the area light (index into Scene::lights) that the
    // surfaces declared from here to the end of the attribute block belong to; -1: none.
    int32_t areaLight = -1;
};

enum class Block { Frame, World, Attribute, Transform };

// The request that opens a block, e.g. "AttributeBegin".
const char* blockName(Block b);

class GraphicsState {
  public:
    struct Saved {
        Block block;
        std::string file;  // where the block was opened, for mismatch messages
        int line;
        Transform transform;
        Attributes attributes;
    };

    Attributes& attributes() { return attributes_; }
    const Attributes& attributes() const { return attributes_; }
    Transform& transform() { return transform_; }
    const Transform& transform() const { return transform_; }

    // Opens a block at file:line, saving the attributes and the transformation.
    void begin(Block b, const std::string& file, int line);
    // Closes block `b` for the request `r` (e.g. AttributeEnd): an error unless `b` is the innermost
    // open block. Transform blocks restore the transformation only, all others also the attributes.
    void end(Block b, const Request& r, const Diagnostics& diag);
    // WorldBegin (RI spec 3.2, sec. 4.1.1): the CTM becomes the camera transformation (stored in
    // `camera`), the coordinate systems "camera" and "world" are defined, and the CTM is reset.
    void beginWorld(const Request& r, Camera& camera, const Diagnostics& diag);

    bool inWorld() const;
    // The innermost open block, nullptr if none (for the end-of-file error).
    const Saved* innermostBlock() const { return stack_.empty() ? nullptr : &stack_.back(); }

    // The object id of a primitive declared now (Attributes::object), assigned from `objectCount` (the
    // scene's counter) on the block's first primitive.
    uint32_t primitiveObject(uint32_t& objectCount);

    // CoordinateSystem / CoordSysTransform (RI spec 3.2, sec. 4.3.2): named copies of the CTM.
    void defineCoordinateSystem(const std::string& name) { coordinateSystems_[name] = transform_; }
    const Transform* coordinateSystem(const std::string& name) const;

  private:
    std::map<std::string, uint32_t> namedObjects_;  // Attribute "identifier" "name" -> object id
    Attributes attributes_;
    Transform transform_;
    std::vector<Saved> stack_;
    std::map<std::string, Transform> coordinateSystems_;
};

}  // namespace tessera::rib
