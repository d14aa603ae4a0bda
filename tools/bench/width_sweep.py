#!/usr/bin/env python3
"""The gate-width sweep: is `combined` never worse than the better of `direct` and `ellipsoidal`?

Renders the Cornell box, the glossy Cornell box, the fence and the proximity scene (its middle
frame) behind box gates of 1 mm, 1 cm, 10 cm and 1 m that open where the scene's light arrives,
with `direct`, `ellipsoidal` and `combined` for equal time (`gatetrace equal-time`), and writes a
table of each method's MSE (mean of the repeats, with its standard error), the ratio of
`combined`'s MSE to the better of the other two, and whether that ratio is at most 1 within two
standard errors of the difference.

    tools/bench/width_sweep.py                         # about 25 minutes on 2 CPU cores
    tools/bench/width_sweep.py --only box --seconds 2  # a quick look
    tools/bench/width_sweep.py --resume                # go on after an interruption

Writes into --out (target/width_sweep): `width_sweep.md` (the table) and one equal-time CSV and
log per scene. The MSE of each method is measured against a reference rendered by `auto` for
--reference-seconds (its own noise subtracted), as `gatetrace equal-time` does, so a method's
MSE can come out slightly negative where it is far below the reference's noise.
"""

import argparse
import csv
import math
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BINARY = ROOT / "target/release/gatetrace"

# Scenes: a key (--only, file names), the scene file, the animation time it is posed at, and the
# path length (m) where each gate opens: on the boxes where light reflected once or twice
# arrives everywhere, on the application scenes where the scene's own gate opens.
SCENES = [
    ("box", "cornell_box.gltf", None, 3.14),
    ("glossy_box", "cornell_box_glossy.gltf", None, 3.14),
    ("fence", "fence.gltf", None, 11.3),
    ("proximity", "proximity.gltf", 0.65, 4.0),
]
# Gate widths (m), 1 mm to 1 m.
WIDTHS = [0.001, 0.01, 0.1, 1.0]
METHODS = ["direct", "ellipsoidal", "combined"]


def width_label(w):
    return f"{w * 1000:g} mm" if w < 0.01 else f"{w * 100:g} cm" if w < 1 else f"{w:g} m"


def equal_time(args, key, scene, anim_time, gates):
    """Runs gatetrace equal-time over the gates of one scene (or, with --resume, reads what an
    earlier run left); returns its CSV rows."""
    out = args.out / f"{key}.csv"
    if args.resume and out.exists():
        print(f"reusing {out}", flush=True)
    else:
        cmd = [BINARY, "equal-time", scene, "--methods", ",".join(METHODS), "--gates", ";".join(gates),
               "--seconds", args.seconds, "--repeats", args.repeats, "--reference-method", "auto",
               "--reference-seconds", args.reference_seconds, "--res", args.res,
               "--max-bounces", args.max_bounces, "--csv", out]
        if anim_time is not None:
            cmd += ["--anim-time", anim_time]
        print("+", " ".join(str(c) for c in cmd), flush=True)
        text = subprocess.run([str(c) for c in cmd], check=True, capture_output=True, text=True).stdout
        print(text, flush=True)
        (args.out / f"{key}.txt").write_text(text)
    with open(out, newline="") as f:
        return list(csv.DictReader(f))


def mean_se(values):
    """Mean and standard error of the mean."""
    n = len(values)
    m = sum(values) / n
    if n < 2:
        return m, float("inf")
    return m, math.sqrt(sum((v - m) ** 2 for v in values) / (n - 1) / n)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=4.0, help="rendering seconds per method, gate and repeat")
    parser.add_argument("--repeats", type=int, default=3, help="renders per method and gate")
    parser.add_argument("--reference-seconds", type=float, default=40.0, help="seconds of each gate's reference")
    parser.add_argument("--res", default="64x64", help="image size, WxH")
    parser.add_argument("--max-bounces", type=int, default=5, help="scattering vertices per path")
    parser.add_argument("--only", help="comma-separated scene keys (box, glossy_box, fence, proximity)")
    parser.add_argument("--out", type=Path, default=ROOT / "target/width_sweep", help="output folder")
    parser.add_argument("--resume", action="store_true", help="reuse the CSVs an interrupted run left in --out")
    parser.add_argument("--no-build", action="store_true", help="use target/release/gatetrace as it is")
    args = parser.parse_args()
    if args.repeats < 2:
        sys.exit("--repeats must be at least 2: the verdicts need standard errors")
    args.out.mkdir(parents=True, exist_ok=True)
    if not args.no_build:
        subprocess.run(["cargo", "build", "--release", "--quiet", "--manifest-path", str(ROOT / "Cargo.toml")],
                       check=True)
    chosen = [s for s in SCENES if not args.only or s[0] in args.only.split(",")]
    if not chosen:
        sys.exit(f"--only {args.only}: no such scene ({', '.join(s[0] for s in SCENES)})")

    lines = ["| scene | gate | MSE `direct` | MSE `ellipsoidal` | MSE `combined` | `combined` / better | "
             "within 2 SE of ≤ 1 | `combined` / worse | `combined` traced |", "|---" * 9 + "|"]
    failures = 0
    for key, file, anim_time, start in chosen:
        gates = [f"box:{start}..{start + w:.4f}" for w in WIDTHS]
        rows = equal_time(args, key, ROOT / "assets/scenes" / file, anim_time, gates)
        mse, traced = defaultdict(list), defaultdict(lambda: defaultdict(int))
        for r in rows:
            mse[(r["gate"], r["method"])].append(float(r["mse"]))
            if r["method"] == "combined" and r.get("chosen_method"):
                traced[r["gate"]][r["chosen_method"]] += 1
        for w, gate in zip(WIDTHS, gates):
            stats = {m: mean_se(mse[(gate, m)]) for m in METHODS}
            better = min(("direct", "ellipsoidal"), key=lambda m: stats[m][0])
            worse = "ellipsoidal" if better == "direct" else "direct"
            c, c_se = stats["combined"]
            b, b_se = stats[better]
            excess_se = math.sqrt(c_se ** 2 + b_se ** 2)
            ok = c - b <= 2 * excess_se
            failures += not ok
            ratio = c / b if b > 0 else float("inf")
            fmt = lambda m: f"{stats[m][0]:.3e} ± {stats[m][1]:.1e}"
            picks = ", ".join(f"{t} ×{n}" for t, n in traced[gate].items())
            lines.append(f"| {key} | {width_label(w)} (`{gate}`) | {fmt('direct')} | {fmt('ellipsoidal')} | "
                         f"{fmt('combined')} | {ratio:.2f} ({better}) | {'yes' if ok else 'no'} | "
                         f"{c / stats[worse][0]:.2f} | {picks} |")
    header = [f"Equal-time MSE, {args.res}, {args.max_bounces} bounces, {args.repeats} × {args.seconds} s per "
              f"method and gate, reference `auto` for {args.reference_seconds} s (± one standard error of the "
              f"mean over the repeats)", ""]
    table = "\n".join(header + lines) + f"\n\n{failures} gate(s) where `combined` is worse than the better " \
                                        f"method by more than two standard errors.\n"
    (args.out / "width_sweep.md").write_text(table)
    print()
    print(table)


if __name__ == "__main__":
    main()
