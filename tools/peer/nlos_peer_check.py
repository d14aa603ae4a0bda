#!/usr/bin/env python3
"""Compare a gatetrace NLOS capture with a peer capture from tools/peer/peer_reference.py --nlos.

Renders the capture the peer file describes (scan, grid, bins, bounces, origins) with gatetrace in
independent batches (different seeds), scales each laser spot by the peer's equivalent beam power
(peer_reference.laser_equivalent_power), and reports:
  * total energy, ours against the peer's, with its z-score;
  * per-bin block z-scores: bins grouped into blocks of --pixels x --pixels sensed points x
    --block bins per channel, z = (ours - peer) / sqrt(var ours + var peer), each variance that
    of a mean over independent batches or passes; their mean and standard deviation (0 and 1 when
    the two agree), the fraction beyond 3 (0.27 % for normal noise) and the largest |z| against
    the Sidak limit for the number of blocks. Only blocks the peer reached are z-tested: where
    it had no sample in any pass its variance estimate of zero says nothing of its error (the
    grazing first and last arrivals, which area sampling reaches a few times in a million
    samples). The energy ours puts in the blocks the peer never reached is reported as a share
    of the total instead.

    tools/peer/nlos_peer_check.py PEER.npz [--method path] [--spp 8192] [--batches 8] [--block 1] [--pixels 1]
        [--worst N] [--save-ours OURS.npz]

Needs numpy; the gatetrace binary is target/release/gatetrace (built with cargo build --release).
"""
import argparse
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def render(peer_meta, args, seed, out):
    m = peer_meta
    cmd = [str(ROOT / "target/release/gatetrace"), "render", m["scene"], "--nlos", m["scan"],
           "--method", args.method, "--res", f"{args.res[0]}x{args.res[1]}",
           "--gate", f"transient:{m['start']},{m['bin_width']},{m['bins']}",
           "--max-bounces", str(m["max_bounces"]), "--spp", str(args.spp), "--seed", str(seed),
           "--relay-wall", m["relay_wall"],
           "--sensor-origin", ",".join(map(str, m["sensor_origin"])),
           "--laser-origin", ",".join(map(str, m["laser_origin"])), "-o", str(out)]
    if m["scan"] == "single":
        cmd += ["--laser-spot", ",".join(map(str, m["laser_spot_uv"]))]
    if m["integrator"].get("account_first_and_last_bounces"):
        cmd += ["--count-first-last"]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return np.load(out).astype(np.float64)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("peer", help=".npz from tools/peer/peer_reference.py --nlos")
    p.add_argument("--method", default="path")
    p.add_argument("--spp", type=int, default=8192, help="samples per pixel per batch")
    p.add_argument("--batches", type=int, default=8)
    p.add_argument("--block", type=int, default=1, help="bins per block")
    p.add_argument("--pixels", type=int, default=1, help="sensed points per block side (divides the grid)")
    p.add_argument("--alpha", type=float, default=0.01, help="family-wise false-alarm rate of the limit")
    p.add_argument("--worst", type=int, default=0, metavar="N",
                   help="also list the N blocks of largest |z|: position, bin, both means and standard "
                        "errors, and in how many of our batches the block had light")
    p.add_argument("--save-ours", metavar="OURS.npz",
                   help="also write our capture (rescaled to the peer's laser powers) as transient_mean "
                        "and transient_var (variance of the mean over the batches), [grid_y, grid_x, T, 3]")
    args = p.parse_args()
    peer = np.load(args.peer)
    meta = json.loads(str(peer["meta"]))
    peer_mean = peer["transient_mean"].astype(np.float64)
    peer_var = peer["transient_var"].astype(np.float64)
    power = peer["laser_power_equivalent"].astype(np.float64)
    args.res = (peer_mean.shape[1], peer_mean.shape[0])
    batches = []
    with tempfile.TemporaryDirectory() as tmp:
        for b in range(args.batches):
            film = render(meta, args, 1000 + b, Path(tmp) / f"b{b}.npy")
            scale = power[..., None, None] if power.shape[0] > 1 else power[0, 0]
            batches.append(film * scale)
    ours = np.mean(batches, axis=0)
    ours_var = np.var(batches, axis=0, ddof=1) / len(batches)
    if args.save_ours:
        np.savez_compressed(args.save_ours, transient_mean=ours.astype(np.float32),
                            transient_var=ours_var.astype(np.float32))

    total_o, total_p = ours.sum(), peer_mean.sum()
    var_total_o = np.var([b.sum() for b in batches], ddof=1) / len(batches)
    z_total = (total_o - total_p) / math.sqrt(var_total_o + peer_var.sum())
    print(f"{meta['scan']} {args.res[0]}x{args.res[1]}, {meta['bins']} bins of {meta['bin_width'] * 1e3:.3g} mm, "
          f"{meta['max_bounces']} bounces; ours: {args.method}, {args.batches} x {args.spp} spp; peer: "
          f"{meta['passes']} x {meta['spp_per_pass']} spp")
    print(f"total energy: ours {total_o:.6g}, peer {total_p:.6g}, ratio {total_o / total_p:.5f}, z {z_total:+.2f}")

    k, q = args.block, args.pixels
    h, w = peer_mean.shape[:2]
    if h % q or w % q:
        sys.exit(f"--pixels {q} does not divide the {w}x{h} grid")
    t = (peer_mean.shape[2] // k) * k
    block = lambda a: a[:, :, :t].reshape(h // q, q, w // q, q, t // k, k, 3).sum(axis=(1, 3, 5))
    o, ov = block(ours), block(ours_var)
    pm, pv = block(peer_mean), block(peer_var)
    # Only blocks the peer reached (see above); the rest are bounded by their energy.
    live = pv > 0
    unseen = o[~live].sum() / o.sum()
    print(f"energy ours puts in blocks the peer never reached: {unseen:.2e} of the total")
    z = (o - pm)[live] / np.sqrt((ov + pv)[live])
    n = z.size
    # The variances are estimates from few batches and passes: z is then closer to Student's t
    # than to a normal variable; the smaller side's degrees of freedom give a conservative limit.
    dof = min(args.batches, meta["passes"]) - 1
    limit = _t_quantile(math.sqrt(2) * _erfc_inv(1 - (1 - args.alpha) ** (1 / n)), dof)
    print(f"block z-scores over {n} blocks of {q}x{q} sensed point(s) x {k} bin(s) the peer reached: mean {z.mean():+.3f}, std {z.std():.3f}, "
          f"|z| > 3: {np.mean(np.abs(z) > 3) * 100:.2f} % (normal: 0.27 %), max |z| {np.abs(z).max():.2f} "
          f"(Sidak limit at alpha {args.alpha}, Student's t with {dof} dof: {limit:.2f})")
    if args.worst > 0:
        lit = block(np.array([(b != 0).astype(np.float64) for b in batches]).sum(axis=0))
        zz = np.zeros(o.shape)
        zz[live] = z
        print(f"largest |z| (block y, x of {q}x{q} sensed points; bins from {meta['start']} m, "
              f"{meta['bin_width'] * 1e3 * k:.3g} mm a block; channel):")
        for i in np.argsort(-np.abs(zz), axis=None)[:args.worst]:
            by, bx, bt, c = np.unravel_index(i, o.shape)
            print(f"  z {zz[by, bx, bt, c]:+7.2f}  block ({by}, {bx}) bin {bt * k} channel {c}: ours "
                  f"{o[by, bx, bt, c]:.4e} +- {math.sqrt(ov[by, bx, bt, c]):.2e} (light in {lit[by, bx, bt, c] / (q * q * k):.1f} "
                  f"of {len(batches)} batches), peer {pm[by, bx, bt, c]:.4e} +- {math.sqrt(pv[by, bx, bt, c]):.2e}")


def _t_quantile(z, dof):
    """Student's t quantile for the standard normal quantile z (Cornish-Fisher expansion,
    Abramowitz and Stegun 26.7.5)."""
    v = float(dof)
    return (z + (z ** 3 + z) / (4 * v) + (5 * z ** 5 + 16 * z ** 3 + 3 * z) / (96 * v ** 2)
            + (3 * z ** 7 + 19 * z ** 5 + 17 * z ** 3 - 15 * z) / (384 * v ** 3))


def _erfc_inv(y):
    """x with erfc(x) = y, by bisection (0 < y < 1)."""
    lo, hi = 0.0, 10.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if math.erfc(mid) > y:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


if __name__ == "__main__":
    sys.exit(main())
