#!/usr/bin/env python3
"""Displacement and micropolygon sampling in Reyes (issue 12): paper 000's and paper 001's measurements as
ratios and counts on this machine (docs/benchmarks/displacement.md).

1. Paper 000 sec. 4.1/4.2 (Killeroo, teapot): render time (the engine's own engine_ms) of
     plain        the scene without its Displacement
     disp_grid    displaced along each patch's own normal, shading normals from grid differences (the paper's
                  approximate baseline, --displacement-normals grid)
     disp_exact   displaced along the exact, shared normals (ours)
   each with the bounding-box and the nearest-neighbour sampler; no displacement-aware splitting, so that the
   tessellation is the same in every column. Ratios: displacement (disp_grid / plain), exact normals
   (disp_exact / disp_grid), bbox over nearest; the holes nearest leaves (empty pixels beyond bbox's, at one
   centred sample per pixel, so a pixel is its sample).
2. Paper 001 Table 1: pieces ("patches") and grid vertices of the displaced teapot at 1280x1024 as the
   diceable threshold (--max-grid) varies, with displacement-aware splitting on and off.

Times are medians of REPS runs, the configurations interleaved within each repetition. Writes
bench/results/displacement_<timestamp>.json and prints markdown tables.
Usage: python3 bench/displacement_bench.py [--build build] [--reps 5] [--threads 2]
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.path.join(ROOT, "scenes")


def variant(src, displaced, tmp):
    """The scene as a temporary RIB with absolute archive and texture paths; without its Displacement
    (and bound) when not `displaced`."""
    out = []
    for line in open(os.path.join(SCENES, src)):
        if not displaced and (line.startswith("Displacement") or line.startswith('Attribute "displacementbound"')):
            continue
        line = line.replace('"archives/', '"' + SCENES + "/archives/").replace('"textures/', '"' + SCENES + "/textures/")
        out.append(line)
    path = os.path.join(tmp, ("d_" if displaced else "p_") + src)
    with open(path, "w") as f:
        f.writelines(out)
    return path


def render(binary, rib, args, tmp):
    stats = os.path.join(tmp, "s.json")
    cmd = [binary, "render", rib, "-q", "-o", os.path.join(tmp, "out.png"), "--stats", stats] + args
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return json.load(open(stats))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--skip-table1", action="store_true")
    a = ap.parse_args()
    binary = os.path.join(a.build, "tessera")
    tmp = tempfile.mkdtemp()
    common = ["--threads", str(a.threads), "--spp", "1", "--sampler", "centred", "--shadows", "off",
              "--displacement-split", "0"]
    configs = {
        "plain": (False, []),
        "disp_grid": (True, ["--displacement-normals", "grid"]),
        "disp_exact": (True, []),
    }
    result = {"machine": os.uname().nodename, "threads": a.threads, "reps": a.reps, "time": time.time(),
              "paper000": {}, "paper001_table1": []}
    for scene in ["displaced_teapot.rib", "displaced_killeroo.rib"]:
        ribs = {d: variant(scene, d, tmp) for d in (False, True)}
        times = {}
        counts = {}
        for rep in range(a.reps):
            for name, (disp, extra) in configs.items():
                for sampling in ("bbox", "nearest"):
                    key = f"{name}/{sampling}"
                    s = render(binary, ribs[disp], common + extra + ["--micropolygon-sampling", sampling], tmp)
                    times.setdefault(key, []).append(s["engine_ms"])
                    counts[key] = {k: s[k] for k in ("micropolygons", "grid_vertices", "pieces", "sample_tests",
                                                     "empty_pixels", "empty_samples")}
                    counts[key]["stage_ms"] = s["stage_ms"]
            print(f"{scene}: repetition {rep + 1}/{a.reps} done", file=sys.stderr)
        med = {k: statistics.median(v) for k, v in times.items()}
        r = {"times_ms": times, "median_ms": med, "counts": counts}
        r["ratios"] = {
            "displacement (disp_grid/plain, bbox)": med["disp_grid/bbox"] / med["plain/bbox"],
            "exact normals (disp_exact/disp_grid, bbox)": med["disp_exact/bbox"] / med["disp_grid/bbox"],
            "displacement + exact normals (disp_exact/plain, bbox)": med["disp_exact/bbox"] / med["plain/bbox"],
            "bbox/nearest, plain": med["plain/bbox"] / med["plain/nearest"],
            "bbox/nearest, displaced": med["disp_exact/bbox"] / med["disp_exact/nearest"],
        }
        r["holes"] = {
            name: {"nearest_extra_empty_pixels": counts[f"{name}/nearest"]["empty_pixels"]
                   - counts[f"{name}/bbox"]["empty_pixels"],
                   "covered_by_bbox": None}
            for name in configs
        }
        res = [int(x) for x in ("796x515" if "killeroo" in scene else "800x600").split("x")]
        for name in configs:
            r["holes"][name]["covered_by_bbox"] = res[0] * res[1] - counts[f"{name}/bbox"]["empty_pixels"]
        result["paper000"][scene] = r

    if not a.skip_table1:
        rib = variant("displaced_teapot.rib", True, tmp)
        for split in (1, 0):
            for grid in (8, 12, 16, 20, 24):
                s = render(binary, rib, ["--threads", str(a.threads), "--spp", "1", "--shadows", "off", "--res",
                                         "1280x1024", "--max-grid", str(grid), "--displacement-split", str(split)],
                           tmp)
                result["paper001_table1"].append(
                    {"max_grid": grid, "displacement_split": split, "pieces": s["pieces"],
                     "grid_vertices": s["grid_vertices"], "micropolygons": s["micropolygons"],
                     "mean_longest_side_px": s["displaced"]["mean_longest_side_px"],
                     "max_longest_side_px": s["displaced"]["max_longest_side_px"], "engine_ms": s["engine_ms"]})
                print(f"table 1: max-grid {grid}, split {split} done", file=sys.stderr)

    os.makedirs(os.path.join(ROOT, "bench", "results"), exist_ok=True)
    out = os.path.join(ROOT, "bench", "results", time.strftime("displacement_%Y%m%dT%H%M%SZ.json", time.gmtime()))
    with open(out, "w") as f:
        json.dump(result, f, indent=1)

    print("| scene | " + " | ".join(f"{k} ms" for k in next(iter(result["paper000"].values()))["median_ms"]) + " |")
    for scene, r in result["paper000"].items():
        print(f"| {scene} | " + " | ".join(f"{v:.0f}" for v in r["median_ms"].values()) + " |")
    print()
    print("| scene | " + " | ".join(next(iter(result["paper000"].values()))["ratios"]) + " |")
    for scene, r in result["paper000"].items():
        print(f"| {scene} | " + " | ".join(f"{v:.3f}" for v in r["ratios"].values()) + " |")
    print()
    print("| scene | config | holes (pixels nearest leaves empty that bbox covers) | pixels bbox covers |")
    for scene, r in result["paper000"].items():
        for name, h in r["holes"].items():
            print(f"| {scene} | {name} | {h['nearest_extra_empty_pixels']} | {h['covered_by_bbox']} |")
    if result["paper001_table1"]:
        print()
        print("| max-grid | split | pieces | grid vertices | micropolygons | mean / max side px | engine ms |")
        for t in result["paper001_table1"]:
            print(f"| {t['max_grid']} | {t['displacement_split']} | {t['pieces']:,} | {t['grid_vertices']:,} | "
                  f"{t['micropolygons']:,} | {t['mean_longest_side_px']:.2f} / {t['max_longest_side_px']:.1f} | "
                  f"{t['engine_ms']:.0f} |")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
