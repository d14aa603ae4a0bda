//! What every wavefront method keeps between passes: the device, the render's parameters, the
//! named buffers, the specialisation constants and the bookkeeping of passes, waves and samples;
//! and the plan every method's passes follow: samples per pass, waves of slots, rounds per
//! submission and the film's size.

use anyhow::{Result, ensure};

use super::RenderSettings;
use super::checkpoint::RenderState;
use crate::film::target::{StratumFactors, TargetSampler, next_target_seed};
use crate::film::{Film, Gate, GateKind, fixed};
use crate::gpu::layout::{QueueCounters, RenderParams, TargetParams, WaveParams};
use crate::gpu::resources::{ChunkLayout, MAX_CHUNKS, read_buffer, storage_init_bytes};
use crate::gpu::{GpuContext, Kernel, Resources};

/// Bytes of the indirect dispatch arguments: ray_queue, shadow_queue, ellipsoid_queries and
/// the resume pass of shadow rays, three words each (see setup_dispatch.wesl).
pub const DISPATCH_ARGS_BYTES: u64 = 12 * 4;

/// Most slots one dispatch can cover (64 invocations x 65535 workgroups).
pub(super) const MAX_SLOTS_PER_DISPATCH: u64 = 64 * 65535;
/// Most samples per pass: `accumulate` loops over a pixel's samples, and lavapipe (gallivm)
/// silently ends any loop after 65535 iterations.
const MAX_SAMPLES_PER_PASS: u32 = 4096;
/// Rounds encoded per submission; between submissions the host checks whether any path is
/// still alive, so huge --max-bounces values cost nothing once the paths have ended.
const ROUNDS_PER_SUBMISSION: u32 = 16;

/// The shadow-ray stages every method shares: `setup_dispatch(shadow_rays)` and
/// `trace_shadow_rays`, then resume passes `setup_dispatch(shadow_resume)` and
/// `trace_shadow_rays(resume)` for the rays a pass left unfinished at the traversal budget
/// (nothing runs in a resume pass when every ray was decided), and `setup_dispatch(shadow_cut)`,
/// which counts what is still unfinished after the last resume pass as cut short.
pub struct ShadowRayStages {
    kernels: [Kernel; 5],
    groups: [wgpu::BindGroup; 5],
}

