#!/usr/bin/env python3
"""Writes the paper's application scenes (Pediredla et al. 2019, section 7) as glTF 2.0 files in
assets/scenes/ (buffers embedded; standard library only). Each scene's `extras` name the gate the
application renders with (lengths in metres of optical path) and why.

* `fence.gltf` (Fig. 8, imaging through partial occluders): a giraffe of about 64,000
  triangles (smooth body, neck, legs and head) 6 m from a camera, behind a chain-link fence of
  thin six-sided wire links 3 m from the camera; a
  flash (point light) beside the camera; a thin lens (aperture radius 15 cm) focused on the
  figure. A 1 ns gate (0.30 m, 2.35 % of a scene 12.8 m across in the paper) on the figure's
  round trip leaves the fence's light out.
* `proximity.gltf` (Fig. 7, a proximity sensor on a car): a road, a car-like body of about
  52,000 triangles (superellipsoid body and cabin, 48-sided wheels) that drives towards the sensor
  from 3.5 m to 1.2 m ahead over 1 s of animation clock (`--frames N --anim-time 0..1`), and the
  sensor on the front of the ego car 0.5 m above the road: a pinhole camera and a spot light
  beside it. A 200 ps gate (6 cm, 1.14 % of a scene 5.3 m across in the paper) at a 2 m range.
* `cw_room.gltf` (Fig. 9, a depth-selective CW-ToF camera): a room 3 m wide, 2.4 m high and 3.5 m
  deep (5.2 m across) with a table, a cabinet, a figure on a plinth and a lamp; a flash beside
  the camera. A 13.2 MHz depth-selective code of 1,024 chips whose window (flat top of 2 chips, 44
  mm; 222 ps = 1.28 % of the scene across at half height) sits on the figure's round trip;
  everything else weighs 1/1024. `extras.gate_20ps` holds the same code with the paper's
  absolute 20 ps window (4,096 chips of 2 mm at 36.6 MHz).
* `dynamic.gltf` (Fig. 6, transients of a dynamic scene): a corner of a room 3.45 m across with a
  swinging pendulum and a turning fan, lit by a flash beside the camera. A gated transient camera
  images one 200 ps (6 cm, 1.74 % of the scene across) slice per 50 ms while the scene moves:
  `--frames 24 --gate-step 60mm --anim-time 0..1.15` renders 24 slices, each of the scene at
  its own time.

    tools/scenes/make_application_scenes.py
"""
import base64
import json
import math
import struct
from pathlib import Path

from make_nlos_scene import look_at_rotation

ROOT = Path(__file__).resolve().parents[2]


