#!/usr/bin/env python3
"""Writes assets/scenes/cornell_box_moving_block.gltf: the Cornell box with a white block
(0.3 m cube) sliding across the floor from x = -0.25 m to x = +0.25 m while turning 90 degrees
about the vertical, over 1 s of animation clock (linear keys). Standard library only.

    tools/scenes/make_animated_cornell.py
"""
import base64
import json
import math
import struct
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SOURCE = ROOT / "assets/scenes/cornell_box.gltf"
TARGET = ROOT / "assets/scenes/cornell_box_moving_block.gltf"

HALF = 0.15  # half the block's edge (m)
START_X, END_X = -0.25, 0.25  # block centre at t = 0 s and t = 1 s (m)
FLOOR_Y = -0.5


def cube():
    """24 vertices (4 per face, outward normals) and 36 indices, counter-clockwise outside."""
    positions, normals, indices = [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = [0.0, 0.0, 0.0]
            n[axis] = sign
            u = [0.0, 0.0, 0.0]
            v = [0.0, 0.0, 0.0]
            u[(axis + 1) % 3] = 1.0
            v[(axis + 2) % 3] = 1.0
            if sign < 0:
                u, v = v, u
            base = len(positions)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                positions.append([HALF * (n[i] + a * u[i] + b * v[i]) for i in range(3)])
                normals.append(n)
            indices += [base, base + 1, base + 2, base, base + 2, base + 3]
    return positions, normals, indices


def main():
    doc = json.loads(SOURCE.read_text())
    data = bytearray(base64.b64decode(doc["buffers"][0]["uri"].split(",", 1)[1]))

    def add_view(payload, target=None):
        while len(data) % 4:
            data.append(0)
        view = {"buffer": 0, "byteOffset": len(data), "byteLength": len(payload)}
        if target:
            view["target"] = target
        data.extend(payload)
        doc["bufferViews"].append(view)
        return len(doc["bufferViews"]) - 1

    def add_accessor(view, component, count, kind, lo=None, hi=None):
        acc = {"bufferView": view, "componentType": component, "count": count, "type": kind}
        if lo is not None:
            acc["min"], acc["max"] = lo, hi
        doc["accessors"].append(acc)
        return len(doc["accessors"]) - 1

    positions, normals, indices = cube()
    flat = lambda rows: b"".join(struct.pack("<3f", *r) for r in rows)
    pos = add_accessor(add_view(flat(positions), 34962), 5126, 24, "VEC3", [-HALF] * 3, [HALF] * 3)
    nor = add_accessor(add_view(flat(normals), 34962), 5126, 24, "VEC3")
    idx = add_accessor(add_view(struct.pack(f"<{len(indices)}I", *indices), 34963), 5125, len(indices), "SCALAR")
    doc["meshes"].append({"name": "block", "primitives": [{"attributes": {"POSITION": pos, "NORMAL": nor},
                                                           "indices": idx, "material": 0}]})
    y = FLOOR_Y + HALF
    doc["nodes"].insert(len(doc["nodes"]) - 1, {"name": "block", "mesh": len(doc["meshes"]) - 1,
                                                 "translation": [START_X, y, 0.0]})
    block = len(doc["nodes"]) - 2
    doc["scenes"][doc.get("scene", 0)]["nodes"] = list(range(len(doc["nodes"])))

    times = add_accessor(add_view(struct.pack("<2f", 0.0, 1.0)), 5126, 2, "SCALAR", [0.0], [1.0])
    moves = add_accessor(add_view(struct.pack("<6f", START_X, y, 0.0, END_X, y, 0.0)), 5126, 2, "VEC3")
    s = math.sin(math.pi / 4)
    turns = add_accessor(add_view(struct.pack("<8f", 0.0, 0.0, 0.0, 1.0, 0.0, s, 0.0, s)), 5126, 2, "VEC4")
    doc["animations"] = [{
        "name": "slide",
        "samplers": [{"input": times, "output": moves, "interpolation": "LINEAR"},
                     {"input": times, "output": turns, "interpolation": "LINEAR"}],
        "channels": [{"sampler": 0, "target": {"node": block, "path": "translation"}},
                     {"sampler": 1, "target": {"node": block, "path": "rotation"}}],
    }]
    doc["buffers"][0] = {"byteLength": len(data),
                         "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(data)).decode()}
    doc["asset"]["generator"] = "gatetrace tools/scenes/make_animated_cornell.py"
    doc["extras"] = {"description": doc["extras"]["description"] + (
        f" A white {2 * HALF} m block on the floor slides from x = {START_X} m to x = {END_X} m and turns 90 deg"
        " about +y over 1 s of animation clock (linear keys).")}
    TARGET.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {TARGET}")


if __name__ == "__main__":
    main()
