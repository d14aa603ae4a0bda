//! How a capture is rendered (`gatetrace render --nlos`): the settings a capture defaults to and
//! the choices that override them, when the band index applies, the scene's preparation for it,
//! one render per laser spot of the scan, and the capture's output (its data's shape, its
//! record of the sensed points and laser spots, its files).

use std::ops::ControlFlow;
use std::path::Path;

use anyhow::{Context as _, Result, ensure};
use glam::{Vec2, Vec3};

use crate::film::Gate;
use crate::film::output::{Metadata, write_film_with, write_npy_f32, write_sidecar};
use crate::frames::frame_seed;
use crate::gpu::GpuContext;
use crate::gpu::layout::WallPoint;
use crate::integrator::bidirectional::{DEFAULT_NLOS_CONNECTIONS_PER_QUERY, DEFAULT_NLOS_TARGET_PILOT};
use crate::integrator::{Budget, Method, Progress, RenderOutput, RenderSettings, render_metadata, render_resumable};
use crate::nlos::band_index::AUTO_MIN_TRIANGLES;
use crate::nlos::{Laser, LaserAim, NlosCapture, Scan, ShellPreparation, capture_record, cell_uv, check_capture};
use crate::scene::{LoadOptions, PreparedScene, SceneCapture, load_scene_with};

/// The method a capture renders with when none is asked for: ellipsoidal where a gate gives
/// target lengths (the default the capture tables of docs/nlos.md measure), path without one.
pub fn default_method(gate: &Gate) -> Method {
    if *gate != Gate::None { Method::Ellipsoidal } else { Method::Path }
}

/// Connections per ellipsoid query of a capture rendered with `method` when none is asked for.
pub fn default_connections_per_query(method: Method) -> u32 {
    if method == Method::Ellipsoidal {
        DEFAULT_NLOS_CONNECTIONS_PER_QUERY
    } else {
        crate::integrator::bidirectional::default_connections_per_query(method)
    }
}

/// Whether a capture's ellipsoid queries weigh their picks by reflection when not asked: they
/// do (`QuerySettings::reflection_weights`).
pub const DEFAULT_REFLECTION_WEIGHTS: bool = true;

/// Samples per pixel of a capture's target pilot when none is asked for: for ellipsoidal on a
/// transient gate, 0 (no pilot) otherwise.
pub fn default_target_pilot(method: Method, gate: &Gate) -> u32 {
    if method == Method::Ellipsoidal && matches!(gate, Gate::Transient { .. }) { DEFAULT_NLOS_TARGET_PILOT } else { 0 }
}

/// Whether a capture can use the band index: ellipsoidal on a transient gate.
pub fn band_index_applies(method: Method, gate: &Gate) -> bool {
    method == Method::Ellipsoidal && matches!(gate, Gate::Transient { .. })
}

/// What a capture's renders are asked for where a capture has defaults of its own (`render
/// --nlos --method, --connections-per-query, --query-weights, --target-pilot, --band-index`):
/// None takes the capture's default.
#[derive(Clone, Copy, Debug, Default)]
pub struct CaptureChoices {
    /// The method (None: [`default_method`]).
    pub method: Option<Method>,
    /// Connections per ellipsoid query (None: [`default_connections_per_query`]).
    pub connections_per_query: Option<u32>,
    /// Ellipsoid queries weigh their picks by reflection (None: [`DEFAULT_REFLECTION_WEIGHTS`]).
    pub reflection_weights: Option<bool>,
    /// Samples per pixel of the target pilot (None: [`default_target_pilot`]).
    pub target_pilot: Option<u32>,
    /// The band index: Some(true) on, Some(false) off, None decided by itself (`auto`: on where it
    /// applies, declined by [`prepare_capture`] for small hidden scenes).
    pub band_index: Option<bool>,
}

impl CaptureChoices {
    /// The method a capture of `gate` renders with.
    pub fn method(&self, gate: &Gate) -> Method {
        self.method.unwrap_or_else(|| default_method(gate))
    }

    /// Sets the method, the connections per query, the query weights, the target pilot and the
    /// band index of `settings` (whose gate is the capture's) as asked, or to the capture's
    /// defaults.
    pub fn apply(&self, settings: &mut RenderSettings) {
        let gate = &settings.gate;
        let method = self.method(gate);
        settings.method = method;
        settings.connections_per_query =
            self.connections_per_query.unwrap_or_else(|| default_connections_per_query(method));
        settings.query.reflection_weights = self.reflection_weights.unwrap_or(DEFAULT_REFLECTION_WEIGHTS);
        settings.target_pilot_spp = self.target_pilot.unwrap_or_else(|| default_target_pilot(method, gate));
        settings.band_index = self.band_index != Some(false) && band_index_applies(method, gate);
    }
}

