//! Sampling routines: chi-square tests of the CPU twins against their densities, and the WGSL
//! versions against the CPU twins on lavapipe (probe kernels).

mod common;

use common::stats::{chi2_sf, chi2_test, normal_two_sided_p, sidak, t_critical, t_two_sided_p};
use gatetrace::film::Gate;
use gatetrace::integrator::{PathTracer, RenderSettings};
use gatetrace::rng::Rng;
use gatetrace::sampling::{Frame, power_heuristic, sample_cosine_hemisphere, sample_triangle_barycentrics};
use glam::{Vec2, Vec3};
use std::f64::consts::PI;

/// Family-wise false-alarm rate of the chi-square tests in this file.
const ALPHA: f64 = 0.01;
/// Number of chi-square tests in this file (for the Sidak correction).
const CHI2_TESTS: usize = 3;

#[test]
fn statistics_helpers_match_tabulated_values() {
    assert!((normal_two_sided_p(1.959964) - 0.05).abs() < 1e-6);
    assert!((chi2_sf(3.841459, 1.0) - 0.05).abs() < 1e-6);
    assert!((chi2_sf(124.342, 100.0) - 0.05).abs() < 1e-4);
    assert!((t_critical(0.05, 10.0) - 2.228139).abs() < 1e-4);
    assert!((t_critical(0.01, 30.0) - 2.749996).abs() < 1e-4);
    assert!((t_two_sided_p(2.0, 1e6) - normal_two_sided_p(2.0)).abs() < 1e-5);
}

#[test]
fn cosine_hemisphere_sampling_follows_cos_over_pi() {
    let (nc, np) = (20usize, 40usize);
    let n = 400_000;
    let mut observed = vec![0.0; nc * np];
    let mut rng = Rng::new(1, 2, 3);
    for _ in 0..n {
        let d = sample_cosine_hemisphere(rng.next_vec2());
        assert!((d.length() - 1.0).abs() < 1e-5 && d.z >= 0.0);
        let c = ((d.z as f64 * nc as f64) as usize).min(nc - 1);
        let phi = (d.y as f64).atan2(d.x as f64).rem_euclid(2.0 * PI);
        let p = ((phi / (2.0 * PI) * np as f64) as usize).min(np - 1);
        observed[c * np + p] += 1.0;
    }
    // P(cell) = (dphi / pi) (c1^2 - c0^2) / 2 for cos(theta) in [c0, c1).
    let mut expected = vec![0.0; nc * np];
    for c in 0..nc {
        let (c0, c1) = (c as f64 / nc as f64, (c + 1) as f64 / nc as f64);
        for p in 0..np {
            expected[c * np + p] = n as f64 * (2.0 * PI / np as f64) / PI * 0.5 * (c1 * c1 - c0 * c0);
        }
    }
    let (stat, dof, p) = chi2_test(&observed, &expected);
    assert!(p > sidak(ALPHA, CHI2_TESTS), "chi2 = {stat:.1} with {dof} dof, p = {p:.2e}");
}

#[test]
fn triangle_sampling_is_uniform() {
    let g = 24usize;
    let n = 400_000;
    let mut observed = vec![0.0; g * g];
    let mut rng = Rng::new(4, 5, 6);
    for _ in 0..n {
        let b = sample_triangle_barycentrics(rng.next_vec2());
        assert!(b.x >= 0.0 && b.y >= 0.0 && b.x + b.y <= 1.0 + 1e-6);
        let (i, j) = (((b.x * g as f32) as usize).min(g - 1), ((b.y * g as f32) as usize).min(g - 1));
        observed[i * g + j] += 1.0;
    }
    // Area of cell (i, j) inside b1 + b2 <= 1, over the triangle's area 1/2.
    let expected: Vec<f64> = (0..g * g)
        .map(|k| {
            let (i, j) = (k / g, k % g);
            let inside = if i + j + 2 <= g {
                1.0
            } else if i + j + 1 == g {
                0.5
            } else {
                0.0
            };
            n as f64 * inside / (g * g) as f64 * 2.0
        })
        .collect();
    let (stat, dof, p) = chi2_test(&observed, &expected);
    assert!(p > sidak(ALPHA, CHI2_TESTS), "chi2 = {stat:.1} with {dof} dof, p = {p:.2e}");
}

