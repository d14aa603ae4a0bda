//! The material's BSDF (shaders/lib/bsdf.wesl and its CPU twin src/scene/bsdf.rs): the WGSL
//! matches the twin; sampling follows the pdf it reports (chi-square over the hemisphere for
//! glossy and blended lobes); and a white furnace: with F0 = albedo = 1 the directional albedo
//! estimated from samples (f cos / pdf) equals the quadrature of f cos and never exceeds 1. The
//! plastics of assets/scenes/mitsuba_box (rough, rough with a texture and `nonlinear`, smooth)
//! pass the same three checks, and a white plastic reflects what its coat and base let through.

mod common;

use common::stats::{chi2_test, sidak};
use gatetrace::film::Gate;
use gatetrace::integrator::{PathTracer, RenderSettings};
use gatetrace::scene::bsdf::{Bsdf, PlasticLobe};
use gatetrace::scene::{LoadOptions, PreparedScene, load_gltf, load_scene_with, plastic};
use glam::{Vec2, Vec3};

const ALPHA: f64 = 0.01;

/// A scene with glossy materials, so the probe's kernels keep the conductor lobe.
fn glossy_scene() -> PreparedScene {
    PreparedScene::new(load_gltf(&common::repo_path("assets/scenes/cornell_box_glossy.gltf")).unwrap()).unwrap()
}

fn probe_bsdf(metallic: f32, alpha: f32, white: bool) -> Bsdf {
    let base_color = if white { Vec3::ONE } else { Vec3::new(0.9, 0.6, 0.3) };
    Bsdf { base_color, metallic, alpha, plastic: None, dielectric: None, conductor_index: None }
}

/// The Mitsuba box, whose block, pyramid and slab are plastics, and their material indices.
fn plastic_scene() -> (PreparedScene, Vec<u32>) {
    let path = common::repo_path("assets/scenes/mitsuba_box/scene.xml");
    let scene = PreparedScene::new(load_scene_with(&path, &LoadOptions::default()).unwrap()).unwrap();
    let plastics: Vec<u32> = (0..scene.scene.materials.len() as u32)
        .filter(|&m| scene.scene.materials[m as usize].plastic.is_some())
        .collect();
    assert_eq!(plastics.len(), 3, "the box has three plastics");
    (scene, plastics)
}

/// The rough ones among `plastics` (alpha 0.15 and 0.3): the quadratures of the sampling and
/// albedo tests resolve their lobes, not the smooth coat's (alpha 10^-3, which the twin test and
/// the white plastic's sampled albedo cover).
fn rough(scene: &PreparedScene, plastics: &[u32]) -> Vec<u32> {
    let rough: Vec<u32> = plastics.iter().copied().filter(|&m| scene.materials[m as usize].alpha >= 0.1).collect();
    assert_eq!(rough.len(), 2);
    rough
}

/// Where the plastic probes read the material's texture.
const PROBE_UV: Vec2 = Vec2::new(0.3, 0.7);

/// Runs probe FUNCTION `function` (12 sample, 13 evaluate) for material `material` of the
/// tracer's scene.
fn run_material(
    ctx: &gatetrace::gpu::GpuContext,
    tracer: &PathTracer,
    function: u32,
    material: u32,
    input: &[[f32; 4]],
) -> Vec<[f32; 4]> {
    let extra = [("FUNCTION", function as f64), ("PROBE_SCENE_MATERIAL", 1.0), ("PROBE_MATERIAL", material as f64)];
    common::run_probe(ctx, tracer, "probe_functions", &extra, input, input.len())
}

fn wo_of(cos: f32) -> Vec3 {
    Vec3::new((1.0 - cos * cos).max(0.0).sqrt(), 0.0, cos)
}

/// Runs probe FUNCTION `function` (12 sample, 13 evaluate) for the given material.
fn run(
    ctx: &gatetrace::gpu::GpuContext,
    tracer: &PathTracer,
    function: u32,
    (metallic, alpha, white): (f32, f32, bool),
    input: &[[f32; 4]],
) -> Vec<[f32; 4]> {
    let extra = [
        ("FUNCTION", function as f64),
        ("PROBE_METALLIC", metallic as f64),
        ("PROBE_ALPHA", alpha as f64),
        ("PROBE_WHITE", white as u32 as f64),
    ];
    common::run_probe(ctx, tracer, "probe_functions", &extra, input, input.len())
}

/// Deterministic uniform numbers in [0, 1) (a Weyl sequence per component, scrambled).
fn uniforms(n: usize, seed: u32) -> Vec<[f32; 4]> {
    let mut rng = gatetrace::rng::Rng::new(seed, 0, 0);
    (0..n).map(|_| [rng.next_f32(), rng.next_f32(), rng.next_f32(), rng.next_f32()]).collect()
}

/// 2,048 inputs of the sampling probe: (u_lobe, u) and cos theta of wo in [0.05, 1).
fn sampling_inputs(seed: u32) -> Vec<[f32; 4]> {
    uniforms(2048, seed).iter().map(|u| [u[0], u[1], u[2], 0.05 + 0.95 * u[3]]).collect()
}

/// 2,048 inputs of the evaluation probe: wi cosine-distributed over the upper hemisphere, and
/// cos theta of wo in [0.05, 1).
fn evaluation_inputs(seed: u32) -> Vec<[f32; 4]> {
    uniforms(2048, seed)
        .iter()
        .map(|u| {
            let w = gatetrace::sampling::sample_cosine_hemisphere(Vec2::new(u[0], u[1]));
            [w.x, w.y, w.z, 0.05 + 0.95 * u[2]]
        })
        .collect()
}

