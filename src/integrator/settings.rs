//! The settings of a render besides the scene: the method, the gate, the image size, the
//! bounces and each method's options ([`RenderSettings`]), and its budget of samples or time
//! ([`Budget`]).

pub use crate::ellipsoid::query::QuerySettings;
use std::time::Duration;

use crate::film::Gate;

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
    /// [`super::bidirectional::MAX_CONNECTIONS_PER_QUERY`]; 1 for the other methods): K
    /// independent picks share one BVH traversal, each weighted 1/K. The default, 1, is the only
    /// value `path` and `direct` take; the command line and the viewer give `ellipsoidal`
    /// [`super::bidirectional::default_connections_per_query`].
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
    /// [`super::bidirectional::DEFAULT_NLOS_TARGET_PILOT`].
    pub target_pilot_spp: u32,
    /// `direct` with a camera and a gate of one bin: samples per pixel of the camera pilot,
    /// traced before the first pass and then discarded, whose per-pixel variance scales the
    /// camera's density in the MIS weights (see [`super::bidirectional::camera_pilot`]); 0:
    /// none, the textbook power heuristic. None: a render chooses
    /// ([`super::bidirectional::default_camera_pilot`] of its budget), an integrator built
    /// directly takes none. `render --camera-pilot`.
    pub camera_pilot_spp: Option<u32>,
    /// `ellipsoidal` NLOS captures on a transient gate: build the band index (see
    /// [`crate::nlos::band_index`]) before the first pass and draw each connection between a pixel's
    /// laser spot and its sensed point from it, instead of descending the whole BVH (`render
    /// --band-index on`; off by default).
    pub band_index: bool,
    /// `combined`: samples per pixel of the ellipsoidal half per sample of the direct half
    /// (dimensionless, 1 / [`super::combined::MAX_SHARE`] ..= MAX_SHARE); None: a render's pilot
    /// chooses it (see [`super::combined::allocate`]), an integrator built directly takes 1.
    pub ellipsoidal_share: Option<f64>,
    /// `ellipsoidal` (not NLOS captures) and `combined`'s ellipsoidal half: the probability (1 /
    /// [`super::query_roulette::MAX_SKIP`] ..= 1) with which a sample makes each of its ellipsoid
    /// queries for paths of two or more scattering vertices, a query made weighing its inverse
    /// (unbiased for any); `render --query-roulette`. None: with a time budget a render's pilot
    /// chooses it (see [`super::query_roulette::choose`], [`super::combined::allocate`]),
    /// otherwise, and for an integrator built directly, 1 (every query).
    pub query_roulette: Option<f32>,
    /// `path` in scenes with homogeneous media on a box or transient gate: also place scattering
    /// vertices where a flight's ray meets the spheroid of a target length drawn from the gate
    /// (medium connections, docs/design.md section 4.1; `render --medium-connections`). Off by
    /// default: free flights alone place them.
    pub medium_connections: bool,
    /// Most bytes of per-slot state (subpath vertices, queues, path states) one wave aims for;
    /// None: the tracer's own target for the device. A bounded wave still holds
    /// `wavefront::BOUNDED_WAVE_SAMPLES` samples of every pixel where the device's bindings fit
    /// them. Pilots, whose images are small and whose tracers live for a few
    /// batches, ask for [`super::pilot::PILOT_WAVE_BYTES`]: the device clears a tracer's
    /// buffers before their first use, and on CPU Vulkan clearing a full wave for each of a
    /// pilot's tracers was most of its start-up.
    pub wave_bytes: Option<u64>,
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
            camera_pilot_spp: None,
            band_index: false,
            ellipsoidal_share: None,
            query_roulette: None,
            medium_connections: false,
            wave_bytes: None,
        }
    }
}

/// How long to render.
#[derive(Clone, Copy, Debug)]
pub enum Budget {
    /// Exactly this many samples per pixel.
    Samples(u64),
    /// Passes sized by a [`super::PassSizer`] to end within this much rendering time (setup
    /// excluded).
    Time(Duration),
}
