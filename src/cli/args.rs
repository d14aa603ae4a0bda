//! The arguments of `gatetrace render`, and the image options it shares with `gatetrace view`.
//! Help is one or two lines an option, with units; README.md and docs/ explain the methods, gates and
//! NLOS captures at length. The options shared with view end their help with `{n}`, so that
//! their defaults show on lines of their own in both commands' help.

use std::path::PathBuf;

use gatetrace::integrator::Method;
use gatetrace::nlos::Scan;
use gatetrace::scene::{LoadOptions, SceneSettings};

use super::parse::{
    MethodParser, NamesOnly, parse_define, parse_fog, parse_point, parse_resolution, parse_shard, parse_strategy,
    parse_uv,
};

/// What both render and view render: the scene, its camera's lens, the gate, the image and
/// the paths. One definition of each option, so both commands take the same options with the
/// same defaults.
#[derive(clap::Args)]
pub struct ImageArgs {
    /// glTF 2.0 scene (.gltf, .glb) or Mitsuba 3 XML scene, whose film, sampler and integrator
    /// set the defaults of --res, --spp, --max-bounces, --gate and --seed (default: the Cornell box)
    pub scene: Option<PathBuf>,
    /// Render transmissive glTF materials as opaque, with a warning, instead of refusing them.
    #[arg(long)]
    pub allow_unsupported_materials: bool,
    /// A Mitsuba XML scene's parameter: VALUE replaces the file's default for $NAME (repeatable).
    #[arg(long, short = 'D', value_name = "NAME=VALUE", value_parser = parse_define)]
    pub define: Vec<(String, String)>,
    /// Fill the scene with homogeneous fog: extinction SIGMA_T (m^-1; a visibility V in metres is
    /// about 3.9 / V), single-scattering ALBEDO (0..1, default 0.9) and Henyey-Greenstein mean
    /// cosine G (default 0.8, forward); rendered by --method path, direct or ellipsoidal{n}
    #[arg(long, value_name = "SIGMA_T[,ALBEDO[,G]]", value_parser = parse_fog)]
    pub fog: Option<gatetrace::scene::MediumDesc>,
    /// Pathlength importance W, lengths in metres of optical path or with a ps/ns/mm suffix: none;
    /// box:A..B (W = 1 on [A, B)); gaussian:MU,SIGMA; cw:FREQ_HZ,PHASE_DEG[,CODE] (signed);
    /// table:FILE.csv (length,weight rows); transient:START,WIDTH,BINS (a cube of BINS images){n}
    #[arg(long, default_value = "none", value_name = "SPEC")]
    pub gate: String,
    /// Image size in pixels, WIDTHxHEIGHT{n}
    #[arg(long, default_value = "256x256", value_parser = parse_resolution, allow_hyphen_values = true)]
    pub res: (u32, u32),
    /// Maximum number of scattering vertices of a path (0: only lights seen directly){n}
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(0..=1_000_000), allow_hyphen_values = true)]
    pub max_bounces: u32,
    /// Start Russian roulette after this many scattering vertices (off when not given).
    #[arg(long, allow_hyphen_values = true)]
    pub rr_depth: Option<u32>,
    /// Random seed; equal seeds and settings give identical images at equal samples per pixel{n}
    #[arg(long, default_value_t = 0, allow_hyphen_values = true)]
    pub seed: u32,
    /// Thin-lens camera: lens radius in metres (0: a pinhole; overrides the camera's extras).
    #[arg(long, value_name = "METRES", allow_hyphen_values = true)]
    pub aperture_radius: Option<f32>,
    /// Thin-lens camera: distance to the plane in focus in metres (overrides the camera's extras).
    #[arg(long, value_name = "METRES", allow_hyphen_values = true)]
    pub focus_distance: Option<f32>,
    /// The options the command line gave; the others may take the scene file's settings.
    #[arg(skip)]
    pub given: Vec<String>,
}

