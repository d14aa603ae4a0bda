//! `gatetrace equal-time`: several methods rendered for the same wall time each, and their mean
//! squared error against a long reference render.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context as _, Result, ensure};

use gatetrace::film::Gate;
use gatetrace::gpu::GpuContext;
use gatetrace::integrator::{Method, RenderSettings};
use gatetrace::scene::PreparedScene;

use super::bench::{Variant, parse_variant};
use super::parse::parse_resolution;

#[derive(clap::Args)]
pub struct EqualTimeArgs {
    /// Scenes (glTF 2.0 or Mitsuba 3 XML), each compared separately; the Cornell box when omitted.
    scenes: Vec<PathBuf>,
    /// Methods to compare, comma-separated: path, direct, ellipsoidal, combined, auto, and
    /// ellipsoidal (or auto, for its ellipsoidal candidate) with options after colons: K (render
    /// --connections-per-query), exhaustive (render --query-split 0), split=R, bottom=N,
    /// reflection or arcs (render --query-weights), wide (render --query-tree wide) or
    /// roulette=P (render --query-roulette), e.g. ellipsoidal:4:exhaustive;
    /// combined:roulette=P; and path:medium-connections=on (render --medium-connections on).
    #[arg(long, value_delimiter = ',', default_value = "path,direct", value_parser = parse_variant)]
    methods: Vec<Variant>,
    /// Gates to compare at, separated by ; (same syntax as render --gate).
    #[arg(long, default_value = "none;box:3.14..3.1425")]
    gates: String,
    /// Animation time (seconds of the scene's clock) at which animated scenes are compared, as
    /// render --anim-time poses them; without it, as the file poses them.
    #[arg(long, value_name = "SECONDS")]
    anim_time: Option<f64>,
    /// Seconds of rendering per method, gate and repeat (kernel builds excluded).
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Renders per method and gate; repeat r of every method renders from the same seed, and
    /// every method's repeat r runs before any repeat r + 1.
    #[arg(long, default_value_t = 3)]
    repeats: u32,
    /// Method of the reference images (same syntax as --methods).
    #[arg(long, default_value = "direct", value_parser = parse_variant)]
    reference_method: Variant,
    /// Seconds of rendering of each gate's reference.
    #[arg(long, default_value_t = 120.0)]
    reference_seconds: f64,
    /// Image size in pixels, WIDTHxHEIGHT.
    #[arg(long, default_value = "64x64", value_parser = parse_resolution)]
    res: (u32, u32),
    /// Maximum number of scattering vertices.
    #[arg(long, default_value_t = 5)]
    max_bounces: u32,
    /// Write one row per render to this CSV file (scene, triangles, gate, method, repeat,
    /// seconds, spp, MSE, relative MSE, the reference's noise, for ellipsoidal the loop
    /// iterations and triangles tested per ellipsoid query, and what the pilots chose: auto's
    /// method, what combined traced, the query roulette).
    #[arg(long)]
    csv: Option<PathBuf>,
}

/// `gatetrace equal-time`.
pub fn run(args: EqualTimeArgs) -> Result<()> {
    let scenes = if args.scenes.is_empty() { vec![PathBuf::from(super::DEFAULT_SCENE)] } else { args.scenes.clone() };
    let gates =
        args.gates.split(';').map(|g| Ok((g.trim().to_owned(), Gate::parse(g.trim())?))).collect::<Result<Vec<_>>>()?;
    ensure!(args.seconds > 0.0 && args.reference_seconds > 0.0, "--seconds and --reference-seconds must be positive");
    ensure!(args.repeats >= 1, "--repeats must be at least 1");
    let settings = EqualTimeSettings {
        methods: args.methods,
        gates,
        seconds: args.seconds,
        repeats: args.repeats,
        reference: args.reference_method,
        reference_seconds: args.reference_seconds,
        base: RenderSettings {
            width: args.res.0,
            height: args.res.1,
            max_bounces: args.max_bounces,
            ..Default::default()
        },
        anim_time: args.anim_time,
        csv: args.csv,
    };
    run_equal_time(&scenes, &settings)
}

/// Settings of an equal-time comparison (`gatetrace equal-time`).
pub struct EqualTimeSettings {
    /// Methods compared, each rendered for the same wall time.
    pub methods: Vec<Variant>,
    /// Gates, each compared separately.
    pub gates: Vec<(String, Gate)>,
    /// Rendering time per method, gate and repeat (s), setup excluded.
    pub seconds: f64,
    /// Renders per method and gate, repeat r of each from the same seed (the MSE is their mean).
    pub repeats: u32,
    /// Method of the reference images.
    pub reference: Variant,
    /// Rendering time of each gate's reference (s), in 8 independent batches.
    pub reference_seconds: f64,
    /// Image size and bounces shared by all renders.
    pub base: RenderSettings,
    /// CSV file for the results.
    pub csv: Option<std::path::PathBuf>,
    /// Animation time (s) at which animated scenes are posed; None: as the file poses them.
    pub anim_time: Option<f64>,
}

