//! The options of the bidirectional methods: their limits and defaults, the family a tracer is
//! in a combined render, the (s, t) strategies of a path length and their `--stats` counters,
//! and the checks of the settings and scenes (participating media) they are given.

use anyhow::{Result, ensure};

use crate::gpu::layout::VERTEX_MEDIUM_BITS;
use crate::integrator::{Method, RenderSettings, kernel_bounces};
use crate::scene::PreparedScene;

/// Most scattering vertices `direct` supports: the strategies of a slot grow as B^2 and
/// lavapipe ends a shader invocation's loops after 65535 iterations in total.
pub const MAX_BOUNCES: u32 = 24;
/// Most connections one ellipsoid query can draw (two reservoirs of four lanes each).
pub const MAX_CONNECTIONS_PER_QUERY: u32 = 8;
/// Connections per ellipsoid query when none are asked for (`--connections-per-query`). At
/// equal time on lavapipe (`gatetrace equal-time`, 64x64, 5 bounces, 3 x 3-4 s per method)
/// K = 4 had 0.51-0.64x the MSE of K = 1 on the Cornell box behind box gates of 2.5 mm, 5 cm
/// and 50 cm, and 0.53x on a 327,692-triangle mesh at 2.5 mm; K = 8 was no better (0.49-0.89x).
pub const DEFAULT_CONNECTIONS_PER_QUERY: u32 = 4;

/// Connections per ellipsoid query that `render --nlos` gives `ellipsoidal` unless told
/// otherwise. With a pilot render (DEFAULT_NLOS_TARGET_PILOT), at equal time on lavapipe
/// (confocal 16x16, 4 ps bins, 10 s), K = 1 had 0.41x the MSE of K = 4 on a 327,680-triangle
/// hidden sphere and 2.4x on the example scene's 12-triangle letter; large hidden meshes are the
/// case to serve.
pub const DEFAULT_NLOS_CONNECTIONS_PER_QUERY: u32 = 1;

/// Samples per pixel of the pilot render (`RenderSettings::target_pilot_spp`) that `render
/// --nlos` gives `ellipsoidal` unless told otherwise (`--target-pilot`).
pub const DEFAULT_NLOS_TARGET_PILOT: u32 = 256;

/// The connections per ellipsoid query a method uses unless told otherwise:
/// DEFAULT_CONNECTIONS_PER_QUERY for `ellipsoidal` and for `auto` (whose `ellipsoidal` pilot and
/// render use it), 1 (the only value they take) for the others.
pub fn default_connections_per_query(method: Method) -> u32 {
    if matches!(method, Method::Ellipsoidal | Method::Combined | Method::Auto) {
        DEFAULT_CONNECTIONS_PER_QUERY
    } else {
        1
    }
}

/// Which half of a combined render a tracer is: its connection kernels weigh each contribution
/// by their family's share of the path (shaders/lib/family_mis.wesl). `integrator::combined`
/// derives each half's settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Family {
    /// connect_direct's strategies.
    Direct = 1,
    /// connect_ellipsoidal's, connect_medium's and connect_spherical's.
    Ellipsoidal = 2,
}

/// A combined render's half: its family, and the ellipsoidal connections per direct one that
/// the family weights count (shaders/lib/family_mis.wesl).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FamilyRole {
    /// Which half.
    pub family: Family,
    /// Connections through a surface vertex per direct one (dimensionless): K per spheroid
    /// times the ellipsoidal half's samples per direct sample.
    pub ratio: f64,
    /// Connections through a vertex in a participating medium per direct one (dimensionless):
    /// one per spheroid times the ellipsoidal half's samples per direct sample.
    pub medium_ratio: f64,
}

/// The (s, t) strategies with at most `max_bounces` scattering vertices and t >= 1, in the
/// order of `strategy_stats` (depth d = s + t - 2, then s).
pub fn strategies(max_bounces: u32) -> Vec<(u32, u32)> {
    (0..=max_bounces).flat_map(|d| (0..=d + 1).map(move |s| (s, d + 2 - s))).collect()
}