/// A light table over three emissive triangles of different areas and radiances and one point
/// light, built from a scene assembled in memory.
fn light_test_scene() -> gatetrace::scene::Scene {
    use gatetrace::scene::{CameraDesc, MaterialDesc, PointLight, Scene, SceneTriangle};
    let material = |e: f32| MaterialDesc {
        name: String::new(),
        base_color: Vec3::ZERO,
        base_color_texture: None,
        emission: Vec3::new(e, e, 0.5 * e),
        double_sided: false,
        metallic: 0.0,
        roughness: 1.0,
        plastic: None,
        dielectric: None,
        conductor_index: None,
        media: Default::default(),
        null: false,
    };
    let tri = |a: [f32; 3], b: [f32; 3], c: [f32; 3], m: u32| SceneTriangle {
        positions: [a.into(), b.into(), c.into()],
        normals: None,
        uvs: [Vec2::ZERO; 3],
        material: m,
    };
    Scene {
        source: "memory".into(),
        triangles: vec![
            tri([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 0),
            tri([2.0, 0.0, 1.0], [2.0, 3.0, 1.0], [2.0, 0.0, 2.0], 1),
            tri([0.0, 0.0, -1.0], [0.2, 0.1, -1.0], [0.0, 0.3, -1.2], 2),
            tri([5.0, 5.0, 5.0], [6.0, 5.0, 5.0], [5.0, 6.0, 5.0], 3),
        ],
        materials: vec![material(1.0), material(4.0), material(30.0), material(0.0)],
        textures: vec![],
        point_lights: vec![PointLight { position: Vec3::new(0.0, 3.0, 0.0), intensity: Vec3::splat(0.2), spot: None }],
        directional_lights: vec![],
        camera: CameraDesc { position: Vec3::Z, right: Vec3::X, up: Vec3::Y, forward: -Vec3::Z, yfov: 1.0, lens: None },
        dropped_degenerate: 0,
        nodes: Vec::new(),
        warnings: Vec::new(),
        settings: Default::default(),
        media: Vec::new(),
        camera_medium: None,
    }
}

#[test]
fn light_sampling_follows_power_and_area() {
    let scene = light_test_scene();
    let prepared = gatetrace::scene::PreparedScene::new(scene).unwrap();
    let table = &prepared.lights;
    assert_eq!(table.lights.len(), 4, "three emissive triangles and one point light");
    // Selection probabilities are proportional to power: pi A mean(L) for one-sided emitters,
    // 4 pi mean(I) for point lights.
    let power: Vec<f64> = table
        .lights
        .iter()
        .map(|l| {
            let mean = (l.emission.x + l.emission.y + l.emission.z) as f64 / 3.0;
            if l.kind == gatetrace::gpu::layout::LIGHT_POINT { 4.0 * PI * mean } else { PI * l.area as f64 * mean }
        })
        .collect();
    let total: f64 = power.iter().sum();
    for (l, p) in table.lights.iter().zip(&power) {
        assert!((l.select_pdf as f64 - p / total).abs() < 1e-6);
    }
    // Sample points; cell = (light, cell of a G x G grid over the barycentrics (b1, b2)).
    const G: usize = 8;
    let n = 400_000;
    let cells = G * G * table.lights.len();
    let mut observed = vec![0.0; cells];
    let mut rng = Rng::new(7, 8, 9);
    for _ in 0..n {
        let s = table.sample(&prepared.triangles, rng.next_f32(), rng.next_vec2());
        let (light, cell) = if s.is_delta {
            let l = table.lights.iter().position(|l| l.position == s.position).unwrap();
            (l, 0)
        } else {
            let l = table.lights.iter().position(|l| l.triangle == s.triangle).unwrap();
            let t = &prepared.triangles[s.triangle as usize];
            assert!((s.pdf - table.lights[l].select_pdf / table.lights[l].area).abs() < 1e-6 * s.pdf);
            // Barycentrics of the point: solve p - v0 = b1 e1 + b2 e2 in the least-squares sense.
            let d = s.position - t.v0;
            let (a11, a12, a22) = (t.e1.dot(t.e1), t.e1.dot(t.e2), t.e2.dot(t.e2));
            let (r1, r2) = (t.e1.dot(d), t.e2.dot(d));
            let det = a11 * a22 - a12 * a12;
            let b1 = (r1 * a22 - r2 * a12) / det;
            let b2 = (a11 * r2 - a12 * r1) / det;
            let cell = |b: f32| ((b.clamp(0.0, 1.0) * G as f32) as usize).min(G - 1);
            (l, cell(b1) * G + cell(b2))
        };
        observed[G * G * light + cell] += 1.0;
    }
    // A grid cell's share of the triangle: whole, half (on the diagonal) or none.
    let share = |k: usize| {
        let (i, j) = (k / G, k % G);
        if i + j + 2 <= G {
            2.0 / (G * G) as f64
        } else if i + j + 1 == G {
            1.0 / (G * G) as f64
        } else {
            0.0
        }
    };
    let mut expected = vec![0.0; cells];
    for (i, l) in table.lights.iter().enumerate() {
        if l.kind == gatetrace::gpu::layout::LIGHT_POINT {
            expected[G * G * i] = n as f64 * l.select_pdf as f64;
        } else {
            for k in 0..G * G {
                expected[G * G * i + k] = n as f64 * l.select_pdf as f64 * share(k);
            }
        }
    }
    let (stat, dof, p) = chi2_test(&observed, &expected);
    assert!(p > sidak(ALPHA, CHI2_TESTS), "chi2 = {stat:.1} with {dof} dof, p = {p:.2e}");
}

#[test]
fn frames_are_orthonormal() {
    let mut rng = Rng::new(3, 3, 3);
    for _ in 0..10_000 {
        let n = (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5).normalize();
        let f = Frame::from_normal(n);
        for (a, b) in [(f.t, f.b), (f.t, f.n), (f.b, f.n)] {
            assert!(a.dot(b).abs() < 1e-5);
        }
        for v in [f.t, f.b] {
            assert!((v.length() - 1.0).abs() < 1e-5);
        }
        assert!((f.t.cross(f.b) - n).length() < 1e-4, "right-handed frame");
    }
}

#[test]
fn power_heuristic_is_a_partition_of_unity() {
    let mut rng = Rng::new(1, 1, 1);
    for _ in 0..1000 {
        let (a, b) = (rng.next_f32() * 10.0, rng.next_f32() * 10.0);
        assert!((power_heuristic(a, b) + power_heuristic(b, a) - 1.0).abs() < 1e-6);
    }
    assert_eq!(power_heuristic(0.0, 0.0), 0.0);
}

// ---- WGSL against the CPU twins ----

/// Precision the Vulkan spec guarantees for sin/cos on [-pi, pi]: 2^-11 absolute.
const SIN_COS_ABS: f32 = 1.0 / 2048.0;
/// Relative allowance for one sqrt or division: the Vulkan spec allows 2.5 ulp for division and
/// about 3 ulp for sqrt (from inversesqrt's 2 ulp); 4e-7 is 3.4 ulp of f32.
const FEW_ULP: f32 = 4e-7;
// Vector results (frames, normals, camera directions, light points) sum several products, which
// the device may fuse into multiply-adds, and may cancel: they get 1e-5 relative (about 80 ulp)
// plus 1e-6 absolute for components near zero.

fn tracer_for<'a>(
    ctx: &'a gatetrace::gpu::GpuContext,
    scene: &gatetrace::scene::PreparedScene,
    gate: Gate,
) -> PathTracer<'a> {
    PathTracer::new(ctx, scene, &RenderSettings { width: 32, height: 24, gate, ..Default::default() }).unwrap()
}

