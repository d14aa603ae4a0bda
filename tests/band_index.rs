//! The band index of NLOS captures (src/nlos/band_index.rs): its clusters partition the
//! BVH's triangles, and `ellipsoidal` captures that draw their three-bounce connections from it
//! agree with captures that descend the BVH (both unbiased, independent estimators), bin group
//! by bin group, on a hidden sphere of 5,120 triangles split over many clusters, for confocal and
//! single scans.

mod common;

use glam::Vec3;

use gatetrace::film::{Film, Gate};
use gatetrace::integrator::{BidirectionalTracer, Integrator, Method};
use gatetrace::nlos::LaserAim;
use gatetrace::nlos::band_index::{
    CLUSTER_NODES, SMALL_CLUSTER_NODES, SMALL_CLUSTERS_UP_TO, cluster_nodes, clusters, interpolation_bound,
    strip_point, tent_cdf,
};

#[test]
fn clusters_partition_the_triangles_into_small_subtrees() {
    let scene = common::nlos_sphere_scene(16, false);
    assert_eq!(cluster_nodes(scene.triangles.len()), SMALL_CLUSTER_NODES, "a small scene takes small clusters");
    assert_eq!(cluster_nodes(SMALL_CLUSTERS_UP_TO + 1), CLUSTER_NODES);
    for max_nodes in [SMALL_CLUSTER_NODES, CLUSTER_NODES] {
        clusters_partition(&scene, max_nodes);
    }
}

/// `clusters(.., max_nodes)` of the scene's BVH partition its triangles into subtrees of at most
/// `max_nodes` nodes (or single leaves), in node order.
fn clusters_partition(scene: &gatetrace::scene::PreparedScene, max_nodes: u32) {
    let nodes = &scene.bvh.nodes;
    let clusters = clusters(nodes, max_nodes);
    assert!(clusters.len() > 50, "only {} clusters", clusters.len());
    let mut covered = vec![0u32; scene.triangles.len()];
    let mut next_root = 0;
    for &[root, end, first, last] in &clusters {
        // Between two clusters lie only inner nodes whose subtrees are too large to be one.
        assert!(root >= next_root, "clusters must follow each other in node order");
        for i in next_root..root {
            let n = &nodes[i as usize];
            assert!(n.leaf == 0 && n.skip - i > max_nodes, "node {i} lies in no cluster");
        }
        assert_eq!(end, nodes[root as usize].skip, "a cluster is its root's whole subtree");
        assert!(end - root <= max_nodes || nodes[root as usize].leaf != 0, "cluster at {root} too large");
        // Its leaves address exactly [first, last), with no gap.
        let leaf_triangles: u32 =
            nodes[root as usize..end as usize].iter().filter_map(|n| n.leaf_range()).map(|r| r.len() as u32).sum();
        assert_eq!(leaf_triangles, last - first, "cluster at {root}: its triangles are not contiguous");
        for t in first..last {
            covered[t as usize] += 1;
        }
        next_root = end;
    }
    assert_eq!(next_root as usize, nodes.len());
    assert!(covered.iter().all(|&c| c == 1), "every triangle must lie in exactly one cluster");
}

/// Renders `batches` films of `spp` of an `ellipsoidal` capture of the hidden sphere (with the
/// example's occluder when `occluder`), with the band index (its scene prepared for shells as
/// the command line does: the closed sphere one-sided, large triangles cut) or without; returns
/// them and the index's report.
fn capture(
    aim: LaserAim,
    band_index: bool,
    occluder: bool,
    seed: u32,
    batches: usize,
    spp: u32,
) -> (Vec<Film>, Option<String>) {
    let ctx = common::gpu();
    let gate = Gate::Transient { start: 0.85, width: 0.0024, bins: 300 };
    let mut scene = common::nlos_sphere_scene_unprepared(16, occluder);
    if band_index {
        let origin = glam::Vec3::new(-1.2, 0.0, 0.6);
        gatetrace::nlos::prepare_for_shells(&mut scene, "relay_wall", 0.0024, &[origin], 0).unwrap();
    }
    let scene = gatetrace::scene::PreparedScene::new(scene).unwrap();
    let capture = common::example_capture(4, 4, gate, aim, Method::Ellipsoidal);
    // Without the index: exhaustive queries (the exact arcs at each target length; the
    // stochastic descent reaches some slivers of the sphere's limb too rarely for a few thousand
    // samples to estimate its error there), each bin visited equally (no pilot).
    let query = gatetrace::integrator::QuerySettings {
        reflection_weights: true,
        ..gatetrace::integrator::QuerySettings::EXHAUSTIVE
    };
    let settings = gatetrace::integrator::RenderSettings {
        seed,
        band_index,
        query: if band_index { capture.query } else { query },
        target_pilot_spp: if band_index { capture.target_pilot_spp } else { 0 },
        ..capture
    };
    let mut tracer = BidirectionalTracer::new(ctx, &scene, &settings).unwrap();
    let films = common::films_of(&mut tracer, batches, spp);
    assert_eq!(tracer.truncated_traversals().unwrap(), 0);
    (films, tracer.band_index_report())
}

