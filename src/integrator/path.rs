//! The wavefront path tracer. A *pass* traces `samples_per_pass` samples of every pixel; it runs
//! as one or more *waves*, each a block of path slots (one per pixel and sample) small enough
//! for the device. The stages of a wave, in order, are the table of contents:
//!
//! ```text
//! generate_camera_rays                  every slot -> next_ray_queue
//! for round in 0..=max_bounces:         (stops early once every path has ended)
//!     setup_dispatch(rays)              next_ray_queue becomes ray_queue
//!     intersect_closest                 closest hits of ray_queue
//!     shade                             emission, light sample + shadow_queue, next ray
//!     setup_dispatch(shadow_rays)
//!     trace_shadow_rays                 occluded light samples are cleared
//!     accumulate                        contributions -> film (W, bin), per pixel
//! ```

use anyhow::{Result, ensure};

use super::RenderSettings;
use crate::film::Film;
use crate::gpu::layout::{Contribution, Hit, NONE, PathState, QueueCounters, RenderParams, ShadowRay, WaveParams};
use crate::gpu::resources::{ChunkLayout, MAX_CHUNKS, read_buffer};
use crate::gpu::{GpuContext, Kernel, Resources};
use crate::scene::PreparedScene;

/// Path slots a wave aims for when the caller does not fix the samples per pass.
const TARGET_SLOTS_PER_WAVE: u64 = 1 << 18;
/// Most slots one dispatch can cover (64 invocations x 65535 workgroups).
const MAX_SLOTS_PER_DISPATCH: u64 = 64 * 65535;
/// Most samples per pass: `accumulate` loops over a pixel's samples, and lavapipe (gallivm)
/// silently ends any loop after 65535 iterations.
const MAX_SAMPLES_PER_PASS: u32 = 4096;
/// Rounds encoded per submission; between submissions the host checks whether any path is
/// still alive, so huge --max-bounces values cost nothing once the paths have ended.
const ROUNDS_PER_SUBMISSION: u32 = 16;
/// Pipelines of the path tracer, one per stage.
struct Stages {
    generate_camera_rays: Kernel,
    setup_dispatch_rays: Kernel,
    intersect_closest: Kernel,
    shade: Kernel,
    setup_dispatch_shadow_rays: Kernel,
    trace_shadow_rays: Kernel,
    accumulate: Kernel,
}

/// Bind groups of the stages; `[even, odd]` rounds swap ray_queue and next_ray_queue.
struct Bindings {
    generate_camera_rays: wgpu::BindGroup,
    setup_dispatch_rays: [wgpu::BindGroup; 2],
    intersect_closest: [wgpu::BindGroup; 2],
    shade: [wgpu::BindGroup; 2],
    setup_dispatch_shadow_rays: wgpu::BindGroup,
    trace_shadow_rays: wgpu::BindGroup,
    accumulate: wgpu::BindGroup,
}

/// A path tracer bound to one scene and one set of settings, accumulating into its film.
pub struct PathTracer<'a> {
    ctx: &'a GpuContext,
    params: RenderParams,
    stages: Stages,
    bindings: Bindings,
    resources: Resources,
    film_layout: ChunkLayout,
    /// Specialisation constants of the kernels (the scene's and the gate's).
    constants: Vec<(&'static str, f64)>,
    /// Most path slots of one wave.
    slots_per_wave: u64,
    samples_per_pass: u32,
    /// Samples per pixel accumulated in the film.
    samples_in_film: u64,
    /// Index of the next sample to trace (never reused, so batches are independent).
    next_sample: u64,
}

