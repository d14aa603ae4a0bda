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

/// An emitter of `radiance` at 1 m filling the view of a camera at the origin (yfov `yfov`),
/// facing the camera or away from it.
fn emitter_wall(radiance: f32, facing_camera: bool, yfov: f32, name: &str) -> PreparedScene {
    prepare(
        &Scene {
            meshes: vec![quad_z(10.0, -1.0, facing_camera, 0)],
            materials: vec![Material::emitter(radiance)],
            camera: Some(Camera { position: [0.0; 3], rotation: LOOK_DOWN_Z, yfov }),
            point_lights: vec![],
        },
        name,
    )
}

#[test]
fn pixels_on_an_emitter_return_its_radiance() {
    // An emitter of radiance 7.5 fills the view at 1 m; every sample sees exactly 7.5.
    let scene = emitter_wall(7.5, true, 0.9, "emitter_radiance");
    let ctx = common::gpu();
    for (bounces, gate) in [(0, Gate::None), (4, Gate::None), (0, Gate::Box { start: 1.0, end: 1.5 })] {
        let settings = RenderSettings { width: 16, height: 12, max_bounces: bounces, gate, ..Default::default() };
        let film = common::render_films(ctx, &scene, &settings, 1, 8).remove(0);
        for v in &film.data {
            // The sum of 8 equal f32 values divided by 8 is exact.
            assert_eq!(*v, 7.5, "a pixel on the emitter must read its radiance exactly ({bounces} bounces)");
        }
    }
    // A gate beyond every path length gives black, not NaN.
    let settings =
        RenderSettings { width: 16, height: 12, gate: Gate::Box { start: 5.0, end: 6.0 }, ..Default::default() };
    let film = common::render_films(ctx, &scene, &settings, 1, 4).remove(0);
    assert!(film.data.iter().all(|&v| v == 0.0));
}

#[test]
fn one_sided_emitters_are_dark_from_behind() {
    let scene = emitter_wall(7.5, false, 0.9, "emitter_back");
    let ctx = common::gpu();
    let film = common::render_films(ctx, &scene, &RenderSettings { width: 8, height: 8, ..Default::default() }, 1, 4)
        .remove(0);
    assert!(film.data.iter().all(|&v| v == 0.0));
}

/// Solid angle of the rectangle [x0, x1] x [y0, y1] on the plane at unit distance.
fn rectangle_solid_angle(x0: f64, x1: f64, y0: f64, y1: f64) -> f64 {
    let f = |x: f64, y: f64| (x * y / (1.0 + x * x + y * y).sqrt()).atan();
    f(x1, y1) - f(x0, y1) - f(x1, y0) + f(x0, y0)
}

/// A Lambertian plane (albedo RHO) at distance PLANE_D facing a pinhole camera (vertical field
/// of view PLANE_FOV) with a point light of intensity PLANE_I at the pinhole.
const PLANE_D: f64 = 2.0;
const PLANE_RHO: f64 = 0.6;
const PLANE_I: f64 = 5.0;
const PLANE_FOV: f64 = 0.5;
const PLANE_RES: u32 = 16;

fn plane_lit_from_the_camera(name: &str) -> PreparedScene {
    prepare(
        &Scene {
            meshes: vec![quad_z(4.0, -PLANE_D as f32, true, 0)],
            materials: vec![Material::diffuse([PLANE_RHO as f32; 3])],
            camera: Some(Camera { position: [0.0; 3], rotation: LOOK_DOWN_Z, yfov: PLANE_FOV as f32 }),
            point_lights: vec![PointLight { position: [0.0; 3], intensity: PLANE_I as f32 }],
        },
        name,
    )
}

/// Image-plane rectangle (at unit distance) of pixel (x, y): (x0, x1, y0, y1).
fn plane_pixel(x: u32, y: u32) -> (f64, f64, f64, f64) {
    let t = (PLANE_FOV / 2.0).tan();
    let p = 2.0 * t / PLANE_RES as f64;
    let (x0, y0) = (-t + x as f64 * p, t - (y + 1) as f64 * p);
    (x0, x0 + p, y0, y0 + p)
}

