//! Target path lengths drawn from the gate (for ellipsoidal connections): the WGSL sampler
//! matches its CPU twin, the estimate E[W(tau)/p(tau) g(tau)] equals the integral of W g by
//! quadrature for every gate kind, and a pixel's low-discrepancy numbers are uniform and spread;
//! transient gates' stratified target lengths visit every bin once per round (and each as often
//! as its row of extra visits says), lie in their bin as the film sees it, match their CPU
//! twin, and the film's factors count each bin's samples; a pilot's transient shapes the rows.

mod common;

use gatetrace::film::Gate;
use gatetrace::film::gate::gate_weight;
use gatetrace::film::target::{TargetSampler, target_u};
use gatetrace::integrator::{Integrator, PathTracer, RenderSettings, target_sampler};

fn gates() -> Vec<(&'static str, Gate)> {
    vec![
        ("box", Gate::Box { start: 3.14, end: 3.1425 }),
        ("wide box", Gate::Box { start: 2.5, end: 4.0 }),
        ("gaussian", Gate::Gaussian { mean: 3.2, sigma: 0.05 }),
        ("cw", Gate::Cw { frequency_hz: 1e8, phase_deg: 30.0 }),
        ("cw depth-selective", Gate::parse("cw:4.7e9,-30,depthsel").unwrap()),
        ("cw hamiltonian", Gate::parse("cw:300e6,75,ham4:3").unwrap()),
        (
            "table",
            Gate::Table {
                points: vec![(2.8, 0.0), (3.0, 1.0), (3.2, 1.0), (3.4, -0.5), (3.6, 0.0)],
                source: "t.csv".into(),
            },
        ),
        ("transient", Gate::Transient { start: 1.94, width: 0.1, bins: 20 }),
    ]
}

#[test]
fn weighted_target_lengths_integrate_the_gate() {
    // The Cornell box with 5 bounces: path lengths from 1.94 m to the bound of path_length_bounds.
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
        let exact: f64 = (0..n)
            .map(|i| {
                let l = lo + (i as f64 + 0.5) * h;
                gate_weight(kind, &gp, &table, l as f32) as f64 * g(l) * h
            })
            .sum();
        // Estimate with stratified u.
        let m = 200_000;
        let estimate: f64 = (0..m)
            .map(|i| {
                let (l, inv_pdf) = sampler.sample((i as f32 + 0.5) / m as f32);
                let w = sampler.weight(l) * inv_pdf;
                assert!((lo as f32..=hi as f32).contains(&l) && w.is_finite(), "{name}: tau {l}, weight {w}");
                w as f64 * g(l as f64)
            })
            .sum::<f64>()
            / m as f64;
        println!("{name}: [{lo:.4}, {hi:.4}] m, integral {exact:.6e}, estimate {estimate:.6e}");
        let scale: f64 = (0..n)
            .map(|i| {
                (gate_weight(kind, &gp, &table, (lo + (i as f64 + 0.5) * h) as f32) as f64
                    * g(lo + (i as f64 + 0.5) * h))
                .abs()
                    * h
            })
            .sum();
        assert!((estimate - exact).abs() <= 2e-3 * scale, "{name}: estimate {estimate} vs integral {exact}");
    }
}

