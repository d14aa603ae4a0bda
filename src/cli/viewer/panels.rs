//! The viewer's window: the gate's controls, the method and display controls, the time
//! profile's plot, each frame's layout, and the screenshot mode (a PNG with its JSON sidecar).

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, anyhow};
use eframe::egui;

use gatetrace::film::Gate;
use gatetrace::integrator::Method;
use gatetrace::units::metres_to_ps;

use super::Viewer;
use super::gate::{GateChoice, KEEP, length_range};

impl Viewer<'_> {
    /// The gate's kind and, per kind, what moves it through time: τ (box, Gaussian), the bin
    /// shown (transient), the phase (CW), the shift (table).
    pub(super) fn gate_controls(&mut self, ui: &mut egui::Ui) {
        let g = &mut self.gate;
        ui.heading("Gate");
        ui.horizontal_wrapped(|ui| {
            ui.selectable_value(&mut g.kind, GateChoice::None, "none");
            ui.selectable_value(&mut g.kind, GateChoice::Box, "box");
            ui.selectable_value(&mut g.kind, GateChoice::Gaussian, "gaussian");
            ui.selectable_value(&mut g.kind, GateChoice::Transient, "transient");
            ui.selectable_value(&mut g.kind, GateChoice::Cw, "cw");
            if g.table.is_some() {
                ui.selectable_value(&mut g.kind, GateChoice::Table, "table");
            }
        });
        let (lo, hi) = length_range(self.lengths);
        let length = |ui: &mut egui::Ui, value: &mut f64| {
            ui.horizontal(|ui| {
                ui.add(
                    egui::DragValue::new(value)
                        .speed(0.0005)
                        .range(0.0..=1e4)
                        .clamp_existing_to_range(false)
                        .suffix(" m"),
                );
                ui.label(format!("= {:.1} ps = {:.4} ns", metres_to_ps(*value), metres_to_ps(*value) / 1e3));
            });
        };
        match g.kind {
            GateChoice::None => {
                ui.label("steady state");
            }
            GateChoice::Box | GateChoice::Gaussian => {
                ui.label("centre τ (m of optical path)");
                ui.add(egui::Slider::new(&mut g.tau, lo..=hi).max_decimals(5).clamping(KEEP));
                length(ui, &mut g.tau);
                ui.label(if g.kind == GateChoice::Gaussian { "σ (m)" } else { "width (m)" });
                ui.add(egui::Slider::new(&mut g.width, 1e-4..=1.0).logarithmic(true).max_decimals(5).clamping(KEEP));
                ui.label(format!("= {:.2} ps", metres_to_ps(g.width)));
            }
            GateChoice::Transient => {
                g.bins = g.bins.max(1);
                g.bin = g.bin.min(g.bins - 1);
                ui.label("bin shown");
                ui.add(egui::Slider::new(&mut g.bin, 0..=g.bins - 1));
                let (a, b) = (
                    g.transient_start + g.bin as f64 * g.bin_width,
                    g.transient_start + (g.bin + 1) as f64 * g.bin_width,
                );
                ui.label(format!("[{a:.4} m, {b:.4} m) = [{:.1} ps, {:.1} ps)", metres_to_ps(a), metres_to_ps(b)));
                ui.label("start of bin 0 (m of optical path)");
                length(ui, &mut g.transient_start);
                ui.horizontal(|ui| {
                    ui.label("bins");
                    ui.add(egui::DragValue::new(&mut g.bins).range(1..=4096).clamp_existing_to_range(false));
                    ui.label("of");
                    ui.add(
                        egui::DragValue::new(&mut g.bin_width)
                            .speed(0.0005)
                            .range(1e-6..=10.0)
                            .clamp_existing_to_range(false)
                            .suffix(" m"),
                    );
                });
                ui.label("(the cube accumulates as a whole: moving the bin shown keeps the samples)");
            }
            GateChoice::Cw => {
                ui.label("phase (degrees)");
                ui.add(egui::Slider::new(&mut g.phase_deg, -180.0..=180.0).max_decimals(2).clamping(KEEP));
                ui.horizontal(|ui| {
                    ui.label("frequency");
                    let mut mhz = g.frequency_hz / 1e6;
                    if ui
                        .add(
                            egui::DragValue::new(&mut mhz)
                                .speed(1.0)
                                .range(1e-3..=1e5)
                                .clamp_existing_to_range(false)
                                .suffix(" MHz"),
                        )
                        .changed()
                    {
                        g.frequency_hz = mhz * 1e6;
                    }
                });
                ui.label(match g.code {
                    Some(code) => format!("code {}", code.name()),
                    None => "code: cosine".into(),
                });
            }
            GateChoice::Table => {
                if let Some((points, source)) = &g.table {
                    ui.label(format!("{} ({} points), moved by (m)", source.display(), points.len()));
                    // Never below zero length.
                    let least = -points[0].0;
                    ui.add(
                        egui::Slider::new(&mut g.table_shift, least.max(lo - hi)..=hi - lo)
                            .max_decimals(5)
                            .clamping(KEEP),
                    );
                    ui.add(egui::DragValue::new(&mut g.table_shift).speed(0.0005).range(least..=1e4).suffix(" m"));
                }
            }
        }
        if g.gate().is_signed() {
            ui.label("signed gate: the luminance is shown, orange above zero, blue below, black at zero");
        }
        ui.separator();
    }

    pub(super) fn controls(&mut self, ui: &mut egui::Ui) {
        self.gate_controls(ui);
        let o = &mut self.options;
        ui.separator();
        ui.heading("Method");
        ui.horizontal(|ui| {
            ui.selectable_value(&mut o.method, Method::Path, "path");
            ui.selectable_value(&mut o.method, Method::Direct, "direct");
            ui.selectable_value(&mut o.method, Method::Ellipsoidal, "ellipsoidal");
        });
        if o.method == Method::Ellipsoidal && self.gate.kind == GateChoice::None {
            ui.label("(steady state: ellipsoidal needs a gate; rendering with direct)");
        }
        ui.add(egui::Slider::new(&mut o.max_bounces, 0..=12).text("max bounces").clamping(KEEP));
        ui.separator();
        ui.heading("Display");
        ui.horizontal(|ui| {
            ui.add(egui::Slider::new(&mut o.exposure_ev, -20.0..=30.0).text("exposure (EV)").clamping(KEEP));
        });
        if ui.button("auto exposure").clicked() {
            self.auto_exposure_pending = true;
        }
        ui.horizontal(|ui| {
            ui.selectable_value(&mut o.log_curve, false, "linear");
            ui.selectable_value(&mut o.log_curve, true, "log (4 decades)");
        });
        ui.separator();
        if let Some(tracer) = &self.tracer {
            ui.label(format!("{} samples per pixel", tracer.samples_done()));
        }
        ui.label(format!("{:.3} Msamples/s", self.timing.samples_per_second / 1e6));
        if let Some(l) = self.timing.last_latency {
            ui.label(format!("gate change -> image: {:.0} ms", l.as_secs_f64() * 1e3));
        }
        let t = &self.timing.frame_times;
        if t.len() >= 2 {
            let recent = &t[t.len().saturating_sub(20)..];
            let mean = recent.iter().sum::<Duration>().as_secs_f64() / recent.len() as f64;
            ui.label(format!("refresh: {:.1} frames/s", 1.0 / mean.max(1e-9)));
        }
        ui.label(format!("device: {}", self.ctx.adapter_info.name));
        ui.separator();
        ui.horizontal(|ui| {
            for ext in ["exr", "npy"] {
                if ui.button(format!("save .{ext}")).clicked() {
                    let stem = self.options.scene.file_stem().and_then(|s| s.to_str()).unwrap_or("view").to_owned();
                    let path = PathBuf::from(format!("{stem}_view.{ext}"));
                    self.message = match self.save(&path) {
                        Ok(()) => format!("saved {}", path.display()),
                        Err(e) => format!("{e:#}"),
                    };
                }
            }
        });
        if !self.message.is_empty() {
            ui.label(&self.message);
        }
    }

    pub(super) fn profile_plot(&self, ui: &mut egui::Ui) {
        use egui_plot::{Line, Plot, Span, VLine};
        let Some(p) = &self.profile else {
            ui.label("Click a pixel to see its transient response (radiance against path length).");
            return;
        };
        ui.label(format!(
            "pixel ({}, {}): radiance per metre of path length, {} spp ({} bins of {:.1} ps)",
            p.pixel.0,
            p.pixel.1,
            p.tracer.samples_done(),
            p.bins,
            metres_to_ps((p.range.1 - p.range.0) / p.bins as f64)
        ));
        let width = (p.range.1 - p.range.0) / p.bins as f64;
        let points: Vec<[f64; 2]> =
            p.values.iter().enumerate().map(|(i, &v)| [p.range.0 + (i as f64 + 0.5) * width, v]).collect();
        let gate = self.gate.gate();
        let bin = self.gate.shown_bin();
        Plot::new("time_profile").height(ui.available_height().max(120.0)).x_axis_label("path length (m)").show(
            ui,
            |plot| {
                plot.line(Line::new("radiance", points));
                match gate {
                    Gate::Box { start, end } => plot.span(
                        Span::new("gate", start..=end).fill(egui::Color32::from_rgba_unmultiplied(255, 200, 0, 60)),
                    ),
                    Gate::Gaussian { mean, .. } => plot.vline(VLine::new("gate", mean)),
                    Gate::Transient { .. } => {
                        if let Some((a, b)) = gate.bin_range(bin) {
                            plot.span(
                                Span::new("bin shown", a..=b)
                                    .fill(egui::Color32::from_rgba_unmultiplied(255, 200, 0, 60)),
                            )
                        }
                    }
                    _ => {}
                }
            },
        );
    }

    pub(super) fn screenshot_mode(&mut self, ctx: &egui::Context) -> Result<()> {
        let Some(path) = self.options.screenshot.clone() else { return Ok(()) };
        if let Some(step) = self.options.scrub_step
            && self.frames > 0
            && self.frames.is_multiple_of(10)
            && self.frames < self.options.after_frames
        {
            self.gate.step(step);
            // A transient gate's new bin needs no new render: its first image is this frame's.
            self.timing.pending_change = Some(Instant::now());
        }
        if let Some(rx) = &self.screenshot_rx {
            if let Ok(image) = rx.try_recv() {
                save_screenshot(&path, &image, self.image_rect, ctx.pixels_per_point(), self)?;
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
            return Ok(());
        }
        if self.frames >= self.options.after_frames {
            let (tx, rx) = mpsc::channel();
            ctx.send_viewport_cmd(egui::ViewportCommand::Screenshot(egui::ScreenshotCallback::new(move |image| {
                let _ = tx.send(image);
            })));
            self.screenshot_rx = Some(rx);
        }
        Ok(())
    }

    pub(super) fn frame(&mut self, ui: &mut egui::Ui) -> Result<()> {
        let now = Instant::now();
        if let Some(last) = self.timing.last_frame.replace(now) {
            self.timing.frame_times.push(now - last);
        }
        if let Some(changed) = self.timing.shown_pending.take() {
            let latency = now - changed;
            self.timing.last_latency = Some(latency);
            self.timing.latencies.push(latency);
        }
        let ctx = ui.ctx().clone();
        self.screenshot_mode(&ctx)?;
        if let Err(e) = self.sync() {
            self.message = format!("{e:#}");
        }
        if self.auto_exposure_pending && self.tracer.as_ref().is_some_and(|t| t.samples_done() >= 4) {
            self.auto_exposure_pending = false;
            if let Some(ev) = self.auto_exposure()? {
                self.options.exposure_ev = (ev * 4.0).round() / 4.0;
            }
        }
        if let Some(p) = &self.profile
            && p.max_bounces != self.options.max_bounces
        {
            let pixel = p.pixel;
            self.profile = None;
            self.select_pixel(pixel)?;
        }
        if self.screenshot_rx.is_none() {
            self.render(Duration::from_millis(25))?;
            self.update_profile()?;
            self.frames += 1;
        }
        egui::Panel::left("controls").resizable(false).exact_size(300.0).show(ui, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| self.controls(ui));
        });
        egui::CentralPanel::default().show(ui, |ui| {
            let Some(display) = &self.display else { return };
            let (w, h) = (self.options.width as f32, self.options.height as f32);
            let room = ui.available_size() * egui::vec2(1.0, 0.62);
            let zoom = (room.x / w).min(room.y / h).floor().max(1.0);
            let size = egui::vec2(w * zoom, h * zoom);
            let image =
                egui::Image::new((display.texture_id, size)).fit_to_exact_size(size).sense(egui::Sense::click());
            let response = ui.add(image);
            self.image_rect = Some(response.rect);
            if response.clicked()
                && let Some(pos) = response.interact_pointer_pos()
            {
                let rel = (pos - response.rect.min) / zoom;
                let pixel = ((rel.x as u32).min(self.options.width - 1), (rel.y as u32).min(self.options.height - 1));
                if let Err(e) = self.select_pixel(pixel) {
                    self.message = format!("{e:#}");
                }
            }
            ui.separator();
            self.profile_plot(ui);
        });
        ctx.request_repaint();
        Ok(())
    }
}