#[test]
fn first_return_of_a_plane_lit_from_the_camera() {
    // Along a ray at angle theta: L = rho I cos^3(theta) / (pi d^2), path length
    // 2 d / cos(theta). A pixel averages L over its image-plane rectangle R (box filter), so its
    // value is rho I / (pi d^2) * solid_angle(R) / area(R) (since dOmega = cos^3 dA), and its
    // light arrives only at lengths between 2 d sqrt(1 + r_min^2) and 2 d sqrt(1 + r_max^2),
    // r being the distance of a point of R from the axis.
    let scene = plane_lit_from_the_camera("plane_first_return");
    let (w, h) = (PLANE_RES, PLANE_RES);
    // 1 cm bins from 3.955 m: 2 d = 4 m lies inside bin 4, the image corners reach bin 29.
    let (start, width, bins) = (3.955, 0.01, 40usize);
    let gate = Gate::Transient { start, width, bins: bins as u32 };
    let settings = RenderSettings { width: w, height: h, max_bounces: 3, gate, ..Default::default() };
    let ctx = common::gpu();
    let batches = 16;
    let stats = common::render_batches(ctx, &scene, &settings, batches, 16);
    let (mean, var) = (stats.mean(), stats.var_of_mean());
    let threshold = t_critical(sidak(0.01, (w * h) as usize), (batches - 1) as f64);
    // Lengths are computed in f32 on the device: allow a few f32 ulps of 4 m at bin edges.
    let slack = 1e-5;
    for y in 0..h {
        for x in 0..w {
            let (x0, x1, y0, y1) = plane_pixel(x, y);
            let expected = PLANE_RHO * PLANE_I / (std::f64::consts::PI * PLANE_D * PLANE_D)
                * rectangle_solid_angle(x0, x1, y0, y1)
                / ((x1 - x0) * (y1 - y0));
            let p = (y * w + x) as usize;
            let (mut sum, mut sum_var) = (0.0, 0.0);
            for b in 0..bins {
                let i = (p * bins + b) * 3;
                sum += mean[i];
                sum_var += var[i];
                assert_eq!(mean[i], mean[i + 1], "grey scene: channels must agree");
            }
            let z = (sum - expected) / sum_var.sqrt().max(1e-12 * expected);
            assert!(
                z.abs() < threshold,
                "pixel ({x}, {y}): {sum} vs closed form {expected} (z = {z:.2}, limit {threshold:.2})"
            );
            // Light arrives only in the bins the pixel's path lengths cover.
            let nearest = |a: f64, b: f64| if a <= 0.0 && b >= 0.0 { 0.0 } else { a.abs().min(b.abs()) };
            let r_min2 = nearest(x0, x1).powi(2) + nearest(y0, y1).powi(2);
            let r_max2 = x0.abs().max(x1.abs()).powi(2) + y0.abs().max(y1.abs()).powi(2);
            let (shortest, longest) = (2.0 * PLANE_D * (1.0 + r_min2).sqrt(), 2.0 * PLANE_D * (1.0 + r_max2).sqrt());
            for b in 0..bins {
                let (lo, hi) = (start + b as f64 * width, start + (b + 1) as f64 * width);
                if hi < shortest - slack || lo > longest + slack {
                    assert_eq!(
                        mean[(p * bins + b) * 3],
                        0.0,
                        "pixel ({x}, {y}) bin [{lo}, {hi}) outside [{shortest}, {longest}]"
                    );
                }
            }
            let centre = (x == w / 2 - 1 || x == w / 2) && (y == h / 2 - 1 || y == h / 2);
            if centre {
                let first = (0..bins).find(|&b| mean[(p * bins + b) * 3] > 0.0).unwrap();
                assert_eq!(first, 4, "the first return of the central pixels is in the bin holding 2d = 4 m");
            }
        }
    }
}

