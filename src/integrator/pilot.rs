//! The pilots' measurement, shared by `auto` (one pilot per candidate method), `combined` (its
//! halves, each family alone and both halves together) and the query roulette: batches of a
//! few samples per pixel on the pilot's image, each method's variance per sample from the
//! medians of consecutive batch pairs (their means where the medians are zero, and at least
//! their means for a pilot that found less light than the most trustworthy one), what a pilot
//! missed charged against that one (see `auto`'s header), and a sample's time without each
//! pass's fixed cost.

use std::time::Instant;

use anyhow::Result;

use super::Integrator;
use super::auto::PILOT_BATCHES;

/// One camera pilot for all of a pilot's tracers that weigh with camera scales (`direct`, and
/// both halves of `combined`; docs/design.md section 4.2, "Camera scales"), so that each is
/// measured as its render will weigh: the first such tracer runs the camera pilot its render
/// would run (of the render's samples per pixel, on the pilot's image), and later ones adopt its
/// scales, being of the same image. `combined`'s halves thus weigh with the scales of `direct`
/// alone, where their render measures them on its direct half (both with every camera density
/// scaled alike): one of both halves at a split of 1 would cost about 4 of `direct`'s on the
/// fence, where an ellipsoidal sample costs 3.3 direct ones (docs/benchmarks.md, "The paper's
/// applications").
#[derive(Default)]
pub(super) struct CameraScalesOnce {
    /// The first tracer's scales and its camera pilot's samples per pixel.
    scales: Option<(Vec<f32>, u32)>,
    /// Seconds spent in [`Self::prepare`] (camera pilot and other work before a first pass).
    pub seconds: f64,
}

impl CameraScalesOnce {
    /// Readies `tracer`, after its warm-up, for its pilot batches: the work its render does
    /// before the first pass (`Integrator::prepare`), with the camera scales of the first tracer
    /// that weighed with them; timed in `seconds`, so that no batch's time holds it.
    pub fn prepare(&mut self, tracer: &mut dyn Integrator) -> Result<()> {
        let start = Instant::now();
        if let Some((scales, traced)) = &self.scales {
            tracer.adopt_camera_mis_scales(scales, *traced);
        }
        tracer.prepare()?;
        if self.scales.is_none() && !tracer.camera_mis_scales().is_empty() {
            self.scales = Some((tracer.camera_mis_scales().to_vec(), tracer.camera_pilot_spp()));
        }
        self.seconds += start.elapsed().as_secs_f64();
        Ok(())
    }
}

