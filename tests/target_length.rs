//! Target path lengths drawn from the gate (for ellipsoidal connections): the WGSL sampler
//! matches its CPU twin, the estimate E[W(tau)/p(tau) g(tau)] equals the integral of W g by
//! quadrature for every gate kind, and a pixel's low-discrepancy numbers are uniform and spread.

mod common;

use gatetrace::film::Gate;
use gatetrace::film::target::{TargetSampler, target_u};
use gatetrace::film::gate::gate_weight;
use gatetrace::integrator::{PathTracer, RenderSettings, target_sampler};

fn gates() -> Vec<(&'static str, Gate)> {
    vec![
        ("box", Gate::Box { start: 3.14, end: 3.1425 }),
        ("wide box", Gate::Box { start: 2.5, end: 4.0 }),
        ("gaussian", Gate::Gaussian { mean: 3.2, sigma: 0.05 }),
        ("cw", Gate::Cw { frequency_hz: 1e8, phase_deg: 30.0 }),
        ("table", Gate::Table { points: vec![(2.8, 0.0), (3.0, 1.0), (3.2, 1.0), (3.4, -0.5), (3.6, 0.0)], source: "t.csv".into() }),
        ("transient", Gate::Transient { start: 1.94, width: 0.1, bins: 20 }),
    ]
}

#[test]
fn weighted_target_lengths_integrate_the_gate() {
    // The Cornell box with 5 bounces: path lengths in [1.94, ~10.4] m.
    let scene = common::cornell_box();
    let g = |l: f64| 1.0 + (3.0 * l).sin() + 0.3 * l;
    for (name, gate) in gates() {
        let settings = RenderSettings { max_bounces: 5, gate: gate.clone(), ..Default::default() };
        let sampler = target_sampler(&scene, &settings).unwrap();
        let (lo, hi) = (sampler.params.lo as f64, sampler.params.hi as f64);
        // Quadrature of W g over [lo, hi] (independent of the sampler's table).
        let (gp, kind, table) = (gate.to_gpu(), gate.kind(), gate.table());
        let n = 400_000;
        let h = (hi - lo) / n as f64;
        let exact: f64 = (0..n).map(|i| {
            let l = lo + (i as f64 + 0.5) * h;
            gate_weight(kind, &gp, &table, l as f32) as f64 * g(l) * h
        }).sum();
        // Estimate with stratified u.
        let m = 200_000;
        let estimate: f64 = (0..m).map(|i| {
            let (l, inv_pdf) = sampler.sample((i as f32 + 0.5) / m as f32);
            let w = sampler.weight(l) * inv_pdf;
            assert!((lo as f32..=hi as f32).contains(&l) && w.is_finite(), "{name}: tau {l}, weight {w}");
            w as f64 * g(l as f64)
        }).sum::<f64>() / m as f64;
        println!("{name}: [{lo:.4}, {hi:.4}] m, integral {exact:.6e}, estimate {estimate:.6e}");
        let scale: f64 = (0..n).map(|i| (gate_weight(kind, &gp, &table, (lo + (i as f64 + 0.5) * h) as f32) as f64 * g(lo + (i as f64 + 0.5) * h)).abs() * h).sum();
        assert!((estimate - exact).abs() <= 2e-3 * scale, "{name}: estimate {estimate} vs integral {exact}");
    }
}

#[test]
fn wgsl_target_lengths_match_cpu_twin() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    for (name, gate) in gates() {
        let settings = RenderSettings { width: 4, height: 4, max_bounces: 5, gate: gate.clone(), ..Default::default() };
        let tracer = PathTracer::new(&ctx, &scene, &settings).unwrap();
        let sampler: TargetSampler = target_sampler(&scene, &settings).unwrap();
        let input: Vec<[f32; 4]> = (0..4096u32)
            .map(|i| [(i as f32 + 0.37) / 4096.0, f32::from_bits(i.wrapping_mul(2_246_822_519)), f32::from_bits(i % 97), 0.0])
            .collect();
        let out = common::run_probe(&ctx, &tracer, "probe_functions", &[("FUNCTION", 14.0)], &input, input.len());
        for (i, (x, o)) in input.iter().zip(&out).enumerate() {
            let (l, w) = sampler.sample(x[0]);
            assert!((o[0] - l).abs() <= 1e-6 * l, "{name} record {i}: tau GPU {} CPU {l}", o[0]);
            assert!((o[1] - w).abs() <= 1e-4 * w.abs() + 1e-7, "{name} record {i}: 1/p GPU {} CPU {w}", o[1]);
            assert_eq!(o[2], target_u(x[1].to_bits(), x[2].to_bits()), "{name} record {i}: target_u");
        }
    }
}

#[test]
fn a_pixels_target_numbers_are_uniform_and_spread() {
    // For a fixed sample index, over random pixel offsets: uniform (chi-square over 64 bins).
    let mut rng = gatetrace::rng::Rng::new(1, 2, 3);
    let mut counts = vec![0.0; 64];
    for _ in 0..64_000 {
        let offset = (rng.next_f32() * 16_777_216.0) as u32 * 256;
        counts[(target_u(offset, 12345) * 64.0) as usize] += 1.0;
    }
    let (stat, dof, p) = common::stats::chi2_test(&counts, &vec![1000.0; 64]);
    assert!(p > 0.001, "chi2 {stat} dof {dof} p {p}");
    // Within one pixel, n consecutive samples put at most 3 numbers in any of n equal cells.
    for n in [10usize, 100, 1000] {
        let mut cells = vec![0; n];
        for s in 0..n as u32 {
            cells[(target_u(0x1234_5678, s) * n as f32) as usize] += 1;
        }
        assert!(cells.iter().all(|&c| c <= 3), "{n} samples: {:?}", cells.iter().max());
    }
}
