//! `gatetrace view`: an egui window in which the gate is scrubbed through time while the image
//! accumulates progressively. The window shares the renderer's wgpu device: every UI frame runs
//! a bounded amount of rendering (a few passes, ~25 ms), `resolve_display` turns the film into
//! RGBA8 on the GPU and the result is copied into the texture egui draws (no CPU round trip).
//! Moving τ within one gate kind rewrites the gate parameters in place (`Integrator::set_gate`)
//! and restarts accumulation at once; a new method, gate kind or bounce count rebuilds the
//! integrator. A transient gate's cube accumulates as a whole and `resolve_display` shows one
//! bin, so moving the bin shown costs nothing; signed gates (CW) show the signed luminance on a
//! diverging map. Clicking a pixel shows its transient response (a `path` render with a transient
//! gate over the scene's path lengths, accumulated alongside) with the gate drawn on it.

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, anyhow, bail};
use eframe::egui;

use crate::film::output::{Metadata, write_film};
use crate::film::preview::auto_exposure_ev;
use crate::film::{CwCode, Gate, fixed};
use crate::gpu::layout::{DISPLAY_LINEAR, DISPLAY_LOG, DisplayParams};
use crate::gpu::{GpuContext, Kernel, Resources};
use crate::integrator::{Integrator, Method, PassSizer, RenderSettings, create_integrator};
use crate::scene::{LoadOptions, PreparedScene, load_gltf_with};
use crate::units::metres_to_ps;

/// Gate kinds the viewer offers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GateChoice {
    /// Steady state.
    None,
    /// W = 1 on [τ − width/2, τ + width/2).
    Box,
    /// Gaussian of mean τ and standard deviation width.
    Gaussian,
    /// A cube of bins rendered together; one bin is shown.
    Transient,
    /// Continuous-wave gate (cosine, or one period of a code), signed.
    Cw,
    /// Tabulated W, moved through time as a whole.
    Table,
}

/// The window's gate controls: the parameters of every kind, so that switching kinds and back
/// keeps each kind's settings.
#[derive(Clone, Debug)]
pub struct GateControls {
    /// The kind rendered.
    pub kind: GateChoice,
    /// Box and Gaussian gates: centre τ (m of optical path).
    pub tau: f64,
    /// Box gates: width; Gaussian gates: standard deviation (m).
    pub width: f64,
    /// Transient gates: start of bin 0 (m).
    pub transient_start: f64,
    /// Transient gates: bin width (m).
    pub bin_width: f64,
    /// Transient gates: number of bins.
    pub bins: u32,
    /// Transient gates: the bin shown (0 to bins - 1).
    pub bin: u32,
    /// CW gates: modulation frequency (Hz).
    pub frequency_hz: f64,
    /// CW gates: phase (degrees).
    pub phase_deg: f64,
    /// CW gates: the code's correlation over one period (None: a cosine).
    pub code: Option<CwCode>,
    /// Table gates: the table's (length m, weight) points as read, and its file.
    pub table: Option<(Vec<(f64, f64)>, PathBuf)>,
    /// Table gates: how far the table is moved to longer paths (m).
    pub table_shift: f64,
}

impl GateControls {
    /// Controls showing `gate`, with `bin` shown for a transient gate; the other kinds start
    /// from defaults within `lengths`, the scene's range of path lengths (m).
    pub fn new(gate: &Gate, bin: u32, lengths: (f64, f64)) -> Self {
        let (lo, hi) = length_range(lengths);
        let mut c = GateControls {
            kind: GateChoice::None,
            tau: 3.165,
            width: 0.05,
            transient_start: lo,
            bin_width: (hi - lo) / 32.0,
            bins: 32,
            bin: 0,
            frequency_hz: 100e6,
            phase_deg: 0.0,
            code: None,
            table: None,
            table_shift: 0.0,
        };
        match gate.clone() {
            Gate::None => {}
            Gate::Box { start, end } => (c.kind, c.tau, c.width) = (GateChoice::Box, 0.5 * (start + end), end - start),
            Gate::Gaussian { mean, sigma } => (c.kind, c.tau, c.width) = (GateChoice::Gaussian, mean, sigma),
            Gate::Transient { start, width, bins } => {
                (c.kind, c.transient_start, c.bin_width, c.bins, c.bin) =
                    (GateChoice::Transient, start, width, bins, bin.min(bins - 1))
            }
            Gate::Cw { frequency_hz, phase_deg } => {
                (c.kind, c.frequency_hz, c.phase_deg) = (GateChoice::Cw, frequency_hz, phase_deg)
            }
            Gate::CwCode { frequency_hz, phase_deg, code } => {
                (c.kind, c.frequency_hz, c.phase_deg, c.code) = (GateChoice::Cw, frequency_hz, phase_deg, Some(code))
            }
            Gate::Table { points, source } => (c.kind, c.table) = (GateChoice::Table, Some((points, source))),
        }
        c
    }