impl ShadowRayStages {
    /// Builds the kernels with `constants` and binds them to `resources`.
    pub fn new(ctx: &GpuContext, constants: &[(&'static str, f64)], resources: &Resources) -> Self {
        let with = |name: &'static str, value: f64| {
            let mut c = constants.to_vec();
            c.push((name, value));
            c
        };
        let kernels = [
            Kernel::new(ctx, "setup_dispatch", Some("shadow_rays"), &with("QUEUE", 1.0)),
            Kernel::new(ctx, "trace_shadow_rays", None, constants),
            Kernel::new(ctx, "setup_dispatch", Some("shadow_resume"), &with("QUEUE", 3.0)),
            Kernel::new(ctx, "trace_shadow_rays", Some("resume"), &with("RESUME", 1.0)),
            Kernel::new(ctx, "setup_dispatch", Some("shadow_cut"), &with("QUEUE", 4.0)),
        ];
        let groups = kernels.each_ref().map(|k| k.bind(ctx, resources));
        Self { kernels, groups }
    }

    /// Encodes the first pass over every queued shadow ray.
    pub fn encode(&self, pass: &mut wgpu::ComputePass, args: &wgpu::Buffer) {
        self.kernels[0].dispatch(pass, &self.groups[0], 1);
        self.kernels[1].dispatch_indirect(pass, &self.groups[1], args, 12);
    }

    /// Encodes a resume pass (empty when the pass before decided every ray).
    pub fn encode_resume(&self, pass: &mut wgpu::ComputePass, args: &wgpu::Buffer) {
        self.kernels[2].dispatch(pass, &self.groups[2], 1);
        self.kernels[3].dispatch_indirect(pass, &self.groups[3], args, 36);
    }

    /// Encodes the count of rays still unfinished as traversals cut short.
    pub fn encode_cut(&self, pass: &mut wgpu::ComputePass) {
        self.kernels[4].dispatch(pass, &self.groups[4], 1);
    }
}

/// The state a wavefront method shares with the others.
pub struct Wavefront<'a> {
    /// The device.
    pub ctx: &'a GpuContext,
    /// Render-wide parameters (the `params` uniform).
    pub params: RenderParams,
    /// The named buffers the kernels bind (scene, wavefront state, film).
    pub resources: Resources,
    /// How the film is split over bindings.
    pub film_layout: ChunkLayout,
    /// Specialisation constants every kernel of the render gets.
    pub constants: Vec<(&'static str, f64)>,
    /// Most slots of one wave.
    pub slots_per_wave: u64,
    /// Samples per pixel of a full pass.
    pub samples_per_pass: u32,
    /// Most times one ray traversal can stop before it is complete (`WideBvh::most_stops`).
    pub most_traversal_stops: u32,
    /// The gate kind the kernels are specialised for (their GATE_KIND).
    pub gate_kind: GateKind,
    /// Samples per pixel accumulated in the film since the last reset.
    pub samples_in_film: u64,
    /// Index of the next sample to trace (never reused, so batches are independent).
    pub next_sample: u64,
    /// The host copy of `target_visits` (per pixel, `strata + 1` cumulative extra visits of
    /// the stratified bins); empty while `params.target_length.extra` is 0.
    pub target_visits: Vec<u32>,
    /// Most pixels a pass traces, from the first; None for all of them. A warm-up pass
    /// (`Integrator::warm_up`) traces `WARM_UP_PIXELS`.
    pub pass_pixels: Option<u32>,
}

impl<'a> Wavefront<'a> {
    /// Bookkeeping for a render whose buffers are `resources`, whose kernels were specialised
    /// for gates of kind `gate_kind`.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        ctx: &'a GpuContext,
        params: RenderParams,
        resources: Resources,
        film_layout: ChunkLayout,
        constants: Vec<(&'static str, f64)>,
        (samples_per_pass, slots_per_wave): (u32, u64),
        most_traversal_stops: u32,
        gate_kind: GateKind,
    ) -> Self {
        Self {
            ctx,
            params,
            resources,
            film_layout,
            constants,
            slots_per_wave,
            samples_per_pass,
            most_traversal_stops,
            gate_kind,
            samples_in_film: 0,
            next_sample: 0,
            target_visits: Vec::new(),
            pass_pixels: None,
        }
    }

    /// Moves the render to `gate`, whose target lengths `sampler` draws (see
    /// `integrator::target_sampler`), without rebuilding anything when the kernels'
    /// specialisation and the buffers' sizes allow it (same gate kind, bins and table length,
    /// target lengths stratified or not, STRATIFIED_TARGETS):
    /// rewrites the gate's device data ([`upload_gate`]). Returns false, changing nothing, when
    /// the integrator must be rebuilt. The film is not cleared (see `Integrator::set_gate`).
    pub fn set_gate(&mut self, gate: &Gate, sampler: Option<TargetSampler>) -> Result<bool> {
        let new = gate.to_gpu();
        if gate.kind() != self.gate_kind
            || new.bins != self.params.gate.bins
            || new.table_len != self.params.gate.table_len
        {
            return Ok(false);
        }
        let cdf = target_cdf(sampler.as_ref());
        let stratified = sampler.as_ref().is_some_and(|t| t.params.strata > 0);
        if storage_init_bytes(&cdf) != self.resources.get("target_cdf").unwrap().size()
            || stratified != (self.params.target_length.strata > 0)
        {
            return Ok(false);
        }
        self.params.gate = new;
        let (seed, film_first_sample) = (self.params.target_length.seed, self.params.target_length.film_first_sample);
        // Extra visits were shaped for the old gate: each bin gets one a cycle again.
        self.params.target_length =
            TargetParams { seed, film_first_sample, ..sampler.map(|t| t.params).unwrap_or_default() };
        self.target_visits.clear();
        upload_gate(self.ctx, &mut self.resources, &self.params, &gate.table(), &cdf)?;
        Ok(true)
    }

