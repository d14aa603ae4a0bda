//! CPU twin of `shaders/lib/bsdf.wesl`: the glTF metallic-roughness material as a linear blend
//! (weight `metallic`) of a Lambertian lobe and a GGX conductor lobe (F0 = base colour, Schlick
//! Fresnel, height-correlated Smith masking, visible-normal sampling), or a plastic: a Lambertian
//! base under a dielectric GGX coat (`scene::plastic`); these reflect only. A smooth dielectric
//! (glass) is a delta BSDF: reflection with the Fresnel reflectance, else refraction, returned
//! only by `sample` (see bsdf.wesl for the convention of its samples). A rough dielectric (its
//! `alpha` > 0) is an interface of GGX microfacets that reflect and refract (Walter et al. 2007):
//! `eval` and `pdf` give its reflection, [`Bsdf::rough_dielectric_eval`] and
//! [`Bsdf::rough_dielectric_pdf`] both sides, and `sample` may refract.
//!
//! Directions are unit vectors in the local frame of the shading normal (z up); `wo` points back
//! along the path, `wi` onwards. f is in sr^-1 (no cosine), pdfs are solid-angle densities.

use std::f32::consts::{FRAC_1_PI, PI};

use glam::{Vec2, Vec3};

use super::materials::{albedo_at, plastic_table};
use super::prepared::PreparedScene;
use crate::gpu::layout::{
    MATERIAL_CONDUCTOR_INDEX, MATERIAL_DIELECTRIC, MATERIAL_PLASTIC, MATERIAL_PLASTIC_NONLINEAR, MATERIAL_ROUGH,
    MATERIAL_THIN,
};
use crate::scene::plastic::TRANSMITTANCE_TABLE_LEN;

/// The material at a surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bsdf {
    /// Lambertian albedo and conductor F0 (linear RGB); for a plastic, the albedo its base
    /// reflects through the coat, internal reflections included, divided by eta^2.
    pub base_color: Vec3,
    /// Weight of the conductor lobe (0..1), also its sampling probability; 0 for a plastic.
    pub metallic: f32,
    /// GGX alpha (roughness^2) of the conductor lobe or of a plastic's coat.
    pub alpha: f32,
    /// A plastic's coat, when the material is one.
    pub plastic: Option<PlasticLobe>,
    /// A smooth dielectric, when the material is one (`base_color` its transmittance factor),
    /// its `eta` across the interface from the side the path arrives on.
    pub dielectric: Option<crate::scene::Dielectric>,
    /// The conductor lobe's complex index (eta, k), when its Fresnel term is the exact one
    /// (times `base_color`) instead of Schlick's.
    pub conductor_index: Option<(Vec3, Vec3)>,
}

/// Unpolarised Fresnel reflectance of a conductor of complex index eta + i k (per channel) for
/// light at `cos_i` > 0 (twin of `fresnel_conductor`).
pub fn fresnel_conductor(cos_i: f32, eta: Vec3, k: Vec3) -> Vec3 {
    let (c2, s2) = (cos_i * cos_i, 1.0 - cos_i * cos_i);
    let t0 = eta * eta - k * k - Vec3::splat(s2);
    let a2b2 = (t0 * t0 + 4.0 * eta * eta * k * k).powf(0.5);
    let a = (0.5 * (a2b2 + t0)).max(Vec3::ZERO).powf(0.5);
    let t1 = a2b2 + Vec3::splat(c2);
    let t2 = 2.0 * cos_i * a;
    let rs = (t1 - t2) / (t1 + t2);
    let t3 = c2 * a2b2 + Vec3::splat(s2 * s2);
    let t4 = t2 * s2;
    let ratio = Vec3::select((t3 + t4).cmpeq(Vec3::ZERO), Vec3::ONE, (t3 - t4) / (t3 + t4));
    0.5 * (rs + rs * ratio)
}

