#!/usr/bin/env python3
"""Paper 004's Table 2 on Tessera's scenes (issue 15; docs/benchmarks/adaptive.md): fixed 1, 4, 9, 16 spp and
--adaptive at tau_col 0.1, 0.3, 0.6, 1.0, each against a 256-spp reference (PSNR of premultiplied RGB clamped
to [0, 1], tessera_imgdiff), with camera rays per pixel as the paper counts them, all rays traced relative to
fixed 9, and the trace time (stats trace_ms: the render loop without the accel build; the fastest of --reps
interleaved runs, --threads 1 by default so that a shared machine disturbs it least) relative to fixed 9.
Every render uses a one-pixel box filter (the adaptive pixel is the paper's box weighting): the script
renders a copy of the scene with PixelFilter "box" 1 1, written beside it so its archives resolve.

    python3 bench/adaptive_table.py [--reps 3] [--threads 1] [SCENE.rib:WxH ...]
Writes bench/results/adaptive_<time>.json and prints the Markdown tables.
"""
import argparse, json, os, re, subprocess, sys, tempfile, time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEFAULT = ["scenes/teapot_mirror_floor.rib:400x300", "scenes/bigguy_box.rib:300x300", "scenes/killeroo2.rib:400x300"]
RUNS = [("fixed 1", ["--spp", "1"]), ("fixed 4", ["--spp", "4"]), ("fixed 9", ["--spp", "9"]),
        ("fixed 16", ["--spp", "16"])] + [
    (f"adaptive {t}", ["--adaptive", "--adaptive-threshold", t]) for t in ("0.1", "0.3", "0.6", "1.0")]


def render(scene, res, threads, args, out, stats):
    cmd = [os.path.join(ROOT, "build/tessera"), "render", scene, "--engine", "rt", "--res", res, "--threads",
           str(threads), "-q", "-o", out, "--stats", stats] + args
    subprocess.run(cmd, check=True)
    return json.load(open(stats))


def psnr(ref, img):
    out = subprocess.run([os.path.join(ROOT, "build/tessera_imgdiff"), ref, img], check=True,
                         capture_output=True, text=True).stdout
    return json.loads(out)["psnr_db"]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scenes", nargs="*", default=DEFAULT)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--ref-spp", type=int, default=256)
    a = ap.parse_args()
    os.chdir(ROOT)
    results = {"date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "threads": a.threads,
               "reps": a.reps, "scenes": []}
    work = tempfile.mkdtemp(prefix="tessera_adaptive_")
    for item in a.scenes:
        scene, res = item.split(":")
        box = os.path.join(os.path.dirname(scene), ".adaptive_box_" + os.path.basename(scene))
        text = open(scene).read()
        text = re.sub(r"^(PixelFilter|PixelSamples).*\n", "", text, flags=re.M)
        text = re.sub(r"^(Format .*)$", r'\1\nPixelFilter "box" 1 1', text, count=1, flags=re.M)
        open(box, "w").write(text)
        try:
            ref = os.path.join(work, "ref.exr")
            render(box, res, 2, ["--spp", str(a.ref_spp)], ref, os.path.join(work, "ref.json"))
            rows = {name: {"trace_ms": []} for name, _ in RUNS}
            for rep in range(a.reps):  # interleaved, so that a change in the machine's load hits every run
                for name, args in RUNS:
                    img = os.path.join(work, "img.exr")
                    s = render(box, res, a.threads, args, img, os.path.join(work, "s.json"))
                    row = rows[name]
                    row["trace_ms"].append(s["trace_ms"])
                    if rep == 0:
                        ad = s.get("adaptive", {})
                        row["psnr_db"] = psnr(ref, img)
                        row["camera_rays_per_pixel"] = ad.get("camera_rays_per_pixel", int(args[1]) if
                                                              args[0] == "--spp" else None)
                        row["rays_total"] = s["rays_total"]
                        row["active_fraction"] = ad.get("active_fraction")
            f9 = rows["fixed 9"]
            for row in rows.values():
                row["trace_ms_min"] = min(row["trace_ms"])
                row["rays_of_fixed9"] = row["rays_total"] / f9["rays_total"]
                row["time_of_fixed9"] = row["trace_ms_min"] / min(f9["trace_ms"])
            results["scenes"].append({"scene": scene, "res": res, "runs": rows})
        finally:
            os.remove(box)
        print(f"\n### {os.path.basename(scene)}, {res}\n")
        print("| run | PSNR dB | camera rays/pixel | active subpixels | rays traced / fixed 9 | trace ms | "
              "time / fixed 9 |")
        print("|---|---:|---:|---:|---:|---:|---:|")
        for name, row in rows.items():
            act = row["active_fraction"]
            print(f"| {name} | {row['psnr_db']:.2f} | {row['camera_rays_per_pixel']:.2f} | "
                  f"{'' if act is None else f'{100 * act:.1f}%'} | {row['rays_of_fixed9']:.2f} | "
                  f"{row['trace_ms_min']:.0f} | {row['time_of_fixed9']:.2f} |")
        sys.stdout.flush()
    os.makedirs(os.path.join(ROOT, "bench/results"), exist_ok=True)
    path = os.path.join(ROOT, "bench/results", "adaptive_" + time.strftime("%Y%m%dT%H%M%SZ", time.gmtime()) + ".json")
    json.dump(results, open(path, "w"), indent=1)
    print("\nwrote", path)


if __name__ == "__main__":
    main()