impl<'a> PathTracer<'a> {
    /// Uploads the scene, creates the wavefront state and builds the specialised kernels.
    pub fn new(ctx: &'a GpuContext, scene: &PreparedScene, settings: &RenderSettings) -> Result<Self> {
        let (width, height) = (settings.width, settings.height);
        ensure!(width > 0 && height > 0, "the resolution must be at least 1x1");
        let pixels = width as u64 * height as u64;
        ensure!(pixels <= u32::MAX as u64, "{width}x{height} has more than 2^32 pixels");
        let gate = &settings.gate;
        let limit = settings.binding_limit.unwrap_or(u64::MAX).min(ctx.max_binding_size());

        // Slots per wave: as many as the target (or the requested samples per pass) asks for,
        // within one dispatch and within the largest per-slot buffer's binding.
        let largest_per_slot = size_of::<PathState>().max(size_of::<ShadowRay>()) as u64;
        let fit = (limit / largest_per_slot).clamp(1, MAX_SLOTS_PER_DISPATCH);
        let samples_per_pass = match settings.samples_per_pass {
            Some(k) => {
                ensure!(k <= MAX_SAMPLES_PER_PASS, "at most {MAX_SAMPLES_PER_PASS} samples per pass (got {k})");
                ensure!(
                    k <= 1 || pixels * k as u64 <= fit,
                    "{k} samples per pass of {width}x{height} need {} path slots, more than the {fit} one wave \
                     can hold on this device; ask for fewer samples per pass",
                    pixels * k as u64
                );
                k.max(1)
            }
            None => (TARGET_SLOTS_PER_WAVE.min(fit) / pixels).clamp(1, MAX_SAMPLES_PER_PASS as u64) as u32,
        };
        // One wave per pass when it fits; otherwise a pass of one sample runs as several waves.
        let slots_per_wave = (pixels * samples_per_pass as u64).min(fit);
        let slots = slots_per_wave;

        let params = RenderParams {
            camera: scene.scene.camera.to_gpu(width, height),
            gate: gate.to_gpu(),
            width,
            height,
            seed: settings.seed,
            max_bounces: settings.max_bounces,
            rr_depth: settings.rr_depth.unwrap_or(NONE),
            light_count: scene.lights.lights.len() as u32,
            node_count: scene.bvh.nodes.len() as u32,
            ray_epsilon: scene.ray_epsilon,
            one: 1.0,
            ..Default::default()
        };

        let mut r = Resources::default();
        r.uniform_init(ctx, "params", &params);
        r.uniform_init(ctx, "wave", &WaveParams::default());
        let triangles = r.storage_chunked_init(ctx, "triangles", &scene.triangles, limit)?;
        let triangle_shading = r.storage_chunked_init(ctx, "triangle_shading", &scene.shading, limit)?;
        let bvh_nodes = r.storage_chunked_init(ctx, "bvh_nodes", &scene.bvh.nodes, limit)?;
        r.storage_init(ctx, "materials", &scene.materials)?;
        r.storage_init(ctx, "texture_infos", &scene.texture_infos)?;
        r.storage_init(ctx, "texels", &scene.texels)?;
        r.storage_init(ctx, "lights", &scene.lights.lights)?;
        r.storage_init(ctx, "light_cdf", &scene.lights.cdf)?;
        r.storage_init(ctx, "gate_table", &gate.table())?;
        let none = wgpu::BufferUsages::empty();
        r.storage_zeroed(ctx, "paths", size_of::<PathState>() as u64 * slots, none)?;
        r.storage_zeroed(ctx, "hits", size_of::<Hit>() as u64 * slots, none)?;
        r.storage_zeroed(ctx, "ray_queue", 4 * slots, none)?;
        r.storage_zeroed(ctx, "next_ray_queue", 4 * slots, none)?;
        r.storage_zeroed(ctx, "shadow_queue", size_of::<ShadowRay>() as u64 * slots, none)?;
        r.storage_zeroed(ctx, "counters", size_of::<QueueCounters>() as u64, none)?;
        r.storage_zeroed(ctx, "dispatch_args", 6 * 4, wgpu::BufferUsages::INDIRECT)?;
        r.storage_zeroed(ctx, "contributions", 2 * size_of::<Contribution>() as u64 * slots, none)?;
        let film_len = film_elements(settings)?;
        let film = r.storage_chunked_zeroed(ctx, "film", film_len, 8, limit)?;

        let constants = vec![
            ("GATE_KIND", gate.kind() as u32 as f64),
            ("HAS_TEXTURES", scene.has_textures() as u32 as f64),
            ("HAS_POINT_LIGHTS", scene.has_point_lights() as u32 as f64),
            ("LIGHT_STRATEGY", settings.light_strategy as u32 as f64),
            ("TRIANGLES_CHUNK_BITS", triangles.bits as f64),
            ("TRIANGLE_SHADING_CHUNK_BITS", triangle_shading.bits as f64),
            ("BVH_NODES_CHUNK_BITS", bvh_nodes.bits as f64),
            ("FILM_CHUNK_BITS", film.bits as f64),
        ];
        let with = |queue: f64| {
            let mut c = constants.clone();
            c.push(("QUEUE", queue));
            c
        };
        let stages = Stages {
            generate_camera_rays: Kernel::new(ctx, "generate_camera_rays", None, &constants),
            setup_dispatch_rays: Kernel::new(ctx, "setup_dispatch", Some("rays"), &with(0.0)),
            intersect_closest: Kernel::new(ctx, "intersect_closest", None, &constants),
            shade: Kernel::new(ctx, "shade", None, &constants),
            setup_dispatch_shadow_rays: Kernel::new(ctx, "setup_dispatch", Some("shadow_rays"), &with(1.0)),
            trace_shadow_rays: Kernel::new(ctx, "trace_shadow_rays", None, &constants),
            accumulate: Kernel::new(ctx, "accumulate", None, &constants),
        };
        // Even rounds read ray_queue and push to next_ray_queue; odd rounds the other way round.
        let even = r.clone();
        let odd = r.swapped("ray_queue", "next_ray_queue");
        let both = |k: &Kernel| [k.bind(ctx, &even), k.bind(ctx, &odd)];
        let bindings = Bindings {
            // generate fills the queue that round 0 reads.
            generate_camera_rays: stages.generate_camera_rays.bind(ctx, &odd),
            setup_dispatch_rays: both(&stages.setup_dispatch_rays),
            intersect_closest: both(&stages.intersect_closest),
            shade: both(&stages.shade),
            setup_dispatch_shadow_rays: stages.setup_dispatch_shadow_rays.bind(ctx, &even),
            trace_shadow_rays: stages.trace_shadow_rays.bind(ctx, &even),
            accumulate: stages.accumulate.bind(ctx, &even),
        };
        Ok(Self {
            ctx,
            params,
            stages,
            bindings,
            resources: r,
            film_layout: film,
            constants,
            slots_per_wave,
            samples_per_pass,
            samples_in_film: 0,
            next_sample: 0,
        })
    }

