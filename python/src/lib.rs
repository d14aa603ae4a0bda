//! `gatetrace._gatetrace`: the extension module behind the `gatetrace` Python package
//! (python/gatetrace/__init__.py wraps it). It translates arguments, films and errors; the
//! renderer is the `gatetrace` crate, exactly as the command line runs it.
//!
//! One device serves the whole process (opened on first use). A `Renderer` keeps the scene
//! uploaded and its kernels built: a render with a gate of the same kind and bins as the last
//! one only moves the gate (`Integrator::set_gate`) and restarts the sample sequence from the
//! seed (`Integrator::restart`), so its image equals a fresh render's bit for bit. `capture`
//! renders an NLOS capture through the library's `gatetrace::nlos` (`prepare_capture`,
//! `render_capture`), as `render --nlos` does. Renders and captures release the GIL between
//! passes and check for signals after each, so Ctrl-C stops them.

use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use numpy::{PyArray1, PyArrayMethods};
use pyo3::exceptions::{PyFileNotFoundError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use gatetrace::capture::{
    CaptureChoices, CaptureOptions, CaptureProgress, CaptureRequest, prepare_capture, render_capture,
};
use gatetrace::film::output::Metadata;
use gatetrace::film::{Film, Gate};
use gatetrace::gpu::GpuContext;
use gatetrace::integrator::{
    Budget, EllipsoidGuards, Integrator, Method, Progress, QuerySettings, RenderOutput, RenderSettings,
    black_image_warning, create_integrator, render_metadata, trace_budget, unreachable_gate,
};
use gatetrace::nlos::Scan;
use gatetrace::scene::{LoadOptions, PreparedScene, load_scene_with};

/// The process's device, opened on first use and shared by every renderer.
fn device() -> PyResult<&'static GpuContext> {
    static DEVICE: OnceLock<GpuContext> = OnceLock::new();
    static OPENING: Mutex<()> = Mutex::new(());
    if let Some(ctx) = DEVICE.get() {
        return Ok(ctx);
    }
    let _opening = OPENING.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(ctx) = DEVICE.get() {
        return Ok(ctx);
    }
    let ctx = GpuContext::new().map_err(|e| PyRuntimeError::new_err(format!("{e:#}")))?;
    Ok(DEVICE.get_or_init(|| ctx))
}

/// A renderer error as a Python exception: ValueError for what the caller gave (settings,
/// gates, scenes), RuntimeError for the device.
fn value_error(e: anyhow::Error) -> PyErr {
    PyValueError::new_err(format!("{e:#}"))
}

fn runtime_error(e: anyhow::Error) -> PyErr {
    PyRuntimeError::new_err(format!("{e:#}"))
}

/// A loaded glTF scene (`gatetrace.Scene.load`), baked to world space with its BVH built.
#[pyclass(module = "gatetrace._gatetrace", frozen)]
struct Scene {
    prepared: Arc<PreparedScene>,
    path: PathBuf,
}

