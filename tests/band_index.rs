//! The band index of NLOS captures (src/integrator/band_index.rs): its clusters partition the
//! BVH's triangles, and `ellipsoidal` captures that draw their three-bounce connections from it
//! agree with captures that descend the BVH (both unbiased, independent estimators), bin group
//! by bin group, on a hidden sphere of 5,120 triangles split over many clusters, for confocal and
//! single scans.

mod common;

use gatetrace::film::{Film, Gate};
use gatetrace::integrator::band_index::{CLUSTER_NODES, clusters};
use gatetrace::integrator::{BidirectionalTracer, Integrator, Method};
use gatetrace::nlos::LaserAim;

#[test]
fn clusters_partition_the_triangles_into_small_subtrees() {
    let scene = common::nlos_sphere_scene(16, false);
    let nodes = &scene.bvh.nodes;
    let clusters = clusters(nodes, CLUSTER_NODES);
    assert!(clusters.len() > 50, "only {} clusters", clusters.len());
    let mut covered = vec![0u32; scene.triangles.len()];
    let mut next_root = 0;
    for &[root, end, first, last] in &clusters {
        // Between two clusters lie only inner nodes whose subtrees are too large to be one.
        assert!(root >= next_root, "clusters must follow each other in node order");
        for i in next_root..root {
            let n = &nodes[i as usize];
            assert!(n.leaf == 0 && n.skip - i > CLUSTER_NODES, "node {i} lies in no cluster");
        }
        assert_eq!(end, nodes[root as usize].skip, "a cluster is its root's whole subtree");
        assert!(end - root <= CLUSTER_NODES || nodes[root as usize].leaf != 0, "cluster at {root} too large");
        // Its leaves address exactly [first, last), with no gap.
        let leaf_triangles: u32 = nodes[root as usize..end as usize].iter().filter_map(|n| n.leaf_range()).map(|r| r.len() as u32).sum();
        assert_eq!(leaf_triangles, last - first, "cluster at {root}: its triangles are not contiguous");
        for t in first..last {
            covered[t as usize] += 1;
        }
        next_root = end;
    }
    assert_eq!(next_root as usize, nodes.len());
    assert!(covered.iter().all(|&c| c == 1), "every triangle must lie in exactly one cluster");
}

/// Renders `batches` films of `spp` of an `ellipsoidal` capture of the hidden sphere, with or
/// without the band index; returns them and the index's report.
fn capture(aim: LaserAim, band_index: bool, seed: u32, batches: usize, spp: u32) -> (Vec<Film>, Option<String>) {
    let ctx = common::gpu();
    let scene = common::nlos_sphere_scene(16, false);
    let gate = Gate::Transient { start: 0.85, width: 0.0024, bins: 300 };
    let settings = gatetrace::integrator::RenderSettings {
        seed,
        band_index,
        ..common::example_capture(4, 4, gate, aim, Method::Ellipsoidal)
    };
    let mut tracer = BidirectionalTracer::new(&ctx, &scene, &settings).unwrap();
    let films = common::films_of(&mut tracer, batches, spp);
    assert_eq!(tracer.truncated_traversals().unwrap(), 0);
    (films, tracer.band_index_report())
}

fn band_index_agrees_with_the_descent(scan: &str, aim: LaserAim) {
    const BATCHES: usize = 16;
    const SPP: u32 = 96;
    const GROUP: usize = 10;
    // The descent's estimates are skewed (rare large values), so its batches take more samples
    // for their means and variances to be trusted; the noise comparison below is per sample.
    const DESCENT_SPP: u32 = 8 * SPP;
    let (indexed, report) = capture(aim, true, 71, BATCHES, SPP);
    let (descended, none) = capture(aim, false, 72, BATCHES, DESCENT_SPP);
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
    let result = common::compare_films(&indexed, &descended, groups, group);
    common::assert_groups_agree(&format!("{scan}, band index vs descent"), "group", &result, (BATCHES - 1) as f64, 0.01);
    // Whole-capture energy.
    let energy = common::compare_films(&indexed, &descended, 1, |_| Some(0))[0];
    println!("{scan}: energy {:.6e} vs {:.6e} (z {:+.2})", energy.0, energy.1, energy.2);
    assert!(energy.2.abs() < 4.0, "{scan}: energies differ (z = {:.2})", energy.2);
    assert!(energy.0 > 0.0);
    // What the index is for, printed (its gain depends on the mesh and the samples per bin, and
    // is measured by tools/nlos_equal_time.py): the batch variance per sample.
    let variance = |films: &[Film], spp: u32| -> f64 {
        let totals: Vec<f64> = films.iter().map(|f| f.data.iter().map(|&v| v as f64).sum()).collect();
        let mean = totals.iter().sum::<f64>() / totals.len() as f64;
        totals.iter().map(|t| (t - mean).powi(2)).sum::<f64>() / (totals.len() - 1) as f64 * spp as f64
    };
    println!(
        "{scan}: variance of a batch's total x spp: band index {:.3e}, descent {:.3e}",
        variance(&indexed, SPP),
        variance(&descended, DESCENT_SPP)
    );
}

#[test]
fn confocal_band_index_agrees_with_the_descent_on_a_hidden_sphere() {
    band_index_agrees_with_the_descent("confocal", LaserAim::Confocal);
}

#[test]
fn single_scan_band_index_agrees_with_the_descent_on_a_hidden_sphere() {
    band_index_agrees_with_the_descent("single", LaserAim::Spot(glam::Vec2::new(0.3, 0.6)));
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
        let mut tracer = BidirectionalTracer::new(&ctx, &scene, &settings).unwrap();
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
