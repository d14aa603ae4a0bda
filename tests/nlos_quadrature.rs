//! NLOS captures at fine time bins against an independent, deterministic reference: the
//! three-bounce transient (laser spot -> hidden point -> sensed point) of the example scene's
//! hidden letter, integrated by quadrature on the CPU.
//!
//! The example scene without its occluder is a relay wall and a planar letter that see each
//! other unobstructed. With three bounces, the radiance leaving a sensed point x_s within a bin
//! of path lengths [l, l + w) is then exactly
//!
//!   L = (rho_w / pi) (rho_h / pi) (rho_w / pi) P  integral over the letter of
//!       [cos_l cos_h' / |h - x_l|^2] [cos_h cos_s / |h - x_s|^2] [l <= |x_l - h| + |h - x_s| < l + w] dA,
//!
//! the laser spot x_l reflecting a beam of power P as a Lambertian point (docs/design.md section 6.6). The
//! quadrature integrates it exactly along lines across each triangle (the bin edges on a line
//! are the roots of a quadratic, the line meeting a spheroid with foci x_l and x_s) and by the
//! midpoint rule across lines, in two directions whose difference bounds the error and enters
//! each bin's variance, with the share of a bin that the device's f32 path lengths resolve. Every bin of a 4x4 grid at 1.2 mm (4 ps) bins is compared, for
//! single and confocal scans, path tracing and ellipsoidal connections: the sharp arrival edges,
//! where a bias of a tenth of a millimetre in path length would show, are tested bin by bin.
//!
//! Shell connections (the band index) are checked the same way on a convex hidden sphere, which
//! nothing occludes either: every sensed point's whole light against a quadrature over the
//! sphere's triangles.

mod common;

use common::stats::{BatchStats, sidak, t_critical};
use gatetrace::film::Gate;
use gatetrace::integrator::{Method, RenderSettings};
use gatetrace::nlos::{LaserAim, wall_points};
use gatetrace::scene::{PreparedScene, load_gltf};
use glam::{DVec3, Vec2};
use std::f64::consts::PI;

const ALPHA: f64 = 0.01;
const BATCHES: usize = 16;
const GRID: u32 = 4;
/// 1000 bins of 1.2 mm (4 ps) from 0.9 m: every three-bounce path through the letter.
const START: f64 = 0.9;
const WIDTH: f64 = 0.0012;
const BINS: usize = 1000;
/// Lines across each triangle, of each of two directions: about 0.05 mm apart on the letter.
const LINES: usize = 8192;

/// The example scene without its occluder (the last node's triangles), so that three-bounce
/// paths are exactly those through the letter.
fn letter_and_wall() -> PreparedScene {
    let mut scene = load_gltf(&common::repo_path("assets/scenes/nlos_letter.gltf")).unwrap();
    let occluder = scene.node("occluder").unwrap().triangles.clone();
    assert_eq!(occluder.end, scene.triangles.len(), "the occluder's triangles are expected last");
    scene.triangles.truncate(occluder.start);
    scene.nodes.iter_mut().find(|n| n.name == "occluder").unwrap().triangles = occluder.start..occluder.start;
    PreparedScene::new(scene).unwrap()
}

fn settings(aim: LaserAim, method: Method) -> RenderSettings {
    common::example_capture(GRID, GRID, Gate::Transient { start: START, width: WIDTH, bins: BINS as u32 }, aim, method)
}

/// The relay wall's albedo and unit normal (its first triangle's).
fn relay_wall(scene: &PreparedScene) -> (DVec3, DVec3) {
    let wall = scene.scene.node("relay_wall").unwrap().triangles.clone();
    let tri = &scene.scene.triangles[wall.start];
    let [w0, w1, w2] = tri.positions.map(|p| p.as_dvec3());
    (scene.scene.materials[tri.material as usize].base_color.as_dvec3(), (w1 - w0).cross(w2 - w0).normalize())
}

/// A hidden triangle: vertices (m), albedo, whether both faces reflect.
struct Hidden {
    v: [DVec3; 3],
    albedo: DVec3,
    double_sided: bool,
}

