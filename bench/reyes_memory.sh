#!/usr/bin/env bash
# Reyes memory against the patch count (issue 18): the Big Guy grid of scenes/bigguy24.rib at 1, 4 and 16
# times its patches (6x4, 12x8, 24x16 Big Guys: 85,680, 342,720 and 1,370,880 patches; the camera backs
# off with the grid, so each frame covers about the same pixels), rendered by Reyes at its 1024x768, 16 spp,
# 2 threads, with and without the key light's shadow map. Per binary and run: the process's peak RSS
# (/usr/bin/time), the scene's own share (the peak of `tessera info`, which loads the scene and renders
# nothing), the pieces the frame makes and the most alive at once (stats `pieces`, `pieces_peak`), and
# engine_ms. Minimum time and largest RSS of R runs, binaries alternating.
# Usage: R=2 bench/reyes_memory.sh [tessera binary ...]   (default build/tessera)
# Prints a markdown table; JSON lines in build/bench/reyes_memory.json.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
R="${R:-2}"
BINS=("$@")
[ ${#BINS[@]} -gt 0 ] || BINS=("$ROOT/build/tessera")
SCENES="$ROOT/build/bench/reyes_memory_scenes"
mkdir -p "$SCENES"
ln -sfn "$ROOT/scenes/archives" "$SCENES/archives"
(cd "$ROOT" && python3 - "$SCENES" <<'PY'
import sys
sys.path.insert(0, "scripts")
import make_scenes
make_scenes.OUT_DIR = sys.argv[1]
for name, cols, rows in (("bigguy24", 6, 4), ("bigguy96", 12, 8), ("bigguy384", 24, 16)):
    make_scenes.bigguy_grid(name, cols, rows)
PY
)
TMP="$(mktemp -d /tmp/reyes_memory.XXXXXX)"
trap 'rm -rf "$TMP"' EXIT
OUT="$ROOT/build/bench/reyes_memory.json"
: > "$OUT"
echo "| binary | scene | patches | shadows | peak RSS MB | scene-only MB | pieces | pieces alive at most | engine ms |"
echo "|---|---|---:|---|---:|---:|---:|---:|---:|"
for sc in bigguy24 bigguy96 bigguy384; do
    for shadows in off on; do
        : > "$TMP/rows"
        for _ in $(seq "$R"); do
            for bi in "${!BINS[@]}"; do
                bin="${BINS[$bi]}"
                m=$( { /usr/bin/time -f "%M" "$bin" render "$SCENES/$sc.rib" --threads 2 --shadows "$shadows" \
                    --stats "$TMP/s.json" -o "$TMP/o.exr" -q; } 2>&1 | tail -1)
                i=$( { /usr/bin/time -f "%M" "$bin" info "$SCENES/$sc.rib" > /dev/null; } 2>&1 | tail -1)
                python3 -c "import json;s=json.load(open('$TMP/s.json'));print($bi,s['patches_in'],s['pieces'],s.get('pieces_peak',s['pieces']),s['engine_ms'],$m,$i)" >> "$TMP/rows"
            done
        done
        python3 - "$sc" "$shadows" "$TMP/rows" "$OUT" "${BINS[@]}" <<'PY'
import json, sys
sc, shadows, rows, out, bins = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4], sys.argv[5:]
data = [l.split() for l in open(rows)]
for bi, b in enumerate(bins):
    rs = [list(map(float, r[1:])) for r in data if int(r[0]) == bi]
    rec = {"binary": b, "scene": sc, "shadows": shadows, "patches": int(rs[0][0]), "pieces": int(rs[0][1]),
           "pieces_peak": int(max(r[2] for r in rs)), "engine_ms": min(r[3] for r in rs),
           "peak_rss_mb": max(r[4] for r in rs) / 1024, "scene_rss_mb": max(r[5] for r in rs) / 1024}
    open(out, "a").write(json.dumps(rec) + "\n")
    print(f"| {b} | {sc} | {rec['patches']} | {shadows} | {rec['peak_rss_mb']:.0f} | {rec['scene_rss_mb']:.0f} | "
          f"{rec['pieces']} | {rec['pieces_peak']} | {rec['engine_ms']:.0f} |")
PY
    done
done
