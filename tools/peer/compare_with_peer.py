#!/usr/bin/env python3
"""Compare gatetrace renders with a peer reference, judging agreement by measured variance.

Usage: tools/peer/compare_with_peer.py PEER.npz KEY RENDER.npy [RENDER.npy ...]

PEER.npz holds KEY_mean and KEY_var (variance of the mean), e.g. the references written by
tools/peer/peer_reference.py or ../tests/data/cornell_box_peer (keys steady, gate_3_14_3_19,
transient_1_94_step_0_1). The RENDER files are independent gatetrace renders of the same
settings with different --seed values (at least 2; 8 or more give a usable variance). Arrays are
[H, W, 3] or [H, W, T, 3], values bin-integrated radiance, lengths in metres of optical path.

Prints, per channel (and per bin for cubes), our mean of the image mean, its standard error from
the spread of the renders, the peer's, and z = difference / combined standard error; then the
distribution of per-pixel z-scores. Needs numpy.
"""
import sys

import numpy as np


def main():
    if len(sys.argv) < 5:
        sys.exit(__doc__)
    peer = np.load(sys.argv[1])
    key = sys.argv[2]
    ref_mean, ref_var = peer[key + "_mean"].astype(np.float64), peer[key + "_var"].astype(np.float64)
    renders = np.stack([np.load(p).astype(np.float64) for p in sys.argv[3:]])
    if renders.shape[1:] != ref_mean.shape:
        sys.exit(f"shape mismatch: renders {renders.shape[1:]} vs peer {ref_mean.shape}")
    n = renders.shape[0]
    pixel_axes = (1, 2)
    # Image mean per render (per bin and channel), then mean and standard error over renders.
    image_means = renders.mean(axis=pixel_axes)
    ours = image_means.mean(axis=0)
    ours_se = image_means.std(axis=0, ddof=1) / np.sqrt(n)
    npix = ref_mean.shape[0] * ref_mean.shape[1]
    peer_img = ref_mean.mean(axis=(0, 1))
    peer_se = np.sqrt(ref_var.sum(axis=(0, 1))) / npix
    z = (ours - peer_img) / np.sqrt(ours_se**2 + peer_se**2)
    print(f"{n} renders; image mean per channel{' and bin' if ours.ndim > 1 else ''}:")
    rows = ours.reshape(-1, 3)
    for i, (o, s, p, q, zz) in enumerate(zip(rows, ours_se.reshape(-1, 3), peer_img.reshape(-1, 3),
                                             peer_se.reshape(-1, 3), z.reshape(-1, 3))):
        label = f"bin {i:3d}" if ours.ndim > 1 else "image"
        print(f"  {label}: ours {np.array2string(o, precision=6)} +- {np.array2string(s, precision=2)}"
              f"  peer {np.array2string(p, precision=6)} +- {np.array2string(q, precision=2)}"
              f"  z {np.array2string(zz, precision=2)}")
    print(f"  max |z| = {np.abs(z).max():.2f} over {z.size} comparisons")
    # Per-pixel z-scores.
    pix_mean = renders.mean(axis=0)
    pix_var = renders.var(axis=0, ddof=1) / n
    denom = np.sqrt(pix_var + ref_var)
    valid = denom > 0
    zp = (pix_mean - ref_mean)[valid] / denom[valid]
    print(f"per-pixel z over {zp.size} values: mean {zp.mean():+.3f}, std {zp.std():.3f}, "
          f"|z|>4: {(np.abs(zp) > 4).mean() * 100:.3f}% (student-t with {n - 1} dof expects std "
          f"{np.sqrt((n - 1) / (n - 3)) if n > 3 else float('nan'):.3f})")


if __name__ == "__main__":
    main()
