//! `--method auto`: a short pilot of `path`, `direct` and (with a gate) `ellipsoidal` on the
//! render's own scene, gate and image, then the whole budget on the one whose measured variance
//! x time per sample is lowest. The pilot's films are discarded and its random numbers are not
//! reused, so the render is an unbiased estimate of the chosen method whatever the pilot saw
//! (choosing from samples that are then kept would bias it).
//!
//! Why a pilot and not a rule of gate width: where one method wins depends on the gate's width
//! against the scene's size, on where the gate sits in the scene's path lengths, on the
//! geometry the ellipsoid queries cross (their cost) and on the image; a measurement on the
//! render itself sees all of it. One fact no pilot can measure is a rule: where a point or spot
//! light stands in a scattering medium `path` has infinite variance, and it is not a candidate
//! ([`candidate_methods`]). The pilot costs [`PILOT_SHARE`] of a time budget, and renders
//! the camera's image at a lower resolution ([`pilot_resolution`]) so that its floor of a few
//! one-sample batches stays small beside a short budget on a slow scene. It runs from a seed of
//! its own ([`pilot_seed`]); the render then starts afresh from the user's seed, so an `auto`
//! image is the chosen method's image with the same seed and budget.
//!
//! Estimating the variances: each method renders a few independent batches; the squared
//! differences of consecutive pairs of them, summed over the image's values (pixel, bin,
//! channel), give estimates of its variance per sample, and the median of the pairs' estimates
//! is taken (a firefly in one batch moves one pair's estimate, not the median), or their mean
//! where the median is zero (the light the method found came in rare batches: see
//! `pilot::Batches::variance`), and at least their mean for a pilot that found less light than
//! the reference below (`per_sample_variances`). A narrow gate makes that
//! spread blind where it matters most: a `direct` pilot that found none of a gate's rare paths
//! has zero spread, though its true variance is huge, and per pixel the other pilot is often
//! too sparse to show it (a pixel where one batch of 8 holds all of `ellipsoidal`'s light
//! differs from a zero by just what that one batch's spread predicts). Summed over the image,
//! the evidence is plain. The pilot whose groups' means (one group per bin and channel, summed
//! over the pixels) have the smallest relative variance is the reference; every other pilot is
//! compared with it. Per group, where the two pilots' means differ by more than [`MISS_FACTOR`]
//! times the squared difference the groups' batch spreads predict, the excess is charged to the
//! other method (the one that saw fewer of the paths that make its estimate, and whose spread
//! is the less trustworthy: an estimator of rare large values usually falls short of the truth
//! and now and then overshoots it, both by more than its spread says): N times the excess is
//! the per-sample variance of the group's sum that a mean of N samples that far off implies,
//! and it is added to that method's variance.
//! A pilot that found no light at all where the other found plenty scores M times the missed
//! light's square, M the values the light spreads over, which is the order of its true
//! variance (zero hits in N x M tries bound its hit rate by about 1 / (N M)).

use anyhow::{Result, ensure};

use super::bidirectional::resolve_camera_pilot;
use super::pilot::{Batches, CameraScalesOnce, PILOT_WAVE_BYTES, PilotBudget, per_sample_variances, pilot_batch};
use super::{Budget, Method, RenderSettings, create_integrator};
use crate::film::Gate;
use crate::gpu::GpuContext;
use crate::scene::PreparedScene;

/// Share of a time budget the pilot spends (both methods together; dimensionless). The render
/// keeps the rest, so at worst its MSE is 1 / (1 - PILOT_SHARE) that of the better method.
pub const PILOT_SHARE: f64 = 0.05;

/// Batches per method in the pilot: the variance estimate needs at least two, and more
/// batches cost more film readbacks.
pub const PILOT_BATCHES: u32 = 8;

/// After this many batches of each method the pilot stops where one method is predicted at
/// least [`EARLY_STOP_RATIO`] times ahead (the narrowest and the widest gates), halving its cost.
pub const EARLY_STOP_BATCHES: u32 = 4;

/// See [`EARLY_STOP_BATCHES`]: a margin far beyond what two pairs of batches mismeasure, so only
/// a clear choice stops early (a firefly in one method's batch can only stop it early for the
/// other method).
pub const EARLY_STOP_RATIO: f64 = 8.0;

/// With a sample budget of N samples per pixel, each method's pilot batches take in all the
/// work of N / SAMPLE_BUDGET_DIVISOR samples per pixel of the image (at least one sample per
/// pixel of the pilot's image per batch).
pub const SAMPLE_BUDGET_DIVISOR: u64 = 16;

/// The pilot's image keeps at least this many pixels (below, it is the render's own image).
pub const PILOT_MIN_PIXELS: u32 = 1024;

