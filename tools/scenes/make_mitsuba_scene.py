#!/usr/bin/env python3
"""Writes assets/scenes/mitsuba_box/: a Mitsuba 3 XML scene that uses every part of gatetrace's
Mitsuba loader, for the tests that compare its renders with Mitsuba 3 + mitransient rendering
the same file (standard library only).

The Cornell box of cornell_box.xml (walls as `rectangle`s) with
* an `include`d file holding shared BSDFs, `default` parameters and `$name` substitution;
* a block from an OBJ file (quads, vertex normals ignored by `face_normals`), turned by `rotate`,
  of GGX `roughplastic`;
* a tetrahedron from a binary little-endian PLY file, placed by a `matrix`;
* a pyramid, the second of two shapes in a Mitsuba `serialized` file (format version 4, double
  precision, texture coordinates), picked by `shape_index`, of `roughplastic` with a checkerboard
  diffuse reflectance, `nonlinear` and a specular reflectance of 0.8;
* a `sphere` with a GGX `roughconductor` of gold (`material` Au: the exact Fresnel term of its
  complex index), alpha 0.2;
* a `cylinder` (open tube) and a `disk`, both `twosided`;
* a `cube` scaled flat, of smooth `plastic` (index of refraction by name, `bk7`), and a
  `shapegroup` of a cube placed twice by `instance`s;
* a floor with a `checkerboard` texture (`to_uv` scaled) and a back wall with a `bitmap` texture
  (a 4 x 4 sRGB PNG, nearest lookups);
* the area light, a `point` light and a `spot` light;
* a `transient_hdr_film` of 20 bins of 0.1 m from 1.94 m, a `transient_path` integrator of
  `max_depth` 6 (5 bounces), and a near clip of 1e-5 m (mitransient measures the camera's segment
  from the near clip plane: a negligible one keeps both renderers' time origin at the pinhole).

    tools/scenes/make_mitsuba_scene.py
"""
import struct
import zlib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "assets/scenes/mitsuba_box"

