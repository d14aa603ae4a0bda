//! Interrupted and resumed renders: a saved state continues the render it came from, SIGINT and
//! SIGTERM leave the image of the samples taken (and a checkpoint), and `--resume` finishes it
//! as the uninterrupted render would have. Tracers built one after another on a device share
//! the scene's arrays (`integrator::upload::scene_buffers`), and a scene rendered again after
//! another one renders the same film.

mod common;

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use gatetrace::film::{Film, Gate};
use gatetrace::integrator::upload::scene_buffers;
use gatetrace::integrator::{Method, RenderSettings, create_integrator};
use gatetrace::scene::{PreparedScene, load_gltf_for_capture};

/// Renders `first` samples per pixel, saves the state, loads it into a new integrator and
/// renders `second` more; returns that film and the film of one integrator rendering both.
fn continued_and_uninterrupted(
    ctx: &gatetrace::gpu::GpuContext,
    scene: &PreparedScene,
    settings: &RenderSettings,
    first: u64,
    second: u64,
) -> (Film, Film) {
    let mut whole = create_integrator(ctx, scene, settings).unwrap();
    whole.render_samples(first).unwrap();
    let state = whole.save_state().unwrap();
    whole.render_samples(second).unwrap();
    let mut resumed = create_integrator(ctx, scene, settings).unwrap();
    resumed.load_state(&state).unwrap();
    resumed.render_samples(second).unwrap();
    (resumed.film().unwrap(), whole.film().unwrap())
}

#[test]
fn a_saved_state_continues_the_render() {
    let ctx = common::gpu();
    let cornell = common::cornell_box();
    let base =
        RenderSettings { width: 16, height: 16, max_bounces: 4, samples_per_pass: Some(4), ..Default::default() };
    let gated = Gate::Box { start: 3.14, end: 3.19 };
    let transient = Gate::Transient { start: 3.0, width: 0.1, bins: 8 };
    // Every method's sums are exact (fixed point), so the resumed film equals the whole one bit
    // for bit.
    for (method, gate) in [
        (Method::Path, Gate::None),
        (Method::Path, transient.clone()),
        (Method::Direct, gated.clone()),
        (Method::Ellipsoidal, gated.clone()),
        (Method::Ellipsoidal, transient.clone()),
    ] {
        let settings = RenderSettings { method, gate: gate.clone(), ..base.clone() };
        let (resumed, whole) = continued_and_uninterrupted(ctx, &cornell, &settings, 12, 8);
        assert_eq!(resumed.spp, 20);
        check(&format!("{} {}", method.name(), gate.describe()), &resumed, &whole);
    }
    // An NLOS capture whose pilot render shapes the target lengths' visits per sensed point.
    let letter =
        PreparedScene::new(load_gltf_for_capture(&common::repo_path("assets/scenes/nlos_letter.gltf")).unwrap())
            .unwrap();
    let settings = RenderSettings {
        target_pilot_spp: 8,
        samples_per_pass: Some(4),
        ..common::example_capture(
            8,
            8,
            Gate::Transient { start: 1.6, width: 0.02, bins: 40 },
            gatetrace::nlos::LaserAim::Confocal,
            Method::Ellipsoidal,
        )
    };
    let (resumed, whole) = continued_and_uninterrupted(ctx, &letter, &settings, 8, 8);
    check("NLOS confocal ellipsoidal with a target pilot", &resumed, &whole);
}

#[test]
fn tracers_of_one_scene_share_its_arrays_and_another_scene_does_not_change_its_film() {
    let ctx = common::gpu();
    let cornell = common::cornell_box();
    let limit = ctx.max_binding_size();
    let first = scene_buffers(ctx, &cornell, false, limit).unwrap();
    let again = scene_buffers(ctx, &cornell, false, limit).unwrap();
    assert!(Arc::ptr_eq(&first, &again), "a second tracer of the scene uploads it again");
    assert!(first.resources.get("triangles").is_some() && first.resources.get("lights").is_some());
    // The wide query's node surfaces are other arrays; a clone may be changed before it renders.
    let wide = scene_buffers(ctx, &cornell, true, limit).unwrap();
    assert_ne!(wide.resources.get("bvh_node_surfaces"), first.resources.get("bvh_node_surfaces"));
    let clone = cornell.clone();
    assert!(!Arc::ptr_eq(&scene_buffers(ctx, &clone, false, limit).unwrap(), &first), "a clone shares the upload");

    // A film of the box, then one of another scene (its upload replaces the box's), then the
    // box's again from a new tracer: the same bits.
    let settings = RenderSettings {
        width: 16,
        height: 16,
        max_bounces: 4,
        method: Method::Direct,
        gate: Gate::Box { start: 3.14, end: 3.19 },
        ..Default::default()
    };
    let film = |scene: &PreparedScene| {
        let mut tracer = create_integrator(ctx, scene, &settings).unwrap();
        tracer.render_samples(4).unwrap();
        tracer.film().unwrap()
    };
    let before = film(&cornell);
    let sphere = common::sphere_scene(8);
    let other = film(&sphere);
    assert!(other.data.iter().any(|&v| v > 0.0), "the sphere's film is black");
    check("the box after another scene", &film(&cornell), &before);
}