/// Writes the window's pixels as PNG and, beside it (FILE.json), the image's rectangle in those
/// pixels, its samples per pixel and the display settings, for comparison with a headless render.
fn save_screenshot(
    path: &Path,
    image: &egui::ColorImage,
    rect: Option<egui::Rect>,
    ppp: f32,
    viewer: &Viewer,
) -> Result<()> {
    let [w, h] = image.size;
    let file =
        std::fs::File::create(path).with_context(|| format!("{}: cannot write the screenshot", path.display()))?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), w as u32, h as u32);
    encoder.set_color(png::ColorType::Rgba);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().with_context(|| format!("{}: cannot write PNG", path.display()))?;
    let bytes: Vec<u8> = image.pixels.iter().flat_map(|c| c.to_array()).collect();
    writer.write_image_data(&bytes).with_context(|| format!("{}: cannot write PNG", path.display()))?;
    let rect = rect.ok_or_else(|| anyhow!("the image was never drawn"))?;
    let r = [rect.min.x * ppp, rect.min.y * ppp, rect.max.x * ppp, rect.max.y * ppp].map(|v| v.round() as i64);
    let built = viewer.built.as_ref().ok_or_else(|| anyhow!("nothing rendered"))?;
    let latencies: Vec<f64> = viewer.timing.latencies.iter().map(|d| d.as_secs_f64() * 1e3).collect();
    let frame_ms: Vec<f64> = viewer.timing.frame_times.iter().map(|d| d.as_secs_f64() * 1e3).collect();
    let sidecar = serde_json::json!({
        "image_rect_px": r,
        "width": viewer.options.width,
        "height": viewer.options.height,
        "spp": viewer.tracer.as_ref().map_or(0, |t| t.samples_done()),
        "method": built.method.name(),
        "gate": built.gate.describe(),
        "bin": matches!(built.gate, Gate::Transient { .. }).then(|| viewer.gate.shown_bin()),
        "display": if built.gate.is_signed() { "signed luminance" } else { "rgb" },
        "exposure": 2f32.powf(viewer.options.exposure_ev),
        "curve": if viewer.options.log_curve { "log" } else { "linear" },
        "frames": viewer.frames,
        "gate_change_to_image_ms": latencies,
        "frame_ms": frame_ms,
        "adapter": viewer.ctx.adapter_description(),
    });
    let json_path = path.with_extension("json");
    std::fs::write(&json_path, serde_json::to_string_pretty(&sidecar)?)
        .with_context(|| format!("{}: cannot write", json_path.display()))?;
    Ok(())
}
