//! Shared helpers of the integration tests.
#![allow(dead_code)]

pub mod gltf_builder;
pub mod stats;

use std::path::{Path, PathBuf};

use gatetrace::film::Film;
use gatetrace::gpu::GpuContext;
use gatetrace::integrator::{PathTracer, RenderSettings};
use gatetrace::scene::{PreparedScene, load_gltf};
use stats::BatchStats;

/// The device every GPU test uses. Without an adapter the test fails (never skips).
pub fn gpu() -> GpuContext {
    match GpuContext::new() {
        Ok(ctx) => ctx,
        Err(e) => panic!("GPU tests need a Vulkan adapter (CI installs lavapipe): {e:#}"),
    }
}

pub fn repo_path(relative: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(relative)
}

pub fn cornell_box() -> PreparedScene {
    PreparedScene::new(load_gltf(&repo_path("assets/scenes/cornell_box.gltf")).unwrap()).unwrap()
}

/// Renders `batches` independent films of `spp` samples per pixel each and returns the
/// per-element mean and variance of the mean over batches.
pub fn render_batches(
    ctx: &GpuContext,
    scene: &PreparedScene,
    settings: &RenderSettings,
    batches: usize,
    spp: u32,
) -> BatchStats {
    let films = render_films(ctx, scene, settings, batches, spp);
    let mut stats = BatchStats::new(films[0].data.len());
    for film in &films {
        stats.add(&film.data);
    }
    stats
}

/// Renders `batches` films of `spp` each and returns them (for image-level statistics).
pub fn render_films(
    ctx: &GpuContext,
    scene: &PreparedScene,
    settings: &RenderSettings,
    batches: usize,
    spp: u32,
) -> Vec<Film> {
    let mut tracer = PathTracer::new(ctx, scene, settings).unwrap();
    (0..batches)
        .map(|_| {
            tracer.render_samples(spp as u64).unwrap();
            let film = tracer.film().unwrap();
            assert!(film.all_finite(), "non-finite pixel values");
            tracer.reset_film();
            film
        })
        .collect()
}

/// Reads a reference array from tests/data.
pub fn reference(relative: &str) -> (Vec<usize>, Vec<f32>) {
    gatetrace::film::output::read_npy_f32(&repo_path(&format!("tests/data/{relative}"))).unwrap()
}

/// Writes actual, reference and difference arrays of a failing image test to
/// target/test-failures/NAME_{actual,reference,difference}.npy and returns the directory.
pub fn write_failure_images(name: &str, shape: &[usize], actual: &[f32], reference: &[f32]) -> PathBuf {
    let dir = repo_path("target/test-failures");
    std::fs::create_dir_all(&dir).unwrap();
    let diff: Vec<f32> = actual.iter().zip(reference).map(|(a, b)| a - b).collect();
    for (suffix, data) in [("actual", actual), ("reference", reference), ("difference", &diff[..])] {
        gatetrace::film::output::write_npy_f32(&dir.join(format!("{name}_{suffix}.npy")), shape, data).unwrap();
    }
    dir
}

/// A fresh empty directory under target/test-scratch for files a test writes.
pub fn scratch_dir(name: &str) -> PathBuf {
    let dir = repo_path("target/test-scratch").join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs test-only probe kernel `kernel` over `input` records with the resources and
/// specialisation of `tracer` (plus `extra` constants) and returns `outputs` output records.
pub fn run_probe(
    ctx: &GpuContext,
    tracer: &PathTracer,
    kernel: &str,
    extra: &[(&'static str, f64)],
    input: &[[f32; 4]],
    outputs: usize,
) -> Vec<[f32; 4]> {
    use gatetrace::gpu::{Kernel, resources::read_buffer};
    let mut resources = tracer.resources().clone();
    resources.storage_init(ctx, "probe_input", input).unwrap();
    resources.storage_zeroed(ctx, "probe_output", 16 * outputs as u64, wgpu::BufferUsages::empty()).unwrap();
    let mut constants = tracer.constants().to_vec();
    constants.extend_from_slice(extra);
    let k = Kernel::new(ctx, kernel, None, &constants);
    let bind_group = k.bind(ctx, &resources);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        k.dispatch(&mut pass, &bind_group, outputs as u32);
    }
    ctx.queue.submit([encoder.finish()]);
    read_buffer(ctx, resources.get("probe_output").unwrap(), outputs).unwrap()
}
