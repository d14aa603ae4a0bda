//! `--method direct` (bidirectional path tracing) against `--method path`, an independent
//! estimator of the same images: the Cornell box at the steady state, at box, Gaussian and CW
//! gates, its glossy variant, a mix of area and point lights, and double-sided materials; the
//! transient cube against the box gate over the same range; the per-strategy debug images
//! against the full render; the camera pilot's scales of the MIS weights; and the
//! gate-before-ray statistics.
//! Both sides' variances are measured over independent batches.

mod common;

use gatetrace::film::{Film, Gate};
use gatetrace::integrator::{BidirectionalTracer, Integrator, Method, RenderSettings};
use gatetrace::scene::{PointLight, PreparedScene, load_gltf};

/// Family-wise false-alarm rate of each comparison's block tests.
const ALPHA: f64 = 0.01;
const BATCHES: usize = 16;

fn settings(method: Method, gate: Gate, seed: u32) -> RenderSettings {
    RenderSettings { width: 32, height: 32, max_bounces: 5, method, gate, seed, ..Default::default() }
}

/// Renders `scene` with `path` and with `direct` (BATCHES x spp each) and asserts agreement.
fn assert_direct_matches_path(label: &str, scene: &PreparedScene, gate: Gate, spp: u32, seed: u32) {
    let ctx = common::gpu();
    let path = common::render_films(ctx, scene, &settings(Method::Path, gate.clone(), seed), BATCHES, spp);
    let direct = common::render_films(ctx, scene, &settings(Method::Direct, gate, seed + 1), BATCHES, spp);
    assert!(direct.iter().any(|f| f.mean_rgb()[0] != 0.0), "{label}: direct renders black");
    common::assert_films_agree(label, &direct, &path, 8, ALPHA);
}

fn glossy_cornell_box() -> PreparedScene {
    let scene = load_gltf(&common::repo_path("assets/scenes/cornell_box_glossy.gltf")).unwrap();
    PreparedScene::new(scene).unwrap()
}

#[test]
fn direct_matches_path_at_the_steady_state() {
    assert_direct_matches_path("steady", &common::cornell_box(), Gate::None, 32, 100);
}

#[test]
fn direct_matches_path_at_two_box_gates() {
    let scene = common::cornell_box();
    assert_direct_matches_path("box [3.14, 3.19)", &scene, Gate::Box { start: 3.14, end: 3.19 }, 32, 110);
    assert_direct_matches_path("box [2.2, 2.6)", &scene, Gate::Box { start: 2.2, end: 2.6 }, 32, 120);
}

#[test]
fn direct_matches_path_on_the_glossy_cornell_box() {
    let scene = glossy_cornell_box();
    assert_direct_matches_path("glossy steady", &scene, Gate::None, 32, 130);
    assert_direct_matches_path("glossy box [3.0, 3.3)", &scene, Gate::Box { start: 3.0, end: 3.3 }, 32, 140);
}

#[test]
fn direct_matches_path_at_gaussian_cw_and_table_gates() {
    let scene = common::cornell_box();
    assert_direct_matches_path("gaussian 3.2, 0.05", &scene, Gate::Gaussian { mean: 3.2, sigma: 0.05 }, 32, 150);
    // 100 MHz: signed weights over the box's path lengths.
    let cw = Gate::Cw { frequency_hz: 1e8, phase_deg: 30.0 };
    assert_direct_matches_path("cw 100 MHz", &scene, cw, 32, 160);
    // A trapezoid with a negative lobe (signed table weights).
    let points = vec![(2.8, 0.0), (3.0, 1.0), (3.2, 1.0), (3.4, -0.5), (3.6, 0.0)];
    let table = Gate::Table { points, source: "trapezoid.csv".into() };
    assert_direct_matches_path("table trapezoid", &scene, table, 32, 165);
}

/// The Cornell box with a point light added near the floor (`point`) and every material
/// made double-sided (`double_sided`): the ceiling light then also shines upwards, and the
/// walls reflect on both faces.
fn modified_cornell_box(point: bool, double_sided: bool) -> PreparedScene {
    let mut scene = load_gltf(&common::repo_path("assets/scenes/cornell_box.gltf")).unwrap();
    if point {
        scene.point_lights.push(PointLight {
            position: glam::Vec3::new(0.2, -0.3, -0.1),
            intensity: glam::Vec3::new(0.3, 0.2, 0.1),
            spot: None,
        });
    }
    for m in &mut scene.materials {
        m.double_sided |= double_sided;
    }
    PreparedScene::new(scene).unwrap()
}

#[test]
fn direct_matches_path_with_a_point_light() {
    // Delta lights have no s = 0 strategy; area and point lights share the light CDF.
    assert_direct_matches_path("point + area lights", &modified_cornell_box(true, false), Gate::None, 32, 170);
}

#[test]
fn direct_matches_path_with_double_sided_materials() {
    assert_direct_matches_path("double-sided", &modified_cornell_box(false, true), Gate::None, 32, 180);
}

