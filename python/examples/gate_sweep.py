"""A gate sweep of the Cornell box from Python: one Renderer, eight box gates 10 cm wide (its
kernels built once), and the transient of one pixel on the red wall, plotted with matplotlib.

    python python/examples/gate_sweep.py [--out sweep.png] [--spp 256] [--res 128]

Needs the package (pip install .) and matplotlib.
"""

import argparse
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import gatetrace

ROOT = Path(__file__).resolve().parents[2]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default=str(ROOT / "assets/scenes/cornell_box.gltf"))
    parser.add_argument("--out", default="gate_sweep.png", help="the figure (PNG)")
    parser.add_argument("--spp", type=int, default=256, help="samples per pixel of each gated image")
    parser.add_argument("--res", type=int, default=128, help="image width and height (pixels)")
    parser.add_argument("--method", default="ellipsoidal", help="path, direct, ellipsoidal or auto")
    args = parser.parse_args()

    scene = gatetrace.Scene.load(args.scene)
    renderer = gatetrace.Renderer(scene, method=args.method, max_bounces=4, res=(args.res, args.res))
    starts = 1.95 + 0.1 * np.arange(8)  # metres of optical path
    frames = []
    begin = time.perf_counter()
    for start in starts:
        image, meta = renderer.render(gatetrace.box(start, start + 0.1), spp=args.spp, seed=1)
        frames.append(image)
    sweep = time.perf_counter() - begin
    print(f"{len(starts)} gates of {args.res}x{args.res} at {args.spp} spp in {sweep:.1f} s on {meta['adapter']}")

    # One pixel's transient: 240 bins of 1 cm (33 ps) of path from 1.9 m.
    transient = gatetrace.Renderer(scene, method="path", max_bounces=4, res=(args.res, args.res))
    bins = 240
    cube, _ = transient.render(gatetrace.transient(1.9, 0.01, bins), spp=4 * args.spp, seed=2)
    y, x = args.res // 2, args.res // 8  # on the left (red) wall
    lengths = 1.9 + 0.01 * (np.arange(bins) + 0.5)

    fig = plt.figure(figsize=(12, 5.2))
    grid = fig.add_gridspec(2, 6)
    scale = np.percentile(np.concatenate([f.ravel() for f in frames]), 99.5)
    for i, (start, frame) in enumerate(zip(starts, frames)):
        ax = fig.add_subplot(grid[i // 4, i % 4])
        ax.imshow(np.clip(frame / scale, 0, 1) ** (1 / 2.2))
        ax.set_title(f"[{start:.2f}, {start + 0.1:.2f}) m", fontsize=9)
        ax.plot([x], [y], "c+", markersize=8)
        ax.axis("off")
    ax = fig.add_subplot(grid[:, 4:])
    for c, colour in enumerate(("tab:red", "tab:green", "tab:blue")):
        ax.plot(lengths, cube[y, x, :, c] / 0.01, color=colour)
    ax.set_xlabel("optical path length (m)")
    ax.set_ylabel("radiance per metre of path (W m$^{-2}$ sr$^{-1}$ m$^{-1}$)")
    ax.set_title(f"transient of pixel ({x}, {y})", fontsize=10)
    fig.suptitle(f"gatetrace from Python: {args.method}, {args.spp} spp per gate", fontsize=11)
    fig.tight_layout()
    fig.savefig(args.out, dpi=90)
    print(f"figure written to {args.out}")


if __name__ == "__main__":
    main()
