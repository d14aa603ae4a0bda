//! The coat of a plastic (Mitsuba's `plastic` and `roughplastic`): what the host computes once per
//! material for the kernels. A plastic is a Lambertian base under a dielectric interface of
//! relative index eta (inside over outside) with GGX roughness alpha (bsdf.wesl). Light that the
//! coat does not reflect reaches the base; the base's light leaves through the coat or is
//! reflected back into the base. The model needs two numbers of the coat, both integrals over
//! its microfacets seen from a direction, computed here in f64 by quadrature:
//!
//! - the transmittance t(cos θ): the fraction of light arriving at angle θ that the rough
//!   interface refracts into the base, with Smith masking of the refracted direction, tabulated
//!   at cos θ = i / 63 (i = 0..63, the first at 10⁻⁶) and interpolated linearly by the kernels
//!   ([`transmittance_table`]);
//! - the internal reflectance: the fraction of the base's diffuse light (cosine-weighted) that the
//!   interface reflects back, 2 · mean over the same 64 cosines of R(cos θ, 1/eta) · cos θ, R the
//!   reflectance seen from inside ([`internal_reflectance`]). A smooth coat takes the published
//!   fit of Egan and Hilgeman (1973) for it instead ([`smooth_internal_reflectance`]).
//!
//! Both follow Mitsuba 3's definitions, so a scene renders as the peer renders it. The twins
//! of the kernels' lookups are `scene::materials::plastic_transmittance` and `scene::bsdf`.

use glam::DVec3;

/// Entries of a coat's transmittance table.
pub const TRANSMITTANCE_TABLE_LEN: usize = 64;

/// Points per axis of the quadrature over the visible-normal sample square.
const QUADRATURE_POINTS: usize = 160;

/// The unpolarised Fresnel reflectance of a dielectric interface for light arriving at
/// `cos_i` > 0 from the side whose index is 1 / `eta` times the other's (eta = n_t / n_i);
/// 1 under total internal reflection.
pub fn fresnel_dielectric(cos_i: f64, eta: f64) -> f64 {
    let sin_t2 = (1.0 - cos_i * cos_i).max(0.0) / (eta * eta);
    if sin_t2 >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin_t2).sqrt();
    let rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    0.5 * (rs * rs + rp * rp)
}

/// Smith's masking G1 of GGX (alpha) for direction `w` over the facet `m` (either hemisphere).
fn smith_g1(w: DVec3, m: DVec3, alpha: f64) -> f64 {
    if w.dot(m) * w.z <= 0.0 {
        return 0.0;
    }
    let c2 = w.z * w.z;
    let t2 = (1.0 - c2).max(0.0) / c2.max(1e-300);
    2.0 / (1.0 + (1.0 + alpha * alpha * t2).sqrt())
}

/// Heitz's visible-normal sampling of GGX seen from `w` (upper hemisphere), in f64.
fn sample_visible_normal(w: DVec3, alpha: f64, u: (f64, f64)) -> DVec3 {
    let vh = DVec3::new(alpha * w.x, alpha * w.y, w.z).normalize();
    let len2 = vh.x * vh.x + vh.y * vh.y;
    let t1 = if len2 > 0.0 { DVec3::new(-vh.y, vh.x, 0.0) / len2.sqrt() } else { DVec3::X };
    let t2 = vh.cross(t1);
    let r = u.0.sqrt();
    let phi = std::f64::consts::TAU * u.1;
    let p1 = r * phi.cos();
    let s = 0.5 * (1.0 + vh.z);
    let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
    let nh = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * vh;
    DVec3::new(alpha * nh.x, alpha * nh.y, nh.z.max(1e-12)).normalize()
}