#[test]
fn wgsl_bsdf_matches_cpu_twin() {
    let ctx = common::gpu();
    let scene = glossy_scene();
    let tracer = PathTracer::new(ctx, &scene, &RenderSettings { width: 4, height: 4, ..Default::default() }).unwrap();
    for material in [(1.0, 0.3, false), (0.4, 0.05, false), (0.0, 1.0, false)] {
        let bsdf = probe_bsdf(material.0, material.1, material.2);
        // Sampling: the same numbers give the same direction, pdf; evaluation at random
        // directions of the upper hemisphere.
        let input = sampling_inputs(3);
        let dirs = evaluation_inputs(4);
        let (sampled, evaluated) = (run(ctx, &tracer, 12, material, &input), run(ctx, &tracer, 13, material, &dirs));
        assert_matches_twin(&format!("{material:?}"), &bsdf, &input, &sampled, &dirs, &evaluated);
    }
}

/// Integral of `g(wi)` over the cell z in [z0, z1), phi in [p0, p1) of the upper hemisphere
/// (d omega = dz dphi), by an n x n midpoint rule in (t, phi) with z = 1 - t^2, which crowds
/// points towards the pole where glossy lobes peak.
fn integrate_cell(g: &dyn Fn(Vec3) -> f64, (z0, z1): (f64, f64), (p0, p1): (f64, f64), n: usize) -> f64 {
    let (t0, t1) = ((1.0 - z1).sqrt(), (1.0 - z0).sqrt());
    let mut sum = 0.0;
    for i in 0..n {
        let t = t0 + (t1 - t0) * (i as f64 + 0.5) / n as f64;
        let z = 1.0 - t * t;
        let r = (1.0 - z * z).max(0.0).sqrt();
        for j in 0..n {
            let phi = p0 + (p1 - p0) * (j as f64 + 0.5) / n as f64;
            let w = Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
            sum += g(w) * 2.0 * t;
        }
    }
    sum * (t1 - t0) / n as f64 * (p1 - p0) / n as f64
}

/// Pearson's chi-square of BSDF samples (probe outputs: wi, pdf; pdf 0 when sampling failed)
/// against `bsdf`'s pdf seen from cos theta = `cos_wo`: Mitsuba's recipe, samples binned over
/// the hemisphere in (t = sqrt(1 - z), phi), 16 x 24 cells finer towards the pole, expected counts
/// from the pdf integrated per cell, the failed samples against the pdf's missing mass, low
/// counts pooled. Returns (statistic, degrees of freedom, p, failed samples).
fn sampling_chi2(samples: &[[f32; 4]], bsdf: &Bsdf, cos_wo: f32) -> (f64, usize, f64, f64) {
    let wo = wo_of(cos_wo);
    sampling_chi2_with(samples, &|w: Vec3| bsdf.pdf(wo, w) as f64)
}

/// `sampling_chi2` against the density `pdf` over the upper hemisphere (samples outside it
/// counted as failed).
fn sampling_chi2_with(samples: &[[f32; 4]], pdf: &dyn Fn(Vec3) -> f64) -> (f64, usize, f64, f64) {
    let (nz, nphi, n) = (16usize, 24usize, samples.len());
    let mut observed = vec![0.0; nz * nphi];
    let mut failed = 0.0;
    for g in samples {
        if g[3] <= 0.0 || g[2] <= 0.0 {
            failed += 1.0;
            continue;
        }
        let t = (1.0 - g[2] as f64).max(0.0).sqrt();
        let phi = (g[1] as f64).atan2(g[0] as f64).rem_euclid(std::f64::consts::TAU);
        let iz = ((t * nz as f64) as usize).min(nz - 1);
        let ip = ((phi / std::f64::consts::TAU * nphi as f64) as usize).min(nphi - 1);
        observed[iz * nphi + ip] += 1.0;
    }
    let mut expected = vec![0.0; nz * nphi];
    for iz in 0..nz {
        let (t0, t1) = (iz as f64 / nz as f64, (iz + 1) as f64 / nz as f64);
        for ip in 0..nphi {
            let p = (
                ip as f64 / nphi as f64 * std::f64::consts::TAU,
                (ip + 1) as f64 / nphi as f64 * std::f64::consts::TAU,
            );
            expected[iz * nphi + ip] = n as f64 * integrate_cell(pdf, (1.0 - t1 * t1, 1.0 - t0 * t0), p, 12);
        }
    }
    observed.push(failed);
    expected.push((n as f64 - expected.iter().sum::<f64>()).max(0.0));
    let (stat, dof, p) = chi2_test(&observed, &expected);
    (stat, dof, p, failed)
}