class Builder:
    """Triangle meshes (one primitive per material), nodes, a camera and punctual lights."""

    def __init__(self):
        self.data = bytearray()
        self.doc = {"asset": {"version": "2.0", "generator": "gatetrace tools/scenes/make_application_scenes.py"},
                    "scene": 0, "scenes": [{"nodes": []}], "nodes": [], "meshes": [], "materials": [],
                    "accessors": [], "bufferViews": [], "extensionsUsed": []}

    def material(self, name, rgb, metallic=0.0, roughness=1.0):
        self.doc["materials"].append({"name": name, "pbrMetallicRoughness": {
            "baseColorFactor": list(rgb) + [1.0], "metallicFactor": metallic, "roughnessFactor": roughness}})
        return len(self.doc["materials"]) - 1

    def _view(self, payload, target):
        while len(self.data) % 4:
            self.data.append(0)
        self.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(self.data), "byteLength": len(payload),
                                        "target": target})
        self.data.extend(payload)
        return len(self.doc["bufferViews"]) - 1

    def mesh(self, name, triangles, material):
        """A node with one mesh of `triangles` (lists of three xyz points, counter-clockwise seen
        from their front), flat-shaded (no normals)."""
        pts = [p for t in triangles for p in t]
        raw = b"".join(struct.pack("<3f", *p) for p in pts)
        lo = [min(p[k] for p in pts) for k in range(3)]
        hi = [max(p[k] for p in pts) for k in range(3)]
        view = self._view(raw, 34962)
        self.doc["accessors"].append({"bufferView": view, "componentType": 5126, "count": len(pts),
                                      "type": "VEC3", "min": lo, "max": hi})
        acc = len(self.doc["accessors"]) - 1
        self.doc["meshes"].append({"name": name, "primitives": [{"attributes": {"POSITION": acc},
                                                                 "material": material}]})
        self.node({"name": name, "mesh": len(self.doc["meshes"]) - 1})

    def indexed_mesh(self, name, mesh, material, node_extra=None):
        """A node with one indexed mesh (`mesh`: an IndexedMesh), flat-shaded (no normals); returns
        the node's index."""
        raw = b"".join(struct.pack("<3f", *p) for p in mesh.points)
        lo = [min(p[k] for p in mesh.points) for k in range(3)]
        hi = [max(p[k] for p in mesh.points) for k in range(3)]
        view = self._view(raw, 34962)
        self.doc["accessors"].append({"bufferView": view, "componentType": 5126, "count": len(mesh.points),
                                      "type": "VEC3", "min": lo, "max": hi})
        positions = len(self.doc["accessors"]) - 1
        view = self._view(struct.pack(f"<{3 * len(mesh.triangles)}I", *(i for t in mesh.triangles for i in t)), 34963)
        self.doc["accessors"].append({"bufferView": view, "componentType": 5125, "count": 3 * len(mesh.triangles),
                                      "type": "SCALAR"})
        self.doc["meshes"].append({"name": name, "primitives": [{"attributes": {"POSITION": positions},
                                                                 "indices": len(self.doc["accessors"]) - 1,
                                                                 "material": material}]})
        self.node(dict({"name": name, "mesh": len(self.doc["meshes"]) - 1}, **(node_extra or {})))
        return len(self.doc["nodes"]) - 1

    def node(self, node):
        self.doc["nodes"].append(node)
        self.doc["scenes"][0]["nodes"].append(len(self.doc["nodes"]) - 1)

    def camera(self, eye, target, yfov, extras=None):
        self.doc["cameras"] = [{"type": "perspective", "perspective": {"yfov": yfov, "znear": 1e-5}}]
        node = {"name": "camera", "camera": 0, "translation": list(eye),
                "rotation": look_at_rotation(eye, target)}
        if extras:
            node["extras"] = extras
        self.node(node)

    def point_light(self, name, position, intensity):
        ext = self.doc.setdefault("extensions", {}).setdefault("KHR_lights_punctual", {"lights": []})
        ext["lights"].append({"name": name, "type": "point", "intensity": intensity})
        self.node({"name": name, "translation": list(position),
                   "extensions": {"KHR_lights_punctual": {"light": len(ext["lights"]) - 1}}})
        if "KHR_lights_punctual" not in self.doc["extensionsUsed"]:
            self.doc["extensionsUsed"].append("KHR_lights_punctual")

    def child_mesh(self, parent, name, triangles, material, node_extra=None):
        """A mesh node under `parent`."""
        self.mesh(name, triangles, material)
        index = len(self.doc["nodes"]) - 1
        self.doc["scenes"][0]["nodes"].remove(index)
        self.doc["nodes"][parent].setdefault("children", []).append(index)
        self.doc["nodes"][index].update(node_extra or {})
        return index

    def mesh_node(self, name, triangles, material, node_extra):
        """Like mesh, with extra node fields (a translation to animate)."""
        self.mesh(name, triangles, material)
        self.doc["nodes"][-1].update(node_extra)
        return len(self.doc["nodes"]) - 1

    def accessor(self, payload, count, kind, lo=None, hi=None):
        view = self._view(payload, None)
        del self.doc["bufferViews"][view]["target"]
        acc = {"bufferView": view, "componentType": 5126, "count": count, "type": kind}
        if lo is not None:
            acc["min"], acc["max"] = lo, hi
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def spot_light(self, name, position, aim, intensity, inner, outer):
        ext = self.doc.setdefault("extensions", {}).setdefault("KHR_lights_punctual", {"lights": []})
        ext["lights"].append({"name": name, "type": "spot", "intensity": intensity,
                              "spot": {"innerConeAngle": inner, "outerConeAngle": outer}})
        self.node({"name": name, "translation": list(position), "rotation": look_at_rotation(position, aim),
                   "extensions": {"KHR_lights_punctual": {"light": len(ext["lights"]) - 1}}})
        if "KHR_lights_punctual" not in self.doc["extensionsUsed"]:
            self.doc["extensionsUsed"].append("KHR_lights_punctual")

    def write(self, name, description, gate, why, frames=None, alternate=None):
        self.doc["buffers"] = [{"byteLength": len(self.data), "uri": "data:application/octet-stream;base64,"
                                + base64.b64encode(bytes(self.data)).decode()}]
        if not self.doc["extensionsUsed"]:
            del self.doc["extensionsUsed"]
        self.doc["extras"] = {"description": description, "gate": gate, "gate_reason": why}
        if frames:
            self.doc["extras"]["frames"] = frames
        self.doc["extras"].update(alternate or {})
        path = ROOT / "assets/scenes" / name
        path.write_text(json.dumps(self.doc) + "\n")
        count = sum(self.doc["accessors"][p.get("indices", p["attributes"]["POSITION"])]["count"]
                    for m in self.doc["meshes"] for p in m["primitives"]) // 3
        print(f"wrote {path}: {count} triangles")