    /// The gate the controls describe.
    pub fn gate(&self) -> Gate {
        match self.kind {
            GateChoice::None => Gate::None,
            GateChoice::Box => {
                let start = (self.tau - 0.5 * self.width).max(0.0);
                Gate::Box { start, end: start + self.width }
            }
            GateChoice::Gaussian => Gate::Gaussian { mean: self.tau, sigma: self.width },
            GateChoice::Transient => {
                Gate::Transient { start: self.transient_start, width: self.bin_width, bins: self.bins.max(1) }
            }
            GateChoice::Cw => match self.code {
                None => Gate::Cw { frequency_hz: self.frequency_hz, phase_deg: self.phase_deg },
                Some(code) => Gate::CwCode { frequency_hz: self.frequency_hz, phase_deg: self.phase_deg, code },
            },
            GateChoice::Table => match &self.table {
                Some((points, source)) => Gate::Table {
                    points: points.iter().map(|&(l, w)| (l + self.table_shift, w)).collect(),
                    source: source.clone(),
                },
                None => Gate::None,
            },
        }
    }

    /// The transient bin shown (0 for other gates).
    pub fn shown_bin(&self) -> u32 {
        if self.kind == GateChoice::Transient { self.bin.min(self.bins.max(1) - 1) } else { 0 }
    }

    /// Moves the gate `d` metres of optical path later (earlier when negative): τ for box and
    /// Gaussian gates, the table's shift, the CW phase by -360 f d / c degrees, and for a
    /// transient gate the bin shown by d / bin width bins (rounded, kept within the cube).
    pub fn step(&mut self, d: f64) {
        match self.kind {
            GateChoice::None => {}
            GateChoice::Box | GateChoice::Gaussian => self.tau += d,
            GateChoice::Table => self.table_shift += d,
            GateChoice::Cw => self.phase_deg -= 360.0 * self.frequency_hz * d / crate::units::SPEED_OF_LIGHT,
            GateChoice::Transient => {
                let bin = self.bin as f64 + (d / self.bin_width).round();
                self.bin = bin.clamp(0.0, (self.bins.max(1) - 1) as f64) as u32;
            }
        }
    }
}

/// Sliders keep values from the command line outside their range (only dragging is bounded):
/// a gate or bounce count given at start is rendered as given.
const KEEP: egui::SliderClamping = egui::SliderClamping::Edits;

/// The range of path lengths (m) the sliders span: from just below the shortest path the scene
/// allows, over at most four times that (long tails carry little light).
fn length_range(lengths: (f64, f64)) -> (f64, f64) {
    (lengths.0 * 0.95, lengths.0 + (lengths.1 - lengths.0).min(4.0 * lengths.0.max(0.5)))
}

/// Settings of `gatetrace view` (initial values of the controls and the screenshot mode).
#[derive(Clone, Debug)]
pub struct ViewOptions {
    /// glTF scene.
    pub scene: PathBuf,
    /// See [`crate::scene::LoadOptions::allow_unsupported_materials`].
    pub allow_unsupported_materials: bool,
    /// Image size (pixels).
    pub width: u32,
    /// Image size (pixels).
    pub height: u32,
    /// Sampling method.
    pub method: Method,
    /// Gate at start (any kind).
    pub gate: Gate,
    /// Transient gates: the bin shown at start.
    pub bin: u32,
    /// Maximum scattering vertices.
    pub max_bounces: u32,
    /// Russian roulette after this many scattering vertices (None: off).
    pub rr_depth: Option<u32>,
    /// Thin-lens camera: lens radius (m), overriding the scene's camera (0: a pinhole).
    pub aperture_radius: Option<f32>,
    /// Thin-lens camera: focus distance (m), overriding the scene's camera.
    pub focus_distance: Option<f32>,
    /// Exposure (stops: the radiance is multiplied by 2^EV).
    pub exposure_ev: f32,
    /// Set the exposure from the first image (99th percentile to 1), overriding `exposure_ev`.
    pub auto_exposure: bool,
    /// Logarithmic tone curve instead of linear.
    pub log_curve: bool,
    /// Screenshot mode: after `after_frames` frames, save the window's pixels here (PNG) with a
    /// JSON sidecar giving the image's rectangle, and close.
    pub screenshot: Option<PathBuf>,
    /// Frames rendered before the screenshot.
    pub after_frames: u32,
    /// Screenshot mode: move the gate by this much (m of optical path, see
    /// [`GateControls::step`]) every 10 frames and report the time from each change to the
    /// first image of the new gate.
    pub scrub_step: Option<f64>,
    /// Pixel (x, y) whose time profile is shown from the start (as if clicked).
    pub profile_pixel: Option<(u32, u32)>,
    /// Render seed.
    pub seed: u32,
}

