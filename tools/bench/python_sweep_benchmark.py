#!/usr/bin/env python3
"""Wall time of a gate sweep: N renders through one gatetrace.Renderer (device, scene upload and
kernels kept) against N invocations of `gatetrace render` with the same settings, side by side
in one run, and whether the images agree (bit for bit for `path`).

    tools/bench/python_sweep_benchmark.py [--gates 10] [--spp 64] [--res 64] [--method path]

Needs the Python package installed (pip install .) and the command line built
(cargo build --release, or --binary PATH).
"""

import argparse
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

import gatetrace

ROOT = Path(__file__).resolve().parents[2]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default=str(ROOT / "assets/scenes/cornell_box.gltf"))
    parser.add_argument("--gates", type=int, default=10, help="box gates of 5 cm, 5 cm apart from 3.0 m")
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--res", type=int, default=64, help="width and height (pixels)")
    parser.add_argument("--method", default="path")
    parser.add_argument("--max-bounces", type=int, default=8)
    parser.add_argument("--binary", default=str(ROOT / "target/release/gatetrace"))
    args = parser.parse_args()
    gates = [gatetrace.box(3.0 + 0.05 * i, 3.05 + 0.05 * i) for i in range(args.gates)]

    begin = time.perf_counter()
    renderer = gatetrace.Renderer(args.scene, method=args.method, max_bounces=args.max_bounces,
                                  res=(args.res, args.res))
    python_images = [renderer.render(g, spp=args.spp, seed=1)[0] for g in gates]
    python_seconds = time.perf_counter() - begin

    cli_images = []
    with tempfile.TemporaryDirectory() as tmp:
        begin = time.perf_counter()
        for i, g in enumerate(gates):
            out = Path(tmp) / f"g{i}.npy"
            subprocess.run([args.binary, "render", args.scene, "--method", args.method, "--gate", str(g),
                            "--spp", str(args.spp), "--res", f"{args.res}x{args.res}", "--max-bounces",
                            str(args.max_bounces), "--seed", "1", "--out", str(out)],
                           check=True, capture_output=True)
            cli_images.append(np.load(out))
        cli_seconds = time.perf_counter() - begin

    equal = sum(np.array_equal(a, b) for a, b in zip(python_images, cli_images))
    print(f"device: {gatetrace.device_name()}")
    print(f"{args.gates} gates, {args.method}, {args.res}x{args.res}, {args.spp} spp, {args.max_bounces} bounces")
    print(f"one Renderer:            {python_seconds:7.2f} s (scene load and kernel builds included)")
    print(f"{args.gates} command-line renders: {cli_seconds:7.2f} s")
    print(f"ratio: {cli_seconds / python_seconds:.2f}x; images equal bit for bit: {equal} of {args.gates}")


if __name__ == "__main__":
    main()
