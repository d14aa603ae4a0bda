//! The `gatetrace` command line.

mod interrupt;

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, bail, ensure};
use clap::{Args, Parser, Subcommand};
use gatetrace::film::Gate;
use gatetrace::film::output::{OutputFormat, check_writable, write_film};
use gatetrace::film::preview::{PreviewSettings, write_preview};
use gatetrace::frames::{FramePlan, frame_path, frame_seed, is_frame_pattern, parse_frame_range, parse_time_range};
use gatetrace::gpu::GpuContext;
use gatetrace::integrator::checkpoint::{
    check_fingerprint, checkpoint_path, fingerprint, merge_states, read_checkpoint, read_state_file, write_checkpoint,
    write_state_file,
};
use gatetrace::integrator::{
    Budget, LightStrategy, Method, RenderSettings, film_elements, render_metadata, render_resumable,
};
use gatetrace::scene::{LoadOptions, PreparedScene, load_gltf_with};

/// The scene rendered when none is given.
const DEFAULT_SCENE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/assets/scenes/cornell_box.gltf");

/// gatetrace: a physically based GPU renderer for time-of-flight cameras.
///
/// Time is optical path length (OPL) in metres, with c = 1: a path's length runs from the point
/// on the light through every scattering vertex to the camera's pinhole. Wherever a length is
/// asked for, ps and ns suffixes give times instead (c = 0.299792458 mm/ps).
#[derive(Parser)]
#[command(version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render an image (or a transient cube, or a sequence of frames) to EXR or NPY, or a PNG
    /// preview.
    Render(RenderArgs),
    /// Open the interactive viewer: scrub the gate through time and watch light move; click a
    /// pixel for its transient response.
    ///
    /// It takes render's gates, with the same defaults: a box or Gaussian gate is scrubbed by its
    /// centre tau, a table gate by moving the whole table, a CW gate by its phase; a transient
    /// gate renders its whole cube and a slider picks the bin shown (--bin at start). Signed
    /// gates (CW, tables with negative weights) show the luminance on a diverging map: orange
    /// above zero, blue below, black at zero.
    View(ViewArgs),
    /// Measure samples per second of each method on a scene (tools/throughput.py adds
    /// Mitsuba 3 + mitransient's in the same run).
    Bench(BenchArgs),
    /// Render a scene with several methods for the same wall time each and report their mean
    /// squared error against a long reference render (error at equal time).
    EqualTime(EqualTimeArgs),
    /// Compare the kernels' f32 ellipsoid code with the f64 oracle on many random and
    /// adversarial configurations and print the error distributions per family.
    StressEllipsoid(StressArgs),
    /// Combine the shards of a render (render --shard I/N, one file each) into the image the
    /// unsplit render gives, bit for bit; refuses parts of different renders, missing or
    /// repeated shards.
    Merge(MergeArgs),
    /// Say what an output holds: its layout, the gate (as typed and in metres), the units and
    /// how it was rendered, from the file and its metadata (.npy with its .json sidecar, .exr,
    /// or a .png preview).
    Info(InfoArgs),
}