/// Opens the window and runs until it is closed (or the screenshot is saved).
pub fn run_viewer(options: ViewOptions) -> Result<()> {
    let load = LoadOptions { allow_unsupported_materials: options.allow_unsupported_materials, ..Default::default() };
    let mut scene = load_gltf_with(&options.scene, &load)?;
    if options.aperture_radius.is_some() || options.focus_distance.is_some() {
        scene
            .camera
            .override_lens(options.aperture_radius, options.focus_distance, "--focus-distance METRES")
            .with_context(|| format!("{}: --aperture-radius/--focus-distance", scene.source))?;
    }
    let scene = PreparedScene::new(scene)?;
    let ctx = GpuContext::new()?;
    let (shortest, longest) = scene.scene.path_length_bounds(options.max_bounces.max(1));
    let native = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title(format!("gatetrace — {}", options.scene.display()))
            .with_inner_size([1100.0, 760.0]),
        wgpu_options: eframe::egui_wgpu::WgpuConfiguration {
            wgpu_setup: eframe::egui_wgpu::WgpuSetup::Existing(eframe::egui_wgpu::WgpuSetupExisting {
                instance: ctx.instance.clone(),
                adapter: ctx.adapter.clone(),
                device: ctx.device.clone(),
                queue: ctx.queue.clone(),
            }),
            ..Default::default()
        },
        renderer: eframe::Renderer::Wgpu,
        ..Default::default()
    };
    let mut failure: Option<anyhow::Error> = None;
    let result = eframe::run_native(
        "gatetrace",
        native,
        Box::new(|cc| {
            let state = cc.wgpu_render_state.as_ref().ok_or("eframe started without its wgpu renderer")?;
            let app = Viewer::new(&ctx, &scene, options, (shortest as f64, longest as f64), state, &mut failure)
                .map_err(|e| format!("{e:#}"))?;
            Ok(Box::new(app))
        }),
    );
    if let Some(e) = failure {
        return Err(e);
    }
    result.map_err(|e| anyhow!("the viewer window failed: {e} (is there a display? under CI use xvfb-run)"))
}

/// The GPU side of the displayed image: the resolve kernel, its buffers and the egui texture.
struct Display {
    kernel: Kernel,
    bind_group: wgpu::BindGroup,
    params: wgpu::Buffer,
    pixels: wgpu::Buffer,
    texture: wgpu::Texture,
    texture_id: egui::TextureId,
    /// Pixels per row of `pixels` (a multiple of 64, as texture copies need 256-byte rows).
    stride: u32,
}

/// The transient response of one pixel, accumulated by a transient `path` render.
struct Profile<'a> {
    pixel: (u32, u32),
    /// Bounces of its render (it follows the main one's).
    max_bounces: u32,
    tracer: Box<dyn Integrator + 'a>,
    /// Bin range (m).
    range: (f64, f64),
    bins: u32,
    /// Mean radiance per bin (bin-integrated), luminance-weighted.
    values: Vec<f64>,
    staging: wgpu::Buffer,
}

/// Timing readouts.
#[derive(Default)]
struct Timing {
    /// When the gate last changed and the image has not been shown since.
    pending_change: Option<Instant>,
    /// A gate change whose first image is being painted in this frame.
    shown_pending: Option<Instant>,
    /// Time from the last gate change to its first image on screen (the end of the frame that
    /// rendered it).
    last_latency: Option<Duration>,
    latencies: Vec<Duration>,
    frame_times: Vec<Duration>,
    last_frame: Option<Instant>,
    /// Samples per second over the last frames (pixels x samples).
    samples_per_second: f64,
}

struct Viewer<'a> {
    ctx: &'a GpuContext,
    scene: &'a PreparedScene,
    /// Path lengths the scene allows (m), for the sliders and the profile.
    lengths: (f64, f64),
    options: ViewOptions,
    /// The gate's controls.
    gate: GateControls,
    /// Settings of the current integrator.
    built: Option<RenderSettings>,
    tracer: Option<Box<dyn Integrator + 'a>>,
    display: Option<Display>,
    profile: Option<Profile<'a>>,
    renderer: std::sync::Arc<egui::mutex::RwLock<eframe::egui_wgpu::Renderer>>,
    timing: Timing,
    /// Sizes each frame's passes from the measured rate.
    sizer: PassSizer,
    frames: u32,
    image_rect: Option<egui::Rect>,
    screenshot_rx: Option<mpsc::Receiver<std::sync::Arc<egui::ColorImage>>>,
    message: String,
    /// Set the exposure from the image at the next frame (the 99th percentile maps to 1).
    auto_exposure_pending: bool,
    failure: &'a mut Option<anyhow::Error>,
}

impl<'a> Viewer<'a> {
    fn new(
        ctx: &'a GpuContext,
        scene: &'a PreparedScene,
        options: ViewOptions,
        lengths: (f64, f64),
        state: &eframe::egui_wgpu::RenderState,
        failure: &'a mut Option<anyhow::Error>,
    ) -> Result<Self> {
        let gate = GateControls::new(&options.gate, options.bin, lengths);
        let mut viewer = Self {
            ctx,
            scene,
            lengths,
            gate,
            auto_exposure_pending: options.auto_exposure,
            options,
            built: None,
            tracer: None,
            display: None,
            profile: None,
            renderer: state.renderer.clone(),
            timing: Timing::default(),
            sizer: PassSizer::default(),
            frames: 0,
            image_rect: None,
            screenshot_rx: None,
            message: String::new(),
            failure,
        };
        viewer.sync()?;
        if let Some((x, y)) = viewer.options.profile_pixel {
            if x >= viewer.options.width || y >= viewer.options.height {
                bail!(
                    "--profile-pixel {x},{y} lies outside the {}x{} image",
                    viewer.options.width,
                    viewer.options.height
                );
            }
            viewer.select_pixel((x, y))?;
        }
        Ok(viewer)
    }