#[pymethods]
impl Scene {
    /// Loads a glTF 2.0 scene (.gltf or .glb) or a Mitsuba 3 XML scene. `aperture_radius` and `focus_distance` (m) make
    /// the camera a thin lens, overriding the camera node's `extras` (aperture 0: a pinhole).
    /// `allow_unsupported_materials` renders materials using a glTF extension that lets light
    /// through the surface (KHR_materials_transmission, KHR_materials_volume, ...) as opaque
    /// surfaces instead of refusing the scene (`render --allow-unsupported-materials`).
    /// `parameters` (name to value) replace a Mitsuba scene's `<default>`s (`render --define`).
    /// `fog` = [sigma_t, albedo, g] (1 to 3 numbers: extinction in m^-1, albedo 0..1 (default 0.9),
    /// Henyey-Greenstein g (default 0.8)) fills a scene without media with homogeneous fog
    /// (`render --fog`), which only the path tracer renders.
    /// FileNotFoundError when the file does not exist; ValueError when it cannot be used.
    #[staticmethod]
    #[pyo3(signature = (path, *, aperture_radius=None, focus_distance=None, allow_unsupported_materials=false,
        parameters=None, fog=None))]
    fn load(
        py: Python<'_>,
        path: PathBuf,
        aperture_radius: Option<f32>,
        focus_distance: Option<f32>,
        allow_unsupported_materials: bool,
        parameters: Option<std::collections::BTreeMap<String, String>>,
        fog: Option<Vec<f32>>,
    ) -> PyResult<Self> {
        if !path.exists() {
            return Err(PyFileNotFoundError::new_err(format!("{}: no such file", path.display())));
        }
        let load = || -> anyhow::Result<PreparedScene> {
            let parameters = parameters.unwrap_or_default().into_iter().collect();
            let fog = fog
                .map(|f| {
                    let spec: Vec<String> = f.iter().map(|x| x.to_string()).collect();
                    gatetrace::scene::MediumDesc::parse_fog(&spec.join(",")).map_err(|e| e.context("fog"))
                })
                .transpose()?;
            let options = LoadOptions { allow_unsupported_materials, parameters, fog, ..Default::default() };
            let mut scene = load_scene_with(&path, &options)?;
            scene
                .camera
                .override_lens(aperture_radius, focus_distance, "focus_distance=METRES")
                .map_err(|e| e.context(format!("{}: aperture_radius/focus_distance", scene.source)))?;
            PreparedScene::new(scene)
        };
        let prepared = py.detach(load).map_err(value_error)?;
        // What loading ignored or changed, as Python warnings (RuntimeWarning, as a render's warnings) naming the file.
        let category = py.get_type::<pyo3::exceptions::PyRuntimeWarning>();
        for warning in &prepared.scene.warnings {
            let message = std::ffi::CString::new(warning.replace('\0', " ")).expect("no NUL left");
            PyErr::warn(py, category.as_any(), &message, 1)?;
        }
        Ok(Self { prepared: Arc::new(prepared), path })
    }

    /// The file the scene came from.
    #[getter]
    fn path(&self) -> PathBuf {
        self.path.clone()
    }

    /// Number of triangles (zero-area ones dropped at load are not counted).
    #[getter]
    fn triangles(&self) -> usize {
        self.prepared.scene.triangles.len()
    }

    /// The render settings the file carries (a Mitsuba scene's film, sampler and integrator),
    /// each None where it has none: res (width, height), spp, max_bounces, gate (the command
    /// line's syntax, lengths in metres), seed.
    #[getter]
    fn settings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = &self.prepared.scene.settings;
        let d = PyDict::new(py);
        d.set_item("res", s.resolution)?;
        d.set_item("spp", s.spp)?;
        d.set_item("max_bounces", s.max_bounces)?;
        d.set_item("gate", s.gate.as_deref())?;
        d.set_item("seed", s.seed)?;
        Ok(d)
    }

    /// The camera: position, forward, up and right (unit vectors, world space, metres), yfov
    /// (rad), and the thin lens's aperture_radius and focus_distance (m; None for a pinhole).
    #[getter]
    fn camera<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let c = &self.prepared.scene.camera;
        let d = PyDict::new(py);
        d.set_item("position", c.position.to_array())?;
        d.set_item("forward", c.forward.to_array())?;
        d.set_item("up", c.up.to_array())?;
        d.set_item("right", c.right.to_array())?;
        d.set_item("yfov", c.yfov)?;
        d.set_item("aperture_radius", c.lens.map(|l| l.aperture_radius))?;
        d.set_item("focus_distance", c.lens.map(|l| l.focus_distance))?;
        Ok(d)
    }

    /// The lights, one dict each: `point` and `spot` (position m, intensity W/sr per channel;
    /// a spot's direction and inner/outer half-angles in rad), `directional` (direction of
    /// travel, irradiance W/m^2 per channel) and `area` (one per emissive material: its
    /// radiance W m^-2 sr^-1 per channel, triangles, double_sided).
    #[getter]
    fn lights<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let scene = &self.prepared.scene;
        let list = PyList::empty(py);
        for l in &scene.point_lights {
            let d = PyDict::new(py);
            d.set_item("type", if l.spot.is_some() { "spot" } else { "point" })?;
            d.set_item("position", l.position.to_array())?;
            d.set_item("intensity", l.intensity.to_array())?;
            if let Some(s) = l.spot {
                d.set_item("direction", s.direction.to_array())?;
                d.set_item("inner_cone_angle", s.inner)?;
                d.set_item("outer_cone_angle", s.outer)?;
            }
            list.append(d)?;
        }
        for l in &scene.directional_lights {
            let d = PyDict::new(py);
            d.set_item("type", "directional")?;
            d.set_item("direction", l.direction.to_array())?;
            d.set_item("irradiance", l.irradiance.to_array())?;
            list.append(d)?;
        }
        for (i, m) in scene.materials.iter().enumerate() {
            if !m.is_emissive() {
                continue;
            }
            let triangles = scene.triangles.iter().filter(|t| t.material as usize == i).count();
            if triangles == 0 {
                continue;
            }
            let d = PyDict::new(py);
            d.set_item("type", "area")?;
            d.set_item("material", &m.name)?;
            d.set_item("radiance", m.emission.to_array())?;
            d.set_item("triangles", triangles)?;
            d.set_item("double_sided", m.double_sided)?;
            list.append(d)?;
        }
        Ok(list)
    }

    /// Names of the scene's named nodes, in the order they were visited.
    #[getter]
    fn nodes(&self) -> Vec<String> {
        self.prepared.scene.nodes.iter().map(|n| n.name.clone()).collect()
    }

    /// Axis-aligned bounds of the scene (m): (min xyz, max xyz).
    #[getter]
    fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        let (lo, hi) = self.prepared.bounds();
        (lo.to_array(), hi.to_array())
    }

    /// Shortest and longest optical path length (m) a path with at most `max_bounces`
    /// scattering vertices can have in this scene (bounds, not exact).
    fn path_length_bounds(&self, max_bounces: u32) -> (f32, f32) {
        self.prepared.path_length_bounds(max_bounces)
    }

    fn __repr__(&self) -> String {
        format!("Scene('{}', {} triangles)", self.path.display(), self.prepared.scene.triangles.len())
    }
}

