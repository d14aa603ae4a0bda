//! The thin-lens camera, spot lights and directional lights against peer references (Mitsuba
//! 3.9.1 + mitransient 1.3.1: `thinlens` sensor, `spot` and `directional` emitters;
//! tests/data/cornell_box_{thin_lens,spot,directional}_peer/README.md). Thin lens and spot,
//! through every method: `path` for the steady
//! image and the transient cube, `direct` and `ellipsoidal` for a box gate (`direct` at the
//! steady state for the thin lens, see below); the directional light: `path` and `direct`
//! against the peer's steady image, `direct` against `path` and `ellipsoidal` against `direct`
//! behind gates. Image means per
//! channel (|z| < 4), 8x8-pixel blocks and transient bins (Sidak-corrected) from the variance
//! measured over independent batches on our side and the peer's variance of its mean.

mod common;

use common::peer::{check_image, check_transient};
use gatetrace::film::Gate;
use gatetrace::integrator::{Method, RenderSettings};
use gatetrace::scene::{PreparedScene, load_gltf};

const BATCHES: usize = 16;

fn scene(name: &str) -> PreparedScene {
    PreparedScene::new(load_gltf(&common::repo_path(&format!("assets/scenes/{name}.gltf"))).unwrap()).unwrap()
}

/// The peer's settings: 64x64, at most 5 bounces (max_depth 6), no Russian roulette.
fn settings(method: Method, gate: Gate, seed: u32) -> RenderSettings {
    RenderSettings { width: 64, height: 64, max_bounces: 5, method, gate, seed, ..Default::default() }
}

/// Renders `name` with `method` (BATCHES x spp) and compares it with the peer's `key`.
fn check(name: &str, method: Method, gate: Gate, spp: u32, seed: u32, key: &str) {
    let ctx = common::gpu();
    let films = common::render_films(ctx, &scene(name), &settings(method, gate, seed), BATCHES, spp);
    let label = format!("{name}_{}_{key}", method.name());
    check_image(&label, &films, &format!("{name}_peer/{key}"));
}

#[test]
fn thin_lens_steady_image_matches_peer() {
    check("cornell_box_thin_lens", Method::Path, Gate::None, 64, 1, "steady");
}

/// `direct` is compared at the steady state: at the box gate, the light of a pixel on the
/// lens-blurred lower edge of the gated band comes from the few lens points whose paths are
/// short enough (about one sample in a thousand, each worth ~1e-5), so 16 batches of 64 spp can
/// all miss an 8x8 block whose peer mean is ~1e-6 (1/4000 of the image mean), and a z-score
/// from batch variances is then meaningless (zero over zero). `ellipsoidal`, whose paths all
/// have the gate's lengths, samples those edges densely and is compared at the gate.
#[test]
fn thin_lens_steady_image_matches_peer_with_direct_connections() {
    check("cornell_box_thin_lens", Method::Direct, Gate::None, 32, 2, "steady");
}

#[test]
fn thin_lens_box_gate_matches_peer_with_ellipsoidal_connections() {
    check("cornell_box_thin_lens", Method::Ellipsoidal, Gate::Box { start: 3.1, end: 3.15 }, 16, 3, "gate_3_1_3_15");
}

#[test]
fn thin_lens_transient_cube_matches_peer_per_bin() {
    let ctx = common::gpu();
    let gate = Gate::Transient { start: 1.9, width: 0.1, bins: 20 };
    let films =
        common::render_films(ctx, &scene("cornell_box_thin_lens"), &settings(Method::Path, gate, 4), BATCHES, 64);
    check_transient("cornell_box_thin_lens_transient", &films, "cornell_box_thin_lens_peer/transient_1_9_step_0_1", 20);
}

#[test]
fn spot_light_steady_image_matches_peer() {
    check("cornell_box_spot", Method::Path, Gate::None, 64, 11, "steady");
}

#[test]
fn spot_light_box_gate_matches_peer_with_direct_connections() {
    check("cornell_box_spot", Method::Direct, Gate::Box { start: 3.6, end: 3.65 }, 64, 12, "gate_3_6_3_65");
}

#[test]
fn spot_light_box_gate_matches_peer_with_ellipsoidal_connections() {
    check("cornell_box_spot", Method::Ellipsoidal, Gate::Box { start: 3.6, end: 3.65 }, 16, 13, "gate_3_6_3_65");
}

#[test]
fn spot_light_transient_cube_matches_peer_per_bin() {
    let ctx = common::gpu();
    let gate = Gate::Transient { start: 2.8, width: 0.1, bins: 20 };
    let films = common::render_films(ctx, &scene("cornell_box_spot"), &settings(Method::Path, gate, 14), BATCHES, 64);
    let bins =
        check_transient("cornell_box_spot_transient", &films, "cornell_box_spot_peer/transient_2_8_step_0_1", 20);
    // Nothing arrives before the shortest path (spot -> floor -> camera).
    assert!(bins.iter().any(|b| b.0 > 0.0), "the spot light lights the cube");
}