/// Three-point Gauss-Legendre nodes and weights on [0, 1].
const GAUSS: [(f64, f64); 3] =
    [(0.5 - 0.387_298_334_620_741_7, 5.0 / 18.0), (0.5, 8.0 / 18.0), (0.5 + 0.387_298_334_620_741_7, 5.0 / 18.0)];

/// Parameters t of the line p + t u (|u| = 1) where |h - a| + |h - b| = c: the line meets the
/// spheroid with foci a and b. From |h - b| = (c^2 + |h-b|^2 - |h-a|^2) / 2c, linear in t, squared.
fn spheroid_crossings(p: DVec3, u: DVec3, a: DVec3, b: DVec3, c: f64) -> [Option<f64>; 2] {
    let (pa, pb) = (p - a, p - b);
    let alpha0 = c * c + pb.length_squared() - pa.length_squared();
    let alpha1 = 2.0 * u.dot(a - b);
    let k = 1.0 / (4.0 * c * c);
    let qa = 1.0 - alpha1 * alpha1 * k;
    let qb = 2.0 * u.dot(pb) - 2.0 * alpha1 * alpha0 * k;
    let qc = pb.length_squared() - alpha0 * alpha0 * k;
    let disc = qb * qb - 4.0 * qa * qc;
    if disc < 0.0 {
        return [None, None];
    }
    let s = disc.sqrt();
    // Both roots, computed without cancellation.
    let q = -0.5 * (qb + s.copysign(qb));
    let (t0, t1) = (q / qa, if q != 0.0 { qc / q } else { -qb / (2.0 * qa) });
    // Squaring admits |h - b| > c; keep the crossings of the spheroid itself.
    let valid = |t: f64| (alpha0 + alpha1 * t) >= 0.0 && ((p + t * u - b).length() <= c * (1.0 + 1e-12));
    [Some(t0).filter(|&t| valid(t)), Some(t1).filter(|&t| valid(t))]
}

/// Bin-integrated radiance per channel (W m^-2 sr^-1 per W of laser power) leaving `sensed`
/// through exactly one hidden vertex, with `lines` lines across each triangle parallel to its
/// edge `edge` (0, 1 or 2).
fn quadrature(
    hidden: &[Hidden],
    wall_albedo: DVec3,
    wall_normal: DVec3,
    sensed: DVec3,
    spot: DVec3,
    lines: usize,
    edge: usize,
) -> Vec<[f64; 3]> {
    let mut bins = vec![[0.0; 3]; BINS];
    let edges: Vec<f64> = (0..=BINS).map(|k| START + WIDTH * k as f64).collect();
    let mut breaks = Vec::new();
    for tri in hidden {
        let [a, b, c] = [tri.v[edge], tri.v[(edge + 1) % 3], tri.v[(edge + 2) % 3]];
        let n = (b - a).cross(c - a);
        let (area2, normal) = (n.length(), n.normalize());
        let height = area2 / (b - a).length();
        // The geometric part of the integrand at h, zero where a face does not reflect.
        let geometry = |h: DVec3| -> f64 {
            let (to_s, to_l) = (sensed - h, spot - h);
            let (ds2, dl2) = (to_s.length_squared(), to_l.length_squared());
            let (ds, dl) = (ds2.sqrt(), dl2.sqrt());
            let (cos_s, cos_l) = (-wall_normal.dot(to_s) / ds, -wall_normal.dot(to_l) / dl);
            let (cos_hs, cos_hl) = (normal.dot(to_s) / ds, normal.dot(to_l) / dl);
            let same_side = cos_hs * cos_hl > 0.0;
            let facing = tri.double_sided || cos_hs > 0.0;
            if cos_s <= 0.0 || cos_l <= 0.0 || !same_side || !facing {
                return 0.0;
            }
            cos_l * cos_hl.abs() / dl2 * cos_hs.abs() * cos_s / ds2
        };
        let scale = tri.albedo * wall_albedo * wall_albedo / (PI * PI * PI);
        for i in 0..lines {
            // The line at fraction s of the way from edge ab to vertex c, parallel to ab.
            let s = (i as f64 + 0.5) / lines as f64;
            let (p, q) = (a + s * (c - a), b + s * (c - b));
            let len = (q - p).length();
            let u = (q - p) / len;
            let across = height / lines as f64;
            breaks.clear();
            breaks.extend([0.0, len]);
            let length_at = |t: f64| {
                let h = p + t * u;
                (h - sensed).length() + (h - spot).length()
            };
            let (l0, l1) = (length_at(0.0), length_at(len));
            // Along the line the length changes at most twice as fast as t, so only the edges between
            // that bound on its minimum and its longer end can cross it.
            let (lo, hi) = (0.5 * (l0 + l1) - len, l0.max(l1));
            let first = edges.partition_point(|&e| e < lo);
            for &e in edges[first..].iter().take_while(|&&e| e <= hi) {
                for t in spheroid_crossings(p, u, sensed, spot, e).into_iter().flatten() {
                    if t > 0.0 && t < len {
                        breaks.push(t);
                    }
                }
            }
            breaks.sort_by(f64::total_cmp);
            for w in breaks.windows(2) {
                let (t0, t1) = (w[0], w[1]);
                if t1 <= t0 {
                    continue;
                }
                let bin = ((length_at(0.5 * (t0 + t1)) - START) / WIDTH).floor();
                if bin < 0.0 || bin >= BINS as f64 {
                    continue;
                }
                let g: f64 =
                    GAUSS.iter().map(|&(x, wt)| wt * geometry(p + (t0 + x * (t1 - t0)) * u)).sum::<f64>() * (t1 - t0);
                let cell = &mut bins[bin as usize];
                for ch in 0..3 {
                    cell[ch] += scale[ch] * g * across;
                }
            }
        }
    }
    bins
}

