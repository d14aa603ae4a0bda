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
    let device = run_on_device(ctx, &configs).unwrap();
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
        assert!(
            r.validity_mismatches <= r.configs / 1000,
            "{}: {} validity mismatches",
            r.family,
            r.validity_mismatches
        );
        assert!(
            r.theta_total_error.quantile(0.99) < 1e-4,
            "{}: Theta p99 {}",
            r.family,
            r.theta_total_error.quantile(0.99)
        );
        assert!(
            r.length_error.quantile(0.99) < 1e-6,
            "{}: |L - tau|/tau p99 {}",
            r.family,
            r.length_error.quantile(0.99)
        );
        assert!(r.jacobian_error.quantile(0.99) < 1e-4, "{}: J p99 {}", r.family, r.jacobian_error.quantile(0.99));
        assert!(r.jacobian_error.quantile(0.5) < 1e-6, "{}: J median {}", r.family, r.jacobian_error.quantile(0.5));
    }
}

#[test]
fn sliver_triangles_are_as_accurate_as_random_ones() {
    // Slivers (height / base 1e-6 .. 1e-2) get their plane's normal from the host's f64 cross
    // product, as every triangle of a scene does: their Jacobian errs no more than a random
    // triangle's (in an f32 cross product of nearly parallel edges it erred by up to 13 %).
    println!("{}", Report::header());
    let random = run(Family::Random, 50_000, 7);
    let sliver = run(Family::Sliver, 50_000, 7);
    assert_eq!(sliver.non_finite, 0);
    let (r99, s99) = (random.jacobian_error.quantile(0.99), sliver.jacobian_error.quantile(0.99));
    assert!(s99 < 2.0 * r99, "sliver J p99 {s99:.2e} against random {r99:.2e}");
    assert!(sliver.jacobian_error.quantile(1.0) < 1e-4, "sliver J max {:.2e}", sliver.jacobian_error.quantile(1.0));
}

