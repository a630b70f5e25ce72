"""The tessera Python module end to end: scenes from files and RIB text, both engines, AOVs as arrays against
an analytic scene, the statistics, crops, writing files, the same pixels as the CLI, errors, Ctrl-C.

Run by CTest (PythonModule) with PYTHONPATH=build/python, TESSERA_SOURCE_DIR and TESSERA_BINARY set."""
import math
import os
import signal
import subprocess
import threading
from pathlib import Path

import numpy as np
import pytest

import tessera

SOURCE = Path(os.environ.get("TESSERA_SOURCE_DIR", Path(__file__).resolve().parents[2]))
BINARY = os.environ.get("TESSERA_BINARY", str(SOURCE / "build" / "tessera"))
TEAPOT = SOURCE / "scenes" / "teapot.rib"

# Two planes facing the eye (the camera looks down +z): the left half at depth 5 (object 0), the right
# half at depth 7 (object 1); 40-degree view of the vertical side. As tests/test_aov.cpp.
PLANES = """Format 64 48 1
PixelSamples 2 2
Projection "perspective" "fov" 40
WorldBegin
LightSource "ambientlight" 1 "intensity" 1
AttributeBegin
Patch "bilinear" "P" [-20 -20 5  0 -20 5  -20 20 5  0 20 5]
AttributeEnd
AttributeBegin
Patch "bilinear" "P" [0 -20 7  20 -20 7  0 20 7  20 20 7]
AttributeEnd
WorldEnd
"""


def psnr(a, b):
    mse = float(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2))
    return math.inf if mse == 0 else 10 * math.log10(1.0 / mse)


@pytest.mark.parametrize("engine", ["reyes", "rt"])
def test_aovs_of_two_planes_are_their_depth_normal_and_object(engine):
    r = tessera.render(rib=PLANES, engine=engine, aovs=["z", "N", "id", "Ci", "a"])
    assert r.image.shape == (48, 64, 4) and r.image.dtype == np.float32
    assert (r.width, r.height, r.origin) == (64, 48, (0, 0))
    z, n, ids = r.aovs["z"], r.aovs["N"], r.aovs["id"]
    assert z.shape == (48, 64) and n.shape == (48, 64, 3) and ids.shape == (48, 64)
    assert ids.dtype == np.uint32
    # Away from the seam at the centre column: exact depths, the normal towards the eye, one id per plane.
    cols = np.abs(np.arange(64) + 0.5 - 32) >= 2
    left, right = cols & (np.arange(64) < 32), cols & (np.arange(64) >= 32)
    np.testing.assert_allclose(z[:, left], 5.0, atol=1e-3)
    np.testing.assert_allclose(z[:, right], 7.0, atol=1e-3)
    np.testing.assert_allclose(n[:, cols], np.broadcast_to([0, 0, -1], n[:, cols].shape), atol=1e-3)
    assert (ids[:, left] == 0).all() and (ids[:, right] == 1).all()
    # The planes cover the frame: alpha 1, and Ci / a are the image's own colour and alpha.
    np.testing.assert_allclose(r.image[..., 3], 1.0, atol=1e-6)
    np.testing.assert_array_equal(r.aovs["Ci"], r.image[..., :3])
    np.testing.assert_array_equal(r.aovs["a"], r.image[..., 3])


def test_stats_are_a_dict_of_the_render():
    r = tessera.render(TEAPOT, res=(80, 60), spp=4)
    s = r.stats
    assert isinstance(s, dict)
    assert s["micropolygons"] > 0 and s["render_ms"] > 0
    assert s["blur"]["enabled"] is True and s["shadows"]["mode"] == "scene"
    rt = tessera.render(TEAPOT, engine="rt", res=(80, 60), spp=4, shadows="off").stats
    assert rt["shadows"]["casting_lights"] == 0
    assert "micropolygons" not in rt


