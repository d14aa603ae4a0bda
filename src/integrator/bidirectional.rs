//! Bidirectional path tracing, aware of path length: with direct connections (`--method
//! direct`; Veach 1997, PBRT's BDPT) every connection's optical length is known before its
//! shadow ray, so connections the gate weighs zero cost no ray; with ellipsoidal connections
//! (`--method ellipsoidal`; Pediredla et al. 2019) every slot draws a target length from the
//! gate and joins its subpaths through a vertex on the spheroid of that length. A pass runs as
//! waves of slots (one camera subpath and one light subpath per pixel and sample), like the
//! path tracer. The stages of a wave, in order:
//!
//! ```text
//! generate_subpaths                     pinhole + light vertices; both rays -> next_ray_queue;
//!                                       (ellipsoidal) the slot's target length
//! for round in 0, 1, ...:               (until every subpath has ended; a traversal that
//!                                       stops at the budget resumes one round later)
//!     setup_dispatch(rays)              next_ray_queue becomes ray_queue
//!     extend_subpaths                   closest hit, store the vertex, sample the BSDF, next
//!                                       ray (a traversal stopped at the budget: next round)
//! connect_direct                        every (s, t): contribution, MIS, shadow_queue
//! | connect_spherical                   (ellipsoidal) lights seen directly, and camera vertices
//!                                       joined to directional lights: splat, shadow_queue
//!   queue_ellipsoid_queries             every (s, t) with a spheroid -> ellipsoid_queries
//!   setup_dispatch(ellipsoid_queries)
//!   connect_ellipsoidal                 one query per entry: contribution, MIS, shadow_queue
//!                                       (BVHs where traversals cannot stop: connect_spherical
//!                                       and connect_ellipsoidal trace their shadow rays
//!                                       themselves, the queue stays empty, and t = 1
//!                                       contributions go straight to splat_film)
//! setup_dispatch(shadow_rays)
//! trace_shadow_rays                     occluded connections are cleared (media: attenuated)
//! [connect_medium]                      (ellipsoidal, scenes with media) per ellipsoid query
//!                                       entry: a vertex in the medium, both rays traced there
//! [setup_dispatch(shadow_resume)        while shadow rays stopped at the traversal budget
//!  trace_shadow_rays(resume)]           (read back after each pass)
//! accumulate                            t >= 2 contributions -> film, per pixel, in order
//! splat_light_paths                     t = 1 contributions -> splat_film (exact fixed
//!                                       point, integer atomics: the same bits in any order)
//! ```
//!
//! Slot `slot` keeps its camera subpath in queue entry `slot` and its light subpath in entry
//! `slot_count + slot` of the path, hit and queue buffers; its vertices lie in
//! `subpath_vertices[slot * stride ..]`, camera vertices first (see shaders/lib/subpath.wesl).
//!
//! `options` holds the methods' limits, defaults, checks of settings and strategy counters;
//! `slot_layout` what a slot holds, how many slots a wave fits, and its buffers;
//! `target_visits` how extra visits of stratified bins are shared out (band index or pilot
//! render); `camera_pilot` the per-pixel scales of the camera's density in `direct`'s weights.

pub mod camera_pilot;
mod options;
mod slot_layout;
mod stats;
mod target_visits;

use anyhow::{Result, ensure};

pub use super::check_settings;
use super::wavefront::{DISPATCH_ARGS_BYTES, ShadowRayStages, plan_waves, wave_target};
use super::{Integrator, Method, RenderSettings, Wavefront};
use crate::gpu::layout::{QueueCounters, WaveParams};
use crate::gpu::resources::read_buffer;
use crate::gpu::{GpuContext, Kernel};
use crate::scene::PreparedScene;
pub use camera_pilot::{camera_pilot_applies, default_camera_pilot, resolve_camera_pilot};
pub use options::{
    DEFAULT_CONNECTIONS_PER_QUERY, DEFAULT_NLOS_CONNECTIONS_PER_QUERY, DEFAULT_NLOS_TARGET_PILOT, Family, FamilyRole,
    MAX_BOUNCES, MAX_CONNECTIONS_PER_QUERY, StrategyStats, check_media, check_tracer_settings,
    default_connections_per_query, strategies,
};
use slot_layout::SlotLayout;

