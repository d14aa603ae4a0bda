//! NLOS captures of the example scene against the peer (Mitsuba 3.9.1 + mitransient 1.3.1,
//! `transient_nlos_path`; tests/data/nlos_letter_peer/README.md): single and confocal scans of a
//! 16x16 grid, three bounces, 100 bins of 12 mm from 0.9 m. Every bin of every pixel and
//! channel is compared (Sidak-corrected Student's t limits), and the total energy must agree
//! within 1 %. The peer's projector laser is matched per spot by its equivalent beam power.

mod common;

use common::stats::{BatchStats, sidak, t_critical};
use gatetrace::film::Gate;
use gatetrace::integrator::{Method, RenderSettings};
use gatetrace::nlos::{LaserAim, NlosCapture};
use gatetrace::scene::{PreparedScene, load_gltf};
use glam::{Vec2, Vec3};

const ALPHA: f64 = 0.01;
const BATCHES: usize = 16;
const SPP: u32 = 4096;

fn example_scene() -> PreparedScene {
    PreparedScene::new(load_gltf(&common::repo_path("assets/scenes/nlos_letter.gltf")).unwrap()).unwrap()
}

/// The peer's setup: origins at (-1.2, 0, 0.6) m, a 1 W laser (rescaled per spot below).
fn settings(aim: LaserAim, method: Method) -> RenderSettings {
    let origin = Vec3::new(-1.2, 0.0, 0.6);
    RenderSettings {
        width: 16,
        height: 16,
        method,
        gate: Gate::Transient { start: 0.9, width: 0.012, bins: 100 },
        max_bounces: 3,
        nlos: Some(NlosCapture {
            relay_wall: "relay_wall".into(),
            sensor_origin: origin,
            laser_origin: origin,
            aim,
            laser_power: 1.0,
            count_first_and_last: false,
        }),
        ..Default::default()
    }
}

/// Renders the capture in batches, scales each pixel by the peer's equivalent laser power and
/// compares every bin with the peer's.
fn compare_with_peer(name: &str, aim: LaserAim) {
    let ctx = common::gpu();
    let scene = example_scene();
    let (shape, peer_mean) = common::reference(&format!("nlos_letter_peer/{name}_mean.npy"));
    let (_, peer_var) = common::reference(&format!("nlos_letter_peer/{name}_var.npy"));
    let (_, power) = common::reference(&format!("nlos_letter_peer/{name}_laser_power_equivalent.npy"));
    assert_eq!(shape, vec![16, 16, 100, 3]);
    let per_pixel = 100 * 3;
    let scale = |i: usize| power[if power.len() == 1 { 0 } else { i / per_pixel }] as f64;
    let films = common::render_films(&ctx, &scene, &settings(aim, Method::Path), BATCHES, SPP);
    let mut stats = BatchStats::new(peer_mean.len());
    let mut totals = Vec::new();
    for film in &films {
        let scaled: Vec<f32> = film.data.iter().enumerate().map(|(i, &v)| (v as f64 * scale(i)) as f32).collect();
        totals.push(scaled.iter().map(|&v| v as f64).sum::<f64>());
        stats.add(&scaled);
    }
    let (mean, var) = (stats.mean(), stats.var_of_mean());

    // Total energy: within 1 % and consistent with the noise of both sides.
    let ours: f64 = totals.iter().sum::<f64>() / BATCHES as f64;
    let ours_var = totals.iter().map(|t| (t - ours).powi(2)).sum::<f64>() / ((BATCHES - 1) * BATCHES) as f64;
    let peer: f64 = peer_mean.iter().map(|&v| v as f64).sum();
    let peer_v: f64 = peer_var.iter().map(|&v| v as f64).sum();
    let z = (ours - peer) / (ours_var + peer_v).sqrt();
    println!("{name}: total energy ours {ours:.6} peer {peer:.6} ratio {:.5} z {z:+.2}", ours / peer);
    assert!((ours / peer - 1.0).abs() < 0.01, "{name}: total energy ours {ours} vs peer {peer}");
    assert!(z.abs() < t_critical(ALPHA, (BATCHES - 1) as f64), "{name}: total energy z = {z:.2}");

    // Every bin that either side lit.
    let live: Vec<usize> = (0..mean.len()).filter(|&i| var[i] + peer_var[i] as f64 > 0.0).collect();
    let zs: Vec<f64> =
        live.iter().map(|&i| (mean[i] - peer_mean[i] as f64) / (var[i] + peer_var[i] as f64).sqrt()).collect();
    let worst = zs.iter().fold(0.0f64, |w, z| w.max(z.abs()));
    let spread = (zs.iter().map(|z| z * z).sum::<f64>() / zs.len() as f64).sqrt();
    let limit = t_critical(sidak(ALPHA, zs.len()), (BATCHES - 1) as f64);
    println!("{name}: {} bins with light, rms z {spread:.3}, worst |z| {worst:.2} (limit {limit:.2})", zs.len());
    assert!(zs.len() > 10_000, "{name}: only {} bins saw light", zs.len());
    assert!(worst < limit, "{name}: a bin differs from the peer (|z| = {worst:.2} >= {limit:.2})");
    // With variances estimated from BATCHES batches, z is close to Student's t with BATCHES - 1
    // degrees of freedom, whose rms is sqrt(dof / (dof - 2)) (1.074 for 15): an rms well outside
    // [0.9, that + 0.05] means a bias or a wrong noise model, even with every bin within its limit.
    let dof = (BATCHES - 1) as f64;
    let t_rms = (dof / (dof - 2.0)).sqrt();
    assert!(spread > 0.9 && spread < t_rms + 0.05, "{name}: the z-scores' rms {spread:.3} is not that of noise");
}

