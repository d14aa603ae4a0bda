#!/usr/bin/env python3
"""Render peer reference data for an NLOS capture described in a Mitsuba 3 XML scene (an
`nlos_capture_meter` on its relay wall, a `projector` laser, `transient_nlos_path`) with
Mitsuba 3 + mitransient, from the very file gatetrace reads.

    tools/peer/nlos_xml_reference.py SCENE.xml OUT_DIR [--grid WxH] [--spp S] [--passes P]
        [--max-bounces N] [--hidden-geometry-sampling off|file] [--param NAME=VALUE ...]
        [--key KEY] [--variant llvm_ad_rgb]

mitransient 1.3.1 refuses the properties of its earlier capture meter, for which its own
examples (`examples/transient-nlos/nlos_Z.xml`) are written: `confocal`, `laser_origin`,
`laser_lookat_pixel`, `laser_lookat_3d` and the meter's `account_first_and_last_bounces`. This
tool reads them as that meter did and as gatetrace does, removes them from a copy of the file
(written beside it, so that its relative paths hold, and deleted after loading), and sets the
scene up as mitransient's notebooks do: the projector moved to `laser_origin` and focused with
`mitransient.nlos.focus_emitter_at_relay_wall_uv` at the wall point (x, y) / film size of
`laser_lookat_pixel`, the scan in the integrator's `capture_type`. The film's width and height
become --grid, `max_depth` --max-bounces where given (laser sampling connects through the spot
without counting it: a path of `max_depth` d has d scattering vertices).

mitransient's hidden-geometry sampling draws a point of the hidden geometry and weighs the
surface the ray meets first by that point's density, so where hidden objects occlude each other
it is biased; the tool turns it off (`--hidden-geometry-sampling off`, the default), leaving
mitransient's BSDF sampling, unbiased and noisier.

Segment lengths are measured between surface points, not from Mitsuba's offset ray origins
(`peer_reference.use_exact_segment_lengths`).

Writes, float32, each pass's seed drawn from `--seed`: `KEY_mean.npy` (the average over passes)
and `KEY_var.npy` (the variance of that average), the capture [grid_y, grid_x, T, 3] with bin b
holding paths of [start_opl + b width, start_opl + (b + 1) width) metres from the laser spot
to the sensed point (plus the first and last segments where the file counts them).

Requirements: pip install mitsuba==3.9.1 mitransient==1.3.1 numpy (plus libllvm19 for llvm
variants).
"""
import argparse
import os
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from peer_reference import _RunningMoments, use_exact_segment_lengths  # noqa: E402

EARLIER_METER = ("confocal", "laser_origin", "laser_lookat_pixel", "laser_lookat_3d",
                 "account_first_and_last_bounces")


def point(e):
    if "value" in e.attrib:
        v = [float(x) for x in e.attrib["value"].replace(",", " ").split()]
        return np.array(v * 3 if len(v) == 1 else v, dtype=np.float64)
    return np.array([float(e.attrib.get(k, 0.0)) for k in "xyz"], dtype=np.float64)


def prepare(scene_path, grid, max_bounces, params, hidden_geometry_sampling):
    """The file's tree with its parameters substituted (`params` over its `<default>`s), the
    earlier meter's properties removed and the grid and depth set, and what those properties
    said (laser origin, aim in (u, v), confocal)."""
    tree = ET.parse(scene_path)
    root = tree.getroot()
    values = {d.attrib["name"]: d.attrib["value"] for d in root.findall("default")}
    values.update(params)
    for e in root.iter():
        for k, v in e.attrib.items():
            if v.startswith("$"):
                e.attrib[k] = values[v[1:]]
    wall = next(s for s in root.iter("shape") if s.find("sensor") is not None)
    meter = wall.find("sensor")
    props = {c.attrib.get("name"): c for c in meter}
    film = meter.find("film")
    size = {c.attrib["name"]: int(c.attrib["value"]) for c in film if c.tag == "integer"
            and c.attrib.get("name") in ("width", "height")}
    said = {}
    for name in EARLIER_METER:
        if name in props:
            e = props[name]
            said[name] = e.attrib["value"].lower() == "true" if e.tag == "boolean" else point(e)
            meter.remove(e)
    integrator = root.find("integrator")
    ints = {c.attrib.get("name"): c for c in integrator}
    if said.get("confocal"):
        ET.SubElement(integrator, "string", name="capture_type", value="confocal")
    if "account_first_and_last_bounces" in said and "account_first_and_last_bounces" not in ints:
        ET.SubElement(integrator, "boolean", name="account_first_and_last_bounces",
                      value=str(said["account_first_and_last_bounces"]).lower())
    # Laser sampling connects the last vertex through the laser spot, uncounted by max_depth:
    # a path of max_depth d has d scattering vertices, the spot included.
    changed = {"max_depth": ("integer", max_bounces)} if max_bounces is not None else {}
    if not hidden_geometry_sampling:
        changed["nlos_hidden_geometry_sampling"] = ("boolean", "false")
    for name, (tag, value) in changed.items():
        if name in ints:
            integrator.remove(ints[name])
        ET.SubElement(integrator, tag, name=name, value=str(value))
    for c in film:
        if c.attrib.get("name") in ("width", "height"):
            c.attrib["value"] = str(grid[0] if c.attrib["name"] == "width" else grid[1])
    if "laser_lookat_pixel" in said:
        p = said["laser_lookat_pixel"]
        said["uv"] = (float(p[0] / size["width"]), float(p[1] / size["height"]))
    return tree, said