fn uniform_inputs(n: usize, seed: u32) -> Vec<[f32; 4]> {
    let mut rng = Rng::new(seed, 0, 0);
    (0..n).map(|_| [rng.next_f32(), rng.next_f32(), rng.next_f32(), rng.next_f32()]).collect()
}

fn assert_close(what: &str, i: usize, gpu: f32, cpu: f32, abs: f32, rel: f32) {
    assert!(
        (gpu - cpu).abs() <= abs + rel * cpu.abs(),
        "{what}, record {i}: GPU {gpu} vs CPU {cpu} (abs {abs}, rel {rel})"
    );
}

#[test]
fn wgsl_sampling_matches_cpu_twins() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let tracer = tracer_for(ctx, &scene, Gate::None);
    let input = uniform_inputs(4096, 1);
    let run = |f: u32, input: &[[f32; 4]]| {
        common::run_probe(ctx, &tracer, "probe_functions", &[("FUNCTION", f as f64)], input, input.len())
    };

    for (i, (x, g)) in input.iter().zip(run(0, &input)).enumerate() {
        let c = sample_cosine_hemisphere(Vec2::new(x[0], x[1]));
        for k in 0..3 {
            assert_close("cosine hemisphere", i, g[k], c[k], SIN_COS_ABS, FEW_ULP);
        }
    }
    for (i, (x, g)) in input.iter().zip(run(1, &input)).enumerate() {
        let c = sample_triangle_barycentrics(Vec2::new(x[0], x[1]));
        assert_close("triangle barycentrics", i, g[0], c.x, 0.0, FEW_ULP);
        assert_close("triangle barycentrics", i, g[1], c.y, 0.0, FEW_ULP);
    }
    let normals: Vec<[f32; 4]> = input.iter().map(|x| [x[0] - 0.5, x[1] - 0.5, x[2] - 0.5, 0.0]).collect();
    for (i, (x, g)) in normals.iter().zip(run(2, &normals)).enumerate() {
        let f = Frame::from_normal(Vec3::new(x[0], x[1], x[2]).normalize());
        let c = f.to_world(Vec3::new(0.25, -0.5, 0.75));
        for k in 0..3 {
            assert_close("frame", i, g[k], c[k], 1e-6, 1e-5);
        }
    }
    // (seed, pixel, sample, dimension) as bits.
    let keys: Vec<[f32; 4]> = (0..4096u32)
        .map(|i| [f32::from_bits(i * 7919), f32::from_bits(i % 97), f32::from_bits(i / 3), f32::from_bits(i % 5)])
        .collect();
    for (i, (x, g)) in keys.iter().zip(run(3, &keys)).enumerate() {
        let mut rng = Rng::new(x[0].to_bits(), x[1].to_bits(), x[2].to_bits());
        rng.dimension = x[3].to_bits();
        let c = [rng.next_f32(), rng.next_f32(), rng.next_f32()];
        assert_eq!([g[0], g[1], g[2]], c, "rng record {i}");
        assert_eq!(g[3].to_bits(), rng.dimension, "rng dimension {i}");
    }
    let pairs: Vec<[f32; 4]> = input.iter().map(|x| [x[0] * 5.0, x[1] * 0.1, 0.0, 0.0]).collect();
    for (i, (x, g)) in pairs.iter().zip(run(8, &pairs)).enumerate() {
        assert_close("power heuristic", i, g[0], power_heuristic(x[0], x[1]), 0.0, FEW_ULP * 4.0);
    }
}

