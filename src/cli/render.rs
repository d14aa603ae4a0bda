//! `gatetrace render` of images and sequences of frames: the options' checks, each frame's
//! settings and output, checkpoints (--checkpoint-every, --resume) and the report of each render.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, bail, ensure};
use gatetrace::capture;
use gatetrace::film::Gate;
use gatetrace::film::output::{OutputFormat, check_writable, write_film};
use gatetrace::film::preview::{PreviewSettings, write_preview};
use gatetrace::frames::{FramePlan, frame_path, frame_seed, is_frame_pattern, parse_frame_range, parse_time_range};
use gatetrace::gpu::GpuContext;
use gatetrace::integrator::checkpoint::{checkpoint_path, fingerprint, read_checkpoint, write_checkpoint};
use gatetrace::integrator::{
    Budget, LightStrategy, Method, RenderSettings, film_elements, render_metadata, render_resumable,
};
use gatetrace::scene::{PreparedScene, load_scene_with};

use super::args::{ImageArgs, OnOff, QueryTree, QueryWeights, RenderArgs, Switch};
use super::interrupt;
use super::report::{print_stats, print_warnings, progress_bar, say};

/// The scene with its camera's lens set by --aperture-radius and --focus-distance, where given
/// (each overrides the glTF camera node's extras; an aperture radius of 0 makes a pinhole).
fn with_lens_options(mut scene: gatetrace::scene::Scene, args: &ImageArgs) -> Result<gatetrace::scene::Scene> {
    scene
        .camera
        .override_lens(args.aperture_radius, args.focus_distance, "--focus-distance METRES")
        .with_context(|| format!("{}: --aperture-radius/--focus-distance", scene.source))?;
    Ok(scene)
}