/// What a renderer keeps between renders: the integrator for the last gate (None before the
/// first render, and for `auto`, which builds its chosen method's integrator per render).
struct State {
    integrator: Option<Box<dyn Integrator>>,
    /// The integrator has traced its warm-up pass (kernels compiled at first dispatch).
    warm: bool,
}

/// A renderer bound to one scene and one set of settings: keeps the device, the scene upload
/// and the compiled kernels across renders (`gatetrace.Renderer`).
#[pyclass(module = "gatetrace._gatetrace", frozen)]
struct Renderer {
    scene: Arc<PreparedScene>,
    path: PathBuf,
    /// The settings every render shares (gate and seed are each render's).
    base: RenderSettings,
    state: Mutex<State>,
}

/// A method name as the command line spells it.
fn parse_method(name: &str) -> PyResult<Method> {
    Method::parse(name).map_err(|e| PyValueError::new_err(e.to_string()))
}

/// What a render or capture returns to Python: the image or capture as a float32 numpy array,
/// and the metadata as (key, value as JSON text) pairs.
type Rendered<'py> = (Bound<'py, PyAny>, Vec<(String, String)>);

#[pymethods]
impl Renderer {
    /// A renderer of `scene` with the command line's defaults (see gatetrace.Renderer).
    #[new]
    #[pyo3(signature = (scene, *, method="path", max_bounces=8, res=(256, 256), rr_depth=None, samples_per_pass=None,
        connections_per_query=None, query_split=1.0, query_bottom_nodes=31, query_weights="arcs",
        query_tree="binary", query_roulette=None, medium_connections=false))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        scene: PyRef<'_, Scene>,
        method: &str,
        max_bounces: u32,
        res: (u32, u32),
        rr_depth: Option<u32>,
        samples_per_pass: Option<u32>,
        connections_per_query: Option<u32>,
        query_split: f32,
        query_bottom_nodes: u32,
        query_weights: &str,
        query_tree: &str,
        query_roulette: Option<f32>,
        medium_connections: bool,
    ) -> PyResult<Self> {
        let method = parse_method(method)?;
        let (width, height) = check_image(res, samples_per_pass)?;
        let reflection_weights = parse_query_weights(query_weights)?;
        let wide = parse_query_tree(query_tree)?;
        let settings = RenderSettings {
            width,
            height,
            method,
            max_bounces,
            rr_depth,
            samples_per_pass,
            connections_per_query: connections_per_query
                .unwrap_or(gatetrace::integrator::bidirectional::default_connections_per_query(method)),
            query: QuerySettings {
                split: query_split,
                bottom_nodes: query_bottom_nodes,
                reflection_weights,
                wide,
                ..Default::default()
            },
            query_roulette,
            medium_connections,
            ..Default::default()
        };
        gatetrace::integrator::film_elements(&settings).map_err(value_error)?;
        Ok(Self {
            scene: scene.prepared.clone(),
            path: scene.path.clone(),
            base: settings,
            state: Mutex::new(State { integrator: None, warm: false }),
        })
    }

    /// Renders `gate` (the command line's syntax) for `spp` samples per pixel or `seconds` of
    /// rendering from `seed`; returns (film data as float32 numpy array [H, W, 3] or
    /// [H, W, T, 3], the metadata as (key, value as JSON text) pairs).
    #[pyo3(signature = (gate, spp=None, seconds=None, seed=0))]
    fn render<'py>(
        &self,
        py: Python<'py>,
        gate: &str,
        spp: Option<u64>,
        seconds: Option<f64>,
        seed: u32,
    ) -> PyResult<Rendered<'py>> {
        let gate_value = parse_gate(gate)?;
        let budget = parse_budget(spp, seconds)?;
        // Never wait for the lock: a render releases the GIL and takes it back between passes, so
        // a thread waiting here with the GIL would deadlock with it.
        let mut state = match self.state.try_lock() {
            Ok(state) => state,
            Err(std::sync::TryLockError::Poisoned(e)) => e.into_inner(),
            Err(std::sync::TryLockError::WouldBlock) => {
                return Err(PyRuntimeError::new_err(
                    "this Renderer is rendering in another thread: give each thread its own Renderer",
                ));
            }
        };
        let settings = RenderSettings { gate: gate_value, seed, ..self.base.clone() };
        gatetrace::integrator::film_elements(&settings).map_err(value_error)?;
        let scene = self.scene.clone();
        let start = Instant::now();
        let output = if unreachable_gate(&scene, &settings).is_some() {
            let output = RenderOutput::black(&settings, start.elapsed());
            let mut metadata = self.metadata(&settings, gate, &output)?;
            let warning = black_image_warning(&scene, &settings, gate, &output.film).expect("a black film");
            metadata.push(("warning".into(), warning.into()));
            return Ok((film_array(py, &output.film)?, as_text(metadata)));
        } else if matches!(settings.method, Method::Auto | Method::Combined) {
            // auto builds the chosen method's integrator after its pilot, and combined its halves
            // after the pilot that splits their samples, every render (and stops for Ctrl-C only
            // when it is done).
            let ctx = device()?;
            py.detach(|| gatetrace::integrator::render(ctx, &scene, &settings, budget, |_| {})).map_err(value_error)?
        } else {
            let ctx = device()?;
            let state = &mut *state;
            let reuse = match state.integrator.as_mut() {
                Some(tracer) => py.detach(|| tracer.set_gate(&scene, &settings)).map_err(runtime_error)?,
                None => false,
            };
            if !reuse {
                state.integrator = None;
                let tracer = py.detach(|| create_integrator(ctx, &scene, &settings)).map_err(value_error)?;
                state.integrator = Some(tracer);
                state.warm = false;
            }
            let tracer = state.integrator.as_mut().expect("built above");
            // The device counts cut traversals over the integrator's life: this render's are the
            // difference.
            let truncated_before = tracer.truncated_traversals().map_err(runtime_error)?;
            let mut interrupted: Option<PyErr> = None;
            let traced = py.detach(|| -> anyhow::Result<Duration> {
                if matches!(budget, Budget::Time(_)) && !std::mem::replace(&mut state.warm, true) {
                    tracer.warm_up()?;
                }
                tracer.restart(seed);
                let rendering = Instant::now();
                // Ctrl-C raises KeyboardInterrupt: the error stops the render (never a Break).
                let _ = trace_budget(tracer.as_mut(), budget, |_, _| {
                    Python::attach(|py| py.check_signals()).map(|_| std::ops::ControlFlow::Continue(())).map_err(|e| {
                        interrupted = Some(e);
                        anyhow::anyhow!("interrupted")
                    })
                })?;
                Ok(rendering.elapsed())
            });
            let rendering = match traced {
                Ok(r) => r,
                Err(e) => {
                    // The film holds a partial render: the next render restarts it anyway.
                    return Err(interrupted.take().unwrap_or_else(|| runtime_error(e)));
                }
            };
            RenderOutput {
                film: tracer.film().map_err(runtime_error)?,
                elapsed: start.elapsed(),
                rendering,
                truncated_traversals: tracer.truncated_traversals().map_err(runtime_error)? - truncated_before,
                stats: None,
                target_pilot_spp: tracer.target_pilot_spp(),
                camera_pilot_spp: tracer.camera_pilot_spp(),
                band_index: tracer.band_index_report(),
                band_index_off: tracer.band_index_off(),
                samples_to_visit_every_bin: tracer.samples_to_visit_every_bin(),
                choice: None,
                allocation: None,
                roulette: None,
                stopped_early: false,
                state: None,
            }
        };
        let mut metadata = self.metadata(&settings, gate, &output)?;
        let mut warnings = Vec::new();
        warnings.extend(output.truncated_traversals_warning());
        warnings.extend(output.budget_overrun_warning(budget));
        warnings.extend(output.unvisited_bins_warning());
        warnings.extend(black_image_warning(&self.scene, &settings, gate, &output.film));
        if !warnings.is_empty() {
            metadata.push(("warning".into(), warnings.join("; ").into()));
        }
        Ok((film_array(py, &output.film)?, as_text(metadata)))
    }

    /// The settings every render shares, as the command line names them: (key, value as JSON
    /// text) pairs, valued as in the metadata.
    #[getter]
    fn settings(&self) -> Vec<(String, String)> {
        let s = &self.base;
        let settings: Metadata = vec![
            ("method".into(), s.method.name().into()),
            ("max_bounces".into(), s.max_bounces.into()),
            ("resolution".into(), vec![s.width, s.height].into()),
            ("connections_per_query".into(), s.connections_per_query.into()),
        ];
        settings.into_iter().map(|(k, v)| (k, v.to_string())).collect()
    }

    fn __repr__(&self) -> String {
        let s = &self.base;
        format!(
            "Renderer('{}', method={}, res=({}, {}), max_bounces={})",
            self.path.display(),
            s.method.name(),
            s.width,
            s.height,
            s.max_bounces
        )
    }
}

