//! The wavefront path tracer. One wave traces `samples` samples of every pixel at once
//! (one path slot per pixel and sample); its stages, in order, are the table of contents:
//!
//! ```text
//! generate_camera_rays                  every slot -> next_ray_queue
//! for round in 0..=max_bounces:
//!     setup_dispatch(rays)              next_ray_queue becomes ray_queue
//!     intersect_closest                 closest hits of ray_queue
//!     shade                             emission, light sample + shadow_queue, next ray
//!     setup_dispatch(shadow_rays)
//!     trace_shadow_rays                 occluded light samples are cleared
//!     accumulate                        contributions -> film (W, bin), per pixel
//! ```

use anyhow::Result;

use super::RenderSettings;
use crate::film::Film;
use crate::gpu::layout::{Contribution, Hit, NONE, PathState, QueueCounters, RenderParams, ShadowRay, WaveParams};
use crate::gpu::resources::ChunkLayout;
use crate::gpu::{GpuContext, Kernel, Resources};
use crate::scene::PreparedScene;

/// Path slots a wave aims for when the caller does not fix the samples per wave.
const TARGET_SLOTS_PER_WAVE: u32 = 1 << 18;

/// Pipelines of the path tracer, one per stage.
struct Stages {
    generate_camera_rays: Kernel,
    setup_rays: Kernel,
    intersect_closest: Kernel,
    shade: Kernel,
    setup_shadow_rays: Kernel,
    trace_shadow_rays: Kernel,
    accumulate: Kernel,
}

/// Bind groups of the stages; `[even, odd]` rounds swap ray_queue and next_ray_queue.
struct Bindings {
    generate_camera_rays: wgpu::BindGroup,
    setup_rays: [wgpu::BindGroup; 2],
    intersect_closest: [wgpu::BindGroup; 2],
    shade: [wgpu::BindGroup; 2],
    setup_shadow_rays: wgpu::BindGroup,
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
    samples_per_wave: u32,
    /// Samples per pixel accumulated in the film.
    samples_in_film: u64,
    /// Index of the next sample to trace (never reused, so batches are independent).
    next_sample: u64,
}

impl<'a> PathTracer<'a> {
    pub fn new(ctx: &'a GpuContext, scene: &PreparedScene, settings: &RenderSettings) -> Result<Self> {
        let (width, height) = (settings.width, settings.height);
        anyhow::ensure!(width > 0 && height > 0, "the resolution must be at least 1x1");
        let pixels = width * height;
        let samples_per_wave = settings.samples_per_wave.unwrap_or((TARGET_SLOTS_PER_WAVE / pixels).max(1)).max(1);
        let slots = pixels as u64 * samples_per_wave as u64;
        anyhow::ensure!(slots <= 64 * 65535, "{slots} path slots per wave exceed one dispatch; use fewer samples per wave");
        let slots = slots as usize;
        let gate = &settings.gate;

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
            triangle_count: scene.triangles.len() as u32,
            ray_epsilon: scene.ray_epsilon,
            ..Default::default()
        };

        let mut r = Resources::default();
        r.uniform_init(ctx, "params", &params);
        r.uniform_init(ctx, "wave", &WaveParams::default());
        let limit = settings.binding_limit.unwrap_or(u64::MAX).min(ctx.max_binding_size());
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
        r.storage_zeroed(ctx, "paths", size_of::<PathState>() as u64 * slots as u64, none)?;
        r.storage_zeroed(ctx, "hits", size_of::<Hit>() as u64 * slots as u64, none)?;
        r.storage_zeroed(ctx, "ray_queue", 4 * slots as u64, none)?;
        r.storage_zeroed(ctx, "next_ray_queue", 4 * slots as u64, none)?;
        r.storage_zeroed(ctx, "shadow_queue", size_of::<ShadowRay>() as u64 * slots as u64, none)?;
        r.storage_zeroed(ctx, "counters", size_of::<QueueCounters>() as u64, none)?;
        r.storage_zeroed(ctx, "dispatch_args", 6 * 4, wgpu::BufferUsages::INDIRECT)?;
        r.storage_zeroed(ctx, "contributions", 2 * size_of::<Contribution>() as u64 * slots as u64, none)?;
        let film_len = 3 * pixels as u64 * gate.bins() as u64;
        let film = r.storage_chunked_zeroed(ctx, "film", film_len, 4, limit)?;