#[test]
fn sections_near_tangency_and_of_needle_spheroids_are_resolved() {
    // Planes within 1e-8 .. 1e-2 a of tangency (arrival onsets) and spheroids with tau_e - d
    // down to 1e-7 d: sample_on_triangle's section (exact polynomials in double-f32) against
    // the oracle on the triangle as the device holds it. In f32 these had Theta p99 8e-2 (up
    // to 0.8 for the needles), J max 1.3e-3, and 6 % of near-tangent planes cut or missed
    // wrongly.
    println!("{}", Report::header());
    let mut families = vec![Family::NearTangent];
    families.extend([1e-4, 1e-6, 1e-7].map(Family::NearDegenerate));
    for family in families {
        let r = run(family, 20_000, 3);
        assert_eq!(r.non_finite, 0, "{}: non-finite outputs", r.family);
        assert_eq!(r.validity_mismatches, 0, "{}: validity mismatches", r.family);
        assert!(r.cut > 15_000, "{}: only {} sections", r.family, r.cut);
        let (theta99, jmax) = (r.theta_total_error.quantile(0.99), r.jacobian_error.quantile(1.0));
        assert!(theta99 <= 1e-4, "{}: Theta p99 {theta99:.2e}", r.family);
        assert!(jmax <= 1e-4, "{}: J max {jmax:.2e}", r.family);
        assert!(
            r.length_error.quantile(0.99) < 1e-6,
            "{}: |L - tau|/tau p99 {:.2e}",
            r.family,
            r.length_error.quantile(0.99)
        );
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

/// The exhaustive query (every node the spheroid may touch, no allowance), as probe constants.
const EXHAUSTIVE: &[(&str, f64)] = &[("QUERY_SPLIT", 0.0), ("QUERY_ALLOWANCE", u32::MAX as f64)];
/// The exhaustive query with picks weighed by arcs times the reflection factor (render
/// --query-weights reflection).
const EXHAUSTIVE_REFLECTION: &[(&str, f64)] =
    &[("QUERY_SPLIT", 0.0), ("QUERY_ALLOWANCE", u32::MAX as f64), ("QUERY_REFLECTION_WEIGHTS", 1.0)];

/// Runs `probe_ellipsoid_query` with the default query settings: (triangle, the sample's weight
/// in (triangle, theta), theta, J, point, loop iterations).
fn run_queries(
    ctx: &gatetrace::gpu::GpuContext,
    tracer: &gatetrace::integrator::PathTracer,
    queries: &[(glam::Vec3, glam::Vec3, f32, f32, [u32; 3])],
) -> Vec<(u32, f32, f32, f32, glam::Vec3, u32)> {
    run_queries_with(ctx, tracer, &[], queries)
}

/// `run_queries` with the probe specialised by `constants` (QUERY_SPLIT, QUERY_ALLOWANCE, ...).
fn run_queries_with(
    ctx: &gatetrace::gpu::GpuContext,
    tracer: &gatetrace::integrator::PathTracer,
    constants: &[(&'static str, f64)],
    queries: &[(glam::Vec3, glam::Vec3, f32, f32, [u32; 3])],
) -> Vec<(u32, f32, f32, f32, glam::Vec3, u32)> {
    let input: Vec<[f32; 4]> = queries
        .iter()
        .flat_map(|(fs, fc, tau, u, key)| {
            [
                [fs.x, fs.y, fs.z, *tau],
                [fc.x, fc.y, fc.z, *u],
                [f32::from_bits(key[0]), f32::from_bits(key[1]), f32::from_bits(key[2]), 0.0],
            ]
        })
        .collect();
    let out = common::run_probe(ctx, tracer, "probe_ellipsoid_query", constants, &input, 2 * queries.len());
    out.chunks(2)
        .map(|o| {
            (
                o[0][0].to_bits(),
                o[0][1],
                o[0][2],
                o[0][3],
                glam::Vec3::new(o[1][0], o[1][1], o[1][2]),
                o[1][3].to_bits(),
            )
        })
        .collect()
}

#[test]
fn bvh_queries_find_every_intersected_triangle() {
    // The exhaustive query: the sum of Theta found by the pruned BVH traversal equals the
    // brute-force sum over every triangle (pruning never drops a triangle the spheroid cuts), the
    // picked triangle is cut, and the sampled point lies on the spheroid.
    use gatetrace::integrator::{PathTracer, RenderSettings};
    let ctx = common::gpu();
    let mut rng = gatetrace::rng::Rng::new(3, 0, 0);
    for (name, scene) in [("cornell box", common::cornell_box()), ("soup", common::soup_scene(2000, 12, "query_soup"))]
    {
        let tracer =
            PathTracer::new(ctx, &scene, &RenderSettings { width: 4, height: 4, ..Default::default() }).unwrap();
        let mut v = || glam::Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5;
        let queries: Vec<_> = (0..400u32)
            .map(|i| {
                let (fs, fc) = (v() * 0.98, v() * 0.98);
                let extra = 0.02 + 1.5 * v().x.abs();
                (fs, fc, fs.distance(fc) + extra, v().y + 0.5, [i, 17, 23])
            })
            .collect();
        let results = run_queries_with(ctx, &tracer, EXHAUSTIVE, &queries);
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
        println!(
            "{name}: {cut} of {} queries cut the scene; {:.1} nodes visited per query of {}",
            queries.len(),
            nodes as f64 / queries.len() as f64,
            scene.bvh.nodes.len()
        );
        assert!(cut > 100);
        use gatetrace::integrator::Integrator;
        assert_eq!(tracer.truncated_traversals().unwrap(), 0, "{name}: queries ran out of the device's loop budget");
    }
}

/// Runs 40,000 exhaustive queries (`constants`) of one spheroid on a 2000-triangle soup and
/// checks with a chi-square test that they pick triangle i with probability q_i / sum q,
/// q_i = Theta_i times `factor(i)`; returns the triangles with q > 0.
fn check_picks(
    constants: &[(&'static str, f64)],
    factor: impl Fn(&gatetrace::scene::PreparedScene, usize) -> f64,
) -> usize {
    use common::stats::chi2_test;
    use gatetrace::integrator::{PathTracer, RenderSettings};
    let ctx = common::gpu();
    let scene = common::soup_scene(2000, 12, "reservoir_soup");
    let tracer = PathTracer::new(ctx, &scene, &RenderSettings { width: 4, height: 4, ..Default::default() }).unwrap();
    let (fs, fc, tau) = (glam::Vec3::new(-0.2, 0.1, 0.0), glam::Vec3::new(0.25, -0.1, 0.1), 0.9f32);
    let n = 40_000u32;
    let queries: Vec<_> = (0..n).map(|i| (fs, fc, tau, 0.5, [i, 99, 7])).collect();
    let results = run_queries_with(ctx, &tracer, constants, &queries);
    let weights: Vec<f64> =
        oracle_thetas(&scene, fs, fc, tau).iter().enumerate().map(|(i, theta)| theta * factor(&scene, i)).collect();
    let total: f64 = weights.iter().sum();
    let mut observed = vec![0.0; weights.len()];
    for r in &results {
        observed[r.0 as usize] += 1.0;
    }
    let expected: Vec<f64> = weights.iter().map(|w| n as f64 * w / total).collect();
    let cut = weights.iter().filter(|&&w| w > 0.0).count();
    let (stat, dof, p) = chi2_test(&observed, &expected);
    println!("{cut} triangles with weight; chi2 {stat:.1}, dof {dof}, p {p:.3}");
    assert!(p > 0.01, "picks do not follow q_i / sum q: chi2 {stat:.1}, dof {dof}, p {p:.2e}");
    cut
}

#[test]
fn reservoir_picks_triangles_in_proportion_to_their_arcs() {
    // By default the exhaustive query picks triangle i with probability Theta_i / sum Theta.
    let cut = check_picks(EXHAUSTIVE, |_, _| 1.0);
    assert!(cut > 20, "the test spheroid should cut many triangles ({cut})");
}

#[test]
fn reservoir_picks_follow_arcs_times_the_reflection_factor() {
    // With reflection weights they are Theta_i times the reflection factor (src/ellipsoid/query.rs,
    // f64 here): zero for triangles whose plane separates the foci, so the soup's picks fall
    // only on triangles that can reflect between them.
    use gatetrace::ellipsoid::query::{Query, reflection_factor};
    let query = Query {
        focus_s: glam::DVec3::new(-0.2, 0.1, 0.0),
        focus_c: glam::DVec3::new(0.25, -0.1, 0.1),
        tau_e: 0.9f32 as f64,
        ignore: [gatetrace::gpu::layout::NONE; 2],
        lights_only: false,
        reach: [glam::DVec4::ZERO; 2],
    };
    let cut = check_picks(EXHAUSTIVE_REFLECTION, |scene, i| {
        let t = &scene.triangles[i];
        let v0 = t.v0.as_dvec3();
        let tri = gatetrace::ellipsoid::Triangle { vertices: [v0, v0 + t.e1.as_dvec3(), v0 + t.e2.as_dvec3()] };
        reflection_factor(&query, &tri, &scene.materials[t.material as usize])
    });
    assert!(cut > 10, "the test spheroid should cut many triangles that reflect between its foci ({cut})");
}

/// The integrand of the quad test: the geometry terms of a one-bounce path x_s -> x -> x_c over
/// the quad z = 0 facing +z, f(x) = cos_s cos_c / (|x - x_s|^2 |x - x_c|^2) (point light at x_s,
/// pinhole at x_c, Lambertian constants left out).
fn quad_integrand(x: glam::DVec3, fs: glam::DVec3, fc: glam::DVec3) -> f64 {
    let (ds, dc) = (fs - x, fc - x);
    ds.z.max(0.0) * dc.z.max(0.0) / (ds.length().powi(3) * dc.length().powi(3))
}

/// Integral of f over the part of the quad [-0.5, 0.5]^2 with path length in [a, b), by area
/// sampling: 8 independent jittered 1000 x 1000 grids; returns the mean and its standard error.
fn quad_area_integral(fs: glam::DVec3, fc: glam::DVec3, a: f64, b: f64) -> (f64, f64) {
    let n = 1000;
    let h = 1.0 / n as f64;
    let mut rng = gatetrace::rng::Rng::new(77, 1, 2);
    let estimates: Vec<f64> = (0..8)
        .map(|_| {
            let mut sum = 0.0;
            for i in 0..n {
                for j in 0..n {
                    let (u, v) = (rng.next_f32() as f64, rng.next_f32() as f64);
                    let x = glam::DVec3::new(-0.5 + (i as f64 + u) * h, -0.5 + (j as f64 + v) * h, 0.0);
                    let l = x.distance(fs) + x.distance(fc);
                    if l >= a && l < b {
                        sum += quad_integrand(x, fs, fc);
                    }
                }
            }
            sum * h * h
        })
        .collect();
    mean_and_error(&estimates)
}

/// Mean and standard error of `values`.
fn mean_and_error(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

#[test]
fn ellipsoidal_vertex_sampling_agrees_with_area_sampling() {
    // A quad lit by a point light at x_s, seen from a pinhole at x_c, behind a box gate [a, b):
    // sampling tau uniformly in [a, b), then a point on the spheroid's intersection with the quad
    // (triangle by Theta, theta uniform), the estimate f(x) J sum(Theta) (b - a) is unbiased for
    // the integral of f over the quad's points with path length in [a, b). Checked with the f64
    // oracle and with the device's query (f32), against area sampling.
    use common::gltf_builder::{Camera, Material, Scene, quad_z};
    use gatetrace::ellipsoid::{Spheroid, Triangle, clip_arcs};
    use gatetrace::integrator::{PathTracer, RenderSettings};
    use glam::DVec3;
    let (fs, fc) = (DVec3::new(0.1, 0.2, 0.6), DVec3::new(-0.2, 0.1, 0.8));
    let shortest = (0..=200)
        .flat_map(|i| (0..=200).map(move |j| DVec3::new(-0.5 + i as f64 / 200.0, -0.5 + j as f64 / 200.0, 0.0)))
        .map(|x| x.distance(fs) + x.distance(fc))
        .fold(f64::INFINITY, f64::min);
    let ctx = common::gpu();
    let gltf = Scene {
        meshes: vec![quad_z(0.5, 0.0, true, 0), quad_z(0.05, 5.0, false, 1)],
        materials: vec![Material::diffuse([0.5; 3]), Material::emitter(1.0)],
        camera: Some(Camera { position: [-0.2, 0.1, 0.8], rotation: [0.0, 0.0, 0.0, 1.0], yfov: 0.8 }),
        point_lights: vec![],
    };
    let scene = gatetrace::scene::PreparedScene::new(
        gatetrace::scene::load_gltf(&gltf.write(&common::scratch_dir("ellipsoid_quad"), "quad.gltf")).unwrap(),
    )
    .unwrap();
    let tracer = PathTracer::new(ctx, &scene, &RenderSettings { width: 4, height: 4, ..Default::default() }).unwrap();
    // The quad's two triangles (the emitter far above is never reached by these spheroids).
    let quad: Vec<Triangle> = scene.triangles[..]
        .iter()
        .filter(|t| t.v0.z == 0.0)
        .map(|t| {
            let v0 = t.v0.as_dvec3();
            Triangle { vertices: [v0, v0 + t.e1.as_dvec3(), v0 + t.e2.as_dvec3()] }
        })
        .collect();
    assert_eq!(quad.len(), 2);
    let mut rng = gatetrace::rng::Rng::new(5, 0, 0);
    for (a, b) in [(shortest + 0.05, shortest + 0.0575), (shortest + 0.1, shortest + 0.6)] {
        let (reference, reference_error) = quad_area_integral(fs, fc, a, b);
        let n = 40_000;
        let taus: Vec<f64> = (0..n).map(|_| a + (b - a) * rng.next_f32() as f64).collect();
        let us: Vec<(f64, f64)> = (0..n).map(|_| (rng.next_f32() as f64, rng.next_f32() as f64)).collect();
        // f64 oracle: brute force over the quad's triangles.
        let oracle: Vec<f64> = taus
            .iter()
            .zip(&us)
            .map(|(&tau, &(u_pick, _))| {
                let sp = Spheroid { focus_s: fs, focus_c: fc, length: tau };
                let found: Vec<_> = quad
                    .iter()
                    .filter_map(|t| sp.section(t.vertices[0], t.normal()).map(|s| (s, clip_arcs(&s, t))))
                    .filter(|(_, arcs)| arcs.total > 0.0)
                    .collect();
                let total: f64 = found.iter().map(|(_, arcs)| arcs.total).sum();
                let mut pick = u_pick * total;
                for (sec, arcs) in &found {
                    if pick < arcs.total {
                        let theta = arcs.sample(pick / arcs.total);
                        let x = sec.point(theta);
                        return quad_integrand(x, fs, fc) * sec.jacobian(theta) * total * (b - a);
                    }
                    pick -= arcs.total;
                }
                0.0
            })
            .collect();
        // The device's query.
        let queries: Vec<_> = taus
            .iter()
            .zip(&us)
            .enumerate()
            .map(|(i, (&tau, &(_, u_theta)))| {
                (fs.as_vec3(), fc.as_vec3(), tau as f32, u_theta as f32, [i as u32, 5, 6])
            })
            .collect();
        let device: Vec<f64> = run_queries(ctx, &tracer, &queries)
            .iter()
            .map(|&(tri, total, _, j, x, _)| {
                if tri == gatetrace::gpu::layout::NONE {
                    return 0.0;
                }
                quad_integrand(x.as_dvec3(), fs, fc) * j as f64 * total as f64 * (b - a)
            })
            .collect();
        for (name, values) in [("oracle", &oracle), ("device", &device)] {
            let (mean, error) = mean_and_error(values);
            let z = (mean - reference) / (error * error + reference_error * reference_error).sqrt();
            println!(
                "gate [{a:.4}, {b:.4}): {name} {mean:.6e} +- {error:.1e}, area sampling {reference:.6e} +- {reference_error:.1e}, z {z:+.2}"
            );
            assert!(z.abs() < 4.0, "{name}: {mean} +- {error} vs area sampling {reference} (z = {z:.2})");
        }
    }
}