impl Renderer {
    /// The metadata the command line writes beside its outputs, and the camera.
    fn metadata(&self, settings: &RenderSettings, gate: &str, output: &RenderOutput) -> PyResult<Metadata> {
        let mut metadata = render_metadata(device()?, &self.path, gate, settings, output);
        metadata.push(("camera".into(), self.scene.scene.camera.describe().into()));
        Ok(metadata)
    }
}

/// Metadata as (key, value as JSON text) pairs.
fn as_text(metadata: Metadata) -> Vec<(String, String)> {
    metadata.into_iter().map(|(k, v)| (k, v.to_string())).collect()
}

/// A gate given in the command line's syntax.
/// The image size, checked with the samples per pass: (width, height) in pixels.
fn check_image(res: (u32, u32), samples_per_pass: Option<u32>) -> PyResult<(u32, u32)> {
    let (width, height) = res;
    if width == 0 || height == 0 {
        return Err(PyValueError::new_err(format!("res {width}x{height}: both sides must be at least 1 pixel")));
    }
    if samples_per_pass == Some(0) {
        return Err(PyValueError::new_err("samples_per_pass must be at least 1"));
    }
    Ok(res)
}

/// `query_weights`: "arcs" (false) or "reflection" (true, weights with a bound on the reflected
/// light).
fn parse_query_weights(name: &str) -> PyResult<bool> {
    match name {
        "arcs" => Ok(false),
        "reflection" => Ok(true),
        other => Err(PyValueError::new_err(format!("query_weights `{other}`: choose arcs or reflection"))),
    }
}

