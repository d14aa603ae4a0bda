#!/usr/bin/env python3
"""Writes the Cornell-box variants that exercise the thin-lens camera and the punctual lights
(standard library only):

* assets/scenes/cornell_box_thin_lens.gltf: the Cornell box with a white block (0.3 m cube,
  turned 30 deg) on the floor and a thin-lens camera (camera node extras: aperture radius
  0.15 m, focus distance 2.5 m, i.e. the back wall is in focus and the block is not).
* assets/scenes/cornell_box_spot.gltf: the Cornell box without its area light, lit by a
  KHR_lights_punctual spot light under the ceiling aimed down towards the back-left corner
  (intensity 3 W/sr, outer cone 0.5 rad, inner cone 0.4999 rad: an almost hard edge, which a
  Mitsuba `spot` emitter reproduces).
* assets/scenes/cornell_box_directional.gltf: the Cornell box without its area light and with
  the front of its ceiling cut away, lit by a directional light (irradiance 2 W/m^2) shining
  down and backwards through the opening.

    tools/scenes/make_cornell_variants.py
"""
import base64
import json
import math
import struct
from pathlib import Path

from make_animated_cornell import cube, HALF, FLOOR_Y

ROOT = Path(__file__).resolve().parents[2]
SOURCE = ROOT / "assets/scenes/cornell_box.gltf"


def quat_from_to(a, b):
    """Unit quaternion (x, y, z, w) turning unit vector a onto unit vector b."""
    ax = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    w = 1.0 + sum(x * y for x, y in zip(a, b))
    n = math.sqrt(sum(x * x for x in ax) + w * w)
    return [ax[0] / n, ax[1] / n, ax[2] / n, w / n]


def normalized(v):
    n = math.sqrt(sum(x * x for x in v))
    return [x / n for x in v]


class Doc:
    """The Cornell box's glTF with helpers to append buffer data, nodes and lights."""

    def __init__(self):
        self.doc = json.loads(SOURCE.read_text())
        self.data = bytearray(base64.b64decode(self.doc["buffers"][0]["uri"].split(",", 1)[1]))

    def view(self, payload, target=None):
        while len(self.data) % 4:
            self.data.append(0)
        view = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(payload)}
        if target:
            view["target"] = target
        self.data.extend(payload)
        self.doc["bufferViews"].append(view)
        return len(self.doc["bufferViews"]) - 1

    def accessor(self, view, component, count, kind, lo=None, hi=None):
        acc = {"bufferView": view, "componentType": component, "count": count, "type": kind}
        if lo is not None:
            acc["min"], acc["max"] = lo, hi
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def node(self, name):
        return next(i for i, n in enumerate(self.doc["nodes"]) if n.get("name") == name)

    def drop_node(self, name):
        index = self.node(name)
        scene = self.doc["scenes"][self.doc.get("scene", 0)]
        scene["nodes"] = [n for n in scene["nodes"] if n != index]

    def add_node(self, node):
        self.doc["nodes"].append(node)
        self.doc["scenes"][self.doc.get("scene", 0)]["nodes"].append(len(self.doc["nodes"]) - 1)

    def add_light(self, light, node):
        ext = self.doc.setdefault("extensions", {}).setdefault("KHR_lights_punctual", {"lights": []})
        ext["lights"].append(light)
        node["extensions"] = {"KHR_lights_punctual": {"light": len(ext["lights"]) - 1}}
        self.add_node(node)
        if "KHR_lights_punctual" not in self.doc["extensionsUsed"]:
            self.doc["extensionsUsed"].append("KHR_lights_punctual")

    def write(self, target, description):
        self.doc["buffers"][0] = {"byteLength": len(self.data), "uri": "data:application/octet-stream;base64,"
                                  + base64.b64encode(bytes(self.data)).decode()}
        self.doc["asset"]["generator"] = "gatetrace tools/scenes/make_cornell_variants.py"
        self.doc["extras"] = {"description": description}
        path = ROOT / "assets/scenes" / target
        path.write_text(json.dumps(self.doc, indent=1) + "\n")
        print(f"wrote {path}")


