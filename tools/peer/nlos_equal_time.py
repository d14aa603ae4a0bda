#!/usr/bin/env python3
"""Error at equal time of gatetrace's NLOS methods against mitransient's transient_nlos_path, per
time-bin width, in one run.

One capture (default: the example scene's confocal 16x16 scan, three bounces) is rendered at the
finest bin width (--base-ps, default 1 ps = 0.29979 mm of optical path, --bins bins from --start);
coarser widths (--widths-ps, multiples of the base) are the same renders with neighbouring bins
summed, which is what rendering with the coarser bins gives (box bins on both sides).

1. Reference: `gatetrace render --method REF` (default ellipsoidal) in 8 batches of
   --reference-seconds / 8 each. The variance of their mean estimates the reference's own
   noise, which is subtracted from every MSE (per width).
2. Each gatetrace method renders --repeats captures of --seconds of rendering each
   (`render --time`: scene loading, BVH and kernel builds excluded).
3. The peer, mitransient's transient_nlos_path with laser sampling and hidden-geometry sampling
   on (its best NLOS options; --peer-hidden-geometry off turns the latter off), renders
   --repeats captures with the sample count its measured rate fits into --seconds, after a warm
   render (Dr.Jit's compilation excluded); its own render time is measured and reported. It
   runs as shipped, with Mitsuba's own segment lengths (tools/peer/peer_reference.py's exact lengths
   would cost it about 1.5x the time; on the example's confocal scan at 4 ps the difference is
   about 3 % of its MSE at equal time, in its disfavour).
   gatetrace's values are scaled by the peer's laser power equivalent per spot (see
   tools/peer/peer_reference.py), so both sides are in the peer's units.

Prints per bin width: each renderer's MSE (mean over pixels, bins and channels) and its accuracy
against the peer at equal time, (peer MSE x peer seconds) / (MSE x seconds); above 1: better
than the peer. Also each renderer's MSE x spp over the lowest per-sample MSE that any estimator
adding each sample to a single bin can have (bins drawn in proportion to the reference, exact
values): how far each is from that floor, and so how much any such estimator could gain on it
per sample. Also a JSON line with everything.

With --per-width, gatetrace renders each width with bins of that width instead (stratified
target lengths and the band index see the bins they render; the peer's coarser bins are exact
sums either way).

Usage: tools/peer/nlos_equal_time.py [--seconds T] [--repeats R] [--methods ellipsoidal,ellipsoidal:4,path]
           [--reference-seconds S] [--widths-ps 1,2,4,10,20,50,100] [--per-width] [--exe BINARY]
           [--reference-args '--band-index on'] [--reference-cache NPZ]
Requires: a built gatetrace (cargo build --release), numpy, mitsuba and mitransient.
"""

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
EXE = os.path.join(ROOT, "target", "release", "gatetrace")

C_MM_PER_PS = 0.299792458  # optical path per picosecond (mm)


def gatetrace_render(args, method, seconds, seed, out, extra=(), factor=1):
    """`render --nlos ... --time`; returns (capture [H, W, T, 3], rendering seconds, spp), with
    bins `factor` times the base width (and a factor-th as many).
    `method` may go on with `:K` (ellipsoidal's connections per query), `:arcs` or
    `:reflection` (its query weights), `:pilotN` (its pilot render of N spp, `--target-pilot`),
    `:split=R` (`--query-split R`) and `:index` (`--band-index on`), e.g. `ellipsoidal:1:arcs:pilot0`."""
    origin = ",".join(map(str, args.origin))
    method, *options = method.split(":")
    extra = list(extra)
    for option in options:
        if option in ("arcs", "reflection"):
            extra += ["--query-weights", option]
        elif option.isdigit():
            extra += ["--connections-per-query", option]
        elif option.startswith("pilot") and option[5:].isdigit():
            extra += ["--target-pilot", option[5:]]
        elif option.startswith("split="):
            extra += ["--query-split", option[6:]]
        elif option in ("index", "noindex"):
            extra += ["--band-index", "on" if option == "index" else "off"]
        else:
            sys.exit(f"method option {option!r}: neither a number of connections per query, arcs|reflection, "
                     "pilotN, split=R nor index|noindex")
    cmd = [args.exe, "render", args.scene, "--nlos", args.scan, "--method", method,
           "--res", f"{args.res}x{args.res}", "--max-bounces", str(args.max_bounces),
           "--gate", f"transient:{args.start},{args.base_width * factor},{args.bins // factor}",
           f"--sensor-origin={origin}", f"--laser-origin={origin}",
           "--time", str(seconds), "--seed", str(seed), "-o", out]
    if args.scan == "single":
        cmd += ["--laser-spot", ",".join(map(str, args.laser_spot))]
    cmd += extra
    text = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    m = re.search(r"\| (\d+) spp, ([0-9.]+) s rendering", text)
    if not m:
        sys.exit(f"cannot read the render's summary line:\n{text}")
    with open(os.path.splitext(out)[0] + ".json") as f:
        index = json.load(f).get("band_index")
    if index:
        print(f"  {method} x{factor}, seed {seed}: band index {index}", file=sys.stderr)
    return np.load(out).astype(np.float64), float(m.group(2)), int(m.group(1))


