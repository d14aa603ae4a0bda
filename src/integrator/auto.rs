//! `--method auto`: a short pilot of `direct` and `ellipsoidal` on the render's own scene, gate
//! and image, then the whole budget on the one whose measured variance x time per sample is
//! lower. The pilot's films are discarded, so the render is an unbiased estimate of the chosen
//! method whatever the pilot saw (choosing from samples that are then kept would bias it).
//!
//! Why a pilot and not a rule of gate width: where one method wins depends on the gate's width
//! against the scene's size, on where the gate sits in the scene's path lengths, on the
//! geometry the ellipsoid queries cross (their cost) and on the image; a measurement on the
//! render itself sees all of it. The pilot costs [`PILOT_SHARE`] of a time budget.
//!
//! Estimating the variances: each method renders a few independent batches, whose spread gives
//! its variance per sample, value by value (pixel, bin, channel). A narrow gate makes that
//! spread blind where it matters most: a `direct` pilot that found none of a gate's rare paths
//! has zero spread, though its true variance is huge, and per pixel the other pilot is often
//! too sparse to show it (a pixel where one batch of 8 holds all of `ellipsoidal`'s light
//! differs from a zero by just what that one batch's spread predicts). Summed over the image,
//! the evidence is plain. Per group of values (one bin and channel, summed over the pixels),
//! where the two pilots' means differ by more than [`MISS_FACTOR`] times the squared difference
//! the groups' batch spreads predict, the excess is charged to the method whose mean is smaller
//! in magnitude (an estimator that misses rare large values falls short of the truth far more
//! often than it overshoots): N times the excess is the per-sample variance of the group's sum
//! that a mean of N samples that far off implies, and it is added to that method's variance.
//! A pilot that found no light at all where the other found plenty scores M times the missed
//! light's square, M the values the light spreads over, which is the order of its true
//! variance (zero hits in N x M tries bound its hit rate by about 1 / (N M)).

use std::time::Instant;

use anyhow::{Result, ensure};

use super::{Budget, Integrator, Method, RenderSettings, create_integrator};
use crate::film::Gate;
use crate::gpu::GpuContext;
use crate::scene::PreparedScene;

/// Share of a time budget the pilot spends (both methods together; dimensionless). The render
/// keeps the rest, so at worst its MSE is 1 / (1 - PILOT_SHARE) that of the better method.
pub const PILOT_SHARE: f64 = 0.05;

/// Batches per method in the pilot: the variance estimate needs at least two, and more
/// batches cost more film readbacks.
pub const PILOT_BATCHES: u32 = 8;

/// With a sample budget of N samples per pixel, each method's pilot batches take N /
/// SAMPLE_BUDGET_DIVISOR samples per pixel in all (at least one per batch).
pub const SAMPLE_BUDGET_DIVISOR: u64 = 16;

/// What the pilot measured of one method.
#[derive(Clone, Debug, PartialEq)]
pub struct CandidateFigures {
    /// The method.
    pub method: Method,
    /// Samples per pixel the pilot traced with it (all batches).
    pub spp: u64,
    /// Seconds its pilot passes took (film clears and readbacks not counted).
    pub seconds: f64,
    /// Estimated variance of one sample per pixel, summed over the image's values and divided by
    /// their number (radiance squared; the MSE of a 1-spp image).
    pub variance_per_sample: f64,
}

impl CandidateFigures {
    /// Seconds per sample per pixel.
    pub fn seconds_per_sample(&self) -> f64 {
        self.seconds / self.spp.max(1) as f64
    }

    /// Variance x time per sample: the MSE of an image rendered for one second (radiance
    /// squared x seconds). Lower is better.
    pub fn cost(&self) -> f64 {
        self.variance_per_sample * self.seconds_per_sample()
    }
}

/// What `auto` chose and why.
#[derive(Clone, Debug, PartialEq)]
pub struct MethodChoice {
    /// The method that rendered the image.
    pub chosen: Method,
    /// The pilot's figures of each method measured (empty when only one method applied).
    pub candidates: Vec<CandidateFigures>,
    /// Why, in words (for logs and metadata).
    pub reason: String,
    /// Seconds the pilot took: passes, film clears and readbacks (counted in a time budget).
    pub pilot_seconds: f64,
}

/// `settings` with `method`, and the connections per query it takes (1 for `direct`; the auto
/// settings' own K for `ellipsoidal`).
pub fn candidate_settings(settings: &RenderSettings, method: Method) -> RenderSettings {
    let connections_per_query = if method == Method::Ellipsoidal { settings.connections_per_query } else { 1 };
    RenderSettings { method, connections_per_query, ..settings.clone() }
}

