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
        // Optional features the kernels have variants for, and timestamps for --profile.
        let features = adapter.features()
            & (wgpu::Features::SHADER_FLOAT32_ATOMIC
                | wgpu::Features::TIMESTAMP_QUERY
                | wgpu::Features::TIMESTAMP_QUERY_INSIDE_PASSES);
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("gatetrace"),
            required_features: features,
            required_limits: limits.clone(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .with_context(|| format!("cannot open a device on adapter `{}`", adapter_info.name))?;
        Ok(Self { instance, adapter, device, queue, adapter_info, limits, features, profiler: None })
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

    /// True when kernels may add floats atomically in storage buffers (SHADER_FLOAT32_ATOMIC;
    /// lavapipe has it).
    pub fn has_float_atomics(&self) -> bool {
        self.features.contains(wgpu::Features::SHADER_FLOAT32_ATOMIC)
    }

    /// Largest storage-buffer binding the device allows (bytes).
    pub fn max_binding_size(&self) -> u64 {
        self.limits.max_storage_buffer_binding_size.min(self.limits.max_buffer_size)
    }

    /// Blocks until all submitted work has finished (and adds the finished dispatches' times to
    /// the profiler, when there is one).
    pub fn wait_idle(&self) -> Result<()> {
        self.device.poll(wgpu::PollType::wait_indefinitely()).context("GPU device lost while waiting")?;
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
        return adapters
            .into_iter()
            .find(|a| a.get_info().name.to_lowercase().contains(&wanted_lower))
            .with_context(|| {
                format!("WGPU_ADAPTER_NAME={wanted:?} matches no adapter; available: {}", names.join(", "))
            });
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
