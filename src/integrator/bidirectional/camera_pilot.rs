//! The camera pilot of `direct`: per-pixel scales of the camera's density in the MIS weights
//! (docs/design.md section 4.2, "Camera scales").
//!
//! The power heuristic weighs a light-tracing splat (t = 1) against the camera's strategies by
//! their densities over the whole image. That ignores how differently the two spread their
//! samples: every pixel gets exactly one camera sample per pass, while splats land in it at
//! random, so a pixel the camera's strategies estimate almost without noise (a lit diffuse or
//! glossy surface seen directly) still takes a share of its light from splats and their
//! random count. With a light next to the camera, as in time-of-flight sensors, that share is
//! large everywhere the light reaches.
//!
//! A short pilot measures, per pixel, the relative variance kappa = variance / mean^2 of one
//! sample of the camera's strategies (the film's sums and accumulate's sums of squares; splats
//! left out), rendered with the camera's
//! density scaled by [`CAMERA_PILOT_SCALE`] everywhere, so that those strategies carry nearly
//! the whole estimate wherever they can sample the path. The render then scales
//! the camera's density in that pixel by 1 / sqrt(kappa), clamped to 1 ..=
//! [`CAMERA_MIS_SCALE_MAX`]. With two estimators of a pixel, one whose relative variance per
//! sample is kappa and one limited by the count of its samples, the variance of their weighted
//! sum is least for weights the power heuristic gives when one density is scaled by about
//! 1 / sqrt(kappa); below 1 the pilot's noise cost more than it saved on every scene measured,
//! so no pixel gives the camera less than the textbook weight.
//!
//! Any positive scales leave the estimate unbiased: every weight of a path reads the camera's
//! density through the same function (subpath.wesl `camera_direction_pdf`), at the pixel the
//! path's first camera-side vertex projects to, so the weights of a path's strategies still sum
//! to one; the pilot's samples are discarded, and the scales are fixed before the film's first
//! sample.

use std::time::Instant;

use anyhow::Result;

use super::BidirectionalTracer;
use crate::film::fixed;
use crate::gpu::resources::read_buffer;
use crate::integrator::{Budget, Integrator, Method, RenderSettings};

/// Samples per pixel of the camera pilot. Four samples give each pixel's kappa a spread of
/// tens of per cent, which moves its scale, 1 / sqrt(kappa), by less; at equal time `direct`
/// with a pilot of 4 had 0.84-0.97 times the MSE it had with 16 on every scene measured, the
/// proximity sensor at 0.65 s (where the scales cut the error 18-fold) included, at 4 s and at
/// 16 s (docs/benchmarks.md, "Camera scales").
pub const CAMERA_PILOT_SPP: u32 = 4;
/// Renders by samples run the pilot from this many samples per pixel on, where it costs at most
/// 1/64 of the render's samples.
pub const CAMERA_PILOT_FROM_SPP: u64 = 256;
/// The scale of every pixel while the pilot renders.
pub const CAMERA_PILOT_SCALE: f32 = 16.0;
/// The largest scale a pixel gets (dimensionless), before its 8-bit storage (see
/// [`encode_scale`]) rounds it to at most 2^(255/32), about 251.
pub const CAMERA_MIS_SCALE_MAX: f32 = 256.0;
/// vec4<u32> words of the camera_mis_scales uniform buffer (64 KiB).
pub const SCALE_WORDS: usize = 4096;
/// Tiles the buffer holds, one byte each.
pub const SCALE_TILES: usize = 16 * SCALE_WORDS;

/// The tiles of pixels that share a scale: squares of `size` pixels across (a power of two, the
/// least that leaves at most [`SCALE_TILES`] tiles), `across` x `down` of them, row-major.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CameraTiles {
    /// Pixels across a tile.
    pub size: u32,
    /// Tiles across the image.
    pub across: u32,
    /// Tiles down the image.
    pub down: u32,
}

