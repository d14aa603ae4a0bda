//! The render loop: budgets of samples or time, passes sized to a time budget, a whole render
//! from settings to film (with `auto`'s and `combined`'s pilots, resuming and shards), and the
//! checks and warnings about gates no path can reach.

use std::ops::ControlFlow;
use std::time::{Duration, Instant};

use anyhow::Result;

use super::{
    Budget, Integrator, Method, RenderSettings, auto, checkpoint, combined, create_integrator, film_elements,
    query_roulette,
};
use crate::film::Film;
use crate::gpu::GpuContext;
use crate::scene::PreparedScene;

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
    /// Samples per pixel of the camera pilot whose per-pixel scales weigh the film's samples
    /// (see `RenderSettings::camera_pilot_spp`), 0 for none.
    pub camera_pilot_spp: u32,
    /// Why a capture that asked for the band index went without it (see
    /// [`Integrator::band_index_off`]).
    pub band_index_off: Option<String>,
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
    /// `ellipsoidal`: the query roulette's probability and why (a pilot's time is in
    /// `rendering`).
    pub roulette: Option<query_roulette::Choice>,
    /// The render stopped before its budget was spent (see [`render_resumable`]).
    pub stopped_early: bool,
    /// The render's state after its last pass, when asked for (see [`render_resumable`]).
    pub state: Option<checkpoint::RenderState>,
}

impl RenderOutput {
    /// A warning for a render some of whose ray traversals the device cut short (see
    /// [`Integrator::truncated_traversals`]), or None. The library prints nothing: callers show
    /// this and the other warnings.
    pub fn truncated_traversals_warning(&self) -> Option<String> {
        (self.truncated_traversals > 0).then(|| {
            format!(
                "{} ray traversals were cut short by the device (lavapipe ends a shader's loops after 65535 \
                 iterations); the image may miss geometry. Use a GPU for this scene.",
                self.truncated_traversals
            )
        })
    }

    /// A warning for a render that ended before every bin of its stratified target lengths had
    /// a sample (see [`Integrator::samples_to_visit_every_bin`]), or None.
    pub fn unvisited_bins_warning(&self) -> Option<String> {
        let needed = self.samples_to_visit_every_bin.filter(|&n| self.film.spp < n)?;
        Some(format!(
            "each sample of a pixel aims its ellipsoidal connections at one of the gate's {} bins in turn, and \
             {needed} samples per pixel visit every bin once (with the extra visits a pilot or the band index \
             gives bins that hold more light), but this render stopped at {}, so some bins had no sample of their \
             own and are estimated from samples aimed at others (unbiased, but noisier): render at least --spp \
             {needed}",
            self.film.bins, self.film.spp
        ))
    }

