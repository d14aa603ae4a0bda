//! Integrators and the render loop: `path` is the wavefront path tracer (docs/design.md section
//! 4.1); `bidirectional` serves `direct` and `ellipsoidal` (bidirectional path tracing with
//! direct or ellipsoidal connections, sections 4.2 to 4.4); `combined` joins the two in one
//! estimator; `mis` is the CPU twin of the connections' MIS weights.

pub mod auto;
pub mod band_index;
pub mod bidirectional;
pub mod checkpoint;
pub mod combined;
pub mod mis;
pub mod path;
pub mod wavefront;

use std::ops::ControlFlow;
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Result;

use serde_json::json;

use crate::film::output::Metadata;
use crate::film::target::TargetSampler;
use crate::film::{Film, Gate};
use crate::gpu::GpuContext;
use crate::gpu::Resources;
use crate::gpu::layout::{
    MAX_UNIFORM_LIGHTS, MAX_UNIFORM_MATERIALS, NONE, RenderParams, TargetParams, TriangleShading, WaveParams,
};
use crate::gpu::resources::ChunkLayout;
use crate::scene::PreparedScene;
pub use bidirectional::{BidirectionalTracer, StrategyStats};
pub use path::{FILM_ELEMENT_BYTES, PathTracer, film_elements};
pub use wavefront::Wavefront;

/// Sampling strategy (`--method`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// Unidirectional path tracing with next-event estimation and MIS.
    Path,
    /// Bidirectional path tracing with direct connections.
    Direct,
    /// Bidirectional path tracing with ellipsoidal connections.
    Ellipsoidal,
    /// Direct and ellipsoidal connections in one estimator: each pixel sample takes one sample
    /// of each family, weighted by a balance heuristic between the families (module combined).
    Combined,
    /// Path, direct or (with a gate) ellipsoidal, whichever a short pilot of each on this render
    /// measures to have the lowest variance x time per sample (module auto).
    Auto,
}

impl Method {
    /// The name used on the command line and in metadata.
    pub fn name(self) -> &'static str {
        match self {
            Method::Path => "path",
            Method::Direct => "direct",
            Method::Ellipsoidal => "ellipsoidal",
            Method::Combined => "combined",
            Method::Auto => "auto",
        }
    }

    /// The method of a name as the command line spells it (`name`), for the command line's
    /// `--method`, the benchmarks' method lists and the Python bindings.
    pub fn parse(name: &str) -> anyhow::Result<Method> {
        Ok(match name {
            "path" => Method::Path,
            "direct" => Method::Direct,
            "ellipsoidal" => Method::Ellipsoidal,
            "combined" => Method::Combined,
            "auto" => Method::Auto,
            other => anyhow::bail!("method `{other}`: choose path, direct, ellipsoidal, combined or auto"),
        })
    }
}

/// How paths reach area lights (the LIGHT_STRATEGY override of `extend_paths`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightStrategy {
    /// Light sampling and BSDF sampling combined by the power heuristic.
    Mis = 0,
    /// Light sampling (next-event estimation) only.
    NextEvent = 1,
    /// BSDF sampling only (point lights still use next-event estimation).
    Bsdf = 2,
}

/// Everything that defines a render besides the scene and the sample budget.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Sampling method.
    pub method: Method,
    /// Pathlength importance W.
    pub gate: Gate,
    /// Paths keep at most this many scattering vertices (0: lights seen directly).
    pub max_bounces: u32,
    /// Russian roulette from this many scattering vertices on; None: never.
    pub rr_depth: Option<u32>,
    /// Render seed: equal seeds and settings give identical images.
    pub seed: u32,
    /// Samples per pixel of one pass (traced together when they fit the device); None
    /// chooses from the image size.
    pub samples_per_pass: Option<u32>,
    /// How area lights are reached (MIS by default; the single strategies are for tests).
    pub light_strategy: LightStrategy,
    /// Count connections per (s, t) strategy (`--stats`; bidirectional methods).
    pub stats: bool,
    /// Only this (s, t) strategy contributes, MIS-weighted (`--debug-strategy`; `direct`).
    pub debug_strategy: Option<(u32, u32)>,
    /// Largest storage binding to use (bytes); None: the device's limit. Smaller values force
    /// the split-array layout (used by tests to check it against the unsplit one).
    pub binding_limit: Option<u64>,
    /// K, the connections drawn from one ellipsoid query (`--connections-per-query`, 1 ..=
    /// [`bidirectional::MAX_CONNECTIONS_PER_QUERY`]; 1 for the other methods): K independent
    /// picks share one BVH traversal, each weighted 1/K. The default, 1, is the only value
    /// `path` and `direct` take; the command line and the viewer give `ellipsoidal`
    /// [`bidirectional::default_connections_per_query`].
    pub connections_per_query: u32,
    /// How `ellipsoidal`'s ellipsoid queries traverse the BVH.
    pub query: QuerySettings,
    /// Where `ellipsoidal` leaves out connections f32 cannot place (numerical studies).
    pub ellipsoid_guards: EllipsoidGuards,
    /// An NLOS capture (`--nlos`): pixels are sensed points of a relay wall lit by a laser spot,
    /// and the image's width x height is the grid of sensed points (see [`crate::nlos`]).
    pub nlos: Option<crate::nlos::NlosCapture>,
    /// `ellipsoidal` on a transient gate: samples per pixel of a pilot render, traced before
    /// the first pass and then discarded, whose transient shares out extra visits of each
    /// pixel's bins (`film::target::visit_tables`); 0: none, every bin gets the same share of
    /// the samples. `--target-pilot`; `render --nlos` gives `ellipsoidal`
    /// [`bidirectional::DEFAULT_NLOS_TARGET_PILOT`].
    pub target_pilot_spp: u32,
    /// `ellipsoidal` NLOS captures on a transient gate: build the band index (see
    /// [`band_index`]) before the first pass and draw each connection between a pixel's laser
    /// spot and its sensed point from it, instead of descending the whole BVH
    /// (`render --band-index on`; off by default).
    pub band_index: bool,
    /// `combined`: samples per pixel of the ellipsoidal half per sample of the direct half
    /// (dimensionless, 1 / [`combined::MAX_SHARE`] ..= MAX_SHARE); None: a render's pilot
    /// chooses it (see [`combined::allocate`]), an integrator built directly takes 1.
    pub ellipsoidal_share: Option<f64>,
}

