//! BSDFs and textures of Mitsuba scenes: what each `<bsdf>` element becomes (a Lambertian,
//! conductor or plastic material), its textures (`bitmap`, `checkerboard`) and their images.

use std::path::Path;

use anyhow::{Result, anyhow};
use glam::Vec3;

use super::Builder;
use super::xml::{Element, Object};
use crate::gpu::layout::MIN_ALPHA;
use crate::scene::{Dielectric, PlasticCoat, TextureData};

/// What a BSDF turns into.
#[derive(Clone, Debug)]
pub(super) struct Surface {
    pub base_color: Vec3,
    /// A texture of the base colour, and the affine map from the shape's uv to the texture's.
    pub texture: Option<(u32, glam::Affine2)>,
    pub metallic: f32,
    pub roughness: f32,
    pub plastic: Option<PlasticCoat>,
    pub dielectric: Option<Dielectric>,
    pub conductor_index: Option<(Vec3, Vec3)>,
    pub double_sided: bool,
    pub name: String,
}

/// Indices of refraction by name, as Mitsuba's scenes give them (at 589 nm).
const IORS: [(&str, f32); 23] = [
    ("vacuum", 1.0),
    ("helium", 1.000036),
    ("hydrogen", 1.000132),
    ("air", 1.000277),
    ("carbon dioxide", 1.00045),
    ("water", 1.333),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.52045),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.470),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.575),
    ("diamond", 2.419),
];

/// The index of refraction of a material named as in Mitsuba's table (any case).
fn named_ior(name: &str) -> Option<f32> {
    IORS.iter().find(|(n, _)| n.eq_ignore_ascii_case(name.trim())).map(|&(_, ior)| ior)
}

impl<'e> Builder<'e> {
    /// What a `<bsdf>` element describes, or an error for the BSDFs gatetrace does not render.
    pub(super) fn surface(&mut self, e: &'e Element) -> Result<Surface> {
        e.only_attributes(&["type", "id", "name"])?;
        let o = Object::new(e);
        let name = e.attribute("id").unwrap_or("").to_owned();
        let surface = match o.kind()? {
            "twosided" => {
                let inner: Vec<&Element> =
                    e.children.iter().filter(|c| matches!(c.tag.as_str(), "bsdf" | "ref")).collect();
                let [inner] = inner[..] else {
                    return Err(e.error(
                        "a twosided BSDF with a different BSDF on each side is not rendered (give it one BSDF)",
                    ));
                };
                let inner = if inner.tag == "ref" { self.resolve(inner, "bsdf")? } else { inner };
                if inner.attribute("type") == Some("twosided") {
                    return Err(inner.error("a twosided BSDF inside a twosided BSDF"));
                }
                o.finish(&["bsdf", "ref"])?;
                let mut s = self.surface(inner)?;
                s.double_sided = true;
                if !name.is_empty() {
                    s.name = name;
                }
                return Ok(s);
            }
            "diffuse" => {
                let (reflectance, texture) = self.albedo(&o, "reflectance")?;
                o.finish(&["texture", "ref"])?;
                Surface {
                    base_color: reflectance,
                    texture,
                    metallic: 0.0,
                    roughness: 1.0,
                    plastic: None,
                    dielectric: None,
                    conductor_index: None,
                    double_sided: false,
                    name,
                }
            }
            kind @ ("plastic" | "roughplastic") => {
                let (diffuse, texture) = self.albedo(&o, "diffuse_reflectance")?;
                // Mitsuba's plastics default to polypropylene.
                let (eta, specular) = self.interface(&o, 1.49)?;
                let nonlinear = o.boolean("nonlinear")?.unwrap_or(false);
                let smooth = kind == "plastic";
                let alpha = if smooth {
                    self.warn(
                        e,
                        format!(
                            "a smooth plastic's coat is rendered as a GGX coat of alpha {MIN_ALPHA}, gatetrace's \
                             smallest"
                        ),
                    );
                    MIN_ALPHA
                } else {
                    self.microfacet_alpha(&o)?
                };
                o.finish(&["texture", "ref"])?;
                Surface {
                    base_color: diffuse,
                    texture,
                    metallic: 0.0,
                    roughness: alpha.sqrt(),
                    plastic: Some(PlasticCoat { eta, specular, nonlinear, smooth }),
                    dielectric: None,
                    conductor_index: None,
                    double_sided: false,
                    name,
                }
            }
            kind @ ("conductor" | "roughconductor") => {
                if let Some(t) = e.children.iter().find(|c| matches!(c.tag.as_str(), "texture" | "ref")) {
                    return Err(
                        t.error("a conductor's textures are not read (textures apply to a diffuse reflectance)")
                    );
                }
                let (specular, index) = self.conductor(&o)?;
                let alpha = if kind == "roughconductor" {
                    self.microfacet_alpha(&o)?
                } else {
                    self.warn(
                        e,
                        format!("a smooth conductor is rendered as a GGX conductor of alpha {MIN_ALPHA}, gatetrace's smallest"),
                    );
                    MIN_ALPHA
                };
                o.finish(&[])?;
                Surface {
                    base_color: specular,
                    texture: None,
                    metallic: 1.0,
                    roughness: alpha.sqrt(),
                    plastic: None,
                    dielectric: None,
                    conductor_index: index,
                    double_sided: false,
                    name,
                }
            }
            kind @ ("dielectric" | "thindielectric" | "roughdielectric") => {
                if let Some(t) = e.children.iter().find(|c| matches!(c.tag.as_str(), "texture" | "ref")) {
                    return Err(t.error("a dielectric's textures are not read"));
                }
                let alpha = if kind == "roughdielectric" { self.microfacet_alpha(&o)? } else { 0.0 };
                // Mitsuba's dielectrics default to BK7.
                let (eta, specular) = self.interface(&o, 1.5046)?;
                let transmittance = o.color("specular_transmittance")?.unwrap_or(Vec3::ONE);
                check_albedo(e, transmittance)?;
                o.finish(&[])?;
                Surface {
                    base_color: transmittance,
                    texture: None,
                    metallic: 0.0,
                    roughness: alpha.sqrt(),
                    plastic: None,
                    conductor_index: None,
                    dielectric: Some(Dielectric { eta, specular, thin: kind == "thindielectric", alpha }),
                    double_sided: true,
                    name,
                }
            }
            "null" => {
                return Err(
                    e.error("a `null` BSDF stands directly on a shape (which then bounds media or is not there)")
                );
            }
            other => return Err(e.error(format!("the BSDF `{other}` is not rendered by gatetrace"))),
        };
        Ok(surface)
    }

