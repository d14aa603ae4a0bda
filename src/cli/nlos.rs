//! `gatetrace render --nlos`: non-line-of-sight captures. The options' defaults for captures,
//! the band index's automatic choice and the preparation of the hidden scene for shell
//! connections, one render per laser spot of the scan, and the capture's output with its
//! sensed points and laser spots.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, ensure};
use gatetrace::film::output::{OutputFormat, check_writable};
use gatetrace::frames::frame_seed;
use gatetrace::gpu::GpuContext;
use gatetrace::integrator::{Budget, RenderSettings, film_elements, render_metadata, render_resumable};
use gatetrace::nlos::{self, LaserAim, NlosCapture, Scan};
use gatetrace::scene::{LoadOptions, PreparedScene, load_gltf_with};

use super::args::{OnOff, RenderArgs};
use super::interrupt;
use super::render::load_options;
use super::report::{print_stats, progress_bar, say};

/// Renders an NLOS capture (`--nlos`): one render for a single or confocal scan, one per laser
/// spot for an exhaustive one; writes the transients with the sensed points and laser spots.
pub fn run(
    args: &RenderArgs,
    scan: gatetrace::nlos::Scan,
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
    ensure!(
        base.max_bounces >= 2,
        "--nlos: --max-bounces {} counts the laser spot and the sensed point, so it must be at least 2 (3: the \
         three-bounce paths spot -> hidden point -> sensed point)",
        base.max_bounces
    );
    ensure!(args.laser_grid.is_none() || scan == Scan::Exhaustive, "--laser-grid needs --nlos exhaustive");
    film_elements(&base)?;
    check_writable(&out, args.mkdir)?;
    let mut loaded = load_gltf_with(scene_path, &LoadOptions { capture: true, ..load_options(args, None) })?;
    let mut base = base;
    let hidden_triangles = loaded.triangles.len() - loaded.node(&args.relay_wall).map_or(0, |n| n.triangles.len());
    let band_index_declined = base.band_index
        && args.band_index == OnOff::Auto
        && hidden_triangles <= gatetrace::integrator::band_index::AUTO_MIN_TRIANGLES;
    if band_index_declined {
        base.band_index = false;
    }
    let origin = |given: Option<glam::Vec3>, node: &str, flag: &str| -> Result<glam::Vec3> {
        given.or_else(|| nlos::origin_from_nodes(&loaded, node)).with_context(|| {
            format!("{}: no node named `{node}` or `nlos_origin`: give {flag} X,Y,Z (m)", scene_path.display())
        })
    };
    let (sensor_origin, laser_origin) = (
        origin(args.sensor_origin, "sensor_origin", "--sensor-origin")?,
        origin(args.laser_origin, "laser_origin", "--laser-origin")?,
    );
    // Shell connections want the hidden scene's closed surfaces one-sided and its large
    // triangles cut into pieces (nlos::prepare_for_shells).
    let shells = match (base.band_index, &base.gate) {
        (true, gatetrace::film::Gate::Transient { width, .. }) if loaded.node(&args.relay_wall).is_some() => Some(
            nlos::prepare_for_shells(&mut loaded, &args.relay_wall, *width, &[sensor_origin, laser_origin])
                .with_context(|| scene_path.display().to_string())?,
        ),
        _ => None,
    };
    let scene = PreparedScene::new(loaded)?;
    let capture = NlosCapture {
        relay_wall: args.relay_wall.clone(),
        sensor_origin,
        laser_origin,
        aim: if scan == Scan::Confocal { LaserAim::Confocal } else { LaserAim::Spot(args.laser_spot) },
        laser_power: args.laser_power,
        count_first_and_last: args.count_first_last,
    };
    nlos::check_capture(&scene.scene, &capture)?;
    let (w, h) = (base.width, base.height);
    let (laser_w, laser_h) = match scan {
        Scan::Single => (1, 1),
        Scan::Confocal => (w, h),
        Scan::Exhaustive => args.laser_grid.unwrap_or((w, h)),
    };
    let aims: Vec<LaserAim> = match scan {
        Scan::Exhaustive => (0..laser_h)
            .flat_map(|j| (0..laser_w).map(move |i| LaserAim::Spot(nlos::cell_uv(i, j, laser_w, laser_h))))
            .collect(),
        _ => vec![capture.aim],
    };
    let mut ctx = GpuContext::new()?;
    if args.profile {
        ctx.enable_profiling()?;
    }
    let bars = indicatif::MultiProgress::new();
    let pixels = (w * h) as usize;
    let (mut data, mut spots, mut sensed) = (Vec::new(), Vec::new(), Vec::new());
    let mut last = None;
    for (k, &aim) in aims.iter().enumerate() {
        let capture = NlosCapture { aim, ..capture.clone() };
        let (points, warnings) = nlos::wall_points_and_warnings(&scene, &capture, w, h)?;
        if k == 0 {
            for warning in warnings {
                eprintln!("warning: {warning}");
            }
        }
        sensed = points[..pixels].to_vec();
        spots.extend_from_slice(if scan == Scan::Confocal { &points[pixels..] } else { &points[pixels..pixels + 1] });
        let seed = if aims.len() > 1 { frame_seed(base.seed, k as u32) } else { base.seed };
        let settings = RenderSettings { nlos: Some(capture), seed, ..base.clone() };
        let bar = bars.add(progress_bar(budget));
        let label = if aims.len() > 1 { format!("laser spot {}/{}: ", k + 1, aims.len()) } else { String::new() };
        // The band index is built before the first sample (a minute on a large mesh and grid
        // on lavapipe): say so until the first pass reports.
        if settings.band_index {
            bar.set_message(format!("{label}building the band index"));
        }
        let output = render_resumable(&ctx, &scene, &settings, budget, Default::default(), |_, p| {
            match budget {
                Budget::Samples(_) => bar.set_position(p.spp),
                Budget::Time(_) => bar.set_position(p.rendering.as_millis() as u64),
            }
            bar.set_message(format!("{label}{} spp", p.spp));
            Ok(if interrupt::received().is_some() { ControlFlow::Break(()) } else { ControlFlow::Continue(()) })
        })?;
        bar.finish_and_clear();
        if let Some(signal) = interrupt::received() {
            if aims.len() > 1 {
                eprintln!(
                    "{}: stopped at laser spot {} of {}: an exhaustive capture is written only whole, so {} was not \
                     written",
                    interrupt::name(signal),
                    k + 1,
                    aims.len(),
                    out.display()
                );
                return Err(interrupt::Interrupted { signal }.into());
            }
        }
        data.extend_from_slice(&output.film.data);
        last = Some((settings, output));
    }
    let (settings, output) = last.expect("at least one laser spot");
    if let Some(warning) = output.unvisited_bins_warning() {
        eprintln!("warning: {warning}");
    }
    let mut metadata = render_metadata(&ctx, scene_path, &args.gate, &settings, &output);
    metadata.retain(|(k, _)| k != "units");
    metadata.push((
        "units".into(),
        "bin-integrated radiance (W m^-2 sr^-1) leaving each sensed point towards the sensor origin; lengths are \
         optical path in metres from the laser spot to the sensed point (plus the first and last segments when \
         count_first_and_last)"
            .into(),
    ));
    if band_index_declined {
        metadata.push((
            "band_index".into(),
            format!("off (auto): the scene's {hidden_triangles} triangles besides the relay wall are searched whole by every query")
                .into(),
        ));
    }
    if let Some(r) = shells {
        metadata.push((
            "shell_preparation".into(),
            serde_json::json!({
                "closed_meshes_made_one_sided": r.closed_meshes,
                "triangles_cut_into_pieces": r.refined,
                "triangles": r.triangles,
            }),
        ));
    }
    let signal = interrupt::received().filter(|_| output.stopped_early);
    if let Some(signal) = signal {
        metadata.push(("interrupted_by".into(), interrupt::name(signal).into()));
    }
    let extras = nlos::capture_record(&scene, &capture, scan, &sensed, w, &spots, laser_w);
    let film = &output.film;
    let bin_ranges: Vec<(f64, f64)> = (0..settings.gate.bins()).filter_map(|b| settings.gate.bin_range(b)).collect();
    if scan == Scan::Exhaustive {
        let bins = film.bins as usize;
        let mut shape = vec![laser_h as usize, laser_w as usize, h as usize, w as usize];
        if bins > 1 {
            shape.push(bins);
        }
        shape.push(3);
        ensure!(
            data.iter().all(|v| v.is_finite()),
            "refusing to write {}: the capture holds non-finite values",
            out.display()
        );
        gatetrace::film::output::write_npy_f32(&out, &shape, &data)?;
        gatetrace::film::output::write_sidecar(&out, &metadata, &extras)?;
    } else {
        gatetrace::film::output::write_film_with(&out, film, &metadata, &bin_ranges, &extras)?;
    }
    let total: f64 = data.iter().map(|&v| v as f64).sum();
    say(
        &bars,
        format!(
            "{}: NLOS {} capture, {}x{} sensed points, {} laser spot(s), gate {} | {} spp, {:.2} s rendering{} on {} | \
         total {total:.6e} -> {}",
            scene_path.file_name().map(|n| n.to_string_lossy()).unwrap_or_default(),
            scan.name(),
            w,
            h,
            spots.len(),
            args.gate,
            film.spp,
            output.rendering.as_secs_f64(),
            if aims.len() > 1 { " per laser spot" } else { "" },
            ctx.adapter_info.name,
            out.display()
        ),
    )?;
    print_stats(&settings, &output);
    if let Some(signal) = signal {
        return Err(interrupt::Interrupted { signal }.into());
    }
    if let Some(report) = ctx.profile_report()? {
        print!("{report}");
    }
    Ok(())
}