    /// The waves of the next pass of `samples` (1 ..= samples_per_pass) samples per pixel, over
    /// the first `pass_pixels` pixels where that is set.
    pub fn pass_waves(&self, samples: u32) -> Result<Vec<WaveParams>> {
        assert!(samples >= 1 && samples <= self.samples_per_pass);
        let waves = waves_of_pass(&self.params, self.slots_per_wave, self.next_sample, samples)?;
        Ok(match self.pass_pixels {
            Some(limit) => first_pixels(waves, limit),
            None => waves,
        })
    }

    /// Records that a pass of `samples` samples per pixel has been added to the film.
    pub fn pass_done(&mut self, samples: u32) {
        self.samples_in_film += samples as u64;
        self.next_sample += samples as u64;
    }

    /// Waves a full pass takes (more than one when the image does not fit one wave).
    pub fn waves_per_pass(&self) -> u64 {
        let pixels = self.params.width as u64 * self.params.height as u64;
        let pixels_per_wave = (self.slots_per_wave / self.samples_per_pass as u64).min(pixels);
        pixels.div_ceil(pixels_per_wave)
    }

    /// Uploads the wave's parameters (before its kernels are encoded).
    pub fn write_wave(&self, wave: &WaveParams) {
        self.ctx.queue.write_buffer(self.resources.get("wave").unwrap(), 0, bytemuck::bytes_of(wave));
    }

