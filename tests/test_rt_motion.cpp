// Motion blur and depth of field in the ray tracer (paper 002, secs. 5.3.3-5.3.4) against analytic truth:
// the time-averaged coverage of a square sweeping across the film, the thin-lens circle of confusion of an
// edge out of focus, the shutter-time fraction of a moving occluder's shadow, and the exactness of the
// binning stages, thread-count independence and the static path.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "film/image_compare.h"
#include "io/scene_loader.h"
#include "rt/rt_renderer.h"
#include "rt/trace_service.h"
#include "test_util.h"

namespace tessera::test::rt_motion_tests {

namespace {

BezierPatch moved(const BezierPatch& p, Vec3 delta) {
    BezierPatch q = p;
    for (Vec3& c : q.cp) c += delta;
    return q;
}

// Patch `i` moves linearly by `delta` (world space) from shutter open (time 0) to close (time 1).
void addLinearMotion(Scene& s, uint32_t i, Vec3 delta) {
    PatchAttributes& a = s.attributes[i];
    a.motion.first = uint32_t(s.motionPatches.size());
    a.motion.count = 2;
    s.motionPatches.push_back(s.patches[i]);
    s.motionPatches.push_back(moved(s.patches[i], delta));
    s.motionTimes.push_back(0.f);
    s.motionTimes.push_back(1.f);
}

RenderResult renderFrame(const Scene& s, int threads = 2, bool binning = true, bool blur = true) {
    RenderSettings rs;
    rs.engine = "rt";
    rs.threads = threads;
    rs.rayBinning = binning;
    rs.blur.enabled = blur;
    return render(s, rs);
}

// Length of [a, b] inside [x0, x1].
double overlap(double a, double b, double x0, double x1) {
    return std::max(0.0, std::min(b, x1) - std::max(a, x0));
}

// A scene whose square covers the whole image height, so that coverage depends on x only.
// Raster scale 160 pixels per unit of the z = 1 plane (the fov spans the shorter axis).
Scene tallSquareScene(int w, int h, int spp) {
    Scene s = cameraSpaceScene(w, h, float(2.0 * std::atan(0.5 * std::min(w, h) / 160.0) * 180.0 / M_PI));
    s.image.pixelSamplesX = s.image.pixelSamplesY = spp;
    s.camera.shutterOpen = 0.f, s.camera.shutterClose = 1.f;
    return s;
}

}  // namespace

TEST(RtMotion, SweepingSquareCoverageIsTheTimeAverage) {
    // A fronto-parallel square at depth 10 moving sideways over the shutter: with a 1x1 box filter a
    // pixel's alpha is the time average of the fraction of the pixel the square covers, i.e.
    // the integral over t of |[px, px+1] n [a(t), b(t)]|, a and b moving linearly in raster space.
    Scene s = tallSquareScene(96, 8, 16);
    const float z = 10.f;
    addPatch(s, planarPatch({-1.0f, -5.f, z}, {1.2f, 0, 0}, {0, 10.f, 0}));
    const Vec3 delta{1.5f, 0, 0};
    addLinearMotion(s, 0, delta);
    const RenderResult r = renderFrame(s);
    ASSERT_TRUE(r.stats.contains("blur"));
    EXPECT_TRUE(r.stats["blur"]["motion"].get<bool>());
    EXPECT_EQ(r.stats["blur"]["moving_patches"].get<int>(), 1);
    const Projector pr(s.camera);
    const double a0 = pr.toRaster({-1.0f, 0, z}).x, b0 = pr.toRaster({0.2f, 0, z}).x;
    const double a1 = pr.toRaster({0.5f, 0, z}).x, b1 = pr.toRaster({1.7f, 0, z}).x;
    ASSERT_GT(a1 - a0, 20.0);  // a sweep of many pixels
    double sumErr = 0, maxErr = 0;
    int n = 0;
    for (int y = 0; y < s.camera.height; ++y)
        for (int x = 0; x < s.camera.width; ++x) {
            double expect = 0;
            const int steps = 4000;
            for (int k = 0; k < steps; ++k) {
                const double t = (k + 0.5) / steps;
                expect += overlap(a0 + (a1 - a0) * t, b0 + (b1 - b0) * t, x, x + 1.0);
            }
            expect /= steps;
            const double err = std::fabs(alphaAt(r.image, x, y) - expect);
            sumErr += err, maxErr = std::max(maxErr, err), ++n;
        }
    std::printf("sweep: mean |alpha - analytic| %.5f, max %.5f (256 spp)\n", sumErr / n, maxErr);
    EXPECT_LT(sumErr / n, 0.01);
    EXPECT_LT(maxErr, 0.06);
}

TEST(RtMotion, IdenticalKeysRenderTheStaticImage) {
    // Motion keys that do not move: the patch is traced as moving (swept boxes, interpolation at each
    // ray's time), and the image is bit-identical to the scene without keys.
    Scene s = cameraSpaceScene(64, 48, 40.f);
    s.camera.shutterOpen = 0.f, s.camera.shutterClose = 1.f;
    addPatch(s, planarPatch({-1.f, -1.f, 8.f}, {2.f, 0, 0.5f}, {0, 2.f, 0.3f}));
    addPatch(s, planarPatch({-6.f, -6.f, 12.f}, {12.f, 0, 0}, {0, 12.f, 0}));
    const RenderResult still = renderFrame(s);
    Scene keyed = s;
    addLinearMotion(keyed, 0, {0, 0, 0});
    const RenderResult k = renderFrame(keyed);
    EXPECT_EQ(k.stats["blur"]["moving_patches"].get<int>(), 1);
    EXPECT_TRUE(still.image.rgba == k.image.rgba);
}

TEST(RtMotion, LensBlursAnEdgeByTheCircleOfConfusion) {
    // Thin lens (radius R, focal distance fd): a ray from lens point a through the focal-plane point of
    // raster x meets depth z at raster x + a_x R (1/z - 1/fd) sx, so a vertical edge at depth z is blurred
    // into the profile of a disk of radius c = R |1/z - 1/fd| sx (Projector::circleOfConfusion): coverage
    // at distance d from the edge = the fraction of the disk beyond d. Box filter 1x1 over the pixel.
    for (const float z : {10.f, 5.f}) {
        Scene s = tallSquareScene(96, 4, 16);
        s.camera.shutterOpen = s.camera.shutterClose = 0.f;
        s.camera.focalDistance = 5.f;
        s.camera.focalLength = 0.8f;
        s.camera.fStop = 1.f;  // lens radius 0.4
        addPatch(s, planarPatch({-0.3f * z / 10.f, -5.f, z}, {10.f, 0, 0}, {0, 10.f, 0}));
        const RenderResult r = renderFrame(s);
        const Projector pr(s.camera);
        const double c = pr.circleOfConfusion(z), e = pr.toRaster({-0.3f * z / 10.f, 0, z}).x;
        // Probability that a uniform disk point's x-component exceeds q (q in [-1, 1]).
        auto beyond = [](double q) {
            q = std::clamp(q, -1.0, 1.0);
            return (std::acos(q) - q * std::sqrt(1 - q * q)) / M_PI;
        };
        double maxErr = 0;
        int ramp = 0;
        for (int x = 0; x < s.camera.width; ++x) {
            double expect = 0;
            const int steps = 256;
            for (int k = 0; k < steps; ++k) {
                const double px = x + (k + 0.5) / steps;
                expect += c > 0 ? beyond((e - px) / c) : (px >= e ? 1.0 : 0.0);
            }
            expect /= steps;
            for (int y = 0; y < s.camera.height; ++y)
                maxErr = std::max(maxErr, std::fabs(alphaAt(r.image, x, y) - expect));
            const float a = alphaAt(r.image, x, 1);
            ramp += a > 0.01f && a < 0.99f;
        }
        std::printf("lens, z %.0f: circle of confusion %.2f px, ramp %d px, max |alpha - analytic| %.4f\n", z,
                    c, ramp, maxErr);
        EXPECT_LT(maxErr, 0.06) << z;
        if (z == s.camera.focalDistance) {
            EXPECT_LE(ramp, 1);  // in the focal plane: sharp
        } else {
            EXPECT_GT(c, 5.0);
            EXPECT_NEAR(ramp, 2 * c, 2.5);
        }
    }
}

TEST(RtMotion, ShadowOfAMovingOccluderIsTheOccludedShutterFraction) {
    // Matte floor z = 10, a point light at L = (0, 3, 4) and a unit square at z = 8 moving by +1.5 in x over
    // the shutter. A floor point F is shadowed at time t when the segment F-L crosses the square there:
    // it crosses z = 8 at Q = F + (L - F) / 3, so when |Qy| < 0.5 and |Qx - 1.5 t| < 0.5. Shadow rays
    // keep their camera ray's time, so a floor pixel's value over the unshadowed one is the fraction of
    // the shutter it is occluded. No ambient light. The shadow (fy in [-2.25, -0.75]) lies below the
    // square's swept image (|y| / z < 0.0625), so the floor pixels tested never see the occluder.
    Scene s = cameraSpaceScene(160, 160, 60.f);
    s.image.pixelSamplesX = s.image.pixelSamplesY = 8;
    s.camera.shutterOpen = 0.f, s.camera.shutterClose = 1.f;
    s.lights.clear();
    s.lights.push_back({LightType::Point, {36, 36, 36}, {0, 3, 4}, {0, 0, 0}});
    s.lights.back().castsShadows = true;
    addPatch(s, planarPatch({-20, -20, 10}, {40, 0, 0}, {0, 40, 0}));
    const RenderResult bare = renderFrame(s);
    addPatch(s, planarPatch({-0.5f, -0.5f, 8}, {1, 0, 0}, {0, 1, 0}));
    addLinearMotion(s, 1, {1.5f, 0, 0});
    const RenderResult r = renderFrame(s);
    const Projector pr(s.camera);
    auto fraction = [](double fx, double fy) {
        const double qx = fx + (0 - fx) / 3, qy = fy + (3 - fy) / 3;
        if (std::fabs(qy) >= 0.5) return 0.0;
        // t in [0, 1] with qx - 0.5 < 1.5 t < qx + 0.5
        return std::max(0.0, std::min(1.0, (qx + 0.5) / 1.5) - std::max(0.0, (qx - 0.5) / 1.5));
    };
    double sumErr = 0, maxErr = 0, shadowed = 0;
    int n = 0;
    for (int y = 0; y < 160; ++y)
        for (int x = 0; x < 160; ++x) {
            const float base = bare.image.pixel(x, y)[0];
            double expect = 0;
            const int sub = 8;
            double fyMax = -1e9;
            for (int j = 0; j < sub; ++j)
                for (int i = 0; i < sub; ++i) {
                    const float cx = (x + (i + 0.5f) / sub - pr.ox) / pr.sx;
                    const float cy = (y + (j + 0.5f) / sub - pr.oy) / pr.sy;
                    expect += fraction(cx * 10, cy * 10);
                    fyMax = std::max(fyMax, double(cy * 10));
                }
            expect /= sub * sub;
            if (!(base > 0.05f) || fyMax > -0.6) continue;  // unlit, or where the occluder may be seen
            const double vis = r.image.pixel(x, y)[0] / base, err = std::fabs((1 - vis) - expect);
            sumErr += err, maxErr = std::max(maxErr, err), ++n;
            shadowed += expect;
        }
    std::printf("moving shadow: %d pixels (%.0f shadowed), mean |shadow - analytic| %.4f, max %.4f\n", n,
                shadowed, sumErr / n, maxErr);
    EXPECT_GT(shadowed, 300.0);
    EXPECT_LT(sumErr / n, 0.01);
    EXPECT_LT(maxErr, 0.1);
}

TEST(RtMotion, BinningStaysExactAndImagesDoNotDependOnThreads) {
    // The teapot moving (every patch by a world-space offset) and seen through a lens, with its distant
    // light and a point light: camera binning (rectangles of swept boxes, widened by the circle of
    // confusion) and shadow binning give the per-ray traversal's candidates; 1 and 2 threads give the
    // same image.
    Scene s = loadScene(std::string(TESSERA_SOURCE_DIR) + "/scenes/teapot.rib", [](const std::string&) {});
    s.camera.width = 160;
    s.camera.height = 120;
    s.image.pixelSamplesX = s.image.pixelSamplesY = 2;
    s.camera.shutterOpen = 0.f, s.camera.shutterClose = 1.f;
    s.lights.push_back({LightType::Point, {1e4f, 1e4f, 1e4f}, {20.f, 40.f, -10.f}, {}});
    const Bounds3 b = [&] {
        Bounds3 bb;
        for (const BezierPatch& p : s.patches)
            for (const Vec3& c : p.cp) bb.extend(c);
        return bb;
    }();
    const float size = maxComponent(b.diagonal());
    for (uint32_t i = 0; i < s.patches.size(); ++i) addLinearMotion(s, i, Vec3{0.15f, 0.05f, 0.1f} * size);
    for (const bool lens : {false, true}) {
        Scene sc = s;
        if (lens) {
            const Vec3 centre = s.camera.cameraFromWorld.point((b.lo + b.hi) * 0.5f);
            sc.camera.focalDistance = centre.z * 0.8f;
            sc.camera.focalLength = 0.1f * size;
            sc.camera.fStop = 1.f;
        }
        const RenderResult binned = renderFrame(sc, 2, true), traversed = renderFrame(sc, 2, false);
        const RenderResult one = renderFrame(sc, 1, true);
        EXPECT_TRUE(binned.stats["ray_binning"].get<bool>());
        EXPECT_EQ(binned.stats["candidates"], traversed.stats["candidates"]) << lens;
        const ImageDiff d = compareImages(binned.image, traversed.image, 0.1f);
        std::printf("moving teapot%s: candidates %llu, alpha mismatch %.4f%%, PSNR %.1f dB\n",
                    lens ? " with lens" : "", (unsigned long long)binned.stats["candidates"].get<uint64_t>(),
                    100 * d.alphaMismatch, d.psnrColor);
        EXPECT_EQ(d.alphaMismatch, 0.0);
        EXPECT_TRUE(binned.image.rgba == one.image.rgba) << lens;
        EXPECT_GT(binned.stats["hits"]["primary"].get<uint64_t>(), 1000u);
    }
}

TEST(RtMotion, StaticPathsAreUnchanged) {
    // --no-blur on a scene with a lens and moving patches renders the pinhole, shutter-open image, bit for
    // bit the image of the same scene without lens and keys; so does a scene whose shutter is closed.
    Scene s = cameraSpaceScene(80, 60, 40.f);
    addPatch(s, planarPatch({-1.f, -1.f, 8.f}, {2.f, 0, 0.5f}, {0, 2.f, 0.3f}));
    addPatch(s, planarPatch({-6.f, -6.f, 12.f}, {12.f, 0, 0}, {0, 12.f, 0}));
    const RenderResult plain = renderFrame(s);
    Scene blurred = s;
    blurred.camera.shutterOpen = 0.f, blurred.camera.shutterClose = 1.f;
    blurred.camera.focalDistance = 8.f, blurred.camera.focalLength = 0.5f, blurred.camera.fStop = 1.f;
    addLinearMotion(blurred, 0, {0.5f, 0.2f, 0.f});
    const RenderResult off = renderFrame(blurred, 2, true, /*blur=*/false);
    EXPECT_FALSE(off.stats.contains("blur"));
    EXPECT_TRUE(plain.image.rgba == off.image.rgba);
    const RenderResult on = renderFrame(blurred);
    EXPECT_TRUE(on.stats["blur"]["lens"].get<bool>());
    EXPECT_FALSE(plain.image.rgba == on.image.rgba);
}

TEST(RtMotion, WavefrontAgreesWithScalarAtEachRaysTime) {
    // The wavefront's Newton stage (per-ray interpolated patch data) and the scalar reference
    // (traceRayScalar with the ray's time) find the same hits on a moving, bending patch.
    Scene s;
    BezierPatch p;
    for (int j = 0; j < 4; ++j)
        for (int i = 0; i < 4; ++i)
            p.at(i, j) = {-1.f + i * 0.66f, -1.f + j * 0.66f, 5.f + 0.3f * ((i + j) % 2)};
    addPatch(s, p);
    s.camera.shutterOpen = 0.f, s.camera.shutterClose = 1.f;
    PatchAttributes& a = s.attributes[0];
    a.motion = {0, 3};
    s.motionPatches = {p, moved(p, {0.8f, 0.f, 1.f}), moved(p, {0.8f, 0.6f, 0.f})};
    s.motionTimes = {0.f, 0.5f, 1.f};
    const FrameMotion fm = prepareFrameMotion(s, s.camera, true);
    ASSERT_EQ(fm.knotCount(), 3);
    RtAccel acc;
    buildRtAccel(s, Mat4::identity(), 6, false, acc, &fm);
    ASSERT_EQ(acc.movingPatches, 1u);
    int hitsScalar = 0, agree = 0, total = 0;
    for (int k = 0; k < 400; ++k) {
        const float time = (k % 20 + 0.5f) / 20.f;
        const Vec3 d{-0.3f + 0.6f * float(k / 20) / 19.f, -0.3f + 0.6f * float((k * 7) % 20) / 19.f, 1.f};
        TraceOptions opt;
        opt.time = time;
        RayHit hs;
        const Ray ray{{0, 0, 0}, d, 0.f, 1e30f};
        const bool got = traceRayScalar(acc, ray, opt, hs);
        std::vector<RayHit> hw;
        traceBatch(acc, std::span<const Ray>(&ray, 1), opt, hw);
        ++total;
        hitsScalar += got;
        if (got == hw[0].hit && (!got || std::fabs(hs.h.t - hw[0].h.t) < 1e-4f * hs.h.t)) ++agree;
        if (got) {  // the hit lies on the patch at the ray's time
            const BezierPatch at = fm.patchAt(0, time);
            const Vec3 q = evalPatch(at, hs.h.u, hs.h.v);
            EXPECT_LT(length(q - ray.d * hs.h.t), 1e-3f);
        }
    }
    EXPECT_GT(hitsScalar, 50);
    EXPECT_EQ(agree, total);
}

namespace {
// Rotation by `degrees` about the vertical axis through `c`.
Vec3 turned(Vec3 p, Vec3 c, float degrees) {
    const float a = degrees * float(M_PI) / 180.f, cs = std::cos(a), sn = std::sin(a);
    const Vec3 d = p - c;
    return c + Vec3{cs * d.x + sn * d.z, d.y, -sn * d.x + cs * d.z};
}

// Five bent patches side by side, turning 60 degrees about a vertical axis over the shutter in `keys`
// keys (deformation keys: the scene's linear motion between them).
Scene turningScene(int keys) {
    Scene s = cameraSpaceScene(64, 48, 40.f);
    s.camera.shutterOpen = 0.f, s.camera.shutterClose = 1.f;
    const Vec3 centre{0.f, 0.f, 6.f};
    for (int q = 0; q < 5; ++q) {
        BezierPatch p;
        for (int j = 0; j < 4; ++j)
            for (int i = 0; i < 4; ++i)
                p.at(i, j) = {-2.5f + q + i / 3.f, -1.f + 2.f * j / 3.f, 6.f + 0.4f * float((i + j) % 2)};
        addPatch(s, p);
        PatchAttributes& a = s.attributes.back();
        a.motion = {uint32_t(s.motionPatches.size()), uint32_t(keys)};
        for (int k = 0; k < keys; ++k) {
            const float t = float(k) / float(keys - 1);
            BezierPatch m = p;
            for (Vec3& c : m.cp) c = turned(c, centre, 60.f * t);
            s.motionPatches.push_back(m);
            s.motionTimes.push_back(t);
        }
    }
    return s;
}
}  // namespace

TEST(RtMotion, TimeSlabsBoundTheMovingPatchesAtEveryTime) {
    // The time slabs' boxes (a slab's quads: the union of its knots' subpatch trees) must hold every leaf of
    // the patch at every time of the slab: checked at 9 x 9 points of every leaf of every patch at 200
    // times, against the leaf boxes of the slab the traversal picks for that time.
    const Scene s = turningScene(13);
    const FrameMotion fm = prepareFrameMotion(s, s.camera, true);
    ASSERT_EQ(fm.knotCount(), 13);
    RtAccel acc;
    buildRtAccel(s, Mat4::identity(), 6, false, acc, &fm);
    const SubpatchForest& f = acc.forest;
    ASSERT_EQ(f.slabCount, 12);
    const uint32_t leafQuadFirst = f.quadsPerPatch - (1u << (f.depth - 2));
    int outside = 0, checked = 0;
    double sweptArea = 0, slabArea = 0;  // mean leaf box size, the swept and the slab's
    for (int ti = 0; ti < 200; ++ti) {
        const float time = (ti + 0.37f) / 200.f;
        const int slab = acc.timeSlab(time);
        for (uint32_t patch = 0; patch < s.patches.size(); ++patch) {
            const BezierPatch at = fm.patchAt(patch, time);
            const SubpatchQuad* quads = f.quadTree(patch, slab);
            for (uint32_t leaf = 0; leaf < (1u << f.depth); ++leaf) {
                const SubpatchQuad& q = quads[leafQuadFirst + leaf / 4];
                const int lane = int(leaf % 4);
                const Bounds3 swept = f.nodeBox(patch, f.firstLeaf() + leaf);
                sweptArea += swept.diagonal().x * swept.diagonal().z;
                const Bounds3 qbox = q.box(lane);
                slabArea += (qbox.hi.x - qbox.lo.x) * (qbox.hi.z - qbox.lo.z);
                float u0, u1, v0, v1;
                subpatchLeafRect(f.depth, leaf, u0, u1, v0, v1);
                for (int b = 0; b <= 8; ++b)
                    for (int a = 0; a <= 8; ++a) {
                        const Vec3 p = evalPatch(at, u0 + (u1 - u0) * a / 8.f, v0 + (v1 - v0) * b / 8.f);
                        bool in = true;
                        for (int k = 0; k < 3; ++k) in &= p[k] >= qbox.lo[k] && p[k] <= qbox.hi[k];
                        outside += !in, ++checked;
                    }
            }
        }
    }
    std::printf("%d of %d points outside their slab's leaf box; leaf boxes %.1fx smaller than swept\n",
                outside, checked, sweptArea / slabArea);
    EXPECT_EQ(outside, 0);
    EXPECT_GT(sweptArea / slabArea, 4.0);  // the point of the slabs
}

TEST(RtMotion, TimeSlabsFindTheSameHitsAsTheSweptBoxesWithFewerCandidates) {
    // Rays at many times through the turning patches: the slabbed accel finds the same hits (patch and
    // distance) as one whose boxes are swept over the whole shutter, testing far fewer candidates.
    const Scene s = turningScene(13);
    const FrameMotion fm = prepareFrameMotion(s, s.camera, true);
    RtAccel slabbed, swept;
    buildRtAccel(s, Mat4::identity(), 6, false, slabbed, &fm);
    buildRtAccel(s, Mat4::identity(), 6, false, swept, &fm, 1);
    ASSERT_GT(slabbed.forest.slabCount, 1);
    ASSERT_EQ(swept.forest.slabCount, 0);
    rt::RayList list;
    for (int k = 0; k < 4000; ++k) {
        const float time = float((k * 37) % 1000) / 1000.f;
        const Vec3 d{-0.45f + 0.9f * float(k % 80) / 79.f, -0.2f + 0.4f * float(k / 80) / 49.f, 1.f};
        list.push({0, 0, 0}, d, 0.f, 1e30f, 0, {1, 1, 1}, 0xffffffffu, rt::kReflection, 0, {-1.f, -1.f},
                  {0.f, 0.f, 0.f}, time);
    }
    std::vector<RayHit> a, b;
    rt::TraceService sa(slabbed), sb(swept);
    sa.trace(list, a);
    sb.trace(list, b);
    int hits = 0, agree = 0;
    for (size_t r = 0; r < list.size(); ++r) {
        hits += b[r].hit;
        agree +=
            a[r].hit == b[r].hit &&
            (!a[r].hit || (a[r].patch == b[r].patch && std::fabs(a[r].h.t - b[r].h.t) < 1e-4f * b[r].h.t));
    }
    const double ca = double(sa.counters().candidates), cb = double(sb.counters().candidates);
    std::printf("%d hits of %zu rays, %d agree; candidates %.0f with slabs, %.0f swept\n", hits, list.size(),
                agree, ca, cb);
    EXPECT_GT(hits, 1000);
    EXPECT_EQ(agree, int(list.size()));
    EXPECT_LT(ca * 3, cb);
}

TEST(RtMotion, AdaptiveSamplingRefinesTheSweepAndConvergesToTheTimeAverage) {
    // --adaptive in a motion-blurred frame (the sweeping square of SweepingSquareCoverageIsTheTimeAverage,
    // one-pixel box filter): presamples on the moving square are blurred, so the pixels it touches refine
    // (whole pixels) and the rest does not, and the alpha's error against the analytic time average is
    // close to the fixed 4x4 render's and far below the presample's alone. Every subpixel refined, the
    // pixel is the mean of the fixed 4x4 render's 16 samples (bounding-box times).
    Scene s = tallSquareScene(96, 8, 4);
    const float z = 10.f;
    addPatch(s, planarPatch({-1.0f, -5.f, z}, {1.2f, 0, 0}, {0, 10.f, 0}));
    addLinearMotion(s, 0, Vec3{1.5f, 0, 0});
    auto adaptive = [&](float threshold) {
        RenderSettings rs;
        rs.engine = "rt";
        rs.threads = 2;
        rs.adaptive.enabled = true;
        AdaptiveThresholds& t = rs.adaptive.thresholds;
        if (threshold >= 0.f) t.color = t.objectId = t.normal = t.shadow = t.texture = threshold;
        return render(s, rs);
    };
    const RenderResult a = adaptive(-1.f), all = adaptive(0.f), none = adaptive(10.f);
    EXPECT_TRUE(a.warnings.empty());
    s.image.pixelSamplesX = s.image.pixelSamplesY = 4;
    const RenderResult fixed = renderFrame(s);
    double maxDiff = 0;
    for (size_t i = 0; i < all.image.rgba.size(); ++i)
        maxDiff = std::max(maxDiff, double(std::fabs(all.image.rgba[i] - fixed.image.rgba[i])));
    EXPECT_LT(maxDiff, 1e-5);

    const Projector pr(s.camera);
    const double a0 = pr.toRaster({-1.0f, 0, z}).x, b0 = pr.toRaster({0.2f, 0, z}).x;
    const double a1 = pr.toRaster({0.5f, 0, z}).x, b1 = pr.toRaster({1.7f, 0, z}).x;
    int refinedInside = 0, pixelsInside = 0;
    double err = 0, errFixed = 0, errPresample = 0;
    for (int x = 0; x < 96; ++x) {
        double expect = 0;
        for (int k = 0; k < 4000; ++k) {
            const double t = (k + 0.5) / 4000;
            expect += overlap(a0 + (a1 - a0) * t, b0 + (b1 - b0) * t, x, x + 1.0) / 4000;
        }
        // Pixels the square never reaches (those it covers at every instant do refine: it moves).
        const bool untouched = x + 1 < a0 - 1 || x > b1 + 1;
        for (int y = 0; y < 8; ++y) {
            int refined = 0;
            for (int q = 0; q < 4; ++q)
                refined += a.refinedSubpixels[size_t(2 * y + q / 2) * 192 + size_t(2 * x + (q & 1))];
            if (untouched) {
                EXPECT_EQ(refined, 0) << x << "," << y;
            }
            if (expect > 0.05 && expect < 0.95) {
                refinedInside += refined > 0, ++pixelsInside;
                err += std::fabs(alphaAt(a.image, x, y) - expect);
                errFixed += std::fabs(alphaAt(fixed.image, x, y) - expect);
                errPresample += std::fabs(alphaAt(none.image, x, y) - expect);
            }
        }
    }
    std::printf(
        "adaptive sweep: %d of %d partly covered pixels refined; mean |alpha - analytic| %.4f "
        "(fixed 16: %.4f, presample: %.4f)\n",
        refinedInside, pixelsInside, err / pixelsInside, errFixed / pixelsInside,
        errPresample / pixelsInside);
    EXPECT_GT(pixelsInside, 100);
    EXPECT_GT(refinedInside, pixelsInside * 9 / 10);
    EXPECT_LT(err, 1.5 * errFixed);
    EXPECT_LT(err, 0.5 * errPresample);
}

}  // namespace tessera::test::rt_motion_tests
