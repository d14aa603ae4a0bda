//! Integrators and the render loop: `path` is the wavefront path tracer (docs/design.md section
//! 4.1); `bidirectional` serves `direct` and `ellipsoidal` (bidirectional path tracing with
//! direct or ellipsoidal connections, sections 4.2 to 4.4); `combined` joins the two in one
//! estimator; `mis` is the CPU twin of the connections' MIS weights. This module holds the
//! [`Integrator`] trait, [`create_integrator`] and [`check_settings`]; `settings` the render
//! settings and budgets, `upload` what every method puts on the device, `wavefront` the state
//! and wave plan every method shares, `render_loop` the passes of a render and `metadata` what
//! its outputs record.

pub mod auto;
pub mod bidirectional;
pub mod checkpoint;
pub mod combined;
pub mod metadata;
pub mod mis;
pub mod path;
pub mod pilot;
pub mod query_roulette;
pub mod render_loop;
pub mod settings;
pub mod upload;
pub mod wavefront;

use anyhow::{Result, ensure};

use crate::film::Film;
use crate::gpu::GpuContext;
use crate::gpu::Resources;
use crate::scene::PreparedScene;
pub use bidirectional::{BidirectionalTracer, StrategyStats};
pub use metadata::{milli, render_metadata};
pub use path::PathTracer;
pub use render_loop::{
    PassSizer, Progress, RenderOutput, RenderStart, black_image_warning, render, render_resumable, trace_budget,
    unreachable_gate,
};
pub use settings::{Budget, EllipsoidGuards, LightStrategy, Method, QuerySettings, RenderSettings};
pub use upload::{kernel_bounces, render_params, target_sampler, upload_scene};
pub use wavefront::{FILM_ELEMENT_BYTES, Wavefront, film_elements};

