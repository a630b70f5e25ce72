#!/usr/bin/env python3
"""Subpatch depth sweep (issue 18, docs/rt.md "Subpatch depth per frame"): per scene and depth, the ray
tracer's trace and build time (minimum of R runs, depths interleaved), subpatch memory, peak RSS, Newton
iterations per run and the image against depth 6 (tessera_imgdiff), plus what --subpatch-depth auto picks.
Writes bench/results/subpatch_depth.json and prints a Markdown table.
Usage: R=3 SCENES="teapot killeroo" DEPTHS="4 6" RES=800x600 SPP=4 bench/subpatch_depth.py [tessera]"""
import json, os, shutil, subprocess, sys, tempfile

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
tessera = sys.argv[1] if len(sys.argv) > 1 else os.path.join(root, "build", "tessera")
imgdiff = os.path.join(os.path.dirname(tessera), "tessera_imgdiff")
runs = int(os.environ.get("R", "3"))
scenes = os.environ.get("SCENES", "teapot killeroo bigguy bigguy24").split()
depths = [int(d) for d in os.environ.get("DEPTHS", "2 4 6").split()]
if 6 not in depths:
    depths.append(6)  # the reference image
res, spp = os.environ.get("RES", "800x600"), os.environ.get("SPP", "4")
tmp = tempfile.mkdtemp(prefix="subpatch_depth.")


def render(scene, depth, tag):
    stats, out, rss = (os.path.join(tmp, f"{tag}.{ext}") for ext in ("json", "png", "rss"))
    subprocess.run(["/usr/bin/time", "-f", "%M", "-o", rss, tessera, "render", os.path.join(root, "scenes", scene + ".rib"),
                    "--engine", "rt", "--res", res, "--spp", spp, "--threads", "2", "--subpatch-depth", str(depth),
                    "--stats", stats, "-o", out, "-q"], check=True)
    s = json.load(open(stats))
    s["peak_rss_kb"] = int(open(rss).read().split()[-1])
    return s, out


results = []
for scene in scenes:
    rows = {d: [] for d in depths + ["auto"]}
    images = {}
    for _ in range(runs):
        for d in depths + ["auto"]:
            s, out = render(scene, d, f"{scene}.{d}")
            rows[d].append(s)
            images[d] = out
    for d in depths + ["auto"]:
        r = rows[d]
        diff = json.loads(subprocess.run([imgdiff, images[6], images[d]], capture_output=True, text=True,
                                         check=True).stdout)
        results.append({
            "scene": scene, "depth": d, "chosen_depth": r[0]["subpatch_depth"],
            "samples_per_patch": r[0].get("subpatch_depth_auto", {}).get("samples_per_patch"),
            "trace_ms": min(x["trace_ms"] for x in r), "build_ms": min(x["build_ms"] for x in r),
            "subpatch_mb": r[0]["memory"]["subpatch_bytes"] / 2**20,
            "peak_rss_mb": max(x["peak_rss_kb"] for x in r) / 1024,
            "newton_iterations_per_run": r[0]["newton_iterations"]["mean"],
            "primary_hits": r[0]["hits"]["primary"],
            "max_abs_color_vs_6": diff["max_abs_color"], "psnr_db_vs_6": diff["psnr_db"]})
os.makedirs(os.path.join(root, "bench", "results"), exist_ok=True)
json.dump({"res": res, "spp": spp, "runs": runs, "rows": results},
          open(os.path.join(root, "bench", "results", "subpatch_depth.json"), "w"), indent=1)
print("| scene | depth | trace ms | build ms | subpatch MB | peak RSS MB | Newton it. | primary hits | max / PSNR vs 6 |")
print("|---|---|---:|---:|---:|---:|---:|---:|---|")
for x in results:
    d = x["depth"] if x["depth"] != "auto" else f"auto ({x['chosen_depth']}, {x['samples_per_patch']:.0f} samples)"
    psnr = "" if x["psnr_db_vs_6"] is None else f"{x['max_abs_color_vs_6']:.2f} / {x['psnr_db_vs_6']:.0f} dB"
    print(f"| {x['scene']} | {d} | {x['trace_ms']:.0f} | {x['build_ms']:.0f} | {x['subpatch_mb']:.1f} | "
          f"{x['peak_rss_mb']:.0f} | {x['newton_iterations_per_run']:.2f} | {x['primary_hits']} | {psnr} |")
shutil.rmtree(tmp)
