//! Numerical stress test of the f32 ellipsoid code (shaders/lib/ellipsoid.wesl) against the f64
//! oracle: random configurations and adversarial families, run on the device through the
//! test-only kernel `probe_ellipsoid`, with the error distributions of Theta (the arcs' total
//! angle), the sampled angle, the sampled point's |L(x) - tau_e| relative to tau_e, and J.
//! Used by a CI-sized test and by `gatetrace stress-ellipsoid` (a million configurations).

use anyhow::Result;
use glam::{DVec3, Vec3};

use super::{Spheroid, Triangle, clip_arcs};
use crate::gpu::resources::read_buffer;
use crate::gpu::{GpuContext, Kernel, Resources};
use crate::rng::Xorshift64Star;

/// A family of configurations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Family {
    /// Foci in [-1, 1]^3, tau_e = d (1.01 .. 3), a triangle of random size and shape about a
    /// point of the spheroid.
    Random,
    /// tau_e - d = `0` x d: needle-thin spheroids.
    NearDegenerate(f64),
    /// Planes within 10^-8 .. 10^-2 a of tangency (inside).
    NearTangent,
    /// Planes through the light-side focus.
    PlaneThroughFocus,
    /// Both foci on the triangle's plane.
    FociOnPlane,
    /// Sliver triangles (height / base 10^-6 .. 10^-2).
    Sliver,
    /// `Random` scaled by `0` (e.g. 1e-3: millimetre scenes, 1e3: kilometre scenes).
    Scaled(f64),
}

impl Family {
    /// A short name for reports.
    pub fn name(&self) -> String {
        match self {
            Family::Random => "random".into(),
            Family::NearDegenerate(e) => format!("tau_e - d = {e:.0e} d"),
            Family::NearTangent => "near-tangent planes".into(),
            Family::PlaneThroughFocus => "plane through a focus".into(),
            Family::FociOnPlane => "foci on the plane".into(),
            Family::Sliver => "sliver triangles".into(),
            Family::Scaled(s) => format!("random x {s:.0e}"),
        }
    }

    /// Every family the stress test covers.
    pub fn all() -> Vec<Family> {
        let mut v = vec![Family::Random];
        v.extend([1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7].map(Family::NearDegenerate));
        v.extend([Family::NearTangent, Family::PlaneThroughFocus, Family::FociOnPlane, Family::Sliver]);
        v.extend([1e-3, 1e3].map(Family::Scaled));
        v
    }
}

/// One query, in the f32 values the device sees.
#[derive(Clone, Copy, Debug)]
pub struct Config {
    /// Light-side focus (m).
    pub focus_s: Vec3,
    /// Camera-side focus (m).
    pub focus_c: Vec3,
    /// Target length of the connection (m).
    pub tau_e: f32,
    /// Triangle vertices (m), counter-clockwise about its normal.
    pub triangle: [Vec3; 3],
    /// Fraction along the arcs at which theta is sampled.
    pub u: f32,
}

impl Config {
    /// The triangle as the device holds it, exactly: v0 and the f32 edges v1 - v0, v2 - v0 (as a
    /// scene's triangles are stored), their sums taken in f64 (where they are exact).
    pub fn device_triangle(&self) -> Triangle {
        let [v0, v1, v2] = self.triangle;
        let (e1, e2) = (v1 - v0, v2 - v0);
        let v0 = v0.as_dvec3();
        Triangle { vertices: [v0, v0 + e1.as_dvec3(), v0 + e2.as_dvec3()] }
    }
}

/// The draws of a configuration beyond [`Xorshift64Star`]'s own.
trait Draws {
    /// A uniform unit vector (rejection from the cube).
    fn unit(&mut self) -> DVec3;
    /// A number whose logarithm is uniform between those of `lo` and `hi`.
    fn log_uniform(&mut self, lo: f64, hi: f64) -> f64;
}

impl Draws for Xorshift64Star {
    fn unit(&mut self) -> DVec3 {
        loop {
            let v = self.next_dvec3();
            let l2 = v.length_squared();
            if l2 > 0.01 && l2 <= 1.0 {
                return v / l2.sqrt();
            }
        }
    }

    fn log_uniform(&mut self, lo: f64, hi: f64) -> f64 {
        (lo.ln() + (hi.ln() - lo.ln()) * self.next_f64()).exp()
    }
}