impl CameraTiles {
    /// Number of tiles.
    pub fn count(&self) -> usize {
        self.across as usize * self.down as usize
    }

    /// The tile of pixel (x, y) (as subpath.wesl camera_mis_scale).
    pub fn of(&self, x: u32, y: u32) -> usize {
        (y / self.size) as usize * self.across as usize + (x / self.size) as usize
    }
}

/// The tiles of a `width` x `height` image: single pixels up to 65,536 pixels (256 x 256),
/// 2 x 2 pixels up to 512 x 512, and so on.
pub fn camera_scale_tiles(width: u32, height: u32) -> CameraTiles {
    let mut size = 1;
    while (width.div_ceil(size) as usize) * (height.div_ceil(size) as usize) > SCALE_TILES {
        size *= 2;
    }
    CameraTiles { size, across: width.div_ceil(size), down: height.div_ceil(size) }
}

/// The byte that stores `scale`: round(32 log2 scale), 0 (scale 1) to 255.
pub fn encode_scale(scale: f32) -> u8 {
    (32.0 * scale.max(1.0).log2()).round().min(255.0) as u8
}

/// The scale byte `b` stores, 2^(b / 32) (subpath.wesl camera_mis_scale).
pub fn decode_scale(b: u8) -> f32 {
    (b as f32 / 32.0).exp2()
}

/// Per tile, the scale of its pixels' moments: a tile's mean is the root of its pixels'
/// summed squared means and its variance their summed variances, so that a tile of one pixel
/// takes that pixel's scale ([`camera_mis_scales`]). `means` and `variances` are per pixel,
/// row-major over a `width`-pixel-wide image.
pub fn camera_tile_scales(tiles: CameraTiles, width: u32, means: &[f64], variances: &[f64]) -> Vec<f32> {
    let mut squares = vec![0.0f64; tiles.count()];
    let mut spread = vec![0.0f64; tiles.count()];
    for (p, (&mean, &variance)) in means.iter().zip(variances).enumerate() {
        let t = tiles.of(p as u32 % width, p as u32 / width);
        squares[t] += mean * mean;
        spread[t] += variance;
    }
    let rms: Vec<f64> = squares.iter().map(|s| s.sqrt()).collect();
    camera_mis_scales(&rms, &spread)
}
/// A render with a time budget stops its pilot after this share of the budget and goes without
/// scales (every pixel 1) if it is not complete by then.
const CAMERA_PILOT_BUDGET_SHARE: f64 = 1.0 / 8.0;

/// Whether `settings` can take a camera pilot: `direct` or `combined` (whose halves share one
/// set of scales, see `combined::CombinedTracer`), a camera (not an NLOS capture), and a gate of
/// one bin.
pub fn camera_pilot_applies(settings: &RenderSettings) -> bool {
    matches!(settings.method, Method::Direct | Method::Combined)
        && settings.nlos.is_none()
        && settings.debug_strategy.is_none()
        && settings.gate.bins() == 1
}

/// The camera pilot's samples per pixel for a render of `settings` with `budget` when
/// `settings.camera_pilot_spp` leaves it to the renderer: [`CAMERA_PILOT_SPP`] where the pilot
/// applies and the render has a time budget or at least [`CAMERA_PILOT_FROM_SPP`] samples per
/// pixel, 0 otherwise.
pub fn default_camera_pilot(settings: &RenderSettings, budget: Budget) -> u32 {
    let enough = match budget {
        Budget::Samples(n) => n >= CAMERA_PILOT_FROM_SPP,
        Budget::Time(_) => true,
    };
    if camera_pilot_applies(settings) && enough { CAMERA_PILOT_SPP } else { 0 }
}

/// `settings` with the camera pilot of its render under `budget` resolved: as given, else
/// [`default_camera_pilot`].
pub fn resolve_camera_pilot(settings: &RenderSettings, budget: Budget) -> RenderSettings {
    let spp = settings.camera_pilot_spp.unwrap_or_else(|| default_camera_pilot(settings, budget));
    RenderSettings { camera_pilot_spp: Some(spp), ..settings.clone() }
}

