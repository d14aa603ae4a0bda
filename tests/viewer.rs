//! `gatetrace view` in a real window under `xvfb-run`: after N frames its screenshot's image
//! region is not blank and agrees, within noise, with headless renders of the same settings, for
//! the steady state and for transient (the bin shown), CW (the signed display) and table gates.
//! Needs `xvfb-run` (Debian package `xvfb`, installed by tools/setup.sh); without it the test
//! fails, never passes silently.

mod common;

use std::path::Path;
use std::process::Command;

use gatetrace::film::{Film, Gate};
use gatetrace::integrator::{Method, RenderSettings};

/// sRGB-encoded byte to linear [0, 1].
fn srgb_decode(byte: u8) -> f64 {
    let e = byte as f64 / 255.0;
    if e <= 0.04045 { e / 12.92 } else { ((e + 0.055) / 1.055).powf(2.4) }
}

fn read_png(path: &Path) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgba);
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

/// A screenshot of `gatetrace view` on the Cornell box: its sidecar, and the image region
/// sampled at the centre of each film pixel's square, as [H, W] of sRGB-encoded RGB bytes.
struct Shot {
    meta: serde_json::Value,
    spp: u32,
    pixels: Vec<[u8; 3]>,
}

/// Runs the viewer at `W` x `H` with `args` until its screenshot, and reads it back.
fn screenshot(name: &str, args: &[&str]) -> Shot {
    let xvfb = Command::new("sh").args(["-c", "command -v xvfb-run"]).output().unwrap();
    assert!(
        xvfb.status.success(),
        "xvfb-run is missing: install it (apt-get install xvfb xauth, as tools/setup.sh does) to run the viewer test"
    );
    let dir = common::scratch_dir(name);
    let shot = dir.join("shot.png");
    let res = format!("{W}x{H}");
    // One X server at a time, each on a display number of its own: `xvfb-run` kills its server
    // without waiting for it to exit, so a later `xvfb-run -a` starting from the same number can
    // pick a display whose dying server still holds it, and the viewer then finds no X server.
    static XVFB: std::sync::Mutex<()> = std::sync::Mutex::new(());
    static DISPLAYS: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let _one_at_a_time = XVFB.lock().unwrap_or_else(|e| e.into_inner());
    let mut o = None;
    // A second try only when no X server answered: that is the machine, not the viewer.
    for _ in 0..2 {
        let first_display =
            200 + (std::process::id() % 400) * 16 + DISPLAYS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let run = Command::new("xvfb-run")
            .args(["-n", &first_display.to_string(), "-a", "-s", "-screen 0 1280x900x24"])
            .args([env!("CARGO_BIN_EXE_gatetrace"), "view", "--res", &res])
            .args(args)
            .args(["--after-frames", "12", "--screenshot", shot.to_str().unwrap()])
            .output()
            .unwrap();
        let no_server = String::from_utf8_lossy(&run.stderr).contains("Failed to open connection to X server");
        o = Some(run);
        if !no_server {
            break;
        }
    }
    let o = o.unwrap();
    assert!(
        o.status.success(),
        "the viewer failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("shot.json")).unwrap()).unwrap();
    println!("{meta}");
    let rect: Vec<i64> = meta["image_rect_px"].as_array().unwrap().iter().map(|v| v.as_i64().unwrap()).collect();
    let spp = meta["spp"].as_u64().unwrap() as u32;
    assert!(spp >= 1);
    let (sw, _, png) = read_png(&shot);
    let (x0, y0) = (rect[0] as f64, rect[1] as f64);
    let zoom = (rect[2] - rect[0]) as f64 / W as f64;
    assert!(zoom >= 1.0 && ((rect[3] - rect[1]) as f64 / H as f64 - zoom).abs() < 0.05, "rect {rect:?}");
    let mut pixels = Vec::new();
    for y in 0..H {
        for x in 0..W {
            let sx = (x0 + (x as f64 + 0.5) * zoom) as u32;
            let sy = (y0 + (y as f64 + 0.5) * zoom) as u32;
            let i = ((sy * sw + sx) * 4) as usize;
            pixels.push([png[i], png[i + 1], png[i + 2]]);
        }
    }
    let distinct: std::collections::HashSet<[u8; 3]> = pixels.iter().copied().collect();
    assert!(distinct.len() > 20, "the image region is blank ({} distinct colours)", distinct.len());
    Shot { meta, spp, pixels }
}

/// Film size of the viewer tests (pixels).
const W: u32 = 32;
const H: u32 = 32;

/// Headless renders of the Cornell box with the viewer's settings: `batches` films of `spp`.
fn headless(gate: Gate, spp: u32, batches: usize) -> Vec<Film> {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let settings = RenderSettings {
        width: W,
        height: H,
        method: Method::Path,
        gate,
        max_bounces: 3,
        seed: 77,
        ..Default::default()
    };
    common::render_films(ctx, &scene, &settings, batches, spp)
}

/// Compares the quadrant means of `viewer` ([H, W, K] values as displayed) with those of the
/// headless `batches` (the same values of each batch, one image of the viewer's spp each): the
/// batches' spread is the noise of one image; 8-bit sRGB rounding adds at most half a step.
fn assert_quadrants_agree(label: &str, viewer: &[f64], batches: &[Vec<f64>]) {
    let k = viewer.len() / (W * H) as usize;
    let quadrant = |data: &[f64], q: u32| -> f64 {
        let mut sum = 0.0;
        let mut n = 0.0;
        for y in 0..H {
            for x in 0..W {
                if (x >= W / 2) as u32 + 2 * (y >= H / 2) as u32 == q {
                    for c in 0..k {
                        sum += data[(y * W + x) as usize * k + c];
                        n += 1.0;
                    }
                }
            }
        }
        sum / n
    };
    let count = batches.len() as f64;
    for q in 0..4 {
        let shown = quadrant(viewer, q);
        let batch_means: Vec<f64> = batches.iter().map(|b| quadrant(b, q)).collect();
        let mean = batch_means.iter().sum::<f64>() / count;
        let var = batch_means.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (count - 1.0);
        let quantisation = 0.5 / 255.0 * 2.4 / 1.055;
        let sigma = (var * (1.0 + 1.0 / count)).sqrt();
        let z = (shown - mean) / sigma;
        println!("{label}, quadrant {q}: viewer {shown:.5} headless {mean:.5} (sigma {sigma:.5}, z {z:+.2})");
        assert!(
            (shown - mean).abs() < 4.0 * sigma + quantisation,
            "{label}, quadrant {q}: viewer {shown} vs headless {mean} (sigma {sigma})"
        );
    }
}

/// The RGB display: linear values of every channel.
fn rgb_shown(shot: &Shot) -> Vec<f64> {
    shot.pixels.iter().flat_map(|p| p.map(srgb_decode)).collect()
}

/// The RGB display of a headless film's bin: radiance times the exposure, clamped to 1.
fn rgb_expected(film: &Film, bin: u32, exposure: f64) -> Vec<f64> {
    (0..H)
        .flat_map(|y| (0..W).map(move |x| (x, y)))
        .flat_map(|(x, y)| film.get(x, y, bin).map(|v| (v as f64 * exposure).min(1.0)))
        .collect()
}

#[test]
fn the_viewer_screenshot_matches_a_headless_render() {
    let shot = screenshot("viewer", &["--gate", "none", "--max-bounces", "3", "--exposure", "1"]);
    assert_eq!(shot.meta["display"], "rgb");
    let films = headless(Gate::None, shot.spp, 8);
    let batches: Vec<Vec<f64>> = films.iter().map(|f| rgb_expected(f, 0, 2.0)).collect();
    assert_quadrants_agree("steady state", &rgb_shown(&shot), &batches);
}

/// A transient gate renders its cube; the viewer shows the bin asked for with --bin, as the
/// same bin of a headless render of the cube.
#[test]
fn a_transient_gate_shows_the_chosen_bin() {
    let (start, width, bins, bin) = (3.0, 0.1, 8, 3);
    let spec = format!("transient:{start},{width},{bins}");
    let bin_arg = bin.to_string();
    let shot =
        screenshot("viewer_transient", &["--gate", &spec, "--bin", &bin_arg, "--max-bounces", "3", "--exposure", "3"]);
    assert_eq!(shot.meta["bin"], bin);
    assert_eq!(shot.meta["display"], "rgb");
    let films = headless(Gate::Transient { start, width, bins }, shot.spp, 8);
    let batches: Vec<Vec<f64>> = films.iter().map(|f| rgb_expected(f, bin, 8.0)).collect();
    assert_quadrants_agree("transient bin 3", &rgb_shown(&shot), &batches);
}

/// A CW gate's signed image shows its luminance on the diverging map: orange (red dominant)
/// above zero, blue (blue dominant) below, the dominant channel the tone curve of the
/// magnitude; it agrees with the headless render's signed luminance, and both signs show.
#[test]
fn a_cw_gate_shows_the_signed_luminance() {
    let (frequency_hz, phase_deg) = (300e6, 90.0);
    let spec = format!("cw:{frequency_hz},{phase_deg}");
    let shot = screenshot("viewer_cw", &["--gate", &spec, "--max-bounces", "3", "--exposure", "3"]);
    assert_eq!(shot.meta["display"], "signed luminance");
    let shown: Vec<f64> =
        shot.pixels.iter().map(|&[r, _, b]| if r >= b { srgb_decode(r) } else { -srgb_decode(b) }).collect();
    let positive = shown.iter().filter(|&&v| v > 0.05).count();
    let negative = shown.iter().filter(|&&v| v < -0.05).count();
    assert!(positive > 0 && negative > 0, "{positive} pixels above zero, {negative} below");
    let films = headless(Gate::Cw { frequency_hz, phase_deg }, shot.spp, 8);
    let batches: Vec<Vec<f64>> = films
        .iter()
        .map(|f| {
            (0..H)
                .flat_map(|y| (0..W).map(move |x| (x, y)))
                .map(|(x, y)| {
                    let c = f.get(x, y, 0).map(|v| v as f64);
                    ((0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]) * 8.0).clamp(-1.0, 1.0)
                })
                .collect()
        })
        .collect();
    assert_quadrants_agree("cw", &shown, &batches);
}

/// A table gate renders like `render --gate table:FILE.csv`.
#[test]
fn a_table_gate_matches_a_headless_render() {
    let dir = common::scratch_dir("viewer_table_csv");
    let csv = dir.join("gate.csv");
    std::fs::write(&csv, "3.1,0\n3.2,1\n3.5,0.5\n3.9,0\n").unwrap();
    let spec = format!("table:{}", csv.display());
    let shot = screenshot("viewer_table", &["--gate", &spec, "--max-bounces", "3", "--exposure", "3"]);
    assert_eq!(shot.meta["display"], "rgb");
    let gate = Gate::parse(&spec).unwrap();
    let films = headless(gate, shot.spp, 8);
    let batches: Vec<Vec<f64>> = films.iter().map(|f| rgb_expected(f, 0, 8.0)).collect();
    assert_quadrants_agree("table", &rgb_shown(&shot), &batches);
}
