//! glTF materials: base colour, metallic and roughness, emission (with
//! KHR_materials_emissive_strength), sides, base-colour textures decoded from sRGB, and
//! participating media (a material's `extras.medium`).

use anyhow::{Context as _, Result, anyhow, bail};
use glam::Vec3;

use super::{Loader, TRANSMISSIVE_EXTENSIONS};
use crate::scene::{MaterialDesc, MediumDesc, MediumInterface, TextureData};

impl Loader<'_> {
    pub(super) fn material(
        &self,
        m: &gltf::Material,
        textures: &mut Vec<TextureData>,
        texture_of_image: &mut std::collections::HashMap<(usize, bool, bool), u32>,
        media: &mut Vec<MediumDesc>,
    ) -> Result<MaterialDesc> {
        let name = self.name;
        let label = match (m.name(), m.index()) {
            (Some(n), _) => format!("material `{n}`"),
            (None, Some(i)) => format!("material {i}"),
            (None, None) => "the default material".to_owned(),
        };
        for extension in m.extensions().into_iter().flat_map(|e| e.keys()) {
            if !TRANSMISSIVE_EXTENSIONS.contains(&extension.as_str()) {
                self.warn(format!(
                    "{name}: {label}: the glTF extension {extension} is not implemented: ignored (the surface is \
                     rendered with its base colour, metallic and roughness only)"
                ));
            } else if self.allow_unsupported_materials {
                self.warn(format!(
                    "{name}: {label}: the glTF extension {extension} is not implemented: the material is rendered as \
                     an opaque surface (unsupported materials allowed)"
                ));
            } else {
                bail!(
                    "{name}: {label}: the glTF extension {extension} is not implemented: gatetrace renders every \
                     surface opaque, so light would not pass through this material; remove the extension, or allow \
                     the opaque stand-in with --allow-unsupported-materials (Python: \
                     Scene.load(..., allow_unsupported_materials=True))"
                );
            }
        }
        if let Some(medium) = medium_extras(m, self.base).with_context(|| format!("{name}: {label}: extras.medium"))? {
            media.push(MediumDesc { name: format!("{name}: {label}"), ..medium });
            let interface = MediumInterface { interior: Some(media.len() as u32 - 1), exterior: None };
            return Ok(MaterialDesc::null_boundary(m.name().unwrap_or("").to_owned(), interface));
        }
        let pbr = m.pbr_metallic_roughness();
        let [r, g, b, _] = pbr.base_color_factor();
        let base_color = Vec3::new(r, g, b);
        let emission = Vec3::from(m.emissive_factor()) * m.emissive_strength().unwrap_or(1.0);
        if !base_color.is_finite() || base_color.min_element() < 0.0 {
            bail!("{name}: {label}: baseColorFactor {base_color} is not finite and non-negative");
        }
        if !emission.is_finite() || emission.min_element() < 0.0 {
            bail!("{name}: {label}: emission {emission} is not finite and non-negative");
        }
        if m.emissive_texture().is_some() {
            self.warn(format!("{name}: {label}: emissiveTexture is ignored (uniform emission only)"));
        }
        let metallic = pbr.metallic_factor();
        let roughness = pbr.roughness_factor();
        if !(0.0..=1.0).contains(&metallic) || !(0.0..=1.0).contains(&roughness) {
            bail!("{name}: {label}: metallicFactor {metallic} and roughnessFactor {roughness} must lie in [0, 1]");
        }
        if metallic > 0.0 && roughness * roughness < crate::gpu::layout::MIN_ALPHA {
            self.warn(format!(
                "{name}: {label}: roughness {roughness} is rendered as {} (GGX alpha at least {})",
                crate::gpu::layout::MIN_ALPHA.sqrt(),
                crate::gpu::layout::MIN_ALPHA
            ));
        }
        if pbr.metallic_roughness_texture().is_some() {
            self.warn(format!("{name}: {label}: metallicRoughnessTexture is ignored (factors only)"));
        }
        let base_color_texture = match pbr.base_color_texture() {
            None => None,
            Some(info) => {
                let texture = info.texture();
                let sampler = texture.sampler();
                let clamp_u = sampler.wrap_s() == gltf::texture::WrappingMode::ClampToEdge;
                let clamp_v = sampler.wrap_t() == gltf::texture::WrappingMode::ClampToEdge;
                let image = texture.source().index();
                let key = (image, clamp_u, clamp_v);
                if let Some(&t) = texture_of_image.get(&key) {
                    Some(t)
                } else {
                    let data =
                        self.images.get(image).ok_or_else(|| anyhow!("{name}: {label}: image {image} is missing"))?;
                    let mut tex = decode_srgb_image(data).with_context(|| format!("{name}: {label}: image {image}"))?;
                    tex.clamp_u = clamp_u;
                    tex.clamp_v = clamp_v;
                    textures.push(tex);
                    let t = textures.len() as u32 - 1;
                    texture_of_image.insert(key, t);
                    Some(t)
                }
            }
        };
        Ok(MaterialDesc {
            name: m.name().unwrap_or("").to_owned(),
            base_color,
            base_color_texture,
            emission,
            double_sided: m.double_sided(),
            metallic,
            roughness,
            plastic: None,
            dielectric: None,
            conductor_index: None,
            media: Default::default(),
            null: false,
        })
    }
}