/// A film rendered for `seconds` as `render --time` renders it: passes sized to end on time,
/// after a warm-up pass (kernel builds, upload and the device's first compilation excluded;
/// `auto`'s pilot included); returns the film, the seconds actually spent and what its pilots
/// chose, in words (empty where none ran): for `auto` the method, for `combined` what it traced
/// (`both halves`, `direct alone`, `ellipsoidal alone`) and the query roulette where it applies,
/// for `ellipsoidal` the roulette.
fn render_for(
    ctx: &GpuContext,
    scene: &PreparedScene,
    settings: &RenderSettings,
    seconds: f64,
) -> Result<(gatetrace::film::Film, f64, String)> {
    let budget = gatetrace::integrator::Budget::Time(Duration::from_secs_f64(seconds));
    let output = gatetrace::integrator::render(ctx, scene, settings, budget, |_| {})?;
    super::report::print_warnings(&output.truncated_traversals_warning());
    let roulette = output.roulette.as_ref().map(|r| format!("roulette {}", r.probability));
    let chosen = match (&output.choice, &output.allocation, roulette) {
        (Some(c), _, None) => c.chosen.name().to_string(),
        (Some(c), _, Some(r)) => format!("{} {r}", c.chosen.name()),
        (None, Some(a), None) => a.renders().to_string(),
        (None, Some(a), Some(r)) => format!("{} {r}", a.renders()),
        (None, None, r) => r.unwrap_or_default(),
    };
    Ok((output.film, output.rendering.as_secs_f64(), chosen))
}

/// Work of one ellipsoid query: (loop iterations, triangles tested), from a short render with
/// `--stats` (None for methods without queries).
fn query_cost(ctx: &GpuContext, scene: &PreparedScene, settings: &RenderSettings) -> Result<Option<(f64, f64)>> {
    if settings.method != Method::Ellipsoidal {
        return Ok(None);
    }
    let settings = RenderSettings { stats: true, ..settings.clone() };
    let mut tracer = gatetrace::integrator::BidirectionalTracer::new(ctx, scene, &settings)?;
    use gatetrace::integrator::Integrator;
    tracer.render_samples(2)?;
    Ok(tracer.query_cost())
}

/// The ellipsoid query's work as printed: (loop iterations, triangles tested), empty for methods
/// without queries.
fn cost_columns(cost: Option<(f64, f64)>) -> (String, String) {
    cost.map_or((String::new(), String::new()), |(n, t)| (format!("{n:.2}"), format!("{t:.2}")))
}