#[test]
fn wgsl_camera_and_lights_match_cpu_twins() {
    use gatetrace::scene::camera::camera_direction;
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let tracer = tracer_for(ctx, &scene, Gate::None);
    let run = |f: u32, input: &[[f32; 4]]| {
        common::run_probe(ctx, &tracer, "probe_functions", &[("FUNCTION", f as f64)], input, input.len())
    };
    let camera = scene.scene.camera.to_gpu(32, 24);
    let film: Vec<[f32; 4]> = uniform_inputs(2048, 2).iter().map(|x| [x[0] * 32.0, x[1] * 24.0, 0.0, 0.0]).collect();
    for (i, (x, g)) in film.iter().zip(run(5, &film)).enumerate() {
        let c = camera_direction(&camera, Vec2::new(x[0], x[1]), 32, 24);
        for k in 0..3 {
            assert_close("camera direction", i, g[k], c[k], 1e-6, 1e-5);
        }
    }
    // Light selection and sampling over several area lights and a point light.
    let lights = gatetrace::scene::PreparedScene::new(light_test_scene()).unwrap();
    let tracer = tracer_for(ctx, &lights, Gate::None);
    let input = uniform_inputs(4096, 3);
    let out = common::run_probe(ctx, &tracer, "probe_functions", &[("FUNCTION", 6.0)], &input, input.len());
    for (i, (x, g)) in input.iter().zip(out).enumerate() {
        let c = lights.lights.sample(&lights.triangles, x[0], Vec2::new(x[1], x[2]));
        for k in 0..3 {
            assert_close("light sample position", i, g[k], c.position[k], 1e-6, 1e-5);
        }
        assert_close("light sample pdf", i, g[3], c.pdf, 0.0, 1e-6);
    }
}

