//! The wavefront path tracer. A *pass* traces `samples_per_pass` samples of every pixel; it runs
//! as one or more *waves*, each a block of path slots (one per pixel and sample) small enough
//! for the device. A wave runs in one of two ways (see [`Tracing`]). In scenes small enough to
//! be held by every invocation, with a gate of one bin, its paths are traced whole:
//!
//! ```text
//! trace_paths                           every slot: camera ray to last vertex, each invocation
//!                                       tracing a pixel's samples one after another; the
//!                                       paths' gate-weighted sums -> film (one invocation per
//!                                       pixel) or -> path_radiance (several)
//! [accumulate]                          several invocations per pixel: the paths' sums -> film,
//!                                       per pixel, in sample order
//! ```
//!
//! Otherwise it runs in rounds of one vertex (two where paths sum their own contributions and
//! trace their own shadow rays):
//!
//! ```text
//! generate_camera_rays                  every slot -> next_ray_queue
//! for round in 0, 1, ...:               (until every path has ended)
//!     setup_dispatch(rays)              next_ray_queue becomes ray_queue
//!     extend_paths                      closest hit, emission, light sample and its shadow
//!                                       ray, next ray (a closest-hit traversal that stops at
//!                                       the budget goes back to the queue: one round later);
//!                                       two vertices per round where paths sum their own
//!                                       contributions (SUM_PER_PATH) and trace their shadow
//!                                       rays; a queued one's contribution waits, and joins
//!                                       the path's sum at its next vertex
//!     [setup_dispatch(shadow_rays)      BVHs whose traversals can stop (RESUMABLE): the shadow
//!      trace_shadow_rays                rays extend_paths queued (it traces them itself in
//!      setup_dispatch(shadow_resume)    smaller BVHs), resume passes for those that stopped
//!      trace_shadow_rays(resume)] x R   at the budget (empty when none did; R = 0 while the
//!      setup_dispatch(shadow_cut)]      film is backed up, see render_pass), and a count of
//!                                       any still unfinished as cut short
//!     accumulate                        contributions -> film (W, bin), per pixel
//! accumulate                            SUM_PER_PATH (gates of one bin) instead: the paths'
//!                                       sums (and last waiting contributions) -> film, once
//! ```
//!
//! The stages of one vertex are fused into extend_paths (shaders/lib/path_vertex.wesl
//! extend_path, which trace_paths calls too): on CPU Vulkan a stage boundary's round trip of
//! the path state through memory cost more than the stages' own work. On meshes large enough
//! for resumable traversals, shadow rays stay a compacted stage of their own: there their long
//! traversals cost more than the round trip.

use anyhow::Result;

use super::wavefront::{DISPATCH_ARGS_BYTES, ShadowRayStages, plan_waves, wave_target};
use super::{Integrator, LightStrategy, RenderSettings, Wavefront};
use crate::gpu::layout::{Contribution, Hit, PathState, QueueCounters, ShadowRay, Splat, WaveParams};
use crate::gpu::{GpuContext, Kernel};
use crate::scene::PreparedScene;

/// Path slots a wave aims for on a CPU device when the caller does not fix the samples per pass
/// (target_slots_per_wave: more on a GPU).
const TARGET_SLOTS_PER_WAVE: u64 = 1 << 18;
/// Vertices extend_paths adds to a path per round when paths sum their own contributions
/// (SUM_PER_PATH) in BVHs whose traversals cannot stop. On lavapipe (Cornell box, 64x64, 5
/// bounces, median of 3 alternating runs) 2 vertices per round traced 2.32 M samples/s, 3
/// traced 2.26 M and 6 (every vertex in one round) 2.05 M, against 1.90 M for 1: beyond 2 the
/// lanes of ended paths idle more than the saved round trips of the path state gain.
const VERTICES_PER_ROUND_SUMMING: u32 = 2;
/// Pipelines and bind groups of the wavefront rounds (`[even, odd]` rounds swap ray_queue and
/// next_ray_queue).
struct Rounds {
    generate_camera_rays: Kernel,
    setup_dispatch_rays: Kernel,
    extend_paths: Kernel,
    shadow_rays: ShadowRayStages,
    generate_camera_rays_binding: wgpu::BindGroup,
    setup_dispatch_rays_bindings: [wgpu::BindGroup; 2],
    extend_paths_bindings: [wgpu::BindGroup; 2],
    /// Resume passes of each round's shadow rays: as many as a ray can need
    /// (`WideBvh::most_stops`), at most MAX_SHADOW_RESUMES.
    shadow_resumes: u32,
    /// Vertices extend_paths adds to a path before it goes back to the queue.
    vertices_per_round: u32,
}

