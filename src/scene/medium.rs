//! Participating media: homogeneous media bounded by `null` surfaces (Mitsuba's `null` BSDF with
//! an `interior` medium) or around the camera, and the CPU twin of `shaders/lib/medium.wesl`
//! (the Henyey-Greenstein phase function, its sampling, transmittance).
//!
//! Conventions: a phase function is written in terms of mu, the cosine between the direction a
//! ray travelled in and the direction it leaves in, so mu = 1 is no deflection; a positive mean
//! cosine g scatters forward (Mitsuba's and pbrt's `hg` alike).

use glam::Vec3;

use crate::gpu::layout::Medium;

/// A homogeneous medium as loaded.
#[derive(Clone, Debug, PartialEq)]
pub struct MediumDesc {
    /// Where it was declared (file and element), for messages.
    pub name: String,
    /// Extinction coefficient sigma_t (m^-1), the same in every channel.
    pub sigma_t: f32,
    /// Single-scattering albedo sigma_s / sigma_t (linear RGB, 0..1).
    pub albedo: Vec3,
    /// Mean cosine of the Henyey-Greenstein phase function (-1 < g < 1; 0: isotropic).
    pub g: f32,
}

impl MediumDesc {
    /// The medium in the kernels' layout.
    pub fn to_gpu(&self) -> Medium {
        Medium { albedo: self.albedo, sigma_t: self.sigma_t, g: self.g, ..Default::default() }
    }
}

impl MediumDesc {
    /// A fog given as `SIGMA_T[,ALBEDO[,G]]`: extinction sigma_t (m^-1, positive), albedo (0..1,
    /// default 0.9) and the phase function's mean cosine g (-1 < g < 1, default 0.8, forward as
    /// droplets scatter), as `--fog` takes it.
    pub fn parse_fog(spec: &str) -> anyhow::Result<Self> {
        let numbers: Vec<f32> = spec
            .split(',')
            .map(|x| x.trim().parse::<f32>().ok().filter(|x| x.is_finite()))
            .collect::<Option<_>>()
            .ok_or_else(|| anyhow::anyhow!("`{spec}` is not SIGMA_T[,ALBEDO[,G]] (numbers)"))?;
        let (sigma_t, albedo, g) = match numbers[..] {
            [s] => (s, 0.9, 0.8),
            [s, a] => (s, a, 0.8),
            [s, a, g] => (s, a, g),
            _ => anyhow::bail!("`{spec}` is not SIGMA_T[,ALBEDO[,G]]: at most three numbers"),
        };
        anyhow::ensure!(sigma_t > 0.0, "fog `{spec}`: the extinction {sigma_t} m^-1 is not positive");
        anyhow::ensure!((0.0..=1.0).contains(&albedo), "fog `{spec}`: the albedo {albedo} is not within [0, 1]");
        anyhow::ensure!(g > -1.0 && g < 1.0, "fog `{spec}`: g {g} is not within (-1, 1)");
        Ok(MediumDesc { name: format!("fog {spec}"), sigma_t, albedo: Vec3::splat(albedo), g })
    }
}

/// The media on the two sides of a surface, indices into `Scene::media` (None: vacuum).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct MediumInterface {
    /// Behind the triangles' front faces (inside a closed, outward-wound mesh).
    pub interior: Option<u32>,
    /// In front of them.
    pub exterior: Option<u32>,
}

/// The Henyey-Greenstein phase function of mean cosine `g` at cosine `mu` between the directions
/// of travel before and after scattering (sr^-1; twin of `hg_phase`).
pub fn hg_phase(mu: f32, g: f32) -> f32 {
    let denominator = 1.0 + g * g - 2.0 * g * mu;
    (1.0 - g * g) / (4.0 * std::f32::consts::PI * denominator * denominator.sqrt())
}

/// The cosine mu drawn from the Henyey-Greenstein phase function of mean cosine `g` by inverting
/// its distribution at `u` in [0, 1) (twin of `sample_hg_cosine`).
pub fn sample_hg_cosine(g: f32, u: f32) -> f32 {
    if g.abs() < 1e-3 {
        return 2.0 * u - 1.0;
    }
    let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
    ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
}

/// A unit direction drawn from the Henyey-Greenstein phase function about unit direction of
/// travel `d`, with `u` in [0, 1)^2, and its density (sr^-1; twin of `sample_hg`).
pub fn sample_hg(d: Vec3, g: f32, u: [f32; 2]) -> (Vec3, f32) {
    let mu = sample_hg_cosine(g, u[0]);
    let sin = (1.0 - mu * mu).max(0.0).sqrt();
    let phi = 2.0 * std::f32::consts::PI * u[1];
    let (x, y) = d.any_orthonormal_pair();
    let w = (x * phi.cos() + y * phi.sin()) * sin + d * mu;
    (w.normalize(), hg_phase(mu, g))
}

/// The share of light that crosses a distance `t` (m) of a medium of extinction `sigma_t`
/// (m^-1) unscattered: exp(-sigma_t t).
pub fn transmittance(sigma_t: f32, t: f32) -> f32 {
    (-sigma_t * t).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The phase function integrates to one over the sphere and has mean cosine g.
    #[test]
    fn hg_phase_is_normalised_with_mean_cosine_g() {
        for g in [-0.7f32, -0.2, 0.0, 0.3, 0.5, 0.9] {
            let n = 200_000;
            let (mut total, mut mean) = (0.0f64, 0.0f64);
            for i in 0..n {
                let mu = -1.0 + 2.0 * (i as f64 + 0.5) / n as f64;
                let p = hg_phase(mu as f32, g) as f64 * 2.0 * std::f64::consts::PI * 2.0 / n as f64;
                total += p;
                mean += p * mu;
            }
            assert!((total - 1.0).abs() < 1e-3, "g {g}: integral {total}");
            assert!((mean - g as f64).abs() < 2e-3, "g {g}: mean cosine {mean}");
        }
    }

    /// Inverting the distribution: mu is -1 at u = 0, 1 at u = 1, and increasing.
    #[test]
    fn hg_cosine_sampling_spans_minus_one_to_one() {
        for g in [-0.8f32, 0.0, 0.4, 0.95] {
            assert!((sample_hg_cosine(g, 0.0) + 1.0).abs() < 1e-5);
            assert!((sample_hg_cosine(g, 1.0) - 1.0).abs() < 1e-5);
            let mut last = -1.0;
            for i in 1..100 {
                let mu = sample_hg_cosine(g, i as f32 / 100.0);
                assert!(mu >= last, "g {g}: not increasing at {i}");
                last = mu;
            }
        }
    }
}