/// Decodes an 8- or 16-bit sRGB-encoded (or float, linear) image to linear RGB.
fn decode_srgb_image(data: &gltf::image::Data) -> Result<TextureData> {
    use gltf::image::Format as F;
    let (channels, bytes_per_channel, float) = match data.format {
        F::R8 => (1, 1, false),
        F::R8G8 => (2, 1, false),
        F::R8G8B8 => (3, 1, false),
        F::R8G8B8A8 => (4, 1, false),
        F::R16 => (1, 2, false),
        F::R16G16 => (2, 2, false),
        F::R16G16B16 => (3, 2, false),
        F::R16G16B16A16 => (4, 2, false),
        F::R32G32B32FLOAT => (3, 4, true),
        F::R32G32B32A32FLOAT => (4, 4, true),
    };
    let texel_count = (data.width * data.height) as usize;
    if data.pixels.len() < texel_count * channels * bytes_per_channel {
        bail!("pixel data is shorter than {}x{} texels", data.width, data.height);
    }
    let channel = |i: usize| -> f32 {
        let o = i * bytes_per_channel;
        match (bytes_per_channel, float) {
            (1, _) => srgb_to_linear(data.pixels[o] as f32 / 255.0),
            (2, _) => srgb_to_linear(u16::from_le_bytes([data.pixels[o], data.pixels[o + 1]]) as f32 / 65535.0),
            _ => f32::from_le_bytes(data.pixels[o..o + 4].try_into().unwrap()),
        }
    };
    let texels = (0..texel_count)
        .map(|t| {
            let base = t * channels;
            match channels {
                1 | 2 => Vec3::splat(channel(base)),
                _ => Vec3::new(channel(base), channel(base + 1), channel(base + 2)),
            }
        })
        .collect();
    Ok(TextureData { width: data.width, height: data.height, texels, clamp_u: false, clamp_v: false, nearest: false })
}

/// sRGB transfer function, encoded [0, 1] to linear.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
}

/// The medium a material's `extras.medium` describes, which makes the material no surface at
/// all, only the boundary of that medium (inside its closed, outward-wound meshes; in front of
/// them vacuum): `{"medium": {"sigma_t": S, "albedo": A, "g": G, "grid": {...}}}`, S the
/// extinction (m^-1, positive), A the single-scattering albedo (a number or [r, g, b], 0..1,
/// default 0.9), G the Henyey-Greenstein mean cosine (-1..1, default 0). With `grid` (see
/// [`grid_extras`]) the medium is heterogeneous: its extinction is S times the grid's value.
/// Relative paths start at `base`. None without one.
fn medium_extras(m: &gltf::Material, base: &std::path::Path) -> Result<Option<MediumDesc>> {
    let Some(raw) = m.extras() else { return Ok(None) };
    let value: serde_json::Value = serde_json::from_str(raw.get())?;
    let Some(medium) = value.get("medium") else { return Ok(None) };
    let number = |key: &str| -> Result<Option<f32>> {
        match medium.get(key) {
            None => Ok(None),
            Some(v) => v.as_f64().map(|x| Some(x as f32)).ok_or_else(|| anyhow!("`{key}` is {v}, not a number")),
        }
    };
    let sigma_t = number("sigma_t")?.ok_or_else(|| anyhow!("`sigma_t` (the extinction, m^-1) is missing"))?;
    if !(sigma_t > 0.0 && sigma_t.is_finite()) {
        bail!("sigma_t {sigma_t} is not a positive extinction (m^-1)");
    }
    let albedo = match medium.get("albedo") {
        None => Vec3::splat(0.9),
        Some(serde_json::Value::Array(a)) if a.len() == 3 => {
            let c: Option<Vec<f32>> = a.iter().map(|x| x.as_f64().map(|x| x as f32)).collect();
            Vec3::from_slice(&c.ok_or_else(|| anyhow!("`albedo` {a:?} is not three numbers"))?)
        }
        Some(v) => Vec3::splat(v.as_f64().ok_or_else(|| anyhow!("`albedo` is {v}, not a number or [r, g, b]"))? as f32),
    };
    if !(albedo.min_element() >= 0.0 && albedo.max_element() <= 1.0) {
        bail!("albedo {albedo} is not within [0, 1]");
    }
    let g = number("g")?.unwrap_or(0.0);
    if !(g > -1.0 && g < 1.0) {
        bail!("g {g} is not within (-1, 1)");
    }
    let mut desc = MediumDesc { name: String::new(), sigma_t, albedo, g, grid: None };
    if let Some(grid) = medium.get("grid") {
        grid_extras(&mut desc, grid, base).context("grid")?;
    }
    Ok(Some(desc))
}