fn band_index_agrees_with_exhaustive_queries(scan: &str, aim: LaserAim, occluder: bool) {
    const BATCHES: usize = 16;
    // The queries: more samples than bins (300), each bin visited equally (no allocation). The
    // index: a whole cycle of visits per batch (a base visit and 15 extra ones per bin, which
    // its masses share out), so that every bin has a visit in every batch. A batch that ends
    // within its cycle may leave bins of little mass unvisited (at 320 samples, 20 base visits
    // a batch), and which bins it visits then decides its group sums: a t test over 16 batches
    // cannot model that lottery (with visits following the masses alone, a group no batch
    // visited failed at |z| = 25).
    const GROUP: usize = 10;
    const QUERY_SPP: u32 = 320;
    const INDEX_SPP: u32 = 16 * 300;
    let (indexed, report) = capture(aim, true, occluder, 71, BATCHES, INDEX_SPP);
    let (queried, none) = capture(aim, false, occluder, 72, BATCHES, QUERY_SPP);
    let report = report.expect("the capture asked for a band index");
    println!("{scan}: band index {report}");
    assert!(!report.starts_with("off"), "{scan}: the band index was not built: {report}");
    assert!(none.is_none());
    // Groups of GROUP bins per pixel and channel.
    let bins = indexed[0].bins as usize;
    let groups = indexed[0].data.len() / GROUP;
    let group = |i: usize| {
        let (c, bin, pixel) = (i % 3, (i / 3) % bins, i / (3 * bins));
        Some((pixel * (bins / GROUP) + bin / GROUP) * 3 + c)
    };
    let result = common::compare_films(&indexed, &queried, groups, group);
    // Where a pixel's light starts or ends within a bin, it fills a sliver of the bin's target
    // lengths, which the queries' 16 x 320 targets may all miss, and their variance estimate of
    // zero then says nothing of their error: groups they never reached are left out of the test,
    // and the index may put only a ten-thousandth of the capture's energy there.
    let (reached, unreached): (Vec<&(f64, f64, f64)>, Vec<_>) = result.iter().partition(|r| r.1 != 0.0);
    let total: f64 = result.iter().map(|r| r.0).sum();
    let stray: f64 = unreached.iter().map(|r| r.0).sum();
    println!(
        "{scan}: {} of {} groups the queries never reached, with {:.2e} of the index's energy",
        unreached.len(),
        result.len(),
        stray / total
    );
    assert!(stray <= 1e-4 * total, "{scan}: {:.2e} of the energy where the queries found none", stray / total);
    let reached: Vec<(f64, f64, f64)> = reached.into_iter().copied().collect();
    common::assert_groups_agree(
        &format!("{scan}, band index vs exhaustive queries"),
        "group",
        &reached,
        (BATCHES - 1) as f64,
        0.01,
    );
    // Whole-capture energy.
    let energy = common::compare_films(&indexed, &queried, 1, |_| Some(0))[0];
    println!("{scan}: energy {:.6e} vs {:.6e} (z {:+.2})", energy.0, energy.1, energy.2);
    assert!(energy.2.abs() < 4.0, "{scan}: energies differ (z = {:.2})", energy.2);
    assert!(energy.0 > 0.0);
    // What the index is for, printed (its gain depends on the mesh and the samples per bin, and
    // is measured by tools/peer/nlos_equal_time.py): the batch variance per sample.
    let variance = |films: &[Film], spp: u32| -> f64 {
        let totals: Vec<f64> = films.iter().map(|f| f.data.iter().map(|&v| v as f64).sum()).collect();
        let mean = totals.iter().sum::<f64>() / totals.len() as f64;
        totals.iter().map(|t| (t - mean).powi(2)).sum::<f64>() / (totals.len() - 1) as f64 * spp as f64
    };
    println!(
        "{scan}: variance of a batch's total x spp: band index {:.3e}, exhaustive queries {:.3e}",
        variance(&indexed, INDEX_SPP),
        variance(&queried, QUERY_SPP)
    );
}

#[test]
fn confocal_band_index_agrees_with_exhaustive_queries_on_a_hidden_sphere() {
    band_index_agrees_with_exhaustive_queries("confocal", LaserAim::Confocal, false);
}

/// With the example's occluder, whose two large panels the capture cuts into pieces.
#[test]
fn confocal_band_index_agrees_with_exhaustive_queries_behind_the_occluder() {
    band_index_agrees_with_exhaustive_queries("confocal, occluder", LaserAim::Confocal, true);
}

#[test]
fn single_scan_band_index_agrees_with_exhaustive_queries_on_a_hidden_sphere() {
    band_index_agrees_with_exhaustive_queries("single", LaserAim::Spot(glam::Vec2::new(0.3, 0.6)), false);
}

