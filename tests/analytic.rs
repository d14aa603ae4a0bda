//! Scenes with closed-form answers.

mod common;

use common::gltf_builder::{Camera, Material, PointLight, Scene, quad_z};
use common::stats::{sidak, t_critical};
use gatetrace::film::Gate;
use gatetrace::integrator::RenderSettings;
use gatetrace::scene::{PreparedScene, load_gltf};

/// Camera at the origin looking down -z.
const LOOK_DOWN_Z: [f32; 4] = [0.0, 0.0, 0.0, 1.0];

fn prepare(scene: &Scene, name: &str) -> PreparedScene {
    let dir = common::scratch_dir(name);
    PreparedScene::new(load_gltf(&scene.write(&dir, &format!("{name}.gltf"))).unwrap()).unwrap()
}

#[test]
fn pixels_on_an_emitter_return_its_radiance() {
    // An emitter of radiance 7.5 fills the view at 1 m; every sample sees exactly 7.5.
    let scene = prepare(
        &Scene {
            meshes: vec![quad_z(10.0, -1.0, true, 0)],
            materials: vec![Material::emitter(7.5)],
            camera: Some(Camera { position: [0.0; 3], rotation: LOOK_DOWN_Z, yfov: 0.9 }),
            point_lights: vec![],
        },
        "emitter_radiance",
    );
    let ctx = common::gpu();
    for (bounces, gate) in [(0, Gate::None), (4, Gate::None), (0, Gate::Box { start: 1.0, end: 1.5 })] {
        let settings = RenderSettings { width: 16, height: 12, max_bounces: bounces, gate, ..Default::default() };
        let film = common::render_films(&ctx, &scene, &settings, 1, 8).remove(0);
        for v in &film.data {
            // The sum of 8 equal f32 values divided by 8 is exact.
            assert_eq!(*v, 7.5, "a pixel on the emitter must read its radiance exactly ({bounces} bounces)");
        }
    }
    // A gate beyond every path length gives black, not NaN.
    let settings = RenderSettings { width: 16, height: 12, gate: Gate::Box { start: 5.0, end: 6.0 }, ..Default::default() };
    let film = common::render_films(&ctx, &scene, &settings, 1, 4).remove(0);
    assert!(film.data.iter().all(|&v| v == 0.0));
}

#[test]
fn one_sided_emitters_are_dark_from_behind() {
    let scene = prepare(
        &Scene {
            meshes: vec![quad_z(10.0, -1.0, false, 0)],
            materials: vec![Material::emitter(7.5)],
            camera: Some(Camera { position: [0.0; 3], rotation: LOOK_DOWN_Z, yfov: 0.9 }),
            point_lights: vec![],
        },
        "emitter_back",
    );
    let ctx = common::gpu();
    let film = common::render_films(&ctx, &scene, &RenderSettings { width: 8, height: 8, ..Default::default() }, 1, 4).remove(0);
    assert!(film.data.iter().all(|&v| v == 0.0));
}

/// Solid angle of the rectangle [x0, x1] x [y0, y1] on the plane at unit distance.
fn rectangle_solid_angle(x0: f64, x1: f64, y0: f64, y1: f64) -> f64 {
    let f = |x: f64, y: f64| (x * y / (1.0 + x * x + y * y).sqrt()).atan();
    f(x1, y1) - f(x0, y1) - f(x1, y0) + f(x0, y0)
}