/// The reference of every pixel (sensed point, laser spot, laser power) per bin and channel,
/// [pixel][bin][channel], and the variance of its error: the mean of two quadratures whose lines
/// run in different directions, so that their errors (largest where lines graze a bin's edge)
/// fall in different places; their difference squared bounds the variance of the mean's error.
/// Pixels are integrated on every core (rayon).
fn reference_bins(
    hidden: &[Hidden],
    wall_albedo: DVec3,
    wall_normal: DVec3,
    points: &[(DVec3, DVec3, DVec3)],
) -> (Vec<f64>, Vec<f64>) {
    let pixel = |&(sensed, spot, power): &(DVec3, DVec3, DVec3)| {
        let one = quadrature(hidden, wall_albedo, wall_normal, sensed, spot, LINES, 0);
        let other = quadrature(hidden, wall_albedo, wall_normal, sensed, spot, LINES, 1);
        let mut values = Vec::with_capacity(BINS * 3);
        for (k, (f, g)) in one.iter().zip(&other).enumerate() {
            // The device resolves path lengths, and so bin edges, to an f32 unit in the last place:
            // a bin's value is defined to no better than that share of its width.
            let edge = (START + WIDTH * (k + 1) as f64) as f32;
            let resolution = (f32::from_bits(edge.to_bits() + 1) - edge) as f64 / WIDTH;
            for ch in 0..3 {
                let value = 0.5 * (f[ch] + g[ch]) * power[ch];
                values.push((value, ((f[ch] - g[ch]) * power[ch]).powi(2) + (value * resolution).powi(2)));
            }
        }
        values
    };
    use rayon::prelude::*;
    let values: Vec<(f64, f64)> = points.par_iter().flat_map_iter(pixel).collect();
    values.into_iter().unzip()
}

/// The reference of scan `key`, computed by `compute` once per process: the tests of one scan
/// with different methods share it.
fn reference_of(key: &str, compute: impl FnOnce() -> (Vec<f64>, Vec<f64>)) -> (Vec<f64>, Vec<f64>) {
    type References = std::collections::HashMap<String, (Vec<f64>, Vec<f64>)>;
    static REFERENCES: std::sync::Mutex<Option<References>> = std::sync::Mutex::new(None);
    // Held while computing, so that two tests of one scan compute it once.
    let mut references = REFERENCES.lock().unwrap_or_else(|e| e.into_inner());
    references.get_or_insert_with(Default::default).entry(key.to_owned()).or_insert_with(compute).clone()
}