/// `query_tree`: "binary" (false) or "wide" (true, queries over the four-wide BVH).
fn parse_query_tree(name: &str) -> PyResult<bool> {
    match name {
        "binary" => Ok(false),
        "wide" => Ok(true),
        other => Err(PyValueError::new_err(format!("query_tree `{other}`: choose binary or wide"))),
    }
}

fn parse_gate(spec: &str) -> PyResult<Gate> {
    Gate::parse(spec).map_err(|e| value_error(e.context(format!("gate `{spec}`"))))
}

/// How long to render: `spp` samples per pixel or `seconds` of rendering (64 spp when neither is
/// given), as the command line's --spp and --time.
fn parse_budget(spp: Option<u64>, seconds: Option<f64>) -> PyResult<Budget> {
    match (spp, seconds) {
        (Some(_), Some(_)) => Err(PyValueError::new_err("give spp or seconds, not both")),
        (Some(0), None) => Err(PyValueError::new_err("spp must be at least 1")),
        (Some(n), None) => Ok(Budget::Samples(n)),
        (None, Some(t)) => match Duration::try_from_secs_f64(t) {
            Ok(d) if t > 0.0 => Ok(Budget::Time(d)),
            _ => Err(PyValueError::new_err(format!("seconds={t}: give a positive number of seconds"))),
        },
        (None, None) => Ok(Budget::Samples(64)),
    }
}