/// A plastic's coat as the BSDF reads it (twin of the `plastic_*` members of WGSL `Bsdf`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlasticLobe {
    /// Relative index of refraction.
    pub eta: f32,
    /// Factor of the coat's specular reflection.
    pub specular: f32,
    /// Specular weight of the lobe choice.
    pub specular_weight: f32,
    /// The transmittance table's entries, as the kernels read them.
    pub transmittance: [f32; TRANSMITTANCE_TABLE_LEN],
}

impl PlasticLobe {
    /// t(cos theta), linear between the table's entries (twin of `plastic_transmittance`).
    pub fn transmittance(&self, cos_theta: f32) -> f32 {
        let n = TRANSMITTANCE_TABLE_LEN;
        let x = cos_theta.clamp(0.0, 1.0) * (n - 1) as f32;
        let i = (x as usize).min(n - 2);
        let (a, b) = (self.transmittance[i], self.transmittance[i + 1]);
        a + (b - a) * (x - i as f32)
    }
}

/// Reflectance of a thin pane of relative index `eta` for light at `cos_i`: the interface's F
/// plus the light reflected back out after bouncing inside, F + (1 - F)^2 F / (1 - F^2) (twin
/// of `thin_reflectance`).
pub fn thin_reflectance(cos_i: f32, eta: f32) -> f32 {
    let f = fresnel_dielectric(cos_i, eta);
    if f >= 1.0 { 1.0 } else { f + (1.0 - f) * (1.0 - f) * f / (1.0 - f * f) }
}

/// Unpolarised Fresnel reflectance of a dielectric interface (twin of `fresnel_dielectric`,
/// evaluated in f64 by `scene::plastic::fresnel_dielectric`).
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    super::plastic::fresnel_dielectric(cos_i as f64, eta as f64) as f32
}

fn ggx_d(h: Vec3, a2: f32) -> f32 {
    let d = h.z * h.z * (a2 - 1.0) + 1.0;
    a2 / (PI * d * d)
}

fn ggx_lambda(w: Vec3, a2: f32) -> f32 {
    let c2 = w.z * w.z;
    let t2 = (1.0 - c2).max(0.0) / c2.max(1e-12);
    0.5 * ((1.0 + a2 * t2).sqrt() - 1.0)
}

/// Heitz's visible-normal sampling of the GGX distribution seen from `wo`.
pub fn ggx_sample_visible_normal(wo: Vec3, alpha: f32, u: Vec2) -> Vec3 {
    let vh = Vec3::new(alpha * wo.x, alpha * wo.y, wo.z).normalize();
    let len2 = vh.x * vh.x + vh.y * vh.y;
    let t1 = if len2 > 0.0 { Vec3::new(-vh.y, vh.x, 0.0) / len2.sqrt() } else { Vec3::X };
    let t2 = vh.cross(t1);
    let r = u.x.sqrt();
    let phi = 2.0 * PI * u.y;
    let p1 = r * phi.cos();
    let s = 0.5 * (1.0 + vh.z);
    let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
    let nh = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * vh;
    Vec3::new(alpha * nh.x, alpha * nh.y, nh.z.max(1e-7)).normalize()
}

/// Smith's G1 of direction w for microfacet normal h, zero unless w meets h from its own side
/// (twin of `ggx_g1`).
fn ggx_g1(w: Vec3, h: Vec3, a2: f32) -> f32 {
    if w.dot(h) * w.z <= 0.0 {
        return 0.0;
    }
    1.0 / (1.0 + ggx_lambda(w, a2))
}

/// The microfacet normal (z >= 0) that reflects wo into wi or refracts one into the other
/// across relative index `eta` (twin of `rough_dielectric_normal`); zero when there is none.
fn rough_dielectric_normal(wo: Vec3, wi: Vec3, eta: f32) -> Vec3 {
    let h = if wi.z < 0.0 { wo + eta * wi } else { wo + wi };
    let len = h.length();
    if !(len > 0.0) {
        return Vec3::ZERO;
    }
    h * (h.z.signum() / len)
}

fn schlick_fresnel(f0: Vec3, cos_theta: f32) -> Vec3 {
    let m = (1.0 - cos_theta).clamp(0.0, 1.0);
    let m2 = m * m;
    f0 + (Vec3::ONE - f0) * (m2 * m2 * m)
}