/// Compares renders of `spp` samples per pixel in BATCHES batches with the quadrature, bin by
/// bin after summing groups of `group` neighbouring bins (1: the 4 ps bins themselves).
fn compare_with_quadrature(scan: &str, aim: LaserAim, method: Method, spp: u32, group: usize) {
    let scene = letter_and_wall();
    let s = settings(aim, method);
    let capture = s.nlos.clone().unwrap();
    let points = wall_points(&scene, &capture, GRID, GRID).unwrap();
    let pixels = (GRID * GRID) as usize;
    let albedo = |m: u32| scene.scene.materials[m as usize].base_color.as_dvec3();
    let (wall_albedo, wall_normal) = relay_wall(&scene);
    let letter = scene.scene.node("hidden_letter").unwrap().triangles.clone();
    let hidden: Vec<Hidden> = scene.scene.triangles[letter]
        .iter()
        .map(|t| Hidden {
            v: t.positions.map(|p| p.as_dvec3()),
            albedo: albedo(t.material),
            double_sided: scene.scene.materials[t.material as usize].double_sided,
        })
        .collect();
    assert!(hidden.len() >= 2 && hidden.iter().all(|h| (h.v[0].z - 0.5).abs() < 1e-6));

    let (reference, quadrature_var) = reference_of(&format!("{aim:?}"), || {
        let points: Vec<(DVec3, DVec3, DVec3)> = (0..pixels)
            .map(|px| {
                let (sensed, spot) = (points[px].position.as_dvec3(), points[pixels + px].position.as_dvec3());
                (sensed, spot, points[pixels + px].power.as_dvec3())
            })
            .collect();
        reference_bins(&hidden, wall_albedo, wall_normal, &points)
    });

    let ctx = common::gpu();
    let films = common::render_films(ctx, &scene, &s, BATCHES, spp);
    // [pixel][bin][channel] values summed over groups of `group` bins.
    let coarsen = |v: &[f64]| -> Vec<f64> {
        let mut out = vec![0.0; v.len() / group];
        for (i, x) in v.iter().enumerate() {
            let (px, bin, ch) = (i / (3 * BINS), (i / 3) % BINS, i % 3);
            out[(px * (BINS / group) + bin / group) * 3 + ch] += x;
        }
        out
    };
    let (reference, quadrature_var) = (coarsen(&reference), coarsen(&quadrature_var));
    let bins = BINS / group;
    let mut stats = BatchStats::new(reference.len());
    for film in &films {
        let summed = coarsen(&film.data.iter().map(|&x| x as f64).collect::<Vec<_>>());
        stats.add(&summed.iter().map(|&x| x as f32).collect::<Vec<_>>());
    }
    let (mean, var) = (stats.mean(), stats.var_of_mean());
    let name = format!("{scan} scan, {}", method.name());

    let total: f64 = mean.iter().sum();
    let expected: f64 = reference.iter().sum();
    println!("{name}: total ours {total:.6e} quadrature {expected:.6e} ratio {:.5}", total / expected);
    if spp >= BINS as u32 {
        assert!((total / expected - 1.0).abs() < 0.01, "{name}: total energy {total:.6e} vs {expected:.6e}");
    } else {
        // Fewer samples than bins: which bins a batch visits moves its total by several percent,
        // so the total is tested against the spread of the batches' totals.
        let totals: Vec<f64> = films.iter().map(|f| f.data.iter().map(|&v| v as f64).sum()).collect();
        let var_of_mean = totals.iter().map(|t| (t - total).powi(2)).sum::<f64>() / (BATCHES * (BATCHES - 1)) as f64;
        let z = (total - expected) / var_of_mean.sqrt();
        let limit = t_critical(ALPHA, (BATCHES - 1) as f64);
        println!("{name}: total's z {z:.2} (limit {limit:.2})");
        assert!(z.abs() < limit, "{name}: total energy {total:.6e} vs {expected:.6e} (z {z:.2})");
    }

    // Bins with light on either side. A bin ours never reached (no variance) while the
    // quadrature has light would give an infinite z: such bins are counted and bounded by their
    // share of the energy instead.
    let mut zs = Vec::new();
    // z-scores of the bins whose error is mostly ours (the sampling noise), for their rms.
    let mut noise_zs = Vec::new();
    let mut missed = 0.0;
    let mut worst = (0.0f64, 0usize);
    for i in 0..reference.len() {
        if reference[i] == 0.0 && mean[i] == 0.0 {
            continue;
        }
        if var[i] == 0.0 {
            missed += reference[i];
            continue;
        }
        let z = (mean[i] - reference[i]) / (var[i] + quadrature_var[i]).sqrt();
        if z.abs() > worst.0 {
            worst = (z.abs(), i);
        }
        zs.push(z);
        if var[i] > quadrature_var[i] {
            noise_zs.push(z);
        }
    }
    let limit = t_critical(sidak(ALPHA, zs.len()), (BATCHES - 1) as f64);
    let rms = (noise_zs.iter().map(|z| z * z).sum::<f64>() / noise_zs.len() as f64).sqrt();
    let (px, bin) = (worst.1 / (3 * bins), (worst.1 / 3) % bins);
    println!(
        "{name}: {} bins with light, rms z {rms:.3} over the {} whose noise exceeds the quadrature's, worst |z| {:.2} (pixel {px}, bin {bin}: ours {:.4e} ± {:.1e}, \
         quadrature {:.4e} ± {:.1e}; limit {limit:.2}); unreached bins hold {:.2e} of the energy",
        zs.len(),
        noise_zs.len(),
        worst.0,
        mean[worst.1],
        var[worst.1].sqrt(),
        reference[worst.1],
        quadrature_var[worst.1].sqrt(),
        missed / expected
    );
    assert!(zs.len() > 3 * pixels * 100 / group, "{name}: only {} bins saw light", zs.len());
    assert!(missed < 1e-4 * expected, "{name}: bins ours never reached hold {missed:.3e} of {expected:.3e}");
    assert!(worst.0 < limit, "{name}: a bin differs from the quadrature (|z| = {:.2} >= {limit:.2})", worst.0);
    let dof = (BATCHES - 1) as f64;
    let t_rms = (dof / (dof - 2.0)).sqrt();
    assert!(
        noise_zs.len() > zs.len() / 2,
        "{name}: the quadrature's error dominates {} of {} bins",
        zs.len() - noise_zs.len(),
        zs.len()
    );
    assert!(rms > 0.9 && rms < t_rms + 0.05, "{name}: the z-scores' rms {rms:.3} is not that of noise");
}

