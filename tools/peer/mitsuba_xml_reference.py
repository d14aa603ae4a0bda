#!/usr/bin/env python3
"""Render peer reference data for a Mitsuba 3 XML scene with Mitsuba 3 + mitransient, reading the
very file gatetrace reads (no conversion), for the tests that compare gatetrace's Mitsuba loader
with the peer.

    tools/peer/mitsuba_xml_reference.py SCENE.xml OUT_DIR [--res N] [--spp S] [--passes P]
        [--param NAME=VALUE ...] [--key KEY] [--variant llvm_ad_rgb]

The scene must use one of mitransient's integrators `transient_path` (surfaces) or
`transient_prbvolpath` (surfaces and participating media), which is rendered as the file sets it,
and a `transient_hdr_film`.
`--param` values replace the file's `<default>`s (`res` is set from --res); `--res`, `--spp`
go to `mi.load_file` as the parameters `res` and `spp`. The film's width and height must
therefore read `$res`.

Writes, float32, row 0 at the top, RGB last, `*_mean` the average over passes and `*_var` the
variance of that average:
* `KEY_steady_mean.npy`, `KEY_steady_var.npy`: the steady image [H, W, 3];
* `KEY_transient_mean.npy`, `KEY_transient_var.npy`: the transient cube [H, W, T, 3], bin b
  the film's [start_opl + b width, start_opl + (b + 1) width) in the file's units.

Mitsuba's perspective camera starts its rays on the near clip plane and mitransient measures
the camera's segment from there: a scene compared with gatetrace (which measures it from the
pinhole) should set a negligible `near_clip`.

Requirements: pip install mitsuba==3.9.1 mitransient==1.3.1 numpy (plus libllvm19 for llvm
variants).
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", help="Mitsuba 3 XML scene")
    p.add_argument("out_dir", help="directory for the .npy files")
    p.add_argument("--res", type=int, default=64, help="image width and height in pixels (parameter `res`)")
    p.add_argument("--spp", type=int, default=1024, help="samples per pixel of one pass (parameter `spp`)")
    p.add_argument("--passes", type=int, default=8, help="independent passes (seeds 0..P-1)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help="another parameter")
    p.add_argument("--key", default="xml", help="prefix of the output files")
    p.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant")
    args = p.parse_args(argv)

    import mitsuba as mi
    mi.set_variant(args.variant)
    import mitransient  # noqa: F401  (registers transient_path, transient_prbvolpath and transient_hdr_film)

    params = dict(kv.split("=", 1) for kv in args.param)
    params.update(res=str(args.res), spp=str(args.spp))
    scene = mi.load_file(args.scene, **params)
    steady, transient = [], []
    started = time.time()
    for seed in range(args.passes):
        s, t = mi.render(scene, spp=args.spp, seed=seed)
        steady.append(np.array(s, dtype=np.float64)[..., :3])
        transient.append(np.array(t, dtype=np.float64)[..., :3])
        print(f"pass {seed + 1}/{args.passes}: {time.time() - started:.1f} s", file=sys.stderr)
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for name, passes in (("steady", steady), ("transient", transient)):
        a = np.stack(passes)
        np.save(out / f"{args.key}_{name}_mean.npy", a.mean(axis=0).astype(np.float32))
        np.save(out / f"{args.key}_{name}_var.npy", (a.var(axis=0, ddof=1) / len(a)).astype(np.float32))
        print(f"{name}: shape {a.shape[1:]}, mean {a.mean(axis=tuple(range(a.ndim - 1)))}")


if __name__ == "__main__":
    main()