/// A capture as asked for: the scan, the relay wall, the laser and the sensor.
#[derive(Clone, Debug)]
pub struct CaptureRequest {
    /// How the laser moves.
    pub scan: Scan,
    /// Name of the relay wall's glTF node.
    pub relay_wall: String,
    /// Where the sensor looks at the wall from (m); None: the node named sensor_origin, else
    /// nlos_origin.
    pub sensor_origin: Option<Vec3>,
    /// Where the laser beam starts (m); None: the node named laser_origin, else nlos_origin.
    pub laser_origin: Option<Vec3>,
    /// Single scans: where the laser is aimed (the wall's texture coordinates).
    pub laser_spot: Vec2,
    /// Exhaustive scans: the grid of laser spots, width x height (None: the sensed points').
    pub laser_grid: Option<(u32, u32)>,
    /// The laser.
    pub laser: Laser,
    /// Count the laser origin -> spot and sensed point -> sensor origin segments in path lengths.
    pub count_first_and_last: bool,
    /// The band index was left to decide by itself (`auto`): it is declined where the hidden
    /// scene has at most `AUTO_MIN_TRIANGLES` triangles, which every query searches whole.
    pub band_index_auto: bool,
}

/// What a caller asks of a capture over its defaults (the command line's options, Python's
/// arguments): each None keeps the setting of the capture the scene file describes, else the
/// default of [`CaptureRequest::new`].
#[derive(Clone, Debug, Default)]
pub struct CaptureOptions {
    /// The relay wall's node name (default [`crate::nlos::DEFAULT_RELAY_WALL`]).
    pub relay_wall: Option<String>,
    /// Where the sensor looks at the wall from (m; default: the scene's nodes).
    pub sensor_origin: Option<Vec3>,
    /// Where the laser starts (m; default: the scene's nodes).
    pub laser_origin: Option<Vec3>,
    /// Single scans: the spot, texture coordinates of the wall (default (0.5, 0.5)).
    pub laser_spot: Option<Vec2>,
    /// Exhaustive scans: the grid of laser spots, width x height (default: the file's, else the
    /// sensed points').
    pub laser_grid: Option<(u32, u32)>,
    /// A beam of this power (W) as the laser (default: the file's projector, else 1 W).
    pub laser_power: Option<f32>,
    /// Count the first and last segments in path lengths (also where the file does).
    pub count_first_and_last: bool,
    /// The band index is left to decide by itself.
    pub band_index_auto: bool,
}

impl CaptureRequest {
    /// A capture scanned by `scan`: the one `file` describes (a Mitsuba scene's; None for a
    /// glTF scene), with `options` over it.
    pub fn new(scan: Scan, file: Option<&SceneCapture>, options: CaptureOptions) -> CaptureRequest {
        CaptureRequest {
            scan,
            relay_wall: options
                .relay_wall
                .or(file.map(|f| f.relay_wall.clone()))
                .unwrap_or_else(|| crate::nlos::DEFAULT_RELAY_WALL.into()),
            sensor_origin: options.sensor_origin.or(file.map(|f| f.sensor_origin)),
            laser_origin: options.laser_origin.or(file.map(|f| f.laser_origin)),
            laser_spot: options.laser_spot.or(file.map(|f| f.laser_spot)).unwrap_or(Vec2::splat(0.5)),
            laser_grid: options.laser_grid.or(file.and_then(|f| f.laser_grid)),
            laser: match (options.laser_power, file) {
                (Some(power), _) => Laser::Beam(power),
                (None, Some(f)) => Laser::Projector(f.projector_irradiance),
                (None, None) => Laser::Beam(1.0),
            },
            count_first_and_last: options.count_first_and_last || file.is_some_and(|f| f.count_first_and_last),
            band_index_auto: options.band_index_auto,
        }
    }

    /// Checks the request against the render's settings before any work.
    pub fn check(&self, settings: &RenderSettings) -> Result<()> {
        ensure!(
            settings.max_bounces >= 2,
            "--nlos: --max-bounces {} counts the laser spot and the sensed point, so it must be at least 2 (3: the \
             three-bounce paths spot -> hidden point -> sensed point)",
            settings.max_bounces
        );
        ensure!(self.laser_grid.is_none() || self.scan == Scan::Exhaustive, "--laser-grid needs --nlos exhaustive");
        ensure!(
            settings.method != Method::Auto,
            "--method auto does not apply to NLOS captures (--nlos): choose path, direct or ellipsoidal"
        );
        Ok(())
    }
}

