//! The headless GPU device: adapter choice (`WGPU_ADAPTER_NAME`), features and limits.

use anyhow::{Context as _, Result, bail};

/// How to get a Vulkan device on a machine without a GPU; printed with "no adapter" errors.
pub const NO_ADAPTER_HINT: &str = "gatetrace needs a Vulkan (or Metal/DX12) device. On a machine without a GPU, \
install Mesa's CPU implementation lavapipe: `sudo apt-get install -y mesa-vulkan-drivers` (Debian/Ubuntu).";

/// A device and queue with the adapter's name and limits (the device gets all of the adapter's
/// limits, e.g. storage bindings per stage).
pub struct GpuContext {
    /// The instance the adapter came from (the viewer creates its window surface with it).
    pub instance: wgpu::Instance,
    /// The adapter the device was opened on.
    pub adapter: wgpu::Adapter,
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// Name, backend and type of the adapter.
    pub adapter_info: wgpu::AdapterInfo,
    /// The device's limits.
    pub limits: wgpu::Limits,
    /// The optional features the device was opened with.
    pub features: wgpu::Features,
    /// GPU time per stage, when enabled (`enable_profiling`); kernels built afterwards record
    /// their dispatches into it.
    pub profiler: Option<super::profiler::SharedProfiler>,
    /// The kernels built on this device so far, reused by later renders.
    pub kernels: super::kernels::KernelCache,
    /// The arrays of the scene uploaded last, bound by every tracer of that scene
    /// (`integrator::upload::scene_buffers`).
    pub scene_buffers: super::resources::SharedBufferCache,
    /// Why the device was lost, once it has been (the driver's reason and message).
    lost: std::sync::Arc<std::sync::Mutex<Option<String>>>,
    /// The first error the device reported outside an error scope (running out of memory for
    /// a staging buffer, say); `wait_idle` returns it instead of the process panicking.
    uncaptured: std::sync::Arc<std::sync::Mutex<Option<String>>>,
}

impl GpuContext {
    /// Opens a headless device. `WGPU_ADAPTER_NAME` (case-insensitive substring) picks the adapter;
    /// otherwise a discrete GPU is preferred over an integrated, virtual or CPU one.
    /// `WGPU_BACKEND` restricts the backends as in wgpu.
    pub fn new() -> Result<Self> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        if std::env::var_os("WGPU_BACKEND").is_none() {
            desc.backends = wgpu::Backends::VULKAN | wgpu::Backends::METAL | wgpu::Backends::DX12;
        }
        let instance = wgpu::Instance::new(desc);
        let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
        let adapter = choose_adapter(adapters)?;
        let adapter_info = adapter.get_info();
        let limits = adapter.limits();
        // Timestamps for --profile, where the device has them.
        let features =
            adapter.features() & (wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_PASSES);
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("gatetrace"),
            required_features: features,
            required_limits: limits.clone(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .with_context(|| format!("cannot open a device on adapter `{}`", adapter_info.name))?;
        let lost = std::sync::Arc::new(std::sync::Mutex::new(None));
        let record = lost.clone();
        device.set_device_lost_callback(move |reason, message| {
            *record.lock().unwrap_or_else(|e| e.into_inner()) = Some(format!("{reason:?}: {message}"));
        });
        let uncaptured = std::sync::Arc::new(std::sync::Mutex::new(None));
        let record = uncaptured.clone();
        device.on_uncaptured_error(std::sync::Arc::new(move |e: wgpu::Error| {
            let message = match &e {
                wgpu::Error::OutOfMemory { .. } => {
                    "the device ran out of memory; reduce the resolution, the bins or the samples per pass".to_owned()
                }
                other => format!("device error: {other}"),
            };
            record.lock().unwrap_or_else(|e| e.into_inner()).get_or_insert(message);
        }));
        Ok(Self {
            instance,
            adapter,
            device,
            queue,
            adapter_info,
            limits,
            features,
            profiler: None,
            kernels: Default::default(),
            scene_buffers: Default::default(),
            lost,
            uncaptured,
        })
    }