/// The point of the spheroid in direction `w` from its centre (bisection on L).
fn surface_point(sp: &Spheroid, w: DVec3) -> DVec3 {
    let m = sp.centre();
    let (mut lo, mut hi) = (0.0, sp.a());
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if sp.path_length(m + mid * w) < sp.length {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    m + lo * w
}

/// A triangle in the plane through `x` with unit normal `n`, around x, of size `size`,
/// counter-clockwise about n.
fn triangle_in_plane(rng: &mut Xorshift64Star, x: DVec3, n: DVec3, size: f64, sliver: Option<f64>) -> [DVec3; 3] {
    let t = n.any_orthonormal_vector();
    let b = n.cross(t);
    let mut corners = [DVec3::ZERO; 3];
    for (k, c) in corners.iter_mut().enumerate() {
        let angle = std::f64::consts::TAU * (k as f64 + 0.8 * rng.next_f64()) / 3.0;
        *c = x
            + size * (0.3 + rng.next_f64()) * (angle.cos() * t + angle.sin() * b)
            + 0.2 * size * (rng.next_f64() - 0.5) * t;
    }
    if let Some(aspect) = sliver {
        // Squash across the first edge: height = aspect x base.
        let e = (corners[1] - corners[0]).normalize();
        let across = n.cross(e);
        let h = (corners[2] - corners[0]).dot(across);
        corners[2] += across * (aspect * (corners[1] - corners[0]).length() - h);
    }
    let normal = (corners[1] - corners[0]).cross(corners[2] - corners[0]);
    if normal.dot(n) < 0.0 {
        corners.swap(1, 2);
    }
    corners
}

/// `count` configurations of `family` (reproducible from `seed`).
pub fn generate(family: Family, count: usize, seed: u64) -> Vec<Config> {
    let mut rng = Xorshift64Star(seed.wrapping_mul(0x9E3779B97F4A7C15) | 1);
    let mut out = Vec::with_capacity(count);
    while out.len() < count {
        let s = rng.next_dvec3();
        let c = rng.next_dvec3();
        let d = s.distance(c);
        if d < 0.05 {
            continue;
        }
        let ratio = match family {
            Family::NearDegenerate(e) => 1.0 + e,
            _ => 1.01 + 2.0 * rng.next_f64(),
        };
        let sp = Spheroid { focus_s: s, focus_c: c, length: d * ratio };
        let x = surface_point(&sp, rng.unit());
        let grad = ((x - s).normalize() + (x - c).normalize()).normalize();
        let size = sp.a() * rng.log_uniform(0.01, 1.0);
        let (point, n, sliver) = match family {
            Family::NearTangent => {
                let inward = sp.a() * rng.log_uniform(1e-8, 1e-2);
                (x - inward * grad, grad, None)
            }
            Family::PlaneThroughFocus => (x, (x - s).cross(rng.unit()).normalize(), None),
            Family::FociOnPlane => (x, (c - s).cross(x - s).normalize(), None),
            Family::Sliver => (x, rng.unit(), Some(rng.log_uniform(1e-6, 1e-2))),
            _ => (x, rng.unit(), None),
        };
        if !n.is_finite() {
            continue;
        }
        let mut tri = triangle_in_plane(&mut rng, point, n, size, sliver);
        let (mut s32, mut c32, mut tau) = (s, c, sp.length);
        if let Family::Scaled(k) = family {
            tri = tri.map(|v| v * k);
            s32 *= k;
            c32 *= k;
            tau *= k;
        }
        out.push(Config {
            focus_s: s32.as_vec3(),
            focus_c: c32.as_vec3(),
            tau_e: tau as f32,
            triangle: tri.map(|v| v.as_vec3()),
            u: rng.next_f64() as f32,
        });
    }
    out
}

/// What the device returned for one configuration.
#[derive(Clone, Copy, Debug)]
pub struct DeviceResult {
    /// Whether the plane cuts the spheroid.
    pub valid: bool,
    /// Total angle of the arcs inside the triangle (radians).
    pub theta_total: f32,
    /// The sampled eccentric angle (radians).
    pub theta: f32,
    /// J at theta (m).
    pub jacobian: f32,
    /// The point at theta (m).
    pub point: Vec3,
}

/// Runs `probe_ellipsoid` on the device for every configuration.
pub fn run_on_device(ctx: &GpuContext, configs: &[Config]) -> Result<Vec<DeviceResult>> {
    let kernel = Kernel::new(ctx, "probe_ellipsoid", None, &[]);
    let mut results = Vec::with_capacity(configs.len());
    for chunk in configs.chunks(1 << 18) {
        let input: Vec<[f32; 4]> = chunk
            .iter()
            .flat_map(|c| {
                let [v0, v1, v2] = c.triangle;
                let (e1, e2) = (v1 - v0, v2 - v0);
                [
                    [c.focus_s.x, c.focus_s.y, c.focus_s.z, c.tau_e],
                    [c.focus_c.x, c.focus_c.y, c.focus_c.z, c.u],
                    [v0.x, v0.y, v0.z, 0.0],
                    [e1.x, e1.y, e1.z, 0.0],
                    [e2.x, e2.y, e2.z, 0.0],
                ]
            })
            .collect();
        let mut r = Resources::default();
        r.storage_init(ctx, "probe_input", &input)?;
        r.storage_zeroed(ctx, "probe_output", 32 * chunk.len() as u64, wgpu::BufferUsages::empty())?;
        let bind_group = kernel.bind(ctx, &r);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            kernel.dispatch(&mut pass, &bind_group, chunk.len() as u32);
        }
        ctx.queue.submit([encoder.finish()]);
        let out: Vec<[f32; 4]> = read_buffer(ctx, r.get("probe_output").unwrap(), 2 * chunk.len())?;
        results.extend(out.chunks(2).map(|o| DeviceResult {
            valid: o[1][3] == 1.0,
            theta_total: o[0][0],
            theta: o[0][3],
            jacobian: o[0][2],
            point: Vec3::new(o[1][0], o[1][1], o[1][2]),
        }));
    }
    Ok(results)
}

