//! The ellipsoid query's stochastic descent (shaders/lib/ellipsoid_query.wesl, CPU twin
//! src/ellipsoid/query.rs) is unbiased: a triangle reached with probability P enters with
//! weight q / P, so averaged over the query's random numbers every triangle's weight must come
//! to its q (the arcs' total angle times the reflection factor), and the picks weighted by the
//! query's total W must come to the same. Checked on the twin against brute force, and on the device (f32) against the
//! f64 oracle, with the default settings and with an allowance so small that most queries end
//! in the final descent over the rest of the tree. Tolerances come from the variance measured
//! over the keys (z-scores, Sidak-corrected at a family-wise alpha of 0.01).

mod common;

use gatetrace::ellipsoid::query::{Query, QueryScene, arc_weight, pick, reached, reflection_factor};
use gatetrace::ellipsoid::{Spheroid, Triangle, clip_arcs};
use gatetrace::gpu::layout::NONE;
use gatetrace::integrator::QuerySettings;
use glam::{DVec3, DVec4, Vec3};

const ALPHA: f64 = 0.01;
/// The default query with reflection weights (as NLOS captures use), which the checks below
/// test; with arcs alone the weights are the factor-free special case (tests/ellipsoid.rs).
const REFLECTION: QuerySettings =
    QuerySettings { split: 1.0, bottom_nodes: 31, allowance: 4096, reflection_weights: true, wide: false };
/// Triangles are compared in groups of consecutive BVH positions.
const GROUPS: usize = 12;

fn oracle_triangle(t: &gatetrace::gpu::layout::Triangle) -> Triangle {
    let v0 = t.v0.as_dvec3();
    Triangle { vertices: [v0, v0 + t.e1.as_dvec3(), v0 + t.e2.as_dvec3()] }
}

/// Every triangle's exact arcs' angle and reflection factor in a query for reflecting vertices
/// (f64 oracle, brute force): the reservoir weight is their product.
fn exact_arcs_and_factors(
    scene: &gatetrace::scene::PreparedScene,
    fs: DVec3,
    fc: DVec3,
    tau_e: f64,
) -> Vec<(f64, f64)> {
    let sp = Spheroid { focus_s: fs, focus_c: fc, length: tau_e };
    let query =
        Query { focus_s: fs, focus_c: fc, tau_e, ignore: [NONE; 2], lights_only: false, reach: [DVec4::ZERO; 2] };
    scene
        .triangles
        .iter()
        .map(|t| {
            let tri = oracle_triangle(t);
            let arcs = sp.section(tri.vertices[0], tri.normal()).map_or(0.0, |s| clip_arcs(&s, &tri).total);
            (arcs, reflection_factor(&query, &tri, &scene.materials[t.material as usize]))
        })
        .collect()
}

/// The reservoir weights q = arcs x factor (what the twin's weights and W x pick come to).
fn exact_weights(scene: &gatetrace::scene::PreparedScene, fs: DVec3, fc: DVec3, tau_e: f64) -> Vec<f64> {
    exact_arcs_and_factors(scene, fs, fc, tau_e).iter().map(|(arcs, factor)| arcs * factor).collect()
}

/// The arcs where the picks' density is positive (factor > 0): what a pick's weight, the
/// inverse of its density in (triangle, theta), comes to.
fn exact_sampled_arcs(scene: &gatetrace::scene::PreparedScene, fs: DVec3, fc: DVec3, tau_e: f64) -> Vec<f64> {
    exact_arcs_and_factors(scene, fs, fc, tau_e)
        .iter()
        .map(|&(arcs, factor)| if factor > 0.0 { arcs } else { 0.0 })
        .collect()
}

