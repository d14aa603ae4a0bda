//! The Cornell box against the peer reference (Mitsuba 3.9.1 + mitransient 1.3.1, 131k spp;
//! tests/data/cornell_box_peer/README.md): image means per channel, 8x8-pixel block means, and
//! the transient cube per bin. Our variance comes from independent batches; a z-score divides a
//! difference by the combined standard error of both sides.

mod common;

use common::stats::{sidak, t_critical};
use gatetrace::film::{Film, Gate};
use gatetrace::integrator::{Method, RenderSettings};

/// Family-wise false-alarm rate of every multi-comparison in this file.
const ALPHA: f64 = 0.01;
const BATCHES: usize = 16;

/// The peer's settings: 64x64, at most 5 bounces (max_depth 6), no Russian roulette.
fn settings(gate: Gate, seed: u32) -> RenderSettings {
    RenderSettings { width: 64, height: 64, max_bounces: 5, gate, seed, ..Default::default() }
}

/// Per-element mean over batches, as f32 (for failure images).
fn batch_mean(films: &[Film]) -> Vec<f32> {
    let mut stats = common::stats::BatchStats::new(films[0].data.len());
    for f in films {
        stats.add(&f.data);
    }
    stats.mean().iter().map(|&v| v as f32).collect()
}

/// Sums over groups of elements: `group(i)` gives the group of element i (None: skip).
fn group_sums(values: &[f64], groups: usize, group: impl Fn(usize) -> Option<usize>) -> Vec<f64> {
    let mut out = vec![0.0; groups];
    for (i, v) in values.iter().enumerate() {
        if let Some(g) = group(i) {
            out[g] += v;
        }
    }
    out
}

/// Compares group means (the image mean per channel, or block means) of our batches with the
/// peer's; returns the z-scores. The variance of a group mean is the variance over batches of
/// the group's batch means (so pixel correlations are included); the peer's variance of a group
/// mean adds its per-pixel variances (independent pixels).
fn group_z(films: &[Film], peer_mean: &[f32], peer_var: &[f32], groups: usize, group: impl Fn(usize) -> Option<usize> + Copy) -> Vec<(f64, f64, f64)> {
    let n = films.len() as f64;
    let count = group_sums(&vec![1.0; peer_mean.len()], groups, group);
    let ours: Vec<Vec<f64>> = films
        .iter()
        .map(|f| {
            let data: Vec<f64> = f.data.iter().map(|&v| v as f64).collect();
            group_sums(&data, groups, group).iter().zip(&count).map(|(s, c)| s / c).collect()
        })
        .collect();
    let peer: Vec<f64> = group_sums(&peer_mean.iter().map(|&v| v as f64).collect::<Vec<_>>(), groups, group)
        .iter()
        .zip(&count)
        .map(|(s, c)| s / c)
        .collect();
    let peer_v: Vec<f64> = group_sums(&peer_var.iter().map(|&v| v as f64).collect::<Vec<_>>(), groups, group)
        .iter()
        .zip(&count)
        .map(|(s, c)| s / (c * c))
        .collect();
    (0..groups)
        .map(|g| {
            let mean = ours.iter().map(|o| o[g]).sum::<f64>() / n;
            let var = ours.iter().map(|o| (o[g] - mean).powi(2)).sum::<f64>() / (n - 1.0) / n;
            let z = (mean - peer[g]) / (var + peer_v[g]).sqrt().max(1e-300);
            (mean, peer[g], z)
        })
        .collect()
}

fn check_image(name: &str, films: &[Film], reference: &str) {
    let (shape, peer_mean) = common::reference(&format!("cornell_box_peer/{reference}_mean.npy"));
    let (_, peer_var) = common::reference(&format!("cornell_box_peer/{reference}_var.npy"));
    assert_eq!(shape, vec![64, 64, 3]);
    let write_failure = || common::write_failure_images(name, &shape, &batch_mean(films), &peer_mean).display().to_string();
    // Image mean per channel: |z| < 4 (the acceptance criterion).
    let channel = group_z(films, &peer_mean, &peer_var, 3, |i| Some(i % 3));
    for (c, (ours, peer, z)) in channel.iter().enumerate() {
        println!("{name} channel {c}: ours {ours:.6} peer {peer:.6} z {z:+.2}");
        if z.abs() >= 4.0 {
            panic!("{name}: channel {c} mean {ours} vs peer {peer}, z = {z:.2}; images in {}", write_failure());
        }
    }
    // 8x8-pixel blocks per channel (192 comparisons), Sidak-corrected.
    let blocks = group_z(films, &peer_mean, &peer_var, 192, |i| {
        let (p, c) = (i / 3, i % 3);
        let (x, y) = (p % 64, p / 64);
        Some(((y / 8) * 8 + x / 8) * 3 + c)
    });
    let limit = t_critical(sidak(ALPHA, blocks.len()), (films.len() - 1) as f64);
    let worst = blocks.iter().map(|b| b.2.abs()).fold(0.0, f64::max);
    println!("{name}: worst block |z| {worst:.2} (limit {limit:.2})");
    if worst >= limit {
        panic!("{name}: a block differs from the peer (|z| = {worst:.2} >= {limit:.2}); images in {}", write_failure());
    }
}

#[test]
fn steady_image_matches_peer() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let films = common::render_films(&ctx, &scene, &settings(Gate::None, 1), BATCHES, 64);
    check_image("cornell_box_steady", &films, "steady");
}

