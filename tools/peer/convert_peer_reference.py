#!/usr/bin/env python3
"""Unpack a peer-reference .npz (as written by tools/peer/peer_reference.py or shipped with the
canonical scenes) into one float32 .npy per array, the form the Rust tests read.

Usage: tools/peer/convert_peer_reference.py REFERENCE.npz OUT_DIR

Every array keeps its layout: images [H, W, 3] and transient cubes [H, W, T, 3], row 0 at the
top, values bin-integrated radiance with lengths in metres of optical path. `*_var` arrays are
the variance of the corresponding `*_mean` (variance of a mean over independent passes).
Needs numpy.
"""
import os
import sys

import numpy as np


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    src, out = sys.argv[1], sys.argv[2]
    os.makedirs(out, exist_ok=True)
    data = np.load(src)
    for key in data.files:
        arr = data[key]
        if arr.dtype.kind != "f":
            continue
        path = os.path.join(out, key + ".npy")
        np.save(path, np.ascontiguousarray(arr, dtype=np.float32))
        print(f"{path}: {arr.shape}")


if __name__ == "__main__":
    main()