/// The occluder's two large triangles over 4000 bins of 0.3 mm (1 ps): indexing their cluster
/// whole would take one invocation past lavapipe's loop limit, so the build fills it over
/// ranges of strata in several dispatches (and checks that every entry was written). The
/// capture must agree with the descent pixel by pixel (totals over all bins).
#[test]
fn a_cluster_of_large_triangles_over_fine_bins_is_filled_in_ranges_of_strata() {
    const BATCHES: usize = 12;
    let ctx = common::gpu();
    let scene = common::nlos_sphere_scene(8, true);
    let gate = Gate::Transient { start: 0.85, width: 0.0003, bins: 4000 };
    let capture = |band_index: bool, seed: u32, spp: u32| {
        let settings = gatetrace::integrator::RenderSettings {
            seed,
            band_index,
            ..common::example_capture(4, 4, gate.clone(), LaserAim::Confocal, Method::Ellipsoidal)
        };
        let mut tracer = BidirectionalTracer::new(ctx, &scene, &settings).unwrap();
        let films = common::films_of(&mut tracer, BATCHES, spp);
        (films, tracer.band_index_report())
    };
    let (indexed, report) = capture(true, 81, 512);
    let (descended, _) = capture(false, 82, 2048);
    let report = report.unwrap();
    println!("band index: {report}");
    assert!(!report.starts_with("off"), "the band index was not built: {report}");
    let per_pixel = indexed[0].data.len() / 16;
    let result = common::compare_films(&indexed, &descended, 16, |i| Some(i / per_pixel));
    let limit = common::stats::t_critical(common::stats::sidak(0.01, 16), (BATCHES - 1) as f64);
    for (p, (a, b, z)) in result.iter().enumerate() {
        println!("pixel {p}: band index {a:.6e}, descent {b:.6e}, z {z:+.2}");
        assert!(z.abs() < limit, "pixel {p}: band index {a} vs descent {b} (|z| {:.2} >= {limit:.2})", z.abs());
    }
}

/// A build whose count pass predicts it past the render's time budget stops there (from its
/// first dispatch where that predicts three times the budget; from its measured rate past the
/// first dispatch otherwise; after a single dispatch, at twice its time), and not before.
#[test]
fn the_build_clock_stops_a_build_that_would_outlast_its_budget() {
    use gatetrace::nlos::band_index::BuildClock;
    use std::time::{Duration, Instant};
    let second_ago = Instant::now() - Duration::from_secs(1);
    // One dispatch of ten took a second: 20 s predicted, past three times 0.5 s.
    let why = BuildClock::new(second_ago, 0.5, 100).count_done(10).expect("a build of 20 s within 0.5 s");
    assert!(why.contains("0.5 s budget"), "{why}");
    // ... but within three times 10 s: the build goes on, and the next dispatch, done at once,
    // measures a rate that ends it within the budget.
    let mut clock = BuildClock::new(second_ago, 10.0, 100);
    assert_eq!(clock.count_done(10), None);
    assert_eq!(clock.count_done(10), None);
    // A count pass of a single dispatch that took a second: a build of 2 s.
    assert!(BuildClock::new(second_ago, 1.5, 10).count_done(10).is_some());
    assert_eq!(BuildClock::new(second_ago, 2.5, 10).count_done(10), None);
}

/// A render whose time budget the band index's build would outlast goes without the index (its
/// captures are unbiased either way: the tests above), says why, and leaves the build to the
/// next render, which here renders by samples and builds it.
#[test]
fn a_build_past_the_time_budget_waits_for_the_next_render() {
    let ctx = common::gpu();
    let scene = common::nlos_sphere_scene(8, false);
    let gate = Gate::Transient { start: 0.85, width: 0.0024, bins: 300 };
    let settings = gatetrace::integrator::RenderSettings {
        seed: 5,
        band_index: true,
        ..common::example_capture(4, 4, gate, LaserAim::Confocal, Method::Ellipsoidal)
    };
    let mut tracer = BidirectionalTracer::new(ctx, &scene, &settings).unwrap();
    tracer.set_time_budget(Some(1e-6));
    tracer.render_samples(1).unwrap();
    let why = tracer.band_index_off().expect("a build within a microsecond");
    assert!(why.contains("budget"), "{why}");
    assert_eq!(tracer.band_index_report(), Some(format!("off: {why}")));
    tracer.set_time_budget(None);
    tracer.render_samples(1).unwrap();
    assert_eq!(tracer.band_index_off(), None);
    let report = tracer.band_index_report().unwrap();
    assert!(report.contains("entries"), "the band index was not built: {report}");
}

/// A random triangle and two foci in metres: edges from 0.1 mm to 40 cm, foci 0.2 to 2 m away
/// (some pairs coincide, as a confocal scan's), so that the bound eps spans its range.
fn random_piece(rng: &mut gatetrace::rng::Rng) -> ([Vec3; 3], Vec3, Vec3) {
    let mut unit = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - Vec3::ONE;
    let size = 1e-4 * 4000f32.powf(unit().x * 0.5 + 0.5);
    let centre = unit() * 0.3;
    let v = [centre + unit() * size, centre + unit() * size, centre + unit() * size];
    let far = |d: Vec3, r: f32| centre + d.normalize_or(Vec3::Z) * (0.2 + 1.8 * r);
    let (d, r) = (unit(), unit().x * 0.5 + 0.5);
    let spot = far(d, r);
    let sensed = if unit().x < -0.5 { spot } else { far(unit(), unit().y * 0.5 + 0.5) };
    (v, spot, sensed)
}

