#!/usr/bin/env python3
"""Turns bench/results/{suite.json, quality.json, embree.json} into SUMMARY.md and scaling_*.svg plots.
Standard library only."""
import json
import math
import os
import sys

out = sys.argv[1] if len(sys.argv) > 1 else "bench/results"


def load_jsonl(path):
    if not os.path.exists(path):
        return []
    with open(path) as f:
        return [json.loads(line) for line in f if line.strip()]


records = json.load(open(os.path.join(out, "suite.json")))
by_name = {r["name"]: r for r in records}
quality = load_jsonl(os.path.join(out, "quality.json"))
embree = {e["scene"]: e for e in load_jsonl(os.path.join(out, "embree.json"))}


def fmt_ms(v):
    return f"{v:.0f}" if v >= 100 else f"{v:.1f}"


def throughput(r):
    if r.get("engine") == "reyes" and r.get("micropolygons_per_s"):
        return f"{r['micropolygons_per_s'] / 1e6:.2f} M µpoly/s"
    rays = r.get("rays")
    if isinstance(rays, dict) and r.get("render_ms_median"):
        total = sum(v for v in rays.values() if isinstance(v, (int, float)))
        return f"{total / (r['render_ms_median'] * 1e3):.2f} M rays/s"
    return ""


def setup_ms(r):
    if "build_ms" in r:
        return fmt_ms(r["build_ms"])
    st = r.get("stage_ms", {})
    if "bin" in st or "split" in st:  # the up-front set-up: weld and bin (split before session 17)
        return fmt_ms(st.get("bin", st.get("split", 0)) + st.get("weld", 0))
    return ""


lines = ["# Benchmark summary", "",
         "Produced by `bash bench/run_suite.sh`; times in ms, median (min) of the runs; peak memory is the "
         "process's peak resident set. Figures from one run on one machine: compare ratios, not absolutes.", ""]
lines += ["## Scenes x engines", "",
          "| scene | patches | engine | render ms | wall ms | setup ms | throughput | peak MB |",
          "|---|---:|---|---:|---:|---:|---:|---:|"]
scene_rows = [r for r in records if r["name"].startswith("scene:")]
for r in scene_rows:
    _, scene, engine = r["name"].split(":")
    lines.append(f"| {scene} | {r.get('patches_in', '')} | {engine} | {fmt_ms(r['render_ms_median'])} "
                 f"({fmt_ms(r['render_ms_min'])}) | {fmt_ms(r['wall_ms_median'])} | {setup_ms(r)} | "
                 f"{throughput(r)} | {r['peak_rss_mb_max']:.0f} |")

if quality:
    lines += ["", "## Image quality", "",
              "PSNR of colour (dB) and the fraction of pixels whose coverage differs by more than 0.5; "
              "`ref` is the Reyes engine at 64 spp. Only the ray tracer casts shadows, so the colour PSNR "
              "between the engines on these lit scenes mostly measures the shadows; coverage is the like-for-like "
              "check (the test `RtCrossEngine` compares colours with a light at the eye, where the engines "
              "must agree: >= 35 dB).", "",
              "| scene | reyes vs rt | coverage mismatch | reyes vs ref | rt vs ref |", "|---|---:|---:|---:|---:|"]
    scenes = []
    for q in quality:
        if q["scene"] not in scenes:
            scenes.append(q["scene"])
    for s in scenes:
        q = {x["pair"]: x for x in quality if x["scene"] == s}
        def p(k):
            v = q.get(k, {}).get("psnr_db")
            return "" if v is None else ("inf" if v == float("inf") or v > 1e6 else f"{v:.1f}")
        mm = q.get("reyes-rt", {}).get("alpha_mismatch_fraction")
        lines.append(f"| {s} | {p('reyes-rt')} | {'' if mm is None else f'{100 * mm:.3f}%'} | {p('reyes-ref')} | "
                     f"{p('rt-ref')} |")

lines += ["", "## Ray tracer vs the Embree triangle baseline", ""]
if not embree:
    lines.append("Embree is not installed on this machine: the baseline was not run "
                 "(`apt-get install libembree-dev`, then `bash scripts/build.sh`).")
