//! `gatetrace bench`: samples per second of the path tracer on the Cornell box.

use std::path::Path;
use std::time::Duration;

use anyhow::Result;

use crate::film::Gate;
use crate::gpu::GpuContext;
use crate::integrator::{Budget, Method, RenderSettings, render};
use crate::scene::{PreparedScene, load_gltf};

/// Renders the scene with `path` at 64x64 and 256x256 for `seconds` each (after a one-wave
/// warm-up) and prints pixel samples per second with the adapter's name.
pub fn run_bench(seconds: f64, max_bounces: u32, scene_path: &Path) -> Result<()> {
    let scene = PreparedScene::new(load_gltf(scene_path)?)?;
    let ctx = GpuContext::new()?;
    println!("adapter: {}", ctx.adapter_description());
    println!("scene: {} ({} triangles), method path, gate none, max bounces {max_bounces}", scene_path.display(), scene.triangles.len());
    println!("{:>10} {:>8} {:>10} {:>14}", "resolution", "spp", "seconds", "Msamples/s");
    for size in [64u32, 256] {
        let settings = RenderSettings {
            width: size,
            height: size,
            method: Method::Path,
            gate: Gate::None,
            max_bounces,
            ..Default::default()
        };
        render(&ctx, &scene, &settings, Budget::Samples(1), |_| {})?;
        let out = render(&ctx, &scene, &settings, Budget::Time(Duration::from_secs_f64(seconds)), |_| {})?;
        let samples = out.film.spp as f64 * (size * size) as f64;
        println!(
            "{:>10} {:>8} {:>10.2} {:>14.3}",
            format!("{size}x{size}"),
            out.film.spp,
            out.elapsed.as_secs_f64(),
            samples / out.elapsed.as_secs_f64() / 1e6
        );
    }
    Ok(())
}