/// How the path tracer's waves run.
enum Tracing {
    /// Rounds of the wavefront: generate_camera_rays, then per round extend_paths (and the
    /// shadow-ray stages of large BVHs), until every path has ended.
    Rounds(Box<Rounds>),
    /// Whole paths, one trace_paths dispatch per wave: gates of one bin in scenes of at most
    /// MAX_SMALL_SCENE_TRIANGLES triangles (no traversal loops, so an invocation's loop count
    /// is its vertices; see tracers_per_pixel). On lavapipe (Cornell box, 64x64, 5 bounces,
    /// median of 3 alternating runs) it traced 3.59 M samples/s against 2.59 M for rounds of two
    /// vertices: no path state goes through memory, and lanes start new paths instead of idling.
    /// One invocation per pixel adding to the film itself (no path_radiance, no accumulate)
    /// then raised it from 5.31 to 6.26 M.
    /// In BVH scenes it traced no faster than rounds (sphere_5120.glb: 0.36 against 0.38 M),
    /// and there traversal loops would share lavapipe's loop budget.
    WholePaths { trace_paths: Kernel, binding: wgpu::BindGroup },
}

/// A path tracer bound to one scene and one set of settings, accumulating into its film.
pub struct PathTracer<'a> {
    wf: Wavefront<'a>,
    tracing: Tracing,
    accumulate: Kernel,
    accumulate_binding: wgpu::BindGroup,
    /// Paths sum their own gate-weighted contributions (SUM_PER_PATH; every gate of one bin):
    /// accumulate runs once per wave instead of after every round. A next-event contribution
    /// whose shadow ray is queued waits in `contributions` and joins its path's sum at the
    /// path's next vertex, or in accumulate.
    sum_per_path: bool,
    /// A copy of the film before the pass, one buffer per film chunk, while passes run no
    /// resume passes (see [`PathTracer::render_pass`]); None once a pass needed them, and in
    /// renders without shadow-ray stages or with films above MOST_BACKED_UP_FILM_BYTES.
    film_backup: Option<Vec<wgpu::Buffer>>,
}

/// Largest film (bytes, all chunks) the path tracer backs up before each pass so that its
/// shadow rays can go without resume passes. On lavapipe a resume pass costs two dispatches
/// of about 0.1 ms even when empty, six to eight of them per round in a large BVH: on the fence
/// (8 bounces) a 1-spp pass of a 32x32 image took 15 ms with them and 10 ms without, of which
/// about 4 ms is the samples' own work. Films this large take passes long enough for that to
/// vanish, and the copy stays far below a pass's time.
const MOST_BACKED_UP_FILM_BYTES: u64 = 64 << 20;

/// Most resume passes a round of the path tracer runs for shadow rays that stopped at the
/// traversal budget (a resume pass costs two empty dispatches when every ray was decided):
/// shadow rays that stop more than MAX_SHADOW_RESUMES times (which takes more than
/// MAX_SHADOW_RESUMES - 1 budgets of resume-mode steps, asked for only by adversarial
/// geometry) are counted as cut short.
pub const MAX_SHADOW_RESUMES: u32 = 8;