#[test]
fn smooth_gates_weigh_each_path_by_its_length() {
    // The plane again, with Gaussian and cw gates: a pixel is the average over its rectangle of
    // L(theta) W(2 d / cos theta), computed here by a 48 x 48 midpoint rule (its error, about
    // 1e-6 relative, is far below the noise).
    let scene = plane_lit_from_the_camera("plane_smooth_gates");
    let ctx = common::gpu();
    let gates = [Gate::Gaussian { mean: 4.08, sigma: 0.05 }, Gate::Cw { frequency_hz: 1.0e9, phase_deg: 40.0 }];
    let batches = 16;
    let threshold = t_critical(sidak(0.01, gates.len() * (PLANE_RES * PLANE_RES) as usize), (batches - 1) as f64);
    for gate in gates {
        let settings = RenderSettings {
            width: PLANE_RES,
            height: PLANE_RES,
            max_bounces: 1,
            gate: gate.clone(),
            ..Default::default()
        };
        let stats = common::render_batches(ctx, &scene, &settings, batches, 64);
        let (mean, var) = (stats.mean(), stats.var_of_mean());
        let (kind, g, table) = (gate.kind(), gate.to_gpu(), gate.table());
        let w = |l: f64| gatetrace::film::gate::gate_weight(kind, &g, &table, l as f32) as f64;
        let n = 48;
        for y in 0..PLANE_RES {
            for x in 0..PLANE_RES {
                let (x0, x1, y0, y1) = plane_pixel(x, y);
                let mut acc = 0.0;
                for i in 0..n {
                    for j in 0..n {
                        let u = x0 + (x1 - x0) * (i as f64 + 0.5) / n as f64;
                        let v = y0 + (y1 - y0) * (j as f64 + 0.5) / n as f64;
                        let sec = (1.0 + u * u + v * v).sqrt();
                        acc += w(2.0 * PLANE_D * sec) / (sec * sec * sec);
                    }
                }
                let expected = PLANE_RHO * PLANE_I / (std::f64::consts::PI * PLANE_D * PLANE_D) * acc / (n * n) as f64;
                let i = ((y * PLANE_RES + x) * 3) as usize;
                let z = (mean[i] - expected) / var[i].sqrt().max(1e-9 * expected.abs());
                assert!(
                    z.abs() < threshold,
                    "{}: pixel ({x}, {y}) {} vs {expected} (z = {z:.2})",
                    gate.describe(),
                    mean[i]
                );
            }
        }
    }
}

#[test]
fn transient_bins_sum_to_the_steady_image_of_the_same_run() {
    // Same seed, same paths: bins covering every path length add up to the steady image. The
    // film's fixed-point sums are exact, so the difference is the
    // rounding of each bin to f32 and the f32 sum over 80 bins: under 82 f32 epsilons.
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let spp = 32;
    let steady = RenderSettings { width: 32, height: 32, max_bounces: 5, seed: 3, ..Default::default() };
    let transient = RenderSettings { gate: Gate::Transient { start: 0.0, width: 0.25, bins: 80 }, ..steady.clone() };
    let a = common::render_films(ctx, &scene, &steady, 1, spp).remove(0);
    let b = common::render_films(ctx, &scene, &transient, 1, spp).remove(0).sum_bins();
    let tolerance = 82.0 * f32::EPSILON;
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
    // docs/design.md section 3: the shortest path of the Cornell box (pinhole to the light's nearest
    // point) is 1.9403 m.
    let (shortest, _) = scene.scene.path_length_bounds(5);
    assert!((shortest - 1.9403).abs() < 1e-4, "{shortest}");
    let ctx = common::gpu();
    for gate in [Gate::Box { start: 1.0, end: 1.94 }, Gate::Box { start: 50.0, end: 51.0 }] {
        let settings = RenderSettings { width: 8, height: 8, max_bounces: 5, gate, ..Default::default() };
        assert!(unreachable_gate(&scene, &settings).is_some());
        let out = render(ctx, &scene, &settings, Budget::Samples(1_000_000), |_| panic!("nothing is traced")).unwrap();
        assert_eq!(out.film.spp, 0);
        assert!(out.film.data.iter().all(|&v| v == 0.0));
    }
    let reachable = RenderSettings { gate: Gate::Box { start: 1.9, end: 1.95 }, max_bounces: 5, ..Default::default() };
    assert!(unreachable_gate(&scene, &reachable).is_none());
}

#[test]
fn cw_gates_accumulate_signed_weights() {
    // Same seed, same paths; only W differs. cw with phase 180 deg is exactly the negative of
    // phase 0 (cos(x + pi) = -cos(x) up to f32 rounding of the argument).
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let base = RenderSettings { width: 16, height: 16, max_bounces: 4, seed: 8, ..Default::default() };
    let render =
        |gate: Gate| common::render_films(ctx, &scene, &RenderSettings { gate, ..base.clone() }, 1, 8).remove(0);
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
    let stats = common::render_batches(ctx, &scene, &settings, batches, spp);
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
                assert!(
                    z.abs() < limit,
                    "pixel ({x}, {y}): {got:.5} vs {expected:.5} (coverage {coverage:.5}, z = {z:.2})"
                );
            }
        }
    }
    assert!(partial >= 20, "the light's outline crosses at least 20 pixels ({partial})");
}