class PeerRenderer:
    """mitransient's transient_nlos_path on the same capture, built by tools/peer/peer_reference.py."""

    def __init__(self, args):
        import drjit as dr
        import mitsuba as mi
        import gltf_reader
        import peer_reference
        mi.set_variant("llvm_ad_rgb")
        import mitransient  # noqa: F401
        argv = [args.scene, "--nlos", args.scan, "--res", str(args.res), str(args.res),
                "--max-bounces", str(args.max_bounces), "--start", str(args.start),
                "--bin-width", str(args.base_width), "--bins", str(args.bins),
                "--sensor-origin", *map(str, args.origin), "--laser-origin", *map(str, args.origin),
                "--laser-spot", *map(str, args.laser_spot)]
        if args.peer_hidden_geometry == "on":
            argv.append("--hidden-geometry-sampling")
        pargs = peer_reference.parse_args(argv)
        scene_data = gltf_reader.load_gltf(args.scene)
        scene_dict, point_at, _, laser_origin = peer_reference.build_nlos_scene(mi, scene_data, pargs)
        self.integrator_dict = scene_dict["integrator"]
        self.scene = mi.load_dict(scene_dict)
        self.integrator = self.scene.integrator()
        self.chunk = 1024
        res = args.res
        cells = np.array([[point_at((i + 0.5) / res, (j + 0.5) / res) for i in range(res)] for j in range(res)])
        normal = np.cross(point_at(1, 0) - point_at(0, 0), point_at(0, 1) - point_at(0, 0))
        normal /= np.linalg.norm(normal)
        targets = cells if args.scan == "confocal" else point_at(*args.laser_spot)[None, None, :]
        self.power = peer_reference.laser_equivalent_power(point_at, laser_origin, normal, targets)
        self.dr = dr

    def render(self, spp, seed):
        """(capture [H, W, T, 3], seconds): spp samples per pixel in chunks, evaluated in the time."""
        start = time.perf_counter()
        total = 0.0
        left, k = spp, 0
        while left > 0:
            n = min(self.chunk, left)
            _, t_img = self.integrator.render(self.scene, seed=seed * 100003 + k, spp=n)
            total = total + np.array(t_img, dtype=np.float64)[..., :3] * n
            left -= n
            k += 1
        return total / spp, time.perf_counter() - start


