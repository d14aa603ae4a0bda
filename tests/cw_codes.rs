//! Continuous-wave codes (`cw:FREQ_HZ,PHASE_DEG,CODE` gates) against numerical integration of
//! a transient render: the path tracer draws the same paths whatever the gate, so a code-gated
//! image equals the transient of the same seed with each bin weighed by the code's mean over
//! it, up to the code's change within a bin (its largest slope times the bin width, per unit of
//! the steady image) and f32 rounding. Every code is tested at two phases.

mod common;

use gatetrace::film::{CwCode, Gate};
use gatetrace::integrator::{Method, RenderSettings};
use gatetrace::units::SPEED_OF_LIGHT;

/// Integral of a code's period (`CwCode::breakpoints`) from phase 0 to x (periods, any x >= 0).
fn code_integral(points: &[(f64, f64)], x: f64) -> f64 {
    let trapezoid = |a: (f64, f64), b: (f64, f64), end: f64| {
        let end = end.clamp(a.0, b.0);
        if b.0 <= a.0 {
            return 0.0;
        }
        let at_end = a.1 + (b.1 - a.1) * (end - a.0) / (b.0 - a.0);
        0.5 * (a.1 + at_end) * (end - a.0)
    };
    let period: f64 = points.windows(2).map(|w| trapezoid(w[0], w[1], w[1].0)).sum();
    let whole = x.floor();
    whole * period + points.windows(2).map(|w| trapezoid(w[0], w[1], x - whole)).sum::<f64>()
}

#[test]
fn cw_codes_weigh_paths_as_their_integrated_transient() {
    let scene = common::cornell_box();
    let ctx = common::gpu();
    let bounces = 3;
    let longest = scene.scene.path_length_bounds(bounces).1 as f64;
    // Bins of 0.1 mm over every path length the scene allows with 3 bounces.
    let width = 1e-4;
    let bins = ((longest + 0.01) / width).ceil() as u32;
    let base = RenderSettings {
        width: 4,
        height: 4,
        max_bounces: bounces,
        method: Method::Path,
        seed: 17,
        ..Default::default()
    };
    let spp = 64;
    let render =
        |gate: Gate| common::render_films(ctx, &scene, &RenderSettings { gate, ..base.clone() }, 1, spp).remove(0);
    let transient = render(Gate::Transient { start: 0.0, width, bins });
    let pixels = 16;
    let bins = bins as usize;
    let mut steady = vec![0.0f64; pixels * 3];
    for (i, v) in transient.data.iter().enumerate() {
        steady[(i / (3 * bins)) * 3 + i % 3] += *v as f64;
    }
    assert!(steady.iter().all(|&s| s > 0.0), "every pixel sees light");
    let codes = [
        CwCode::Square,
        CwCode::Hamiltonian3,
        CwCode::Hamiltonian4(1),
        CwCode::Hamiltonian4(2),
        CwCode::Hamiltonian4(3),
        CwCode::Hamiltonian4(4),
        CwCode::MSequence { chips: 31 },
        CwCode::DepthSelective { chips: 32, neighbours: 3 },
    ];
    for code in codes {
        for (frequency_hz, phase_deg) in [(300e6, 0.0), (450e6, 137.0)] {
            let gate = Gate::CwCode { frequency_hz, phase_deg, code };
            let coded = render(gate.clone());
            let points = code.breakpoints();
            let per_metre = frequency_hz / SPEED_OF_LIGHT;
            let phase = phase_deg / 360.0;
            // The code's mean over each bin.
            let means: Vec<f64> = (0..bins)
                .map(|b| {
                    let (x0, x1) =
                        ((b as f64 * width) * per_metre + phase, ((b + 1) as f64 * width) * per_metre + phase);
                    (code_integral(&points, x1) - code_integral(&points, x0)) / (x1 - x0)
                })
                .collect();
            let within_bin = code.steepest_slope() * per_metre * width;
            let mut worst = 0.0f64;
            let mut spread = 0.0f64;
            for p in 0..pixels {
                for c in 0..3 {
                    let integrated: f64 =
                        (0..bins).map(|b| transient.data[(p * bins + b) * 3 + c] as f64 * means[b]).sum();
                    let s = steady[p * 3 + c];
                    let ours = coded.data[p * 3 + c] as f64;
                    let bound = (within_bin + 1e-4) * s;
                    worst = worst.max((ours - integrated).abs() / bound);
                    spread = spread.max((ours / s - integrated / s).abs().max((ours / s - 1.0).abs()));
                    assert!(
                        (ours - integrated).abs() <= bound,
                        "{}: pixel {p} channel {c}: {ours:.6e} vs the integrated transient {integrated:.6e} (bound {bound:.2e})",
                        gate.describe()
                    );
                }
            }
            println!("{}: largest difference {worst:.3} of its bound", gate.describe());
            // The bound must be small against what the code does to the image.
            assert!(within_bin + 1e-4 < 0.02, "{}: bins too wide for the code", gate.describe());
            assert!(spread > 0.05, "{}: the code leaves the image as the steady state", gate.describe());
        }
    }
}