    /// A warning for a render with a time budget that ran well past it (by a fifth and by more
    /// than a quarter of a second), or None: a time budget counts whole passes, at least one
    /// sample of every pixel, and its pilots, so on a large image of a heavy scene one pass can
    /// outlast the whole budget.
    pub fn budget_overrun_warning(&self, budget: Budget) -> Option<String> {
        let Budget::Time(budget) = budget else { return None };
        let (asked, took) = (budget.as_secs_f64(), self.rendering.as_secs_f64());
        (took > 1.2 * asked && took - asked > 0.25).then(|| {
            format!(
                "the render took {took:.2} s of rendering for a time budget of {asked:.2} s ({} spp): a time \
                 budget counts its pilots and whole passes of every pixel, at least one, and a pass here took \
                 longer than the time left; a smaller image fits the budget better",
                self.film.spp
            )
        })
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
            camera_pilot_spp: 0,
            band_index: None,
            band_index_off: None,
            samples_to_visit_every_bin: None,
            choice: None,
            allocation: None,
            roulette: None,
            stopped_early: false,
            state: None,
        }
    }
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
            tracer.set_time_budget(None);
            let target = tracer.samples_done() + n;
            while tracer.samples_done() < target && flow.is_continue() {
                let next = (target - tracer.samples_done()).min(tracer.samples_per_pass() as u64) as u32;
                tracer.render_pass(next)?;
                passes += 1;
                flow = after_pass(tracer, passes)?;
            }
        }
        Budget::Time(t) => {
            tracer.set_time_budget(Some(t.as_secs_f64()));
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
    let (shortest, longest) = scene.path_length_bounds(settings.max_bounces);
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
    let (shortest, longest) = scene.path_length_bounds(settings.max_bounces);
    let mut warning = match unreachable_gate(scene, settings) {
        Some(reason) => format!("{reason}: the image is black; no samples were traced"),
        None => format!(
            "the image is black: no path of its {} samples per pixel reached gate {} (paths of this scene with at \
             most {} bounces: {})",
            film.spp,
            settings.gate.describe(),
            settings.max_bounces,
            crate::film::gate::describe_lengths(shortest as f64, longest as f64)
        ),
    };
    if let Some(hint) = crate::film::gate::time_unit_hint(gate_spec, (shortest as f64, longest as f64)) {
        warning += &format!("; {hint}");
    }
    Some(warning)
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
        (None, Some(a), _) => a.render_settings(settings),
        (None, None, Some(state)) if settings.method == Method::Auto => {
            auto::candidate_settings(settings, state.method)
        }
        _ => settings.clone(),
    };
    // ellipsoidal (also as auto's choice): the query roulette, from a pilot with a time budget
    // (counted against it), or from the resumed state; combined: its allocation's.
    let roulette = match resume {
        // A family alone is that method's render: `ellipsoidal` alone chooses its roulette as
        // `ellipsoidal` does (the allocation's pilot weighed it making every query), unless given.
        _ if allocation.as_ref().is_some_and(|a| a.alone == Some(Method::Ellipsoidal))
            && settings.query_roulette.is_none() =>
        {
            let ellipsoidal = RenderSettings { query_roulette: None, ..render_settings.clone() };
            Some(query_roulette::choose(ctx, scene, &ellipsoidal, budget)?)
        }
        _ if allocation.is_some() => {
            allocation.as_ref().filter(|a| a.alone != Some(Method::Direct)).map(|a| query_roulette::Choice {
                probability: a.query_roulette,
                reason: "the combined render's allocation".into(),
                pilot_seconds: 0.0,
            })
        }
        _ if !query_roulette::applies(&render_settings) => None,
        None => Some(query_roulette::choose(ctx, scene, &render_settings, budget)?),
        Some(state) => Some(query_roulette::Choice {
            probability: render_settings.query_roulette.unwrap_or(query_roulette::saved(state)),
            reason: "as the resumed render had it".into(),
            pilot_seconds: 0.0,
        }),
    };
    let mut render_settings = match &roulette {
        Some(r) => RenderSettings { query_roulette: Some(r.probability), ..render_settings },
        None => render_settings,
    };
    // direct and combined (also as auto's choice): the camera pilot, by the whole render's
    // budget, or as the resumed render had it.
    if render_settings.camera_pilot_spp.is_none() {
        render_settings.camera_pilot_spp = Some(match resume {
            Some(state) => super::bidirectional::camera_pilot::saved_camera_pilot(state),
            None => super::bidirectional::default_camera_pilot(&render_settings, budget),
        });
    }
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
        + Duration::from_secs_f64(allocation.as_ref().map_or(0.0, |a| a.pilot_seconds))
        + Duration::from_secs_f64(roulette.as_ref().map_or(0.0, |r| r.pilot_seconds));
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
    let stats = if settings.stats { tracer.stats_report()? } else { None };
    let target_pilot_spp = tracer.target_pilot_spp();
    let camera_pilot_spp = tracer.camera_pilot_spp();
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
        camera_pilot_spp,
        band_index: tracer.band_index_report(),
        band_index_off: tracer.band_index_off(),
        samples_to_visit_every_bin: tracer.samples_to_visit_every_bin(),
        choice,
        allocation,
        roulette,
        stopped_early: flow.is_break(),
        state,
    })
}

#[cfg(test)]
mod pass_sizer_tests {
    use super::{Budget, Duration, PassSizer, RenderOutput, RenderSettings};

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

    #[test]
    fn a_render_well_past_its_time_budget_says_so() {
        let settings = RenderSettings { width: 8, height: 8, ..Default::default() };
        let took = |seconds: f64| RenderOutput {
            rendering: Duration::from_secs_f64(seconds),
            ..RenderOutput::black(&settings, Duration::ZERO)
        };
        let two = Budget::Time(Duration::from_secs(2));
        assert!(
            took(5.2).budget_overrun_warning(two).unwrap().contains("5.20 s of rendering for a time budget of 2.00 s")
        );
        // Within a fifth, or within a quarter second of a short budget: no warning.
        assert!(took(2.3).budget_overrun_warning(two).is_none());
        assert!(took(0.3).budget_overrun_warning(Budget::Time(Duration::from_millis(100))).is_none());
        // A budget of samples takes the time it takes.
        assert!(took(100.0).budget_overrun_warning(Budget::Samples(4)).is_none());
    }
}