/// What a capture's renders report to Python: its setup's warnings, kept for the metadata, and
/// Ctrl-C, checked after every pass (KeyboardInterrupt stops the capture unwritten).
#[derive(Default)]
struct CaptureSignals {
    warnings: Vec<String>,
    interrupted: Option<PyErr>,
}

impl CaptureProgress for CaptureSignals {
    fn warning(&mut self, warning: &str) {
        self.warnings.push(warning.to_owned());
    }

    fn render_started(&mut self, _k: usize, _count: usize, _settings: &RenderSettings) {}

    fn pass(&mut self, _progress: Progress) -> ControlFlow<()> {
        match Python::attach(|py| py.check_signals()) {
            Ok(()) => ControlFlow::Continue(()),
            Err(e) => {
                self.interrupted = Some(e);
                ControlFlow::Break(())
            }
        }
    }

    fn render_ended(&mut self, _k: usize, _count: usize) -> ControlFlow<()> {
        if self.interrupted.is_some() { ControlFlow::Break(()) } else { ControlFlow::Continue(()) }
    }
}

/// Renders an NLOS capture of the scene at `path`, as `gatetrace render PATH --nlos SCAN` with
/// the same options and defaults (see gatetrace.capture); returns (the capture as a float32 numpy
/// array in the layout of the command line's .npy, the metadata and the capture's record as (key,
/// value as JSON text) pairs).
#[pyfunction]
#[pyo3(signature = (path, scan=None, gate=None, *, spp=None, seconds=None, seed=None, method=None, max_bounces=None,
    res=None, rr_depth=None, samples_per_pass=None, connections_per_query=None, query_split=1.0,
    query_bottom_nodes=31, query_weights=None, query_tree="binary", target_pilot=None, band_index="auto", needle_guard=1e-6,
    length_guard=1e-5, relay_wall=None, sensor_origin=None, laser_origin=None,
    laser_spot=None, laser_grid=None, laser_power=None, count_first_last=false,
    allow_unsupported_materials=false, parameters=None))]
