//! The `gatetrace` command: outputs with their metadata, help text, and errors for bad input.

mod common;

use std::process::{Command, Output};

use gatetrace::film::output::read_npy_f32;

fn gatetrace(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gatetrace")).args(args).output().expect("the binary runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn help_explains_units() {
    let o = gatetrace(&["render", "--help"]);
    assert!(o.status.success());
    let text = String::from_utf8_lossy(&o.stdout).split_whitespace().collect::<Vec<_>>().join(" ");
    for needle in ["metres", "ps", "box:A..B", "transient:START,WIDTH,BINS", "--spp", "--time", "[H, W, T, 3]"] {
        assert!(text.contains(needle), "render --help should mention `{needle}`:\n{text}");
    }
}

/// The help text `gatetrace ARGS` prints (with --help or -h among ARGS).
fn help(args: &[&str]) -> String {
    let o = gatetrace(args);
    assert!(o.status.success(), "gatetrace {}: {}", args.join(" "), stderr(&o));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The subcommands `gatetrace --help` lists (without `help`).
fn subcommands() -> Vec<String> {
    let text = help(&["--help"]);
    let list = text.split("Commands:").nth(1).expect("a Commands section");
    let names: Vec<String> = list
        .lines()
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        .filter(|l| l.starts_with("  ") && !l.starts_with("   "))
        .map(|l| l.split_whitespace().next().unwrap().to_owned())
        .filter(|n| n != "help")
        .collect();
    assert!(names.len() >= 6, "subcommands {names:?} in:\n{text}");
    names
}

/// The options of a long help text, each with the lines of its description.
fn options(text: &str) -> Vec<(String, Vec<String>)> {
    let mut out: Vec<(String, Vec<String>)> = Vec::new();
    for line in text.lines() {
        let t = line.trim_start();
        // Options are indented by 2 to 6 spaces, their descriptions by 10.
        let indent = line.len() - t.len();
        let is_option = (2..=6).contains(&indent) && t.starts_with('-') && t.contains("--");
        if is_option && let Some(name) = t.split("--").nth(1) {
            let name = name.split([' ', '<', ',']).next().unwrap();
            out.push((name.to_owned(), Vec::new()));
        } else if let Some((_, lines)) = out.last_mut() {
            lines.push(t.to_owned());
        }
    }
    out
}

/// Option name -> its `[default: ...]`, if any.
fn defaults(text: &str) -> std::collections::BTreeMap<String, Option<String>> {
    options(text)
        .into_iter()
        .map(|(name, lines)| {
            let default = lines.iter().find_map(|l| l.strip_prefix("[default: ")?.strip_suffix(']').map(str::to_owned));
            (name, default)
        })
        .collect()
}

/// Help is plain text: doc comments' markup (backticks, intra-doc links such as [auto] or
/// [crate::film::Gate]) must not reach it, in any subcommand's short or long help.
#[test]
fn help_has_no_rustdoc_markup() {
    let mut commands: Vec<Vec<String>> = vec![vec![]];
    commands.extend(subcommands().into_iter().map(|c| vec![c]));
    for command in commands {
        for flag in ["--help", "-h"] {
            let mut args: Vec<&str> = command.iter().map(String::as_str).collect();
            args.push(flag);
            let text = help(&args);
            let name = args.join(" ");
            assert!(!text.contains('`'), "gatetrace {name} shows backticks:\n{text}");
            for link in text.split('[').skip(1).filter_map(|rest| rest.split_once(']').map(|(inside, _)| inside)) {
                // Clap's own brackets: [OPTIONS], [SCENE], [default: ...], [possible values: ...];
                // the help's intervals and shapes: [A, B), [H, W, 3].
                let identifier = !link.is_empty()
                    && link.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == ':')
                    && link.chars().any(|c| c.is_ascii_lowercase());
                assert!(!identifier, "gatetrace {name} shows a rustdoc link [{link}]:\n{text}");
            }
        }
    }
}

/// `view --help` lists just the methods the viewer renders (path, direct, ellipsoidal: the
/// window's buttons), and the viewer accepts each and refuses the others.
#[test]
fn view_help_lists_only_the_methods_the_viewer_renders() {
    let text = help(&["view", "--help"]);
    let (_, method) = options(&text).into_iter().find(|(name, _)| name == "method").expect("view --method");
    let listed: Vec<String> =
        method.iter().filter_map(|l| l.strip_prefix("- ")?.split(':').next().map(|n| n.trim().to_owned())).collect();
    assert_eq!(listed, ["path", "direct", "ellipsoidal"], "view --method lists {listed:?}:\n{text}");
    for name in ["path", "direct", "ellipsoidal"] {
        // Accepted: the run gets as far as the later check of --bin (no window opens).
        let o = gatetrace(&["view", "--method", name, "--bin", "1"]);
        assert!(stderr(&o).contains("--bin 1 applies to transient gates only"), "{name}: {}", stderr(&o));
    }
    for name in ["combined", "auto"] {
        let o = gatetrace(&["view", "--method", name]);
        assert!(!o.status.success() && stderr(&o).contains("viewer renders progressively"), "{name}: {}", stderr(&o));
    }
    let o = gatetrace(&["view", "--method", "bogus"]);
    assert!(!o.status.success() && stderr(&o).contains("possible values: path, direct, ellipsoidal"), "{}", stderr(&o));
}

/// `view` and `render` take the options they share with the same defaults.
#[test]
fn view_takes_the_defaults_of_render() {
    let render_help = help(&["render", "--help"]);
    let render = defaults(&render_help);
    let view = defaults(&help(&["view", "--help"]));
    let shared: Vec<&String> = view.keys().filter(|k| render.contains_key(*k)).collect();
    for option in ["gate", "res", "max-bounces", "rr-depth", "seed", "method", "aperture-radius", "focus-distance"] {
        assert!(shared.iter().any(|k| *k == option), "view lacks render's --{option} (shared: {shared:?})");
    }
    for option in shared {
        if option == "method" {
            // render's default depends on --nlos (a capture renders with ellipsoidal), which the
            // viewer does not take; for images it is the viewer's.
            let text = render_help.split_whitespace().collect::<Vec<_>>().join(" ");
            assert!(text.contains("Default: path; for --nlos captures"), "render --help: {text}");
            assert_eq!(view[option].as_deref(), Some("path"));
            continue;
        }
        assert_eq!(view[option], render[option], "--{option}: view's default differs from render's");
    }
}

/// --bin picks a bin of a transient gate's cube; others are refused before a window opens.
#[test]
fn view_refuses_a_bin_outside_the_transient_cube() {
    let o = gatetrace(&["view", "--gate", "transient:3,0.1,8", "--bin", "8"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--bin 8: the transient gate transient:3,0.1,8 has bins 0 to 7"), "{}", stderr(&o));
    let o = gatetrace(&["view", "--gate", "box:3.1..3.2", "--bin", "2"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--bin 2 applies to transient gates only"), "{}", stderr(&o));
}

#[test]
fn npy_output_has_the_documented_layout_and_metadata() {
    let dir = common::scratch_dir("cli_npy");
    let out = dir.join("steady.npy");
    let o = gatetrace(&[
        "render",
        "--res",
        "12x8",
        "--spp",
        "4",
        "--max-bounces",
        "2",
        "--seed",
        "5",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (shape, data) = read_npy_f32(&out).unwrap();
    assert_eq!(shape, vec![8, 12, 3], "[H, W, 3]");
    assert!(data.iter().all(|v| v.is_finite()) && data.iter().any(|&v| v > 0.0));
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("steady.json")).unwrap()).unwrap();
    for key in ["scene", "method", "gate", "spp", "seed", "elapsed_seconds", "adapter"] {
        assert!(meta.get(key).is_some(), "metadata lacks `{key}`: {meta}");
    }
    // Numbers are numbers, the gate is in metres beside its spec.
    assert_eq!(meta["spp"], 4);
    assert_eq!(meta["seed"], 5);
    assert_eq!(meta["method"], "path");
    assert_eq!(meta["resolution"], serde_json::json!([12, 8]));
    assert!(meta["elapsed_seconds"].is_f64() && meta["rendering_seconds"].is_f64(), "{meta}");
    assert!(meta["max_bounces"].is_u64() && meta["truncated_traversals"] == 0, "{meta}");
    assert_eq!(meta["gate_parameters"], serde_json::json!({ "kind": "none" }));

    let cube = dir.join("cube.npy");
    let o = gatetrace(&[
        "render",
        "--res",
        "6x4",
        "--spp",
        "2",
        "--gate",
        "transient:1.9,0.5,7",
        "--out",
        cube.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (shape, _) = read_npy_f32(&cube).unwrap();
    assert_eq!(shape, vec![4, 6, 7, 3], "[H, W, T, 3]");
}

#[test]
fn exr_output_has_a_layer_per_bin_and_metadata() {
    use exr::prelude::*;
    let dir = common::scratch_dir("cli_exr");
    let out = dir.join("cube.exr");
    let o = gatetrace(&[
        "render",
        "--res",
        "6x4",
        "--spp",
        "2",
        "--gate",
        "transient:6.5ns,200ps,5",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let image = read_all_data_from_file(&out).unwrap();
    assert_eq!(image.layer_data.len(), 5, "one layer per bin");
    // Custom attributes are stored in the headers; the reader files them under the layers.
    let attribute = |key: &str| {
        let key = Text::from(key);
        image.attributes.other.get(&key).or_else(|| image.layer_data[0].attributes.other.get(&key)).cloned()
    };
    let gate = attribute("gatetrace.gate").expect("gate attribute");
    assert!(matches!(&gate, AttributeValue::Text(t) if t == "transient:6.5ns,200ps,5"), "{gate:?}");
    assert!(attribute("gatetrace.adapter").is_some());
    assert!(matches!(attribute("gatetrace.spp"), Some(AttributeValue::Text(t)) if t.to_string() == "2"));
    // Structured values are JSON text: the gate in metres, whatever units it was typed in.
    let Some(AttributeValue::Text(parameters)) = attribute("gatetrace.gate_parameters") else {
        panic!("gate_parameters attribute")
    };
    let parameters: serde_json::Value = serde_json::from_str(&parameters.to_string()).unwrap();
    assert_eq!(parameters["kind"], "transient");
    assert_eq!(parameters["bins"], 5);
    let c = 0.299792458;
    assert!((parameters["start_m"].as_f64().unwrap() - 6.5 * c).abs() < 1e-12, "{parameters}");
    assert!((parameters["bin_width_m"].as_f64().unwrap() - 0.2 * c).abs() < 1e-12, "{parameters}");
    for layer in &image.layer_data {
        assert_eq!(layer.size, Vec2(6, 4));
        assert_eq!(layer.channel_data.list.len(), 3);
    }
}

#[test]
fn time_budget_renders_passes_sized_to_the_budget() {
    // Passes are sized from the measured rate (PassSizer): at least one sample, the rendering
    // time recorded apart from the setup's.
    let dir = common::scratch_dir("cli_time");
    let out = dir.join("timed.npy");
    let o = gatetrace(&[
        "render",
        "--res",
        "8x8",
        "--time",
        "0.5",
        "--samples-per-pass",
        "3",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("timed.json")).unwrap()).unwrap();
    let number = |key: &str| -> f64 { meta[key].as_f64().unwrap() };
    assert!(number("spp") >= 1.0, "no sample rendered");
    let rendering = number("rendering_seconds");
    assert!(rendering > 0.0, "no rendering time recorded: {meta}");
}

#[test]
fn without_an_adapter_the_error_says_how_to_get_one() {
    // Point the Vulkan loader at no driver at all.
    let o = Command::new(env!("CARGO_BIN_EXE_gatetrace"))
        .args(["render", "--res", "4x4", "--spp", "1", "--out", "/dev/null.npy"])
        .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
        .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
        .env_remove("WGPU_ADAPTER_NAME")
        .env_remove("WGPU_BACKEND")
        .output()
        .unwrap();
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("no GPU adapter") && e.contains("mesa-vulkan-drivers"), "{e}");
}

#[test]
fn stats_report_connections_per_strategy() {
    let dir = common::scratch_dir("cli_stats");
    let out = dir.join("gated.npy");
    let o = gatetrace(&[
        "render",
        "--method",
        "direct",
        "--res",
        "8x8",
        "--spp",
        "2",
        "--max-bounces",
        "2",
        "--gate",
        "box:3.14..3.19",
        "--stats",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(text.contains("skipped by gate") && text.contains("shadow rays"), "{text}");
    // One row per strategy with at most 2 bounces, (0,2) .. (3,1), and a total.
    for st in ["( 0, 2)", "( 1, 1)", "( 2, 2)", "( 3, 1)", "total"] {
        assert!(text.contains(st), "row {st} missing:\n{text}");
    }
}

#[test]
fn profile_reports_gpu_time_per_stage() {
    // A gate of one bin on the Cornell box traces whole paths; a transient gate runs rounds.
    check_profile("box:3.14..3.19", &["trace_paths", "accumulate"]);
    check_profile(
        "transient:3.0,0.05,8",
        &["generate_camera_rays", "extend_paths", "accumulate", "setup_dispatch(rays)"],
    );
}

/// Renders the Cornell box with `--profile` and `gate`, and checks that each of `stages` has a
/// row with time and dispatches, all within the render's wall time.
fn check_profile(gate: &str, stages: &[&str]) {
    let dir = common::scratch_dir("cli_profile");
    let out = dir.join("p.npy");
    let o = gatetrace(&[
        "render",
        "--res",
        "16x16",
        "--spp",
        "8",
        "--max-bounces",
        "3",
        "--gate",
        gate,
        "--profile",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    let wall_seconds: f64 = {
        let meta: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("p.json")).unwrap()).unwrap();
        meta["elapsed_seconds"].as_f64().unwrap()
    };
    let mut total_ms = 0.0;
    for stage in stages {
        let row = text
            .lines()
            .find(|l| l.split_whitespace().next() == Some(stage))
            .unwrap_or_else(|| panic!("no row for {stage} ({gate}):\n{text}"));
        let cols: Vec<&str> = row.split_whitespace().collect();
        let ms: f64 = cols[1].parse().unwrap();
        let dispatches: u64 = cols[3].parse().unwrap();
        assert!(ms > 0.0 && dispatches > 0, "{row}");
        total_ms += ms;
    }
    // A check of the timestamp units, not of speed: the stages ran inside the render's wall
    // time (a wrong tick period would put them orders of magnitude off).
    assert!(
        total_ms > 0.0 && total_ms / 1e3 <= wall_seconds + 1.0,
        "{total_ms} ms of stages in a {wall_seconds} s render"
    );
}

#[test]
fn a_missing_output_directory_is_an_error_unless_mkdir_asks_for_it() {
    let dir = common::scratch_dir("cli_mkdir");
    let missing = dir.join("made/deeper");
    let _ = std::fs::remove_dir_all(dir.join("made"));
    let out = missing.join("x.npy");
    let args = ["render", "--res", "6x4", "--spp", "1", "--max-bounces", "1", "--out", out.to_str().unwrap()];
    let o = gatetrace(&args);
    assert!(!o.status.success(), "a missing directory must be an error");
    let err = stderr(&o);
    assert!(err.contains(&format!("{}: no such directory", missing.display())) && err.contains("--mkdir"), "{err}");
    assert!(!dir.join("made").exists(), "the failed render created a directory");
    let o = gatetrace(&[&args[..], &["--mkdir"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.exists() && missing.join("x.json").exists());
}

#[test]
fn a_gate_no_path_reaches_is_said_and_times_typed_as_metres_are_named() {
    let dir = common::scratch_dir("cli_black");
    // Renders the box with 3 bounces at `gate` to NAME.npy: (stderr, metadata).
    let render = |name: &str, gate: &str| -> (String, serde_json::Value) {
        let out = dir.join(format!("{name}.npy"));
        let args = ["--max-bounces", "3", "--res", "8x8", "--spp", "2", "--out", out.to_str().unwrap()];
        let o = gatetrace(&[&["render", "--gate", gate], &args[..]].concat());
        assert!(o.status.success(), "{}", stderr(&o));
        let meta = serde_json::from_str(&std::fs::read_to_string(out.with_extension("json")).unwrap()).unwrap();
        (stderr(&o), meta)
    };
    // Nanoseconds without their unit: 10.474 m lies beyond every 3-bounce path of the box.
    let (err, meta) = render("late", "box:10.474..10.641");
    assert!(err.contains("warning") && err.contains("longest path possible with 3 bounces"), "{err}");
    assert!(err.contains("`box:10.474ns..10.641ns`"), "the hint names the gate meant: {err}");
    assert!(meta["warning"].as_str().unwrap().contains("image is black"), "{meta}");

    // Reachable in principle, but no sample reaches a gaussian this far out: still said.
    let (err, _) = render("far", "gaussian:10.5,0.05");
    assert!(err.contains("the image is black: no path of its 2 samples per pixel reached"), "{err}");
    assert!(err.contains("`gaussian:10.5ns,0.05ns`"), "{err}");

    // A gate with its units, or with light, gets no such warning.
    for gate in ["box:3.14..3.19", "box:10.474ns..10.641ns"] {
        let out = dir.join("lit.npy");
        let o = gatetrace(&["render", "--gate", gate, "--res", "8x8", "--spp", "4", "--out", out.to_str().unwrap()]);
        assert!(o.status.success() && !stderr(&o).contains("warning"), "{gate}: {}", stderr(&o));
    }
}

/// Reads an 8-bit RGB PNG: (width, height, bytes).
fn read_png(path: &std::path::Path) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut bytes = vec![0; reader.output_buffer_size()];
    let frame = reader.next_frame(&mut bytes).unwrap();
    assert_eq!((frame.color_type, frame.bit_depth), (png::ColorType::Rgb, png::BitDepth::Eight));
    bytes.truncate(frame.buffer_size());
    (frame.width, frame.height, bytes)
}

#[test]
fn png_outputs_are_previews_with_their_exposure_and_info_reads_every_output() {
    let dir = common::scratch_dir("cli_preview");
    let render = |name: &str, extra: &[&str]| {
        let out = dir.join(name);
        let o = gatetrace(
            &[&["render", "--res", "16x12", "--spp", "8", "--seed", "3"], extra, &["--out", out.to_str().unwrap()]]
                .concat(),
        );
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        out
    };
    // A steady preview at a stated exposure is the data through the viewer's tone curve.
    let data = render("steady.npy", &[]);
    let png = render("steady.png", &["--exposure", "1.5"]);
    let (w, h, bytes) = read_png(&png);
    assert_eq!((w, h), (16, 12));
    let (_, values) = read_npy_f32(&data).unwrap();
    let expected: Vec<u8> = values.iter().map(|&v| gatetrace::film::preview::tone_srgb(v, 1.5f32.exp2())).collect();
    assert_eq!(bytes, expected, "the preview is the image's tone-mapped bytes");
    let info = gatetrace(&["info", png.to_str().unwrap(), "--json"]);
    assert!(info.status.success(), "{}", stderr(&info));
    let info: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    assert_eq!(info["metadata"]["preview"]["exposure_ev"], 1.5, "{info}");
    assert_eq!(info["metadata"]["spp"], 8, "{info}");

    // A transient: a contact sheet of its bins at one automatic exposure, or one bin.
    let gate = ["--gate", "transient:6.5ns,200ps,6"];
    let sheet = render("cube.png", &gate);
    let (w, h, _) = read_png(&sheet);
    let gap = gatetrace::film::preview::TILE_GAP;
    assert_eq!((w, h), (3 * 16 + 2 * gap, 2 * 12 + gap), "6 bins as 3 x 2 tiles");
    let one = render("bin2.png", &[&gate[..], &["--preview-bin", "2"]].concat());
    assert_eq!(read_png(&one).0, 16);

    // info: layout, the gate in metres and the units, for every format.
    let cube = render("cube.npy", &gate);
    let exr = render("cube.exr", &gate);
    for (file, layout) in [(&cube, "[H, W, T, 3]"), (&exr, "6 layer(s) of 16x12 pixels"), (&sheet, "preview")] {
        let o = gatetrace(&["info", file.to_str().unwrap()]);
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success(), "{}", stderr(&o));
        for needle in [layout, "transient:6.5ns,200ps,6", "bin_width_m 0.0599584916", "bins 6", "units:", "spp 8"] {
            assert!(text.contains(needle), "info {}: no `{needle}` in\n{text}", file.display());
        }
    }
    assert!(String::from_utf8_lossy(&gatetrace(&["info", sheet.to_str().unwrap()]).stdout).contains("6 tile(s)"));
    let o = gatetrace(&["info", dir.join("none.npy").to_str().unwrap()]);
    assert!(!o.status.success() && stderr(&o).contains("none.npy: no such file"), "{}", stderr(&o));
}
