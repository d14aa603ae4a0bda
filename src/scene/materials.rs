//! Material and texture tables for the GPU (with plastics' transmittance tables), and the CPU
//! twin of `shaders/lib/materials.wesl`.

use glam::{Vec2, Vec3};

use std::collections::HashMap;

use super::{MediumInterface, Scene, TextureData, plastic};
use crate::gpu::layout::{
    MATERIAL_CONDUCTOR_INDEX, MATERIAL_DIELECTRIC, MATERIAL_DOUBLE_SIDED, MATERIAL_MEDIUM_TRANSITION, MATERIAL_NULL,
    MATERIAL_PLASTIC, MATERIAL_PLASTIC_NONLINEAR, MATERIAL_ROUGH, MATERIAL_THIN, MIN_ALPHA, Material, NONE,
    TEXTURE_CLAMP_U, TEXTURE_CLAMP_V, TEXTURE_NEAREST, TextureInfo,
};
pub use crate::gpu::packing::{pack2x16float, unpack2x16float};

/// GPU materials and the texture table of a scene: its textures, then one transmittance table
/// (64 x 1 texels, the red channel) per distinct plastic coat (alpha, eta).
pub fn gpu_materials_and_textures(scene: &Scene) -> (Vec<Material>, Vec<TextureInfo>, Vec<[u32; 2]>) {
    let mut infos = Vec::new();
    let mut texels = Vec::new();
    let mut push = |t: &TextureData| {
        infos.push(TextureInfo {
            offset: texels.len() as u32,
            width: t.width,
            height: t.height,
            wrap: if t.clamp_u { TEXTURE_CLAMP_U } else { 0 }
                | if t.clamp_v { TEXTURE_CLAMP_V } else { 0 }
                | if t.nearest { TEXTURE_NEAREST } else { 0 },
        });
        texels.extend(t.texels.iter().map(|c| [pack2x16float(c.x, c.y), pack2x16float(c.z, 1.0)]));
        infos.len() as u32 - 1
    };
    for t in &scene.textures {
        push(t);
    }
    // Coats of equal (alpha, eta, smoothness) share a table and internal reflectance.
    let mut coats: HashMap<(u32, u32, bool), (u32, f32)> = HashMap::new();
    let materials = scene
        .materials
        .iter()
        .map(|m| {
            let alpha = (m.roughness * m.roughness).max(MIN_ALPHA);
            let mut material = Material {
                base_color: m.base_color,
                base_color_texture: m.base_color_texture.unwrap_or(NONE),
                emission: m.emission,
                flags: if m.double_sided { MATERIAL_DOUBLE_SIDED } else { 0 },
                metallic: m.metallic,
                alpha,
                ..Default::default()
            };
            if let Some(coat) = m.plastic {
                let (table, internal) =
                    *coats.entry((alpha.to_bits(), coat.eta.to_bits(), coat.smooth)).or_insert_with(|| {
                        let (alpha, eta) = (alpha as f64, coat.eta as f64);
                        let t = plastic::transmittance_table(alpha, eta);
                        let table = push(&TextureData {
                            width: t.len() as u32,
                            height: 1,
                            texels: t.iter().map(|&t| Vec3::new(t as f32, 0.0, 0.0)).collect(),
                            clamp_u: true,
                            clamp_v: true,
                            nearest: true,
                        });
                        let internal = if coat.smooth {
                            plastic::smooth_internal_reflectance(eta)
                        } else {
                            plastic::internal_reflectance(alpha, eta)
                        };
                        (table, internal as f32)
                    });
                let texture_mean = m.base_color_texture.map_or(Vec3::ONE, |t| {
                    let t = &scene.textures[t as usize];
                    t.texels.iter().copied().sum::<Vec3>() / t.texels.len().max(1) as f32
                });
                let diffuse_mean = (m.base_color * texture_mean).element_sum() / 3.0;
                material.flags |= MATERIAL_PLASTIC | if coat.nonlinear { MATERIAL_PLASTIC_NONLINEAR } else { 0 };
                material.metallic = 0.0;
                material.eta = coat.eta;
                material.plastic_table = table;
                material.specular = coat.specular;
                material.plastic_internal_reflectance = internal;
                material.plastic_specular_weight = coat.specular / (coat.specular + diffuse_mean).max(1e-6);
            }
            if let Some((eta, k)) = m.conductor_index {
                material.flags |= MATERIAL_CONDUCTOR_INDEX;
                material.conductor_eta = eta;
                material.conductor_k = k;
            }
            material.interior_medium = m.media.interior.unwrap_or(NONE);
            material.exterior_medium = m.media.exterior.unwrap_or(NONE);
            if m.media != MediumInterface::default() {
                material.flags |= MATERIAL_MEDIUM_TRANSITION;
            }
            if m.null {
                material.flags |= MATERIAL_NULL | MATERIAL_DOUBLE_SIDED;
            }
            if let Some(d) = m.dielectric {
                material.flags |= MATERIAL_DIELECTRIC | MATERIAL_DOUBLE_SIDED | if d.thin { MATERIAL_THIN } else { 0 };
                material.metallic = 0.0;
                material.eta = d.eta;
                material.specular = d.specular;
                if d.alpha > 0.0 {
                    material.flags |= MATERIAL_ROUGH;
                    material.alpha = d.alpha.max(MIN_ALPHA);
                }
            }
            material
        })
        .collect();
    (materials, infos, texels)
}