    /// Encodes `start` and then `round(pass, r)` for rounds r = 0, 1, ... in submissions of
    /// ROUNDS_PER_SUBMISSION rounds (the first holds the rounds that max_bounces + 1 vertices
    /// take at `vertices_per_round` vertices each, at most), until no path is
    /// queued: paths end after max_bounces scattering vertices, and a path whose closest-hit
    /// traversal stopped at the traversal budget takes one round more per stop (so huge
    /// --max-bounces values cost nothing after the paths have ended, and no traversal is cut
    /// short). Waits for each submission but the last.
    pub fn trace_rounds(
        &self,
        vertices_per_round: u32,
        start: impl Fn(&mut wgpu::ComputePass),
        round: impl Fn(&mut wgpu::ComputePass, u32),
    ) -> Result<()> {
        let ctx = self.ctx;
        let rounds = (self.params.max_bounces as u64 + 1).div_ceil(vertices_per_round.max(1) as u64);
        // A path waits one round per stop of its closest-hit traversal: a bound that only a bug
        // can reach.
        let most = rounds * (self.most_traversal_stops as u64 + 2);
        let mut first = 0u64;
        loop {
            let mut encoder =
                ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("wave") });
            {
                let mut pass = encoder
                    .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("wave"), timestamp_writes: None });
                if first == 0 {
                    start(&mut pass);
                }
                let end = if first == 0 {
                    rounds.min(ROUNDS_PER_SUBMISSION as u64)
                } else {
                    first + ROUNDS_PER_SUBMISSION as u64
                };
                for r in first..end {
                    round(&mut pass, (r % 2) as u32);
                }
                first = end;
            }
            ctx.queue.submit([encoder.finish()]);
            if self.counters()?.next_rays == 0 {
                break;
            }
            ensure!(first < most, "paths still queued after {first} rounds: a traversal does not end");
        }
        Ok(())
    }

    /// Records `encode` into one compute pass labelled `label` and submits it.
    pub fn submit_pass(&self, label: &str, encode: impl FnOnce(&mut wgpu::ComputePass)) {
        let mut encoder =
            self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
        {
            let mut pass =
                encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(label), timestamp_writes: None });
            encode(&mut pass);
        }
        self.ctx.queue.submit([encoder.finish()]);
    }

    /// The queue counters as the last submission left them.
    pub fn counters(&self) -> Result<QueueCounters> {
        Ok(read_buffer::<QueueCounters>(self.ctx, self.resources.get("counters").unwrap(), 1)?[0])
    }

    /// The state every method keeps between passes (see `checkpoint`): the sample counters,
    /// the params uniform (seeds, target-length sampling), the target lengths' extra visits and
    /// the film's sums (`film`, four words per element). `method` names the integrator.
    pub fn save_state(&self, method: super::Method) -> Result<RenderState> {
        let elements = self.film_element_count();
        let film: Vec<[u32; 4]> = self.resources.read_chunked(self.ctx, "film", self.film_layout, elements)?;
        let mut state = RenderState {
            method,
            samples_in_film: self.samples_in_film,
            next_sample: self.next_sample,
            rendering_seconds: 0.0,
            blobs: Vec::new(),
        };
        state.push("params", std::slice::from_ref(&self.params));
        state.push("target_visits", &self.target_visits);
        state.push("film", &film);
        Ok(state)
    }

    /// Puts a state [`Self::save_state`] took into this render (built with the same settings),
    /// so that its next pass continues where that render stopped.
    pub fn load_state(&mut self, method: super::Method, state: &RenderState) -> Result<()> {
        ensure!(
            state.method == method,
            "the checkpoint was rendered with --method {}, this render uses {}",
            state.method.name(),
            method.name()
        );
        let params: RenderParams = state.values("params", 1)?[0];
        let (a, b) = (&params, &self.params);
        ensure!(
            (a.width, a.height, a.gate.bins, a.max_bounces) == (b.width, b.height, b.gate.bins, b.max_bounces),
            "the checkpoint's image ({}x{}, {} bins, {} bounces) is not this render's ({}x{}, {} bins, {} bounces)",
            a.width,
            a.height,
            a.gate.bins,
            a.max_bounces,
            b.width,
            b.height,
            b.gate.bins,
            b.max_bounces
        );
        let film: Vec<[u32; 4]> = state.values("film", self.film_element_count() as usize)?;
        let visits: Vec<u32> = state.all_values("target_visits")?;
        if !visits.is_empty() {
            let buffer = self
                .resources
                .get("target_visits")
                .ok_or_else(|| anyhow::anyhow!("this render keeps no target visits"))?;
            ensure!(
                (visits.len() * 4) as u64 <= buffer.size(),
                "the checkpoint's target visits do not fit this render's"
            );
            self.ctx.queue.write_buffer(buffer, 0, bytemuck::cast_slice(&visits));
        }
        self.resources.write_chunked(self.ctx, "film", self.film_layout, &film);
        self.params = params;
        self.ctx.queue.write_buffer(self.resources.get("params").unwrap(), 0, bytemuck::bytes_of(&self.params));
        self.target_visits = visits;
        self.samples_in_film = state.samples_in_film;
        self.next_sample = state.next_sample;
        Ok(())
    }

    /// Elements (pixel, bin, channel) of the film.
    pub fn film_element_count(&self) -> u64 {
        self.params.width as u64 * self.params.height as u64 * self.params.gate.bins as u64 * 3
    }

    /// Starts afresh from `seed` as a newly built render with that seed would: clears the film
    /// (and the buffers `also` names), restarts the sample sequence at 0 and gives the target
    /// lengths the seed render_params gives them, without extra visits (a pilot shapes them
    /// again). The kernels and buffers stay.
    pub fn restart(&mut self, seed: u32, also: &[&str]) {
        self.next_sample = 0;
        self.reset_film(also);
        self.params.seed = seed;
        self.params.target_length.seed = seed;
        self.params.target_length.film_first_sample = 0;
        self.params.target_length.extra = 0;
        self.target_visits.clear();
        self.ctx.queue.write_buffer(self.resources.get("params").unwrap(), 0, bytemuck::bytes_of(&self.params));
    }

    /// Clears the film and the further buffers `also` (e.g. a splat film), and draws the next
    /// film's target-length seed.
    pub fn reset_film(&mut self, also: &[&str]) {
        let mut encoder =
            self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("reset_film") });
        self.resources.clear_chunked(&mut encoder, "film");
        for name in also {
            encoder.clear_buffer(self.resources.get(name).unwrap(), 0, None);
        }
        self.params.target_length.seed = next_target_seed(self.params.target_length.seed);
        // The film's cycles of target-length visits start at its first sample.
        self.params.target_length.film_first_sample = self.next_sample as u32;
        self.ctx.queue.write_buffer(self.resources.get("params").unwrap(), 0, bytemuck::bytes_of(&self.params));
        self.ctx.queue.submit([encoder.finish()]);
        self.samples_in_film = 0;
    }
}