fn path_length(x: glam::DVec3, spot: Vec3, sensed: Vec3) -> f64 {
    x.distance(spot.as_dvec3()) + x.distance(sensed.as_dvec3())
}

/// The strips of the shell connection rest on L <= L_int <= L + eps over a piece: L (the sum of
/// the distances to the two foci) is convex, and eps bounds its interpolation error. Checked in
/// f64 on 2,000 random pieces at 200 points each, and eps is no looser than needed by more than
/// the factor its derivation allows on small pieces.
#[test]
fn the_linear_interpolant_of_the_path_length_bounds_it_within_eps() {
    let mut rng = gatetrace::rng::Rng::new(5, 0, 0);
    let mut tightest = f64::INFINITY;
    for _ in 0..2000 {
        let (v, spot, sensed) = random_piece(&mut rng);
        let eps = interpolation_bound(v, spot, sensed) as f64;
        let l: Vec<f64> = v.iter().map(|p| path_length(p.as_dvec3(), spot, sensed)).collect();
        let mut worst = 0.0f64;
        for _ in 0..200 {
            let (r1, r2) = (rng.next_f32().sqrt() as f64, rng.next_f32() as f64);
            let w = [1.0 - r1, r1 * (1.0 - r2), r1 * r2];
            let x = v[0].as_dvec3() * w[0] + v[1].as_dvec3() * w[1] + v[2].as_dvec3() * w[2];
            let gap = w[0] * l[0] + w[1] * l[1] + w[2] * l[2] - path_length(x, spot, sensed);
            assert!(gap >= -1e-12, "L_int below L by {gap:e} m");
            assert!(gap <= eps, "L_int - L = {gap:e} m beyond eps = {eps:e} m (triangle {v:?}, foci {spot} {sensed})");
            worst = worst.max(gap);
        }
        if eps > 1e-9 {
            tightest = tightest.min(eps / worst.max(1e-300));
        }
    }
    // The bound is sharp within a small factor on some pieces (it is not a loose constant).
    assert!(tightest < 20.0, "eps is at least {tightest:.1}x the largest gap found on every piece");
}

/// strip_point draws points uniformly on the strip lo <= L_int < hi of a triangle: its points
/// lie in the triangle with L_int in [lo, hi], and their counts over a grid of barycentric cells
/// match those of uniform points kept when they fall in the strip (two-sample chi-square,
/// Sidak-corrected alpha = 0.01 over the cases), for strips inside, at either end of and across
/// the whole range of L_int, and a triangle of constant L_int.
#[test]
fn strip_points_are_uniform_on_their_strip() {
    let v = [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.2, 0.0), Vec3::new(0.3, 0.9, 0.1)];
    let cases: [([f32; 3], f32, f32); 6] = [
        ([1.0, 1.3, 1.9], 1.2, 1.5),
        ([1.0, 1.3, 1.9], 1.0, 1.1),
        ([1.0, 1.3, 1.9], 1.7, 1.9),
        ([2.0, 1.0, 1.5], 1.0, 2.0),
        ([1.0, 1.0, 1.6], 1.1, 1.4),
        ([1.2, 1.2, 1.2], 1.2, 1.2),
    ];
    const N: usize = 200_000;
    const CELLS: usize = 8;
    let bary = |p: Vec3| {
        let (e1, e2, q) = (v[1] - v[0], v[2] - v[0], p - v[0]);
        let (d00, d01, d11, d20, d21) = (e1.dot(e1), e1.dot(e2), e2.dot(e2), q.dot(e1), q.dot(e2));
        let den = d00 * d11 - d01 * d01;
        ((d11 * d20 - d01 * d21) / den, (d00 * d21 - d01 * d20) / den)
    };
    let cell = |p: Vec3| {
        let (b1, b2) = bary(p);
        let (i, j) = (((b1 * CELLS as f32) as usize).min(CELLS - 1), ((b2 * CELLS as f32) as usize).min(CELLS - 1));
        i * CELLS + j
    };
    let alpha = common::stats::sidak(0.01, cases.len());
    let mut rng = gatetrace::rng::Rng::new(9, 0, 0);
    for (case, &(l, lo, hi)) in cases.iter().enumerate() {
        let linear = |p: Vec3| {
            let (b1, b2) = bary(p);
            (1.0 - b1 - b2) * l[0] + b1 * l[1] + b2 * l[2]
        };
        let (mut drawn, mut kept) = (vec![0.0f64; CELLS * CELLS], vec![0.0f64; CELLS * CELLS]);
        let mut n_kept = 0usize;
        for _ in 0..N {
            let p = strip_point(v, l, lo, hi, rng.next_f32(), rng.next_f32());
            let (b1, b2) = bary(p);
            assert!(b1 >= -1e-5 && b2 >= -1e-5 && b1 + b2 <= 1.0 + 1e-5, "case {case}: {p} lies off the triangle");
            let x = linear(p);
            assert!(x >= lo - 1e-5 && x <= hi + 1e-5, "case {case}: L_int = {x} outside [{lo}, {hi}]");
            drawn[cell(p)] += 1.0;
        }
        while n_kept < N {
            let (r1, r2) = (rng.next_f32().sqrt(), rng.next_f32());
            let p = v[0] + r1 * (1.0 - r2) * (v[1] - v[0]) + r1 * r2 * (v[2] - v[0]);
            let x = linear(p);
            if (x >= lo && x < hi) || lo == hi {
                kept[cell(p)] += 1.0;
                n_kept += 1;
            }
        }
        // Two equal-size samples: sum (a - b)^2 / (a + b) is chi-square with (cells used - 1) dof.
        let (mut chi2, mut used) = (0.0, 0usize);
        for (a, b) in drawn.iter().zip(&kept) {
            if a + b > 0.0 {
                chi2 += (a - b) * (a - b) / (a + b);
                used += 1;
            }
        }
        let p = common::stats::chi2_sf(chi2, (used - 1) as f64);
        println!("case {case}: chi2 {chi2:.1} over {used} cells, p = {p:.3}");
        assert!(p > alpha, "case {case}: strip points are not uniform (chi2 {chi2:.1}, {used} cells, p = {p:.2e})");
    }
    // The strip's share of the area is the tent's mass between lo and hi.
    assert!((tent_cdf(1.0, 1.3, 1.9, 1.3) - 0.3 / 0.9).abs() < 1e-6);
}

