#!/usr/bin/env python3
"""Samples per second of gatetrace's methods against Mitsuba 3 + mitransient, in one run.

For each scene (the Cornell box by default; --scaling adds the displaced spheres of
tools/scenes/make_sphere_scene.py, made in target/scenes when missing), measures mitransient's
``transient_path`` (one time bin covering every path length, i.e. the steady image) at the same
resolution and bounce count, then ``gatetrace bench`` (path, direct, ellipsoidal), then the
peer again, and prints each method's samples/s and its ratio to the mean of the two peer
measurements (the bracket shows how much the machine drifted). At the end, one markdown table
of every scene (for docs/benchmarks.md).

A sample is one path per pixel: samples/s = spp x pixels / seconds, warm-up
(kernel compilation) excluded on both sides.

Usage: tools/peer/throughput.py [--scene S.glb ...] [--scaling] [--triangles N,N,...] [--seconds S]
                           [--res N] [--max-bounces B] [--peer-variant V] [--exe PATH] [--json FILE]
Requires: a built gatetrace (cargo build --release) and, for the peer,
``pip install mitsuba mitransient`` (+ ``apt-get install libllvm19``).
"""

import argparse
import json
import math
import os
import re
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
SCENE = os.path.join(ROOT, "assets", "scenes", "cornell_box.gltf")
SCALING = "20480,327680,1310720"


def peer_samples_per_second(scene_path, res, max_bounces, seconds, variant, spp=256):
    """Renders passes of `spp` with transient_path (one bin over all path lengths) in Mitsuba's
    `variant` for at least `seconds` after one warm-up."""
    import peer_reference as peer

    renderer = peer.OneBinRenderer(scene_path, res, max_bounces, 0.0, 1000.0, variant)
    renderer.render(spp, 0)
    start, passes = time.perf_counter(), 0
    while time.perf_counter() - start < seconds:
        passes += 1
        renderer.render(spp, passes)
    elapsed = time.perf_counter() - start
    return passes * spp * res * res / elapsed


def gatetrace_bench(exe, scene_path, res, max_bounces, seconds, methods):
    cmd = [exe, "bench", "--seconds", str(seconds), "--max-bounces", str(max_bounces),
           "--res", f"{res}x{res}", "--methods", methods, "--scene", scene_path]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    rows, adapter, triangles = [], "", 0
    for line in out.splitlines():
        if line.startswith("adapter:"):
            adapter = line.split(":", 1)[1].strip()
        m = re.match(r"scene: .* \((\d+) triangles\)", line)
        if m:
            triangles = int(m.group(1))
        m = re.match(r"bench: (\S+)\s+(\S+)\s+\S+\s+\d+\s+\d+\s+[\d.]+\s+([\d.]+)$", line)
        if m:
            rows.append((m.group(1), m.group(2), float(m.group(3)) * 1e6))
    return adapter, triangles, rows


