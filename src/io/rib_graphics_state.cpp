#include "io/rib_graphics_state.h"

#include <algorithm>
#include <cmath>

namespace tessera::rib {

Transform Transform::moving(std::vector<TransformKey> keys) {
    bool same = true;
    for (const TransformKey& k : keys)
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j) same &= k.matrix.m[i][j] == keys.front().matrix.m[i][j];
    if (same || keys.size() < 2) return Transform(keys.empty() ? Mat4() : keys.front().matrix);
    Transform t;
    t.factors_ = {{Mat4(), std::move(keys)}};
    return t;
}

bool Transform::moving() const {
    for (const Factor& f : factors_)
        if (!f.keys.empty()) return true;
    return false;
}

Mat4 Transform::at(double time) const {
    Mat4 m =
        factors_.front().keys.empty() ? factors_.front().matrix : transformAt(factors_.front().keys, time);
    for (size_t i = 1; i < factors_.size(); ++i)
        m = m * (factors_[i].keys.empty() ? factors_[i].matrix : transformAt(factors_[i].keys, time));
    return m;
}

std::optional<std::vector<double>> Transform::sampleTimes(double maxAngleRadians) const {
    std::vector<double> knots;
    for (const Factor& f : factors_)
        for (const TransformKey& k : f.keys) knots.push_back(k.time);
    std::sort(knots.begin(), knots.end());
    knots.erase(std::unique(knots.begin(), knots.end()), knots.end());
    if (knots.size() < 2) return std::vector<double>{};
    if (knots.size() > kMaxMotionKeys) return std::nullopt;
    // Between two knots every factor is on one segment of its own keys (or clamped), so its rotation
    // there is one slerp: evenly spaced times split every factor's turn evenly.
    std::vector<int> pieces(knots.size(), 0);
    size_t total = 1;
    for (size_t k = 1; k < knots.size(); ++k) {
        double angle = 0;
        for (const Factor& f : factors_)
            if (!f.keys.empty())
                angle += rotationAngle(decompose(transformAt(f.keys, knots[k - 1])),
                                       decompose(transformAt(f.keys, knots[k])));
        // The tolerance lets keys written by the RIB writer and read back keep their count.
        const double n = std::ceil(angle / maxAngleRadians - 1e-6);
        if (!(n < double(kMaxMotionKeys))) return std::nullopt;
        pieces[k] = std::max(1, int(n));
        total += size_t(pieces[k]);
        if (total > kMaxMotionKeys) return std::nullopt;
    }
    std::vector<double> out{knots.front()};
    for (size_t k = 1; k < knots.size(); ++k) {
        for (int i = 1; i < pieces[k]; ++i)
            out.push_back(knots[k - 1] + (knots[k] - knots[k - 1]) * i / pieces[k]);
        out.push_back(knots[k]);
    }
    return out;
}

std::optional<std::vector<TransformKey>> Transform::keys(double maxAngleRadians) const {
    std::optional<std::vector<double>> times = sampleTimes(maxAngleRadians);
    if (!times) return std::nullopt;
    std::vector<TransformKey> out;
    for (double t : *times) out.push_back({t, at(t)});
    return out;
}

void Transform::concatenate(const Mat4& m) {
    if (factors_.back().keys.empty())
        factors_.back().matrix = factors_.back().matrix * m;
    else
        factors_.push_back({m, {}});
}

void Transform::concatenate(const Transform& t) {
    for (const Factor& f : t.factors_) {
        if (f.keys.empty())
            concatenate(f.matrix);
        else
            factors_.push_back(f);
    }
}

bool Transform::isIdentity() const {
    if (factors_.size() != 1 || !factors_.front().keys.empty()) return false;
    bool identity = true;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) identity &= factors_.front().matrix.m[i][j] == (i == j ? 1.0 : 0.0);
    return identity;
}

bool Transform::isFinite() const {
    auto finite = [](const Mat4& m) {
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j)
                if (!std::isfinite(m.m[i][j])) return false;
        return true;
    };
    for (const Factor& f : factors_) {
        if (!finite(f.matrix)) return false;
        for (const TransformKey& k : f.keys)
            if (!finite(k.matrix)) return false;
    }
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
    if (b != Block::Transform) attributes_.object.reset();  // a new attribute block: a new object
}

uint32_t GraphicsState::primitiveObject(uint32_t& objectCount) {
    if (!attributes_.object) {
        if (attributes_.identifier.empty())
            attributes_.object = objectCount++;
        else {
            auto [it, added] = namedObjects_.try_emplace(attributes_.identifier, objectCount);
            objectCount += added;
            attributes_.object = it->second;
        }
    }
    return *attributes_.object;
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
    // A moving camera (MotionBegin before WorldBegin, RI spec 3.2, sec. 6): keys refined so that no segment
    // turns more than 2 degrees; cameraFromWorld is the camera at shutter open.
    camera.motion.clear();
    if (transform_.moving()) {
        std::optional<std::vector<TransformKey>> keys = transform_.keys();
        if (!keys)
            diag.fail(r.line, "WorldBegin: the camera motion needs more than " +
                                  std::to_string(kMaxMotionKeys) + " keys (at most 2 degrees of turn each)");
        camera.motion = refineTransformKeys(*keys, kMaxMotionSegmentRadians * (1 + 1e-6));
    }
    camera.cameraFromWorld = transform_.at(camera.shutterOpen);
    coordinateSystems_["camera"] = Transform(camera.cameraFromWorld.inverse());
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