def test_instancing_can_be_turned_off():
    # The eight teapots of instanced_teapots.rib share their object's subpatch trees unless instancing=False;
    # the images agree to rounding (docs/rt.md, "Instancing").
    scene = SOURCE / "scenes" / "instanced_teapots.rib"
    shared = tessera.render(scene, engine="rt", res=(80, 60), spp=1)
    copies = tessera.render(scene, engine="rt", res=(80, 60), spp=1, instancing=False)
    assert shared.stats["instancing"]["shared_patches"] == 6 * 32
    assert copies.stats["instancing"]["shared_patches"] == 0
    assert np.abs(np.asarray(shared.image) - np.asarray(copies.image)).max() < 0.05


def test_a_scene_renders_many_times_under_different_options():
    scene = tessera.load(TEAPOT)
    assert (scene.width, scene.height) == (800, 600) and scene.surfaces == 32 and scene.lights >= 1
    small = scene.render(res=(40, 30), spp=1)
    wide = scene.render(res="64x32", spp=1, engine="rt")
    assert small.image.shape == (30, 40, 4) and wide.image.shape == (32, 64, 4)
    # The overrides edit a copy: the scene keeps its own resolution.
    assert (scene.width, scene.height) == (800, 600)
    # Same options, same pixels (the sampler is deterministic per pixel).
    np.testing.assert_array_equal(scene.render(res=(40, 30), spp=1).image, small.image)


def test_the_engines_agree_on_the_teapot():
    scene = tessera.load(TEAPOT)
    reyes = scene.render(res=(160, 120), spp=16).image
    rt = scene.render(res=(160, 120), spp=16, engine="rt").image
    print(f"teapot 160x120, 16 spp: Reyes vs rt PSNR {psnr(reyes, rt):.1f} dB, "
          f"mean |alpha difference| {np.mean(np.abs(reyes[..., 3] - rt[..., 3])):.5f}")
    assert psnr(reyes, rt) >= 45.0
    # Coverage: the same silhouette up to the two engines' edge sampling.
    assert np.mean(np.abs(reyes[..., 3] - rt[..., 3])) < 0.002


@pytest.mark.parametrize("engine", ["reyes", "rt"])
def test_a_crop_is_the_same_pixels_as_the_full_render(engine):
    full = tessera.render(TEAPOT, engine=engine, res=(96, 72), spp=4).image
    crop = tessera.render(TEAPOT, engine=engine, res=(96, 72), spp=4, crop=(0.25, 0.75, 0.5, 1.0))
    x0, y0 = crop.origin
    assert (x0, y0, crop.width, crop.height) == (24, 36, 48, 36)
    np.testing.assert_array_equal(crop.image, full[y0 : y0 + 36, x0 : x0 + 48])


def test_the_module_and_the_cli_make_the_same_file(tmp_path):
    cli = tmp_path / "cli.exr"
    subprocess.run([BINARY, "render", str(TEAPOT), "--res", "64x48", "--spp", "4", "--engine", "rt",
                    "--aov", "z", "-q", "-o", str(cli)], check=True)
    r = tessera.render(TEAPOT, res=(64, 48), spp=4, engine="rt", aovs="z")
    out = tmp_path / "module.exr"
    r.write(out.as_posix())
    np.testing.assert_array_equal(tessera.read_image(str(out)), tessera.read_image(str(cli)))
    with pytest.raises(ValueError, match="AOVs: they need an OpenEXR file"):
        r.write(str(tmp_path / "module.png"))
    png = tmp_path / "beauty.png"
    tessera.render(TEAPOT, res=(64, 48), spp=4, engine="rt").write(png)
    cli_png = tmp_path / "cli.png"
    subprocess.run([BINARY, "render", str(TEAPOT), "--res", "64x48", "--spp", "4", "--engine", "rt", "-q", "-o",
                    str(cli_png)], check=True)
    assert png.read_bytes() == cli_png.read_bytes()
    with pytest.raises(ValueError, match="unsupported output format"):
        r.write(str(tmp_path / "x.tif"))
    assert not list(tmp_path.glob(".*tmp*"))  # no temporary file left behind


