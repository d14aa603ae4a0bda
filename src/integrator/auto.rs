//! `--method auto`: a short pilot of `path`, `direct` and (with a gate) `ellipsoidal` on the
//! render's own scene, gate and image, then the whole budget on the one whose measured variance
//! x time per sample is lowest. The pilot's films are discarded and its random numbers are not
//! reused, so the render is an unbiased estimate of the chosen method whatever the pilot saw
//! (choosing from samples that are then kept would bias it).
//!
//! Why a pilot and not a rule of gate width: where one method wins depends on the gate's width
//! against the scene's size, on where the gate sits in the scene's path lengths, on the
//! geometry the ellipsoid queries cross (their cost) and on the image; a measurement on the
//! render itself sees all of it. The pilot costs [`PILOT_SHARE`] of a time budget, and renders
//! the camera's image at a lower resolution ([`pilot_resolution`]) so that its floor of a few
//! one-sample batches stays small beside a short budget on a slow scene. It runs from a seed of
//! its own ([`pilot_seed`]); the render then starts afresh from the user's seed, so an `auto`
//! image is the chosen method's image with the same seed and budget.
//!
//! Estimating the variances: each method renders a few independent batches; the squared
//! differences of consecutive pairs of them, summed over the image's values (pixel, bin,
//! channel), give estimates of its variance per sample, and the median of the pairs' estimates
//! is taken (a firefly in one batch moves one pair's estimate, not the median). A narrow gate
//! makes that
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

/// The pilot's image is at most this many times smaller than the render's along each axis.
pub const PILOT_MAX_SHRINK: u32 = 4;

/// The pilot renders the same camera at a resolution shrunk by an integer factor f along each
/// axis, the largest f <= [`PILOT_MAX_SHRINK`] that divides both and leaves
/// [`PILOT_MIN_PIXELS`] pixels (so the image keeps its aspect exactly): its
/// floor of [`PILOT_BATCHES`] one-sample batches then costs about 1/f^2 of that at full size.
/// The variance of one sample of a pixel's estimate barely depends on the pixel's size (a
/// camera sample averages radiance over the pixel whatever its size; a light-tracing splat is
/// f^2 times smaller, lands f^2 times more often per light path, and the image has f^2 times
/// fewer light paths per sample), so per-sample variances mostly carry over (not where the
/// radiance varies within a pixel: on the glossy box `path`'s variance per sample is 17x
/// `direct`'s at 32x32 and 11x at 64x64, docs/methods.md, `auto`); times per sample are
/// scaled by the pixel count (`Batches::seconds_per_sample`). Returns (width, height, f).
pub fn pilot_resolution(width: u32, height: u32) -> (u32, u32, u32) {
    let pixels = width as u64 * height as u64;
    let fits = |f: u32| {
        width.is_multiple_of(f) && height.is_multiple_of(f) && pixels / (f as u64 * f as u64) >= PILOT_MIN_PIXELS as u64
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
/// `path` alone, which only it renders.
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
                "{} is the only method that renders this scene (an NLOS capture of glass, or participating media that `direct` does not render yet): no pilot",
                only.name()
            ),
            pilot_seconds: 0.0,
        });
    }
    let (width, height, shrink) = pilot_resolution(settings.width, settings.height);
    let pixel_ratio = (settings.width as f64 * settings.height as f64) / (width as f64 * height as f64);
    let per_method = pilot_budget(budget, pixel_ratio, methods.len());
    let pilot = RenderSettings { width, height, seed: pilot_seed(settings.seed), ..settings.clone() };
    let mut tracers = Vec::new();
    for &method in &methods {
        let mut tracer = create_integrator(ctx, scene, &candidate_settings(&pilot, method))?;
        tracer.warm_up()?;
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
    let pilot_seconds = batches.iter().map(|b| b.wall_seconds).sum();
    Ok(MethodChoice { chosen, candidates, pilot_resolution: (width, height), reason, pilot_seconds })
}

