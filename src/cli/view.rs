//! `gatetrace view`: its options and their checks; the window is module viewer.

use std::path::PathBuf;

use anyhow::{Context as _, Result, ensure};
use gatetrace::film::Gate;
use gatetrace::integrator::Method;

use super::args::ImageArgs;
use super::parse::{MethodParser, parse_pixel};
use super::viewer::{ViewOptions, run_viewer};

#[derive(clap::Args)]
pub struct ViewArgs {
    #[command(flatten)]
    pub image: ImageArgs,
    /// Sampling method at start; switchable in the window.
    #[arg(long, default_value = "path", value_parser = MethodParser::VIEW)]
    method: Method,
    /// Transient gates: the bin shown at start (0 to BINS - 1); the window's slider moves it.
    #[arg(long, default_value_t = 0, value_name = "BIN")]
    bin: u32,
    /// Exposure in stops (the radiance is multiplied by 2^EV before the tone curve); by default
    /// set from the first image (its 99th percentile shows as white).
    #[arg(long, allow_hyphen_values = true, value_name = "EV")]
    exposure: Option<f32>,
    /// Start with the logarithmic tone curve (4 decades) instead of the linear one.
    #[arg(long)]
    log: bool,
    /// Show the time profile of pixel X,Y (0-based, row 0 at the top) from the start, as if
    /// clicked.
    #[arg(long, value_name = "X,Y", value_parser = parse_pixel)]
    profile_pixel: Option<(u32, u32)>,
    /// Save the window's pixels to this PNG after --after-frames frames and exit (with FILE.json
    /// beside it: the image's rectangle, samples per pixel, gate, bin shown, display, timings).
    /// For tests and figures.
    #[arg(long, value_name = "FILE.png")]
    screenshot: Option<PathBuf>,
    /// Frames to render before --screenshot.
    #[arg(long, default_value_t = 30, value_name = "N")]
    after_frames: u32,
    /// With --screenshot: move the gate by D every 10 frames (metres of optical path, or with a
    /// mm/ps/ns suffix; a transient gate's shown bin moves by D / WIDTH bins, rounded, a CW
    /// gate's phase by -360 f D / c degrees), and record the time from each move to its first
    /// image.
    #[arg(long, value_name = "D", allow_hyphen_values = true)]
    scrub_step: Option<String>,
}

/// `gatetrace view`: checks the options, then opens the window.
pub fn run(mut args: ViewArgs) -> Result<()> {
    let scene = args.image.scene.clone().unwrap_or_else(|| PathBuf::from(super::DEFAULT_SCENE));
    // The viewer renders progressively: a scene's sample count does not apply.
    args.image.take_scene_settings(&scene)?;
    let image = &args.image;
    let gate = Gate::parse(&image.gate).with_context(|| format!("--gate {}", image.gate))?;
    match gate {
        Gate::Transient { bins, .. } => {
            ensure!(args.bin < bins, "--bin {}: the transient gate {} has bins 0 to {}", args.bin, image.gate, bins - 1)
        }
        _ => ensure!(args.bin == 0, "--bin {} applies to transient gates only (--gate {})", args.bin, image.gate),
    }
    if args.screenshot.is_some() {
        ensure!(args.after_frames >= 1, "--after-frames must be at least 1");
    }
    let scrub_step =
        args.scrub_step.as_deref().map(gatetrace::units::parse_length).transpose().context("--scrub-step")?;
    ensure!(scrub_step.is_none() || args.screenshot.is_some(), "--scrub-step needs --screenshot");
    run_viewer(ViewOptions {
        scene,
        allow_unsupported_materials: image.allow_unsupported_materials,
        parameters: image.define.clone(),
        fog: image.fog.clone(),
        width: image.res.0,
        height: image.res.1,
        method: args.method,
        gate,
        bin: args.bin,
        max_bounces: image.max_bounces,
        rr_depth: image.rr_depth,
        aperture_radius: image.aperture_radius,
        focus_distance: image.focus_distance,
        exposure_ev: args.exposure.unwrap_or(0.0),
        auto_exposure: args.exposure.is_none(),
        log_curve: args.log,
        screenshot: args.screenshot,
        after_frames: args.after_frames,
        scrub_step,
        profile_pixel: args.profile_pixel,
        seed: image.seed,
    })
}
