#!/usr/bin/env python3
"""Render peer reference data for a glTF scene with Mitsuba 3 + mitransient.

This tool produces an independent ("peer") reference for gatetrace: it reads a
glTF 2.0 scene itself (JSON + base64 / external buffers, or .glb), builds the
equivalent Mitsuba 3 scene in memory and renders it with mitransient's
``transient_path`` integrator into a ``transient_hdr_film``, repeating the
render for several independent passes (different seeds) so that every output
comes with the variance of its mean.

Requirements
------------
* Python >= 3.9 with ``pip install mitsuba mitransient numpy``
  (verified with mitsuba 3.9.1, drjit 1.5.0, mitransient 1.3.1, numpy 2.4.6).
* The ``llvm_ad_*`` variants need a system LLVM shared library; on Debian 12:
  ``apt-get install -y libllvm19``.  ``--variant cuda_ad_rgb`` uses an NVIDIA
  GPU instead.

Units and conventions
---------------------
* Lengths are the glTF's metres.  **Time is optical path length in metres**
  (not seconds), measured from the emitter to the camera and including both
  the light segment and the camera segment (mitransient's
  ``camera_unwarp = false``).  Divide by c = 299792458 m/s for seconds.
* Bin ``b`` of the transient cube covers ``[start + b*bin_width,
  start + (b+1)*bin_width)`` metres and holds the *bin-integrated* radiance
  (the sum of all contributions whose path length falls into the bin, not a
  density per metre).  Summing bins therefore gives a box time gate.
* ``--max-bounces N`` counts diffuse reflections: N = 0 sees emitters only,
  1 is direct lighting.  Mitsuba's ``max_depth`` is ``N + 1``.  Russian
  roulette is disabled (``rr_depth`` beyond ``max_depth``).
* Materials become one-sided Lambertian ``diffuse`` BSDFs with the
  ``baseColorFactor`` RGB (wrapped in ``twosided`` when ``doubleSided``);
  metallic/roughness and textures are ignored with a warning.  Emissive
  materials get an ``area`` emitter with radiance ``emissiveFactor *
  KHR_materials_emissive_strength`` (Mitsuba area lights emit on the front
  side only, also for double-sided materials: a warning is printed).
* KHR_lights_punctual lights (any number, together with area lights) become
  Mitsuba emitters; ``intensity`` x ``color`` is taken as radiant intensity
  in W/sr at the beam's centre (point, spot) or as irradiance in W/m^2 on a
  surface facing the light (directional).  A light's direction is its node's
  world -z.

  - ``point``: ``point`` emitter, ``intensity``, ``position`` = the node's
    world origin.
  - ``spot``: ``spot`` emitter, ``intensity``, ``cutoff_angle`` =
    degrees(outerConeAngle), ``beam_width`` = degrees(innerConeAngle)
    (always set: Mitsuba's default is 3/4 of the cutoff), ``to_world`` a
    rigid look-at frame whose local +z (Mitsuba's beam axis) is the node's
    world -z.  Mitsuba's intensity is constant inside the inner cone, falls
    off linearly in *angle* to zero at the outer cone and is zero beyond
    (glTF suggests a smooth profile: a warning is printed when the cones
    differ by more than 1e-3 rad; a hard edge, inner ~ outer, sidesteps it).
  - ``directional``: ``directional`` emitter, ``irradiance``, ``direction``
    = the travel direction (the node's world -z).  mitransient gives its
    light segment a constant length 2 x (radius of the scene's bounding
    sphere, or more for points outside it) rather than a plane-wave distance,
    so with directional lights only the steady image is a meaningful
    reference; the transient cube and gates are shifted by an arbitrary
    amount.
  - ``range`` is ignored (warning); other light types are an error.
* The camera is the glTF's first camera: ``perspective`` sensor, vertical fov
  ``yfov`` (``fov_axis = 'y'``), ``near_clip = znear``, pinhole, box pixel
  filter, ``independent`` sampler.  glTF cameras look down -z with +y up;
  Mitsuba cameras look down +z with +x to the *left*, so the node matrix is
  multiplied by diag(-1, 1, -1) (a 180 degree turn about y).
* Thin lens: when the camera *node's* ``extras`` hold ``aperture_radius`` > 0
  (metres) and ``focus_distance`` (metres), the sensor is Mitsuba's
  ``thinlens`` with those values (same fov, fov_axis, near_clip, to_world;
  the node matrix must be rigid).  The lens is a disc of that radius centred
  on the node's origin, perpendicular to the viewing direction; the focus
  surface is the plane at focus_distance along the viewing direction.  The
  camera segment starts on the lens (uniformly sampled point of the disc).
* Mitsuba starts camera rays on the near plane, so the first ``near_clip /
  cos(angle to the optical axis)`` metres of the camera segment are *not*
  counted in the path length (checked: znear 0.5 shifts everything by about
  0.52 m).  ``thinlens`` does the same from the lens point (origin moved
  by near_clip / d_z along the ray direction d).  With the canonical znear =
  1e-5 this is negligible; a warning is printed when it could exceed 1% of a
  bin.
* Segment lengths: Mitsuba starts a ray leaving a surface point p at an
  origin moved off the surface along its normal by about (1 + max|p_i|) x
  8.9e-5 m (0.1-0.2 mm in a metre-sized scene), and mitransient adds the hit
  distance from that origin, so every segment after the first comes out up
  to that much short.  That moves light across the edges of fine bins (a
  1.2 mm bin's first arrival).  By default this tool therefore replaces each
  hit distance by the exact distance between the two surface points: the
  surface a ray left is found by a short ray cast backwards from its origin,
  and p is the foot of the perpendicular from the origin onto it.  Origins
  more than 1 mm off any surface (cameras, the sensor origin) keep Mitsuba's
  distance.  ``--mitsuba-segment-lengths`` keeps Mitsuba's own distances
  (as the committed Cornell box references, made with bins of 5 cm or more,
  where the difference is far below their noise).
* The steady image is accumulated by a separate ``hdrfilm`` from every
  path, whatever its length; when the bins cover all path lengths it equals
  the sum of the bins (checked to 1e-6).

Output (.npz, all arrays float32, row 0 = top of the image, RGB last)
--------------------------------------------------------------------
``transient_mean`` [H, W, T, 3]   mean over passes of the transient cube
``transient_var``  [H, W, T, 3]   variance of that mean (sample variance
                                   over passes / passes)
``steady_mean``    [H, W, 3]      steady image: the integrator's steady
``steady_var``     [H, W, 3]      output, all path lengths (not only the
                                   binned range), and its variance of the mean
``gate_mean``      [H, W, 3]      only with ``--gate A B``: sum of the bins
``gate_var``       [H, W, 3]      covering [A, B) (must lie on bin edges); the
                                   variance is taken over per-pass gate images.
                                   ``--gate`` may be repeated: with more than
                                   one, each is written as ``gate_A_B_*``
``transient_coarse_mean`` / ``_var`` [H, W, T/K, 3]  only with ``--sum-bins K``
                                   (K > 1): every K consecutive bins summed in
                                   each pass, variance over those per-pass sums
``meta``           0-d str        JSON: versions, settings, bin edges, seeds,
                                   camera, lights, timings and the command line

``--steady-only`` keeps only ``steady_*``.  ``--test-keys`` renames the arrays
as in tests/data/*_peer: ``gate_A_B_*`` and ``transient_START_step_WIDTH_*``
(numbers with dots as underscores; the cube is the ``--sum-bins`` one when
K > 1, and the fine cube is then not written).

Example (Cornell box; ~3.5 min on 2 CPU cores for 16 x 8192 spp, comparable
with shared/references/cornell_box_peer.npz)::

    python tools/peer/peer_reference.py assets/scenes/cornell_box.gltf -o cb.npz \\
        --res 64 64 --max-bounces 5 --spp 8192 --passes 16 --seed 1 \\
        --start 1.94 --bin-width 0.05 --bins 40 --gate 3.14 3.19

With ``--test-keys --sum-bins 2`` the same run writes the arrays under the
names of tests/data/cornell_box_peer (steady, gate_3_14_3_19,
transient_1_94_step_0_1: 20 bins of 0.1 m, each the per-pass sum of two
0.05 m bins), ready for tools/peer/convert_peer_reference.py.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import platform
import shlex
import sys
import time
import urllib.parse

import numpy as np

from gltf_reader import warn, load_gltf


# --------------------------------------------------------------------------
# Mitsuba scene
# --------------------------------------------------------------------------

# glTF camera: looks down -z, +y up, +x right.  Mitsuba camera: looks down +z,
# +y up, +x left.  Rotating 180 degrees about y maps one onto the other.
_GLTF_TO_MITSUBA_CAMERA = np.diag([-1.0, 1.0, -1.0, 1.0])


def build_mitsuba_scene(mi, scene, args, max_depth):
    """Return the Mitsuba scene dict for the parsed glTF scene."""
    cam = scene["camera"]
    if cam is None:
        raise ValueError("the glTF has no camera")
    width, height = args.res
    if cam["aspect_ratio"] is not None and abs(cam["aspect_ratio"] - width / height) > 1e-6:
        warn(f"camera aspectRatio {cam['aspect_ratio']} differs from --res "
              f"{width}x{height}; the vertical fov is kept")

    # Largest near-plane offset (image corner) that Mitsuba leaves out of the
    # optical path length: near_clip / cos(ray angle to the optical axis); a
    # thin-lens ray from the aperture's rim is tilted further by up to
    # atan(aperture_radius / focus_distance).
    tan_y = math.tan(cam["yfov"] / 2)
    tan_corner = tan_y * math.sqrt(1 + (width / height) ** 2)
    thin_lens = cam.get("aperture_radius", 0.0) > 0
    if thin_lens:
        tan_corner += cam["aperture_radius"] / cam["focus_distance"]
    corner = math.sqrt(1 + tan_corner ** 2)
    if cam["znear"] * corner > 0.01 * args.bin_width:
        warn(f"znear {cam['znear']} m: Mitsuba omits up to "
              f"{cam['znear'] * corner:.3g} m of the camera segment from the "
              "path length (rays start on the near plane)")

    to_world = cam["to_world"] @ _GLTF_TO_MITSUBA_CAMERA
    if thin_lens:
        lin = to_world[:3, :3]
        if np.abs(lin.T @ lin - np.eye(3)).max() > 1e-5:
            raise ValueError("thin-lens camera: the camera node's world matrix has a scale or "
                             "shear (Mitsuba's thinlens sensor accepts rigid transforms only)")
    sensor = {
        "type": "thinlens" if thin_lens else "perspective",
        "fov": math.degrees(cam["yfov"]),
        "fov_axis": "y",
        "near_clip": cam["znear"],
        "to_world": mi.ScalarTransform4f(to_world.tolist()),
        "sampler": {"type": "independent", "sample_count": args.spp},
        "film": {
            "type": "transient_hdr_film",
            "width": width,
            "height": height,
            "temporal_bins": args.bins,
            "start_opl": args.start,
            "bin_width_opl": args.bin_width,
            "rfilter": {"type": "box"},
        },
    }
    if cam["zfar"] is not None:
        sensor["far_clip"] = cam["zfar"]
    if thin_lens:
        sensor["aperture_radius"] = cam["aperture_radius"]
        sensor["focus_distance"] = cam["focus_distance"]

    out = {
        "type": "scene",
        "integrator": {
            "type": "transient_path",
            "max_depth": max_depth,
            "rr_depth": max_depth + 1,  # Russian roulette never starts
            "camera_unwarp": False,
        },
        "sensor": sensor,
    }
    for m in scene["meshes"]:
        out[m["name"]] = _make_mesh(mi, m)
    for i, light in enumerate(scene.get("lights", [])):
        out[f"punctual_{i}_{light['type']}"] = _make_light(mi, light)
    if not scene.get("lights") and not any(any(v > 0 for v in m["material"]["emission"])
                                           for m in scene["meshes"]):
        warn("the scene has no emissive material and no KHR_lights_punctual light: it renders black")
    return out


def _make_light(mi, light):
    """Mitsuba emitter dict of a parsed KHR_lights_punctual light (see _light_info)."""
    rgb = {"type": "rgb", "value": light["rgb"]}
    if light["type"] == "point":
        return {"type": "point", "intensity": rgb, "position": light["position"].tolist()}
    if light["type"] == "directional":
        # Mitsuba radiates along its local +Z; `direction` is the travel direction.
        return {"type": "directional", "irradiance": rgb, "direction": light["direction"].tolist()}
    # spot: Mitsuba's beam axis is its local +Z; look_at maps +Z onto target - origin, so the
    # beam runs along the node's world -Z (the rigid frame drops any scale of the node).
    origin, axis = light["position"], light["direction"]
    up = light["up"] - axis * np.dot(light["up"], axis)
    if np.linalg.norm(up) < 1e-6:
        up = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    return {"type": "spot", "intensity": rgb,
            "cutoff_angle": math.degrees(light["outer"]),
            # Always given: Mitsuba's default beam_width is 3/4 of the cutoff.
            "beam_width": math.degrees(light["inner"]),
            "to_world": mi.ScalarTransform4f().look_at(origin=origin.tolist(),
                                                       target=(origin + axis).tolist(),
                                                       up=(up / np.linalg.norm(up)).tolist())}


def _make_mesh(mi, m):
    mat = m["material"]
    bsdf = {"type": "diffuse", "reflectance": {"type": "rgb", "value": mat["albedo"]}}
    if mat["double_sided"]:
        bsdf = {"type": "twosided", "material": bsdf}
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf)
    if any(v > 0 for v in mat["emission"]):
        if mat["double_sided"]:
            warn(f"material '{mat['name']}': Mitsuba area lights emit on the "
                  "front side only; the back side will not emit")
        props["emitter"] = mi.load_dict(
            {"type": "area", "radiance": {"type": "rgb", "value": mat["emission"]}})
    has_normals = m["normals"] is not None
    mesh = mi.Mesh(m["name"], len(m["positions"]), len(m["faces"]),
                   props=props, has_vertex_normals=has_normals)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(m["positions"].ravel())
    params["faces"] = mi.UInt32(m["faces"].ravel())
    if has_normals:
        params["vertex_normals"] = mi.Float(m["normals"].ravel())
    params.update()
    return mesh


# --------------------------------------------------------------------------
# NLOS captures (transient_nlos_path + nlos_capture_meter)
# --------------------------------------------------------------------------

def wall_rectangle(scene, wall_node):
    """The relay wall as a Mitsuba rectangle: the affine map from the wall's TEXCOORD_0 to its
    positions, checked to hold at every vertex (a planar parallelogram parameterised linearly).
    Returns (to_world 4x4, point_at(u, v)). The rectangle's local [-1, 1]^2 maps to uv [0, 1]^2,
    so nlos_capture_meter's grid cell (i, j) lies at uv ((i + 0.5) / W, (j + 0.5) / H), as in
    gatetrace."""
    walls = [m for m in scene["meshes"] if m["node"] == wall_node]
    if not walls:
        raise SystemExit(f"no mesh node named '{wall_node}' (the relay wall)")
    pos = np.concatenate([m["positions"] for m in walls]).astype(np.float64)
    if any(m["uvs"] is None for m in walls):
        raise SystemExit(f"the relay wall '{wall_node}' has no TEXCOORD_0")
    uv = np.concatenate([m["uvs"] for m in walls])
    design = np.column_stack([uv, np.ones(len(uv))])
    affine, *_ = np.linalg.lstsq(design, pos, rcond=None)  # pos = [u v 1] @ affine
    if np.abs(design @ affine - pos).max() > 1e-5:
        raise SystemExit(f"the relay wall '{wall_node}' is not a parallelogram with linear texture "
                         "coordinates: Mitsuba's rectangle cannot reproduce it")
    du, dv, p00 = affine
    normal = np.cross(du, dv)
    normal /= np.linalg.norm(normal)
    f = walls[0]["faces"][0]
    face_normal = np.cross(pos[f[1]] - pos[f[0]], pos[f[2]] - pos[f[0]])
    if np.dot(face_normal, normal) <= 0:
        raise SystemExit(f"the relay wall '{wall_node}' faces against its (u, v) frame: Mitsuba's "
                         "rectangle would face the other way")
    to_world = np.eye(4)
    to_world[:3, 0], to_world[:3, 1], to_world[:3, 2] = du / 2, dv / 2, normal
    to_world[:3, 3] = p00 + (du + dv) / 2
    return to_world, lambda u, v: p00 + u * du + v * dv


def build_nlos_scene(mi, scene, args):
    """Mitsuba scene dict of an NLOS capture of the glTF scene: every mesh but the relay wall as
    it is, the relay wall as a rectangle carrying an nlos_capture_meter, and a projector laser
    of irradiance 1 at unit distance. Returns (dict, wall point_at, sensor and laser
    origins)."""
    to_world, point_at = wall_rectangle(scene, args.relay_wall)
    if scene.get("lights"):
        warn("--nlos: the glTF's KHR_lights_punctual lights are ignored (the laser lights the scene)")
    origins = scene["node_positions"]
    sensor_origin = np.array(args.sensor_origin if args.sensor_origin else
                             origins.get("sensor_origin", origins.get("nlos_origin")), dtype=np.float64)
    laser_origin = np.array(args.laser_origin if args.laser_origin else
                            origins.get("laser_origin", origins.get("nlos_origin")), dtype=np.float64)
    width, height = args.res
    wall = next(m for m in scene["meshes"] if m["node"] == args.relay_wall)
    mat = wall["material"]
    bsdf = {"type": "diffuse", "reflectance": {"type": "rgb", "value": mat["albedo"]}}
    if mat["double_sided"]:
        bsdf = {"type": "twosided", "material": bsdf}
    target = point_at(*args.laser_spot)
    up = [0.0, 1.0, 0.0] if abs(np.dot(target - laser_origin, [0, 1, 0])) < 0.99 * np.linalg.norm(
        target - laser_origin) else [1.0, 0.0, 0.0]
    out = {
        "type": "scene",
        "integrator": {
            "type": "transient_nlos_path",
            # Laser sampling connects the last vertex through the spot without counting it: a
            # path of max_depth d has d scattering vertices, the spot included.
            "max_depth": args.max_bounces,
            "rr_depth": args.max_bounces + 1,
            "capture_type": args.nlos,
            "nlos_laser_sampling": True,
            "nlos_hidden_geometry_sampling": args.hidden_geometry_sampling,
            "account_first_and_last_bounces": args.count_first_last,
            "temporal_filter": "box",
        },
        "laser": {"type": "projector", "irradiance": 1.0, "fov": 0.2,
                  "to_world": mi.ScalarTransform4f().look_at(origin=laser_origin.tolist(), target=target.tolist(),
                                                             up=up)},
        "relay_wall": {
            "type": "rectangle",
            "to_world": mi.ScalarTransform4f(to_world.tolist()),
            "bsdf": bsdf,
            "nlos_sensor": {
                "type": "nlos_capture_meter",
                "sensor_origin": sensor_origin.tolist(),
                "sampler": {"type": "independent", "sample_count": args.spp},
                "film": {"type": "transient_hdr_film", "width": width, "height": height,
                         "temporal_bins": args.bins, "bin_width_opl": args.bin_width,
                         "start_opl": args.start, "rfilter": {"type": "box"}},
            },
        },
    }
    for m in scene["meshes"]:
        if m["node"] != args.relay_wall:
            out[m["name"]] = _make_mesh(mi, m)
    return out, point_at, sensor_origin, laser_origin


def laser_equivalent_power(point_at, laser_origin, wall_normal, targets):
    """The beam power (W) gatetrace's laser needs, per laser spot, to match the projector.
    mitransient treats the spot as a point of area pdf 1 lit by the projector, whose emitter sample
    weighs pi E / d^2 on its axis (E = its `irradiance`, here 1; measured with
    Emitter.sample_direction: pi / 4 at d = 2, whatever the fov), and the wall's BSDF evaluation
    adds the incident cosine: P = pi cos / d^2."""
    d = targets - laser_origin
    dist = np.linalg.norm(d, axis=-1)
    cos = np.abs((d / dist[..., None]) @ wall_normal)
    return np.pi * cos / dist ** 2


# Largest distance, metres, back along a ray at which its origin's surface is looked for
# (an origin offset of 0.2 mm reached at 0.1 degree from grazing), and largest height of an
# origin above that surface still taken for Mitsuba's offset rather than a free origin.
_BACKTRACK_M = 0.1
_SPAWN_OFFSET_MAX_M = 1e-3


def use_exact_segment_lengths(mi, dr):
    """Replace Scene.ray_intersect so that a hit's `t` is the distance from the surface point the
    ray was spawned at, not from Mitsuba's offset origin (see "Segment lengths" above). The
    surface is found by a cast backwards from the origin; the spawn point is the foot of the
    perpendicular from the origin onto that surface's plane."""
    intersect = mi.Scene.ray_intersect

    def ray_intersect_exact(self, ray, *args, **kwargs):
        si = intersect(self, ray, *args, **kwargs)
        below = intersect(self, mi.Ray3f(ray.o, -ray.d, _BACKTRACK_M, ray.time, ray.wavelengths))
        height = dr.dot(ray.o - below.p, below.n)
        spawn_point = ray.o - height * below.n
        spawned = below.is_valid() & (dr.abs(height) < _SPAWN_OFFSET_MAX_M) & si.is_valid()
        si.t = dr.select(spawned, dr.norm(si.p - spawn_point), si.t)
        return si

    mi.Scene.ray_intersect = ray_intersect_exact


