#!/usr/bin/env python3
"""Plots the CSV of `gatetrace equal-time` as mean squared error against box-gate width, one
curve per method (log-log), and prints the widths where the best method changes.

    gatetrace equal-time --methods direct,ellipsoidal --gates 'box:3.14..3.141;box:3.14..3.15' \
        --csv sweep.csv
    tools/bench/plot_equal_time.py sweep.csv sweep.png

Needs numpy and matplotlib (pip install numpy matplotlib); not a dependency of the renderer.
"""

import argparse
import csv
import sys
from collections import defaultdict


def gate_width(spec):
    """Width in metres of a `box:A..B` gate spec (plain metres only)."""
    if not spec.startswith("box:"):
        sys.exit(f"{spec}: only box gates can be plotted against their width")
    start, end = spec[4:].split("..")
    return float(end) - float(start)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("csv", help="CSV written by gatetrace equal-time --csv")
    parser.add_argument("png", help="output plot")
    args = parser.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mse = defaultdict(lambda: defaultdict(list))
    seconds = set()
    with open(args.csv, newline="") as f:
        for row in csv.DictReader(f):
            mse[row["method"]][gate_width(row["gate"])].append(float(row["relative_mse"]))
            seconds.add(round(float(row["seconds"])))
    if not mse:
        sys.exit(f"{args.csv}: no rows")

    fig, ax = plt.subplots(figsize=(6, 4))
    means = {}
    for method, by_width in sorted(mse.items()):
        widths = sorted(by_width)
        values = [sum(by_width[w]) / len(by_width[w]) for w in widths]
        means[method] = dict(zip(widths, values))
        ax.loglog([w * 1000 for w in widths], values, marker="o", label=method)
    ax.set_xlabel("box gate width (mm of optical path)")
    ax.set_ylabel("relative MSE at equal time")
    ax.set_title(f"equal time ({', '.join(str(s) for s in sorted(seconds))} s per render)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.png, dpi=120)

    widths = sorted(set().union(*[m.keys() for m in means.values()]))
    print(f"{'width (mm)':>10} " + " ".join(f"{m:>14}" for m in sorted(means)) + "  best")
    previous = None
    for w in widths:
        row = {m: means[m].get(w) for m in sorted(means)}
        best = min((v, m) for m, v in row.items() if v is not None)[1]
        print(f"{w * 1000:>10.1f} " + " ".join(f"{row[m]:>14.4e}" if row[m] is not None else f"{'-':>14}" for m in sorted(means)) + f"  {best}")
        if previous is not None and best != previous[1]:
            print(f"  best method changes from {previous[1]} to {best} between {previous[0] * 1000:.1f} and {w * 1000:.1f} mm")
        previous = (w, best)
    print(f"plot written to {args.png}")


if __name__ == "__main__":
    main()