/// Bytes of wave state (the per-slot buffers) a wave on a GPU aims for: a wave of few slots
/// leaves most of a GPU's cores idle (on an NVIDIA H200 with 1,310,732 triangles, waves of 2^16
/// slots traced `direct` at 18 M samples/s at 64x64, waves of the whole image 75 M at
/// 1024x1024), and 1 GiB leaves room on any GPU that holds a large scene.
const GPU_WAVE_BYTES: u64 = 1 << 30;
/// Most slots a wave aims for on a GPU (an H200 keeps about 2^18 invocations in flight).
const GPU_MAX_TARGET_SLOTS: u64 = 1 << 20;

/// Slots a wave aims for at `bytes_per_slot` of per-slot state: `cpu_target` on a CPU device
/// (`on_cpu`: lavapipe runs one invocation per lane of its 2 to 16 cores, and a small wave keeps
/// its state in cache), and on a GPU as many as GPU_WAVE_BYTES holds, between `cpu_target` and
/// GPU_MAX_TARGET_SLOTS.
pub(super) fn target_slots_per_wave(on_cpu: bool, cpu_target: u64, bytes_per_slot: u64) -> u64 {
    if on_cpu {
        return cpu_target;
    }
    (GPU_WAVE_BYTES / bytes_per_slot.max(1)).clamp(cpu_target, GPU_MAX_TARGET_SLOTS.max(cpu_target))
}

/// Samples of every pixel a wave bounded by `RenderSettings::wave_bytes` still holds (where the
/// device's bindings fit them): a pilot's batches, one pass each, alternate sizes so that the
/// time of a sample can be told from a pass's fixed cost (`pilot::pilot_batch`).
pub(super) const BOUNDED_WAVE_SAMPLES: u64 = 4;

/// Slots a wave of `settings` aims for at `bytes_per_slot` of per-slot state:
/// [`target_slots_per_wave`], within `settings.wave_bytes` where a pilot sets it (yet at least
/// [`BOUNDED_WAVE_SAMPLES`] samples of every pixel).
pub(super) fn wave_target(on_cpu: bool, cpu_target: u64, bytes_per_slot: u64, settings: &RenderSettings) -> u64 {
    let target = target_slots_per_wave(on_cpu, cpu_target, bytes_per_slot);
    match settings.wave_bytes {
        Some(bytes) => {
            let pixels = settings.width as u64 * settings.height as u64;
            target.min((bytes / bytes_per_slot.max(1)).max(pixels * BOUNDED_WAVE_SAMPLES)).max(1)
        }
        None => target,
    }
}

/// Samples per pass and slots per wave of a render: as many slots as `target` (or the requested
/// samples per pass) asks for, within one dispatch and within `fit` slots (what the device's
/// bindings hold).
pub(super) fn plan_waves(settings: &RenderSettings, fit: u64, target: u64) -> Result<(u32, u64)> {
    let (width, height) = (settings.width, settings.height);
    ensure!(width > 0 && height > 0, "the resolution must be at least 1x1");
    let pixels = width as u64 * height as u64;
    ensure!(pixels <= u32::MAX as u64, "{width}x{height} has more than 2^32 pixels");
    let fit = fit.clamp(1, MAX_SLOTS_PER_DISPATCH);
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
        None => (target.min(fit) / pixels).clamp(1, MAX_SAMPLES_PER_PASS as u64) as u32,
    };
    // One wave per pass when it fits; otherwise a pass of one sample runs as several waves.
    Ok((samples_per_pass, (pixels * samples_per_pass as u64).min(fit)))
}