#[derive(Args)]
struct InfoArgs {
    /// An output of gatetrace render or merge: .npy, .exr or .png.
    file: PathBuf,
    /// Print everything as one JSON object (format, shape, layout, metadata) instead.
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
struct MergeArgs {
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

#[derive(Args)]
struct StressArgs {
    /// Configurations of the random family; each adversarial family gets a quarter as many.
    #[arg(long, default_value_t = 1_000_000)]
    configs: usize,
    /// Seed of the configurations.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

/// What both render and view render: the scene, its camera's lens, the gate, the image and
/// the paths. One definition of each option, so both commands take the same options with the
/// same defaults.
#[derive(Args)]
struct ImageArgs {
    /// glTF 2.0 scene (.gltf or .glb); the Cornell box when omitted. Other formats (OBJ, PLY,
    /// FBX, USD, Mitsuba XML, ...) are refused with how to convert them.
    scene: Option<PathBuf>,
    /// Render materials that use a glTF extension letting light through the surface
    /// (KHR_materials_transmission, KHR_materials_volume, KHR_materials_diffuse_transmission),
    /// which gatetrace does not implement, as the opaque surfaces their other properties describe,
    /// with a warning, instead of refusing the scene. Other unimplemented material extensions
    /// (clearcoat, sheen, specular, ...) are always ignored with a warning.
    #[arg(long)]
    allow_unsupported_materials: bool,
    /// Pathlength importance W (lengths in metres of optical path, or with a ps/ns/mm suffix):
    /// none (steady state); box:A..B (W = 1 on [A, B)); gaussian:MU,SIGMA;
    /// cw:FREQ_HZ,PHASE_DEG (W = cos(2 pi f l / c + phase), signed);
    /// cw:FREQ_HZ,PHASE_DEG,CODE (W = C(f l / c + phase / 360), one period C of a CW-ToF code:
    /// sine, square, ham3, ham4:1 to ham4:4, mseq or mseq:CHIPS, depthsel, depthsel:CHIPS or
    /// depthsel:CHIPS:N; see the README); table:FILE.csv (rows length,weight, linear in between,
    /// 0 outside); transient:START,WIDTH,BINS (a cube of BINS bin-integrated images).
    #[arg(long, default_value = "none", value_name = "SPEC")]
    gate: String,
    /// Image size in pixels, WIDTHxHEIGHT.
    #[arg(long, default_value = "256x256", value_parser = parse_resolution, allow_hyphen_values = true)]
    res: (u32, u32),
    /// Maximum number of scattering vertices of a path (0: only lights seen directly).
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(0..=1_000_000), allow_hyphen_values = true)]
    max_bounces: u32,
    /// Start Russian roulette after this many scattering vertices (off when not given).
    #[arg(long, allow_hyphen_values = true)]
    rr_depth: Option<u32>,
    /// Random seed; equal seeds and settings give identical images at equal samples per pixel.
    #[arg(long, default_value_t = 0, allow_hyphen_values = true)]
    seed: u32,
    /// Thin-lens camera: radius of the lens in metres (0: a pinhole). Overrides the camera
    /// node's extras.aperture_radius; needs a focus distance (--focus-distance or
    /// extras.focus_distance). The lens lies in the plane through the camera node's origin
    /// normal to its viewing direction.
    #[arg(long, value_name = "METRES", allow_hyphen_values = true)]
    aperture_radius: Option<f32>,
    /// Thin-lens camera: distance in metres along the viewing direction from the lens to the
    /// plane in focus. Overrides the camera node's extras.focus_distance.
    #[arg(long, value_name = "METRES", allow_hyphen_values = true)]
    focus_distance: Option<f32>,
}

#[derive(Args)]
struct RenderArgs {
    #[command(flatten)]
    image: ImageArgs,
    /// Sampling method: path (path tracing with next-event estimation and MIS); direct
    /// (bidirectional path tracing, every (s, t) strategy, power-heuristic MIS; at most 24
    /// bounces); ellipsoidal (bidirectional path tracing whose subpaths are joined through a
    /// vertex on the spheroid of a target length drawn from the gate, so every path has a
    /// length the gate weighs; needs a gate; at most 24 bounces); auto (path, direct or,
    /// with a gate, ellipsoidal, whichever a pilot of each on this render measures to have the
    /// lowest variance x time per sample; the pilot renders a smaller image (down to 32x32) from
    /// a seed of its own, takes 5 % of a --time budget (half where one method is 8x ahead of the
    /// others after half its batches), or the work of 1/16 of --spp per method, and is
    /// discarded, so the image is the chosen method's with the same seed; the metadata records
    /// the choice and the pilot's figures). Default: path; for --nlos captures with a gate,
    /// ellipsoidal (see "NLOS captures" in the README).
    #[arg(long, value_enum)]
    method: Option<Method>,
    /// Samples per pixel (default 64 unless --time is given).
    #[arg(long, conflicts_with = "time", allow_hyphen_values = true)]
    spp: Option<u64>,
    /// Render for this many seconds instead of --spp (rendering only: scene loading, BVH build
    /// and kernel builds come first). Passes are sized from the measured rate so the render
    /// ends before the budget, overrunning it by at most one sample per pixel's time.
    #[arg(long, value_name = "SECONDS", allow_hyphen_values = true)]
    time: Option<f64>,
    /// Samples per pixel of one pass, traced together on the GPU when they fit (chosen from the
    /// image size by default). --time renders whole passes.
    #[arg(long, allow_hyphen_values = true)]
    samples_per_pass: Option<u32>,
    /// Print, per (s, t) strategy of a bidirectional method, the connections evaluated, those
    /// skipped (direct: the gate weighs their length zero; ellipsoidal: the spheroid met no
    /// surface) and the shadow rays traced (ellipsoidal: pairs), and for ellipsoidal the loop
    /// iterations (BVH nodes and triangles) and triangles tested and intersected per ellipsoid
    /// query.
    #[arg(long)]
    stats: bool,
    /// Write only the MIS-weighted contribution of strategy S,T (S light-subpath vertices, T
    /// camera-subpath vertices, the pinhole included; direct only). The images of all
    /// strategies of a scene sum to the full render.
    #[arg(long, value_name = "S,T", value_parser = parse_strategy)]
    debug_strategy: Option<(u32, u32)>,
    /// --method ellipsoidal: connections drawn from each ellipsoid query (1 to 8). One BVH traversal
    /// serves K independent points on the spheroid, each weighted 1/K; every point still costs
    /// its shading and two shadow rays. Default 4: it measured about half the error of 1 at
    /// equal time, from 2.5 mm to 50 cm gates and from 12 to 327,692 triangles. For --nlos
    /// captures 1: 0.41x the error of 4 at equal time on a 327,680-triangle hidden object (4 ps
    /// bins), though 2.4x on the example scene's letter.
    #[arg(long, value_name = "K", allow_hyphen_values = true)]
    connections_per_query: Option<u32>,
    /// --method combined: samples per pixel of the ellipsoidal half per sample of the direct half
    /// (dimensionless, 1/8 to 8). Default: a pilot (like auto's, about 5 % of a --time budget)
    /// measures both halves' variance and time per sample and picks the split of least error at
    /// equal time.
    #[arg(long, value_name = "R")]
    ellipsoidal_share: Option<f64>,
    /// --method ellipsoidal: BVH nodes whose box diagonal is at most R times the spheroid's semi-major
    /// axis are entered by a stochastic descent (one child at a time, in proportion to an
    /// estimate of the arcs below it), so a query's work grows with the tree's depth rather
    /// than with the triangles near the spheroid (dimensionless; any R is unbiased, larger is
    /// cheaper and noisier). 0: the exhaustive query, which visits every node the spheroid may
    /// touch.
    #[arg(long, default_value_t = 1.0, value_name = "R")]
    query_split: f32,
    /// --method ellipsoidal: a stochastic descent visits every node of a subtree once it reaches one
    /// of at most N BVH nodes (1: descend to single leaves).
    #[arg(long, default_value_t = 31, value_name = "N")]
    query_bottom_nodes: u32,
    /// --method ellipsoidal: how an ellipsoid query weighs the triangles a spheroid cuts when it picks
    /// one. arcs: by their arcs' angle. reflection: by the angle times a bound on the
    /// contribution per radian (the material's albedo and the cosines towards both foci), zero
    /// only where the contribution is (foci on opposite sides or in the triangle's plane, the
    /// back of a one-sided surface, black). Both are unbiased. Default: reflection for --nlos
    /// captures (on the example capture, 4 ps bins, arcs measured about 900x its error at
    /// equal time), arcs otherwise (0.57x the error of reflection on the Cornell box at a
    /// 2.5 mm gate, 1.1x at 5 and 50 cm).
    #[arg(long, value_name = "WEIGHTS")]
    query_weights: Option<QueryWeights>,
    /// --nlos captures with ellipsoidal on a transient gate: samples per pixel of a pilot
    /// render, traced first and then discarded, whose transient decides how the render's target
    /// lengths visit each pixel's bins: every bin once a cycle, and 7 more visits per bin (at
    /// most 65,535 a cycle), half shared out evenly and half in proportion to the light the
    /// pilot saw near each bin. Unbiased whatever the pilot saw (each bin is divided by its own
    /// visits). 0: no pilot, every bin an equal share. Default 256 (at equal time, 4 ps bins,
    /// K = 1: a quarter of the error on a 327,680-triangle hidden object with --band-index off,
    /// a seventh on the example scene's letter). Needs at most pixels x (bins + 1) x 4 bytes of
    /// device memory in one binding; where that does not fit, the render goes without (the
    /// metadata's target_pilot_spp says 0). With the band index and --max-bounces 3 its masses
    /// share out the visits instead (15 more per bin) and no pilot runs.
    #[arg(long, value_name = "SPP", allow_hyphen_values = true)]
    target_pilot: Option<u32>,
    /// --nlos captures with ellipsoidal on a transient gate: on: builds the band index before
    /// the first pass (per sensed point and bin, the BVH clusters whose triangles reach into the
    /// bin's shell of three-bounce path lengths, with their masses there; device memory: 8
    /// bytes per entry, up to four bindings) and makes each spot-to-sensed-point connection a
    /// shell connection: a point drawn from the index in the bin's shell, whose estimate covers
    /// the whole bin; its masses also share out each pixel's visits to its bins (with
    /// --max-bounces 3, instead of --target-pilot). The hidden scene is prepared for it: closed
    /// double-sided meshes become one-sided, triangles larger than the bins resolve are cut
    /// (the metadata's shell_preparation). off: queries the BVH for every connection (a
    /// stochastic descent). auto (default): on when the scene has more than 64 triangles
    /// besides the relay wall (a smaller one is searched whole by every query, exactly).
    /// Unbiased either way; the build counts in a time budget. A capture goes without it where
    /// it cannot be built completely (the metadata's band_index says why, or gives its size and
    /// build time). On the 327,680-triangle hidden sphere at 4 ps bins and 10 s it has 1/2,400
    /// of the descent's error (README, NLOS captures).
    #[arg(long, value_name = "auto|on|off", default_value = "auto")]
    band_index: OnOff,
    /// --method ellipsoidal, for numerical studies: skip spheroids with tau_e <= d (1 + REL), d the
    /// distance between the foci (dimensionless; f32 cannot place points on thinner ones).
    #[arg(long, default_value_t = 1e-6, value_name = "REL")]
    needle_guard: f32,
    /// --method ellipsoidal, for numerical studies: drop sampled points whose path length misses the
    /// target tau_e by more than REL x tau_e (dimensionless).
    #[arg(long, default_value_t = 1e-5, value_name = "REL")]
    length_guard: f32,
    /// Print the GPU time of every stage (kernel) at the end, measured with timestamp queries
    /// around each dispatch (ms, share, dispatches, mean us per dispatch).
    #[arg(long)]
    profile: bool,
    /// Render a sequence of N frames (see --gate-step); --out then names each frame with
    /// {frame} or {frame:04}. Frame i renders with seed S + i x 0x9E3779B9 (mod 2^32), so frame
    /// 0 is the single image of seed S.
    #[arg(long, default_value_t = 1, value_name = "N", allow_hyphen_values = true)]
    frames: u32,
    /// Move the gate by D per frame: metres of optical path, or with a mm/ps/ns suffix
    /// (negative: earlier). A CW gate's phase moves by -360 f D / c degrees.
    #[arg(long, default_value = "0", value_name = "D", allow_hyphen_values = true)]
    gate_step: String,
    /// Sample the scene's glTF animations (node translation, rotation, scale; all animations on
    /// one clock) at --frames evenly spaced times from T0 to T1 (seconds of the animation
    /// clock; T0 alone for one frame), rebuilding the BVH for every frame.
    #[arg(long, value_name = "T0..T1")]
    anim_time: Option<String>,
    /// Render only frames A..B (0-based, inclusive; or one frame A) of the --frames sequence,
    /// exactly as a full run renders them: split a sequence across processes or machines.
    #[arg(long, value_name = "A..B")]
    frame_range: Option<String>,
    /// Render frames whose output file exists already (by default they are skipped, so an
    /// interrupted sequence resumes where it stopped).
    #[arg(long)]
    force: bool,
    /// Save the render's state to OUT.checkpoint (beside the output) after the first pass that
    /// ends this many seconds after the last save, and once more when the render is done
    /// (0: after every pass). --resume continues from it. Without this option a checkpoint is
    /// written only when the render is interrupted (SIGINT or SIGTERM: the pass in flight
    /// finishes, the image of the samples traced so far is written with them in its metadata,
    /// and gatetrace exits with status 128 + the signal's number; a second signal aborts at
    /// once); a finished render then removes an old checkpoint.
    #[arg(long, value_name = "SECONDS", allow_hyphen_values = true)]
    checkpoint_every: Option<f64>,
    /// Continue the render saved in OUT.checkpoint to the requested samples per pixel (--spp,
    /// counting those already taken, so a larger --spp extends a finished render saved with
    /// --checkpoint-every) or total rendering time (--time). Every other option must be as
    /// when the checkpoint was made (the scene file too); the result is the image the render
    /// would have given without the interruption, bit for bit (--spp; a --time budget stops
    /// where time runs out). For a sequence, frames with a checkpoint are continued and
    /// finished frames skipped.
    #[arg(long)]
    resume: bool,
    /// Render only shard I of N (I from 0) of the image: samples floor(I S / N) to
    /// floor((I + 1) S / N) of each pixel's S = --spp, written to --out (default
    /// SCENE_NAME.shard_I_of_N) as the sums gatetrace merge adds into the image of the unsplit
    /// render, bit for bit, with every method. Run the N shards anywhere (a job array), with
    /// identical other options. Needs --spp; not for sequences, NLOS captures or --method auto
    /// (whose choice depends on timings).
    #[arg(long, value_name = "I/N", value_parser = parse_shard)]
    shard: Option<(u32, u32)>,
    /// Output file: .exr (one layer per transient bin) or .npy (float32 [H, W, 3] or
    /// [H, W, T, 3], row 0 at the top, with a .json sidecar), or .png (an 8-bit sRGB preview,
    /// not data: see --exposure and --preview-bin). Default: SCENE_NAME.exr, or
    /// SCENE_NAME_{frame:04}.exr for a sequence, or SCENE_NAME_nlos.npy for --nlos.
    #[arg(long, short)]
    out: Option<PathBuf>,
    /// Create the output's directory when it does not exist (without this, a missing directory
    /// is an error, so a mistyped path never creates directories).
    #[arg(long)]
    mkdir: bool,
    /// With a .png output: the bin of a transient gate to show (from 0); without it a preview
    /// of a transient is a contact sheet of up to 64 tiles, each the sum of consecutive bins.
    #[arg(long, value_name = "BIN")]
    preview_bin: Option<u32>,
    /// With a .png output: exposure in EV (values are scaled by 2^EV, then clamped to [0, 1]
    /// and sRGB-encoded); default: the 99th percentile of the nonzero values maps to 1. The
    /// preview's metadata records the exposure used.
    #[arg(long, value_name = "EV", allow_hyphen_values = true)]
    exposure: Option<f32>,
    /// Non-line-of-sight capture with this laser scan: single (one laser spot, --laser-spot),
    /// confocal (each sensed point lit by a laser spot on itself, in one render) or
    /// exhaustive (every spot of --laser-grid with every sensed point). --res is then the grid
    /// of sensed points on the relay wall: cell (i, j) is sensed at the wall's texture
    /// coordinates ((i + 0.5) / W, (j + 0.5) / H), and pixel value is the radiance (W m^-2 sr^-1
    /// per bin) leaving that point towards the sensor origin. Path lengths run from the laser spot
    /// to the sensed point (see --count-first-last); --max-bounces counts the spot and the sensed
    /// point (3: the classic three-bounce paths). The scene's own lights and camera are ignored
    /// (and may be absent). Every --method renders captures; ellipsoidal joins the laser spot and
    /// the sensed point through their spheroid of each target length. Output:
    /// NPY [grid_y, grid_x, T, 3], or [laser_y, laser_x, grid_y, grid_x, T, 3] for exhaustive, with
    /// the sensed points and laser spots in the JSON sidecar.
    #[arg(long, value_enum, value_name = "SCAN")]
    nlos: Option<gatetrace::nlos::Scan>,
    /// --nlos: the relay wall's glTF node (a mesh with TEXCOORD_0 over [0, 1]^2).
    #[arg(long, default_value = gatetrace::nlos::DEFAULT_RELAY_WALL, value_name = "NODE")]
    relay_wall: String,
    /// --nlos: where the sensor looks at the wall from, X,Y,Z in metres (default: the node named
    /// sensor_origin, else the one named nlos_origin).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_point, allow_hyphen_values = true)]
    sensor_origin: Option<glam::Vec3>,
    /// --nlos: where the laser beam starts, X,Y,Z in metres (default: the node named
    /// laser_origin, else the one named nlos_origin).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_point, allow_hyphen_values = true)]
    laser_origin: Option<glam::Vec3>,
    /// --nlos single: where the laser is aimed, as texture coordinates U,V of the relay wall.
    #[arg(long, default_value = "0.5,0.5", value_name = "U,V", value_parser = parse_uv)]
    laser_spot: glam::Vec2,
    /// --nlos exhaustive: the grid of laser spots, WIDTHxHEIGHT, at cell centres like the sensed
    /// points (default: --res).
    #[arg(long, value_name = "WxH", value_parser = parse_resolution)]
    laser_grid: Option<(u32, u32)>,
    /// --nlos: the laser beam's power (W).
    #[arg(long, default_value_t = 1.0, value_name = "WATTS", allow_hyphen_values = true)]
    laser_power: f32,
    /// --nlos: count the laser origin -> spot and sensed point -> sensor origin segments in path
    /// lengths (mitransient's account_first_and_last_bounces; off by default, as there).
    #[arg(long)]
    count_first_last: bool,
}

/// The render's shared options read as its own fields (args.gate, args.res, ...).
impl std::ops::Deref for RenderArgs {
    type Target = ImageArgs;