#[test]
fn bsdf_sampling_follows_its_pdf() {
    // Mitsuba's recipe: samples binned over the hemisphere in (z, phi); expected counts from the
    // pdf integrated per cell; Pearson chi-square with low-count cells pooled; Sidak-corrected.
    let ctx = common::gpu();
    let scene = glossy_scene();
    let tracer = PathTracer::new(ctx, &scene, &RenderSettings { width: 4, height: 4, ..Default::default() }).unwrap();
    let configs = [(1.0, 0.3, 0.8), (1.0, 0.1, 0.35), (0.5, 0.2, 0.6), (1.0, 0.6, 0.15), (0.0, 1.0, 0.5)];
    let n = 200_000usize;
    for (c, &(metallic, alpha, cos_wo)) in configs.iter().enumerate() {
        let material = (metallic, alpha, false);
        let bsdf = probe_bsdf(metallic, alpha, false);
        let input: Vec<[f32; 4]> = uniforms(n, 10 + c as u32).iter().map(|u| [u[0], u[1], u[2], cos_wo]).collect();
        let (stat, dof, p, failed) = sampling_chi2(&run(ctx, &tracer, 12, material, &input), &bsdf, cos_wo);
        println!(
            "metallic {metallic} alpha {alpha} cos_wo {cos_wo}: chi2 {stat:.1} dof {dof} p {p:.3}, {failed} rejected"
        );
        assert!(
            p > sidak(ALPHA, configs.len()),
            "metallic {metallic} alpha {alpha} cos_wo {cos_wo}: chi2 {stat:.1}, dof {dof}, p {p:.2e}"
        );
    }
}

#[test]
fn white_furnace_albedo_matches_quadrature_and_stays_below_one() {
    let ctx = common::gpu();
    let scene = glossy_scene();
    let tracer =
        PathTracer::new(ctx, &scene, &RenderSettings { width: 4, height: 4, gate: Gate::None, ..Default::default() })
            .unwrap();
    let n = 100_000;
    for (metallic, alpha) in [(1.0f32, 0.05f32), (1.0, 0.3), (1.0, 0.8), (0.5, 0.3), (0.0, 1.0)] {
        for cos_wo in [1.0f32, 0.5, 0.1] {
            let bsdf = probe_bsdf(metallic, alpha, true);
            let wo = wo_of(cos_wo);
            let input: Vec<[f32; 4]> = uniforms(n, 99).iter().map(|u| [u[0], u[1], u[2], cos_wo]).collect();
            // Estimate from sampling: mean of f cos / pdf (0 for rejected samples).
            let weights: Vec<f64> = run(ctx, &tracer, 12, (metallic, alpha, true), &input)
                .iter()
                .map(|g| {
                    if g[3] <= 0.0 {
                        return 0.0;
                    }
                    let wi = Vec3::new(g[0], g[1], g[2]);
                    (bsdf.eval(wo, wi).x * wi.z / g[3]) as f64
                })
                .collect();
            let mean = weights.iter().sum::<f64>() / n as f64;
            let var = weights.iter().map(|w| (w - mean).powi(2)).sum::<f64>() / (n as f64 - 1.0) / n as f64;
            // Independent: quadrature of f cos over the hemisphere, parametrised by the half
            // vector h (wi = reflect(wo, h), d omega_i = 4 (wo.h) d omega_h), where glossy lobes
            // peak at the pole for any wo.
            let fcos = |h: Vec3| {
                let c = wo.dot(h);
                if c <= 0.0 {
                    return 0.0;
                }
                let wi = 2.0 * c * h - wo;
                (bsdf.eval(wo, wi).x * wi.z * 4.0 * c) as f64
            };
            let quad = integrate_cell(&fcos, (0.0, 1.0), (0.0, std::f64::consts::TAU), 600);
            let z = (mean - quad) / var.sqrt().max(1e-12);
            println!(
                "metallic {metallic} alpha {alpha} cos_wo {cos_wo}: sampled {mean:.5} +- {:.5}, quadrature {quad:.5}",
                var.sqrt()
            );
            assert!(
                z.abs() < 4.0 || (mean - quad).abs() < 2e-3,
                "sampled albedo {mean} vs quadrature {quad} (z = {z:.2})"
            );
            assert!(quad <= 1.0 + 1e-3 && mean <= 1.0 + 4.0 * var.sqrt(), "energy gain: {mean} / {quad}");
            if metallic == 0.0 {
                assert!((mean - 1.0).abs() < 1e-5, "white Lambertian albedo {mean}");
            }
            if alpha <= 0.05 && cos_wo >= 0.5 {
                assert!(mean > 0.98, "a smooth white conductor reflects almost everything: {mean}");
            }
        }
    }
}

/// Compares the GPU's sampled directions, pdfs and values of `bsdf` (probe output `sampled` for
/// inputs `input`, `evaluated` for `dirs`) with the CPU twin's. GGX's D(h) near its peak takes
/// 1 - h.z^2 of order alpha^2 from a unit vector rounded to f32 on each side, so its relative
/// rounding error is about 4 epsilon / alpha^2 or more: the tolerance adds that to 10^-3
/// (nothing for alpha 0.15). For a near-mirror coat (alpha 10^-3) that bound exceeds the value
/// itself at its sampled directions, which all lie in the peak: there only the directions are
/// compared, and the values at the evaluation directions, which lie outside it.
fn assert_matches_twin(
    label: &str,
    bsdf: &Bsdf,
    input: &[[f32; 4]],
    sampled: &[[f32; 4]],
    dirs: &[[f32; 4]],
    evaluated: &[[f32; 4]],
) {
    let conditioning = 4.0 * f32::EPSILON / (bsdf.alpha * bsdf.alpha);
    for (i, (x, g)) in input.iter().zip(sampled).enumerate() {
        let c = bsdf.sample(wo_of(x[3]), x[0], Vec2::new(x[1], x[2]));
        if c.pdf == 0.0 {
            assert!(g[3] == 0.0 || c.wi.z.abs() < 1e-4, "{label} record {i}: CPU fails, GPU pdf {}", g[3]);
            continue;
        }
        for k in 0..3 {
            assert!((g[k] - c.wi[k]).abs() < 2e-4, "{label} record {i}: wi GPU {g:?} CPU {:?}", c.wi);
        }
        if conditioning > 0.1 {
            continue;
        }
        let tolerance = (2e-3 + conditioning) * c.pdf + 1e-5;
        assert!((g[3] - c.pdf).abs() <= tolerance, "{label} record {i}: pdf GPU {} CPU {}", g[3], c.pdf);
    }
    for (i, (x, g)) in dirs.iter().zip(evaluated).enumerate() {
        let wo = wo_of(x[3]);
        let wi = Vec3::new(x[0], x[1], x[2]);
        let (f, pdf) = (bsdf.eval(wo, wi), bsdf.pdf(wo, wi));
        for k in 0..3 {
            let tolerance = (1e-3 + conditioning) * f[k] + 1e-6;
            assert!((g[k] - f[k]).abs() <= tolerance, "{label} record {i}: f GPU {g:?} CPU {f:?}");
        }
        let tolerance = (1e-3 + conditioning) * pdf + 1e-6;
        assert!((g[3] - pdf).abs() <= tolerance, "{label} record {i}: pdf GPU {} CPU {pdf}", g[3]);
    }
}

