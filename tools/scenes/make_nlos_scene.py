#!/usr/bin/env python3
"""Writes the example non-line-of-sight scene, assets/scenes/nlos_letter.gltf (glTF 2.0, buffer
embedded). Standard library only.

    tools/scenes/make_nlos_scene.py [--out assets/scenes/nlos_letter.gltf]

Geometry (metres; +y up):
- `relay_wall`: the visible relay wall, 1 m x 1 m in the plane z = 0 (x, y in [-0.5, 0.5]),
  facing +z, Lambertian white (albedo 0.8). Its texture coordinates run u along +x and v along
  +y (0 at the lower left corner), the parameterisation a sensed-point grid is laid on: as
  mitransient's nlos_capture_meter on a rectangle, whose grid row j lies at y = (j + 0.5) / M of
  the wall's height from its lower edge (checked by rendering with it: a hidden patch at +y
  lit the higher rows).
- `hidden_letter`: a "Z" 0.4 m tall and 0.3 m wide, in the plane z = 0.5 facing the wall
  (double-sided), Lambertian white: the hidden object.
- `occluder`: a dark (albedo 0.05), double-sided panel in the plane x = -0.55 spanning
  y in [-0.6, 0.6] and z in [0.45, 1.2]: it hides the letter from the sensor and laser origin,
  but not the wall.
- `nlos_origin`: a pinhole camera at the sensor and laser origin (-1.2, 0, 0.6), looking at the
  wall's centre, 60 degree vertical field of view, and a point light of 1 W/sr there, so that
  the scene renders as an ordinary one (the wall lit, the letter out of sight).

Every segment from the origin to the wall clears the occluder's lower edge (the lowest crossing
is at z = 0.37 m, below 0.45), and every segment from the origin to the letter crosses it (at
z between 0.54 and 0.55 m). The wall and letter see each other unobstructed. The shortest
three-bounce path origin -> wall -> letter -> wall -> origin is listed in the asset's extras.
"""
import argparse
import base64
import json
import math
import struct
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
ORIGIN = (-1.2, 0.0, 0.6)  # sensor and laser origin (m)
WALL_HALF = 0.5  # m
LETTER_Z = 0.5  # m
LETTER_HEIGHT = 0.4  # m
LETTER_WIDTH = 0.3  # m
LETTER_STROKE = 0.08  # m
OCCLUDER_X = -0.55  # m
OCCLUDER_Y = (-0.6, 0.6)  # m
OCCLUDER_Z = (0.45, 1.2)  # m


def quad(a, b, c, d):
    """Two triangles of the quad a b c d (counter-clockwise about its front face)."""
    return [a, b, c, a, c, d]


def wall():
    h = WALL_HALF
    corners = [(-h, -h, 0.0), (h, -h, 0.0), (h, h, 0.0), (-h, h, 0.0)]  # CCW seen from +z
    uv = lambda p: ((p[0] + h) / (2 * h), (p[1] + h) / (2 * h))
    tris = quad(*corners)
    return tris, [uv(p) for p in tris]


def letter():
    """The Z as three quads in the plane z = LETTER_Z, counter-clockwise seen from -z (the wall)."""
    w, hgt, s, z = LETTER_WIDTH / 2, LETTER_HEIGHT / 2, LETTER_STROKE, LETTER_Z
    # Seen from -z, +x points left: list corners clockwise in (x, y) to be CCW from -z.
    def bar(x0, x1, y0, y1):
        return quad((x0, y0, z), (x0, y1, z), (x1, y1, z), (x1, y0, z))
    top = bar(-w, w, hgt - s, hgt)
    bottom = bar(-w, w, -hgt, -hgt + s)
    # Diagonal from the top bar's right end (+x) to the bottom bar's left end (-x).
    diagonal = quad((w - s, hgt - s, z), (w, hgt - s, z), (-w + s, -hgt + s, z), (-w, -hgt + s, z))
    return top + bottom + diagonal


def occluder():
    x, (y0, y1), (z0, z1) = OCCLUDER_X, OCCLUDER_Y, OCCLUDER_Z
    return quad((x, y0, z1), (x, y1, z1), (x, y1, z0), (x, y0, z0))  # CCW seen from -x


def sub(a, b):
    return tuple(x - y for x, y in zip(a, b))


def norm(a):
    return math.sqrt(sum(x * x for x in a))


def look_at_rotation(eye, target):
    """Unit quaternion (x, y, z, w) turning the glTF camera (looking down -z, +y up) to look
    from eye at target with +y up."""
    f = sub(target, eye)
    n = norm(f)
    f = tuple(x / n for x in f)
    # Camera basis: right = f x up, up' = right x f; columns (right, up', -f).
    up = (0.0, 1.0, 0.0)
    r = (f[1] * up[2] - f[2] * up[1], f[2] * up[0] - f[0] * up[2], f[0] * up[1] - f[1] * up[0])
    rn = norm(r)
    r = tuple(x / rn for x in r)
    u = (r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2], r[0] * f[1] - r[1] * f[0])
    back = tuple(-x for x in f)
    m = [[r[0], u[0], back[0]], [r[1], u[1], back[1]], [r[2], u[2], back[2]]]
    trace = m[0][0] + m[1][1] + m[2][2]
    if trace > 0:
        s = 0.5 / math.sqrt(trace + 1.0)
        return [(m[2][1] - m[1][2]) * s, (m[0][2] - m[2][0]) * s, (m[1][0] - m[0][1]) * s, 0.25 / s]
    i = max(range(3), key=lambda k: m[k][k])
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2.0 * math.sqrt(1.0 + m[i][i] - m[j][j] - m[k][k])
    q = [0.0] * 4
    q[i] = 0.25 * s
    q[j] = (m[j][i] + m[i][j]) / s
    q[k] = (m[k][i] + m[i][k]) / s
    q[3] = (m[k][j] - m[j][k]) / s
    return q


