//! The paper's application scenes (tools/scenes/make_application_scenes.py): each loads, names in its
//! extras a gate the renderer parses, and renders light inside that gate (the fence through its
//! thin lens; the proximity sensor at the animation time its car is in range); the gated figures
//! are detailed meshes, and the CW room's second code has the paper's 20 ps window.

mod common;

use gatetrace::film::Gate;
use gatetrace::film::gate::gate_weight;
use gatetrace::integrator::{Method, RenderSettings};
use gatetrace::scene::{PreparedScene, load_gltf, load_gltf_at};

/// A scene file's glTF document.
fn scene_document(name: &str) -> serde_json::Value {
    let text = std::fs::read_to_string(common::repo_path(&format!("assets/scenes/{name}"))).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// The gate named in a scene's extras (field `gate`, or another such as `gate_20ps`).
fn scene_gate_field(name: &str, field: &str) -> Gate {
    let doc = scene_document(name);
    let spec = doc["extras"][field].as_str().unwrap_or_else(|| panic!("{name}: extras.{field}"));
    Gate::parse(spec).unwrap_or_else(|e| panic!("{name}: gate {spec}: {e:#}"))
}

fn scene_gate(name: &str) -> Gate {
    scene_gate_field(name, "gate")
}

fn gated_mean(scene: &PreparedScene, gate: Gate, method: Method) -> f64 {
    let ctx = common::gpu();
    let settings =
        RenderSettings { width: 16, height: 16, max_bounces: 3, gate, method, seed: 5, ..Default::default() };
    let film = common::render_films(ctx, scene, &settings, 1, 16).remove(0);
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
        common::render_films(ctx, &scene, &settings, 1, 64).remove(0)
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

#[test]
fn giraffe_and_car_are_detailed_meshes() {
    // The figures the paper's Figs. 7 and 8 gate on are meshes of at least 50,000 triangles, and
    // the loader reads every one of them (indexed primitives).
    for (file, parts) in
        [("fence.gltf", &["giraffe"][..]), ("proximity.gltf", &["car_body", "car_cabin", "car_wheels"][..])]
    {
        let doc = scene_document(file);
        let accessors = doc["accessors"].as_array().unwrap();
        let triangles_of = |mesh: &serde_json::Value| -> u64 {
            let primitives = mesh["primitives"].as_array().unwrap();
            let indices =
                |p: &serde_json::Value| p.get("indices").unwrap_or(&p["attributes"]["POSITION"]).as_u64().unwrap();
            primitives.iter().map(|p| accessors[indices(p) as usize]["count"].as_u64().unwrap() / 3).sum()
        };
        let meshes = doc["meshes"].as_array().unwrap();
        let figure: u64 =
            meshes.iter().filter(|m| parts.contains(&m["name"].as_str().unwrap())).map(triangles_of).sum();
        assert!(figure >= 50_000, "{file}: the figure has {figure} triangles");
        let loaded = load_gltf(&common::repo_path(&format!("assets/scenes/{file}"))).unwrap().triangles.len() as u64;
        assert_eq!(loaded, meshes.iter().map(triangles_of).sum::<u64>(), "{file}: triangles loaded");
    }
}

#[test]
fn cw_room_narrow_code_has_the_papers_20ps_window() {
    // The second CW case's window is 20 ps (5.996 mm of path) wide at half height, about the
    // figure's round trip of 4.36 m, like the 1.28 % window of the first about the same length.
    let gate = scene_gate_field("cw_room.gltf", "gate_20ps");
    let (params, table) = (gate.to_gpu(), gate.table());
    let step = 1e-5;
    let lengths: Vec<f64> = (0..12_000).map(|i| 4.30 + i as f64 * step).collect();
    let weights: Vec<f32> = lengths.iter().map(|&l| gate_weight(gate.kind(), &params, &table, l as f32)).collect();
    let peak = weights.iter().cloned().fold(0.0f32, f32::max);
    let above: Vec<f64> = lengths.iter().zip(&weights).filter(|(_, w)| **w >= 0.5 * peak).map(|(l, _)| *l).collect();
    let width = above.len() as f64 * step;
    let centre = 0.5 * (above[0] + above[above.len() - 1]);
    let twenty_ps = 20e-12 * 299_792_458.0;
    assert!((width - twenty_ps).abs() < 0.05 * twenty_ps, "window {:.3} mm at half height", width * 1e3);
    assert!((centre - 4.36).abs() < 1e-3, "window centred at {centre:.4} m");
    // One window: over the paths of the room (up to 8 m) nothing else reaches half the peak.
    let elsewhere = (0..8000).map(|i| 0.5 + i as f64 * 1e-3).filter(|l| (l - 4.36).abs() > 0.01);
    assert!(elsewhere.map(|l| gate_weight(gate.kind(), &params, &table, l as f32)).all(|w| w < 0.5 * peak));
}

/// `combined` on an application scene (the proximity sensor's third frame, the car's 52k
/// triangles in the scene, at its 200 ps gate) agrees with `path`, an independent estimator:
/// image means and 8 x 8 blocks within the Sidak-corrected Student's t limit over 16 batches.
/// The box tests (tests/bidirectional.rs) check the families' weights on every strategy; this
/// one checks them where the spheroids cut a detailed mesh seen through a spot light's cone.
#[test]
fn combined_matches_path_on_the_proximity_scene() {
    const BATCHES: usize = 16;
    let path = common::repo_path("assets/scenes/proximity.gltf");
    let scene = PreparedScene::new(load_gltf_at(&path, Some(0.95)).unwrap()).unwrap();
    let gate = scene_gate("proximity.gltf");
    let ctx = common::gpu();
    let settings = |method: Method, seed: u32| RenderSettings {
        width: 16,
        height: 16,
        max_bounces: 3,
        gate: gate.clone(),
        method,
        seed,
        ellipsoidal_share: (method == Method::Combined).then_some(1.0),
        ..Default::default()
    };
    let combined = common::render_films(ctx, &scene, &settings(Method::Combined, 91), BATCHES, 16);
    let reference = common::render_films(ctx, &scene, &settings(Method::Path, 92), BATCHES, 256);
    assert!(combined.iter().all(|f| f.mean_rgb()[0] > 0.0), "every combined batch holds the gate's light");
    common::assert_films_agree("combined vs path, proximity at 0.95 s", &combined, &reference, 8, 0.01);
}
