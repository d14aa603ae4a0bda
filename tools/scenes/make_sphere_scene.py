#!/usr/bin/env python3
"""Writes a test scene of any size: the Cornell box (assets/scenes/cornell_box.gltf) holding one
white, displaced geodesic sphere (radius 0.25 m, resting 5 cm above the floor), as a binary glTF
(.glb); with --nlos, the NLOS example scene (assets/scenes/nlos_letter.gltf) with the hidden
letter replaced by such a sphere (node `hidden_sphere`, radius 0.15 m, centred 0.6 m in front of
the relay wall's centre, still hidden from the origin by the occluder). An --out ending in .ply
writes the sphere alone, in the same place, as a binary PLY mesh (metres, no normals) for Mitsuba
XML scenes: assets/scenes/nlos_sphere.xml reads it with --nlos. The sphere is an icosahedron
whose faces are cut into f x f triangles (20 f^2 triangles;
f = 2^k gives the subdivided icospheres of 5,120 / 20,480 / 81,920 / 327,680 / 1,310,720
triangles), each vertex pushed along its radius by a smooth deterministic bump field of +-4 %,
so the mesh has curvature at several scales. Flat-shaded (no normals): every triangle's geometric normal. Standard library only.

    tools/scenes/make_sphere_scene.py --triangles 1300000 --out target/scenes/sphere_1310720.glb
    tools/scenes/make_sphere_scene.py --frequency 16 --out sphere_5120.glb
    tools/scenes/make_sphere_scene.py --nlos --frequency 128 --out target/scenes/nlos_sphere_327680.glb
    tools/scenes/make_sphere_scene.py --nlos --frequency 128 --out target/scenes/nlos_sphere_327680.ply

The scene's name, the triangle count and the frequency are in the asset's `extras`. The time
convention, camera and light are the Cornell box's (shortest path 1.9403 m).
"""
import argparse
import base64
import json
import math
import struct
import sys
from array import array
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BOX = ROOT / "assets/scenes/cornell_box.gltf"
NLOS = ROOT / "assets/scenes/nlos_letter.gltf"

RADIUS = 0.25  # m
CENTRE = (0.0, -0.5 + 0.05 + RADIUS, -0.05)  # m: 5 cm above the floor, a little back
NLOS_RADIUS = 0.15  # m
NLOS_CENTRE = (0.0, 0.0, 0.6)  # m: in front of the relay wall (z = 0), behind the occluder
BUMP = 0.04  # relative amplitude of the radial displacement

# Bumps: (direction, wavenumber, phase, weight); sums of sines of the direction's projection.
WAVES = [
    ((0.36, 0.48, 0.80), 7.0, 0.3, 0.45),
    ((-0.60, 0.64, 0.48), 11.0, 1.7, 0.30),
    ((0.00, -0.28, 0.96), 17.0, 2.9, 0.15),
    ((0.80, 0.00, -0.60), 29.0, 0.8, 0.10),
]