#[test]
fn wgsl_gates_match_cpu_twin() {
    use gatetrace::film::gate::{gate_bin, gate_weight};
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let dir = common::scratch_dir("wgsl_gates");
    let table = dir.join("trapezoid.csv");
    std::fs::write(&table, "length_m,weight\n2.0,0\n2.5,1\n3.0,1\n3.2,-0.5\n4.0,0\n").unwrap();
    let gates = [
        Gate::parse("box:2.5..3.1").unwrap(),
        Gate::parse("gaussian:3.0,0.1").unwrap(),
        Gate::parse("cw:50e6,30").unwrap(),
        Gate::parse("cw:4.7e9,-20,depthsel").unwrap(),
        Gate::parse("cw:300e6,75,ham4:3").unwrap(),
        Gate::parse("cw:450e6,200,square").unwrap(),
        Gate::parse(&format!("table:{}", table.display())).unwrap(),
        Gate::parse("transient:1.94,0.1,20").unwrap(),
        Gate::None,
    ];
    let lengths: Vec<[f32; 4]> = uniform_inputs(4096, 4).iter().map(|x| [1.5 + 3.5 * x[0], 0.0, 0.0, 0.0]).collect();
    for gate in gates {
        let tracer = tracer_for(ctx, &scene, gate.clone());
        let out = common::run_probe(ctx, &tracer, "probe_functions", &[("FUNCTION", 4.0)], &lengths, lengths.len());
        let (kind, g, tab) = (gate.kind(), gate.to_gpu(), gate.table());
        for (i, (x, o)) in lengths.iter().zip(out).enumerate() {
            let w = gate_weight(kind, &g, &tab, x[0]);
            // exp and cos differ between libm and the device within the Vulkan precision; a cw
            // code's phase f l / c + phase may be rounded once (fused) or twice, a unit in the
            // last place of it times the code's steepest slope.
            let abs = match &gate {
                Gate::Cw { .. } => SIN_COS_ABS,
                Gate::CwCode { code, .. } => {
                    let x = g.p0 * x[0] + g.p1 + 1.0;
                    (4.0 * code.steepest_slope() * (f32::from_bits(x.to_bits() + 1) - x) as f64) as f32 + 1e-6
                }
                _ => 1e-6,
            };
            assert_close(&format!("{} weight", gate.describe()), i, o[0], w, abs, 1e-5);
            assert_eq!(o[1], gate_bin(kind, &g, x[0]) as f32, "{} bin of {}", gate.describe(), x[0]);
        }
    }
}

#[test]
fn wgsl_fixed_point_sums_match_cpu_twin() {
    use gatetrace::film::fixed::{fixed_from_f32, to_words};
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let tracer = tracer_for(ctx, &scene, Gate::None);
    let seed = gatetrace::integrator::Integrator::wavefront(&tracer).params.seed;
    // Values across the whole range, both signs, denormals, and ones rounded at random.
    let mut values: Vec<f32> =
        (0..600).map(|i| f32::from_bits(0x0000_1000u32.wrapping_add(0x0071_c6a3u32.wrapping_mul(i)))).collect();
    values.extend([0.0, -0.0, 1.0, -1.0, 1e-25, -3e-20, 5.4e-20, 2.7e-20, 1e18, -9.0e18, f32::MIN_POSITIVE]);
    let input: Vec<[f32; 4]> = values
        .iter()
        .enumerate()
        .map(|(i, &a)| {
            [a, f32::from_bits(i as u32 * 7919), -values[(i * 31) % values.len()] * 0.37, f32::from_bits(i as u32)]
        })
        .collect();
    let out = common::run_probe(ctx, &tracer, "probe_functions", &[("FUNCTION", 11.0)], &input, input.len());
    for (x, g) in input.iter().zip(out) {
        let (a, b) = (fixed_from_f32(x[0], x[1].to_bits(), seed), fixed_from_f32(x[2], x[3].to_bits(), seed));
        let expected = to_words(a.unwrap_or(0).wrapping_add(b.unwrap_or(0)));
        assert_eq!(g.map(f32::to_bits), expected, "{:e} + {:e}", x[0], x[2]);
    }
}