#[test]
fn wgsl_plastic_matches_cpu_twin() {
    let ctx = common::gpu();
    let (scene, plastics) = plastic_scene();
    let tracer = PathTracer::new(ctx, &scene, &RenderSettings { width: 4, height: 4, ..Default::default() }).unwrap();
    let input = sampling_inputs(5);
    let dirs = evaluation_inputs(6);
    for &m in &plastics {
        let bsdf = Bsdf::at(&scene, m, PROBE_UV);
        assert!(bsdf.plastic.is_some());
        let sampled = run_material(ctx, &tracer, 12, m, &input);
        let evaluated = run_material(ctx, &tracer, 13, m, &dirs);
        assert_matches_twin(&format!("plastic {m}"), &bsdf, &input, &sampled, &dirs, &evaluated);
    }
}

#[test]
fn plastic_sampling_follows_its_pdf() {
    let ctx = common::gpu();
    let (scene, plastics) = plastic_scene();
    let tracer = PathTracer::new(ctx, &scene, &RenderSettings { width: 4, height: 4, ..Default::default() }).unwrap();
    let n = 200_000usize;
    let plastics = rough(&scene, &plastics);
    let cosines = [0.9f32, 0.4, 0.12];
    let tests = plastics.len() * cosines.len();
    for &m in &plastics {
        let bsdf = Bsdf::at(&scene, m, PROBE_UV);
        for (c, &cos_wo) in cosines.iter().enumerate() {
            let input: Vec<[f32; 4]> =
                uniforms(n, 40 + c as u32 + 10 * m).iter().map(|u| [u[0], u[1], u[2], cos_wo]).collect();
            let (stat, dof, p, failed) = sampling_chi2(&run_material(ctx, &tracer, 12, m, &input), &bsdf, cos_wo);
            println!("plastic {m} cos_wo {cos_wo}: chi2 {stat:.1} dof {dof} p {p:.3}, {failed} rejected");
            assert!(p > sidak(ALPHA, tests), "plastic {m} cos_wo {cos_wo}: chi2 {stat:.1}, dof {dof}, p {p:.2e}");
        }
    }
}

/// Quadrature of f cos over the hemisphere for `wo`, parametrised by the half vector (see
/// the white furnace test), of channel `k`.
fn albedo_quadrature(bsdf: &Bsdf, wo: Vec3, k: usize, n: usize) -> f64 {
    let fcos = |h: Vec3| {
        let c = wo.dot(h);
        if c <= 0.0 {
            return 0.0;
        }
        let wi = 2.0 * c * h - wo;
        (bsdf.eval(wo, wi)[k] * wi.z * 4.0 * c) as f64
    };
    integrate_cell(&fcos, (0.0, 1.0), (0.0, std::f64::consts::TAU), n)
}

#[test]
fn plastic_albedo_from_sampling_matches_quadrature() {
    let ctx = common::gpu();
    let (scene, plastics) = plastic_scene();
    let tracer =
        PathTracer::new(ctx, &scene, &RenderSettings { width: 4, height: 4, gate: Gate::None, ..Default::default() })
            .unwrap();
    let n = 100_000;
    for &m in &rough(&scene, &plastics) {
        let bsdf = Bsdf::at(&scene, m, PROBE_UV);
        for cos_wo in [1.0f32, 0.5, 0.1] {
            let wo = wo_of(cos_wo);
            let input: Vec<[f32; 4]> = uniforms(n, 77).iter().map(|u| [u[0], u[1], u[2], cos_wo]).collect();
            let out = run_material(ctx, &tracer, 12, m, &input);
            for k in 0..3 {
                let weights: Vec<f64> = out
                    .iter()
                    .map(|g| {
                        if g[3] <= 0.0 {
                            return 0.0;
                        }
                        let wi = Vec3::new(g[0], g[1], g[2]);
                        (bsdf.eval(wo, wi)[k] * wi.z / g[3]) as f64
                    })
                    .collect();
                let mean = weights.iter().sum::<f64>() / n as f64;
                let var = weights.iter().map(|w| (w - mean).powi(2)).sum::<f64>() / (n as f64 - 1.0) / n as f64;
                let quad = albedo_quadrature(&bsdf, wo, k, 600);
                let z = (mean - quad) / var.sqrt().max(1e-12);
                println!(
                    "plastic {m} cos_wo {cos_wo} channel {k}: sampled {mean:.5} +- {:.5}, quadrature {quad:.5}",
                    var.sqrt()
                );
                assert!(
                    z.abs() < 4.0 || (mean - quad).abs() < 2e-3,
                    "plastic {m} cos_wo {cos_wo} channel {k}: sampled {mean} vs quadrature {quad} (z = {z:.2})"
                );
                assert!(quad <= 1.0 + 1e-3, "plastic {m}: energy gain {quad}");
            }
        }
    }
}