/// The methods' figures from their pilot batches so far, the method of the lowest variance x
/// time per sample, and how many times lower it is than the next best's.
fn compare(methods: &[Method], batches: &[Batches], pixel_ratio: f64) -> (Vec<CandidateFigures>, Method, f64) {
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
pub(super) fn figures(methods: &[Method], batches: &[Batches], pixel_ratio: f64) -> Vec<CandidateFigures> {
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

/// How much pilot each method gets.
#[derive(Clone, Copy, Debug)]
pub(super) enum PilotBudget {
    /// Seconds of passes (at least [`PILOT_BATCHES`] passes of one sample).
    Seconds(f64),
    /// Samples per pixel of each batch.
    Samples(u32),
}

/// Sums over one method's pilot batches (k_j: samples per pixel of batch j) of the batches'
/// estimates (x), weighted by k_j: sum k_j x and sum k_j x^2, one entry per value (here, per
/// group's sum over pixels).
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
pub(super) struct Batches {
    /// Batches rendered (n).
    count: u32,
    /// Samples per pixel in all (N = sum_j k_j).
    pub(super) samples: u64,
    /// Seconds of their passes (what the sample rate is measured by).
    pub(super) seconds: f64,
    /// Per batch: its samples per pixel and the seconds of its pass.
    passes: Vec<(u32, f64)>,
    /// Seconds of the whole batches: passes, film clears and readbacks (the pilot's cost).
    pub(super) wall_seconds: f64,
    /// Values of an image (pixels x bins x channels).
    values: usize,
    /// The last batch's samples per pixel and image while it waits for its pair.
    unpaired: Option<(u32, Vec<f64>)>,
    /// One estimate per pair of consecutive batches (a, b) of the per-sample variance summed
    /// over the values: sum_i (x_a,i - x_b,i)^2 / (1/k_a + 1/k_b).
    pair_variances: Vec<f64>,
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
        self.groups.add(k as f64, sums.into_iter());
        self.values = image.len();
        match self.unpaired.take() {
            None => self.unpaired = Some((k, image.to_vec())),
            Some((k_a, a)) => {
                let squares: f64 = a.iter().zip(image).map(|(x, y)| (x - y) * (x - y)).sum();
                self.pair_variances.push(squares / (1.0 / k_a as f64 + 1.0 / k as f64));
            }
        }
        self.samples += k as u64;
        self.count += 1;
    }

    /// Seconds per sample per pixel of the pilot's image without each pass's fixed cost
    /// (dispatches and waits, which a render's larger passes spread thinner): the median of the
    /// slopes of a pass's seconds over its samples between every two batches of different
    /// sizes (Theil-Sen; `pilot_batch` alternates sizes), within [`MARGINAL_SHARE_FLOOR`]..=1
    /// of the mean seconds per sample (a pass costs at least its samples); the mean where every
    /// batch had one size. A pass's time varies by tens of per cent from pass to pass (the first
    /// passes of a new tracer are the slowest), which a least-squares fit over so few batches
    /// follows and the median of slopes does not. The fixed cost matters most for the cheapest
    /// method: on the fence at 1 ns `path`'s one-sample passes at 32x32 took about twice its
    /// time per sample.
    pub(super) fn seconds_per_sample(&self) -> f64 {
        let mean = self.seconds / self.samples.max(1) as f64;
        let mut slopes = Vec::new();
        for (i, &(k_i, t_i)) in self.passes.iter().enumerate() {
            for &(k_j, t_j) in &self.passes[i + 1..] {
                if k_i != k_j {
                    slopes.push((t_j - t_i) / (k_j as f64 - k_i as f64));
                }
            }
        }
        if slopes.is_empty() {
            return mean;
        }
        median(slopes).clamp(MARGINAL_SHARE_FLOOR * mean, mean)
    }

    /// The per-sample variance summed over the values: the median of the pairs' estimates
    /// (the mean of the middle two for an even count). Each pair's estimate is unbiased; their
    /// median keeps one firefly (a rare path of huge weight, which a render of a hundred times
    /// the pilot's samples shows at its true rate, not at the one in a few hundred it was drawn
    /// with) from deciding the choice, where the mean of the pairs would follow it.
    pub(super) fn variance(&self) -> f64 {
        median(self.pair_variances.clone())
    }
}

/// The median of `values` (the mean of the middle two for an even count; 0 for none).
fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    match values.len() {
        0 => 0.0,
        n if n % 2 == 1 => values[n / 2],
        n => 0.5 * (values[n / 2 - 1] + values[n / 2]),
    }
}

/// The least share of the mean time per sample that a sample's time is taken to be
/// (dimensionless): a floor against a fit that timing jitter drove to zero.
pub const MARGINAL_SHARE_FLOOR: f64 = 0.05;

/// A group's means differ beyond noise where their squared difference exceeds MISS_FACTOR times
/// its expectation under fair sampling (|t| > 3.2: with variances from 8 batches, Student's t
/// of 7 degrees of freedom passes it with probability 1.6 %).
pub const MISS_FACTOR: f64 = 10.0;

