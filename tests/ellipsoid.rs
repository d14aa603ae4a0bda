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


/// Sum of Theta over every triangle of the scene (f64 oracle, brute force) and each triangle's.
fn oracle_thetas(scene: &gatetrace::scene::PreparedScene, fs: glam::Vec3, fc: glam::Vec3, tau_e: f32) -> Vec<f64> {
    use gatetrace::ellipsoid::{Spheroid, Triangle, clip_arcs};
    let sp = Spheroid { focus_s: fs.as_dvec3(), focus_c: fc.as_dvec3(), length: tau_e as f64 };
    scene
        .triangles
        .iter()
        .map(|t| {
            let v0 = t.v0.as_dvec3();
            let (e1, e2) = (t.e1.as_dvec3(), t.e2.as_dvec3());
            let tri = Triangle { vertices: [v0, v0 + e1, v0 + e2] };
            match sp.section(v0, e1.cross(e2).normalize()) {
                Some(sec) => clip_arcs(&sec, &tri).total,
                None => 0.0,
            }
        })
        .collect()
}

/// Runs `probe_ellipsoid_query`: (triangle, sum of Theta, theta, J, point, nodes visited).
fn run_queries(
    ctx: &gatetrace::gpu::GpuContext,
    tracer: &gatetrace::integrator::PathTracer,
    queries: &[(glam::Vec3, glam::Vec3, f32, f32, [u32; 3])],
) -> Vec<(u32, f32, f32, f32, glam::Vec3, u32)> {
    let input: Vec<[f32; 4]> = queries
        .iter()
        .flat_map(|(fs, fc, tau, u, key)| {
            [[fs.x, fs.y, fs.z, *tau], [fc.x, fc.y, fc.z, *u], [f32::from_bits(key[0]), f32::from_bits(key[1]), f32::from_bits(key[2]), 0.0]]
        })
        .collect();
    let out = common::run_probe(ctx, tracer, "probe_ellipsoid_query", &[], &input, 2 * queries.len());
    out.chunks(2)
        .map(|o| (o[0][0].to_bits(), o[0][1], o[0][2], o[0][3], glam::Vec3::new(o[1][0], o[1][1], o[1][2]), o[1][3].to_bits()))
        .collect()
}

#[test]
fn bvh_queries_find_every_intersected_triangle() {
    // The sum of Theta found by the pruned BVH traversal equals the brute-force sum over every
    // triangle (pruning never drops a triangle the spheroid cuts), the picked triangle is cut,
    // and the sampled point lies on the spheroid.
    use gatetrace::integrator::{PathTracer, RenderSettings};
    let ctx = common::gpu();
    let mut rng = gatetrace::rng::Rng::new(3, 0, 0);
    for (name, scene) in [("cornell box", common::cornell_box()), ("soup", common::soup_scene(2000, 12, "query_soup"))] {
        let tracer = PathTracer::new(&ctx, &scene, &RenderSettings { width: 4, height: 4, ..Default::default() }).unwrap();
        let mut v = || glam::Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5;
        let queries: Vec<_> = (0..400u32)
            .map(|i| {
                let (fs, fc) = (v() * 0.98, v() * 0.98);
                let extra = 0.02 + 1.5 * v().x.abs();
                (fs, fc, fs.distance(fc) + extra, v().y + 0.5, [i, 17, 23])
            })
            .collect();
        let results = run_queries(&ctx, &tracer, &queries);
        let (mut cut, mut nodes) = (0, 0u64);
        for ((fs, fc, tau, _, _), &(tri, total, _, _, point, visited)) in queries.iter().zip(&results) {
            let thetas = oracle_thetas(&scene, *fs, *fc, *tau);
            let expected: f64 = thetas.iter().sum();
            nodes += visited as u64;
            assert!(
                (total as f64 - expected).abs() <= 1e-4 * expected + 1e-4,
                "{name}: sum of Theta {total} vs oracle {expected} ({} triangles cut, {visited} nodes visited)",
                thetas.iter().filter(|&&t| t > 0.0).count()
            );
            if expected > 1e-3 {
                cut += 1;
                assert_ne!(tri, gatetrace::gpu::layout::NONE, "{name}: no triangle picked (oracle sum {expected})");
                assert!(thetas[tri as usize] > 0.0, "{name}: picked triangle {tri} is not cut");
                let l = point.distance(*fs) + point.distance(*fc);
                assert!((l - tau).abs() < 1e-5 * tau, "{name}: sampled point has L = {l}, tau_e = {tau}");
            }
        }
        println!("{name}: {cut} of {} queries cut the scene; {:.1} nodes visited per query of {}", queries.len(), nodes as f64 / queries.len() as f64, scene.bvh.nodes.len());
        assert!(cut > 100);
        use gatetrace::integrator::Integrator;
        assert_eq!(tracer.truncated_traversals().unwrap(), 0, "{name}: queries ran out of the device's loop budget");
    }
}

#[test]
fn reservoir_picks_triangles_in_proportion_to_their_arcs() {
    use common::stats::chi2_test;
    use gatetrace::integrator::{PathTracer, RenderSettings};
    let ctx = common::gpu();
    let scene = common::soup_scene(2000, 12, "reservoir_soup");
    let tracer = PathTracer::new(&ctx, &scene, &RenderSettings { width: 4, height: 4, ..Default::default() }).unwrap();
    let (fs, fc, tau) = (glam::Vec3::new(-0.2, 0.1, 0.0), glam::Vec3::new(0.25, -0.1, 0.1), 0.9f32);
    let n = 40_000u32;
    let queries: Vec<_> = (0..n).map(|i| (fs, fc, tau, 0.5, [i, 99, 7])).collect();
    let results = run_queries(&ctx, &tracer, &queries);
    let thetas = oracle_thetas(&scene, fs, fc, tau);
    let total: f64 = thetas.iter().sum();
    let mut observed = vec![0.0; thetas.len()];
    for r in &results {
        observed[r.0 as usize] += 1.0;
    }
    let expected: Vec<f64> = thetas.iter().map(|t| n as f64 * t / total).collect();
    let cut = thetas.iter().filter(|&&t| t > 0.0).count();
    let (stat, dof, p) = chi2_test(&observed, &expected);
    println!("{cut} triangles cut; chi2 {stat:.1}, dof {dof}, p {p:.3}");
    assert!(cut > 20, "the test spheroid should cut many triangles ({cut})");
    assert!(p > 0.01, "picks do not follow Theta_i / sum Theta: chi2 {stat:.1}, dof {dof}, p {p:.2e}");
}