    /// The named buffers the kernels bind (scene, wavefront state, film).
    pub fn resources(&self) -> &Resources {
        &self.resources
    }

    /// The specialisation constants every kernel of this render gets.
    pub fn constants(&self) -> &[(&'static str, f64)] {
        &self.constants
    }

    /// Samples per pixel of a full pass.
    pub fn samples_per_pass(&self) -> u32 {
        self.samples_per_pass
    }

    /// Waves a full pass takes (more than one when the image does not fit one wave).
    pub fn waves_per_pass(&self) -> u64 {
        let pixels = self.params.width as u64 * self.params.height as u64;
        let pixels_per_wave = (self.slots_per_wave / self.samples_per_pass as u64).min(pixels);
        pixels.div_ceil(pixels_per_wave)
    }

    /// Samples per pixel accumulated in the film since the last reset.
    pub fn samples_done(&self) -> u64 {
        self.samples_in_film
    }

    /// Traces `samples` (at most `samples_per_pass`) more samples of every pixel and adds them
    /// to the film; returns when the GPU has finished.
    pub fn render_pass(&mut self, samples: u32) -> Result<()> {
        assert!(samples >= 1 && samples <= self.samples_per_pass);
        let sample_base = u32::try_from(self.next_sample + samples as u64 - 1)
            .map(|_| self.next_sample as u32)
            .map_err(|_| anyhow::anyhow!("more than 2^32 samples per pixel"))?;
        let pixels = self.params.width * self.params.height;
        // A wave holds `samples` samples of a block of pixels (all pixels when they fit).
        let pixels_per_wave = (self.slots_per_wave / samples as u64).min(pixels as u64) as u32;
        let mut pixel_base = 0;
        while pixel_base < pixels {
            let pixel_count = pixels_per_wave.min(pixels - pixel_base);
            self.render_wave(WaveParams {
                sample_base,
                samples,
                pixel_base,
                pixel_count,
                slot_count: pixel_count * samples,
                ..Default::default()
            })?;
            pixel_base += pixel_count;
        }
        self.samples_in_film += samples as u64;
        self.next_sample += samples as u64;
        Ok(())
    }

    /// Traces `spp` more samples of every pixel, in as few passes as possible.
    pub fn render_samples(&mut self, spp: u64) -> Result<()> {
        let mut left = spp;
        while left > 0 {
            let n = left.min(self.samples_per_pass as u64) as u32;
            self.render_pass(n)?;
            left -= n as u64;
        }
        Ok(())
    }

    fn render_wave(&self, wave: WaveParams) -> Result<()> {
        let ctx = self.ctx;
        ctx.queue.write_buffer(self.resources.get("wave").unwrap(), 0, bytemuck::bytes_of(&wave));
        let args = self.resources.get("dispatch_args").unwrap();
        let (s, b) = (&self.stages, &self.bindings);
        let rounds = self.params.max_bounces + 1;
        let mut round = 0;
        while round < rounds {
            let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("wave") });
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("wave"), timestamp_writes: None });
                if round == 0 {
                    s.generate_camera_rays.dispatch(&mut pass, &b.generate_camera_rays, wave.slot_count);
                }
                let end = rounds.min(round + ROUNDS_PER_SUBMISSION);
                for r in round..end {
                    let parity = (r % 2) as usize;
                    s.setup_dispatch_rays.dispatch(&mut pass, &b.setup_dispatch_rays[parity], 1);
                    s.intersect_closest.dispatch_indirect(&mut pass, &b.intersect_closest[parity], args, 0);
                    s.shade.dispatch_indirect(&mut pass, &b.shade[parity], args, 0);
                    s.setup_dispatch_shadow_rays.dispatch(&mut pass, &b.setup_dispatch_shadow_rays, 1);
                    s.trace_shadow_rays.dispatch_indirect(&mut pass, &b.trace_shadow_rays, args, 12);
                    s.accumulate.dispatch(&mut pass, &b.accumulate, wave.pixel_count);
                }
                round = end;
            }
            ctx.queue.submit([encoder.finish()]);
            if round < rounds {
                let counters: Vec<QueueCounters> = read_buffer(ctx, self.resources.get("counters").unwrap(), 1)?;
                if counters[0].next_rays == 0 {
                    break;
                }
            }
        }
        ctx.wait_idle()
    }

    /// The film's current estimate (compensated sums divided by the samples per pixel).
    pub fn film(&self) -> Result<Film> {
        let bins = self.params.gate.bins;
        let mut film = Film::zeroed(self.params.width, self.params.height, bins);
        let sums: Vec<[f32; 2]> = self.resources.read_chunked(self.ctx, "film", self.film_layout, film.data.len() as u64)?;
        let n = self.samples_in_film.max(1) as f64;
        film.data = sums.iter().map(|s| ((s[0] as f64 + s[1] as f64) / n) as f32).collect();
        film.spp = self.samples_in_film;
        Ok(film)
    }

    /// Ray traversals the device cut short so far (lavapipe ends a shader invocation's loops
    /// after 65535 iterations in total); nonzero means the image may miss geometry.
    pub fn truncated_traversals(&self) -> Result<u64> {
        let counters: Vec<QueueCounters> = read_buffer(self.ctx, self.resources.get("counters").unwrap(), 1)?;
        Ok(counters[0].truncated_traversals as u64)
    }

    /// Clears the film; later samples continue the random sequence, so the next estimate is
    /// independent of the previous one (for batch statistics).
    pub fn reset_film(&mut self) {
        let mut encoder = self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("reset_film") });
        self.resources.clear_chunked(&mut encoder, "film");
        self.ctx.queue.submit([encoder.finish()]);
        self.samples_in_film = 0;
    }
}

/// Elements (pixel, bin, channel) of the film of `settings`, checked against what the device can
/// hold at all: up to four bindings of 8-byte compensated sums.
pub fn film_elements(settings: &RenderSettings) -> Result<u64> {
    let elements = settings.width as u64 * settings.height as u64 * settings.gate.bins() as u64 * 3;
    let most = MAX_CHUNKS * (1u64 << 31) / 8;
    ensure!(
        elements <= most,
        "the film of {}x{} pixels x {} bins needs {:.1} GiB; reduce the resolution or the bins",
        settings.width,
        settings.height,
        settings.gate.bins(),
        elements as f64 * 8.0 / (1u64 << 30) as f64
    );
    Ok(elements)
}