    /// A reflectance given as a colour or a texture named `name` (Mitsuba's default 0.5), checked
    /// to lie in [0, 1]: the colour (1 with a texture) and the texture.
    fn albedo(&mut self, o: &Object<'e>, name: &str) -> Result<(Vec3, Option<(u32, glam::Affine2)>)> {
        let e = o.element;
        let mut texture = None;
        for t in e.children.iter().filter(|c| matches!(c.tag.as_str(), "texture" | "ref")) {
            if t.attribute("name") != Some(name) || texture.is_some() {
                return Err(
                    t.error(format!("a {} BSDF takes one texture, named `{name}`", e.attribute("type").unwrap_or("")))
                );
            }
            let t = if t.tag == "ref" { self.resolve(t, "texture")? } else { t };
            texture = Some(self.texture(t)?);
        }
        let reflectance = o.color(name)?;
        if texture.is_some() && reflectance.is_some() {
            return Err(e.error(format!("`{name}` is given twice (a value and a texture)")));
        }
        let reflectance = reflectance.unwrap_or(if texture.is_some() { Vec3::ONE } else { Vec3::splat(0.5) });
        check_albedo(e, reflectance)?;
        Ok((reflectance, texture))
    }

    /// The GGX alpha of a rough BSDF (`alpha`, Mitsuba's default 0.1; a Beckmann distribution is
    /// rendered as GGX with a warning), at least gatetrace's smallest.
    fn microfacet_alpha(&mut self, o: &Object<'e>) -> Result<f32> {
        let e = o.element;
        match o.string("distribution")?.unwrap_or("beckmann") {
            "ggx" => {}
            "beckmann" => self.warn(
                e,
                "the Beckmann distribution (Mitsuba's default) is rendered as GGX with the same alpha: highlights \
                 get GGX's longer tails (give `distribution` ggx to match Mitsuba)",
            ),
            other => return Err(e.error(format!("the microfacet distribution `{other}` is not known"))),
        }
        if o.float("alpha_u")?.is_some() || o.float("alpha_v")?.is_some() {
            return Err(e.error("anisotropic roughness (alpha_u, alpha_v) is not rendered: give `alpha`"));
        }
        o.ignore(&["sample_visible"]);
        let alpha = o.float("alpha")?.unwrap_or(0.1);
        if !(alpha > 0.0 && alpha <= 1.0) {
            return Err(e.error(format!("alpha {alpha} is not in (0, 1]")));
        }
        if alpha < MIN_ALPHA {
            self.warn(e, format!("alpha {alpha} is rendered as {MIN_ALPHA}, gatetrace's smallest roughness"));
        }
        Ok(alpha.max(MIN_ALPHA))
    }

