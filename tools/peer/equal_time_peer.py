#!/usr/bin/env python3
"""Error at equal time of gatetrace's methods against Mitsuba 3 + mitransient, in one run.

For one scene and one box gate [A, B) metres of optical path:

1. A reference image: `gatetrace render --method REF` in 8 batches of --reference-seconds / 8,
   averaged; the variance of that mean estimates the reference's own noise, which is subtracted
   from every MSE below (as `gatetrace equal-time` does).
2. Each gatetrace method renders --repeats images for --seconds of rendering each
   (`render --time`, kernel builds excluded).
3. The peer, mitransient's `transient_path` (llvm_ad_rgb) with one time bin [A, B), renders
   --repeats images with the sample count its measured rate fits into --seconds (warm-up
   render of the same size first, so Dr.Jit's compilation is excluded too); its actual render
   time is reported.

Prints per method the mean spp, seconds, MSE and relative MSE (MSE / mean squared reference
value; every value is bin-integrated radiance, the same convention on both sides), and each
method's accuracy against the peer's at equal time: (peer MSE x peer seconds) / (MSE x seconds),
MSE times time being constant for an unbiased estimator (above 1: more accurate than the peer).
The reference's noise should stay well below the MSEs compared; a narrow gate wants a long
reference, or `--reference-method ellipsoidal` (validated against `direct` by the tests).

Usage: tools/peer/equal_time_peer.py [--scene S] [--gate A B] [--seconds T] [--repeats R]
           [--methods path,ellipsoidal] [--reference-method direct] [--reference-seconds S]
           [--res N] [--max-bounces B]
Requires: a built gatetrace (cargo build --release), numpy, and
``pip install mitsuba mitransient`` (+ ``apt-get install libllvm19``).
"""

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
EXE = os.path.join(ROOT, "target", "release", "gatetrace")


def gatetrace_render(args, method, seconds, seed, out):
    """Renders with `render --time`; returns (image [H, W, 3], rendering seconds, spp)."""
    cmd = [EXE, "render", args.scene, "--method", method, "--gate", f"box:{args.gate[0]}..{args.gate[1]}",
           "--time", str(seconds), "--seed", str(seed), "--res", f"{args.res}x{args.res}",
           "--max-bounces", str(args.max_bounces), "--out", out]
    text = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    m = re.search(r"(\d+) spp in [0-9.]+ s \(([0-9.]+) s rendering", text)
    if not m:
        sys.exit(f"cannot read the render's summary line:\n{text}")
    return np.load(out).astype(np.float64).reshape(args.res, args.res, 3), float(m.group(2)), int(m.group(1))


def spp_for(peer, seconds, probe_spp=64):
    """Samples per pixel the peer renders in `seconds`, from the rate of a warm render."""
    peer.render(probe_spp, 0)
    _, t = peer.render(probe_spp, 1)
    return max(1, int(probe_spp * seconds / t))


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", default=os.path.join(ROOT, "assets", "scenes", "cornell_box.gltf"),
                   help="glTF 2.0 scene (default: the Cornell box)")
    p.add_argument("--gate", nargs=2, type=float, default=[1.94, 7.94], metavar=("A", "B"),
                   help="box gate [A, B), metres of optical path (default 1.94 7.94)")
    p.add_argument("--seconds", type=float, default=4.0, help="seconds of rendering per image (default 4)")
    p.add_argument("--repeats", type=int, default=3, help="images per method (default 3)")
    p.add_argument("--methods", default="path,ellipsoidal", help="gatetrace methods (default path,ellipsoidal)")
    p.add_argument("--reference-method", default="direct", help="method of the reference (default direct)")
    p.add_argument("--reference-seconds", type=float, default=120.0,
                   help="seconds of rendering of the reference, in 8 batches (default 120)")
    p.add_argument("--res", type=int, default=64, help="square image size in pixels (default 64)")
    p.add_argument("--max-bounces", type=int, default=5, help="scattering vertices (default 5)")
    args = p.parse_args()
    if not os.path.exists(EXE):
        sys.exit(f"{EXE} not found: run cargo build --release first")
    if not args.gate[0] < args.gate[1]:
        sys.exit("--gate A B needs A < B")

    tmp = tempfile.mkdtemp(prefix="equal_time_peer_")
    out = os.path.join(tmp, "image.npy")
    batches = 8
    refs = [gatetrace_render(args, args.reference_method, args.reference_seconds / batches, 9000 + k, out)
            for k in range(batches)]
    stack = np.stack([r[0] for r in refs])
    reference = stack.mean(axis=0)
    noise = (stack.var(axis=0, ddof=1) / batches).mean()
    power = (reference ** 2).mean()
    print(f"scene {os.path.basename(args.scene)}, {args.res}x{args.res}, {args.max_bounces} bounces, "
          f"gate box:{args.gate[0]}..{args.gate[1]}")
    print(f"reference: {args.reference_method}, {sum(r[2] for r in refs)} spp in {sum(r[1] for r in refs):.0f} s, "
          f"mean {reference.mean():.6g}, its noise variance {noise:.3e} (subtracted)")

    rows = []
    for method in args.methods.split(","):
        results = [gatetrace_render(args, method, args.seconds, 100 + k, out) for k in range(args.repeats)]
        mse = np.mean([((img - reference) ** 2).mean() - noise for img, _, _ in results])
        rows.append((f"gatetrace {method}", np.mean([r[2] for r in results]), np.mean([r[1] for r in results]), mse))

    import peer_reference

    peer = peer_reference.OneBinRenderer(args.scene, args.res, args.max_bounces, args.gate[0],
                                         args.gate[1] - args.gate[0])
    spp = spp_for(peer, args.seconds)
    results = [peer.render(spp, 200 + k) for k in range(args.repeats)]
    peer_mse = np.mean([((img - reference) ** 2).mean() - noise for img, _ in results])
    rows.append(("mitransient transient_path", spp, np.mean([t for _, t in results]), peer_mse))

    peer_cost = peer_mse * rows[-1][2]
    print(f"{'renderer':>30} {'spp':>8} {'seconds':>8} {'MSE':>11} {'rel. MSE':>11} {'vs peer, equal time':>20}")
    for name, s, secs, mse in rows:
        print(f"{name:>30} {s:8.0f} {secs:8.2f} {mse:11.3e} {mse / power:11.3e} {peer_cost / (mse * secs):20.2f}")
    print(json.dumps({"gate": args.gate, "seconds": args.seconds, "reference_noise": noise,
                      "rows": [{"renderer": n, "spp": s, "seconds": t, "mse": m, "relative_mse": m / power}
                               for n, s, t, m in rows]}))


if __name__ == "__main__":
    main()