/// The WGSL strip_point and tent_cdf (band_index.wesl) equal their CPU twins on random
/// triangles, values and strips (points within 1e-5 of the triangle's size).
#[test]
fn wgsl_strip_point_matches_its_twin() {
    let ctx = common::gpu();
    let scene = common::nlos_sphere_scene(2, false);
    let settings = gatetrace::integrator::RenderSettings { width: 4, height: 4, ..Default::default() };
    let tracer = gatetrace::integrator::PathTracer::new(ctx, &scene, &settings).unwrap();
    let mut rng = gatetrace::rng::Rng::new(13, 0, 0);
    let mut input = Vec::new();
    let mut expected = Vec::new();
    for _ in 0..4096 {
        let (v, spot, sensed) = random_piece(&mut rng);
        let l: [f32; 3] = v.map(|p| p.distance(spot) + p.distance(sensed));
        let (a, c) = (l[0].min(l[1]).min(l[2]), l[0].max(l[1]).max(l[2]));
        let (x, y) = (a + (c - a) * rng.next_f32(), a + (c - a) * rng.next_f32());
        let (lo, hi) = (x.min(y), x.max(y));
        let (u1, u2) = (rng.next_f32(), rng.next_f32());
        input.extend([
            [v[0].x, v[0].y, v[0].z, lo],
            [v[1].x, v[1].y, v[1].z, hi],
            [v[2].x, v[2].y, v[2].z, u1],
            [l[0], l[1], l[2], u2],
        ]);
        let b = l[0].min(l[1]).max(l[0].max(l[1]).min(l[2]));
        expected.push((strip_point(v, l, lo, hi, u1, u2), tent_cdf(a, b, c, hi) - tent_cdf(a, b, c, lo), v));
    }
    let out = common::run_probe(ctx, &tracer, "probe_strip", &[], &input, expected.len());
    for (i, (o, (p, share, v))) in out.iter().zip(&expected).enumerate() {
        let size = v[0].distance(v[1]).max(v[0].distance(v[2])).max(v[1].distance(v[2]));
        let got = Vec3::new(o[0], o[1], o[2]);
        assert!(got.distance(*p) <= 1e-5 * size + 1e-7, "configuration {i}: device {got}, twin {p}");
        assert!((o[3] - share).abs() <= 1e-5, "configuration {i}: device share {}, twin {share}", o[3]);
    }
}

