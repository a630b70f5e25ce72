// Ray-traced answers to another engine's visibility queries (engine/visibility.h): Reyes with
// --reyes-shadows raytrace asks the ray tracer's trace service whether each grid vertex sees each light,
// with the same shadow rays the integrator traces (rt/shadow_rays.h), so that a Reyes image with shadows can
// be checked against the ray tracer's.
#pragma once
#include <tbb/enumerable_thread_specific.h>

#include "engine/visibility.h"
#include "rt/accel.h"
#include "rt/trace_service.h"

namespace tessera {

class RayTracedVisibility final : public LightVisibility {
  public:
    // `acc`: the scene in the querying engine's shading space (camera space), kept by reference.
    explicit RayTracedVisibility(const RtAccel& acc, rt::TraceServiceOptions options = {});
    void answer(const VisibilityQuery& query, LightSamples& samples) const override;
    void writeStats(nlohmann::json& shadows) const override;

  private:
    struct Workspace {
        explicit Workspace(const RtAccel& acc, rt::TraceServiceOptions opt) : trace(acc, opt) {}
        rt::TraceService trace;
        rt::RayList rays;
        std::vector<rt::ShadowRun> runs;
        std::vector<uint32_t> shadowIdx;
        std::vector<uint8_t> blocked;
    };
    const RtAccel& acc_;
    mutable tbb::enumerable_thread_specific<Workspace> workspaces_;
};

}  // namespace tessera