/// Spheroids like a render's: foci at the light's centre, the pinhole and points on the sphere
/// and the walls, with tau_e from 5 cm to 1.2 m beyond the foci's distance.
fn spheroids(scene: &gatetrace::scene::PreparedScene) -> Vec<(DVec3, DVec3, f64)> {
    let light = DVec3::new(0.0, 0.499, 0.0);
    let camera = DVec3::new(0.0, 0.0, 2.0);
    let sphere_top = DVec3::new(0.01, -0.2 + 0.25, -0.05);
    let floor = DVec3::new(-0.3, -0.5, 0.2);
    let back = DVec3::new(0.2, 0.1, -0.5);
    let _ = scene;
    vec![
        (light, camera, light.distance(camera) + 1.1),
        (light, floor, light.distance(floor) + 0.3),
        (sphere_top, camera, sphere_top.distance(camera) + 0.6),
        (back, sphere_top, back.distance(sphere_top) + 0.05),
    ]
}

/// z-scores of the groups' mean weights against their exact sums: `samples[k][g]` is the
/// weight sample k puts on group g. The error adds to the standard error of the mean the
/// rounding `relative` x exact of the arcs themselves (groups near the root are reached with
/// probability one, and their weights do not vary at all). Picks are rare events where weights
/// span orders of magnitude (a group of small weight is picked seldom, with a large weight), so
/// their sample variance can fall far below the true one; `second_moments` (per group, when
/// given) holds E[sample^2] from the estimator's own formula, and the variance used is the
/// larger of the two.
fn group_z(samples: &[Vec<f64>], exact: &[f64], relative: f64, second_moments: Option<&[f64]>) -> Vec<f64> {
    let n = samples.len() as f64;
    (0..exact.len())
        .map(|g| {
            let mean = samples.iter().map(|s| s[g]).sum::<f64>() / n;
            let mut var = samples.iter().map(|s| (s[g] - mean).powi(2)).sum::<f64>() / (n - 1.0);
            if let Some(m2) = second_moments {
                var = var.max(m2[g] - exact[g] * exact[g]);
            }
            let error = (var / n + (relative * exact[g]).powi(2)).sqrt();
            if error == 0.0 {
                // Never reached: only right when nothing is there.
                if mean == 0.0 { 0.0 } else { f64::INFINITY }
            } else {
                (mean - exact[g]) / error
            }
        })
        .collect()
}

fn group_of(position: u32, triangles: usize) -> usize {
    (position as usize * GROUPS / triangles).min(GROUPS - 1)
}

/// Sums of `values` (per triangle) over the groups.
fn grouped(values: &[f64]) -> Vec<f64> {
    let mut sums = vec![0.0; GROUPS];
    for (i, v) in values.iter().enumerate() {
        sums[group_of(i as u32, values.len())] += v;
    }
    sums
}

#[test]
fn arc_weights_from_circular_intervals_equal_the_clipped_arcs() {
    // The reservoir weight q (three edges' circular intervals intersected, no break points)
    // against clip_arcs' total, in f64 on the stress test's families.
    use gatetrace::ellipsoid::stress::{Family, generate};
    let mut worst = 0.0f64;
    let mut cut = 0;
    for family in [Family::Random, Family::Sliver, Family::PlaneThroughFocus, Family::NearTangent] {
        for c in generate(family, 20_000, 9) {
            let sp = Spheroid { focus_s: c.focus_s.as_dvec3(), focus_c: c.focus_c.as_dvec3(), length: c.tau_e as f64 };
            let tri = Triangle { vertices: c.triangle.map(|v| v.as_dvec3()) };
            let arcs = sp.section(tri.vertices[0], tri.normal()).map_or(0.0, |s| clip_arcs(&s, &tri).total);
            let q = arc_weight(&sp, &tri);
            cut += (arcs > 0.0) as usize;
            worst = worst.max((q - arcs).abs());
        }
    }
    println!("{cut} sections with arcs; largest |q - Theta| {worst:.2e} rad");
    assert!(cut > 20_000);
    assert!(worst < 1e-9, "interval form differs from clip_arcs by {worst:.2e} rad");
}

