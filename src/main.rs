//! The `gatetrace` command: parses the command line and runs the subcommand (module cli).

mod cli;

use anyhow::Context as _;
use cli::{Cli, Command, interrupt};

fn main() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        // Mesa's Vulkan driver probes for a Wayland display and complains when this is unset;
        // a headless render needs none.
        // SAFETY: nothing else runs yet: main has not started any thread.
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir()) };
    }
    let result = match Cli::parse_recording().command {
        Command::Render(args) => {
            interrupt::install().context("cannot watch for SIGINT and SIGTERM").and_then(|_| cli::render::run(args))
        }
        Command::View(args) => cli::view::run(args),
        Command::EqualTime(args) => cli::equal_time::run(args),
        Command::StressEllipsoid(args) => cli::stress::run(args),
        Command::Merge(args) => cli::merge::run(args),
        Command::Info(args) => cli::info::run(args),
        Command::Bench(args) => cli::bench::run(args),
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
