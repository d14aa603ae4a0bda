#!/usr/bin/env python3
"""The applications benchmark: renders each of the paper's application scenes (Pediredla et al.
2019, section 7; made by tools/scenes/make_application_scenes.py) with `path`, `direct`, `ellipsoidal`,
`combined` and `auto` for equal time at the gate the scene names in its extras (the proximity
sensor at three frames; the CW room also with a window of the paper's absolute 20 ps), and writes a table
of the equal-time MSE gains over `direct` beside the paper's, with the variance and the time of
one sample of `ellipsoidal` and `combined` relative to `direct`'s, and a picture of each scene.

    tools/bench/applications_benchmark.py                  # about 30 minutes on 2 CPU cores
    tools/bench/applications_benchmark.py --seconds 2 --reference-seconds 20 --no-pictures   # a quick look
    tools/bench/applications_benchmark.py --resume         # go on after an interruption

Writes into --out (target/applications): `applications.md` (the table), `applications.csv`
(every render, from `gatetrace equal-time --csv`), `SCENE.png` (a steady-state picture beside
the gated one; for the dynamic scene, four slices of its transient) and the raw NPY renders.
The MSE of each method is measured against a reference rendered by `auto` for
--reference-seconds (its own noise subtracted), as `gatetrace equal-time` does.

Needs numpy and Pillow (pip install numpy pillow) for the pictures; not a dependency of the
renderer.
"""

import argparse
import csv
import json
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BINARY = ROOT / "target/release/gatetrace"

# The rows of the table: a key naming the row's files, the application's name (--only), scene
# file, the animation time the comparison poses it at, the scene's extras field holding the gate,
# the paper's figure, the paper's gate as it states it, and the paper's equal-time MSE gains of
# ellipsoidal over direct connections (Fig. 7 reports one per frame; Fig. 6 gives no figure).
APPLICATIONS = [
    ("fence", "fence", "fence.gltf", None, "gate", "Fig. 8", "1 ns, 2.35 %", [3.37]),
    ("proximity_0.35", "proximity", "proximity.gltf", 0.35, "gate", "Fig. 7, frame 1", "200 ps, 1.14 %", [9.25]),
    ("proximity_0.65", "proximity", "proximity.gltf", 0.65, "gate", "Fig. 7, frame 2", "200 ps, 1.14 %", [9.39]),
    ("proximity_0.95", "proximity", "proximity.gltf", 0.95, "gate", "Fig. 7, frame 3", "200 ps, 1.14 %", [2.73]),
    ("cw_room", "cw_room", "cw_room.gltf", None, "gate", "Fig. 9", "depth-selective, window 1.28 % of the scene",
     [5.49]),
    ("cw_room_20ps", "cw_room", "cw_room.gltf", None, "gate_20ps", "Fig. 9", "depth-selective, 20 ps window",
     [5.49]),
    ("dynamic", "dynamic", "dynamic.gltf", 0.0, "gate", "Fig. 6", "200 ps, 1.74 %", []),
]
METHODS = ["path", "direct", "ellipsoidal", "combined", "auto"]


def run(cmd):
    print("+", " ".join(str(c) for c in cmd), flush=True)
    subprocess.run([str(c) for c in cmd], check=True)


def scene_extras(path):
    return json.loads(path.read_text()).get("extras", {})


def equal_time(args, name, scene, gate, anim_time):
    """Runs gatetrace equal-time on one scene (or, with --resume, reads what an earlier run of
    it left); returns its CSV rows and the adapter line."""
    out = args.out / f"{name}_equal_time.csv"
    log = args.out / f"{name}_equal_time.txt"
    if args.resume and out.exists():
        print(f"reusing {out}", flush=True)
        text = log.read_text() if log.exists() else ""
        adapter = next((line for line in text.splitlines() if line.startswith("adapter:")), "adapter: unknown")
        with open(out, newline="") as f:
            return list(csv.DictReader(f)), adapter
    cmd = [BINARY, "equal-time", scene, "--methods", ",".join(METHODS), "--gates", gate,
           "--seconds", args.seconds, "--repeats", args.repeats, "--reference-method", "auto",
           "--reference-seconds", args.reference_seconds, "--res", args.res,
           "--max-bounces", args.max_bounces, "--csv", out]
    if anim_time is not None:
        cmd += ["--anim-time", anim_time]
    print("+", " ".join(str(c) for c in cmd), flush=True)
    text = subprocess.run([str(c) for c in cmd], check=True, capture_output=True, text=True).stdout
    print(text, flush=True)
    log.write_text(text)
    adapter = next((line for line in text.splitlines() if line.startswith("adapter:")), "adapter: unknown")
    with open(out, newline="") as f:
        return list(csv.DictReader(f)), adapter


def tone_map(rgb, white):
    """Linear radiance to 8-bit sRGB-like values, `white` mapping to 1."""
    import numpy as np

    x = np.clip(rgb / max(white, 1e-30), 0.0, 1.0) ** (1 / 2.2)
    return (x * 255 + 0.5).astype(np.uint8)


