//! The `gatetrace` command line.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context as _, Result, bail, ensure};
use clap::{Args, Parser, Subcommand};
use gatetrace::film::Gate;
use gatetrace::film::output::{Metadata, OutputFormat, check_writable, write_film};
use gatetrace::gpu::GpuContext;
use gatetrace::integrator::{Budget, LightStrategy, Method, RenderSettings, film_elements, render};
use gatetrace::scene::{PreparedScene, load_gltf};

/// The scene rendered when none is given.
const DEFAULT_SCENE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/assets/scenes/cornell_box.gltf");

/// gatetrace: a physically based GPU renderer for time-of-flight cameras.
///
/// Time is optical path length (OPL) in metres, with c = 1: a path's length runs from the point
/// on the light through every scattering vertex to the camera's pinhole. Wherever a length is
/// asked for, `ps` and `ns` suffixes give times instead (c = 0.299792458 mm/ps).
#[derive(Parser)]
#[command(version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render an image (or a transient cube) to EXR or NPY.
    Render(RenderArgs),
    /// Measure samples per second of `path` on the Cornell box at 64x64 and 256x256.
    Bench(BenchArgs),
    /// Render a scene with several methods for the same wall time each and report their mean
    /// squared error against a long reference render (error at equal time).
    EqualTime(EqualTimeArgs),
    /// Compare the kernels' f32 ellipsoid code with the f64 oracle on many random and
    /// adversarial configurations and print the error distributions per family.
    StressEllipsoid(StressArgs),
}

#[derive(Args)]
struct StressArgs {
    /// Configurations of the random family; each adversarial family gets a quarter as many.
    #[arg(long, default_value_t = 1_000_000)]
    configs: usize,
    /// Seed of the configurations.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

#[derive(Args)]
struct RenderArgs {
    /// glTF 2.0 scene (.gltf or .glb); the Cornell box when omitted.
    scene: Option<PathBuf>,
    /// Sampling method: `path` (path tracing with next-event estimation and MIS); `direct`
    /// (bidirectional path tracing, every (s, t) strategy, power-heuristic MIS; at most 24
    /// bounces); `ellipsoidal` (bidirectional path tracing whose subpaths are joined through a
    /// vertex on the spheroid of a target length drawn from the gate, so every path has a
    /// length the gate weighs; needs a gate; at most 24 bounces).
    #[arg(long, value_enum, default_value_t = Method::Path)]
    method: Method,
    /// Pathlength importance W (lengths in metres of optical path, or with a ps/ns/mm suffix):
    /// `none` (steady state); `box:A..B` (W = 1 on [A, B)); `gaussian:MU,SIGMA`;
    /// `cw:FREQ_HZ,PHASE_DEG` (W = cos(2 pi f l / c + phase), signed); `table:FILE.csv`
    /// (rows `length,weight`, linear in between, 0 outside); `transient:START,WIDTH,BINS`
    /// (a cube of BINS bin-integrated images).
    #[arg(long, default_value = "none", value_name = "SPEC")]
    gate: String,
    /// Samples per pixel (default 64 unless --time is given).
    #[arg(long, conflicts_with = "time")]
    spp: Option<u64>,
    /// Render whole passes until this many seconds have passed, instead of --spp.
    #[arg(long, value_name = "SECONDS")]
    time: Option<f64>,
    /// Image size in pixels, WIDTHxHEIGHT.
    #[arg(long, default_value = "256x256", value_parser = parse_resolution)]
    res: (u32, u32),
    /// Maximum number of scattering vertices of a path (0: only lights seen directly).
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(0..=1_000_000))]
    max_bounces: u32,
    /// Start Russian roulette after this many scattering vertices (off when not given).
    #[arg(long)]
    rr_depth: Option<u32>,
    /// Random seed; equal seeds and settings give identical images.
    #[arg(long, default_value_t = 0)]
    seed: u32,
    /// Samples per pixel of one pass, traced together on the GPU when they fit (chosen from the
    /// image size by default). --time renders whole passes.
    #[arg(long)]
    samples_per_pass: Option<u32>,
    /// Print, per (s, t) strategy of a bidirectional method, the connections evaluated, those
    /// skipped (direct: the gate weighs their length zero; ellipsoidal: the spheroid met no
    /// surface) and the shadow rays traced (ellipsoidal: pairs), and for ellipsoidal the BVH
    /// nodes visited and triangles tested and intersected per ellipsoid query.
    #[arg(long)]
    stats: bool,
    /// Write only the MIS-weighted contribution of strategy S,T (S light-subpath vertices, T
    /// camera-subpath vertices, the pinhole included; `direct` only). The images of all
    /// strategies of a scene sum to the full render.
    #[arg(long, value_name = "S,T", value_parser = parse_strategy)]
    debug_strategy: Option<(u32, u32)>,
    /// `ellipsoidal`: connections drawn from each ellipsoid query (1 to 8). One BVH traversal
    /// serves K independent points on the spheroid, each weighted 1/K; every point still costs
    /// its shading and two shadow rays.
    #[arg(long, default_value_t = 1, value_name = "K")]
    connections_per_query: u32,
    /// `ellipsoidal`, for numerical studies: skip spheroids with tau_e <= d (1 + REL), d the
    /// distance between the foci (dimensionless; f32 cannot place points on thinner ones).
    #[arg(long, default_value_t = 1e-6, value_name = "REL")]
    needle_guard: f32,
    /// `ellipsoidal`, for numerical studies: drop sampled points whose path length misses the
    /// target tau_e by more than REL x tau_e (dimensionless).
    #[arg(long, default_value_t = 1e-5, value_name = "REL")]
    length_guard: f32,
    /// Output file: .exr (one layer per transient bin) or .npy (float32 [H, W, 3] or
    /// [H, W, T, 3], row 0 at the top, with a .json sidecar). Default: SCENE_NAME.exr.
    #[arg(long, short)]
    out: Option<PathBuf>,
}

