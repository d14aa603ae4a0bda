//! The viewer's rendering: the integrator it keeps for the current settings, a bounded
//! amount of rendering per UI frame, the display's resolve to RGBA8 on the GPU, the clicked
//! pixel's time profile, the exposure from the image and `S` to save the film.

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Result, anyhow, bail};

use gatetrace::film::output::{Metadata, write_film};
use gatetrace::film::preview::auto_exposure_ev;
use gatetrace::film::{Gate, fixed};
use gatetrace::gpu::layout::{DISPLAY_LINEAR, DISPLAY_LOG, DisplayParams};
use gatetrace::gpu::{GpuContext, Kernel, Resources};
use gatetrace::integrator::{Integrator, Method, PassSizer, RenderSettings, create_integrator};
use gatetrace::scene::PreparedScene;

use super::gate::{GateChoice, GateControls};
use super::{Display, Profile, Timing, ViewOptions, Viewer};

impl<'a> Viewer<'a> {
    pub(super) fn new(
        ctx: &'a GpuContext,
        scene: &'a PreparedScene,
        options: ViewOptions,
        lengths: (f64, f64),
        state: &eframe::egui_wgpu::RenderState,
        failure: &'a mut Option<anyhow::Error>,
    ) -> Result<Self> {
        let gate = GateControls::new(&options.gate, options.bin, lengths);
        let mut viewer = Self {
            ctx,
            scene,
            lengths,
            gate,
            auto_exposure_pending: options.auto_exposure,
            options,
            built: None,
            tracer: None,
            display: None,
            profile: None,
            renderer: state.renderer.clone(),
            timing: Timing::default(),
            sizer: PassSizer::default(),
            frames: 0,
            image_rect: None,
            screenshot_rx: None,
            message: String::new(),
            failure,
        };
        viewer.sync()?;
        if let Some((x, y)) = viewer.options.profile_pixel {
            if x >= viewer.options.width || y >= viewer.options.height {
                bail!(
                    "--profile-pixel {x},{y} lies outside the {}x{} image",
                    viewer.options.width,
                    viewer.options.height
                );
            }
            viewer.select_pixel((x, y))?;
        }
        Ok(viewer)
    }

    pub(super) fn settings(&self) -> RenderSettings {
        let o = &self.options;
        let method = if self.gate.kind == GateChoice::None && o.method == Method::Ellipsoidal {
            Method::Direct
        } else {
            o.method
        };
        RenderSettings {
            width: o.width,
            height: o.height,
            method,
            gate: self.gate.gate(),
            max_bounces: o.max_bounces,
            rr_depth: o.rr_depth,
            seed: o.seed,
            connections_per_query: gatetrace::integrator::bidirectional::default_connections_per_query(method),
            ..Default::default()
        }
    }

    /// Brings the integrator in line with the controls: the gate moved in place where possible,
    /// otherwise a new integrator (and display bindings).
    pub(super) fn sync(&mut self) -> Result<()> {
        let wanted = self.settings();
        if self.built.as_ref() == Some(&wanted) {
            return Ok(());
        }
        wanted.gate.validate()?;
        self.timing.pending_change = Some(Instant::now());
        if let (Some(built), Some(tracer)) = (&self.built, &mut self.tracer) {
            let same_but_gate = RenderSettings { gate: wanted.gate.clone(), ..built.clone() } == wanted;
            if same_but_gate && tracer.set_gate(self.scene, &wanted)? {
                self.built = Some(wanted);
                return Ok(());
            }
        }
        wanted.check()?;
        self.tracer = None;
        let tracer = create_integrator(self.ctx, self.scene, &wanted)?;
        self.display = Some(self.make_display(tracer.as_ref(), wanted.method != Method::Path)?);
        self.tracer = Some(tracer);
        self.built = Some(wanted);
        Ok(())
    }

