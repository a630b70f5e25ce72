#!/usr/bin/env python3
"""Markdown tables from a bench/blur_tables.sh result (bench/results/blur_*.json, one object per line):
python3 bench/blur_summary.py bench/results/blur_<stamp>.json"""
import json
import sys


def load(path):
    rows = []
    for line in open(path):
        line = line.strip()
        if line.startswith("{"):
            rows.append(json.loads(line))
    return rows


def name(r):
    if r["config"] == "interleaved":
        return f"IL {r['tile']}x{r['tile']} P={r['permutations']}"
    return r["config"]


def table(rows, part, title):
    t = [r for r in rows if r["part"] == part + "_time"]
    q = {(name(r), r["spp"]): r for r in rows if r["part"] == part + "_rmse" and "rmse" in r}
    sharp = {r["spp"]: r["engine_ms"] for r in t if r["config"] == "sharp"}
    if not t:
        return
    print(f"\n### {title}\n")
    print("| scheme | spp | engine ms | / sharp same spp | / simple same spp | sample tests | RMSE (QRES) | tile peak |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    simple = {r["spp"]: r["engine_ms"] for r in t if r["config"] == "simple"}
    for r in t:
        n = name(r)
        qq = q.get((n, r["spp"]), {})
        rm = f"{qq['rmse']:.5f}" if "rmse" in qq else ""
        tp = f"{qq['tile_peak']:.2f}" if "tile_peak" in qq else ""
        s = sharp.get(r["spp"])
        si = simple.get(r["spp"])
        print(f"| {n} | {r['spp']} | {r['engine_ms']:.0f} | {r['engine_ms'] / s:.1f} | "
              f"{(r['engine_ms'] / si) if si else float('nan'):.2f} | {r.get('sample_tests', '')} | {rm} | {tp} |"
              if s else f"| {n} | {r['spp']} | {r['engine_ms']:.0f} | | | {r.get('sample_tests', '')} | {rm} | {tp} |")


def teapot(rows):
    parts = sorted({r["part"] for r in rows if r["part"].startswith("teapot_")})
    if not parts:
        return
    print("\n### Teapot frames (800x600)\n")
    print("| frame | engine | scheme | spp | engine ms | / sharp | RMSE vs 256-spp bbox | sharp RMSE vs 256-spp sharp |")
    print("|---|---|---|---:|---:|---:|---:|---:|")
    for p in parts:
        rs = [r for r in rows if r["part"] == p]
        sharp = {r["spp"]: r for r in rs if r["config"] == "sharp"}
        for r in rs:
            if r["config"] in ("reference", "sharp_reference", "sharp"):
                continue
            s = sharp.get(r["spp"])
            ratio = f"{r['engine_ms'] / s['engine_ms']:.2f}" if s else ""
            rm = f"{r['rmse']:.5f}" if "rmse" in r else ""
            srm = f"{s['rmse']:.5f}" if s and "rmse" in s else ""
            print(f"| {p.replace('teapot_', '').replace('_rt', '')} | {r['engine']} | {name(r)} | {r['spp']} | "
                  f"{r['engine_ms']:.0f} | {ratio} | {rm} | {srm} |")
        for spp, s in sorted(sharp.items()):
            print(f"| {p.replace('teapot_', '').replace('_rt', '')} | {s['engine']} | sharp (--no-blur) | {spp} | "
                  f"{s['engine_ms']:.0f} | 1 | | {s['rmse']:.5f} |" if "rmse" in s else
                  f"| {p.replace('teapot_', '').replace('_rt', '')} | {s['engine']} | sharp (--no-blur) | {spp} | "
                  f"{s['engine_ms']:.0f} | 1 | | |")


rows = load(sys.argv[1])
table(rows, "table1", "Table 1: Killeroo spinning 30 degrees, seen from above (motion blur)")
table(rows, "table2", "Table 2: the still Killeroo through a lens focused on its head (depth of field)")
teapot(rows)