    fn settings(&self) -> RenderSettings {
        let o = &self.options;
        let method = if self.gate.kind == GateChoice::None && o.method == Method::Ellipsoidal {
            Method::Direct
        } else {
            o.method
        };
        RenderSettings {
            width: o.width,
            height: o.height,
            method,
            gate: self.gate.gate(),
            max_bounces: o.max_bounces,
            rr_depth: o.rr_depth,
            seed: o.seed,
            connections_per_query: crate::integrator::bidirectional::default_connections_per_query(method),
            ..Default::default()
        }
    }

    /// Brings the integrator in line with the controls: the gate moved in place where possible,
    /// otherwise a new integrator (and display bindings).
    fn sync(&mut self) -> Result<()> {
        let wanted = self.settings();
        if self.built.as_ref() == Some(&wanted) {
            return Ok(());
        }
        wanted.gate.validate()?;
        self.timing.pending_change = Some(Instant::now());
        if let (Some(built), Some(tracer)) = (&self.built, &mut self.tracer) {
            let same_but_gate = RenderSettings { gate: wanted.gate.clone(), ..built.clone() } == wanted;
            if same_but_gate && tracer.set_gate(self.scene, &wanted)? {
                self.built = Some(wanted);
                return Ok(());
            }
        }
        if wanted.method != Method::Path {
            crate::integrator::bidirectional::check_settings(&wanted)?;
        }
        self.tracer = None;
        let tracer = create_integrator(self.ctx, self.scene, &wanted)?;
        self.display = Some(self.make_display(tracer.as_ref(), wanted.method != Method::Path)?);
        self.tracer = Some(tracer);
        self.built = Some(wanted);
        Ok(())
    }

    fn make_display(&self, tracer: &dyn Integrator, splats: bool) -> Result<Display> {
        let ctx = self.ctx;
        let (w, h) = (self.options.width, self.options.height);
        let stride = w.div_ceil(64) * 64;
        let constants = tracer.constants();
        let kernel = if splats {
            Kernel::with_feature(ctx, "resolve_display", "splats", constants)
        } else {
            Kernel::new(ctx, "resolve_display", None, constants)
        };
        let mut resources: Resources = tracer.resources().clone();
        resources.uniform_init(ctx, "display_params", &DisplayParams::default());
        resources.storage_zeroed(ctx, "display", stride as u64 * h as u64 * 4, wgpu::BufferUsages::COPY_SRC)?;
        let bind_group = kernel.bind(ctx, &resources);
        let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("display"),
            size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            // egui composes in gamma space: the texels are already sRGB-encoded (resolve_display).
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        let view = texture.create_view(&Default::default());
        let texture_id = match &self.display {
            Some(old) => {
                self.renderer.write().update_egui_texture_from_wgpu_texture(
                    &ctx.device,
                    &view,
                    wgpu::FilterMode::Nearest,
                    old.texture_id,
                );
                old.texture_id
            }
            None => self.renderer.write().register_native_texture(&ctx.device, &view, wgpu::FilterMode::Nearest),
        };
        Ok(Display {
            kernel,
            bind_group,
            params: resources.get("display_params").unwrap().clone(),
            pixels: resources.get("display").unwrap().clone(),
            texture,
            texture_id,
            stride,
        })
    }