/// The camera pilot's per-pixel scales of the camera's density (`RenderSettings::
/// camera_pilot_spp`) move weight between the camera's strategies and light tracing and leave
/// the image as it was: `direct` with them against `path`, on the Cornell box lit also by a
/// point light beside the camera (a time-of-flight camera's illuminator), steady and behind a
/// box gate. The scales must differ across the image, from 1 to at least 2 (light tracing
/// keeps weight where the pilot found the camera's strategies noisy, and little elsewhere).
#[test]
fn direct_with_the_camera_pilots_scales_matches_path() {
    let ctx = common::gpu();
    let mut scene = load_gltf(&common::repo_path("assets/scenes/cornell_box.gltf")).unwrap();
    let camera = scene.camera;
    scene.point_lights.push(PointLight {
        position: camera.position + 0.1 * camera.right + 0.3 * camera.forward,
        intensity: glam::Vec3::new(4.0, 4.0, 3.0),
        spot: None,
    });
    let scene = PreparedScene::new(scene).unwrap();
    for (label, gate, seed) in
        [("steady", Gate::None, 300), ("box [3.3, 3.5)", Gate::Box { start: 3.3, end: 3.5 }, 310)]
    {
        let with_scales = RenderSettings { camera_pilot_spp: Some(16), ..settings(Method::Direct, gate.clone(), seed) };
        let mut tracer = BidirectionalTracer::new(ctx, &scene, &with_scales).unwrap();
        let direct = common::films_of(&mut tracer, BATCHES, 32);
        assert_eq!(tracer.camera_pilot_spp(), 16, "{label}: the pilot ran");
        let scales = tracer.camera_mis_scales();
        let (low, high) = scales.iter().fold((f32::MAX, 0.0f32), |(l, h), &s| (l.min(s), h.max(s)));
        assert!(low == 1.0 && high >= 2.0, "{label}: scales from {low} to {high}");
        let path = common::render_films(ctx, &scene, &settings(Method::Path, gate.clone(), seed + 1), BATCHES, 32);
        common::assert_films_agree(&format!("camera scales, {label}"), &direct, &path, 8, ALPHA);
        if gate != Gate::None {
            // combined: both halves weigh with the scales of its one pilot.
            let combined = RenderSettings {
                ellipsoidal_share: Some(1.0),
                connections_per_query: 1,
                ..RenderSettings { method: Method::Combined, ..with_scales }
            };
            let mut own = gatetrace::integrator::combined::CombinedTracer::new(ctx, &scene, &combined).unwrap();
            // A pilot's candidates take the scales of one camera pilot: adopted, they stay
            // (no pilot of its own runs at the first pass).
            let mut adopting = gatetrace::integrator::combined::CombinedTracer::new(ctx, &scene, &combined).unwrap();
            adopting.adopt_camera_mis_scales(scales, 16);
            adopting.render_pass(1).unwrap();
            assert_eq!((adopting.camera_mis_scales(), adopting.camera_pilot_spp()), (scales, 16), "{label}: adopted");
            let films = common::films_of(&mut own, BATCHES, 16);
            assert_eq!(own.camera_pilot_spp(), 16, "{label}: combined's pilot ran");
            assert_ne!(own.camera_mis_scales(), scales, "{label}: combined's own pilot measured its scales");
            common::assert_films_agree(&format!("combined with camera scales, {label}"), &films, &path, 8, ALPHA);
        }
    }
}

#[test]
fn transient_bins_sum_to_the_box_gate_over_their_range() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let transient = Gate::Transient { start: 1.94, width: 0.1, bins: 12 };
    let cube = common::render_films(ctx, &scene, &settings(Method::Direct, transient, 200), BATCHES, 32);
    let summed: Vec<Film> = cube.iter().map(Film::sum_bins).collect();
    let gate = Gate::Box { start: 1.94, end: 1.94 + 12.0 * 0.1 };
    let boxed = common::render_films(ctx, &scene, &settings(Method::Direct, gate, 201), BATCHES, 32);
    common::assert_films_agree("sum of 12 bins vs box [1.94, 3.14)", &summed, &boxed, 8, ALPHA);
}

#[test]
fn debug_strategy_images_sum_to_the_full_render() {
    // With the same seed every strategy sees the same subpaths, so the single-strategy images
    // (each MIS-weighted) add up to the full render up to f32 rounding.
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let base =
        RenderSettings { width: 16, height: 16, max_bounces: 3, method: Method::Direct, seed: 7, ..Default::default() };
    let render = |s: &RenderSettings| {
        let mut tracer = BidirectionalTracer::new(ctx, &scene, s).unwrap();
        tracer.render_samples(16).unwrap();
        tracer.film().unwrap()
    };
    let full = render(&base);
    let mut sum = vec![0.0f64; full.data.len()];
    for (s, t) in gatetrace::integrator::bidirectional::strategies(base.max_bounces) {
        let single = render(&RenderSettings { debug_strategy: Some((s, t)), ..base.clone() });
        for (acc, v) in sum.iter_mut().zip(&single.data) {
            *acc += *v as f64;
        }
    }
    let total: f64 = full.data.iter().map(|&v| v as f64).sum();
    assert!(total > 0.0);
    for (i, (a, b)) in sum.iter().zip(&full.data).enumerate() {
        let tolerance = 1e-4 * (*b as f64).abs() + 1e-7;
        assert!((a - *b as f64).abs() <= tolerance, "element {i}: strategies sum to {a}, full render {b}");
    }
}

