//! `render --frames`: gate sweeps whose first frame is the single image of the same gate and
//! seed, bit for bit; `--frame-range` reproducing frames of a full run; existing frames skipped
//! unless `--force`; animated scenes whose frames follow the motion, with every method.

mod common;

use std::path::Path;
use std::process::{Command, Output};

use gatetrace::film::output::read_npy_f32;

fn gatetrace(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gatetrace")).args(args).output().expect("the binary runs")
}

fn run(args: &[&str]) -> String {
    let o = gatetrace(args);
    assert!(o.status.success(), "gatetrace {}:\n{}", args.join(" "), String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn image(path: &Path) -> Vec<f32> {
    let (_, data) = read_npy_f32(path).unwrap();
    assert!(data.iter().all(|v| v.is_finite()), "{}: non-finite values", path.display());
    data
}

fn bits(data: &[f32]) -> Vec<u32> {
    data.iter().map(|v| v.to_bits()).collect()
}

const BASE: [&str; 8] = ["render", "--res", "16x16", "--spp", "8", "--max-bounces", "3", "--seed"];

#[test]
fn a_gate_sweep_starts_at_the_single_image_and_ranges_reproduce_frames() {
    let dir = common::scratch_dir("frames_sweep");
    let pattern = dir.join("f_{frame:04}.npy");
    let single = dir.join("single.npy");
    let with = |extra: &[&str]| -> Vec<String> {
        BASE.iter()
            .map(|s| s.to_string())
            .chain(["11".into(), "--gate".into(), "box:3.14..3.19".into()])
            .chain(extra.iter().map(|s| s.to_string()))
            .collect()
    };
    let args = with(&["--frames", "3", "--gate-step", "0.05", "--out", pattern.to_str().unwrap()]);
    let out = run(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(out.lines().filter(|l| l.starts_with("frame ")).count(), 3, "{out}");
    let frames: Vec<Vec<f32>> = (0..3).map(|i| image(&dir.join(format!("f_{i:04}.npy")))).collect();
    // Later gates see longer paths: different images, none black.
    for f in &frames {
        assert!(f.iter().any(|&v| v > 0.0));
    }
    assert_ne!(bits(&frames[0]), bits(&frames[1]));
    assert_ne!(bits(&frames[1]), bits(&frames[2]));
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("f_0002.json")).unwrap()).unwrap();
    assert_eq!(meta["frame"], 2);
    assert!(meta["gate_description"].as_str().unwrap().contains("3.24"), "{meta}");

    // Frame 0 is the single image of the same gate and seed.
    let args = with(&["--out", single.to_str().unwrap()]);
    run(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(bits(&image(&single)), bits(&frames[0]), "frame 0 differs from the single image");

    // Existing frames are skipped; --frame-range 1..1 --force renders frame 1 again, bit for bit.
    let args =
        with(&["--frames", "3", "--gate-step", "0.05", "--frame-range", "1..1", "--out", pattern.to_str().unwrap()]);
    let out = run(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(out.contains("skipped"), "{out}");
    let frame1 = dir.join("f_0001.npy");
    std::fs::remove_file(&frame1).unwrap();
    let out = run(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(out.lines().filter(|l| l.starts_with("frame 1/2")).count() == 1, "{out}");
    assert_eq!(bits(&image(&frame1)), bits(&frames[1]), "--frame-range 1..1 differs from the full run's frame 1");
    let mut forced = args.clone();
    forced.push("--force".into());
    let out = run(&forced.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(!out.contains("skipped"), "{out}");
}

#[test]
fn sequences_need_a_frame_pattern_and_sane_ranges() {
    let dir = common::scratch_dir("frames_errors");
    let plain = dir.join("plain.npy");
    for (args, needle) in [
        (vec!["--frames", "3", "--out", plain.to_str().unwrap()], "{frame}"),
        (vec!["--frames", "3", "--frame-range", "2..5", "--out", "f{frame}.npy"], "--frame-range"),
        (vec!["--frames", "2", "--gate-step", "1ns", "--out", "f{frame}.npy"], "cannot be shifted"),
        (vec!["--frames", "2", "--anim-time", "0..1", "--out", "f{frame}.npy"], "no animation"),
        (vec!["--frames", "2", "--anim-time", "zero..1", "--out", "f{frame}.npy"], "--anim-time"),
    ] {
        let full: Vec<&str> = ["render", "--res", "4x4", "--spp", "1"].into_iter().chain(args).collect();
        let o = gatetrace(&full);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{full:?} should fail");
        assert!(err.contains(needle), "{full:?}: error should mention `{needle}`:\n{err}");
    }
}

/// The moving-block scene rendered at the start and end of its motion, with every method:
/// the block's side of the image changes, the rest of the box stays lit.
#[test]
fn an_animated_scene_moves_with_every_method() {
    let dir = common::scratch_dir("frames_animated");
    let scene = common::repo_path("assets/scenes/cornell_box_moving_block.gltf");
    for method in ["path", "direct", "ellipsoidal"] {
        let pattern = dir.join(format!("{method}_{{frame}}.npy"));
        run(&[
            "render",
            scene.to_str().unwrap(),
            "--method",
            method,
            "--gate",
            "box:2.0..3.6",
            "--res",
            "24x24",
            "--spp",
            "16",
            "--max-bounces",
            "3",
            "--frames",
            "2",
            "--anim-time",
            "0..1",
            "--out",
            pattern.to_str().unwrap(),
        ]);
        let (a, b) = (image(&dir.join(format!("{method}_0.npy"))), image(&dir.join(format!("{method}_1.npy"))));
        // The block moves from x = -0.25 m to +0.25 m: at t = 0 it covers the lower left of the
        // image (dark sides in front of the lit floor), at t = 1 the lower right.
        let region = |img: &[f32], left: bool| -> f64 {
            let mut sum = 0.0;
            for y in 14..24 {
                for x in 0..24 {
                    if (x < 10) == left && !(10..14).contains(&x) {
                        sum += (0..3).map(|c| img[(y * 24 + x) * 3 + c] as f64).sum::<f64>();
                    }
                }
            }
            sum
        };
        let (a_left, a_right, b_left, b_right) =
            (region(&a, true), region(&a, false), region(&b, true), region(&b, false));
        println!("{method}: t = 0 left {a_left:.4} right {a_right:.4}; t = 1 left {b_left:.4} right {b_right:.4}");
        assert!(a_left > 0.0 && a_right > 0.0 && b_left > 0.0 && b_right > 0.0, "{method}: a black region");
        // Where the block stands, the floor behind it is hidden: that side loses light.
        assert!(b_left > 1.1 * a_left, "{method}: the left side should brighten once the block has left it");
        assert!(a_right > 1.1 * b_right, "{method}: the right side should darken once the block covers it");
    }
}

#[test]
fn animation_sampling_moves_the_block_in_the_loaded_scene() {
    use gatetrace::scene::load_gltf_at;
    let path = common::repo_path("assets/scenes/cornell_box_moving_block.gltf");
    let centre_x = |t: f64| -> f32 {
        let scene = load_gltf_at(&path, Some(t)).unwrap();
        // The block is the last mesh of the scene graph: its 12 triangles come last.
        let block: Vec<_> = scene.triangles.iter().skip(scene.triangles.len() - 12).collect();
        let xs: Vec<f32> = block.iter().flat_map(|t| t.positions.iter().map(|p| p.x)).collect();
        0.5 * (xs.iter().cloned().fold(f32::MAX, f32::min) + xs.iter().cloned().fold(f32::MIN, f32::max))
    };
    assert!((centre_x(0.0) + 0.25).abs() < 1e-5);
    assert!((centre_x(0.5) - 0.0).abs() < 1e-5);
    assert!((centre_x(1.0) - 0.25).abs() < 1e-5);
    assert!((centre_x(7.0) - 0.25).abs() < 1e-5, "after the last key the block stays put");
}
