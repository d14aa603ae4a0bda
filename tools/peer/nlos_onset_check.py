#!/usr/bin/env python3
"""Checks the arrival edges of an NLOS capture of a planar hidden object at fine bins against
quadrature, for gatetrace and for the peer (Mitsuba 3 + mitransient), and tests one explanation
of a difference: Mitsuba measures each segment from a ray origin offset off the surface.

    tools/peer/nlos_onset_check.py PEER.npz [--method ellipsoidal] [--spp 4096] [--batches 16]

PEER.npz is a capture written by `tools/peer/peer_reference.py --nlos single|confocal` (its sensed
points, laser spots, bins and origins are reused). The tool renders gatetrace's capture of the
same setup in --batches independent batches, then integrates the three-bounce transient
(laser spot -> hidden point -> sensed point) of the hidden node over its plane by the midpoint
rule on a grid of --cell metres, ignoring occlusion (the wall and the hidden object must see each
other). For every sensed point whose light starts with the hidden object's (others, e.g. lit
first by an occluder, are left out) it z-tests the first bins from the arrival edge on against
the quadrature, for ours and for the peer (a bin a side never sampled in any batch or pass has no
variance estimate: counted, not tested), twice:
- with exact path lengths;
- with the first hidden segment shortened as Mitsuba's spawned rays shorten it: their origin
  lies (1 + max |x_s|) x 1500 x 2^-24 m off the wall along its normal (Mitsuba's RayEpsilon), so
  the distance to the hit is that much times the cosine at the wall shorter than the segment.
Peer data made with `tools/peer/peer_reference.py --mitsuba-segment-lengths` fits the second; the
tool's default (exact segment lengths) should fit the first.

Needs the release build (cargo build --release). Standard library + numpy;
tools/peer/gltf_reader.py, tools/peer/nlos_peer_check.py's renders.
"""
import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
import nlos_peer_check
import gltf_reader

MITSUBA_RAY_EPSILON = 1500 * 2.0 ** -24  # Mitsuba 3's math::RayEpsilon<float>


def planar_triangles(scene, node):
    """The node's triangles (m) in 2D coordinates of their common plane, the plane's origin,
    unit axes and normal, and the material's albedo and sidedness."""
    mesh = next((m for m in scene["meshes"] if m["node"] == node), None)
    if mesh is None:
        raise SystemExit(f"no mesh node named '{node}'")
    pos = mesh["positions"].astype(np.float64)
    tris = pos[mesh["faces"]]
    n = np.cross(tris[0, 1] - tris[0, 0], tris[0, 2] - tris[0, 0])
    n /= np.linalg.norm(n)
    if np.abs((pos - pos[0]) @ n).max() > 1e-6:
        raise SystemExit(f"the node '{node}' is not planar")
    e0 = tris[0, 1] - tris[0, 0]
    e0 /= np.linalg.norm(e0)
    e1 = np.cross(n, e0)
    flat = np.stack([(tris - pos[0]) @ e0, (tris - pos[0]) @ e1], axis=-1)
    return flat, pos[0], e0, e1, n, mesh["material"]


def inside(flat, x, y):
    hit = np.zeros(x.shape, bool)
    for a, b, c in flat:
        s = [(q[0] - p[0]) * (y - p[1]) - (q[1] - p[1]) * (x - p[0]) for p, q in ((a, b), (b, c), (c, a))]
        hit |= ((s[0] >= 0) & (s[1] >= 0) & (s[2] >= 0)) | ((s[0] <= 0) & (s[1] <= 0) & (s[2] <= 0))
    return hit


def quadrature(plane, wall_normal, albedo, sensed, spot, start, width, first, count, cell, ray_offset):
    """Bins first .. first + count of the three-bounce transient at `sensed` lit from `spot` by
    1 W, per unit albedo product: the midpoint rule over the plane's triangles."""
    flat, origin, e0, e1, n, material = plane
    lo, hi = start + width * first, start + width * (first + count)
    xs = np.arange(flat[..., 0].min(), flat[..., 0].max(), cell) + cell / 2
    ys = np.arange(flat[..., 1].min(), flat[..., 1].max(), cell) + cell / 2
    out = np.zeros(count)
    for i in range(0, len(ys), 128):
        u, v = np.meshgrid(xs, ys[i:i + 128])
        h = origin + u[..., None] * e0 + v[..., None] * e1
        to_s, to_l = sensed - h, spot - h
        ds, dl = np.linalg.norm(to_s, axis=-1), np.linalg.norm(to_l, axis=-1)
        cos_s = -(to_s @ wall_normal) / ds
        length = ds + dl - ray_offset * cos_s
        keep = (length >= lo) & (length < hi)
        if not keep.any():
            continue
        hit = inside(flat, u[keep], v[keep])
        cos_hs, cos_hl = (to_s[keep] @ n) / ds[keep], (to_l[keep] @ n) / dl[keep]
        cos_l = -(to_l[keep] @ wall_normal) / dl[keep]
        ok = hit & (cos_hs * cos_hl > 0) & (cos_s[keep] > 0) & (cos_l > 0)
        if not material["double_sided"]:
            ok &= cos_hs > 0
        g = cos_l * np.abs(cos_hl) / dl[keep] ** 2 * np.abs(cos_hs) * cos_s[keep] / ds[keep] ** 2 * cell * cell
        np.add.at(out, ((length[keep][ok] - lo) / width).astype(int), g[ok])
    return out


