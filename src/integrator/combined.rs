//! `--method combined`: direct and ellipsoidal connections in one estimator. A pixel sample of
//! each family comes from one of two tracers with independent random streams: a direct one (all
//! (s, t) strategies) and an ellipsoidal one (a vertex on a spheroid for each pair of subpath
//! vertices, K connections per spheroid). Each contribution is weighted by its family's share
//! of its path, a balance heuristic between the families (their densities times their samples
//! per pixel sample, the ellipsoidal density approximated as shaders/lib/family_mis.wesl says);
//! within its family a contribution keeps the weight it has there. The weights of every path
//! sum to one over both families whatever the sample counts they assume, so the image, the sum
//! of the two tracers' films (each the mean of its own samples), is an unbiased estimate (the
//! tests compare it with `path` and `direct`).
//!
//! The two families' samples cost different times and their shares of the image differ in
//! noise, so a render splits its samples between them ([`Allocation`]): the ellipsoidal half
//! traces r samples per pixel for each of the direct half's, r chosen by a pilot (as `auto`'s,
//! on a smaller image and a seed of its own, its films discarded) to minimise the variance of
//! the sum at equal time, and the weights count the families' samples in that ratio. The
//! ellipsoidal half has `ellipsoidal`'s query roulette (a multi-bounce query made with
//! probability p, `query_roulette`), which the weights of both halves count (p R
//! connections per direct one on such paths, so the direct half takes them over as p falls);
//! with a time budget the same pilot weighs p = 1 against p = `query_roulette::TRIAL`.
//!
//! Not yet: checkpoints, shards, NLOS captures and directional lights (refused with a clear
//! error).

mod allocate;

use anyhow::{Result, bail, ensure};

pub use self::allocate::{Allocation, HALVES_PILOT_SHARE, allocate, ellipsoidal_share, equal_time_error};
use super::bidirectional::camera_pilot::{camera_pilot_applies, trace_camera_pilot};
pub use super::bidirectional::{Family, FamilyRole};
use super::{BidirectionalTracer, Integrator, Method, RenderSettings, Wavefront, checkpoint};
use crate::film::Film;
use crate::gpu::GpuContext;
use crate::scene::PreparedScene;

impl Family {
    /// The settings of this half of the combined render `settings`: its method, one connection
    /// per strategy for the direct half, and for the ellipsoidal half a seed of its own, so its
    /// subpaths are independent of the direct half's.
    pub fn settings(self, settings: &RenderSettings) -> RenderSettings {
        match self {
            Family::Direct => RenderSettings { method: Method::Direct, connections_per_query: 1, ..settings.clone() },
            Family::Ellipsoidal => RenderSettings {
                method: Method::Ellipsoidal,
                seed: ellipsoidal_half_seed(settings.seed),
                ..settings.clone()
            },
        }
    }
}

/// The seed of a combined render's ellipsoidal half, given the render's.
fn ellipsoidal_half_seed(seed: u32) -> u32 {
    seed ^ 0x5bd1_e995
}

/// Errors for settings `combined` cannot render (checked before any work): both halves must be
/// valid, and a combined render has no captures and no debug strategy yet.
pub fn check_settings(settings: &RenderSettings) -> Result<()> {
    ensure!(
        !matches!(settings.gate, crate::film::Gate::None),
        "--method combined weighs direct and ellipsoidal connections against each other and needs a gate (box, \
         gaussian, cw, table or transient); without one use --method path or direct"
    );
    ensure!(settings.nlos.is_none(), "--method combined does not render --nlos captures yet: use --method ellipsoidal");
    ensure!(settings.debug_strategy.is_none(), "--debug-strategy needs --method direct");
    if let Some(share) = settings.ellipsoidal_share {
        ensure!(
            (1.0 / MAX_SHARE..=MAX_SHARE).contains(&share),
            "--ellipsoidal-share {share}: give 1/{MAX_SHARE} to {MAX_SHARE} ellipsoidal samples per direct one"
        );
    }
    for role in [Family::Direct, Family::Ellipsoidal] {
        super::bidirectional::check_tracer_settings(&role.settings(settings))?;
    }
    Ok(())
}

/// Most samples per pixel one half of a combined render traces per sample of the other
/// (dimensionless): however far a pilot misjudges a half's variance, that half keeps at least
/// 1 / MAX_SHARE of the other's samples.
pub const MAX_SHARE: f64 = 8.0;

