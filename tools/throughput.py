#!/usr/bin/env python3
"""Samples per second of gatetrace's methods against Mitsuba 3 + mitransient, in one run.

Measures mitransient's ``transient_path`` (one time bin covering every path
length, i.e. the steady image) on a scene (the Cornell box by default) at the same resolution and
bounce count, then ``gatetrace bench`` (path, direct, ellipsoidal), then the
peer again, and prints each method's samples/s and its ratio to the mean of
the two peer measurements (the bracket shows how much the machine drifted).

A sample is one path per pixel: samples/s = spp x pixels / seconds, warm-up
(kernel compilation) excluded on both sides.

Usage: tools/throughput.py [--scene S.glb] [--seconds S] [--res N] [--max-bounces B]
Requires: a built gatetrace (cargo build --release) and, for the peer,
``pip install mitsuba mitransient`` (+ ``apt-get install libllvm19``).
"""

import argparse
import os
import re
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
SCENE = os.path.join(ROOT, "assets", "scenes", "cornell_box.gltf")
sys.path.insert(0, HERE)


def peer_samples_per_second(scene_path, res, max_bounces, seconds, spp=256):
    """Renders passes of `spp` with transient_path (one bin over all path lengths) for at least
    `seconds` after one warm-up."""
    import peer_reference as peer

    renderer = peer.OneBinRenderer(scene_path, res, max_bounces, 0.0, 1000.0)
    renderer.render(spp, 0)
    start, passes = time.perf_counter(), 0
    while time.perf_counter() - start < seconds:
        passes += 1
        renderer.render(spp, passes)
    elapsed = time.perf_counter() - start
    return passes * spp * res * res / elapsed


def gatetrace_bench(scene_path, res, max_bounces, seconds, methods):
    exe = os.path.join(ROOT, "target", "release", "gatetrace")
    cmd = [exe, "bench", "--seconds", str(seconds), "--max-bounces", str(max_bounces),
           "--res", f"{res}x{res}", "--methods", methods, "--scene", scene_path]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    rows, adapter = [], ""
    for line in out.splitlines():
        if line.startswith("adapter:"):
            adapter = line.split(":", 1)[1].strip()
        m = re.match(r"bench: (\S+)\s+(\S+)\s+\S+\s+\d+\s+[\d.]+\s+([\d.]+)$", line)
        if m:
            rows.append((m.group(1), m.group(2), float(m.group(3)) * 1e6))
    return adapter, rows


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", default=SCENE, help="glTF 2.0 scene (default: the Cornell box)")
    p.add_argument("--seconds", type=float, default=10.0, help="seconds per measurement (default 10)")
    p.add_argument("--res", type=int, default=64, help="square image size in pixels (default 64)")
    p.add_argument("--max-bounces", type=int, default=5, help="scattering vertices (default 5)")
    p.add_argument("--methods", default="path,direct,ellipsoidal", help="gatetrace bench --methods")
    args = p.parse_args()

    try:
        before = peer_samples_per_second(args.scene, args.res, args.max_bounces, args.seconds)
    except ImportError as e:
        before = None
        print(f"peer not measured ({e}); pip install mitsuba mitransient", file=sys.stderr)
    adapter, rows = gatetrace_bench(args.scene, args.res, args.max_bounces, args.seconds, args.methods)
    after = peer_samples_per_second(args.scene, args.res, args.max_bounces, args.seconds) if before else None

    print(f"{os.path.basename(args.scene)}, {args.res}x{args.res}, {args.max_bounces} bounces, {args.seconds:g} s per measurement")
    print(f"gatetrace on {adapter}")
    if before:
        print(f"peer: Mitsuba 3 + mitransient transient_path (llvm_ad_rgb), one bin: "
              f"{before / 1e6:.3f} M samples/s before, {after / 1e6:.3f} after")
    print(f"{'method':<14} {'gate':<20} {'Msamples/s':>11} {'/ peer':>8}")
    peer = (before + after) / 2 if before else None
    for name, gate, rate in rows:
        ratio = f"{rate / peer:8.3f}" if peer else "       -"
        print(f"{name:<14} {gate:<20} {rate / 1e6:11.3f} {ratio}")


if __name__ == "__main__":
    main()