/// The waves of a pass of `samples` samples per pixel starting at sample `next_sample`: each
/// holds `samples` samples of a block of pixels (all pixels when they fit `slots_per_wave`).
pub(super) fn waves_of_pass(
    params: &RenderParams,
    slots_per_wave: u64,
    next_sample: u64,
    samples: u32,
) -> Result<Vec<WaveParams>> {
    let sample_base = u32::try_from(next_sample + samples as u64 - 1)
        .map(|_| next_sample as u32)
        .map_err(|_| anyhow::anyhow!("more than 2^32 samples per pixel"))?;
    let pixels = params.width * params.height;
    let pixels_per_wave = (slots_per_wave / samples as u64).min(pixels as u64) as u32;
    let mut waves = Vec::new();
    let mut pixel_base = 0;
    while pixel_base < pixels {
        let pixel_count = pixels_per_wave.min(pixels - pixel_base);
        waves.push(WaveParams {
            sample_base,
            samples,
            pixel_base,
            pixel_count,
            slot_count: pixel_count * samples,
            ..Default::default()
        });
        pixel_base += pixel_count;
    }
    Ok(waves)
}

/// Pixels a warm-up pass traces (`Integrator::warm_up`): one workgroup of the kernels' 64
/// invocations, enough for every kernel a pass dispatches to run, so that a device compiling
/// kernels at their first dispatch (lavapipe) has compiled them all. What a warm-up costs then
/// is that compilation and the clearing of buffers at their first use, not its samples: a pass
/// of the whole image took seconds at 256x256 on 327,680 triangles.
pub const WARM_UP_PIXELS: u32 = 64;

/// `waves` cut to their first `limit` pixels: waves past them dropped, the one across the limit
/// shortened (at least one pixel is kept).
fn first_pixels(waves: Vec<WaveParams>, limit: u32) -> Vec<WaveParams> {
    let limit = limit.max(1);
    waves
        .into_iter()
        .filter(|w| w.pixel_base < limit)
        .map(|w| {
            let pixel_count = w.pixel_count.min(limit - w.pixel_base);
            WaveParams { pixel_count, slot_count: pixel_count * w.samples, ..w }
        })
        .collect()
}

/// Bytes of one film element (pixel, bin, channel): a 128-bit fixed-point sum
/// (`crate::film::fixed`).
pub const FILM_ELEMENT_BYTES: u64 = 16;

/// Elements (pixel, bin, channel) of the film of `settings`, checked against what the device can
/// hold at all: up to four bindings of 2 GiB.
pub fn film_elements(settings: &RenderSettings) -> Result<u64> {
    let elements = settings.width as u64 * settings.height as u64 * settings.gate.bins() as u64 * 3;
    let most = MAX_CHUNKS * (1u64 << 31) / FILM_ELEMENT_BYTES;
    ensure!(
        elements <= most,
        "--res {}x{} with {} bins: the film needs {:.1} GiB of device memory, more than the {} GiB it can be \
         split over; reduce the resolution or the bins",
        settings.width,
        settings.height,
        settings.gate.bins(),
        (elements * FILM_ELEMENT_BYTES) as f64 / (1u64 << 30) as f64,
        (most * FILM_ELEMENT_BYTES) >> 30
    );
    Ok(elements)
}

/// The target-length CDF the kernels read: `sampler`'s, or a stand-in of two values where the
/// gate draws no target lengths.
pub fn target_cdf(sampler: Option<&TargetSampler>) -> Vec<f32> {
    sampler.map_or(vec![0.0, 1.0], |t| t.cdf.clone())
}