/// refine_for_shells cuts the hidden scene's large triangles into congruent pieces and keeps
/// the surface: every node keeps its triangles contiguous, the relay wall is untouched, the
/// area per material and node is the same, pieces face as their triangle did, and the wall's
/// texture coordinates still find the same points.
#[test]
fn refining_for_shells_keeps_the_surface() {
    let scene = common::nlos_sphere_scene_unprepared(4, true);
    let mut refined = scene.clone();
    let summary = gatetrace::nlos::refine_for_shells(&mut refined, "relay_wall", 0.0012, 0).unwrap();
    println!("{summary:?}, {} triangles before", scene.triangles.len());
    assert!(summary.refined >= 2, "the occluder's two panels must be cut");
    assert_eq!(summary.triangles, refined.triangles.len());
    assert_eq!(scene.nodes.len(), refined.nodes.len());
    for (a, b) in scene.nodes.iter().zip(&refined.nodes) {
        let area = |s: &gatetrace::scene::Scene, r: &std::ops::Range<usize>| -> f64 {
            s.triangles[r.clone()].iter().map(|t| t.area() as f64).sum()
        };
        let (before, after) = (area(&scene, &a.triangles), area(&refined, &b.triangles));
        assert!((after - before).abs() <= 1e-5 * before.max(1e-9), "node {}: area {before} became {after}", a.name);
        if a.name == "relay_wall" {
            assert_eq!(a.triangles.len(), b.triangles.len(), "the relay wall must be kept whole");
        }
        assert_eq!(a.texcoords.is_some(), b.texcoords.is_some());
        if let Some(uv) = &b.texcoords {
            assert_eq!(uv.len(), b.triangles.len());
        }
    }
    let normal = |t: &gatetrace::scene::SceneTriangle| {
        (t.positions[1] - t.positions[0]).cross(t.positions[2] - t.positions[0]).normalize()
    };
    let occluder =
        (scene.node("occluder").unwrap().triangles.clone(), refined.node("occluder").unwrap().triangles.clone());
    assert!(occluder.1.len() > 100 * occluder.0.len(), "the occluder was cut into {} pieces", occluder.1.len());
    for t in &refined.triangles[occluder.1.clone()] {
        let longest = (0..3).map(|i| t.positions[i].distance(t.positions[(i + 1) % 3])).fold(0.0f32, f32::max);
        assert!(longest < 0.03, "an occluder piece of {longest} m");
        assert!(normal(t).dot(normal(&scene.triangles[occluder.0.start])) > 0.999, "a piece turned over");
    }
    for uv in [glam::Vec2::new(0.3, 0.6), glam::Vec2::new(0.9, 0.1)] {
        let before = gatetrace::nlos::wall_point_at(&scene, "relay_wall", uv).unwrap();
        let after = gatetrace::nlos::wall_point_at(&refined, "relay_wall", uv).unwrap();
        assert!(before.distance(after) < 1e-6, "wall point at {uv} moved from {before} to {after}");
    }
}

/// With a budget of pieces (`finer_pieces`), refine_for_shells cuts the edges by the finest of
/// FINER_CUTS whose pieces fit it, never coarser than its edge rule, and the budget a capture
/// gets grows with its seconds over its pixels (or with its samples).
#[test]
fn finer_cuts_take_the_finest_that_fits_the_budget() {
    use gatetrace::capture::finer_pieces;
    use gatetrace::integrator::Budget;
    use gatetrace::nlos::{FINER_CUTS, refine_for_shells};
    let scene = common::nlos_sphere_scene_unprepared(4, true);
    let cut = |budget: u64| {
        let mut refined = scene.clone();
        let summary = refine_for_shells(&mut refined, "relay_wall", 0.0012, budget).unwrap();
        let occluder = refined.node("occluder").unwrap().triangles.clone();
        let longest = refined.triangles[occluder]
            .iter()
            .map(|t| (0..3).map(|i| t.positions[i].distance(t.positions[(i + 1) % 3])).fold(0.0f32, f32::max))
            .fold(0.0f32, f32::max);
        (summary.triangles as u64, longest, summary.finer_cut)
    };
    let (rule, rule_edge, rule_cut) = cut(0);
    let (finest, finest_edge, _) = cut(u64::MAX);
    assert_eq!(rule_cut, 1);
    println!("edge rule: {rule} triangles, longest occluder piece {rule_edge} m; finest: {finest}, {finest_edge} m");
    // The occluder's panels reach MAX_REFINE_PIECES per edge before the finest cut's 1/8.
    assert!(finest_edge < 0.3 * rule_edge, "the finest cut's edges: {finest_edge} m");
    // Each budget takes the finest cut that fits it: just below a cut's count, the next coarser.
    let (mut counts, mut cuts) = (Vec::new(), Vec::new());
    let mut budget = finest;
    loop {
        let (n, _, finer_cut) = cut(budget);
        assert!(n <= budget, "{n} triangles over a budget of {budget}");
        assert!(counts.last().is_none_or(|&finer| n < finer), "cuts must get coarser as the budget falls");
        if n == rule {
            break;
        }
        counts.push(n);
        cuts.push(finer_cut);
        budget = n - 1;
    }
    assert_eq!(counts.len(), FINER_CUTS.len(), "every finer cut is taken by some budget: {counts:?}");
    assert_eq!(counts[0], finest);
    let expected: Vec<u32> = FINER_CUTS.iter().rev().copied().collect();
    assert_eq!(cuts, expected, "the metadata's finer_cut of each");
    assert_eq!(cut(rule - 1).0, rule, "a budget below the edge rule's pieces keeps the rule");
    // The budget: 10 s of a 16x16 capture, and a capture of 4096 samples per point.
    assert_eq!(finer_pieces(Budget::Time(std::time::Duration::from_secs(10)), 256), 195_312);
    assert_eq!(finer_pieces(Budget::Time(std::time::Duration::from_secs(10)), 1024), 48_828);
    assert_eq!(finer_pieces(Budget::Samples(4096), 256), 30_720);
}