/// The image of a combined render's allocation pilot keeps at least this many pixels (16x16):
/// its runs (up to nine with a time budget) mostly render at their floor of batches, which then
/// costs about 1/16 of the full image's where `auto`'s 32x32 costs 1/4 of it (docs/methods.md,
/// "The gate-width sweep": on the fence at 1 m, 1.09 times `direct`'s error where 32x32 left
/// 1.36).
pub const ALLOCATION_MIN_PIXELS: u32 = 256;

/// The pilot's image is at most this many times smaller than the render's along each axis.
pub const PILOT_MAX_SHRINK: u32 = 4;

/// The pilot renders the same camera at a resolution shrunk by an integer factor f along each
/// axis, the largest f <= [`PILOT_MAX_SHRINK`] that divides both and leaves `min_pixels`
/// pixels ([`PILOT_MIN_PIXELS`] for `auto`; the image keeps its aspect exactly): its
/// floor of [`PILOT_BATCHES`] one-sample batches then costs about 1/f^2 of that at full size.
/// The variance of one sample of a pixel's estimate barely depends on the pixel's size (a
/// camera sample averages radiance over the pixel whatever its size; a light-tracing splat is
/// f^2 times smaller, lands f^2 times more often per light path, and the image has f^2 times
/// fewer light paths per sample), so per-sample variances mostly carry over (not where the
/// radiance varies within a pixel: on the glossy box `path`'s variance per sample is 17x
/// `direct`'s at 32x32 and 11x at 64x64, docs/methods.md, `auto`); times per sample are
/// scaled by the pixel count (`Batches::seconds_per_sample`). Returns (width, height, f).
pub fn pilot_resolution(width: u32, height: u32, min_pixels: u32) -> (u32, u32, u32) {
    let pixels = width as u64 * height as u64;
    let fits = |f: u32| {
        width.is_multiple_of(f) && height.is_multiple_of(f) && pixels / (f as u64 * f as u64) >= min_pixels as u64
    };
    let f = (1..=PILOT_MAX_SHRINK).rev().find(|&f| fits(f)).unwrap_or(1);
    (width / f, height / f, f)
}

/// The seed of the pilot's renders: a stream of its own, so the render that follows, from the
/// user's seed, is independent of what the pilot saw and equals `--method <chosen>` with that
/// seed.
pub fn pilot_seed(seed: u32) -> u32 {
    // One step of a 32-bit integer hash (lowbias32): nearby seeds give unrelated pilot seeds.
    let mut x = seed ^ 0x9e37_79b9;
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^ (x >> 16)
}

/// The settings of a pilot's renders of `settings` on a `width` x `height` image: its own seed
/// ([`pilot_seed`]) and waves of at most [`PILOT_WAVE_BYTES`].
pub fn pilot_settings(settings: &RenderSettings, width: u32, height: u32) -> RenderSettings {
    RenderSettings {
        width,
        height,
        seed: pilot_seed(settings.seed),
        wave_bytes: Some(PILOT_WAVE_BYTES),
        ..settings.clone()
    }
}

/// What the pilot measured of one method.
#[derive(Clone, Debug, PartialEq)]
pub struct CandidateFigures {
    /// The method.
    pub method: Method,
    /// Samples per pixel the pilot traced with it (all batches), on the pilot's image.
    pub spp: u64,
    /// Seconds its pilot passes took (film clears and readbacks not counted).
    pub seconds: f64,
    /// Seconds per sample per pixel of the pilot's image, without each pass's fixed cost (see
    /// `Batches::seconds_per_sample`).
    pub pilot_seconds_per_sample: f64,
    /// The render's pixels per pilot pixel (f^2 of [`pilot_resolution`]): a sample per pixel of
    /// the render is this many times the pilot's work.
    pub pixel_ratio: f64,
    /// Estimated variance of one sample per pixel, summed over the image's values and divided by
    /// their number (radiance squared; the MSE of a 1-spp image).
    pub variance_per_sample: f64,
}

