//! `gatetrace bench`: samples per second of each method on a scene; the method variants
//! (`ellipsoidal:4:exhaustive`, ...) it and `gatetrace equal-time` measure.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};

use gatetrace::film::Gate;
use gatetrace::gpu::GpuContext;
use gatetrace::integrator::{Method, RenderSettings, create_integrator};
use gatetrace::scene::{PreparedScene, load_scene_with};

use super::parse::parse_resolution;

#[derive(clap::Args)]
pub struct BenchArgs {
    /// Seconds of rendering per measurement (after a discarded warm-up pass).
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Maximum number of scattering vertices.
    #[arg(long, default_value_t = 5)]
    max_bounces: u32,
    /// Methods to measure, comma-separated (as in equal-time --methods).
    #[arg(long, value_delimiter = ',', default_value = "path,direct,ellipsoidal", value_parser = parse_variant)]
    methods: Vec<Variant>,
    /// Image sizes, comma-separated WIDTHxHEIGHT.
    #[arg(long, value_delimiter = ',', default_value = "64x64", value_parser = parse_resolution)]
    res: Vec<(u32, u32)>,
    /// Samples per pixel of one pass, comma-separated, each measured (default: the renderer's
    /// choice for the image and the device; a pass of K samples of a WxH image fills W*H*K
    /// path slots, the wave a GPU keeps in flight).
    #[arg(long, value_delimiter = ',')]
    samples_per_pass: Vec<u32>,
    /// Scene, glTF 2.0 or Mitsuba 3 XML (default: the Cornell box).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Gate of path and direct (see render --gate; metres of optical path).
    #[arg(long, default_value = "none")]
    gate: String,
    /// Gate of ellipsoidal, which needs one with target lengths (default: a 2.5 mm box).
    #[arg(long, default_value = "box:3.16..3.1625")]
    ellipsoidal_gate: String,
    /// Also print each measurement's GPU time per stage (ms; the timestamps cost a little
    /// throughput).
    #[arg(long)]
    profile: bool,
    /// Also write the adapter, the scene (with its load and BVH build time, s) and every
    /// measurement (samples/s, set-up s, GPU ms per stage) to this JSON file.
    #[arg(long, value_name = "FILE.json")]
    json: Option<PathBuf>,
}

/// `gatetrace bench`.
pub fn run(args: BenchArgs) -> Result<()> {
    let settings = BenchSettings {
        seconds: args.seconds,
        max_bounces: args.max_bounces,
        methods: args.methods,
        resolutions: args.res,
        samples_per_pass: args.samples_per_pass,
        gates: (args.gate, args.ellipsoidal_gate),
        profile: args.profile,
        json: args.json,
    };
    let scene = args.scene.unwrap_or_else(|| PathBuf::from(super::DEFAULT_SCENE));
    run_bench(&settings, &scene)
}

