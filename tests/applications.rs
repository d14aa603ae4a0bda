//! The paper's application scenes (tools/make_application_scenes.py): each loads, names in its
//! extras a gate the renderer parses, and renders light inside that gate (the fence through its
//! thin lens; the proximity sensor at the animation time its car is in range).

mod common;

use gatetrace::film::Gate;
use gatetrace::integrator::{Method, RenderSettings};
use gatetrace::scene::{PreparedScene, load_gltf, load_gltf_at};

/// The gate named in a scene's extras.
fn scene_gate(name: &str) -> Gate {
    let text = std::fs::read_to_string(common::repo_path(&format!("assets/scenes/{name}"))).unwrap();
    let doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    let spec = doc["extras"]["gate"].as_str().unwrap_or_else(|| panic!("{name}: extras.gate"));
    Gate::parse(spec).unwrap_or_else(|e| panic!("{name}: gate {spec}: {e:#}"))
}

fn gated_mean(scene: &PreparedScene, gate: Gate, method: Method) -> f64 {
    let ctx = common::gpu();
    let settings = RenderSettings { width: 16, height: 16, max_bounces: 3, gate, method, seed: 5, ..Default::default() };
    let film = common::render_films(&ctx, scene, &settings, 1, 16).remove(0);
    film.mean_rgb()[0]
}

#[test]
fn fence_scene_renders_its_gate_through_the_thin_lens() {
    let scene = load_gltf(&common::repo_path("assets/scenes/fence.gltf")).unwrap();
    assert!(scene.camera.lens.is_some(), "the fence is seen through a thin lens");
    let scene = PreparedScene::new(scene).unwrap();
    for method in [Method::Path, Method::Direct, Method::Ellipsoidal] {
        assert!(gated_mean(&scene, scene_gate("fence.gltf"), method) > 0.0, "{method:?}: the gate holds the figure's light");
    }
}

#[test]
fn proximity_scene_lights_its_gate_when_the_car_is_in_range() {
    let path = common::repo_path("assets/scenes/proximity.gltf");
    let gate = scene_gate("proximity.gltf");
    // The car's front passes 2 m ahead (a 4 m round trip) at about 0.65 s.
    let in_range = PreparedScene::new(load_gltf_at(&path, Some(0.65)).unwrap()).unwrap();
    let far = PreparedScene::new(load_gltf_at(&path, Some(0.0)).unwrap()).unwrap();
    let (near_light, far_light) =
        (gated_mean(&in_range, gate.clone(), Method::Ellipsoidal), gated_mean(&far, gate, Method::Ellipsoidal));
    assert!(near_light > 2.0 * far_light, "the car in range lights the gate: {near_light} vs {far_light} out of range");
}