/// `gatetrace render`: checks every option and frame before any work, then renders the image,
/// the frames of a sequence, a shard, or (module nlos) an NLOS capture.
pub fn run(mut args: RenderArgs) -> Result<()> {
    let scene_path = args.scene.clone().unwrap_or_else(|| PathBuf::from(super::DEFAULT_SCENE));
    let scene_settings = args.image.take_scene_settings(&scene_path)?;
    if args.spp.is_none() && args.time.is_none() {
        args.spp = scene_settings.spp;
    }
    let gate = Gate::parse(&args.gate).with_context(|| format!("--gate {}", args.gate))?;
    // A capture the scene file describes is rendered as one; --nlos overrides its scan.
    let file_capture = scene_settings.capture;
    let scan = args.nlos.or(file_capture.as_ref().map(|c| c.scan));
    // NLOS captures have defaults of their own (gatetrace::capture).
    let is_capture = scan.is_some();
    let choices = capture::CaptureChoices {
        method: args.method,
        connections_per_query: args.connections_per_query,
        reflection_weights: args.query_weights.map(|weights| weights == QueryWeights::Reflection),
        target_pilot: args.target_pilot,
        band_index: match args.band_index {
            OnOff::Auto => None,
            OnOff::On => Some(true),
            OnOff::Off => Some(false),
        },
    };
    let method = if is_capture { choices.method(&gate) } else { args.method.unwrap_or(Method::Path) };
    let budget = match (args.spp, args.time) {
        (_, Some(t)) => match Duration::try_from_secs_f64(t) {
            Ok(d) if t > 0.0 => Budget::Time(d),
            _ => bail!("--time {t}: give a positive number of seconds"),
        },
        (Some(0), _) => bail!("--spp must be at least 1"),
        (Some(n), None) => Budget::Samples(n),
        (None, None) => Budget::Samples(64),
    };
    let range = args.frame_range.as_deref().map(parse_frame_range).transpose().context("--frame-range")?;
    let gate_step = gatetrace::units::parse_length(&args.gate_step).context("--gate-step")?;
    let anim_time = args.anim_time.as_deref().map(parse_time_range).transpose().context("--anim-time")?;
    let plan = FramePlan::new(args.frames, gate_step, anim_time, range)?;
    let sequence = args.frames > 1 || args.frame_range.is_some();
    let stem = scene_path.file_stem().and_then(|s| s.to_str()).unwrap_or("render").to_owned();
    let out = args.out.clone().unwrap_or_else(|| {
        PathBuf::from(if let Some((i, n)) = args.shard {
            format!("{stem}.shard_{i}_of_{n}")
        } else if sequence {
            format!("{stem}_{{frame:04}}.exr")
        } else {
            format!("{stem}.exr")
        })
    });
    let pattern = out.to_string_lossy().into_owned();
    ensure!(
        !sequence || is_frame_pattern(&pattern),
        "--out {pattern}: a sequence of frames needs {{frame}} or {{frame:04}} in the output name, e.g. \
         frames/f_{{frame:04}}.npy"
    );
    let mut settings = RenderSettings {
        width: args.res.0,
        height: args.res.1,
        method,
        gate: gate.clone(),
        max_bounces: args.max_bounces,
        rr_depth: args.rr_depth,
        seed: args.seed,
        samples_per_pass: args.samples_per_pass,
        light_strategy: LightStrategy::Mis,
        stats: args.stats,
        debug_strategy: args.debug_strategy,
        binding_limit: None,
        connections_per_query: args
            .connections_per_query
            .unwrap_or(gatetrace::integrator::bidirectional::default_connections_per_query(method)),
        query: gatetrace::integrator::QuerySettings {
            split: args.query_split,
            bottom_nodes: args.query_bottom_nodes,
            reflection_weights: args.query_weights == Some(QueryWeights::Reflection),
            wide: args.query_tree == QueryTree::Wide,
            ..Default::default()
        },
        ellipsoid_guards: gatetrace::integrator::EllipsoidGuards {
            needle: args.needle_guard,
            length: args.length_guard,
        },
        nlos: None,
        target_pilot_spp: args.target_pilot.unwrap_or(0),
        camera_pilot_spp: args.camera_pilot,
        band_index: false,
        ellipsoidal_share: args.ellipsoidal_share,
        query_roulette: args.query_roulette,
        medium_connections: args.medium_connections == Switch::On,
        wave_bytes: None,
    };
    // A capture's own defaults, and its band index (`auto` is decided once the scene is loaded:
    // capture::prepare_capture).
    if is_capture {
        choices.apply(&mut settings);
    }
    if let Some(every) = args.checkpoint_every {
        ensure!(every.is_finite() && every >= 0.0, "--checkpoint-every {every}: give seconds, 0 or more");
    }
    if args.shard.is_some() {
        ensure!(
            matches!(budget, Budget::Samples(_)),
            "--shard needs --spp: a shard renders a slice of a known number of samples per pixel"
        );
        ensure!(
            method != Method::Auto,
            "--shard: --method auto chooses from timings, so shards could choose differently; choose path, direct or \
             ellipsoidal"
        );
        ensure!(
            !is_capture && !sequence && args.anim_time.is_none(),
            "--shard splits one image: it does not apply to NLOS captures (--nlos), --frames, --frame-range or \
             --anim-time"
        );
        ensure!(
            !args.resume && args.checkpoint_every.is_none(),
            "--shard keeps no checkpoint (--resume, --checkpoint-every): rerun an interrupted shard whole"
        );
    }
    if let Some(scan) = scan {
        ensure!(
            args.checkpoint_every.is_none() && !args.resume,
            "--checkpoint-every and --resume do not apply to NLOS captures (--nlos) yet: an interrupted capture writes \
             the samples traced so far (single and confocal scans) but keeps no checkpoint"
        );
        // --method auto is refused by CaptureRequest::check (in nlos::run).
        ensure!(
            args.aperture_radius.is_none() && args.focus_distance.is_none(),
            "--aperture-radius and --focus-distance set the camera's lens: an NLOS capture (--nlos) has no camera"
        );
        ensure!(
            !sequence && args.anim_time.is_none(),
            "an NLOS capture (--nlos, or one the scene file describes) has no frames: --frames, --frame-range and \
             --anim-time do not apply to it"
        );
        return super::nlos::run(&args, scan, file_capture.as_ref(), &scene_path, settings, budget);
    }
    // Every frame's settings and output, checked before any work.
    let mut frames = Vec::new();
    for frame in plan.frames() {
        let path = if is_frame_pattern(&pattern) { frame_path(&pattern, frame)? } else { out.clone() };
        if args.shard.is_none() {
            let format = OutputFormat::of(&path)?;
            ensure!(
                format == OutputFormat::Png || (args.preview_bin.is_none() && args.exposure.is_none()),
                "--preview-bin and --exposure apply to .png previews, not to {}",
                path.display()
            );
            if let Some(bin) = args.preview_bin {
                ensure!(bin < gate.bins(), "--preview-bin {bin}: gate {} has {} bin(s)", args.gate, gate.bins());
            }
            ensure!(args.exposure.is_none_or(f32::is_finite), "--exposure must be a finite number of EV");
        }
        let settings =
            RenderSettings { gate: plan.gate(&gate, frame)?, seed: frame_seed(args.seed, frame), ..settings.clone() };
        settings.check()?;
        film_elements(&settings)?;
        check_writable(&path, args.mkdir)?;
        frames.push((frame, path, settings));
    }

    // A static scene is loaded once; an animated one at every frame's time (checked first).
    let static_scene = match plan.anim_time {
        None => {
            let scene = with_lens_options(load_scene_with(&scene_path, &args.load_options(None))?, &args)?;
            print_warnings(&scene.warnings);
            Some(PreparedScene::new(scene)?)
        }
        Some(_) => {
            // Every frame's load warns alike: the first frame's says it once.
            let scene = with_lens_options(
                load_scene_with(&scene_path, &args.load_options(plan.anim_time(plan.range.0)))?,
                &args,
            )?;
            print_warnings(&scene.warnings);
            None
        }
    };
    let mut ctx = GpuContext::new()?;
    if args.profile {
        ctx.enable_profiling()?;
    }
    let bars = indicatif::MultiProgress::new();
    if let (Some(shard), Some(scene), Budget::Samples(total)) = (args.shard, &static_scene, budget) {
        let (_, path, settings) = &frames[0];
        // Every shard takes the camera pilot the whole render would, not one of its slice.
        let mut settings = settings.clone();
        if settings.camera_pilot_spp.is_none() {
            settings.camera_pilot_spp =
                Some(gatetrace::integrator::bidirectional::default_camera_pilot(&settings, budget));
        }
        return super::merge::render_shard(&ctx, scene, &scene_path, &args, shard, &settings, total, path, &bars);
    }
    // A sequence shows a bar over its frames above each frame's bar over passes.
    let frames_bar = sequence.then(|| {
        let bar = bars.add(indicatif::ProgressBar::new(frames.len() as u64));
        let style =
            indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} frames (ETA {eta})");
        bar.set_style(style.unwrap().progress_chars("=> "));
        bar
    });
    if args.resume && !sequence {
        let checkpoint = checkpoint_path(&frames[0].1);
        ensure!(
            checkpoint.exists(),
            "--resume: there is no checkpoint {} (renders write one when interrupted, or with --checkpoint-every)",
            checkpoint.display()
        );
    }
    for (frame, path, settings) in &frames {
        if let Some(signal) = interrupt::received() {
            return Err(interrupt::Interrupted { signal }.into());
        }
        let incomplete = checkpoint_path(path).exists();
        if sequence && path.exists() && !args.force && !incomplete {
            say(&bars, format!("frame {frame}: {} exists, skipped (--force renders it again)", path.display()))?;
        } else {
            let resume = args.resume && incomplete;
            if sequence && incomplete && !args.resume {
                say(
                    &bars,
                    format!(
                        "frame {frame}: {} was interrupted (a checkpoint lies beside it): rendered again from the \
                         start (--resume continues it)",
                        path.display()
                    ),
                )?;
            }
            let animated;
            let scene = match &static_scene {
                Some(scene) => scene,
                None => {
                    animated = PreparedScene::new(with_lens_options(
                        load_scene_with(&scene_path, &args.load_options(plan.anim_time(*frame)))?,
                        &args,
                    )?)?;
                    &animated
                }
            };
            let label = sequence.then(|| format!("frame {frame}/{}", plan.count - 1));
            let frame_info = (sequence || plan.anim_time.is_some()).then_some((*frame, &plan));
            let anim_time = plan.anim_time(*frame);
            let checkpoints = Checkpoints {
                every: args.checkpoint_every.map(Duration::from_secs_f64),
                resume,
                fingerprint: fingerprint(
                    &scene_path,
                    settings,
                    &[
                        ("camera", scene.scene.camera.describe()),
                        ("anim_time_s", anim_time.map_or("none".into(), |t| t.to_string())),
                    ],
                )?,
            };
            render_one(
                &ctx,
                scene,
                &scene_path,
                &args.gate,
                settings,
                budget,
                path,
                label,
                frame_info,
                &checkpoints,
                PreviewSettings { bin: args.preview_bin, exposure_ev: args.exposure },
                &bars,
            )?;
        }
        if let Some(bar) = &frames_bar {
            bar.inc(1);
        }
    }
    if let Some(bar) = frames_bar {
        bar.finish_and_clear();
    }
    if let Some(report) = ctx.profile_report()? {
        print!("{report}");
    }
    Ok(())
}

