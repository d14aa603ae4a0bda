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
    let settings =
        RenderSettings { width: 16, height: 16, max_bounces: 3, gate, method, seed: 5, ..Default::default() };
    let film = common::render_films(&ctx, scene, &settings, 1, 16).remove(0);
    film.mean_rgb()[0]
}

#[test]
fn fence_scene_renders_its_gate_through_the_thin_lens() {
    let scene = load_gltf(&common::repo_path("assets/scenes/fence.gltf")).unwrap();
    assert!(scene.camera.lens.is_some(), "the fence is seen through a thin lens");
    let scene = PreparedScene::new(scene).unwrap();
    for method in [Method::Path, Method::Direct, Method::Ellipsoidal] {
        assert!(
            gated_mean(&scene, scene_gate("fence.gltf"), method) > 0.0,
            "{method:?}: the gate holds the figure's light"
        );
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

#[test]
fn cw_room_code_selects_the_figure_depth() {
    // The depth-selective code weighs the figure's round trip 1024 times the rest of the room:
    // against the steady image, the figure (the image centre) keeps far more of its light than
    // the room does.
    let ctx = common::gpu();
    let scene = PreparedScene::new(load_gltf(&common::repo_path("assets/scenes/cw_room.gltf")).unwrap()).unwrap();
    let render = |gate: Gate| {
        let settings = RenderSettings { width: 16, height: 16, max_bounces: 3, gate, seed: 9, ..Default::default() };
        common::render_films(&ctx, &scene, &settings, 1, 64).remove(0)
    };
    let (gated, steady) = (render(scene_gate("cw_room.gltf")), render(Gate::None));
    let centre = |film: &gatetrace::film::Film| -> f64 {
        // The 4 x 4 pixels about the centre, red channel.
        (6..10)
            .flat_map(|y| (6..10).map(move |x| (y, x)))
            .map(|(y, x)| film.data[((y * 16 + x) * 3) as usize] as f64)
            .sum()
    };
    let whole = |film: &gatetrace::film::Film| film.mean_rgb()[0];
    let kept_by_figure = centre(&gated) / centre(&steady);
    let kept_by_room = whole(&gated) / whole(&steady);
    assert!(
        kept_by_figure > 3.0 * kept_by_room,
        "the figure keeps {kept_by_figure:.3e} of its light, the room {kept_by_room:.3e}"
    );
}

#[test]
fn dynamic_scene_moves_and_its_frames_command_runs() {
    let path = common::repo_path("assets/scenes/dynamic.gltf");
    let (start, later) = (load_gltf_at(&path, Some(0.0)).unwrap(), load_gltf_at(&path, Some(0.5)).unwrap());
    assert_eq!(start.triangles.len(), later.triangles.len());
    let moved = start.triangles.iter().zip(&later.triangles).filter(|(a, b)| a.positions != b.positions).count();
    assert!(moved > 100, "the pendulum and the fan move: {moved} triangles moved");
    // The first slice holds the pendulum's round trip.
    let scene = PreparedScene::new(start).unwrap();
    assert!(gated_mean(&scene, scene_gate("dynamic.gltf"), Method::Ellipsoidal) > 0.0);
    // The sequence its extras describe renders (two of its frames, tiny).
    let text = std::fs::read_to_string(&path).unwrap();
    let doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    let frames = doc["extras"]["frames"].as_str().unwrap().split(':').next().unwrap().to_owned();
    let dir = common::scratch_dir("dynamic_frames");
    let out = dir.join("f_{frame}.npy");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_gatetrace"))
        .arg("render")
        .arg(&path)
        .args(frames.split_whitespace())
        .args(["--frame-range", "0..1", "--res", "8x8", "--spp", "2", "--method", "ellipsoidal", "--gate"])
        .arg(doc["extras"]["gate"].as_str().unwrap())
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{frames}: {}", String::from_utf8_lossy(&o.stderr));
    assert!(dir.join("f_0.npy").exists() && dir.join("f_1.npy").exists());
}