def sub(a, b):
    return [a[i] - b[i] for i in range(3)]


def add(a, b):
    return [a[i] + b[i] for i in range(3)]


def scale(a, s):
    return [x * s for x in a]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def norm(a):
    n = math.sqrt(sum(x * x for x in a))
    return [x / n for x in a]


def box(lo, hi):
    """The 12 outward-facing triangles of an axis-aligned box."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    c = [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
         [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]]
    faces = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (3, 7, 6, 2), (0, 4, 7, 3), (1, 2, 6, 5)]
    return [t for a, b, cc, d in faces for t in ([c[a], c[b], c[cc]], [c[a], c[cc], c[d]])]


def tilted_box(base, top, half_width):
    """A square prism of half-width `half_width` from point `base` to point `top`."""
    axis = norm(sub(top, base))
    side = norm(cross(axis, [0.0, 0.0, 1.0])) if abs(axis[2]) < 0.9 else norm(cross(axis, [1.0, 0.0, 0.0]))
    other = cross(axis, side)
    ring = lambda p: [add(p, add(scale(side, half_width * a), scale(other, half_width * b)))
                      for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    lo, hi = ring(base), ring(top)
    tris = []
    for i in range(4):
        j = (i + 1) % 4
        tris += [[lo[i], lo[j], hi[j]], [lo[i], hi[j], hi[i]]]
    tris += [[lo[0], lo[2], lo[1]], [lo[0], lo[3], lo[2]], [hi[0], hi[1], hi[2]], [hi[0], hi[2], hi[3]]]
    return tris


def cylinder(a, b, radius, sides=6):
    """An open six-sided tube from a to b, faces outward."""
    axis = norm(sub(b, a))
    u = norm(cross(axis, [0.0, 0.0, 1.0]))
    v = cross(axis, u)
    ring = lambda p: [add(p, add(scale(u, radius * math.cos(2 * math.pi * k / sides)),
                                 scale(v, radius * math.sin(2 * math.pi * k / sides)))) for k in range(sides)]
    ra, rb = ring(a), ring(b)
    tris = []
    for k in range(sides):
        m = (k + 1) % sides
        tris += [[ra[k], ra[m], rb[m]], [ra[k], rb[m], rb[k]]]
    return tris


def superellipsoid(centre, radii, exponent, nu=40, nv=20):
    """A closed superellipsoid (|x/a|^(2/e) + ... = 1 with e = exponent; small e: box-like with
    rounded edges), faces outward."""
    def f(w, m):
        c = math.cos(w)
        return math.copysign(abs(c) ** m, c)

    def g(w, m):
        s_ = math.sin(w)
        return math.copysign(abs(s_) ** m, s_)

    def point(i, j):
        u = 2 * math.pi * i / nu
        v = -math.pi / 2 + math.pi * j / nv
        return [centre[0] + radii[0] * f(v, exponent) * f(u, exponent),
                centre[1] + radii[1] * g(v, exponent),
                centre[2] + radii[2] * f(v, exponent) * g(u, exponent)]
    tris = []
    for i in range(nu):
        for j in range(nv):
            a, b, c, d = point(i, j), point(i + 1, j), point(i + 1, j + 1), point(i, j + 1)
            if j > 0:
                tris.append([a, c, b])
            if j < nv - 1:
                tris.append([a, d, c])
    return tris


def wheel(centre, radius, width, sides=32):
    """A closed cylinder along x (a wheel), faces outward."""
    tris = []
    x0, x1 = centre[0] - width / 2, centre[0] + width / 2
    ring = lambda x: [[x, centre[1] + radius * math.cos(2 * math.pi * k / sides),
                       centre[2] + radius * math.sin(2 * math.pi * k / sides)] for k in range(sides)]
    a, b = ring(x0), ring(x1)
    for k in range(sides):
        m = (k + 1) % sides
        tris += [[a[k], a[m], b[m]], [a[k], b[m], b[k]]]
        tris += [[[x0, centre[1], centre[2]], a[m], a[k]], [[x1, centre[1], centre[2]], b[k], b[m]]]
    return tris


class IndexedMesh:
    """Points and counter-clockwise (seen from outside) index triples, merged part by part."""

    def __init__(self, points=None, triangles=None):
        self.points = points or []
        self.triangles = triangles or []

    def add(self, other):
        base = len(self.points)
        self.points += other.points
        self.triangles += [(a + base, b + base, c + base) for a, b, c in other.triangles]
        return self


def smooth_superellipsoid(centre, radii, exponent, nu, nv):
    """The closed superellipsoid of `superellipsoid` as an indexed mesh of 2 nu (nv - 1)
    triangles (one vertex per pole)."""
    def f(w, m):
        return math.copysign(abs(math.cos(w)) ** m, math.cos(w))

    def g(w, m):
        return math.copysign(abs(math.sin(w)) ** m, math.sin(w))

    mesh = IndexedMesh()
    mesh.points.append([centre[0], centre[1] - radii[1], centre[2]])
    for j in range(1, nv):
        v = -math.pi / 2 + math.pi * j / nv
        for i in range(nu):
            u = 2 * math.pi * i / nu
            mesh.points.append([centre[0] + radii[0] * f(v, exponent) * f(u, exponent),
                                centre[1] + radii[1] * g(v, exponent),
                                centre[2] + radii[2] * f(v, exponent) * g(u, exponent)])
    mesh.points.append([centre[0], centre[1] + radii[1], centre[2]])
    top = len(mesh.points) - 1
    ring = lambda j, i: 1 + (j - 1) * nu + i % nu
    for i in range(nu):
        mesh.triangles.append((0, ring(1, i), ring(1, i + 1)))
        mesh.triangles.append((top, ring(nv - 1, i + 1), ring(nv - 1, i)))
        for j in range(1, nv - 1):
            a, b, c, d = ring(j, i), ring(j, i + 1), ring(j + 1, i + 1), ring(j + 1, i)
            mesh.triangles += [(a, c, b), (a, d, c)]
    return mesh


def catmull_rom(points, samples):
    """`samples` points along the Catmull-Rom spline through `points` (its ends included)."""
    ext = [sub(scale(points[0], 2.0), points[1])] + list(points) + [sub(scale(points[-1], 2.0), points[-2])]
    spans = len(points) - 1
    out = []
    for k in range(samples):
        x = k / (samples - 1) * spans
        i = min(int(x), spans - 1)
        t = x - i
        p0, p1, p2, p3 = ext[i], ext[i + 1], ext[i + 2], ext[i + 3]
        out.append([0.5 * (2 * p1[d] + (p2[d] - p0[d]) * t + (2 * p0[d] - 5 * p1[d] + 4 * p2[d] - p3[d]) * t * t
                           + (3 * p1[d] - p0[d] - 3 * p2[d] + p3[d]) * t ** 3) for d in range(3)])
    return out


def tube(centres, radii, sides):
    """A closed tube swept along the polyline `centres` (ring k of radius radii[k], frames carried
    along by parallel transport), capped at both ends, faces outward: 2 sides (len - 1) + 2 sides
    triangles."""
    n = len(centres)
    tangents = [norm(sub(centres[min(k + 1, n - 1)], centres[max(k - 1, 0)])) for k in range(n)]
    t0 = tangents[0]
    u = norm(cross(t0, [0.0, 0.0, 1.0])) if abs(t0[2]) < 0.9 else norm(cross(t0, [1.0, 0.0, 0.0]))
    mesh = IndexedMesh()
    for k in range(n):
        t = tangents[k]
        u = norm(sub(u, scale(t, sum(u[d] * t[d] for d in range(3)))))
        v = cross(t, u)
        for j in range(sides):
            a = 2 * math.pi * j / sides
            mesh.points.append(add(centres[k], add(scale(u, radii[k] * math.cos(a)), scale(v, radii[k] * math.sin(a)))))
    idx = lambda k, j: k * sides + j % sides
    for k in range(n - 1):
        for j in range(sides):
            mesh.triangles += [(idx(k, j), idx(k, j + 1), idx(k + 1, j + 1)), (idx(k, j), idx(k + 1, j + 1), idx(k + 1, j))]
    mesh.points += [centres[0], centres[-1]]
    first, last = len(mesh.points) - 2, len(mesh.points) - 1
    for j in range(sides):
        mesh.triangles += [(first, idx(0, j + 1), idx(0, j)), (last, idx(n - 1, j), idx(n - 1, j + 1))]
    return mesh


def giraffe(z):
    """A giraffe about 3.5 m tall facing +x in the plane z: a superellipsoid body and head, a neck,
    four jointed legs, a tail and two ossicones swept as smooth tubes (about 64,000 triangles)."""
    mesh = smooth_superellipsoid([0.0, 1.65, z], [0.85, 0.38, 0.33], 0.9, 160, 80)
    neck = catmull_rom([[0.6, 1.75, z], [0.85, 2.3, z], [1.0, 2.8, z], [1.12, 3.18, z]], 80)
    mesh.add(tube(neck, [0.21 - 0.11 * k / 79 for k in range(80)], 64))
    mesh.add(smooth_superellipsoid([1.3, 3.25, z], [0.27, 0.12, 0.1], 1.0, 64, 32))
    for dz in (-0.05, 0.05):
        horn = catmull_rom([[1.15, 3.3, z + dz], [1.14, 3.42, z + dz], [1.12, 3.52, z + dz]], 8)
        mesh.add(tube(horn, [0.022, 0.02, 0.018, 0.017, 0.018, 0.022, 0.027, 0.03], 24))
    for x in (-0.6, 0.55):
        for dz in (-0.18, 0.18):
            leg = catmull_rom([[x, 1.55, z + dz], [x + 0.05, 0.85, z + dz], [x - 0.02, 0.32, z + dz],
                               [x, 0.0, z + dz]], 72)
            mesh.add(tube(leg, [0.11 - 0.05 * min(k / 40, 1.0) + 0.012 * max(k - 66, 0) / 5 for k in range(72)], 40))
    tail = catmull_rom([[-0.78, 1.85, z], [-0.9, 1.6, z], [-0.95, 1.3, z]], 24)
    mesh.add(tube(tail, [0.03 - 0.015 * k / 23 for k in range(24)], 16))
    return mesh


def proximity():
    b = Builder()
    road = b.material("asphalt", (0.12, 0.12, 0.12))
    verge = b.material("verge", (0.3, 0.4, 0.2))
    paint = b.material("car_paint", (0.6, 0.08, 0.06), metallic=0.3, roughness=0.35)
    glass = b.material("glass", (0.05, 0.06, 0.08), metallic=1.0, roughness=0.1)
    tyre = b.material("tyre", (0.04, 0.04, 0.04))
    b.mesh("road", [[[-1.8, 0, 1.0], [1.8, 0, 1.0], [1.8, 0, -5.0]], [[-1.8, 0, 1.0], [1.8, 0, -5.0], [-1.8, 0, -5.0]]],
           road)
    b.mesh("verge", [[[-1.8, 0, 1.0], [-1.8, 0, -5.0], [-3.0, 0.3, -5.0]], [[-1.8, 0, 1.0], [-3.0, 0.3, -5.0],
                                                                           [-3.0, 0.3, 1.0]]], verge)
    # The car, modelled about its own origin (front bumper at z = +2.1 relative to its centre),
    # then animated along -z -> +z towards the sensor at z = 0.
    body = smooth_superellipsoid([0.0, 0.55, 0.0], [0.85, 0.35, 2.1], 0.25, 200, 100)
    cabin = smooth_superellipsoid([0.0, 1.0, -0.2], [0.75, 0.3, 1.1], 0.3, 128, 48)
    wheels = []
    for x in (-0.8, 0.8):
        for z in (-1.35, 1.35):
            wheels += wheel([x, 0.32, z], 0.32, 0.22, sides=48)
    start, end = -3.5 - 2.1, -1.2 - 2.1  # car centre: front bumper from 3.5 m to 1.2 m ahead
    nodes = [b.indexed_mesh("car_body", body, paint, {"translation": [0.0, 0.0, start]}),
             b.indexed_mesh("car_cabin", cabin, glass, {"translation": [0.0, 0.0, start]}),
             b.mesh_node("car_wheels", wheels, tyre, {"translation": [0.0, 0.0, start]})]
    times = b.accessor(struct.pack("<2f", 0.0, 1.0), 2, "SCALAR", [0.0], [1.0])
    moves = b.accessor(struct.pack("<6f", 0.0, 0.0, start, 0.0, 0.0, end), 2, "VEC3")
    b.doc["animations"] = [{"name": "approach",
                            "samplers": [{"input": times, "output": moves, "interpolation": "LINEAR"}],
                            "channels": [{"sampler": 0, "target": {"node": n, "path": "translation"}}
                                         for n in nodes]}]
    eye, target = [0.0, 0.5, 0.0], [0.0, 0.5, -3.0]
    b.camera(eye, target, math.radians(50.0))
    b.spot_light("illuminator", [0.1, 0.5, 0.0], [0.1, 0.5, -3.0], 20.0, 0.5, 0.6)
    b.write("proximity.gltf",
            "A road, a car-like body (superellipsoid body and cabin, 48-sided wheels; 52,000 triangles) driving towards a proximity "
            "sensor from 3.5 m to 1.2 m ahead over 1 s of animation clock, and the sensor on the ego car 0.5 m "
            "above the road: a pinhole camera (50 deg) and a 20 W/sr spot light (cone 0.6 rad) beside it. "
            "Pediredla et al. 2019, Fig. 7.",
            "box:4.0..4.06",
            "200 ps (6 cm) at a round trip of 4 m: surfaces about 2 m ahead, where the car enters the sensor's "
            "range mid-animation")

def fence():
    b = Builder()
    ground = b.material("ground", (0.35, 0.45, 0.25))
    backdrop = b.material("backdrop", (0.6, 0.55, 0.45))
    hide = b.material("giraffe", (0.8, 0.6, 0.25))
    wire = b.material("wire", (0.7, 0.7, 0.72), metallic=1.0, roughness=0.5)
    half = 7.0
    b.mesh("ground", [[[-half, 0, -half], [-half, 0, half], [half, 0, half]],
                      [[-half, 0, -half], [half, 0, half], [half, 0, -half]]], ground)
    b.mesh("backdrop", [[[-half, 0, -6.0], [half, 0, -6.0], [half, 4.0, -6.0]],
                        [[-half, 0, -6.0], [half, 4.0, -6.0], [-half, 4.0, -6.0]]], backdrop)
    # The giraffe: body, four legs, a neck and a head, about 3 m tall, 6 m from the camera.
    z = -3.0
    b.indexed_mesh("giraffe", giraffe(z), hide)
    # Chain-link fence at z = 0: diagonal wires 0.2 m apart both ways, radius 1 cm, 0 <= y <= 2.4,
    # |x| <= 4, and two posts. Each wire is made of links from crossing to crossing (0.14 m), as a
    # modelled chain-link mesh is: tubes spanning the fence in one piece are long slivers whose
    # boxes overlap everywhere, and cost every method over twice its time per sample.
    spacing, top, width = 0.2, 2.4, 4.0
    wires = []
    n = int((2 * width + top) / spacing) + 1
    for sign in (1.0, -1.0):
        for i in range(n):
            # The line x = sign * (y + c) clipped to the fence's rectangle.
            c = -width - top + i * spacing
            pts = []
            for y in (0.0, top):
                x = sign * (y + c) if sign > 0 else -(y + c)
                pts.append([x, y])
            (xa, ya), (xb, yb) = pts
            # Clip to |x| <= width.
            def clip(x0, y0, x1, y1):
                t0, t1 = 0.0, 1.0
                for p, q in ((-(x1 - x0), x0 + width), (x1 - x0, width - x0)):
                    if p == 0:
                        if q < 0:
                            return None
                        continue
                    r = q / p
                    if p < 0:
                        t0 = max(t0, r)
                    else:
                        t1 = min(t1, r)
                if t0 >= t1:
                    return None
                return ([x0 + t0 * (x1 - x0), y0 + t0 * (y1 - y0)], [x0 + t1 * (x1 - x0), y0 + t1 * (y1 - y0)])
            seg = clip(xa, ya, xb, yb)
            if seg:
                (x0, y0), (x1, y1) = seg
                pieces = max(1, round(math.hypot(x1 - x0, y1 - y0) / (spacing * math.sqrt(0.5))))
                for k in range(pieces):
                    a, c2 = k / pieces, (k + 1) / pieces
                    wires += cylinder([x0 + a * (x1 - x0), y0 + a * (y1 - y0), 0.0],
                                      [x0 + c2 * (x1 - x0), y0 + c2 * (y1 - y0), 0.0], 0.01)
    for x in (-width, width):
        wires += cylinder([x, 0.0, 0.0], [x, top + 0.1, 0.0], 0.05, sides=8)
    b.mesh("fence", wires, wire)
    eye, target = [0.0, 1.7, 3.0], [0.3, 2.0, z]
    focus = math.dist(eye, target)
    b.camera(eye, target, math.radians(40.0), {"aperture_radius": 0.15, "focus_distance": round(focus, 4)})
    b.point_light("flash", [0.3, 1.7, 3.0], 60.0)
    b.write("fence.gltf",
            "A giraffe (a smooth mesh of 64,000 triangles) 6 m from the camera behind a chain-link fence (galvanised GGX wire links "
            "of radius 1 cm, 0.2 m apart, at z = 0, 3 m from the camera), a grassy ground and a backdrop at "
            "z = -6 m; a 60 W/sr flash beside the camera; a thin lens (aperture radius 15 cm) focused on the "
            "figure. Pediredla et al. 2019, Fig. 8.",
            "box:11.3..11.6",
            "1 ns (0.30 m) about the flash -> figure -> camera round trip (11.4 m to the front of its body); the fence's round trip "
            "(about 6 m) falls outside it, so a gated camera sees through the fence")


def room_shell(b, lo, hi, materials):
    """The six inward-facing walls of the box lo..hi: floor, ceiling, then walls -z, +z, -x, +x."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    c = [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
         [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]]
    # Outward faces of box() reversed: each quad listed counter-clockwise seen from inside.
    faces = {"floor": (0, 4, 5, 1), "ceiling": (3, 2, 6, 7), "back_wall": (0, 1, 2, 3),
             "front_wall": (4, 7, 6, 5), "left_wall": (0, 3, 7, 4), "right_wall": (1, 5, 6, 2)}
    for name, (a, bb, cc, d) in faces.items():
        if name in materials:
            b.mesh(name, [[c[a], c[bb], c[cc]], [c[a], c[cc], c[d]]], materials[name])