/// A plastic with a white base (albedo 1, not nonlinear) reflects what Mitsuba's model of it
/// reflects: its directional albedo, the mean of f cos / pdf over the twin's own samples (which
/// resolve a near-mirror coat's lobe where a quadrature would not), against Mitsuba 3.9.1's
/// (`plastic` and GGX `roughplastic` with int_ior eta, ext_ior 1, 2^20 samples of its own
/// `sample`, each within 10^-3). A smooth coat reflects R + T = 1 of the light (computed
/// independently in f64), but for the published fit of its internal reflectance (good to 0.1 %,
/// which the diffuse part scales by 1 / (1 - F_dr), about 2.5); a rough coat's model loses light
/// (0.85 at alpha 0.15) and never reflects more than R + T.
#[test]
fn a_white_plastic_reflects_as_mitsubas_does() {
    let n = 400_000;
    let cosines = [1.0f32, 0.6, 0.25];
    let cases = [
        (0.001f32, 1.49f32, [1.0011, 1.0011, 1.0009]),
        (0.15, 1.5, [0.8523, 0.8484, 0.8271]),
        (0.5, 1.33, [0.6152, 0.5768, 0.5007]),
    ];
    for (alpha, eta, mitsuba) in cases {
        let table = plastic::transmittance_table(alpha as f64, eta as f64);
        let internal = if alpha <= 0.001 {
            plastic::smooth_internal_reflectance(eta as f64)
        } else {
            plastic::internal_reflectance(alpha as f64, eta as f64)
        } as f32;
        let bsdf = Bsdf {
            base_color: Vec3::splat(1.0 / ((1.0 - internal) * eta * eta)),
            metallic: 0.0,
            alpha,
            plastic: Some(PlasticLobe {
                eta,
                specular: 1.0,
                specular_weight: 0.5,
                transmittance: std::array::from_fn(|i| table[i] as f32),
            }),
            dielectric: None,
            conductor_index: None,
        };
        for (&cos_wo, &peer) in cosines.iter().zip(&mitsuba) {
            let wo = wo_of(cos_wo);
            let weights: Vec<f64> = uniforms(n, 123)
                .iter()
                .map(|u| {
                    let s = bsdf.sample(wo, u[0], Vec2::new(u[1], u[2]));
                    if s.pdf > 0.0 { (s.f.x * s.wi.z / s.pdf) as f64 } else { 0.0 }
                })
                .collect();
            let mean = weights.iter().sum::<f64>() / n as f64;
            let sigma = (weights.iter().map(|w| (w - mean).powi(2)).sum::<f64>() / (n as f64 - 1.0) / n as f64).sqrt();
            let (r, t) = (
                plastic::reflectance(cos_wo as f64, alpha as f64, eta as f64),
                plastic::transmittance(cos_wo as f64, alpha as f64, eta as f64),
            );
            println!(
                "alpha {alpha} eta {eta} cos_wo {cos_wo}: albedo {mean:.4} +- {sigma:.4}, Mitsuba {peer:.4}, R {r:.4} + T {t:.4} = {:.4}",
                r + t
            );
            let label = format!("alpha {alpha} eta {eta} cos_wo {cos_wo}");
            assert!((mean - peer).abs() < 1e-3 + 4.0 * sigma, "{label}: albedo {mean} vs Mitsuba's {peer}");
            assert!(mean <= (r + t) * 1.002 + 4.0 * sigma, "{label}: albedo {mean} above R + T {}", r + t);
            if alpha <= 0.001 {
                assert!((mean - (r + t)).abs() < 2e-3 + 4.0 * sigma, "{label}: albedo {mean} vs R + T {}", r + t);
            }
        }
    }
}

/// The glass box and the material index of its sphere (a smooth BK7 dielectric) or, with
/// `thin`, of its pane (a thin dielectric).
fn glass_scene(thin: bool) -> (PreparedScene, u32) {
    let path = common::repo_path("assets/scenes/glass_box.xml");
    let scene = PreparedScene::new(load_scene_with(&path, &LoadOptions::default()).unwrap()).unwrap();
    let glass = (0..scene.scene.materials.len() as u32)
        .find(|&m| scene.scene.materials[m as usize].dielectric.is_some_and(|d| d.thin == thin))
        .expect("the glass box has a dielectric of each kind");
    (scene, glass)
}

