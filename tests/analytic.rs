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
    let stats = common::render_batches(&ctx, &scene, &settings, batches, 16);
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

#[test]
fn signed_and_smooth_gates_weigh_the_same_paths() {
    // Same seed, same paths; only W differs. cw with phase 180 deg is exactly the negative of
    // phase 0 (cos(x + pi) = -cos(x) up to f32 rounding of the argument); a Gaussian far wider
    // than the scene weighs every path by 1 - O(1e-12), i.e. gives the steady image.
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let base = RenderSettings { width: 16, height: 16, max_bounces: 4, seed: 8, ..Default::default() };
    let render = |gate: Gate| common::render_films(&ctx, &scene, &RenderSettings { gate, ..base.clone() }, 1, 8).remove(0);
    let steady = render(Gate::None);
    let cw0 = render(Gate::Cw { frequency_hz: 100e6, phase_deg: 0.0 });
    let cw180 = render(Gate::Cw { frequency_hz: 100e6, phase_deg: 180.0 });
    let mut negative = 0;
    for ((a, b), s) in cw0.data.iter().zip(&cw180.data).zip(&steady.data) {
        // |W| <= 1 per term; the two cosines differ by at most a few f32 ulps of the argument.
        assert!((a + b).abs() <= 1e-5 * s + 1e-7, "cw 0 deg {a} vs 180 deg {b}");
        assert!(a.abs() <= s * (1.0 + 1e-5) + 1e-7, "|cw| cannot exceed the steady value");
        negative += (*a < 0.0) as usize;
    }
    assert!(negative > 0, "at 100 MHz (3 m wavelength) some pixels must come out negative");
    let wide = render(Gate::Gaussian { mean: 3.0, sigma: 1e6 });
    for (a, s) in wide.data.iter().zip(&steady.data) {
        assert!((a - s).abs() <= 1e-6 * s, "wide gaussian {a} vs steady {s}");
    }
}

/// Area of the part of polygon `poly` (film coordinates) inside the pixel [x, x+1] x [y, y+1]
/// (Sutherland-Hodgman clipping, then the shoelace formula).
fn clipped_area(poly: &[(f64, f64)], x: f64, y: f64) -> f64 {
    let mut p = poly.to_vec();
    // Half-planes as (axis, bound, keep_greater).
    for (axis, bound, greater) in [(0, x, true), (0, x + 1.0, false), (1, y, true), (1, y + 1.0, false)] {
        let inside = |q: &(f64, f64)| {
            let v = if axis == 0 { q.0 } else { q.1 };
            if greater { v >= bound } else { v <= bound }
        };
        let mut out = Vec::new();
        for i in 0..p.len() {
            let (a, b) = (p[i], p[(i + 1) % p.len()]);
            let (va, vb) = if axis == 0 { (a.0, b.0) } else { (a.1, b.1) };
            if inside(&a) {
                out.push(a);
            }
            if inside(&a) != inside(&b) {
                let t = (bound - va) / (vb - va);
                out.push((a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1)));
            }
        }
        p = out;
        if p.is_empty() {
            return 0.0;
        }
    }
    0.5 * (0..p.len()).map(|i| p[i].0 * p[(i + 1) % p.len()].1 - p[(i + 1) % p.len()].0 * p[i].1).sum::<f64>().abs()
}

#[test]
fn pixels_partly_on_the_light_read_radiance_times_coverage() {
    // With max_bounces 0 a pixel of the Cornell box reads L x (fraction of the pixel whose rays
    // hit the light). The light's triangles project to triangles on the film (pinhole), so the
    // coverage is exact polygon clipping. Pixels that are never hit or always hit read exactly
    // 0 or L; the others are compared with z-scores from the batch variance.
    let scene = common::cornell_box();
    let (w, h) = (64u32, 64u32);
    let cam = scene.scene.camera;
    let tan_half = (0.5 * cam.yfov as f64).tan();
    let project = |p: glam::Vec3| {
        let d = (p - cam.position).as_dvec3();
        let depth = d.dot(cam.forward.as_dvec3());
        let x_ndc = d.dot(cam.right.as_dvec3()) / depth / tan_half;
        let y_ndc = d.dot(cam.up.as_dvec3()) / depth / tan_half;
        ((x_ndc + 1.0) * 0.5 * w as f64, (1.0 - y_ndc) * 0.5 * h as f64)
    };
    let lights: Vec<Vec<(f64, f64)>> = scene
        .scene
        .triangles
        .iter()
        .filter(|t| scene.scene.materials[t.material as usize].is_emissive())
        .map(|t| t.positions.iter().map(|&p| project(p)).collect())
        .collect();
    let radiance = 10.0;
    let settings = RenderSettings { width: w, height: h, max_bounces: 0, seed: 21, ..Default::default() };
    let ctx = common::gpu();
    let (batches, spp) = (16, 256);
    let stats = common::render_batches(&ctx, &scene, &settings, batches, spp);
    let (mean, var) = (stats.mean(), stats.var_of_mean());
    let pixels = (w * h) as usize;
    let p_each = sidak(0.01, pixels);
    let limit = t_critical(p_each, (batches - 1) as f64);
    let samples = (batches * spp as usize) as f64;
    let mut partial = 0;
    for y in 0..h {
        for x in 0..w {
            let coverage: f64 = lights.iter().map(|t| clipped_area(t, x as f64, y as f64)).sum();
            let expected = radiance * coverage;
            let i = ((y * w + x) * 3) as usize;
            let got = mean[i];
            if var[i] == 0.0 {
                // Every sample gave the same value: all hits or all misses. Such a run must
                // not be too unlikely under the exact coverage.
                let p = if got == 0.0 { (1.0 - coverage).powf(samples) } else { coverage.powf(samples) };
                assert!(got == 0.0 || got == radiance, "pixel ({x}, {y}) = {got}");
                assert!(p >= p_each, "pixel ({x}, {y}): {got} in every sample, but the coverage is {coverage:.6}");
            } else {
                partial += 1;
                let z = (got - expected) / var[i].sqrt();
                assert!(z.abs() < limit, "pixel ({x}, {y}): {got:.5} vs {expected:.5} (coverage {coverage:.5}, z = {z:.2})");
            }
        }
    }
    assert!(partial >= 20, "the light's outline crosses at least 20 pixels ({partial})");
}
