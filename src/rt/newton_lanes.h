// Newton iteration on many (ray, patch) starts at once: one start per lane, kNewtonLanes lanes, structure
// of arrays. One call of the step function advances every lane by one iteration with exactly the
// arithmetic and stop rules of newtonIterate<float> (intersect.h: same basis expressions, same summation
// order as its 4-wide evaluation, no fused multiply-add), so a start gives bit-identical roots either way.
// The caller refills a lane as soon as its start finishes (converged or failed), so lanes do not wait for
// the slowest start of a group. Plain data, no globals: the step is a pure function of the lane arrays.
#pragma once
#include <cstdint>

namespace tessera {

constexpr int kNewtonLanes = 8;

enum NewtonLaneStatus : int32_t { kLaneRunning = 0, kLaneConverged = 1, kLaneFailed = 2 };

struct alignas(32) NewtonLanes {
    // The 16 control points projected on the ray's two planes, [control point][lane], control points
    // row-major like BezierPatch::cp (index 4 * j + i, u index i).
    float a1[16][kNewtonLanes], a2[16][kNewtonLanes];
    float u[kNewtonLanes], v[kNewtonLanes];  // current iterate; the root once converged
    float eps[kNewtonLanes];                 // residual tolerance
    float prevNorm[kNewtonLanes];            // |R| of the previous iteration (+inf at the start)
    float evals[kNewtonLanes];               // evaluations so far; the reported iteration count at the end
    float clamps[kNewtonLanes];              // consecutive clamps back into the domain
    int32_t status[kNewtonLanes];            // NewtonLaneStatus after a step

    // Start lane `l` at (u0, v0); the caller has filled its a1/a2 column.
    void start(int l, float u0, float v0, float tolerance) {
        u[l] = u0, v[l] = v0, eps[l] = tolerance;
        prevNorm[l] = __builtin_inff();
        evals[l] = 0.f, clamps[l] = 0.f;
        status[l] = kLaneRunning;
    }
};

// A ray's frame for projecting patches into the lanes: its two planes (n1.X + d1 and n2.X + d2, as
// makeRayPlanes builds them), its origin and direction, and 1 / (d.d).
struct LaneRayFrame {
    float n1[3], d1, n2[3], d2, o[3], d[3], invDD;
};

// The frames of n rays given by their origins and directions (structure of arrays, n a multiple of 8):
// makeRayPlanes' arithmetic operation for operation (its branch a lane select), so out[i] holds exactly
// the frame built from makeRayPlanes(o_i, d_i), eight rays at a time (AVX2 when the processor has it, SSE2
// otherwise): the square roots and divisions of a chunk's rays in a few vector instructions.
void makeLaneRayFrames(const float* ox, const float* oy, const float* oz, const float* dx, const float* dy,
                       const float* dz, int n, LaneRayFrame* out);
// The SSE2 build, whatever the processor (tests compare the two).
void makeLaneRayFramesBaseline(const float* ox, const float* oy, const float* oz, const float* dx,
                               const float* dy, const float* dz, int n, LaneRayFrame* out);

// Projects a patch's 16 control points (x, y, z: structure of arrays) on the ray's planes straight into
// lane l's columns of a1 and a2, and writes their distances along the ray, (P - o).d / (d.d), to depth.
// The arithmetic of projectPatch operation for operation (no fused multiply-add), so the columns hold
// exactly its values; 8 control points at a time (AVX2 when the processor has it, SSE2 otherwise).
void projectIntoLane(NewtonLanes& lanes, int l, const LaneRayFrame& f, const float* x, const float* y,
                     const float* z, float depth[16]);
// The SSE2 build of the same projection, whatever the processor (tests compare the two).
void projectIntoLaneBaseline(NewtonLanes& lanes, int l, const LaneRayFrame& f, const float* x, const float* y,
                             const float* z, float depth[16]);

// One Newton iteration on every lane (lanes already finished, or idle, compute values nobody reads).
// After the call, status[l] tells whether lane l converged (u, v hold the root after the free final
// step), failed (left the domain twice, diverged, NaN, or 16 iterations) or runs on; evals[l] is the
// iteration count newtonIterate would report. Returns the lanes whose status is not kLaneRunning (bit l
// for lane l). Uses AVX2 when the processor has it, SSE2 otherwise (the same results).
unsigned newtonLanesStep(NewtonLanes& lanes);
// The SSE2 build of the same step, whatever the processor (tests compare the two).
unsigned newtonLanesStepBaseline(NewtonLanes& lanes);

}  // namespace tessera
