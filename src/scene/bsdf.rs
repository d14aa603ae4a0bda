//! CPU twin of `shaders/lib/bsdf.wesl`: the glTF metallic-roughness material as a linear blend
//! (weight `metallic`) of a Lambertian lobe and a GGX conductor lobe (F0 = base colour, Schlick
//! Fresnel, height-correlated Smith masking, visible-normal sampling). Reflection only.
//!
//! Directions are unit vectors in the local frame of the shading normal (z up); `wo` points back
//! along the path, `wi` onwards. f is in sr^-1 (no cosine), pdfs are solid-angle densities.

use std::f32::consts::{FRAC_1_PI, PI};

use glam::{Vec2, Vec3};

/// The material at a surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bsdf {
    /// Lambertian albedo and conductor F0 (linear RGB).
    pub base_color: Vec3,
    /// Weight of the conductor lobe (0..1), also its sampling probability.
    pub metallic: f32,
    /// GGX alpha (roughness^2).
    pub alpha: f32,
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
}

impl Bsdf {
    fn conductor_eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        let h = (wo + wi).normalize();
        let a2 = self.alpha * self.alpha;
        let g2 = 1.0 / (1.0 + ggx_lambda(wo, a2) + ggx_lambda(wi, a2));
        schlick_fresnel(self.base_color, wo.dot(h)) * (ggx_d(h, a2) * g2 / (4.0 * wo.z) / wi.z)
    }

    fn conductor_pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let h = (wo + wi).normalize();
        let a2 = self.alpha * self.alpha;
        let g1 = 1.0 / (1.0 + ggx_lambda(wo, a2));
        g1 * ggx_d(h, a2) / (4.0 * wo.z)
    }

    /// f(wo, wi) (sr^-1); zero unless both directions lie above the surface.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Vec3::ZERO;
        }
        let mut f = (1.0 - self.metallic) * FRAC_1_PI * self.base_color;
        if self.metallic > 0.0 {
            f += self.metallic * self.conductor_eval(wo, wi);
        }
        f
    }

    /// Solid-angle pdf (sr^-1) with which `sample` returns wi given wo.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let mut pdf = (1.0 - self.metallic) * wi.z * FRAC_1_PI;
        if self.metallic > 0.0 {
            pdf += self.metallic * self.conductor_pdf(wo, wi);
        }
        pdf
    }

    /// Picks the conductor lobe with probability `metallic` (by `u_lobe`), samples it with `u`.
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> BsdfSample {
        let wi = if u_lobe < self.metallic {
            let h = ggx_sample_visible_normal(wo, self.alpha, u);
            2.0 * wo.dot(h) * h - wo
        } else {
            crate::sampling::sample_cosine_hemisphere(u)
        };
        let pdf = self.pdf(wo, wi);
        if wo.z <= 0.0 || wi.z <= 0.0 || pdf.is_nan() || pdf <= 0.0 {
            return BsdfSample { wi, pdf: 0.0, f: Vec3::ZERO };
        }
        BsdfSample { wi, pdf, f: self.eval(wo, wi) }
    }
}