def shortest_three_bounce():
    """Shortest origin -> wall -> letter -> wall -> origin path (m), by search over a grid of
    wall points and the letter's centre line (coarse, for the extras only)."""
    best = math.inf
    for i in range(41):
        for j in range(41):
            p = (-WALL_HALF + i / 40, -WALL_HALF + j / 40, 0.0)
            to_letter = math.inf
            for k in range(21):
                q = (-LETTER_WIDTH / 2 + k * LETTER_WIDTH / 20, 0.0, LETTER_Z)
                to_letter = min(to_letter, norm(sub(q, p)))
            best = min(best, 2 * (norm(sub(p, ORIGIN)) + to_letter))
    return best


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=ROOT / "assets/scenes/nlos_letter.gltf", help="output .gltf")
    args = parser.parse_args()

    data = bytearray()
    doc = {
        "asset": {"version": "2.0", "generator": "gatetrace tools/scenes/make_nlos_scene.py"},
        "extensionsUsed": ["KHR_lights_punctual"],
        "scene": 0,
        "scenes": [{"nodes": []}],
        "nodes": [],
        "meshes": [],
        "accessors": [],
        "bufferViews": [],
        "materials": [
            {"name": "white", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1.0],
                                                       "metallicFactor": 0.0, "roughnessFactor": 1.0}},
            {"name": "white_double_sided", "doubleSided": True,
             "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1.0], "metallicFactor": 0.0,
                                      "roughnessFactor": 1.0}},
            {"name": "dark_double_sided", "doubleSided": True,
             "pbrMetallicRoughness": {"baseColorFactor": [0.05, 0.05, 0.05, 1.0], "metallicFactor": 0.0,
                                      "roughnessFactor": 1.0}},
        ],
        "cameras": [{"type": "perspective", "perspective": {"yfov": math.radians(60.0), "aspectRatio": 1.0,
                                                             "znear": 1e-5}}],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"type": "point", "color": [1.0, 1.0, 1.0], "intensity": 1.0}]}},
    }

    def add_view(payload, target):
        while len(data) % 4:
            data.append(0)
        doc["bufferViews"].append({"buffer": 0, "byteOffset": len(data), "byteLength": len(payload),
                                   "target": target})
        data.extend(payload)
        return len(doc["bufferViews"]) - 1

    def add_mesh(name, triangles, material, uvs=None):
        flat = [c for p in triangles for c in p]
        view = add_view(struct.pack(f"<{len(flat)}f", *flat), 34962)
        cols = list(zip(*triangles))
        doc["accessors"].append({"bufferView": view, "componentType": 5126, "count": len(triangles),
                                 "type": "VEC3", "min": [min(c) for c in cols], "max": [max(c) for c in cols]})
        attributes = {"POSITION": len(doc["accessors"]) - 1}
        if uvs is not None:
            flat_uv = [c for p in uvs for c in p]
            view = add_view(struct.pack(f"<{len(flat_uv)}f", *flat_uv), 34962)
            doc["accessors"].append({"bufferView": view, "componentType": 5126, "count": len(uvs), "type": "VEC2"})
            attributes["TEXCOORD_0"] = len(doc["accessors"]) - 1
        doc["meshes"].append({"name": name, "primitives": [{"attributes": attributes, "material": material}]})
        doc["nodes"].append({"name": name, "mesh": len(doc["meshes"]) - 1})
        doc["scenes"][0]["nodes"].append(len(doc["nodes"]) - 1)

    wall_tris, wall_uvs = wall()
    add_mesh("relay_wall", wall_tris, 0, wall_uvs)
    add_mesh("hidden_letter", letter(), 1)
    add_mesh("occluder", occluder(), 2)
    doc["nodes"].append({"name": "nlos_origin", "camera": 0, "translation": list(ORIGIN),
                         "rotation": look_at_rotation(ORIGIN, (0.0, 0.0, 0.0)),
                         "extensions": {"KHR_lights_punctual": {"light": 0}}})
    doc["scenes"][0]["nodes"].append(len(doc["nodes"]) - 1)
    while len(data) % 4:
        data.append(0)
    doc["buffers"] = [{"byteLength": len(data),
                       "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(data)).decode()}]
    doc["extras"] = {
        "description": "Non-line-of-sight example: a 1 m relay wall (node relay_wall, z = 0, facing +z), a "
                       "hidden Z (node hidden_letter, z = 0.5 m) that an occluder (node occluder, x = -0.55 m) "
                       "hides from the sensor and laser origin (node nlos_origin, (-1.2, 0, 0.6) m: a pinhole "
                       "camera looking at the wall's centre and a 1 W/sr point light).",
        "nlos": {"relay_wall": "relay_wall", "sensor_origin": list(ORIGIN), "laser_origin": list(ORIGIN)},
        "shortest_three_bounce_path_m": round(shortest_three_bounce(), 4),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"{args.out}: relay wall, hidden letter ({len(letter()) // 3} triangles), occluder; "
          f"shortest three-bounce path {doc['extras']['shortest_three_bounce_path_m']} m")


if __name__ == "__main__":
    main()