    /// Renders for about `budget`, at least one pass (one sample per pixel right after a
    /// change, so the first image comes quickly), then resolves the film into the texture.
    fn render(&mut self, budget: Duration) -> Result<()> {
        let (Some(tracer), Some(display)) = (&mut self.tracer, &self.display) else { return Ok(()) };
        let start = Instant::now();
        let before = tracer.samples_done();
        let pixels = (self.options.width * self.options.height) as f64;
        // Passes sized to the budget from the measured rate (one sample right after a change,
        // when nothing is measured yet), so a frame never waits for a long pass.
        if tracer.samples_done() == 0 {
            self.sizer = PassSizer::default();
        }
        self.sizer.render_for(tracer.as_mut(), budget.as_secs_f64(), |_, _| Ok(std::ops::ControlFlow::Continue(())))?;
        let done = tracer.samples_done() - before;
        let rate = done as f64 * pixels / start.elapsed().as_secs_f64().max(1e-9);
        let t = &mut self.timing;
        t.samples_per_second = if t.samples_per_second == 0.0 { rate } else { 0.8 * t.samples_per_second + 0.2 * rate };

        let params = DisplayParams {
            inverse_spp: 1.0 / tracer.samples_done().max(1) as f32,
            exposure: 2f32.powf(self.options.exposure_ev),
            curve: if self.options.log_curve { DISPLAY_LOG } else { DISPLAY_LINEAR },
            bin: self.gate.shown_bin(),
            signed: self.built.as_ref().is_some_and(|b| b.gate.is_signed()) as u32,
            decades: 4.0,
            stride: display.stride,
            ..Default::default()
        };
        let ctx = self.ctx;
        ctx.queue.write_buffer(&display.params, 0, bytemuck::bytes_of(&params));
        let mut encoder =
            ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("resolve_display") });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("resolve_display"),
                timestamp_writes: None,
            });
            display.kernel.dispatch(&mut pass, &display.bind_group, self.options.width * self.options.height);
        }
        let (w, h) = (self.options.width, self.options.height);
        encoder.copy_buffer_to_texture(
            wgpu::TexelCopyBufferInfo {
                buffer: &display.pixels,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(display.stride * 4),
                    rows_per_image: Some(h),
                },
            },
            display.texture.as_image_copy(),
            wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        );
        ctx.queue.submit([encoder.finish()]);
        // The new gate's first image is on screen once this frame has been painted: the latency
        // is taken at the start of the next frame.
        if let Some(changed) = self.timing.pending_change.take() {
            self.timing.shown_pending = Some(changed);
        }
        Ok(())
    }

    /// One more pass of the selected pixel's transient render, and its bins read back.
    fn update_profile(&mut self) -> Result<()> {
        let Some(p) = &mut self.profile else { return Ok(()) };
        p.tracer.render_pass(1)?;
        let ctx = self.ctx;
        let film = p.tracer.resources().get("film").unwrap();
        let w = self.options.width;
        let element = crate::integrator::FILM_ELEMENT_BYTES;
        let first = ((p.pixel.1 * w + p.pixel.0) * p.bins * 3) as u64 * element;
        let bytes = p.bins as u64 * 3 * element;
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(film, first, &p.staging, 0, bytes);
        ctx.queue.submit([encoder.finish()]);
        let slice = p.staging.slice(..);
        slice.map_async(wgpu::MapMode::Read, |_| {});
        ctx.wait_idle()?;
        let sums: Vec<[u32; 4]> = {
            let view = slice.get_mapped_range().map_err(|e| anyhow!("cannot read the time profile back: {e:?}"))?;
            bytemuck::cast_slice(&view).to_vec()
        };
        p.staging.unmap();
        let spp = p.tracer.samples_done().max(1) as f64;
        let width = (p.range.1 - p.range.0) / p.bins as f64;
        p.values = sums
            .chunks(3)
            .map(|c| {
                let rgb: Vec<f64> = c.iter().map(|&s| fixed::to_f64(fixed::from_words(s)) / spp).collect();
                (0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]) / width
            })
            .collect();
        Ok(())
    }

    fn select_pixel(&mut self, pixel: (u32, u32)) -> Result<()> {
        let bounces = self.options.max_bounces;
        if self.profile.as_ref().is_some_and(|p| p.pixel == pixel && p.max_bounces == bounces) {
            return Ok(());
        }
        if let Some(p) = self.profile.as_mut().filter(|p| p.max_bounces == bounces) {
            p.pixel = pixel;
            p.tracer.reset_film();
            p.values.clear();
            return Ok(());
        }
        // One film binding (the readback assumes an unsplit film): as many bins, up to 128, as fit.
        let per_bin = self.options.width as u64 * self.options.height as u64 * 24;
        let bins = (self.ctx.max_binding_size() / per_bin).min(128) as u32;
        if bins < 8 {
            bail!("the time profile needs at least 8 bins per pixel; this image is too large for one binding");
        }
        let range =
            (self.lengths.0, self.lengths.0 + (self.lengths.1 - self.lengths.0).min(4.0 * self.lengths.0.max(0.5)));
        let gate = Gate::Transient { start: range.0, width: (range.1 - range.0) / bins as f64, bins };
        let settings = RenderSettings {
            width: self.options.width,
            height: self.options.height,
            method: Method::Path,
            gate,
            max_bounces: self.options.max_bounces,
            rr_depth: self.options.rr_depth,
            seed: self.options.seed ^ 0x5bd1_e995,
            ..Default::default()
        };
        let tracer = create_integrator(self.ctx, self.scene, &settings)?;
        let staging = self.ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("profile_staging"),
            size: bins as u64 * 3 * crate::integrator::FILM_ELEMENT_BYTES,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        self.profile = Some(Profile { pixel, max_bounces: bounces, tracer, range, bins, values: Vec::new(), staging });
        Ok(())
    }

    /// Exposure (EV) that maps the 99th percentile of the shown image's values (channels, or
    /// the luminance's magnitude on the signed display; the shown bin of a transient gate) to 1.
    fn auto_exposure(&self) -> Result<Option<f32>> {
        let (Some(tracer), Some(built)) = (&self.tracer, &self.built) else { return Ok(None) };
        let film = tracer.film()?;
        let bin = self.gate.shown_bin().min(film.bins - 1);
        let pixels = (0..film.height).flat_map(|y| (0..film.width).map(move |x| (x, y)));
        let shown: Vec<[f32; 3]> = pixels.map(|(x, y)| film.get(x, y, bin)).collect();
        Ok(if built.gate.is_signed() {
            auto_exposure_ev(shown.iter().map(|c| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]))
        } else {
            auto_exposure_ev(shown.iter().flatten().copied())
        })
    }

    fn save(&mut self, path: &Path) -> Result<()> {
        let (Some(tracer), Some(built)) = (&self.tracer, &self.built) else { bail!("nothing rendered yet") };
        let film = tracer.film()?;
        let metadata: Metadata = vec![
            ("scene".into(), self.options.scene.display().to_string().into()),
            ("method".into(), built.method.name().into()),
            ("gate_parameters".into(), built.gate.parameters()),
            ("gate_description".into(), built.gate.describe().into()),
            ("spp".into(), film.spp.into()),
            ("seed".into(), built.seed.into()),
            ("max_bounces".into(), built.max_bounces.into()),
            ("adapter".into(), self.ctx.adapter_description().into()),
        ];
        let gate = &built.gate;
        let bin_ranges: Vec<(f64, f64)> = (0..gate.bins()).filter_map(|b| gate.bin_range(b)).collect();
        write_film(path, &film, &metadata, &bin_ranges)
    }

    /// The gate's kind and, per kind, what moves it through time: τ (box, Gaussian), the bin
    /// shown (transient), the phase (CW), the shift (table).
    fn gate_controls(&mut self, ui: &mut egui::Ui) {
        let g = &mut self.gate;
        ui.heading("Gate");
        ui.horizontal_wrapped(|ui| {
            ui.selectable_value(&mut g.kind, GateChoice::None, "none");
            ui.selectable_value(&mut g.kind, GateChoice::Box, "box");
            ui.selectable_value(&mut g.kind, GateChoice::Gaussian, "gaussian");
            ui.selectable_value(&mut g.kind, GateChoice::Transient, "transient");
            ui.selectable_value(&mut g.kind, GateChoice::Cw, "cw");
            if g.table.is_some() {
                ui.selectable_value(&mut g.kind, GateChoice::Table, "table");
            }
        });
        let (lo, hi) = length_range(self.lengths);
        let length = |ui: &mut egui::Ui, value: &mut f64| {
            ui.horizontal(|ui| {
                ui.add(
                    egui::DragValue::new(value)
                        .speed(0.0005)
                        .range(0.0..=1e4)
                        .clamp_existing_to_range(false)
                        .suffix(" m"),
                );
                ui.label(format!("= {:.1} ps = {:.4} ns", metres_to_ps(*value), metres_to_ps(*value) / 1e3));
            });
        };
        match g.kind {
            GateChoice::None => {
                ui.label("steady state");
            }
            GateChoice::Box | GateChoice::Gaussian => {
                ui.label("centre τ (m of optical path)");
                ui.add(egui::Slider::new(&mut g.tau, lo..=hi).max_decimals(5).clamping(KEEP));
                length(ui, &mut g.tau);
                ui.label(if g.kind == GateChoice::Gaussian { "σ (m)" } else { "width (m)" });
                ui.add(egui::Slider::new(&mut g.width, 1e-4..=1.0).logarithmic(true).max_decimals(5).clamping(KEEP));
                ui.label(format!("= {:.2} ps", metres_to_ps(g.width)));
            }
            GateChoice::Transient => {
                g.bins = g.bins.max(1);
                g.bin = g.bin.min(g.bins - 1);
                ui.label("bin shown");
                ui.add(egui::Slider::new(&mut g.bin, 0..=g.bins - 1));
                let (a, b) = (
                    g.transient_start + g.bin as f64 * g.bin_width,
                    g.transient_start + (g.bin + 1) as f64 * g.bin_width,
                );
                ui.label(format!("[{a:.4} m, {b:.4} m) = [{:.1} ps, {:.1} ps)", metres_to_ps(a), metres_to_ps(b)));
                ui.label("start of bin 0 (m of optical path)");
                length(ui, &mut g.transient_start);
                ui.horizontal(|ui| {
                    ui.label("bins");
                    ui.add(egui::DragValue::new(&mut g.bins).range(1..=4096).clamp_existing_to_range(false));
                    ui.label("of");
                    ui.add(
                        egui::DragValue::new(&mut g.bin_width)
                            .speed(0.0005)
                            .range(1e-6..=10.0)
                            .clamp_existing_to_range(false)
                            .suffix(" m"),
                    );
                });
                ui.label("(the cube accumulates as a whole: moving the bin shown keeps the samples)");
            }
            GateChoice::Cw => {
                ui.label("phase (degrees)");
                ui.add(egui::Slider::new(&mut g.phase_deg, -180.0..=180.0).max_decimals(2).clamping(KEEP));
                ui.horizontal(|ui| {
                    ui.label("frequency");
                    let mut mhz = g.frequency_hz / 1e6;
                    if ui
                        .add(
                            egui::DragValue::new(&mut mhz)
                                .speed(1.0)
                                .range(1e-3..=1e5)
                                .clamp_existing_to_range(false)
                                .suffix(" MHz"),
                        )
                        .changed()
                    {
                        g.frequency_hz = mhz * 1e6;
                    }
                });
                ui.label(match g.code {
                    Some(code) => format!("code {}", code.name()),
                    None => "code: cosine".into(),
                });
            }
            GateChoice::Table => {
                if let Some((points, source)) = &g.table {
                    ui.label(format!("{} ({} points), moved by (m)", source.display(), points.len()));
                    // Never below zero length.
                    let least = -points[0].0;
                    ui.add(
                        egui::Slider::new(&mut g.table_shift, least.max(lo - hi)..=hi - lo)
                            .max_decimals(5)
                            .clamping(KEEP),
                    );
                    ui.add(egui::DragValue::new(&mut g.table_shift).speed(0.0005).range(least..=1e4).suffix(" m"));
                }
            }
        }
        if g.gate().is_signed() {
            ui.label("signed gate: the luminance is shown, orange above zero, blue below, black at zero");
        }
        ui.separator();
    }

    fn controls(&mut self, ui: &mut egui::Ui) {
        self.gate_controls(ui);
        let o = &mut self.options;
        ui.separator();
        ui.heading("Method");
        ui.horizontal(|ui| {
            ui.selectable_value(&mut o.method, Method::Path, "path");
            ui.selectable_value(&mut o.method, Method::Direct, "direct");
            ui.selectable_value(&mut o.method, Method::Ellipsoidal, "ellipsoidal");
        });
        if o.method == Method::Ellipsoidal && self.gate.kind == GateChoice::None {
            ui.label("(steady state: ellipsoidal needs a gate; rendering with direct)");
        }
        ui.add(egui::Slider::new(&mut o.max_bounces, 0..=12).text("max bounces").clamping(KEEP));
        ui.separator();
        ui.heading("Display");
        ui.horizontal(|ui| {
            ui.add(egui::Slider::new(&mut o.exposure_ev, -20.0..=30.0).text("exposure (EV)").clamping(KEEP));
        });
        if ui.button("auto exposure").clicked() {
            self.auto_exposure_pending = true;
        }
        ui.horizontal(|ui| {
            ui.selectable_value(&mut o.log_curve, false, "linear");
            ui.selectable_value(&mut o.log_curve, true, "log (4 decades)");
        });
        ui.separator();
        if let Some(tracer) = &self.tracer {
            ui.label(format!("{} samples per pixel", tracer.samples_done()));
        }
        ui.label(format!("{:.3} Msamples/s", self.timing.samples_per_second / 1e6));
        if let Some(l) = self.timing.last_latency {
            ui.label(format!("gate change -> image: {:.0} ms", l.as_secs_f64() * 1e3));
        }
        let t = &self.timing.frame_times;
        if t.len() >= 2 {
            let recent = &t[t.len().saturating_sub(20)..];
            let mean = recent.iter().sum::<Duration>().as_secs_f64() / recent.len() as f64;
            ui.label(format!("refresh: {:.1} frames/s", 1.0 / mean.max(1e-9)));
        }
        ui.label(format!("device: {}", self.ctx.adapter_info.name));
        ui.separator();
        ui.horizontal(|ui| {
            for ext in ["exr", "npy"] {
                if ui.button(format!("save .{ext}")).clicked() {
                    let stem = self.options.scene.file_stem().and_then(|s| s.to_str()).unwrap_or("view").to_owned();
                    let path = PathBuf::from(format!("{stem}_view.{ext}"));
                    self.message = match self.save(&path) {
                        Ok(()) => format!("saved {}", path.display()),
                        Err(e) => format!("{e:#}"),
                    };
                }
            }
        });
        if !self.message.is_empty() {
            ui.label(&self.message);
        }
    }

    fn profile_plot(&self, ui: &mut egui::Ui) {
        use egui_plot::{Line, Plot, Span, VLine};
        let Some(p) = &self.profile else {
            ui.label("Click a pixel to see its transient response (radiance against path length).");
            return;
        };
        ui.label(format!(
            "pixel ({}, {}): radiance per metre of path length, {} spp ({} bins of {:.1} ps)",
            p.pixel.0,
            p.pixel.1,
            p.tracer.samples_done(),
            p.bins,
            metres_to_ps((p.range.1 - p.range.0) / p.bins as f64)
        ));
        let width = (p.range.1 - p.range.0) / p.bins as f64;
        let points: Vec<[f64; 2]> =
            p.values.iter().enumerate().map(|(i, &v)| [p.range.0 + (i as f64 + 0.5) * width, v]).collect();
        let gate = self.gate.gate();
        let bin = self.gate.shown_bin();
        Plot::new("time_profile").height(ui.available_height().max(120.0)).x_axis_label("path length (m)").show(
            ui,
            |plot| {
                plot.line(Line::new("radiance", points));
                match gate {
                    Gate::Box { start, end } => plot.span(
                        Span::new("gate", start..=end).fill(egui::Color32::from_rgba_unmultiplied(255, 200, 0, 60)),
                    ),
                    Gate::Gaussian { mean, .. } => plot.vline(VLine::new("gate", mean)),
                    Gate::Transient { .. } => {
                        if let Some((a, b)) = gate.bin_range(bin) {
                            plot.span(
                                Span::new("bin shown", a..=b)
                                    .fill(egui::Color32::from_rgba_unmultiplied(255, 200, 0, 60)),
                            )
                        }
                    }
                    _ => {}
                }
            },
        );
    }

    fn screenshot_mode(&mut self, ctx: &egui::Context) -> Result<()> {
        let Some(path) = self.options.screenshot.clone() else { return Ok(()) };
        if let Some(step) = self.options.scrub_step
            && self.frames > 0
            && self.frames % 10 == 0
            && self.frames < self.options.after_frames
        {
            self.gate.step(step);
            // A transient gate's new bin needs no new render: its first image is this frame's.
            self.timing.pending_change = Some(Instant::now());
        }
        if let Some(rx) = &self.screenshot_rx {
            if let Ok(image) = rx.try_recv() {
                save_screenshot(&path, &image, self.image_rect, ctx.pixels_per_point(), self)?;
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
            return Ok(());
        }
        if self.frames >= self.options.after_frames {
            let (tx, rx) = mpsc::channel();
            ctx.send_viewport_cmd(egui::ViewportCommand::Screenshot(egui::ScreenshotCallback::new(move |image| {
                let _ = tx.send(image);
            })));
            self.screenshot_rx = Some(rx);
        }
        Ok(())
    }

    fn frame(&mut self, ui: &mut egui::Ui) -> Result<()> {
        let now = Instant::now();
        if let Some(last) = self.timing.last_frame.replace(now) {
            self.timing.frame_times.push(now - last);
        }
        if let Some(changed) = self.timing.shown_pending.take() {
            let latency = now - changed;
            self.timing.last_latency = Some(latency);
            self.timing.latencies.push(latency);
        }
        let ctx = ui.ctx().clone();
        self.screenshot_mode(&ctx)?;
        if let Err(e) = self.sync() {
            self.message = format!("{e:#}");
        }
        if self.auto_exposure_pending && self.tracer.as_ref().is_some_and(|t| t.samples_done() >= 4) {
            self.auto_exposure_pending = false;
            if let Some(ev) = self.auto_exposure()? {
                self.options.exposure_ev = (ev * 4.0).round() / 4.0;
            }
        }
        if let Some(p) = &self.profile
            && p.max_bounces != self.options.max_bounces
        {
            let pixel = p.pixel;
            self.profile = None;
            self.select_pixel(pixel)?;
        }
        if self.screenshot_rx.is_none() {
            self.render(Duration::from_millis(25))?;
            self.update_profile()?;
            self.frames += 1;
        }
        egui::Panel::left("controls").resizable(false).exact_size(300.0).show(ui, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| self.controls(ui));
        });
        egui::CentralPanel::default().show(ui, |ui| {
            let Some(display) = &self.display else { return };
            let (w, h) = (self.options.width as f32, self.options.height as f32);
            let room = ui.available_size() * egui::vec2(1.0, 0.62);
            let zoom = (room.x / w).min(room.y / h).floor().max(1.0);
            let size = egui::vec2(w * zoom, h * zoom);
            let image =
                egui::Image::new((display.texture_id, size)).fit_to_exact_size(size).sense(egui::Sense::click());
            let response = ui.add(image);
            self.image_rect = Some(response.rect);
            if response.clicked()
                && let Some(pos) = response.interact_pointer_pos()
            {
                let rel = (pos - response.rect.min) / zoom;
                let pixel = ((rel.x as u32).min(self.options.width - 1), (rel.y as u32).min(self.options.height - 1));
                if let Err(e) = self.select_pixel(pixel) {
                    self.message = format!("{e:#}");
                }
            }
            ui.separator();
            self.profile_plot(ui);
        });
        ctx.request_repaint();
        Ok(())
    }
}