/// close_surfaces makes the closed hidden sphere one-sided (it is watertight, wound outwards,
/// and clear of the wall and the origins) and leaves the open occluder panel and the wall
/// alone; an origin inside the sphere's box, or a sphere whose winding is reversed, keeps it
/// double-sided.
#[test]
fn closed_surfaces_become_one_sided_and_nothing_else() {
    let origin = Vec3::new(-1.2, 0.0, 0.6);
    let scene = common::nlos_sphere_scene_unprepared(4, true);
    let sided = |s: &gatetrace::scene::Scene, node: &str| -> Vec<bool> {
        s.triangles[s.node(node).unwrap().triangles.clone()]
            .iter()
            .map(|t| s.materials[t.material as usize].double_sided)
            .collect()
    };
    assert!(sided(&scene, "hidden_sphere").iter().all(|&d| d), "the test expects a double-sided sphere");
    let mut closed = scene.clone();
    assert_eq!(gatetrace::nlos::close_surfaces(&mut closed, "relay_wall", &[origin]).unwrap(), 1);
    assert!(sided(&closed, "hidden_sphere").iter().all(|&d| !d), "the closed sphere must become one-sided");
    assert_eq!(sided(&closed, "occluder"), sided(&scene, "occluder"), "the open occluder must stay as it was");
    assert_eq!(sided(&closed, "relay_wall"), sided(&scene, "relay_wall"));
    // An origin inside the sphere's box.
    let mut inside = scene.clone();
    assert_eq!(gatetrace::nlos::close_surfaces(&mut inside, "relay_wall", &[Vec3::new(0.0, 0.0, 0.6)]).unwrap(), 0);
    // Wound inwards: negative volume.
    let mut reversed = scene.clone();
    for t in &mut reversed.triangles[scene.node("hidden_sphere").unwrap().triangles.clone()] {
        t.positions.swap(1, 2);
    }
    assert_eq!(gatetrace::nlos::close_surfaces(&mut reversed, "relay_wall", &[origin]).unwrap(), 0);
    // A hole: one triangle fewer.
    let mut open = scene.clone();
    let r = scene.node("hidden_sphere").unwrap().triangles.clone();
    open.triangles[r.start].positions[0] += Vec3::splat(1e-3);
    assert_eq!(gatetrace::nlos::close_surfaces(&mut open, "relay_wall", &[origin]).unwrap(), 0);
}

