//! `gatetrace bench`: samples per second of each method on a scene, and the
//! equal-time comparison (`gatetrace equal-time`).

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};

use crate::film::Gate;
use crate::gpu::GpuContext;
use crate::integrator::{Method, RenderSettings, create_integrator};
use crate::scene::{PreparedScene, load_gltf};

/// What `gatetrace bench` measures.
pub struct BenchSettings {
    /// Seconds of rendering per measurement.
    pub seconds: f64,
    /// Maximum scattering vertices.
    pub max_bounces: u32,
    /// Methods (with their options) to measure.
    pub methods: Vec<Variant>,
    /// Image sizes (pixels).
    pub resolutions: Vec<(u32, u32)>,
    /// Gate of `path` and `direct`, and gate of `ellipsoidal` (which needs target lengths), as
    /// `render --gate` takes them.
    pub gates: (String, String),
    /// Time every dispatch (`render --profile`) and report each measurement's GPU time per
    /// stage; the timestamps cost a little throughput.
    pub profile: bool,
    /// Also write the adapter, the scene and every measurement to this JSON file.
    pub json: Option<std::path::PathBuf>,
}

/// Renders the scene with each method at each resolution and prints pixel samples per second
/// with the adapter's name. Each measurement builds its tracer, renders one warm-up pass
/// (lavapipe compiles kernels at their first dispatch), then times whole passes for at least
/// `seconds` (upload and kernel builds excluded). Rows start with `bench:` for scripts
/// (tools/throughput.py); with `profile`, each is followed by its GPU time per stage, in rows
/// that start with `stage:`. With `json`, the same goes to a file (tools/device_bench.sh).
pub fn run_bench(s: &BenchSettings, scene_path: &Path) -> Result<()> {
    let loading = Instant::now();
    let scene = PreparedScene::new(load_gltf(scene_path)?)?;
    let load_seconds = loading.elapsed().as_secs_f64();
    let mut ctx = GpuContext::new()?;
    let mut rows = Vec::new();
    println!("adapter: {}", ctx.adapter_description());
    println!("scene: {} ({} triangles), max bounces {}", scene_path.display(), scene.triangles.len(), s.max_bounces);
    println!(
        "bench: {:<14} {:<20} {:>10} {:>8} {:>9} {:>11}",
        "method", "gate", "resolution", "spp", "seconds", "Msamples/s"
    );
    for variant in &s.methods {
        let (spec, option) = if variant.method == Method::Ellipsoidal {
            (&s.gates.1, "--ellipsoidal-gate")
        } else {
            (&s.gates.0, "--gate")
        };
        let gate = Gate::parse(spec).with_context(|| format!("{option} {spec}"))?;
        for &(width, height) in &s.resolutions {
            let base =
                RenderSettings { width, height, max_bounces: s.max_bounces, gate: gate.clone(), ..Default::default() };
            let settings = variant.settings(&base);
            if s.profile {
                // A profiler of its own, so that each measurement's stages are its own.
                ctx.enable_profiling()?;
            }
            let building = Instant::now();
            let mut tracer = create_integrator(&ctx, &scene, &settings)?;
            tracer.render_pass(tracer.samples_per_pass())?;
            let setup_seconds = building.elapsed().as_secs_f64();
            tracer.reset_film();
            let before = ctx.profile_totals()?.unwrap_or_default();
            let start = Instant::now();
            while start.elapsed() < Duration::from_secs_f64(s.seconds) {
                tracer.render_pass(tracer.samples_per_pass())?;
            }
            let elapsed = start.elapsed().as_secs_f64();
            let samples = tracer.samples_done() as f64 * (width * height) as f64;
            println!(
                "bench: {:<14} {:<20} {:>10} {:>8} {:>9.2} {:>11.3}",
                variant.name(),
                spec,
                format!("{width}x{height}"),
                tracer.samples_done(),
                elapsed,
                samples / elapsed / 1e6
            );
            // GPU time per stage over the timed passes (the warm-up pass left out).
            let mut stages: Vec<(String, f64, u64)> = ctx
                .profile_totals()?
                .unwrap_or_default()
                .into_iter()
                .map(|(label, t)| {
                    let b = before.get(&label).copied().unwrap_or_default();
                    (label, (t.nanoseconds - b.nanoseconds) / 1e6, t.dispatches - b.dispatches)
                })
                .filter(|(_, _, dispatches)| *dispatches > 0)
                .collect();
            stages.sort_by(|a, b| b.1.total_cmp(&a.1));
            for (label, ms, dispatches) in &stages {
                println!("stage: {:<14} {label:<38} {ms:>10.1} ms {dispatches:>8} dispatches", variant.name());
            }
            rows.push(serde_json::json!({
                "method": variant.name(),
                "gate": spec,
                "width": width,
                "height": height,
                "spp": tracer.samples_done(),
                "seconds": elapsed,
                "samples_per_second": samples / elapsed,
                "setup_seconds": setup_seconds,
                "stages": stages.iter().map(|(label, ms, dispatches)| serde_json::json!({
                    "stage": label, "milliseconds": ms, "dispatches": dispatches,
                })).collect::<Vec<_>>(),
            }));
        }
    }
    if let Some(path) = &s.json {
        let report = serde_json::json!({
            "adapter": ctx.adapter_info.name,
            "backend": format!("{:?}", ctx.adapter_info.backend),
            "device_type": format!("{:?}", ctx.adapter_info.device_type),
            "driver": ctx.adapter_info.driver,
            "driver_info": ctx.adapter_info.driver_info,
            "scene": scene_path.display().to_string(),
            "triangles": scene.triangles.len(),
            "load_and_build_seconds": load_seconds,
            "max_bounces": s.max_bounces,
            "profiled": s.profile,
            "measurements": rows,
        });
        let text = serde_json::to_string_pretty(&report)?;
        std::fs::write(path, text + "\n").with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

/// A method with its own settings, as named in `equal-time --methods`: `path`, `direct`,
/// `ellipsoidal`, and for ellipsoidal options after colons: a number K (connections per query;
/// default `DEFAULT_CONNECTIONS_PER_QUERY`),
/// `exhaustive` (exhaustive ellipsoid queries), `split=R` or `bottom=N` (the stochastic
/// descent's settings, see `QuerySettings`), `reflection` (picks weighed by arcs times the
/// reflection factor), e.g. `ellipsoidal:4:exhaustive`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Variant {
    /// Sampling method.
    pub method: crate::integrator::Method,
    /// Connections drawn from one ellipsoid query (1 for the other methods).
    pub connections_per_query: u32,
    /// How ellipsoid queries traverse the BVH (ellipsoidal only).
    pub query: crate::integrator::QuerySettings,
}

impl Variant {
    /// Parses `METHOD` or `ellipsoidal[:OPTION]...`.
    pub fn parse(s: &str) -> Result<Self> {
        use clap::ValueEnum;
        let mut parts = s.split(':').map(str::trim);
        let name = parts.next().unwrap_or_default();
        let method = crate::integrator::Method::from_str(name, true)
            .map_err(|_| anyhow::anyhow!("`{s}` is not a method: path, direct, ellipsoidal or ellipsoidal:OPTION"))?;
        let connections_per_query = crate::integrator::bidirectional::default_connections_per_query(method);
        let mut variant = Self { method, connections_per_query, query: Default::default() };
        for option in parts {
            anyhow::ensure!(
                matches!(method, crate::integrator::Method::Ellipsoidal | crate::integrator::Method::Auto),
                "`{s}`: only ellipsoidal and auto (for its ellipsoidal candidate) take options (K, exhaustive, \
                 split=R, bottom=N, reflection)"
            );
            if option == "exhaustive" {
                variant.query.split = 0.0;
            } else if option == "reflection" {
                variant.query.reflection_weights = true;
            } else if let Some(r) = option.strip_prefix("split=") {
                variant.query.split =
                    r.parse().map_err(|_| anyhow::anyhow!("`{s}`: split=R needs a number, got `{r}`"))?;
            } else if let Some(n) = option.strip_prefix("bottom=") {
                variant.query.bottom_nodes =
                    n.parse().map_err(|_| anyhow::anyhow!("`{s}`: bottom=N needs a whole number, got `{n}`"))?;
            } else {
                variant.connections_per_query = option.parse().map_err(|_| {
                    anyhow::anyhow!("`{s}`: `{option}` is not an option of ellipsoidal (K, exhaustive, split=R, bottom=N, reflection)")
                })?;
            }
        }
        Ok(variant)
    }

    /// The name it was given by (options in a fixed order).
    pub fn name(&self) -> String {
        let mut name = self.method.name().to_owned();
        if self.connections_per_query != crate::integrator::bidirectional::default_connections_per_query(self.method) {
            name += &format!(":{}", self.connections_per_query);
        }
        if matches!(self.method, crate::integrator::Method::Ellipsoidal | crate::integrator::Method::Auto) {
            let default = crate::integrator::QuerySettings::default();
            if self.query.split == 0.0 {
                name += ":exhaustive";
            } else if self.query.split != default.split {
                name += &format!(":split={}", self.query.split);
            }
            if self.query.bottom_nodes != default.bottom_nodes {
                name += &format!(":bottom={}", self.query.bottom_nodes);
            }
            if self.query.reflection_weights {
                name += ":reflection";
            }
        }
        name
    }

    /// `base` with this variant's method and options.
    pub fn settings(&self, base: &RenderSettings) -> RenderSettings {
        RenderSettings {
            method: self.method,
            connections_per_query: self.connections_per_query,
            query: self.query,
            ..base.clone()
        }
    }
}

/// Settings of an equal-time comparison (`gatetrace equal-time`).
pub struct EqualTimeSettings {
    /// Methods compared, each rendered for the same wall time.
    pub methods: Vec<Variant>,
    /// Gates, each compared separately.
    pub gates: Vec<(String, crate::film::Gate)>,
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
/// `auto`'s pilot included); returns the film, the seconds actually spent and, for `auto`, the
/// method it chose.
fn render_for(
    ctx: &GpuContext,
    scene: &PreparedScene,
    settings: &RenderSettings,
    seconds: f64,
) -> Result<(crate::film::Film, f64, Option<Method>)> {
    let budget = crate::integrator::Budget::Time(Duration::from_secs_f64(seconds));
    let output = crate::integrator::render(ctx, scene, settings, budget, |_| {})?;
    Ok((output.film, output.rendering.as_secs_f64(), output.choice.map(|c| c.chosen)))
}

/// Work of one ellipsoid query: (loop iterations, triangles tested), from a short render with
/// `--stats` (None for methods without queries).
fn query_cost(ctx: &GpuContext, scene: &PreparedScene, settings: &RenderSettings) -> Result<Option<(f64, f64)>> {
    if settings.method != crate::integrator::Method::Ellipsoidal {
        return Ok(None);
    }
    let settings = RenderSettings { stats: true, ..settings.clone() };
    let mut tracer = crate::integrator::BidirectionalTracer::new(ctx, scene, &settings)?;
    use crate::integrator::Integrator;
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
        let scene = PreparedScene::new(crate::scene::load_gltf_at(scene_path, s.anim_time)?)?;
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
                "{:>24} {:>8} {:>12} {:>12} {:>12} {:>11} {:>9} {}",
                "method", "spp", "MSE", "rel. MSE", "MSE / first", "iter/query", "tri/query", "chosen"
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
            let mut results: Vec<(Vec<f64>, Vec<u64>, Vec<&str>)> = vec![Default::default(); s.methods.len()];
            for repeat in 0..s.repeats {
                for ((variant, (base, cost)), (mses, spps, choices)) in s.methods.iter().zip(&bases).zip(&mut results) {
                    let (iterations, tested) = cost_columns(*cost);
                    let settings = RenderSettings { seed: REPEAT_SEEDS + repeat, ..base.clone() };
                    let (film, secs, chosen) = render_for(&ctx, &scene, &settings, s.seconds)?;
                    let chosen = chosen.map_or("", Method::name);
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
                // auto: the methods its pilots chose, e.g. `direct x2, ellipsoidal x1`.
                let mut chosen = String::new();
                for method in [Method::Path, Method::Direct, Method::Ellipsoidal] {
                    let n = choices.iter().filter(|&&c| c == method.name()).count();
                    if n > 0 {
                        chosen += &format!("{}{} x{n}", if chosen.is_empty() { "" } else { ", " }, method.name());
                    }
                }
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