/// A renderer bound to one scene and one set of settings, accumulating into its film.
pub trait Integrator: Send {
    /// The state every wavefront method keeps.
    fn wavefront(&self) -> &Wavefront<'_>;
    /// Traces `samples` (1 ..= `samples_per_pass`) more samples of every pixel and adds them to
    /// the film; returns when the GPU has finished.
    fn render_pass(&mut self, samples: u32) -> Result<()>;
    /// Clears the film; later samples continue the random sequence and target lengths get a new
    /// seed (`film::target::next_target_seed`), so the next estimate is independent of the
    /// previous one (for batch statistics).
    fn reset_film(&mut self);
    /// Starts afresh from `seed`: clears the film and restarts the random sequence and the
    /// target lengths exactly as a newly built integrator with that seed would, so the next
    /// passes give its image bit for bit, without rebuilding kernels or buffers (the Python
    /// package's renders reuse one integrator).
    fn restart(&mut self, seed: u32);
    /// Moves to `settings.gate` (everything else as when built) and clears the film, without
    /// rebuilding kernels or buffers when the gate has the same kind, bins and table length
    /// (the viewer scrubbing tau). Returns false, changing nothing, when a new integrator is
    /// needed instead.
    fn set_gate(&mut self, scene: &PreparedScene, settings: &RenderSettings) -> Result<bool>;
    /// The film's current estimate (sums divided by the samples per pixel): the film of its
    /// state (see [`wavefront::film_of_state`]), so that a render, a resumed one and merged
    /// shards turn equal sums into equal images.
    ///
    /// An error when a contribution was NaN, infinite or beyond the film's range (a bug or a
    /// scene far outside physical values), which the sums could not hold.
    fn film(&self) -> Result<Film> {
        let invalid = self.wavefront().counters()?.invalid_contributions;
        anyhow::ensure!(
            invalid == 0,
            "{invalid} contributions were NaN, infinite or of 2^63 (9.2e18) or more, which the film cannot hold: \
             the image would be wrong"
        );
        wavefront::film_of_state(&self.save_state()?)
    }
    /// The named buffers the kernels bind (scene, wavefront state, film).
    fn resources(&self) -> &Resources {
        &self.wavefront().resources
    }
    /// The specialisation constants every kernel of this render gets.
    fn constants(&self) -> &[(&'static str, f64)] {
        &self.wavefront().constants
    }
    /// Samples per pixel of a full pass.
    fn samples_per_pass(&self) -> u32 {
        self.wavefront().samples_per_pass
    }
    /// Samples per pixel accumulated in the film since the last reset.
    fn samples_done(&self) -> u64 {
        self.wavefront().samples_in_film
    }
    /// Ray traversals the device cut short so far (lavapipe ends a shader invocation's loops
    /// after 65535 iterations in total); nonzero means the image may miss geometry.
    fn truncated_traversals(&self) -> Result<u64> {
        Ok(self.wavefront().counters()?.truncated_traversals as u64)
    }
    /// The scales of the camera's density in the MIS weights the film's samples are weighed
    /// with, one per tile (`bidirectional::camera_pilot`): empty for a method without them,
    /// every one 1 before its camera pilot has run.
    fn camera_mis_scales(&self) -> &[f32] {
        &[]
    }
    /// Weighs the film's samples from now on with `scales` (one per tile of an image of this
    /// tracer's size), which the camera pilot of `traced` samples per pixel of another tracer
    /// measured, in place of a camera pilot of its own: a pilot's candidates share one (see
    /// `pilot::CameraScalesOnce`). Nothing for a tracer that does not weigh with camera scales.
    fn adopt_camera_mis_scales(&mut self, _scales: &[f32], _traced: u32) {}
    /// What `--stats` prints about the work done so far, if the method keeps statistics.
    fn stats_report(&self) -> Result<Option<String>> {
        Ok(None)
    }
    /// Samples per pixel of the pilot render traced before the film's (discarded; see
    /// `RenderSettings::target_pilot_spp`), 0 for none.
    fn target_pilot_spp(&self) -> u32 {
        0
    }
    /// Samples per pixel of the camera pilot whose scales weigh the film's samples (see
    /// `RenderSettings::camera_pilot_spp`), 0 for none.
    fn camera_pilot_spp(&self) -> u32 {
        0
    }
    /// What became of the band index of an NLOS capture (`RenderSettings::band_index`): its
    /// size and build time, or why the capture went without; None when it was not asked for.
    fn band_index_report(&self) -> Option<String> {
        None
    }
    /// Why an NLOS capture that asked for the band index goes without it, if it does.
    fn band_index_off(&self) -> Option<String> {
        None
    }
    /// The time budget (s) of the render about to start, None for a render by samples (called
    /// before `prepare`): work before the first pass that would outlast it is left out where the
    /// render can go without it (the band index's build,
    /// [`crate::nlos::band_index::BuildClock`]), and tried again at the next render.
    fn set_time_budget(&mut self, _seconds: Option<f64>) {}
    /// Samples per pixel after which every bin of a transient gate's stratified target lengths
    /// has had one (`film::target::samples_to_visit_every_bin`); None for other methods and gates.
    fn samples_to_visit_every_bin(&self) -> Option<u64> {
        None
    }
    /// Work a render does once before its first pass (`BidirectionalTracer`: the pilot render
    /// of `RenderSettings::target_pilot_spp`); `render_pass` does it when it has not been done.
    /// A time budget counts it, but the pass sizer's rate of samples does not.
    fn prepare(&mut self) -> Result<()> {
        Ok(())
    }
    /// Traces later passes over only the first `pixels` pixels of the image (all of them with
    /// None): the warm-up pass's block ([`wavefront::WARM_UP_PIXELS`]).
    fn limit_pass_pixels(&mut self, pixels: Option<u32>);
    /// Traces one sample of each of the first [`wavefront::WARM_UP_PIXELS`] pixels and discards
    /// it, so that a device that compiles kernels at their first dispatch (lavapipe does) does
    /// so, and clears the buffers it clears at their first use, before a time budget starts;
    /// then restarts from the render's seed, so the render that follows is the one it would
    /// have been without. Work that belongs to the render (a pilot) is left for its first pass.
    fn warm_up(&mut self) -> Result<()> {
        let seed = self.wavefront().params.seed;
        self.warm_up_pass()?;
        self.restart(seed);
        Ok(())
    }
    /// The pass of [`Self::warm_up`], without the restart: one sample of the warm-up's block.
    fn warm_up_pass(&mut self) -> Result<()> {
        self.limit_pass_pixels(Some(wavefront::WARM_UP_PIXELS));
        let traced = self.render_pass(1);
        self.limit_pass_pixels(None);
        traced
    }
    /// Everything the render has accumulated so far (see [`checkpoint`]), to continue it in
    /// another process. `rendering_seconds` is left 0 for the caller to fill in.
    fn save_state(&self) -> Result<checkpoint::RenderState>;
    /// Continues the render whose state [`Self::save_state`] took: this integrator must have
    /// been built with the same scene and settings (it refuses states of another image size,
    /// method or kind). The next pass then traces the samples that render would have traced.
    fn load_state(&mut self, state: &checkpoint::RenderState) -> Result<()>;
    /// Moves the sample sequence `samples` samples per pixel on without tracing them, after the
    /// work a render does before its first pass ([`Self::prepare`]): a shard of a render
    /// traces its own slice of the samples, and the sums of all slices are the render's.
    fn skip_samples(&mut self, samples: u64) -> Result<()>;
    /// Traces `spp` more samples of every pixel, in as few passes as possible.
    fn render_samples(&mut self, spp: u64) -> Result<()> {
        let mut left = spp;
        while left > 0 {
            let n = left.min(self.samples_per_pass() as u64) as u32;
            self.render_pass(n)?;
            left -= n as u64;
        }
        Ok(())
    }
}

/// Errors for settings `direct`, `ellipsoidal`, `combined` or `auto` cannot render (checked
/// before any work; also reachable as `bidirectional::check_settings`): `auto` needs both its
/// bidirectional candidates valid, ellipsoidal only where it applies (it needs a gate).
pub fn check_settings(settings: &RenderSettings) -> Result<()> {
    match settings.method {
        Method::Combined => combined::check_settings(settings),
        Method::Auto => {
            bidirectional::check_tracer_settings(&auto::candidate_settings(settings, Method::Direct))?;
            if !matches!(settings.gate, crate::film::Gate::None) {
                bidirectional::check_tracer_settings(&auto::candidate_settings(settings, Method::Ellipsoidal))?;
            }
            Ok(())
        }
        _ => bidirectional::check_tracer_settings(settings),
    }
}

impl RenderSettings {
    /// Errors for settings that cannot render as asked, checked before any work: options of
    /// other methods, and each method's own limits ([`check_settings`]). The command line and
    /// the viewer call it; its messages name the command line's options.
    pub fn check(&self) -> Result<()> {
        ensure!(
            self.ellipsoidal_share.is_none() || self.method == Method::Combined,
            "--ellipsoidal-share applies to --method combined only"
        );
        ensure!(
            self.query_roulette.is_none()
                || matches!(self.method, Method::Ellipsoidal | Method::Combined | Method::Auto),
            "--query-roulette applies to --method ellipsoidal and combined (and auto's ellipsoidal choice) only"
        );
        ensure!(
            self.query_roulette.is_none() || self.nlos.is_none(),
            "--query-roulette does not apply to NLOS captures: their three-bounce queries are the signal"
        );
        ensure!(
            self.target_pilot_spp == 0 || self.method == Method::Ellipsoidal,
            "--target-pilot applies to --method ellipsoidal only"
        );
        ensure!(
            self.camera_pilot_spp.is_none_or(|spp| spp == 0 || bidirectional::camera_pilot_applies(self)),
            "--camera-pilot applies to --method direct with a camera (not --nlos), a gate of one bin and no \
             --debug-strategy"
        );
        ensure!(
            self.camera_pilot_spp.is_none_or(|spp| spp != 1),
            "--camera-pilot 1: the pilot's variance needs at least 2 samples per pixel (or 0 for none)"
        );
        ensure!(
            self.debug_strategy.is_none() || self.method == Method::Direct,
            "--debug-strategy needs --method direct"
        );
        match self.method {
            Method::Path => ensure!(
                self.connections_per_query == 1,
                "--connections-per-query applies to --method ellipsoidal and combined only"
            ),
            _ => check_settings(self)?,
        }
        Ok(())
    }
}

/// The integrator of `settings.method`, with the scene uploaded and its kernels built.
pub fn create_integrator<'a>(
    ctx: &'a GpuContext,
    scene: &PreparedScene,
    settings: &RenderSettings,
) -> Result<Box<dyn Integrator + 'a>> {
    Ok(match settings.method {
        Method::Path => Box::new(PathTracer::new(ctx, scene, settings)?),
        Method::Direct | Method::Ellipsoidal => Box::new(BidirectionalTracer::new(ctx, scene, settings)?),
        Method::Combined => Box::new(combined::CombinedTracer::new(ctx, scene, settings)?),
        Method::Auto => anyhow::bail!(
            "--method auto has no integrator of its own: it renders with path, direct or ellipsoidal after a pilot of \
             each (integrator::render); measure those instead"
        ),
    })
}