/// How an ellipsoid query traverses the BVH (shaders/lib/ellipsoid_query.wesl): every child
/// the spheroid may touch near the root, a stochastic descent (one child at a time, in
/// proportion to an estimate of the arcs below it) into nodes that are small against the
/// spheroid, and every node of the small subtrees a descent ends in. Any setting is unbiased;
/// they trade work per query against variance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QuerySettings {
    /// Nodes whose box diagonal is at most `split` times the spheroid's semi-major axis are
    /// entered by a descent (dimensionless); 0: the exhaustive query, which visits every node
    /// the spheroid may touch (cost grows with the triangles near the spheroid).
    pub split: f32,
    /// A descent visits whole subtrees of at most this many BVH nodes.
    pub bottom_nodes: u32,
    /// Loop iterations (node boxes and triangles) after which a query finishes with one descent
    /// over the rest of the tree: bounds every query's work, which lavapipe needs (it ends an
    /// invocation's loops after 65535 iterations in total). Unbiased like the rest.
    pub allowance: u32,
    /// Weigh a triangle's pick by its arcs' angle times the reflection factor (an estimate of
    /// its contribution per radian, zero only where the contribution is; see
    /// `ellipsoid::query::reflection_factor`); false (the default; `render --nlos` sets it): by
    /// the arcs' angle alone. Both unbiased.
    pub reflection_weights: bool,
}

impl QuerySettings {
    /// The exhaustive query (every node the spheroid may touch, up to the allowance).
    pub const EXHAUSTIVE: Self = Self { split: 0.0, bottom_nodes: 31, allowance: 4096, reflection_weights: false };
}

impl Default for QuerySettings {
    fn default() -> Self {
        Self { split: 1.0, bottom_nodes: 31, allowance: 4096, reflection_weights: false }
    }
}

/// The two numerical guards of ellipsoidal connections, relative (dimensionless). Each leaves
/// out a set of connections that only grows with the guard, so rendering with a larger guard
/// bounds the bias of a smaller one from above (the `needle_guard` and `length_guard` tests).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EllipsoidGuards {
    /// Spheroids with tau_e <= d (1 + needle) are skipped, d the distance between the foci.
    pub needle: f32,
    /// Sampled points whose path length misses tau_e by more than length x tau_e are dropped.
    pub length: f32,
}