def sphere_scene(triangles):
    """target/scenes/sphere_N.glb of N = 20 f^2 triangles, made when missing."""
    f = round(math.sqrt(triangles / 20))
    if 20 * f * f != triangles:
        sys.exit(f"throughput.py: {triangles} is not 20 f^2 for an integer f (e.g. 20480, 327680, 1310720)")
    path = os.path.join(ROOT, "target", "scenes", f"sphere_{triangles}.glb")
    if not os.path.exists(path):
        os.makedirs(os.path.dirname(path), exist_ok=True)
        subprocess.run([sys.executable, os.path.join(ROOT, "tools", "scenes", "make_sphere_scene.py"), "--frequency", str(f),
                        "--out", path], check=True)
    return path


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", action="append", help="glTF 2.0 scene (repeatable; default: the Cornell box)")
    p.add_argument("--scaling", action="store_true",
                   help="also the Cornell box holding displaced spheres of --triangles triangles")
    p.add_argument("--triangles", default=SCALING, help=f"sphere sizes of --scaling (default {SCALING})")
    p.add_argument("--seconds", type=float, default=10.0, help="seconds per measurement (default 10)")
    p.add_argument("--res", type=int, default=64, help="square image size in pixels (default 64)")
    p.add_argument("--max-bounces", type=int, default=5, help="scattering vertices (default 5)")
    p.add_argument("--methods", default="path,direct,ellipsoidal", help="gatetrace bench --methods")
    p.add_argument("--peer-variant", default="llvm_ad_rgb",
                   help="Mitsuba variant of the peer (default llvm_ad_rgb, the CPU; cuda_ad_rgb on an NVIDIA GPU)")
    p.add_argument("--exe", default=os.path.join(ROOT, "target", "release", "gatetrace"),
                   help="gatetrace binary (default target/release/gatetrace)")
    p.add_argument("--json", help="also write every measurement to this JSON file (samples/s)")
    args = p.parse_args()
    scenes = list(args.scene or [SCENE])
    if args.scaling:
        scenes += [sphere_scene(int(n)) for n in args.triangles.split(",")]

    table = []
    for scene in scenes:
        try:
            before = peer_samples_per_second(scene, args.res, args.max_bounces, args.seconds, args.peer_variant)
        except ImportError as e:
            before = None
            print(f"peer not measured ({e}); pip install mitsuba mitransient", file=sys.stderr)
        adapter, triangles, rows = gatetrace_bench(args.exe, scene, args.res, args.max_bounces, args.seconds,
                                                   args.methods)
        after = (peer_samples_per_second(scene, args.res, args.max_bounces, args.seconds, args.peer_variant)
                 if before else None)

        print(f"{os.path.basename(scene)} ({triangles} triangles), {args.res}x{args.res}, {args.max_bounces} "
              f"bounces, {args.seconds:g} s per measurement")
        print(f"gatetrace on {adapter}")
        if before:
            print(f"peer: Mitsuba 3 + mitransient transient_path ({args.peer_variant}), one bin: "
                  f"{before / 1e6:.3f} M samples/s before, {after / 1e6:.3f} after")
        print(f"{'method':<14} {'gate':<20} {'Msamples/s':>11} {'/ peer':>8}")
        peer = (before + after) / 2 if before else None
        for name, gate, rate in rows:
            ratio = f"{rate / peer:8.3f}" if peer else "       -"
            print(f"{name:<14} {gate:<20} {rate / 1e6:11.3f} {ratio}")
        print(flush=True)
        table.append((os.path.basename(scene), triangles, before, after, rows))

    if args.json:
        report = {
            "adapter": adapter,
            "peer": f"Mitsuba 3 + mitransient transient_path ({args.peer_variant}), one bin",
            "res": args.res,
            "max_bounces": args.max_bounces,
            "seconds_per_measurement": args.seconds,
            "scenes": [{
                "scene": name,
                "triangles": triangles,
                "peer_samples_per_second": [before, after] if before else None,
                "measurements": [{"method": m, "gate": gate, "samples_per_second": rate,
                                  "per_peer": rate / ((before + after) / 2) if before else None}
                                 for m, gate, rate in rows],
            } for name, triangles, before, after, rows in table],
        }
        with open(args.json, "w") as f:
            json.dump(report, f, indent=2)
            f.write("\n")

    methods = [name for name, _, _ in table[0][4]]
    print("| scene | triangles | peer M samples/s (before, after) | "
          + " | ".join(f"`{m}` M samples/s (/ peer)" for m in methods) + " |")
    print("|---|---|---|" + "---|" * len(methods))
    for name, triangles, before, after, rows in table:
        peer = (before + after) / 2 if before else None
        cells = [f"{rate / 1e6:.3f} ({rate / peer:.2f}×)" if peer else f"{rate / 1e6:.3f}" for _, _, rate in rows]
        bracket = f"{before / 1e6:.2f}, {after / 1e6:.2f}" if before else "-"
        print(f"| {name} | {triangles:,} | {bracket} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
