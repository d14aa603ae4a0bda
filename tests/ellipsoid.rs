//! The f32 ellipsoid code of the kernels (shaders/lib/ellipsoid.wesl) against the f64 oracle
//! (src/ellipsoid/), CI-sized: random configurations with tight bounds, and every adversarial
//! family (needle-thin spheroids, near-tangent planes, planes through a focus, foci on the plane,
//! sliver triangles, millimetre and kilometre scenes) for finiteness and reported accuracy.
//! `gatetrace stress-ellipsoid` runs the same comparison on a million configurations.

mod common;

use gatetrace::ellipsoid::stress::{Family, Report, compare, generate, run_on_device};

fn run(family: Family, count: usize, seed: u64) -> Report {
    let ctx = common::gpu();
    let configs = generate(family, count, seed);
    let device = run_on_device(&ctx, &configs).unwrap();
    let report = compare(&family.name(), &configs, &device);
    println!("{}", report.row());
    report
}

#[test]
fn generic_configurations_match_the_oracle() {
    println!("{}", Report::header());
    for family in [Family::Random, Family::Scaled(1e-3), Family::Scaled(1e3)] {
        let r = run(family, 20_000, 1);
        assert_eq!(r.non_finite, 0, "{}: non-finite outputs", r.family);
        assert!(r.cut > 10_000, "{}: only {} sections", r.family, r.cut);
        // Validity can differ only where g is within rounding of 0.
        assert!(r.validity_mismatches <= r.configs / 1000, "{}: {} validity mismatches", r.family, r.validity_mismatches);
        assert!(r.theta_total_error.quantile(0.99) < 1e-4, "{}: Theta p99 {}", r.family, r.theta_total_error.quantile(0.99));
        assert!(r.length_error.quantile(0.99) < 1e-6, "{}: |L - tau|/tau p99 {}", r.family, r.length_error.quantile(0.99));
        assert!(r.jacobian_error.quantile(0.99) < 1e-4, "{}: J p99 {}", r.family, r.jacobian_error.quantile(0.99));
        assert!(r.jacobian_error.quantile(0.5) < 1e-6, "{}: J median {}", r.family, r.jacobian_error.quantile(0.5));
    }
}

#[test]
fn adversarial_configurations_stay_finite() {
    println!("{}", Report::header());
    for family in Family::all() {
        let r = run(family, 4_000, 2);
        assert_eq!(r.non_finite, 0, "{}: non-finite outputs", r.family);
        assert!(r.cut > 0, "{}: no section at all", r.family);
    }
}

