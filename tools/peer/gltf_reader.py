"""Reading glTF 2.0 scenes (.gltf with base64 or external buffers, or .glb) into numpy arrays.

The one glTF reader of the peer tools: peer_reference.py builds Mitsuba scenes from what
``load_gltf`` returns, and nlos_equal_time.py and nlos_onset_check.py read scenes with it.
Lengths are the glTF's metres; triangles are counter-clockwise about their geometric normal.
Needs numpy only.
"""

from __future__ import annotations

import base64
import json
import math
import os
import struct
import sys
import urllib.parse

import numpy as np


_COMPONENT_DTYPES = {
    5120: np.int8, 5121: np.uint8, 5122: np.int16,
    5123: np.uint16, 5125: np.uint32, 5126: np.float32,
}
_TYPE_SIZES = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4,
               "MAT2": 4, "MAT3": 9, "MAT4": 16}


def warn(msg: str) -> None:
    print(f"warning: {msg}", file=sys.stderr)


def _read_gltf_file(path: str):
    """Return (json dict, embedded GLB binary chunk or None)."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] == b"glTF":
        _, version, length = struct.unpack_from("<4sII", data, 0)
        if version != 2:
            raise ValueError(f"{path}: unsupported GLB version {version}")
        offset, doc, bin_chunk = 12, None, None
        while offset < length:
            chunk_len, chunk_type = struct.unpack_from("<II", data, offset)
            chunk = data[offset + 8: offset + 8 + chunk_len]
            if chunk_type == 0x4E4F534A:  # JSON
                doc = json.loads(chunk.decode("utf-8"))
            elif chunk_type == 0x004E4942 and bin_chunk is None:  # BIN
                bin_chunk = chunk
            offset += 8 + chunk_len
        if doc is None:
            raise ValueError(f"{path}: GLB without a JSON chunk")
        return doc, bin_chunk
    return json.loads(data.decode("utf-8")), None


def _load_buffers(doc, base_dir, glb_bin):
    buffers = []
    for i, buf in enumerate(doc.get("buffers", [])):
        uri = buf.get("uri")
        if uri is None:
            if i != 0 or glb_bin is None:
                raise ValueError(f"buffer {i} has no uri and no GLB chunk")
            raw = glb_bin
        elif uri.startswith("data:"):
            header, _, payload = uri.partition(",")
            if not header.endswith(";base64"):
                raise ValueError(f"buffer {i}: only base64 data URIs supported")
            raw = base64.b64decode(payload)
        else:
            with open(os.path.join(base_dir, urllib.parse.unquote(uri)), "rb") as f:
                raw = f.read()
        if len(raw) < buf["byteLength"]:
            raise ValueError(f"buffer {i} is shorter than its byteLength")
        buffers.append(raw)
    return buffers


def _read_accessor(doc, buffers, index):
    """Return the accessor's data as an array of shape [count, ncomp]."""
    acc = doc["accessors"][index]
    dtype = np.dtype(_COMPONENT_DTYPES[acc["componentType"]]).newbyteorder("<")
    ncomp = _TYPE_SIZES[acc["type"]]
    count = acc["count"]
    if "sparse" in acc:
        raise NotImplementedError(f"accessor {index}: sparse accessors unsupported")
    if "bufferView" not in acc:
        return np.zeros((count, ncomp), dtype=dtype)
    view = doc["bufferViews"][acc["bufferView"]]
    raw = buffers[view["buffer"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    elem = dtype.itemsize * ncomp
    stride = view.get("byteStride", elem)
    if stride == elem:
        out = np.frombuffer(raw, dtype=dtype, count=count * ncomp, offset=start)
        out = out.reshape(count, ncomp)
    else:
        out = np.empty((count, ncomp), dtype=dtype)
        for k in range(count):
            out[k] = np.frombuffer(raw, dtype=dtype, count=ncomp,
                                   offset=start + k * stride)
    if acc.get("normalized", False) and dtype.kind in "iu":
        info = np.iinfo(dtype)
        out = np.maximum(out.astype(np.float64) / info.max, -1.0)
    return out


def _quat_to_matrix(q):
    x, y, z, w = (float(v) for v in q)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def _node_local_matrix(node):
    if "matrix" in node:
        # glTF stores 4x4 matrices column-major.
        return np.array(node["matrix"], dtype=np.float64).reshape(4, 4).T
    m = np.eye(4)
    t = node.get("translation", [0.0, 0.0, 0.0])
    r = node.get("rotation", [0.0, 0.0, 0.0, 1.0])
    s = node.get("scale", [1.0, 1.0, 1.0])
    m[:3, :3] = _quat_to_matrix(r) @ np.diag(np.asarray(s, dtype=np.float64))
    m[:3, 3] = t
    return m


def _material_info(doc, index):
    """Extract the Lambertian + emissive parameters of a glTF material."""
    if index is None:
        warn("primitive without material: using white (1,1,1) Lambertian")
        return {"name": "<default>", "albedo": [1.0, 1.0, 1.0],
                "emission": [0.0, 0.0, 0.0], "double_sided": False}
    mat = doc["materials"][index]
    name = mat.get("name", f"material{index}")
    pbr = mat.get("pbrMetallicRoughness", {})
    albedo = [float(v) for v in pbr.get("baseColorFactor", [1, 1, 1, 1])[:3]]
    metallic = float(pbr.get("metallicFactor", 1.0))
    if metallic != 0.0:
        warn(f"material '{name}': metallicFactor {metallic} ignored (Lambertian)")
    for tex in ("baseColorTexture", "metallicRoughnessTexture"):
        if tex in pbr:
            warn(f"material '{name}': {tex} ignored")
    for tex in ("emissiveTexture", "normalTexture", "occlusionTexture"):
        if tex in mat:
            warn(f"material '{name}': {tex} ignored")
    strength = float(mat.get("extensions", {})
                     .get("KHR_materials_emissive_strength", {})
                     .get("emissiveStrength", 1.0))
    emission = [float(v) * strength for v in mat.get("emissiveFactor", [0, 0, 0])]
    return {"name": name, "albedo": albedo, "emission": emission,
            "double_sided": bool(mat.get("doubleSided", False))}


def load_gltf(path):
    """Parse a glTF 2.0 file into world-space triangle meshes and a camera.

    Returns a dict with ``meshes`` (list of dicts: name, positions [N,3],
    normals [N,3] or None, faces [M,3] uint32, material dict), ``camera``
    (dict: to_world 4x4 in glTF camera convention, yfov, znear, zfar,
    aspect_ratio, aperture_radius (0: pinhole), focus_distance) or None, and
    ``lights`` (KHR_lights_punctual lights, see _light_info).
    """
    doc, glb_bin = _read_gltf_file(path)
    buffers = _load_buffers(doc, os.path.dirname(os.path.abspath(path)), glb_bin)
    for ext in doc.get("extensionsRequired", []):
        if ext not in ("KHR_materials_emissive_strength", "KHR_lights_punctual"):
            warn(f"required extension {ext} is not supported")
    punctual = doc.get("extensions", {}).get("KHR_lights_punctual", {}).get("lights", [])

    nodes = doc.get("nodes", [])
    if doc.get("scenes"):
        roots = doc["scenes"][doc.get("scene", 0)].get("nodes", [])
    else:
        children = {c for n in nodes for c in n.get("children", [])}
        roots = [i for i in range(len(nodes)) if i not in children]

    meshes, camera_nodes, node_positions, lights = [], [], {}, []
    stack = [(i, np.eye(4)) for i in reversed(roots)]
    while stack:  # depth-first, in document order
        ni, parent = stack.pop()
        node = nodes[ni]
        world = parent @ _node_local_matrix(node)
        stack.extend((c, world) for c in reversed(node.get("children", [])))
        if "camera" in node:
            camera_nodes.append((node["camera"], world, node.get("extras") or {}))
        light_ref = node.get("extensions", {}).get("KHR_lights_punctual")
        if light_ref is not None:
            lights.append(_light_info(punctual, light_ref.get("light"), node, world))
        if node.get("name"):
            node_positions.setdefault(node["name"], world[:3, 3].copy())
        if "mesh" in node:
            mesh = doc["meshes"][node["mesh"]]
            lin = world[:3, :3]
            flip = np.linalg.det(lin) < 0
            normal_matrix = np.linalg.inv(lin).T
            for pi, prim in enumerate(mesh["primitives"]):
                mode = prim.get("mode", 4)
                if mode != 4:
                    raise NotImplementedError(
                        f"mesh '{mesh.get('name')}' primitive {pi}: mode {mode} "
                        "(only TRIANGLES=4 supported)")
                attrs = prim["attributes"]
                pos = _read_accessor(doc, buffers, attrs["POSITION"]).astype(np.float64)
                pos = pos @ lin.T + world[:3, 3]
                nrm = None
                if "NORMAL" in attrs:
                    nrm = _read_accessor(doc, buffers, attrs["NORMAL"]).astype(np.float64)
                    nrm = nrm @ normal_matrix.T
                    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)
                if "indices" in prim:
                    idx = _read_accessor(doc, buffers, prim["indices"]).reshape(-1)
                else:
                    idx = np.arange(len(pos))
                faces = idx.astype(np.uint32).reshape(-1, 3)
                if flip:  # mirrored transform: glTF says to reverse winding
                    faces = faces[:, ::-1].copy()
                base = node.get("name") or mesh.get("name") or "mesh"
                base = "".join(ch if ch.isalnum() else "_" for ch in base)
                name = f"{base}_{ni}_{pi}"  # unique scene-dict key
                uvs = None
                if "TEXCOORD_0" in attrs:
                    uvs = _read_accessor(doc, buffers, attrs["TEXCOORD_0"]).astype(np.float64)
                meshes.append({
                    "name": name,
                    "node": node.get("name"),
                    "node_position": world[:3, 3].copy(),
                    "uvs": uvs,
                    "positions": pos.astype(np.float32),
                    "normals": None if nrm is None else nrm.astype(np.float32),
                    "faces": faces,
                    "material": _material_info(doc, prim.get("material")),
                })
                _check_winding(meshes[-1])

    camera = None
    if camera_nodes:
        cam_index, cam_world, cam_extras = min(camera_nodes, key=lambda c: c[0])
        cam = doc["cameras"][cam_index]
        if cam.get("type") != "perspective":
            raise NotImplementedError("only perspective cameras are supported")
        p = cam["perspective"]
        camera = {"index": cam_index, "to_world": cam_world,
                  "yfov": float(p["yfov"]), "znear": float(p["znear"]),
                  "zfar": float(p["zfar"]) if "zfar" in p else None,
                  "aspect_ratio": p.get("aspectRatio"),
                  "aperture_radius": float(cam_extras.get("aperture_radius", 0.0)),
                  "focus_distance": cam_extras.get("focus_distance")}
        if camera["aperture_radius"] < 0:
            raise ValueError(f"camera node extras: aperture_radius {camera['aperture_radius']} < 0")
        if camera["aperture_radius"] > 0:
            fd = camera["focus_distance"]
            if fd is None or not float(fd) > 0:
                raise ValueError("camera node extras: a thin lens (aperture_radius > 0) needs "
                                 f"focus_distance > 0, got {fd!r}")
            camera["focus_distance"] = float(fd)
    return {"meshes": meshes, "camera": camera, "lights": lights, "doc": doc,
            "node_positions": node_positions}


_LIGHT_TYPES = ("point", "spot", "directional")


def _light_info(punctual, index, node, world):
    """A KHR_lights_punctual light placed by its node's world matrix: type, name, rgb
    (intensity x color: W/sr for point and spot at the beam's centre, W/m^2 for directional),
    position, direction (the node's world -Z, normalised) and, for spots, the cone angles in
    radians."""
    name = node.get("name", "<unnamed node>")
    if index is None or not 0 <= index < len(punctual):
        raise ValueError(f"node '{name}': KHR_lights_punctual light {index!r} does not exist")
    light = punctual[index]
    kind = light.get("type")
    if kind not in _LIGHT_TYPES:
        raise NotImplementedError(
            f"node '{name}': KHR_lights_punctual light type {kind!r} is not supported "
            f"(supported: {', '.join(_LIGHT_TYPES)})")
    color = [float(v) for v in light.get("color", [1.0, 1.0, 1.0])]
    intensity = float(light.get("intensity", 1.0))
    direction = world[:3, :3] @ np.array([0.0, 0.0, -1.0])
    norm = np.linalg.norm(direction)
    if kind != "point" and not norm > 0:
        raise ValueError(f"node '{name}': degenerate transform, the light has no direction")
    info = {"type": kind, "name": light.get("name", name), "node": name,
            "rgb": [c * intensity for c in color],
            "position": world[:3, 3].copy(),
            "direction": direction / norm if norm > 0 else direction,
            "up": world[:3, :3] @ np.array([0.0, 1.0, 0.0])}
    if "range" in light and kind != "directional":
        warn(f"light '{info['name']}': range {light['range']} ignored (Mitsuba lights have no range)")
    if kind == "spot":
        spot = light.get("spot", {})
        inner = float(spot.get("innerConeAngle", 0.0))
        outer = float(spot.get("outerConeAngle", math.pi / 4))
        if not 0.0 <= inner <= outer <= math.pi / 2 or outer <= 0.0:
            raise ValueError(f"light '{info['name']}': need 0 <= innerConeAngle <= outerConeAngle "
                             f"<= pi/2 and outerConeAngle > 0, got {inner}, {outer}")
        if outer - inner > 1e-3:
            warn(f"light '{info['name']}': Mitsuba's spot falls off linearly in angle from the inner "
                  "to the outer cone; a renderer with another transition profile will differ there")
        info["inner"], info["outer"] = inner, outer
    return info


def _check_winding(mesh):
    """Warn when vertex normals disagree with the counter-clockwise winding.

    Mitsuba decides the front side (for one-sided BSDFs and area lights) from
    the shading frame, so inconsistent data would render differently from a
    renderer that uses the geometric normal.
    """
    if mesh["normals"] is None:
        return
    p, f, n = mesh["positions"], mesh["faces"], mesh["normals"]
    geo = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    avg = n[f].sum(axis=1)
    if np.any(np.einsum("ij,ij->i", geo, avg) < 0):
        warn(f"mesh '{mesh['name']}': vertex normals oppose the winding order")