/// Errors for settings a [`super::BidirectionalTracer`] (`direct` or `ellipsoidal`) cannot
/// render (checked before any work); [`crate::integrator::check_settings`] checks those of every
/// method that uses one.
pub fn check_tracer_settings(settings: &RenderSettings) -> Result<()> {
    let b = kernel_bounces(settings);
    let method = settings.method.name();
    ensure!(
        b <= MAX_BOUNCES,
        "--method {method} supports at most {MAX_BOUNCES} bounces (got {b}); use --method path for longer paths"
    );
    if settings.method == Method::Ellipsoidal {
        ensure!(
            !matches!(settings.gate, crate::film::Gate::None),
            "--method ellipsoidal draws target path lengths from the gate: give a gate (box, gaussian, cw, table or \
             transient), not `{}`",
            settings.gate.describe()
        );
        ensure!(settings.debug_strategy.is_none(), "--debug-strategy needs --method direct");
        let k = settings.connections_per_query;
        ensure!(
            (1..=MAX_CONNECTIONS_PER_QUERY).contains(&k),
            "--connections-per-query {k}: give 1 to {MAX_CONNECTIONS_PER_QUERY}"
        );
        let q = settings.query;
        ensure!(
            q.split >= 0.0 && q.split.is_finite(),
            "--query-split {}: give a non-negative number (0: exhaustive queries)",
            q.split
        );
        if let Some(p) = settings.query_roulette {
            let least = 1.0 / crate::integrator::query_roulette::MAX_SKIP;
            ensure!(
                (least..=1.0).contains(&p),
                "--query-roulette {p}: give a probability from {least} to 1 (1: every query)"
            );
        }
        let g = settings.ellipsoid_guards;
        ensure!(
            g.needle >= 0.0 && g.needle.is_finite() && g.length > 0.0,
            "ellipsoid guards (needle {}, length {}) must be non-negative and finite (length positive)",
            g.needle,
            g.length
        );
        ensure!(
            settings.target_pilot_spp == 0 || matches!(settings.gate, crate::film::Gate::Transient { .. }),
            "--target-pilot shapes the target lengths of a transient gate: give --gate transient:... or --target-pilot 0"
        );
        // Light-tracing connections (t = 1) land in other pixels, whose bins cannot be divided by
        // the source pixel's visits: with extra visits only whole cycles would be unbiased.
        // Captures have none (no connection ends at the sensor origin).
        ensure!(
            settings.target_pilot_spp == 0 || settings.nlos.is_some(),
            "--target-pilot applies to --nlos captures only (a camera's light-tracing connections would be biased \
             by the extra visits)"
        );
    } else {
        ensure!(
            settings.connections_per_query == 1,
            "--connections-per-query applies to --method ellipsoidal and combined only"
        );
    }
    if settings.method != Method::Ellipsoidal {
        ensure!(settings.target_pilot_spp == 0, "--target-pilot applies to --method ellipsoidal only");
    }
    if let Some((s, t)) = settings.debug_strategy {
        ensure!(
            t >= 1 && s + t >= 2 && s + t <= b + 2,
            "--debug-strategy {s},{t} is not a strategy of paths with at most {b} bounces: \
             need t >= 1 and 2 <= s + t <= max_bounces + 2"
        );
    }
    Ok(())
}

/// Refuses what bidirectional subpaths through participating media do not render yet (`method`
/// names what the user asked for: a combined render's, for either half): NLOS captures and
/// double-sided lights between two media.
pub fn check_media(scene: &PreparedScene, settings: &RenderSettings, method: &str) -> Result<()> {
    let source = &scene.scene.source;
    let refuse = |what: &str, instead: &str| -> Result<()> {
        anyhow::bail!("{source}: the scene has participating media, and {what}: render it with --method {instead}")
    };
    if !matches!(settings.method, Method::Direct | Method::Ellipsoidal) {
        return refuse(
            &format!("`{method}` does not weigh connection vertices in media yet"),
            "path, direct, ellipsoidal or combined",
        );
    }
    anyhow::ensure!(
        settings.nlos.is_none(),
        "{source}: NLOS captures of scenes with participating media are not rendered yet"
    );
    if scene.lights.two_sided_media {
        return refuse("a double-sided light has different media on its two faces", "path");
    }
    anyhow::ensure!(
        scene.scene.media.len() < (1 << VERTEX_MEDIUM_BITS) - 1,
        "{source}: {} participating media; bidirectional methods render at most {}",
        scene.scene.media.len(),
        (1 << VERTEX_MEDIUM_BITS) - 2
    );
    Ok(())
}

/// Connections of one (s, t) strategy (`--stats`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StrategyStats {
    /// Light-subpath vertices.
    pub s: u32,
    /// Camera-subpath vertices (the pinhole included).
    pub t: u32,
    /// Connections whose vertices both existed and could contribute.
    pub evaluated: u64,
    /// Of those, connections dropped before any shading because W(length) = 0.
    pub skipped_by_gate: u64,
    /// Shadow rays traced.
    pub shadow_rays: u64,
}