    /// Why the device was lost (a driver reset, a hung kernel, an unplugged GPU), if it was.
    pub fn lost_reason(&self) -> Option<String> {
        self.lost.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Runs `create`, which makes buffer `name` of `size` bytes, and turns the device running out
    /// of memory for it into an error naming the buffer, its size and the adapter.
    pub fn allocate<T>(&self, name: &str, size: u64, create: impl FnOnce() -> T) -> Result<T> {
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let value = create();
        if let Some(e) = pollster::block_on(scope.pop()) {
            bail!(
                "out of device memory: buffer `{name}` of {:.1} MiB does not fit on `{}` ({e}); reduce the resolution, \
                 the bins or the samples per pass",
                size as f64 / 1048576.0,
                self.adapter_info.name
            );
        }
        Ok(value)
    }

    /// "name (backend, device type)", as recorded with every output.
    pub fn adapter_description(&self) -> String {
        let i = &self.adapter_info;
        format!("{} ({:?}, {:?})", i.name, i.backend, i.device_type)
    }

    /// True when the device is a CPU (lavapipe): it runs a few SIMD groups at a time, where a
    /// GPU wants tens of thousands of invocations in flight.
    pub fn is_cpu(&self) -> bool {
        self.adapter_info.device_type == wgpu::DeviceType::Cpu
    }

    /// Largest storage-buffer binding the device allows (bytes).
    pub fn max_binding_size(&self) -> u64 {
        self.limits.max_storage_buffer_binding_size.min(self.limits.max_buffer_size)
    }

    /// Blocks until all submitted work has finished (and adds the finished dispatches' times to
    /// the profiler, when there is one).
    pub fn wait_idle(&self) -> Result<()> {
        let polled = self.device.poll(wgpu::PollType::wait_indefinitely());
        if let Some(error) = self.uncaptured.lock().unwrap_or_else(|e| e.into_inner()).clone() {
            bail!("GPU `{}`: {error}", self.adapter_info.name);
        }
        if let Err(e) = polled {
            let reason = self.lost_reason().unwrap_or_else(|| e.to_string());
            bail!(
                "the GPU device `{}` was lost while rendering ({reason}); the render cannot go on (a render with \
                 --checkpoint-every resumes from its last checkpoint with --resume)",
                self.adapter_info.name
            );
        }
        if let Some(profiler) = &self.profiler {
            profiler.lock().unwrap().collect(&self.device, &self.queue)?;
        }
        Ok(())
    }

    /// Times every dispatch of kernels built from now on (`render --profile`).
    pub fn enable_profiling(&mut self) -> Result<()> {
        let profiler = super::profiler::Profiler::new(&self.device, &self.queue)?;
        self.profiler = Some(std::sync::Arc::new(std::sync::Mutex::new(profiler)));
        Ok(())
    }

    /// The profiler's sums per stage (pipeline label) so far (None unless profiling).
    pub fn profile_totals(&self) -> Result<Option<std::collections::BTreeMap<String, super::profiler::StageTime>>> {
        let Some(profiler) = &self.profiler else { return Ok(None) };
        self.wait_idle()?;
        Ok(Some(profiler.lock().unwrap().totals().clone()))
    }

    /// The per-stage table of the profiler (None unless profiling).
    pub fn profile_report(&self) -> Result<Option<String>> {
        let Some(profiler) = &self.profiler else { return Ok(None) };
        self.wait_idle()?;
        Ok(Some(profiler.lock().unwrap().report(&self.adapter_description())))
    }
}

fn choose_adapter(adapters: Vec<wgpu::Adapter>) -> Result<wgpu::Adapter> {
    if adapters.is_empty() {
        bail!("no GPU adapter found. {NO_ADAPTER_HINT}");
    }
    if let Ok(wanted) = std::env::var("WGPU_ADAPTER_NAME") {
        let wanted_lower = wanted.to_lowercase();
        let names: Vec<String> = adapters.iter().map(|a| a.get_info().name).collect();
        return adapters.into_iter().find(|a| a.get_info().name.to_lowercase().contains(&wanted_lower)).with_context(
            || format!("WGPU_ADAPTER_NAME={wanted:?} matches no adapter; available: {}", names.join(", ")),
        );
    }
    let rank = |a: &wgpu::Adapter| match a.get_info().device_type {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    };
    Ok(adapters.into_iter().min_by_key(rank).expect("adapters is not empty"))
}