    fn deref(&self) -> &ImageArgs {
        &self.image
    }
}

#[derive(Args)]
struct ViewArgs {
    #[command(flatten)]
    image: ImageArgs,
    /// Sampling method at start; switchable in the window.
    #[arg(long, default_value = "path", value_parser = ViewMethodParser)]
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

/// Parses view --method: the methods the viewer renders progressively, listed with their help
/// from Method; auto and combined, which decide from a pilot per render, are refused with the
/// reason.
#[derive(Clone)]
struct ViewMethodParser;

/// The methods the viewer renders (its window's buttons).
const VIEW_METHODS: [Method; 3] = [Method::Path, Method::Direct, Method::Ellipsoidal];

impl clap::builder::TypedValueParser for ViewMethodParser {
    type Value = Method;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> Result<Method, clap::Error> {
        use clap::ValueEnum as _;
        let pilot = match Method::from_str(&value.to_string_lossy(), false) {
            Ok(method) if VIEW_METHODS.contains(&method) => return Ok(method),
            Ok(Method::Auto) => "auto chooses a method per render from a pilot",
            Ok(Method::Combined) => "combined shares its samples between its halves after a pilot",
            // Anything else: clap's own error, with the possible values.
            _ => {
                let names = self.possible_values().into_iter().flatten();
                let name = clap::builder::PossibleValuesParser::new(names).parse_ref(cmd, arg, value)?;
                return Method::from_str(&name, false)
                    .map_err(|e| clap::Error::raw(clap::error::ErrorKind::InvalidValue, e).with_cmd(cmd));
            }
        };
        let message = format!(
            "--method {}: {pilot}; the viewer renders progressively: start it with path, direct or ellipsoidal\n",
            value.to_string_lossy()
        );
        Err(clap::Error::raw(clap::error::ErrorKind::InvalidValue, message).with_cmd(cmd))
    }