    /// A dielectric interface (a dielectric's, or a plastic's coat): its relative index
    /// int_ior / ext_ior (`int_ior` defaulting to `default_int_ior`, `ext_ior` to air) and its
    /// `specular_reflectance`, one value for all channels.
    fn interface(&mut self, o: &Object<'e>, default_int_ior: f32) -> Result<(f32, f32)> {
        let e = o.element;
        let int_ior = self.ior(o, "int_ior", default_int_ior)?;
        let ext_ior = self.ior(o, "ext_ior", 1.000277)?;
        if int_ior == ext_ior {
            return Err(e.error(format!("int_ior and ext_ior are both {int_ior}: the interface must refract")));
        }
        let specular = o.color("specular_reflectance")?.unwrap_or(Vec3::ONE);
        check_albedo(e, specular)?;
        if specular.x != specular.y || specular.y != specular.z {
            return Err(e.error(format!(
                "a coloured specular_reflectance ({specular}) is not rendered: give one value for all channels"
            )));
        }
        Ok((int_ior / ext_ior, specular.x))
    }

    /// An index of refraction: a number, or the name of a material in Mitsuba's table
    /// ([`named_ior`]); `default` when absent.
    fn ior(&mut self, o: &Object<'e>, name: &str, default: f32) -> Result<f32> {
        let e = o.element;
        let ior = match o.float_or_name(name)? {
            None => default,
            Some(Ok(x)) => x,
            Some(Err(material)) => named_ior(material).ok_or_else(|| {
                e.error(format!(
                    "`{material}` ({name}) is not a known material: give a number or one of {}",
                    IORS.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
                ))
            })?,
        };
        if !(1.0..=10.0).contains(&ior) {
            return Err(e.error(format!("{name} {ior} is not an index of refraction in [1, 10]")));
        }
        Ok(ior)
    }

    /// A texture (`bitmap` or `checkerboard`): its index in the scene's textures and its `to_uv`.
    fn texture(&mut self, t: &'e Element) -> Result<(u32, glam::Affine2)> {
        t.only_attributes(&["type", "id", "name"])?;
        let o = Object::new(t);
        let m = o.transform("to_uv")?;
        let map = glam::Affine2::from_cols(
            m.x_axis.truncate().truncate(),
            m.y_axis.truncate().truncate(),
            m.w_axis.truncate().truncate(),
        );
        if let Some(&index) = self.texture_of.get(&(t as *const Element as usize)) {
            o.finish(&[])?;
            return Ok((index, map));
        }
        let texture = match o.kind()? {
            "checkerboard" => {
                let c0 = o.color("color0")?.unwrap_or(Vec3::splat(0.4));
                let c1 = o.color("color1")?.unwrap_or(Vec3::splat(0.2));
                check_albedo(t, c0)?;
                check_albedo(t, c1)?;
                // Mitsuba's checkerboard: color0 where u and v lie in halves of the same parity
                // of their unit square, color1 elsewhere: two by two texels, nearest lookups.
                TextureData {
                    width: 2,
                    height: 2,
                    texels: vec![c0, c1, c1, c0],
                    clamp_u: false,
                    clamp_v: false,
                    nearest: true,
                }
            }
            "bitmap" => {
                let file = o.string("filename")?.ok_or_else(|| t.error("`filename` is missing"))?;
                let path = self.base.join(file);
                let raw = o.boolean("raw")?.unwrap_or(false);
                let nearest = match o.string("filter_type")?.unwrap_or("bilinear") {
                    "bilinear" => false,
                    "nearest" => true,
                    other => return Err(t.error(format!("filter_type `{other}` is not bilinear or nearest"))),
                };
                let clamp = match o.string("wrap_mode")?.unwrap_or("repeat") {
                    "repeat" => false,
                    "clamp" => true,
                    other => return Err(t.error(format!("wrap_mode `{other}` is not rendered (repeat and clamp are)"))),
                };
                let (width, height, texels) = read_bitmap(&path, raw).map_err(|err| t.error(format!("{err:#}")))?;
                if texels.iter().any(|c| c.min_element() < 0.0 || c.max_element() > 1.0) {
                    return Err(t.error("a reflectance texture with values outside [0, 1]"));
                }
                TextureData { width, height, texels, clamp_u: clamp, clamp_v: clamp, nearest }
            }
            other => return Err(t.error(format!("the texture `{other}` is not read (bitmap and checkerboard are)"))),
        };
        o.finish(&[])?;
        self.textures.push(texture);
        let index = self.textures.len() as u32 - 1;
        self.texture_of.insert(t as *const Element as usize, index);
        Ok((index, map))
    }

