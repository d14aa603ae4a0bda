#!/usr/bin/env python3
"""Write the smoke puff of assets/scenes/smoke_box/scene.xml: a grid of 12 x 12 x 12 extinction
values in Mitsuba's volume format (.vol, one channel), a lumpy ball that fades to zero at the
grid's faces (so that the box's faces, wherever they lie, hold no extinction), and its albedo on
the same voxels (albedo.vol beside it, three channels): warm (0.95, 0.75, 0.45) at the bottom
to cool (0.55, 0.75, 0.95) at the top, with a little variation across.

    tools/scenes/make_smoke_volume.py [--out assets/scenes/smoke_box/smoke.vol] [--res 12]

Extinction values are in [0, 1]; the scene's medium scales them (`scale`, m^-1). Standard
library only.
"""
import argparse
import math
import struct
from pathlib import Path


def smoke(res):
    """Values x fastest, then y, then z."""
    values = []
    for z in range(res):
        for y in range(res):
            for x in range(res):
                if min(x, y, z) == 0 or max(x, y, z) == res - 1:
                    values.append(0.0)
                    continue
                # Voxel centre in [-1, 1]^3.
                p = [2.0 * (i + 0.5) / res - 1.0 for i in (x, y, z)]
                r2 = sum(c * c for c in p)
                ball = max(0.0, 1.0 - r2 / 0.8)
                lumps = 0.65 + 0.35 * math.sin(5.0 * p[0] + 1.0) * math.cos(4.0 * p[1] - 0.5) * math.sin(3.0 * p[2] + 2.0)
                values.append(ball * lumps)
    top = max(values)
    return [v / top for v in values]


def albedo(res):
    """RGB triples, x fastest, then y, then z."""
    values = []
    for z in range(res):
        for y in range(res):
            for x in range(res):
                h = (y + 0.5) / res
                wobble = 0.05 * math.sin(4.0 * (x + 0.5) / res + 3.0 * (z + 0.5) / res)
                warm, cool = (0.95, 0.75, 0.45), (0.55, 0.75, 0.95)
                values.extend(min(1.0, max(0.0, w + (c - w) * h + wobble)) for w, c in zip(warm, cool))
    return values


def write_vol(path, res, values, channels=1):
    header = b"VOL" + bytes([3]) + struct.pack("<5i", 1, res, res, res, channels) + struct.pack("<6f", 0, 0, 0, 1, 1, 1)
    path.write_bytes(header + struct.pack(f"<{len(values)}f", *values))


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default=str(Path(__file__).resolve().parents[2] / "assets/scenes/smoke_box/smoke.vol"))
    p.add_argument("--res", type=int, default=12, help="voxels along each axis")
    args = p.parse_args()
    out = Path(args.out)
    write_vol(out, args.res, smoke(args.res))
    write_vol(out.with_name("albedo.vol"), args.res, albedo(args.res), channels=3)
    print(f"wrote {out} and {out.with_name('albedo.vol')}: {args.res}^3 voxels")


if __name__ == "__main__":
    main()