/// A sampled direction; `pdf` 0 when sampling failed.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    /// The sampled direction (local frame).
    pub wi: Vec3,
    /// Solid-angle pdf of the blend (sr^-1).
    pub pdf: f32,
    /// f(wo, wi) of the blend (sr^-1).
    pub f: Vec3,
    /// A dielectric's reflection or refraction: `pdf` is the choice's probability and f |wi.z| /
    /// pdf the path's weight.
    pub delta: bool,
}

impl Bsdf {
    /// The BSDF of material `material` of `scene` at texture coordinates `uv` (twin of `bsdf_at`).
    pub fn at(scene: &PreparedScene, material: u32, uv: Vec2) -> Bsdf {
        let m = scene.materials[material as usize];
        let albedo = albedo_at(&scene.texture_infos, &scene.texels, &m, uv);
        if m.flags & MATERIAL_DIELECTRIC != 0 {
            let thin = m.flags & MATERIAL_THIN != 0;
            let alpha = if m.flags & MATERIAL_ROUGH != 0 { m.alpha } else { 0.0 };
            let dielectric = Some(crate::scene::Dielectric { eta: m.eta, specular: m.specular, thin, alpha });
            return Bsdf {
                base_color: albedo,
                metallic: 0.0,
                alpha: m.alpha,
                plastic: None,
                dielectric,
                conductor_index: None,
            };
        }
        if m.flags & MATERIAL_PLASTIC == 0 {
            let conductor_index = (m.flags & MATERIAL_CONDUCTOR_INDEX != 0).then_some((m.conductor_eta, m.conductor_k));
            return Bsdf {
                base_color: albedo,
                metallic: m.metallic,
                alpha: m.alpha,
                plastic: None,
                dielectric: None,
                conductor_index,
            };
        }
        let mut reflected = Vec3::splat(m.plastic_internal_reflectance);
        if m.flags & MATERIAL_PLASTIC_NONLINEAR != 0 {
            reflected *= albedo;
        }
        let eta = m.eta;
        let table = plastic_table(&scene.texture_infos, &scene.texels, m.plastic_table);
        let transmittance = std::array::from_fn(|i| table[i]);
        Bsdf {
            base_color: albedo / ((Vec3::ONE - reflected) * (eta * eta)),
            metallic: 0.0,
            alpha: m.alpha,
            plastic: Some(PlasticLobe {
                eta,
                specular: m.specular,
                specular_weight: m.plastic_specular_weight,
                transmittance,
            }),
            dielectric: None,
            conductor_index: None,
        }
    }

    fn plastic_eval(&self, p: &PlasticLobe, wo: Vec3, wi: Vec3) -> Vec3 {
        let h = (wo + wi).normalize();
        let a2 = self.alpha * self.alpha;
        let g = 1.0 / ((1.0 + ggx_lambda(wo, a2)) * (1.0 + ggx_lambda(wi, a2)));
        let specular = p.specular * fresnel_dielectric(wo.dot(h), p.eta) * (ggx_d(h, a2) * g / (4.0 * wo.z) / wi.z);
        let through = p.transmittance(wo.z) * p.transmittance(wi.z);
        self.base_color * (FRAC_1_PI * through) + Vec3::splat(specular)
    }

    /// Probability that a plastic's sampling picks the coat's reflection (twin of
    /// `plastic_specular_probability`).
    fn plastic_specular_probability(p: &PlasticLobe, wo: Vec3) -> f32 {
        let t = p.transmittance(wo.z);
        let s = (1.0 - t) * p.specular_weight;
        let d = t * (1.0 - p.specular_weight);
        s / (s + d).max(1e-20)
    }

