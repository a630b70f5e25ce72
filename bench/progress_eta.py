#!/usr/bin/env python3
"""How steady the progress estimate is: runs a tessera command with --progress and prints, at 10/25/50/75/90%,
the total time a linear extrapolation of the elapsed time projects, against the actual total.
Usage: bench/progress_eta.py build/tessera render SCENE --progress [options]"""
import subprocess
import sys
import time
cmd = sys.argv[1:]
t0 = time.time()
p = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True)
rows = []
for line in p.stderr:
    if line.startswith("progress "):
        pct = int(line.split()[1].rstrip('%'))
        t = time.time() - t0
        rows.append((pct, t))
p.wait()
total = time.time() - t0
ests = [(pct, t, t * 100 / pct) for pct, t in rows if 0 < pct < 100]
for q in (10, 25, 50, 75, 90):
    c = min(ests, key=lambda e: abs(e[0] - q))
    print(f"at {c[0]:3d}% ({c[1]:.2f}s): projected total {c[2]:.2f}s")
print(f"actual total {total:.2f}s")
