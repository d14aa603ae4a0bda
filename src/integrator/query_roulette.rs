//! The query roulette of `ellipsoidal`: each ellipsoid query for a path of two or more
//! scattering vertices (light-subpath vertex s and camera-subpath vertex t with s + t > 2) is
//! made with probability p and then weighs 1 / p (`RenderParams::query_roulette`,
//! shaders/lib/ellipsoid_query.wesl `query_made`, each pair's decision independent); the queries of one-bounce paths always are.
//! The image's expectation is the same for any p in (0, 1]. Where one-bounce light fills the
//! gate (the fence at 1 ns, 96 % of it), the other queries take most of a sample's time for
//! little of its light, and a smaller p buys more samples; where multi-bounce light matters (a
//! narrow gate in the Cornell box) it adds their variance instead.
//!
//! With a time budget a pilot chooses p. Per sample, the variance and the time are
//!
//!     V(p) = A + B / p,    C(p) = D + E p,
//!
//! the variance exactly (B is the sum of the rouletted queries' contributions' second moments,
//! A holds everything else, their covariances with the rest included, which do not depend on
//! p), the time as far as it follows the queries made (E their time at p = 1). The pilot measures
//! both at p = 1 and at p = [`TRIAL`] (on `auto`'s smaller image, from its own seed, films
//! discarded), solves for A, B, D and E, and takes the p that minimises V(p) C(p), the error at
//! equal time: p = sqrt(B D / (A E)), clamped to [`TRIAL`] ..= 1 (it never extrapolates below
//! what it measured).
//!
//! Both probabilities trace the same samples (one seed, batches of the same sizes), and a
//! query's decision is drawn apart from everything else a sample draws, so a sample at TRIAL is
//! the sample at 1 plus D = sum over its rouletted queries of Q (I / TRIAL - 1), which has mean
//! zero whatever the rest drew: V(TRIAL) = V(1) + E[D^2], E[D^2] = B (1 / TRIAL - 1). The
//! squared differences of the paired batches measure E[D^2] alone, and the differences of their
//! passes' times E ([`PairedBatches`]). Measured apart, as the difference of the two pilots' own
//! variances, B carried the noise of A twice: on the fence at 1 ns it came out negative in most
//! pilots, which then took every query, at about 1.7 times the error of TRIAL. Where no
//! rouletted query added light in the pilot (B = 0) it takes every query.
//!
//! With a sample budget (`--spp`, shards, checkpoints), a sample stays what it was: every query
//! is made, unless `--query-roulette` says otherwise.

use std::fmt::Write as _;

use anyhow::{Result, ensure};

use super::auto::{
    EARLY_STOP_BATCHES, PILOT_BATCHES, PILOT_MIN_PIXELS, pilot_budget, pilot_resolution, pilot_settings,
};
use super::pilot::{Batches, PilotBudget, pilot_batch};
use super::{Budget, Method, RenderSettings, create_integrator};
use crate::gpu::GpuContext;
use crate::scene::PreparedScene;

/// The least probability `--query-roulette` takes is 1 / MAX_SKIP (dimensionless).
pub const MAX_SKIP: f32 = 16.0;

/// The pilot's second probability, and the least it chooses (dimensionless): far enough below 1
/// that the multi-bounce queries' variance, B / p, stands out of the pilot's noise where it
/// matters.
pub const TRIAL: f32 = 0.125;

/// After `auto::EARLY_STOP_BATCHES` batches at each probability the pilot stops where the model's
/// optimum lies at least this factor above 1 (every query; a wrong stop there costs nothing but
/// the roulette's gain) ...
pub const EARLY_STOP_ALL: f64 = 1.5;

/// ... or this factor below [`TRIAL`] (a wrong stop there adds the multi-bounce queries'
/// variance, so only a clear case stops).
pub const EARLY_STOP_LEAST: f64 = 4.0;

/// The query roulette's probability of a render, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Choice {
    /// The probability with which a sample makes each multi-bounce query (dimensionless).
    pub probability: f32,
    /// Why, in words (for logs and metadata).
    pub reason: String,
    /// Seconds the pilot took: passes, film clears and readbacks (counted in a time budget).
    pub pilot_seconds: f64,
}

/// The probability that minimises the variance x time per sample of the model V(p) = A + B / p,
/// C(p) = D + E p fitted to a pilot's variance per sample v (radiance squared) and seconds per
/// sample c at p = 1 and at p = `trial`: sqrt(B D / (A E)), clamped to `trial` ..= 1. D <= 0
/// (the rouletted queries are all the time) gives `trial`; A <= 0 or E <= 0 (nothing else
/// varies, or they cost nothing) give 1, and so does B <= 0 (with [`PairedBatches`], B = 0:
/// no rouletted query added light in the pilot, which is no evidence that they never do).
pub fn probability(v_all: f64, c_all: f64, v_trial: f64, c_trial: f64, trial: f64) -> f32 {
    optimum(v_all, c_all, v_trial, c_trial, trial).clamp(trial, 1.0) as f32
}

