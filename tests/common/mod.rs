//! Shared helpers of the integration tests.
#![allow(dead_code)]

pub mod gltf_builder;
pub mod peer;
pub mod quadrature;
pub mod stats;

use std::path::{Path, PathBuf};

use gatetrace::film::Film;
use gatetrace::gpu::GpuContext;
use gatetrace::integrator::{Integrator, RenderSettings, create_integrator};
use gatetrace::scene::{PreparedScene, load_gltf};
use stats::BatchStats;

/// The device every GPU test of a test binary uses, opened by the first: its kernel cache then
/// serves every later test, which on lavapipe (compiling each kernel at its first dispatch)
/// spares each test the compilation of the kernels an earlier one built. Without an adapter the
/// test fails (never skips).
pub fn gpu() -> &'static GpuContext {
    static DEVICE: std::sync::OnceLock<GpuContext> = std::sync::OnceLock::new();
    DEVICE.get_or_init(|| match GpuContext::new() {
        Ok(ctx) => ctx,
        Err(e) => panic!("GPU tests need a Vulkan adapter (CI installs lavapipe): {e:#}"),
    })
}

pub fn repo_path(relative: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(relative)
}

pub fn cornell_box() -> PreparedScene {
    PreparedScene::new(load_gltf(&repo_path("assets/scenes/cornell_box.gltf")).unwrap()).unwrap()
}

/// Renders `batches` independent films of `spp` samples per pixel each and returns the
/// per-element mean and variance of the mean over batches.
pub fn render_batches(
    ctx: &GpuContext,
    scene: &PreparedScene,
    settings: &RenderSettings,
    batches: usize,
    spp: u32,
) -> BatchStats {
    let films = render_films(ctx, scene, settings, batches, spp);
    let mut stats = BatchStats::new(films[0].data.len());
    for film in &films {
        stats.add(&film.data);
    }
    stats
}

/// Renders `batches` films of `spp` each and returns them (for image-level statistics).
pub fn render_films(
    ctx: &GpuContext,
    scene: &PreparedScene,
    settings: &RenderSettings,
    batches: usize,
    spp: u32,
) -> Vec<Film> {
    let mut tracer = create_integrator(ctx, scene, settings).unwrap();
    films_of(tracer.as_mut(), batches, spp)
}

/// `batches` independent films of `spp` samples per pixel from an existing integrator.
pub fn films_of(tracer: &mut dyn gatetrace::integrator::Integrator, batches: usize, spp: u32) -> Vec<Film> {
    (0..batches)
        .map(|_| {
            tracer.render_samples(spp as u64).unwrap();
            let film = tracer.film().unwrap();
            assert!(film.all_finite(), "non-finite pixel values");
            tracer.reset_film();
            film
        })
        .collect()
}

/// Reads a reference array from tests/data.
pub fn reference(relative: &str) -> (Vec<usize>, Vec<f32>) {
    gatetrace::film::output::read_npy_f32(&repo_path(&format!("tests/data/{relative}"))).unwrap()
}

/// Writes actual, reference and difference arrays of a failing image test to
/// target/test-failures/NAME_{actual,reference,difference}.npy and returns the directory.
pub fn write_failure_images(name: &str, shape: &[usize], actual: &[f32], reference: &[f32]) -> PathBuf {
    let dir = repo_path("target/test-failures");
    std::fs::create_dir_all(&dir).unwrap();
    let diff: Vec<f32> = actual.iter().zip(reference).map(|(a, b)| a - b).collect();
    for (suffix, data) in [("actual", actual), ("reference", reference), ("difference", &diff[..])] {
        gatetrace::film::output::write_npy_f32(&dir.join(format!("{name}_{suffix}.npy")), shape, data).unwrap();
    }
    dir
}