/// Runs the CPU twin `keys` times on each spheroid and checks every group's mean weight, and
/// the mean of W x [pick in group], against the brute-force sums.
fn check_twin(settings: &QuerySettings, allowance: u32, keys: u32) {
    let scene = common::sphere_scene(16);
    let view = QueryScene::of(&scene);
    let spheroids = spheroids(&scene);
    let tests = spheroids.len() * 2 * GROUPS;
    let limit = common::stats::t_critical(common::stats::sidak(ALPHA, tests), keys as f64 - 1.0);
    let (mut rest_used, mut total_iterations) = (0, 0u64);
    for (s, &(fs, fc, tau_e)) in spheroids.iter().enumerate() {
        let exact = grouped(&exact_weights(&scene, fs, fc, tau_e));
        let query =
            Query { focus_s: fs, focus_c: fc, tau_e, ignore: [NONE; 2], lights_only: false, reach: [DVec4::ZERO; 2] };
        let mut weights = Vec::new();
        let mut picks = Vec::new();
        for k in 0..keys {
            let key = [k, s as u32, 0x5eed];
            let r = reached(view, &query, settings, allowance, key);
            total_iterations += r.iterations as u64;
            rest_used += (r.iterations > allowance) as u32;
            let mut w = vec![0.0; GROUPS];
            for &(t, weight) in &r.triangles {
                w[group_of(t, scene.triangles.len())] += weight;
            }
            let mut p = vec![0.0; GROUPS];
            if let Some(t) = pick(&r, key, 0) {
                p[group_of(t, scene.triangles.len())] = r.total();
            }
            weights.push(w);
            picks.push(p);
        }
        // E[(W [pick in g])^2] = E[W^2 P(pick in g)] = E[W w_g], w_g the group's weight in the
        // key's traversal: estimated from every key, not only those whose pick fell in g.
        let pick_moments: Vec<f64> = (0..GROUPS)
            .map(|g| weights.iter().map(|w| w.iter().sum::<f64>() * w[g]).sum::<f64>() / keys as f64)
            .collect();
        for (what, samples, moments) in [("weights", &weights, None), ("W x pick", &picks, Some(&pick_moments[..]))] {
            // The twin's arcs equal the oracle's to 1e-9 rad (the test above).
            let z = group_z(samples, &exact, 1e-9, moments);
            let worst = z.iter().fold(0.0f64, |a, b| a.max(b.abs()));
            println!("spheroid {s} {what}: worst group z {worst:.2} (limit {limit:.2})");
            let means: Vec<f64> =
                (0..GROUPS).map(|g| samples.iter().map(|x| x[g]).sum::<f64>() / samples.len() as f64).collect();
            let hits: Vec<usize> = (0..GROUPS).map(|g| samples.iter().filter(|x| x[g] != 0.0).count()).collect();
            assert!(
                worst < limit,
                "spheroid {s} {what}: group z-scores {z:.2?} against the arcs {exact:?} means {means:?} hits {hits:?}"
            );
        }
    }
    println!(
        "{:.1} iterations per query; {rest_used} queries went past the allowance",
        total_iterations as f64 / (keys as f64 * spheroids.len() as f64)
    );
    if allowance < 100 {
        assert!(rest_used > keys, "the allowance of {allowance} was hardly ever reached ({rest_used} queries)");
    }
}

#[test]
fn the_descent_twin_is_unbiased() {
    check_twin(&REFLECTION, QuerySettings::default().allowance, 3000);
}

#[test]
fn the_descent_twin_is_unbiased_past_the_allowance() {
    let settings = QuerySettings { split: 0.2, ..REFLECTION };
    check_twin(&settings, 40, 3000);
}

#[test]
fn the_wide_descent_twin_is_unbiased() {
    check_twin(&QuerySettings { wide: true, ..REFLECTION }, QuerySettings::default().allowance, 3000);
    // Bottom subtrees of one wide node and of the most the stack allows.
    check_twin(&QuerySettings { wide: true, bottom_nodes: 1, ..REFLECTION }, 4096, 1000);
    check_twin(&QuerySettings { wide: true, bottom_nodes: 1000, ..REFLECTION }, 4096, 1000);
}

#[test]
fn the_wide_descent_twin_is_unbiased_past_the_allowance() {
    check_twin(&QuerySettings { split: 0.2, wide: true, ..REFLECTION }, 40, 3000);
}