#[test]
fn box_gate_matches_peer() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let films = common::render_films(&ctx, &scene, &settings(Gate::Box { start: 3.14, end: 3.19 }, 2), BATCHES, 64);
    check_image("cornell_box_gate_3_14_3_19", &films, "gate_3_14_3_19");
}

#[test]
fn direct_steady_image_matches_peer() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let settings = RenderSettings { method: Method::Direct, ..settings(Gate::None, 21) };
    let films = common::render_films(&ctx, &scene, &settings, BATCHES, 64);
    check_image("cornell_box_direct_steady", &films, "steady");
}

#[test]
fn direct_box_gate_matches_peer() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let settings = RenderSettings { method: Method::Direct, ..settings(Gate::Box { start: 3.14, end: 3.19 }, 22) };
    let films = common::render_films(&ctx, &scene, &settings, BATCHES, 64);
    check_image("cornell_box_direct_gate_3_14_3_19", &films, "gate_3_14_3_19");
}

#[test]
fn transient_cube_matches_peer_per_bin() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let gate = Gate::Transient { start: 1.94, width: 0.1, bins: 20 };
    let films = common::render_films(&ctx, &scene, &settings(gate, 3), BATCHES, 64);
    let (shape, peer_mean) = common::reference("cornell_box_peer/transient_1_94_step_0_1_mean.npy");
    let (_, peer_var) = common::reference("cornell_box_peer/transient_1_94_step_0_1_var.npy");
    assert_eq!(shape, vec![64, 64, 20, 3]);
    // Image mean of every bin and channel (60 comparisons), Sidak-corrected.
    let bins = group_z(&films, &peer_mean, &peer_var, 60, |i| Some(i % 60));
    let limit = t_critical(sidak(ALPHA, bins.len()), (films.len() - 1) as f64);
    for (g, (ours, peer, z)) in bins.iter().enumerate() {
        if z.abs() >= limit {
            let dir = common::write_failure_images("cornell_box_transient", &shape, &batch_mean(&films), &peer_mean);
            panic!("bin {} channel {}: {ours} vs peer {peer} (z = {z:.2}, limit {limit:.2}); images in {}", g / 3, g % 3, dir.display());
        }
    }
    // The light seen directly (its nearest point is 1.9403 m from the pinhole) reaches the
    // camera in the first bin, [1.94, 2.04).
    let first_bin_total: f64 = bins[..3].iter().map(|b| b.0).sum();
    assert!(first_bin_total > 0.0, "light reaches the camera in the first bin [1.94, 2.04)");
}

#[test]
fn russian_roulette_keeps_the_steady_image_unbiased() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let settings = RenderSettings { rr_depth: Some(1), ..settings(Gate::None, 4) };
    let films = common::render_films(&ctx, &scene, &settings, BATCHES, 64);
    check_image("cornell_box_steady_rr1", &films, "steady");
}

#[test]
fn light_sampling_bsdf_sampling_and_mis_agree() {
    // Each strategy alone is unbiased, and MIS weights that sum to one keep the combination
    // unbiased: all three images agree (image means and 8x8-pixel blocks, Sidak-corrected).
    use gatetrace::integrator::LightStrategy;
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let render = |strategy: LightStrategy, seed: u32| {
        let settings = RenderSettings { width: 32, height: 32, max_bounces: 3, seed, light_strategy: strategy, ..Default::default() };
        common::render_films(&ctx, &scene, &settings, BATCHES, 64)
    };
    let mis = render(LightStrategy::Mis, 11);
    let others = [(LightStrategy::NextEvent, render(LightStrategy::NextEvent, 12)), (LightStrategy::Bsdf, render(LightStrategy::Bsdf, 13))];
    // Groups: 3 channel means + 16 blocks x 3 channels, for 2 comparisons.
    let groups = |i: usize| {
        let (p, c) = (i / 3, i % 3);
        let (x, y) = (p % 32, p / 32);
        ((y / 8) * 4 + x / 8) * 3 + c
    };
    let tests = 2 * (3 + 48);
    let limit = t_critical(sidak(ALPHA, tests), (BATCHES - 1) as f64);
    for (strategy, films) in &others {
        for (name, count, group) in [("image", 3, Box::new(|i: usize| i % 3) as Box<dyn Fn(usize) -> usize>), ("block", 48, Box::new(groups))] {
            let means = |fs: &[Film]| -> Vec<Vec<f64>> {
                fs.iter()
                    .map(|f| {
                        let data: Vec<f64> = f.data.iter().map(|&v| v as f64).collect();
                        group_sums(&data, count, |i| Some(group(i)))
                    })
                    .collect()
            };
            let (a, b) = (means(&mis), means(films));
            for g in 0..count {
                let stat = |m: &Vec<Vec<f64>>| {
                    let n = m.len() as f64;
                    let mean = m.iter().map(|v| v[g]).sum::<f64>() / n;
                    let var = m.iter().map(|v| (v[g] - mean).powi(2)).sum::<f64>() / (n - 1.0) / n;
                    (mean, var)
                };
                let ((ma, va), (mb, vb)) = (stat(&a), stat(&b));
                let z = (ma - mb) / (va + vb).sqrt();
                assert!(z.abs() < limit, "{strategy:?} vs MIS, {name} {g}: {mb} vs {ma} (z = {z:.2}, limit {limit:.2})");
            }
        }
    }
}