def icosahedron():
    """12 unit vertices and 20 faces, counter-clockwise seen from outside."""
    p = (1.0 + math.sqrt(5.0)) / 2.0
    raw = [(-1, p, 0), (1, p, 0), (-1, -p, 0), (1, -p, 0), (0, -1, p), (0, 1, p), (0, -1, -p), (0, 1, -p),
           (p, 0, -1), (p, 0, 1), (-p, 0, -1), (-p, 0, 1)]
    verts = [tuple(c / math.sqrt(1 + p * p) for c in v) for v in raw]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
             (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5),
             (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    return verts, faces


def displaced(d, centre, radius):
    """The sphere's surface point along unit direction d (m)."""
    r = 1.0
    for (w, k, phase, weight) in WAVES:
        r += BUMP * weight * math.sin(k * (w[0] * d[0] + w[1] * d[1] + w[2] * d[2]) + phase)
    r *= radius
    return (centre[0] + r * d[0], centre[1] + r * d[1], centre[2] + r * d[2])


def sphere(frequency, centre=CENTRE, radius=RADIUS):
    """Positions (flat float list) and triangle indices of the geodesic sphere; vertices on the
    icosahedron's edges are shared between faces, so the surface is closed."""
    verts, faces = icosahedron()
    f = frequency
    positions = array("f")
    indices = array("I")
    shared = {}  # exact lattice point (face-independent key) -> vertex index

    def vertex(a, b, c, i, j):
        # Lattice point i steps toward b and j toward c from a, on face (a, b, c); the key is
        # the point's barycentric weights over the icosahedron's vertex indices, so faces that
        # share an edge share its vertices.
        weights = {}
        for idx, w in ((a, f - i - j), (b, i), (c, j)):
            if w:
                weights[idx] = weights.get(idx, 0) + w
        key = tuple(sorted(weights.items()))
        found = shared.get(key)
        if found is not None:
            return found
        x = sum(verts[k][0] * w for k, w in key)
        y = sum(verts[k][1] * w for k, w in key)
        z = sum(verts[k][2] * w for k, w in key)
        n = math.sqrt(x * x + y * y + z * z)
        positions.extend(displaced((x / n, y / n, z / n), centre, radius))
        index = len(positions) // 3 - 1
        # Interior points of a face are never shared: skip the dictionary for them.
        if len(key) < 3:
            shared[key] = index
        return index

    for (a, b, c) in faces:
        rows = [[vertex(a, b, c, i, j) for j in range(f + 1 - i)] for i in range(f + 1)]
        for i in range(f):
            for j in range(f - i):
                indices.extend((rows[i][j], rows[i + 1][j], rows[i][j + 1]))
                if j + 1 < f - i:
                    indices.extend((rows[i + 1][j], rows[i + 1][j + 1], rows[i][j + 1]))
    return positions, indices


def write_ply(path, positions, indices):
    """The mesh as binary little-endian PLY: float x, y, z per vertex, and a uchar-counted list
    of uint indices per face (what Mitsuba's and gatetrace's PLY readers take)."""
    vertices = len(positions) // 3
    faces = len(indices) // 3
    header = ("ply\nformat binary_little_endian 1.0\ncomment gatetrace tools/scenes/make_sphere_scene.py\n"
              f"element vertex {vertices}\nproperty float x\nproperty float y\nproperty float z\n"
              f"element face {faces}\nproperty list uchar uint vertex_indices\nend_header\n")
    if sys.byteorder != "little":
        positions.byteswap()
        indices.byteswap()
    body = bytearray(positions.tobytes())
    raw = indices.tobytes()
    for k in range(faces):
        body.append(3)
        body.extend(raw[12 * k:12 * k + 12])
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as out:
        out.write(header.encode("ascii"))
        out.write(body)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    size = parser.add_mutually_exclusive_group(required=True)
    size.add_argument("--triangles", type=int, help="about this many sphere triangles (20 f^2, f rounded)")
    size.add_argument("--frequency", type=int, help="cut each icosahedron face into f x f triangles")
    parser.add_argument("--nlos", action="store_true",
                        help="the sphere replaces the NLOS example scene's hidden letter instead")
    parser.add_argument("--out", required=True, type=Path,
                        help="output file: .glb (the whole scene) or .ply (the sphere alone)")
    args = parser.parse_args()
    f = args.frequency if args.frequency else max(1, round(math.sqrt(args.triangles / 20.0)))
    if f < 1 or f > 2048:
        sys.exit(f"make_sphere_scene: frequency {f} must be 1 to 2048 (20 to 84M triangles)")
    if args.out.suffix not in (".glb", ".ply"):
        sys.exit(f"make_sphere_scene: --out {args.out}: name it .glb (binary glTF, the whole scene) "
                 f"or .ply (the sphere alone)")
    if args.out.suffix == ".ply":
        centre, radius = (NLOS_CENTRE, NLOS_RADIUS) if args.nlos else (CENTRE, RADIUS)
        positions, indices = sphere(f, centre, radius)
        write_ply(args.out, positions, indices)
        print(f"{args.out}: {len(indices) // 3} sphere triangles (frequency {f}), "
              f"{len(positions) // 3} vertices")
        return

    doc = json.loads((NLOS if args.nlos else BOX).read_text())
    data = bytearray(base64.b64decode(doc["buffers"][0]["uri"].split(",", 1)[1]))
    centre, radius = (NLOS_CENTRE, NLOS_RADIUS) if args.nlos else (CENTRE, RADIUS)
    positions, indices = sphere(f, centre, radius)
    triangles = len(indices) // 3

    def add_view(payload, target):
        while len(data) % 4:
            data.append(0)
        doc["bufferViews"].append({"buffer": 0, "byteOffset": len(data), "byteLength": len(payload), "target": target})
        data.extend(payload)
        return len(doc["bufferViews"]) - 1

    xs, ys, zs = positions[0::3], positions[1::3], positions[2::3]
    doc["accessors"].append({"bufferView": add_view(positions.tobytes(), 34962), "componentType": 5126,
                             "count": len(positions) // 3, "type": "VEC3",
                             "min": [min(xs), min(ys), min(zs)], "max": [max(xs), max(ys), max(zs)]})
    doc["accessors"].append({"bufferView": add_view(indices.tobytes(), 34963), "componentType": 5125,
                             "count": len(indices), "type": "SCALAR"})
    white = next(i for i, m in enumerate(doc["materials"]) if m["name"] == "white")
    doc["meshes"].append({"name": "sphere", "primitives": [
        {"attributes": {"POSITION": len(doc["accessors"]) - 2}, "indices": len(doc["accessors"]) - 1,
         "material": white}]})
    description = (f"a displaced geodesic sphere of {triangles} triangles (frequency {f}, radius {radius} m, "
                   f"+-{BUMP:.0%} bumps)")
    doc["asset"]["generator"] = "gatetrace tools/scenes/make_sphere_scene.py"
    if args.nlos:
        # The letter's node holds the sphere (its buffer data stays, unreferenced).
        node = next(n for n in doc["nodes"] if n["name"] == "hidden_letter")
        node.update(name="hidden_sphere", mesh=len(doc["meshes"]) - 1)
        doc["extras"] = {"description": f"The NLOS example scene with {description} hidden in place of the letter",
                         "nlos": doc["extras"]["nlos"], "sphere_triangles": triangles, "frequency": f}
    else:
        doc["nodes"].append({"name": "sphere", "mesh": len(doc["meshes"]) - 1})
        doc["scenes"][0]["nodes"].append(len(doc["nodes"]) - 1)
        doc["extras"] = {"description": f"Cornell box with {description}", "sphere_triangles": triangles,
                         "frequency": f}
    while len(data) % 4:
        data.append(0)
    doc["buffers"] = [{"byteLength": len(data)}]
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    total = 12 + 8 + len(text) + 8 + len(data)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with open(args.out, "wb") as out:
        out.write(struct.pack("<III", 0x46546C67, 2, total))
        out.write(struct.pack("<II", len(text), 0x4E4F534A) + text)
        out.write(struct.pack("<II", len(data), 0x004E4942) + bytes(data))
    print(f"{args.out}: {triangles} sphere triangles (frequency {f}), "
          f"{len(positions) // 3} sphere vertices")


if __name__ == "__main__":
    main()