def cw_room():
    b = Builder()
    wall = b.material("plaster", (0.7, 0.68, 0.62))
    floor = b.material("oak", (0.45, 0.3, 0.18), roughness=0.6)
    wood = b.material("walnut", (0.3, 0.18, 0.1))
    stone = b.material("stone", (0.75, 0.75, 0.72))
    brass = b.material("brass", (0.8, 0.6, 0.3), metallic=1.0, roughness=0.3)
    room_shell(b, [-1.5, 0.0, -3.0], [1.5, 2.4, 0.5],
               {"floor": floor, "ceiling": wall, "back_wall": wall, "front_wall": wall, "left_wall": wall,
                "right_wall": wall})
    # A table near the camera (left), a cabinet against the back wall (right).
    table = box([-1.3, 0.72, -1.2], [-0.4, 0.76, -0.5])
    for x in (-1.25, -0.45):
        for z in (-1.15, -0.55):
            table += box([x - 0.03, 0.0, z - 0.03], [x + 0.03, 0.72, z + 0.03])
    b.mesh("table", table, wood)
    b.mesh("cabinet", box([0.5, 0.0, -3.0], [1.4, 1.6, -2.5]), wood)
    # The figure the code selects: a bust-like superellipsoid and head on a plinth, 2.2 m ahead.
    figure = box([-0.25, 0.0, -2.15], [0.25, 0.9, -1.85])
    figure += superellipsoid([0.0, 1.15, -2.0], [0.22, 0.25, 0.14], 0.6, 40, 20)
    figure += superellipsoid([0.0, 1.55, -2.0], [0.11, 0.15, 0.12], 1.0, 32, 16)
    b.mesh("figure", figure, stone)
    lamp = superellipsoid([-0.85, 1.0, -0.85], [0.12, 0.14, 0.12], 1.0, 32, 16)
    lamp += tilted_box([-0.85, 0.76, -0.85], [-0.85, 0.9, -0.85], 0.015)
    b.mesh("lamp", lamp, brass)
    eye, target = [0.2, 1.4, 0.3], [0.0, 1.1, -2.0]
    b.camera(eye, target, math.radians(60.0))
    b.point_light("flash", [0.3, 1.4, 0.3], 8.0)
    # The figure's front is about 2.15 m from the flash and the camera: a round trip near 4.3 m.
    centre = 4.36
    gate, freq, period = depth_selective_gate(1024, 3, 0.0222, centre)
    narrow, narrow_freq, narrow_period = depth_selective_gate(4096, 3, 0.005996 / 3, centre)
    b.write("cw_room.gltf",
            "A room 3 m x 2.4 m x 3.5 m (5.2 m across) with a table and a lamp near the camera, a cabinet against "
            "the back wall and a stone figure on a plinth 2.2 m ahead; an 8 W/sr flash beside a 60 deg pinhole "
            "camera. Pediredla et al. 2019, Fig. 9 (Tadano et al. 2015's depth-selective camera).",
            gate,
            f"a CW-ToF code of 1024 chips at {freq / 1e6:.2f} MHz (period {period:.2f} m of path, longer than the "
            f"paths that matter): weight 1 over a flat top of 2 chips (44 mm) about the figure's round trip "
            f"({centre} m), falling to 1/1024 over one chip either side (222 ps, 1.28 % of the room across, at half "
            "height); the rest of the room weighs 1/1024",
            alternate={"gate_20ps": narrow, "gate_20ps_reason":
                       f"the same code with the paper's absolute window: 4096 chips of 2.0 mm at {narrow_freq / 1e6:.2f} "
                       f"MHz, 3 chips (6.0 mm, 20 ps) at half height about the figure's round trip; the period, "
                       f"{narrow_period:.2f} m of path, is shorter than the longest paths of five bounces, so paths "
                       f"{narrow_period:.2f} m longer than the window's fall in it again"})