/// Slots a wave aims for on a CPU device (target_slots_per_wave: more on a GPU): each slot
/// holds two subpaths and all their connections (a few KiB).
const TARGET_SLOTS_PER_WAVE: u64 = 1 << 16;
/// Counters after the strategies' in `strategy_stats`: ellipsoid query work and guards, and the
/// check of a combined render's direct-family weights.
const QUERY_COUNTERS: usize = 7;

/// Pipelines of the stages.
struct Stages {
    generate_subpaths: Kernel,
    setup_dispatch_rays: Kernel,
    extend_subpaths: Kernel,
    connect: Kernel,
    /// Ellipsoidal connections: connect_spherical, queue_ellipsoid_queries and
    /// setup_dispatch(ellipsoid_queries) (connect is then indirect).
    ellipsoidal: Option<[Kernel; 3]>,
    shadow_rays: ShadowRayStages,
    /// Ellipsoidal renders of scenes with media: connect_medium, after the shadow rays.
    medium: Option<Kernel>,
    accumulate: Kernel,
    /// Not where the connection kernels splat light-tracing contributions themselves
    /// (`inline_shadow_rays`).
    splat_light_paths: Option<Kernel>,
}

/// Bind groups; `[even, odd]` rounds swap ray_queue and next_ray_queue.
struct Bindings {
    generate_subpaths: wgpu::BindGroup,
    setup_dispatch_rays: [wgpu::BindGroup; 2],
    extend_subpaths: [wgpu::BindGroup; 2],
    connect: wgpu::BindGroup,
    ellipsoidal: Option<[wgpu::BindGroup; 3]>,
    medium: Option<wgpu::BindGroup>,
    accumulate: wgpu::BindGroup,
    splat_light_paths: Option<wgpu::BindGroup>,
}

/// Bidirectional path tracing with direct connections, bound to one scene and one set of
/// settings, accumulating into its film (camera-side sums) and splat film (light tracing).
pub struct BidirectionalTracer<'a> {
    wf: Wavefront<'a>,
    stages: Stages,
    bindings: Bindings,
    /// Strategy counters summed over the waves so far (when `stats` is on).
    stats: Option<Vec<StrategyStats>>,
    /// Ellipsoid queries' loop iterations, triangles tested and triangles intersected, spheroids
    /// left out by the needle guard and points dropped by the length guard, summed; then a
    /// combined render's direct-family weights checked, and those that failed the check.
    query_work: [u64; QUERY_COUNTERS],
    /// Which connections join the subpaths.
    method: Method,
    /// Samples per pixel of a pilot render that shapes the target lengths' extra visits
    /// (`RenderSettings::target_pilot_spp`; 0 where the gate is not stratified or the
    /// per-pixel tables do not fit a binding).
    target_pilot_asked: u32,
    /// The pilot render is still to run (before the next pass).
    target_pilot_pending: bool,
    /// Samples per pixel of the pilot render whose extra visits the film's target lengths
    /// follow: `target_pilot_asked`, or fewer where a time budget cut it short
    /// (`run_target_pilot`); 0: none.
    target_pilot_traced: u32,
    /// The band index of an NLOS capture, while it is still to be built (before the pilot and
    /// the first pass).
    band_index: Option<crate::nlos::band_index::BandIndex>,
    /// The render's time budget (s), which the band index's build must not outlast; None: none.
    time_budget: Option<f64>,
    /// The band index whose build a render's time budget cut short: the next render tries again.
    band_index_deferred: Option<crate::nlos::band_index::BandIndex>,
    /// What became of the band index: built (its figures) or why not; None when not asked for.
    band_index_result: Option<std::result::Result<crate::nlos::band_index::BandIndexSummary, String>>,
    /// The built band index's masses per pixel and stratum (empty without one): they share out
    /// the target lengths' extra visits instead of a pilot render.
    band_masses: Vec<f32>,
    /// Samples per pixel of the camera pilot this tracer runs itself
    /// (`RenderSettings::camera_pilot_spp`; 0 where it does not apply, the scales do not fit a
    /// binding, or the tracer is a combined render's half).
    camera_pilot_asked: u32,
    /// The camera pilot is still to run (before the next pass).
    camera_pilot_pending: bool,
    /// Samples per pixel of the camera pilot whose scales the film's samples use; 0: none (a
    /// time budget cut it short, or none was asked for).
    camera_pilot_traced: u32,
    /// What camera_mis_scales holds, one scale per pixel (empty where the kernels keep no
    /// scales).
    camera_mis_scales: Vec<f32>,
    /// Bytes one binding may hold.
    binding_limit: u64,
    /// `target_visits` holds visit tables of the gate it was built for (a target pilot or a band
    /// index shares out extra visits); otherwise it is a stand-in of one element.
    keeps_visit_tables: bool,
}

