//! `gatetrace render --nlos`: the options of a capture turned into the library's request
//! (gatetrace::capture renders it), the progress bars of its renders, what a signal does
//! to a capture, and the report.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use anyhow::{Result, ensure};
use gatetrace::capture::{CaptureOptions, CaptureProgress, CaptureRequest, prepare_capture, render_capture};
use gatetrace::film::output::{OutputFormat, check_writable};
use gatetrace::gpu::GpuContext;
use gatetrace::integrator::{Budget, Progress, RenderSettings, film_elements};
use gatetrace::nlos::Scan;
use gatetrace::scene::SceneCapture;

use super::args::{OnOff, RenderArgs};
use super::interrupt;
use super::report::{print_stats, print_warnings, progress_bar, say};

/// Renders an NLOS capture (`--nlos`, or the one a Mitsuba scene describes: `file`, whose
/// settings the command line's options override) and writes its transients with the sensed
/// points and laser spots.
pub fn run(
    args: &RenderArgs,
    scan: Scan,
    file: Option<&SceneCapture>,
    scene_path: &Path,
    base: RenderSettings,
    budget: Budget,
) -> Result<()> {
    let stem = scene_path.file_stem().and_then(|s| s.to_str()).unwrap_or("render");
    let out = args.out.clone().unwrap_or_else(|| PathBuf::from(format!("{stem}_nlos.npy")));
    let format = OutputFormat::of(&out)?;
    ensure!(
        scan != Scan::Exhaustive || format == OutputFormat::Npy,
        "--out {}: an exhaustive capture is written as NPY [laser_y, laser_x, grid_y, grid_x, T, 3]; name a .npy file",
        out.display()
    );
    // The file's capture, with the options the command line gave over it.
    let given = |id: &str| args.was_given(id);
    let options = CaptureOptions {
        relay_wall: given("relay_wall").then(|| args.relay_wall.clone()),
        sensor_origin: args.sensor_origin,
        laser_origin: args.laser_origin,
        laser_spot: given("laser_spot").then_some(args.laser_spot),
        laser_grid: args.laser_grid,
        laser_power: given("laser_power").then_some(args.laser_power),
        count_first_and_last: args.count_first_last,
        band_index_auto: args.band_index == OnOff::Auto,
    };
    let request = CaptureRequest::new(scan, file, options);
    request.check(&base)?;
    film_elements(&base)?;
    check_writable(&out, args.mkdir)?;
    let prepared = prepare_capture(scene_path, args.load_options(None), &request, base, budget)?;
    print_warnings(&prepared.scene.scene.warnings);
    let mut ctx = GpuContext::new()?;
    if args.profile {
        ctx.enable_profiling()?;
    }
    let bars = indicatif::MultiProgress::new();
    let mut progress = Bars { bars: &bars, budget, out: &out, bar: None, label: String::new(), stopped_by: None };
    let Some(capture) = render_capture(&ctx, &prepared, budget, &mut progress)? else {
        let signal = progress.stopped_by.expect("only a signal stops a capture");
        return Err(interrupt::Interrupted { signal }.into());
    };
    let output = &capture.output;
    print_warnings(&output.unvisited_bins_warning());
    let mut metadata = capture.metadata(&ctx, scene_path, &args.gate, &prepared);
    let signal = interrupt::received().filter(|_| output.stopped_early);
    if let Some(signal) = signal {
        metadata.push(("interrupted_by".into(), interrupt::name(signal).into()));
    }
    capture.write(&out, &prepared, &metadata)?;
    let film = &output.film;
    let total: f64 = capture.data.iter().map(|&v| v as f64).sum();
    say(
        &bars,
        format!(
            "{}: NLOS {} capture, {}x{} sensed points, {} laser spot(s), gate {} | {} spp, {:.2} s rendering{} on {} | \
         total {total:.6e} -> {}",
            scene_path.file_name().map(|n| n.to_string_lossy()).unwrap_or_default(),
            scan.name(),
            capture.settings.width,
            capture.settings.height,
            capture.spots.len(),
            args.gate,
            film.spp,
            output.rendering.as_secs_f64(),
            if prepared.aims.len() > 1 { " per laser spot" } else { "" },
            ctx.adapter_info.name,
            out.display()
        ),
    )?;
    print_stats(&capture.settings, output);
    if let Some(signal) = signal {
        return Err(interrupt::Interrupted { signal }.into());
    }
    if let Some(report) = ctx.profile_report()? {
        print!("{report}");
    }
    Ok(())
}

/// A capture's progress: a bar per render, and the first signal stops it. A single or confocal
/// capture then writes the samples traced so far; an exhaustive one, written only whole, stops
/// after the render in flight without writing.
struct Bars<'a> {
    bars: &'a indicatif::MultiProgress,
    budget: Budget,
    out: &'a Path,
    /// The bar of the render in flight.
    bar: Option<indicatif::ProgressBar>,
    /// Which laser spot the bar's render lights.
    label: String,
    /// The signal that stopped the capture between renders.
    stopped_by: Option<i32>,
}

impl CaptureProgress for Bars<'_> {
    fn warning(&mut self, warning: &str) {
        eprintln!("warning: {warning}");
    }

    fn render_started(&mut self, k: usize, count: usize, settings: &RenderSettings) {
        let bar = self.bars.add(progress_bar(self.budget));
        self.label = if count > 1 { format!("laser spot {}/{}: ", k + 1, count) } else { String::new() };
        // The band index is built before the first sample (a minute on a large mesh and grid
        // on lavapipe): say so until the first pass reports.
        if settings.band_index {
            bar.set_message(format!("{}building the band index", self.label));
        }
        self.bar = Some(bar);
    }

    fn pass(&mut self, p: Progress) -> ControlFlow<()> {
        if let Some(bar) = &self.bar {
            match self.budget {
                Budget::Samples(_) => bar.set_position(p.spp),
                Budget::Time(_) => bar.set_position(p.rendering.as_millis() as u64),
            }
            bar.set_message(format!("{}{} spp", self.label, p.spp));
        }
        if interrupt::received().is_some() { ControlFlow::Break(()) } else { ControlFlow::Continue(()) }
    }

    fn render_ended(&mut self, k: usize, count: usize) -> ControlFlow<()> {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
        match interrupt::received() {
            Some(signal) if count > 1 => {
                eprintln!(
                    "{}: stopped at laser spot {} of {}: an exhaustive capture is written only whole, so {} was not \
                     written",
                    interrupt::name(signal),
                    k + 1,
                    count,
                    self.out.display()
                );
                self.stopped_by = Some(signal);
                ControlFlow::Break(())
            }
            _ => ControlFlow::Continue(()),
        }
    }
}