/// [`probability`] before its clamp: infinite where A, B or E <= 0, 0 where D <= 0.
fn optimum(v_all: f64, c_all: f64, v_trial: f64, c_trial: f64, trial: f64) -> f64 {
    let b = (v_trial - v_all) / (1.0 / trial - 1.0);
    let a = v_all - b;
    let e = (c_all - c_trial) / (1.0 - trial);
    let d = c_all - e;
    if !(a > 0.0) || !(b > 0.0) || !(e > 0.0) {
        f64::INFINITY
    } else if !(d > 0.0) {
        0.0
    } else {
        (b * d / (a * e)).sqrt()
    }
}

/// What the pilot's pairs of batches of the same samples at p = 1 and at p = `TRIAL` measure
/// beside each probability's own batches (the module's header): a sample at TRIAL is the sample
/// at 1 plus D = sum over its rouletted queries of Q (I / TRIAL - 1), which has mean zero
/// whatever the rest of the sample drew.
#[derive(Default)]
pub struct PairedBatches {
    /// Per pair, k |x_TRIAL - x_1|^2 summed over the values (k samples per pixel in each batch),
    /// whose expectation is E[D^2] summed over the values (radiance squared).
    squares: Vec<f64>,
    /// Seconds of the passes at 1 less those of the passes at TRIAL, summed over the pairs.
    seconds_saved: f64,
    /// Samples per pixel of each probability's batches in all.
    samples: u64,
}

impl PairedBatches {
    /// Adds a pair of batches of `k` samples per pixel, estimates `all` (p = 1) and `trial`,
    /// whose passes took `seconds_all` and `seconds_trial`.
    pub fn add(&mut self, k: u32, all: &[f64], trial: &[f64], seconds_all: f64, seconds_trial: f64) {
        let squares: f64 = all.iter().zip(trial).map(|(a, t)| (t - a) * (t - a)).sum();
        self.squares.push(k as f64 * squares);
        self.seconds_saved += seconds_all - seconds_trial;
        self.samples += k as u64;
    }

    /// The variance per sample at TRIAL (radiance squared, summed over the values) from the one
    /// at 1, `v_all`: V(TRIAL) = V(1) + E[D^2], E[D^2] the mean of the pairs' squares without the
    /// largest where there are three or more. A rouletted query of rare and large weight (8
    /// times its contribution where kept) shows in one pair as a square many times the others;
    /// left in, one such pair in a pilot of 8 decided for every query on the fence at 1 ns,
    /// where the renders at p = 1/8 had 0.6 times the error of those at 1 (one firefly does not
    /// decide, as `auto`'s medians of pairs have it; one in every pair or two still does).
    pub fn trial_variance(&self, v_all: f64) -> f64 {
        let mut squares = self.squares.clone();
        squares.sort_by(f64::total_cmp);
        if squares.len() >= 3 {
            squares.pop();
        }
        v_all + squares.iter().sum::<f64>() / squares.len().max(1) as f64
    }

    /// The seconds per sample at TRIAL from those at 1, `c_all`: less the seconds the pairs'
    /// passes at TRIAL saved per sample. The pairs trace the same samples one after the other,
    /// with the same dispatches, so each pass's fixed cost and the host's drift cancel in the
    /// difference.
    pub fn trial_seconds_per_sample(&self, c_all: f64) -> f64 {
        c_all - self.seconds_saved / self.samples.max(1) as f64
    }
}

/// Does a render of `settings` make queries the roulette may skip? Paths of two or more
/// scattering vertices, outside NLOS captures (whose three-bounce queries are the signal).
pub fn has_multi_bounce_queries(settings: &RenderSettings) -> bool {
    settings.nlos.is_none() && settings.max_bounces >= 2
}

/// Does `settings` take `ellipsoidal`'s query roulette at all ([`has_multi_bounce_queries`];
/// `combined` chooses its own in `combined::allocate`)?
pub fn applies(settings: &RenderSettings) -> bool {
    settings.method == Method::Ellipsoidal && has_multi_bounce_queries(settings)
}