#[test]
fn zero_weight_connections_trace_no_shadow_ray() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let render = |gate: Gate| {
        let s = RenderSettings { stats: true, ..settings(Method::Direct, gate, 300) };
        let mut tracer = BidirectionalTracer::new(ctx, &scene, &s).unwrap();
        tracer.render_samples(4).unwrap();
        tracer.strategy_stats().unwrap().to_vec()
    };
    let steady = render(Gate::None);
    let gated = render(Gate::Box { start: 3.14, end: 3.19 });
    let total = |st: &[gatetrace::integrator::StrategyStats],
                 f: fn(&gatetrace::integrator::StrategyStats) -> u64|
     -> u64 { st.iter().map(f).sum() };
    // Steady state: nothing is skipped; every shadow ray belongs to an evaluated connection.
    assert_eq!(total(&steady, |s| s.skipped_by_gate), 0);
    for st in steady.iter().chain(&gated) {
        assert!(st.shadow_rays + st.skipped_by_gate <= st.evaluated, "{st:?}");
        if st.s == 0 {
            assert_eq!(st.shadow_rays, 0, "s = 0 needs no shadow ray: {st:?}");
        }
    }
    // A 5 cm gate drops most connections before their shadow rays; the direct light (1,1) and
    // (0,2) paths (at most ~2.1 m long) are all dropped.
    let (evaluated, skipped, rays) =
        (total(&gated, |s| s.evaluated), total(&gated, |s| s.skipped_by_gate), total(&gated, |s| s.shadow_rays));
    println!("gate [3.14, 3.19): {evaluated} connections, {skipped} skipped by the gate, {rays} shadow rays");
    assert!(skipped as f64 > 0.8 * evaluated as f64, "{skipped} of {evaluated} skipped");
    assert!(rays < total(&steady, |s| s.shadow_rays) / 5);
    for st in gated.iter().filter(|st| st.s + st.t == 2) {
        assert_eq!(st.skipped_by_gate, st.evaluated, "{st:?}");
    }
}

#[test]
fn bidirectional_films_are_the_same_bits_however_additions_are_ordered_and_grouped() {
    // Light-tracing splats are added with integer atomics to exact fixed-point sums: the same
    // samples give the same bits whatever order the GPU runs the additions in, and however
    // they are grouped into passes.
    let ctx = common::gpu();
    let scene = common::cornell_box();
    for (method, gate) in [
        (Method::Direct, Gate::None),
        (Method::Ellipsoidal, Gate::Box { start: 3.14, end: 3.19 }),
        (Method::Ellipsoidal, Gate::Transient { start: 3.0, width: 0.1, bins: 6 }),
    ] {
        let base = RenderSettings {
            width: 16,
            height: 16,
            max_bounces: 3,
            method,
            gate: gate.clone(),
            seed: 9,
            ..Default::default()
        };
        let render = |per_pass: u32| {
            let s = RenderSettings { samples_per_pass: Some(per_pass), ..base.clone() };
            let mut tracer = BidirectionalTracer::new(ctx, &scene, &s).unwrap();
            tracer.render_samples(48).unwrap();
            tracer.film().unwrap()
        };
        let (a, b, c) = (render(48), render(48), render(4));
        assert!(a.mean_rgb()[0] > 0.0);
        assert!(a.data == b.data, "{} {}: two runs differ", method.name(), gate.describe());
        assert!(a.data == c.data, "{} {}: passes of 48 and of 4 differ", method.name(), gate.describe());
    }
}

