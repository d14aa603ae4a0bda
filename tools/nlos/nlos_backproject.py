#!/usr/bin/env python3
"""Filtered back-projection of a confocal NLOS capture: a picture of the hidden scene.

Reads a capture written by `gatetrace render --nlos confocal ... -o CAPTURE.npy` (float32
[grid_y, grid_x, T, 3] with CAPTURE.json beside it: the sensed points, the gate) and back-projects
it onto a volume in front of the relay wall: a voxel v gathers, from every sensed point x, the bin
holding path length 2 |v - x| (spot and sensed point coincide; the first and last segments must
not be counted). A Laplacian along depth then sharpens the volume (the usual filter of filtered
back-projection), and the image is the maximum over depth, drawn with the wall's u (x) to the right and v (y) up:
the hidden side as seen through the wall from the sensor's side.

    tools/nlos/nlos_backproject.py CAPTURE.npy [--depth 0.2,0.9] [--voxels 64] [-o picture.png]

Lengths in metres. Needs numpy only. Writes an 8-bit grey PNG (4 pixels a voxel), or the
picture as float32 .npy (peak 1) when the output's name ends in .npy.
"""
import argparse
import json
import struct
import zlib
from pathlib import Path

import numpy as np


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("capture", type=Path)
    p.add_argument("--depth", default="0.2,0.9", help="distances in front of the wall to reconstruct, A,B (m)")
    p.add_argument("--voxels", type=int, default=64, help="voxels along each side of the wall and along depth")
    p.add_argument("-o", "--out", type=Path, default=None, help="picture (.png or .npy)")
    args = p.parse_args()
    meta = json.loads(args.capture.with_suffix(".json").read_text())
    if meta.get("nlos_scan") != "confocal" or meta.get("count_first_and_last"):
        raise SystemExit(f"{args.capture}: back-projection here needs a confocal capture without the first and "
                         "last segments counted")
    gate = meta.get("gate_parameters")
    if gate is None:
        raise SystemExit(f"{args.capture}: the sidecar has no gate_parameters (written by an older gatetrace): "
                         "render the capture again")
    if gate["kind"] != "transient":
        raise SystemExit(f"{args.capture}: gate {meta['gate']} is not transient:START,WIDTH,BINS")
    # Metres of optical path, whatever units the gate was typed in.
    start, width, bins = gate["start_m"], gate["bin_width_m"], gate["bins"]
    h = np.load(args.capture).astype(np.float64).sum(axis=-1)  # [gy, gx, T], summed over RGB
    points = np.array(meta["sensor_grid_xyz"], dtype=np.float64)  # [gy, gx, 3]
    normals = np.array(meta["sensor_grid_normals"], dtype=np.float64)
    normal = normals.reshape(-1, 3).mean(0)
    normal /= np.linalg.norm(normal)
    # The wall's in-plane axes from the grid itself.
    u_axis = points[0, -1] - points[0, 0]
    v_axis = points[-1, 0] - points[0, 0]
    centre = points.reshape(-1, 3).mean(0)
    n = args.voxels
    a, b = (float(v) for v in args.depth.split(","))
    su = np.linspace(-0.5, 0.5, n)
    depths = np.linspace(a, b, n)
    uu, vv, dd = np.meshgrid(su, su, depths, indexing="ij")
    voxels = centre + uu[..., None] * u_axis * 1.1 + vv[..., None] * v_axis * 1.1 + dd[..., None] * normal
    volume = np.zeros(voxels.shape[:3])
    flat_points = points.reshape(-1, 3)
    flat_h = h.reshape(len(flat_points), -1)
    for k, x in enumerate(flat_points):
        length = 2.0 * np.linalg.norm(voxels - x, axis=-1)
        b_index = np.floor((length - start) / width).astype(np.int64)
        ok = (b_index >= 0) & (b_index < int(bins))
        volume[ok] += flat_h[k, b_index[ok]]
    # Laplacian along depth (second difference), keep positive responses.
    filtered = np.zeros_like(volume)
    filtered[:, :, 1:-1] = -(volume[:, :, 2:] - 2 * volume[:, :, 1:-1] + volume[:, :, :-2])
    picture = np.clip(filtered, 0, None).max(axis=2).T[::-1]  # rows: v up the page
    picture /= max(picture.max(), 1e-30)
    out = args.out or args.capture.with_name(args.capture.stem + "_backprojection.png")
    if out.suffix.lower() == ".npy":
        np.save(out, picture.astype(np.float32))
    elif out.suffix.lower() == ".png":
        grey = np.round(picture * 255).astype(np.uint8).repeat(4, axis=0).repeat(4, axis=1)
        write_grey_png(out, grey)
    else:
        raise SystemExit(f"{out}: name a .png or .npy output")
    print(f"{out}: max over depth {a}..{b} m of the filtered back-projection ({n}^3 voxels)")


def write_grey_png(path, grey):
    """An 8-bit greyscale PNG of the array `grey` [rows, columns] (PNG 1.2: IHDR, one IDAT of
    unfiltered scanlines, IEND)."""
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    height, width = grey.shape
    rows = b"".join(b"\x00" + bytes(row) for row in np.ascontiguousarray(grey, dtype=np.uint8))
    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    Path(path).write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(rows, 9))
                           + chunk(b"IEND", b""))


if __name__ == "__main__":
    main()