impl<'a> PathTracer<'a> {
    /// Uploads the scene, creates the wavefront state and builds the specialised kernels.
    pub fn new(ctx: &'a GpuContext, scene: &PreparedScene, settings: &RenderSettings) -> Result<Self> {
        check_media(scene, settings)?;
        let limit = settings.binding_limit.unwrap_or(u64::MAX).min(ctx.max_binding_size());
        let params = super::render_params(scene, settings);
        let resumable = scene.wide.traversals_can_stop();
        let sum_per_path = settings.gate.kind() != crate::film::GateKind::Transient;
        // Next-event contributions wait in `contributions` for their queued shadow rays
        // (path_vertex.wesl contribute; media scenes trace them on the spot).
        let queued_next_event = resumable && !scene.scene.has_media();
        let medium_connections = uses_medium_connections(scene, settings);
        // Emission, next-event estimation, and a medium connection.
        let contributions_per_slot = if medium_connections { 3 } else { 2 };
        let whole_paths = sum_per_path && !resumable && !crate::bvh::small_scene_triangles(&scene.triangles).is_empty();

        // Slots per wave: within the largest per-slot buffer's binding.
        let largest_per_slot =
            if whole_paths { 3 * 4 } else { size_of::<PathState>().max(size_of::<ShadowRay>()) as u64 };
        // Per-slot state: a path state, a hit, two queue entries, a shadow ray, the
        // contributions and the path's radiance.
        let bytes_per_slot = (size_of::<PathState>() + size_of::<Hit>() + 8 + size_of::<ShadowRay>()) as u64
            + contributions_per_slot * size_of::<Contribution>() as u64
            + 12;
        let target = wave_target(ctx.is_cpu(), TARGET_SLOTS_PER_WAVE, bytes_per_slot, settings);
        let (samples_per_pass, slots_per_wave) = plan_waves(settings, limit / largest_per_slot, target)?;
        // Whole paths keep their state in registers: the rounds' per-slot buffers get one element.
        let slots = if whole_paths { 1 } else { slots_per_wave };

        let (mut r, mut constants, film) = super::upload_scene(ctx, scene, settings, &params, limit)?;
        let none = wgpu::BufferUsages::empty();
        r.storage_zeroed(ctx, "paths", size_of::<PathState>() as u64 * slots, none)?;
        r.storage_zeroed(ctx, "hits", size_of::<Hit>() as u64 * slots, none)?;
        r.storage_zeroed(ctx, "ray_queue", 4 * slots, none)?;
        r.storage_zeroed(ctx, "next_ray_queue", 4 * slots, none)?;
        r.storage_zeroed(ctx, "shadow_queue", size_of::<ShadowRay>() as u64 * slots, none)?;
        r.storage_zeroed(ctx, "counters", size_of::<QueueCounters>() as u64, none)?;
        r.storage_zeroed(ctx, "dispatch_args", DISPATCH_ARGS_BYTES, wgpu::BufferUsages::INDIRECT)?;
        let contribution_slots = if sum_per_path && !queued_next_event { 1 } else { slots };
        r.storage_zeroed(
            ctx,
            "contributions",
            contributions_per_slot * size_of::<Contribution>() as u64 * contribution_slots,
            none,
        )?;
        let path_radiance_bytes = if sum_per_path { 3 * 4 * slots_per_wave } else { 4 };
        r.storage_zeroed(ctx, "path_radiance", path_radiance_bytes, none)?;
        // trace_shadow_rays can clear light-tracing splats; the path tracer has none.
        r.storage_zeroed(ctx, "splats", size_of::<Splat>() as u64, none)?;
        // accumulate reads subpath lengths only for bidirectional methods
        // (CONTRIBUTIONS_PER_STRATEGY 0 here).
        r.storage_zeroed(ctx, "subpath_lengths", 4, none)?;
        // Not where traversals can stop: a second vertex would resume the first's stopped
        // traversal in the same invocation (beyond lavapipe's loop limit), or overwrite its
        // waiting contribution.
        let vertices_per_round = if sum_per_path && !resumable { VERTICES_PER_ROUND_SUMMING } else { 1 };
        constants.push(("LIGHT_STRATEGY", settings.light_strategy as u32 as f64));
        constants.push(("CONTRIBUTIONS_PER_SLOT", contributions_per_slot as f64));
        constants.push(("MEDIUM_CONNECTIONS", medium_connections as u32 as f64));
        constants.push(("SUM_PER_PATH", sum_per_path as u32 as f64));
        constants.push(("VERTICES_PER_ROUND", vertices_per_round as f64));

        let accumulate = Kernel::new(ctx, "accumulate", None, &constants);
        let accumulate_binding = accumulate.bind(ctx, &r);
        let tracing = if whole_paths {
            let trace_paths = Kernel::new(ctx, "trace_paths", None, &constants);
            let binding = trace_paths.bind(ctx, &r);
            Tracing::WholePaths { trace_paths, binding }
        } else {
            let with = |queue: f64| {
                let mut c = constants.clone();
                c.push(("QUEUE", queue));
                c
            };
            let generate_camera_rays = Kernel::new(ctx, "generate_camera_rays", None, &constants);
            let setup_dispatch_rays = Kernel::new(ctx, "setup_dispatch", Some("rays"), &with(0.0));
            let extend_paths = Kernel::new(ctx, "extend_paths", None, &constants);
            // Even rounds read ray_queue and push to next_ray_queue; odd rounds the other way round.
            let even = r.clone();
            let odd = r.swapped("ray_queue", "next_ray_queue");
            let both = |k: &Kernel| [k.bind(ctx, &even), k.bind(ctx, &odd)];
            Tracing::Rounds(Box::new(Rounds {
                // generate fills the queue that round 0 reads.
                generate_camera_rays_binding: generate_camera_rays.bind(ctx, &odd),
                setup_dispatch_rays_bindings: both(&setup_dispatch_rays),
                extend_paths_bindings: both(&extend_paths),
                shadow_rays: ShadowRayStages::new(ctx, &constants, &r),
                generate_camera_rays,
                setup_dispatch_rays,
                extend_paths,
                shadow_resumes: if resumable { scene.wide.most_stops().min(MAX_SHADOW_RESUMES) } else { 0 },
                vertices_per_round,
            }))
        };
        let film_chunks: Vec<&wgpu::Buffer> = crate::gpu::resources::chunk_names("film")[..film.chunks as usize]
            .iter()
            .map(|n| r.get(n).unwrap())
            .collect();
        let film_bytes: u64 = film_chunks.iter().map(|b| b.size()).sum();
        let film_backup = if matches!(&tracing, Tracing::Rounds(s) if s.shadow_resumes > 0)
            && film_bytes <= MOST_BACKED_UP_FILM_BYTES
        {
            let mut backup = Vec::new();
            for chunk in film_chunks {
                backup.push(ctx.allocate("film_backup", chunk.size(), || {
                    ctx.device.create_buffer(&wgpu::BufferDescriptor {
                        label: Some("film_backup"),
                        size: chunk.size(),
                        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
                        mapped_at_creation: false,
                    })
                })?);
            }
            Some(backup)
        } else {
            None
        };
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
        Ok(Self { wf, tracing, accumulate, accumulate_binding, sum_per_path, film_backup })
    }