/// How a render keeps checkpoints (see --checkpoint-every and --resume).
struct Checkpoints {
    /// Save the state after the first pass this long after the last save.
    every: Option<Duration>,
    /// Continue from the checkpoint beside the output.
    resume: bool,
    /// What identifies the render (see `checkpoint::fingerprint`).
    fingerprint: std::collections::BTreeMap<String, String>,
}

/// Renders one image (or frame) and writes it with its metadata.
#[allow(clippy::too_many_arguments)]
fn render_one(
    ctx: &GpuContext,
    scene: &PreparedScene,
    scene_path: &Path,
    gate_spec: &str,
    settings: &RenderSettings,
    budget: Budget,
    out: &Path,
    label: Option<String>,
    frame: Option<(u32, &FramePlan)>,
    checkpoints: &Checkpoints,
    preview: PreviewSettings,
    bars: &indicatif::MultiProgress,
) -> Result<()> {
    let checkpoint = checkpoint_path(out);
    let resumed = if checkpoints.resume {
        let state = read_checkpoint(&checkpoint, &checkpoints.fingerprint)?;
        if let Budget::Samples(n) = budget {
            ensure!(
                n >= state.samples_in_film,
                "--resume: {} holds {} spp already; ask --spp {} or more",
                checkpoint.display(),
                state.samples_in_film,
                state.samples_in_film
            );
        }
        Some(state)
    } else {
        None
    };
    let bar = bars.add(progress_bar(budget));
    let prefix = label.as_deref().map(|l| format!("{l}: ")).unwrap_or_default();
    let mut last_save = Instant::now();
    let keep_state = checkpoints.every.is_some();
    let start = gatetrace::integrator::RenderStart { resume: resumed.as_ref(), skip_samples: 0, keep_state };
    let output = render_resumable(ctx, scene, settings, budget, start, |tracer, p| {
        match budget {
            Budget::Samples(_) => bar.set_position(p.spp),
            Budget::Time(_) => bar.set_position(p.rendering.as_millis() as u64),
        }
        let rate = (p.spp * (settings.width * settings.height) as u64) as f64 / p.elapsed.as_secs_f64().max(1e-9);
        bar.set_message(format!("{prefix}{} passes, {} spp, {:.2} Msamples/s", p.passes, p.spp, rate / 1e6));
        let stop = interrupt::received().is_some();
        if stop || checkpoints.every.is_some_and(|every| last_save.elapsed() >= every) {
            let mut state = tracer.save_state()?;
            state.rendering_seconds = p.rendering.as_secs_f64();
            write_checkpoint(&checkpoint, &checkpoints.fingerprint, &state)?;
            last_save = Instant::now();
        }
        Ok(if stop { ControlFlow::Break(()) } else { ControlFlow::Continue(()) })
    })?;
    bar.finish_and_clear();
    bars.suspend(|| {
        print_warnings(&output.truncated_traversals_warning());
        print_warnings(&output.budget_overrun_warning(budget));
    });

    let gate = &settings.gate;
    let film = &output.film;
    let secs = output.elapsed.as_secs_f64();
    let mut metadata = render_metadata(ctx, scene_path, gate_spec, settings, &output);
    metadata.push(("camera".into(), scene.scene.camera.describe().into()));
    if scene.scene.has_media() {
        let media: Vec<_> = scene
            .scene
            .media
            .iter()
            .map(|m| {
                let mut d = serde_json::json!({
                    "name": m.name, "sigma_t_per_m": m.sigma_t, "albedo": m.albedo.to_array(), "hg_g": m.g,
                });
                // A heterogeneous medium: sigma_t is the majorant, which the grid's values scale.
                if let Some(grid) = &m.grid {
                    d["grid_resolution"] = grid.resolution.to_vec().into();
                }
                d
            })
            .collect();
        metadata.push(("media".into(), media.into()));
        metadata.push(("camera_medium".into(), scene.scene.camera_medium.into()));
    }
    if let Some((index, plan)) = frame {
        metadata.push(("frame".into(), index.into()));
        metadata.push(("frames".into(), plan.count.into()));
        metadata.push(("gate_shift_m".into(), (plan.gate_step * index as f64).into()));
        if let Some(t) = plan.anim_time(index) {
            metadata.push(("anim_time_s".into(), t.into()));
        }
    }
    if let Some(state) = &resumed {
        metadata.push(("resumed_from_spp".into(), state.samples_in_film.into()));
    }
    let signal = interrupt::received().filter(|_| output.stopped_early);
    if let Some(signal) = signal {
        metadata.push(("interrupted_by".into(), interrupt::name(signal).into()));
        metadata.push((
            "requested".into(),
            match budget {
                Budget::Samples(n) => serde_json::json!({ "spp": n }),
                Budget::Time(t) => serde_json::json!({ "seconds": t.as_secs_f64() }),
            },
        ));
    }
    let black = gatetrace::integrator::black_image_warning(scene, settings, gate_spec, film);
    if let Some(warning) = &black {
        metadata.push(("warning".into(), warning.clone().into()));
        bars.suspend(|| eprintln!("warning: {warning}"));
    }
    let bin_ranges: Vec<(f64, f64)> = (0..gate.bins()).filter_map(|b| gate.bin_range(b)).collect();
    if OutputFormat::of(out)? == OutputFormat::Png {
        write_preview(out, film, &metadata, &bin_ranges, preview)?;
    } else {
        write_film(out, film, &metadata, &bin_ranges)?;
    }
    if let Some(signal) = signal {
        say(
            bars,
            format!(
                "{}: wrote {} with the {} spp traced so far, and {}; run the same command with --resume to continue",
                interrupt::name(signal),
                out.display(),
                film.spp,
                checkpoint.display()
            ),
        )?;
        return Err(interrupt::Interrupted { signal }.into());
    }
    if let Some(state) = &output.state {
        // The finished render's state, saved after its image: --resume with a larger --spp
        // extends it.
        write_checkpoint(&checkpoint, &checkpoints.fingerprint, state)?;
    } else if checkpoint.exists() {
        std::fs::remove_file(&checkpoint)
            .with_context(|| format!("{}: cannot remove the finished render's checkpoint", checkpoint.display()))?;
    }
    let mean = film.mean_rgb();
    say(
        bars,
        format!(
            "{}{}: {}x{} {} gate {} | {} spp{} in {:.2} s ({:.2} s rendering, {:.2} Msamples/s) on {} | mean RGB [{:.5}, {:.5}, {:.5}] -> {}",
            label.map(|l| format!("{l} ")).unwrap_or_default(),
            scene_path.file_name().map(|n| n.to_string_lossy()).unwrap_or_default(),
            settings.width,
            settings.height,
            match &output.choice {
                Some(choice) => format!("auto ({})", choice.chosen.name()),
                None => settings.method.name().to_owned(),
            },
            if frame.is_some_and(|(i, p)| p.gate_step != 0.0 && i > 0) {
                gate.describe()
            } else {
                gate_spec.to_owned()
            },
            film.spp,
            resumed.as_ref().map(|r| format!(" (resumed from {})", r.samples_in_film)).unwrap_or_default(),
            secs,
            output.rendering.as_secs_f64(),
            (film.spp * (settings.width * settings.height) as u64) as f64
                / output.rendering.as_secs_f64().max(1e-9)
                / 1e6,
            ctx.adapter_info.name,
            mean[0],
            mean[1],
            mean[2],
            out.display()
        ),
    )?;
    if let Some(choice) = &output.choice {
        say(
            bars,
            format!("auto chose {} (pilot {:.2} s): {}", choice.chosen.name(), choice.pilot_seconds, choice.reason),
        )?;
    }
    if let Some(allocation) = &output.allocation {
        say(bars, format!("combined (pilot {:.2} s): {}", allocation.pilot_seconds, allocation.reason))?;
    }
    if let Some(roulette) = output.roulette.as_ref().filter(|r| r.pilot_seconds > 0.0) {
        say(bars, format!("query roulette: {}", roulette.reason))?;
    }
    print_stats(settings, &output);
    Ok(())
}
