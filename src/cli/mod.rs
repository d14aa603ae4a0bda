//! The `gatetrace` command line: the subcommands' arguments, and one module per subcommand that
//! checks them and calls the library (render with its NLOS captures and shards, view with its
//! window, bench, equal-time, stress-ellipsoid, merge, info), with the progress and report
//! printing they share.

pub mod args;
pub mod bench;
pub mod equal_time;
pub mod info;
pub mod interrupt;
pub mod merge;
pub mod nlos;
pub mod parse;
pub mod render;
pub mod report;
pub mod stress;
pub mod view;
pub mod viewer;

use clap::{CommandFactory as _, FromArgMatches as _, Parser, Subcommand};

/// The scene rendered when none is given.
pub const DEFAULT_SCENE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/assets/scenes/cornell_box.gltf");

/// gatetrace: a physically based GPU renderer for time-of-flight cameras.
///
/// Time is optical path length (OPL) in metres, with c = 1: a path's length runs from the point
/// on the light through every scattering vertex to the camera's pinhole. Wherever a length is
/// asked for, ps and ns suffixes give times instead (c = 0.299792458 mm/ps).
#[derive(Parser)]
#[command(version, about, long_about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

impl Cli {
    /// The command line, with each image command's record of the options it gave (so a scene
    /// file's settings can fill the others).
    pub fn parse_recording() -> Cli {
        let matches = Cli::command().get_matches();
        let mut cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
        match (&mut cli.command, matches.subcommand()) {
            (Command::Render(args), Some((_, m))) => args.image.record_given(m),
            (Command::View(args), Some((_, m))) => args.image.record_given(m),
            _ => {}
        }
        cli
    }
}

// The command is parsed once per process: boxing the large variants would save nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
pub enum Command {
    /// Render an image (or a transient cube, or a sequence of frames) to EXR or NPY, or a PNG
    /// preview.
    Render(args::RenderArgs),
    /// Open the interactive viewer: scrub the gate through time and watch light move; click a
    /// pixel for its transient response.
    ///
    /// It takes render's gates, with the same defaults: a box or Gaussian gate is scrubbed by its
    /// centre tau, a table gate by moving the whole table, a CW gate by its phase; a transient
    /// gate renders its whole cube and a slider picks the bin shown (--bin at start). Signed
    /// gates (CW, tables with negative weights) show the luminance on a diverging map: orange
    /// above zero, blue below, black at zero.
    View(view::ViewArgs),
    /// Measure samples per second of each method on a scene (tools/peer/throughput.py adds
    /// Mitsuba 3 + mitransient's in the same run).
    Bench(bench::BenchArgs),
    /// Render a scene with several methods for the same wall time each and report their mean
    /// squared error against a long reference render (error at equal time).
    EqualTime(equal_time::EqualTimeArgs),
    /// Compare the kernels' f32 ellipsoid code with the f64 oracle on many random and
    /// adversarial configurations and print the error distributions per family.
    StressEllipsoid(stress::StressArgs),
    /// Combine the shards of a render (render --shard I/N, one file each) into the image the
    /// unsplit render gives, bit for bit; refuses parts of different renders, missing or
    /// repeated shards.
    Merge(merge::MergeArgs),
    /// Say what an output holds: its layout, the gate (as typed and in metres), the units and
    /// how it was rendered, from the file and its metadata (.npy with its .json sidecar, .exr,
    /// or a .png preview).
    Info(info::InfoArgs),
}
