#!/usr/bin/env python3
"""Accuracy of NLOS captures against mitransient at equal time over the benchmark set of hidden
scenes, at several time budgets, and where each side's error lies: one table for the README.

    tools/peer/nlos_benchmark_set.py [--scenes z,panels,staircase,boxes,sphere]
        [--seconds 1,3,10,30] [--repeats 3] [--grid 16x16] [--param NAME=VALUE ...]
        [--distances D[,D...]] [--json FILE] [--exe BINARY]

Every scene is a Mitsuba 3 XML file in assets/scenes/ that both renderers read unchanged:

    z          nlos_z.xml                 a flat letter facing the wall, 0.8 m from it
    panels     nlos_panels.xml            a wide object: a tilted panel, a cube and a disk, 0.37-0.9 m
    staircase  nlos_staircase.xml         a deep object: five steps, risers 0.4-1.0 m from the wall
    boxes      nlos_staircase_boxes.xml   the same steps as five overlapping boxes
    sphere     nlos_sphere.xml            a displaced sphere of 327,680 triangles, 0.6 m from the wall

Each is rendered as a confocal capture (--grid points, default 16 x 16) with 4 ps bins (1.1992 mm
of optical path) over its whole transient, by `ellipsoidal` with the capture defaults, through
tools/peer/nlos_xml_equal_time.py: --repeats captures per budget and side, the error being the
variance across them (the MSE of an unbiased renderer), mitransient (`llvm_ad_rgb`) rendering
without its hidden-geometry sampling (unbiased: the ratios' base) and with it, in the same run.
--param NAME=VALUE sets a parameter of every file (e.g. `origin_x=-1.5`, the laser's and
sensor's offset from the wall's centre in metres, in the Z's and the sphere's files), after the
set's own. --distances renders every scene once per distance of the origins from the wall
(`distance`, metres): at the files' default `origin_x`, the lines from origins more than about
0.8 m away to the wall's points cross the hidden objects (gatetrace warns; mitransient's meter
samples the wall regardless), so a sweep wants the origins beside them (`--scenes z,sphere
--param origin_x=-1.5`). The sphere's mesh is written by
tools/scenes/make_sphere_scene.py when it is missing (target/scenes/nlos_sphere_327680.ply).

Prints, as the runs end, each scene's output of nlos_xml_equal_time.py; then a Markdown table
of accuracy at equal time, (peer MSE x peer seconds) / (MSE x seconds), against unbiased
mitransient (and, in brackets, mitransient with its hidden-geometry sampling) per scene and
budget, and a table of where `ellipsoidal`'s squared error lies (onset, middle and tail bins)
at each budget. --json FILE writes every figure. About 8 minutes per scene at the default
budgets on 2 CPU cores.

Requires: a built gatetrace (cargo build --release), numpy, mitsuba and mitransient.
"""
import argparse
import json
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
SCENES = ROOT / "assets" / "scenes"
EXE = ROOT / "target" / "release" / "gatetrace"
BIN_WIDTH = 0.0011992  # m of optical path: 4 ps
# name -> (file, bins of BIN_WIDTH that cover its transients from the file's start_opl)
SET = {
    "z": ("nlos_z.xml", 1000),
    "panels": ("nlos_panels.xml", 1700),
    "staircase": ("nlos_staircase.xml", 1600),
    "boxes": ("nlos_staircase_boxes.xml", 1600),
    "sphere": ("nlos_sphere.xml", 1000),
}
SPHERE_MESH = ROOT / "target" / "scenes" / "nlos_sphere_327680.ply"
PEER_OFF = "mitransient, hidden-geometry sampling off"
PEER_ON = "mitransient, hidden-geometry sampling on"
OURS = "gatetrace ellipsoidal"


