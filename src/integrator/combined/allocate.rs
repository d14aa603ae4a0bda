//! The allocation of a combined render: how its samples split between the halves, with which
//! query roulette, or which family renders alone, chosen by a pilot ([`allocate`]).

use std::fmt::Write as _;

use anyhow::Result;

use super::super::auto::{
    ALLOCATION_MIN_PIXELS, CandidateFigures, EARLY_STOP_RATIO, PILOT_BATCHES, candidate_methods, candidate_settings,
    compare, pilot_budget, pilot_resolution, pilot_settings,
};
use super::super::bidirectional::camera_pilot::resolve_camera_pilot;
use super::super::pilot::{Batches, CameraScalesOnce, pilot_batch};
use super::super::{Budget, Integrator, Method, RenderSettings, create_integrator, query_roulette};
use super::{CombinedTracer, MAX_SHARE, check_settings};
use crate::gpu::GpuContext;
use crate::scene::PreparedScene;
/// Share of a time budget (dimensionless) within which a combined render's whole pilot must be
/// predicted to fit, from the families' first batches alone, for it to go on and weigh both
/// halves; otherwise the families alone render as many batches again and the render traces the
/// one that leads over all of them. At its floor of batches the whole pilot renders about as
/// many batches as the families' first ones times the candidate roulettes plus three (each
/// roulette's halves about one batch of each family, the last weighing two and the halves), and
/// a short render cannot pay that: on the fence at 1 ns (87,140 triangles, 64×64, 4 s) nine runs
/// at their floor left `combined` 108 samples per pixel where `direct` traced 278, at 1.8 times
/// `direct`'s error.
pub const HALVES_PILOT_SHARE: f64 = 0.1;

/// How a combined render splits its samples between its halves, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Allocation {
    /// Samples per pixel of the ellipsoidal half per sample of the direct half (dimensionless,
    /// 1 / MAX_SHARE ..= MAX_SHARE).
    pub ellipsoidal_share: f64,
    /// The ellipsoidal half's query roulette (dimensionless; `RenderSettings::query_roulette`),
    /// which both halves' weights count; where `alone` is `ellipsoidal`, its own (every query
    /// unless given: [`allocate`]).
    pub query_roulette: f32,
    /// `Method::Direct` or `Method::Ellipsoidal` where the pilot found that family alone, with
    /// its own weights, ahead of both halves at their split: the render is then that method's
    /// (the limit of a split that gives the other family no samples, where the family weights'
    /// cost buys nothing). `None`: both halves.
    pub alone: Option<Method>,
    /// Why, in words (for logs and metadata).
    pub reason: String,
    /// Seconds the pilot took: passes, film clears and readbacks (counted in a time budget).
    pub pilot_seconds: f64,
}

impl Allocation {
    /// Family `method` traced alone at query roulette `roulette` (for `ellipsoidal`), chosen by
    /// a pilot of `pilot_seconds` for `reason`.
    fn alone(method: Method, roulette: f32, reason: String, pilot_seconds: f64) -> Self {
        Self { ellipsoidal_share: 1.0, query_roulette: roulette, alone: Some(method), reason, pilot_seconds }
    }

    /// What the render traces, in words, with the roulette of `ellipsoidal` alone (the end of
    /// `reason`).
    fn choice_words(&self) -> String {
        match self.alone {
            Some(Method::Ellipsoidal) => format!("{}, query roulette {}", self.renders(), self.query_roulette),
            _ => self.renders().to_string(),
        }
    }

    /// What the render traces, in words (metadata `combined_renders`).
    pub fn renders(&self) -> &'static str {
        match self.alone {
            Some(Method::Direct) => "direct alone",
            Some(_) => "ellipsoidal alone",
            None => "both halves",
        }
    }

    /// The settings the render of `settings` (method `combined`) runs with under this
    /// allocation: both halves at its split and roulette, or the family alone.
    pub fn render_settings(&self, settings: &RenderSettings) -> RenderSettings {
        self.settings_with(settings, self.alone)
    }

    /// The settings of both halves at this allocation's split and roulette (`alone` None), or
    /// of family `alone` by itself, for the render of `settings`.
    fn settings_with(&self, settings: &RenderSettings, alone: Option<Method>) -> RenderSettings {
        let both = RenderSettings {
            ellipsoidal_share: Some(self.ellipsoidal_share),
            query_roulette: Some(self.query_roulette),
            ..settings.clone()
        };
        match alone {
            Some(Method::Direct) => RenderSettings {
                ellipsoidal_share: None,
                query_roulette: None,
                ..candidate_settings(settings, Method::Direct)
            },
            Some(method) => RenderSettings { ellipsoidal_share: None, ..candidate_settings(&both, method) },
            None => both,
        }
    }
}