#[derive(Args)]
struct BenchArgs {
    /// Seconds of rendering per measurement.
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Maximum number of scattering vertices.
    #[arg(long, default_value_t = 5)]
    max_bounces: u32,
}

#[derive(Args)]
struct EqualTimeArgs {
    /// glTF 2.0 scene; the Cornell box when omitted.
    scene: Option<PathBuf>,
    /// Methods to compare, comma-separated: path, direct, ellipsoidal, or ellipsoidal:K (K
    /// connections per ellipsoid query, see render --connections-per-query).
    #[arg(long, value_delimiter = ',', default_value = "path,direct", value_parser = parse_variant)]
    methods: Vec<gatetrace::bench::Variant>,
    /// Gates to compare at, separated by `;` (same syntax as `render --gate`).
    #[arg(long, default_value = "none;box:3.14..3.1425")]
    gates: String,
    /// Seconds of rendering per method, gate and repeat (kernel builds excluded).
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Independent renders per method and gate.
    #[arg(long, default_value_t = 3)]
    repeats: u32,
    /// Method of the reference images.
    #[arg(long, value_enum, default_value_t = Method::Direct)]
    reference_method: Method,
    /// Seconds of rendering of each gate's reference.
    #[arg(long, default_value_t = 120.0)]
    reference_seconds: f64,
    /// Image size in pixels, WIDTHxHEIGHT.
    #[arg(long, default_value = "64x64", value_parser = parse_resolution)]
    res: (u32, u32),
    /// Maximum number of scattering vertices.
    #[arg(long, default_value_t = 5)]
    max_bounces: u32,
    /// Write one row per render to this CSV file.
    #[arg(long)]
    csv: Option<PathBuf>,
}

fn run_stress(args: StressArgs) -> Result<()> {
    use gatetrace::ellipsoid::stress::{Family, Report, compare, generate, run_on_device};
    ensure!(args.configs >= 1, "--configs must be at least 1");
    let ctx = GpuContext::new()?;
    println!("adapter: {}", ctx.adapter_description());
    println!("errors of the device's f32 results against the f64 oracle on the same inputs; \
              guard: fraction of samples with |L(x) - tau_e| > 1e-5 tau_e");
    println!("{}", Report::header());
    for family in Family::all() {
        let count = if family == Family::Random { args.configs } else { args.configs.div_ceil(4) };
        let configs = generate(family, count, args.seed);
        let device = run_on_device(&ctx, &configs)?;
        println!("{}", compare(&family.name(), &configs, &device).row());
    }
    Ok(())
}