#[test]
fn accumulate_and_splats_leave_no_contribution_behind() {
    // accumulate reads a slot's contributions only up to the strategies its subpaths reach, and
    // splat_light_paths its splats only up to its light subpath's vertices and the end splats of
    // connect_spherical; each clears what it reads: one written beyond would stay, and be added
    // in a later wave. After each pass no contribution or splat may hold light (one whose shadow
    // ray was blocked keeps its path length, harmlessly): direct, ellipsoidal with its K
    // connections queued for shadow rays (the fence's BVH can stop traversals) and with media
    // (every ray queued), ellipsoidal behind a transient gate, and ellipsoidal in fog with a
    // directional light and with the box's light seen directly (connect_spherical splats at the
    // end of a slot's range).
    let ctx = common::gpu();
    let load_with = |name: &str, options: &gatetrace::scene::LoadOptions| {
        PreparedScene::new(gatetrace::scene::load_scene_with(&common::repo_path(name), options).unwrap()).unwrap()
    };
    let load = |name: &str| load_with(name, &Default::default());
    let (cornell, fence, fog) =
        (common::cornell_box(), load("assets/scenes/fence.gltf"), load("assets/scenes/fog_box.xml"));
    let sunlit_fog = load_with(
        "assets/scenes/cornell_box_directional.gltf",
        &gatetrace::scene::LoadOptions {
            fog: Some(gatetrace::scene::MediumDesc::parse_fog("0.2").unwrap()),
            ..Default::default()
        },
    );
    let foggy_box = load_with(
        "assets/scenes/cornell_box.gltf",
        &gatetrace::scene::LoadOptions {
            fog: Some(gatetrace::scene::MediumDesc::parse_fog("0.2").unwrap()),
            ..Default::default()
        },
    );
    let gated = Gate::Box { start: 3.14, end: 3.3 };
    for (label, scene, method, gate, k) in [
        ("box direct", &cornell, Method::Direct, Gate::None, 1),
        ("fence ellipsoidal", &fence, Method::Ellipsoidal, Gate::Box { start: 11.3, end: 11.6 }, 4),
        ("fog ellipsoidal", &fog, Method::Ellipsoidal, gated.clone(), 4),
        (
            "box ellipsoidal transient",
            &cornell,
            Method::Ellipsoidal,
            Gate::Transient { start: 3.0, width: 0.1, bins: 6 },
            1,
        ),
        ("sunlit fog ellipsoidal", &sunlit_fog, Method::Ellipsoidal, Gate::Box { start: 3.0, end: 3.5 }, 2),
        // The light seen directly through the fog (connect_spherical's last splat).
        (
            "box in fog ellipsoidal transient",
            &foggy_box,
            Method::Ellipsoidal,
            Gate::Transient { start: 2.0, width: 0.25, bins: 12 },
            2,
        ),
    ] {
        let settings = RenderSettings {
            width: 16,
            height: 16,
            max_bounces: 3,
            method,
            gate,
            connections_per_query: k,
            ..Default::default()
        };
        let mut tracer = BidirectionalTracer::new(ctx, scene, &settings).unwrap();
        for _ in 0..2 {
            tracer.render_samples(2).unwrap();
            // Contributions are 4 words (radiance, path length), splats 8 (radiance, path
            // length, pixel, padding).
            for (name, words) in [("contributions", 4), ("splats", 8)] {
                let buffer = tracer.resources().get(name).unwrap();
                let left: Vec<f32> =
                    gatetrace::gpu::resources::read_buffer(ctx, buffer, (buffer.size() / 4) as usize).unwrap();
                let nonzero: Vec<(usize, &[f32])> =
                    left.chunks_exact(words).enumerate().filter(|(_, c)| c[..3].iter().any(|&x| x != 0.0)).collect();
                assert!(
                    nonzero.is_empty(),
                    "{label}: {} of {} {name} left after a pass: {:?}",
                    nonzero.len(),
                    left.len() / words,
                    &nonzero[..nonzero.len().min(4)]
                );
            }
        }
        assert!(tracer.film().unwrap().mean_rgb()[0] > 0.0, "{label}: the film is black");
    }
}

/// Renders `scene` with `direct` and with `ellipsoidal` (BATCHES x spp each) and asserts
/// agreement.
fn assert_ellipsoidal_matches_direct(label: &str, scene: &PreparedScene, gate: Gate, spp: u32, seed: u32) {
    let ctx = common::gpu();
    let direct = common::render_films(ctx, scene, &settings(Method::Direct, gate.clone(), seed), BATCHES, spp);
    let ellipsoidal = common::render_films(ctx, scene, &settings(Method::Ellipsoidal, gate, seed + 1), BATCHES, spp);
    assert!(ellipsoidal.iter().any(|f| f.mean_rgb()[0] != 0.0), "{label}: ellipsoidal renders black");
    common::assert_films_agree(label, &ellipsoidal, &direct, 8, ALPHA);
}

#[test]
fn ellipsoidal_matches_direct_at_box_gates() {
    let scene = common::cornell_box();
    assert_ellipsoidal_matches_direct(
        "ellipsoidal box [3.14, 3.19)",
        &scene,
        Gate::Box { start: 3.14, end: 3.19 },
        32,
        400,
    );
    assert_ellipsoidal_matches_direct(
        "ellipsoidal box [2.0, 2.6)",
        &scene,
        Gate::Box { start: 2.0, end: 2.6 },
        32,
        410,
    );
}

#[test]
fn ellipsoidal_matches_direct_at_a_gaussian_gate_and_on_the_glossy_box() {
    assert_ellipsoidal_matches_direct(
        "ellipsoidal gaussian 3.2, 0.05",
        &common::cornell_box(),
        Gate::Gaussian { mean: 3.2, sigma: 0.05 },
        32,
        420,
    );
    assert_ellipsoidal_matches_direct(
        "ellipsoidal glossy box [3.0, 3.3)",
        &glossy_cornell_box(),
        Gate::Box { start: 3.0, end: 3.3 },
        32,
        430,
    );
}