/// Asserts that `resumed` equals `whole` bit for bit, and that the films are not black.
/// A warm-up pass (one sample of the image's first pixels, `Integrator::warm_up`) leaves the
/// render that follows it as it would have been without: same pilots, same samples, bit for bit.
#[test]
fn a_warm_up_leaves_the_render_after_it_unchanged() {
    let ctx = common::gpu();
    let cornell = common::cornell_box();
    // 40x40 holds more pixels than the warm-up's block, so the warm-up covers part of the image.
    let base =
        RenderSettings { width: 40, height: 40, max_bounces: 4, samples_per_pass: Some(4), ..Default::default() };
    let gated = Gate::Box { start: 3.14, end: 3.19 };
    let transient = Gate::Transient { start: 3.0, width: 0.1, bins: 8 };
    for settings in [
        RenderSettings { method: Method::Path, ..base.clone() },
        RenderSettings { method: Method::Direct, gate: gated.clone(), camera_pilot_spp: Some(2), ..base.clone() },
        RenderSettings { method: Method::Ellipsoidal, gate: transient.clone(), ..base.clone() },
        RenderSettings { method: Method::Combined, gate: gated.clone(), camera_pilot_spp: Some(2), ..base.clone() },
    ] {
        let label = format!("{} {}", settings.method.name(), settings.gate.describe());
        let mut fresh = create_integrator(ctx, &cornell, &settings).unwrap();
        fresh.render_samples(4).unwrap();
        let mut warmed = create_integrator(ctx, &cornell, &settings).unwrap();
        warmed.warm_up().unwrap();
        assert_eq!(warmed.samples_done(), 0, "{label}: the warm-up's sample stayed in the film");
        warmed.render_samples(4).unwrap();
        check(&label, &warmed.film().unwrap(), &fresh.film().unwrap());
    }
}

fn check(label: &str, resumed: &Film, whole: &Film) {
    assert_eq!((resumed.spp, resumed.bins), (whole.spp, whole.bins), "{label}");
    assert!(whole.data.iter().any(|&v| v > 0.0), "{label}: the film is black");
    let differing = resumed.data.iter().zip(&whole.data).filter(|(a, b)| a != b).count();
    assert_eq!(differing, 0, "{label}: {differing} values of the resumed film differ from the uninterrupted one");
}

fn gatetrace() -> Command {
    Command::new(env!("CARGO_BIN_EXE_gatetrace"))
}