impl<'a> BidirectionalTracer<'a> {
    /// Uploads the scene, creates the subpath and connection buffers and builds the kernels.
    pub fn new(ctx: &'a GpuContext, scene: &PreparedScene, settings: &RenderSettings) -> Result<Self> {
        Self::with_family(ctx, scene, settings, None)
    }

    /// A tracer of `settings.method` (direct or ellipsoidal) that is one half of a combined
    /// render (`family`: which half, and the ellipsoidal connections per direct one its weights
    /// count), or a method on its own (None).
    pub fn with_family(
        ctx: &'a GpuContext,
        scene: &PreparedScene,
        settings: &RenderSettings,
        family: Option<FamilyRole>,
    ) -> Result<Self> {
        check_tracer_settings(settings)?;
        // The method the user asked for: a combined render's, for either half.
        let method = if family.is_some() { Method::Combined.name() } else { settings.method.name() };
        if scene.scene.has_media() {
            check_media(scene, settings, method)?;
        }
        if scene.has_dielectric() {
            if settings.nlos.is_some() {
                anyhow::bail!(
                    "the scene has a dielectric (glass) material, which NLOS captures do not render yet with \
                     `{method}`: capture it with --method path"
                );
            }
            // A path seen or lit only through glass has no vertex a spheroid can place (none lies
            // next to a delta vertex, nor on or next to rough glass): ellipsoidal connections
            // alone would leave it out. A combined render's direct half samples those paths.
            if settings.method == Method::Ellipsoidal && family.is_none() {
                anyhow::bail!(
                    "the scene has a dielectric (glass) material: paths seen or lit through it have no ellipsoidal \
                     connection, so `ellipsoidal` alone would leave them out; render it with --method combined (direct \
                     connections for those paths, ellipsoidal ones for the rest), direct, path or auto"
                );
            }
        }
        let limit = settings.binding_limit.unwrap_or(u64::MAX).min(ctx.max_binding_size());
        let layout = SlotLayout::new(scene, settings);
        let (b, ellipsoidal) = (layout.bounces, layout.ellipsoidal);
        let (inline_shadow_rays, medium_connections) = (layout.inline_shadow_rays, layout.medium_connections);
        let strategy_count = strategies(b).len() as u64;
        let target = wave_target(ctx.is_cpu(), TARGET_SLOTS_PER_WAVE, layout.bytes.total(), settings);
        let (samples_per_pass, slots_per_wave) = plan_waves(settings, layout.fit(limit), target)?;
        let slots = slots_per_wave;

        let mut params = super::render_params(scene, settings);
        if let Some(role) = family {
            params.family_ratio = role.ratio as f32;
            params.family_medium_ratio = role.medium_ratio as f32;
        }
        let (mut r, mut constants, film) = super::upload_scene(ctx, scene, settings, &params, limit)?;
        if ellipsoidal {
            ensure!(
                params.target_length.cells > 0,
                "--method ellipsoidal: no path of this scene with at most {b} bounces can reach gate {}",
                settings.gate.describe()
            );
        }
        // A pilot render shares out extra visits of each pixel's stratified bins; their tables
        // (strata + 1 counts per pixel) must fit one binding, or the render goes without.
        let pixels = settings.width as u64 * settings.height as u64;
        let strata = params.target_length.strata as u64;
        let visits_bytes = pixels * (strata + 1) * 4;
        let visits_fit = ellipsoidal && strata > 0 && visits_bytes <= limit;
        let target_pilot_spp = if visits_fit { settings.target_pilot_spp } else { 0 };
        // A band index's masses share out the extra visits too (see `prepare`).
        let index_visits = visits_fit && settings.band_index && settings.nlos.is_some();
        let keeps_visit_tables = target_pilot_spp > 0 || index_visits;
        if keeps_visit_tables {
            r.storage_zeroed(ctx, "target_visits", visits_bytes, wgpu::BufferUsages::empty())?;
        }
        // The camera pilot's scales, one per pixel (see camera_pilot), where they fit a binding:
        // a direct render runs its own pilot; a combined render's halves keep the scales its
        // pilot writes (CombinedTracer passes them settings with a pilot only where it applies).
        let camera_scales = settings.camera_pilot_spp.unwrap_or(0) > 0
            && pixels * 4 <= limit
            && (family.is_some() || camera_pilot_applies(settings));
        let camera_pilot_spp =
            if camera_scales && family.is_none() { settings.camera_pilot_spp.unwrap_or(0) } else { 0 };
        let camera_tiles = camera_pilot::camera_scale_tiles(settings.width, settings.height);
        let camera_mis_scales = vec![1.0f32; if camera_scales { camera_tiles.count() } else { 0 }];
        if camera_scales {
            r.storage_zeroed(ctx, "pixel_moments", pixels * 4, wgpu::BufferUsages::empty())?;
        }
        let splat_film_bytes = super::film_elements(settings)? * super::FILM_ELEMENT_BYTES;
        ensure!(
            splat_film_bytes <= limit,
            "--method {} keeps its light-tracing image in one binding of at most {limit} bytes; {}x{} pixels x {} \
             bins need {splat_film_bytes}: reduce the resolution or the bins",
            settings.method.name(),
            settings.width,
            settings.height,
            settings.gate.bins()
        );
        layout.allocate(ctx, &mut r, slots)?;
        let none = wgpu::BufferUsages::empty();
        r.storage_zeroed(ctx, "counters", size_of::<QueueCounters>() as u64, none)?;
        r.storage_zeroed(ctx, "dispatch_args", DISPATCH_ARGS_BYTES, wgpu::BufferUsages::INDIRECT)?;
        r.storage_zeroed(ctx, "splat_film", splat_film_bytes, none)?;
        // Three counters per strategy, then five for the ellipsoid queries' work and guards.
        r.storage_zeroed(ctx, "strategy_stats", 4 * (3 * strategy_count + QUERY_COUNTERS as u64), none)?;
        // The band index of an NLOS capture (built in `prepare`), or stand-ins for its buffers.
        let mut band_index_result = None;
        let mut band_index_planned = false;
        if ellipsoidal && settings.band_index && settings.nlos.is_some() {
            match crate::nlos::band_index::unfit(&params, limit) {
                None => band_index_planned = true,
                Some(why) => band_index_result = Some(Err(why)),
            }
        }
        if !band_index_planned {
            crate::nlos::band_index::placeholders(ctx, &mut r)?;
        }

        constants.extend(layout.constants());
        if let Some(role) = family {
            ensure!(
                scene.scene.directional_lights.is_empty(),
                "{}: --method combined does not weigh connections to directional lights yet: use --method direct or \
                 ellipsoidal for this scene",
                scene.scene.source
            );
            constants.push(("FAMILY", role.family as u32 as f64));
        }
        if ellipsoidal || family.is_some() {
            // (A combined render's direct half leaves out the spheroids its ellipsoidal half does.)
            constants.push(("NEEDLE_GUARD", settings.ellipsoid_guards.needle as f64));
        }
        if ellipsoidal {
            constants.push(("CONNECTIONS_PER_QUERY", layout.connections_per_query as f64));
            constants.push(("LENGTH_GUARD", settings.ellipsoid_guards.length as f64));
            constants.push(("QUERY_SPLIT", settings.query.split as f64));
            constants.push(("QUERY_BOTTOM_NODES", settings.query.device_bottom_nodes() as f64));
            constants.push(("QUERY_WIDE", settings.query.wide as u32 as f64));
            constants.push(("QUERY_ALLOWANCE", settings.query.allowance as f64));
            constants.push(("QUERY_REFLECTION_WEIGHTS", settings.query.reflection_weights as u32 as f64));
        }
        constants.push(("BAND_ENTRIES_CHUNK_BITS", crate::nlos::band_index::entries_chunk_bits(limit) as f64));
        let band_index = match band_index_planned {
            true => Some(crate::nlos::band_index::BandIndex::new(ctx, &mut r, scene, &params, &constants, limit)?),
            false => None,
        };
        constants.push(("BAND_INDEX", band_index_planned as u32 as f64));
        constants.push(("STATS", settings.stats as u32 as f64));
        constants.push(("CAMERA_MIS_SCALES", camera_scales as u32 as f64));
        constants.push(("PIXEL_MOMENTS", camera_scales as u32 as f64));
        constants.push(("CAMERA_SCALE_TILE", camera_tiles.size as f64));
        constants.push(("ELLIPSOIDAL", ellipsoidal as u32 as f64));
        if let Some((s, t)) = settings.debug_strategy {
            constants.push(("DEBUG_S", s as f64));
            constants.push(("DEBUG_T", t as f64));
        }
        let with = |queue: f64| {
            let mut c = constants.clone();
            c.push(("QUEUE", queue));
            c
        };
        let build = |name: &str| Kernel::new(ctx, name, None, &constants);
        // The connection kernels are by far the largest: the driver compiles them on threads of
        // their own while this one builds the rest (pipeline creation is CPU work, kernel by
        // kernel, even when the driver finds the compiled code in its disk cache).
        let stages = std::thread::scope(|scope| {
            let connect = scope.spawn(|| build(if ellipsoidal { "connect_ellipsoidal" } else { "connect_direct" }));
            let spherical = ellipsoidal.then(|| scope.spawn(|| build("connect_spherical")));
            let generate_subpaths = build("generate_subpaths");
            let setup_dispatch_rays = Kernel::new(ctx, "setup_dispatch", Some("rays"), &with(0.0));
            let extend_subpaths = build("extend_subpaths");
            let queue = ellipsoidal.then(|| {
                [
                    build("queue_ellipsoid_queries"),
                    Kernel::new(ctx, "setup_dispatch", Some("ellipsoid_queries"), &with(2.0)),
                ]
            });
            let shadow_rays = ShadowRayStages::new(ctx, &constants, &r);
            let medium = medium_connections.then(|| build("connect_medium"));
            let accumulate = build("accumulate");
            let splat_light_paths = (!inline_shadow_rays).then(|| build("splat_light_paths"));
            let joined =
                |h: std::thread::ScopedJoinHandle<Kernel>| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e));
            Stages {
                generate_subpaths,
                setup_dispatch_rays,
                extend_subpaths,
                connect: joined(connect),
                ellipsoidal: spherical.zip(queue).map(|(spherical, [queue, setup])| [joined(spherical), queue, setup]),
                shadow_rays,
                medium,
                accumulate,
                splat_light_paths,
            }
        });
        let even = r.clone();
        let odd = r.swapped("ray_queue", "next_ray_queue");
        let both = |k: &Kernel| [k.bind(ctx, &even), k.bind(ctx, &odd)];
        let bindings = Bindings {
            generate_subpaths: stages.generate_subpaths.bind(ctx, &odd),
            setup_dispatch_rays: both(&stages.setup_dispatch_rays),
            extend_subpaths: both(&stages.extend_subpaths),
            connect: stages.connect.bind(ctx, &even),
            ellipsoidal: stages.ellipsoidal.as_ref().map(|kernels| kernels.each_ref().map(|k| k.bind(ctx, &even))),
            medium: stages.medium.as_ref().map(|k| k.bind(ctx, &even)),
            accumulate: stages.accumulate.bind(ctx, &even),
            splat_light_paths: stages.splat_light_paths.as_ref().map(|k| k.bind(ctx, &even)),
        };
        let stats = settings
            .stats
            .then(|| strategies(b).into_iter().map(|(s, t)| StrategyStats { s, t, ..Default::default() }).collect());
        let wf = Wavefront::new(
            ctx,
            params,
            r,
            film,
            constants,
            (samples_per_pass, slots_per_wave),
            scene.wide.most_stops(),
            settings.gate.kind(),
        );
        Ok(Self {
            wf,
            stages,
            bindings,
            stats,
            query_work: [0; QUERY_COUNTERS],
            method: settings.method,
            target_pilot_asked: target_pilot_spp,
            target_pilot_pending: target_pilot_spp > 0,
            target_pilot_traced: 0,
            band_index,
            time_budget: None,
            band_index_deferred: None,
            band_index_result,
            band_masses: Vec::new(),
            camera_pilot_asked: camera_pilot_spp,
            camera_pilot_pending: camera_pilot_spp > 0,
            camera_pilot_traced: 0,
            camera_mis_scales,
            binding_limit: limit,
            keeps_visit_tables,
        })
    }

    fn render_wave(&mut self, wave: WaveParams) -> Result<()> {
        let ctx = self.wf.ctx;
        self.wf.write_wave(&wave);
        let args = self.wf.resources.get("dispatch_args").unwrap();
        let (s, b) = (&self.stages, &self.bindings);
        // ---- trace the subpaths ----
        self.wf.trace_rounds(
            1,
            |pass| s.generate_subpaths.dispatch(pass, &b.generate_subpaths, wave.slot_count),
            |pass, r| {
                let parity = (r % 2) as usize;
                s.setup_dispatch_rays.dispatch(pass, &b.setup_dispatch_rays[parity], 1);
                s.extend_subpaths.dispatch_indirect(pass, &b.extend_subpaths[parity], args, 0);
            },
        )?;
        // ---- connect, test visibility, accumulate ----
        self.wf.submit_pass("connect", |pass| {
            match (&s.ellipsoidal, &b.ellipsoidal) {
                (Some([spherical, queue, setup]), Some([spherical_group, queue_group, setup_group])) => {
                    spherical.dispatch(pass, spherical_group, wave.slot_count);
                    queue.dispatch(pass, queue_group, wave.slot_count);
                    setup.dispatch(pass, setup_group, 1);
                    s.connect.dispatch_indirect(pass, &b.connect, args, 24);
                }
                _ => s.connect.dispatch(pass, &b.connect, wave.slot_count),
            }
            s.shadow_rays.encode(pass, args);
            // Vertices in media: both segments traced there, after the surface connections'
            // shadow rays (connect_medium adds to their decided contributions).
            if let (Some(kernel), Some(group)) = (&s.medium, &b.medium) {
                kernel.dispatch_indirect(pass, group, args, 24);
            }
        });
        // Shadow rays that stopped at the traversal budget resume until every one is decided.
        while self.wf.counters()?.unfinished_shadow_rays > 0 {
            self.wf.submit_pass("resume", |pass| s.shadow_rays.encode_resume(pass, args));
        }
        self.wf.submit_pass("accumulate", |pass| {
            s.accumulate.dispatch(pass, &b.accumulate, wave.pixel_count);
            if let (Some(kernel), Some(group)) = (&s.splat_light_paths, &b.splat_light_paths) {
                kernel.dispatch(pass, group, wave.slot_count);
            }
        });
        ctx.wait_idle()?;
        if let Some(stats) = &mut self.stats {
            // Per-wave u32 counters cannot overflow (one connection per slot and strategy).
            let buffer = self.wf.resources.get("strategy_stats").unwrap();
            let counts: Vec<u32> = read_buffer(ctx, buffer, 3 * stats.len() + QUERY_COUNTERS)?;
            for (st, c) in stats.iter_mut().zip(counts.chunks(3)) {
                st.evaluated += c[0] as u64;
                st.skipped_by_gate += c[1] as u64;
                st.shadow_rays += c[2] as u64;
            }
            for (w, &c) in self.query_work.iter_mut().zip(&counts[3 * stats.len()..]) {
                *w += c as u64;
            }
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            encoder.clear_buffer(buffer, 0, None);
            ctx.queue.submit([encoder.finish()]);
        }
        Ok(())
    }
}