#[test]
fn first_return_of_a_plane_lit_from_the_camera() {
    // A Lambertian plane (albedo rho) at distance d, lit by a point light of intensity I at the
    // pinhole. Along a ray at angle theta: L = rho I cos^3(theta) / (pi d^2), path length
    // 2 d / cos(theta). A pixel averages L over its image-plane rectangle R (box filter), so its
    // value is rho I / (pi d^2) * solid_angle(R) / area(R) (since dOmega = cos^3 dA).
    let (d, rho, intensity, yfov) = (2.0f64, 0.6f64, 5.0f64, 0.5f64);
    let scene = prepare(
        &Scene {
            meshes: vec![quad_z(4.0, -d as f32, true, 0)],
            materials: vec![Material::diffuse([rho as f32; 3])],
            camera: Some(Camera { position: [0.0; 3], rotation: LOOK_DOWN_Z, yfov: yfov as f32 }),
            point_lights: vec![PointLight { position: [0.0; 3], intensity: intensity as f32 }],
        },
        "plane_first_return",
    );
    let (w, h) = (16u32, 16u32);
    // Bins of 0.25 m from 3.9 m: 2 d = 4 m lies in bin 0, the image corners reach bin 1.
    let gate = Gate::Transient { start: 3.9, width: 0.25, bins: 4 };
    let settings = RenderSettings { width: w, height: h, max_bounces: 3, gate, ..Default::default() };
    let ctx = common::gpu();
    let batches = 16;
    let (stats, _) = common::render_batches(&ctx, &scene, &settings, batches, 16);
    let (mean, var) = (stats.mean(), stats.var_of_mean());
    let t = (yfov / 2.0).tan();
    let pixel = 2.0 * t / w as f64;
    let threshold = t_critical(sidak(0.01, (w * h) as usize), (batches - 1) as f64);
    for y in 0..h {
        for x in 0..w {
            let (x0, y0) = (-t + x as f64 * pixel, t - (y + 1) as f64 * pixel);
            let expected = rho * intensity / (std::f64::consts::PI * d * d) * rectangle_solid_angle(x0, x0 + pixel, y0, y0 + pixel)
                / (pixel * pixel);
            let p = (y * w + x) as usize;
            let (mut sum, mut sum_var) = (0.0, 0.0);
            for b in 0..4 {
                let i = (p * 4 + b) * 3;
                sum += mean[i];
                sum_var += var[i];
                assert_eq!(mean[i], mean[i + 1], "grey scene: channels must agree");
            }
            let z = (sum - expected) / sum_var.sqrt().max(1e-12 * expected);
            assert!(z.abs() < threshold, "pixel ({x}, {y}): {sum} vs closed form {expected} (z = {z:.2}, limit {threshold:.2})");
            // Nothing arrives before 2d: bins before the one containing 2d are empty.
            let first = (0..4).find(|&b| mean[(p * 4 + b) * 3] > 0.0).unwrap();
            let centre = (x == w / 2 - 1 || x == w / 2) && (y == h / 2 - 1 || y == h / 2);
            if centre {
                assert_eq!(first, 0, "the first return of the central pixels is in the bin containing 2d");
                assert_eq!(mean[(p * 4 + 1) * 3], 0.0, "central pixels are shorter than 4.15 m");
            }
        }
    }
}

#[test]
fn transient_bins_sum_to_the_steady_image_of_the_same_run() {
    // Same seed, same paths: bins covering every path length add up to the steady image up to
    // f32 summation order. Each film cell sums at most spp * 2 (max_bounces + 1) terms, so
    // the rounding difference is below that count times f32 epsilon, relative.
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let spp = 32;
    let steady = RenderSettings { width: 32, height: 32, max_bounces: 5, seed: 3, ..Default::default() };
    let transient = RenderSettings { gate: Gate::Transient { start: 0.0, width: 0.25, bins: 80 }, ..steady.clone() };
    let a = common::render_films(&ctx, &scene, &steady, 1, spp).remove(0);
    let b = common::render_films(&ctx, &scene, &transient, 1, spp).remove(0).sum_bins();
    let tolerance = (spp as f32 * 2.0 * 6.0) * f32::EPSILON;
    let mut nonzero = 0;
    for (x, y) in a.data.iter().zip(&b.data) {
        assert!((x - y).abs() <= tolerance * x.abs() + 1e-9, "steady {x} vs sum of bins {y}");
        nonzero += (*x > 0.0) as usize;
    }
    assert!(nonzero > a.data.len() / 2);
}

#[test]
fn gates_no_path_can_reach_are_black_without_tracing() {
    use gatetrace::integrator::{Budget, render, unreachable_gate};
    let scene = common::cornell_box();
    // DESIGN.md: the shortest path of the Cornell box (pinhole to the light's nearest point) is 1.9403 m.
    let (shortest, _) = scene.scene.path_length_bounds(5);
    assert!((shortest - 1.9403).abs() < 1e-4, "{shortest}");
    let ctx = common::gpu();
    for gate in [Gate::Box { start: 1.0, end: 1.94 }, Gate::Box { start: 50.0, end: 51.0 }] {
        let settings = RenderSettings { width: 8, height: 8, max_bounces: 5, gate, ..Default::default() };
        assert!(unreachable_gate(&scene, &settings).is_some());
        let out = render(&ctx, &scene, &settings, Budget::Samples(1_000_000), |_| panic!("nothing is traced")).unwrap();
        assert_eq!(out.film.spp, 0);
        assert!(out.film.data.iter().all(|&v| v == 0.0));
    }
    let reachable = RenderSettings { gate: Gate::Box { start: 1.9, end: 1.95 }, max_bounces: 5, ..Default::default() };
    assert!(unreachable_gate(&scene, &reachable).is_none());
}