#[test]
fn long_renders_do_not_drift() {
    // 2^22 samples of a pixel that sees an emitter of radiance 0.1 everywhere: every term is
    // the same f32, so the mean must be 0.1 to f32 precision. A plain f32 sum of these terms
    // is off by percents; the film's fixed-point sums are exact.
    let scene = emitter_wall(0.1, true, 0.5, "long_render");
    let ctx = common::gpu();
    let settings = RenderSettings { width: 1, height: 2, max_bounces: 0, ..Default::default() };
    let film = common::render_films(ctx, &scene, &settings, 1, 1 << 22).remove(0);
    for v in &film.data {
        assert!((v - 0.1).abs() <= 0.1 * f32::EPSILON, "mean {v} after 2^22 samples of 0.1");
    }
}

#[test]
fn one_sided_emitters_light_only_their_front() {
    // A floor lit by an emitter 1 m above it. Facing up (away from the floor) the emitter must
    // not light it, through light sampling or otherwise; facing down it must.
    let ctx = common::gpu();
    let render = |facing_floor: bool| {
        let scene = prepare(
            &Scene {
                meshes: vec![quad_z(2.0, 0.0, true, 0), quad_z(0.3, 1.0, !facing_floor, 1)],
                materials: vec![Material::diffuse([0.7; 3]), Material::emitter(5.0)],
                // Between floor and emitter, looking down: the emitter itself is out of view.
                camera: Some(Camera { position: [0.0, 0.0, 0.5], rotation: LOOK_DOWN_Z, yfov: 0.9 }),
                point_lights: vec![],
            },
            &format!("one_sided_{facing_floor}"),
        );
        let settings = RenderSettings { width: 16, height: 16, max_bounces: 3, ..Default::default() };
        common::render_films(ctx, &scene, &settings, 1, 16).remove(0)
    };
    let away = render(false);
    assert!(away.data.iter().all(|&v| v == 0.0), "an emitter facing away lights nothing");
    let towards = render(true);
    let lit = towards.data.iter().filter(|&&v| v > 0.0).count();
    assert!(lit > towards.data.len() / 2, "an emitter facing the floor lights it ({lit} values)");
}

#[test]
fn a_spot_light_lights_the_plane_by_its_falloff() {
    spot_lights_the_plane(gatetrace::scene::SpotFalloff::CosineRampSquared);
}

#[test]
fn a_mitsuba_spot_light_lights_the_plane_by_its_falloff_linear_in_angle() {
    spot_lights_the_plane(gatetrace::scene::SpotFalloff::LinearInAngle);
}