/// A directional light (a plane wave through the open front of the ceiling): `path` and
/// `direct` against the peer's steady image (mitransient times directional light differently,
/// so its transients are no reference), and against each other at a box gate.
#[test]
fn directional_light_steady_image_matches_peer() {
    check("cornell_box_directional", Method::Path, Gate::None, 64, 21, "steady");
}

#[test]
fn directional_light_steady_image_matches_peer_with_direct_connections() {
    check("cornell_box_directional", Method::Direct, Gate::None, 32, 22, "steady");
}

/// Also with glossy walls (GGX, metallic 0.5, roughness 0.4), whose BSDFs depend on the
/// direction light arrives from. (Light subpaths from the beam's disk carry only about 1 % of
/// the MIS weight here, so a wrong arrival direction at their first vertex would hide in the
/// noise: kept right by construction in connect_direct, not caught by this test.)
#[test]
fn directional_light_direct_matches_path_at_a_box_gate() {
    let ctx = common::gpu();
    let mut glossy = load_gltf(&common::repo_path("assets/scenes/cornell_box_directional.gltf")).unwrap();
    for m in &mut glossy.materials {
        (m.metallic, m.roughness) = (0.5, 0.4);
    }
    let gate = Gate::Box { start: 3.6, end: 3.7 };
    let small = |method, seed| RenderSettings { width: 32, height: 32, ..settings(method, gate.clone(), seed) };
    for (label, scene, seed) in [
        ("directional box [3.6, 3.7)", scene("cornell_box_directional"), 23),
        ("glossy directional box [3.6, 3.7)", PreparedScene::new(glossy).unwrap(), 33),
    ] {
        let path = common::render_films(ctx, &scene, &small(Method::Path, seed), BATCHES, 64);
        let direct = common::render_films(ctx, &scene, &small(Method::Direct, seed + 1), BATCHES, 64);
        assert!(path.iter().any(|f| f.mean_rgb()[0] > 0.0), "{label}: the gate holds light");
        common::assert_films_agree(label, &direct, &path, 8, common::peer::ALPHA);
    }
}

/// `ellipsoidal` with a directional light against `direct`: its connections from camera
/// vertices to the light along the beam (in place of the spheroids next to the light, which
/// would be paraboloids) and its spheroids beyond, at a box gate on the plain and the glossy box,
/// and on a transient of 6 bins at a sample count that is no multiple of 6, so that each bin's
/// share of the stratified target lengths differs (the connections to the light land in the
/// light-tracing film, which no per-bin visit count may divide). Seen from 2 m, the box lies in
/// a beam so wide (the sphere bounding the scene holds the camera) that light subpaths carry
/// almost none of the MIS weight; seen from inside with a wide lens, they carry much of it, so
/// the connections to the light must take exactly the weight of the strategy they replace.
#[test]
fn directional_light_ellipsoidal_matches_direct() {
    let ctx = common::gpu();
    let mut glossy = load_gltf(&common::repo_path("assets/scenes/cornell_box_directional.gltf")).unwrap();
    for m in &mut glossy.materials {
        (m.metallic, m.roughness) = (0.5, 0.4);
    }
    let mut inside = load_gltf(&common::repo_path("assets/scenes/cornell_box_directional.gltf")).unwrap();
    inside.camera.position = glam::Vec3::new(0.0, 0.0, 0.45);
    inside.camera.yfov = 1.7;
    let box_gate = Gate::Box { start: 3.6, end: 3.7 };
    let transient = Gate::Transient { start: 3.5, width: 0.05, bins: 6 };
    let inside_transient = Gate::Transient { start: 1.0, width: 0.25, bins: 8 };
    for (label, scene, gate, spp, seed) in [
        ("ellipsoidal, directional box [3.6, 3.7)", scene("cornell_box_directional"), box_gate.clone(), 16, 25),
        ("ellipsoidal, glossy directional box [3.6, 3.7)", PreparedScene::new(glossy).unwrap(), box_gate, 16, 35),
        ("ellipsoidal, directional transient 3.5 + 6 x 0.05", scene("cornell_box_directional"), transient, 13, 45),
        (
            "ellipsoidal, directional, inside, transient 1 + 8 x 0.25",
            PreparedScene::new(inside).unwrap(),
            inside_transient,
            13,
            55,
        ),
    ] {
        let small = |method, seed| RenderSettings { width: 32, height: 32, ..settings(method, gate.clone(), seed) };
        let direct = common::render_films(ctx, &scene, &small(Method::Direct, seed), BATCHES, 64);
        let ellipsoidal = common::render_films(ctx, &scene, &small(Method::Ellipsoidal, seed + 1), BATCHES, spp);
        assert!(direct.iter().any(|f| f.mean_rgb()[0] > 0.0), "{label}: the gate holds light");
        common::assert_films_agree(label, &ellipsoidal, &direct, 8, common::peer::ALPHA);
    }
}