/// The two halves of a combined render, and the ellipsoidal half's samples per direct one.
pub struct CombinedTracer<'a> {
    direct: BidirectionalTracer<'a>,
    ellipsoidal: BidirectionalTracer<'a>,
    share: f64,
    /// Samples per pixel (of the leading half) of the camera pilot whose scales both halves
    /// weigh with (`RenderSettings::camera_pilot_spp`; 0: none).
    camera_pilot_asked: u32,
    /// The camera pilot is still to run (before the next pass).
    camera_pilot_pending: bool,
    /// Samples per pixel of the camera pilot whose scales weigh the film's samples; 0: none.
    camera_pilot_traced: u32,
    /// The render's time budget (s), a share of which the camera pilot may take.
    time_budget: Option<f64>,
}

impl<'a> CombinedTracer<'a> {
    /// Builds both halves (`settings.method` is `combined`) for `settings.ellipsoidal_share`
    /// ellipsoidal samples per direct one (1 where not given; [`allocate`] chooses it for a
    /// render): the weights count K connections per spheroid times that share.
    pub fn new(ctx: &'a GpuContext, scene: &PreparedScene, settings: &RenderSettings) -> Result<Self> {
        check_settings(settings)?;
        let share = settings.ellipsoidal_share.unwrap_or(1.0);
        // Both halves weigh with the scales of one camera pilot, which this tracer runs: a path's
        // weights in either half read the same camera density (see bidirectional::camera_pilot).
        let camera_pilot = match camera_pilot_applies(settings) {
            true => settings.camera_pilot_spp.unwrap_or(0),
            false => 0,
        };
        let half = |family: Family| {
            let role = FamilyRole { family, ratio: settings.connections_per_query as f64 * share, medium_ratio: share };
            let half_settings = RenderSettings { camera_pilot_spp: Some(camera_pilot), ..family.settings(settings) };
            BidirectionalTracer::with_family(ctx, scene, &half_settings, Some(role))
        };
        let (direct, ellipsoidal) = (half(Family::Direct)?, half(Family::Ellipsoidal)?);
        // Where the scales do not fit a binding neither half keeps them.
        let camera_pilot = if direct.keeps_camera_scales() { camera_pilot } else { 0 };
        Ok(Self {
            direct,
            ellipsoidal,
            share,
            camera_pilot_asked: camera_pilot,
            camera_pilot_pending: camera_pilot > 0,
            camera_pilot_traced: 0,
            time_budget: None,
        })
    }

    /// The camera pilot of both halves (as `direct`'s, bidirectional::camera_pilot): the
    /// halves render `camera_pilot_asked` samples per pixel of the leading half at the split,
    /// every scale [`CAMERA_PILOT_SCALE`](super::bidirectional::camera_pilot::CAMERA_PILOT_SCALE),
    /// and the scales follow the direct half's camera strategies (its film), whose density they
    /// scale against light tracing and the ellipsoidal family. Both halves then take the same
    /// scales; a pilot a time budget cut short leaves them 1.
    fn run_camera_pilot(&mut self) -> Result<()> {
        self.camera_pilot_pending = false;
        let (asked, budget) = (self.camera_pilot_asked, self.time_budget);
        self.direct.begin_camera_pilot();
        self.ellipsoidal.begin_camera_pilot();
        let complete = trace_camera_pilot(self, asked, budget)?;
        let scales = self.direct.camera_pilot_scales(complete)?;
        let traced = if complete { asked } else { 0 };
        self.direct.finish_camera_pilot(scales.clone(), traced);
        self.ellipsoidal.finish_camera_pilot(scales, traced);
        self.camera_pilot_traced = traced;
        Ok(())
    }

    /// The half with more samples per pixel (the direct one at equal shares), whose samples a
    /// pass counts, and the other.
    fn halves(&mut self) -> (&mut BidirectionalTracer<'a>, &mut BidirectionalTracer<'a>, f64) {
        if self.share > 1.0 {
            (&mut self.ellipsoidal, &mut self.direct, 1.0 / self.share)
        } else {
            (&mut self.direct, &mut self.ellipsoidal, self.share)
        }
    }

    fn unsupported(what: &str) -> anyhow::Error {
        anyhow::anyhow!("--method combined cannot {what} yet: use --method direct or ellipsoidal for that")
    }
}