/// Uploads the gate's device data: the params uniform (which holds the gate and its
/// target-length sampling), the gate table and the target-length CDF. The first upload (no
/// `params` in `r` yet) creates the buffers; later ones (a moved gate, see
/// [`Wavefront::set_gate`]) rewrite them in place, which needs a table and a CDF of the sizes
/// the buffers were created with (a gate without a table leaves its stand-in as it is).
pub fn upload_gate(
    ctx: &GpuContext,
    r: &mut Resources,
    params: &RenderParams,
    table: &[[f32; 2]],
    cdf: &[f32],
) -> Result<()> {
    let Some(params_buffer) = r.get("params") else {
        r.uniform_init(ctx, "params", params);
        r.storage_init(ctx, "gate_table", table)?;
        return r.storage_init(ctx, "target_cdf", cdf);
    };
    let queue = &ctx.queue;
    queue.write_buffer(r.get("target_cdf").unwrap(), 0, bytemuck::cast_slice(cdf));
    if !table.is_empty() {
        queue.write_buffer(r.get("gate_table").unwrap(), 0, bytemuck::cast_slice(table));
    }
    queue.write_buffer(params_buffer, 0, bytemuck::bytes_of(params));
    Ok(())
}

/// The film a render's state holds: each element's sum over the samples per pixel, the
/// camera-side sums (`film`) of stratified target lengths divided per bin by the samples whose
/// target fell in it (see [`divide_by_stratum_counts`]), plus the light-tracing sums
/// (`splat_film`, where the method keeps them). A render's `film()` is this function of its
/// state, so equal sums (an uninterrupted render, a resumed one, merged shards) give equal
/// images, bit for bit.
pub fn film_of_state(state: &RenderState) -> Result<Film> {
    let params: RenderParams = state.values("params", 1)?[0];
    let mut film = Film::zeroed(params.width, params.height, params.gate.bins);
    let n = film.data.len();
    let spp = state.samples_in_film.max(1) as f64;
    let sums: Vec<[u32; 4]> = state.values("film", n)?;
    film.data = sums.iter().map(|&w| (fixed::to_f64(fixed::from_words(w)) / spp) as f32).collect();
    film.spp = state.samples_in_film;
    if state.method == super::Method::Ellipsoidal {
        let visits: Vec<u32> = state.all_values("target_visits")?;
        divide_by_stratum_counts(&params, &visits, state.samples_in_film, &mut film);
    }
    if state.blobs.iter().any(|(name, _)| name == "splat_film") {
        let splats: Vec<[u32; 4]> = state.values("splat_film", n)?;
        for (v, &w) in film.data.iter_mut().zip(&splats) {
            *v = (*v as f64 + fixed::to_f64(fixed::from_words(w)) / spp) as f32;
        }
    }
    Ok(film)
}