def load_capture(mi, mitr, scene_path, grid, max_bounces, params, hidden_geometry_sampling):
    """The Mitsuba scene of the capture the file describes (`prepare`), loaded from a copy
    written beside it (its relative paths hold) and deleted after, its laser moved to the
    meter's `laser_origin` and focused on its `laser_lookat_pixel` or `laser_lookat_3d`."""
    tree, said = prepare(scene_path, grid, max_bounces, params, hidden_geometry_sampling)
    copy = Path(scene_path).with_name(f".{Path(scene_path).stem}.peer.xml")
    tree.write(copy)
    try:
        scene = mi.load_file(str(copy))
    finally:
        os.remove(copy)
    relay_wall = next(s for s in scene.shapes() if s.sensor() is not None)
    [laser] = scene.emitters()
    if "laser_origin" in said:
        params = mi.traverse(laser)
        params["to_world"] = mi.Transform4f().translate(said["laser_origin"].tolist())
        params.update()
    if not said.get("confocal"):
        if "uv" in said:
            mitr.nlos.focus_emitter_at_relay_wall_uv(mi.Point2f(*[float(x) for x in said["uv"]]), relay_wall, laser)
        elif "laser_lookat_3d" in said:
            mitr.nlos.focus_emitter_at_relay_wall_3dpoint(mi.Point3f(said["laser_lookat_3d"]), relay_wall, laser)
    return scene


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", help="Mitsuba 3 XML scene describing an NLOS capture")
    p.add_argument("out_dir", help="directory for the .npy files")
    p.add_argument("--grid", default="16x16", help="sensed points, WIDTHxHEIGHT (the film's size)")
    p.add_argument("--spp", type=int, default=1024, help="samples per sensed point of one pass")
    p.add_argument("--passes", type=int, default=8, help="independent passes")
    p.add_argument("--max-bounces", type=int, default=None,
                   help="scattering vertices, spot and sensed point included (default: the file's max_depth)")
    p.add_argument("--hidden-geometry-sampling", choices=["file", "off"], default="off",
                   help="off (the default): mitransient's BSDF sampling, unbiased; file: as the file says (its "
                        "hidden-geometry sampling ignores occlusion between hidden objects, a bias)")
    p.add_argument("--seed", type=int, default=7, help="seed of the passes' seeds")
    p.add_argument("--key", default="capture", help="prefix of the output files")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="a value for the file's parameter NAME (replaces its <default>)")
    p.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant")
    args = p.parse_args(argv)
    grid = tuple(int(x) for x in args.grid.lower().split("x"))

    import drjit as dr
    import mitsuba as mi
    mi.set_variant(args.variant)
    import mitransient as mitr

    use_exact_segment_lengths(mi, dr)
    params = dict(kv.split("=", 1) for kv in args.param)
    scene = load_capture(mi, mitr, args.scene, grid, args.max_bounces, params, args.hidden_geometry_sampling == "file")
    integrator = scene.integrator()
    seeds = np.random.SeedSequence(args.seed).generate_state(args.passes, dtype=np.uint32)
    moments = _RunningMoments()
    started = time.time()
    for k in range(args.passes):
        _, t = integrator.render(scene, seed=int(seeds[k]), spp=args.spp)
        moments.add(np.array(t, dtype=np.float64)[..., :3])
        print(f"pass {k + 1}/{args.passes}: {time.time() - started:.1f} s", file=sys.stderr, flush=True)
    mean, var = moments.mean_and_var_of_mean()
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    np.save(out / f"{args.key}_mean.npy", mean.astype(np.float32))
    np.save(out / f"{args.key}_var.npy", var.astype(np.float32))
    print(f"{args.key}: shape {mean.shape}, total {mean.sum():.6g}, {time.time() - started:.1f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