impl Default for EllipsoidGuards {
    fn default() -> Self {
        Self { needle: 1e-6, length: 1e-5 }
    }
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            width: 256,
            height: 256,
            method: Method::Path,
            gate: Gate::None,
            max_bounces: 8,
            rr_depth: None,
            seed: 0,
            samples_per_pass: None,
            light_strategy: LightStrategy::Mis,
            stats: false,
            debug_strategy: None,
            binding_limit: None,
            connections_per_query: 1,
            query: QuerySettings::default(),
            ellipsoid_guards: EllipsoidGuards::default(),
            nlos: None,
            target_pilot_spp: 0,
            band_index: false,
            ellipsoidal_share: None,
        }
    }
}

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
    /// What `--stats` prints about the work done so far, if the method keeps statistics.
    fn stats_report(&self) -> Result<Option<String>> {
        Ok(None)
    }
    /// Samples per pixel of the pilot render traced before the film's (discarded; see
    /// `RenderSettings::target_pilot_spp`), 0 for none.
    fn target_pilot_spp(&self) -> u32 {
        0
    }
    /// What became of the band index of an NLOS capture (`RenderSettings::band_index`): its
    /// size and build time, or why the capture went without; None when it was not asked for.
    fn band_index_report(&self) -> Option<String> {
        None
    }
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
    /// Traces one sample per pixel and discards it, so that a device that compiles kernels at
    /// their first dispatch (lavapipe does) does so before a time budget starts; then restarts
    /// from the render's seed, so the render that follows is the one it would have been without.
    /// Work that belongs to the render (a pilot) is left for its first pass.
    fn warm_up(&mut self) -> Result<()> {
        let seed = self.wavefront().params.seed;
        self.render_pass(1)?;
        self.restart(seed);
        Ok(())
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

/// How long to render.
#[derive(Clone, Copy, Debug)]
pub enum Budget {
    /// Exactly this many samples per pixel.
    Samples(u64),
    /// Passes sized by a [`PassSizer`] to end within this much rendering time (setup excluded).
    Time(Duration),
}

/// Sizes passes to a time budget from the measured time per sample per pixel, so a render, an
/// equal-time measurement or a viewer frame ends close to its budget instead of up to a whole
/// pass late (a pass of a large scene can take seconds on a CPU device).
#[derive(Clone, Copy, Debug, Default)]
pub struct PassSizer {
    /// Seconds one sample per pixel took in the last pass (None before any pass).
    seconds_per_sample: Option<f64>,
}

impl PassSizer {
    /// Samples per pixel of the next pass, at most `max`, predicted to end within `remaining`
    /// seconds (with 5 % to spare); one sample before anything was measured; None when even one
    /// sample is predicted to overrun.
    pub fn next(&self, remaining: f64, max: u32) -> Option<u32> {
        let Some(per_sample) = self.seconds_per_sample else {
            return Some(1);
        };
        let fit = 0.95 * remaining / per_sample.max(1e-12);
        (fit >= 1.0).then(|| (fit.min(max as f64) as u32).max(1))
    }

    /// Records a pass of `samples` samples per pixel that took `seconds`.
    pub fn record(&mut self, samples: u32, seconds: f64) {
        self.seconds_per_sample = Some(seconds / samples.max(1) as f64);
    }

    /// Renders passes on `tracer` until `seconds` have passed or the next pass would overrun
    /// them (at least one pass), calling `after_pass` after each (an error from it stops the
    /// render and is returned); returns the seconds spent.
    /// `after_pass` may stop the render early (`ControlFlow::Break`).
    pub fn render_for(
        &mut self,
        tracer: &mut dyn Integrator,
        seconds: f64,
        mut after_pass: impl FnMut(&dyn Integrator, f64) -> Result<ControlFlow<()>>,
    ) -> Result<f64> {
        let start = Instant::now();
        tracer.prepare()?;
        let mut passes = 0;
        loop {
            let remaining = seconds - start.elapsed().as_secs_f64();
            let next = match self.next(remaining, tracer.samples_per_pass()) {
                Some(n) => n,
                None if passes == 0 => 1,
                None => break,
            };
            let pass_start = Instant::now();
            tracer.render_pass(next)?;
            self.record(next, pass_start.elapsed().as_secs_f64());
            passes += 1;
            if after_pass(tracer, start.elapsed().as_secs_f64())?.is_break() {
                break;
            }
        }
        Ok(start.elapsed().as_secs_f64())
    }
}

/// Progress of a render, reported after every pass.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    /// Passes finished.
    pub passes: u64,
    /// Samples per pixel finished.
    pub spp: u64,
    /// Time since the render started (setup included).
    pub elapsed: Duration,
    /// Time since the first pass started (what a time budget counts).
    pub rendering: Duration,
}

/// A finished render.
pub struct RenderOutput {
    /// The estimate (samples per pixel in `film.spp`).
    pub film: Film,
    /// Wall time of the whole render: upload, kernel builds and passes.
    pub elapsed: Duration,
    /// Wall time of the passes alone (what a time budget counts).
    pub rendering: Duration,
    /// Ray traversals the device cut short (see [`Integrator::truncated_traversals`]).
    pub truncated_traversals: u64,
    /// The method's `--stats` report, when asked for.
    pub stats: Option<String>,
    /// Samples per pixel of the pilot render traced before the film's and discarded (see
    /// `RenderSettings::target_pilot_spp`).
    pub target_pilot_spp: u32,
    /// What became of the band index (see [`Integrator::band_index_report`]).
    pub band_index: Option<String>,
    /// Samples per pixel a stratified render needs before every bin has had one (see
    /// [`Integrator::samples_to_visit_every_bin`]); fewer leave bins estimated from the others.
    pub samples_to_visit_every_bin: Option<u64>,
    /// `--method auto`: the method chosen and the pilot's figures (its time is in `rendering`).
    pub choice: Option<auto::MethodChoice>,
    /// `--method combined`: how its samples were split between its halves (a pilot's time is
    /// in `rendering`).
    pub allocation: Option<combined::Allocation>,
    /// The render stopped before its budget was spent (see [`render_resumable`]).
    pub stopped_early: bool,
    /// The render's state after its last pass, when asked for (see [`render_resumable`]).
    pub state: Option<checkpoint::RenderState>,
}