    /// A conductor's `specular_reflectance` and complex index of refraction (eta, k): none for
    /// Mitsuba's `material="none"` (its default: a perfect mirror), a preset's
    /// ([`super::conductors`]), or `eta` and `k` as given (k defaults to 1, as in Mitsuba).
    fn conductor(&mut self, o: &Object<'e>) -> Result<(Vec3, Option<(Vec3, Vec3)>)> {
        let e = o.element;
        let eta = o.color("eta")?;
        let k = o.color("k")?;
        let material = o.string("material")?;
        let index = match (material, eta, k) {
            (Some(m), Some(_), _) | (Some(m), _, Some(_)) if m != "none" => {
                return Err(e.error(format!("give either `material` ({m}) or `eta` and `k`, not both")));
            }
            (Some("none") | None, None, None) => None,
            (Some(m), None, None) => {
                let (eta, k) = super::conductors::conductor(m).ok_or_else(|| {
                    e.error(format!(
                        "the conductor `{m}` is not known: give its `eta` and `k` as <rgb>, `none` (a perfect \
                         mirror), or one of {}",
                        super::conductors::CONDUCTORS.iter().map(|(n, _, _)| *n).collect::<Vec<_>>().join(", ")
                    ))
                })?;
                Some((Vec3::from(eta), Vec3::from(k)))
            }
            (_, Some(eta), k) => Some((eta, k.unwrap_or(Vec3::ONE))),
            (_, None, Some(_)) => return Err(e.error("`k` needs `eta` beside it")),
        };
        if let Some((eta, k)) = index
            && (eta.min_element() < 0.0 || k.min_element() < 0.0)
        {
            return Err(e.error(format!("a conductor's eta ({eta}) and k ({k}) must not be negative")));
        }
        let specular = o.color("specular_reflectance")?.unwrap_or(Vec3::ONE);
        check_albedo(e, specular)?;
        Ok((specular, index))
    }
}

/// A bitmap's size and linear RGB texels, row 0 at the top (v = 0): PNG and JPEG decoded from
/// sRGB unless `raw`, EXR as stored (linear).
fn read_bitmap(path: &Path, raw: bool) -> Result<(u32, u32, Vec<Vec3>)> {
    // Texels a texture may hold (8192 x 8192), checked from the header before decoding.
    const MAX_TEXELS: u64 = 1 << 26;
    let name = path.display();
    let too_large =
        |w: u64, h: u64| anyhow!("{name}: a {w} x {h} image is larger than the {MAX_TEXELS} texels a texture may hold");
    let extension = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if extension == "exr" {
        let meta = exr::meta::MetaData::read_from_file(path, false)
            .map_err(|e| anyhow!("{name}: cannot read the EXR image: {e}"))?;
        for header in &meta.headers {
            let (w, h) = (header.layer_size.width() as u64, header.layer_size.height() as u64);
            if w * h > MAX_TEXELS {
                return Err(too_large(w, h));
            }
        }
        let image = exr::prelude::read_first_rgba_layer_from_file(
            path,
            |resolution, _| (resolution.width(), vec![Vec3::ZERO; resolution.width() * resolution.height()]),
            |(width, texels): &mut (usize, Vec<Vec3>), position, (r, g, b, _a): (f32, f32, f32, f32)| {
                texels[position.y() * *width + position.x()] = Vec3::new(r, g, b);
            },
        )
        .map_err(|e| anyhow!("{name}: cannot read the EXR image: {e}"))?;
        let size = image.layer_data.size;
        let (_, texels) = image.layer_data.channel_data.pixels;
        return Ok((size.width() as u32, size.height() as u32, texels));
    }
    let open = || -> Result<image::ImageReader<std::io::BufReader<std::fs::File>>> {
        image::ImageReader::open(path)
            .map_err(|e| anyhow!("{name}: cannot read the image: {e}"))?
            .with_guessed_format()
            .map_err(|e| anyhow!("{name}: cannot read the image: {e}"))
    };
    let (w, h) = open()?
        .into_dimensions()
        .map_err(|e| anyhow!("{name}: cannot decode the image (PNG, JPEG and EXR are read): {e}"))?;
    if w as u64 * h as u64 > MAX_TEXELS {
        return Err(too_large(w as u64, h as u64));
    }
    let image =
        open()?.decode().map_err(|e| anyhow!("{name}: cannot decode the image (PNG, JPEG and EXR are read): {e}"))?;
    let rgb = image.to_rgb32f();
    let decode = |c: f32| if raw { c } else { crate::scene::gltf_loader::srgb_to_linear(c) };
    let texels = rgb.pixels().map(|p| Vec3::new(decode(p.0[0]), decode(p.0[1]), decode(p.0[2]))).collect();
    Ok((rgb.width(), rgb.height(), texels))
}

/// Errors on a reflectance outside [0, 1] (such a surface would create energy).
fn check_albedo(e: &Element, c: Vec3) -> Result<()> {
    if c.min_element() < 0.0 || c.max_element() > 1.0 {
        return Err(e.error(format!("the reflectance {c} is outside [0, 1]")));
    }
    Ok(())
}