def test_a_file_without_a_camera_is_framed_and_renders(tmp_path):
    # A Catmull-Clark cube from an OBJ file: the module frames it as the CLI does (docs/inputs.md).
    obj = tmp_path / "cube.obj"
    obj.write_text("v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n"
                   "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n")
    scene = tessera.load(obj)
    assert scene.surfaces > 0 and scene.lights > 0
    r = scene.render(res=(48, 48), spp=4)
    alpha = r.image[..., 3]
    assert alpha[24, 24] == pytest.approx(1.0) and alpha[0, 0] == 0.0
    assert np.isfinite(r.image).all()


def test_errors_are_python_exceptions(tmp_path):
    with pytest.raises(TypeError, match="unknown option 'sp'"):
        tessera.render(rib=PLANES, sp=4)
    with pytest.raises(ValueError, match="engine must be one of"):
        tessera.render(rib=PLANES, engine="pbrt")
    with pytest.raises(ValueError, match="unknown AOV 'depth'"):
        tessera.render(rib=PLANES, aovs=["depth"])
    with pytest.raises(ValueError, match="samples per pixel"):
        tessera.render(rib=PLANES, spp=100000)
    with pytest.raises(ValueError, match="res"):
        tessera.render(rib=PLANES, res=(0, 10))
    with pytest.raises(ValueError, match="crop"):
        tessera.render(rib=PLANES, crop=(0.5, 0.4, 0, 1))
    with pytest.raises(ValueError, match="shutter: close is before open"):
        tessera.render(rib=PLANES, shutter=(1, 0))
    with pytest.raises(TypeError, match="option spp: wrong type"):
        tessera.render(rib=PLANES, spp="many")
    # Malformed scene input: tessera.InputError (a ValueError) naming the file and line.
    bad = PLANES.replace('"fov" 40', '"fov" [40')
    with pytest.raises(tessera.InputError, match=r"<rib>:4: error: expected '\]'"):
        tessera.load_rib(bad)
    assert issubclass(tessera.InputError, ValueError)
    with pytest.raises(tessera.InputError, match="nothing.rib"):
        tessera.load(tmp_path / "nothing.rib")
    with pytest.raises(ValueError, match="no geometry"):
        tessera.render(rib="WorldBegin\nWorldEnd\n")