impl RenderOutput {
    /// A warning for a render that ended before every bin of its stratified target lengths had
    /// a sample (see [`Integrator::samples_to_visit_every_bin`]), or None.
    pub fn unvisited_bins_warning(&self) -> Option<String> {
        let needed = self.samples_to_visit_every_bin.filter(|&n| (self.film.spp as u64) < n)?;
        Some(format!(
            "each sample of a pixel aims its ellipsoidal connections at one of the gate's {} bins in turn, and \
             {needed} samples per pixel visit every bin once (with the extra visits a pilot gives bins that hold more \
             light), but this render stopped at {}, so some bins had no sample of their own and are estimated from \
             samples aimed at others (unbiased, but noisier): render at least --spp {needed}",
            self.film.bins, self.film.spp
        ))
    }

    /// The black image of a render that traced nothing (no path can reach its gate), after
    /// `elapsed` of setup.
    pub fn black(settings: &RenderSettings, elapsed: Duration) -> Self {
        RenderOutput {
            film: Film::zeroed(settings.width, settings.height, settings.gate.bins()),
            elapsed,
            rendering: Duration::ZERO,
            truncated_traversals: 0,
            stats: None,
            target_pilot_spp: 0,
            band_index: None,
            samples_to_visit_every_bin: None,
            choice: None,
            allocation: None,
            stopped_early: false,
            state: None,
        }
    }
}

/// Seconds rounded to milliseconds, as metadata records them.
pub fn milli(seconds: f64) -> serde_json::Value {
    ((seconds * 1e3).round() / 1e3).into()
}

/// What every output records about its render (scene, settings, timing, device), as the
/// command line's outputs and the Python package give it: (key, typed value) pairs in order.
pub fn render_metadata(
    ctx: &GpuContext,
    scene_path: &Path,
    gate_spec: &str,
    settings: &RenderSettings,
    output: &RenderOutput,
) -> Metadata {
    let film = &output.film;
    let secs = output.elapsed.as_secs_f64();
    let gate = &settings.gate;
    let mut metadata: Metadata = vec![
        ("scene".into(), scene_path.display().to_string().into()),
        ("method".into(), settings.method.name().into()),
        ("gate".into(), gate_spec.into()),
        ("gate_parameters".into(), gate.parameters()),
        ("gate_description".into(), gate.describe().into()),
        ("spp".into(), film.spp.into()),
        ("seed".into(), settings.seed.into()),
        ("max_bounces".into(), settings.max_bounces.into()),
        ("rr_depth".into(), settings.rr_depth.into()),
        ("resolution".into(), json!([settings.width, settings.height])),
        ("elapsed_seconds".into(), milli(secs)),
        ("rendering_seconds".into(), milli(output.rendering.as_secs_f64())),
        ("adapter".into(), ctx.adapter_description().into()),
        ("truncated_traversals".into(), output.truncated_traversals.into()),
        (
            "units".into(),
            "bin-integrated radiance W m^-2 sr^-1 weighted by W; lengths are optical path in metres; resolution is \
             [width, height] in pixels; rr_depth null means Russian roulette is off"
                .into(),
        ),
        ("gatetrace_version".into(), env!("CARGO_PKG_VERSION").into()),
    ];
    if let Some((s, t)) = settings.debug_strategy {
        metadata.push(("debug_strategy".into(), json!([s, t])));
    }
    if let Some(allocation) = &output.allocation {
        metadata.push(("ellipsoidal_share".into(), allocation.ellipsoidal_share.into()));
        metadata.push(("combined_allocation".into(), allocation.reason.clone().into()));
    }
    if let Some(choice) = &output.choice {
        metadata.push(("chosen_method".into(), choice.chosen.name().into()));
        metadata.push(("auto_reason".into(), choice.reason.clone().into()));
        for c in &choice.candidates {
            metadata.push((
                format!("auto_pilot_{}", c.method.name()),
                json!({
                    "spp": c.spp,
                    "resolution": [choice.pilot_resolution.0, choice.pilot_resolution.1],
                    "seconds": c.seconds,
                    "variance_per_sample": c.variance_per_sample,
                    "variance_seconds_per_sample": c.cost(),
                }),
            ));
        }
    }
    if matches!(settings.method, Method::Ellipsoidal | Method::Auto) {
        let g = settings.ellipsoid_guards;
        metadata.push(("connections_per_query".into(), settings.connections_per_query.into()));
        metadata.push(("query_split".into(), settings.query.split.into()));
        metadata.push((
            "query_weights".into(),
            if settings.query.reflection_weights { "reflection" } else { "arcs" }.into(),
        ));
        metadata.push(("ellipsoid_guards".into(), json!({ "needle": g.needle, "length": g.length })));
        metadata.push(("target_pilot_spp".into(), output.target_pilot_spp.into()));
        if let Some(report) = &output.band_index {
            metadata.push(("band_index".into(), report.clone().into()));
        }
    }
    metadata
}