/// CW codes: a Hamiltonian code (zero over a third of its period, where connections trace no
/// shadow ray) through direct connections, and the depth-selective code of the paper's Fig. 9
/// (a trapezoid about 20 ps wide at half height on a floor of 1/32; 4.7 GHz) through ellipsoidal
/// ones, whose target lengths follow it.
#[test]
fn bidirectional_methods_match_at_cw_codes() {
    let scene = common::cornell_box();
    assert_direct_matches_path("direct cw ham3 300 MHz", &scene, Gate::parse("cw:300e6,40,ham3").unwrap(), 32, 480);
    assert_ellipsoidal_matches_direct(
        "ellipsoidal cw depthsel 4.7 GHz",
        &scene,
        Gate::parse("cw:4.7e9,-30,depthsel").unwrap(),
        32,
        490,
    );
}

/// Transient gates draw target lengths bin by bin (stratified); with at least as many samples
/// per pixel as bins each bin is divided by its own samples (32 spp over 6 bins: 5 rounds and 2
/// bins more), with fewer by their expected number (32 spp over 40 bins). Both are unbiased.
#[test]
fn ellipsoidal_matches_direct_per_bin_of_transient_gates() {
    let scene = common::cornell_box();
    assert_ellipsoidal_matches_direct(
        "ellipsoidal transient 3.0 + 6 x 0.1",
        &scene,
        Gate::Transient { start: 3.0, width: 0.1, bins: 6 },
        32,
        460,
    );
    assert_ellipsoidal_matches_direct(
        "ellipsoidal transient 2.5 + 40 x 0.02",
        &scene,
        Gate::Transient { start: 2.5, width: 0.02, bins: 40 },
        32,
        470,
    );
}

#[test]
fn ellipsoidal_with_four_connections_per_query_matches_direct() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let gate = Gate::Box { start: 3.14, end: 3.19 };
    let direct = common::render_films(ctx, &scene, &settings(Method::Direct, gate.clone(), 440), BATCHES, 32);
    let four = RenderSettings { connections_per_query: 4, ..settings(Method::Ellipsoidal, gate, 441) };
    let ellipsoidal = common::render_films(ctx, &scene, &four, BATCHES, 16);
    common::assert_films_agree("ellipsoidal K = 4 box [3.14, 3.19)", &ellipsoidal, &direct, 8, ALPHA);
}

/// The query roulette (`--query-roulette`): a sample makes each query for a path of two or
/// more scattering vertices with probability p and weighs it 1 / p, which leaves the image's
/// expectation as it was, on the box and the glossy box.
#[test]
fn ellipsoidal_with_a_query_roulette_matches_direct() {
    let ctx = common::gpu();
    for (label, scene, gate, seed) in [
        ("box [3.14, 3.19)", common::cornell_box(), Gate::Box { start: 3.14, end: 3.19 }, 446),
        ("glossy box [3.0, 3.3)", glossy_cornell_box(), Gate::Box { start: 3.0, end: 3.3 }, 448),
    ] {
        let direct = common::render_films(ctx, &scene, &settings(Method::Direct, gate.clone(), seed), BATCHES, 32);
        let rouletted = RenderSettings { query_roulette: Some(0.25), ..settings(Method::Ellipsoidal, gate, seed + 1) };
        let ellipsoidal = common::render_films(ctx, &scene, &rouletted, BATCHES, 32);
        common::assert_films_agree(
            &format!("ellipsoidal, query roulette 0.25, {label}"),
            &ellipsoidal,
            &direct,
            8,
            ALPHA,
        );
    }
}

/// The roulette keeps the one-bounce queries (s + t = 2 in the kernels' count, (1, 2) in the
/// statistics) and a binomial share p of the others: from the same subpaths (same seed), p = 1/4
/// makes as many of the former and a quarter of the latter, within four standard deviations.
#[test]
fn the_query_roulette_keeps_its_share_of_the_multi_bounce_queries() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let gate = Gate::Box { start: 3.14, end: 3.19 };
    let queries = |p: f32| {
        let s =
            RenderSettings { stats: true, query_roulette: Some(p), ..settings(Method::Ellipsoidal, gate.clone(), 450) };
        let mut tracer = BidirectionalTracer::new(ctx, &scene, &s).unwrap();
        tracer.render_samples(8).unwrap();
        let stats = tracer.strategy_stats().unwrap().to_vec();
        let count = |one: bool| -> u64 {
            stats
                .iter()
                .filter(|st| st.s >= 1 && (st.s + st.t == 3) == one && st.s + st.t >= 3)
                .map(|st| st.evaluated)
                .sum()
        };
        (count(true), count(false))
    };
    let (one_all, multi_all) = queries(1.0);
    let (one_quarter, multi_quarter) = queries(0.25);
    println!("one-bounce queries {one_all} and {one_quarter}; others {multi_all} and {multi_quarter}");
    assert!(multi_all > 1000, "too few multi-bounce queries to measure: {multi_all}");
    assert_eq!(one_all, one_quarter, "the one-bounce queries are all made");
    let (n, p) = (multi_all as f64, 0.25);
    let sigma = (n * p * (1.0 - p)).sqrt();
    assert!(
        (multi_quarter as f64 - n * p).abs() < 4.0 * sigma,
        "{multi_quarter} of {multi_all} multi-bounce queries made, expected {} +- {sigma:.1}",
        n * p
    );
}