/// Turns each bin of a film of stratified target lengths (ellipsoidal connections on a
/// transient gate, `TargetParams::strata` > 0) from the sum over the pixel's samples divided
/// by their number into the mean over the samples whose target fell in it, wherever the bin is
/// sure to have had one (see `film::target::StratumFactors`; elsewhere, with extra visits, the
/// sum over the bin's expected count). Both are unbiased; the first is free of the error of a
/// bin's sample count. Only for the film of camera-subpath
/// contributions, whose lengths are their slot's target; light-tracing splats land in
/// other pixels and keep the plain mean. `visits`: the extra visits (empty without a pilot).
pub fn divide_by_stratum_counts(params: &RenderParams, visits: &[u32], samples: u64, film: &mut Film) {
    let t = &params.target_length;
    let n = t.strata as usize;
    if n == 0 {
        return;
    }
    let mut factors = vec![0.0f32; n];
    let bins = film.bins as usize;
    let stratum_factors = StratumFactors::new(t, samples);
    for pixel in 0..(film.width * film.height) as usize {
        let row = if t.extra > 0 { &visits[pixel * (n + 1)..(pixel + 1) * (n + 1)] } else { &[][..] };
        // None when there is nothing to change (no extra visits and fewer samples than bins).
        if stratum_factors.pixel(row, pixel as u32, &mut factors).is_none() {
            continue;
        }
        for (j, f) in factors.iter().enumerate() {
            let base = (pixel * bins + t.first_bin as usize + j) * 3;
            film.data[base..base + 3].iter_mut().for_each(|v| *v *= f);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waves_on_a_gpu_fill_their_byte_budget_within_bounds() {
        // A CPU device keeps the tracer's own target whatever a slot holds.
        assert_eq!(target_slots_per_wave(true, 1 << 16, 100), 1 << 16);
        assert_eq!(target_slots_per_wave(true, 1 << 16, 1 << 20), 1 << 16);
        // A GPU takes as many slots as GPU_WAVE_BYTES holds (direct at 5 bounces: 5,264 bytes)...
        assert_eq!(target_slots_per_wave(false, 1 << 16, 5264), GPU_WAVE_BYTES / 5264);
        // ...never fewer than on a CPU (ellipsoidal's 26,992 bytes would give 39,779)...
        assert_eq!(target_slots_per_wave(false, 1 << 16, 26_992), 1 << 16);
        // ...and at most GPU_MAX_TARGET_SLOTS (path: a few hundred bytes).
        assert_eq!(target_slots_per_wave(false, 1 << 18, 300), GPU_MAX_TARGET_SLOTS);
        assert_eq!(target_slots_per_wave(false, 1 << 18, 0), GPU_MAX_TARGET_SLOTS);
    }

    #[test]
    fn a_pilots_wave_holds_its_bytes_yet_a_few_samples_of_every_pixel() {
        let pilot = |width, height| RenderSettings { width, height, wave_bytes: Some(16 << 20), ..Default::default() };
        // Without a bound, the tracer's own target.
        assert_eq!(wave_target(true, 1 << 16, 2800, &RenderSettings::default()), 1 << 16);
        // `direct` on the fence (2,800 bytes a slot): 16 MiB hold 5,991 slots, 23 samples of 16x16.
        assert_eq!(wave_target(true, 1 << 16, 2800, &pilot(16, 16)), (16 << 20) / 2800);
        // An `ellipsoidal` slot of 14 KiB: 16 MiB hold 1,170 slots, yet a 32x32 pilot keeps 4 samples
        // of each pixel in one pass.
        assert_eq!(wave_target(true, 1 << 16, 14 << 10, &pilot(32, 32)), 1024 * BOUNDED_WAVE_SAMPLES);
        // Never more than the tracer's own target.
        assert_eq!(wave_target(true, 1 << 10, 100, &pilot(16, 16)), 1 << 10);
    }

    #[test]
    fn a_warm_up_pass_traces_only_its_first_pixels() {
        let params = RenderParams { width: 64, height: 64, ..Default::default() };
        // A pass of 64x64 in waves of 1,500 slots at 1 sample: three waves, cut to 1,024 pixels.
        let waves = waves_of_pass(&params, 1500, 7, 1).unwrap();
        assert_eq!(waves.len(), 3);
        let cut = first_pixels(waves, 1024);
        assert_eq!(cut.len(), 1);
        assert_eq!((cut[0].pixel_base, cut[0].pixel_count, cut[0].slot_count, cut[0].sample_base), (0, 1024, 1024, 7));
        // Across a wave boundary, at 2 samples a pixel: 750 pixels a wave.
        let cut = first_pixels(waves_of_pass(&params, 1500, 0, 2).unwrap(), 1000);
        let spans: Vec<_> = cut.iter().map(|w| (w.pixel_base, w.pixel_count, w.slot_count)).collect();
        assert_eq!(spans, [(0, 750, 1500), (750, 250, 500)]);
        // An image smaller than the limit is traced whole.
        let small = RenderParams { width: 16, height: 16, ..Default::default() };
        let cut = first_pixels(waves_of_pass(&small, 1 << 16, 0, 1).unwrap(), 1024);
        assert_eq!(cut.iter().map(|w| w.pixel_count).sum::<u32>(), 256);
        // The warm-up's block is one workgroup.
        let cut = first_pixels(waves_of_pass(&small, 1 << 16, 0, 1).unwrap(), WARM_UP_PIXELS);
        assert_eq!((cut.len(), cut[0].pixel_count), (1, 64));
    }
}