/// Traces `budget` on `tracer`, from its current state: exactly that many more samples per
/// pixel in as few passes as fit, or passes sized by a [`PassSizer`] to end within the time.
/// Calls `after_pass` with the tracer and the passes so far after each pass; an error from it
/// stops the render and is returned (the Python package stops on Ctrl-C this way).
pub fn trace_budget(
    tracer: &mut dyn Integrator,
    budget: Budget,
    mut after_pass: impl FnMut(&dyn Integrator, u64) -> Result<ControlFlow<()>>,
) -> Result<ControlFlow<()>> {
    let mut passes = 0;
    let mut flow = ControlFlow::Continue(());
    match budget {
        Budget::Samples(n) => {
            let target = tracer.samples_done() + n;
            while tracer.samples_done() < target && flow.is_continue() {
                let next = (target - tracer.samples_done()).min(tracer.samples_per_pass() as u64) as u32;
                tracer.render_pass(next)?;
                passes += 1;
                flow = after_pass(tracer, passes)?;
            }
        }
        Budget::Time(t) => {
            PassSizer::default().render_for(tracer, t.as_secs_f64(), |tracer, _| {
                passes += 1;
                flow = after_pass(tracer, passes)?;
                Ok(flow)
            })?;
        }
    }
    Ok(flow)
}

/// Why no path of the scene can reach the gate, if none can (checked before any work).
pub fn unreachable_gate(scene: &PreparedScene, settings: &RenderSettings) -> Option<String> {
    if settings.nlos.is_some() {
        // The bounds below run from the pinhole to the lights, which a capture does not use.
        return None;
    }
    let (shortest, longest) = scene.scene.path_length_bounds(settings.max_bounces);
    let gate = &settings.gate;
    if let Some(end) = gate.max_length()
        && end <= shortest as f64
    {
        return Some(format!(
            "gate {} ends at {end} m, but the shortest possible path (pinhole to the nearest light) is {shortest:.4} m",
            gate.describe()
        ));
    }
    if gate.min_length() > longest as f64 {
        return Some(format!(
            "gate {} starts at {} m, beyond the longest path possible with {} bounces in this scene ({longest:.4} m)",
            gate.describe(),
            gate.min_length(),
            settings.max_bounces
        ));
    }
    None
}

/// What to tell the user about a film that came out black (every value zero): why no path of
/// the scene can reach the gate, or that none of the samples did; and, where the gate's numbers
/// look like times typed as metres, the gate they probably meant. None for a film with light,
/// and for NLOS captures.
pub fn black_image_warning(
    scene: &PreparedScene,
    settings: &RenderSettings,
    gate_spec: &str,
    film: &Film,
) -> Option<String> {
    if settings.nlos.is_some() || film.data.iter().any(|&v| v != 0.0) {
        return None;
    }
    let (shortest, longest) = scene.scene.path_length_bounds(settings.max_bounces);
    let mut warning = match unreachable_gate(scene, settings) {
        Some(reason) => format!("{reason}: the image is black; no samples were traced"),
        None => format!(
            "the image is black: no path of its {} samples per pixel reached gate {} (paths of this scene with at \
             most {} bounces are {shortest:.3} to {longest:.3} m long)",
            film.spp,
            settings.gate.describe(),
            settings.max_bounces
        ),
    };
    if let Some(hint) = crate::film::gate::time_unit_hint(gate_spec, (shortest as f64, longest as f64)) {
        warning += &format!("; {hint}");
    }
    Some(warning)
}

/// The render-wide parameters of `settings` on `scene`, shared by every method's kernels.
pub fn render_params(scene: &PreparedScene, settings: &RenderSettings) -> RenderParams {
    let (light_bounds_min, light_bounds_max) = scene.scene.light_bounds();
    RenderParams {
        camera: scene.scene.camera.to_gpu(settings.width, settings.height),
        gate: settings.gate.to_gpu(),
        target_length: TargetParams {
            seed: settings.seed,
            ..target_sampler(scene, settings).map(|t| t.params).unwrap_or_default()
        },
        light_bounds_min,
        image_area: scene.scene.camera.image_area(settings.width, settings.height),
        light_bounds_max,
        width: settings.width,
        height: settings.height,
        seed: settings.seed,
        max_bounces: kernel_bounces(settings),
        rr_depth: settings.rr_depth.unwrap_or(NONE),
        light_count: scene.lights.lights.len() as u32,
        node_count: scene.bvh.nodes.len() as u32,
        ray_epsilon: scene.ray_epsilon,
        one: 1.0,
        ..Default::default()
    }
}

/// The scattering vertices the kernels' subpaths may have: `max_bounces`, less one in an NLOS
/// capture, whose laser spot is a bounce to the user and a light to the kernels.
pub fn kernel_bounces(settings: &RenderSettings) -> u32 {
    if settings.nlos.is_some() { settings.max_bounces.saturating_sub(1) } else { settings.max_bounces }
}