impl ImageArgs {
    /// Records which options the command line gave (`matches`: the subcommand's).
    pub fn record_given(&mut self, matches: &clap::ArgMatches) {
        self.given = matches
            .ids()
            .filter(|id| matches.value_source(id.as_str()) == Some(clap::parser::ValueSource::CommandLine))
            .map(|id| id.as_str().to_owned())
            .collect();
    }

    /// True when the command line gave the option with id `id` (the field's name).
    pub fn was_given(&self, id: &str) -> bool {
        self.given.iter().any(|g| g == id)
    }

    /// Takes the scene file's render settings (a Mitsuba scene's film, sampler and integrator)
    /// for the options the command line did not give; returns them (the samples per pixel and
    /// the capture are the caller's to take).
    pub fn take_scene_settings(&mut self, scene: &std::path::Path) -> anyhow::Result<SceneSettings> {
        let settings = gatetrace::scene::scene_settings(scene, &self.define)?;
        if let Some(gate) = settings.gate.clone().filter(|_| !self.was_given("gate")) {
            self.gate = gate;
        }
        if let Some(res) = settings.resolution.filter(|_| !self.was_given("res")) {
            self.res = res;
        }
        if let Some(bounces) = settings.max_bounces.filter(|_| !self.was_given("max_bounces")) {
            self.max_bounces = bounces;
        }
        if let Some(seed) = settings.seed.filter(|_| !self.was_given("seed")) {
            self.seed = seed;
        }
        Ok(settings)
    }
}

