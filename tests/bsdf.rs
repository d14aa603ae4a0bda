//! The material's BSDF (shaders/lib/bsdf.wesl and its CPU twin src/scene/bsdf.rs): the WGSL
//! matches the twin; sampling follows the pdf it reports (chi-square over the hemisphere for
//! glossy and blended lobes); and a white furnace: with F0 = albedo = 1 the directional albedo
//! estimated from samples (f cos / pdf) equals the quadrature of f cos and never exceeds 1.

mod common;

use common::stats::{chi2_test, sidak};
use gatetrace::film::Gate;
use gatetrace::integrator::{PathTracer, RenderSettings};
use gatetrace::scene::bsdf::Bsdf;
use gatetrace::scene::{PreparedScene, load_gltf};
use glam::{Vec2, Vec3};

const ALPHA: f64 = 0.01;

/// A scene with glossy materials, so the probe's kernels keep the conductor lobe.
fn glossy_scene() -> PreparedScene {
    PreparedScene::new(load_gltf(&common::repo_path("assets/scenes/cornell_box_glossy.gltf")).unwrap()).unwrap()
}

fn probe_bsdf(metallic: f32, alpha: f32, white: bool) -> Bsdf {
    let base_color = if white { Vec3::ONE } else { Vec3::new(0.9, 0.6, 0.3) };
    Bsdf { base_color, metallic, alpha }
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

#[test]
fn wgsl_bsdf_matches_cpu_twin() {
    let ctx = common::gpu();
    let scene = glossy_scene();
    let tracer = PathTracer::new(&ctx, &scene, &RenderSettings { width: 4, height: 4, ..Default::default() }).unwrap();
    for material in [(1.0, 0.3, false), (0.4, 0.05, false), (0.0, 1.0, false)] {
        let bsdf = probe_bsdf(material.0, material.1, material.2);
        // Sampling: the same numbers give the same direction, pdf.
        let input: Vec<[f32; 4]> = uniforms(2048, 3).iter().map(|u| [u[0], u[1], u[2], 0.05 + 0.95 * u[3]]).collect();
        for (i, (x, g)) in input.iter().zip(run(&ctx, &tracer, 12, material, &input)).enumerate() {
            let c = bsdf.sample(wo_of(x[3]), x[0], Vec2::new(x[1], x[2]));
            if c.pdf == 0.0 {
                assert!(g[3] == 0.0 || c.wi.z.abs() < 1e-4, "record {i}: CPU fails, GPU pdf {}", g[3]);
                continue;
            }
            for k in 0..3 {
                assert!((g[k] - c.wi[k]).abs() < 2e-4, "{material:?} record {i}: wi GPU {g:?} CPU {:?}", c.wi);
            }
            assert!(
                (g[3] - c.pdf).abs() <= 2e-3 * c.pdf + 1e-5,
                "{material:?} record {i}: pdf GPU {} CPU {}",
                g[3],
                c.pdf
            );
        }
        // Evaluation at random directions of the upper hemisphere.
        let dirs: Vec<[f32; 4]> = uniforms(2048, 4)
            .iter()
            .map(|u| {
                let w = gatetrace::sampling::sample_cosine_hemisphere(Vec2::new(u[0], u[1]));
                [w.x, w.y, w.z, 0.05 + 0.95 * u[2]]
            })
            .collect();
        for (i, (x, g)) in dirs.iter().zip(run(&ctx, &tracer, 13, material, &dirs)).enumerate() {
            let wo = wo_of(x[3]);
            let wi = Vec3::new(x[0], x[1], x[2]);
            let (f, pdf) = (bsdf.eval(wo, wi), bsdf.pdf(wo, wi));
            for k in 0..3 {
                assert!((g[k] - f[k]).abs() <= 1e-3 * f[k] + 1e-6, "{material:?} record {i}: f GPU {g:?} CPU {f:?}");
            }
            assert!((g[3] - pdf).abs() <= 1e-3 * pdf + 1e-6, "{material:?} record {i}: pdf GPU {} CPU {pdf}", g[3]);
        }
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

#[test]
fn bsdf_sampling_follows_its_pdf() {
    // Mitsuba's recipe: samples binned over the hemisphere in (z, phi); expected counts from the
    // pdf integrated per cell; Pearson chi-square with low-count cells pooled; Sidak-corrected.
    let ctx = common::gpu();
    let scene = glossy_scene();
    let tracer = PathTracer::new(&ctx, &scene, &RenderSettings { width: 4, height: 4, ..Default::default() }).unwrap();
    let configs = [(1.0, 0.3, 0.8), (1.0, 0.1, 0.35), (0.5, 0.2, 0.6), (1.0, 0.6, 0.15), (0.0, 1.0, 0.5)];
    let (nz, nphi, n) = (16usize, 24usize, 200_000usize);
    for (c, &(metallic, alpha, cos_wo)) in configs.iter().enumerate() {
        let material = (metallic, alpha, false);
        let bsdf = probe_bsdf(metallic, alpha, false);
        let input: Vec<[f32; 4]> = uniforms(n, 10 + c as u32).iter().map(|u| [u[0], u[1], u[2], cos_wo]).collect();
        let mut observed = vec![0.0; nz * nphi];
        let mut failed = 0.0;
        for g in run(&ctx, &tracer, 12, material, &input) {
            if g[3] <= 0.0 {
                failed += 1.0;
                continue;
            }
            // Cells in t = sqrt(1 - z) (finer towards the pole) and phi.
            let t = (1.0 - g[2] as f64).max(0.0).sqrt();
            let phi = (g[1] as f64).atan2(g[0] as f64).rem_euclid(std::f64::consts::TAU);
            let iz = ((t * nz as f64) as usize).min(nz - 1);
            let ip = ((phi / std::f64::consts::TAU * nphi as f64) as usize).min(nphi - 1);
            observed[iz * nphi + ip] += 1.0;
        }
        let wo = wo_of(cos_wo);
        let pdf = |w: Vec3| bsdf.pdf(wo, w) as f64;
        let mut expected = vec![0.0; nz * nphi];
        for iz in 0..nz {
            let (t0, t1) = (iz as f64 / nz as f64, (iz + 1) as f64 / nz as f64);
            let z = (1.0 - t1 * t1, 1.0 - t0 * t0);
            for ip in 0..nphi {
                let p = (
                    ip as f64 / nphi as f64 * std::f64::consts::TAU,
                    (ip + 1) as f64 / nphi as f64 * std::f64::consts::TAU,
                );
                expected[iz * nphi + ip] = n as f64 * integrate_cell(&pdf, z, p, 12);
            }
        }
        // Directions below the surface (rejected samples) are the pdf's missing mass.
        observed.push(failed);
        expected.push((n as f64 - expected.iter().sum::<f64>()).max(0.0));
        let (stat, dof, p) = chi2_test(&observed, &expected);
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
        PathTracer::new(&ctx, &scene, &RenderSettings { width: 4, height: 4, gate: Gate::None, ..Default::default() })
            .unwrap();
    let n = 100_000;
    for (metallic, alpha) in [(1.0f32, 0.05f32), (1.0, 0.3), (1.0, 0.8), (0.5, 0.3), (0.0, 1.0)] {
        for cos_wo in [1.0f32, 0.5, 0.1] {
            let bsdf = probe_bsdf(metallic, alpha, true);
            let wo = wo_of(cos_wo);
            let input: Vec<[f32; 4]> = uniforms(n, 99).iter().map(|u| [u[0], u[1], u[2], cos_wo]).collect();
            // Estimate from sampling: mean of f cos / pdf (0 for rejected samples).
            let weights: Vec<f64> = run(&ctx, &tracer, 12, (metallic, alpha, true), &input)
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
