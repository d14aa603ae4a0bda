//! Shards of a render: `gatetrace render --shard I/N` renders a slice of each pixel's samples
//! and writes its sums; `gatetrace merge` adds the shards' sums into the image of the unsplit
//! render, bit for bit.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use anyhow::{Result, bail, ensure};
use gatetrace::film::output::{OutputFormat, check_writable, write_film};
use gatetrace::gpu::GpuContext;
use gatetrace::integrator::checkpoint::{
    check_fingerprint, fingerprint, merge_states, read_state_file, write_state_file,
};
use gatetrace::integrator::{Budget, RenderSettings, render_metadata, render_resumable};
use gatetrace::scene::PreparedScene;

use super::args::RenderArgs;
use super::interrupt;
use super::report::{print_stats, print_warnings, progress_bar, say};

#[derive(clap::Args)]
pub struct MergeArgs {
    /// The shard files, one per shard index 0 .. N-1 (any order).
    #[arg(required = true)]
    parts: Vec<PathBuf>,
    /// Output file: .exr or .npy (with a .json sidecar), as render writes them.
    #[arg(long, short)]
    out: PathBuf,
    /// Create the output's directory when it does not exist (without this, a missing directory
    /// is an error).
    #[arg(long)]
    mkdir: bool,
}

/// Renders shard `index` of `count` of the image: samples floor(index total / count) to
/// floor((index + 1) total / count) of each pixel, written to `out` as a state file with the
/// image's metadata for `gatetrace merge`.
#[allow(clippy::too_many_arguments)]
pub fn render_shard(
    ctx: &GpuContext,
    scene: &PreparedScene,
    scene_path: &Path,
    args: &RenderArgs,
    (index, count): (u32, u32),
    settings: &RenderSettings,
    total: u64,
    out: &Path,
    bars: &indicatif::MultiProgress,
) -> Result<()> {
    let (first, end) = (total * index as u64 / count as u64, total * (index as u64 + 1) / count as u64);
    let fingerprint = fingerprint(
        scene_path,
        settings,
        &[("camera", scene.scene.camera.describe()), ("shards", count.to_string()), ("spp", total.to_string())],
    )?;
    let bar = bars.add(progress_bar(Budget::Samples(end - first)));
    let start = gatetrace::integrator::RenderStart { resume: None, skip_samples: first, keep_state: true };
    let output = render_resumable(ctx, scene, settings, Budget::Samples(end - first), start, |_, p| {
        bar.set_position(p.spp);
        bar.set_message(format!("shard {index}/{count}: {} spp", p.spp));
        Ok(if interrupt::received().is_some() { ControlFlow::Break(()) } else { ControlFlow::Continue(()) })
    })?;
    bar.finish_and_clear();
    print_warnings(&output.truncated_traversals_warning());
    if let Some(signal) = interrupt::received().filter(|_| output.stopped_early) {
        eprintln!(
            "{}: shard {index}/{count} stopped; {} was not written (rerun the shard)",
            interrupt::name(signal),
            out.display()
        );
        return Err(interrupt::Interrupted { signal }.into());
    }
    let state = output.state.as_ref().expect("the render keeps its state");
    let mut metadata = render_metadata(ctx, scene_path, &args.gate, settings, &output);
    metadata.push(("camera".into(), scene.scene.camera.describe().into()));
    let gate = &settings.gate;
    let bin_ranges: Vec<(f64, f64)> = (0..gate.bins()).filter_map(|b| gate.bin_range(b)).collect();
    let mut extra = serde_json::Map::new();
    extra.insert("part".into(), index.into());
    extra.insert("metadata".into(), serde_json::json!(metadata));
    extra.insert("bin_ranges".into(), serde_json::json!(bin_ranges));
    write_state_file(out, &fingerprint, state, extra)?;
    say(
        bars,
        format!(
            "shard {index}/{count}: samples {first}..{end} of {total} per pixel, {:.2} s rendering on {} -> {} (gatetrace \
             merge combines the {count} shards)",
            output.rendering.as_secs_f64(),
            ctx.adapter_info.name,
            out.display()
        ),
    )?;
    print_stats(settings, &output);
    Ok(())
}

/// `gatetrace merge`: adds the shards' sums and writes the unsplit render's image.
pub fn run(args: MergeArgs) -> Result<()> {
    OutputFormat::of(&args.out)?;
    check_writable(&args.out, args.mkdir)?;
    let mut parts = Vec::new();
    for path in &args.parts {
        parts.push((path, read_state_file(path)?));
    }
    let (first_path, (first_fingerprint, _, first_header)) = &parts[0];
    let not_a_shard =
        |path: &Path| anyhow::anyhow!("{}: not a shard (gatetrace render --shard I/N writes them)", path.display());
    let count: u32 =
        first_fingerprint.get("shards").and_then(|n| n.parse().ok()).ok_or_else(|| not_a_shard(first_path))?;
    let mut by_index: Vec<Option<usize>> = vec![None; count as usize];
    for (k, (path, (fingerprint, _, header))) in parts.iter().enumerate() {
        let problem = format!("not a shard of the render {} belongs to", first_path.display());
        check_fingerprint(path, &problem, fingerprint, first_fingerprint)?;
        let index = header["part"].as_u64().filter(|&i| i < count as u64).ok_or_else(|| not_a_shard(path))? as usize;
        if let Some(other) = by_index[index] {
            bail!("{} and {} are both shard {index}/{count}", parts[other].0.display(), path.display());
        }
        by_index[index] = Some(k);
    }
    let missing: Vec<String> =
        by_index.iter().enumerate().filter(|(_, k)| k.is_none()).map(|(i, _)| i.to_string()).collect();
    ensure!(missing.is_empty(), "shards {} of {count} are missing", missing.join(", "));
    let order: Vec<usize> = by_index.into_iter().flatten().collect();
    let states: Vec<_> = order.iter().map(|&k| parts[k].1.1.clone()).collect();
    let names: Vec<String> = order.iter().map(|&k| parts[k].0.display().to_string()).collect();
    let merged = merge_states(&states, &names)?;
    let film = gatetrace::integrator::wavefront::film_of_state(&merged)?;
    let mut metadata: gatetrace::film::output::Metadata =
        serde_json::from_value(first_header["metadata"].clone()).map_err(|_| not_a_shard(first_path))?;
    let bin_ranges: Vec<(f64, f64)> =
        serde_json::from_value(first_header["bin_ranges"].clone()).map_err(|_| not_a_shard(first_path))?;
    for (key, value) in metadata.iter_mut() {
        match key.as_str() {
            "spp" => *value = merged.samples_in_film.into(),
            "rendering_seconds" => *value = gatetrace::integrator::milli(merged.rendering_seconds),
            // Shards run side by side: their wall clocks do not add up to one.
            "elapsed_seconds" => *value = serde_json::Value::Null,
            _ => {}
        }
    }
    metadata.push(("shards".into(), count.into()));
    write_film(&args.out, &film, &metadata, &bin_ranges)?;
    let mean = film.mean_rgb();
    println!(
        "merged {count} shards: {}x{}, {} spp, {:.2} s rendering in all | mean RGB [{:.5}, {:.5}, {:.5}] -> {}",
        film.width,
        film.height,
        film.spp,
        merged.rendering_seconds,
        mean[0],
        mean[1],
        mean[2],
        args.out.display()
    );
    Ok(())
}