/// Renders the next of a method's [`PILOT_BATCHES`] independent batches on `tracer`, sized to
/// `budget` in multiples of `unit` samples per pixel (as far as a pass holds them), and adds it
/// to `batches`. With a time budget the first batch has one unit and the others spread the
/// time left over the batches left, alternately 2/3 and 4/3 of an equal share (odd batches at
/// least two units), so that the batches' sizes differ and the time a sample takes beyond a
/// pass's fixed cost can be fitted (`Batches::seconds_per_sample`). A unit above one keeps the
/// ratio of a combined render's halves in every batch (the other half traces at least one
/// sample a pass).
pub(super) fn pilot_batch(
    tracer: &mut dyn Integrator,
    batches: &mut Batches,
    budget: PilotBudget,
    unit: u32,
) -> Result<()> {
    let unit = unit.clamp(1, tracer.samples_per_pass().max(1));
    let k = match budget {
        PilotBudget::Samples(k) => k.div_ceil(unit) * unit,
        PilotBudget::Seconds(_) if batches.count == 0 => unit,
        PilotBudget::Seconds(total) => {
            let per_sample = batches.seconds / batches.samples as f64;
            let left = (total - batches.wall_seconds).max(0.0) / (PILOT_BATCHES - batches.count) as f64;
            let odd = batches.count % 2 == 1;
            let share = left / per_sample.max(1e-12) * if odd { 4.0 / 3.0 } else { 2.0 / 3.0 };
            let k = (share as u32).div_ceil(unit) * unit;
            if odd { k.max(2 * unit) } else { k }
        }
    };
    let k = k.min(tracer.samples_per_pass() / unit * unit).max(unit);
    let start = Instant::now();
    tracer.reset_film();
    let pass = Instant::now();
    tracer.render_pass(k)?;
    let seconds = pass.elapsed().as_secs_f64();
    batches.seconds += seconds;
    batches.passes.push((k, seconds));
    let film = tracer.film()?;
    let image: Vec<f64> = film.data.iter().map(|&x| x as f64).collect();
    batches.add(k, &image, film.data.len() / (film.width as usize * film.height as usize).max(1));
    batches.wall_seconds += start.elapsed().as_secs_f64();
    Ok(())
}

/// The per-sample variances of the methods' pilots, averaged over the image's values: each
/// one's median pair estimate, plus the excesses of groups whose means differ beyond noise from
/// those of the most trustworthy pilot (the one of the smallest relative variance, the
/// reference), charged to the other method (the module's header). With two methods this is
/// the same as charging the less trustworthy of the pair.
fn per_sample_variances(pilots: &[&Batches]) -> Vec<f64> {
    let values = pilots.iter().map(|p| p.values).max().unwrap_or(0);
    let mut variances: Vec<f64> = pilots.iter().map(|p| p.variance()).collect();
    // A rare-event pilot's variance moves with the share of the rare paths it drew, and so does
    // its mean: a less trustworthy method's variance is scaled by the reference's mean over its
    // own (summed magnitudes of the groups' means), which is exact where its variance is
    // proportional to its mean (hits of one size). A pilot that found nothing is left to the
    // groups' test below.
    let magnitude = |m: &Batches| {
        (0..m.groups.weighted_sum.len()).map(|g| m.groups.get(g, m.count, m.samples).0.abs()).sum::<f64>()
    };
    let noise: Vec<f64> = pilots.iter().map(|p| relative_noise(p)).collect();
    let reference = (0..pilots.len()).fold(0, |r, i| if noise[i] < noise[r] { i } else { r });
    let r = pilots[reference];
    for (i, m) in pilots.iter().enumerate() {
        if i == reference {
            continue;
        }
        if noise[i] > noise[reference] && magnitude(m) > 0.0 {
            variances[i] *= magnitude(r) / magnitude(m);
        }
        for g in 0..m.groups.weighted_sum.len().min(r.groups.weighted_sum.len()) {
            let (mean_m, var_m) = m.groups.get(g, m.count, m.samples);
            let (mean_r, var_r) = r.groups.get(g, r.count, r.samples);
            let expected = var_m / m.samples as f64 + var_r / r.samples as f64;
            let difference = (mean_m - mean_r).powi(2);
            if difference > MISS_FACTOR * expected {
                variances[i] += m.samples as f64 * (difference - expected);
            }
        }
    }
    variances.iter().map(|v| v / values.max(1) as f64).collect()
}