/// The entries of a plastic coat's transmittance table `table` as the kernels read them.
pub fn plastic_table(infos: &[TextureInfo], texels: &[[u32; 2]], table: u32) -> Vec<f32> {
    let info = infos[table as usize];
    (0..info.width).map(|i| unpack2x16float(texels[(info.offset + i) as usize][0]).x).collect()
}

/// Albedo of `material` at `uv`: its base colour times its texture (twin of `albedo_at`).
pub fn albedo_at(infos: &[TextureInfo], texels: &[[u32; 2]], material: &Material, uv: Vec2) -> Vec3 {
    if material.base_color_texture == NONE {
        return material.base_color;
    }
    material.base_color * texture_bilinear(infos, texels, material.base_color_texture, uv)
}

/// Bilinear texture lookup, or the nearest texel's with [`TEXTURE_NEAREST`] (twin of
/// `texture_bilinear`).
pub fn texture_bilinear(infos: &[TextureInfo], texels: &[[u32; 2]], index: u32, uv: Vec2) -> Vec3 {
    let info = infos[index as usize];
    let nearest = info.wrap & TEXTURE_NEAREST != 0;
    let centre = if nearest { 0.0 } else { 0.5 };
    let x = uv.x * info.width as f32 - centre;
    let y = uv.y * info.height as f32 - centre;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = if nearest { (0.0, 0.0) } else { (x - x0, y - y0) };
    let wrap = |i: i32, n: u32, clamp: bool| -> u32 {
        if clamp { i.clamp(0, n as i32 - 1) as u32 } else { i.rem_euclid(n as i32) as u32 }
    };
    let cu = info.wrap & TEXTURE_CLAMP_U != 0;
    let cv = info.wrap & TEXTURE_CLAMP_V != 0;
    let (xa, xb) = (wrap(x0 as i32, info.width, cu), wrap(x0 as i32 + 1, info.width, cu));
    let (ya, yb) = (wrap(y0 as i32, info.height, cv), wrap(y0 as i32 + 1, info.height, cv));
    let texel = |x: u32, y: u32| {
        let w = texels[(info.offset + y * info.width + x) as usize];
        let rg = unpack2x16float(w[0]);
        Vec3::new(rg.x, rg.y, unpack2x16float(w[1]).x)
    };
    let top = texel(xa, ya).lerp(texel(xb, ya), fx);
    let bottom = texel(xa, yb).lerp(texel(xb, yb), fx);
    top.lerp(bottom, fy)
}