/// A heterogeneous medium's grids from `extras.medium.grid`: `{"uri": "smoke.vol", "min": [x, y,
/// z], "max": [x, y, z], "filter": "trilinear" | "nearest", "albedo": "albedo.vol"}`: a `.vol`
/// file of one channel (Mitsuba's volume format) whose voxels span the world-space box from
/// `min` to `max` (m; the file's own bounding box is not read), looked up with `filter` (default
/// trilinear), and optionally an albedo grid of one or three channels on the same voxels, which
/// then replaces the medium's albedo. The medium's `sigma_t` scales the grid's values.
fn grid_extras(medium: &mut MediumDesc, grid: &serde_json::Value, base: &std::path::Path) -> Result<()> {
    use crate::scene::medium::{DensityGrid, read_vol};
    let corner = |key: &str| -> Result<Vec3> {
        let v = grid.get(key).ok_or_else(|| anyhow!("`{key}` (the box's {key} corner, m) is missing"))?;
        let c: Option<Vec<f32>> = v
            .as_array()
            .filter(|a| a.len() == 3)
            .map(|a| a.iter().filter_map(|x| x.as_f64().map(|x| x as f32)).collect::<Vec<_>>());
        match c {
            Some(c) if c.len() == 3 && c.iter().all(|x| x.is_finite()) => Ok(Vec3::from_slice(&c)),
            _ => bail!("`{key}` is {v}, not three numbers"),
        }
    };
    let file = |key: &str| -> Result<Option<std::path::PathBuf>> {
        match grid.get(key) {
            None => Ok(None),
            Some(v) => Ok(Some(base.join(v.as_str().ok_or_else(|| anyhow!("`{key}` is {v}, not a file name"))?))),
        }
    };
    let uri = file("uri")?.ok_or_else(|| anyhow!("`uri` (the .vol file of the extinction) is missing"))?;
    let (lo, hi) = (corner("min")?, corner("max")?);
    if !(hi - lo).cmpgt(Vec3::ZERO).all() {
        bail!("the box from min {lo} to max {hi} is empty");
    }
    let nearest = match grid.get("filter").map(|f| f.as_str()) {
        None | Some(Some("trilinear")) => false,
        Some(Some("nearest")) => true,
        Some(_) => bail!("`filter` is {}, not \"trilinear\" or \"nearest\"", grid["filter"]),
    };
    let (resolution, channels, mut values) = read_vol(&uri)?;
    if channels != 1 {
        bail!("{}: {channels} channels: an extinction grid has one", uri.display());
    }
    let max = values.iter().fold(0.0f32, |a, &b| a.max(b));
    if !(max > 0.0) {
        bail!("{}: the grid holds no extinction anywhere (its largest value is 0)", uri.display());
    }
    values.iter_mut().for_each(|v| *v /= max);
    let world_to_grid = glam::Mat4::from_scale(1.0 / (hi - lo)) * glam::Mat4::from_translation(-lo);
    let mut density = DensityGrid { resolution, values, world_to_grid, nearest, albedo: None };
    if let Some(path) = file("albedo")? {
        let (r, channels, a) = read_vol(&path)?;
        density.set_albedo(r, channels, a).with_context(|| path.display().to_string())?;
        medium.albedo = Vec3::ONE;
    }
    medium.sigma_t *= max;
    medium.grid = Some(density);
    Ok(())
}
