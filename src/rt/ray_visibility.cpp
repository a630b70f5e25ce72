#include "rt/ray_visibility.h"

#include <tbb/task_arena.h>

#include <functional>

#include "rt/shadow_rays.h"

namespace tessera {

RayTracedVisibility::RayTracedVisibility(const RtAccel& acc, rt::TraceServiceOptions options)
    : acc_(acc), workspaces_(std::cref(acc), options) {}  // cref: ETS would keep a copy of the accel

void RayTracedVisibility::answer(const VisibilityQuery& q, LightSamples& ls) const {
    Workspace& ws = workspaces_.local();
    rt::makeShadowRays(
        acc_, q.lights, q.points, ls,
        [&](size_t k) {
            return rt::ShadowOrigin{q.patch ? q.patch[k] : rt::kNone, q.uv ? q.uv[k] : Vec2{-1.f, -1.f},
                                    q.time, uint32_t(k)};
        },
        ws.rays, ws.runs, ws.shadowIdx);
    if (ws.rays.size() == 0) return;
    // The trace stages run parallel loops; the caller may be dicing a grid that other threads wait for
    // (Reyes' LazyPieces::forEach), so this thread must not pick up the caller's other tasks while it waits.
    tbb::this_task_arena::isolate([&] { ws.trace.occluded(ws.rays, ws.runs, ws.blocked); });
    rt::applyShadowRays(ws.shadowIdx, ws.blocked, ls, q.points.count, nullptr);
}

void RayTracedVisibility::writeStats(nlohmann::json& s) const {
    rt::TraceCounters total;
    for (const Workspace& w : workspaces_) total.add(w.trace.counters());
    s["method"] = "raytrace";
    s["shadow_rays"] = total.rays[rt::kShadow];
    s["shadow_hits"] = total.hits[rt::kShadow];
    s["trace_cpu_ms"] = total.traversalMs + total.newtonMs;
}

}  // namespace tessera