/// A smooth dielectric: the WGSL samples the twin's directions with the twin's probabilities;
/// reflection is chosen as often as the Fresnel reflectance says (binomial z-test at five
/// angles); the directions obey the law of reflection and Snell's law, refracting back recovers
/// the incident direction, light from inside beyond the critical angle is reflected whole, and
/// every sample's weight f |cos| / pdf is the specular factor (reflection) or the transmittance
/// over eta^2 (refraction: radiance is compressed into the denser medium).
#[test]
fn a_dielectric_reflects_and_refracts_as_fresnel_and_snell_say() {
    let ctx = common::gpu();
    let (scene, glass) = glass_scene(false);
    let tracer = PathTracer::new(ctx, &scene, &RenderSettings { width: 4, height: 4, ..Default::default() }).unwrap();
    let bsdf = Bsdf::at(&scene, glass, PROBE_UV);
    let d = bsdf.dielectric.expect("a dielectric");
    assert!((d.eta - 1.5046 / 1.000277).abs() < 1e-6);
    let n = 100_000;
    for (c, cos_wo) in [1.0f32, 0.8, 0.5, 0.2, 0.05].into_iter().enumerate() {
        let wo = wo_of(cos_wo);
        let input: Vec<[f32; 4]> = uniforms(n, 200 + c as u32).iter().map(|u| [u[0], u[1], u[2], cos_wo]).collect();
        let sampled = run_material(ctx, &tracer, 12, glass, &input);
        let mut reflected = 0usize;
        for (i, (x, g)) in input.iter().zip(&sampled).enumerate() {
            let s = bsdf.sample(wo, x[0], Vec2::new(x[1], x[2]));
            assert!(s.delta && s.pdf > 0.0);
            for k in 0..3 {
                assert!((g[k] - s.wi[k]).abs() < 1e-5, "cos {cos_wo} record {i}: wi GPU {g:?} CPU {:?}", s.wi);
            }
            assert!((g[3] - s.pdf).abs() < 1e-5, "cos {cos_wo} record {i}: pdf GPU {} CPU {}", g[3], s.pdf);
            let weight = s.f * s.wi.z.abs() / s.pdf;
            if s.wi.z > 0.0 {
                reflected += 1;
                assert!((s.wi - Vec3::new(-wo.x, -wo.y, wo.z)).length() < 1e-6, "the law of reflection");
                assert!((weight - Vec3::splat(d.specular)).abs().max_element() < 1e-5);
            } else {
                let sin_t = (s.wi.x * s.wi.x + s.wi.y * s.wi.y).sqrt();
                assert!((sin_t * d.eta - (1.0 - cos_wo * cos_wo).sqrt()).abs() < 1e-5, "Snell's law");
                assert!((s.wi.length() - 1.0).abs() < 1e-5);
                assert!((weight - bsdf.base_color / (d.eta * d.eta)).abs().max_element() < 1e-5);
                // Back through the interface from inside: the incident direction again.
                let inside = Bsdf { dielectric: Some(gatetrace::scene::Dielectric { eta: 1.0 / d.eta, ..d }), ..bsdf };
                let back = inside.sample(-s.wi, 1.0, Vec2::ZERO);
                assert!(back.wi.z < 0.0 && (-back.wi - wo).length() < 1e-5, "refraction is reversible");
            }
        }
        let f = gatetrace::scene::bsdf::fresnel_dielectric(cos_wo, d.eta) as f64;
        let z = (reflected as f64 - n as f64 * f) / (n as f64 * f * (1.0 - f)).sqrt();
        println!("cos {cos_wo}: reflected {reflected} of {n}, Fresnel {f:.5}, z {z:+.2}");
        assert!(z.abs() < 4.5, "cos {cos_wo}: {reflected} reflections of {n} for F = {f} (z = {z:.2})");
    }
    // From inside, beyond the critical angle (sin > 1 / eta): total internal reflection.
    let inside = Bsdf { dielectric: Some(gatetrace::scene::Dielectric { eta: 1.0 / d.eta, ..d }), ..bsdf };
    let critical = (1.0 - 1.0 / (d.eta * d.eta)).sqrt();
    for cos_wo in [0.5 * critical, 0.9 * critical] {
        for u in [0.0f32, 0.5, 0.999] {
            let s = inside.sample(wo_of(cos_wo), u, Vec2::ZERO);
            assert!(s.wi.z > 0.0 && s.pdf == 1.0, "cos {cos_wo}: total internal reflection");
        }
    }
}

/// A thin pane: the WGSL samples the twin's directions with the twin's probabilities; it
/// reflects as often as its reflectance says, which sums the light bouncing inside it to the
/// closed form 2F / (1 + F); it passes the rest straight on (wi = -wo) without changing its
/// radiance, and looks alike from both sides.
#[test]
fn a_thin_pane_reflects_2f_over_1_plus_f_and_passes_the_rest_straight_on() {
    use gatetrace::scene::bsdf::{fresnel_dielectric, thin_reflectance};
    let ctx = common::gpu();
    let (scene, pane) = glass_scene(true);
    let tracer = PathTracer::new(ctx, &scene, &RenderSettings { width: 4, height: 4, ..Default::default() }).unwrap();
    let bsdf = Bsdf::at(&scene, pane, PROBE_UV);
    let d = bsdf.dielectric.expect("a dielectric");
    assert!(d.thin && (d.eta - 1.5 / 1.000277).abs() < 1e-6);
    let n = 100_000;
    for (c, cos_wo) in [1.0f32, 0.6, 0.2, 0.05].into_iter().enumerate() {
        let f = fresnel_dielectric(cos_wo, d.eta);
        let r = thin_reflectance(cos_wo, d.eta);
        assert!((r - 2.0 * f / (1.0 + f)).abs() < 1e-6, "cos {cos_wo}: {r} vs 2F / (1 + F)");
        let wo = wo_of(cos_wo);
        let input: Vec<[f32; 4]> = uniforms(n, 400 + c as u32).iter().map(|u| [u[0], u[1], u[2], cos_wo]).collect();
        let sampled = run_material(ctx, &tracer, 12, pane, &input);
        let mut reflected = 0usize;
        for (i, (x, g)) in input.iter().zip(&sampled).enumerate() {
            let s = bsdf.sample(wo, x[0], Vec2::new(x[1], x[2]));
            for k in 0..3 {
                assert!((g[k] - s.wi[k]).abs() < 1e-6, "cos {cos_wo} record {i}: wi GPU {g:?} CPU {:?}", s.wi);
            }
            assert!((g[3] - s.pdf).abs() < 1e-6, "cos {cos_wo} record {i}: pdf GPU {} CPU {}", g[3], s.pdf);
            let weight = s.f * s.wi.z.abs() / s.pdf;
            if s.wi.z > 0.0 {
                reflected += 1;
                assert!((weight - Vec3::splat(d.specular)).abs().max_element() < 1e-5);
            } else {
                assert_eq!(s.wi, -wo, "straight through");
                assert!((weight - bsdf.base_color).abs().max_element() < 1e-5, "radiance passes unchanged");
            }
        }
        let z = (reflected as f64 - n as f64 * r as f64) / (n as f64 * r as f64 * (1.0 - r as f64)).sqrt();
        println!("cos {cos_wo}: reflected {reflected} of {n}, thin reflectance {r:.5}, z {z:+.2}");
        assert!(z.abs() < 4.5, "cos {cos_wo}: {reflected} reflections of {n} for R = {r} (z = {z:.2})");
    }
}

