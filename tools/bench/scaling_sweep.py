#!/usr/bin/env python3
"""How ellipsoidal connections scale with the scene's triangle count (the paper's Fig. 4b): the
Cornell box, then the Cornell box holding a displaced geodesic sphere of 5,120 to 1,310,720
triangles (tools/scenes/make_sphere_scene.py), each rendered with every method for the same wall time
at narrow box gates; the mean squared error against a long reference render, and the work of
one ellipsoid query (loop iterations over BVH nodes and triangles, triangles tested).

    tools/bench/scaling_sweep.py                       # about 40 minutes on 2 CPU cores (lavapipe)
    tools/bench/scaling_sweep.py --frequencies 16,32 --seconds 4 --reference-seconds 20

Writes OUT/scaling.csv (one row per render, from `gatetrace equal-time --csv`), OUT/scaling.png
(MSE ratio of each method over `direct` against triangles, per gate; query work against
triangles) and prints the table. Builds gatetrace in release mode when needed. The plot needs
matplotlib (pip install matplotlib); the renders do not.
"""
import argparse
import csv
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frequencies", default="16,32,64,128,256",
                        help="sphere frequencies f (20 f^2 triangles each); the Cornell box is always first")
    parser.add_argument("--gates", default="box:3.16..3.1625;box:3.16..3.168",
                        help="gates, separated by ';' (default: 2.5 mm and 8 mm box gates)")
    parser.add_argument("--methods", default="direct,ellipsoidal,ellipsoidal:exhaustive",
                        help="methods as `gatetrace equal-time --methods` takes them; the first is the baseline")
    parser.add_argument("--seconds", type=float, default=10.0, help="rendering time per method, gate and repeat")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--reference-method", default="ellipsoidal")
    parser.add_argument("--reference-seconds", type=float, default=60.0)
    parser.add_argument("--res", default="64x64")
    parser.add_argument("--max-bounces", type=int, default=5)
    parser.add_argument("--out", type=Path, default=ROOT / "target/scaling", help="output folder (meshes, CSV, plot)")
    parser.add_argument("--plot-only", action="store_true", help="plot an existing OUT/scaling.csv")
    args = parser.parse_args()

    args.out.mkdir(parents=True, exist_ok=True)
    table = args.out / "scaling.csv"
    if not args.plot_only:
        scenes = [ROOT / "assets/scenes/cornell_box.gltf"]
        for f in (int(x) for x in args.frequencies.split(",") if x.strip()):
            path = args.out / f"sphere_{20 * f * f}.glb"
            if not path.exists():
                subprocess.run([sys.executable, str(ROOT / "tools/scenes/make_sphere_scene.py"), "--frequency", str(f),
                                "--out", str(path)], check=True)
            scenes.append(path)
        subprocess.run(["cargo", "build", "--release", "--quiet"], cwd=ROOT, check=True)
        command = [str(ROOT / "target/release/gatetrace"), "equal-time", *map(str, scenes),
                   "--methods", args.methods, "--gates", args.gates, "--seconds", str(args.seconds),
                   "--repeats", str(args.repeats), "--reference-method", args.reference_method,
                   "--reference-seconds", str(args.reference_seconds), "--res", args.res,
                   "--max-bounces", str(args.max_bounces), "--csv", str(table)]
        print(" ".join(command), flush=True)
        subprocess.run(command, check=True)
    report(table, args.out / "scaling.png", args.methods.split(",")[0].strip())


def report(table, png, baseline):
    """Prints the MSE ratios and query work per scene and gate and plots them."""
    mse = defaultdict(list)  # (triangles, gate, method) -> relative MSEs
    work = {}  # (triangles, method) -> (iterations, tested)
    with open(table, newline="") as f:
        for row in csv.DictReader(f):
            n = int(row["triangles"])
            mse[(n, row["gate"], row["method"])].append(float(row["relative_mse"]))
            if row["iterations_per_query"]:
                work[(n, row["method"])] = (float(row["iterations_per_query"]), float(row["triangles_tested_per_query"]))
    mean = {k: sum(v) / len(v) for k, v in mse.items()}
    sizes = sorted({k[0] for k in mean})
    gates = sorted({k[1] for k in mean})
    methods = sorted({k[2] for k in mean} - {baseline})
    print(f"\nMSE of {baseline} / MSE of each method at equal time (higher: the method wins by more)")
    print(f"{'triangles':>10} {'gate':>18} " + " ".join(f"{m:>24}" for m in methods))
    for n in sizes:
        for g in gates:
            base = mean.get((n, g, baseline))
            cells = [f"{base / mean[(n, g, m)]:>24.2f}" if base and mean.get((n, g, m)) else f"{'-':>24}" for m in methods]
            print(f"{n:>10} {g:>18} " + " ".join(cells))
    print("\nwork of one ellipsoid query: loop iterations / triangles tested")
    print(f"{'triangles':>10} " + " ".join(f"{m:>24}" for m in methods))
    for n in sizes:
        cells = [f"{work[(n, m)][0]:>12.1f} / {work[(n, m)][1]:>9.1f}" if (n, m) in work else f"{'-':>24}" for m in methods]
        print(f"{n:>10} " + " ".join(cells))

    try:
        import matplotlib
    except ImportError:
        print("matplotlib is not installed (pip install matplotlib): no plot")
        return
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    for g in gates:
        for m in methods:
            xs = [n for n in sizes if mean.get((n, g, baseline)) and mean.get((n, g, m))]
            ys = [mean[(n, g, baseline)] / mean[(n, g, m)] for n in xs]
            if xs:
                left.loglog(xs, ys, marker="o", label=f"{m}, {g}")
    left.axhline(1.0, color="grey", lw=0.8)
    left.set_xlabel("triangles")
    left.set_ylabel(f"MSE of {baseline} / MSE of method (equal time)")
    left.set_title("equal-time advantage over " + baseline)
    left.grid(True, which="both", alpha=0.3)
    left.legend(fontsize=7)
    for m in methods:
        xs = [n for n in sizes if (n, m) in work]
        if xs:
            right.loglog(xs, [work[(n, m)][0] for n in xs], marker="o", label=f"{m}: loop iterations")
            right.loglog(xs, [max(work[(n, m)][1], 1e-2) for n in xs], marker="s", ls="--", label=f"{m}: triangles tested")
    right.set_xlabel("triangles")
    right.set_ylabel("per ellipsoid query")
    right.set_title("work of one ellipsoid query")
    right.grid(True, which="both", alpha=0.3)
    right.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    print(f"\nplot written to {png}")


if __name__ == "__main__":
    main()