/// Why `ellipsoidal` cannot render `settings` on `scene`, if it cannot (then `auto` takes
/// `direct` without a pilot).
fn ellipsoidal_unavailable(scene: &PreparedScene, settings: &RenderSettings) -> Option<&'static str> {
    if matches!(settings.gate, Gate::None) {
        Some("ellipsoidal connections need a gate; the steady state has none")
    } else if !scene.scene.directional_lights.is_empty() {
        Some("ellipsoidal connections do not support directional lights")
    } else {
        None
    }
}

/// Runs the pilot of `settings` (method `auto`) and returns the chosen method's integrator,
/// warmed up, its film cleared and its random sequence past the pilot's, with the choice.
/// With a time budget the pilot spends about [`PILOT_SHARE`] of it.
pub fn choose<'a>(
    ctx: &'a GpuContext,
    scene: &PreparedScene,
    settings: &RenderSettings,
    budget: Budget,
) -> Result<(Box<dyn Integrator + 'a>, MethodChoice)> {
    ensure!(settings.method == Method::Auto, "auto::choose needs --method auto, got {}", settings.method.name());
    ensure!(settings.nlos.is_none(), "--method auto does not apply to NLOS captures: choose path, direct or ellipsoidal");
    if let Some(why) = ellipsoidal_unavailable(scene, settings) {
        let mut tracer = create_integrator(ctx, scene, &candidate_settings(settings, Method::Direct))?;
        tracer.warm_up()?;
        let choice = MethodChoice { chosen: Method::Direct, candidates: vec![], reason: why.into(), pilot_seconds: 0.0 };
        return Ok((tracer, choice));
    }
    let per_method = match budget {
        Budget::Time(t) => PilotBudget::Seconds(t.as_secs_f64() * PILOT_SHARE / 2.0),
        Budget::Samples(n) => {
            PilotBudget::Samples((n / SAMPLE_BUDGET_DIVISOR / PILOT_BATCHES as u64).max(1) as u32)
        }
    };
    let mut pilots = Vec::new();
    for method in [Method::Direct, Method::Ellipsoidal] {
        let mut tracer = create_integrator(ctx, scene, &candidate_settings(settings, method))?;
        tracer.warm_up()?;
        let batches = pilot_batches(tracer.as_mut(), per_method)?;
        tracer.reset_film();
        pilots.push((method, tracer, batches));
    }
    let (b, e) = (&pilots[0].2, &pilots[1].2);
    let (v_direct, v_ellipsoidal) = per_sample_variances(b, e);
    let candidates: Vec<CandidateFigures> = [(b, v_direct, Method::Direct), (e, v_ellipsoidal, Method::Ellipsoidal)]
        .into_iter()
        .map(|(p, v, method)| CandidateFigures {
            method,
            spp: p.samples,
            seconds: p.seconds,
            variance_per_sample: v,
        })
        .collect();
    let (d, el) = (&candidates[0], &candidates[1]);
    // Ties (both zero: nothing reaches the gate in the pilot) go to the faster method.
    let pick_ellipsoidal = if d.cost() == el.cost() {
        el.seconds_per_sample() < d.seconds_per_sample()
    } else {
        el.cost() < d.cost()
    };
    let chosen = if pick_ellipsoidal { Method::Ellipsoidal } else { Method::Direct };
    let ratio = if pick_ellipsoidal { d.cost() / el.cost() } else { el.cost() / d.cost() };
    let reason = format!(
        "pilot: variance x time per sample {:.3e} (direct) vs {:.3e} (ellipsoidal); {} predicted {:.3}x lower MSE at \
         equal time",
        d.cost(),
        el.cost(),
        chosen.name(),
        ratio
    );
    let pilot_seconds = b.wall_seconds + e.wall_seconds;
    let tracer = pilots.into_iter().find(|p| p.0 == chosen).map(|p| p.1).expect("the chosen method was piloted");
    Ok((tracer, MethodChoice { chosen, candidates, reason, pilot_seconds }))
}

/// How much pilot each method gets.
#[derive(Clone, Copy, Debug)]
enum PilotBudget {
    /// Seconds of passes (at least [`PILOT_BATCHES`] passes of one sample).
    Seconds(f64),
    /// Samples per pixel of each batch.
    Samples(u32),
}

