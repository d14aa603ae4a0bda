//! Target path lengths drawn from the gate (for ellipsoidal connections): the WGSL sampler
//! matches its CPU twin, the estimate E[W(tau)/p(tau) g(tau)] equals the integral of W g by
//! quadrature for every gate kind, and a pixel's low-discrepancy numbers are uniform and spread;
//! transient gates' stratified target lengths visit every bin once per round, lie in their bin
//! as the film sees it, match their CPU twin, and the film's factors count each bin's samples.

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

/// Transient gates of the Cornell box (5 bounces, paths from 1.94 m): bins all within the
/// scene's lengths, and 4000 fine bins of which the first ~3,470 lie below them (first_bin > 0).
fn transient_gates() -> Vec<Gate> {
    vec![
        Gate::Transient { start: 1.94, width: 0.1, bins: 20 },
        Gate::Transient { start: 0.9, width: 0.0003, bins: 4000 },
        Gate::Transient { start: 3.0, width: 0.05, bins: 1 },
    ]
}

#[test]
fn stratified_target_lengths_visit_every_bin_once_per_round() {
    use gatetrace::film::gate::gate_bin;
    use gatetrace::film::target::{golden_stride, stratum};
    for n in 1..300u32 {
        let g = golden_stride(n);
        assert!((1..n.max(2)).contains(&g) && (1..=g).all(|d| d == 1 || g % d != 0 || n % d != 0), "stride {g} of {n}");
    }
    let scene = common::cornell_box();
    let mut rng = gatetrace::rng::Rng::new(5, 6, 7);
    for gate in transient_gates() {
        let settings = RenderSettings { max_bounces: 5, gate: gate.clone(), seed: 11, ..Default::default() };
        let sampler = target_sampler(&scene, &settings).unwrap();
        let t = sampler.params;
        let Gate::Transient { start, width, bins } = gate else { unreachable!() };
        assert!(t.strata >= 1 && t.first_bin + t.strata <= bins, "{gate:?}: {t:?}");
        // The strata are whole bins covering the lengths the scene allows within the gate.
        assert_eq!(t.lo as f64, (start + t.first_bin as f64 * width) as f32 as f64);
        let shortest = (scene.scene.path_length_bounds(5).0 as f64).max(start);
        assert!(t.lo as f64 <= shortest + 1e-6 && t.lo as f64 > shortest - width - 1e-6, "{gate:?}: lo {}", t.lo);
        let n = t.strata;
        for _ in 0..20 {
            let pixel = (rng.next_f32() * 1e6) as u32;
            let first = (rng.next_f32() * 1e7) as u32;
            let mut seen = vec![0u32; n as usize];
            for sample in first..first + n {
                let j = stratum(&t, settings.seed, pixel, sample);
                seen[j as usize] += 1;
                let (tau, inv_pdf, bin) = sampler.stratified_sample(settings.seed, pixel, sample);
                assert_eq!(bin, t.first_bin + j);
                assert_eq!(gate_bin(gate.kind(), &gate.to_gpu(), tau), bin as i32, "{gate:?}: tau {tau} outside bin {bin}");
                assert!((inv_pdf as f64 - n as f64 * width).abs() <= 1e-6 * n as f64 * width, "1/p {inv_pdf}");
            }
            assert!(seen.iter().all(|&c| c == 1), "{gate:?}: {n} consecutive samples from {first} of pixel {pixel}");
        }
    }
}

#[test]
fn stratum_factors_divide_each_bin_by_its_samples() {
    use gatetrace::film::target::{stratum, stratum_factors};
    let scene = common::cornell_box();
    let settings = RenderSettings { max_bounces: 5, gate: transient_gates()[0].clone(), seed: 3, ..Default::default() };
    let t = target_sampler(&scene, &settings).unwrap().params;
    let n = t.strata as u64;
    let mut factors = vec![0.0f32; n as usize];
    for (pixel, first, samples) in [(0u32, 0u64, n - 1), (7, 13, n), (9, 1000, 3 * n + 5), (123, 77, 10 * n + n - 1)] {
        let done = stratum_factors(&t, settings.seed, pixel, first, samples, &mut factors);
        if samples < n {
            assert!(done.is_none(), "{samples} samples < {n} strata: no factors");
            continue;
        }
        let mut counts = vec![0u64; n as usize];
        for s in first..first + samples {
            counts[stratum(&t, settings.seed, pixel, s as u32) as usize] += 1;
        }
        for (j, (&f, &c)) in factors.iter().zip(&counts).enumerate() {
            let expected = samples as f64 / (n as f64 * c as f64);
            assert!((f as f64 - expected).abs() <= 1e-6 * expected, "stratum {j}: factor {f}, {c} samples of {samples}");
        }
    }
}

#[test]
fn wgsl_stratified_target_lengths_match_cpu_twin() {
    use gatetrace::film::gate::gate_bin;
    let ctx = common::gpu();
    let scene = common::cornell_box();
    for gate in transient_gates() {
        let settings = RenderSettings { width: 4, height: 4, max_bounces: 5, gate: gate.clone(), seed: 21, ..Default::default() };
        let tracer = PathTracer::new(&ctx, &scene, &settings).unwrap();
        let sampler = target_sampler(&scene, &settings).unwrap();
        let input: Vec<[f32; 4]> = (0..4096u32)
            .map(|i| [f32::from_bits(i.wrapping_mul(2_246_822_519) >> 12), f32::from_bits(i * 7919), 0.0, 0.0])
            .collect();
        let out = common::run_probe(&ctx, &tracer, "probe_functions", &[("FUNCTION", 15.0)], &input, input.len());
        for (i, (x, o)) in input.iter().zip(&out).enumerate() {
            let (tau, inv_pdf, bin) = sampler.stratified_sample(settings.seed, x[0].to_bits(), x[1].to_bits());
            assert_eq!(o[2] as u32 + sampler.params.first_bin, bin, "{gate:?} record {i}: stratum");
            assert!((o[0] - tau).abs() <= 2.0 * f32::EPSILON * tau, "{gate:?} record {i}: tau GPU {} CPU {tau}", o[0]);
            assert_eq!(gate_bin(gate.kind(), &gate.to_gpu(), o[0]), bin as i32, "{gate:?} record {i}: GPU tau {} outside bin {bin}", o[0]);
            assert!((o[1] - inv_pdf).abs() <= 1e-6 * inv_pdf, "{gate:?} record {i}: 1/p GPU {} CPU {inv_pdf}", o[1]);
        }
    }
}