def test_ctrl_c_stops_a_render():
    scene = tessera.load(TEAPOT)
    timer = threading.Timer(0.3, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            scene.render(res=(1600, 1200), spp=256, engine="rt")
    finally:
        timer.cancel()


def test_progress_reports_increasing_fractions_and_can_stop_the_render():
    seen = []
    tessera.render(TEAPOT, res=(160, 120), spp=4, progress=seen.append)
    assert seen and seen[-1] == 1.0
    assert all(0.0 <= a < b <= 1.0 for a, b in zip(seen, seen[1:]))

    class Stop(Exception):
        pass

    def stop(fraction):
        raise Stop(fraction)

    scene = tessera.load(TEAPOT)
    with pytest.raises(Stop):
        scene.render(res=(1600, 1200), spp=256, engine="rt", progress=stop)
    with pytest.raises(TypeError, match="progress: must be callable"):
        scene.render(res=(16, 12), progress=3)


def test_adaptive_sampling_reports_its_refined_subpixels():
    # The two planes in two colours: refinement only along the seam between them (docs/adaptive.md).
    two_colours = PLANES.replace('Patch "bilinear" "P" [0 -20 7', 'Color [1 0.2 0.1]\nPatch "bilinear" "P" [0 -20 7')
    r = tessera.render(rib=two_colours, engine="rt", adaptive=True)
    refined = r.refined
    assert refined.shape == (96, 128) and refined.dtype == np.uint8
    cols = np.nonzero(refined.any(axis=0))[0]
    assert len(cols) > 0 and all(abs(c + 0.5 - 64) <= 4 for c in cols), cols
    assert tessera.render(rib=PLANES, engine="rt").refined is None
    with pytest.raises(ValueError, match="engine rt"):
        tessera.render(rib=PLANES, adaptive=True)
    with pytest.raises(ValueError, match="give no spp"):
        tessera.render(rib=PLANES, engine="rt", adaptive=True, spp=4)
    # The paper's other thresholds by name, the focus list and the interpolation, as on the command line:
    # the seam is between objects 0 and 1 with the same colour, so only the object id can refine it, and
    # only where the focus names one of them.
    ids = dict(engine="rt", adaptive=True, adaptive_thresholds="col=1,poid=0,psn=1,psc=1,pte=1")
    assert tessera.render(rib=PLANES, adaptive_focus=[1], **ids).refined.any()
    assert not tessera.render(rib=PLANES, adaptive_focus="7", **ids).refined.any()
    r = tessera.render(rib=PLANES, adaptive_interpolate=True, **ids)
    assert r.stats["adaptive"]["interpolate"] is True
    assert r.stats["adaptive"]["thresholds"]["object_id"] == 0
    with pytest.raises(ValueError, match="not NAME=VALUE"):
        tessera.render(rib=PLANES, engine="rt", adaptive=True, adaptive_thresholds="zz=1")
    with pytest.raises(ValueError, match="need adaptive sampling"):
        tessera.render(rib=PLANES, engine="rt", adaptive_interpolate=True)


def test_frames_of_a_multi_frame_rib(tmp_path):
    rib = tmp_path / "frames.rib"
    frame = 'FrameBegin {n}\nFormat {w} 24 1\nProjection "perspective" "fov" 40\nWorldBegin\n' \
            'Translate 0 0 5\nSphere 1 -1 1 360\nWorldEnd\nFrameEnd\n'
    rib.write_text(frame.format(n=3, w=32) + frame.format(n=7, w=48))
    assert tessera.frames(rib) == [3, 7]
    assert tessera.load(rib).width == 32  # the first frame, with a warning
    assert any("only the first frame" in w for w in tessera.load(rib).warnings)
    assert tessera.load(rib, frame=7).width == 48
    with pytest.raises(ValueError, match="no FrameBegin 5"):
        tessera.load(rib, frame=5)


CUBE = """Format 200 200 1
Projection "perspective" "fov" 40
Translate 0 0 30
WorldBegin
LightSource "ambientlight" 1
SubdivisionMesh "catmull-clark" [4 4 4 4 4 4] [0 3 2 1 4 5 6 7 0 1 5 4 1 2 6 5 2 3 7 6 3 0 4 7]
  "P" [-1 -1 -1 1 -1 -1 1 1 -1 -1 1 -1 -1 -1 1 1 -1 1 1 1 1 -1 1 1]
WorldEnd
"""


def test_res_at_load_chooses_the_subdivision_level(tmp_path):
    # A SubdivisionMesh is refined for its size in the image rendered (docs/subdivision.md): level 2
    # (6 x 16 patches) at the file's 200 x 200, level 3 (6 x 64) loaded for 1600 x 1600, as the CLI's --res.
    path = tmp_path / "cube.rib"
    path.write_text(CUBE)
    assert tessera.load(path).surfaces == 96
    big = tessera.load(path, res=(1600, 1600))
    assert big.surfaces == 384 and big.width == 1600 and big.height == 1600
    assert tessera.load(path, res="1600x1600").surfaces == 384
    assert tessera.load_rib(CUBE, res=(1600, 1600)).surfaces == 384
    # render(path, res=...) loads for that size
    assert tessera.render(path, res=(1600, 1600), crop=(0.45, 0.55, 0.45, 0.55)).stats["patches_in"] == 384
    with pytest.raises(ValueError):
        tessera.load(path, res=(0, 5))