def render_ours(peer_meta, peer, args):
    """Mean and variance of the mean of gatetrace's capture of the peer's setup, in the peer's
    units (each spot at the projector's equivalent beam power)."""
    args.res = (peer["transient_mean"].shape[1], peer["transient_mean"].shape[0])
    power = peer["laser_power_equivalent"].astype(np.float64)
    power = power[..., None] if power.size > 1 else float(power.ravel()[0])
    batches = []
    with tempfile.TemporaryDirectory() as tmp:
        for b in range(args.batches):
            film = nlos_peer_check.render(peer_meta, args, args.seed + b, Path(tmp) / "capture.npy")
            batches.append(film[..., 0] * power)
            print(f"batch {b + 1}/{args.batches}", file=sys.stderr)
    batches = np.stack(batches)
    return batches.mean(0), batches.var(0, ddof=1) / len(batches)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("peer", help="capture from tools/peer/peer_reference.py --nlos (npz)")
    p.add_argument("--hidden", default="hidden_letter", help="the planar hidden node (default hidden_letter)")
    p.add_argument("--method", default="ellipsoidal", help="gatetrace's method (default ellipsoidal)")
    p.add_argument("--spp", type=int, default=4096, help="samples per pixel of each batch (default 4096)")
    p.add_argument("--batches", type=int, default=16, help="independent batches (default 16)")
    p.add_argument("--seed", type=int, default=1000, help="seed of the first batch (default 1000)")
    p.add_argument("--cell", type=float, default=1.5e-4, help="quadrature grid spacing (m; default 1.5e-4)")
    p.add_argument("--edge-bins", type=int, default=4, help="bins tested from the arrival edge on (default 4)")
    args = p.parse_args()

    peer = np.load(args.peer)
    meta = json.loads(str(peer["meta"]))
    scene_path = ROOT / meta["scene"] if not Path(meta["scene"]).is_absolute() else Path(meta["scene"])
    scene = gltf_reader.load_gltf(str(scene_path))
    plane = planar_triangles(scene, args.hidden)
    wall = next(m for m in scene["meshes"] if m["node"] == meta["relay_wall"])
    wall_albedo = float(wall["material"]["albedo"][0])
    hidden_albedo = float(plane[5]["albedo"][0])
    w = wall["positions"][wall["faces"][0]].astype(np.float64)
    wall_normal = np.cross(w[1] - w[0], w[2] - w[0])
    wall_normal /= np.linalg.norm(wall_normal)
    scale = (wall_albedo / np.pi) ** 2 * hidden_albedo / np.pi

    ours, ours_var = render_ours(meta, peer, args)
    theirs, theirs_var = peer["transient_mean"][..., 0].astype(np.float64), peer["transient_var"][..., 0].astype(np.float64)
    sensed = peer["sensor_grid_xyz"].astype(np.float64)
    spots = np.broadcast_to(peer["laser_grid_xyz"].astype(np.float64), sensed.shape)
    power = np.broadcast_to(peer["laser_power_equivalent"].astype(np.float64), sensed.shape[:2])
    n = args.edge_bins
    z = {m: {"ours": [], "peer": []} for m in ("exact", "mitsuba")}
    skipped = 0
    for y in range(sensed.shape[0]):
        for x in range(sensed.shape[1]):
            lit = ours[y, x] > 1e-3 * ours[y, x].max() if ours[y, x].max() > 0 else None
            if lit is None:
                continue
            edge = int(np.argmax(lit))
            for model, offset in (("exact", 0.0), ("mitsuba", MITSUBA_RAY_EPSILON * (1 + np.abs(sensed[y, x]).max()))):
                q = scale * power[y, x] * quadrature(plane, wall_normal, hidden_albedo, sensed[y, x], spots[y, x],
                                                     meta["start"], meta["bin_width"], edge - 1, n + 1, args.cell, offset)
                if model == "exact" and q[1] == 0:
                    # No light of the hidden object in ours' first lit bin: another surface
                    # lights this point first.
                    skipped += 1
                    break
                for name, mean, var in (("ours", ours, ours_var), ("peer", theirs, theirs_var)):
                    got, v = mean[y, x, edge:edge + n], var[y, x, edge:edge + n]
                    # A bin without a single sample in any batch has no variance estimate: not tested.
                    z[model][name].append(np.where(v > 0, (got - q[1:]) / np.sqrt(np.where(v > 0, v, 1.0)), np.nan))
    print(f"{args.peer}: {meta['scan']} scan, bins of {meta['bin_width'] * 1e3:g} mm; ours: {args.method}, "
          f"{args.batches} x {args.spp} spp; {skipped} sensed points lit first by other surfaces left out")
    for model, title in (("exact", "exact path lengths"),
                         ("mitsuba", "first hidden segment shortened by Mitsuba's ray offset")):
        print(f"quadrature with {title}:")
        for name in ("ours", "peer"):
            a = np.array(z[model][name])
            if a.size == 0:
                continue
            cols = "  ".join(f"bin {k}: z mean {np.nanmean(a[:, k]):+.2f} std {np.nanstd(a[:, k]):.2f}"
                             + (f" ({np.isnan(a[:, k]).sum()} unsampled)" if np.isnan(a[:, k]).any() else "")
                             for k in range(n))
            print(f"  {name} ({len(a)} points)  {cols}")


if __name__ == "__main__":
    main()