/// The camera pilot of the render a checkpoint holds, for its resumption when the settings
/// leave it to the renderer: [`CAMERA_PILOT_SPP`] where the state keeps scales (which its
/// loading restores; the pilot does not run again), 0 otherwise.
pub fn saved_camera_pilot(state: &crate::integrator::checkpoint::RenderState) -> u32 {
    match state.all_values::<f32>("camera_mis_scales") {
        Ok(scales) if !scales.is_empty() => CAMERA_PILOT_SPP,
        _ => 0,
    }
}

/// Per-pixel scales from the pilot's per-pixel means and variances of one sample:
/// |mean| / sqrt(variance) = 1 / sqrt(kappa), clamped to 1 ..= [`CAMERA_MIS_SCALE_MAX`]; 1
/// where the pilot saw no light, the largest scale where it saw light without noise.
pub fn camera_mis_scales(means: &[f64], variances: &[f64]) -> Vec<f32> {
    means
        .iter()
        .zip(variances)
        .map(|(&mean, &variance)| {
            if mean == 0.0 || !mean.is_finite() || !variance.is_finite() {
                1.0
            } else if variance <= 0.0 {
                CAMERA_MIS_SCALE_MAX
            } else {
                ((mean.abs() / variance.sqrt()) as f32).clamp(1.0, CAMERA_MIS_SCALE_MAX)
            }
        })
        .collect()
}

/// Traces a camera pilot's `asked` samples per pixel on `tracer` (after `begin_camera_pilot` on
/// the tracers whose films it reads) in full passes; with a time budget of `budget` seconds no
/// pass starts after [`CAMERA_PILOT_BUDGET_SHARE`] of it. Whether all were traced.
pub(crate) fn trace_camera_pilot(tracer: &mut dyn Integrator, asked: u32, budget: Option<f64>) -> Result<bool> {
    let start = Instant::now();
    let limit = budget.map(|seconds| seconds * CAMERA_PILOT_BUDGET_SHARE);
    let asked = asked as u64;
    while tracer.samples_done() < asked && !limit.is_some_and(|limit| start.elapsed().as_secs_f64() >= limit) {
        let n = (asked - tracer.samples_done()).min(tracer.samples_per_pass() as u64) as u32;
        tracer.render_pass(n)?;
    }
    Ok(tracer.samples_done() >= asked)
}