    fn possible_values(&self) -> Option<Box<dyn Iterator<Item = clap::builder::PossibleValue> + '_>> {
        use clap::ValueEnum as _;
        Some(Box::new(VIEW_METHODS.iter().filter_map(|m| m.to_possible_value())))
    }
}

#[derive(Args)]
struct BenchArgs {
    /// Seconds of rendering per measurement (after a discarded warm-up pass).
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Maximum number of scattering vertices.
    #[arg(long, default_value_t = 5)]
    max_bounces: u32,
    /// Methods to measure, comma-separated (as in equal-time --methods).
    #[arg(long, value_delimiter = ',', default_value = "path,direct,ellipsoidal", value_parser = parse_variant)]
    methods: Vec<gatetrace::bench::Variant>,
    /// Image sizes, comma-separated WIDTHxHEIGHT.
    #[arg(long, value_delimiter = ',', default_value = "64x64", value_parser = parse_resolution)]
    res: Vec<(u32, u32)>,
    /// glTF 2.0 scene (default: the Cornell box).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Gate of path and direct (see render --gate; metres of optical path).
    #[arg(long, default_value = "none")]
    gate: String,
    /// Gate of ellipsoidal, which needs one with target lengths: by default the 2.5 mm box of
    /// the README's equal-time figures.
    #[arg(long, default_value = "box:3.16..3.1625")]
    ellipsoidal_gate: String,
    /// Also print each measurement's GPU time per stage (ms; timestamp queries around every
    /// dispatch, which cost a little throughput).
    #[arg(long)]
    profile: bool,
    /// Also write the adapter, the scene (with its load and BVH build time, s) and every
    /// measurement (samples/s, set-up s, GPU ms per stage) to this JSON file.
    #[arg(long, value_name = "FILE.json")]
    json: Option<PathBuf>,
}

/// How ellipsoid queries weigh the triangles they pick from (render --query-weights).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum QueryWeights {
    /// By their arcs' angle.
    Arcs,
    /// By their arcs' angle times a bound on the contribution per radian.
    Reflection,
}

