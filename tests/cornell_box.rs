//! The Cornell box against the peer reference (Mitsuba 3.9.1 + mitransient 1.3.1, 131k spp;
//! tests/data/cornell_box_peer/README.md): image means per channel, 8x8-pixel block means, and
//! the transient cube per bin. Our variance comes from independent batches; a z-score divides a
//! difference by the combined standard error of both sides.

mod common;

use common::peer::{ALPHA, check_image, check_transient, group_sums};
use common::stats::{sidak, t_critical};
use gatetrace::film::{Film, Gate};
use gatetrace::integrator::{Method, RenderSettings};

const BATCHES: usize = 16;

/// The peer's settings: 64x64, at most 5 bounces (max_depth 6), no Russian roulette.
fn settings(gate: Gate, seed: u32) -> RenderSettings {
    RenderSettings { width: 64, height: 64, max_bounces: 5, gate, seed, ..Default::default() }
}

#[test]
fn steady_image_matches_peer() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let films = common::render_films(ctx, &scene, &settings(Gate::None, 1), BATCHES, 64);
    check_image("cornell_box_steady", &films, "cornell_box_peer/steady");
}

#[test]
fn box_gate_matches_peer() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let films = common::render_films(ctx, &scene, &settings(Gate::Box { start: 3.14, end: 3.19 }, 2), BATCHES, 64);
    check_image("cornell_box_gate_3_14_3_19", &films, "cornell_box_peer/gate_3_14_3_19");
}

#[test]
fn direct_steady_image_matches_peer() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let settings = RenderSettings { method: Method::Direct, ..settings(Gate::None, 21) };
    let films = common::render_films(ctx, &scene, &settings, BATCHES, 64);
    check_image("cornell_box_direct_steady", &films, "cornell_box_peer/steady");
}

#[test]
fn direct_box_gate_matches_peer() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let settings = RenderSettings { method: Method::Direct, ..settings(Gate::Box { start: 3.14, end: 3.19 }, 22) };
    let films = common::render_films(ctx, &scene, &settings, BATCHES, 64);
    check_image("cornell_box_direct_gate_3_14_3_19", &films, "cornell_box_peer/gate_3_14_3_19");
}

#[test]
fn transient_cube_matches_peer_per_bin() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let gate = Gate::Transient { start: 1.94, width: 0.1, bins: 20 };
    let films = common::render_films(ctx, &scene, &settings(gate, 3), BATCHES, 64);
    let bins = check_transient("cornell_box_transient", &films, "cornell_box_peer/transient_1_94_step_0_1", 20);
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
    let films = common::render_films(ctx, &scene, &settings, BATCHES, 64);
    check_image("cornell_box_steady_rr1", &films, "cornell_box_peer/steady");
}

#[test]
fn light_sampling_bsdf_sampling_and_mis_agree() {
    // Each strategy alone is unbiased, and MIS weights that sum to one keep the combination
    // unbiased: all three images agree (image means and 8x8-pixel blocks, Sidak-corrected).
    use gatetrace::integrator::LightStrategy;
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let render = |strategy: LightStrategy, seed: u32| {
        let settings = RenderSettings {
            width: 32,
            height: 32,
            max_bounces: 3,
            seed,
            light_strategy: strategy,
            ..Default::default()
        };
        common::render_films(ctx, &scene, &settings, BATCHES, 64)
    };
    let mis = render(LightStrategy::Mis, 11);
    let others = [
        (LightStrategy::NextEvent, render(LightStrategy::NextEvent, 12)),
        (LightStrategy::Bsdf, render(LightStrategy::Bsdf, 13)),
    ];
    // Groups: 3 channel means + 16 blocks x 3 channels, for 2 comparisons.
    let groups = |i: usize| {
        let (p, c) = (i / 3, i % 3);
        let (x, y) = (p % 32, p / 32);
        ((y / 8) * 4 + x / 8) * 3 + c
    };
    let tests = 2 * (3 + 48);
    let limit = t_critical(sidak(ALPHA, tests), (BATCHES - 1) as f64);
    for (strategy, films) in &others {
        for (name, count, group) in
            [("image", 3, Box::new(|i: usize| i % 3) as Box<dyn Fn(usize) -> usize>), ("block", 48, Box::new(groups))]
        {
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
                assert!(
                    z.abs() < limit,
                    "{strategy:?} vs MIS, {name} {g}: {mb} vs {ma} (z = {z:.2}, limit {limit:.2})"
                );
            }
        }
    }
}