/// Renders every gate of every scene with every method for equal wall time and prints, per
/// method, the mean squared error against a reference rendered much longer (its own estimated
/// noise variance is subtracted), with the ratio of MSEs to the first method, and the
/// ellipsoid queries' work. Repeat r of every method renders from the same seed, and every
/// method's repeat r runs before any repeat r + 1. Writes one CSV row per render.
pub fn run_equal_time(scene_paths: &[std::path::PathBuf], s: &EqualTimeSettings) -> Result<()> {
    use std::fmt::Write as _;
    let ctx = GpuContext::new()?;
    let b = &s.base;
    println!("adapter: {}", ctx.adapter_description());
    println!(
        "{}x{}, max bounces {}, {} s per render, {} repeats, reference: {} for {} s",
        b.width,
        b.height,
        b.max_bounces,
        s.seconds,
        s.repeats,
        s.reference.name(),
        s.reference_seconds
    );
    let mut csv = String::from(
        "scene,triangles,gate,method,repeat,seconds,spp,mse,relative_mse,reference_noise,iterations_per_query,\
         triangles_tested_per_query,chosen_method\n",
    );
    // Repeat r of every method renders from seed REPEAT_SEEDS + r (common random numbers: `auto`
    // then renders exactly its chosen method's image, less the samples its pilot took, so a
    // comparison shows the pilot's cost instead of the methods' independent noise); references
    // draw seeds from another range.
    const REPEAT_SEEDS: u32 = 1000;
    let mut reference_seed = 1_000_000;
    for scene_path in scene_paths {
        let scene = gatetrace::scene::load_scene_with(
            scene_path,
            &gatetrace::scene::LoadOptions { time: s.anim_time, ..Default::default() },
        )?;
        super::report::print_warnings(&scene.warnings);
        let scene = PreparedScene::new(scene)?;
        let triangles = scene.triangles.len();
        let posed = s.anim_time.map_or(String::new(), |t| format!(", posed at {t} s"));
        println!("\nscene {} ({triangles} triangles{posed})", scene_path.display());
        let scene_name = scene_path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        for (spec, gate) in &s.gates {
            // Reference: 8 batches, mean and variance of the mean per element.
            let batches = 8;
            let mut stats: Option<(Vec<f64>, Vec<f64>)> = None;
            let mut ref_spp = 0;
            for _ in 0..batches {
                reference_seed += 1;
                let seed = reference_seed;
                let settings = RenderSettings { gate: gate.clone(), seed, ..s.reference.settings(b) };
                let (film, _, _) = render_for(&ctx, &scene, &settings, s.reference_seconds / batches as f64)?;
                ref_spp += film.spp;
                let (sum, sq) = stats.get_or_insert_with(|| (vec![0.0; film.data.len()], vec![0.0; film.data.len()]));
                for (i, &v) in film.data.iter().enumerate() {
                    sum[i] += v as f64;
                    sq[i] += (v as f64) * (v as f64);
                }
            }
            let (sum, sq) = stats.unwrap();
            let n = batches as f64;
            let reference: Vec<f64> = sum.iter().map(|x| x / n).collect();
            let ref_var: Vec<f64> =
                sq.iter().zip(&reference).map(|(q, m)| ((q / n - m * m) * n / (n - 1.0)).max(0.0) / n).collect();
            let elements = reference.len() as f64;
            let ref_noise = ref_var.iter().sum::<f64>() / elements;
            let ref_power = reference.iter().map(|x| x * x).sum::<f64>() / elements;
            println!(
                "gate {spec}: reference {ref_spp} spp, mean {:.6}, its noise variance {ref_noise:.3e}",
                sum.iter().sum::<f64>() / n / elements
            );
            println!(
                "{:>24} {:>8} {:>12} {:>12} {:>12} {:>11} {:>9} chosen",
                "method", "spp", "MSE", "rel. MSE", "MSE / first", "iter/query", "tri/query"
            );
            // Repeat-major: repeat r of every method before repeat r + 1 of any, so that a
            // stretch where the device runs slower (other load, clocks) falls on all methods
            // alike instead of on one method's repeats.
            let mut bases = Vec::new();
            for variant in &s.methods {
                let base = RenderSettings { gate: gate.clone(), ..variant.settings(b) };
                let cost = query_cost(&ctx, &scene, &base)?;
                bases.push((base, cost));
            }
            let mut results: Vec<(Vec<f64>, Vec<u64>, Vec<String>)> = vec![Default::default(); s.methods.len()];
            for repeat in 0..s.repeats {
                for ((variant, (base, cost)), (mses, spps, choices)) in s.methods.iter().zip(&bases).zip(&mut results) {
                    let (iterations, tested) = cost_columns(*cost);
                    let settings = RenderSettings { seed: REPEAT_SEEDS + repeat, ..base.clone() };
                    let (film, secs, chosen) = render_for(&ctx, &scene, &settings, s.seconds)?;
                    let se: f64 =
                        film.data.iter().zip(&reference).map(|(&x, r)| (x as f64 - r).powi(2)).sum::<f64>() / elements;
                    let mse = se - ref_noise;
                    writeln!(
                        csv,
                        "{scene_name},{triangles},\"{}\",{},{repeat},{secs:.3},{},{mse:.6e},{:.6e},{ref_noise:.6e},{iterations},{tested},{chosen}",
                        // Quoted: cw and transient gates hold commas.
                        spec.replace('"', "\"\""),
                        variant.name(),
                        film.spp,
                        mse / ref_power
                    )
                    .unwrap();
                    mses.push(mse);
                    spps.push(film.spp);
                    if !chosen.is_empty() {
                        choices.push(chosen);
                    }
                }
            }
            let mut first = None;
            for ((variant, (_, cost)), (mses, spps, choices)) in s.methods.iter().zip(&bases).zip(&results) {
                let (iterations, tested) = cost_columns(*cost);
                let mse = mses.iter().sum::<f64>() / mses.len() as f64;
                let first_mse = *first.get_or_insert(mse);
                // What the pilots chose, each choice once with its count in order of first
                // appearance, e.g. `direct x2, ellipsoidal roulette 1 x1`.
                let mut counts: Vec<(&str, usize)> = Vec::new();
                for choice in choices {
                    match counts.iter_mut().find(|(c, _)| c == choice) {
                        Some((_, n)) => *n += 1,
                        None => counts.push((choice, 1)),
                    }
                }
                let chosen: Vec<String> = counts.iter().map(|(c, n)| format!("{c} x{n}")).collect();
                let chosen = chosen.join(", ");
                println!(
                    "{:>24} {:>8} {:>12.4e} {:>12.4e} {:>12.3} {:>11} {:>9} {}",
                    variant.name(),
                    spps.iter().sum::<u64>() / spps.len() as u64,
                    mse,
                    mse / ref_power,
                    mse / first_mse,
                    iterations,
                    tested,
                    chosen
                );
            }
        }
    }
    if let Some(path) = &s.csv {
        std::fs::write(path, csv).with_context(|| format!("cannot write {}", path.display()))?;
        println!("\nrows written to {}", path.display());
    }
    Ok(())
}