/// A switch that may decide by itself (render --band-index).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum OnOff {
    Auto,
    On,
    Off,
}

#[derive(Args)]
struct EqualTimeArgs {
    /// glTF 2.0 scenes, each compared separately; the Cornell box when omitted.
    scenes: Vec<PathBuf>,
    /// Methods to compare, comma-separated: path, direct, ellipsoidal, auto, and ellipsoidal
    /// (or auto, for its ellipsoidal candidate) with options after colons: K (connections per
    /// query, see render --connections-per-query), exhaustive (render --query-split 0),
    /// split=R, bottom=N or reflection (render --query-weights reflection), e.g.
    /// ellipsoidal:4:exhaustive. auto's pilot counts in its time; the chosen column says
    /// which method each of its renders took.
    #[arg(long, value_delimiter = ',', default_value = "path,direct", value_parser = parse_variant)]
    methods: Vec<gatetrace::bench::Variant>,
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
    /// Renders per method and gate; repeat r of every method renders from the same seed (common
    /// random numbers: auto then shows just what its pilot costs), references from others.
    /// Every method's repeat r runs before any method's repeat r + 1, so a slower stretch of the
    /// device falls on all methods alike.
    #[arg(long, default_value_t = 3)]
    repeats: u32,
    /// Method of the reference images (same syntax as --methods).
    #[arg(long, default_value = "direct", value_parser = parse_variant)]
    reference_method: gatetrace::bench::Variant,
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
    /// seconds, spp, MSE, relative MSE, the reference's noise, and for ellipsoidal the loop
    /// iterations and triangles tested per ellipsoid query).
    #[arg(long)]
    csv: Option<PathBuf>,
}