#[derive(clap::Args)]
pub struct RenderArgs {
    #[command(flatten)]
    pub image: ImageArgs,
    /// Sampling method: path, direct (bidirectional), ellipsoidal (via the gate's spheroids),
    /// combined or auto (a pilot's pick). Default: path; for --nlos captures with a gate, ellipsoidal.
    #[arg(long, value_parser = MethodParser::ALL)]
    pub method: Option<Method>,
    /// Samples per pixel (default 64 unless --time is given).
    #[arg(long, conflicts_with = "time", allow_hyphen_values = true)]
    pub spp: Option<u64>,
    /// Render for this many seconds instead of --spp (rendering and pilots only, in whole passes of
    /// every pixel, at least one: a warning says when a pass ran well past it).
    #[arg(long, value_name = "SECONDS", allow_hyphen_values = true)]
    pub time: Option<f64>,
    /// Samples per pixel of one pass (default: chosen from the image size).
    #[arg(long, allow_hyphen_values = true)]
    pub samples_per_pass: Option<u32>,
    /// Print a bidirectional method's statistics per strategy (connections, ellipsoid queries).
    #[arg(long)]
    pub stats: bool,
    /// Write only the MIS-weighted contribution of strategy S,T (direct only).
    #[arg(long, value_name = "S,T", value_parser = parse_strategy)]
    pub debug_strategy: Option<(u32, u32)>,
    /// Ellipsoidal connections drawn from each ellipsoid query, 1 to 8 (default 4; 1 for --nlos).
    #[arg(long, value_name = "K", allow_hyphen_values = true)]
    pub connections_per_query: Option<u32>,
    /// --method combined: ellipsoidal samples per direct sample, 1/8 to 8 (default: from a pilot).
    #[arg(long, value_name = "R")]
    pub ellipsoidal_share: Option<f64>,
    /// --method ellipsoidal or combined: probability, 1/16 to 1, with which a sample makes each ellipsoid query
    /// for paths of two or more scattering vertices (weighted by its inverse; default: from a
    /// pilot with --time, 1 with --spp)
    #[arg(long, value_name = "P")]
    pub query_roulette: Option<f32>,
    /// Ellipsoid queries descend stochastically below BVH nodes of diagonal <= R x semi-major axis
    #[arg(long, default_value_t = 1.0, value_name = "R")]
    pub query_split: f32,
    /// Ellipsoid queries: the stochastic descent visits whole subtrees of at most N BVH nodes
    /// (binary nodes; the wide tree's subtrees hold about as many leaves)
    #[arg(long, default_value_t = 31, value_name = "N")]
    pub query_bottom_nodes: u32,
    /// Ellipsoid queries walk the binary BVH, or the four-wide one the rays traverse (slower on
    /// CPU Vulkan)
    #[arg(long, value_name = "TREE", value_enum, default_value = "binary")]
    pub query_tree: QueryTree,
    /// Ellipsoid queries pick triangles by arc angle, or times a bound on the reflected light
    /// (default: reflection for --nlos, else arcs).
    #[arg(long, value_name = "WEIGHTS", value_enum)]
    pub query_weights: Option<QueryWeights>,
    /// --nlos, ellipsoidal, transient gate: spp of a pilot that shares out the bins' samples
    /// (default 256; with a band index and --max-bounces 3 its masses do, and no pilot runs;
    /// with --time it stops after an eighth of the budget).
    #[arg(long, value_name = "SPP", allow_hyphen_values = true)]
    pub target_pilot: Option<u32>,
    /// direct, one-bin gate: spp of a pilot (then discarded) whose per-pixel variance shares
    /// each pixel's light between camera paths and light tracing in the MIS weights (default 4
    /// with --time or from 256 spp, else 0; with --time no pass starts after 1/8 of the budget).
    #[arg(long, value_name = "SPP")]
    pub camera_pilot: Option<u32>,
    /// --nlos, ellipsoidal, transient gate: connect through the band index of three-bounce
    /// shells (auto: on above 16 hidden triangles; with --time, not where its build would
    /// outlast the budget)
    #[arg(long, value_name = "auto|on|off", default_value = "auto", value_enum)]
    pub band_index: OnOff,
    /// path, homogeneous media, box or transient gate: also place scattering vertices where a
    /// ray meets the spheroid of a length drawn from the gate (medium connections)
    #[arg(long, value_name = "on|off", default_value = "off", value_enum)]
    pub medium_connections: Switch,
    /// Ellipsoid queries: skip spheroids with tau_e <= d (1 + REL), d the foci's distance
    #[arg(long, default_value_t = 1e-6, value_name = "REL")]
    pub needle_guard: f32,
    /// Ellipsoid queries: drop points whose length misses tau_e by more than REL x tau_e
    #[arg(long, default_value_t = 1e-5, value_name = "REL")]
    pub length_guard: f32,
    /// Print the GPU time of every stage at the end (ms, share, dispatches).
    #[arg(long)]
    pub profile: bool,
    /// Render a sequence of N frames, named by {frame} or {frame:04} in --out
    #[arg(long, default_value_t = 1, value_name = "N", allow_hyphen_values = true)]
    pub frames: u32,
    /// Move the gate by D per frame (metres of optical path, or with a mm/ps/ns suffix)
    #[arg(long, default_value = "0", value_name = "D", allow_hyphen_values = true)]
    pub gate_step: String,
    /// Pose the scene's glTF animations at --frames evenly spaced times from T0 to T1 (s).
    #[arg(long, value_name = "T0..T1")]
    pub anim_time: Option<String>,
    /// Render only frames A..B (0-based, inclusive) of the sequence, as a full run renders them.
    #[arg(long, value_name = "A..B")]
    pub frame_range: Option<String>,
    /// Render frames whose output exists already (by default they are skipped).
    #[arg(long)]
    pub force: bool,
    /// Save the state to OUT.checkpoint every SECONDS (0: every pass; interrupted renders save one).
    #[arg(long, value_name = "SECONDS", allow_hyphen_values = true)]
    pub checkpoint_every: Option<f64>,
    /// Continue the render saved in OUT.checkpoint to --spp or --time (other options unchanged).
    #[arg(long)]
    pub resume: bool,
    /// Render only shard I of N (from 0) of the --spp samples, for gatetrace merge.
    #[arg(long, value_name = "I/N", value_parser = parse_shard)]
    pub shard: Option<(u32, u32)>,
    /// Output: .exr, .npy (float32 [H, W, 3] or [H, W, T, 3], with a .json sidecar) or .png (a
    /// preview). Default: SCENE_NAME.exr, SCENE_NAME_{frame:04}.exr, or SCENE_NAME_nlos.npy.
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// Create the output's directory when it does not exist.
    #[arg(long)]
    pub mkdir: bool,
    /// With a .png output: the transient bin to show (default: a contact sheet of the bins).
    #[arg(long, value_name = "BIN")]
    pub preview_bin: Option<u32>,
    /// With a .png output: exposure in EV (default: the 99th percentile maps to 1).
    #[arg(long, value_name = "EV", allow_hyphen_values = true)]
    pub exposure: Option<f32>,
    /// NLOS capture of --res relay-wall points lit by one spot (single), each on itself
    /// (confocal) or every --laser-grid spot (exhaustive).
    #[arg(long, value_name = "SCAN", value_parser = NamesOnly::<Scan>::new())]
    pub nlos: Option<Scan>,
    /// --nlos: the relay wall's node (a glTF mesh with TEXCOORD_0 over [0, 1]^2; default: a
    /// Mitsuba capture's, else relay_wall)
    #[arg(long, default_value = gatetrace::nlos::DEFAULT_RELAY_WALL, value_name = "NODE")]
    pub relay_wall: String,
    /// --nlos: the sensor's position, X,Y,Z in metres (default: a Mitsuba capture's, else node
    /// sensor_origin or nlos_origin).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_point, allow_hyphen_values = true)]
    pub sensor_origin: Option<glam::Vec3>,
    /// --nlos: the laser's position, X,Y,Z in metres (default: a Mitsuba capture's, else node
    /// laser_origin or nlos_origin).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_point, allow_hyphen_values = true)]
    pub laser_origin: Option<glam::Vec3>,
    /// --nlos single: where the laser is aimed, texture coordinates U,V of the relay wall
    /// (default: a Mitsuba capture's aim, else 0.5,0.5)
    #[arg(long, default_value = "0.5,0.5", value_name = "U,V", value_parser = parse_uv)]
    pub laser_spot: glam::Vec2,
    /// --nlos exhaustive: the grid of laser spots, WIDTHxHEIGHT (default: a Mitsuba capture's, else
    /// --res).
    #[arg(long, value_name = "WxH", value_parser = parse_resolution)]
    pub laser_grid: Option<(u32, u32)>,
    /// --nlos: the laser beam's power (W; default 1, or a Mitsuba capture's projector)
    #[arg(long, default_value_t = 1.0, value_name = "WATTS", allow_hyphen_values = true)]
    pub laser_power: f32,
    /// --nlos: count the laser -> spot and sensed point -> sensor segments in path lengths
    /// (also when a Mitsuba capture's account_first_and_last_bounces is true).
    #[arg(long)]
    pub count_first_last: bool,
}

impl RenderArgs {
    /// How `render` loads its scene: at animation time `time` (s), as its options say.
    pub fn load_options(&self, time: Option<f64>) -> LoadOptions {
        LoadOptions {
            time,
            capture: false,
            allow_unsupported_materials: self.allow_unsupported_materials,
            parameters: self.define.clone(),
            fog: self.fog.clone(),
        }
    }
}

/// The render's shared options read as its own fields (args.gate, args.res, ...).
impl std::ops::Deref for RenderArgs {
    type Target = ImageArgs;

    fn deref(&self) -> &ImageArgs {
        &self.image
    }
}

/// How ellipsoid queries weigh the triangles they pick from (render --query-weights): by their
/// arcs' angle, or by the angle times a bound on the contribution per radian.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum QueryWeights {
    Arcs,
    Reflection,
}

/// Which BVH the ellipsoid queries walk (render --query-tree).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum QueryTree {
    Binary,
    Wide,
}

/// A switch (render --medium-connections).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Switch {
    On,
    Off,
}

/// A switch that may decide by itself (render --band-index).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum OnOff {
    Auto,
    On,
    Off,
}