#[allow(clippy::too_many_arguments)]
fn capture<'py>(
    py: Python<'py>,
    path: PathBuf,
    scan: Option<&str>,
    gate: Option<&str>,
    spp: Option<u64>,
    seconds: Option<f64>,
    seed: Option<u32>,
    method: Option<&str>,
    max_bounces: Option<u32>,
    res: Option<(u32, u32)>,
    rr_depth: Option<u32>,
    samples_per_pass: Option<u32>,
    connections_per_query: Option<u32>,
    query_split: f32,
    query_bottom_nodes: u32,
    query_weights: Option<&str>,
    query_tree: &str,
    target_pilot: Option<u32>,
    band_index: &str,
    needle_guard: f32,
    length_guard: f32,
    relay_wall: Option<&str>,
    sensor_origin: Option<[f32; 3]>,
    laser_origin: Option<[f32; 3]>,
    laser_spot: Option<(f32, f32)>,
    laser_grid: Option<(u32, u32)>,
    laser_power: Option<f32>,
    count_first_last: bool,
    allow_unsupported_materials: bool,
    parameters: Option<std::collections::BTreeMap<String, String>>,
) -> PyResult<Rendered<'py>> {
    if !path.exists() {
        return Err(PyFileNotFoundError::new_err(format!("{}: no such file", path.display())));
    }
    // The capture a Mitsuba scene describes, and its film, sampler and depth, give what the
    // caller left as None (as the command line's options override a file's).
    let parameters: Vec<(String, String)> = parameters.unwrap_or_default().into_iter().collect();
    let file = gatetrace::scene::scene_settings(&path, &parameters).map_err(value_error)?;
    let described = file.capture.as_ref();
    let scan = match (scan, described) {
        (Some(scan), _) => [Scan::Single, Scan::Confocal, Scan::Exhaustive]
            .into_iter()
            .find(|s| s.name() == scan)
            .ok_or_else(|| PyValueError::new_err(format!("scan `{scan}`: choose single, confocal or exhaustive")))?,
        (None, Some(c)) => c.scan,
        (None, None) => {
            return Err(PyValueError::new_err(format!(
                "{}: give scan (single, confocal or exhaustive): the file describes no capture",
                path.display()
            )));
        }
    };
    let gate = gate.map(str::to_owned).or(file.gate.clone()).unwrap_or_else(|| "none".into());
    let gate = gate.as_str();
    let seed = seed.or(file.seed).unwrap_or(0);
    let max_bounces = max_bounces.or(file.max_bounces).unwrap_or(8);
    let spp = if seconds.is_none() { spp.or(file.spp) } else { spp };
    let budget = parse_budget(spp, seconds)?;
    let (width, height) = check_image(res.or(file.resolution).unwrap_or((256, 256)), samples_per_pass)?;
    if let Some((w, h)) = laser_grid
        && (w == 0 || h == 0)
    {
        return Err(PyValueError::new_err(format!("laser_grid {w}x{h}: both sides must be at least 1 spot")));
    }
    let reflection_weights = query_weights.map(parse_query_weights).transpose()?;
    let band_index_choice = match band_index {
        "auto" => None,
        "on" => Some(true),
        "off" => Some(false),
        other => return Err(PyValueError::new_err(format!("band_index `{other}`: choose auto, on or off"))),
    };
    let choices = CaptureChoices {
        method: method.map(parse_method).transpose()?,
        connections_per_query,
        reflection_weights,
        target_pilot,
        band_index: band_index_choice,
    };
    let mut settings = RenderSettings {
        width,
        height,
        gate: parse_gate(gate)?,
        max_bounces,
        rr_depth,
        seed,
        samples_per_pass,
        query: QuerySettings {
            split: query_split,
            bottom_nodes: query_bottom_nodes,
            wide: parse_query_tree(query_tree)?,
            ..Default::default()
        },
        ellipsoid_guards: EllipsoidGuards { needle: needle_guard, length: length_guard },
        ..Default::default()
    };
    choices.apply(&mut settings);
    if settings.target_pilot_spp != 0 && settings.method != Method::Ellipsoidal {
        return Err(PyValueError::new_err("target_pilot applies to method ellipsoidal only"));
    }
    let options = CaptureOptions {
        relay_wall: relay_wall.map(str::to_owned),
        sensor_origin: sensor_origin.map(glam_point),
        laser_origin: laser_origin.map(glam_point),
        laser_spot: laser_spot.map(glam::Vec2::from),
        laser_grid,
        laser_power,
        count_first_and_last: count_first_last,
        band_index_auto: band_index_choice.is_none(),
    };
    let request = CaptureRequest::new(scan, described, options);
    request.check(&settings).map_err(value_error)?;
    gatetrace::integrator::film_elements(&settings).map_err(value_error)?;
    let load = LoadOptions { allow_unsupported_materials, parameters, ..Default::default() };
    let prepared = py.detach(|| prepare_capture(&path, load, &request, settings, budget)).map_err(value_error)?;
    let ctx = device()?;
    let mut signals = CaptureSignals::default();
    let rendered = py.detach(|| render_capture(ctx, &prepared, budget, &mut signals));
    if let Some(interrupted) = signals.interrupted.take() {
        return Err(interrupted);
    }
    let capture = rendered.map_err(value_error)?.expect("only Ctrl-C stops a capture");
    let mut metadata = capture.metadata(ctx, &path, gate, &prepared);
    let mut warnings = signals.warnings;
    warnings.extend(capture.output.unvisited_bins_warning());
    if !warnings.is_empty() {
        metadata.push(("warning".into(), warnings.join("; ").into()));
    }
    metadata.extend(capture.record(&prepared));
    let data = PyArray1::from_slice(py, &capture.data).reshape(capture.shape(&prepared))?.into_any();
    Ok((data, as_text(metadata)))
}