/// The query roulette of the `ellipsoidal` render `settings` with `budget`:
/// `settings.query_roulette` where given; 1 where it does not apply ([`applies`]) or with a
/// sample budget; otherwise the pilot of the module's header, which spends about
/// `auto::PILOT_SHARE` of the time.
pub fn choose(ctx: &GpuContext, scene: &PreparedScene, settings: &RenderSettings, budget: Budget) -> Result<Choice> {
    let given = |probability: f32, reason: &str| Choice { probability, reason: reason.into(), pilot_seconds: 0.0 };
    if let Some(p) = settings.query_roulette {
        return Ok(given(p, "as given"));
    }
    if !applies(settings) {
        return Ok(given(1.0, "every query (no multi-bounce queries to weigh)"));
    }
    if let Budget::Samples(_) = budget {
        return Ok(given(1.0, "every query (a sample budget)"));
    }
    let (width, height, _) = pilot_resolution(settings.width, settings.height, PILOT_MIN_PIXELS);
    let pixel_ratio = (settings.width as f64 * settings.height as f64) / (width as f64 * height as f64);
    let per_probability = pilot_budget(budget, pixel_ratio, 2);
    let pilot = |p: f32| RenderSettings { query_roulette: Some(p), ..pilot_settings(settings, width, height) };
    let mut all = create_integrator(ctx, scene, &pilot(1.0))?;
    let mut trial = create_integrator(ctx, scene, &pilot(TRIAL))?;
    all.warm_up()?;
    trial.warm_up()?;
    let (mut b_all, mut b_trial) = (Batches::default(), Batches::default());
    // Batch j at TRIAL traces the samples of batch j at 1 (same seed, same sizes).
    let mut pairs = PairedBatches::default();
    let figures = |a: &Batches, pairs: &PairedBatches| {
        // The mean seconds per sample at 1, each pass's fixed cost included: the two
        // probabilities' own fits over passes of one and two samples left that cost out but
        // scattered by a factor of ten, and a fit below the pairs' savings gave TRIAL a negative
        // time. The fixed cost counts in D alone (the savings leave it out of E), which moves the
        // choice towards every query.
        let (v_all, c_all) = (a.variance(), a.seconds / a.samples.max(1) as f64);
        (v_all, c_all, pairs.trial_variance(v_all), pairs.trial_seconds_per_sample(c_all))
    };
    let mut batches = 0;
    while batches < PILOT_BATCHES {
        let (before_all, before_trial) = (b_all.seconds, b_trial.seconds);
        pilot_batch(all.as_mut(), &mut b_all, per_probability, 1)?;
        let (k, x_all) = b_all.last();
        pilot_batch(trial.as_mut(), &mut b_trial, PilotBudget::Samples(k), 1)?;
        let (k_trial, x_trial) = b_trial.last();
        ensure!(k_trial == k, "the query roulette's pilot traced {k_trial} samples at {TRIAL} against {k} at 1");
        pairs.add(k, x_all, x_trial, b_all.seconds - before_all, b_trial.seconds - before_trial);
        batches += 1;
        if batches == EARLY_STOP_BATCHES {
            let (v_all, c_all, v_trial, c_trial) = figures(&b_all, &pairs);
            let p = optimum(v_all, c_all, v_trial, c_trial, TRIAL as f64);
            if p >= EARLY_STOP_ALL || p <= TRIAL as f64 / EARLY_STOP_LEAST {
                break;
            }
        }
    }
    let (v_all, c_all, v_trial, c_trial) = figures(&b_all, &pairs);
    let p = probability(v_all, c_all, v_trial, c_trial, TRIAL as f64);
    let mut reason =
        format!("pilot on {width}x{height}, {batches} batches each: variance per sample {v_all:.3e} with ");
    let _ = write!(
        reason,
        "every query and {v_trial:.3e} with {TRIAL} of the multi-bounce ones, seconds per sample {c_all:.3e} and \
         {c_trial:.3e}: probability {p:.3}"
    );
    Ok(Choice { probability: p, reason, pilot_seconds: b_all.wall_seconds + b_trial.wall_seconds })
}

/// Name of the checkpoint blob that holds a render's probability (f32 bits).
pub const STATE_BLOB: &str = "query_roulette";

