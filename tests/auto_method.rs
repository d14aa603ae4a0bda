//! `--method auto`: its pilot of `path`, `direct` and `ellipsoidal` picks `ellipsoidal` where a
//! gate is far narrower than the scene and `path` where it is as wide as the scene, measures
//! `path` and `direct` alone in the steady state (where `ellipsoidal` cannot render), and the
//! render it returns is the chosen method's (all samples after the discarded pilot). Which method
//! wins at a given width is measured by `gatetrace equal-time --methods
//! path,direct,ellipsoidal,auto` (docs/methods.md), not here.

mod common;

use std::process::Command;

use gatetrace::film::Gate;
use gatetrace::integrator::{Budget, Method, RenderSettings, render};

fn auto_settings(gate: &str) -> RenderSettings {
    RenderSettings {
        width: 32,
        height: 32,
        max_bounces: 4,
        method: Method::Auto,
        gate: Gate::parse(gate).unwrap(),
        connections_per_query: gatetrace::integrator::bidirectional::default_connections_per_query(Method::Auto),
        seed: 11,
        ..Default::default()
    }
}

#[test]
fn pilot_picks_ellipsoidal_for_a_millimetre_gate_and_path_for_a_metre() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    // At 1 mm (0.03 % of the box's path lengths) the pilots measured ratios of hundreds in
    // ellipsoidal's favour; at 1 m, path's by 5-7x over direct (docs/methods.md, `auto`).
    for (gate, expected) in [("box:3.14..3.141", Method::Ellipsoidal), ("box:3.14..4.14", Method::Path)] {
        let output = render(ctx, &scene, &auto_settings(gate), Budget::Samples(256), |_| {}).unwrap();
        let choice = output.choice.expect("auto reports its choice");
        assert_eq!(choice.chosen, expected, "gate {gate}: {}", choice.reason);
        assert_eq!(output.film.spp, 256, "the film holds the budget's samples, the pilot's discarded");
        let methods: Vec<Method> = choice.candidates.iter().map(|c| c.method).collect();
        assert_eq!(methods, [Method::Path, Method::Direct, Method::Ellipsoidal]);
        // At 1 mm one method is hundreds of times ahead and the pilot stops after 4 batches of
        // each; at 1 m the lead is near the 8x that stops it early, so either may happen.
        let early = choice.reason.contains("stopped after 4 of 8 batches");
        if expected == Method::Ellipsoidal {
            assert!(early, "gate {gate}: {}", choice.reason);
        }
        for c in &choice.candidates {
            // 256 / 16 samples per method, in batches of 2.
            assert_eq!(c.spp, if early { 8 } else { 16 }, "{:?}", c.method);
            assert!(c.seconds > 0.0 && c.variance_per_sample.is_finite(), "{c:?}");
        }
        assert!(output.film.mean_rgb()[0] > 0.0, "gate {gate}: light reaches the gate");
    }
}

#[test]
fn pilot_renders_a_smaller_image_and_the_render_is_the_chosen_methods() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let settings = RenderSettings { width: 64, height: 64, ..auto_settings("box:3.14..3.141") };
    let auto = render(ctx, &scene, &settings, Budget::Samples(16), |_| {}).unwrap();
    let choice = auto.choice.expect("auto reports its choice");
    assert_eq!(choice.chosen, Method::Ellipsoidal, "{}", choice.reason);
    assert_eq!(choice.pilot_resolution, (32, 32));
    for c in &choice.candidates {
        // The work of 16 / 16 samples per pixel of 64x64 is 4 samples per pixel of 32x32, but a
        // batch takes one at least; the pilot stopped after 4 batches (see above).
        assert_eq!((c.spp, c.pixel_ratio), (4, 4.0), "{c:?}: {}", choice.reason);
    }
    // The pilot ran from a seed of its own: the image is ellipsoidal's with the same seed, bit
    // for bit (the film's sums are exact), where another seed differs by the noise itself.
    let direct = gatetrace::integrator::auto::candidate_settings(&settings, Method::Ellipsoidal);
    let same = render(ctx, &scene, &direct, Budget::Samples(16), |_| {}).unwrap().film;
    let other = render(ctx, &scene, &RenderSettings { seed: 12, ..direct }, Budget::Samples(16), |_| {}).unwrap().film;
    let largest = same.data.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let difference = |a: &[f32], b: &[f32]| a.iter().zip(b).fold(0.0f32, |m, (x, y)| m.max((x - y).abs())) / largest;
    assert!(largest > 0.0);
    assert!(
        auto.film.data == same.data,
        "auto's image differs from ellipsoidal's by {}",
        difference(&auto.film.data, &same.data)
    );
    assert!(difference(&other.data, &same.data) > 1e-2, "{}", difference(&other.data, &same.data));
}

