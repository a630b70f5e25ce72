#include "io/rib_graphics_state.h"

#include <cmath>

namespace tessera::rib {

bool Transform::isIdentity() const {
    bool identity = true;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) identity &= matrix_.m[i][j] == (i == j ? 1.0 : 0.0);
    return identity;
}

bool Transform::isFinite() const {
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            if (!std::isfinite(matrix_.m[i][j])) return false;
    return true;
}

const char* blockName(Block b) {
    switch (b) {
        case Block::Frame:
            return "FrameBegin";
        case Block::World:
            return "WorldBegin";
        case Block::Attribute:
            return "AttributeBegin";
        case Block::Transform:
            return "TransformBegin";
    }
    return "";
}

void GraphicsState::begin(Block b, const std::string& file, int line) {
    stack_.push_back({b, file, line, transform_, attributes_});
}

void GraphicsState::end(Block b, const Request& r, const Diagnostics& diag) {
    if (stack_.empty()) diag.fail(r.line, r.name + " without a matching " + blockName(b));
    const Saved& top = stack_.back();
    if (top.block != b)
        diag.fail(r.line, r.name + " does not match " + blockName(top.block) + " at " + top.file + ":" +
                              std::to_string(top.line));
    transform_ = top.transform;
    if (b != Block::Transform) attributes_ = top.attributes;
    stack_.pop_back();
}

void GraphicsState::beginWorld(const Request& r, Camera& camera, const Diagnostics& diag) {
    if (!transform_.isFinite())
        diag.fail(r.line, "WorldBegin: the camera transformation is not finite (overflow)");
    camera.cameraFromWorld = transform_.matrix();
    coordinateSystems_["camera"] = Transform(transform_.matrix().inverse());
    begin(Block::World, diag.file(), r.line);
    transform_ = Transform();
    coordinateSystems_["world"] = transform_;
}

bool GraphicsState::inWorld() const {
    for (const Saved& s : stack_)
        if (s.block == Block::World) return true;
    return false;
}

const Transform* GraphicsState::coordinateSystem(const std::string& name) const {
    auto it = coordinateSystems_.find(name);
    return it == coordinateSystems_.end() ? nullptr : &it->second;
}

}  // namespace tessera::rib
