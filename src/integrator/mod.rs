//! Integrators and the render loop. `path` is the wavefront path tracer (DESIGN.md section 4.1);
//! `direct` and `ellipsoidal` (bidirectional methods) are not available yet.

pub mod path;

use std::time::{Duration, Instant};

use anyhow::{Result, bail};

use crate::film::{Film, Gate};
use crate::gpu::GpuContext;
use crate::scene::PreparedScene;
pub use path::{PathTracer, film_elements};

/// Sampling strategy (`--method`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// Unidirectional path tracing with next-event estimation and MIS.
    Path,
    /// Bidirectional path tracing with direct connections.
    Direct,
    /// Bidirectional path tracing with ellipsoidal connections.
    Ellipsoidal,
}

impl Method {
    /// An error for the methods this version does not implement yet.
    pub fn ensure_available(self) -> Result<()> {
        match self {
            Method::Path => Ok(()),
            m => bail!(
                "--method {} is not yet available: this version implements `path` \
                 (bidirectional methods arrive in a later version)",
                m.name()
            ),
        }
    }

    /// The name used on the command line and in metadata.
    pub fn name(self) -> &'static str {
        match self {
            Method::Path => "path",
            Method::Direct => "direct",
            Method::Ellipsoidal => "ellipsoidal",
        }
    }
}

/// How paths reach area lights (the LIGHT_STRATEGY override of `shade`).
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
#[derive(Clone, Debug)]
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
    /// Largest storage binding to use (bytes); None: the device's limit. Smaller values force
    /// the split-array layout (used by tests to check it against the unsplit one).
    pub binding_limit: Option<u64>,
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
            binding_limit: None,
        }
    }
}

/// How long to render.
#[derive(Clone, Copy, Debug)]
pub enum Budget {
    /// Exactly this many samples per pixel.
    Samples(u64),
    /// Whole waves until this much wall time has passed.
    Time(Duration),
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
}

/// A finished render.
pub struct RenderOutput {
    /// The estimate (samples per pixel in `film.spp`).
    pub film: Film,
    /// Wall time of the whole render: upload, kernel builds and passes.
    pub elapsed: Duration,
    /// Ray traversals the device cut short (see `PathTracer::truncated_traversals`).
    pub truncated_traversals: u64,
}

/// Why no path of the scene can reach the gate, if none can (checked before any work).
pub fn unreachable_gate(scene: &PreparedScene, settings: &RenderSettings) -> Option<String> {
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

/// Renders `scene` with `settings` until `budget` is spent, calling `progress` after each wave.
pub fn render(
    ctx: &GpuContext,
    scene: &PreparedScene,
    settings: &RenderSettings,
    budget: Budget,
    mut progress: impl FnMut(Progress),
) -> Result<RenderOutput> {
    settings.method.ensure_available()?;
    film_elements(settings)?;
    let start = Instant::now();
    if let Some(reason) = unreachable_gate(scene, settings) {
        eprintln!("warning: {reason}: the image is black; no samples were traced");
        let g = &settings.gate;
        let film = Film::zeroed(settings.width, settings.height, g.bins());
        return Ok(RenderOutput { film, elapsed: start.elapsed(), truncated_traversals: 0 });
    }
    let mut tracer = PathTracer::new(ctx, scene, settings)?;
    let mut passes = 0;
    loop {
        let spp = tracer.samples_done();
        let next = match budget {
            Budget::Samples(n) if spp >= n => break,
            Budget::Samples(n) => (n - spp).min(tracer.samples_per_pass() as u64) as u32,
            Budget::Time(t) if start.elapsed() >= t && spp > 0 => break,
            Budget::Time(_) => tracer.samples_per_pass(),
        };
        tracer.render_pass(next)?;
        passes += 1;
        progress(Progress { passes, spp: tracer.samples_done(), elapsed: start.elapsed() });
    }
    let film = tracer.film()?;
    let truncated_traversals = tracer.truncated_traversals()?;
    if truncated_traversals > 0 {
        eprintln!(
            "warning: {truncated_traversals} ray traversals were cut short by the device (lavapipe ends a shader's \
             loops after 65535 iterations); the image may miss geometry. Use a GPU for this scene."
        );
    }
    Ok(RenderOutput { film, elapsed: start.elapsed(), truncated_traversals })
}