/// A conductor given by its complex index (Mitsuba's `material` Au, the Mitsuba box's ball)
/// takes the exact Fresnel term: at normal incidence ((n - 1)^2 + k^2) / ((n + 1)^2 + k^2), with
/// k = 0 the dielectric's, 1 at grazing light; the WGSL matches the twin on the ball's material.
#[test]
fn a_conductor_of_a_named_material_takes_the_exact_fresnel_term() {
    use gatetrace::scene::bsdf::{fresnel_conductor, fresnel_dielectric};
    let (eta, k) = (Vec3::new(0.143036, 0.375307, 1.44205), Vec3::new(3.983, 2.38556, 1.60336));
    let normal = ((eta - Vec3::ONE) * (eta - Vec3::ONE) + k * k) / ((eta + Vec3::ONE) * (eta + Vec3::ONE) + k * k);
    assert!((fresnel_conductor(1.0, eta, k) - normal).abs().max_element() < 1e-6);
    assert!((fresnel_conductor(1e-6, eta, k) - Vec3::ONE).abs().max_element() < 1e-4, "grazing");
    for c in [0.9f32, 0.5, 0.1] {
        let dielectric = fresnel_conductor(c, Vec3::splat(1.5), Vec3::ZERO).x;
        assert!((dielectric - fresnel_dielectric(c, 1.5)).abs() < 1e-6, "k = 0 at cos {c}");
    }
    assert_eq!(fresnel_conductor(1.0, Vec3::ZERO, Vec3::ZERO), Vec3::ONE, "an index of 0 + 0i at normal incidence");

    let ctx = common::gpu();
    let (scene, _) = plastic_scene();
    let tracer = PathTracer::new(ctx, &scene, &RenderSettings { width: 4, height: 4, ..Default::default() }).unwrap();
    let ball = scene.scene.triangles[scene.scene.node("ball").unwrap().triangles.start].material;
    let bsdf = Bsdf::at(&scene, ball, PROBE_UV);
    let (e, kk) = bsdf.conductor_index.expect("the ball's conductor has its index");
    assert!((e - eta).abs().max_element() < 1e-6 && (kk - k).abs().max_element() < 1e-6);
    let input = sampling_inputs(8);
    let dirs = evaluation_inputs(9);
    let (sampled, evaluated) =
        (run_material(ctx, &tracer, 12, ball, &input), run_material(ctx, &tracer, 13, ball, &dirs));
    assert_matches_twin("gold", &bsdf, &input, &sampled, &dirs, &evaluated);
}

/// The rough glass box and the material index of its frosted sphere (a rough BK7 dielectric,
/// GGX alpha 0.2).
fn rough_glass_scene() -> (PreparedScene, u32) {
    let path = common::repo_path("assets/scenes/rough_glass_box.xml");
    let scene = PreparedScene::new(load_scene_with(&path, &LoadOptions::default()).unwrap()).unwrap();
    let glass = (0..scene.scene.materials.len() as u32)
        .find(|&m| scene.scene.materials[m as usize].dielectric.is_some_and(|d| d.alpha > 0.0))
        .expect("the rough glass box has a rough dielectric");
    (scene, glass)
}