    fn conductor_eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        let h = (wo + wi).normalize();
        let a2 = self.alpha * self.alpha;
        let g2 = 1.0 / (1.0 + ggx_lambda(wo, a2) + ggx_lambda(wi, a2));
        let fresnel = match self.conductor_index {
            Some((eta, k)) => self.base_color * fresnel_conductor(wo.dot(h), eta, k),
            None => schlick_fresnel(self.base_color, wo.dot(h)),
        };
        fresnel * (ggx_d(h, a2) * g2 / (4.0 * wo.z) / wi.z)
    }

    fn ggx_reflection_pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let h = (wo + wi).normalize();
        let a2 = self.alpha * self.alpha;
        let g1 = 1.0 / (1.0 + ggx_lambda(wo, a2));
        g1 * ggx_d(h, a2) / (4.0 * wo.z)
    }

    /// The rough dielectric's interface, when the material is one.
    fn rough_dielectric(&self) -> Option<crate::scene::Dielectric> {
        self.dielectric.filter(|d| d.alpha > 0.0)
    }

    /// f(wo, wi) (sr^-1) of a rough dielectric for wo above the surface and wi on either side
    /// (twin of `rough_dielectric_eval`); zero for other materials.
    pub fn rough_dielectric_eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        let Some(d) = self.rough_dielectric() else { return Vec3::ZERO };
        let h = rough_dielectric_normal(wo, wi, d.eta);
        let a2 = d.alpha * d.alpha;
        let g = ggx_g1(wo, h, a2) * ggx_g1(wi, h, a2);
        if g.is_nan() || g <= 0.0 || wi.z == 0.0 || wo.z <= 0.0 {
            return Vec3::ZERO;
        }
        let wo_h = wo.dot(h);
        let f = fresnel_dielectric(wo_h, d.eta);
        let dh = ggx_d(h, a2);
        if wi.z > 0.0 {
            return Vec3::splat(d.specular * f * dh * g / (4.0 * wo.z * wi.z));
        }
        let wi_h = wi.dot(h);
        let denom = wo_h + d.eta * wi_h;
        self.base_color * ((1.0 - f) * dh * g * (wo_h * wi_h).abs() / (wo.z * wi.z.abs() * denom * denom))
    }

    /// Solid-angle pdf (sr^-1) of a rough dielectric's sampling for wo above the surface and wi
    /// on either side (twin of `rough_dielectric_pdf`); zero for other materials.
    pub fn rough_dielectric_pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let Some(d) = self.rough_dielectric() else { return 0.0 };
        let h = rough_dielectric_normal(wo, wi, d.eta);
        let a2 = d.alpha * d.alpha;
        let g1 = ggx_g1(wo, h, a2);
        let wi_h = wi.dot(h);
        if g1.is_nan() || g1 <= 0.0 || wi_h * wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        let wo_h = wo.dot(h);
        let visible = g1 * wo_h * ggx_d(h, a2) / wo.z;
        let f = fresnel_dielectric(wo_h, d.eta);
        if wi.z > 0.0 {
            return f * visible / (4.0 * wo_h);
        }
        let denom = wo_h + d.eta * wi_h;
        (1.0 - f) * visible * d.eta * d.eta * wi_h.abs() / (denom * denom)
    }

    /// f(wo, wi) (sr^-1); zero unless both directions lie above the surface.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        if self.rough_dielectric().is_some() {
            return if wi.z > 0.0 { self.rough_dielectric_eval(wo, wi) } else { Vec3::ZERO };
        }
        if wo.z <= 0.0 || wi.z <= 0.0 || self.dielectric.is_some() {
            return Vec3::ZERO;
        }
        if let Some(p) = &self.plastic {
            return self.plastic_eval(p, wo, wi);
        }
        let mut f = (1.0 - self.metallic) * FRAC_1_PI * self.base_color;
        if self.metallic > 0.0 {
            f += self.metallic * self.conductor_eval(wo, wi);
        }
        f
    }

    /// Solid-angle pdf (sr^-1) with which `sample` returns wi given wo.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if self.rough_dielectric().is_some() {
            return if wi.z > 0.0 { self.rough_dielectric_pdf(wo, wi) } else { 0.0 };
        }
        if wo.z <= 0.0 || wi.z <= 0.0 || self.dielectric.is_some() {
            return 0.0;
        }
        if let Some(p) = &self.plastic {
            let s = Self::plastic_specular_probability(p, wo);
            return s * self.ggx_reflection_pdf(wo, wi) + (1.0 - s) * wi.z * FRAC_1_PI;
        }
        let mut pdf = (1.0 - self.metallic) * wi.z * FRAC_1_PI;
        if self.metallic > 0.0 {
            pdf += self.metallic * self.ggx_reflection_pdf(wo, wi);
        }
        pdf
    }

    /// Picks the conductor lobe with probability `metallic` (a plastic: the coat's reflection with
    /// its specular probability) by `u_lobe`, samples it with `u`.
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> BsdfSample {
        if let Some(d) = self.rough_dielectric() {
            let failed = BsdfSample { wi: wo, pdf: 0.0, f: Vec3::ZERO, delta: false };
            if wo.z <= 0.0 {
                return failed;
            }
            let h = ggx_sample_visible_normal(wo, d.alpha, u);
            let wo_h = wo.dot(h);
            let reflect = u_lobe < fresnel_dielectric(wo_h, d.eta);
            let wi = if reflect {
                2.0 * wo_h * h - wo
            } else {
                let sin2_t = (1.0 - wo_h * wo_h) / (d.eta * d.eta);
                if sin2_t >= 1.0 {
                    return failed;
                }
                (wo_h / d.eta - (1.0 - sin2_t).sqrt()) * h - wo / d.eta
            };
            // Reflection must stay above, refraction below (checked as the kernel does).
            if reflect != (wi.z > 0.0) || wi.z == 0.0 {
                return failed;
            }
            let pdf = self.rough_dielectric_pdf(wo, wi);
            if pdf.is_nan() || pdf <= 0.0 {
                return failed;
            }
            return BsdfSample { wi, pdf, f: self.rough_dielectric_eval(wo, wi), delta: false };
        }
        if let Some(d) = self.dielectric {
            if wo.z <= 0.0 {
                return BsdfSample { wi: wo, pdf: 0.0, f: Vec3::ZERO, delta: true };
            }
            if d.thin {
                let r = thin_reflectance(wo.z, d.eta);
                if u_lobe < r {
                    let wi = Vec3::new(-wo.x, -wo.y, wo.z);
                    return BsdfSample { wi, pdf: r, f: Vec3::splat(d.specular * r / wo.z), delta: true };
                }
                return BsdfSample { wi: -wo, pdf: 1.0 - r, f: self.base_color * ((1.0 - r) / wo.z), delta: true };
            }
            let f = fresnel_dielectric(wo.z, d.eta);
            if u_lobe < f {
                let wi = Vec3::new(-wo.x, -wo.y, wo.z);
                return BsdfSample { wi, pdf: f, f: Vec3::splat(d.specular * f / wo.z), delta: true };
            }
            let cos_t = (1.0 - (1.0 - wo.z * wo.z) / (d.eta * d.eta)).max(0.0).sqrt();
            let wi = Vec3::new(-wo.x / d.eta, -wo.y / d.eta, -cos_t);
            let value = self.base_color * ((1.0 - f) / (d.eta * d.eta * cos_t));
            return BsdfSample { wi, pdf: 1.0 - f, f: value, delta: true };
        }
        let glossy = match &self.plastic {
            Some(p) if wo.z > 0.0 => u_lobe < Self::plastic_specular_probability(p, wo),
            _ => u_lobe < self.metallic,
        };
        let wi = if glossy {
            let h = ggx_sample_visible_normal(wo, self.alpha, u);
            2.0 * wo.dot(h) * h - wo
        } else {
            crate::sampling::sample_cosine_hemisphere(u)
        };
        let pdf = self.pdf(wo, wi);
        if wo.z <= 0.0 || wi.z <= 0.0 || pdf.is_nan() || pdf <= 0.0 {
            return BsdfSample { wi, pdf: 0.0, f: Vec3::ZERO, delta: false };
        }
        BsdfSample { wi, pdf, f: self.eval(wo, wi), delta: false }
    }
}