/// Sums over one method's pilot batches (k_j: samples per pixel of batch j) of the batches'
/// estimates (x), weighted by k_j: sum k_j x and sum k_j x^2, for the values and for the
/// groups' sums over pixels.
#[derive(Default)]
struct Moments {
    weighted_sum: Vec<f64>,
    weighted_squares: Vec<f64>,
}

impl Moments {
    fn add(&mut self, k: f64, values: impl ExactSizeIterator<Item = f64>) {
        if self.weighted_sum.is_empty() {
            self.weighted_sum = vec![0.0; values.len()];
            self.weighted_squares = vec![0.0; values.len()];
        }
        for ((s, q), x) in self.weighted_sum.iter_mut().zip(&mut self.weighted_squares).zip(values) {
            *s += k * x;
            *q += k * x * x;
        }
    }

    /// Element i's mean and variance per sample, sum_j k_j (x_j - mean)^2 / (n - 1), which is
    /// unbiased for batches of any sizes (n batches, N samples).
    fn get(&self, i: usize, n: u32, samples: u64) -> (f64, f64) {
        let total = samples as f64;
        let mean = self.weighted_sum[i] / total;
        let spread = (self.weighted_squares[i] - total * mean * mean).max(0.0);
        (mean, spread / (n as f64 - 1.0))
    }
}

/// What one method's pilot batches leave.
#[derive(Default)]
struct Batches {
    /// Batches rendered (n).
    count: u32,
    /// Samples per pixel in all (N = sum_j k_j).
    samples: u64,
    /// Seconds of their passes (what the sample rate is measured by).
    seconds: f64,
    /// Seconds of the whole batches: passes, film clears and readbacks (the pilot's cost).
    wall_seconds: f64,
    /// Of every value (pixel, bin, channel).
    values: Moments,
    /// Of every group's sum over the pixels (one group per bin and channel).
    groups: Moments,
}

impl Batches {
    /// Adds a batch of `k` samples per pixel whose estimate is `image`, `per_pixel` values a
    /// pixel (bins x channels).
    fn add(&mut self, k: u32, image: &[f64], per_pixel: usize) {
        let mut sums = vec![0.0; per_pixel];
        for (i, x) in image.iter().enumerate() {
            sums[i % per_pixel] += x;
        }
        self.values.add(k as f64, image.iter().copied());
        self.groups.add(k as f64, sums.into_iter());
        self.samples += k as u64;
        self.count += 1;
    }
}

/// A group's means differ beyond noise where their squared difference exceeds MISS_FACTOR times
/// its expectation under fair sampling (|t| > 3.2: with variances from 8 batches, Student's t
/// of 7 degrees of freedom passes it with probability 1.6 %).
pub const MISS_FACTOR: f64 = 10.0;

/// Renders [`PILOT_BATCHES`] independent batches on `tracer` within `budget`.
fn pilot_batches(tracer: &mut dyn Integrator, budget: PilotBudget) -> Result<Batches> {
    let mut batches = Batches::default();
    while batches.count < PILOT_BATCHES {
        let k = match budget {
            PilotBudget::Samples(k) => k,
            // First one sample, then what spreads the time left over the batches left.
            PilotBudget::Seconds(_) if batches.count == 0 => 1,
            PilotBudget::Seconds(total) => {
                let per_sample = batches.seconds / batches.samples as f64;
                let left = (total - batches.wall_seconds).max(0.0) / (PILOT_BATCHES - batches.count) as f64;
                ((left / per_sample.max(1e-12)) as u32).clamp(1, tracer.samples_per_pass())
            }
        };
        let start = Instant::now();
        tracer.reset_film();
        let pass = Instant::now();
        tracer.render_pass(k)?;
        batches.seconds += pass.elapsed().as_secs_f64();
        let film = tracer.film()?;
        let image: Vec<f64> = film.data.iter().map(|&x| x as f64).collect();
        batches.add(k, &image, film.data.len() / (film.width as usize * film.height as usize).max(1));
        batches.wall_seconds += start.elapsed().as_secs_f64();
    }
    Ok(batches)
}