/// A capture ready to render: its scene (prepared for shell connections where the band index
/// is used), the settings of its renders and the laser aim of each.
pub struct PreparedCapture {
    /// The scene.
    pub scene: PreparedScene,
    /// The capture of the first laser aim.
    pub capture: NlosCapture,
    /// How the laser moves.
    pub scan: Scan,
    /// The settings every render shares (their seed and aim are each render's).
    pub settings: RenderSettings,
    /// Where the band index was declined by itself: the hidden scene's triangles.
    pub band_index_declined: Option<usize>,
    /// What preparing the scene for shell connections did.
    pub shells: Option<ShellPreparation>,
    /// The laser aim of each render: one, or the exhaustive scan's grid in row-major order.
    pub aims: Vec<LaserAim>,
    /// The grid of laser spots, width x height.
    pub laser_grid: (u32, u32),
}

/// Piece-pixels (a piece of the hidden scene times a pixel of the capture) whose band index a
/// second of a render's budget pays for: finer cuts than the edge rule
/// (`crate::nlos::refine_for_shells`) are taken only where the capture's pieces times its pixels
/// stay within this times the budget. The index's build time grows about with that product
/// (on the 2-core test machine's llvmpipe, 0.6 s for 22,108 pieces and 256 pixels, 2.6 s for
/// 341,924), and within short budgets the build's share outweighs the pieces' gain: 2 s
/// captures (confocal 16 x 16, 4 ps bins) had 0.62 of the error with edges of 1/2 on
/// `nlos_panels.xml` (22,108 pieces) but 1.21 on `nlos_staircase.xml` (55,126), where 10 s
/// ones had 0.63 (docs/nlos.md, "Finer pieces").
pub const PIECE_PIXELS_PER_SECOND: f64 = 5.0e6;

/// Pieces per sample per pixel a budget of samples pays for in [`finer_pieces`]: the time
/// rule's pieces over the samples per pixel a capture renders in that time (16 x 16 points of
/// `nlos_staircase.xml` at 4 ps: about 26,000 in 10 s on the 2-core test machine, where
/// PIECE_PIXELS_PER_SECOND allows 195,312 pieces), so that the index's build keeps about its
/// share of the render on any device.
pub const PIECES_PER_SAMPLE: f64 = 7.5;

/// The most triangles a capture of `pixels` pixels within `budget` cuts its hidden scene into
/// beyond the edge rule (`crate::nlos::prepare_for_shells`): PIECE_PIXELS_PER_SECOND times its
/// seconds over its pixels, or PIECES_PER_SAMPLE times its samples per pixel.
pub fn finer_pieces(budget: Budget, pixels: u64) -> u64 {
    match budget {
        Budget::Time(t) => (PIECE_PIXELS_PER_SECOND * t.as_secs_f64() / pixels.max(1) as f64) as u64,
        Budget::Samples(n) => (PIECES_PER_SAMPLE * n as f64) as u64,
    }
}

