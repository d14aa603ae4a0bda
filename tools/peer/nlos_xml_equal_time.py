#!/usr/bin/env python3
"""Error at equal time of gatetrace and mitransient on an NLOS capture described in a Mitsuba 3 XML
scene, both rendering the same file, in one run.

    tools/peer/nlos_xml_equal_time.py SCENE.xml REFERENCE_PREFIX [--param NAME=VALUE ...]
        [--seconds T] [--repeats R] [--methods path,direct,ellipsoidal] [--exe BINARY]

REFERENCE_PREFIX names a long render of the same capture as `tools/peer/nlos_xml_reference.py`
writes it (PREFIX_mean.npy and PREFIX_var.npy, e.g. tests/data/nlos_panels_peer/single): its own
noise (the variance of its mean, summed) is subtracted from every MSE.

1. gatetrace renders the file with each method, --repeats captures of --seconds of rendering each
   (`render --time`: scene loading, BVH and kernel builds excluded; the capture's defaults
   otherwise).
2. mitransient renders it as `nlos_xml_reference.py` sets it up, twice over: with the file's
   hidden-geometry sampling (its best NLOS option, biased where hidden objects occlude each
   other) and without (unbiased BSDF sampling). Each renders --repeats captures with the sample
   count its measured rate fits into --seconds, after a warm render (Dr.Jit's compilation
   excluded); its own render time is measured and reported.

Prints each renderer's samples per point, seconds, MSE (mean over points, bins and channels,
the reference's noise subtracted) and its accuracy against unbiased mitransient at equal time,
(peer MSE x peer seconds) / (MSE x seconds): above 1, better than the peer.

Requires: a built gatetrace (cargo build --release), numpy, mitsuba and mitransient.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from nlos_xml_reference import load_capture  # noqa: E402
from peer_reference import use_exact_segment_lengths  # noqa: E402

EXE = HERE.parent.parent / "target" / "release" / "gatetrace"


def gatetrace_capture(args, method, seed, out):
    """(capture, spp, rendering seconds) of `render SCENE --time T --method METHOD`."""
    command = [str(args.exe), "render", args.scene, "--time", str(args.seconds), "--method", method,
               "--seed", str(seed), "--out", out]
    for kv in args.param:
        command += ["-D", kv]
    subprocess.run(command, check=True, capture_output=True)
    meta = json.loads(Path(out).with_suffix(".json").read_text())
    return np.load(out).astype(np.float64), meta["spp"], meta["rendering_seconds"]


class Peer:
    """mitransient rendering the file, with or without its hidden-geometry sampling."""

    def __init__(self, args, grid, hidden_geometry_sampling):
        import drjit as dr
        import mitsuba as mi
        import mitransient as mitr
        use_exact_segment_lengths(mi, dr)
        params = dict(kv.split("=", 1) for kv in args.param)
        self.scene = load_capture(mi, mitr, args.scene, grid, None, params, hidden_geometry_sampling)
        self.integrator = self.scene.integrator()

    def render(self, spp, seed):
        start = time.perf_counter()
        _, t = self.integrator.render(self.scene, seed=seed, spp=spp)
        data = np.array(t, dtype=np.float64)[..., :3]
        return data, time.perf_counter() - start


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene")
    p.add_argument("reference", help="prefix of the reference's _mean.npy and _var.npy")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE")
    p.add_argument("--seconds", type=float, default=10.0, help="rendering time of each capture")
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--methods", default="path,direct,ellipsoidal")
    p.add_argument("--exe", default=str(EXE))
    args = p.parse_args()

    reference = np.load(args.reference + "_mean.npy").astype(np.float64)
    reference_noise = float(np.load(args.reference + "_var.npy").astype(np.float64).mean())
    grid = (reference.shape[1], reference.shape[0])

    def mse(x):
        return float(((x - reference) ** 2).mean()) - reference_noise

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for method in args.methods.split(","):
            for r in range(args.repeats):
                data, spp, seconds = gatetrace_capture(args, method, r + 1, os.path.join(tmp, f"{method}{r}.npy"))
                rows.append((f"gatetrace {method}", spp, seconds, mse(data)))
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    for hg in (False, True):
        peer = Peer(args, grid, hg)
        _, warm = peer.render(256, 99)
        _, timed = peer.render(4096, 98)
        spp = max(1, int(4096 * args.seconds / timed))
        for r in range(args.repeats):
            data, seconds = peer.render(spp, r + 1)
            rows.append((f"mitransient, hidden-geometry sampling {'on' if hg else 'off'}", spp, seconds, mse(data)))
    names = list(dict.fromkeys(name for name, *_ in rows))
    summary = {}
    for name in names:
        mine = [(spp, s, m) for n, spp, s, m in rows if n == name]
        summary[name] = tuple(float(np.mean(v)) for v in zip(*mine))
    peer_spp, peer_seconds, peer_mse = summary["mitransient, hidden-geometry sampling off"]
    print(f"{args.scene} {' '.join(args.param)}: reference noise {reference_noise:.3e} per value")
    print(f"{'renderer':<46} {'spp':>9} {'seconds':>8} {'MSE':>10} {'vs peer':>8}")
    for name in names:
        spp, seconds, m = summary[name]
        ratio = peer_mse * peer_seconds / (m * seconds)
        print(f"{name:<46} {spp:>9.0f} {seconds:>8.2f} {m:>10.3e} {ratio:>8.2f}")
    print(json.dumps({"rows": rows, "reference_noise": reference_noise}))


if __name__ == "__main__":
    main()