/// The families a combined render of `settings` may trace alone instead of both halves: none
/// where the split is given (`--ellipsoidal-share`), else `direct`, and `ellipsoidal` where it
/// renders the scene alone (not through glass; `auto::candidate_methods`).
fn alone_candidates(settings: &RenderSettings, scene: &PreparedScene) -> Vec<Method> {
    if settings.ellipsoidal_share.is_some() {
        return Vec::new();
    }
    let auto = RenderSettings { method: Method::Auto, ..settings.clone() };
    candidate_methods(&auto, scene).into_iter().filter(|m| matches!(m, Method::Direct | Method::Ellipsoidal)).collect()
}

/// The ellipsoidal half's samples per sample of the direct half that minimise the variance of
/// the sum of the halves' estimates at equal time, from each half's variance per sample v
/// (radiance squared) and seconds per sample c: n_h proportional to sqrt(v_h / c_h) (Neyman
/// allocation), clamped to 1 / MAX_SHARE ..= MAX_SHARE. A half whose pilot saw no variance gets
/// the fewest samples; with neither, one each.
pub fn ellipsoidal_share(v_direct: f64, c_direct: f64, v_ellipsoidal: f64, c_ellipsoidal: f64) -> f64 {
    let (d, e) = (v_direct / c_direct.max(1e-30), v_ellipsoidal / c_ellipsoidal.max(1e-30));
    let share = match (d > 0.0, e > 0.0) {
        (true, true) => (e / d).sqrt(),
        (false, true) => MAX_SHARE,
        (true, false) => 1.0 / MAX_SHARE,
        (false, false) => 1.0,
    };
    share.clamp(1.0 / MAX_SHARE, MAX_SHARE)
}

/// Variance x time per direct sample of the sum of the halves' estimates (radiance squared x
/// seconds) with `share` ellipsoidal samples per direct one, from each half's variance per sample
/// v and seconds per sample c: (v_D + v_E / share)(c_D + share c_E), what the error at equal time
/// is proportional to.
pub fn equal_time_error(v_direct: f64, c_direct: f64, v_ellipsoidal: f64, c_ellipsoidal: f64, share: f64) -> f64 {
    (v_direct + v_ellipsoidal / share) * (c_direct + share * c_ellipsoidal)
}

/// The query roulettes a combined render's pilot weighs: the given one; with a time budget and
/// paths of two or more scattering vertices, every query and `query_roulette::TRIAL` of the
/// multi-bounce ones; otherwise every query (a sample budget keeps a sample what it was).
fn roulette_candidates(settings: &RenderSettings, budget: Budget) -> Vec<f32> {
    match (settings.query_roulette, budget) {
        (Some(p), _) => vec![p],
        (None, Budget::Time(_)) if query_roulette::has_multi_bounce_queries(settings) => {
            vec![1.0, query_roulette::TRIAL]
        }
        _ => vec![1.0],
    }
}