/// A point given as [x, y, z].
fn glam_point(p: [f32; 3]) -> glam::Vec3 {
    glam::Vec3::from_array(p)
}

/// A film as a float32 numpy array: [H, W, 3], or [H, W, T, 3] for more than one bin; row 0 is
/// the top of the image (the command line's .npy layout).
fn film_array<'py>(py: Python<'py>, film: &Film) -> PyResult<Bound<'py, PyAny>> {
    let (h, w, t) = (film.height as usize, film.width as usize, film.bins as usize);
    let shape = if t == 1 { vec![h, w, 3] } else { vec![h, w, t, 3] };
    let flat = PyArray1::from_slice(py, &film.data);
    Ok(flat.reshape(shape)?.into_any())
}

/// Describes a gate given in the command line's syntax (ValueError when it is not one).
#[pyfunction]
fn describe_gate(spec: &str) -> PyResult<String> {
    parse_gate(spec).map(|g| g.describe())
}

/// Compute pipelines (kernels) built in this process so far.
#[pyfunction]
fn kernels_built() -> u64 {
    gatetrace::gpu::kernels::kernels_built()
}

/// The device renders run on: adapter name, backend and type (opens it if needed).
#[pyfunction]
fn device_name() -> PyResult<String> {
    Ok(device()?.adapter_description())
}

/// The renderer's version.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

#[pymodule]
fn _gatetrace(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Scene>()?;
    m.add_class::<Renderer>()?;
    m.add_function(wrap_pyfunction!(capture, m)?)?;
    m.add_function(wrap_pyfunction!(describe_gate, m)?)?;
    m.add_function(wrap_pyfunction!(kernels_built, m)?)?;
    m.add_function(wrap_pyfunction!(device_name, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    Ok(())
}