/// Loads the capture's scene and prepares it: the band index's decision, the origins, the
/// hidden scene's preparation for shell connections (its pieces sized for `budget`, see
/// [`finer_pieces`]), and the checks of the capture.
pub fn prepare_capture(
    scene_path: &Path,
    load: LoadOptions,
    request: &CaptureRequest,
    base: RenderSettings,
    budget: Budget,
) -> Result<PreparedCapture> {
    let mut loaded = load_scene_with(scene_path, &LoadOptions { capture: true, ..load })?;
    let mut settings = base;
    let wall = &request.relay_wall;
    let hidden_triangles = loaded.triangles.len() - loaded.node(wall).map_or(0, |n| n.triangles.len());
    let band_index_declined =
        (settings.band_index && request.band_index_auto && hidden_triangles <= AUTO_MIN_TRIANGLES)
            .then_some(hidden_triangles);
    if band_index_declined.is_some() {
        settings.band_index = false;
    }
    let origin = |given: Option<Vec3>, node: &str, flag: &str| -> Result<Vec3> {
        given.or_else(|| crate::nlos::origin_from_nodes(&loaded, node)).with_context(|| {
            format!("{}: no node named `{node}` or `nlos_origin`: give {flag} X,Y,Z (m)", scene_path.display())
        })
    };
    let (sensor_origin, laser_origin) = (
        origin(request.sensor_origin, "sensor_origin", "--sensor-origin")?,
        origin(request.laser_origin, "laser_origin", "--laser-origin")?,
    );
    // Shell connections want the hidden scene's closed surfaces one-sided and its large
    // triangles cut into pieces (prepare_for_shells).
    let shells = match (settings.band_index, &settings.gate) {
        (true, Gate::Transient { width, .. }) if loaded.node(wall).is_some() => Some(
            crate::nlos::prepare_for_shells(
                &mut loaded,
                wall,
                *width,
                &[sensor_origin, laser_origin],
                finer_pieces(budget, settings.width as u64 * settings.height as u64),
            )
            .with_context(|| scene_path.display().to_string())?,
        ),
        _ => None,
    };
    let scene = PreparedScene::new(loaded)?;
    let scan = request.scan;
    let capture = NlosCapture {
        relay_wall: wall.clone(),
        sensor_origin,
        laser_origin,
        aim: if scan == Scan::Confocal { LaserAim::Confocal } else { LaserAim::Spot(request.laser_spot) },
        laser: request.laser,
        count_first_and_last: request.count_first_and_last,
    };
    check_capture(&scene.scene, &capture)?;
    let (w, h) = (settings.width, settings.height);
    let laser_grid = match scan {
        Scan::Single => (1, 1),
        Scan::Confocal => (w, h),
        Scan::Exhaustive => request.laser_grid.unwrap_or((w, h)),
    };
    let (laser_w, laser_h) = laser_grid;
    let aims: Vec<LaserAim> = match scan {
        Scan::Exhaustive => (0..laser_h)
            .flat_map(|j| (0..laser_w).map(move |i| LaserAim::Spot(cell_uv(i, j, laser_w, laser_h))))
            .collect(),
        _ => vec![capture.aim],
    };
    Ok(PreparedCapture { scene, capture, scan, settings, band_index_declined, shells, aims, laser_grid })
}

/// What a capture's renders report as they go.
pub trait CaptureProgress {
    /// A warning about the capture: about its setup (sensed points hidden from the sensor, a
    /// blocked laser beam) before the first render, or about a render after it (traversals the
    /// device cut short). The scene's load warnings are in `PreparedCapture::scene`.
    fn warning(&mut self, warning: &str);
    /// Render `k` of `count` (one per laser spot) starts with `settings`.
    fn render_started(&mut self, k: usize, count: usize, settings: &RenderSettings);
    /// A pass of the render ended; Break stops the render after it.
    fn pass(&mut self, progress: Progress) -> ControlFlow<()>;
    /// Render `k` of `count` ended; Break stops the capture there, unwritten.
    fn render_ended(&mut self, k: usize, count: usize) -> ControlFlow<()>;
}

/// A rendered capture.
pub struct Capture {
    /// The transients of every render, one after the other (laser spots in row-major order).
    pub data: Vec<f32>,
    /// The sensed points of the grid (row-major).
    pub sensed: Vec<WallPoint>,
    /// The laser spots of the whole scan.
    pub spots: Vec<WallPoint>,
    /// The settings of the last render.
    pub settings: RenderSettings,
    /// The last render (a single and confocal scan's only one).
    pub output: RenderOutput,
}

/// Renders the capture: one render for a single or confocal scan, one per laser spot, each from
/// a seed of its own, for an exhaustive one. None where `progress` stopped it after a render.
pub fn render_capture(
    ctx: &GpuContext,
    prepared: &PreparedCapture,
    budget: Budget,
    progress: &mut dyn CaptureProgress,
) -> Result<Option<Capture>> {
    let PreparedCapture { scene, scan, aims, .. } = prepared;
    let base = &prepared.settings;
    let (w, h) = (base.width, base.height);
    let pixels = (w * h) as usize;
    let (mut data, mut spots, mut sensed) = (Vec::new(), Vec::new(), Vec::new());
    let mut last = None;
    for (k, &aim) in aims.iter().enumerate() {
        let capture = NlosCapture { aim, ..prepared.capture.clone() };
        let (points, warnings) = crate::nlos::wall_points_and_warnings(scene, &capture, w, h)?;
        if k == 0 {
            for warning in warnings {
                progress.warning(&warning);
            }
        }
        sensed = points[..pixels].to_vec();
        spots.extend_from_slice(if *scan == Scan::Confocal { &points[pixels..] } else { &points[pixels..pixels + 1] });
        let seed = if aims.len() > 1 { frame_seed(base.seed, k as u32) } else { base.seed };
        let settings = RenderSettings { nlos: Some(capture), seed, ..base.clone() };
        progress.render_started(k, aims.len(), &settings);
        let output = render_resumable(ctx, scene, &settings, budget, Default::default(), |_, p| Ok(progress.pass(p)))?;
        if let Some(warning) = output.truncated_traversals_warning() {
            progress.warning(&warning);
        }
        if let Some(why) = &output.band_index_off {
            progress.warning(&format!("the band index is off ({why}): connections descend the whole BVH"));
        }
        if progress.render_ended(k, aims.len()).is_break() {
            return Ok(None);
        }
        data.extend_from_slice(&output.film.data);
        last = Some((settings, output));
    }
    let (settings, output) = last.expect("at least one laser spot");
    Ok(Some(Capture { data, sensed, spots, settings, output }))
}

