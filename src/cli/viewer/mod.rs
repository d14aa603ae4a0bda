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
//!
//! This module holds the window's options, state and start; `gate` the gate's controls, `state`
//! the rendering behind the window, `panels` the window's controls, plot and screenshots.

mod gate;
mod panels;
mod state;

use std::path::PathBuf;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, anyhow};
use eframe::egui;

use gatetrace::film::Gate;
use gatetrace::gpu::{GpuContext, Kernel};
use gatetrace::integrator::{Integrator, Method, PassSizer, RenderSettings};
use gatetrace::scene::{LoadOptions, PreparedScene, load_scene_with};

use gate::GateControls;

/// Settings of `gatetrace view` (initial values of the controls and the screenshot mode).
#[derive(Clone, Debug)]
pub struct ViewOptions {
    /// Scene file (glTF 2.0 or Mitsuba 3 XML).
    pub scene: PathBuf,
    /// See [`gatetrace::scene::LoadOptions::allow_unsupported_materials`].
    pub allow_unsupported_materials: bool,
    /// See [`gatetrace::scene::LoadOptions::parameters`].
    pub parameters: Vec<(String, String)>,
    /// See [`gatetrace::scene::LoadOptions::fog`].
    pub fog: Option<gatetrace::scene::MediumDesc>,
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
    let load = LoadOptions {
        allow_unsupported_materials: options.allow_unsupported_materials,
        parameters: options.parameters.clone(),
        fog: options.fog.clone(),
        ..Default::default()
    };
    let mut scene = load_scene_with(&options.scene, &load)?;
    crate::cli::report::print_warnings(&scene.warnings);
    if options.aperture_radius.is_some() || options.focus_distance.is_some() {
        scene
            .camera
            .override_lens(options.aperture_radius, options.focus_distance, "--focus-distance METRES")
            .with_context(|| format!("{}: --aperture-radius/--focus-distance", scene.source))?;
    }
    let scene = PreparedScene::new(scene)?;
    let ctx = GpuContext::new()?;
    let shortest = scene.path_length_bounds(options.max_bounces.max(1)).0;
    let longest = scene.finite_longest_path(options.max_bounces.max(1));
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

impl eframe::App for Viewer<'_> {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        if let Err(e) = self.frame(ui) {
            *self.failure = Some(e);
            ui.ctx().send_viewport_cmd(egui::ViewportCommand::Close);
        }
    }
}
