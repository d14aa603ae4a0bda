//! `gatetrace bench`: samples per second of the path tracer on the Cornell box.

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Result;

use crate::gpu::GpuContext;
use crate::integrator::{RenderSettings, create_integrator};
use crate::scene::{PreparedScene, load_gltf};

/// Renders the scene with `path` (steady state) at 64x64 and 256x256 and prints pixel samples
/// per second with the adapter's name. Each measurement builds its tracer, renders one warm-up
/// pass, then times whole passes for at least `seconds` (upload and kernel builds excluded).
pub fn run_bench(seconds: f64, max_bounces: u32, scene_path: &Path) -> Result<()> {
    let scene = PreparedScene::new(load_gltf(scene_path)?)?;
    let ctx = GpuContext::new()?;
    println!("adapter: {}", ctx.adapter_description());
    println!(
        "scene: {} ({} triangles), method path, gate none, max bounces {max_bounces}",
        scene_path.display(),
        scene.triangles.len()
    );
    println!("{:>10} {:>8} {:>10} {:>14}", "resolution", "spp", "seconds", "Msamples/s");
    for size in [64u32, 256] {
        let settings = RenderSettings { width: size, height: size, max_bounces, ..Default::default() };
        let mut tracer = create_integrator(&ctx, &scene, &settings)?;
        tracer.render_pass(tracer.samples_per_pass())?;
        tracer.reset_film();
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs_f64(seconds) {
            tracer.render_pass(tracer.samples_per_pass())?;
        }
        let elapsed = start.elapsed().as_secs_f64();
        let samples = tracer.samples_done() as f64 * (size * size) as f64;
        println!(
            "{:>10} {:>8} {:>10.2} {:>14.3}",
            format!("{size}x{size}"),
            tracer.samples_done(),
            elapsed,
            samples / elapsed / 1e6
        );
    }
    Ok(())
}
