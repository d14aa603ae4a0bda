#!/usr/bin/env python3
"""The README's figure of a gated camera in fog (assets/scenes/fog_road.xml): the steady image
beside two gated ones of 200 ps (60 mm of path), one on the car's round trip and one on the
pedestrian's, each rendered by gatetrace and shown at its own exposure (its 99th percentile
of nonzero values at 0.8, then sRGB).

    tools/scenes/fog_road_figure.py OUT.png [--gatetrace PATH] [--spp-steady N] [--spp-gated N]
        [--from DIR]

Renders steady.npy, car.npy and pedestrian.npy into a scratch directory (or reads them from
--from DIR) and writes one PNG of the three side by side. Needs numpy only (the PNG is written
with zlib).
"""
import argparse
import struct
import subprocess
import sys
import tempfile
import zlib
from pathlib import Path

import numpy as np

SCENE = "assets/scenes/fog_road.xml"
# 200 ps gates (60 mm of path) on the car's back and the pedestrian's front.
GATES = {"steady": "none", "car": "box:45.62..45.68", "pedestrian": "box:69.75..69.81"}


def render(gatetrace, out, gate, spp):
    cmd = [gatetrace, "render", SCENE, "--gate", gate, "--spp", str(spp), "--out", str(out)]
    print(" ".join(cmd), file=sys.stderr)
    subprocess.run(cmd, check=True)


def tone(img):
    """Linear RGB -> 8-bit sRGB at an exposure mapping the 99th percentile of nonzero values to 0.8."""
    values = img[img > 0]
    scale = 0.8 / np.percentile(values, 99) if values.size else 1.0
    x = np.clip(img * scale, 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return (srgb * 255 + 0.5).astype(np.uint8)


def write_png(path, rgb):
    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[y].tobytes() for y in range(h))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b"")
    Path(path).write_bytes(png)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("out", help="the PNG to write")
    p.add_argument("--gatetrace", default="target/release/gatetrace", help="the gatetrace binary")
    p.add_argument("--spp-steady", type=int, default=512, help="samples per pixel of the steady image")
    p.add_argument("--spp-gated", type=int, default=2048, help="samples per pixel of each gated image")
    p.add_argument("--from", dest="source", help="read steady.npy, car.npy, pedestrian.npy from this directory")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(args.source or scratch)
        panels = []
        for name, gate in GATES.items():
            npy = folder / f"{name}.npy"
            if not args.source:
                render(args.gatetrace, npy, gate, args.spp_steady if gate == "none" else args.spp_gated)
            panels.append(tone(np.load(npy)[..., :3]))
    gap = np.full((panels[0].shape[0], 4, 3), 255, np.uint8)
    write_png(args.out, np.concatenate([panels[0], gap, panels[1], gap, panels[2]], axis=1))
    print(f"wrote {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
