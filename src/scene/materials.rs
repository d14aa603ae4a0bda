//! Material and texture tables for the GPU, and the CPU twin of `shaders/lib/materials.wesl`.

use glam::{Vec2, Vec3};

use super::Scene;
use crate::gpu::layout::{
    MATERIAL_DOUBLE_SIDED, MIN_ALPHA, Material, NONE, TEXTURE_CLAMP_U, TEXTURE_CLAMP_V, TEXTURE_NEAREST, TextureInfo,
};
pub use crate::gpu::packing::{pack2x16float, unpack2x16float};

/// GPU materials of a scene.
pub fn gpu_materials(scene: &Scene) -> Vec<Material> {
    scene
        .materials
        .iter()
        .map(|m| Material {
            base_color: m.base_color,
            base_color_texture: m.base_color_texture.unwrap_or(NONE),
            emission: m.emission,
            flags: if m.double_sided { MATERIAL_DOUBLE_SIDED } else { 0 },
            metallic: m.metallic,
            alpha: (m.roughness * m.roughness).max(MIN_ALPHA),
            reserved0: 0,
            reserved1: 0,
        })
        .collect()
}

/// Texture directory and texels (each texel two `pack2x16float` words: (r, g), (b, 1)).
pub fn gpu_textures(scene: &Scene) -> (Vec<TextureInfo>, Vec<[u32; 2]>) {
    let mut infos = Vec::new();
    let mut texels = Vec::new();
    for t in &scene.textures {
        infos.push(TextureInfo {
            offset: texels.len() as u32,
            width: t.width,
            height: t.height,
            wrap: if t.clamp_u { TEXTURE_CLAMP_U } else { 0 }
                | if t.clamp_v { TEXTURE_CLAMP_V } else { 0 }
                | if t.nearest { TEXTURE_NEAREST } else { 0 },
        });
        texels.extend(t.texels.iter().map(|c| [pack2x16float(c.x, c.y), pack2x16float(c.z, 1.0)]));
    }
    (infos, texels)
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