def pictures(args, name, scene, gate, anim_time):
    """A steady-state render beside the gated one (or four slices of the dynamic scene's
    transient), each tone-mapped to its own 99.5th percentile; returns the PNG's path."""
    import numpy as np
    from PIL import Image

    res = args.picture_res
    common = ["--res", res, "--max-bounces", args.max_bounces, "--time", args.picture_seconds, "--force"]
    panels = []
    steady = args.out / f"{name}_steady.npy"
    posed = ["--anim-time", anim_time] if anim_time is not None else []
    run([BINARY, "render", scene, "--method", "path", "--gate", "none", "--out", steady] + posed + common)
    panels.append(np.load(steady)[..., :3])
    if name == "dynamic":
        # Four slices, 24 cm and 0.3 s of the scene's clock apart.
        pattern = args.out / f"{name}_slice_{{frame}}.npy"
        run([BINARY, "render", scene, "--method", "auto", "--gate", gate, "--frames", 4, "--gate-step", "0.24",
             "--anim-time", "0..0.9", "--out", pattern] + common)
        panels += [np.load(args.out / f"{name}_slice_{k}.npy")[..., :3] for k in range(4)]
    else:
        gated = args.out / f"{name}_gated.npy"
        run([BINARY, "render", scene, "--method", "auto", "--gate", gate, "--out", gated] + posed + common)
        panels.append(np.load(gated)[..., :3])
    tiles = [tone_map(p, np.percentile(p, 99.5)) for p in panels]
    gap = np.full((tiles[0].shape[0], 4, 3), 255, np.uint8)
    row = np.concatenate([t for tile in tiles for t in (tile, gap)][:-1], axis=1)
    path = args.out / f"{name}.png"
    Image.fromarray(row).save(path)
    print(f"wrote {path}")
    return path


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=6.0, help="rendering seconds per method and repeat")
    parser.add_argument("--repeats", type=int, default=3, help="renders per method (repeat r of each from the same seed)")
    parser.add_argument("--reference-seconds", type=float, default=90.0, help="seconds of each reference")
    parser.add_argument("--res", default="64x64", help="image size of the comparison, WxH")
    parser.add_argument("--max-bounces", type=int, default=5, help="scattering vertices per path")
    parser.add_argument("--picture-res", default="192x144", help="image size of the pictures, WxH")
    parser.add_argument("--picture-seconds", type=float, default=20.0, help="rendering seconds per picture")
    parser.add_argument("--no-pictures", action="store_true", help="skip the pictures")
    parser.add_argument("--only", help="comma-separated application names (fence, proximity, cw_room, dynamic)")
    parser.add_argument("--out", type=Path, default=ROOT / "target/applications", help="output folder")
    parser.add_argument("--resume", action="store_true",
                        help="reuse the equal-time CSVs and pictures an interrupted run left in --out")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    run(["cargo", "build", "--release", "--quiet", "--manifest-path", ROOT / "Cargo.toml"])
    chosen = [a for a in APPLICATIONS if not args.only or a[1] in args.only.split(",")]
    if not chosen:
        sys.exit(f"--only {args.only}: no such application (fence, proximity, cw_room, dynamic)")

    lines = ["| scene | paper | gate | triangles | paper's gain | path gain | ellipsoidal gain | combined gain | "
             "auto gain | auto chose | variance per sample (ellipsoidal / combined) | cost per sample "
             "(ellipsoidal / combined) | spp (" + " / ".join(METHODS) + ") |", "|---" * 13 + "|"]
    all_rows = []
    for key, name, file, anim_time, gate_field, figure, paper_gate, paper_gains in chosen:
        scene = ROOT / "assets/scenes" / file
        gate = scene_extras(scene)[gate_field]
        rows, adapter = equal_time(args, key, scene, gate, anim_time)
        all_rows += rows
        mse, spp, picks = defaultdict(list), defaultdict(list), defaultdict(int)
        for r in rows:
            mse[r["method"]].append(float(r["mse"]))
            spp[r["method"]].append(int(r["spp"]))
            if r["method"] == "auto" and r.get("chosen_method"):
                picks[r["chosen_method"]] += 1
        mean = {m: sum(v) / len(v) for m, v in mse.items()}
        gain = lambda m: mean["direct"] / mean[m] if mean[m] > 0 else float("inf")
        paper = ", ".join(f"{g}x" for g in paper_gains) or "(none given)"
        picked = ", ".join(f"{m} x{n}" for m, n in sorted(picks.items()))
        spps = " / ".join(str(sum(spp[m]) // len(spp[m])) for m in METHODS)
        mean_spp = {m: sum(v) / len(v) for m, v in spp.items()}
        # Relative to direct's: the variance of one sample (MSE x samples per pixel) and the time
        # of one sample (direct's samples over the method's, in the same time).
        variance = lambda m: mean[m] * mean_spp[m] / (mean["direct"] * mean_spp["direct"])
        cost = lambda m: mean_spp["direct"] / mean_spp[m]
        label = name + ("" if anim_time is None else f" at {anim_time} s") + ("" if gate_field == "gate" else ", 20 ps")
        lines.append(f"| {label} | {figure}: {paper_gate} | "
                     f"`{gate}` | {rows[0]['triangles']} | {paper} | {gain('path'):.2f}x | "
                     f"{gain('ellipsoidal'):.2f}x | {gain('combined'):.2f}x | {gain('auto'):.2f}x | {picked} | "
                     f"{variance('ellipsoidal'):.2f} / {variance('combined'):.2f} | "
                     f"{cost('ellipsoidal'):.1f} / {cost('combined'):.1f} | {spps} |")
        # One picture per scene: the proximity sensor at its middle frame, the CW room with its
        # own window.
        if key in ("fence", "proximity_0.65", "cw_room", "dynamic") and not args.no_pictures \
                and not (args.resume and (args.out / f"{name}.png").exists()):
            pictures(args, name, scene, gate, anim_time)

    with open(args.out / "applications.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(all_rows[0].keys()))
        writer.writeheader()
        writer.writerows(all_rows)
    header = [f"Equal-time MSE gain over `direct` (MSE of direct / MSE of the method), {args.res}, "
              f"{args.max_bounces} bounces, {args.repeats} x {args.seconds} s per method, reference `auto` for "
              f"{args.reference_seconds} s; {adapter}", ""]
    table = "\n".join(header + lines) + "\n"
    (args.out / "applications.md").write_text(table)
    print()
    print(table)


if __name__ == "__main__":
    main()