/// The roulette's pilot measures the rouletted queries' variance from the differences of
/// batches of the same samples at p = 1 and p = 1/8 (`query_roulette::PairedBatches`), which
/// holds only if the roulette changes nothing else a sample draws. With at most two scattering
/// vertices, from one seed: where the image at p = 1 equals the one-bounce image (no two-bounce
/// query added light there), so does the image at p = 1/8; elsewhere the light p = 1/8 adds,
/// divided by 8, is a part of what p = 1 adds (the queries it kept, each as at p = 1).
#[test]
fn the_query_roulette_changes_nothing_but_the_rouletted_queries() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let gate = Gate::Box { start: 3.14, end: 3.15 };
    let film = |max_bounces: u32, p: f32| {
        let s = RenderSettings {
            max_bounces,
            query_roulette: Some(p),
            width: 16,
            height: 16,
            ..settings(Method::Ellipsoidal, gate.clone(), 452)
        };
        common::render_films(ctx, &scene, &s, 1, 4).remove(0).data
    };
    let (one_bounce, all, eighth) = (film(1, 1.0), film(2, 1.0), film(2, 0.125));
    let (mut added, mut kept) = (0, 0);
    for ((&base, &a), &e) in one_bounce.iter().zip(&all).zip(&eighth) {
        if a == base {
            assert_eq!(e, base, "p = 1/8 changed a value that no two-bounce query lit");
            continue;
        }
        added += 1;
        let (from_all, from_kept) = (a as f64 - base as f64, (e as f64 - base as f64) / 8.0);
        assert!(from_all > 0.0, "a box gate's two-bounce light is positive: {a} against {base}");
        assert!(
            (-1e-6 * from_all..=from_all * (1.0 + 1e-4) + 1e-9).contains(&from_kept),
            "p = 1/8 added {from_kept} x 8 where p = 1 added {from_all}"
        );
        kept += (from_kept > 0.0) as u32;
    }
    println!("{added} values lit by two-bounce queries, {kept} of them by queries p = 1/8 kept");
    assert!(added > 100 && kept > 10, "too little two-bounce light to check: {added} values, {kept} kept");
}

/// The needle guard leaves out a set of connections that grows with the guard, and every
/// contribution of a box gate is non-negative: so the bias of the default guard (1e-6) is at
/// most that of a guard 10^4 times wider, which this bounds by the noise of the comparison with
/// `direct`. The length guard (1e-5) drops points whose f32 section failed; on the Cornell box
/// it should drop (almost) none. (At 1e-7, below f32 resolution, it drops 3% of the points and
/// the image is 3% dark: a guard must stay well above the measured errors of the stress test.)
#[test]
fn ellipsoidal_with_a_much_wider_needle_guard_still_matches_direct() {
    use gatetrace::integrator::EllipsoidGuards;
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let gate = Gate::Box { start: 3.14, end: 3.19 };
    let direct = common::render_films(ctx, &scene, &settings(Method::Direct, gate.clone(), 450), BATCHES, 32);
    let wide = RenderSettings {
        ellipsoid_guards: EllipsoidGuards { needle: 1e-2, ..Default::default() },
        stats: true,
        ..settings(Method::Ellipsoidal, gate, 451)
    };
    let mut tracer = BidirectionalTracer::new(ctx, &scene, &wide).unwrap();
    let films = common::films_of(&mut tracer, BATCHES, 32);
    println!("{}", tracer.stats_report().unwrap().unwrap());
    let queries: u64 = tracer.strategy_stats().unwrap().iter().map(|s| s.evaluated).sum();
    let (needles, off_length) = tracer.guarded();
    assert!(needles > 0, "the needle guard of 1e-2 left nothing out");
    assert!(
        (off_length as f64) < 1e-6 * queries as f64,
        "the length guard dropped {off_length} of {queries} connections"
    );
    common::assert_films_agree("ellipsoidal needle guard 1e-2 box [3.14, 3.19)", &films, &direct, 8, ALPHA);
}

