// Ray lists and the data the trace stages pass along them: the candidates (Newton starts) grouped by ray
// in chunks. Shared by the traversal, binning and Newton stages, the trace service and the integrator.
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/buffer_allocator.h"
#include "core/vec.h"
#include "rt/intersect.h"
#include "rt/subpatch_tree.h"

namespace tessera {

struct TraceOptions {
    bool anyHit = false;                // shadow rays: stop at the first hit
    bool respectSides = false;          // one-sided patches are invisible from behind (camera rays)
    bool cullBackfaces = false;         // skip subpatches marked back-facing (camera rays, --cull-backfaces)
    uint32_t ignorePatch = UINT32_MAX;  // reject hits on this patch with t < ignoreT (self-intersection)
    float ignoreT = 0.f;
    float time = 0.f;  // the ray's normalised shutter time: moving patches are intersected there
};

struct RayHit {
    bool hit = false;
    uint32_t patch = UINT32_MAX;
    PatchHit h;
};

namespace rt {

// The kind of a ray decides its rules: camera rays respect one-sided patches (and --cull-backfaces),
// shadow rays stop at any hit, secondary rays see both sides.
// kOcclusion: ambient-occlusion rays (both sides of every surface block them; closest hit when their
// distance matters, any hit when traced with TraceService::occluded).
enum Kind : uint8_t {
    kPrimary = 0,
    kShadow = 1,
    kReflection = 2,
    kRefraction = 3,
    kOcclusion = 4,
    kKinds = 5
};
inline constexpr const char* kKindNames[kKinds] = {"primary", "shadow", "reflection", "refraction",
                                                   "occlusion"};
inline constexpr uint32_t kNone = UINT32_MAX;
inline constexpr size_t kChunk = 128;  // rays per parallel work item
inline constexpr int kHistBins = 18;   // Newton iteration counts 0..17

// Ray list, structure of arrays. The arrays are per-thread scratch refilled for every tile: `resize` leaves
// new elements unset (DefaultInitAllocator) for the caller to write, as the camera rays' set-up writes
// every field of every ray (a zero fill first was a quarter of the rt frame's memset).
template <class T>
using RayArray = std::vector<T, DefaultInitAllocator<T, false>>;
struct RayList {
    RayArray<Vec3> o, d;
    RayArray<float> tmin, tmax;
    RayArray<uint32_t> owner;   // primary/secondary: sample index in the tile; shadow: unused
    RayArray<Color> weight;     // throughput to the sample
    RayArray<uint32_t> ignore;  // originating patch (self-intersection guard)
    RayArray<Vec2> ignoreUV;    // (u,v) of the ray's origin on `ignore` (x < 0: unknown)
    // Secondary rays: the unit normal n the origin was offset along (o = P + offset n, with d.n > 0), so
    // the ray stays on the far side of the plane through o orthogonal to n; zero when unknown.
    RayArray<Vec3> originN;
    RayArray<uint8_t> kind, depth;
    // Normalised shutter time in [0,1] (paper 002, sec. 5.3.3): camera rays get their sample's, shadow,
    // reflection and refraction rays their parent's. Read only for moving patches.
    RayArray<float> time;
    size_t size() const { return o.size(); }
    // New elements are left unset: the caller writes every field of them.
    void resize(size_t n) {
        o.resize(n), d.resize(n), tmin.resize(n), tmax.resize(n), owner.resize(n), weight.resize(n);
        ignore.resize(n), ignoreUV.resize(n), originN.resize(n), kind.resize(n), depth.resize(n);
        time.resize(n);
    }
    void reserve(size_t n) {
        o.reserve(n), d.reserve(n), tmin.reserve(n), tmax.reserve(n), owner.reserve(n), weight.reserve(n);
        ignore.reserve(n), ignoreUV.reserve(n), originN.reserve(n), kind.reserve(n), depth.reserve(n);
        time.reserve(n);
    }
    void clear() {
        o.clear(), d.clear(), tmin.clear(), tmax.clear(), owner.clear(), weight.clear(), ignore.clear();
        ignoreUV.clear(), originN.clear(), kind.clear(), depth.clear(), time.clear();
    }
    void push(Vec3 o_, Vec3 d_, float t0, float t1, uint32_t own, Color w, uint32_t ign, uint8_t k,
              uint8_t dep, Vec2 uv = {-1.f, -1.f}, Vec3 n = {0.f, 0.f, 0.f}, float tm = 0.f) {
        o.push_back(o_), d.push_back(d_), tmin.push_back(t0), tmax.push_back(t1), owner.push_back(own);
        weight.push_back(w), ignore.push_back(ign), ignoreUV.push_back(uv), originN.push_back(n);
        kind.push_back(k), depth.push_back(dep), time.push_back(tm);
    }
};

// Traversal output: Newton's starting points, grouped by ray (segments sorted by box entry distance).
struct Candidate {
    uint32_t ray, patch, leaf;  // leaf: 0 .. 2^depth - 1 (its centre is Newton's start)
    float tEnter;
};

// Candidate lists grown without zeroing (written through raw pointers). Per-thread scratch reused from
// tile to tile, so not on huge pages: rounded up to whole 2 MB pages, the binning's lists held 2.7 MB more
// of the teapot frame's 35 MB peak (800x600, 4 spp, 2 threads; issue 18).
using CandidateVector = std::vector<Candidate, DefaultInitAllocator<Candidate, false>>;

// Counters of one chunk of a stage (merged in chunk order).
struct StageCounters {
    uint64_t candidates = 0, newtonRuns = 0, newtonIterations = 0, boxTests = 0, hullCulled = 0;
    uint64_t timeCulled = 0;  // candidates of moving patches whose leaf box at the ray's time is missed
    uint64_t rootPairs = 0;   // binning: (ray, patch) pairs sent down their subpatch trees per ray
    uint64_t slabCulled = 0;  // (ray, leaf) box hits dropped by the leaf's slab (LeafSlab4)
    uint64_t originLeafDropped = 0;  // secondary rays' candidates in their origin's leaf (OriginLeafRule)
    std::array<uint64_t, kHistBins> hist{};
};

// One ray's candidates cand[begin, end) sorted by box entry distance, stably (insertion sort: segments are
// short and nearly sorted).
inline void sortSegmentByEntry(Candidate* cand, size_t begin, size_t end) {
    for (size_t i = begin + 1; i < end; ++i) {
        if (!(cand[i - 1].tEnter > cand[i].tEnter)) continue;
        const Candidate x = cand[i];
        size_t j = i;
        while (j > begin && cand[j - 1].tEnter > x.tEnter) {
            cand[j] = cand[j - 1];
            --j;
        }
        cand[j] = x;
    }
}

// The candidates of kChunk consecutive rays of a list (chunk ci: rays ci * kChunk ..), grouped by ray: the
// output of every candidate stage and the input of the Newton stage.
struct Chunk {
    // Written through a raw pointer by the traversal (grown without zeroing), read by index.
    CandidateVector cand;
    std::vector<uint32_t> segEnd;  // per ray of the chunk: end of its candidates
    StageCounters c;               // counters of this chunk (merged in chunk order)
};

// The rules of a ray of `kind` (`cull`: --cull-backfaces), as the scalar path's TraceOptions.
inline TraceOptions optionsFor(uint8_t kind, uint32_t ignore, float offset, bool cull, float time = 0.f) {
    TraceOptions o;
    o.time = time;
    o.anyHit = kind == kShadow;
    o.respectSides = kind == kPrimary;
    o.cullBackfaces = kind == kPrimary && cull;
    o.ignorePatch = ignore;
    o.ignoreT = 8.f * offset;
    return o;
}

}  // namespace rt
}  // namespace tessera