fn run_equal_time(args: EqualTimeArgs) -> Result<()> {
    let scene = args.scene.clone().unwrap_or_else(|| PathBuf::from(DEFAULT_SCENE));
    let gates = args
        .gates
        .split(';')
        .map(|g| Ok((g.trim().to_owned(), Gate::parse(g.trim())?)))
        .collect::<Result<Vec<_>>>()?;
    ensure!(args.seconds > 0.0 && args.reference_seconds > 0.0, "--seconds and --reference-seconds must be positive");
    ensure!(args.repeats >= 1, "--repeats must be at least 1");
    let settings = gatetrace::bench::EqualTimeSettings {
        methods: args.methods,
        gates,
        seconds: args.seconds,
        repeats: args.repeats,
        reference_method: args.reference_method,
        reference_seconds: args.reference_seconds,
        base: RenderSettings { width: args.res.0, height: args.res.1, max_bounces: args.max_bounces, ..Default::default() },
        csv: args.csv,
    };
    gatetrace::bench::run_equal_time(&scene, &settings)
}

fn parse_variant(s: &str) -> Result<gatetrace::bench::Variant, String> {
    gatetrace::bench::Variant::parse(s).map_err(|e| e.to_string())
}

fn parse_strategy(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("`{s}` is not S,T (two non-negative integers, e.g. 1,2)");
    let (a, b) = s.split_once(',').ok_or_else(bad)?;
    Ok((a.trim().parse().map_err(|_| bad())?, b.trim().parse().map_err(|_| bad())?))
}

fn parse_resolution(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("`{s}` is not WIDTHxHEIGHT (e.g. 256x256)");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h) = (w.trim().parse::<u32>().map_err(|_| bad())?, h.trim().parse::<u32>().map_err(|_| bad())?);
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!("resolution {w}x{h} must be between 1x1 and 16384x16384"));
    }
    Ok((w, h))
}