# --------------------------------------------------------------------------
# Rendering
# --------------------------------------------------------------------------

class _RunningMoments:
    """Welford mean/variance over passes, in float64."""

    def __init__(self):
        self.n, self.mean, self.m2 = 0, None, None

    def add(self, x):
        x = np.asarray(x, dtype=np.float64)
        self.n += 1
        if self.mean is None:
            self.mean, self.m2 = x.copy(), np.zeros_like(x)
            return
        delta = x - self.mean
        self.mean += delta / self.n
        self.m2 += delta * (x - self.mean)

    def mean_and_var_of_mean(self):
        if self.n < 2:
            return self.mean, np.full_like(self.mean, np.nan)
        return self.mean, self.m2 / (self.n - 1) / self.n


class OneBinRenderer:
    """transient_path on a glTF scene with one time bin [start, start + width) metres of optical
    path: the peer of tools/peer/throughput.py and tools/peer/equal_time_peer.py. `variant` is
    Mitsuba's (llvm_ad_rgb on a CPU, cuda_ad_rgb on an NVIDIA GPU)."""

    def __init__(self, scene_path, res, max_bounces, start, width, variant="llvm_ad_rgb"):
        import types

        import mitsuba as mi
        mi.set_variant(variant)
        import mitransient  # noqa: F401  (registers transient_path)

        settings = types.SimpleNamespace(res=(res, res), spp=1, bins=1, start=start, bin_width=width)
        self.scene = mi.load_dict(build_mitsuba_scene(mi, load_gltf(scene_path), settings, max_bounces + 1))
        self.integrator, self.sensor = self.scene.integrator(), self.scene.sensors()[0]

    def render(self, spp, seed):
        """(bin image [H, W, 3] as float64, seconds) of one render of `spp` samples per pixel;
        both of the integrator's outputs are evaluated (Dr.Jit is lazy) within the time."""
        start = time.perf_counter()
        steady, transient = self.integrator.render(self.scene, self.sensor, seed=seed, spp=spp)
        np.array(steady)
        image = np.array(transient, dtype=np.float64)[:, :, 0, :3]
        return image, time.perf_counter() - start


