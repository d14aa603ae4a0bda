//! What the renders print as they go and when done: progress bars, lines printed above them,
//! and the `--stats` report.

use anyhow::Result;
use gatetrace::integrator::{Budget, RenderSettings};

/// Prints the method's `--stats` report, or says that it keeps none.
pub fn print_stats(settings: &RenderSettings, output: &gatetrace::integrator::RenderOutput) {
    if let Some(report) = &output.stats {
        print!("{report}");
    } else if settings.stats {
        println!("--stats: method {} keeps no per-strategy statistics", settings.method.name());
    }
}

/// Prints the library's warnings (a scene's load warnings, a render's) as `warning: ...` lines on
/// stderr.
pub fn print_warnings<'a>(warnings: impl IntoIterator<Item = &'a String>) {
    for warning in warnings {
        eprintln!("warning: {warning}");
    }
}

/// Prints a line to stdout, above the progress bars when they are shown.
pub fn say(bars: &indicatif::MultiProgress, line: String) -> Result<()> {
    if bars.is_hidden() {
        println!("{line}");
    } else {
        bars.println(line)?;
    }
    Ok(())
}

/// A progress bar over the samples per pixel or the milliseconds of the budget.
pub fn progress_bar(budget: Budget) -> indicatif::ProgressBar {
    let (len, unit) = match budget {
        Budget::Samples(n) => (n, "spp"),
        Budget::Time(t) => (t.as_millis() as u64, "ms"),
    };
    let bar = indicatif::ProgressBar::new(len);
    let template = format!("{{elapsed_precise}} [{{bar:30}}] {{pos}}/{{len}} {unit} {{msg}} (ETA {{eta}})");
    bar.set_style(indicatif::ProgressStyle::with_template(&template).unwrap().progress_chars("=> "));
    bar
}