fn run_stress(args: StressArgs) -> Result<()> {
    use gatetrace::ellipsoid::stress::{Family, Report, compare, generate, run_on_device};
    ensure!(args.configs >= 1, "--configs must be at least 1");
    let ctx = GpuContext::new()?;
    println!("adapter: {}", ctx.adapter_description());
    println!(
        "errors of the device's f32 results against the f64 oracle on the same inputs; \
              guard: fraction of samples with |L(x) - tau_e| > 1e-5 tau_e"
    );
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
    let scenes = if args.scenes.is_empty() { vec![PathBuf::from(DEFAULT_SCENE)] } else { args.scenes.clone() };
    let gates =
        args.gates.split(';').map(|g| Ok((g.trim().to_owned(), Gate::parse(g.trim())?))).collect::<Result<Vec<_>>>()?;
    ensure!(args.seconds > 0.0 && args.reference_seconds > 0.0, "--seconds and --reference-seconds must be positive");
    ensure!(args.repeats >= 1, "--repeats must be at least 1");
    let settings = gatetrace::bench::EqualTimeSettings {
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
    gatetrace::bench::run_equal_time(&scenes, &settings)
}

fn parse_variant(s: &str) -> Result<gatetrace::bench::Variant, String> {
    gatetrace::bench::Variant::parse(s).map_err(|e| e.to_string())
}

fn parse_point(s: &str) -> Result<glam::Vec3, String> {
    let bad = || format!("`{s}` is not X,Y,Z (three finite numbers in metres, e.g. -1.2,0,0.6)");
    let v: Vec<f32> = s.split(',').map(|c| c.trim().parse::<f32>().map_err(|_| bad())).collect::<Result<_, _>>()?;
    match v[..] {
        [x, y, z] if x.is_finite() && y.is_finite() && z.is_finite() => Ok(glam::Vec3::new(x, y, z)),
        _ => Err(bad()),
    }
}

fn parse_uv(s: &str) -> Result<glam::Vec2, String> {
    let bad = || format!("`{s}` is not U,V (two texture coordinates in [0, 1], e.g. 0.5,0.5)");
    let (u, v) = s.split_once(',').ok_or_else(bad)?;
    let (u, v) = (u.trim().parse::<f32>().map_err(|_| bad())?, v.trim().parse::<f32>().map_err(|_| bad())?);
    if !((0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v)) {
        return Err(bad());
    }
    Ok(glam::Vec2::new(u, v))
}

fn parse_strategy(s: &str) -> Result<(u32, u32), String> {
    parse_pair(s, "S,T")
}

fn parse_pixel(s: &str) -> Result<(u32, u32), String> {
    parse_pair(s, "X,Y")
}

fn parse_pair(s: &str, what: &str) -> Result<(u32, u32), String> {
    let bad = || format!("`{s}` is not {what} (two non-negative integers, e.g. 1,2)");
    let (a, b) = s.split_once(',').ok_or_else(bad)?;
    Ok((a.trim().parse().map_err(|_| bad())?, b.trim().parse().map_err(|_| bad())?))
}

fn parse_shard(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("`{s}` is not I/N (the shard index from 0 and the count, e.g. 0/4)");
    let (i, n) = s.split_once('/').ok_or_else(bad)?;
    let (i, n): (u32, u32) = (i.trim().parse().map_err(|_| bad())?, n.trim().parse().map_err(|_| bad())?);
    if n == 0 || i >= n {
        return Err(format!("shard {i}/{n}: give I/N with 0 <= I < N"));
    }
    Ok((i, n))
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
        Command::Render(args) => {
            interrupt::install().context("cannot watch for SIGINT and SIGTERM").and_then(|_| run_render(args))
        }
        Command::View(args) => run_view(args),
        Command::EqualTime(args) => run_equal_time(args),
        Command::StressEllipsoid(args) => run_stress(args),
        Command::Merge(args) => run_merge(args),
        Command::Info(args) => gatetrace::film::info::file_info(&args.file).map(|info| {
            if args.json {
                println!("{}", serde_json::to_string_pretty(&info.to_json()).expect("JSON values"));
            } else {
                print!("{}", info.to_text(&args.file));
            }
        }),
        Command::Bench(args) => {
            let settings = gatetrace::bench::BenchSettings {
                seconds: args.seconds,
                max_bounces: args.max_bounces,
                methods: args.methods,
                resolutions: args.res,
                gates: (args.gate, args.ellipsoidal_gate),
                profile: args.profile,
                json: args.json,
            };
            let scene = args.scene.unwrap_or_else(|| PathBuf::from(DEFAULT_SCENE));
            gatetrace::bench::run_bench(&settings, &scene)
        }
    };
    if let Err(e) = result {
        if let Some(interrupted) = e.downcast_ref::<interrupt::Interrupted>() {
            eprintln!("{e}");
            std::process::exit(128 + interrupted.signal);
        }
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run_view(args: ViewArgs) -> Result<()> {
    use gatetrace::viewer::{ViewOptions, run_viewer};
    let image = &args.image;
    let scene = image.scene.clone().unwrap_or_else(|| PathBuf::from(DEFAULT_SCENE));
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

/// How `render` loads its scene: at animation time `time` (s), as its options say.
fn load_options(args: &RenderArgs, time: Option<f64>) -> LoadOptions {
    LoadOptions { time, capture: false, allow_unsupported_materials: args.allow_unsupported_materials }
}

/// The scene with its camera's lens set by --aperture-radius and --focus-distance, where given
/// (each overrides the glTF camera node's extras; an aperture radius of 0 makes a pinhole).
fn with_lens_options(mut scene: gatetrace::scene::Scene, args: &ImageArgs) -> Result<gatetrace::scene::Scene> {
    scene
        .camera
        .override_lens(args.aperture_radius, args.focus_distance, "--focus-distance METRES")
        .with_context(|| format!("{}: --aperture-radius/--focus-distance", scene.source))?;
    Ok(scene)
}

fn run_render(args: RenderArgs) -> Result<()> {
    let scene_path = args.scene.clone().unwrap_or_else(|| PathBuf::from(DEFAULT_SCENE));
    let gate = Gate::parse(&args.gate).with_context(|| format!("--gate {}", args.gate))?;
    // NLOS captures default to the method the README's capture tables measure as the default.
    let method = args.method.unwrap_or(if args.nlos.is_some() && gate != Gate::None {
        Method::Ellipsoidal
    } else {
        Method::Path
    });
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
        method: method,
        gate: gate.clone(),
        max_bounces: args.max_bounces,
        rr_depth: args.rr_depth,
        seed: args.seed,
        samples_per_pass: args.samples_per_pass,
        light_strategy: LightStrategy::Mis,
        stats: args.stats,
        debug_strategy: args.debug_strategy,
        binding_limit: None,
        connections_per_query: args.connections_per_query.unwrap_or(
            if args.nlos.is_some() && method == Method::Ellipsoidal {
                gatetrace::integrator::bidirectional::DEFAULT_NLOS_CONNECTIONS_PER_QUERY
            } else {
                gatetrace::integrator::bidirectional::default_connections_per_query(method)
            },
        ),
        query: gatetrace::integrator::QuerySettings {
            split: args.query_split,
            bottom_nodes: args.query_bottom_nodes,
            reflection_weights: match args.query_weights {
                Some(weights) => weights == QueryWeights::Reflection,
                None => args.nlos.is_some(),
            },
            ..Default::default()
        },
        ellipsoid_guards: gatetrace::integrator::EllipsoidGuards {
            needle: args.needle_guard,
            length: args.length_guard,
        },
        nlos: None,
        target_pilot_spp: args.target_pilot.unwrap_or(
            if args.nlos.is_some() && method == Method::Ellipsoidal && matches!(gate, Gate::Transient { .. }) {
                gatetrace::integrator::bidirectional::DEFAULT_NLOS_TARGET_PILOT
            } else {
                0
            },
        ),
        band_index: false,
        ellipsoidal_share: args.ellipsoidal_share,
    };
    ensure!(
        args.ellipsoidal_share.is_none() || method == Method::Combined,
        "--ellipsoidal-share applies to --method combined only"
    );
    ensure!(
        settings.target_pilot_spp == 0 || settings.method == Method::Ellipsoidal,
        "--target-pilot applies to --method ellipsoidal only"
    );
    // `auto` is decided once the scene is loaded (run_nlos).
    settings.band_index = args.band_index != OnOff::Off
        && args.nlos.is_some()
        && settings.method == Method::Ellipsoidal
        && matches!(gate, Gate::Transient { .. });
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
            args.nlos.is_none() && !sequence && args.anim_time.is_none(),
            "--shard splits one image: it does not apply to --nlos, --frames, --frame-range or --anim-time"
        );
        ensure!(
            !args.resume && args.checkpoint_every.is_none(),
            "--shard keeps no checkpoint (--resume, --checkpoint-every): rerun an interrupted shard whole"
        );
    }
    if let Some(scan) = args.nlos {
        ensure!(
            args.checkpoint_every.is_none() && !args.resume,
            "--checkpoint-every and --resume do not apply to NLOS captures (--nlos) yet: an interrupted capture writes \
             the samples traced so far (single and confocal scans) but keeps no checkpoint"
        );
        ensure!(
            method != Method::Auto,
            "--method auto does not apply to NLOS captures (--nlos): choose path, direct or ellipsoidal"
        );
        ensure!(
            args.aperture_radius.is_none() && args.focus_distance.is_none(),
            "--aperture-radius and --focus-distance set the camera's lens: an NLOS capture (--nlos) has no camera"
        );
        ensure!(
            !sequence && args.anim_time.is_none(),
            "--nlos renders one capture: --frames, --frame-range and --anim-time do not apply to it"
        );
        return run_nlos(&args, scan, &scene_path, settings, budget);
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
        if settings.debug_strategy.is_some() && settings.method != Method::Direct {
            bail!("--debug-strategy needs --method direct");
        }
        if settings.method != Method::Path {
            gatetrace::integrator::bidirectional::check_settings(&settings)?;
        } else if settings.connections_per_query != 1 {
            bail!("--connections-per-query applies to --method ellipsoidal and combined only");
        }
        film_elements(&settings)?;
        check_writable(&path, args.mkdir)?;
        frames.push((frame, path, settings));
    }

    // A static scene is loaded once; an animated one at every frame's time (checked first).
    let static_scene = match plan.anim_time {
        None => Some(PreparedScene::new(with_lens_options(
            load_gltf_with(&scene_path, &load_options(&args, None))?,
            &args,
        )?)?),
        Some(_) => {
            with_lens_options(load_gltf_with(&scene_path, &load_options(&args, plan.anim_time(plan.range.0)))?, &args)?;
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
        return render_shard(&ctx, scene, &scene_path, &args, shard, settings, total, path, &bars);
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
                        load_gltf_with(&scene_path, &load_options(&args, plan.anim_time(*frame)))?,
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

/// Renders an NLOS capture (`--nlos`): one render for a single or confocal scan, one per laser
/// spot for an exhaustive one; writes the transients with the sensed points and laser spots.
fn run_nlos(
    args: &RenderArgs,
    scan: gatetrace::nlos::Scan,
    scene_path: &Path,
    base: RenderSettings,
    budget: Budget,
) -> Result<()> {
    use gatetrace::nlos::{self, LaserAim, NlosCapture, Scan};
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

/// Renders shard `index` of `count` of the image: samples floor(index total / count) to
/// floor((index + 1) total / count) of each pixel, written to `out` as a state file with the
/// image's metadata for `gatetrace merge`.
#[allow(clippy::too_many_arguments)]
fn render_shard(
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
fn run_merge(args: MergeArgs) -> Result<()> {
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

    let gate = &settings.gate;
    let film = &output.film;
    let secs = output.elapsed.as_secs_f64();
    let mut metadata = render_metadata(ctx, scene_path, gate_spec, settings, &output);
    metadata.push(("camera".into(), scene.scene.camera.describe().into()));
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
        say(bars, format!("auto chose {}: {}", choice.chosen.name(), choice.reason))?;
    }
    if let Some(allocation) = &output.allocation {
        say(bars, format!("combined: {}", allocation.reason))?;
    }
    print_stats(settings, &output);
    Ok(())
}

/// Prints the method's `--stats` report, or says that it keeps none.
fn print_stats(settings: &RenderSettings, output: &gatetrace::integrator::RenderOutput) {
    if let Some(report) = &output.stats {
        print!("{report}");
    } else if settings.stats {
        println!("--stats: method {} keeps no per-strategy statistics", settings.method.name());
    }
}

/// Prints a line to stdout, above the progress bars when they are shown.
fn say(bars: &indicatif::MultiProgress, line: String) -> Result<()> {
    if bars.is_hidden() {
        println!("{line}");
    } else {
        bars.println(line)?;
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
