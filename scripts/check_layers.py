#!/usr/bin/env python3
"""Fails when a source file includes a header of a higher layer (docs/architecture.md, src/CMakeLists.txt).

Usage: check_layers.py SRC_DIR [APP_DIR]. Prints every violation as file:line and exits 1 if any."""
import re
import sys
from pathlib import Path

# Each layer and the layers it may include (besides itself).
ALLOWED = {
    "core": set(),
    "scene": {"core"},
    "shading": {"core", "scene"},
    "film": {"core", "scene"},
    "io": {"core", "scene", "shading", "film"},
    "engine": {"core", "scene", "shading", "film"},
    "reyes": {"core", "scene", "shading", "film", "engine"},
    "rt": {"core", "scene", "shading", "film", "engine"},
    "render": {"core", "scene", "shading", "film", "engine", "reyes", "rt"},
}
INCLUDE = re.compile(r'^\s*#\s*include\s+"([a-z_]+)/[^"]+"')


def main() -> int:
    src = Path(sys.argv[1] if len(sys.argv) > 1 else "src")
    violations = []
    layers = {d.name for d in src.iterdir() if d.is_dir()}
    unknown = layers - set(ALLOWED)
    for name in sorted(unknown):
        violations.append(f"{src / name}: error: folder is not a known layer (add it to scripts/check_layers.py)")
    for layer in sorted(layers & set(ALLOWED)):
        for f in sorted((src / layer).rglob("*")):
            if f.suffix not in (".h", ".cpp"):
                continue
            for n, line in enumerate(f.read_text().splitlines(), 1):
                m = INCLUDE.match(line)
                if not m:
                    continue
                target = m.group(1)
                if target != layer and target in ALLOWED and target not in ALLOWED[layer]:
                    violations.append(f"{f}:{n}: error: layer '{layer}' includes '{target}' (a higher layer)")
    for v in violations:
        print(v)
    print(f"check_layers: {len(violations)} violation(s) in {src}")
    return 1 if violations else 0


if __name__ == "__main__":
    sys.exit(main())