/// The probability the render of `state` had (1 for states saved before the roulette existed).
pub fn saved(state: &super::checkpoint::RenderState) -> f32 {
    state.values::<u32>(STATE_BLOB, 1).map_or(1.0, |v| f32::from_bits(v[0]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Variance and time per sample of the model at p.
    fn model(a: f64, b: f64, d: f64, e: f64, p: f64) -> (f64, f64) {
        (a + b / p, d + e * p)
    }

    #[test]
    fn the_model_is_solved_exactly() {
        // Measurements from the model itself give back its optimum sqrt(B D / (A E)).
        for (a, b, d, e) in [(2.7, 0.03, 6.1e-3, 6.3e-3), (1.8, 0.36, 2.1e-3, 1.2e-3), (1.0, 1.0, 1.0, 0.01)] {
            let (v1, c1) = model(a, b, d, e, 1.0);
            let (vt, ct) = model(a, b, d, e, 0.125);
            let want = ((b * d / (a * e)).sqrt()).clamp(0.125, 1.0);
            let got = probability(v1, c1, vt, ct, 0.125) as f64;
            assert!((got - want).abs() < 1e-6 * want, "{got} against {want}");
            // It is the model's best: no probability on a grid does better at equal time.
            let cost = |p: f64| {
                let (v, c) = model(a, b, d, e, p);
                v * c
            };
            for k in 1..=64 {
                let p = k as f64 / 64.0;
                if p >= 0.125 {
                    assert!(cost(got) <= cost(p) * (1.0 + 1e-9), "p {p} beats {got}");
                }
            }
        }
    }

    #[test]
    fn degenerate_pilots_give_the_bounds() {
        // Less variance with fewer multi-bounce queries, which the model cannot give: every query.
        assert_eq!(probability(1.0, 2.0, 0.9, 1.0, 0.125), 1.0);
        // The multi-bounce queries are all the time: the least probability, the trial's.
        assert_eq!(probability(1.0, 2.0, 2.0, 0.1, 0.125), 0.125);
        // Multi-bounce queries that cost nothing: every query.
        assert_eq!(probability(1.0, 1.0, 3.0, 1.0, 0.125), 1.0);
        // All the variance in the multi-bounce queries: every query.
        assert_eq!(probability(1.0, 2.0, 8.0, 1.0, 0.125), 1.0);
        // A pilot that saw nothing at all.
        assert_eq!(probability(0.0, 1.0, 0.0, 0.5, 0.125), 1.0);
    }

    #[test]
    fn paired_batches_measure_the_rouletted_variance_and_time() {
        // Per value and sample, X_1 = Z + Q and X_TRIAL = Z + Q I / TRIAL from the same draws:
        // Z uniform on (-sqrt 3, sqrt 3) (variance 1), Q = 4 with probability 1/64, I a
        // Bernoulli(TRIAL). E[D^2] = E[Q^2] (1 / TRIAL - 1) = 0.25 x 7 per value.
        let (values, k) = (4096usize, 2u32);
        let mut seed = 11u64;
        let mut uniform = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let trial = TRIAL as f64;
        let mut pairs = PairedBatches::default();
        for j in 0..8 {
            let (mut all, mut rouletted) = (vec![0.0; values], vec![0.0; values]);
            for (a, t) in all.iter_mut().zip(&mut rouletted) {
                for _ in 0..k {
                    let z = (2.0 * uniform() - 1.0) * 3f64.sqrt();
                    let q = if uniform() < 1.0 / 64.0 { 4.0 } else { 0.0 };
                    let kept = uniform() < trial;
                    *a += (z + q) / k as f64;
                    *t += (z + if kept { q / trial } else { 0.0 }) / k as f64;
                }
            }
            // Passes of 5 ms plus 3 ms a sample at 1 and 1 ms a sample at TRIAL, with jitter.
            let jitter = 1e-3 * (j % 3) as f64;
            pairs.add(k, &all, &rouletted, 5e-3 + 3e-3 * k as f64 + jitter, 5e-3 + 1e-3 * k as f64 + jitter);
        }
        let v_all = values as f64 * (1.0 + 16.0 / 64.0 * (1.0 - 1.0 / 64.0));
        let measured = (pairs.trial_variance(v_all) - v_all) / values as f64;
        // About 900 hits of Q among the 7 pairs kept, each D^2 of 49 or 1 / 4: a few per cent of
        // standard error.
        assert!((measured / 1.75 - 1.0).abs() < 0.15, "E[D^2] per value {measured}, expected 1.75");
        let c_trial = pairs.trial_seconds_per_sample(3e-3);
        assert!((c_trial - 1e-3).abs() < 1e-12, "seconds per sample at TRIAL {c_trial}");

        // One pair of a huge square (a kept query of rare, large weight) does not decide.
        let mut firefly = PairedBatches::default();
        for square in [1.0, 1.2, 0.8, 1.1, 0.9, 1.0, 1000.0, 1.0] {
            firefly.add(1, &[0.0], &[f64::sqrt(square)], 0.0, 0.0);
        }
        assert!((firefly.trial_variance(2.0) - 3.0).abs() < 1e-9, "{}", firefly.trial_variance(2.0));
    }
}