/// The relative variance of a pilot's groups' means: the groups' per-sample variances, from the
/// plain spread of their batches (a firefly counts), summed, over the samples and the sum of
/// the groups' squared means (infinite for a pilot that found no light). Of two pilots whose
/// means differ beyond their spreads, the one with the larger relative variance is the one
/// whose mean is the less trustworthy: it saw fewer of the paths that make its estimate (a
/// `direct` pilot on a narrow gate, whether it found none of them, by chance more than its
/// share, or one path of huge weight, which the median of the pairs leaves out of its variance
/// but not out of its mean).
fn relative_noise(m: &Batches) -> f64 {
    let groups = (0..m.groups.weighted_sum.len()).map(|g| m.groups.get(g, m.count, m.samples));
    let (variances, squares) = groups.fold((0.0, 0.0), |(v, q), (mean, var)| (v + var, q + mean * mean));
    if squares > 0.0 { variances / (m.samples as f64 * squares) } else { f64::INFINITY }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_samples_time_leaves_out_each_passs_fixed_cost() {
        // Passes of 3 ms plus 1 ms a sample, alternating sizes.
        let timed = |passes: &[(u32, f64)]| {
            let mut b = Batches { passes: passes.to_vec(), ..Batches::default() };
            b.seconds = passes.iter().map(|p| p.1).sum();
            b.samples = passes.iter().map(|p| p.0 as u64).sum();
            b
        };
        let pass = |k: u32| (k, 3e-3 + 1e-3 * k as f64);
        let fitted = timed(&[pass(1), pass(2), pass(1), pass(3), pass(2), pass(4), pass(2), pass(4)]);
        assert!((fitted.seconds_per_sample() - 1e-3).abs() < 1e-12, "{}", fitted.seconds_per_sample());
        // A slow first pass (a new tracer) and one stalled pass do not move it.
        let mut slow = fitted.passes.clone();
        slow[0].1 *= 3.0;
        slow[5].1 *= 5.0;
        let slow = timed(&slow);
        assert!((slow.seconds_per_sample() - 1e-3).abs() < 1e-12, "{}", slow.seconds_per_sample());
        // One size: the mean, fixed cost included.
        let mean = timed(&[pass(2); 8]).seconds_per_sample();
        assert!((mean - 2.5e-3).abs() < 1e-12, "{mean}");
        // A fit below the floor (jitter) is held at it; above the mean, at the mean.
        let flat = timed(&[(1, 4e-3), (2, 4e-3)]);
        assert!((flat.seconds_per_sample() - MARGINAL_SHARE_FLOOR * 8e-3 / 3.0).abs() < 1e-15);
        let steep = timed(&[(1, 0.0), (2, 5e-3)]);
        assert!((steep.seconds_per_sample() - 5e-3 / 3.0).abs() < 1e-15);
    }

    /// The per-sample variances of two pilots.
    fn two_variances(a: &Batches, b: &Batches) -> (f64, f64) {
        let v = per_sample_variances(&[a, b]);
        (v[0], v[1])
    }

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
    fn pilot_images_keep_a_thousand_pixels_and_shrink_at_most_fourfold() {
        assert_eq!(pilot_resolution(16, 16), (16, 16, 1));
        assert_eq!(pilot_resolution(32, 32), (32, 32, 1));
        assert_eq!(pilot_resolution(64, 64), (32, 32, 2));
        assert_eq!(pilot_resolution(66, 64), (33, 32, 2));
        assert_eq!(pilot_resolution(65, 64), (65, 64, 1));
        assert_eq!(pilot_resolution(128, 128), (32, 32, 4));
        assert_eq!(pilot_resolution(1920, 1080), (480, 270, 4));
        assert_eq!(pilot_resolution(4096, 1), (4096, 1, 1));
        assert_eq!(pilot_resolution(96, 96), (32, 32, 3));
    }

    #[test]
    fn pilot_seeds_are_their_own() {
        let seeds: Vec<u32> = (0..1000).map(pilot_seed).collect();
        assert!(seeds.iter().enumerate().all(|(s, &p)| p != s as u32 && seeds[..s].iter().all(|&q| q != p)));
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
        let (va, vb) = two_variances(&batches(&a, 2), &batches(&b, 5));
        // Each estimate pools about 8 x 4096 squared deviations: relative error ~ 1/sqrt(16384).
        assert!((va - 1.0).abs() < 0.1, "variance of A: {va}, expected 1");
        assert!((vb - 9.0).abs() < 0.9, "variance of B: {vb}, expected 9");
    }

    #[test]
    fn one_firefly_does_not_decide() {
        // Per-sample standard deviation 1 everywhere, but one batch of 8 holds one value of
        // 1000: the mean of the four pairs' estimates would be about 1 + 1e6 / 2 / 4 / 4096 = 31
        // per value; their median stays near 1.
        let values = 4096;
        let mut seed = 9;
        let mut images: Vec<Vec<f64>> = (0..8).map(|_| normals(&mut seed, values)).collect();
        images[5][17] = 1000.0;
        let (v, _) = two_variances(&batches(&images, 1), &batches(&images, 1));
        assert!((v - 1.0).abs() < 0.1, "variance with a firefly: {v}");
    }

    #[test]
    fn charges_a_rare_event_pilot_that_overshot() {
        // A: hits of 1.15 / p with probability p = 0.05 per value and sample (mean 1.15, 15 %
        // above the truth, as a `direct` pilot that drew more than its share of a narrow gate's
        // paths); B: 1 + 0.01 z. The difference is far beyond the spreads, and it is A's spread
        // that cannot be trusted, though B's mean is the smaller.
        let (values, p) = (4096, 0.05);
        let mut seed = 13u64;
        let mut uniform = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let a: Vec<Vec<f64>> =
            (0..8).map(|_| (0..values).map(|_| if uniform() < p { 1.15 / p } else { 0.0 }).collect()).collect();
        let mut normal_seed = 17;
        let b: Vec<Vec<f64>> =
            (0..8).map(|_| normals(&mut normal_seed, values).into_iter().map(|z| 1.0 + 0.01 * z).collect()).collect();
        let (v_a, v_b) = two_variances(&batches(&a, 1), &batches(&b, 1));
        assert!((v_b / 1e-4 - 1.0).abs() < 0.1, "B's variance stays its own: {v_b}");
        // A's own spread is 1.15^2 (1 - p) / p = 25 per value; the miss adds 8 x (0.15 x 4096)^2
        // / 4096 = 737 per value.
        assert!(v_a > 300.0, "A is charged the difference: {v_a}");
    }

    #[test]
    fn sees_what_a_batch_missed() {
        // A rare-event estimator that found nothing in its pilot (all zeros, no spread) against
        // one that sees the image: its variance is at least the missed signal's square.
        let values = 256;
        let mut seed = 3;
        let seen: Vec<_> =
            (0..8).map(|_| normals(&mut seed, values).into_iter().map(|z| 1.0 + 0.1 * z).collect::<Vec<_>>()).collect();
        let missed = vec![vec![0.0; values]; 8];
        let (v_missed, v_seen) = two_variances(&batches(&missed, 1), &batches(&seen, 1));
        // Missing a sum of 256 in 8 samples implies a per-sample variance of the sum of 8 x
        // 256^2, or 8 x 256 per value.
        assert!((v_missed / 2048.0 - 1.0).abs() < 0.01, "the empty pilot's variance per sample: {v_missed}");
        assert!((v_seen - 0.01).abs() < 0.002, "the other pilot's: {v_seen}");
    }

    #[test]
    fn three_pilots_are_each_compared_with_the_most_trustworthy() {
        // A sees the image with per-sample deviation 0.1, B with 1 (both unbiased: neither is
        // charged), C found nothing: only C is charged, once, for what it missed against A.
        let values = 256;
        let mut seed = 21;
        let mut seen = |sigma: f64| -> Vec<Vec<f64>> {
            (0..8).map(|_| normals(&mut seed, values).into_iter().map(|z| 1.0 + sigma * z).collect()).collect()
        };
        let (a, b) = (seen(0.1), seen(1.0));
        let missed = vec![vec![0.0; values]; 8];
        let v = per_sample_variances(&[&batches(&b, 1), &batches(&missed, 1), &batches(&a, 1)]);
        assert!((v[0] - 1.0).abs() < 0.1, "B keeps its own variance: {v:?}");
        // Missing a sum of 256 in 8 samples: 8 x 256^2 for the sum, 8 x 256 per value.
        assert!((v[1] / 2048.0 - 1.0).abs() < 0.01, "C is charged the miss once: {v:?}");
        assert!((v[2] - 0.01).abs() < 0.002, "A keeps its own variance: {v:?}");
    }

    #[test]
    fn sees_a_miss_behind_noisy_values() {
        // The method that sees the image is itself noisy (per-sample standard deviation equal to
        // the mean, so no single value's difference stands out after 8 samples), but the
        // image's sum shows what the empty pilot missed.
        let values = 4096;
        let mut seed = 5;
        let seen: Vec<_> =
            (0..8).map(|_| normals(&mut seed, values).into_iter().map(|z| 1.0 + z).collect::<Vec<_>>()).collect();
        let missed = vec![vec![0.0; values]; 8];
        let (v_missed, v_seen) = two_variances(&batches(&missed, 1), &batches(&seen, 1));
        assert!((v_missed / (8.0 * 4096.0) - 1.0).abs() < 0.05, "the empty pilot's variance per sample: {v_missed}");
        assert!((v_seen - 1.0).abs() < 0.1, "the other pilot's: {v_seen}");
    }
}