fn main() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        // Mesa's Vulkan driver probes for a Wayland display and complains when this is unset;
        // a headless render needs none.
        // SAFETY: nothing else runs yet: main has not started any thread.
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir()) };
    }
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(args) => run_render(args),
        Command::EqualTime(args) => run_equal_time(args),
        Command::StressEllipsoid(args) => run_stress(args),
        Command::Bench(args) => gatetrace::bench::run_bench(args.seconds, args.max_bounces, Path::new(DEFAULT_SCENE)),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run_render(args: RenderArgs) -> Result<()> {
    let scene_path = args.scene.clone().unwrap_or_else(|| PathBuf::from(DEFAULT_SCENE));
    let gate = Gate::parse(&args.gate).with_context(|| format!("--gate {}", args.gate))?;
    let budget = match (args.spp, args.time) {
        (_, Some(t)) => match Duration::try_from_secs_f64(t) {
            Ok(d) if t > 0.0 => Budget::Time(d),
            _ => bail!("--time {t}: give a positive number of seconds"),
        },
        (Some(0), _) => bail!("--spp must be at least 1"),
        (Some(n), None) => Budget::Samples(n),
        (None, None) => Budget::Samples(64),
    };
    let out = args.out.clone().unwrap_or_else(|| {
        PathBuf::from(format!("{}.exr", scene_path.file_stem().and_then(|s| s.to_str()).unwrap_or("render")))
    });
    OutputFormat::of(&out)?;
    let settings = RenderSettings {
        width: args.res.0,
        height: args.res.1,
        method: args.method,
        gate: gate.clone(),
        max_bounces: args.max_bounces,
        rr_depth: args.rr_depth,
        seed: args.seed,
        samples_per_pass: args.samples_per_pass,
        light_strategy: LightStrategy::Mis,
        stats: args.stats,
        debug_strategy: args.debug_strategy,
        portable_atomics: false,
        binding_limit: None,
        connections_per_query: args.connections_per_query,
        ellipsoid_guards: gatetrace::integrator::EllipsoidGuards { needle: args.needle_guard, length: args.length_guard },
    };
    if settings.debug_strategy.is_some() && settings.method != Method::Direct {
        bail!("--debug-strategy needs --method direct");
    }
    if settings.method != Method::Path {
        gatetrace::integrator::bidirectional::check_settings(&settings)?;
    } else if settings.connections_per_query != 1 {
        bail!("--connections-per-query applies to --method ellipsoidal only");
    }
    film_elements(&settings)?;
    check_writable(&out)?;

    let scene = PreparedScene::new(load_gltf(&scene_path)?)?;
    let ctx = GpuContext::new()?;
    let bar = progress_bar(budget);
    let output = render(&ctx, &scene, &settings, budget, |p| {
        match budget {
            Budget::Samples(_) => bar.set_position(p.spp),
            Budget::Time(_) => bar.set_position(p.elapsed.as_millis() as u64),
        }
        let rate = (p.spp * (settings.width * settings.height) as u64) as f64 / p.elapsed.as_secs_f64().max(1e-9);
        bar.set_message(format!("{} passes, {} spp, {:.2} Msamples/s", p.passes, p.spp, rate / 1e6));
    })?;
    bar.finish_and_clear();

    let film = &output.film;
    let secs = output.elapsed.as_secs_f64();
    let mut metadata: Metadata = vec![
        ("scene".into(), scene_path.display().to_string()),
        ("method".into(), settings.method.name().into()),
        ("gate".into(), args.gate.clone()),
        ("gate_description".into(), gate.describe()),
        ("spp".into(), film.spp.to_string()),
        ("seed".into(), settings.seed.to_string()),
        ("max_bounces".into(), settings.max_bounces.to_string()),
        ("rr_depth".into(), settings.rr_depth.map_or("off".into(), |d| d.to_string())),
        ("resolution".into(), format!("{}x{}", settings.width, settings.height)),
        ("elapsed_seconds".into(), format!("{secs:.3}")),
        ("adapter".into(), ctx.adapter_description()),
        ("truncated_traversals".into(), output.truncated_traversals.to_string()),
        ("units".into(), "bin-integrated radiance W m^-2 sr^-1 weighted by W; lengths are optical path in metres".into()),
        ("gatetrace_version".into(), env!("CARGO_PKG_VERSION").into()),
    ];
    if let Some((s, t)) = settings.debug_strategy {
        metadata.push(("debug_strategy".into(), format!("{s},{t}")));
    }
    if settings.method == Method::Ellipsoidal {
        let g = settings.ellipsoid_guards;
        metadata.push(("connections_per_query".into(), settings.connections_per_query.to_string()));
        metadata.push(("ellipsoid_guards".into(), format!("needle {:e}, length {:e}", g.needle, g.length)));
    }
    let bin_ranges: Vec<(f64, f64)> = (0..gate.bins()).filter_map(|b| gate.bin_range(b)).collect();
    write_film(&out, film, &metadata, &bin_ranges)?;
    let mean = film.mean_rgb();
    println!(
        "{}: {}x{} {} gate {} | {} spp in {:.2} s ({:.2} Msamples/s) on {} | mean RGB [{:.5}, {:.5}, {:.5}] -> {}",
        scene_path.file_name().map(|n| n.to_string_lossy()).unwrap_or_default(),
        settings.width,
        settings.height,
        settings.method.name(),
        args.gate,
        film.spp,
        secs,
        (film.spp * (settings.width * settings.height) as u64) as f64 / secs / 1e6,
        ctx.adapter_info.name,
        mean[0],
        mean[1],
        mean[2],
        out.display()
    );
    if let Some(report) = &output.stats {
        print!("{report}");
    } else if settings.stats {
        println!("--stats: method {} keeps no per-strategy statistics", settings.method.name());
    }
    Ok(())
}

fn progress_bar(budget: Budget) -> indicatif::ProgressBar {
    let (len, unit) = match budget {
        Budget::Samples(n) => (n, "spp"),
        Budget::Time(t) => (t.as_millis() as u64, "ms"),
    };
    let bar = indicatif::ProgressBar::new(len);
    let template = format!("{{elapsed_precise}} [{{bar:30}}] {{pos}}/{{len}} {unit} {{msg}} (ETA {{eta}})");
    bar.set_style(indicatif::ProgressStyle::with_template(&template).unwrap().progress_chars("=> "));
    bar
}