/// The value parser of method lists (`--methods`, `--reference-method`).
pub fn parse_variant(s: &str) -> Result<Variant, String> {
    Variant::parse(s).map_err(|e| e.to_string())
}

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
    /// Samples per pixel of one pass, each measured at every image size; empty: the renderer's
    /// choice.
    pub samples_per_pass: Vec<u32>,
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
/// (tools/peer/throughput.py); with `profile`, each is followed by its GPU time per stage, in rows
/// that start with `stage:`. With `json`, the same goes to a file (tools/bench/device_bench.sh).
pub fn run_bench(s: &BenchSettings, scene_path: &Path) -> Result<()> {
    let loading = Instant::now();
    let scene = load_scene_with(scene_path, &Default::default())?;
    super::report::print_warnings(&scene.warnings);
    let scene = PreparedScene::new(scene)?;
    let load_seconds = loading.elapsed().as_secs_f64();
    let mut ctx = GpuContext::new()?;
    let mut rows = Vec::new();
    println!("adapter: {}", ctx.adapter_description());
    println!("scene: {} ({} triangles), max bounces {}", scene_path.display(), scene.triangles.len(), s.max_bounces);
    println!(
        "bench: {:<14} {:<20} {:>10} {:>6} {:>8} {:>9} {:>11}",
        "method", "gate", "resolution", "spp/ps", "spp", "seconds", "Msamples/s"
    );
    for variant in &s.methods {
        let (spec, option) = if variant.method == Method::Ellipsoidal {
            (&s.gates.1, "--ellipsoidal-gate")
        } else {
            (&s.gates.0, "--gate")
        };
        let gate = Gate::parse(spec).with_context(|| format!("{option} {spec}"))?;
        let passes: Vec<Option<u32>> = match s.samples_per_pass.is_empty() {
            true => vec![None],
            false => s.samples_per_pass.iter().map(|&k| Some(k)).collect(),
        };
        for (&(width, height), samples_per_pass) in
            s.resolutions.iter().flat_map(|r| passes.iter().map(move |&k| (r, k)))
        {
            let base = RenderSettings {
                width,
                height,
                max_bounces: s.max_bounces,
                gate: gate.clone(),
                samples_per_pass,
                ..Default::default()
            };
            let settings = variant.settings(&base);
            if s.profile {
                // A profiler of its own, so that each measurement's stages are its own.
                ctx.enable_profiling()?;
            }
            // What names a measurement in the JSON, with its samples per pass.
            let row = |k: u32| {
                serde_json::json!({
                    "method": variant.name(), "gate": spec, "width": width, "height": height, "samples_per_pass": k,
                })
            };
            let building = Instant::now();
            let mut tracer = match (create_integrator(&ctx, &scene, &settings), samples_per_pass) {
                (Ok(tracer), _) => tracer,
                // A requested pass the device cannot hold (too many path slots for its bindings)
                // is reported, and a sweep goes on to its next value.
                (Err(e), Some(k)) => {
                    let why = format!("{e:#}");
                    println!("bench: {:<14} {width}x{height}, {k} samples per pass: skipped: {why}", variant.name());
                    let mut skipped = row(k);
                    skipped["skipped"] = why.into();
                    rows.push(skipped);
                    continue;
                }
                (Err(e), None) => return Err(e),
            };
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
                "bench: {:<14} {:<20} {:>10} {:>6} {:>8} {:>9.2} {:>11.3}",
                variant.name(),
                spec,
                format!("{width}x{height}"),
                tracer.samples_per_pass(),
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
            let mut measured = row(tracer.samples_per_pass());
            measured["spp"] = tracer.samples_done().into();
            measured["seconds"] = elapsed.into();
            measured["samples_per_second"] = (samples / elapsed).into();
            measured["setup_seconds"] = setup_seconds.into();
            measured["stages"] = stages
                .iter()
                .map(|(label, ms, dispatches)| {
                    serde_json::json!({"stage": label, "milliseconds": ms, "dispatches": dispatches})
                })
                .collect();
            rows.push(measured);
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
/// reflection factor), `wide` (queries over the wide BVH), e.g. `ellipsoidal:4:exhaustive`; for
/// path `medium-connections=on` (render --medium-connections on).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Variant {
    /// Sampling method.
    pub method: Method,
    /// Connections drawn from one ellipsoid query (1 for the other methods).
    pub connections_per_query: u32,
    /// How ellipsoid queries traverse the BVH (ellipsoidal only).
    pub query: gatetrace::integrator::QuerySettings,
    /// Medium connections (path; see `RenderSettings::medium_connections`).
    pub medium_connections: bool,
    /// The query roulette's probability (ellipsoidal, combined; see `RenderSettings::query_roulette`).
    pub query_roulette: Option<f32>,
}

impl Variant {
    /// Parses `METHOD` or `ellipsoidal[:OPTION]...`.
    pub fn parse(s: &str) -> Result<Self> {
        let mut parts = s.split(':').map(str::trim);
        let name = parts.next().unwrap_or_default();
        // Names in any case, as the method lists have always taken them.
        let method = Method::parse(&name.to_ascii_lowercase())
            .map_err(|_| anyhow::anyhow!("`{s}` is not a method: path, direct, ellipsoidal or ellipsoidal:OPTION"))?;
        let connections_per_query = gatetrace::integrator::bidirectional::default_connections_per_query(method);
        let mut variant = Self {
            method,
            connections_per_query,
            query: Default::default(),
            medium_connections: RenderSettings::default().medium_connections,
            query_roulette: None,
        };
        for option in parts {
            if method == Method::Path {
                variant.medium_connections = match option {
                    "medium-connections=on" => true,
                    "medium-connections=off" => false,
                    _ => anyhow::bail!("`{s}`: `{option}` is not an option of path (medium-connections=on|off)"),
                };
                continue;
            }
            if method == Method::Combined {
                let r = option
                    .strip_prefix("roulette=")
                    .ok_or_else(|| anyhow::anyhow!("`{s}`: `{option}` is not an option of combined (roulette=P)"))?;
                variant.query_roulette =
                    Some(r.parse().map_err(|_| anyhow::anyhow!("`{s}`: roulette=P needs a number, got `{r}`"))?);
                continue;
            }
            anyhow::ensure!(
                matches!(method, Method::Ellipsoidal | Method::Auto),
                "`{s}`: only ellipsoidal and auto (for its ellipsoidal candidate) take options (K, exhaustive, \
                 split=R, bottom=N, arcs, reflection, wide, roulette=P), combined roulette=P and path \
                 medium-connections=on|off"
            );
            if option == "exhaustive" {
                variant.query.split = 0.0;
            } else if option == "arcs" {
                variant.query.reflection_weights = false;
            } else if option == "reflection" {
                variant.query.reflection_weights = true;
            } else if option == "wide" {
                variant.query.wide = true;
            } else if let Some(r) = option.strip_prefix("split=") {
                variant.query.split =
                    r.parse().map_err(|_| anyhow::anyhow!("`{s}`: split=R needs a number, got `{r}`"))?;
            } else if let Some(r) = option.strip_prefix("roulette=") {
                variant.query_roulette =
                    Some(r.parse().map_err(|_| anyhow::anyhow!("`{s}`: roulette=P needs a number, got `{r}`"))?);
            } else if let Some(n) = option.strip_prefix("bottom=") {
                variant.query.bottom_nodes =
                    n.parse().map_err(|_| anyhow::anyhow!("`{s}`: bottom=N needs a whole number, got `{n}`"))?;
            } else {
                variant.connections_per_query = option.parse().map_err(|_| {
                    anyhow::anyhow!("`{s}`: `{option}` is not an option of ellipsoidal (K, exhaustive, split=R, bottom=N, arcs, reflection, wide)")
                })?;
            }
        }
        Ok(variant)
    }

    /// The name it was given by (options in a fixed order).
    pub fn name(&self) -> String {
        let mut name = self.method.name().to_owned();
        if self.connections_per_query
            != gatetrace::integrator::bidirectional::default_connections_per_query(self.method)
        {
            name += &format!(":{}", self.connections_per_query);
        }
        if self.medium_connections != RenderSettings::default().medium_connections {
            name += if self.medium_connections { ":medium-connections=on" } else { ":medium-connections=off" };
        }
        if matches!(self.method, Method::Ellipsoidal | Method::Auto) {
            let default = gatetrace::integrator::QuerySettings::default();
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
            if self.query.wide {
                name += ":wide";
            }
        }
        if let Some(p) = self.query_roulette {
            name += &format!(":roulette={p}");
        }
        name
    }

    /// `base` with this variant's method and options.
    pub fn settings(&self, base: &RenderSettings) -> RenderSettings {
        RenderSettings {
            method: self.method,
            connections_per_query: self.connections_per_query,
            query: self.query,
            medium_connections: self.medium_connections,
            query_roulette: self.query_roulette,
            ..base.clone()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Variant;

    #[test]
    fn query_weights_name_what_differs_from_the_default() {
        let default = Variant::parse("ellipsoidal").unwrap();
        assert!(!default.query.reflection_weights, "arc weights are the default");
        assert_eq!(default.name(), "ellipsoidal");
        assert_eq!(Variant::parse("ellipsoidal:arcs").unwrap().name(), "ellipsoidal");
        let reflection = Variant::parse("ellipsoidal:2:reflection").unwrap();
        assert!(reflection.query.reflection_weights);
        assert_eq!(reflection.name(), "ellipsoidal:2:reflection");
        assert!(Variant::parse("direct:arcs").is_err(), "direct takes no query options");
    }
}