def coarsen(capture, factor):
    """Sums groups of `factor` neighbouring bins (axis 2)."""
    h, w, t, c = capture.shape
    return capture[:, :, : t - t % factor].reshape(h, w, t // factor, factor, c).sum(axis=3)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", default=os.path.join(ROOT, "assets", "scenes", "nlos_letter.gltf"))
    p.add_argument("--scan", choices=["confocal", "single"], default="confocal")
    p.add_argument("--laser-spot", nargs=2, type=float, default=[0.3, 0.6], metavar=("U", "V"),
                   help="single scans: the spot's texture coordinates (default 0.3 0.6)")
    p.add_argument("--origin", nargs=3, type=float, default=[-1.2, 0.0, 0.6], metavar=("X", "Y", "Z"),
                   help="sensor and laser origin, m (default the example scene's)")
    p.add_argument("--res", type=int, default=16, help="square grid of sensed points (default 16)")
    p.add_argument("--max-bounces", type=int, default=3, help="bounces, spot and sensed point included (default 3)")
    p.add_argument("--start", type=float, default=0.9, help="start of the first bin, m (default 0.9)")
    p.add_argument("--base-ps", type=float, default=1.0, help="finest bin width, ps (default 1)")
    p.add_argument("--bins", type=int, default=4000, help="bins of the finest width (default 4000: 1.2 m)")
    p.add_argument("--widths-ps", default="1,2,4,10,20,50,100",
                   help="bin widths reported, ps, multiples of --base-ps (default 1,2,4,10,20,50,100)")
    p.add_argument("--seconds", type=float, default=10.0, help="seconds of rendering per capture (default 10)")
    p.add_argument("--repeats", type=int, default=2, help="captures per renderer (default 2)")
    p.add_argument("--methods", default="ellipsoidal,ellipsoidal:4,path",
                   help="gatetrace methods; ellipsoidal:K with K connections per query, ellipsoidal:arcs "
                        "with arc weights, ellipsoidal:pilotN with a pilot of N spp (default "
                        "ellipsoidal,ellipsoidal:4,path; `render --nlos` gives ellipsoidal K = 1 and a 256-spp pilot)")
    p.add_argument("--reference-method", default="ellipsoidal")
    p.add_argument("--reference-seconds", type=float, default=240.0,
                   help="seconds of rendering of the reference, in 8 batches (default 240)")
    p.add_argument("--exe", default=EXE, help=f"the gatetrace binary (default {EXE})")
    p.add_argument("--per-width", action="store_true",
                   help="render gatetrace's captures at each width of --widths-ps (bins of that width) instead of "
                        "summing the finest; the peer's sums are exact either way")
    p.add_argument("--reference-args", default="",
                   help="extra options for the reference's renders, e.g. '--band-index on'")
    p.add_argument("--reference-cache", metavar="NPZ",
                   help="reuse the reference stored in this file, or store it there (same capture settings)")
    p.add_argument("--gatetrace-args", default="",
                   help="extra options for the compared gatetrace renders (not the reference), e.g. "
                        "'--connections-per-query 2'")
    p.add_argument("--peer-hidden-geometry", choices=["on", "off"], default="on",
                   help="mitransient's nlos_hidden_geometry_sampling (default on)")
    args = p.parse_args()
    if not os.path.exists(args.exe):
        sys.exit(f"{args.exe} not found: run cargo build --release first")
    args.base_width = args.base_ps * C_MM_PER_PS * 1e-3
    factors = []
    for w in args.widths_ps.split(","):
        f = float(w) / args.base_ps
        if abs(f - round(f)) > 1e-9 or round(f) < 1:
            sys.exit(f"--widths-ps {w}: not a multiple of --base-ps {args.base_ps}")
        factors.append(int(round(f)))

    peer = PeerRenderer(args)
    power = peer.power[:, :, None, None] if peer.power.ndim == 2 else float(peer.power.ravel()[0])
    tmp = tempfile.mkdtemp(prefix="nlos_equal_time_")
    out = os.path.join(tmp, "capture.npy")

    batches = 8
    if args.reference_cache and os.path.exists(args.reference_cache):
        cached = np.load(args.reference_cache)
        ref_stack, ref_spp, ref_seconds = list(cached["stack"]), int(cached["spp"]), float(cached["seconds"])
        if ref_stack[0].shape != (args.res, args.res, args.bins, 3):
            sys.exit(f"{args.reference_cache}: a reference of shape {ref_stack[0].shape}, not this capture's")
    else:
        refs = [gatetrace_render(args, args.reference_method, args.reference_seconds / batches, 9000 + k, out,
                                 args.reference_args.split())
                for k in range(batches)]
        ref_stack = [r[0] * power for r in refs]
        ref_spp, ref_seconds = sum(r[2] for r in refs), sum(r[1] for r in refs)
        if args.reference_cache:
            np.savez(args.reference_cache, stack=np.stack(ref_stack), spp=ref_spp, seconds=ref_seconds)
    print(f"{os.path.basename(args.scene)}: {args.scan} {args.res}x{args.res}, {args.max_bounces} bounces, "
          f"{args.bins} bins of {args.base_ps} ps from {args.start} m")
    print(f"reference: {args.reference_method}, {ref_spp} spp in {ref_seconds:.0f} s")

    runs = []
    # With --per-width, gatetrace renders every width with bins of that width (runs_at[f]); the
    # peer's coarser bins are exactly sums of its finer ones.
    runs_at = {}
    for method in args.methods.split(","):
        for f in (factors if args.per_width else [1]):
            results = [gatetrace_render(args, method, args.seconds, 100 + k, out, args.gatetrace_args.split(), f)
                       for k in range(args.repeats)]
            runs_at.setdefault(f, []).append(
                (f"gatetrace {method}", [(img * power, secs, spp) for img, secs, spp in results]))
        if not args.per_width:
            runs.append(runs_at[1][-1])
    probe = 512  # large enough that the rate is not that of per-render overheads
    peer.render(probe, 0)
    _, t = peer.render(probe, 1)
    spp = max(1, int(probe * args.seconds / t))
    label = f"mitransient (hidden geometry {args.peer_hidden_geometry})"
    peer_run = (label, [(*peer.render(spp, 200 + k), spp) for k in range(args.repeats)])
    runs.append(peer_run)

    table = []
    for f in factors:
        stack = np.stack([coarsen(r, f) for r in ref_stack])
        reference = stack.mean(axis=0)
        noise = (stack.var(axis=0, ddof=1) / batches).mean()
        rows = []
        for name, results in (runs_at[f] + [peer_run] if args.per_width else runs):
            # A render at this width already has its bins (per_width); the rest are summed.
            rendered_at = f if args.per_width and name != peer_run[0] else 1
            mse = np.mean([((coarsen(img, f // rendered_at) - reference) ** 2).mean() - noise for img, _, _ in results])
            rows.append({"renderer": name, "spp": float(np.mean([r[2] for r in results])),
                         "seconds": float(np.mean([r[1] for r in results])), "mse": float(mse)})
        peer_cost = rows[-1]["mse"] * rows[-1]["seconds"]
        for row in rows:
            row["vs_peer_equal_time"] = peer_cost / (row["mse"] * row["seconds"])
        # Lowest variance per sample of any estimator that adds each sample's contribution to
        # one bin: with bin b drawn with probability P_b and value V, sum_b E[V^2; b] >=
        # sum_b I_b^2 / P_b >= (sum_b I_b)^2 (Cauchy-Schwarz), so the summed variance is at
        # least (sum_b I_b)^2 - sum_b I_b^2, reached by P_b proportional to I_b and exact values.
        # As a mean over bins like the MSE: per-sample MSE can not go below this `floor`.
        total, squares, bins = reference.sum(axis=2), (reference ** 2).sum(axis=2), reference.shape[2]
        floor = ((total ** 2 - squares) / bins).mean()
        # The same with bins drawn uniformly (P_b = 1 / bins), exact values otherwise.
        uniform_floor = ((bins * squares - squares) / bins).mean()
        for row in rows:
            row["mse_per_sample_over_floor"] = row["mse"] * row["spp"] / floor
        table.append({"width_ps": f * args.base_ps, "reference_noise": float(noise),
                      "mean_square": float((reference ** 2).mean()), "single_bin_floor": float(floor),
                      "uniform_bins_floor": float(uniform_floor),
                      "rows": rows})

    print(f"{'width':>8} {'renderer':>34} {'spp':>8} {'seconds':>8} {'MSE':>11} {'vs peer, equal time':>20}"
          f" {'MSE x spp / floor':>18}")
    for entry in table:
        for row in entry["rows"]:
            print(f"{entry['width_ps']:6.0f}ps {row['renderer']:>34} {row['spp']:8.0f} {row['seconds']:8.2f} "
                  f"{row['mse']:11.3e} {row['vs_peer_equal_time']:20.2f} {row['mse_per_sample_over_floor']:18.2f}")
        print(f"{'':8} {'reference noise':>34} {'':8} {'':8} {entry['reference_noise']:11.3e}")
        print(f"{'':8} {'exact values, bins drawn uniformly':>34} {'':8} {'':8} {'':11} {'':20} "
              f"{entry['uniform_bins_floor'] / entry['single_bin_floor']:18.2f}")
    print(json.dumps({"scene": args.scene, "scan": args.scan, "res": args.res, "seconds": args.seconds,
                      "peer_integrator": peer.integrator_dict, "widths": table}))


if __name__ == "__main__":
    main()
