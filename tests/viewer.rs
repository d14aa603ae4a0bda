//! `gatetrace view` in a real window under `xvfb-run`: after N frames its screenshot's image
//! region is not blank and agrees, within noise, with headless renders of the same settings.
//! Needs `xvfb-run` (Debian package `xvfb`, installed by tools/setup.sh); without it the test
//! fails, never passes silently.

mod common;

use std::path::Path;
use std::process::Command;

use gatetrace::film::Gate;
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

#[test]
fn the_viewer_screenshot_matches_a_headless_render() {
    let xvfb = Command::new("sh").args(["-c", "command -v xvfb-run"]).output().unwrap();
    assert!(
        xvfb.status.success(),
        "xvfb-run is missing: install it (apt-get install xvfb xauth, as tools/setup.sh does) to run the viewer test"
    );
    let dir = common::scratch_dir("viewer");
    let shot = dir.join("shot.png");
    let (w, h) = (32u32, 32u32);
    let exposure_ev = 1.0;
    let o = Command::new("xvfb-run")
        .args([
            "-a",
            "-s",
            "-screen 0 1280x900x24",
            env!("CARGO_BIN_EXE_gatetrace"),
            "view",
            "--res",
            "32x32",
            "--gate",
            "none",
        ])
        .args(["--max-bounces", "3", "--exposure", "1", "--after-frames", "12", "--screenshot", shot.to_str().unwrap()])
        .output()
        .unwrap();
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
    let spp = meta["spp"].as_u64().unwrap();
    assert!(spp >= 1);
    let (sw, _, pixels) = read_png(&shot);
    // The image region, sampled at the centre of each film pixel's square.
    let (x0, y0) = (rect[0] as f64, rect[1] as f64);
    let zoom = (rect[2] - rect[0]) as f64 / w as f64;
    assert!(zoom >= 1.0 && ((rect[3] - rect[1]) as f64 / h as f64 - zoom).abs() < 0.05, "rect {rect:?}");
    let mut shown = vec![0.0; (w * h * 3) as usize];
    for y in 0..h {
        for x in 0..w {
            let sx = (x0 + (x as f64 + 0.5) * zoom) as u32;
            let sy = (y0 + (y as f64 + 0.5) * zoom) as u32;
            for c in 0..3 {
                shown[((y * w + x) * 3 + c) as usize] = srgb_decode(pixels[((sy * sw + sx) * 4 + c) as usize]);
            }
        }
    }
    let distinct: std::collections::HashSet<u64> = shown.iter().map(|v| v.to_bits()).collect();
    assert!(distinct.len() > 20, "the image region is blank ({} distinct values)", distinct.len());

    // Headless renders of the same settings: batches of the viewer's spp, displayed the same way
    // (exposure, clamp to 1).
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let settings = RenderSettings {
        width: w,
        height: h,
        method: Method::Path,
        gate: Gate::None,
        max_bounces: 3,
        seed: 77,
        ..Default::default()
    };
    let batches = 8;
    let films = common::render_films(&ctx, &scene, &settings, batches, spp as u32);
    let exposure = 2f64.powf(exposure_ev);
    // Quadrant means: viewer vs the batches' mean, with the batches' spread as the noise of one
    // image of `spp` samples.
    let quadrant = |data: &dyn Fn(usize) -> f64, q: u32| -> f64 {
        let mut sum = 0.0;
        let mut n = 0.0;
        for y in 0..h {
            for x in 0..w {
                if (x >= w / 2) as u32 + 2 * (y >= h / 2) as u32 == q {
                    for c in 0..3 {
                        sum += data(((y * w + x) * 3 + c) as usize);
                        n += 1.0;
                    }
                }
            }
        }
        sum / n
    };
    for q in 0..4 {
        let viewer = quadrant(&|i| shown[i], q);
        let batch_means: Vec<f64> =
            films.iter().map(|f| quadrant(&|i| (f.data[i] as f64 * exposure).min(1.0), q)).collect();
        let mean = batch_means.iter().sum::<f64>() / batches as f64;
        let var = batch_means.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (batches - 1) as f64;
        // 8-bit sRGB rounding: at most half a step of the decoded value per pixel.
        let quantisation = 0.5 / 255.0 * 2.4 / 1.055;
        let sigma = (var * (1.0 + 1.0 / batches as f64)).sqrt();
        let z = (viewer - mean) / sigma;
        println!("quadrant {q}: viewer {viewer:.5} headless {mean:.5} (sigma {sigma:.5}, z {z:+.2})");
        assert!(
            (viewer - mean).abs() < 4.0 * sigma + quantisation,
            "quadrant {q}: viewer {viewer} vs headless {mean} (sigma {sigma})"
        );
    }
}