fn spot_lights_the_plane(profile: gatetrace::scene::SpotFalloff) {
    // The plane lit from the camera again, the point light made a spot looking down the axis
    // with a wide ramp (inner cone 0.05 rad, outer 0.2 rad; the image reaches 0.35 rad at its
    // corners): along a ray at angle theta, L = rho I s(cos theta) cos^3(theta) / (pi d^2) with
    // glTF's falloff s = clamp((cos - cos_outer) / (cos_inner - cos_outer), 0, 1)^2, or
    // Mitsuba's s = clamp((outer - theta) / (outer - inner), 0, 1), averaged over each pixel's
    // rectangle by a 48 x 48 midpoint rule. Both the path tracer (next-event estimation) and
    // `direct` (light subpaths sampled over the cone, MIS) must agree with it.
    use gatetrace::integrator::Method;
    use gatetrace::scene::SpotFalloff;
    let (inner, outer) = (0.05f64, 0.2f64);
    let dir = common::scratch_dir(&format!("plane_spot_{profile:?}"));
    let base = Scene {
        meshes: vec![quad_z(4.0, -PLANE_D as f32, true, 0)],
        materials: vec![Material::diffuse([PLANE_RHO as f32; 3])],
        camera: Some(Camera { position: [0.0; 3], rotation: LOOK_DOWN_Z, yfov: PLANE_FOV as f32 }),
        point_lights: vec![PointLight { position: [0.0; 3], intensity: PLANE_I as f32 }],
    };
    let mut scene = load_gltf(&base.write(&dir, "plane_spot.gltf")).unwrap();
    scene.point_lights[0].spot = Some(gatetrace::scene::SpotCone {
        direction: glam::Vec3::NEG_Z,
        inner: inner as f32,
        outer: outer as f32,
        falloff: profile,
    });
    let scene = PreparedScene::new(scene).unwrap();
    let falloff = |c: f64| match profile {
        SpotFalloff::CosineRampSquared => ((c - outer.cos()) / (inner.cos() - outer.cos())).clamp(0.0, 1.0).powi(2),
        SpotFalloff::LinearInAngle => ((outer - c.clamp(-1.0, 1.0).acos()) / (outer - inner)).clamp(0.0, 1.0),
    };
    let ctx = common::gpu();
    let batches = 16;
    let methods = [Method::Path, Method::Direct];
    let threshold = t_critical(sidak(0.01, methods.len() * (PLANE_RES * PLANE_RES) as usize), (batches - 1) as f64);
    let n = 48;
    for method in methods {
        let settings =
            RenderSettings { width: PLANE_RES, height: PLANE_RES, max_bounces: 1, method, ..Default::default() };
        let stats = common::render_batches(ctx, &scene, &settings, batches, 64);
        let (mean, var) = (stats.mean(), stats.var_of_mean());
        let (mut lit, mut dark, mut edge) = (0, 0, 0);
        for y in 0..PLANE_RES {
            for x in 0..PLANE_RES {
                let (x0, x1, y0, y1) = plane_pixel(x, y);
                let (mut acc, mut inside) = (0.0, 0);
                for i in 0..n {
                    for j in 0..n {
                        let u = x0 + (x1 - x0) * (i as f64 + 0.5) / n as f64;
                        let v = y0 + (y1 - y0) * (j as f64 + 0.5) / n as f64;
                        let sec = (1.0 + u * u + v * v).sqrt();
                        acc += falloff(1.0 / sec) / (sec * sec * sec);
                        inside += (falloff(1.0 / sec) > 0.0) as usize;
                    }
                }
                let expected = PLANE_RHO * PLANE_I / (std::f64::consts::PI * PLANE_D * PLANE_D) * acc / (n * n) as f64;
                let i = ((y * PLANE_RES + x) * 3) as usize;
                if expected == 0.0 {
                    // Wholly outside the cone: no light at all.
                    assert_eq!(mean[i], 0.0, "{method:?}: pixel ({x}, {y}) lies outside the cone");
                    dark += 1;
                    continue;
                }
                // A pixel that the cone's edge only grazes: fewer than 100 of its samples are
                // expected to see any light, too few for a z-score (all batches may see none).
                // The cone bounds it from above: its light is that of the cone's faint edge.
                let lit_samples = inside as f64 / (n * n) as f64 * (batches * 64) as f64;
                if lit_samples < 100.0 {
                    assert!(
                        mean[i] >= 0.0 && mean[i] < 0.01 * PLANE_RHO * PLANE_I / PLANE_D.powi(2),
                        "{method:?}: edge pixel ({x}, {y}) {}",
                        mean[i]
                    );
                    edge += 1;
                    continue;
                }
                lit += 1;
                let z = (mean[i] - expected) / var[i].sqrt().max(1e-9 * expected);
                assert!(
                    z.abs() < threshold,
                    "{method:?}: pixel ({x}, {y}) {} vs {expected} (z = {z:.2}, limit {threshold:.2})",
                    mean[i]
                );
            }
        }
        assert!(lit > 20 && dark > 20 && edge < 16, "{method:?}: {lit} lit, {edge} edge and {dark} dark pixels");
    }
}