#[test]
fn wgsl_target_lengths_match_cpu_twin() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    for (name, gate) in gates() {
        let settings = RenderSettings { width: 4, height: 4, max_bounces: 5, gate: gate.clone(), ..Default::default() };
        let tracer = PathTracer::new(ctx, &scene, &settings).unwrap();
        let sampler: TargetSampler = target_sampler(&scene, &settings).unwrap();
        let input: Vec<[f32; 4]> = (0..4096u32)
            .map(|i| {
                [(i as f32 + 0.37) / 4096.0, f32::from_bits(i.wrapping_mul(2_246_822_519)), f32::from_bits(i % 97), 0.0]
            })
            .collect();
        let out = common::run_probe(ctx, &tracer, "probe_functions", &[("FUNCTION", 14.0)], &input, input.len());
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

/// Rows of `target_visits` for `pixels` pixels of `n` strata sharing `extra` visits at random
/// (some bins none, some many).
// Each pixel's row starts with a 0 (clippy takes those pushes for a fill).
#[allow(clippy::same_item_push)]
fn random_rows(n: u32, extra: u32, pixels: u32, rng: &mut gatetrace::rng::Rng) -> Vec<u32> {
    let mut rows = Vec::new();
    for _ in 0..pixels {
        let weights: Vec<f64> =
            (0..n).map(|_| if rng.next_f32() < 0.3 { 0.0 } else { (rng.next_f32() as f64).powi(3) }).collect();
        let total: f64 = weights.iter().sum::<f64>().max(1e-30);
        let mut acc = 0.0;
        rows.push(0);
        for (j, w) in weights.iter().enumerate() {
            acc += w;
            rows.push(if j + 1 == n as usize {
                extra
            } else {
                ((extra as f64 * acc / total).round() as u32).min(extra)
            });
        }
    }
    rows
}

#[test]
fn stratified_target_lengths_visit_every_bin_once_per_round() {
    use gatetrace::film::gate::gate_bin;
    use gatetrace::film::target::{golden_stride, target_visit};
    for n in 1..300u32 {
        let g = golden_stride(n);
        assert!(
            (1..n.max(2)).contains(&g) && (1..=g).all(|d| d == 1 || !g.is_multiple_of(d) || n % d != 0),
            "stride {g} of {n}"
        );
    }
    let scene = common::cornell_box();
    let mut rng = gatetrace::rng::Rng::new(5, 6, 7);
    for gate in transient_gates() {
        let settings = RenderSettings { max_bounces: 5, gate: gate.clone(), seed: 11, ..Default::default() };
        let sampler = target_sampler(&scene, &settings).unwrap();
        let Gate::Transient { start, width, bins } = gate else { unreachable!() };
        let t = sampler.params;
        assert!(t.strata >= 1 && t.first_bin + t.strata <= bins, "{gate:?}: {t:?}");
        // The strata are whole bins covering the lengths the scene allows within the gate.
        assert_eq!(t.lo as f64, (start + t.first_bin as f64 * width) as f32 as f64);
        let shortest = (scene.scene.path_length_bounds(5).0 as f64).max(start);
        assert!(t.lo as f64 <= shortest + 1e-6 && t.lo as f64 > shortest - width - 1e-6, "{gate:?}: lo {}", t.lo);
        let n = t.strata;
        for _ in 0..20 {
            let pixel = (rng.next_f32() * 1e6) as u32;
            let t = gatetrace::gpu::layout::TargetParams {
                seed: settings.seed,
                film_first_sample: (rng.next_f32() * 1e7) as u32,
                ..t
            };
            let first = t.film_first_sample.wrapping_add((rng.next_f32() * 1e7) as u32);
            let mut seen = vec![0u32; n as usize];
            for sample in first..first + n {
                let v = target_visit(&t, &[], pixel, sample);
                seen[v.stratum as usize] += 1;
                assert_eq!((v.visit, v.per_cycle), ((sample - t.film_first_sample) / n, 1));
                let (tau, inv_pdf, bin) = sampler.stratified_sample(&t, &[], pixel, sample);
                assert_eq!(bin, t.first_bin + v.stratum);
                assert_eq!(
                    gate_bin(gate.kind(), &gate.to_gpu(), tau),
                    bin as i32,
                    "{gate:?}: tau {tau} outside bin {bin}"
                );
                assert!((inv_pdf as f64 - n as f64 * width).abs() <= 1e-6 * n as f64 * width, "1/p {inv_pdf}");
            }
            assert!(seen.iter().all(|&c| c == 1), "{gate:?}: {n} consecutive samples from {first} of pixel {pixel}");
        }
    }
}

/// Every prefix of a stride's sequence spreads evenly: the largest gap between the first m
/// positions of (i g) mod n is at most 3 n / m (the worst of these n is 2.41; the integer
/// nearest 0.618 n gave 6.3 for n = 2100, m = 280, its first points in pairs), so a capture that
/// stops within a cycle has visited its bins evenly.
#[test]
fn stride_prefixes_spread_evenly() {
    use gatetrace::film::target::golden_stride;
    let sizes: Vec<u32> = (3..600).chain([1000, 2100, 4000, 4500, 15_000, 28_000, 60_000, 65_535]).collect();
    for n in sizes {
        let g = golden_stride(n);
        let mut points: Vec<u32> = (0..n).map(|i| (i as u64 * g as u64 % n as u64) as u32).collect();
        let sequence = points.clone();
        points.sort_unstable();
        assert!(points.iter().copied().eq(0..n), "stride {g} of {n} is not a permutation");
        for k in [2, 3, 5, 8, 16, 32, 100] {
            let m = (n / k).max(2) as usize;
            let mut prefix = sequence[..m].to_vec();
            prefix.sort_unstable();
            let wrap = prefix[0] + n - prefix[m - 1];
            let largest = prefix.windows(2).map(|w| w[1] - w[0]).fold(wrap, u32::max);
            assert!(
                largest as f64 * m as f64 <= 3.0 * n as f64,
                "stride {g} of {n}: the first {m} points leave a gap of {largest} (mean {:.1})",
                n as f64 / m as f64
            );
        }
    }
}

#[test]
fn extra_visits_follow_the_pixels_rows() {
    use gatetrace::film::gate::gate_bin;
    use gatetrace::film::target::{golden_stride, target_visit};
    let scene = common::cornell_box();
    let mut rng = gatetrace::rng::Rng::new(8, 9, 10);
    for gate in transient_gates() {
        let settings = RenderSettings { max_bounces: 5, gate: gate.clone(), seed: 12, ..Default::default() };
        let sampler = target_sampler(&scene, &settings).unwrap();
        let Gate::Transient { width, .. } = gate else { unreachable!() };
        let n = sampler.params.strata;
        let extra = 3 * n + 1;
        let pixels = 6u32;
        let rows = random_rows(n, extra, pixels, &mut rng);
        let t = gatetrace::gpu::layout::TargetParams {
            seed: settings.seed,
            extra,
            extra_stride: golden_stride(extra),
            film_first_sample: 1000,
            ..sampler.params
        };
        let cycle = n + extra;
        for pixel in 0..pixels {
            let row = &rows[(pixel * (n + 1)) as usize..((pixel + 1) * (n + 1)) as usize];
            let per_cycle = |j: usize| 1 + row[j + 1] - row[j];
            // Any cycle-long run of samples visits bin j per_cycle_j times.
            for start in [0u32, 1, n, cycle / 2, 5 * cycle + 3] {
                let mut seen = vec![0u32; n as usize];
                for s in start..start + cycle {
                    seen[target_visit(&t, row, pixel, t.film_first_sample + s).stratum as usize] += 1;
                }
                for j in 0..n as usize {
                    assert_eq!(seen[j], per_cycle(j), "{gate:?} pixel {pixel}: bin {j} in the cycle from {start}");
                }
            }
            // Over whole cycles, a bin's visits are numbered 0, 1, ... without gaps or repeats,
            // lie in the bin and weigh cycle x width / per_cycle.
            let mut visits: Vec<Vec<u32>> = vec![Vec::new(); n as usize];
            for s in 0..3 * cycle {
                let sample = t.film_first_sample + s;
                let v = target_visit(&t, row, pixel, sample);
                assert_eq!(v.per_cycle, per_cycle(v.stratum as usize));
                visits[v.stratum as usize].push(v.visit);
                let (tau, inv_pdf, bin) = sampler.stratified_sample(&t, row, pixel, sample);
                assert_eq!(bin, t.first_bin + v.stratum);
                assert_eq!(
                    gate_bin(gate.kind(), &gate.to_gpu(), tau),
                    bin as i32,
                    "{gate:?}: tau {tau} outside bin {bin}"
                );
                let expected = cycle as f64 * width / v.per_cycle as f64;
                assert!((inv_pdf as f64 - expected).abs() <= 1e-6 * expected, "1/p {inv_pdf}, expected {expected}");
            }
            for (j, v) in visits.iter_mut().enumerate() {
                v.sort_unstable();
                assert!(v.iter().copied().eq(0..3 * per_cycle(j)), "{gate:?} pixel {pixel} bin {j}: visits {v:?}");
            }
        }
    }
}

#[test]
fn stratum_factors_divide_each_bin_by_its_samples() {
    use gatetrace::film::target::{golden_stride, samples_to_visit_every_bin, stratum_factors, target_visit};
    let scene = common::cornell_box();
    let settings = RenderSettings { max_bounces: 5, gate: transient_gates()[0].clone(), seed: 3, ..Default::default() };
    let plain = gatetrace::gpu::layout::TargetParams {
        seed: 3,
        film_first_sample: 77,
        ..target_sampler(&scene, &settings).unwrap().params
    };
    let n = plain.strata;
    let extra = 5 * n - 2;
    let mut rng = gatetrace::rng::Rng::new(1, 2, 3);
    let rows = random_rows(n, extra, 130, &mut rng);
    let shaped = gatetrace::gpu::layout::TargetParams { extra, extra_stride: golden_stride(extra), ..plain };
    let mut factors = vec![0.0f32; n as usize];
    for t in [plain, shaped] {
        let cycle = (n + t.extra) as u64;
        let every = samples_to_visit_every_bin(&t);
        let n = n as u64;
        let cases = [
            (0u32, n - 1),
            (7, n),
            (9, 3 * cycle + 5),
            (123, 10 * cycle + cycle - 1),
            (45, n + 3),
            (46, cycle),
            (47, every - 1),
            (48, every),
        ];
        for (pixel, samples) in cases {
            let row = if t.extra > 0 {
                &rows[pixel as usize * (n as usize + 1)..(pixel as usize + 1) * (n as usize + 1)]
            } else {
                &[][..]
            };
            let done = stratum_factors(&t, row, pixel, samples, &mut factors);
            if samples < n && t.extra == 0 {
                assert!(done.is_none(), "{samples} samples < {n} strata, no extra visits: nothing to change");
                continue;
            }
            assert!(done.is_some());
            let counts_of = |t: &gatetrace::gpu::layout::TargetParams| {
                let mut counts = vec![0u64; n as usize];
                for s in 0..samples {
                    counts[target_visit(t, row, pixel, t.film_first_sample + s as u32).stratum as usize] += 1;
                }
                counts
            };
            let per_cycle = |j: usize| if t.extra > 0 { 1 + row[j + 1] - row[j] } else { 1 } as f64;
            if samples < every {
                // Some bins may not have been visited yet, and their factors divide by their
                // expected count; the others' by their actual count. Either way the bin's
                // estimate is unbiased when count_j factor_j has mean samples per_cycle_j /
                // cycle over the random offsets: checked over 400 seeds (new randomisations).
                assert!(t.extra > 0);
                let seeds = 400u32;
                let (mut sum, mut sum2) = (vec![0.0f64; n as usize], vec![0.0f64; n as usize]);
                for seed in 0..seeds {
                    let ts = gatetrace::gpu::layout::TargetParams { seed: 1000 + seed, ..t };
                    assert!(stratum_factors(&ts, row, pixel, samples, &mut factors).is_some());
                    for (j, c) in counts_of(&ts).into_iter().enumerate() {
                        let ratio = c as f64 * factors[j] as f64 * cycle as f64 / (samples as f64 * per_cycle(j));
                        sum[j] += ratio;
                        sum2[j] += ratio * ratio;
                    }
                }
                for j in 0..n as usize {
                    let mean = sum[j] / seeds as f64;
                    let sd = ((sum2[j] / seeds as f64 - mean * mean).max(0.0) / (seeds - 1) as f64).sqrt();
                    assert!(
                        (mean - 1.0).abs() <= 5.0 * sd + 1e-5,
                        "{samples} samples, stratum {j}: count x factor over its mean {mean} +- {sd}"
                    );
                }
                continue;
            }
            let counts = counts_of(&t);
            assert!(counts.iter().all(|&c| c > 0), "{samples} samples from the film's first visit every bin");
            for (j, (&f, &c)) in factors.iter().zip(&counts).enumerate() {
                let expected = samples as f64 * per_cycle(j) / (cycle as f64 * c as f64);
                assert!(
                    (f as f64 - expected).abs() <= 1e-6 * expected,
                    "stratum {j}: factor {f}, {c} samples of {samples}"
                );
            }
        }
    }
}

/// A cycle with extra visits interleaves them with its base visits (one base visit, then
/// extra / strata extra ones, the remainder last), so every prefix of a cycle already spends
/// most of its samples where the allocation puts them; every bin has had its base visit after
/// `samples_to_visit_every_bin` samples and not before.
#[test]
fn a_cycle_interleaves_base_and_extra_visits() {
    use gatetrace::film::target::{
        base_visits_before, cycle_slot, golden_stride, samples_to_visit_every_bin, target_visit,
    };
    let mut rng = gatetrace::rng::Rng::new(4, 5, 6);
    for (n, extra) in [(1u32, 5u32), (7, 3), (7, 7), (40, 15 * 40), (40, 15 * 40 + 13), (300, 65_535), (1000, 999)] {
        let t = gatetrace::gpu::layout::TargetParams {
            strata: n,
            stride: golden_stride(n),
            extra,
            extra_stride: golden_stride(extra),
            seed: 9,
            film_first_sample: 5,
            ..Default::default()
        };
        let run = extra / n + 1;
        let (mut base, mut extras) = (vec![false; n as usize], vec![false; extra as usize]);
        let mut bases_so_far = 0u64;
        for q in 0..n + extra {
            assert_eq!(base_visits_before(&t, q as u64), bases_so_far, "({n}, {extra}) position {q}");
            let (is_base, i) = cycle_slot(&t, q);
            let seen = if is_base { &mut base[i as usize] } else { &mut extras[i as usize] };
            assert!(
                !*seen,
                "({n}, {extra}): position {q} repeats {}",
                if is_base { "a base visit" } else { "an extra visit" }
            );
            *seen = true;
            // In order, and one base visit in each run of `run` positions up to the last.
            if is_base {
                assert_eq!((i as u64, q % run), (bases_so_far, 0), "({n}, {extra}) position {q}");
                bases_so_far += 1;
            }
        }
        assert!(base.iter().all(|&b| b) && extras.iter().all(|&e| e), "({n}, {extra}): a visit missing");
        // Every bin visited after samples_to_visit_every_bin samples from the film's first.
        let rows = random_rows(n, extra, 3, &mut rng);
        let every = samples_to_visit_every_bin(&t);
        // The last base visit of the first cycle is its sample every - 1.
        assert_eq!(
            (base_visits_before(&t, every - 1), base_visits_before(&t, every)),
            (n as u64 - 1, n as u64),
            "({n}, {extra})"
        );
        for pixel in 0..3u32 {
            let row = &rows[(pixel * (n + 1)) as usize..((pixel + 1) * (n + 1)) as usize];
            let mut seen = vec![0u32; n as usize];
            for s in 0..every as u32 {
                seen[target_visit(&t, row, pixel, t.film_first_sample + s).stratum as usize] += 1;
            }
            assert!(seen.iter().all(|&c| c > 0), "({n}, {extra}) pixel {pixel}: a bin unvisited after {every} samples");
        }
    }
}

#[test]
fn visit_tables_follow_the_pilot_and_keep_a_visit_per_bin() {
    use gatetrace::film::target::{EXTRA_VISITS_PER_BIN, PILOT_CELLS, PILOT_SPREAD, PILOT_UNIFORM_SHARE, visit_tables};
    let (strata, bins) = (512u32, 530usize);
    let t = gatetrace::gpu::layout::TargetParams { strata, first_bin: 10, ..Default::default() };
    // Pixel 0: light in bins 110 .. 130 only (strata 100 .. 120); pixel 1: black; pixel 2: NaN.
    let mut film = vec![0.0f32; 3 * bins * 3];
    for bin in 110..130 {
        film[bin * 3 + 1] = -2.0; // signed values count by magnitude
    }
    film[2 * bins * 3 + 40] = f32::NAN;
    let (extra, rows) = visit_tables(&t, &film, bins);
    assert_eq!(extra, EXTRA_VISITS_PER_BIN * strata);
    assert_eq!(rows.len(), 3 * (strata as usize + 1));
    for row in rows.chunks(strata as usize + 1) {
        assert_eq!((row[0], row[strata as usize]), (0, extra));
        assert!(row.windows(2).all(|w| w[0] <= w[1]), "rows are cumulative");
    }
    // Strata 100 .. 120 lie in cells 25 .. 30 of 128 (4 bins each); spread by PILOT_SPREAD
    // cells, the shaped visits fall in cells 23 .. 32, strata 92 .. 128, evenly; the uniform
    // share goes to every stratum.
    assert_eq!((PILOT_CELLS, PILOT_SPREAD), (128, 2));
    let row = &rows[..strata as usize + 1];
    let even = PILOT_UNIFORM_SHARE * extra as f64 / strata as f64;
    let shaped = (1.0 - PILOT_UNIFORM_SHARE) * extra as f64 / 36.0;
    for j in 0..strata as usize {
        let expected = even + if (92..128).contains(&j) { shaped } else { 0.0 };
        assert!(
            ((row[j + 1] - row[j]) as f64 - expected).abs() <= 1.0,
            "stratum {j}: {} extra visits, not {expected:.1}",
            row[j + 1] - row[j]
        );
    }
    // A pixel the pilot saw nothing in (or nothing finite) gets its extra visits evenly.
    for row in rows.chunks(strata as usize + 1).skip(1) {
        for j in 0..strata as usize {
            assert_eq!(row[j + 1] - row[j], EXTRA_VISITS_PER_BIN, "stratum {j}");
        }
    }
}

/// The band index's masses share out the extra visits so that no bin is starved: each gets at
/// least (n + E) min(w, 1/n) visits a cycle (w its share: BAND_UNIFORM_SHARE evenly, the rest by
/// mass), the rest follows w, and a pixel of no mass gets its visits evenly.
#[test]
fn visit_tables_from_masses_floor_every_bin_at_the_lesser_of_even_and_proportional() {
    use gatetrace::film::target::{BAND_EXTRA_VISITS_PER_BIN, BAND_UNIFORM_SHARE, visit_tables_from_masses};
    for strata in [1u32, 7, 60, 100, 1700] {
        let n = strata as usize;
        let t = gatetrace::gpu::layout::TargetParams { strata, ..Default::default() };
        let mut rng = gatetrace::rng::Rng::new(5, strata, 1);
        let mut masses = Vec::new();
        // A peak and its tail; a peak beside a shoulder of a hundred times less per bin; every
        // bin equally lit; random masses with dark runs; nothing; NaN and negative masses.
        masses.extend((0..n).map(|j| if j >= n / 3 { 1.0 / (1.0 + (j - n / 3) as f32).powi(2) } else { 0.0 }));
        masses.extend((0..n).map(|j| {
            if j == n / 2 {
                1.0
            } else if j > n / 2 {
                0.01
            } else {
                0.0
            }
        }));
        masses.extend(std::iter::repeat_n(1.0, n));
        masses.extend((0..n).map(|_| if rng.next_f32() < 0.4 { 0.0 } else { rng.next_f32().powi(4) }));
        masses.extend(std::iter::repeat_n(0.0, n));
        masses.extend((0..n).map(|j| [f32::NAN, -1.0, 0.0][j % 3]));
        let (extra, rows) = visit_tables_from_masses(&t, &masses);
        assert_eq!(extra, BAND_EXTRA_VISITS_PER_BIN * strata);
        let cycle = (n as f64) + extra as f64;
        for (pixel, (row, m)) in rows.chunks(n + 1).zip(masses.chunks(n)).enumerate() {
            assert_eq!((row[0], row[n]), (0, extra), "{n} bins, pixel {pixel}");
            assert!(row.windows(2).all(|w| w[0] <= w[1]), "{n} bins, pixel {pixel}: rows are cumulative");
            let weight = |m: f32| if m.is_finite() && m > 0.0 { m as f64 } else { 0.0 };
            let total: f64 = m.iter().map(|&v| weight(v)).sum();
            let even = 1.0 / n as f64;
            for j in 0..n {
                let w = match total > 0.0 {
                    true => BAND_UNIFORM_SHARE * even + (1.0 - BAND_UNIFORM_SHARE) * weight(m[j]) / total,
                    false => even,
                };
                let visits = 1.0 + (row[j + 1] - row[j]) as f64;
                assert!(
                    visits >= cycle * w.min(even) - 1e-9,
                    "{n} bins, pixel {pixel}, bin {j}: {visits} visits of {cycle}, share {w}"
                );
                // The floors and the rest follow w: no bin gets more than its floor plus its share
                // of what is left, rounded (and an unlit pixel's bins get E/n each).
                assert!(visits <= (cycle * w.min(even)).ceil() + cycle * w + 1.0, "{n} bins, pixel {pixel}, bin {j}");
                if total == 0.0 {
                    assert!((visits - cycle * even).abs() < 1e-9, "{n} bins, pixel {pixel}, bin {j}: {visits}");
                }
            }
        }
    }
}

#[test]
fn wgsl_stratified_target_lengths_match_cpu_twin() {
    use gatetrace::film::gate::gate_bin;
    use gatetrace::film::target::golden_stride;
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let mut rng = gatetrace::rng::Rng::new(4, 4, 4);
    for gate in transient_gates() {
        let settings =
            RenderSettings { width: 4, height: 4, max_bounces: 5, gate: gate.clone(), seed: 21, ..Default::default() };
        let tracer = PathTracer::new(ctx, &scene, &settings).unwrap();
        let sampler = target_sampler(&scene, &settings).unwrap();
        let n = sampler.params.strata;
        // Each bin once a cycle, then with extra visits from random rows of the 16 pixels.
        let plain =
            gatetrace::gpu::layout::TargetParams { seed: settings.seed, film_first_sample: 123_456, ..sampler.params };
        let extra = 2 * n + 3;
        let shaped = gatetrace::gpu::layout::TargetParams { extra, extra_stride: golden_stride(extra), ..plain };
        let rows = random_rows(n, extra, 16, &mut rng);
        for t in [plain, shaped] {
            let mut resources = tracer.resources().clone();
            let mut params = tracer.wavefront().params;
            params.target_length = t;
            resources.uniform_init(ctx, "params", &params);
            resources.storage_init(ctx, "target_visits", if t.extra > 0 { &rows[..] } else { &[0u32][..] }).unwrap();
            let input: Vec<[f32; 4]> = (0..4096u32)
                .map(|i| [f32::from_bits(i % 16), f32::from_bits(i.wrapping_mul(2_246_822_519) >> 12), 0.0, 0.0])
                .collect();
            let out = common::run_probe_with(
                ctx,
                &resources,
                tracer.constants(),
                "probe_functions",
                &[("FUNCTION", 15.0)],
                &input,
                input.len(),
            );
            for (i, (x, o)) in input.iter().zip(&out).enumerate() {
                let pixel = x[0].to_bits();
                let row = if t.extra > 0 {
                    &rows[(pixel * (n + 1)) as usize..((pixel + 1) * (n + 1)) as usize]
                } else {
                    &[][..]
                };
                let (tau, inv_pdf, bin) = sampler.stratified_sample(&t, row, pixel, x[1].to_bits());
                assert_eq!(o[2] as u32 + t.first_bin, bin, "{gate:?} record {i}: stratum");
                assert!(
                    (o[0] - tau).abs() <= 2.0 * f32::EPSILON * tau,
                    "{gate:?} record {i}: tau GPU {} CPU {tau}",
                    o[0]
                );
                assert_eq!(
                    gate_bin(gate.kind(), &gate.to_gpu(), o[0]),
                    bin as i32,
                    "{gate:?} record {i}: GPU tau {} outside bin {bin}",
                    o[0]
                );
                assert!(
                    (o[1] - inv_pdf).abs() <= 1e-6 * inv_pdf,
                    "{gate:?} record {i}: 1/p GPU {} CPU {inv_pdf}",
                    o[1]
                );
            }
        }
    }
}

#[test]
fn no_path_is_longer_than_the_scenes_path_length_bound() {
    // Random paths of the Cornell box: the lens centre, `bounces` points on random triangles
    // (corners weighted 1000x, where the longest paths turn), a point on the light. Every one is
    // within the bound, and the longest come within a quarter of it (the bound is not loose).
    let scene = common::cornell_box();
    let triangles = &scene.scene.triangles;
    let lights: Vec<_> =
        triangles.iter().filter(|t| scene.scene.materials[t.material as usize].is_emissive()).collect();
    let mut rng = gatetrace::rng::Rng::new(7, 0, 0);
    let point = |t: &gatetrace::scene::SceneTriangle, rng: &mut gatetrace::rng::Rng| {
        if rng.next_f32() < 0.5 {
            return t.positions[(rng.next_f32() * 3.0) as usize % 3];
        }
        let b = gatetrace::sampling::sample_triangle_barycentrics(rng.next_vec2());
        t.positions[0] * (1.0 - b.x - b.y) + t.positions[1] * b.x + t.positions[2] * b.y
    };
    for bounces in 0..6 {
        let (shortest, longest) = scene.scene.path_length_bounds(bounces);
        let mut most = 0f32;
        for _ in 0..20_000 {
            let mut at = scene.scene.camera.position;
            let mut length = 0.0;
            for _ in 0..bounces {
                let t = &triangles[(rng.next_f32() * triangles.len() as f32) as usize % triangles.len()];
                let next = point(t, &mut rng);
                length += at.distance(next);
                at = next;
            }
            let light = lights[(rng.next_f32() * lights.len() as f32) as usize % lights.len()];
            length += at.distance(point(light, &mut rng));
            assert!(length <= longest, "{bounces} bounces: a path of {length} m, bound {longest} m");
            assert!(bounces > 0 || length >= shortest, "a direct path of {length} m, bound {shortest} m");
            most = most.max(length);
        }
        assert!(most > 0.75 * longest, "{bounces} bounces: longest sampled {most} m, bound {longest} m");
    }
}