    pub(super) fn make_display(&self, tracer: &dyn Integrator, splats: bool) -> Result<Display> {
        let ctx = self.ctx;
        let (w, h) = (self.options.width, self.options.height);
        let stride = w.div_ceil(64) * 64;
        let constants = tracer.constants();
        let kernel = if splats {
            Kernel::with_feature(ctx, "resolve_display", "splats", constants)
        } else {
            Kernel::new(ctx, "resolve_display", None, constants)
        };
        let mut resources: Resources = tracer.resources().clone();
        resources.uniform_init(ctx, "display_params", &DisplayParams::default());
        resources.storage_zeroed(ctx, "display", stride as u64 * h as u64 * 4, wgpu::BufferUsages::COPY_SRC)?;
        let bind_group = kernel.bind(ctx, &resources);
        let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("display"),
            size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            // egui composes in gamma space: the texels are already sRGB-encoded (resolve_display).
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        let view = texture.create_view(&Default::default());
        let texture_id = match &self.display {
            Some(old) => {
                self.renderer.write().update_egui_texture_from_wgpu_texture(
                    &ctx.device,
                    &view,
                    wgpu::FilterMode::Nearest,
                    old.texture_id,
                );
                old.texture_id
            }
            None => self.renderer.write().register_native_texture(&ctx.device, &view, wgpu::FilterMode::Nearest),
        };
        Ok(Display {
            kernel,
            bind_group,
            params: resources.get("display_params").unwrap().clone(),
            pixels: resources.get("display").unwrap().clone(),
            texture,
            texture_id,
            stride,
        })
    }