/// A rough dielectric (GGX microfacets that reflect with F(wo.h) and refract otherwise): the
/// WGSL samples the twin's directions with the twin's densities and values; its samples follow
/// that density on both sides of the surface (chi-square of the reflected and of the refracted
/// directions, from outside on the GPU and from inside, total internal reflection included, on
/// the twin); a refracted sample's radiance weight is its importance weight over eta^2; and
/// the mean importance weight f |cos| / pdf (eta^2 restored for refraction), which is Smith's
/// G1 of the outgoing direction, lies below one and near it.
#[test]
fn a_rough_dielectric_matches_its_twin_and_samples_its_density_on_both_sides() {
    let ctx = common::gpu();
    let (scene, glass) = rough_glass_scene();
    let tracer = PathTracer::new(ctx, &scene, &RenderSettings { width: 4, height: 4, ..Default::default() }).unwrap();
    let bsdf = Bsdf::at(&scene, glass, PROBE_UV);
    let d = bsdf.dielectric.expect("a dielectric");
    assert!((d.alpha - 0.2).abs() < 1e-6 && (d.eta - 1.5046 / 1.000277).abs() < 1e-6);
    let inside = Bsdf { dielectric: Some(gatetrace::scene::Dielectric { eta: 1.0 / d.eta, ..d }), ..bsdf };
    let n = 200_000;
    let cosines = [0.9f32, 0.5, 0.15];
    // Beyond the critical angle the refracted lobe is a sliver at the horizon, finer than the
    // quadrature's cells: there only the reflected side is tested from inside.
    let critical = (1.0 - 1.0 / (d.eta * d.eta)).sqrt();
    let tests = cosines.iter().map(|&c| if c > critical { 4 } else { 3 }).sum::<usize>();
    for (c, cos_wo) in cosines.into_iter().enumerate() {
        let wo = wo_of(cos_wo);
        let input: Vec<[f32; 4]> = uniforms(n, 300 + c as u32).iter().map(|u| [u[0], u[1], u[2], cos_wo]).collect();
        let sampled = run_material(ctx, &tracer, 12, glass, &input);
        let (mut weights, mut refracted) = (0.0f64, 0usize);
        for (i, (x, g)) in input.iter().zip(&sampled).enumerate() {
            let s = bsdf.sample(wo, x[0], Vec2::new(x[1], x[2]));
            assert!(!s.delta);
            if s.pdf == 0.0 {
                assert!(g[3] == 0.0 || s.wi.z.abs() < 1e-4, "cos {cos_wo} record {i}: CPU fails, GPU pdf {}", g[3]);
                continue;
            }
            for k in 0..3 {
                assert!((g[k] - s.wi[k]).abs() < 2e-4, "cos {cos_wo} record {i}: wi GPU {g:?} CPU {:?}", s.wi);
            }
            assert!(
                (g[3] - s.pdf).abs() <= 2e-3 * s.pdf + 1e-5,
                "cos {cos_wo} record {i}: pdf GPU {} CPU {}",
                g[3],
                s.pdf
            );
            let mut weight = (s.f.x * s.wi.z.abs() / s.pdf) as f64;
            if s.wi.z < 0.0 {
                refracted += 1;
                weight *= (d.eta * d.eta) as f64;
            }
            weights += weight;
        }
        let mean = weights / n as f64;
        println!("cos {cos_wo}: {refracted} of {n} refracted, mean importance weight {mean:.4}");
        assert!(mean <= 1.0 + 1e-4 && mean > 0.9, "cos {cos_wo}: mean weight {mean}");
        // The GPU's samples against the twin's density, each side on its own.
        let above: Vec<[f32; 4]> = sampled.iter().map(|g| if g[2] > 0.0 { *g } else { [0.0; 4] }).collect();
        let below: Vec<[f32; 4]> = sampled
            .iter()
            .map(|g| if g[2] < 0.0 && g[3] > 0.0 { [g[0], g[1], -g[2], g[3]] } else { [0.0; 4] })
            .collect();
        let flip = |w: Vec3| Vec3::new(w.x, w.y, -w.z);
        let sides: [(&str, &[[f32; 4]], &Bsdf, bool); 2] =
            [("reflected", &above, &bsdf, false), ("refracted", &below, &bsdf, true)];
        for (side, samples, b, flipped) in sides {
            let pdf = |w: Vec3| b.rough_dielectric_pdf(wo, if flipped { flip(w) } else { w }) as f64;
            let (stat, dof, p, _) = sampling_chi2_with(samples, &pdf);
            println!("cos {cos_wo}, {side}: chi2 {stat:.1} dof {dof} p {p:.3}");
            assert!(p > sidak(ALPHA, tests), "cos {cos_wo}, {side}: chi2 {stat:.1}, dof {dof}, p {p:.2e}");
        }
        // From inside (the twin): beyond the critical angle most light reflects.
        let twin: Vec<[f32; 4]> = uniforms(n, 400 + c as u32)
            .iter()
            .map(|u| {
                let s = inside.sample(wo, u[0], Vec2::new(u[1], u[2]));
                [s.wi.x, s.wi.y, s.wi.z, s.pdf]
            })
            .collect();
        let above: Vec<[f32; 4]> = twin.iter().map(|g| if g[2] > 0.0 { *g } else { [0.0; 4] }).collect();
        let below: Vec<[f32; 4]> =
            twin.iter().map(|g| if g[2] < 0.0 && g[3] > 0.0 { [g[0], g[1], -g[2], g[3]] } else { [0.0; 4] }).collect();
        let sides = [("reflected from inside", &above, false), ("refracted from inside", &below, true)];
        for (side, samples, flipped) in sides.into_iter().take(if cos_wo > critical { 2 } else { 1 }) {
            let pdf = |w: Vec3| inside.rough_dielectric_pdf(wo, if flipped { flip(w) } else { w }) as f64;
            let (stat, dof, p, _) = sampling_chi2_with(samples, &pdf);
            println!("cos {cos_wo}, {side}: chi2 {stat:.1} dof {dof} p {p:.3}");
            assert!(p > sidak(ALPHA, tests), "cos {cos_wo}, {side}: chi2 {stat:.1}, dof {dof}, p {p:.2e}");
        }
    }
}