impl BidirectionalTracer<'_> {
    /// Runs the camera pilot of a render of its own (`direct`): `camera_pilot_asked` samples
    /// per pixel, in full passes, with every pixel's scale [`CAMERA_PILOT_SCALE`]; each pixel's
    /// mean from the film's sums and its second moment from pixel_moments (accumulate,
    /// PIXEL_MOMENTS). Then writes the scales and clears the film (the render's samples continue
    /// the sequence after the pilot's). With a time budget no pass starts after
    /// [`CAMERA_PILOT_BUDGET_SHARE`] of it, and a pilot cut short leaves every scale 1.
    pub(super) fn run_camera_pilot(&mut self) -> Result<()> {
        self.camera_pilot_pending = false;
        let (asked, budget) = (self.camera_pilot_asked, self.time_budget);
        self.begin_camera_pilot();
        let complete = trace_camera_pilot(self, asked, budget)?;
        let scales = self.camera_pilot_scales(complete)?;
        self.finish_camera_pilot(scales, if complete { asked } else { 0 });
        Ok(())
    }

    /// Whether the kernels weigh with per-pixel camera scales (a `direct` render with a camera
    /// pilot, or either half of a `combined` one).
    pub(crate) fn keeps_camera_scales(&self) -> bool {
        !self.camera_mis_scales.is_empty()
    }

    /// The start of a camera pilot: every scale [`CAMERA_PILOT_SCALE`], the film and the sums
    /// of squares cleared.
    pub(crate) fn begin_camera_pilot(&mut self) {
        self.write_camera_mis_scales(vec![CAMERA_PILOT_SCALE; self.camera_mis_scales.len()]);
        self.reset_film();
        let ctx = self.wf.ctx;
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        encoder.clear_buffer(self.wf.resources.get("pixel_moments").unwrap(), 0, None);
        ctx.queue.submit([encoder.finish()]);
    }

    /// Per pixel, the mean and the variance of one sample of the film's contributions (the sum
    /// of the three channels) since `begin_camera_pilot`; variances infinite with fewer than two
    /// samples.
    pub(crate) fn camera_pilot_moments(&self) -> Result<(Vec<f64>, Vec<f64>)> {
        let ctx = self.wf.ctx;
        let elements = self.wf.film_element_count();
        let sums: Vec<[u32; 4]> = self.wf.resources.read_chunked(ctx, "film", self.wf.film_layout, elements)?;
        let pixels = (self.wf.params.width * self.wf.params.height) as usize;
        let squares: Vec<f32> = read_buffer(ctx, self.wf.resources.get("pixel_moments").unwrap(), pixels)?;
        let n = self.samples_done() as f64;
        Ok(sums
            .chunks_exact(3)
            .zip(&squares)
            .map(|(rgb, &square)| {
                let sum: f64 = rgb.iter().map(|&words| fixed::to_f64(fixed::from_words(words))).sum();
                let mean = sum / n.max(1.0);
                let variance = match n >= 2.0 {
                    true => ((square as f64 - n * mean * mean) / (n - 1.0)).max(0.0),
                    false => f64::INFINITY,
                };
                (mean, variance)
            })
            .unzip())
    }

    /// The scales of the pilot since `begin_camera_pilot` from this tracer's film and sums of
    /// squares ([`camera_tile_scales`]), or every scale 1 where the pilot was cut short.
    pub(crate) fn camera_pilot_scales(&self, complete: bool) -> Result<Vec<f32>> {
        if !complete {
            return Ok(vec![1.0; self.camera_mis_scales.len()]);
        }
        let (means, variances) = self.camera_pilot_moments()?;
        Ok(camera_tile_scales(self.camera_tiles(), self.wf.params.width, &means, &variances))
    }

    /// The end of a camera pilot: `scales` (one per pixel) written, `traced` samples per pixel
    /// recorded (0: the pilot was cut short), and the film cleared with a new seed.
    pub(crate) fn finish_camera_pilot(&mut self, scales: Vec<f32>, traced: u32) {
        self.write_camera_mis_scales(scales);
        self.camera_pilot_traced = traced;
        // Writes the parameters with a new seed and the film's first sample.
        self.reset_film();
    }

    /// As a new tracer: every scale 1, and the pilot (if it runs its own) before the next pass.
    pub(super) fn restart_camera_pilot(&mut self) {
        self.camera_pilot_pending = self.camera_pilot_asked > 0;
        self.camera_pilot_traced = 0;
        self.write_camera_mis_scales(vec![1.0; self.camera_mis_scales.len()]);
    }

    /// Puts `scales` (one per tile) in camera_mis_scales, as bytes, and keeps what they store.
    pub(super) fn write_camera_mis_scales(&mut self, scales: Vec<f32>) {
        if scales.is_empty() {
            return;
        }
        let mut words = vec![[0u32; 4]; SCALE_WORDS];
        for (t, &scale) in scales.iter().enumerate() {
            words[t / 16][(t / 4) % 4] |= (encode_scale(scale) as u32) << (8 * (t % 4));
        }
        let buffer = self.wf.resources.get("camera_mis_scales").unwrap();
        self.wf.ctx.queue.write_buffer(buffer, 0, bytemuck::cast_slice(&words));
        self.camera_mis_scales = scales.iter().map(|&s| decode_scale(encode_scale(s))).collect();
    }

    /// The tiles the scales cover.
    pub(crate) fn camera_tiles(&self) -> CameraTiles {
        camera_scale_tiles(self.wf.params.width, self.wf.params.height)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scales_follow_the_inverse_root_of_the_relative_variance() {
        let means = [0.0, 2.0, 2.0, 2.0, -2.0, 2.0, 1e-9];
        let variances = [1.0, 0.0, 4.0, 0.04, 0.04, 1e-12, 1.0];
        let scales = camera_mis_scales(&means, &variances);
        assert_eq!(scales[0], 1.0, "no light seen: the textbook weights");
        assert_eq!(scales[1], CAMERA_MIS_SCALE_MAX, "light without noise: the largest scale");
        assert_eq!(scales[2], 1.0, "kappa 1");
        assert!((scales[3] - 10.0).abs() < 1e-4, "kappa 0.01: {}", scales[3]);
        assert!((scales[4] - 10.0).abs() < 1e-4, "a signed gate's negative mean: {}", scales[4]);
        assert_eq!(scales[5], CAMERA_MIS_SCALE_MAX, "clamped above");
        assert_eq!(scales[6], 1.0, "clamped below");
    }

    #[test]
    fn tiles_cover_the_image_within_the_buffer() {
        assert_eq!(camera_scale_tiles(64, 64), CameraTiles { size: 1, across: 64, down: 64 });
        assert_eq!(camera_scale_tiles(256, 256).size, 1);
        assert_eq!(camera_scale_tiles(257, 256), CameraTiles { size: 2, across: 129, down: 128 });
        let hd = camera_scale_tiles(1920, 1080);
        assert_eq!((hd.size, hd.across, hd.down), (8, 240, 135));
        assert!(hd.count() <= SCALE_TILES);
        assert_eq!(hd.of(1919, 1079), hd.count() - 1);
        // One byte a scale: 1 and 16 exactly, steps of 2^(1/32), clamped at 2^(255/32).
        assert_eq!((encode_scale(1.0), encode_scale(16.0), encode_scale(1e9)), (0, 128, 255));
        assert_eq!((decode_scale(0), decode_scale(128)), (1.0, 16.0));
        assert!((decode_scale(encode_scale(10.0)) / 10.0 - 1.0).abs() < 0.011);
        // A tile's scale from its pixels' summed moments.
        let tiles = CameraTiles { size: 2, across: 1, down: 1 };
        let scales = camera_tile_scales(tiles, 2, &[2.0, 2.0, 0.0, 0.0], &[0.04, 0.04, 0.0, 0.0]);
        assert!((scales[0] - 10.0).abs() < 1e-4, "{scales:?}");
    }

    #[test]
    fn the_pilot_runs_for_direct_renders_long_enough() {
        let direct = RenderSettings { method: Method::Direct, ..Default::default() };
        assert_eq!(default_camera_pilot(&direct, Budget::Samples(CAMERA_PILOT_FROM_SPP)), CAMERA_PILOT_SPP);
        assert_eq!(default_camera_pilot(&direct, Budget::Samples(CAMERA_PILOT_FROM_SPP - 1)), 0);
        assert_eq!(default_camera_pilot(&direct, Budget::Time(std::time::Duration::from_secs(1))), CAMERA_PILOT_SPP);
        let combined = RenderSettings { method: Method::Combined, ..direct.clone() };
        assert_eq!(default_camera_pilot(&combined, Budget::Samples(CAMERA_PILOT_FROM_SPP)), CAMERA_PILOT_SPP);
        for method in [Method::Path, Method::Ellipsoidal, Method::Auto] {
            let other = RenderSettings { method, ..Default::default() };
            assert_eq!(default_camera_pilot(&other, Budget::Samples(1 << 20)), 0, "{}", method.name());
        }
        let transient = RenderSettings { gate: crate::film::Gate::parse("transient:3,0.1,8").unwrap(), ..direct };
        assert_eq!(default_camera_pilot(&transient, Budget::Samples(1 << 20)), 0, "a transient gate");
    }
}