    /// Resume passes per round the next pass runs for shadow rays stopped at the traversal
    /// budget: none while the film is backed up before each pass, else as many as a ray can
    /// need (at most MAX_SHADOW_RESUMES); 0 where shadow rays have no stages of their own.
    pub fn shadow_resume_passes(&self) -> u32 {
        match &self.tracing {
            Tracing::Rounds(s) if self.film_backup.is_none() => s.shadow_resumes,
            _ => 0,
        }
    }

    /// Copies the film into `film_backup`, or (`restore`) the backup into the film.
    fn copy_film(&self, backup: &[wgpu::Buffer], restore: bool) {
        let ctx = self.wf.ctx;
        let mut encoder =
            ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("film_backup") });
        for (name, copy) in crate::gpu::resources::chunk_names("film").iter().zip(backup) {
            let film = self.wf.resources.get(name).unwrap();
            let (from, to) = if restore { (copy, film) } else { (film, copy) };
            encoder.copy_buffer_to_buffer(from, 0, to, 0, copy.size());
        }
        ctx.queue.submit([encoder.finish()]);
    }

    /// Waves a full pass takes (more than one when the image does not fit one wave).
    pub fn waves_per_pass(&self) -> u64 {
        self.wf.waves_per_pass()
    }

    fn render_wave(&self, mut wave: WaveParams) -> Result<()> {
        let ctx = self.wf.ctx;
        match &self.tracing {
            Tracing::WholePaths { trace_paths, binding } => {
                let target = if ctx.is_cpu() { TARGET_TRACERS_CPU } else { TARGET_TRACERS_GPU };
                wave.tracers_per_pixel = tracers_per_pixel(&wave, self.wf.params.max_bounces, target);
                self.wf.write_wave(&wave);
                self.wf.submit_pass("trace_paths", |pass| {
                    trace_paths.dispatch(pass, binding, wave.pixel_count * wave.tracers_per_pixel);
                    // With one tracer per pixel, trace_paths adds to the film itself.
                    if wave.tracers_per_pixel > 1 {
                        self.accumulate.dispatch(pass, &self.accumulate_binding, wave.pixel_count);
                    }
                });
            }
            Tracing::Rounds(s) => {
                self.wf.write_wave(&wave);
                let args = self.wf.resources.get("dispatch_args").unwrap();
                self.wf.trace_rounds(
                    s.vertices_per_round,
                    |pass| s.generate_camera_rays.dispatch(pass, &s.generate_camera_rays_binding, wave.slot_count),
                    |pass, r| {
                        let parity = (r % 2) as usize;
                        s.setup_dispatch_rays.dispatch(pass, &s.setup_dispatch_rays_bindings[parity], 1);
                        s.extend_paths.dispatch_indirect(pass, &s.extend_paths_bindings[parity], args, 0);
                        if s.shadow_resumes > 0 {
                            s.shadow_rays.encode(pass, args);
                            for _ in 0..self.shadow_resume_passes() {
                                s.shadow_rays.encode_resume(pass, args);
                            }
                            s.shadow_rays.encode_cut(pass);
                        }
                        if !self.sum_per_path {
                            self.accumulate.dispatch(pass, &self.accumulate_binding, wave.pixel_count);
                        }
                    },
                )?;
                if self.sum_per_path {
                    self.wf.submit_pass("accumulate", |pass| {
                        self.accumulate.dispatch(pass, &self.accumulate_binding, wave.pixel_count)
                    });
                }
            }
        }
        ctx.wait_idle()
    }
}