#[test]
fn single_scan_matches_peer() {
    compare_with_peer("single", LaserAim::Spot(Vec2::new(0.3, 0.6)));
}

#[test]
fn confocal_scan_matches_peer() {
    compare_with_peer("confocal", LaserAim::Confocal);
}

/// Sensed points lie at the cell centres of the wall's texture coordinates: on the example wall
/// (u along +x, v along +y over [-0.5, 0.5]^2 m), cell (i, j) of 16x16 is at x = (i + 0.5) / 16 -
/// 0.5, y = (j + 0.5) / 16 - 0.5; a confocal capture's laser spots are the same points; path-length
/// offsets remove the first and last segments unless asked to count them.
#[test]
fn wall_points_follow_the_grid() {
    let scene = example_scene();
    let s = settings(LaserAim::Confocal, Method::Path);
    let capture = s.nlos.clone().unwrap();
    let points = gatetrace::nlos::wall_points(&scene, &capture, 16, 16).unwrap();
    assert_eq!(points.len(), 2 * 256);
    for j in 0..16 {
        for i in 0..16 {
            let p = &points[j * 16 + i];
            let expected = Vec3::new((i as f32 + 0.5) / 16.0 - 0.5, (j as f32 + 0.5) / 16.0 - 0.5, 0.0);
            assert!((p.position - expected).length() < 1e-5, "cell ({i}, {j}) at {} not {expected}", p.position);
            assert!((p.length_offset + (p.position - capture.sensor_origin).length()).abs() < 1e-6);
            let spot = &points[256 + j * 16 + i];
            assert!((spot.position - p.position).length() < 1e-6 && spot.length_offset == 0.0);
            assert_eq!(spot.power, Vec3::ONE);
        }
    }
    let counted = NlosCapture { count_first_and_last: true, ..capture };
    let points = gatetrace::nlos::wall_points(&scene, &counted, 16, 16).unwrap();
    assert_eq!(points[0].length_offset, 0.0);
    assert!((points[256].length_offset - (points[256].position - counted.laser_origin).length()).abs() < 1e-6);
}

/// A capture names its wall: a missing node, or one without texture coordinates, is a clear error.
#[test]
fn a_missing_relay_wall_is_named() {
    let scene = example_scene();
    let mut capture = settings(LaserAim::Confocal, Method::Path).nlos.unwrap();
    capture.relay_wall = "no_such_wall".into();
    let e = gatetrace::nlos::check_capture(&scene.scene, &capture).unwrap_err().to_string();
    assert!(e.contains("no node named `no_such_wall`") && e.contains("nlos_letter.gltf"), "{e}");
    capture.relay_wall = "occluder".into();
    let e = gatetrace::nlos::check_capture(&scene.scene, &capture).unwrap_err().to_string();
    assert!(e.contains("no TEXCOORD_0"), "{e}");
}
