//! `gatetrace stress-ellipsoid`: the kernels' f32 ellipsoid code against the f64 oracle on
//! random and adversarial configurations, with the error distributions per family.

use anyhow::{Result, ensure};
use gatetrace::gpu::GpuContext;

#[derive(clap::Args)]
pub struct StressArgs {
    /// Configurations of the random family; each adversarial family gets a quarter as many.
    #[arg(long, default_value_t = 1_000_000)]
    configs: usize,
    /// Seed of the configurations.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

/// `gatetrace stress-ellipsoid`.
pub fn run(args: StressArgs) -> Result<()> {
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