/// `combined` (direct and ellipsoidal connections in one estimator, family_mis.wesl): its image
/// is the sum of its two halves, whose weights sum to one over both families only if both
/// kernels weigh every path alike; against `direct` and `path`, independent estimators, at a
/// narrow box gate with K = 4 (the ratio of the families' samples then 4), a wide one, on the
/// glossy box, with a point light (no s = 0 strategy), per bin of a stratified transient gate,
/// with the halves' samples split 1 : 4 and 4 : 1 (the weights then count them so), and with a
/// query roulette of 1/4 (the weights of both halves then count a quarter of the multi-bounce
/// queries).
#[test]
fn combined_matches_direct_and_path() {
    let ctx = common::gpu();
    let (box_scene, glossy, point) = (common::cornell_box(), glossy_cornell_box(), modified_cornell_box(true, false));
    let narrow = Gate::Box { start: 3.14, end: 3.19 };
    let cases = [
        ("combined K = 4 box [3.14, 3.19)", &box_scene, narrow.clone(), 4, 1.0, Method::Direct, None),
        ("combined box [2.0, 3.0)", &box_scene, Gate::Box { start: 2.0, end: 3.0 }, 1, 1.0, Method::Path, None),
        ("combined glossy box [3.0, 3.3)", &glossy, Gate::Box { start: 3.0, end: 3.3 }, 4, 1.0, Method::Path, None),
        (
            "combined point + area lights box [2.6, 3.2)",
            &point,
            Gate::Box { start: 2.6, end: 3.2 },
            4,
            1.0,
            Method::Direct,
            None,
        ),
        (
            "combined transient 3.0 + 6 x 0.1",
            &box_scene,
            Gate::Transient { start: 3.0, width: 0.1, bins: 6 },
            4,
            1.0,
            Method::Direct,
            None,
        ),
        (
            "combined 1 ellipsoidal : 4 direct box [3.14, 3.19)",
            &box_scene,
            narrow.clone(),
            4,
            0.25,
            Method::Direct,
            None,
        ),
        (
            "combined 4 ellipsoidal : 1 direct glossy [3.0, 3.3)",
            &glossy,
            Gate::Box { start: 3.0, end: 3.3 },
            1,
            4.0,
            Method::Path,
            None,
        ),
        ("combined, query roulette 0.25, box [3.14, 3.19)", &box_scene, narrow, 4, 1.0, Method::Direct, Some(0.25)),
        (
            "combined, query roulette 0.25, glossy [3.0, 3.3)",
            &glossy,
            Gate::Box { start: 3.0, end: 3.3 },
            4,
            1.0,
            Method::Path,
            Some(0.25),
        ),
    ];
    for (i, (label, scene, gate, k, share, reference, roulette)) in cases.into_iter().enumerate() {
        let seed = 700 + 10 * i as u32;
        let s = RenderSettings {
            connections_per_query: k,
            ellipsoidal_share: Some(share),
            query_roulette: roulette,
            ..settings(Method::Combined, gate.clone(), seed)
        };
        let combined = common::render_films(ctx, scene, &s, BATCHES, 16);
        assert!(combined.iter().any(|f| f.mean_rgb()[0] != 0.0), "{label}: combined renders black");
        let reference = common::render_films(ctx, scene, &settings(reference, gate, seed + 1), BATCHES, 32);
        common::assert_films_agree(label, &combined, &reference, 8, ALPHA);
    }
}

/// Where one family alone is ahead of both halves together, a combined render traces it alone
/// (`Allocation::alone`): on the box at a 1 m gate `direct` is several times ahead of
/// `ellipsoidal`, and of both halves, whose samples also pay for the family weights; the render
/// is then `direct`'s own from the same seed, bit for bit. At 1 mm `ellipsoidal` is hundreds of
/// times ahead of `direct`, so far that the pilot traces `ellipsoidal` alone without measuring
/// the halves (`auto::EARLY_STOP_RATIO`); a short time budget does not measure them either
/// (`combined::HALVES_PILOT_SHARE`). With a time budget, where the pilot would weigh a
/// query roulette for both halves, `ellipsoidal` alone makes every query.
#[test]
fn combined_traces_a_family_alone_where_its_pilot_finds_it_ahead() {
    use gatetrace::integrator::{Budget, render};
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let wide = RenderSettings {
        connections_per_query: 4,
        ..settings(Method::Combined, Gate::Box { start: 3.14, end: 4.14 }, 41)
    };
    let output = render(ctx, &scene, &wide, Budget::Samples(64), |_| {}).unwrap();
    let allocation = output.allocation.expect("a combined render reports its allocation");
    assert_eq!(allocation.alone, Some(Method::Direct), "{}", allocation.reason);
    let direct = RenderSettings { method: Method::Direct, connections_per_query: 1, ..wide.clone() };
    let same = render(ctx, &scene, &direct, Budget::Samples(64), |_| {}).unwrap().film;
    assert!(same.mean_rgb()[0] > 0.0, "light reaches the gate");
    assert!(output.film.data == same.data, "the combined render is direct's own image");
    // A second of rendering cannot pay for weighing the halves (on lavapipe the families' first
    // batches alone take more than a fiftieth of it): the families render more batches instead.
    let short = render(ctx, &scene, &wide, Budget::Time(std::time::Duration::from_secs(1)), |_| {}).unwrap();
    let allocation = short.allocation.expect("a combined render reports its allocation");
    assert_eq!(allocation.alone, Some(Method::Direct), "{}", allocation.reason);
    assert!(allocation.reason.contains("each family alone"), "the halves are not measured: {}", allocation.reason);
    assert!(!allocation.reason.contains("(direct half)"), "the halves are not measured: {}", allocation.reason);
    let narrow = RenderSettings { gate: Gate::Box { start: 3.14, end: 3.141 }, ..wide };
    let output = render(ctx, &scene, &narrow, Budget::Time(std::time::Duration::from_secs(1)), |_| {}).unwrap();
    let allocation = output.allocation.expect("a combined render reports its allocation");
    assert_ne!(allocation.alone, Some(Method::Direct), "{}", allocation.reason);
    assert_eq!(allocation.alone, Some(Method::Ellipsoidal), "{}", allocation.reason);
    assert_eq!(
        allocation.query_roulette, 1.0,
        "the pilot weighs ellipsoidal alone making every query: {}",
        allocation.reason
    );
    // Traced alone, ellipsoidal chooses its roulette as --method ellipsoidal does.
    let roulette = output.roulette.expect("a combined render with ellipsoidal queries reports its roulette");
    assert!(roulette.reason.starts_with("pilot on") && roulette.pilot_seconds > 0.0, "{}", roulette.reason);
    assert!(allocation.reason.contains("each family alone"), "the halves are not measured: {}", allocation.reason);
    assert!(allocation.reason.ends_with("ellipsoidal alone, query roulette 1"), "{}", allocation.reason);
}

