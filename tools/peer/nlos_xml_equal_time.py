#!/usr/bin/env python3
"""Error at equal time of gatetrace and mitransient on an NLOS capture described in a Mitsuba 3 XML
scene, both rendering the same file, in one run, and where each side's error lies.

    tools/peer/nlos_xml_equal_time.py SCENE.xml [REFERENCE_PREFIX] [--param NAME=VALUE ...]
        [--seconds T[,T...]] [--repeats R] [--methods path,direct,ellipsoidal] [--grid WxH]
        [--peer-sampling off,on] [--exe BINARY]

The error of a renderer is measured one of two ways:
- With REFERENCE_PREFIX, a long render of the same capture as `tools/peer/nlos_xml_reference.py`
  writes it (PREFIX_mean.npy and PREFIX_var.npy, e.g. tests/data/nlos_panels_peer/single): the
  MSE against it, its own noise (the variance of its mean) subtracted.
- Without, the variance across the --repeats captures (at least 2) of each renderer: the MSE of
  an unbiased one. Fine bins (`--param bins=1700 --param bin_width=0.0011992` on
  assets/scenes/nlos_panels.xml: 4 ps) need no reference this way. mitransient's hidden-geometry
  sampling is biased where hidden objects occlude each other, which its variance does not show.

1. gatetrace renders the file with each method, --repeats captures of each budget in --seconds
   (`render --time`: scene loading, BVH and kernel builds excluded; the capture's defaults
   otherwise).
2. mitransient renders it as `nlos_xml_reference.py` sets it up, without its hidden-geometry
   sampling (unbiased BSDF sampling: `off`) and with the file's (`on`; its best NLOS option).
   Each renders --repeats captures per budget with the sample count its measured rate fits into
   it, after a warm render (Dr.Jit's compilation excluded); its own render time is measured and
   reported.

Prints per budget each renderer's samples per point, seconds, MSE (mean over points, bins and
channels) and its accuracy at equal time against mitransient without (`vs off`) and with (`vs on`)
its hidden-geometry sampling, (peer MSE x peer seconds) / (MSE x seconds): above 1, better than
the peer. Then where each renderer's error lies: the
shares of its squared error (summed over the channels) in each point's onset bins (the first 4
from the first bin that holds 1e-3 of the point's light; light from the reference, or from all
gatetrace captures pooled), in the bins before the onset, in the tail (after 99 % of the point's
light), in the middle, and in the tenth of the points with the most error. Last, a JSON line with
everything.

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
ONSET_BINS = 4
ONSET_THRESHOLD = 1e-3
TAIL_FRACTION = 0.99
WARNED = set()


def gatetrace_capture(args, method, seconds, seed, out):
    """(capture, spp, rendering seconds) of `render SCENE --time T --method METHOD`."""
    command = [str(args.exe), "render", args.scene, "--time", str(seconds), "--method", method,
               "--seed", str(seed), "--out", out]
    if args.grid:
        command += ["--res", args.grid]
    for kv in args.param:
        command += ["-D", kv]
    done = subprocess.run(command, check=True, capture_output=True, text=True)
    # Warnings that the two renderers do not render the same capture (a sensed point hidden from
    # the sensor origin, a laser beam blocked before the wall), printed once.
    for line in done.stderr.splitlines():
        if ("hidden from the sensor" in line or "meets other geometry" in line) and line not in WARNED:
            WARNED.add(line)
            print(f"gatetrace {line}\n  (mitransient's meter samples the wall regardless: the comparison is not like for "
                  "like)", file=sys.stderr)
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


def bin_classes(light):
    """Boolean masks over [y, x, bin] (light summed over the channels): onset, before, tail,
    middle (see the module's docstring)."""
    total = light.sum(-1, keepdims=True)
    lit = light > ONSET_THRESHOLD * total
    first = np.where(lit.any(-1), np.argmax(lit, -1), light.shape[-1])[..., None]
    index = np.arange(light.shape[-1])[None, None, :]
    onset = (index >= first) & (index < first + ONSET_BINS)
    before = index < first
    # Light before each bin, as a fraction of the point's.
    preceding = (np.cumsum(light, -1) - light) / np.where(total > 0, total, 1.0)
    tail = ~onset & ~before & (preceding > TAIL_FRACTION)
    middle = ~onset & ~before & ~tail
    return {"onset": onset, "before": before, "middle": middle, "tail": tail}


def shares(error, classes):
    """Shares of `error` ([y, x, bin], summed over channels) in each class and in the worst tenth
    of the points."""
    total = float(error.sum())
    out = {name: float(error[mask].sum()) / total for name, mask in classes.items()}
    per_point = np.sort(error.sum(-1).ravel())[::-1]
    out["worst tenth of points"] = float(per_point[:max(1, per_point.size // 10)].sum()) / total
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene")
    p.add_argument("reference", nargs="?", help="prefix of the reference's _mean.npy and _var.npy (else: "
                                                "variance across the repeats)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE")
    p.add_argument("--seconds", default="10", help="rendering time of each capture, or a comma-separated list of "
                                                    "budgets (s)")
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--methods", default="path,direct,ellipsoidal")
    p.add_argument("--grid", help="sensed points WIDTHxHEIGHT (default: the reference's, else the file's)")
    p.add_argument("--peer-sampling", default="off,on",
                   help="mitransient's hidden-geometry sampling: off (unbiased, the ratios' base) and/or on")
    p.add_argument("--exe", default=str(EXE))
    args = p.parse_args()
    budgets = [float(s) for s in args.seconds.split(",")]
    peer_modes = args.peer_sampling.split(",")
    if "off" not in peer_modes or not set(peer_modes) <= {"off", "on"}:
        p.error("--peer-sampling must list off (the base of the ratios), and may list on")
    if args.reference is None and args.repeats < 2:
        p.error("without a reference the error is the variance across repeats: --repeats 2 or more")

    reference = reference_noise = None
    if args.reference:
        reference = np.load(args.reference + "_mean.npy").astype(np.float64)
        reference_noise = float(np.load(args.reference + "_var.npy").astype(np.float64).mean())
        args.grid = args.grid or f"{reference.shape[1]}x{reference.shape[0]}"

    captures = {}  # (renderer, budget) -> list of (capture, spp, seconds)
    with tempfile.TemporaryDirectory() as tmp:
        for budget in budgets:
            for method in args.methods.split(","):
                for r in range(args.repeats):
                    out = os.path.join(tmp, f"{method}{r}.npy")
                    captures.setdefault((f"gatetrace {method}", budget), []).append(
                        gatetrace_capture(args, method, budget, r + 1, out))
    shape = next(iter(captures.values()))[0][0].shape
    grid = (shape[1], shape[0])
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    for mode in peer_modes:
        peer = Peer(args, grid, mode == "on")
        peer.render(256, 99)
        _, timed = peer.render(4096, 98)
        for budget in budgets:
            spp = max(1, int(4096 * budget / timed))
            for r in range(args.repeats):
                data, seconds = peer.render(spp, r + 1)
                captures.setdefault((f"mitransient, hidden-geometry sampling {mode}", budget), []).append(
                    (data, spp, seconds))

    if reference is not None:
        light = reference.sum(-1)
    else:
        light = np.mean([c for (name, _), runs in captures.items() if name.startswith("gatetrace")
                         for c, _, _ in runs], axis=0).sum(-1)
    classes = bin_classes(light)

    def error_per_bin(runs):
        """Squared error per [y, x, bin], summed over channels, and the MSE per value."""
        stack = np.stack([c for c, _, _ in runs])
        if reference is not None:
            per_bin = ((stack - reference) ** 2).mean(0).sum(-1)
            return per_bin, float(per_bin.mean()) / 3 - reference_noise
        per_bin = stack.var(0, ddof=1).sum(-1)
        return per_bin, float(per_bin.mean()) / 3

    summary = {}
    for key, runs in captures.items():
        per_bin, mse = error_per_bin(runs)
        spp, seconds = (float(np.mean([r[i] for r in runs])) for i in (1, 2))
        summary[key] = {"spp": spp, "seconds": seconds, "mse": mse, "shares": shares(per_bin, classes)}

    how = (f"against {args.reference} (its noise {reference_noise:.3e} per value subtracted)" if reference is not None
           else f"variance across {args.repeats} captures each")
    print(f"{args.scene} {' '.join(args.param)} grid {grid[0]}x{grid[1]}, {shape[2]} bins: MSE {how}")
    names = list(dict.fromkeys(name for name, _ in captures))
    for budget in budgets:
        bases = {mode: summary[(f"mitransient, hidden-geometry sampling {mode}", budget)] for mode in peer_modes}
        print(f"\nbudget {budget:g} s")
        print(f"{'renderer':<46} {'spp':>9} {'seconds':>8} {'MSE':>10} " + " ".join(f"{'vs ' + m:>8}" for m in bases))
        for name in names:
            s = summary[(name, budget)]
            ratios = [b["mse"] * b["seconds"] / (s["mse"] * s["seconds"]) for b in bases.values()]
            print(f"{name:<46} {s['spp']:>9.0f} {s['seconds']:>8.2f} {s['mse']:>10.3e} "
                  + " ".join(f"{r:>8.2f}" for r in ratios))
        print(f"{'shares of the squared error':<46} " + " ".join(f"{c:>8}" for c in next(iter(summary.values()))["shares"]))
        for name in names:
            print(f"{name:<46} " + " ".join(f"{v:>8.3f}" for v in summary[(name, budget)]["shares"].values()))
    light_shares = {name: float(light[mask].sum() / light.sum()) for name, mask in classes.items()}
    print(f"\nshares of the light: " + ", ".join(f"{k} {v:.4f}" for k, v in light_shares.items()))
    print(json.dumps({"rows": [{"renderer": n, "budget": b, **s} for (n, b), s in summary.items()],
                      "light_shares": light_shares, "reference_noise": reference_noise}))


if __name__ == "__main__":
    main()