    /// Renders for about `budget`, at least one pass (one sample per pixel right after a
    /// change, so the first image comes quickly), then resolves the film into the texture.
    pub(super) fn render(&mut self, budget: Duration) -> Result<()> {
        let (Some(tracer), Some(display)) = (&mut self.tracer, &self.display) else { return Ok(()) };
        let start = Instant::now();
        let before = tracer.samples_done();
        let pixels = (self.options.width * self.options.height) as f64;
        // Passes sized to the budget from the measured rate (one sample right after a change,
        // when nothing is measured yet), so a frame never waits for a long pass.
        if tracer.samples_done() == 0 {
            self.sizer = PassSizer::default();
        }
        self.sizer.render_for(tracer.as_mut(), budget.as_secs_f64(), |_, _| Ok(std::ops::ControlFlow::Continue(())))?;
        let done = tracer.samples_done() - before;
        let rate = done as f64 * pixels / start.elapsed().as_secs_f64().max(1e-9);
        let t = &mut self.timing;
        t.samples_per_second = if t.samples_per_second == 0.0 { rate } else { 0.8 * t.samples_per_second + 0.2 * rate };

        let params = DisplayParams {
            inverse_spp: 1.0 / tracer.samples_done().max(1) as f32,
            exposure: 2f32.powf(self.options.exposure_ev),
            curve: if self.options.log_curve { DISPLAY_LOG } else { DISPLAY_LINEAR },
            bin: self.gate.shown_bin(),
            signed: self.built.as_ref().is_some_and(|b| b.gate.is_signed()) as u32,
            decades: 4.0,
            stride: display.stride,
            ..Default::default()
        };
        let ctx = self.ctx;
        ctx.queue.write_buffer(&display.params, 0, bytemuck::bytes_of(&params));
        let mut encoder =
            ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("resolve_display") });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("resolve_display"),
                timestamp_writes: None,
            });
            display.kernel.dispatch(&mut pass, &display.bind_group, self.options.width * self.options.height);
        }
        let (w, h) = (self.options.width, self.options.height);
        encoder.copy_buffer_to_texture(
            wgpu::TexelCopyBufferInfo {
                buffer: &display.pixels,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(display.stride * 4),
                    rows_per_image: Some(h),
                },
            },
            display.texture.as_image_copy(),
            wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        );
        ctx.queue.submit([encoder.finish()]);
        // The new gate's first image is on screen once this frame has been painted: the latency
        // is taken at the start of the next frame.
        if let Some(changed) = self.timing.pending_change.take() {
            self.timing.shown_pending = Some(changed);
        }
        Ok(())
    }

    /// One more pass of the selected pixel's transient render, and its bins read back.
    pub(super) fn update_profile(&mut self) -> Result<()> {
        let Some(p) = &mut self.profile else { return Ok(()) };
        p.tracer.render_pass(1)?;
        let ctx = self.ctx;
        let film = p.tracer.resources().get("film").unwrap();
        let w = self.options.width;
        let element = gatetrace::integrator::FILM_ELEMENT_BYTES;
        let first = ((p.pixel.1 * w + p.pixel.0) * p.bins * 3) as u64 * element;
        let bytes = p.bins as u64 * 3 * element;
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(film, first, &p.staging, 0, bytes);
        ctx.queue.submit([encoder.finish()]);
        let slice = p.staging.slice(..);
        slice.map_async(wgpu::MapMode::Read, |_| {});
        ctx.wait_idle()?;
        let sums: Vec<[u32; 4]> = {
            let view = slice.get_mapped_range().map_err(|e| anyhow!("cannot read the time profile back: {e:?}"))?;
            bytemuck::cast_slice(&view).to_vec()
        };
        p.staging.unmap();
        let spp = p.tracer.samples_done().max(1) as f64;
        let width = (p.range.1 - p.range.0) / p.bins as f64;
        p.values = sums
            .chunks(3)
            .map(|c| {
                let rgb: Vec<f64> = c.iter().map(|&s| fixed::to_f64(fixed::from_words(s)) / spp).collect();
                (0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]) / width
            })
            .collect();
        Ok(())
    }

    pub(super) fn select_pixel(&mut self, pixel: (u32, u32)) -> Result<()> {
        let bounces = self.options.max_bounces;
        if self.profile.as_ref().is_some_and(|p| p.pixel == pixel && p.max_bounces == bounces) {
            return Ok(());
        }
        if let Some(p) = self.profile.as_mut().filter(|p| p.max_bounces == bounces) {
            p.pixel = pixel;
            p.tracer.reset_film();
            p.values.clear();
            return Ok(());
        }
        // One film binding (the readback assumes an unsplit film): as many bins, up to 128, as fit.
        let per_bin = self.options.width as u64 * self.options.height as u64 * 24;
        let bins = (self.ctx.max_binding_size() / per_bin).min(128) as u32;
        if bins < 8 {
            bail!("the time profile needs at least 8 bins per pixel; this image is too large for one binding");
        }
        let range =
            (self.lengths.0, self.lengths.0 + (self.lengths.1 - self.lengths.0).min(4.0 * self.lengths.0.max(0.5)));
        let gate = Gate::Transient { start: range.0, width: (range.1 - range.0) / bins as f64, bins };
        let settings = RenderSettings {
            width: self.options.width,
            height: self.options.height,
            method: Method::Path,
            gate,
            max_bounces: self.options.max_bounces,
            rr_depth: self.options.rr_depth,
            seed: self.options.seed ^ 0x5bd1_e995,
            ..Default::default()
        };
        let tracer = create_integrator(self.ctx, self.scene, &settings)?;
        let staging = self.ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("profile_staging"),
            size: bins as u64 * 3 * gatetrace::integrator::FILM_ELEMENT_BYTES,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        self.profile = Some(Profile { pixel, max_bounces: bounces, tracer, range, bins, values: Vec::new(), staging });
        Ok(())
    }

    /// Exposure (EV) that maps the 99th percentile of the shown image's values (channels, or
    /// the luminance's magnitude on the signed display; the shown bin of a transient gate) to 1.
    pub(super) fn auto_exposure(&self) -> Result<Option<f32>> {
        let (Some(tracer), Some(built)) = (&self.tracer, &self.built) else { return Ok(None) };
        let film = tracer.film()?;
        let bin = self.gate.shown_bin().min(film.bins - 1);
        let pixels = (0..film.height).flat_map(|y| (0..film.width).map(move |x| (x, y)));
        let shown: Vec<[f32; 3]> = pixels.map(|(x, y)| film.get(x, y, bin)).collect();
        Ok(if built.gate.is_signed() {
            auto_exposure_ev(shown.iter().map(|c| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]))
        } else {
            auto_exposure_ev(shown.iter().flatten().copied())
        })
    }

    pub(super) fn save(&mut self, path: &Path) -> Result<()> {
        let (Some(tracer), Some(built)) = (&self.tracer, &self.built) else { bail!("nothing rendered yet") };
        let film = tracer.film()?;
        let metadata: Metadata = vec![
            ("scene".into(), self.options.scene.display().to_string().into()),
            ("method".into(), built.method.name().into()),
            ("gate_parameters".into(), built.gate.parameters()),
            ("gate_description".into(), built.gate.describe().into()),
            ("spp".into(), film.spp.into()),
            ("seed".into(), built.seed.into()),
            ("max_bounces".into(), built.max_bounces.into()),
            ("adapter".into(), self.ctx.adapter_description().into()),
        ];
        let gate = &built.gate;
        let bin_ranges: Vec<(f64, f64)> = (0..gate.bins()).filter_map(|b| gate.bin_range(b)).collect();
        write_film(path, &film, &metadata, &bin_ranges)
    }
}