else:
    lines += ["Embree traces the same rays (same camera, samples, filter and shading) through triangles tessellated "
              "so that the chord error stays under 0.1 pixel. Ratios are Tessera / Embree.", "",
              "| scene | triangles | Embree build+tess ms | Embree trace ms | Tessera rt render ms | time ratio | "
              "Embree MB (BVH+mesh) | Tessera rt peak MB |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for s, e in embree.items():
        r = by_name.get(f"scene:{s}:rt")
        emb_mb = (e["embree_bytes_peak"] + e["mesh_bytes"]) / 2**20
        rt_ms = r["render_ms_median"] if r else float("nan")
        emb_ms = e["build_ms"] + e["tessellate_ms"] + e["trace_ms_median"]
        lines.append(f"| {s} | {e['triangles']} | {fmt_ms(e['build_ms'] + e['tessellate_ms'])} | "
                     f"{fmt_ms(e['trace_ms_median'])} | {fmt_ms(rt_ms)} | {rt_ms / emb_ms:.2f} | {emb_mb:.1f} | "
                     f"{r['peak_rss_mb_max'] if r else float('nan'):.0f} |")


def series(prefix, key_of):
    out_series = {}
    for r in records:
        if not r["name"].startswith(prefix):
            continue
        parts = r["name"].split(":")
        engine = parts[-1]
        out_series.setdefault(engine, []).append((key_of(r, parts), r["render_ms_median"]))
    for v in out_series.values():
        v.sort()
    return out_series


def svg_plot(path, title, xlabel, data):
    """A log-log line chart, one line per engine."""
    W, H, L, R, T, B = 560, 360, 70, 20, 40, 50
    pts = [p for v in data.values() for p in v if p[0] > 0 and p[1] > 0]
    if not pts:
        return
    lx = [math.log10(p[0]) for p in pts]
    ly = [math.log10(p[1]) for p in pts]
    x0, x1 = math.floor(min(lx)), math.ceil(max(lx))
    y0, y1 = math.floor(min(ly)), math.ceil(max(ly))
    x1 = x1 if x1 > x0 else x0 + 1
    y1 = y1 if y1 > y0 else y0 + 1
    sx = lambda v: L + (math.log10(v) - x0) / (x1 - x0) * (W - L - R)
    sy = lambda v: H - B - (math.log10(v) - y0) / (y1 - y0) * (H - T - B)
    colours = {"reyes": "#c0392b", "rt": "#2471a3"}
    s = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" font-family="sans-serif" font-size="12">',
         f'<rect width="{W}" height="{H}" fill="white"/>',
         f'<text x="{W / 2}" y="20" text-anchor="middle" font-size="14">{title}</text>',
         f'<text x="{W / 2}" y="{H - 12}" text-anchor="middle">{xlabel} (log)</text>',
         f'<text x="16" y="{H / 2}" transform="rotate(-90 16 {H / 2})" text-anchor="middle">render ms (log)</text>']
    for e in range(x0, x1 + 1):
        x = sx(10 ** e)
        s.append(f'<line x1="{x}" y1="{T}" x2="{x}" y2="{H - B}" stroke="#ddd"/><text x="{x}" y="{H - B + 16}" '
                 f'text-anchor="middle">1e{e}</text>')
    for e in range(y0, y1 + 1):
        y = sy(10 ** e)
        s.append(f'<line x1="{L}" y1="{y}" x2="{W - R}" y2="{y}" stroke="#ddd"/><text x="{L - 6}" y="{y + 4}" '
                 f'text-anchor="end">1e{e}</text>')
    for i, (name, v) in enumerate(sorted(data.items())):
        c = colours.get(name, "#555")
        d = " ".join(f"{sx(a):.1f},{sy(b):.1f}" for a, b in v if a > 0 and b > 0)
        s.append(f'<polyline points="{d}" fill="none" stroke="{c}" stroke-width="2"/>')
        for a, b in v:
            s.append(f'<circle cx="{sx(a):.1f}" cy="{sy(b):.1f}" r="3" fill="{c}"/>')
        s.append(f'<text x="{L + 10}" y="{T + 16 + 16 * i}" fill="{c}">{name}</text>')
    s.append("</svg>")
    with open(path, "w") as f:
        f.write("\n".join(s))


svg_plot(os.path.join(out, "scaling_patches.svg"), "Render time vs patch count (800x600, 4 spp)", "patches",
         series("scene:", lambda r, p: r.get("patches_in", 0)))
svg_plot(os.path.join(out, "scaling_resolution.svg"), "Render time vs pixels (teapot, 4 spp)", "pixels",
         series("res:", lambda r, p: int(p[1].split("x")[0]) * int(p[1].split("x")[1])))
svg_plot(os.path.join(out, "scaling_spp.svg"), "Render time vs samples per pixel (teapot, 800x600)", "spp",
         series("spp:", lambda r, p: int(p[1])))

lines += ["", "## Scaling", "", "![patches](scaling_patches.svg) ![resolution](scaling_resolution.svg) "
          "![spp](scaling_spp.svg)", "", "| scene | engine | 1 thread ms | 2 threads ms | speed-up | peak MB (2 thr) |",
          "|---|---|---:|---:|---:|---:|"]
for s in ["teapot", "killeroo"]:
    for e in ["reyes", "rt"]:
        a, b = by_name.get(f"threads:{s}:{e}:1"), by_name.get(f"threads:{s}:{e}:2")
        if a and b:
            lines.append(f"| {s} | {e} | {fmt_ms(a['render_ms_median'])} | {fmt_ms(b['render_ms_median'])} | "
                         f"{a['render_ms_median'] / b['render_ms_median']:.2f}x | {b['peak_rss_mb_max']:.0f} |")
for prefix, label in [("res:", "resolution"), ("spp:", "spp")]:
    lines += ["", f"| {label} | engine | render ms | peak MB |", "|---|---|---:|---:|"]
    for r in records:
        if r["name"].startswith(prefix):
            _, v, e = r["name"].split(":")
            lines.append(f"| {v} | {e} | {fmt_ms(r['render_ms_median'])} | {r['peak_rss_mb_max']:.0f} |")

with open(os.path.join(out, "SUMMARY.md"), "w") as f:
    f.write("\n".join(lines) + "\n")
print("\n".join(lines))