def run_scene(args, name, extra):
    """The JSON summary nlos_xml_equal_time.py prints for one scene of the set."""
    file, bins = SET[name]
    if name == "sphere" and not SPHERE_MESH.exists():
        subprocess.run([sys.executable, str(ROOT / "tools" / "scenes" / "make_sphere_scene.py"), "--nlos",
                        "--frequency", "128", "--out", str(SPHERE_MESH)], check=True)
    command = [sys.executable, str(HERE / "nlos_xml_equal_time.py"), str(SCENES / file),
               "--param", "confocal=true", "--param", f"bins={bins}", "--param", f"bin_width={BIN_WIDTH}",
               "--seconds", args.seconds, "--repeats", str(args.repeats), "--grid", args.grid,
               "--methods", "ellipsoidal", "--exe", args.exe]
    for kv in args.param + extra:
        command += ["--param", kv]
    done = subprocess.run(command, check=True, capture_output=True, text=True)
    sys.stderr.write(done.stderr)
    lines = done.stdout.strip().splitlines()
    print(f"\n## {name} {' '.join(extra)}\n" + "\n".join(lines[:-1]), flush=True)
    return json.loads(lines[-1])


def accuracy(rows, budget):
    """(vs off, vs on) for `ellipsoidal` at one budget."""
    at = {r["renderer"]: r for r in rows if r["budget"] == budget}
    ours = at[OURS]
    cost = ours["mse"] * ours["seconds"]
    return tuple(at[peer]["mse"] * at[peer]["seconds"] / cost for peer in (PEER_OFF, PEER_ON))


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", default=",".join(SET), help="comma-separated names from the set")
    p.add_argument("--seconds", default="1,3,10,30", help="comma-separated budgets of each capture (s)")
    p.add_argument("--repeats", type=int, default=3, help="captures per budget and side (at least 2)")
    p.add_argument("--grid", default="16x16", help="sensed points WIDTHxHEIGHT")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="a parameter of every file, e.g. distance=1.5 (m)")
    p.add_argument("--distances", help="comma-separated distances of the origins from the wall (m): one run each")
    p.add_argument("--json", type=Path, help="write every figure to this file")
    p.add_argument("--exe", default=str(EXE), help="the gatetrace binary")
    args = p.parse_args()
    names = args.scenes.split(",")
    unknown = [n for n in names if n not in SET]
    if unknown:
        p.error(f"--scenes: {', '.join(unknown)} not in the set ({', '.join(SET)})")
    if args.repeats < 2:
        p.error("--repeats: the error is the variance across captures, so at least 2")
    budgets = [float(s) for s in args.seconds.split(",")]

    distances = args.distances.split(",") if args.distances else [None]
    runs = [(name, d) for name in names for d in distances]
    results = {}
    for name, d in runs:
        extra = [f"distance={d}"] if d is not None else []
        results[(name, d)] = run_scene(args, name, extra)
    setting = f"confocal {args.grid}, 4 ps bins, {args.repeats} captures per budget and side"
    if args.param:
        setting += ", " + ", ".join(args.param)
    print(f"\nAccuracy of `ellipsoidal` at equal time against unbiased mitransient (against mitransient with "
          f"hidden-geometry sampling), {setting}:\n")
    def label(name, d):
        return name if d is None else f"{name}, origins {d} m from the wall"

    print("| scene | " + " | ".join(f"{b:g} s" for b in budgets) + " |")
    print("|---|" + "---|" * len(budgets))
    for name, d in runs:
        cells = []
        for b in budgets:
            off, on = accuracy(results[(name, d)]["rows"], b)
            cells.append(f"{off:,.3g}× ({on:,.3g}×)")
        print(f"| {label(name, d)} | " + " | ".join(cells) + " |")
    print("\nShares of `ellipsoidal`'s squared error in each point's onset, middle and tail bins, per budget:\n")
    print("| scene | " + " | ".join(f"{b:g} s" for b in budgets) + " |")
    print("|---|" + "---|" * len(budgets))
    for name, d in runs:
        cells = []
        for b in budgets:
            row = next(r for r in results[(name, d)]["rows"] if r["renderer"] == OURS and r["budget"] == b)
            s = row["shares"]
            cells.append(f"{s['onset']:.2f} / {s['middle']:.2f} / {s['tail']:.2f}")
        print(f"| {label(name, d)} | " + " | ".join(cells) + " |")
    if args.json:
        args.json.write_text(json.dumps({"setting": setting, "budgets": budgets,
                                         "runs": [{"scene": n, "distance": d, **results[(n, d)]} for n, d in runs]},
                                        indent=1))


if __name__ == "__main__":
    main()