/// Most bytes of per-slot state a pilot's tracer keeps in one wave
/// (`RenderSettings::wave_bytes`): a pilot's image is small and each of its tracers renders a
/// few batches, mostly of one or two samples per pixel, yet without a bound each took a full
/// render's wave (on CPU Vulkan 2^16 slots, 0.18 GB for `direct` on the fence), which the device
/// clears before its first use, a page at a time. At 16 MiB a 16x16 pilot still traces about 23
/// `direct` samples per pixel in one pass, and every pilot at least
/// `wavefront::BOUNDED_WAVE_SAMPLES`.
pub const PILOT_WAVE_BYTES: u64 = 16 << 20;

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
    /// The last batch's samples per pixel and image (see [`Batches::last`]).
    last: (u32, Vec<f64>),
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
        self.last = (k, image.to_vec());
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

    /// The last batch's samples per pixel and estimate (pixels x bins x channels; empty before
    /// the first batch).
    pub(super) fn last(&self) -> (u32, &[f64]) {
        (self.last.0, &self.last.1)
    }

    /// The per-sample variance summed over the values: the median of the pairs' estimates
    /// (the mean of the middle two for an even count). Each pair's estimate is unbiased; their
    /// median keeps one firefly (a rare path of huge weight, which a render of a hundred times
    /// the pilot's samples shows at its true rate, not at the one in a few hundred it was drawn
    /// with) from deciding the choice, where the mean of the pairs would follow it.
    ///
    /// Where the median is zero, at least half of the pairs saw no light at all: what light the
    /// method finds comes in rare batches, and those are its variance, not a firefly on top of
    /// it. Its variance is then the mean of the pairs' estimates (unbiased; zero only where no
    /// batch found light). With the median, a `direct` pilot behind a 1 mm gate on the
    /// proximity sensor's second frame (32x32, 8 batches) measured no variance in 2 renders of
    /// 3 and `combined` traced it alone, where `ellipsoidal` had about 1/4,000 of its error.
    pub(super) fn variance(&self) -> f64 {
        let median = median(self.pair_variances.clone());
        if median > 0.0 { median } else { self.pair_mean_variance() }
    }

    /// The per-sample variance summed over the values from every pair alike: the mean of the
    /// pairs' estimates (unbiased, rare batches of light and fireflies included; zero for no
    /// pairs).
    fn pair_mean_variance(&self) -> f64 {
        self.pair_variances.iter().sum::<f64>() / self.pair_variances.len().max(1) as f64
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
            // Beyond PILOT_BATCHES (`combined`'s second round of each family alone) what is
            // left of the budget goes to the next batch alone.
            let batches_left = PILOT_BATCHES.saturating_sub(batches.count).max(1);
            let left = (total - batches.wall_seconds).max(0.0) / batches_left as f64;
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
pub(super) fn per_sample_variances(pilots: &[&Batches]) -> Vec<f64> {
    let values = pilots.iter().map(|p| p.values).max().unwrap_or(0);
    let mut variances: Vec<f64> = pilots.iter().map(|p| p.variance()).collect();
    // A rare-event pilot's variance moves with the share of the rare paths it drew, and so does
    // its mean: a less trustworthy method's variance is scaled by the reference's mean over its
    // own (summed magnitudes of the groups' means), which is exact where its variance is
    // proportional to its mean (hits of one size), after its variance was taken from all its
    // pairs where its mean is the smaller (below). A pilot that found nothing is left to the
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
        // A less trustworthy pilot that found less light than the reference drew fewer of its
        // rare paths than their share, and its batches that found them are its variance, not
        // fireflies on top of it (a firefly raises a pilot's mean): its variance is at least the
        // mean of its pairs' estimates. The median of 4 pairs leaves out the one batch of 8 that found
        // a 1 mm gate's light: on the glossy box there (16x16) a `direct` pilot's pairs gave 0,
        // 2.2e-6, 2.6e-5 and 1.4e-2, its mean was 0.44 of `ellipsoidal`'s, and the median put it
        // 12.8 times ahead of `ellipsoidal`, which has 1/24 of its error. (Where the pairs are
        // alike their mean is close to their median, and the larger of the two is kept.)
        if noise[i] > noise[reference] && magnitude(m) < magnitude(r) {
            variances[i] = variances[i].max(m.pair_mean_variance());
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
    fn light_in_rare_batches_is_the_variance() {
        // A finds light in one batch of 8 (a value of 64 where the truth is 8 per batch's
        // sample): three of the four pairs saw nothing, so their median is zero, and the variance
        // is the mean of the pairs' estimates, 64^2 / 2 / 4 per value over 1 value of 16.
        let values = 16;
        let mut images = vec![vec![0.0; values]; 8];
        images[3][5] = 64.0;
        let b = batches(&images, 1);
        let expected = 64.0 * 64.0 / 2.0 / 4.0;
        assert!((b.variance() - expected).abs() < 1e-9, "{} against {expected}", b.variance());
        // Nothing at all: no variance.
        assert_eq!(batches(&vec![vec![0.0; values]; 8], 1).variance(), 0.0);
    }

    #[test]
    fn a_pilot_short_of_light_keeps_its_rare_batches() {
        // B sees 1 per value in every batch; A (a `direct` pilot behind a narrow gate) finds
        // 0.01 +- 0.001 in seven batches and 4 in one, about half of B's light: its pairs give
        // 4096 x 0.002^2 / 2 three times and 4096 x 3.989^2 / 2 once, so the median of the four
        // leaves the batch of light out. A's variance is the mean of its pairs, scaled by B's
        // mean over its own (the charge of `per_sample_variances`); its mean is within the
        // spread of its batches, so no miss is charged on top.
        let values = 4096;
        let a: Vec<Vec<f64>> = (0..8)
            .map(|j| vec![if j == 3 { 4.0 } else { 0.01 + if j % 2 == 0 { 0.001 } else { -0.001 } }; values])
            .collect();
        let mut seed = 23;
        let b: Vec<Vec<f64>> =
            (0..8).map(|_| normals(&mut seed, values).into_iter().map(|z| 1.0 + 0.01 * z).collect()).collect();
        let (a, b) = (batches(&a, 1), batches(&b, 1));
        let (v_a, v_b) = two_variances(&a, &b);
        let pairs = [4096.0 * 0.002f64.powi(2) / 2.0, 4096.0 * 3.989f64.powi(2) / 2.0];
        let mean_of_pairs = (3.0 * pairs[0] + pairs[1]) / 4.0;
        let mean_a = (4.0 + 7.0 * 0.01 + 0.001) / 8.0;
        let b_over_a = b.groups.get(0, b.count, b.samples).0 / (mean_a * values as f64);
        let expected = mean_of_pairs * b_over_a / values as f64;
        assert!((v_a / expected - 1.0).abs() < 1e-6, "A's variance {v_a}, expected {expected}");
        assert!((v_b / 1e-4 - 1.0).abs() < 0.1, "B's variance stays its own: {v_b}");
        // A's batch of light pushing its mean above B's is a firefly: the median stays.
        let over: Vec<Vec<f64>> = (0..8)
            .map(|j| vec![if j == 3 { 16.0 } else { 0.01 + if j % 2 == 0 { 0.001 } else { -0.001 } }; values])
            .collect();
        let over = batches(&over, 1);
        let (v_over, _) = two_variances(&over, &b);
        assert!(v_over < 1e-3, "a firefly above B's mean stays out of the variance: {v_over}");
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