impl eframe::App for Viewer<'_> {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        if let Err(e) = self.frame(ui) {
            *self.failure = Some(e);
            ui.ctx().send_viewport_cmd(egui::ViewportCommand::Close);
        }
    }
}

/// Writes the window's pixels as PNG and, beside it (FILE.json), the image's rectangle in those
/// pixels, its samples per pixel and the display settings, for comparison with a headless render.
fn save_screenshot(
    path: &Path,
    image: &egui::ColorImage,
    rect: Option<egui::Rect>,
    ppp: f32,
    viewer: &Viewer,
) -> Result<()> {
    let [w, h] = image.size;
    let file =
        std::fs::File::create(path).with_context(|| format!("{}: cannot write the screenshot", path.display()))?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), w as u32, h as u32);
    encoder.set_color(png::ColorType::Rgba);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().with_context(|| format!("{}: cannot write PNG", path.display()))?;
    let bytes: Vec<u8> = image.pixels.iter().flat_map(|c| c.to_array()).collect();
    writer.write_image_data(&bytes).with_context(|| format!("{}: cannot write PNG", path.display()))?;
    let rect = rect.ok_or_else(|| anyhow!("the image was never drawn"))?;
    let r = [rect.min.x * ppp, rect.min.y * ppp, rect.max.x * ppp, rect.max.y * ppp].map(|v| v.round() as i64);
    let built = viewer.built.as_ref().ok_or_else(|| anyhow!("nothing rendered"))?;
    let latencies: Vec<f64> = viewer.timing.latencies.iter().map(|d| d.as_secs_f64() * 1e3).collect();
    let frame_ms: Vec<f64> = viewer.timing.frame_times.iter().map(|d| d.as_secs_f64() * 1e3).collect();
    let sidecar = serde_json::json!({
        "image_rect_px": r,
        "width": viewer.options.width,
        "height": viewer.options.height,
        "spp": viewer.tracer.as_ref().map_or(0, |t| t.samples_done()),
        "method": built.method.name(),
        "gate": built.gate.describe(),
        "bin": matches!(built.gate, Gate::Transient { .. }).then(|| viewer.gate.shown_bin()),
        "display": if built.gate.is_signed() { "signed luminance" } else { "rgb" },
        "exposure": 2f32.powf(viewer.options.exposure_ev),
        "curve": if viewer.options.log_curve { "log" } else { "linear" },
        "frames": viewer.frames,
        "gate_change_to_image_ms": latencies,
        "frame_ms": frame_ms,
        "adapter": viewer.ctx.adapter_description(),
    });
    let json_path = path.with_extension("json");
    std::fs::write(&json_path, serde_json::to_string_pretty(&sidecar)?)
        .with_context(|| format!("{}: cannot write", json_path.display()))?;
    Ok(())
}