impl Integrator for CombinedTracer<'_> {
    fn wavefront(&self) -> &Wavefront<'_> {
        self.direct.wavefront()
    }

    /// `samples` more of the leading half (see `halves`), then the other up to its share of the
    /// leading half's samples (at least one).
    fn render_pass(&mut self, samples: u32) -> Result<()> {
        self.prepare()?;
        let (leading, other, share) = self.halves();
        leading.render_pass(samples)?;
        let due = ((leading.samples_done() as f64 * share).round() as u64).max(1);
        while other.samples_done() < due {
            let next = (due - other.samples_done()).min(other.samples_per_pass() as u64) as u32;
            other.render_pass(next)?;
        }
        Ok(())
    }

    /// The leading half's samples per pixel.
    fn samples_done(&self) -> u64 {
        self.direct.samples_done().max(self.ellipsoidal.samples_done())
    }

    fn samples_per_pass(&self) -> u32 {
        self.direct.samples_per_pass().min(self.ellipsoidal.samples_per_pass())
    }

    fn reset_film(&mut self) {
        self.direct.reset_film();
        self.ellipsoidal.reset_film();
    }

    fn restart(&mut self, seed: u32) {
        self.direct.restart(seed);
        self.ellipsoidal.restart(ellipsoidal_half_seed(seed));
        self.camera_pilot_pending = self.camera_pilot_asked > 0;
        self.camera_pilot_traced = 0;
    }

    fn set_gate(&mut self, scene: &PreparedScene, settings: &RenderSettings) -> Result<bool> {
        let direct = Family::Direct.settings(settings);
        let ellipsoidal = Family::Ellipsoidal.settings(settings);
        let moved = self.direct.set_gate(scene, &direct)? && self.ellipsoidal.set_gate(scene, &ellipsoidal)?;
        if moved {
            self.camera_pilot_pending = self.camera_pilot_asked > 0;
            self.camera_pilot_traced = 0;
        }
        Ok(moved)
    }

    fn camera_pilot_spp(&self) -> u32 {
        self.camera_pilot_traced
    }

    /// The direct half's, which the ellipsoidal half's equal.
    fn camera_mis_scales(&self) -> &[f32] {
        self.direct.camera_mis_scales()
    }

    fn adopt_camera_mis_scales(&mut self, scales: &[f32], traced: u32) {
        if self.camera_pilot_asked > 0 {
            self.direct.adopt_camera_mis_scales(scales, traced);
            self.ellipsoidal.adopt_camera_mis_scales(scales, traced);
            self.camera_pilot_pending = false;
            self.camera_pilot_traced = traced;
        }
    }

    fn limit_pass_pixels(&mut self, pixels: Option<u32>) {
        self.direct.limit_pass_pixels(pixels);
        self.ellipsoidal.limit_pass_pixels(pixels);
    }

    fn warm_up(&mut self) -> Result<()> {
        let pilot = std::mem::take(&mut self.camera_pilot_pending);
        let seed = self.direct.wavefront().params.seed;
        let traced = self.warm_up_pass();
        self.restart(seed);
        traced?;
        self.camera_pilot_pending = pilot;
        Ok(())
    }

    /// The sum of the two halves' estimates, its samples per pixel those of the leading half.
    fn film(&self) -> Result<Film> {
        let mut film = self.direct.film()?;
        let other = self.ellipsoidal.film()?;
        for (a, b) in film.data.iter_mut().zip(&other.data) {
            *a += b;
        }
        film.spp = film.spp.max(other.spp);
        Ok(film)
    }

    fn truncated_traversals(&self) -> Result<u64> {
        Ok(self.direct.truncated_traversals()? + self.ellipsoidal.truncated_traversals()?)
    }

    fn stats_report(&self) -> Result<Option<String>> {
        let (d, e) = (self.direct.stats_report()?, self.ellipsoidal.stats_report()?);
        Ok(match (d, e) {
            (None, None) => None,
            (d, e) => {
                Some(format!("direct half:\n{}ellipsoidal half:\n{}", d.unwrap_or_default(), e.unwrap_or_default()))
            }
        })
    }

    fn samples_to_visit_every_bin(&self) -> Option<u64> {
        self.ellipsoidal.samples_to_visit_every_bin()
    }

    fn set_time_budget(&mut self, seconds: Option<f64>) {
        self.direct.set_time_budget(seconds);
        self.ellipsoidal.set_time_budget(seconds);
        self.time_budget = seconds;
    }

    fn prepare(&mut self) -> Result<()> {
        self.direct.prepare()?;
        self.ellipsoidal.prepare()?;
        if self.camera_pilot_pending {
            self.run_camera_pilot()?;
        }
        Ok(())
    }

    fn save_state(&self) -> Result<checkpoint::RenderState> {
        Err(Self::unsupported("save its state (--checkpoint, --shard)"))
    }

    fn load_state(&mut self, _state: &checkpoint::RenderState) -> Result<()> {
        Err(Self::unsupported("resume (--resume)"))
    }

    fn skip_samples(&mut self, samples: u64) -> Result<()> {
        if samples > 0 {
            bail!(Self::unsupported("render a shard (--shard)"));
        }
        Ok(())
    }
}