/// Waits until `path` exists (the render has saved a checkpoint), at most 120 s.
fn wait_for(path: &Path, child: &mut Child) {
    let start = Instant::now();
    while !path.exists() {
        assert!(child.try_wait().unwrap().is_none(), "the render ended before its first checkpoint");
        assert!(start.elapsed() < Duration::from_secs(120), "no checkpoint after 120 s");
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn signal(child: &Child, name: &str) {
    let status = Command::new("kill").args([&format!("-{name}"), &child.id().to_string()]).status().unwrap();
    assert!(status.success(), "kill -{name} failed");
}

fn metadata(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// A render of many samples stopped by `signal_name` once it has saved a checkpoint: the exit
/// status is 128 + the signal, the image holds the samples taken (its metadata says how many
/// and why it stopped), and `--resume` to a few samples more gives the image of an
/// uninterrupted render of as many samples, bit for bit. `direct` renders with a camera pilot
/// (`--camera-pilot 16`; its default runs one from 256 spp on), whose scales the checkpoint
/// keeps.
fn interrupt_and_resume(method: &str, signal_name: &str, status: i32, dir: &Path) {
    let args = |out: &str| -> Vec<String> {
        [
            "render",
            "--method",
            method,
            "--res",
            "16x16",
            "--max-bounces",
            "3",
            "--gate",
            "box:3.14..3.19",
            "--samples-per-pass",
            "4",
            "--out",
            out,
        ]
        .map(String::from)
        .into_iter()
        .chain(if method == "direct" { vec!["--camera-pilot".into(), "16".into()] } else { vec![] })
        .collect()
    };
    let out = dir.join("stopped.npy");
    let mut child = gatetrace()
        .args(args(out.to_str().unwrap()))
        .args(["--spp", "100000000", "--checkpoint-every", "0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_for(&dir.join("stopped.npy.checkpoint"), &mut child);
    signal(&child, signal_name);
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    let said = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(status), "{method}, {signal_name}: {err}");
    let meta = metadata(&dir.join("stopped.json"));
    assert_eq!(meta["interrupted_by"], format!("SIG{signal_name}"), "{meta}");
    assert_eq!(meta["requested"], serde_json::json!({ "spp": 100000000 }), "{meta}");
    let taken: u64 = meta["spp"].as_u64().unwrap();
    assert!(taken >= 4 && taken.is_multiple_of(4), "{taken} spp: whole passes of 4");
    assert!(said.contains(&format!("with the {taken} spp traced so far")), "{said}");

    let total = (taken + 8).to_string();
    let resumed = gatetrace().args(args(out.to_str().unwrap())).args(["--spp", &total, "--resume"]).output().unwrap();
    assert!(resumed.status.success(), "{}", String::from_utf8_lossy(&resumed.stderr));
    assert!(!dir.join("stopped.npy.checkpoint").exists(), "a finished render removes its checkpoint");
    let meta = metadata(&dir.join("stopped.json"));
    assert_eq!(meta["spp"], taken + 8);
    assert_eq!(meta["resumed_from_spp"], taken);
    assert!(meta.get("interrupted_by").is_none(), "{meta}");

    let fresh = dir.join("fresh.npy");
    let o = gatetrace().args(args(fresh.to_str().unwrap())).args(["--spp", &total]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (shape, a) = gatetrace::film::output::read_npy_f32(&out).unwrap();
    let (_, b) = gatetrace::film::output::read_npy_f32(&fresh).unwrap();
    let film = |data: Vec<f32>| Film { width: shape[1] as u32, height: shape[0] as u32, bins: 1, spp: taken + 8, data };
    check(&format!("{method} resumed after {signal_name}"), &film(a), &film(b));
}

#[test]
fn sigint_and_sigterm_keep_the_samples_taken_and_resume_finishes_the_render() {
    let dir = common::scratch_dir("interruption_path");
    interrupt_and_resume("path", "INT", 130, &dir);
    let dir = common::scratch_dir("interruption_direct");
    interrupt_and_resume("direct", "TERM", 143, &dir);
}

/// A closed white box (2 m wide, double-sided walls of albedo 0.95) around the camera, lit by
/// a small emitter: no path escapes, so every path runs to --max-bounces.
fn closed_box(dir: &Path) -> std::path::PathBuf {
    use common::gltf_builder::{Camera, Material, Mesh, Scene};
    let face = |corner: [f32; 3], u: [f32; 3], v: [f32; 3], material| {
        let p = |a: f32, b: f32| [0, 1, 2].map(|i| corner[i] + a * u[i] + b * v[i]);
        Mesh {
            positions: vec![p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)],
            normals: None,
            uvs: None,
            indices: vec![0, 1, 2, 0, 2, 3],
            material: Some(material),
        }
    };
    let mut meshes = vec![];
    for axis in 0..3 {
        for side in [-1.0f32, 1.0] {
            let mut corner = [-1.0f32; 3];
            corner[axis] = side;
            let (mut u, mut v) = ([0.0f32; 3], [0.0f32; 3]);
            u[(axis + 1) % 3] = 2.0;
            v[(axis + 2) % 3] = 2.0;
            meshes.push(face(corner, u, v, 0));
        }
    }
    meshes.push(face([-0.1, 0.9, -0.1], [0.2, 0.0, 0.0], [0.0, 0.0, 0.2], 1));
    let mut white = Material::diffuse([0.95; 3]);
    white.double_sided = true;
    let mut light = Material::emitter(5.0);
    light.double_sided = true;
    let scene = Scene {
        meshes,
        materials: vec![white, light],
        camera: Some(Camera { position: [0.0; 3], rotation: [0.0, 0.0, 0.0, 1.0], yfov: 1.0 }),
        point_lights: vec![],
    };
    scene.write(dir, "closed_box.gltf")
}

#[test]
fn a_second_signal_aborts_at_once() {
    let dir = common::scratch_dir("interruption_abort");
    let out = dir.join("x.npy");
    // One pass of 128 x 128 x 240 paths of 100 bounces each takes many seconds: both signals
    // arrive during the first pass.
    let scene = closed_box(&dir);
    let child = gatetrace()
        .args([
            "render",
            scene.to_str().unwrap(),
            "--res",
            "128x128",
            "--spp",
            "240",
            "--samples-per-pass",
            "240",
            "--max-bounces",
            "100",
            "--out",
            out.to_str().unwrap(),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_secs(1));
    signal(&child, "INT");
    std::thread::sleep(Duration::from_millis(200));
    signal(&child, "INT");
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "{err}");
    assert!(err.contains("SIGINT: aborted"), "{err}");
    // The pass in flight did not finish: nothing was written, and no image was reported.
    assert!(!out.exists() && !dir.join("x.npy.checkpoint").exists(), "an aborted render writes nothing");
    assert!(!String::from_utf8_lossy(&o.stdout).contains("spp in"), "the render finished its pass");
}