#[test]
fn wgsl_surfaces_match_cpu_twin() {
    use gatetrace::gpu::layout::Hit;
    use gatetrace::scene::surface::{offset_ray_origin, surface_at};
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let tracer = tracer_for(ctx, &scene, Gate::None);
    let run = |f: u32, input: &[[f32; 4]]| {
        common::run_probe(ctx, &tracer, "probe_functions", &[("FUNCTION", f as f64)], input, input.len())
    };
    let input: Vec<[f32; 4]> = uniform_inputs(2048, 9)
        .iter()
        .map(|x| {
            let (b1, b2) = (x[1], x[2] * (1.0 - x[1]));
            [f32::from_bits((x[0] * scene.triangles.len() as f32) as u32), b1, b2, 0.0]
        })
        .collect();
    let (positions, normals) = (run(9, &input), run(10, &input));
    for (i, x) in input.iter().enumerate() {
        let hit = Hit { t: 1.0, triangle: x[0].to_bits(), b1: x[1], b2: x[2] };
        let s = surface_at(&scene.triangles, &scene.shading, &scene.normals, &hit);
        let p = offset_ray_origin(s.position, s.geometric_normal, scene.ray_epsilon);
        for k in 0..3 {
            assert_close("offset surface point", i, positions[i][k], p[k], 1e-6, 1e-6);
            assert_close("shading normal", i, normals[i][k], s.shading_normal[k], 1e-6, 1e-5);
        }
        assert_close("uv", i, positions[i][3], s.uv.x, 1e-6, 1e-5);
        assert_close("uv", i, normals[i][3], s.uv.y, 1e-6, 1e-5);
    }
}

/// The thin-lens camera (rays, and the image coordinates a ray from a lens point lands on) and
/// a spot light's intensity and direction density, against their CPU twins.
#[test]
fn wgsl_thin_lens_and_spot_light_match_cpu_twins() {
    use gatetrace::scene::camera::{camera_ray, image_coordinates};
    let ctx = common::gpu();
    let scene = gatetrace::scene::PreparedScene::new(
        gatetrace::scene::load_gltf(&common::repo_path("assets/scenes/cornell_box_thin_lens.gltf")).unwrap(),
    )
    .unwrap();
    let lens = scene.scene.camera.lens.expect("the scene has a thin lens");
    let tracer = tracer_for(ctx, &scene, Gate::None);
    let camera = scene.scene.camera.to_gpu(32, 24);
    let input: Vec<[f32; 4]> = uniform_inputs(2048, 7).iter().map(|x| [x[0] * 32.0, x[1] * 24.0, x[2], x[3]]).collect();
    let run =
        |f: u32| common::run_probe(ctx, &tracer, "probe_functions", &[("FUNCTION", f as f64)], &input, input.len());
    let (directions, origins, coordinates) = (run(16), run(17), run(18));
    for (i, x) in input.iter().enumerate() {
        let (origin, direction) = camera_ray(&camera, Vec2::new(x[0], x[1]), Vec2::new(x[2], x[3]), 32, 24);
        assert!((origin - camera.position).length() <= lens.aperture_radius * (1.0 + 1e-6), "record {i}: off the lens");
        for k in 0..3 {
            // The lens point carries sin/cos of the disk's angle.
            assert_close("lens point", i, origins[i][k], origin[k], SIN_COS_ABS * lens.aperture_radius + 1e-6, 1e-5);
            assert_close("thin-lens direction", i, directions[i][k], direction[k], 1e-4, 1e-4);
        }
        // The ray lands where it was aimed: its film point, in [-1, 1]^2 image coordinates.
        let aimed = Vec2::new(2.0 * x[0] / 32.0 - 1.0, 1.0 - 2.0 * x[1] / 24.0);
        let c = image_coordinates(&camera, origin, direction);
        for k in 0..2 {
            assert_close("image coordinates (CPU)", i, c[k], aimed[k], 1e-5, 1e-5);
            assert_close("image coordinates (GPU)", i, coordinates[i][k], aimed[k], 1e-4, 1e-4);
        }
        assert!(
            c.z > 0.0 && (coordinates[i][2] - c.z).abs() <= 1e-4,
            "record {i}: cosine {} vs {}",
            coordinates[i][2],
            c.z
        );
    }

    // A spot light with a wide falloff (inner 0.2 rad, outer 0.5 rad): intensity and the density
    // of its uniform cone sampling towards directions all around.
    let mut spot_scene =
        gatetrace::scene::load_gltf(&common::repo_path("assets/scenes/cornell_box_spot.gltf")).unwrap();
    let spot = spot_scene.point_lights[0].spot.as_mut().expect("the scene's light is a spot");
    (spot.inner, spot.outer) = (0.2, 0.5);
    let spot_scene = gatetrace::scene::PreparedScene::new(spot_scene).unwrap();
    let light = spot_scene.scene.point_lights[0].clone();
    let cone = light.spot.unwrap();
    let tracer = tracer_for(ctx, &spot_scene, Gate::None);
    // Directions concentrated about the axis (half of them inside the outer cone).
    let input: Vec<[f32; 4]> = uniform_inputs(4096, 8)
        .iter()
        .map(|x| {
            let w = cone.direction + 1.2 * (Vec3::new(x[0], x[1], x[2]) * 2.0 - Vec3::ONE);
            [w.x, w.y, w.z, 0.0]
        })
        .collect();
    let out = common::run_probe(ctx, &tracer, "probe_functions", &[("FUNCTION", 19.0)], &input, input.len());
    let mut inside = 0;
    for (i, (x, g)) in input.iter().zip(out).enumerate() {
        let w = Vec3::new(x[0], x[1], x[2]).normalize();
        let intensity = light.intensity.x * cone.falloff(w);
        let in_cone = w.dot(cone.direction) >= cone.outer.cos();
        let pdf = if in_cone { 1.0 / (2.0 * std::f32::consts::PI * (1.0 - cone.outer.cos())) } else { 0.0 };
        inside += in_cone as usize;
        // The ramp's slope is at most 2 / (cos inner - cos outer) = 19.6 per unit cosine.
        assert_close("spot intensity", i, g[0], intensity, 20.0 * 1e-6 * light.intensity.x, 1e-5);
        if (w.dot(cone.direction) - cone.outer.cos()).abs() > 1e-6 {
            assert_close("spot direction pdf", i, g[1], pdf, 0.0, 1e-5);
        }
    }
    assert!(inside > 1000 && inside < 3500, "{inside} of 4096 directions inside the cone");
}