def depth_selective_gate(chips, neighbours, chip, centre):
    """The gate `cw:FREQ,PHASE,depthsel:CHIPS:NEIGHBOURS` whose flat top ((N - 1) chips of `chip`
    metres of path) is centred on the path length `centre` (m); returns it, the frequency (Hz)
    and the period (m of path)."""
    period = chip * chips
    freq = 299792458.0 / period
    # C(x), x = f l / c + phase / 360, is 1 on [0, (N - 1) / P]: centre the flat top on `centre`.
    x_top = (neighbours - 1) / (2 * chips)
    phase = (360.0 * (x_top - centre / period)) % 360.0
    return f"cw:{freq:.6e},{phase:.4f},depthsel:{chips}:{neighbours}", freq, period


def dynamic():
    b = Builder()
    wall = b.material("plaster", (0.72, 0.7, 0.66))
    floor = b.material("tiles", (0.5, 0.5, 0.55), roughness=0.5)
    red = b.material("red", (0.7, 0.1, 0.08))
    steel = b.material("steel", (0.7, 0.72, 0.75), metallic=1.0, roughness=0.35)
    blue = b.material("blue", (0.1, 0.2, 0.6))
    room_shell(b, [-1.2, 0.0, -2.0], [1.2, 2.0, 0.2],
               {"floor": floor, "back_wall": wall, "left_wall": wall, "ceiling": wall})
    # A pendulum: a bob of radius 0.18 m on a 1.2 m rod from a pivot at the ceiling, swinging
    # +-35 deg about z with a period of 2 s (one swing per second of animation clock).
    b.node({"name": "pendulum", "translation": [-0.3, 2.0, -1.2]})
    pendulum = len(b.doc["nodes"]) - 1
    b.child_mesh(pendulum, "pendulum_rod", tilted_box([0.0, 0.0, 0.0], [0.0, -1.2, 0.0], 0.01), steel)
    b.child_mesh(pendulum, "pendulum_bob", superellipsoid([0.0, -1.35, 0.0], [0.18, 0.18, 0.18], 1.0, 32, 16), red)
    times, angles = [], []
    for k in range(25):
        t = k / 24 * 1.2
        a = math.radians(35.0) * math.cos(math.pi * t)
        times.append(t)
        angles += [0.0, 0.0, math.sin(a / 2), math.cos(a / 2)]
    # A fan: four blades turning about a horizontal axis (z) at half a turn per second, mounted
    # on the right of the back wall.
    b.node({"name": "fan", "translation": [0.6, 1.1, -1.9]})
    fan = len(b.doc["nodes"]) - 1
    blades = []
    for k in range(4):
        a = k * math.pi / 2
        tip = [0.45 * math.cos(a), 0.45 * math.sin(a), 0.0]
        blades += tilted_box([0.0, 0.0, 0.0], tip, 0.06)
    b.child_mesh(fan, "fan_blades", blades, blue)
    b.mesh("fan_hub", superellipsoid([0.6, 1.1, -1.9], [0.08, 0.08, 0.08], 1.0, 24, 12), steel)
    spins = []
    for t in times:
        a = math.pi * t
        spins += [0.0, 0.0, math.sin(a / 2), math.cos(a / 2)]
    n = len(times)
    t_acc = b.accessor(struct.pack(f"<{n}f", *times), n, "SCALAR", [times[0]], [times[-1]])
    swing = b.accessor(struct.pack(f"<{4 * n}f", *angles), n, "VEC4")
    spin = b.accessor(struct.pack(f"<{4 * n}f", *spins), n, "VEC4")
    b.doc["animations"] = [{"name": "motion",
                            "samplers": [{"input": t_acc, "output": swing, "interpolation": "LINEAR"},
                                         {"input": t_acc, "output": spin, "interpolation": "LINEAR"}],
                            "channels": [{"sampler": 0, "target": {"node": pendulum, "path": "rotation"}},
                                         {"sampler": 1, "target": {"node": fan, "path": "rotation"}}]}]
    eye, target = [0.0, 1.2, 1.0], [0.0, 1.0, -1.5]
    b.camera(eye, target, math.radians(55.0))
    b.point_light("flash", [0.15, 1.3, 1.0], 6.0)
    b.write("dynamic.gltf",
            "A corner of a room 3.45 m across (floor, ceiling, back and left walls) with a pendulum swinging +-35 deg "
            "(a red bob on a 1.2 m rod, period 2 s) and a four-bladed fan turning half a turn per second, lit by a 6 W/sr "
            "flash beside a 55 deg pinhole camera. Pediredla et al. 2019, Fig. 6.",
            "box:5.0..5.06",
            "200 ps (6 cm, 1.74 % of the scene across) per slice; the first slice holds the pendulum's round trip "
            "(its bob is 2.4 m from the camera)",
            "--frames 24 --gate-step 60mm --anim-time 0..1.15: 24 slices 6 cm apart from 5.0 m, one every 50 ms of "
            "the scene's clock")


if __name__ == "__main__":
    fence()
    proximity()
    cw_room()
    dynamic()