#[test]
fn first_return_of_a_plane_lit_by_a_directional_light() {
    // The plane facing the camera, lit by a directional light of irradiance E travelling along
    // the view (-z): every point sees L = rho E / pi, and light reaches the plane's point x after
    // the plane-wave length l0 = -(x_z - c_z) + r (c, r: the bounding sphere, where the wave
    // starts), so a pixel's light arrives at l0 + d sec(theta), between its rectangle's nearest
    // and farthest points from the axis. `path`, `direct` (light subpaths from the disk, s = 1
    // resampled along the beam) and `ellipsoidal` (camera vertices joined to the light along the
    // beam, at their own lengths) must give it.
    use gatetrace::integrator::Method;
    const E: f64 = 2.5;
    let dir = common::scratch_dir("plane_directional");
    let base = Scene {
        meshes: vec![quad_z(4.0, -PLANE_D as f32, true, 0)],
        materials: vec![Material::diffuse([PLANE_RHO as f32; 3])],
        camera: Some(Camera { position: [0.0; 3], rotation: LOOK_DOWN_Z, yfov: PLANE_FOV as f32 }),
        point_lights: vec![],
    };
    let mut doc = base.to_json();
    doc["extensionsUsed"] = serde_json::json!(["KHR_lights_punctual"]);
    doc["extensions"] =
        serde_json::json!({"KHR_lights_punctual": {"lights": [{"type": "directional", "intensity": E}]}});
    doc["nodes"].as_array_mut().unwrap().push(serde_json::json!({"name": "sun", "translation": [0.0, 0.0, 5.0],
        "extensions": {"KHR_lights_punctual": {"light": 0}}}));
    let count = doc["nodes"].as_array().unwrap().len();
    doc["scenes"][0]["nodes"] = serde_json::json!((0..count).collect::<Vec<_>>());
    let scene = load_gltf(&common::gltf_builder::write_json(&dir, "plane_directional.gltf", &doc)).unwrap();
    assert_eq!(scene.directional_lights.len(), 1);
    let (centre, radius) = scene.bounding_sphere();
    let l0 = PLANE_D + centre.z as f64 + radius as f64;
    let scene = PreparedScene::new(scene).unwrap();
    let (w, h) = (PLANE_RES, PLANE_RES);
    let width = 0.01;
    let start = ((l0 + PLANE_D) / width).floor() * width - 0.005;
    let bins = 40usize;
    let ctx = common::gpu();
    let batches = 16;
    let threshold = t_critical(sidak(0.01, (w * h) as usize), (batches - 1) as f64);
    let expected = PLANE_RHO * E / std::f64::consts::PI;
    let slack = 1e-5 * (l0 + PLANE_D);
    for method in [Method::Path, Method::Direct, Method::Ellipsoidal] {
        let gate = Gate::Transient { start, width, bins: bins as u32 };
        let settings = RenderSettings { width: w, height: h, max_bounces: 3, gate, method, ..Default::default() };
        let films = common::render_films(ctx, &scene, &settings, batches, 16);
        let mut stats = common::stats::BatchStats::new(films[0].data.len());
        for f in &films {
            stats.add(&f.data);
        }
        let (mean, var) = (stats.mean(), stats.var_of_mean());
        // `direct` leaves about 1e-4 of the light to light tracing (MIS), whose splats reach a
        // pixel about twice in all 16 batches: per pixel, a batch variance says nothing about
        // them, so `direct` is judged by its image mean (about 650 splats) and per pixel only by
        // where its light arrives.
        if method == Method::Direct {
            let image: Vec<f64> = films
                .iter()
                .map(|f| f.data.iter().step_by(3).map(|&v| v as f64).sum::<f64>() / (w * h) as f64)
                .collect();
            let n = image.len() as f64;
            let m = image.iter().sum::<f64>() / n;
            let v = image.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0) / n;
            let z = (m - expected) / v.sqrt();
            assert!(z.abs() < 4.0, "direct: image mean {m} vs {expected} (z = {z:.2})");
        }
        for y in 0..h {
            for x in 0..w {
                let (x0, x1, y0, y1) = plane_pixel(x, y);
                let p = (y * w + x) as usize;
                let (mut sum, mut sum_var) = (0.0, 0.0);
                for b in 0..bins {
                    sum += mean[(p * bins + b) * 3];
                    sum_var += var[(p * bins + b) * 3];
                }
                if method != Method::Direct {
                    // Next-event estimation (`ellipsoidal`: the connection to the light, the only
                    // strategy of one-bounce paths, which are all the plane has) gives every sample
                    // exactly rho E / pi (to f32 rounding of the factors, a few ulps): the variance
                    // can vanish, so allow 8 f32 ulps.
                    let z = (sum - expected) / sum_var.sqrt().max(8.0 * f32::EPSILON as f64 * expected);
                    assert!(
                        z.abs() < threshold,
                        "{method:?}: pixel ({x}, {y}) {sum} vs {expected} (z = {z:.2}, limit {threshold:.2})"
                    );
                }
                let nearest = |a: f64, b: f64| if a <= 0.0 && b >= 0.0 { 0.0 } else { a.abs().min(b.abs()) };
                let r_min2 = nearest(x0, x1).powi(2) + nearest(y0, y1).powi(2);
                let r_max2 = x0.abs().max(x1.abs()).powi(2) + y0.abs().max(y1.abs()).powi(2);
                let (shortest, longest) = (l0 + PLANE_D * (1.0 + r_min2).sqrt(), l0 + PLANE_D * (1.0 + r_max2).sqrt());
                for b in 0..bins {
                    let (lo, hi) = (start + b as f64 * width, start + (b + 1) as f64 * width);
                    if hi < shortest - slack || lo > longest + slack {
                        assert_eq!(
                            mean[(p * bins + b) * 3],
                            0.0,
                            "{method:?}: pixel ({x}, {y}) bin [{lo}, {hi}) outside [{shortest}, {longest}]"
                        );
                    }
                }
            }
        }
    }
}