/// The mean of `g(m)` over GGX's visible normals seen from the direction at `cos_theta`: a
/// midpoint rule over the sample square of [`sample_visible_normal`].
fn mean_over_visible_normals(cos_theta: f64, alpha: f64, g: impl Fn(DVec3, DVec3) -> f64) -> f64 {
    let w = DVec3::new((1.0 - cos_theta * cos_theta).max(0.0).sqrt(), 0.0, cos_theta);
    let n = QUADRATURE_POINTS;
    let mut sum = 0.0;
    for i in 0..n {
        for j in 0..n {
            let u = ((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
            sum += g(w, sample_visible_normal(w, alpha, u));
        }
    }
    sum / (n * n) as f64
}

/// The cosines of the table's entries: i / 63, the first raised to 10⁻⁶.
fn table_cosines() -> impl Iterator<Item = f64> {
    (0..TRANSMITTANCE_TABLE_LEN).map(|i| (i as f64 / (TRANSMITTANCE_TABLE_LEN - 1) as f64).max(1e-6))
}

/// Fraction of light arriving from outside at `cos_theta` that the rough interface refracts
/// inside (Fresnel transmission times the refracted direction's masking).
pub fn transmittance(cos_theta: f64, alpha: f64, eta: f64) -> f64 {
    mean_over_visible_normals(cos_theta, alpha, |w, m| {
        let c = w.dot(m);
        let f = fresnel_dielectric(c, eta);
        if f >= 1.0 {
            return 0.0;
        }
        let cos_t = (1.0 - (1.0 - c * c) / (eta * eta)).max(0.0).sqrt();
        let wt = -w / eta + (c / eta - cos_t) * m;
        if wt.z >= 0.0 { 0.0 } else { (1.0 - f) * smith_g1(wt, m, alpha) }
    })
}

/// Fraction of light arriving at `cos_theta` that the rough interface reflects, its relative
/// index `eta` (Fresnel reflection times the reflected direction's masking).
pub fn reflectance(cos_theta: f64, alpha: f64, eta: f64) -> f64 {
    mean_over_visible_normals(cos_theta, alpha, |w, m| {
        let wr = 2.0 * w.dot(m) * m - w;
        if wr.z <= 0.0 { 0.0 } else { fresnel_dielectric(w.dot(m), eta) * smith_g1(wr, m, alpha) }
    })
}

/// The coat's transmittance at the table's cosines.
pub fn transmittance_table(alpha: f64, eta: f64) -> Vec<f64> {
    table_cosines().map(|c| transmittance(c, alpha, eta)).collect()
}

/// The fraction of the base's cosine-distributed light that a rough coat reflects back into it.
pub fn internal_reflectance(alpha: f64, eta: f64) -> f64 {
    2.0 * table_cosines().map(|c| reflectance(c, alpha, 1.0 / eta) * c).sum::<f64>() / TRANSMITTANCE_TABLE_LEN as f64
}

/// The same fraction for a smooth coat: Egan and Hilgeman's fit of the diffuse Fresnel
/// reflectance at relative index 1 / eta (for eta > 1; within 0.1 % for 1 < eta < 1.5), and
/// d'Eon and Irving's (2011) fit for eta < 1.
pub fn smooth_internal_reflectance(eta: f64) -> f64 {
    let e = 1.0 / eta;
    if e < 1.0 {
        -1.4399 * e * e + 0.7099 * e + 0.6681 + 0.0636 / e
    } else {
        let i = 1.0 / e;
        0.919317 - 3.4793 * i + 6.75335 * i.powi(2) - 7.80989 * i.powi(3) + 4.98554 * i.powi(4) - 1.36881 * i.powi(5)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Normal incidence on glass (eta 1.5) reflects ((eta - 1) / (eta + 1))^2 = 4 %; from inside
    /// past the critical angle, everything.
    #[test]
    fn fresnel_has_its_closed_forms() {
        assert!((fresnel_dielectric(1.0, 1.5) - 0.04).abs() < 1e-12);
        assert_eq!(fresnel_dielectric(0.5, 1.0 / 1.5), 1.0);
        assert!((fresnel_dielectric(1e-9, 1.5) - 1.0).abs() < 1e-6, "grazing light is reflected");
    }

    /// A nearly smooth coat transmits 1 - F; the diffuse reflectance from inside, integrated
    /// exactly (2 ∫ F(μ, 1/eta) μ dμ by a fine midpoint rule), matches the published fit
    /// within its stated 0.1 %; the rough coat's definition (Mitsuba's: a mean over 64 cosines,
    /// 2 % below the integral) equals that mean of the exact F at those cosines.
    #[test]
    fn a_smooth_coat_has_the_closed_forms() {
        let eta = 1.49;
        for c in [1.0, 0.7, 0.3, 0.05] {
            let t = transmittance(c, 1e-4, eta);
            assert!((t - (1.0 - fresnel_dielectric(c, eta))).abs() < 2e-4, "cos {c}: t {t}");
        }
        let n = 200_000;
        let exact = 2.0
            * (0..n).map(|i| (i as f64 + 0.5) / n as f64).map(|m| fresnel_dielectric(m, 1.0 / eta) * m).sum::<f64>()
            / n as f64;
        let fit = smooth_internal_reflectance(eta);
        assert!((fit / exact - 1.0).abs() < 1e-3, "fit {fit} exact {exact}");
        let table = internal_reflectance(1e-4, eta);
        let discrete = 2.0 * table_cosines().map(|m| fresnel_dielectric(m, 1.0 / eta) * m).sum::<f64>()
            / TRANSMITTANCE_TABLE_LEN as f64;
        assert!((table - discrete).abs() < 2e-3, "table {table} discrete mean {discrete} (exact {exact})");
    }

    /// Rough coats: reflectance and transmittance from outside never sum above 1 (masking only
    /// loses light); at normal incidence a nearly smooth coat loses under 1 %, and rougher
    /// coats lose more.
    #[test]
    fn a_rough_coat_conserves_energy() {
        let mut previous_loss = 0.0;
        for alpha in [0.05, 0.3, 0.8] {
            for c in [1.0, 0.5, 0.1] {
                let (r, t) = (reflectance(c, alpha, 1.5), transmittance(c, alpha, 1.5));
                assert!(r > 0.0 && t > 0.0 && r + t <= 1.0 + 1e-9, "alpha {alpha} cos {c}: R {r} T {t}");
                if c == 1.0 {
                    let loss = 1.0 - (r + t);
                    assert!(loss > previous_loss, "alpha {alpha}: loses {loss}, less than a smoother coat");
                    assert!(alpha > 0.05 || loss < 0.01, "alpha {alpha}: loses {loss} at normal incidence");
                    previous_loss = loss;
                }
            }
        }
    }
}
