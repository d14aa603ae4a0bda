//! Writes small glTF 2.0 test scenes (one embedded base64 buffer).
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use serde_json::{Value, json};

pub struct Mesh {
    pub positions: Vec<[f32; 3]>,
    pub normals: Option<Vec<[f32; 3]>>,
    /// TEXCOORD_0.
    pub uvs: Option<Vec<[f32; 2]>>,
    pub indices: Vec<u32>,
    pub material: Option<usize>,
}

pub struct Material {
    pub base_color: [f32; 3],
    pub emissive: [f32; 3],
    pub emissive_strength: Option<f32>,
    pub double_sided: bool,
}

impl Material {
    pub fn diffuse(albedo: [f32; 3]) -> Self {
        Self { base_color: albedo, emissive: [0.0; 3], emissive_strength: None, double_sided: false }
    }

    pub fn emitter(radiance: f32) -> Self {
        Self { base_color: [0.0; 3], emissive: [1.0; 3], emissive_strength: Some(radiance), double_sided: false }
    }
}

/// A camera node: position and rotation (unit quaternion x, y, z, w); glTF cameras look along -z.
pub struct Camera {
    pub position: [f32; 3],
    pub rotation: [f32; 4],
    pub yfov: f32,
}

pub struct PointLight {
    pub position: [f32; 3],
    pub intensity: f32,
}

#[derive(Default)]
pub struct Scene {
    pub meshes: Vec<Mesh>,
    pub materials: Vec<Material>,
    pub camera: Option<Camera>,
    pub point_lights: Vec<PointLight>,
}

/// An axis-aligned quad in the plane z = `z` spanning [-h, h]^2, facing +z when `facing_plus_z`.
pub fn quad_z(h: f32, z: f32, facing_plus_z: bool, material: usize) -> Mesh {
    let positions = vec![[-h, -h, z], [h, -h, z], [h, h, z], [-h, h, z]];
    let indices = if facing_plus_z { vec![0, 1, 2, 0, 2, 3] } else { vec![0, 2, 1, 0, 3, 2] };
    let uvs = Some(positions.iter().map(|p| [0.5 * (p[0] / h + 1.0), 0.5 * (p[1] / h + 1.0)]).collect());
    Mesh { positions, normals: None, uvs, indices, material: Some(material) }
}