BASE = ("Cornell box, 1 m, open at +z. Lambertian one-sided walls (albedo = baseColorFactor), "
        "camera at (0,0,2) looking down -z, 40 deg field of view.")


def thin_lens():
    d = Doc()
    positions, normals, indices = cube()
    flat = lambda rows: b"".join(struct.pack("<3f", *r) for r in rows)
    pos = d.accessor(d.view(flat(positions), 34962), 5126, 24, "VEC3", [-HALF] * 3, [HALF] * 3)
    nor = d.accessor(d.view(flat(normals), 34962), 5126, 24, "VEC3")
    idx = d.accessor(d.view(struct.pack(f"<{len(indices)}I", *indices), 34963), 5125, len(indices), "SCALAR")
    d.doc["meshes"].append({"name": "block", "primitives": [{"attributes": {"POSITION": pos, "NORMAL": nor},
                                                             "indices": idx, "material": 0}]})
    turn = math.radians(30.0)
    d.add_node({"name": "block", "mesh": len(d.doc["meshes"]) - 1, "translation": [-0.15, FLOOR_Y + HALF, 0.05],
                "rotation": [0.0, math.sin(turn / 2), 0.0, math.cos(turn / 2)]})
    d.doc["nodes"][d.node("camera")]["extras"] = {"aperture_radius": 0.15, "focus_distance": 2.5}
    d.write("cornell_box_thin_lens.gltf", BASE + (
        " Light radiance 10 W/m^2/sr on its front face (-y). A white 0.3 m block turned 30 deg about +y stands on"
        " the floor at (-0.15, -0.35, 0.05). Thin-lens camera (node extras): aperture radius 0.15 m, focus"
        " distance 2.5 m (the back wall's plane): the block and the walls' front edges are out of focus."))


def spot():
    d = Doc()
    d.drop_node("light")
    aim = normalized([-0.3, -0.95, -0.3])
    d.add_light({"name": "spot", "type": "spot", "color": [1.0, 1.0, 1.0], "intensity": 3.0,
                 "spot": {"innerConeAngle": 0.4999, "outerConeAngle": 0.5}},
                {"name": "spot", "translation": [0.0, 0.45, 0.0],
                 "rotation": quat_from_to([0.0, 0.0, -1.0], aim)})
    d.write("cornell_box_spot.gltf", BASE + (
        " No area light: a KHR_lights_punctual spot light at (0, 0.45, 0) aimed along (-0.3, -0.95, -0.3)"
        " (normalised), intensity 3 W/sr, outer cone 0.5 rad, inner cone 0.4999 rad."))


def directional():
    d = Doc()
    d.drop_node("light")
    # The ceiling ends at z = -0.1: the light enters through the opening in front of it.
    ceiling = d.doc["meshes"][d.doc["nodes"][d.node("ceiling")]["mesh"]]
    acc = d.doc["accessors"][ceiling["primitives"][0]["attributes"]["POSITION"]]
    view = d.doc["bufferViews"][acc["bufferView"]]
    off = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    points = [list(struct.unpack_from("<3f", d.data, off + 12 * i)) for i in range(acc["count"])]
    moved = [[p[0], p[1], min(p[2], -0.1)] for p in points]
    raw = b"".join(struct.pack("<3f", *p) for p in moved)
    acc["bufferView"] = d.view(raw, 34962)
    acc.pop("byteOffset", None)
    acc["min"] = [min(p[k] for p in moved) for k in range(3)]
    acc["max"] = [max(p[k] for p in moved) for k in range(3)]
    travel = normalized([0.2, -1.0, -0.6])
    d.add_light({"name": "sun", "type": "directional", "color": [1.0, 1.0, 1.0], "intensity": 2.0},
                {"name": "sun", "translation": [0.0, 2.0, 1.0], "rotation": quat_from_to([0.0, 0.0, -1.0], travel)})
    d.write("cornell_box_directional.gltf", BASE + (
        " No area light; the ceiling ends at z = -0.1 m. A KHR_lights_punctual directional light (irradiance"
        " 2 W/m^2 on a surface facing it) travels along (0.2, -1, -0.6) (normalised) through the opening."))


if __name__ == "__main__":
    thin_lens()
    spot()
    directional()