#[test]
fn double_f32_sums_and_products_are_exact() {
    // double_float.wesl's two_sum and two_prod (probe_functions 21): hi + lo equals the f64 sum
    // and product of f32 inputs exactly, over 40 binades and both signs. A compiler that
    // rewrote their float expressions as real arithmetic (Mesa's NIR does without the opaque
    // zero) or a fused multiply-add computed unfused would make the error terms 0 and fail here.
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let tracer = tracer_for(ctx, &scene, Gate::None);
    let mut rng = gatetrace::rng::Xorshift64Star(12345);
    let mut input: Vec<[f32; 4]> = (0..4096)
        .map(|_| {
            std::array::from_fn(|_| ((rng.next_f64() - 0.5) * 2f64.powi((rng.next_f64() * 40.0) as i32 - 20)) as f32)
        })
        .collect();
    input.extend([[1.0, 1e-10, 4097.0, 4097.0], [-3.0, 3.0, 0.0, 1e20], [1e30, -1.0, 1e30, 0.5]]);
    let out = common::run_probe(ctx, &tracer, "probe_functions", &[("FUNCTION", 21.0)], &input, input.len());
    let mut inexact_products = 0;
    for (x, g) in input.iter().zip(&out) {
        let (sum, product) = (x[0] as f64 + x[1] as f64, x[2] as f64 * x[3] as f64);
        assert_eq!(g[0], (x[0] + x[1]), "two_sum({:e}, {:e}) rounds differently", x[0], x[1]);
        assert_eq!(g[0] as f64 + g[1] as f64, sum, "two_sum({:e}, {:e}) = {:e} + {:e}", x[0], x[1], g[0], g[1]);
        assert_eq!(g[2], x[2] * x[3], "two_prod({:e}, {:e}) rounds differently", x[2], x[3]);
        inexact_products += (g[2] as f64 + g[3] as f64 != product) as usize;
    }
    assert_eq!(inexact_products, 0, "two_prod inexact on {inexact_products} of {} inputs", input.len());
}