const SPOT: LaserAim = LaserAim::Spot(Vec2::new(0.3, 0.6));

#[test]
fn single_scan_at_fine_bins_matches_quadrature() {
    compare_with_quadrature("single", SPOT, Method::Path, 65536, 1);
}

#[test]
fn confocal_scan_at_fine_bins_matches_quadrature() {
    compare_with_quadrature("confocal", LaserAim::Confocal, Method::Path, 65536, 1);
}

#[test]
fn single_scan_with_ellipsoidal_connections_at_fine_bins_matches_quadrature() {
    compare_with_quadrature("single", SPOT, Method::Ellipsoidal, 4096, 1);
}

#[test]
fn confocal_scan_with_ellipsoidal_connections_at_fine_bins_matches_quadrature() {
    compare_with_quadrature("confocal", LaserAim::Confocal, Method::Ellipsoidal, 4096, 1);
}

/// Fewer samples per film than bins: the film ends within its first cycle, before some bins'
/// base visits, and divides each bin by its expected visits (stratum_factors). With
/// half a visit per bin and batch, single bins are far from normal; groups of 25 (100 ps) are
/// compared.
#[test]
fn confocal_scan_with_ellipsoidal_connections_and_fewer_samples_than_bins_matches_quadrature() {
    compare_with_quadrature("confocal, 512 spp", LaserAim::Confocal, Method::Ellipsoidal, 512, 25);
}