def _key_number(x):
    """A length as used in the tests' array names: 1.94 -> '1_94', 0.1 -> '0_1'."""
    return f"{round(x, 6):g}".replace("-", "minus").replace(".", "_")


def gate_bins(args):
    """Return [(first, last_exclusive) bin indices] of each --gate (empty without any)."""
    return [_gate_bins(args, a, b) for a, b in (args.gate or [])]


def _gate_bins(args, a, b):
    ka, kb = (a - args.start) / args.bin_width, (b - args.start) / args.bin_width
    ia, ib = round(ka), round(kb)
    tol = 1e-6
    if abs(ka - ia) > tol or abs(kb - ib) > tol:
        raise SystemExit(
            f"error: --gate {a} {b} does not lie on bin edges "
            f"(start {args.start}, width {args.bin_width}: edges at "
            f"start + k*width); pick --start/--bin-width so that it does")
    if not (0 <= ia < ib <= args.bins):
        raise SystemExit(f"error: --gate {a} {b} is outside the binned range "
                         f"[{args.start}, {args.start + args.bins * args.bin_width})")
    return ia, ib


def parse_args(argv=None):
    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog=__doc__[__doc__.index("Requirements"):],
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", help="glTF 2.0 scene (.gltf or .glb)")
    p.add_argument("-o", "--output", default=None,
                   help="output .npz (default: <scene stem>_peer.npz)")
    p.add_argument("--res", nargs=2, type=int, default=[64, 64],
                   metavar=("W", "H"), help="image size (default 64 64)")
    p.add_argument("--max-bounces", type=int, default=5,
                   help="maximum number of reflections (default 5; "
                        "Mitsuba max_depth = this + 1)")
    p.add_argument("--spp", type=int, default=256,
                   help="samples per pixel per pass (default 256)")
    p.add_argument("--passes", type=int, default=8,
                   help="independent passes for the variance (default 8)")
    p.add_argument("--seed", type=int, default=0,
                   help="base seed; every render call gets its own seed "
                        "derived from it (default 0)")
    p.add_argument("--start", type=float, default=0.0,
                   help="start of the first time bin, metres of optical path")
    p.add_argument("--bin-width", type=float, default=0.1,
                   help="time bin width, metres of optical path (default 0.1)")
    p.add_argument("--bins", type=int, default=100,
                   help="number of time bins (default 100)")
    p.add_argument("--gate", nargs=2, type=float, metavar=("A", "B"), action="append",
                   help="(repeatable) also write gate_mean/gate_var: the sum of the bins "
                        "covering [A, B) metres; A and B must be bin edges")
    p.add_argument("--sum-bins", type=int, default=1, metavar="K",
                   help="also write transient_coarse_mean/var: the cube with every K "
                        "consecutive bins summed in each pass (--bins must be a multiple "
                        "of K); its variance is taken over the per-pass summed cubes")
    p.add_argument("--test-keys", action="store_true",
                   help="name the arrays as in tests/data/*_peer: steady, gate_A_B and "
                        "transient_START_step_WIDTH (+ _mean/_var, dots as underscores; the "
                        "cube is the --sum-bins one when K > 1, the fine cube is then left out)")
    p.add_argument("--steady-only", action="store_true",
                   help="write only steady_mean/var (e.g. for scenes with directional "
                        "lights, whose path lengths mitransient does not model); --gate and "
                        "--sum-bins are then not allowed")
    p.add_argument("--chunk-spp", type=int, default=1024,
                   help="render a pass in calls of at most this many spp to "
                        "bound memory (default 1024)")
    p.add_argument("--variant", default="llvm_ad_rgb",
                   help="Mitsuba variant (default llvm_ad_rgb; cuda_ad_rgb "
                        "for a GPU); must be an RGB variant")
    p.add_argument("--threads", type=int, default=None,
                   help="CPU threads for the LLVM backend (default: all)")
    p.add_argument("--mitsuba-segment-lengths", action="store_true",
                   help="measure each segment from Mitsuba's offset ray origin, as Mitsuba does "
                        "(up to ~0.2 mm short a segment), instead of between the exact surface points")
    p.add_argument("--nlos", choices=["single", "confocal"],
                   help="render an NLOS capture with transient_nlos_path (laser and hidden-geometry "
                        "sampling on) instead of the camera: --res is the grid of sensed points on the "
                        "relay wall; --max-bounces counts the laser spot and the sensed point")
    p.add_argument("--relay-wall", default="relay_wall", help="--nlos: the relay wall's node")
    p.add_argument("--sensor-origin", nargs=3, type=float, metavar=("X", "Y", "Z"),
                   help="--nlos: sensor origin (m; default: node sensor_origin, else nlos_origin)")
    p.add_argument("--laser-origin", nargs=3, type=float, metavar=("X", "Y", "Z"),
                   help="--nlos: laser origin (m; default: node laser_origin, else nlos_origin)")
    p.add_argument("--laser-spot", nargs=2, type=float, default=[0.5, 0.5], metavar=("U", "V"),
                   help="--nlos single: the laser's target in the wall's texture coordinates")
    p.add_argument("--count-first-last", action="store_true",
                   help="--nlos: account_first_and_last_bounces")
    p.add_argument("--hidden-geometry-sampling", action="store_true",
                   help="--nlos: turn on nlos_hidden_geometry_sampling. Off by default: with it, "
                        "mitransient 1.3.1 misses paths through hidden geometry that faces away from "
                        "its sampling (the example scene's occluder paths, checked against the same "
                        "render with it off), so references are made without it")
    args = p.parse_args(argv)
    if args.max_bounces < 0 or args.spp < 1 or args.passes < 1 or args.bins < 1:
        p.error("--max-bounces must be >= 0; --spp, --passes, --bins >= 1")
    if args.bin_width <= 0:
        p.error("--bin-width must be > 0")
    if args.sum_bins < 1 or args.bins % args.sum_bins:
        p.error("--sum-bins must be >= 1 and divide --bins")
    if args.steady_only and (args.gate is not None or args.sum_bins > 1):
        p.error("--steady-only writes no gate and no cube: drop --gate and --sum-bins")
    if not args.variant.endswith("_rgb"):
        p.error("only RGB variants are supported")
    if args.passes < 2:
        warn("with a single pass the variances are NaN")
    return args


