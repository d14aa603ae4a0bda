//! The device benchmark (tools/bench/device_bench.sh), run on this machine's adapter (lavapipe in CI)
//! in its smoke mode: it must end well and write every measurement it promises, so that a run
//! on a GPU machine, which builds nothing and cannot be fixed there, works the first time.

mod common;

use std::process::Command;

#[test]
fn device_bench_smoke_run_writes_every_measurement() {
    let dir = common::scratch_dir("device_bench");
    let out = dir.join("device_bench.json");
    let run = Command::new("bash")
        .arg(common::repo_path("tools/bench/device_bench.sh"))
        // The peer's CPU variant: measured where Mitsuba is installed, skipped with a reason elsewhere.
        .args([
            "--smoke",
            "--seconds",
            "0.3",
            "--peer-variant",
            "llvm_ad_rgb",
            "--exe",
            env!("CARGO_BIN_EXE_gatetrace"),
        ])
        .arg("--out")
        .arg(&out)
        .output()
        .expect("bash runs");
    let log = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "tools/bench/device_bench.sh --smoke failed:\n{log}");
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert!(!report["adapter"].as_str().unwrap().is_empty(), "no adapter name");
    let scenes = report["scenes"].as_array().unwrap();
    assert_eq!(scenes.len(), 2, "the Cornell box and one mesh");
    assert!(scenes[1]["triangles"].as_u64().unwrap() > 1000, "the mesh is the 1,280-triangle sphere in the box");
    for scene in scenes {
        let name = scene["scene"].as_str().unwrap();
        let methods: Vec<&str> =
            scene["measurements"].as_array().unwrap().iter().map(|m| m["method"].as_str().unwrap()).collect();
        assert_eq!(methods, ["path", "direct", "ellipsoidal", "ellipsoidal:wide"], "{name}");
        for m in scene["measurements"].as_array().unwrap() {
            let method = m["method"].as_str().unwrap();
            assert!(m["samples_per_second"].as_f64().unwrap() > 0.0, "{name} {method}: no samples");
            let stages = m["stages"].as_array().unwrap();
            let total: f64 = stages.iter().map(|s| s["milliseconds"].as_f64().unwrap()).sum();
            assert!(!stages.is_empty() && total > 0.0, "{name} {method}: no GPU time per stage");
        }
        let rows = scene["equal_time"].as_array().unwrap();
        let compared: Vec<&str> = rows.iter().map(|r| r["method"].as_str().unwrap()).collect();
        assert_eq!(compared, ["direct", "ellipsoidal", "ellipsoidal:wide"], "{name}: equal-time rows");
    }
    // The largest mesh at larger images (one in the smoke run).
    let larger = report["larger_images"].as_array().unwrap();
    assert_eq!(larger.len(), 1, "one larger image in the smoke run");
    for bench in larger {
        assert_eq!(bench["triangles"], scenes[1]["triangles"], "the larger images render the largest mesh");
        for m in bench["measurements"].as_array().unwrap() {
            assert_eq!(m["width"].as_u64(), Some(32), "the smoke run's larger image is 32x32");
            assert!(m["samples_per_second"].as_f64().unwrap() > 0.0, "larger image {}: no samples", m["method"]);
        }
    }
    // Passes of 1 and 2 samples of every pixel on the largest mesh, and one too large, reported
    // as skipped.
    let waves = report["waves"]["measurements"].as_array().unwrap();
    assert_eq!(waves.len(), 9, "three methods, three passes each");
    for m in waves {
        let (method, k) = (m["method"].as_str().unwrap(), m["samples_per_pass"].as_u64().unwrap());
        match k {
            1 | 2 => assert!(m["samples_per_second"].as_f64().unwrap() > 0.0, "waves: {method} at {k}: no samples"),
            100_000 => assert!(m["skipped"].as_str().unwrap().contains("samples per pass"), "waves: {method}: {m}"),
            _ => panic!("waves: {method}: unexpected {k} samples per pass"),
        }
    }
    // The peer is measured where its Python packages load, and otherwise the report says why.
    let peer = &report["peer"];
    match peer["skipped"].as_str() {
        Some(why) => assert!(!why.is_empty(), "the peer was skipped without a reason"),
        None => {
            let measured = peer["scenes"].as_array().expect("peer: scenes or skipped");
            assert_eq!(measured.len(), scenes.len(), "the peer on every scene");
            for scene in measured {
                assert_eq!(scene["peer_samples_per_second"].as_array().unwrap().len(), 2, "peer before and after");
                for m in scene["measurements"].as_array().unwrap() {
                    assert!(m["per_peer"].as_f64().unwrap() > 0.0, "{scene}: no ratio to the peer");
                }
            }
        }
    }
}