/// Shell connections (the band index, a capture's default on meshes of more than 16 triangles)
/// on a convex hidden sphere, which nothing occludes, against a quadrature of each sensed
/// point's whole three-bounce light: over the triangles that face both foci,
/// (rho_w / pi)^2 (rho_h / pi) P times the integral of cos_l cos_h' cos_h cos_s / (|h - x_l|^2
/// |h - x_s|^2) dA, a smooth integrand on each triangle that the Dunavant rule gives to about
/// 1e-9 (common::quadrature). The sphere is the band-index tests' 5,120-triangle geodesic sphere without its bumps
/// (radius 0.15 m, 0.6 m from the wall); the gate, 100 bins of 10 mm from 0.85 m, holds all of
/// its light. Each point's total is compared (Student's t over 16 batches, Sidak's correction
/// over the points), and the capture's.
fn shell_connections_match_quadrature_on_a_convex_sphere(scan: &str, aim: LaserAim) {
    const START: f64 = 0.85;
    const WIDTH: f64 = 0.01;
    const BINS: u32 = 100;
    let gate = Gate::Transient { start: START, width: WIDTH, bins: BINS };
    let mut scene = common::nlos_sphere_scene_with_bumps(16, false, 0.0);
    let sphere = scene.node("hidden_sphere").unwrap().triangles.clone();
    // Convex: every vertex of the sphere on or behind every face's plane, so that a point facing
    // a focus sees it.
    let faces: Vec<[DVec3; 3]> =
        scene.triangles[sphere.clone()].iter().map(|t| t.positions.map(|p| p.as_dvec3())).collect();
    for f in &faces {
        let n = (f[1] - f[0]).cross(f[2] - f[0]).normalize();
        let out = faces.iter().flatten().map(|v| n.dot(*v - f[0])).fold(f64::MIN, f64::max);
        assert!(out < 1e-7, "the sphere is not convex: a vertex {out:.2e} m in front of a face");
    }
    let base = common::example_capture(GRID, GRID, gate, aim, Method::Ellipsoidal);
    let capture = base.nlos.clone().unwrap();
    gatetrace::nlos::prepare_for_shells(&mut scene, "relay_wall", WIDTH, &[capture.laser_origin], 0).unwrap();
    let scene = PreparedScene::new(scene).unwrap();
    let points = wall_points(&scene, &capture, GRID, GRID).unwrap();
    let pixels = (GRID * GRID) as usize;
    let albedo = |m: u32| scene.scene.materials[m as usize].base_color.as_dvec3();
    let (wall_albedo, wall_normal) = relay_wall(&scene);
    let sphere_albedo =
        albedo(scene.scene.triangles[scene.scene.node("hidden_sphere").unwrap().triangles.start].material);

    let mut reference = vec![0.0; pixels];
    for (px, value) in reference.iter_mut().enumerate() {
        let (sensed, spot) = (points[px].position.as_dvec3(), points[pixels + px].position.as_dvec3());
        let scale = points[pixels + px].power.as_dvec3() * wall_albedo * wall_albedo * sphere_albedo / (PI * PI * PI);
        let mut integral = 0.0;
        for f in &faces {
            let n = (f[1] - f[0]).cross(f[2] - f[0]).normalize();
            if !(n.dot(spot - f[0]) > 0.0 && n.dot(sensed - f[0]) > 0.0) {
                continue;
            }
            integral += common::quadrature::triangle_integral(*f, 0, &mut |h| {
                let (to_l, to_s) = (spot - h, sensed - h);
                let (dl, ds) = (to_l.length(), to_s.length());
                assert!(
                    dl + ds > START + WIDTH && dl + ds < START + WIDTH * (BINS - 1) as f64,
                    "the gate holds the light"
                );
                let cos_wall = (wall_normal.dot(to_l) / dl).abs() * (wall_normal.dot(to_s) / ds).abs();
                cos_wall * (n.dot(to_l) / dl) * (n.dot(to_s) / ds) / (dl * dl * ds * ds)
            });
        }
        *value = (scale * integral).element_sum();
    }

    let ctx = common::gpu();
    let settings = RenderSettings { band_index: true, target_pilot_spp: 0, seed: 41, ..base };
    let films = common::render_films(ctx, &scene, &settings, BATCHES, 3200);
    common::quadrature::assert_point_totals_match(
        &format!("{scan} scan, shell connections"),
        &films,
        &reference,
        ALPHA,
    );
}

#[test]
fn confocal_shell_connections_match_quadrature_on_a_convex_sphere() {
    shell_connections_match_quadrature_on_a_convex_sphere("confocal", LaserAim::Confocal);
}

#[test]
fn single_scan_shell_connections_match_quadrature_on_a_convex_sphere() {
    shell_connections_match_quadrature_on_a_convex_sphere("single", SPOT);
}