/// The per-sample variances of two methods' pilots, averaged over the image's values: each
/// one's batch spread, plus the excesses of groups whose means differ beyond noise, charged to
/// the method whose mean is the smaller (the module's header).
fn per_sample_variances(a: &Batches, b: &Batches) -> (f64, f64) {
    let values = a.values.weighted_sum.len();
    let own = |m: &Batches| (0..values).map(|i| m.values.get(i, m.count, m.samples).1).sum::<f64>();
    let (mut v_a, mut v_b) = (own(a), own(b));
    for g in 0..a.groups.weighted_sum.len() {
        let (mean_a, var_a) = a.groups.get(g, a.count, a.samples);
        let (mean_b, var_b) = b.groups.get(g, b.count, b.samples);
        let expected = var_a / a.samples as f64 + var_b / b.samples as f64;
        let difference = (mean_a - mean_b).powi(2);
        if difference > MISS_FACTOR * expected {
            if mean_a.abs() < mean_b.abs() {
                v_a += a.samples as f64 * (difference - expected);
            } else {
                v_b += b.samples as f64 * (difference - expected);
            }
        }
    }
    (v_a / values.max(1) as f64, v_b / values.max(1) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Batches of given images, each of `k` samples.
    fn batches(images: &[Vec<f64>], k: u32) -> Batches {
        let mut b = Batches::default();
        for image in images {
            b.add(k, image, 1);
        }
        b
    }

    /// Normal deviates from a small LCG (Box-Muller), so the test needs no crate.
    fn normals(seed: &mut u64, n: usize) -> Vec<f64> {
        let mut uniform = || {
            *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((*seed >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        (0..n).map(|_| (-2.0 * uniform().ln()).sqrt() * (std::f64::consts::TAU * uniform()).cos()).collect()
    }

    #[test]
    fn recovers_known_variances() {
        // Two unbiased estimators of the same 4096-value image, per-sample standard deviations
        // 1 and 3, batches of 2 and 5 samples: the estimates are within a few standard errors.
        let values = 4096;
        let mut seed = 7;
        let truth: Vec<f64> = (0..values).map(|i| (i % 17) as f64).collect();
        let image = |sigma: f64, k: u32, seed: &mut u64| -> Vec<f64> {
            let noise = normals(seed, values);
            truth.iter().zip(noise).map(|(t, z)| t + sigma / (k as f64).sqrt() * z).collect()
        };
        let a: Vec<_> = (0..8).map(|_| image(1.0, 2, &mut seed)).collect();
        let b: Vec<_> = (0..8).map(|_| image(3.0, 5, &mut seed)).collect();
        let (va, vb) = per_sample_variances(&batches(&a, 2), &batches(&b, 5));
        // Each estimate pools about 8 x 4096 squared deviations: relative error ~ 1/sqrt(16384).
        assert!((va - 1.0).abs() < 0.1, "variance of A: {va}, expected 1");
        assert!((vb - 9.0).abs() < 0.9, "variance of B: {vb}, expected 9");
    }

    #[test]
    fn sees_what_a_batch_missed() {
        // A rare-event estimator that found nothing in its pilot (all zeros, no spread) against
        // one that sees the image: its variance is at least the missed signal's square.
        let values = 256;
        let mut seed = 3;
        let seen: Vec<_> = (0..8)
            .map(|_| normals(&mut seed, values).into_iter().map(|z| 1.0 + 0.1 * z).collect::<Vec<_>>())
            .collect();
        let missed = vec![vec![0.0; values]; 8];
        let (v_missed, v_seen) = per_sample_variances(&batches(&missed, 1), &batches(&seen, 1));
        // Missing a sum of 256 in 8 samples implies a per-sample variance of the sum of 8 x
        // 256^2, or 8 x 256 per value.
        assert!((v_missed / 2048.0 - 1.0).abs() < 0.01, "the empty pilot's variance per sample: {v_missed}");
        assert!((v_seen - 0.01).abs() < 0.002, "the other pilot's: {v_seen}");
    }

    #[test]
    fn sees_a_miss_behind_noisy_values() {
        // The method that sees the image is itself noisy (per-sample standard deviation equal to
        // the mean, so no single value's difference stands out after 8 samples), but the
        // image's sum shows what the empty pilot missed.
        let values = 4096;
        let mut seed = 5;
        let seen: Vec<_> = (0..8)
            .map(|_| normals(&mut seed, values).into_iter().map(|z| 1.0 + z).collect::<Vec<_>>())
            .collect();
        let missed = vec![vec![0.0; values]; 8];
        let (v_missed, v_seen) = per_sample_variances(&batches(&missed, 1), &batches(&seen, 1));
        assert!((v_missed / (8.0 * 4096.0) - 1.0).abs() < 0.05, "the empty pilot's variance per sample: {v_missed}");
        assert!((v_seen - 1.0).abs() < 0.1, "the other pilot's: {v_seen}");
    }
}
