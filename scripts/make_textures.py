#!/usr/bin/env python3
"""Writes the procedural textures of the shipped scenes (scenes/textures/, see scenes/README.md).

Usage: python3 scripts/make_textures.py   (from the repository root; pure Python, no dependencies)
  tiles.png  256x256 RGB: soft coloured tiles (8 x 8) with sine bands, for paintedplastic
  bumps.png  256x256 grey: a height field of round bumps in [0, 1], for the bumpy displacement
"""
import math
import os
import struct
import zlib


def write_png(path, width, height, channels, pixel):
    """pixel(x, y) -> tuple of `channels` floats in [0, 1]; 8-bit PNG, row 0 at the top."""
    rows = bytearray()
    for y in range(height):
        rows.append(0)  # filter: none
        for x in range(width):
            for c in pixel(x, y):
                rows.append(max(0, min(255, int(round(c * 255)))))
    color_type = {1: 0, 3: 2}[channels]

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, color_type, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(bytes(rows), 9)) + chunk(b"IEND", b"")
    with open(path, "wb") as f:
        f.write(png)


def tiles(x, y, n=256):
    s, t = (x + 0.5) / n, (y + 0.5) / n
    # Soft-edged 8 x 8 tiles (smoothstep across the borders) in two colours, modulated by sine bands.
    def soft(u):
        f = u * 8 - math.floor(u * 8)
        d = min(f, 1 - f) * 8  # distance to the nearest border, in 1/64 of the texture
        return min(1.0, d / 0.6)
    parity = (int(s * 8) + int(t * 8)) & 1
    edge = soft(s) * soft(t)
    a = (0.85, 0.55, 0.2) if parity else (0.25, 0.45, 0.8)
    band = 0.85 + 0.15 * math.sin(2 * math.pi * 3 * (s + t))
    return tuple(band * (0.15 + (c - 0.15) * edge) for c in a)


def bumps(x, y, n=256):
    s, t = (x + 0.5) / n, (y + 0.5) / n
    # 6 x 6 round bumps (raised cosine), periodic in s and t.
    fs, ft = s * 6 - math.floor(s * 6) - 0.5, t * 6 - math.floor(t * 6) - 0.5
    r = math.sqrt(fs * fs + ft * ft) / 0.45
    return (0.5 + 0.5 * math.cos(math.pi * r) if r < 1 else 0.0,)


if __name__ == "__main__":
    out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scenes", "textures")
    os.makedirs(out, exist_ok=True)
    write_png(os.path.join(out, "tiles.png"), 256, 256, 3, tiles)
    write_png(os.path.join(out, "bumps.png"), 256, 256, 1, bumps)