impl Capture {
    /// The capture's metadata: the render's, with a capture's units, and where they apply why the
    /// band index was declined and what preparing the scene for shell connections did.
    pub fn metadata(
        &self,
        ctx: &GpuContext,
        scene_path: &Path,
        gate_spec: &str,
        prepared: &PreparedCapture,
    ) -> Metadata {
        let mut metadata = render_metadata(ctx, scene_path, gate_spec, &self.settings, &self.output);
        metadata.retain(|(k, _)| k != "units");
        metadata.push((
            "units".into(),
            "bin-integrated radiance (W m^-2 sr^-1) leaving each sensed point towards the sensor origin; lengths \
             are optical path in metres from the laser spot to the sensed point (plus the first and last segments \
             when count_first_and_last)"
                .into(),
        ));
        if let Some(hidden_triangles) = prepared.band_index_declined {
            metadata.push((
                "band_index".into(),
                format!(
                    "off (auto): the scene's {hidden_triangles} triangles besides the relay wall are searched whole \
                     by every query"
                )
                .into(),
            ));
        }
        if let Some(r) = prepared.shells {
            metadata.push((
                "shell_preparation".into(),
                serde_json::json!({
                    "closed_meshes_made_one_sided": r.closed_meshes,
                    "triangles_cut_into_pieces": r.refined,
                    "finer_cut": r.finer_cut,
                    "convex_solids": r.solids,
                    "buried_pieces_dropped": r.buried,
                    "triangles": r.triangles,
                }),
            ));
        }
        metadata
    }

    /// The shape of the capture's data: an exhaustive scan's [laser_y, laser_x, grid_y, grid_x,
    /// T, 3], the others' [grid_y, grid_x, T, 3] (the render's film); T only for several bins.
    pub fn shape(&self, prepared: &PreparedCapture) -> Vec<usize> {
        let (w, h) = (self.settings.width as usize, self.settings.height as usize);
        let (laser_w, laser_h) = prepared.laser_grid;
        let mut shape =
            if prepared.scan == Scan::Exhaustive { vec![laser_h as usize, laser_w as usize] } else { vec![] };
        shape.extend([h, w]);
        let bins = self.output.film.bins as usize;
        if bins > 1 {
            shape.push(bins);
        }
        shape.push(3);
        shape
    }

    /// The capture's record beside its metadata: the scan, the wall, the origins, the laser and
    /// the sensed points and laser spots with their normals (m).
    pub fn record(&self, prepared: &PreparedCapture) -> serde_json::Map<String, serde_json::Value> {
        let (w, laser_w) = (self.settings.width, prepared.laser_grid.0);
        capture_record(&prepared.scene, &prepared.capture, prepared.scan, &self.sensed, w, &self.spots, laser_w)
    }

    /// Writes the capture to `out` with `metadata` and its sensed points and laser spots in the
    /// sidecar: an exhaustive scan as NPY [laser_y, laser_x, grid_y, grid_x, T, 3] (T only for
    /// several bins), the others as the render's film.
    pub fn write(&self, out: &Path, prepared: &PreparedCapture, metadata: &Metadata) -> Result<()> {
        let extras = self.record(prepared);
        let film = &self.output.film;
        let gate = &self.settings.gate;
        let bin_ranges: Vec<(f64, f64)> = (0..gate.bins()).filter_map(|b| gate.bin_range(b)).collect();
        if prepared.scan == Scan::Exhaustive {
            let shape = self.shape(prepared);
            ensure!(
                self.data.iter().all(|v| v.is_finite()),
                "refusing to write {}: the capture holds non-finite values",
                out.display()
            );
            write_npy_f32(out, &shape, &self.data)?;
            write_sidecar(out, metadata, &extras)
        } else {
            write_film_with(out, film, metadata, &bin_ranges, &extras)
        }
    }
}