/// The allocation of the combined render `settings`: its samples' split
/// (`settings.ellipsoidal_share` where given) and its query roulette (`settings.query_roulette`
/// where given). Whatever is not given a pilot chooses, on the image of `auto::pilot_resolution`
/// keeping `auto::ALLOCATION_MIN_PIXELS` pixels, with `auto::pilot_settings`, its films discarded. Unless the split is given, each family alone
/// (`ellipsoidal` making every query, or with `settings.query_roulette` where given) renders
/// batches first, and where one leads the other `auto::EARLY_STOP_RATIO`-fold the render traces
/// it alone ([`Allocation::alone`]); where the rest of the pilot would not fit in
/// [`HALVES_PILOT_SHARE`] of a time budget, the families render as many batches again and the
/// render traces the leader over all of them alone. Otherwise, for each candidate roulette
/// ([`roulette_candidates`]) both halves (one sample each per pixel sample) measure their
/// variance and time per sample, [`ellipsoidal_share`] splits the samples, and the roulette of
/// the least [`equal_time_error`] at its split wins. The weights of both halves change with the
/// roulette (multi-bounce paths go to the direct half as its queries grow rare), so each
/// candidate is measured as it renders. Unless the split is given, both halves at the chosen split
/// then render batches between fresh ones of each family alone, and the least variance x time
/// per sample decides what the render traces. With a time budget the pilot spends about
/// `auto::PILOT_SHARE` of it.
pub fn allocate(
    ctx: &GpuContext,
    scene: &PreparedScene,
    settings: &RenderSettings,
    budget: Budget,
) -> Result<Allocation> {
    check_settings(settings)?;
    let roulettes = roulette_candidates(settings, budget);
    if let (Some(share), [p]) = (settings.ellipsoidal_share, &roulettes[..]) {
        return Ok(Allocation {
            ellipsoidal_share: share,
            query_roulette: *p,
            alone: None,
            reason: format!("{share} ellipsoidal samples per direct one, as given, query roulette {p}"),
            pilot_seconds: 0.0,
        });
    }
    let (width, height, _) = pilot_resolution(settings.width, settings.height, ALLOCATION_MIN_PIXELS);
    let pixel_ratio = (settings.width as f64 * settings.height as f64) / (width as f64 * height as f64);
    let alone = alone_candidates(settings, scene);
    // Each family alone where there are two, then each half at each roulette, and both halves at
    // the chosen split beside each family alone (again).
    let weigh_alone_first = alone.len() > 1;
    let alone_runs = alone.len() * if weigh_alone_first { 2 } else { 1 };
    let runs = 2 * roulettes.len() + if alone.is_empty() { 0 } else { alone_runs + 1 };
    let per_run = pilot_budget(budget, pixel_ratio, runs);
    let pilot = pilot_settings(settings, width, height);
    let mut reason = format!("pilot on {width}x{height}:");
    let mut pilot_seconds = 0.0;

    // Each family alone, as `auto` weighs methods: medians of the batch pairs, and a pilot that
    // missed what another found (a gate's rare paths) charged for it. `ellipsoidal` alone makes
    // every query (unless the roulette is given): a roulette chosen for both halves, whose direct
    // half carries the multi-bounce paths it skips, is no guide to it alone, and where it renders
    // alone multi-bounce light matters (on the glossy box at 1 cm it had 4 times the error at the
    // halves' 1/8; weighing 1/8 alone too, a pilot of this size chose it in 2 renders of 6 there:
    // the medians of pairs miss the heavy tail of queries that weigh 8). Where one family is
    // `auto::EARLY_STOP_RATIO` times ahead of the other after all its batches the render traces
    // it alone without measuring the halves, whose runs are most of the pilot: the halves'
    // samples also pay for the family weights, and at such a margin they have not been measured
    // ahead. (Not after half the batches, as `auto` may stop: there one firefly in a `direct`
    // batch of the glossy box at 10 cm, where `direct` leads 7-fold, put `ellipsoidal` 11 times
    // ahead.) The same holds where weighing the halves would not fit in `HALVES_PILOT_SHARE` of
    // a time budget.
    let alone_roulette = settings.query_roulette.unwrap_or(1.0);
    // Every candidate weighs as its render would: with the camera scales of one camera pilot
    // where its render runs one (`direct` alone and both halves).
    let mut camera_scales = CameraScalesOnce::default();
    let mut alone_tracers = Vec::new();
    for &method in &alone {
        let alone_settings = Allocation::alone(method, alone_roulette, String::new(), 0.0).render_settings(&pilot);
        let mut tracer = create_integrator(ctx, scene, &resolve_camera_pilot(&alone_settings, budget))?;
        tracer.warm_up()?;
        camera_scales.prepare(tracer.as_mut())?;
        alone_tracers.push(tracer);
    }
    let mut alone_batches: Vec<Batches> = alone.iter().map(|_| Batches::default()).collect();
    if weigh_alone_first {
        // A round of batches of each family alone, interleaved so that both are timed alike.
        let mut round = |batches: &mut Vec<Batches>| -> Result<()> {
            for _ in 0..PILOT_BATCHES {
                for (tracer, b) in alone_tracers.iter_mut().zip(batches.iter_mut()) {
                    pilot_batch(tracer.as_mut(), b, per_run, 1)?;
                }
            }
            Ok(())
        };
        round(&mut alone_batches)?;
        let (mut measured, mut best, mut ratio) = compare(&alone, &alone_batches, pixel_ratio);
        let first_seconds = alone_batches.iter().map(|b| b.wall_seconds).sum::<f64>();
        let predicted = first_seconds * (roulettes.len() + 3) as f64;
        let mut batches = PILOT_BATCHES;
        let why = match budget {
            _ if ratio >= EARLY_STOP_RATIO => Some(format!("{} {ratio:.3} times ahead", best.name())),
            Budget::Time(t) if predicted > HALVES_PILOT_SHARE * t.as_secs_f64() => {
                // The families alone again, in place of the halves' runs: 8 batches each chose
                // the wrong one in 1 render of 6 on the box at 1 m and on the glossy box at
                // 1 cm and at 10 cm, where one leads 3 to 7-fold.
                round(&mut alone_batches)?;
                batches += PILOT_BATCHES;
                (measured, best, ratio) = compare(&alone, &alone_batches, pixel_ratio);
                Some(format!(
                    "{} ahead ({ratio:.3} times); weighing both halves would take the pilot to about {predicted:.2} s \
                     of the {:.2} s budget",
                    best.name(),
                    t.as_secs_f64()
                ))
            }
            _ => None,
        };
        if let Some(why) = why {
            let seconds = camera_scales.seconds + alone_batches.iter().map(|b| b.wall_seconds).sum::<f64>();
            let mut allocation = Allocation::alone(best, alone_roulette, String::new(), seconds);
            let words: Vec<String> = measured.iter().map(|m| words_of(m, m.method.name())).collect();
            allocation.reason = format!(
                "{reason} after {batches} batches each, each family alone, variance x time per sample {}: {why}, {}",
                words.join(" vs "),
                allocation.choice_words()
            );
            return Ok(allocation);
        }
    }
    pilot_seconds += alone_batches.iter().map(|b| b.wall_seconds).sum::<f64>();

    // Both halves at each candidate roulette, one sample each per pixel sample.
    let per_sample = |b: &Batches| b.seconds_per_sample();
    let mut best: Option<(f64, f64, f32)> = None; // (variance x time, split, roulette)
    for &p in &roulettes {
        let halves = RenderSettings { ellipsoidal_share: Some(1.0), query_roulette: Some(p), ..pilot.clone() };
        let mut tracer = CombinedTracer::new(ctx, scene, &resolve_camera_pilot(&halves, budget))?;
        tracer.direct.warm_up()?;
        tracer.ellipsoidal.warm_up()?;
        camera_scales.prepare(&mut tracer)?;
        let (mut direct, mut ellipsoidal) = (Batches::default(), Batches::default());
        for _ in 0..PILOT_BATCHES {
            pilot_batch(&mut tracer.direct, &mut direct, per_run, 1)?;
            pilot_batch(&mut tracer.ellipsoidal, &mut ellipsoidal, per_run, 1)?;
        }
        pilot_seconds += direct.wall_seconds + ellipsoidal.wall_seconds;
        let (v_d, c_d, v_e, c_e) =
            (direct.variance(), per_sample(&direct), ellipsoidal.variance(), per_sample(&ellipsoidal));
        let share = settings.ellipsoidal_share.unwrap_or_else(|| ellipsoidal_share(v_d, c_d, v_e, c_e));
        let error = equal_time_error(v_d, c_d, v_e, c_e, share);
        let _ = write!(
            reason,
            " query roulette {p}: variance per sample {v_d:.3e} (direct half) and {v_e:.3e} (ellipsoidal half), \
             seconds per sample {c_d:.3e} and {c_e:.3e}, {share:.3} ellipsoidal samples per direct one, variance x \
             time {error:.3e};"
        );
        // (A pilot that measured nothing, error NaN, never wins over one that did.)
        if best.is_none_or(|(e, _, _)| error < e || e.is_nan()) {
            best = Some((error, share, p));
        }
    }
    let (_, share, p) = best.expect("at least one candidate roulette");
    let _ = write!(reason, " {share:.3} ellipsoidal samples per direct one, query roulette {p}");
    let mut allocation = Allocation { ellipsoidal_share: share, query_roulette: p, alone: None, reason, pilot_seconds };
    if alone.is_empty() {
        allocation.pilot_seconds += camera_scales.seconds;
        return Ok(allocation);
    }
    // Both halves at that split, rendered as the render would (each pass the halves' samples in
    // its ratio, their films summed), weighed against each family alone, whose tracers render
    // batches afresh between the halves' so that all candidates are timed alike (a tracer's
    // first passes are its slowest, and the host's load drifts). Where a family alone is ahead
    // the family weights' cost buys nothing.
    let mut halves =
        CombinedTracer::new(ctx, scene, &resolve_camera_pilot(&allocation.settings_with(&pilot, None), budget))?;
    halves.direct.warm_up()?;
    halves.ellipsoidal.warm_up()?;
    camera_scales.prepare(&mut halves)?;
    let mut tracers: Vec<(Box<dyn Integrator + '_>, u32)> = alone_tracers.into_iter().map(|t| (t, 1)).collect();
    tracers.push((Box::new(halves), samples_per_other_sample(share)));
    let mut batches: Vec<Batches> = tracers.iter().map(|_| Batches::default()).collect();
    for _ in 0..PILOT_BATCHES {
        for ((tracer, unit), b) in tracers.iter_mut().zip(&mut batches) {
            pilot_batch(tracer.as_mut(), b, per_run, *unit)?;
        }
    }
    allocation.pilot_seconds += camera_scales.seconds + batches.iter().map(|b| b.wall_seconds).sum::<f64>();
    let methods: Vec<Method> = alone.iter().copied().chain([Method::Combined]).collect();
    let (candidates, ahead, _) = compare(&methods, &batches, pixel_ratio);
    let words: Vec<String> = candidates
        .iter()
        .map(|c| words_of(c, if c.method == Method::Combined { "both halves" } else { c.method.name() }))
        .collect();
    allocation.alone = Some(ahead).filter(|&m| m != Method::Combined);
    if allocation.alone == Some(Method::Ellipsoidal) {
        allocation.query_roulette = alone_roulette;
    }
    let _ = write!(
        allocation.reason,
        "; then at that split, variance x time per sample {}: {}",
        words.join(" vs "),
        allocation.choice_words()
    );
    Ok(allocation)
}

/// A candidate's figures in words, under `name`.
fn words_of(c: &CandidateFigures, name: &str) -> String {
    format!(
        "{:.3e} ({name}: variance per sample {:.3e}, seconds per sample {:.3e})",
        c.cost(),
        c.variance_per_sample,
        c.seconds_per_sample()
    )
}

/// Samples per pixel of a combined render's leading half (see `CombinedTracer::halves`) for
/// each of the other half's at `share` ellipsoidal samples per direct one, rounded: a pilot's
/// batches hold multiples of it, so each has the halves in about the render's ratio.
fn samples_per_other_sample(share: f64) -> u32 {
    share.max(1.0 / share).round().max(1.0) as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_neyman_split_minimises_the_error_at_equal_time() {
        // At n_E / n_D = sqrt(v_E c_D / (v_D c_E)) the error is (sqrt(v_D c_D) + sqrt(v_E c_E))^2,
        // and no other split on a grid does better.
        for (vd, cd, ve, ce) in [(1.0, 1.0, 4.0, 1.0), (2.0, 3.0, 0.5, 7.0), (0.3, 2e-3, 0.05, 5e-3)] {
            let share = ellipsoidal_share(vd, cd, ve, ce);
            let best = equal_time_error(vd, cd, ve, ce, share);
            assert!((best - ((vd * cd).sqrt() + (ve * ce).sqrt()).powi(2)).abs() < 1e-9 * best);
            for k in 1..=64 {
                let r = k as f64 / 8.0;
                assert!(best <= equal_time_error(vd, cd, ve, ce, r) * (1.0 + 1e-12), "{r} beats {share}");
            }
        }
    }

    #[test]
    fn the_pilot_weighs_a_roulette_only_where_it_may_choose_one() {
        let gated = RenderSettings { gate: crate::film::Gate::Box { start: 3.0, end: 3.2 }, ..Default::default() };
        let time = Budget::Time(std::time::Duration::from_secs(10));
        assert_eq!(roulette_candidates(&gated, time), vec![1.0, query_roulette::TRIAL]);
        // A sample budget keeps every query; a given probability is the only one; one bounce has
        // no multi-bounce queries.
        assert_eq!(roulette_candidates(&gated, Budget::Samples(64)), vec![1.0]);
        assert_eq!(
            roulette_candidates(&RenderSettings { query_roulette: Some(0.5), ..gated.clone() }, time),
            vec![0.5]
        );
        assert_eq!(roulette_candidates(&RenderSettings { max_bounces: 1, ..gated }, time), vec![1.0]);
    }

    #[test]
    fn a_family_alone_renders_with_its_own_settings() {
        let combined = RenderSettings {
            method: Method::Combined,
            connections_per_query: 4,
            gate: crate::film::Gate::Box { start: 3.0, end: 3.2 },
            ..Default::default()
        };
        let allocation = |alone| Allocation {
            ellipsoidal_share: 0.5,
            query_roulette: 0.125,
            alone,
            reason: String::new(),
            pilot_seconds: 0.0,
        };
        let both = allocation(None).render_settings(&combined);
        assert_eq!(
            (both.method, both.ellipsoidal_share, both.query_roulette),
            (Method::Combined, Some(0.5), Some(0.125))
        );
        // Direct alone: one connection per strategy, no split and no roulette (direct has
        // neither); ellipsoidal alone keeps K and the roulette the pilot measured it with.
        let direct = allocation(Some(Method::Direct)).render_settings(&combined);
        assert_eq!(
            (direct.method, direct.connections_per_query, direct.ellipsoidal_share, direct.query_roulette),
            (Method::Direct, 1, None, None)
        );
        let ellipsoidal = allocation(Some(Method::Ellipsoidal)).render_settings(&combined);
        assert_eq!(
            (
                ellipsoidal.method,
                ellipsoidal.connections_per_query,
                ellipsoidal.ellipsoidal_share,
                ellipsoidal.query_roulette
            ),
            (Method::Ellipsoidal, 4, None, Some(0.125))
        );
        assert_eq!(ellipsoidal.seed, combined.seed, "a family alone renders from the render's own seed");
        for (alone, words) in [
            (None, "both halves"),
            (Some(Method::Direct), "direct alone"),
            (Some(Method::Ellipsoidal), "ellipsoidal alone"),
        ] {
            assert_eq!(allocation(alone).renders(), words);
        }
    }

    #[test]
    fn shares_follow_variance_over_time() {
        // n_h proportional to sqrt(v_h / c_h).
        assert_eq!(ellipsoidal_share(1.0, 1.0, 1.0, 1.0), 1.0);
        assert!((ellipsoidal_share(1.0, 1.0, 4.0, 1.0) - 2.0).abs() < 1e-12);
        assert!((ellipsoidal_share(1.0, 1.0, 1.0, 4.0) - 0.5).abs() < 1e-12);
        assert!((ellipsoidal_share(2.0, 3.0, 8.0, 3.0) - 2.0).abs() < 1e-12);
        // Clamped, and a half that showed no variance keeps the fewest samples.
        assert_eq!(ellipsoidal_share(1.0, 1.0, 1e6, 1.0), MAX_SHARE);
        assert_eq!(ellipsoidal_share(1e6, 1.0, 1.0, 1.0), 1.0 / MAX_SHARE);
        assert_eq!(ellipsoidal_share(0.0, 1.0, 1.0, 1.0), MAX_SHARE);
        assert_eq!(ellipsoidal_share(1.0, 1.0, 0.0, 1.0), 1.0 / MAX_SHARE);
        assert_eq!(ellipsoidal_share(0.0, 1.0, 0.0, 1.0), 1.0);
    }
}