impl Scene {
    pub fn to_json(&self) -> Value {
        let mut bin: Vec<u8> = Vec::new();
        let mut views = Vec::new();
        let mut accessors = Vec::new();
        let mut push =
            |data: Vec<u8>, count: usize, component: u32, kind: &str, min_max: Option<(Vec<f32>, Vec<f32>)>| {
                while !bin.len().is_multiple_of(4) {
                    bin.push(0);
                }
                views.push(json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": data.len()}));
                bin.extend_from_slice(&data);
                let mut a =
                    json!({"bufferView": views.len() - 1, "componentType": component, "count": count, "type": kind});
                if let Some((lo, hi)) = min_max {
                    a["min"] = json!(lo);
                    a["max"] = json!(hi);
                }
                accessors.push(a);
                accessors.len() - 1
            };
        let mut meshes = Vec::new();
        let mut nodes = Vec::new();
        for m in &self.meshes {
            let pos: Vec<u8> = m.positions.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
            let lo: Vec<f32> = (0..3).map(|i| m.positions.iter().map(|p| p[i]).fold(f32::INFINITY, f32::min)).collect();
            let hi: Vec<f32> =
                (0..3).map(|i| m.positions.iter().map(|p| p[i]).fold(f32::NEG_INFINITY, f32::max)).collect();
            let finite = lo.iter().chain(&hi).all(|v| v.is_finite());
            let p = push(pos, m.positions.len(), 5126, "VEC3", finite.then_some((lo, hi)));
            let mut attributes = json!({"POSITION": p});
            if let Some(n) = &m.normals {
                let data: Vec<u8> = n.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
                attributes["NORMAL"] = json!(push(data, n.len(), 5126, "VEC3", None));
            }
            if let Some(uv) = &m.uvs {
                let data: Vec<u8> = uv.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
                attributes["TEXCOORD_0"] = json!(push(data, uv.len(), 5126, "VEC2", None));
            }
            let idx: Vec<u8> = m.indices.iter().flat_map(|v| v.to_le_bytes()).collect();
            let i = push(idx, m.indices.len(), 5125, "SCALAR", None);
            let mut prim = json!({"attributes": attributes, "indices": i});
            if let Some(mat) = m.material {
                prim["material"] = json!(mat);
            }
            meshes.push(json!({"primitives": [prim]}));
            nodes.push(json!({"mesh": meshes.len() - 1}));
        }
        let mut cameras = Vec::new();
        if let Some(c) = &self.camera {
            cameras.push(json!({"type": "perspective", "perspective": {"yfov": c.yfov, "znear": 1e-5}}));
            nodes.push(json!({"camera": 0, "translation": c.position, "rotation": c.rotation}));
        }
        let mut lights = Vec::new();
        for l in &self.point_lights {
            lights.push(json!({"type": "point", "color": [1.0, 1.0, 1.0], "intensity": l.intensity}));
            nodes.push(
                json!({"translation": l.position, "extensions": {"KHR_lights_punctual": {"light": lights.len() - 1}}}),
            );
        }
        let materials: Vec<Value> = self
            .materials
            .iter()
            .map(|m| {
                let mut v = json!({
                    "pbrMetallicRoughness": {"baseColorFactor": [m.base_color[0], m.base_color[1], m.base_color[2], 1.0],
                                             "metallicFactor": 0.0, "roughnessFactor": 1.0},
                    "emissiveFactor": m.emissive,
                    "doubleSided": m.double_sided,
                });
                if let Some(s) = m.emissive_strength {
                    v["extensions"] = json!({"KHR_materials_emissive_strength": {"emissiveStrength": s}});
                }
                v
            })
            .collect();
        let node_ids: Vec<usize> = (0..nodes.len()).collect();
        let mut doc = json!({
            "asset": {"version": "2.0"},
            "extensionsUsed": ["KHR_materials_emissive_strength", "KHR_lights_punctual"],
            "scene": 0,
            "scenes": [{"nodes": node_ids}],
            "nodes": nodes,
            "meshes": meshes,
            "materials": materials,
            "buffers": [{"byteLength": bin.len(), "uri": format!("data:application/octet-stream;base64,{}", base64(&bin))}],
            "bufferViews": views,
            "accessors": accessors,
        });
        if !cameras.is_empty() {
            doc["cameras"] = json!(cameras);
        }
        if !lights.is_empty() {
            doc["extensions"] = json!({"KHR_lights_punctual": {"lights": lights}});
        }
        doc
    }

    /// Writes the scene to `dir/name` and returns the path.
    pub fn write(&self, dir: &Path, name: &str) -> PathBuf {
        write_json(dir, name, &self.to_json())
    }
}

pub fn write_json(dir: &Path, name: &str, doc: &Value) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, serde_json::to_string_pretty(doc).unwrap()).unwrap();
    path
}

fn base64(data: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in data.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(T[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// Encodes an 8-bit RGB image as PNG (stored deflate blocks, no compression).
pub fn png_rgb8(width: u32, height: u32, rgb: &[u8]) -> Vec<u8> {
    assert_eq!(rgb.len(), (width * height * 3) as usize);
    fn crc32(data: &[u8]) -> u32 {
        let mut c = 0xffff_ffffu32;
        for &b in data {
            c ^= b as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 { 0xedb8_8320 ^ (c >> 1) } else { c >> 1 };
            }
        }
        !c
    }
    fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
        out.extend_from_slice(&(data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend_from_slice(data);
        out.extend_from_slice(&body);
        out.extend_from_slice(&crc32(&body).to_be_bytes());
    }
    let mut raw = Vec::new();
    for row in rgb.chunks((width * 3) as usize) {
        raw.push(0); // filter: none
        raw.extend_from_slice(row);
    }
    let mut z = vec![0x78, 0x01];
    let blocks: Vec<&[u8]> = raw.chunks(65535).collect();
    for (i, block) in blocks.iter().enumerate() {
        z.push((i + 1 == blocks.len()) as u8);
        z.extend_from_slice(&(block.len() as u16).to_le_bytes());
        z.extend_from_slice(&(!(block.len() as u16)).to_le_bytes());
        z.extend_from_slice(block);
    }
    let (mut a, mut b) = (1u32, 0u32);
    for &x in &raw {
        a = (a + x as u32) % 65521;
        b = (b + a) % 65521;
    }
    z.extend_from_slice(&((b << 16) | a).to_be_bytes());
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&width.to_be_bytes());
    ihdr.extend_from_slice(&height.to_be_bytes());
    ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);
    chunk(&mut out, b"IHDR", &ihdr);
    chunk(&mut out, b"IDAT", &z);
    chunk(&mut out, b"IEND", &[]);
    out
}