/// Target-length sampling of the settings' gate over the path lengths the scene allows with
/// its bounces (None for `none`, or when no path can reach the gate).
pub fn target_sampler(scene: &PreparedScene, settings: &RenderSettings) -> Option<TargetSampler> {
    let (shortest, longest) = match &settings.nlos {
        // A capture's paths run from a laser spot to a sensed point, with at most max_bounces + 1
        // segments counting the laser's and the sensor's, none longer than the diagonal of the
        // scene's bounds with both origins.
        Some(capture) => {
            let (lo, hi) = scene.scene.bounds();
            let (lo, hi) = (
                lo.min(capture.sensor_origin).min(capture.laser_origin),
                hi.max(capture.sensor_origin).max(capture.laser_origin),
            );
            (0.0, (settings.max_bounces as f32 + 1.0) * (hi - lo).length())
        }
        None => scene.scene.path_length_bounds(settings.max_bounces),
    };
    TargetSampler::new(&settings.gate, (shortest as f64, longest as f64))
}

/// Uploads what every method's kernels read (params, scene, lights, gate table) and creates the
/// film; returns the resources, the specialisation constants of the scene and the gate, and the
/// film's chunk layout.
pub fn upload_scene(
    ctx: &GpuContext,
    scene: &PreparedScene,
    settings: &RenderSettings,
    params: &RenderParams,
    limit: u64,
) -> Result<(Resources, Vec<(&'static str, f64)>, ChunkLayout)> {
    let gate = &settings.gate;
    let mut r = Resources::default();
    r.uniform_init(ctx, "params", params);
    r.uniform_init(ctx, "wave", &WaveParams::default());
    let triangles = r.storage_chunked_init(ctx, "triangles", &scene.triangles, limit)?;
    // The kernels read shading data only for vertex normals and texture coordinates
    // (scene.wesl `surface_at`): flat untextured scenes upload none (64 bytes a triangle, which
    // would not fit the bindings of a 10-million-triangle mesh on lavapipe).
    let shading: &[TriangleShading] =
        if scene.has_shading_normals() || scene.has_textures() { &scene.shading } else { &scene.shading[..1] };
    let triangle_shading = r.storage_chunked_init(ctx, "triangle_shading", shading, limit)?;
    let bvh_nodes = r.storage_chunked_init(ctx, "bvh_nodes", &scene.bvh.nodes, limit)?;
    r.storage_init(ctx, "wide_nodes", &scene.wide.nodes)?;
    let bvh_node_surfaces = r.storage_chunked_init(ctx, "bvh_node_surfaces", &scene.node_surfaces, limit)?;
    let small_scene = crate::bvh::small_scene_triangles(&scene.triangles);
    let small = small_scene.len();
    let small_normals: Vec<[f32; 4]> = scene.normals[..small].iter().map(|n| [n[0], n[1], 0.0, 0.0]).collect();
    let max_small = crate::bvh::MAX_SMALL_SCENE_TRIANGLES;
    r.uniform_slice_init(ctx, "small_scene_triangles", &padded_table(small_scene, max_small));
    r.uniform_slice_init(ctx, "small_scene_shading", &padded_table(&scene.shading[..small], max_small));
    r.uniform_slice_init(ctx, "small_scene_normals", &padded_table(&small_normals, max_small));
    r.storage_init(ctx, "triangle_normals", &scene.normals)?;
    r.storage_init(ctx, "materials", &scene.materials)?;
    r.storage_init(ctx, "texture_infos", &scene.texture_infos)?;
    r.storage_init(ctx, "texels", &scene.texels)?;
    r.storage_init(ctx, "lights", &scene.lights.lights)?;
    r.storage_init(ctx, "light_cdf", &scene.lights.cdf)?;
    let tables_in_uniforms =
        scene.materials.len() <= MAX_UNIFORM_MATERIALS && scene.lights.lights.len() <= MAX_UNIFORM_LIGHTS;
    r.uniform_slice_init(ctx, "uniform_materials", &padded_table(&scene.materials, MAX_UNIFORM_MATERIALS));
    r.uniform_slice_init(ctx, "uniform_lights", &padded_table(&scene.lights.lights, MAX_UNIFORM_LIGHTS));
    r.uniform_slice_init(ctx, "uniform_light_cdf", &padded_table(&scene.lights.cdf, MAX_UNIFORM_LIGHTS));
    r.storage_init(ctx, "gate_table", &gate.table())?;
    let wall_points = match &settings.nlos {
        Some(capture) => crate::nlos::wall_points(scene, capture, settings.width, settings.height)?,
        None => vec![crate::gpu::layout::WallPoint::default()],
    };
    r.storage_init(ctx, "wall_points", &wall_points)?;
    let cdf = target_sampler(scene, settings).map_or(vec![0.0, 1.0], |t| t.cdf);
    r.storage_init(ctx, "target_cdf", &cdf)?;
    // Extra target-length visits come from a pilot render (BidirectionalTracer), if any.
    r.storage_init(ctx, "target_visits", &[0u32])?;
    let film_len = film_elements(settings)?;
    check_film_memory(ctx, settings, film_len)?;
    let film = r.storage_chunked_zeroed(ctx, "film", film_len, FILM_ELEMENT_BYTES, limit)?;
    let flag = |b: bool| b as u32 as f64;
    let constants = vec![
        ("GATE_KIND", gate.kind() as u32 as f64),
        ("HAS_TEXTURES", flag(scene.has_textures())),
        ("HAS_SHADING_NORMALS", flag(scene.has_shading_normals())),
        ("HAS_POINT_LIGHTS", flag(scene.has_point_lights())),
        ("HAS_DIRECTIONAL_LIGHTS", flag(!scene.scene.directional_lights.is_empty())),
        ("HAS_GLOSSY", flag(scene.has_glossy())),
        ("TRIANGLES_PER_CHUNK", triangles.per_chunk as f64),
        ("TRIANGLE_SHADING_PER_CHUNK", triangle_shading.per_chunk as f64),
        ("BVH_NODES_PER_CHUNK", bvh_nodes.per_chunk as f64),
        ("BVH_NODE_SURFACES_PER_CHUNK", bvh_node_surfaces.per_chunk as f64),
        ("FILM_PER_CHUNK", film.per_chunk as f64),
        ("TRAVERSAL_BUDGET", crate::bvh::wide::TRAVERSAL_BUDGET as f64),
        ("SMALL_SCENE_TRIANGLES", small as f64),
        ("SCENE_TABLES_IN_UNIFORMS", flag(tables_in_uniforms)),
        ("RESUMABLE", flag(scene.wide.traversals_can_stop())),
        ("NLOS", flag(settings.nlos.is_some())),
    ];
    Ok((r, constants, film))
}

/// Refuses, before anything is allocated, a render whose films do not fit the memory available
/// (MemAvailable of /proc/meminfo): the host holds about three copies of each film when the
/// image is read back (staging buffer, sums, saved state) plus the f32 image, and a CPU device
/// (lavapipe) keeps the films themselves in the same memory. A GPU's free memory cannot be
/// asked for portably: there, running out is reported when a buffer is created
/// (`GpuContext::allocate`) or at the next wait (`GpuContext::wait_idle`).
fn check_film_memory(ctx: &GpuContext, settings: &RenderSettings, elements: u64) -> Result<()> {
    let films = if settings.method == Method::Path { 1 } else { 2 };
    let device = elements * FILM_ELEMENT_BYTES * films;
    let host = elements * (3 * FILM_ELEMENT_BYTES * films + 8);
    let needed = host + if ctx.is_cpu() { device } else { 0 };
    let available = std::fs::read_to_string("/proc/meminfo").ok().and_then(|m| {
        let line = m.lines().find(|l| l.starts_with("MemAvailable:"))?;
        line.split_whitespace().nth(1)?.parse::<u64>().ok().map(|kib| kib * 1024)
    });
    if let Some(available) = available {
        let gib = |b: u64| b as f64 / (1u64 << 30) as f64;
        anyhow::ensure!(
            needed <= available,
            "--res {}x{} with {} bins: the film{} and {} copies need about {:.1} GiB of memory, more than the {:.1} GiB \
             available; reduce the resolution or the bins",
            settings.width,
            settings.height,
            settings.gate.bins(),
            if films > 1 { "s of a bidirectional method" } else { "" },
            if films > 1 { "their" } else { "its" },
            gib(needed),
            gib(available)
        );
    }
    Ok(())
}

/// The first `len` elements of `table`, zero-padded to `len`: the contents of a uniform buffer
/// holding a fixed-length WGSL array (unused when the table is longer, see the overrides that
/// select them).
fn padded_table<T: bytemuck::Pod + Default>(table: &[T], len: usize) -> Vec<T> {
    let mut padded = table[..table.len().min(len)].to_vec();
    padded.resize(len, T::default());
    padded
}

/// Renders `scene` with `settings` until `budget` is spent, calling `progress` after each pass.
pub fn render(
    ctx: &GpuContext,
    scene: &PreparedScene,
    settings: &RenderSettings,
    budget: Budget,
    mut progress: impl FnMut(Progress),
) -> Result<RenderOutput> {
    render_resumable(ctx, scene, settings, budget, RenderStart::default(), |_, p| {
        progress(p);
        Ok(ControlFlow::Continue(()))
    })
}

/// Where a render starts and what it keeps (see [`render_resumable`]).
#[derive(Clone, Copy, Default)]
pub struct RenderStart<'a> {
    /// Continue this saved render (see [`checkpoint`]); the budget then counts the whole
    /// render: samples per pixel in all, or seconds of rendering in all. `auto` renders with
    /// the method the saved render chose, without a new pilot.
    pub resume: Option<&'a checkpoint::RenderState>,
    /// Skip this many samples per pixel of the sequence first (a shard renders its slice).
    pub skip_samples: u64,
    /// Keep the state after the last pass in the output (`RenderOutput::state`).
    pub keep_state: bool,
}