/// Invocations of trace_paths a wave aims for: enough to keep a device's cores busy, and as
/// few as that allows, so that each invocation traces many paths (its lanes rarely wait at its
/// last one) and, at one invocation per pixel, adds to the film itself (no accumulate, no
/// path_radiance). On lavapipe 4096, 16384 and 65536 tracers traced within 3% of each other
/// (Cornell box, 64x64); a GPU wants tens of thousands of threads in flight.
const TARGET_TRACERS_CPU: u32 = 1 << 12;
const TARGET_TRACERS_GPU: u32 = 1 << 16;
/// Most vertices one invocation of trace_paths is given: lavapipe (gallivm) ends all loops of an
/// invocation after 65535 iterations in total, silently (trace_paths counts a cut invocation).
const MOST_VERTICES_PER_TRACER: u64 = 65000;

/// Invocations of trace_paths per pixel of `wave` (WaveParams::tracers_per_pixel): about
/// `target_tracers` in all, and enough that none traces more than MOST_VERTICES_PER_TRACER
/// vertices (max_bounces + 1 per path), at most one per sample.
fn tracers_per_pixel(wave: &WaveParams, max_bounces: u32, target_tracers: u32) -> u32 {
    let paths_per_tracer = (MOST_VERTICES_PER_TRACER / (max_bounces as u64 + 1)).max(1);
    let for_loop_limit = (wave.samples as u64).div_ceil(paths_per_tracer);
    let for_parallelism = target_tracers.div_ceil(wave.pixel_count.max(1)) as u64;
    for_loop_limit.max(for_parallelism).clamp(1, wave.samples.max(1) as u64) as u32
}

impl Integrator for PathTracer<'_> {
    fn wavefront(&self) -> &Wavefront<'_> {
        &self.wf
    }

    /// Traces a pass. While the film is backed up, its shadow rays get no resume passes: the
    /// round's last shadow-ray stage counts a ray still unfinished as a traversal cut short,
    /// and a pass whose count rose is undone (film and counters as before it) and traced again
    /// with the resume passes, which every later pass keeps. The second tracing draws the same
    /// samples, so the film is what a render with resume passes throughout would hold. In BVHs
    /// of sensible quality no shadow ray stops at the budget, and the resume passes were only
    /// dispatch overhead.
    fn render_pass(&mut self, samples: u32) -> Result<()> {
        let waves = self.wf.pass_waves(samples)?;
        if let Some(backup) = &self.film_backup {
            let before = self.wf.counters()?;
            self.copy_film(backup, false);
            for &wave in &waves {
                self.render_wave(wave)?;
            }
            if self.wf.counters()?.truncated_traversals == before.truncated_traversals {
                self.wf.pass_done(samples);
                return Ok(());
            }
            self.copy_film(backup, true);
            let counters = self.wf.resources.get("counters").unwrap();
            self.wf.ctx.queue.write_buffer(counters, 0, bytemuck::bytes_of(&before));
            self.film_backup = None;
        }
        for wave in waves {
            self.render_wave(wave)?;
        }
        self.wf.pass_done(samples);
        Ok(())
    }

    fn reset_film(&mut self) {
        self.wf.reset_film(&[]);
    }

    fn save_state(&self) -> Result<super::checkpoint::RenderState> {
        self.wf.save_state(super::Method::Path)
    }

    fn load_state(&mut self, state: &super::checkpoint::RenderState) -> Result<()> {
        self.wf.load_state(super::Method::Path, state)
    }

    fn skip_samples(&mut self, samples: u64) -> Result<()> {
        self.wf.next_sample += samples;
        Ok(())
    }

    fn restart(&mut self, seed: u32) {
        self.wf.restart(seed, &[]);
    }

    fn limit_pass_pixels(&mut self, pixels: Option<u32>) {
        self.wf.pass_pixels = pixels;
    }

    fn set_gate(&mut self, scene: &crate::scene::PreparedScene, settings: &RenderSettings) -> Result<bool> {
        let moved = self.wf.set_gate(&settings.gate, super::target_sampler(scene, settings))?;
        if moved {
            self.reset_film();
        }
        Ok(moved)
    }
}