/// A combined render's direct half takes its weights from sums formed once per slot
/// (connect_direct family_weight_from_sums); with statistics on, each is checked against the
/// walk of its whole path that the ellipsoidal half's weights also take (family_weight): on the
/// box at a narrow and a wide gate, with a point light (no s = 0 strategy), on the glossy box,
/// at a ratio of 16 and with a query roulette of 1/4, none differs.
#[test]
fn combined_direct_weights_from_sums_equal_the_walk_of_each_path() {
    use gatetrace::integrator::bidirectional::{Family, FamilyRole};
    let ctx = common::gpu();
    let (box_scene, glossy, point) = (common::cornell_box(), glossy_cornell_box(), modified_cornell_box(true, false));
    let narrow = Gate::Box { start: 3.14, end: 3.19 };
    for (label, scene, gate, ratio, roulette) in [
        ("box [3.14, 3.19)", &box_scene, narrow.clone(), 4.0, None),
        ("box [2.0, 3.0)", &box_scene, Gate::Box { start: 2.0, end: 3.0 }, 1.0, None),
        ("point + area lights [2.6, 3.2)", &point, Gate::Box { start: 2.6, end: 3.2 }, 16.0, None),
        ("glossy box [3.0, 3.3), roulette 1/4", &glossy, Gate::Box { start: 3.0, end: 3.3 }, 4.0, Some(0.25)),
    ] {
        let s = RenderSettings { stats: true, query_roulette: roulette, ..settings(Method::Direct, gate, 31) };
        let role = FamilyRole { family: Family::Direct, ratio, medium_ratio: ratio / 4.0 };
        let mut tracer = BidirectionalTracer::with_family(ctx, scene, &s, Some(role)).unwrap();
        tracer.render_samples(16).unwrap();
        let (checked, differing) = tracer.family_weights_checked();
        assert_eq!(differing, 0, "{label}: {differing} of {checked} weights differ from the walk of their path");
        assert!(checked > 1000, "{label}: only {checked} weights checked");
        println!("{label}: {checked} weights checked");
    }
}

/// What `combined` cannot render yet is refused with a clear error: no gate, a directional
/// light, checkpoints.
#[test]
fn combined_refuses_what_it_cannot_render() {
    let ctx = common::gpu();
    let error =
        |scene: &PreparedScene, s: &RenderSettings| match gatetrace::integrator::create_integrator(ctx, scene, s) {
            Ok(_) => panic!("combined accepted {s:?}"),
            Err(e) => e.to_string(),
        };
    let no_gate = settings(Method::Combined, Gate::None, 1);
    assert!(error(&common::cornell_box(), &no_gate).contains("needs a gate"));
    let directional =
        PreparedScene::new(load_gltf(&common::repo_path("assets/scenes/cornell_box_directional.gltf")).unwrap())
            .unwrap();
    let gated = settings(Method::Combined, Gate::Box { start: 3.0, end: 3.2 }, 1);
    assert!(error(&directional, &gated).contains("directional lights"));
    let mut tracer = gatetrace::integrator::create_integrator(ctx, &common::cornell_box(), &gated).unwrap();
    tracer.render_samples(1).unwrap();
    let why = tracer.save_state().unwrap_err().to_string();
    assert!(why.contains("--method combined cannot"), "{why}");
}
