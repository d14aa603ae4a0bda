#!/usr/bin/env python3
"""Converts a gatetrace NLOS capture (`render --nlos`: CAPTURE.npy and its CAPTURE.json sidecar)
to the HDF5 layout of the TAL toolkit (y-tal, `tal.io.read_capture`), which NLOS reconstruction
code reads.

    tools/nlos/nlos_to_hdf5.py CAPTURE.npy [-o CAPTURE.hdf5] [--channels sum|mean|r|g|b]

What is written (TAL's names and conventions):
- H: the transient, float32, (T, Sx, Sy) for single and confocal scans (H_format T_Sx_Sy), or
  (T, Lx, Ly, Sx, Sy) for exhaustive ones (T_Lx_Ly_Sx_Sy); x is the grid column (texture
  coordinate u), y the row (v). The colour channels are summed as TAL's own renders do
  (--channels picks another reduction). Each value is gatetrace's: bin-integrated radiance
  leaving the sensed point towards the sensor origin.
- sensor_xyz, laser_xyz: the sensor and laser origins (m).
- sensor_grid_xyz / sensor_grid_normals, laser_grid_xyz / laser_grid_normals: (X, Y, 3) grids
  (grid format X_Y_3) of the sensed points and laser spots (m) and their unit normals; a single
  scan's laser grid is 1x1.
- delta_t, t_start: bin width and start of the first bin, metres of optical path.
- t_accounts_first_and_last_bounces: whether lengths include the laser-origin -> spot and
  sensed-point -> sensor-origin segments (gatetrace's --count-first-last).
- scene_info: a YAML string with the render's metadata (original_format: gatetrace).
Enumerations (H_format, sensor_grid_format, laser_grid_format) are HDF5 enum datasets as TAL
writes them.

Requires numpy and h5py (pip install h5py).
"""

import argparse
import json
import os
import sys

import numpy as np

# TAL's enumerations (tal/enums.py).
H_FORMAT = {"UNKNOWN": 0, "T_Sx_Sy": 1, "T_Lx_Ly_Sx_Sy": 2, "T_Si": 3, "T_Li_Si": 4,
            "F_Sx_Sy": 10, "F_Lx_Ly_Sx_Sy": 11, "F_Si": 12, "F_Li_Si": 13}
GRID_FORMAT = {"UNKNOWN": 0, "N_3": 1, "X_Y_3": 2}


def transient_gate(parameters):
    """(start, width, bins) of a transient gate's `gate_parameters` (m, m, count), whatever units
    it was typed in; None for another kind."""
    if parameters.get("kind") != "transient":
        return None
    return float(parameters["start_m"]), float(parameters["bin_width_m"]), int(parameters["bins"])


def grid_xy3(rows):
    """A sidecar grid, [row][column][3], as TAL's (X, Y, 3)."""
    return np.transpose(np.asarray(rows, dtype=np.float32), (1, 0, 2))


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("capture", help="CAPTURE.npy written by gatetrace render --nlos (its .json beside it)")
    p.add_argument("-o", "--output", help="HDF5 file to write (default: CAPTURE.hdf5)")
    p.add_argument("--channels", choices=["sum", "mean", "r", "g", "b"], default="sum",
                   help="how the RGB channels become TAL's one (default sum, as TAL's renders)")
    args = p.parse_args()
    try:
        import h5py
        import yaml
    except ImportError as e:
        sys.exit(f"{e}: install with pip install h5py pyyaml")
    sidecar = os.path.splitext(args.capture)[0] + ".json"
    try:
        data = np.load(args.capture)
    except (OSError, ValueError) as e:
        sys.exit(f"{args.capture}: cannot read the capture: {e}")
    try:
        with open(sidecar) as f:
            meta = json.load(f)
    except (OSError, ValueError) as e:
        sys.exit(f"{sidecar}: cannot read the capture's sidecar: {e}")
    scan = meta.get("nlos_scan")
    if scan not in ("single", "confocal", "exhaustive"):
        sys.exit(f"{sidecar}: not an NLOS capture (no nlos_scan): render it with gatetrace render --nlos")
    if "gate_parameters" not in meta:
        sys.exit(f"{sidecar}: no gate_parameters (written by an older gatetrace): render the capture again")
    gate = transient_gate(meta["gate_parameters"])
    if gate is None:
        sys.exit(f"{sidecar}: gate {meta['gate']} is not a transient gate: TAL's H needs time bins")
    start, width, bins = gate

    expected = 6 if scan == "exhaustive" else 4
    if data.ndim == expected - 1 and bins == 1:
        data = data[..., None, :]  # a one-bin transient is written without its time axis
    if data.ndim != expected or data.shape[-1] != 3 or data.shape[-2] != bins:
        sys.exit(f"{args.capture}: shape {data.shape} is not that of a {scan} capture with {bins} bins")
    reduce = {"sum": lambda a: a.sum(-1), "mean": lambda a: a.mean(-1),
              "r": lambda a: a[..., 0], "g": lambda a: a[..., 1], "b": lambda a: a[..., 2]}[args.channels]
    values = reduce(data.astype(np.float32))
    if scan == "exhaustive":
        # [ly, lx, gy, gx, T] -> (T, Lx, Ly, Sx, Sy)
        H = np.transpose(values, (4, 1, 0, 3, 2))
        h_format = "T_Lx_Ly_Sx_Sy"
    else:
        # [gy, gx, T] -> (T, Sx, Sy)
        H = np.transpose(values, (2, 1, 0))
        h_format = "T_Sx_Sy"

    out = args.output or os.path.splitext(args.capture)[0] + ".hdf5"
    info = {k: v for k, v in meta.items() if not k.endswith(("_grid_xyz", "_grid_normals"))}
    info["original_format"] = "gatetrace"
    info["channels"] = args.channels
    with h5py.File(out, "w") as f:
        f["H"] = np.ascontiguousarray(H, dtype=np.float32)

        def enum(key, table, name):
            dt = h5py.enum_dtype(table, basetype="i")
            ds = f.create_dataset(key, (1,), dtype=dt)
            ds[0] = table[name]

        enum("H_format", H_FORMAT, h_format)
        f["sensor_xyz"] = np.asarray(meta["sensor_origin"], dtype=np.float32)
        f["laser_xyz"] = np.asarray(meta["laser_origin"], dtype=np.float32)
        f["sensor_grid_xyz"] = grid_xy3(meta["sensor_grid_xyz"])
        f["sensor_grid_normals"] = grid_xy3(meta["sensor_grid_normals"])
        enum("sensor_grid_format", GRID_FORMAT, "X_Y_3")
        f["laser_grid_xyz"] = grid_xy3(meta["laser_grid_xyz"])
        f["laser_grid_normals"] = grid_xy3(meta["laser_grid_normals"])
        enum("laser_grid_format", GRID_FORMAT, "X_Y_3")
        f["delta_t"] = np.float32(width)
        f["t_start"] = np.float32(start)
        f["t_accounts_first_and_last_bounces"] = bool(meta.get("count_first_and_last", False))
        f["scene_info"] = yaml.safe_dump(info)
    print(f"{out}: H {h_format} {H.shape}, delta_t {width} m, t_start {start} m, "
          f"first and last bounces {'counted' if meta.get('count_first_and_last') else 'not counted'}")


if __name__ == "__main__":
    main()