/// Runs the device's query `keys` times on each spheroid of a 20,480-triangle sphere scene
/// (probe_ellipsoid_query with `constants`) and checks E[weight x (pick in group)] against the
/// oracle's arcs per group; returns the mean loop iterations per query.
fn check_device(constants: &[(&'static str, f64)], keys: u32) -> f64 {
    use gatetrace::integrator::{PathTracer, RenderSettings};
    let ctx = common::gpu();
    let scene = common::sphere_scene(32);
    // Queries over the wide BVH read the wide children's surfaces, which the tracer uploads
    // for settings that ask for them.
    let wide = constants.contains(&("QUERY_WIDE", 1.0));
    let query = QuerySettings { wide, ..Default::default() };
    let settings = RenderSettings { width: 4, height: 4, query, ..Default::default() };
    let tracer = PathTracer::new(ctx, &scene, &settings).unwrap();
    let spheroids = spheroids(&scene);
    let limit =
        common::stats::t_critical(common::stats::sidak(ALPHA, spheroids.len() * (GROUPS + 1)), keys as f64 - 1.0);
    let mut iterations = 0u64;
    for (s, &(fs, fc, tau_e)) in spheroids.iter().enumerate() {
        let arcs = exact_sampled_arcs(&scene, fs, fc, tau_e);
        let mut exact = grouped(&arcs);
        exact.push(arcs.iter().sum());
        // A pick's weight is W Theta_i / q_i with probability q_i / W (W its traversal's sum of
        // q / P, whose mean is sum q): E[weight^2; i] = E[W] Theta_i^2 / q_i where W varies
        // little (the exhaustive query: exactly).
        let weights = exact_weights(&scene, fs, fc, tau_e);
        let total_q: f64 = weights.iter().sum();
        let per_triangle: Vec<f64> =
            arcs.iter().zip(&weights).map(|(a, q)| if *q > 0.0 { total_q * a * a / q } else { 0.0 }).collect();
        let mut moments = grouped(&per_triangle);
        moments.push(per_triangle.iter().sum());
        let mut input = Vec::new();
        for k in 0..keys {
            let (fs, fc) = (fs.as_vec3(), fc.as_vec3());
            input.push([fs.x, fs.y, fs.z, tau_e as f32]);
            input.push([fc.x, fc.y, fc.z, 0.5]);
            input.push([f32::from_bits(k), f32::from_bits(s as u32), f32::from_bits(0x5eed), 0.0]);
        }
        let out = common::run_probe(ctx, &tracer, "probe_ellipsoid_query", constants, &input, 2 * keys as usize);
        let samples: Vec<Vec<f64>> = out
            .chunks(2)
            .map(|o| {
                let (tri, weight) = (o[0][0].to_bits(), o[0][1] as f64);
                iterations += o[1][3].to_bits() as u64;
                let mut v = vec![0.0; GROUPS + 1];
                if tri != NONE {
                    v[group_of(tri, scene.triangles.len())] = weight;
                    v[GROUPS] = weight;
                }
                v
            })
            .collect();
        // f32 arcs: relative error below 1e-4 (tests/ellipsoid.rs, stress-ellipsoid).
        let z = group_z(&samples, &exact, 1e-4, Some(&moments));
        let worst = z.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        println!("spheroid {s}: sum of arcs {:.4}, worst group z {worst:.2} (limit {limit:.2})", exact[GROUPS]);
        assert!(worst < limit, "spheroid {s}: z-scores {z:.2?} (groups, then the total) against {exact:.3?}");
    }
    use gatetrace::integrator::Integrator;
    assert_eq!(tracer.truncated_traversals().unwrap(), 0, "queries ran out of the device's loop budget");
    iterations as f64 / (keys as f64 * spheroids.len() as f64)
}

#[test]
fn device_queries_are_unbiased() {
    let descent = check_device(&[("QUERY_REFLECTION_WEIGHTS", 1.0)], 20_000);
    let exhaustive = check_device(
        &[("QUERY_SPLIT", 0.0), ("QUERY_ALLOWANCE", u32::MAX as f64), ("QUERY_REFLECTION_WEIGHTS", 1.0)],
        2_000,
    );
    println!("loop iterations per query: {descent:.1} with the descent, {exhaustive:.1} exhaustive");
    assert!(
        descent < 0.5 * exhaustive,
        "the descent ({descent:.1}) should cost far less than the exhaustive query ({exhaustive:.1})"
    );
}

#[test]
fn wide_device_queries_are_unbiased() {
    let wide = QuerySettings { wide: true, ..Default::default() };
    let bottom = ("QUERY_BOTTOM_NODES", wide.device_bottom_nodes() as f64);
    let descent = check_device(&[("QUERY_WIDE", 1.0), bottom, ("QUERY_REFLECTION_WEIGHTS", 1.0)], 20_000);
    let past_allowance = check_device(
        &[
            ("QUERY_WIDE", 1.0),
            bottom,
            ("QUERY_SPLIT", 0.2),
            ("QUERY_ALLOWANCE", 20.0),
            ("QUERY_REFLECTION_WEIGHTS", 1.0),
        ],
        20_000,
    );
    println!("loop iterations per query: {descent:.1}; {past_allowance:.1} with an allowance of 20");
    assert!(
        past_allowance > 20.0,
        "the allowance of 20 was hardly ever reached ({past_allowance:.1} iterations per query)"
    );
}

#[test]
fn device_queries_are_unbiased_past_the_allowance() {
    let iterations =
        check_device(&[("QUERY_SPLIT", 0.2), ("QUERY_ALLOWANCE", 40.0), ("QUERY_REFLECTION_WEIGHTS", 1.0)], 20_000);
    println!("{iterations:.1} loop iterations per query");
    // Only queries that went past the allowance take more than 40 iterations.
    assert!(iterations > 40.0, "the allowance of 40 was hardly ever reached ({iterations:.1} iterations per query)");
}

/// Runs the device's and the twin's queries with `settings` on the same keys and checks that they
/// pick the same triangles.
fn check_twin_against_device(settings: QuerySettings) {
    // Same keys, same decisions (up to f32 near-ties): the twin follows the device.
    use gatetrace::integrator::{PathTracer, RenderSettings};
    let ctx = common::gpu();
    let scene = common::sphere_scene(32);
    let render = RenderSettings { width: 4, height: 4, query: settings, ..Default::default() };
    let tracer = PathTracer::new(ctx, &scene, &render).unwrap();
    let constants = [
        ("QUERY_WIDE", settings.wide as u32 as f64),
        ("QUERY_BOTTOM_NODES", settings.device_bottom_nodes() as f64),
        ("QUERY_REFLECTION_WEIGHTS", settings.reflection_weights as u32 as f64),
    ];
    let (fs, fc, tau_e) = spheroids(&scene)[2];
    let keys = 2000u32;
    let mut input = Vec::new();
    for k in 0..keys {
        let (a, b): (Vec3, Vec3) = (fs.as_vec3(), fc.as_vec3());
        input.push([a.x, a.y, a.z, tau_e as f32]);
        input.push([b.x, b.y, b.z, 0.5]);
        input.push([f32::from_bits(k), f32::from_bits(7), f32::from_bits(9), 0.0]);
    }
    let out = common::run_probe(ctx, &tracer, "probe_ellipsoid_query", &constants, &input, 2 * keys as usize);
    let query = Query {
        focus_s: fs.as_vec3().as_dvec3(),
        focus_c: fc.as_vec3().as_dvec3(),
        tau_e: tau_e as f32 as f64,
        ignore: [NONE; 2],
        lights_only: false,
        reach: [DVec4::ZERO; 2],
    };
    let same = (0..keys)
        .filter(|&k| {
            let r = reached(QueryScene::of(&scene), &query, &settings, settings.allowance, [k, 7, 9]);
            pick(&r, [k, 7, 9], 0).unwrap_or(NONE) == out[2 * k as usize][0].to_bits()
        })
        .count();
    println!("{same} of {keys} picks agree");
    // f32 and f64 may decide differently only at near-ties of the descent's estimates.
    assert!(same as f64 > 0.99 * keys as f64, "the twin and the device agree on only {same} of {keys} picks");
}

#[test]
fn the_twin_and_the_device_pick_alike() {
    check_twin_against_device(QuerySettings::default());
}

#[test]
fn the_wide_twin_and_the_device_pick_alike() {
    check_twin_against_device(QuerySettings { wide: true, ..Default::default() });
}

/// Points at the centroids of a triangle's 4^levels congruent sub-triangles (each standing for
/// an equal share of its area): a quadrature independent of the closed forms under test.
fn subdivided_centroids(v: [DVec3; 3], levels: u32, out: &mut Vec<DVec3>) {
    if levels == 0 {
        out.push((v[0] + v[1] + v[2]) / 3.0);
        return;
    }
    let (ab, bc, ca) = (0.5 * (v[0] + v[1]), 0.5 * (v[1] + v[2]), 0.5 * (v[2] + v[0]));
    for sub in [[v[0], ab, ca], [ab, v[1], bc], [ca, bc, v[2]], [ab, bc, ca]] {
        subdivided_centroids(sub, levels - 1, out);
    }
}

/// The descent's node estimate rests on each node's stored surface moments
/// (`Bvh::node_surfaces`: area, centroid, covariance as f16 over the box's squared diagonal)
/// and on `path_length_moments`, which predicts the mean and spread of the path length over a
/// node from them. Both are checked against a quadrature over the node's triangles (centroids
/// of 1024 sub-triangles each, weighted by area, the covariance extrapolated from 256): the
/// moments to f32 and f16 rounding, the
/// predicted mean to a hundredth and the spread to a tenth of the true one for nodes small
/// against their distance to the foci (the prediction is exact to second order in that ratio).
#[test]
fn node_surfaces_and_their_path_length_moments_match_a_quadrature() {
    use gatetrace::ellipsoid::query::path_length_moments;
    use gatetrace::scene::materials::unpack2x16float;
    let scene = common::sphere_scene(16);
    let nodes = &scene.bvh.nodes;
    // Foci outside the Cornell box, on one side of it (no node lies between them).
    let foci = [
        (DVec3::new(0.3, 0.2, 3.0), DVec3::new(-0.4, -0.1, 2.5)),
        (DVec3::new(2.5, 0.1, 0.0), DVec3::new(2.5, 0.1, 0.0)),
    ];
    let mut checked = 0;
    for (i, node) in nodes.iter().enumerate().step_by(37) {
        let end = node.skip as usize;
        // Area-weighted points at 4 and 5 levels of subdivision.
        let quadrature = |levels: u32| {
            let (mut points, mut weights) = (Vec::new(), Vec::new());
            for n in &nodes[i..end] {
                for k in n.leaf_range().into_iter().flatten() {
                    let t = oracle_triangle(&scene.triangles[k as usize]);
                    let before = points.len();
                    subdivided_centroids(t.vertices, levels, &mut points);
                    let [a, b, c] = t.vertices;
                    let share = 0.5 * (b - a).cross(c - a).length() / (points.len() - before) as f64;
                    weights.extend(std::iter::repeat_n(share, points.len() - before));
                }
            }
            (points, weights)
        };
        let (coarse_points, coarse_weights) = quadrature(4);
        let (points, weights) = quadrature(5);
        let area: f64 = weights.iter().sum();
        let surface = scene.node_surfaces[i];
        assert!((surface.area as f64 - area).abs() <= 1e-5 * area, "node {i}: area {} against {area}", surface.area);
        // Sub-triangle centroids average to the centroid exactly.
        let mean = points.iter().zip(&weights).map(|(p, w)| *p * *w).sum::<DVec3>() / area;
        let (lo, hi) = (node.min.as_dvec3(), node.max.as_dvec3());
        let diagonal2 = (hi - lo).length_squared();
        assert!(
            (surface.centroid.as_dvec3() - mean).length() <= 1e-5 * diagonal2.sqrt(),
            "node {i}: centroid {} against {mean}",
            surface.centroid
        );
        // The centroid rule misses each sub-triangle's own spread, 1/4 of it per level: two
        // levels extrapolate to the exact covariance.
        let cov_at = |points: &[DVec3], weights: &[f64], a: usize, b: usize| {
            points.iter().zip(weights).map(|(p, w)| (p[a] - mean[a]) * (p[b] - mean[b]) * w).sum::<f64>() / area
        };
        let cov = |a: usize, b: usize| {
            (4.0 * cov_at(&points, &weights, a, b) - cov_at(&coarse_points, &coarse_weights, a, b)) / 3.0
        };
        let stored = surface.spread.map(|w| unpack2x16float(w).as_dvec2() * diagonal2);
        for (got, (a, b)) in [stored[0].x, stored[0].y, stored[1].x, stored[1].y, stored[2].x, stored[2].y]
            .into_iter()
            .zip([(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)])
        {
            // f16 keeps 11 significant bits (and steps of 6e-8 below 6e-5).
            let want = cov(a, b);
            assert!(
                (got - want).abs() <= 1e-3 * want.abs() + 1e-7 * diagonal2,
                "node {i}: covariance ({a}, {b}) {got} against {want}"
            );
        }
        for &(fs, fc) in &foci {
            let lengths: Vec<f64> = points.iter().map(|p| p.distance(fs) + p.distance(fc)).collect();
            let true_mean = lengths.iter().zip(&weights).map(|(l, w)| l * w).sum::<f64>() / area;
            let true_sd =
                (lengths.iter().zip(&weights).map(|(l, w)| (l - true_mean).powi(2) * w).sum::<f64>() / area).sqrt();
            let distance = mean.distance(fs).min(mean.distance(fc));
            if diagonal2.sqrt() > 0.1 * distance || true_sd < 1e-3 * diagonal2.sqrt() {
                continue;
            }
            let query = Query {
                focus_s: fs,
                focus_c: fc,
                tau_e: true_mean,
                ignore: [NONE; 2],
                lights_only: false,
                reach: [DVec4::ZERO; 2],
            };
            let (m, sd) = path_length_moments(lo, hi, &surface, &query);
            assert!(
                (m - true_mean).abs() <= 0.01 * true_sd.max(1e-3 * diagonal2.sqrt()),
                "node {i}: mean path length {m} against {true_mean} (sd {true_sd})"
            );
            assert!((sd / true_sd - 1.0).abs() <= 0.1, "node {i}: path length deviation {sd} against {true_sd}");
            checked += 1;
        }
    }
    println!("{checked} node and focus pairs checked");
    assert!(checked >= 50, "only {checked} node and focus pairs were small enough to check");
}

/// Queries over the wide BVH weigh each wide child by the surface of the binary node it was
/// collapsed from: the same area and centroid, and the same covariance once each is scaled
/// back by its own box's squared diagonal (the child's decoded box, the node's exact one), to
/// f16 rounding.
#[test]
fn wide_children_carry_their_binary_nodes_surfaces() {
    use gatetrace::scene::materials::unpack2x16float;
    let scene = common::sphere_scene(16);
    let mut checked = 0;
    for (n, (node, sources)) in scene.wide.nodes.iter().zip(&scene.wide.sources).enumerate() {
        for (slot, &k) in sources.iter().enumerate() {
            let child = scene.child_surfaces[4 * n + slot];
            if k == NONE {
                assert_eq!(child, Default::default(), "node {n} slot {slot}: an empty slot has no surface");
                continue;
            }
            let (k, binary) = (k as usize, scene.node_surfaces[k as usize]);
            assert_eq!(
                (child.area, child.light_area, child.centroid),
                (binary.area, binary.light_area, binary.centroid)
            );
            let (lo, hi) = gatetrace::bvh::wide::child_box(node, slot);
            let child_scale = (hi - lo).as_dvec3().length_squared();
            let binary_scale = (scene.bvh.nodes[k].max - scene.bvh.nodes[k].min).as_dvec3().length_squared();
            assert!(child_scale >= binary_scale, "node {n} slot {slot}: the decoded box holds the node's");
            for (c, b) in child.spread.iter().zip(&binary.spread) {
                let (c, b) =
                    (unpack2x16float(*c).as_dvec2() * child_scale, unpack2x16float(*b).as_dvec2() * binary_scale);
                assert!((c - b).abs().max_element() <= 2e-3 * (c.abs() + b.abs()).max_element() + 1e-7 * child_scale);
            }
            checked += 1;
        }
    }
    assert!(checked > 1000, "only {checked} wide children");
}