        let constants = [
            ("GATE_KIND", gate.kind() as u32 as f64),
            ("HAS_TEXTURES", scene.has_textures() as u32 as f64),
            ("HAS_POINT_LIGHTS", scene.has_point_lights() as u32 as f64),
            ("TRIANGLES_CHUNK_BITS", triangles.bits as f64),
            ("TRIANGLE_SHADING_CHUNK_BITS", triangle_shading.bits as f64),
            ("BVH_NODES_CHUNK_BITS", bvh_nodes.bits as f64),
            ("FILM_CHUNK_BITS", film.bits as f64),
        ];
        let constants = constants.to_vec();
        let with = |extra: (&'static str, f64)| {
            let mut c = constants.clone();
            c.push(extra);
            c
        };
        let stages = Stages {
            generate_camera_rays: Kernel::new(ctx, "generate_camera_rays", &constants),
            setup_rays: Kernel::new(ctx, "setup_dispatch", &with(("QUEUE", 0.0))),
            intersect_closest: Kernel::new(ctx, "intersect_closest", &constants),
            shade: Kernel::new(ctx, "shade", &constants),
            setup_shadow_rays: Kernel::new(ctx, "setup_dispatch", &with(("QUEUE", 1.0))),
            trace_shadow_rays: Kernel::new(ctx, "trace_shadow_rays", &constants),
            accumulate: Kernel::new(ctx, "accumulate", &constants),
        };
        // Even rounds read ray_queue and push to next_ray_queue; odd rounds the other way round.
        let even = r.clone();
        let odd = r.swapped("ray_queue", "next_ray_queue");
        let both = |k: &Kernel| [k.bind(ctx, &even), k.bind(ctx, &odd)];
        let bindings = Bindings {
            // generate fills the queue that round 0 reads.
            generate_camera_rays: stages.generate_camera_rays.bind(ctx, &odd),
            setup_rays: both(&stages.setup_rays),
            intersect_closest: both(&stages.intersect_closest),
            shade: both(&stages.shade),
            setup_shadow_rays: stages.setup_shadow_rays.bind(ctx, &even),
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
            samples_per_wave,
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

    /// Samples per pixel of a full wave.
    pub fn samples_per_wave(&self) -> u32 {
        self.samples_per_wave
    }

    /// Samples per pixel accumulated in the film since the last reset.
    pub fn samples_done(&self) -> u64 {
        self.samples_in_film
    }

    /// Traces `samples` (at most `samples_per_wave`) more samples of every pixel and adds them to
    /// the film. Returns once the work is submitted.
    pub fn render_wave(&mut self, samples: u32) {
        assert!(samples >= 1 && samples <= self.samples_per_wave);
        let pixels = self.params.width * self.params.height;
        let wave = WaveParams {
            sample_base: u32::try_from(self.next_sample).expect("more than 2^32 samples per pixel"),
            samples,
            slot_count: pixels * samples,
            reserved: 0,
        };
        let ctx = self.ctx;
        ctx.queue.write_buffer(self.resources.get("wave").unwrap(), 0, bytemuck::bytes_of(&wave));
        let args = self.resources.get("dispatch_args").unwrap();
        let (s, b) = (&self.stages, &self.bindings);
        let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("wave") });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("wave"), timestamp_writes: None });
            s.generate_camera_rays.dispatch(&mut pass, &b.generate_camera_rays, wave.slot_count);
            for round in 0..=self.params.max_bounces as usize {
                let parity = round % 2;
                s.setup_rays.dispatch(&mut pass, &b.setup_rays[parity], 1);
                s.intersect_closest.dispatch_indirect(&mut pass, &b.intersect_closest[parity], args, 0);
                s.shade.dispatch_indirect(&mut pass, &b.shade[parity], args, 0);
                s.setup_shadow_rays.dispatch(&mut pass, &b.setup_shadow_rays, 1);
                s.trace_shadow_rays.dispatch_indirect(&mut pass, &b.trace_shadow_rays, args, 12);
                s.accumulate.dispatch(&mut pass, &b.accumulate, pixels);
            }
        }
        ctx.queue.submit([encoder.finish()]);
        self.samples_in_film += samples as u64;
        self.next_sample += samples as u64;
    }

    /// Traces `spp` more samples of every pixel, in as few waves as possible.
    pub fn render_samples(&mut self, spp: u64) {
        let mut left = spp;
        while left > 0 {
            let n = left.min(self.samples_per_wave as u64) as u32;
            self.render_wave(n);
            left -= n as u64;
        }
    }

    /// The film's current estimate (sums divided by the samples per pixel).
    pub fn film(&self) -> Result<Film> {
        let bins = self.params.gate.bins;
        let mut film = Film::zeroed(self.params.width, self.params.height, bins);
        let sums: Vec<f32> = self.resources.read_chunked(self.ctx, "film", self.film_layout, film.data.len() as u64)?;
        let n = self.samples_in_film.max(1) as f64;
        film.data = sums.iter().map(|&v| (v as f64 / n) as f32).collect();
        film.spp = self.samples_in_film;
        Ok(film)
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