/// Error distribution of one quantity (sorted samples).
#[derive(Clone, Debug, Default)]
pub struct Distribution(pub Vec<f64>);

impl Distribution {
    /// The q-quantile (0..=1); 0 when empty.
    pub fn quantile(&self, q: f64) -> f64 {
        if self.0.is_empty() {
            return 0.0;
        }
        let i = ((self.0.len() - 1) as f64 * q).round() as usize;
        self.0[i]
    }

    fn sorted(mut v: Vec<f64>) -> Self {
        v.sort_by(f64::total_cmp);
        Self(v)
    }
}

/// The comparison of one family's device results with the oracle.
#[derive(Clone, Debug, Default)]
pub struct Report {
    /// Family name.
    pub family: String,
    /// Configurations run.
    pub configs: usize,
    /// Configurations the oracle finds cut (g > 0 in f64).
    pub cut: usize,
    /// Cut by the oracle but not by the device, or the other way round.
    pub validity_mismatches: usize,
    /// Device outputs that were NaN or infinite.
    pub non_finite: usize,
    /// |Theta_device - Theta_oracle| (radians).
    pub theta_total_error: Distribution,
    /// |L(x_device) - tau_e| / tau_e.
    pub length_error: Distribution,
    /// |J_device - J_oracle(theta_device)| / J_oracle.
    pub jacobian_error: Distribution,
    /// Sampled points whose f64 path length errs by more than 1e-5 tau_e (what a renderer's
    /// guard would reject), as a fraction of the cut configurations with arcs.
    pub rejected_by_length_guard: f64,
}

/// Compares device results with the f64 oracle evaluated on the same (f32) inputs.
pub fn compare(family: &str, configs: &[Config], device: &[DeviceResult]) -> Report {
    let mut report = Report { family: family.into(), configs: configs.len(), ..Default::default() };
    let (mut theta_err, mut len_err, mut jac_err) = (Vec::new(), Vec::new(), Vec::new());
    let mut with_arcs = 0usize;
    let mut guarded = 0usize;
    for (c, d) in configs.iter().zip(device) {
        let finite = d.theta_total.is_finite() && d.theta.is_finite() && d.jacobian.is_finite() && d.point.is_finite();
        if !finite {
            report.non_finite += 1;
            continue;
        }
        let sp = Spheroid { focus_s: c.focus_s.as_dvec3(), focus_c: c.focus_c.as_dvec3(), length: c.tau_e as f64 };
        let tri = c.device_triangle();
        let v0 = tri.vertices[0];
        let n = tri.normal();
        let section = sp.section(v0, n);
        if section.is_some() {
            report.cut += 1;
        }
        if section.is_some() != d.valid {
            report.validity_mismatches += 1;
        }
        let (Some(sec), true) = (section, d.valid) else { continue };
        let arcs = clip_arcs(&sec, &tri);
        theta_err.push((d.theta_total as f64 - arcs.total).abs());
        if d.theta_total > 0.0 {
            with_arcs += 1;
            let l = sp.path_length(d.point.as_dvec3());
            let rel = (l - sp.length).abs() / sp.length;
            len_err.push(rel);
            guarded += (rel > 1e-5) as usize;
            let j = sec.jacobian(d.theta as f64);
            jac_err.push((d.jacobian as f64 - j).abs() / j.abs().max(1e-300));
        }
    }
    report.theta_total_error = Distribution::sorted(theta_err);
    report.length_error = Distribution::sorted(len_err);
    report.jacobian_error = Distribution::sorted(jac_err);
    report.rejected_by_length_guard = guarded as f64 / with_arcs.max(1) as f64;
    report
}

impl Report {
    /// One table row: family, counts, median / p99 / max of each error.
    pub fn row(&self) -> String {
        let q = |d: &Distribution| format!("{:.1e} {:.1e} {:.1e}", d.quantile(0.5), d.quantile(0.99), d.quantile(1.0));
        format!(
            "{:<24} {:>8} {:>8} {:>6} {:>4} | {} | {} | {} | {:.1e}",
            self.family,
            self.configs,
            self.cut,
            self.validity_mismatches,
            self.non_finite,
            q(&self.theta_total_error),
            q(&self.length_error),
            q(&self.jacobian_error),
            self.rejected_by_length_guard
        )
    }

    /// The header of [`Report::row`].
    pub fn header() -> String {
        format!(
            "{:<24} {:>8} {:>8} {:>6} {:>4} | {:<25} | {:<25} | {:<25} | {}",
            "family",
            "configs",
            "cut",
            "diff",
            "NaN",
            "Theta abs err (p50 p99 max)",
            "|L-tau|/tau (p50 p99 max)",
            "J rel err (p50 p99 max)",
            "guard"
        )
    }
}