/// Errors for participating media `path` does not render yet: in NLOS captures, and with a camera
/// standing in a medium in a scene with glass that declares no media of its own (its inside would
/// hold the camera's medium, as in Mitsuba, where water or glass holds none). Thin panes pass the
/// medium on unchanged and need none.
/// Whether a render takes medium connections (the MEDIUM_CONNECTIONS override of `extend_paths`):
/// asked for, in a scene with a homogeneous medium, on a box or transient gate, with MIS between
/// the light strategies, outside NLOS captures.
pub fn uses_medium_connections(scene: &PreparedScene, settings: &RenderSettings) -> bool {
    use crate::film::GateKind;
    settings.medium_connections
        && scene.scene.media.iter().any(|m| m.grid.is_none())
        && matches!(settings.gate.kind(), GateKind::Box | GateKind::Transient)
        && settings.light_strategy == LightStrategy::Mis
        && settings.nlos.is_none()
}

fn check_media(scene: &PreparedScene, settings: &RenderSettings) -> Result<()> {
    if !scene.scene.has_media() {
        return Ok(());
    }
    let name = &scene.scene.source;
    anyhow::ensure!(
        settings.nlos.is_none(),
        "{name}: NLOS captures of scenes with participating media are not rendered yet"
    );
    if scene.scene.camera_medium.is_some() {
        let undeclared = |m: &crate::scene::MaterialDesc| {
            m.dielectric.is_some_and(|d| !d.thin) && m.media == crate::scene::medium::MediumInterface::default()
        };
        let materials = &scene.scene.materials;
        if let Some(glass) = scene.scene.triangles.iter().position(|t| undeclared(&materials[t.material as usize])) {
            // The shape's name where the scene names it, else the material's.
            let shape = scene.scene.nodes.iter().find(|n| n.triangles.contains(&glass)).map(|n| &n.name);
            let material = &materials[scene.scene.triangles[glass].material as usize].name;
            anyhow::bail!(
                "{name}: the camera stands in a medium and the glass `{}` declares no media: its inside would hold \
                 the camera's medium (declare the shape's `interior` and `exterior` media, or leave out the fog)",
                shape.filter(|s| !s.is_empty()).unwrap_or(material)
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wave(pixel_count: u32, samples: u32) -> WaveParams {
        WaveParams { samples, pixel_count, slot_count: pixel_count * samples, ..Default::default() }
    }

    /// Every sample has a tracer, no tracer is given more vertices than lavapipe's loop budget
    /// allows (where one path fits it), and small waves still get about TARGET_TRACERS.
    #[test]
    fn tracers_cover_the_wave_within_the_loop_budget() {
        for (pixels, samples) in [(1, 1), (16, 4096), (4096, 64), (65536, 4), (1 << 20, 1), (7, 3000)] {
            for max_bounces in [0, 5, 64, 1000, 70000] {
                let w = wave(pixels, samples);
                let k = tracers_per_pixel(&w, max_bounces, TARGET_TRACERS_GPU);
                assert!(k >= 1 && k <= samples, "{pixels} px, {samples} spp, {max_bounces}: {k}");
                let vertices = samples.div_ceil(k) as u64 * (max_bounces as u64 + 1);
                assert!(
                    vertices <= MOST_VERTICES_PER_TRACER || k == samples,
                    "{pixels} px, {samples} spp, {max_bounces}: {k}"
                );
                assert!(pixels * k >= TARGET_TRACERS_GPU.min(pixels * samples), "{pixels} px, {samples} spp: {k}");
            }
        }
    }
}