#[test]
fn steady_state_pilots_path_and_direct_and_directional_lights_get_all_three() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let output = render(ctx, &scene, &auto_settings("none"), Budget::Samples(4), |_| {}).unwrap();
    let choice = output.choice.unwrap();
    let methods: Vec<Method> = choice.candidates.iter().map(|c| c.method).collect();
    assert_eq!(methods, [Method::Path, Method::Direct], "ellipsoidal needs a gate: {choice:?}");
    assert!(methods.contains(&choice.chosen) && choice.pilot_seconds > 0.0, "{choice:?}");
    assert_eq!(output.film.spp, 4);

    let path = common::repo_path("assets/scenes/cornell_box_directional.gltf");
    let scene = gatetrace::scene::PreparedScene::new(gatetrace::scene::load_gltf(&path).unwrap()).unwrap();
    let output = render(ctx, &scene, &auto_settings("box:3.6..3.7"), Budget::Samples(4), |_| {}).unwrap();
    // Ellipsoidal connections serve directional lights too: every method is measured.
    let choice = output.choice.unwrap();
    assert_eq!(choice.candidates.len(), 3, "{choice:?}");
    assert!(choice.pilot_seconds > 0.0, "{choice:?}");
    assert_eq!(output.film.spp, 4);
}

#[test]
fn a_time_budget_counts_the_pilot() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let budget = Budget::Time(std::time::Duration::from_secs_f64(2.0));
    let output = render(ctx, &scene, &auto_settings("box:3.14..3.19"), budget, |_| {}).unwrap();
    let choice = output.choice.unwrap();
    let rendering = output.rendering.as_secs_f64();
    assert!(choice.pilot_seconds > 0.0 && choice.pilot_seconds < rendering, "{choice:?} in {rendering} s");
    // The pilot's share is 5 % of the budget, or more when 8 one-sample batches of each method
    // take longer; the render ends within its budget (plus at most one pass's overrun).
    assert!(rendering < 2.0 * 1.5, "rendering took {rendering} s of a 2 s budget");
    assert!(output.film.spp >= 1);
}

#[test]
fn cli_records_the_choice_and_refuses_auto_where_it_does_not_apply() {
    let dir = common::scratch_dir("auto_cli");
    let out = dir.join("auto.npy");
    let o = Command::new(env!("CARGO_BIN_EXE_gatetrace"))
        .args(["render", "--method", "auto", "--gate", "box:3.14..3.141", "--res", "16x16", "--spp", "32"])
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("auto chose ellipsoidal"), "{stdout}");
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("auto.json")).unwrap()).unwrap();
    assert_eq!(meta["method"], "auto");
    assert_eq!(meta["chosen_method"], "ellipsoidal");
    assert!(meta["auto_pilot_direct"]["variance_per_sample"].as_f64().unwrap() > 0.0, "{meta}");
    assert!(meta["auto_pilot_direct"]["spp"].as_u64().unwrap() > 0, "{meta}");
    assert_eq!(meta["connections_per_query"], 4);

    for (args, message) in [
        (&["view", "--method", "auto"][..], "viewer renders progressively"),
        (&["render", "--method", "auto", "--nlos", "confocal", "--res", "4x4"][..], "NLOS"),
    ] {
        let o = Command::new(env!("CARGO_BIN_EXE_gatetrace")).args(args).output().unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && stderr.contains(message), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

/// Every place README.md and docs/ state `auto`'s pilot share ("N % of a `--time` budget", "N %
/// of each ... render") states the share the code uses, and the table of `auto`'s equal-time
/// figures states the conditions they were measured under (the pilot, the budget).
#[test]
fn the_docs_state_autos_pilot_share_as_the_code_has_it() {
    let share = (gatetrace::integrator::auto::PILOT_SHARE * 100.0).round() as u32;
    let mut claims = Vec::new();
    for page in ["README.md", "docs/methods.md", "docs/design.md"] {
        let text = std::fs::read_to_string(common::repo_path(page)).unwrap().replace('\n', " ");
        for phrase in [" % of a `--time` budget", " % of each "] {
            for (at, _) in text.match_indices(phrase) {
                let number: String = text[..at]
                    .chars()
                    .rev()
                    .take_while(|c| c.is_ascii_digit())
                    .collect::<Vec<_>>()
                    .into_iter()
                    .rev()
                    .collect();
                claims.push((page, number));
            }
        }
    }
    assert!(claims.len() >= 4, "the pilot's share is stated in README.md and docs/: {claims:?}");
    for (page, number) in &claims {
        assert_eq!(*number, share.to_string(), "{page} states a pilot of {number} %, the code takes {share} %");
    }
    let methods = std::fs::read_to_string(common::repo_path("docs/methods.md")).unwrap().replace('\n', " ");
    assert!(
        methods.contains("Every `auto` figure includes its pilot"),
        "docs/methods.md's table of auto's figures states that they include the pilot"
    );
}