/// [`render`] from `start`, asking `after_pass` after every pass whether to go on: it gets the
/// integrator (to save its state) and the progress, and may stop the render early
/// (`ControlFlow::Break`; the output then has the samples traced so far and `stopped_early`
/// set).
pub fn render_resumable(
    ctx: &GpuContext,
    scene: &PreparedScene,
    settings: &RenderSettings,
    budget: Budget,
    start_at: RenderStart,
    mut after_pass: impl FnMut(&dyn Integrator, Progress) -> Result<ControlFlow<()>>,
) -> Result<RenderOutput> {
    film_elements(settings)?;
    let start = Instant::now();
    if unreachable_gate(scene, settings).is_some() {
        // No samples are traced; black_image_warning says why.
        return Ok(RenderOutput::black(settings, start.elapsed()));
    }
    // auto: a pilot of both methods (counted against a time budget) picks the one to render with.
    let resume = start_at.resume;
    let choice = if settings.method == Method::Auto && resume.is_none() {
        Some(auto::choose(ctx, scene, settings, budget)?)
    } else {
        None
    };
    // combined: a pilot of both halves (counted against a time budget) splits the samples.
    let allocation = if settings.method == Method::Combined && resume.is_none() {
        Some(combined::allocate(ctx, scene, settings, budget)?)
    } else {
        None
    };
    let render_settings = match (&choice, &allocation, resume) {
        (Some(c), _, _) => auto::candidate_settings(settings, c.chosen),
        (None, Some(a), _) => RenderSettings { ellipsoidal_share: Some(a.ellipsoidal_share), ..settings.clone() },
        (None, None, Some(state)) if settings.method == Method::Auto => {
            auto::candidate_settings(settings, state.method)
        }
        _ => settings.clone(),
    };
    let mut tracer = create_integrator(ctx, scene, &render_settings)?;
    if let Budget::Time(_) = budget {
        // A device may compile kernels at their first dispatch (lavapipe does): a pass of one
        // sample, discarded, keeps that out of the budget and out of the rate passes are sized by.
        tracer.warm_up()?;
    }
    let before = match resume {
        Some(state) => {
            tracer.load_state(state)?;
            Duration::try_from_secs_f64(state.rendering_seconds).unwrap_or_default()
        }
        None => Duration::ZERO,
    };
    if start_at.skip_samples > 0 || start_at.keep_state {
        // (With a kept state, the pilot runs even when no sample is traced: every shard's state
        // then records the same pilot.)
        tracer.skip_samples(start_at.skip_samples)?;
    }
    let pilot = before
        + Duration::from_secs_f64(choice.as_ref().map_or(0.0, |c| c.pilot_seconds))
        + Duration::from_secs_f64(allocation.as_ref().map_or(0.0, |a| a.pilot_seconds));
    let budget = match budget {
        Budget::Time(t) => Budget::Time(t.saturating_sub(pilot)),
        Budget::Samples(n) => Budget::Samples(n.saturating_sub(tracer.samples_done())),
    };
    let rendering = Instant::now();
    let flow = trace_budget(tracer.as_mut(), budget, |tracer, passes| {
        let (elapsed, rendering) = (start.elapsed(), pilot + rendering.elapsed());
        after_pass(tracer, Progress { passes, spp: tracer.samples_done(), elapsed, rendering })
    })?;
    let rendering = pilot + rendering.elapsed();
    let film = tracer.film()?;
    let truncated_traversals = tracer.truncated_traversals()?;
    if truncated_traversals > 0 {
        eprintln!(
            "warning: {truncated_traversals} ray traversals were cut short by the device (lavapipe ends a shader's \
             loops after 65535 iterations); the image may miss geometry. Use a GPU for this scene."
        );
    }
    let stats = if settings.stats { tracer.stats_report()? } else { None };
    let target_pilot_spp = tracer.target_pilot_spp();
    let state = match start_at.keep_state {
        true => Some(checkpoint::RenderState { rendering_seconds: rendering.as_secs_f64(), ..tracer.save_state()? }),
        false => None,
    };
    Ok(RenderOutput {
        film,
        elapsed: start.elapsed(),
        rendering,
        truncated_traversals,
        stats,
        target_pilot_spp,
        band_index: tracer.band_index_report(),
        samples_to_visit_every_bin: tracer.samples_to_visit_every_bin(),
        choice,
        allocation,
        stopped_early: flow.is_break(),
        state,
    })
}

#[cfg(test)]
mod pass_sizer_tests {
    use super::PassSizer;

    #[test]
    fn passes_fit_the_time_left() {
        let mut sizer = PassSizer::default();
        assert_eq!(sizer.next(10.0, 64), Some(1), "one sample before anything is measured");
        sizer.record(10, 1.0);
        assert_eq!(sizer.next(100.0, 64), Some(64), "capped at a full pass");
        assert_eq!(sizer.next(0.5, 64), Some(4), "0.95 x 0.5 s at 0.1 s per sample");
        assert_eq!(sizer.next(0.1, 64), None, "one sample would overrun");
        sizer.record(1, 0.01);
        assert_eq!(sizer.next(0.1, 64), Some(9), "the latest pass's rate counts");
    }
}