SCENE = """<?xml version="1.0" encoding="utf-8"?>
<!-- Written by tools/scenes/make_mitsuba_scene.py: every part of gatetrace's Mitsuba loader in a
     Cornell box (lengths in metres). -->
<scene version="3.0.0">
    <default name="spp" value="64"/>
    <default name="res" value="32"/>
    <default name="bins" value="20"/>

    <include filename="materials.xml"/>

    <integrator type="transient_path">
        <integer name="max_depth" value="6"/>
        <boolean name="camera_unwarp" value="false"/>
        <string name="temporal_filter" value="box"/>
    </integrator>

    <sensor type="perspective" id="camera">
        <float name="fov" value="40"/>
        <string name="fov_axis" value="smaller"/>
        <float name="near_clip" value="1e-5"/>
        <float name="far_clip" value="100"/>
        <transform name="to_world">
            <lookat origin="0, 0, 2" target="0, 0, 0" up="0, 1, 0"/>
        </transform>
        <sampler type="independent">
            <integer name="sample_count" value="$spp"/>
        </sampler>
        <film type="transient_hdr_film">
            <integer name="width" value="$res"/>
            <integer name="height" value="$res"/>
            <integer name="temporal_bins" value="$bins"/>
            <float name="start_opl" value="1.94"/>
            <float name="bin_width_opl" value="0.1"/>
            <rfilter type="box"/>
        </film>
    </sensor>

    <shape type="rectangle" id="floor">
        <transform name="to_world">
            <scale value="0.5"/>
            <rotate x="1" angle="-90"/>
            <translate y="-0.5"/>
        </transform>
        <bsdf type="diffuse">
            <texture type="checkerboard" name="reflectance">
                <rgb name="color0" value="0.8, 0.8, 0.7"/>
                <rgb name="color1" value="0.2, 0.3, 0.6"/>
                <transform name="to_uv">
                    <scale x="4" y="4"/>
                </transform>
            </texture>
        </bsdf>
    </shape>

    <shape type="rectangle" id="ceiling">
        <transform name="to_world">
            <scale value="0.5"/>
            <rotate x="1" angle="90"/>
            <translate y="0.5"/>
        </transform>
        <ref id="white"/>
    </shape>

    <shape type="rectangle" id="back">
        <transform name="to_world">
            <scale value="0.5"/>
            <translate z="-0.5"/>
        </transform>
        <bsdf type="diffuse">
            <texture type="bitmap" name="reflectance">
                <string name="filename" value="quadrants.png"/>
                <string name="filter_type" value="nearest"/>
            </texture>
        </bsdf>
    </shape>

    <shape type="rectangle" id="left">
        <transform name="to_world">
            <scale value="0.5"/>
            <rotate y="1" angle="90"/>
            <translate x="-0.5"/>
        </transform>
        <ref id="red"/>
    </shape>

    <shape type="rectangle" id="right">
        <transform name="to_world">
            <scale value="0.5"/>
            <rotate y="1" angle="-90"/>
            <translate x="0.5"/>
        </transform>
        <ref id="green"/>
    </shape>

    <shape type="rectangle" id="light">
        <transform name="to_world">
            <scale value="0.125"/>
            <rotate x="1" angle="90"/>
            <translate y="0.499"/>
        </transform>
        <bsdf type="diffuse">
            <rgb name="reflectance" value="0"/>
        </bsdf>
        <emitter type="area">
            <rgb name="radiance" value="10"/>
        </emitter>
    </shape>

    <emitter type="point">
        <point name="position" x="0.3" y="0.3" z="0.3"/>
        <rgb name="intensity" value="0.2, 0.15, 0.1"/>
    </emitter>

    <emitter type="spot">
        <rgb name="intensity" value="0.6, 0.5, 0.4"/>
        <float name="cutoff_angle" value="25"/>
        <float name="beam_width" value="10"/>
        <transform name="to_world">
            <lookat origin="-0.3, 0.4, 0.3" target="0.3, -0.2, -0.5" up="0, 1, 0"/>
        </transform>
    </emitter>

    <shape type="obj" id="block">
        <string name="filename" value="block.obj"/>
        <boolean name="face_normals" value="true"/>
        <transform name="to_world">
            <scale x="0.12" y="0.2" z="0.12"/>
            <rotate y="1" angle="25"/>
            <translate x="-0.22" y="-0.3" z="-0.2"/>
        </transform>
        <bsdf type="roughplastic">
            <string name="distribution" value="ggx"/>
            <float name="alpha" value="0.15"/>
            <float name="int_ior" value="1.5"/>
            <rgb name="diffuse_reflectance" value="0.25, 0.45, 0.7"/>
        </bsdf>
    </shape>

    <shape type="ply" id="tetrahedron">
        <string name="filename" value="tetrahedron.ply"/>
        <transform name="to_world">
            <matrix value="0.15 0 0 0.25  0 0.15 0 -0.5  0 0 0.15 -0.25  0 0 0 1"/>
        </transform>
        <ref id="white"/>
    </shape>

    <shape type="serialized" id="pyramid">
        <string name="filename" value="shapes.serialized"/>
        <integer name="shape_index" value="1"/>
        <transform name="to_world">
            <scale value="0.1"/>
            <translate x="0.05" y="-0.5" z="-0.05"/>
        </transform>
        <bsdf type="roughplastic">
            <string name="distribution" value="ggx"/>
            <float name="alpha" value="0.3"/>
            <boolean name="nonlinear" value="true"/>
            <float name="specular_reflectance" value="0.8"/>
            <texture type="checkerboard" name="diffuse_reflectance">
                <rgb name="color0" value="0.7, 0.7, 0.2"/>
                <rgb name="color1" value="0.1, 0.5, 0.2"/>
                <transform name="to_uv">
                    <scale x="3" y="3"/>
                </transform>
            </texture>
        </bsdf>
    </shape>

    <shape type="sphere" id="ball">
        <point name="center" x="0.2" y="-0.35" z="0.15"/>
        <float name="radius" value="0.15"/>
        <bsdf type="roughconductor">
            <string name="distribution" value="ggx"/>
            <float name="alpha" value="0.2"/>
            <string name="material" value="Au"/>
        </bsdf>
    </shape>

    <shape type="cylinder" id="post">
        <point name="p0" x="-0.3" y="-0.5" z="0.25"/>
        <point name="p1" x="-0.3" y="-0.2" z="0.25"/>
        <float name="radius" value="0.05"/>
        <ref id="two-sided grey"/>
    </shape>

    <shape type="disk" id="plate">
        <transform name="to_world">
            <scale value="0.1"/>
            <rotate x="1" angle="-90"/>
            <translate x="-0.3" y="-0.2" z="0.25"/>
        </transform>
        <ref id="two-sided grey"/>
    </shape>

    <shape type="cube" id="slab">
        <transform name="to_world">
            <scale x="0.15" y="0.02" z="0.1"/>
            <translate x="0.25" y="0.1" z="-0.35"/>
        </transform>
        <bsdf type="plastic">
            <string name="int_ior" value="bk7"/>
            <rgb name="diffuse_reflectance" value="0.7, 0.35, 0.2"/>
        </bsdf>
    </shape>

    <shape type="shapegroup" id="pillar">
        <shape type="cube" id="pillar cube">
            <transform name="to_world">
                <scale x="0.04" y="0.1" z="0.04"/>
                <translate y="0.1"/>
            </transform>
            <ref id="red"/>
        </shape>
    </shape>

    <shape type="instance" id="left pillar">
        <ref id="pillar"/>
        <transform name="to_world">
            <translate x="-0.4" y="-0.5" z="-0.4"/>
        </transform>
    </shape>

    <shape type="instance" id="right pillar">
        <ref id="pillar"/>
        <transform name="to_world">
            <rotate y="1" angle="45"/>
            <translate x="0.4" y="-0.5" z="-0.4"/>
        </transform>
    </shape>
</scene>
"""