impl Integrator for BidirectionalTracer<'_> {
    fn wavefront(&self) -> &Wavefront<'_> {
        &self.wf
    }

    fn render_pass(&mut self, samples: u32) -> Result<()> {
        self.prepare()?;
        for wave in self.wf.pass_waves(samples)? {
            self.render_wave(wave)?;
        }
        self.wf.pass_done(samples);
        Ok(())
    }

    fn target_pilot_spp(&self) -> u32 {
        self.target_pilot_traced
    }

    fn camera_pilot_spp(&self) -> u32 {
        self.camera_pilot_traced
    }

    /// As stored (every one 1 after a pilot cut short).
    fn camera_mis_scales(&self) -> &[f32] {
        &self.camera_mis_scales
    }

    fn adopt_camera_mis_scales(&mut self, scales: &[f32], traced: u32) {
        if self.keeps_camera_scales() {
            assert_eq!(scales.len(), self.camera_mis_scales.len(), "camera scales of an image of another size");
            self.camera_pilot_pending = false;
            self.finish_camera_pilot(scales.to_vec(), traced);
        }
    }

    fn samples_to_visit_every_bin(&self) -> Option<u64> {
        let t = &self.wf.params.target_length;
        (t.strata > 0).then(|| crate::film::target::samples_to_visit_every_bin(t))
    }

    fn set_time_budget(&mut self, seconds: Option<f64>) {
        self.time_budget = seconds;
        self.band_index = self.band_index.take().or(self.band_index_deferred.take());
    }

    fn band_index_off(&self) -> Option<String> {
        self.band_index_result.as_ref()?.as_ref().err().cloned()
    }

    fn band_index_report(&self) -> Option<String> {
        match self.band_index_result.as_ref()? {
            Ok(b) => Some(format!(
                "{}{}",
                b.describe(),
                if self.wf.params.target_length.band_index == 0 { "; off after a change of gate" } else { "" }
            )),
            Err(why) => Some(format!("off: {why}")),
        }
    }

    fn prepare(&mut self) -> Result<()> {
        self.build_band_index()?;
        if self.apply_band_allocation() {
            self.target_pilot_pending = false;
        }
        if self.target_pilot_pending {
            self.run_target_pilot()?;
        }
        if self.camera_pilot_pending {
            self.run_camera_pilot()?;
        }
        Ok(())
    }

    fn limit_pass_pixels(&mut self, pixels: Option<u32>) {
        self.wf.pass_pixels = pixels;
    }

    fn warm_up(&mut self) -> Result<()> {
        let pilot = std::mem::take(&mut self.target_pilot_pending);
        let camera_pilot = std::mem::take(&mut self.camera_pilot_pending);
        let band_index = self.band_index.take();
        let seed = self.wf.params.seed;
        let traced = self.warm_up_pass();
        self.restart(seed);
        traced?;
        self.target_pilot_pending = pilot;
        self.camera_pilot_pending = camera_pilot;
        self.band_index = band_index;
        Ok(())
    }

    fn reset_film(&mut self) {
        self.wf.reset_film(&["splat_film"]);
    }

    fn save_state(&self) -> Result<super::checkpoint::RenderState> {
        let mut state = self.wf.save_state(self.method)?;
        let splats: Vec<[u32; 4]> = read_buffer(
            self.wf.ctx,
            self.wf.resources.get("splat_film").unwrap(),
            self.wf.film_element_count() as usize,
        )?;
        state.push("splat_film", &splats);
        state.push("target_pilot", &[self.target_pilot_pending as u32, self.target_pilot_traced]);
        state.push("camera_pilot", &[self.camera_pilot_pending as u32, self.camera_pilot_traced]);
        state.push("camera_mis_scales", &self.camera_mis_scales);
        state.push(super::query_roulette::STATE_BLOB, &[self.wf.params.query_roulette.to_bits()]);
        Ok(state)
    }

    fn load_state(&mut self, state: &super::checkpoint::RenderState) -> Result<()> {
        let splats: Vec<[u32; 4]> = state.values("splat_film", self.wf.film_element_count() as usize)?;
        let flags: Vec<u32> = state.values("target_pilot", 2)?;
        let camera_flags: Vec<u32> = state.values("camera_pilot", 2)?;
        let scales: Vec<f32> = state.values("camera_mis_scales", self.camera_mis_scales.len())?;
        self.wf.load_state(self.method, state)?;
        // The state's parameters say whether its render had a band index; this one uses its own.
        self.wf.params.target_length.band_index = matches!(self.band_index_result, Some(Ok(_))) as u32;
        self.wf.ctx.queue.write_buffer(
            self.wf.resources.get("params").unwrap(),
            0,
            bytemuck::bytes_of(&self.wf.params),
        );
        self.wf.ctx.queue.write_buffer(self.wf.resources.get("splat_film").unwrap(), 0, bytemuck::cast_slice(&splats));
        self.target_pilot_pending = flags[0] != 0;
        self.target_pilot_traced = flags[1];
        self.camera_pilot_pending = camera_flags[0] != 0;
        self.camera_pilot_traced = camera_flags[1];
        self.write_camera_mis_scales(scales);
        Ok(())
    }

    fn skip_samples(&mut self, samples: u64) -> Result<()> {
        self.prepare()?;
        self.wf.next_sample += samples;
        Ok(())
    }

    fn restart(&mut self, seed: u32) {
        self.wf.restart(seed, &["splat_film"]);
        // As a new tracer: the pilot (where the gate's tables fit) shapes the extra visits again.
        self.target_pilot_pending = self.target_pilot_fits();
        self.target_pilot_traced = 0;
        self.restart_camera_pilot();
    }

    fn set_gate(&mut self, scene: &PreparedScene, settings: &RenderSettings) -> Result<bool> {
        let moved = self.wf.set_gate(&settings.gate, super::target_sampler(scene, settings))?;
        if moved {
            // The extra visits were shaped for the old gate (wf.set_gate dropped them).
            // A new pilot shapes them again where the new gate's tables fit the buffer.
            self.target_pilot_pending = self.target_pilot_fits();
            self.target_pilot_traced = 0;
            self.restart_camera_pilot();
            self.reset_film();
        }
        Ok(moved)
    }

    fn stats_report(&self) -> Result<Option<String>> {
        Ok(self.stats_text())
    }
}