/// A fresh empty directory under target/test-scratch for files a test writes.
pub fn scratch_dir(name: &str) -> PathBuf {
    // The tests of one binary run on parallel threads: each thread gets a directory of its own,
    // so two tests that use one name cannot remove each other's files.
    let thread = format!("{:?}", std::thread::current().id()).replace(|c: char| !c.is_ascii_alphanumeric(), "");
    let dir = repo_path("target/test-scratch").join(name).join(thread);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs test-only probe kernel `kernel` over `input` records with the resources and
/// specialisation of `tracer` (plus `extra` constants) and returns `outputs` output records.
pub fn run_probe(
    ctx: &GpuContext,
    tracer: &dyn Integrator,
    kernel: &str,
    extra: &[(&'static str, f64)],
    input: &[[f32; 4]],
    outputs: usize,
) -> Vec<[f32; 4]> {
    run_probe_with(ctx, tracer.resources(), tracer.constants(), kernel, extra, input, outputs)
}

/// `run_probe` with the resources and specialisation constants given (e.g. a tracer's, some
/// replaced).
pub fn run_probe_with(
    ctx: &GpuContext,
    resources: &gatetrace::gpu::resources::Resources,
    constants: &[(&'static str, f64)],
    kernel: &str,
    extra: &[(&'static str, f64)],
    input: &[[f32; 4]],
    outputs: usize,
) -> Vec<[f32; 4]> {
    use gatetrace::gpu::{Kernel, resources::read_buffer};
    let mut resources = resources.clone();
    resources.storage_init(ctx, "probe_input", input).unwrap();
    resources.storage_zeroed(ctx, "probe_output", 16 * outputs as u64, wgpu::BufferUsages::empty()).unwrap();
    let mut constants = constants.to_vec();
    constants.extend_from_slice(extra);
    let k = Kernel::new(ctx, kernel, None, &constants);
    let bind_group = k.bind(ctx, &resources);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        k.dispatch(&mut pass, &bind_group, outputs as u32);
    }
    ctx.queue.submit([encoder.finish()]);
    read_buffer(ctx, resources.get("probe_output").unwrap(), outputs).unwrap()
}

/// Per-group statistics of two sets of independent films: for each group of elements
/// (`group(i)` of element i, None: left out), the mean over films of the group's mean, for
/// `a` and `b`, and the z-score of their difference with the variance measured over the films
/// of each side (so correlations between pixels are included).
pub fn compare_films(
    a: &[Film],
    b: &[Film],
    groups: usize,
    group: impl Fn(usize) -> Option<usize>,
) -> Vec<(f64, f64, f64)> {
    let means = |films: &[Film]| -> Vec<Vec<f64>> {
        films
            .iter()
            .map(|f| {
                let mut sums = vec![0.0; groups];
                let mut counts = vec![0.0; groups];
                for (i, &v) in f.data.iter().enumerate() {
                    if let Some(g) = group(i) {
                        sums[g] += v as f64;
                        counts[g] += 1.0;
                    }
                }
                sums.iter().zip(&counts).map(|(s, c)| s / c).collect()
            })
            .collect()
    };
    let stat = |m: &Vec<Vec<f64>>, g: usize| {
        let n = m.len() as f64;
        let mean = m.iter().map(|v| v[g]).sum::<f64>() / n;
        let var = m.iter().map(|v| (v[g] - mean).powi(2)).sum::<f64>() / (n - 1.0) / n;
        (mean, var)
    };
    let (ma, mb) = (means(a), means(b));
    (0..groups)
        .map(|g| {
            let ((xa, va), (xb, vb)) = (stat(&ma, g), stat(&mb, g));
            (xa, xb, (xa - xb) / (va + vb).sqrt().max(1e-300))
        })
        .collect()
}

/// Asserts that two estimators' films ([H, W, bins, 3]) agree: the image mean of every bin and
/// channel with |z| < 4, and every block of `block` x `block` pixels per bin and channel within
/// the Sidak-corrected t-limit at family-wise rate `alpha`. Prints the figures.
pub fn assert_films_agree(label: &str, a: &[Film], b: &[Film], block: u32, alpha: f64) {
    let (w, h, bins) = (a[0].width, a[0].height, a[0].bins);
    let per_pixel = (bins * 3) as usize;
    let images = compare_films(a, b, per_pixel, |i| Some(i % per_pixel));
    for (g, (xa, xb, z)) in images.iter().enumerate() {
        println!("{label}: bin {} channel {}: {xa:.6} vs {xb:.6}, z {z:+.2}", g / 3, g % 3);
        assert!(z.abs() < 4.0, "{label}: image mean of bin {} channel {}: {xa} vs {xb} (z = {z:.2})", g / 3, g % 3);
    }
    let (bx, by) = (w.div_ceil(block), h.div_ceil(block));
    let blocks = (bx * by) as usize * per_pixel;
    let result = compare_films(a, b, blocks, |i| {
        let (p, k) = (i / per_pixel, i % per_pixel);
        let (x, y) = (p as u32 % w, p as u32 / w);
        Some(((y / block) * bx + x / block) as usize * per_pixel + k)
    });
    assert_groups_agree(label, "block", &result, (a.len().min(b.len()) - 1) as f64, alpha);
}

/// Asserts that every group of a comparison (`compare_films`: means and z) lies within the
/// Sidak-corrected Student's t limit at family-wise rate `alpha`, with `dof` degrees of freedom
/// (batches - 1). Prints the worst.
pub fn assert_groups_agree(label: &str, what: &str, result: &[(f64, f64, f64)], dof: f64, alpha: f64) {
    let limit = stats::t_critical(stats::sidak(alpha, result.len()), dof);
    let worst = result.iter().enumerate().max_by(|p, q| p.1.2.abs().total_cmp(&q.1.2.abs())).unwrap();
    println!("{label}: worst of {} {what}s |z| {:.2} (limit {limit:.2})", result.len(), worst.1.2.abs());
    assert!(
        worst.1.2.abs() < limit,
        "{label}: {what} {} differs: {} vs {} (|z| = {:.2} >= {limit:.2})",
        worst.0,
        worst.1.0,
        worst.1.1,
        worst.1.2.abs()
    );
}

/// A soup of `n` random triangles in [-1, 1]^3 with sizes spread over two orders of magnitude.
pub fn random_soup(n: usize, seed: u32) -> Vec<[glam::Vec3; 3]> {
    let mut rng = gatetrace::rng::Rng::new(seed, 0, 0);
    let mut v = || glam::Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
    (0..n)
        .map(|i| {
            let centre = v() * 2.0 - 1.0;
            let size = 0.01 + 0.3 * (i % 7) as f32 / 7.0;
            [centre + (v() - 0.5) * size, centre + (v() - 0.5) * size, centre + (v() - 0.5) * size]
        })
        .collect()
}

/// A soup of `n` random triangles (half-size 0.5) in front of an emitter, seen from +z.
pub fn soup_scene(n: usize, seed: u32, name: &str) -> gatetrace::scene::PreparedScene {
    soup_scene_with(n, seed, name, false)
}

/// `soup_scene`, with vertex normals (tilted from the geometric normal) when `normals`, so that
/// the kernels read shading data.
pub fn soup_scene_with(n: usize, seed: u32, name: &str, normals: bool) -> gatetrace::scene::PreparedScene {
    use gatetrace::scene::{PreparedScene, load_gltf};
    use gltf_builder::{Camera, Material, Mesh, Scene, quad_z};
    let mut mesh =
        Mesh { positions: vec![], normals: normals.then(Vec::new), uvs: None, indices: vec![], material: Some(0) };
    for t in &random_soup(n, seed) {
        let geometric = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
        for (k, p) in t.iter().enumerate() {
            mesh.indices.push(mesh.positions.len() as u32);
            mesh.positions.push((*p * 0.5).to_array());
            if let Some(normals) = &mut mesh.normals {
                let tilt = glam::Vec3::new(0.2 * k as f32, 0.1, -0.1);
                normals.push((geometric + tilt).normalize().to_array());
            }
        }
    }
    let gltf = Scene {
        meshes: vec![mesh, quad_z(1.0, -1.0, true, 1)],
        materials: vec![Material { double_sided: true, ..Material::diffuse([0.7, 0.6, 0.5]) }, Material::emitter(3.0)],
        camera: Some(Camera { position: [0.0, 0.0, 3.0], rotation: [0.0, 0.0, 0.0, 1.0], yfov: 0.8 }),
        point_lights: vec![],
    };
    let dir = scratch_dir(name);
    PreparedScene::new(load_gltf(&gltf.write(&dir, "soup.gltf")).unwrap()).unwrap()
}

/// The Cornell box holding a white geodesic sphere (radius 0.25 m, 5 cm above the floor) of
/// 20 f^2 flat triangles, each vertex pushed along its radius by +-4 % bumps: the scene
/// tools/scenes/make_sphere_scene.py writes, built in memory (f = 128: 327,680 sphere triangles).
pub fn sphere_scene(frequency: u32) -> PreparedScene {
    let mut scene = load_gltf(&repo_path("assets/scenes/cornell_box.gltf")).unwrap();
    let white = scene.materials.iter().position(|m| m.name == "white").unwrap() as u32;
    push_sphere(&mut scene, glam::Vec3::new(0.0, -0.5 + 0.05 + 0.25, -0.05), 0.25, frequency, SPHERE_BUMPS, white);
    PreparedScene::new(scene).unwrap()
}

/// The NLOS example scene (assets/scenes/nlos_letter.gltf) with its hidden letter replaced by a
/// displaced geodesic sphere of 20 f^2 triangles (radius 0.15 m, centred 0.6 m in front of the
/// relay wall's centre, the letter's material), as tools/scenes/make_sphere_scene.py --nlos writes it;
/// without the occluder unless `occluder`: the relay wall and the sphere alone.
pub fn nlos_sphere_scene(frequency: u32, occluder: bool) -> PreparedScene {
    PreparedScene::new(nlos_sphere_scene_unprepared(frequency, occluder)).unwrap()
}

/// The scene of `nlos_sphere_scene` before its BVH is built.
pub fn nlos_sphere_scene_unprepared(frequency: u32, occluder: bool) -> gatetrace::scene::Scene {
    nlos_sphere_scene_with_bumps(frequency, occluder, SPHERE_BUMPS)
}

/// `nlos_sphere_scene_unprepared` with bumps of +-`bumps` of the radius (0: a convex polyhedron
/// whose vertices lie on the sphere).
pub fn nlos_sphere_scene_with_bumps(frequency: u32, occluder: bool, bumps: f32) -> gatetrace::scene::Scene {
    let mut scene = load_gltf(&repo_path("assets/scenes/nlos_letter.gltf")).unwrap();
    if !occluder {
        let range = scene.node("occluder").unwrap().triangles.clone();
        assert_eq!(range.end, scene.triangles.len(), "the occluder's triangles are expected last");
        scene.triangles.truncate(range.start);
        scene.nodes.iter_mut().find(|n| n.name == "occluder").unwrap().triangles = range.start..range.start;
    }
    let letter = scene.node("hidden_letter").unwrap().triangles.clone();
    let material = scene.triangles[letter.start].material;
    scene.triangles.drain(letter.clone());
    for node in &mut scene.nodes {
        let shift = |i: usize| if i >= letter.end { i - letter.len() } else { i.min(letter.start) };
        node.triangles = shift(node.triangles.start)..shift(node.triangles.end);
    }
    let first = scene.triangles.len();
    push_sphere(&mut scene, glam::Vec3::new(0.0, 0.0, 0.6), 0.15, frequency, bumps, material);
    scene.nodes.push(gatetrace::scene::NamedNode {
        name: "hidden_sphere".into(),
        position: glam::Vec3::new(0.0, 0.0, 0.6),
        triangles: first..scene.triangles.len(),
        texcoords: None,
    });
    scene
}

/// The relative amplitude of the test spheres' bumps, as tools/scenes/make_sphere_scene.py has it.
const SPHERE_BUMPS: f32 = 0.04;

/// Appends a geodesic sphere (an icosahedron whose faces are cut into f x f flat triangles,
/// each vertex pushed along its radius by bumps of +-`bumps` of it) of `radius` m about `centre`.
fn push_sphere(
    scene: &mut gatetrace::scene::Scene,
    centre: glam::Vec3,
    radius: f32,
    frequency: u32,
    bumps: f32,
    material: u32,
) {
    use glam::Vec3;
    let p = (1.0 + 5f32.sqrt()) / 2.0;
    let ico: Vec<Vec3> = [
        (-1.0, p, 0.0),
        (1.0, p, 0.0),
        (-1.0, -p, 0.0),
        (1.0, -p, 0.0),
        (0.0, -1.0, p),
        (0.0, 1.0, p),
        (0.0, -1.0, -p),
        (0.0, 1.0, -p),
        (p, 0.0, -1.0),
        (p, 0.0, 1.0),
        (-p, 0.0, -1.0),
        (-p, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let faces = [
        (0, 11, 5),
        (0, 5, 1),
        (0, 1, 7),
        (0, 7, 10),
        (0, 10, 11),
        (1, 5, 9),
        (5, 11, 4),
        (11, 10, 2),
        (10, 7, 6),
        (7, 1, 8),
        (3, 9, 4),
        (3, 4, 2),
        (3, 2, 6),
        (3, 6, 8),
        (3, 8, 9),
        (4, 9, 5),
        (2, 4, 11),
        (6, 2, 10),
        (8, 6, 7),
        (9, 8, 1),
    ];
    let waves = [
        (Vec3::new(0.36, 0.48, 0.80), 7.0, 0.3, 0.45),
        (Vec3::new(-0.60, 0.64, 0.48), 11.0, 1.7, 0.30),
        (Vec3::new(0.0, -0.28, 0.96), 17.0, 2.9, 0.15),
        (Vec3::new(0.80, 0.0, -0.60), 29.0, 0.8, 0.10),
    ];
    let point = |d: Vec3| {
        let d = d.normalize();
        let bump: f32 = waves.iter().map(|&(w, k, phase, weight)| weight * (k * w.dot(d) + phase).sin()).sum();
        centre + radius * (1.0 + bumps * bump) * d
    };
    let f = frequency as f32;
    for &(a, b, c) in &faces {
        let (a, b, c) = (ico[a], ico[b], ico[c]);
        let lattice = |i: u32, j: u32| point(a * (f - (i + j) as f32) + b * i as f32 + c * j as f32);
        for i in 0..frequency {
            for j in 0..frequency - i {
                let mut add = |p: [Vec3; 3]| {
                    scene.triangles.push(gatetrace::scene::SceneTriangle {
                        positions: p,
                        normals: None,
                        uvs: [glam::Vec2::ZERO; 3],
                        material,
                    })
                };
                add([lattice(i, j), lattice(i + 1, j), lattice(i, j + 1)]);
                if j + 1 < frequency - i {
                    add([lattice(i + 1, j), lattice(i + 1, j + 1), lattice(i, j + 1)]);
                }
            }
        }
    }
}

/// An NLOS capture of assets/scenes/nlos_letter.gltf as the peer data was made: sensor and laser
/// origins at (-1.2, 0, 0.6) m, a 1 W laser aimed by `aim`, a `width` x `height` grid of sensed
/// points, three bounces, reflection-weighted ellipsoid queries (as `render --nlos` by default).
pub fn example_capture(
    width: u32,
    height: u32,
    gate: gatetrace::film::Gate,
    aim: gatetrace::nlos::LaserAim,
    method: gatetrace::integrator::Method,
) -> RenderSettings {
    let origin = glam::Vec3::new(-1.2, 0.0, 0.6);
    RenderSettings {
        width,
        height,
        method,
        gate,
        max_bounces: 3,
        nlos: Some(gatetrace::nlos::NlosCapture {
            relay_wall: "relay_wall".into(),
            sensor_origin: origin,
            laser_origin: origin,
            aim,
            laser: gatetrace::nlos::Laser::Beam(1.0),
            count_first_and_last: false,
        }),
        query: gatetrace::integrator::QuerySettings { reflection_weights: true, ..Default::default() },
        // The command line's defaults for captures.
        target_pilot_spp: if method == gatetrace::integrator::Method::Ellipsoidal {
            gatetrace::integrator::bidirectional::DEFAULT_NLOS_TARGET_PILOT
        } else {
            0
        },
        ..Default::default()
    }
}