def main_nlos(args):
    """--nlos: the capture's transient with its variance over passes, and what gatetrace needs to
    render the same capture (laser equivalent powers, sensed points, laser spots)."""
    import drjit as dr
    import mitsuba as mi
    mi.set_variant(args.variant)
    import mitransient  # noqa: F401
    if not args.mitsuba_segment_lengths:
        use_exact_segment_lengths(mi, dr)
    if args.threads is not None:
        dr.set_thread_count(args.threads)
    out_path = args.output or os.path.splitext(os.path.basename(args.scene))[0] + f"_nlos_{args.nlos}_peer.npz"
    scene_data = load_gltf(args.scene)
    scene_dict, point_at, sensor_origin, laser_origin = build_nlos_scene(mi, scene_data, args)
    scene = mi.load_dict(scene_dict)
    integrator = scene.integrator()
    width, height = args.res
    cells = np.array([[point_at((i + 0.5) / width, (j + 0.5) / height) for i in range(width)]
                      for j in range(height)])
    normal = np.cross(point_at(1, 0) - point_at(0, 0), point_at(0, 1) - point_at(0, 0))
    normal /= np.linalg.norm(normal)
    targets = cells if args.nlos == "confocal" else point_at(*args.laser_spot)[None, None, :]
    power = laser_equivalent_power(point_at, laser_origin, normal, targets)
    chunks = [args.chunk_spp] * (args.spp // args.chunk_spp)
    if args.spp % args.chunk_spp:
        chunks.append(args.spp % args.chunk_spp)
    seeds = np.random.SeedSequence(args.seed).generate_state(
        args.passes * len(chunks), dtype=np.uint32).reshape(args.passes, len(chunks))
    moments = _RunningMoments()
    t0 = time.time()
    for p in range(args.passes):
        trans = 0.0
        for c, spp in enumerate(chunks):
            _, t_img = integrator.render(scene, seed=int(seeds[p, c]), spp=spp)
            trans = trans + np.array(t_img, dtype=np.float64)[..., :3] * (spp / args.spp)
        moments.add(trans)
        print(f"pass {p + 1}/{args.passes}: total {trans.sum():.6g}", file=sys.stderr, flush=True)
    total = time.time() - t0
    mean, var = moments.mean_and_var_of_mean()
    meta = {
        "tool": "tools/peer/peer_reference.py",
        "command_line": " ".join(shlex.quote(a) for a in sys.argv),
        "scene": args.scene,
        "versions": {"mitsuba": mi.__version__, "drjit": dr.__version__,
                     "mitransient": mitransient.__version__, "numpy": np.__version__},
        "variant": args.variant,
        "segment_lengths": "mitsuba (from offset ray origins)" if args.mitsuba_segment_lengths
                           else "exact (between surface points)",
        "integrator": scene_dict["integrator"],
        "laser": "projector, irradiance 1 W m^-2 at unit distance, fov 0.2 deg",
        "scan": args.nlos, "relay_wall": args.relay_wall,
        "sensor_origin": sensor_origin.tolist(), "laser_origin": laser_origin.tolist(),
        "laser_spot_uv": args.laser_spot if args.nlos == "single" else None,
        "max_bounces": args.max_bounces, "spp_per_pass": args.spp, "passes": args.passes,
        "seed": args.seed, "start": args.start, "bin_width": args.bin_width, "bins": args.bins,
        "time_unit": "metres of optical path from the laser spot to the sensed point"
                     + (" plus the first and last segments" if args.count_first_last else ""),
        "layout": "transient [grid_y, grid_x, T, 3]; *_var = variance of the mean over passes; "
                  "laser_power_equivalent [laser_y, laser_x] in W",
        "seconds_total": total, "threads": dr.thread_count(),
    }
    np.savez_compressed(out_path, transient_mean=mean.astype(np.float32), transient_var=var.astype(np.float32),
                        laser_power_equivalent=power.astype(np.float32), sensor_grid_xyz=cells.astype(np.float32),
                        laser_grid_xyz=np.broadcast_to(targets, power.shape + (3,)).astype(np.float32),
                        meta=np.array(json.dumps(meta, indent=1)))
    print(f"wrote {out_path} ({total:.1f} s)", file=sys.stderr)


def main(argv=None):
    args = parse_args(argv)
    if args.nlos:
        return main_nlos(args)
    gates = gate_bins(args)
    out_path = args.output or os.path.splitext(os.path.basename(args.scene))[0] + "_peer.npz"

    import drjit as dr
    import mitsuba as mi
    mi.set_variant(args.variant)
    import mitransient  # noqa: F401  (registers transient_* plugins)
    if not args.mitsuba_segment_lengths:
        use_exact_segment_lengths(mi, dr)
    if args.threads is not None:
        dr.set_thread_count(args.threads)

    scene_data = load_gltf(args.scene)
    if not args.steady_only and any(l["type"] == "directional" for l in scene_data["lights"]):
        warn("directional light: mitransient's path lengths for it are a constant 2 x the scene's "
              "bounding radius, not a plane wave's; only the steady image is a meaningful "
              "reference (see --steady-only)")
    max_depth = args.max_bounces + 1
    scene_dict = build_mitsuba_scene(mi, scene_data, args, max_depth)
    scene = mi.load_dict(scene_dict)
    integrator = scene.integrator()
    sensor = scene.sensors()[0]

    chunks = [args.chunk_spp] * (args.spp // args.chunk_spp)
    if args.spp % args.chunk_spp:
        chunks.append(args.spp % args.chunk_spp)
    seeds = np.random.SeedSequence(args.seed).generate_state(
        args.passes * len(chunks), dtype=np.uint32).reshape(args.passes, len(chunks))

    steady_m, trans_m = _RunningMoments(), _RunningMoments()
    gate_ms = [_RunningMoments() for _ in gates]
    coarse_m = _RunningMoments()
    k = args.sum_bins
    t0 = time.time()
    pass_times = []
    for p in range(args.passes):
        tp = time.time()
        steady = trans = 0.0
        for c, spp in enumerate(chunks):
            s_img, t_img = integrator.render(scene, sensor, seed=int(seeds[p, c]), spp=spp)
            # Weight chunks by their share of the pass's samples.
            steady = steady + np.array(s_img, dtype=np.float64) * (spp / args.spp)
            trans = trans + np.array(t_img, dtype=np.float64) * (spp / args.spp)
        steady_m.add(steady[..., :3])
        trans_m.add(trans[..., :3])
        for (ia, ib), gate_m in zip(gates, gate_ms):
            gate_m.add(trans[:, :, ia:ib, :3].sum(axis=2))
        if k > 1:
            h, w, t = trans.shape[:3]
            coarse_m.add(trans[..., :3].reshape(h, w, t // k, k, 3).sum(axis=3))
        pass_times.append(time.time() - tp)
        print(f"pass {p + 1}/{args.passes}: {pass_times[-1]:.1f} s, "
              f"steady image mean {steady[..., :3].reshape(-1, 3).mean(0)}",
              file=sys.stderr, flush=True)
    total = time.time() - t0

    with open(args.scene, "rb") as f:
        scene_sha = hashlib.sha256(f.read()).hexdigest()
    meta = {
        "tool": "tools/peer/peer_reference.py",
        "command_line": " ".join(shlex.quote(a) for a in sys.argv),
        "scene": args.scene,
        "scene_sha256": scene_sha,
        "versions": {
            "mitsuba": mi.__version__, "drjit": dr.__version__,
            "mitransient": mitransient.__version__, "numpy": np.__version__,
            "python": platform.python_version(),
        },
        "variant": args.variant,
        "segment_lengths": "mitsuba (from offset ray origins)" if args.mitsuba_segment_lengths
                           else "exact (between surface points)",
        "integrator": {"type": "transient_path", "max_depth": max_depth,
                       "rr_depth": max_depth + 1, "camera_unwarp": False},
        "film": {"type": "transient_hdr_film", "rfilter": "box",
                 "width": args.res[0], "height": args.res[1]},
        "sampler": "independent",
        "max_bounces": args.max_bounces,
        "spp_per_pass": args.spp,
        "passes": args.passes,
        "chunks_spp": chunks,
        "seed": args.seed,
        "render_seeds": seeds.tolist(),
        "time_unit": "metres of optical path (camera and light segments included)",
        "start": args.start, "bin_width": args.bin_width, "bins": args.bins,
        "bin_edges": [args.start + k * args.bin_width for k in range(args.bins + 1)],
        "gates": args.gate, "gate_bins": [list(g) for g in gates],
        "steady_only": args.steady_only,
        "sum_bins": k,
        "coarse_bin_edges": ([args.start + j * k * args.bin_width for j in range(args.bins // k + 1)]
                             if k > 1 else None),
        "camera": {"type": scene_dict["sensor"]["type"],
                   "yfov_rad": scene_data["camera"]["yfov"],
                   "znear": scene_data["camera"]["znear"],
                   "aperture_radius": scene_data["camera"]["aperture_radius"],
                   "focus_distance": scene_data["camera"]["focus_distance"]},
        "lights": [{key: (val.tolist() if isinstance(val, np.ndarray) else val)
                    for key, val in light.items() if key != "up"}
                   for light in scene_data["lights"]],
        "emitters": {key: {kk: (vv if not hasattr(vv, "matrix") else np.array(vv.matrix).tolist())
                           for kk, vv in val.items()}
                     for key, val in scene_dict.items() if key.startswith("punctual_")},
        "layout": "row 0 at the top, RGB last; transient [H,W,T,3]; "
                  "*_var = variance of the mean over passes",
        "seconds_total": total,
        "seconds_per_pass": pass_times,
        "threads": dr.thread_count(),
    }

    names = {"steady": "steady", "transient": "transient", "coarse": "transient_coarse"}
    moments = [("steady", steady_m), ("transient", trans_m)]
    for i, ((a, b), gate_m) in enumerate(zip(args.gate or [], gate_ms)):
        one = len(gate_ms) == 1 and not args.test_keys
        names[f"gate{i}"] = "gate" if one else f"gate_{_key_number(a)}_{_key_number(b)}"
        moments.append((f"gate{i}", gate_m))
    moments.append(("coarse", coarse_m))
    if len(set(names.values())) != len(names):
        raise SystemExit(f"error: two arrays would share a name: {sorted(names.values())}")
    if args.test_keys:
        cube = f"transient_{_key_number(args.start)}_step_{_key_number(args.bin_width * k)}"
        names["coarse" if k > 1 else "transient"] = cube
        if k > 1:
            names["transient"] = None
    meta["keys"] = {role: name for role, name in names.items() if name}
    out = {}
    for key, mom in moments:
        if mom.n == 0 or names[key] is None or (args.steady_only and key != "steady"):
            continue
        key = names[key]
        mean, var = mom.mean_and_var_of_mean()
        out[f"{key}_mean"] = mean.astype(np.float32)
        out[f"{key}_var"] = var.astype(np.float32)
    out["meta"] = np.array(json.dumps(meta, indent=1))
    np.savez_compressed(out_path, **out)
    print(f"wrote {out_path} ({total:.1f} s)", file=sys.stderr)


if __name__ == "__main__":
    main()