impl CandidateFigures {
    /// Seconds per sample per pixel of the render's image (the pilot's, scaled by
    /// `pixel_ratio`).
    pub fn seconds_per_sample(&self) -> f64 {
        self.pilot_seconds_per_sample * self.pixel_ratio
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
    /// The pilot's figures of each method measured, in the order of [`candidate_methods`].
    pub candidates: Vec<CandidateFigures>,
    /// Width and height of the pilot's image (pixels); (0, 0) when there was no pilot.
    pub pilot_resolution: (u32, u32),
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

/// The methods `auto` measures for `settings` and `scene`: `path` and `direct` always, and
/// `ellipsoidal` where there is a gate (it has no steady state). In a scene with a dielectric,
/// smooth or rough, `ellipsoidal` is left out (alone it cannot sample the paths through glass,
/// nor place a vertex on rough glass); a scene with media weighs the bidirectional methods only
/// where they render it (see `bidirectional::check_media`), and an NLOS capture of glass takes
/// `path` alone, which only it renders. Where a point or spot light stands in a scattering
/// medium, `path`'s estimator has infinite variance ([`Scene::has_delta_light_in_scattering_medium`]):
/// a pilot cannot measure that (it rarely draws the vertices next to the light that ruin a
/// render), so `path` is left out wherever `direct` renders the scene.
///
/// [`Scene::has_delta_light_in_scattering_medium`]: crate::scene::Scene::has_delta_light_in_scattering_medium
pub fn candidate_methods(settings: &RenderSettings, scene: &PreparedScene) -> Vec<Method> {
    let glass = scene.has_dielectric() || scene.has_rough_dielectric();
    if glass && settings.nlos.is_some() {
        return vec![Method::Path];
    }
    let renders_media = |method: Method| {
        let settings = RenderSettings { method, ..settings.clone() };
        !scene.scene.has_media() || super::bidirectional::check_media(scene, &settings, method.name()).is_ok()
    };
    if !renders_media(Method::Direct) {
        return vec![Method::Path];
    }
    let mut methods = vec![Method::Path, Method::Direct];
    if scene.scene.has_delta_light_in_scattering_medium() {
        methods.remove(0);
    }
    if !matches!(settings.gate, Gate::None) && !glass && renders_media(Method::Ellipsoidal) {
        methods.push(Method::Ellipsoidal);
    }
    methods
}

/// What each of `estimators` pilots (methods, or the halves of a combined render) may spend of
/// `budget`, the pilot's image having 1 / `pixel_ratio` of the render's pixels: [`PILOT_SHARE`]
/// of a time budget in all, or batches of N / [`SAMPLE_BUDGET_DIVISOR`] samples of the image
/// in all for a budget of N samples per pixel.
pub(super) fn pilot_budget(budget: Budget, pixel_ratio: f64, estimators: usize) -> PilotBudget {
    match budget {
        Budget::Time(t) => PilotBudget::Seconds(t.as_secs_f64() * PILOT_SHARE / estimators as f64),
        Budget::Samples(n) => {
            let pilot_spp = (n as f64 * pixel_ratio / SAMPLE_BUDGET_DIVISOR as f64) as u64;
            PilotBudget::Samples((pilot_spp / PILOT_BATCHES as u64).clamp(1, u32::MAX as u64) as u32)
        }
    }
}

/// Runs the pilot of `settings` (method `auto`) on its own image ([`pilot_resolution`]) and
/// seed ([`pilot_seed`]) and returns the method to render with and why. With a time budget the
/// pilot spends about [`PILOT_SHARE`] of it (`MethodChoice::pilot_seconds`).
pub fn choose(
    ctx: &GpuContext,
    scene: &PreparedScene,
    settings: &RenderSettings,
    budget: Budget,
) -> Result<MethodChoice> {
    ensure!(settings.method == Method::Auto, "auto::choose needs --method auto, got {}", settings.method.name());
    ensure!(
        settings.nlos.is_none(),
        "--method auto does not apply to NLOS captures: choose path, direct or ellipsoidal"
    );
    let methods = candidate_methods(settings, scene);
    if let [only] = methods[..] {
        // Nothing to compare: no pilot, the whole budget for the render.
        return Ok(MethodChoice {
            chosen: only,
            candidates: Vec::new(),
            pilot_resolution: (0, 0),
            reason: format!(
                "{}: no pilot",
                if only == Method::Path {
                    "path is the only method that renders this scene (an NLOS capture of glass, or participating media that `direct` does not render yet)"
                } else {
                    "direct is the only candidate: a point or spot light in a scattering medium gives path infinite variance, and ellipsoidal needs a gate and a scene without glass"
                }
            ),
            pilot_seconds: 0.0,
        });
    }
    let (width, height, shrink) = pilot_resolution(settings.width, settings.height, PILOT_MIN_PIXELS);
    let pixel_ratio = (settings.width as f64 * settings.height as f64) / (width as f64 * height as f64);
    let per_method = pilot_budget(budget, pixel_ratio, methods.len());
    let pilot = pilot_settings(settings, width, height);
    // Each candidate weighs as its render would: `direct` with the camera scales of a camera
    // pilot where its render runs one.
    let mut camera_scales = CameraScalesOnce::default();
    let mut tracers = Vec::new();
    for &method in &methods {
        let candidate = resolve_camera_pilot(&candidate_settings(&pilot, method), budget);
        let mut tracer = create_integrator(ctx, scene, &candidate)?;
        tracer.warm_up()?;
        camera_scales.prepare(tracer.as_mut())?;
        tracers.push(tracer);
    }
    // The methods' batches alternate, so the pilot can stop after EARLY_STOP_BATCHES of each
    // where one method is far ahead of all others.
    let mut batches: Vec<Batches> = methods.iter().map(|_| Batches::default()).collect();
    let mut early = false;
    for j in 1..=PILOT_BATCHES {
        for (tracer, b) in tracers.iter_mut().zip(&mut batches) {
            pilot_batch(tracer.as_mut(), b, per_method, 1)?;
        }
        if j == EARLY_STOP_BATCHES && compare(&methods, &batches, pixel_ratio).2 >= EARLY_STOP_RATIO {
            early = true;
            break;
        }
    }
    let (candidates, chosen, ratio) = compare(&methods, &batches, pixel_ratio);
    let shrunk = if shrink > 1 { format!(" on a {width}x{height} image") } else { String::new() };
    let stopped =
        if early { format!(", stopped after {EARLY_STOP_BATCHES} of {PILOT_BATCHES} batches") } else { String::new() };
    let costs: Vec<String> = candidates.iter().map(|c| format!("{:.3e} ({})", c.cost(), c.method.name())).collect();
    let reason = format!(
        "pilot{shrunk}{stopped}: variance x time per sample {}; {} predicted {:.3}x lower MSE at equal time than the \
         next best",
        costs.join(" vs "),
        chosen.name(),
        ratio
    );
    let pilot_seconds = camera_scales.seconds + batches.iter().map(|b| b.wall_seconds).sum::<f64>();
    Ok(MethodChoice { chosen, candidates, pilot_resolution: (width, height), reason, pilot_seconds })
}

/// The methods' figures from their pilot batches so far, the method of the lowest variance x
/// time per sample, and how many times lower it is than the next best's (at least two methods).
pub(super) fn compare(
    methods: &[Method],
    batches: &[Batches],
    pixel_ratio: f64,
) -> (Vec<CandidateFigures>, Method, f64) {
    let candidates = figures(methods, batches, pixel_ratio);
    // Ties (all zero: nothing reaches the gate in the pilot) go to the faster method.
    let key = |c: &CandidateFigures| (c.cost(), c.seconds_per_sample());
    let mut order: Vec<&CandidateFigures> = candidates.iter().collect();
    order.sort_by(|a, b| key(a).partial_cmp(&key(b)).unwrap_or(std::cmp::Ordering::Equal));
    let (best, next) = (order[0], order[1]);
    let (chosen, ratio) = (best.method, next.cost() / best.cost());
    (candidates, chosen, ratio)
}

/// Each method's figures from its pilot batches so far (`batches[i]` of `methods[i]`), the
/// variances charged for what a pilot missed (see `per_sample_variances`).
fn figures(methods: &[Method], batches: &[Batches], pixel_ratio: f64) -> Vec<CandidateFigures> {
    let variances = per_sample_variances(&batches.iter().collect::<Vec<_>>());
    methods
        .iter()
        .zip(batches)
        .zip(variances)
        .map(|((&method, p), v)| CandidateFigures {
            method,
            spp: p.samples,
            seconds: p.seconds,
            pilot_seconds_per_sample: p.seconds_per_sample(),
            pixel_ratio,
            variance_per_sample: v,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn pilot_images_keep_a_thousand_pixels_and_shrink_at_most_fourfold() {
        assert_eq!(pilot_resolution(16, 16, PILOT_MIN_PIXELS), (16, 16, 1));
        assert_eq!(pilot_resolution(32, 32, PILOT_MIN_PIXELS), (32, 32, 1));
        assert_eq!(pilot_resolution(64, 64, PILOT_MIN_PIXELS), (32, 32, 2));
        assert_eq!(pilot_resolution(66, 64, PILOT_MIN_PIXELS), (33, 32, 2));
        assert_eq!(pilot_resolution(65, 64, PILOT_MIN_PIXELS), (65, 64, 1));
        assert_eq!(pilot_resolution(128, 128, PILOT_MIN_PIXELS), (32, 32, 4));
        assert_eq!(pilot_resolution(1920, 1080, PILOT_MIN_PIXELS), (480, 270, 4));
        assert_eq!(pilot_resolution(4096, 1, PILOT_MIN_PIXELS), (4096, 1, 1));
        assert_eq!(pilot_resolution(96, 96, PILOT_MIN_PIXELS), (32, 32, 3));
        assert_eq!(pilot_resolution(64, 64, ALLOCATION_MIN_PIXELS), (16, 16, 4));
        assert_eq!(pilot_resolution(128, 128, ALLOCATION_MIN_PIXELS), (32, 32, 4));
        assert_eq!(pilot_resolution(32, 32, ALLOCATION_MIN_PIXELS), (16, 16, 2));
    }

    #[test]
    fn pilot_seeds_are_their_own() {
        let seeds: Vec<u32> = (0..1000).map(pilot_seed).collect();
        assert!(seeds.iter().enumerate().all(|(s, &p)| p != s as u32 && seeds[..s].iter().all(|&q| q != p)));
    }
}