/// Through the command line: `--band-index auto` (the default) declines the example letter (8
/// triangles besides the relay wall, which every query searches whole) and says so in the
/// metadata; `on` prepares its scene (its panels cut into pieces) and builds the index.
#[test]
fn the_command_line_decides_the_band_index_by_the_scene() {
    let dir = common::scratch_dir("band_index_cli");
    let letter = common::repo_path("assets/scenes/nlos_letter.gltf");
    let render = |name: &str, extra: &[&str]| -> serde_json::Value {
        let out = dir.join(format!("{name}.npy"));
        let mut args = vec![
            "render",
            letter.to_str().unwrap(),
            "--nlos",
            "confocal",
            "--method",
            "ellipsoidal",
            "--res",
            "4x4",
            "--max-bounces",
            "3",
            "--gate",
            "transient:0.9,0.0048,80",
            "--spp",
            "96",
            "--seed",
            "3",
            "-o",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_gatetrace")).args(&args).output().unwrap();
        assert!(o.status.success(), "{name}: {}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_str(&std::fs::read_to_string(dir.join(format!("{name}.json"))).unwrap()).unwrap()
    };
    let auto = render("auto", &[]);
    let report = auto["band_index"].as_str().expect("auto says what it decided");
    assert!(report.starts_with("off (auto)") && report.contains("8 triangles"), "{report}");
    assert!(auto.get("shell_preparation").is_none());
    let on = render("on", &["--band-index", "on"]);
    let report = on["band_index"].as_str().unwrap();
    assert!(report.contains("clusters") && !report.starts_with("off"), "{report}");
    let prepared = &on["shell_preparation"];
    let count = |key: &str| prepared[key].as_u64().unwrap_or_else(|| panic!("{key} in {prepared}"));
    assert!(
        count("closed_meshes_made_one_sided") + count("triangles_cut_into_pieces") > 0 && count("triangles") > 0,
        "{prepared}"
    );
}

/// The staircase of boxes (`nlos_staircase_boxes.xml`): its five boxes are closed convex opaque
/// solids, and after the refinement the pieces dropped as buried are exactly within the faces
/// between the boxes (the lower part of each box's front face, which lies against the box in
/// front, and the back faces against the box behind), covering most of them, while every other
/// piece stays. A box holding a path's origin, a box with a face missing, a dented box and glass
/// boxes are not solids.
#[test]
fn buried_pieces_between_boxes_are_dropped_and_nothing_else() {
    let path = common::repo_path("assets/scenes/nlos_staircase_boxes.xml");
    let load = gatetrace::scene::LoadOptions { capture: true, ..Default::default() };
    let scene = gatetrace::scene::load_scene_with(&path, &load).unwrap();
    let origin = Vec3::new(-0.3, 0.1, 0.6);
    let wall = scene.node("relay_wall").unwrap().triangles.clone();
    assert_eq!(scene.triangles.len() - wall.len(), 60, "the test expects five boxes of 12 triangles");
    let solids = gatetrace::nlos::convex_solids(&scene, "relay_wall", &[origin]);
    assert_eq!(solids.len(), 5);
    let mut refined = scene.clone();
    gatetrace::nlos::refine_for_shells(&mut refined, "relay_wall", 0.0012, 0).unwrap();
    let mut dropped = refined.clone();
    let buried = gatetrace::nlos::drop_buried_pieces(&mut dropped, "relay_wall", &solids);
    assert_eq!(dropped.triangles.len() + buried, refined.triangles.len());
    assert_eq!(dropped.node("relay_wall").unwrap().triangles.len(), wall.len(), "the relay wall is kept");
    // Step k spans z in [0.4 + 0.15 k, 0.55 + 0.15 k] and y in [-0.45, -0.45 + 0.15 (k + 1)]:
    // the plane z = 0.55 + 0.15 k between steps k and k + 1 is buried where y < the top of k.
    let between =
        |p: Vec3| (0..4).any(|k| (p.z - (0.55 + 0.15 * k as f32)).abs() < 1e-5 && p.y < -0.3 + 0.15 * k as f32 + 1e-5);
    let centroid = |t: &gatetrace::scene::SceneTriangle| (t.positions[0] + t.positions[1] + t.positions[2]) / 3.0;
    let area = |ts: &[gatetrace::scene::SceneTriangle]| ts.iter().map(|t| t.area() as f64).sum::<f64>();
    // Pieces are told apart by their centroids: the dropped ones are those missing afterwards.
    let key = |t: &gatetrace::scene::SceneTriangle| centroid(t).to_array().map(f32::to_bits);
    let kept: std::collections::HashSet<[u32; 3]> = dropped.triangles.iter().map(key).collect();
    let gone: Vec<gatetrace::scene::SceneTriangle> =
        refined.triangles.iter().filter(|t| !kept.contains(&key(t))).cloned().collect();
    assert_eq!(gone.len(), buried);
    for t in &gone {
        assert!(t.positions.iter().all(|&p| between(p)), "a dropped piece at {} is not between two boxes", centroid(t));
    }
    // The buried faces: 0.6 m wide, 0.15 (k + 1) high, on both sides of each of the four planes.
    let exact = 2.0 * 0.6 * 0.15 * (1 + 2 + 3 + 4) as f64;
    let gone_area = area(&gone);
    let kept_between = dropped.triangles.iter().filter(|t| t.positions.iter().all(|&p| between(p))).count();
    println!("{buried} pieces dropped, {gone_area:.4} m^2 of {exact:.4} m^2 buried");
    assert_eq!(kept_between, 0, "every piece wholly between two boxes is dropped");
    assert!(gone_area <= exact + 1e-4 && gone_area > 0.95 * exact, "{gone_area} m^2 of {exact} m^2 dropped");
    // Not solids: a box holding an origin, a box with a face missing, a dented box, glass.
    let boxes =
        |s: &gatetrace::scene::Scene, origin: Vec3| gatetrace::nlos::convex_solids(s, "relay_wall", &[origin]).len();
    assert_eq!(boxes(&scene, Vec3::new(0.0, -0.4, 0.45)), 4, "an origin inside the first box");
    let first = (0..scene.triangles.len()).find(|i| !wall.contains(i)).unwrap();
    let mut open = scene.clone();
    open.triangles.drain(first..first + 2);
    for node in &mut open.nodes {
        if node.triangles.start > first {
            node.triangles = node.triangles.start - 2..node.triangles.end - 2;
        }
    }
    assert_eq!(boxes(&open, origin), 4, "a box with a face missing");
    let mut dented = scene.clone();
    let corner = dented.triangles[first].positions[0];
    let centre = (0..12).map(|i| centroid(&scene.triangles[first + i])).sum::<Vec3>() / 12.0;
    for t in &mut dented.triangles[first..first + 12] {
        for p in &mut t.positions {
            if *p == corner {
                *p = corner.lerp(centre, 0.3);
            }
        }
    }
    assert_eq!(boxes(&dented, origin), 4, "a box with a corner pushed in");
    let mut glass = scene.clone();
    let stone = scene.triangles[first].material as usize;
    glass.materials[stone].dielectric =
        Some(gatetrace::scene::Dielectric { eta: 1.5, specular: 1.0, thin: false, alpha: 0.0 });
    assert_eq!(boxes(&glass, origin), 0, "glass boxes");
}