MATERIALS = """<?xml version="1.0" encoding="utf-8"?>
<!-- Written by tools/scenes/make_mitsuba_scene.py: the shared BSDFs of scene.xml. -->
<scene version="3.0.0">
    <default name="white_value" value="0.8"/>
    <bsdf type="diffuse" id="white">
        <float name="reflectance" value="$white_value"/>
    </bsdf>
    <bsdf type="diffuse" id="red">
        <rgb name="reflectance" value="0.8, 0.05, 0.05"/>
    </bsdf>
    <bsdf type="diffuse" id="green">
        <rgb name="reflectance" value="0.05 0.8 0.05"/>
    </bsdf>
    <bsdf type="twosided" id="two-sided grey">
        <bsdf type="diffuse">
            <spectrum name="reflectance" value="0.5"/>
        </bsdf>
    </bsdf>
</scene>
"""

# A unit cube [-1, 1]^3 as six quads, faces outwards, with (unused) vertex normals.
BLOCK_OBJ = """# A cube of six quads (tools/scenes/make_mitsuba_scene.py)
o block
v -1 -1 -1
v 1 -1 -1
v 1 1 -1
v -1 1 -1
v -1 -1 1
v 1 -1 1
v 1 1 1
v -1 1 1
vn 0 0 1
f 1//1 4//1 3//1 2//1
f 5//1 6//1 7//1 8//1
f 1//1 2//1 6//1 5//1
f 4//1 8//1 7//1 3//1
f 1//1 5//1 8//1 4//1
f 2//1 3//1 7//1 6//1
"""


def tetrahedron_ply():
    """A tetrahedron standing on y = 0, faces outwards, as binary little-endian PLY."""
    vertices = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.5, 0.0, 0.866), (0.5, 0.8, 0.289)]
    faces = [(0, 1, 2), (0, 3, 1), (1, 3, 2), (2, 3, 0)]
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment tools/scenes/make_mitsuba_scene.py\n"
        f"element vertex {len(vertices)}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode()
    body = b"".join(struct.pack("<3f", *v) for v in vertices)
    body += b"".join(struct.pack("<B3i", 3, *f) for f in faces)
    return header + body


def serialized(shapes):
    """A Mitsuba `serialized` file (format version 4) of `shapes`, each (name, vertices, uvs or
    None, triangles): per shape the tag 0x041C, the version and a zlib stream of flags (double
    precision, texture coordinates when given), the name, the vertex and triangle counts and the
    arrays; then the shapes' 64-bit offsets and their 32-bit count."""
    out, offsets = b"", []
    for name, vertices, uvs, triangles in shapes:
        flags = 0x2000 | (0x0002 if uvs else 0)
        body = struct.pack("<I", flags) + name.encode() + b"\0" + struct.pack("<QQ", len(vertices), len(triangles))
        body += b"".join(struct.pack("<3d", *v) for v in vertices)
        if uvs:
            body += b"".join(struct.pack("<2d", *t) for t in uvs)
        body += b"".join(struct.pack("<3I", *t) for t in triangles)
        offsets.append(len(out))
        out += struct.pack("<HH", 0x041C, 4) + zlib.compress(body)
    return out + b"".join(struct.pack("<Q", o) for o in offsets) + struct.pack("<I", len(shapes))


def png_rgb8(width, height, rows):
    """An 8-bit RGB PNG of `rows` (lists of (r, g, b) per pixel, top row first)."""
    raw = b"".join(b"\x00" + bytes(c for pixel in row for c in pixel) for row in rows)

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "scene.xml").write_text(SCENE)
    (OUT / "materials.xml").write_text(MATERIALS)
    (OUT / "block.obj").write_text(BLOCK_OBJ)
    (OUT / "tetrahedron.ply").write_bytes(tetrahedron_ply())
    # A quad (never used: shape 0), and a square pyramid standing on y = 0, faces outwards.
    quad = ("quad", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], None, [(0, 1, 2), (0, 2, 3)])
    apex, base = (0.0, 1.2, 0.0), [(-1.0, 0.0, -1.0), (1.0, 0.0, -1.0), (1.0, 0.0, 1.0), (-1.0, 0.0, 1.0)]
    pyramid = ("pyramid", base + [apex], [(0, 0), (1, 0), (1, 1), (0, 1), (0.5, 0.5)],
               [(0, 1, 2), (0, 2, 3), (0, 4, 1), (1, 4, 2), (2, 4, 3), (3, 4, 0)])
    (OUT / "shapes.serialized").write_bytes(serialized([quad, pyramid]))
    # Quadrants: red, green over blue, yellow (sRGB), in a 4 x 4 image.
    top = [(230, 60, 60)] * 2 + [(60, 200, 60)] * 2
    bottom = [(60, 60, 220)] * 2 + [(220, 220, 60)] * 2
    (OUT / "quadrants.png").write_bytes(png_rgb8(4, 4, [top, top, bottom, bottom]))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
