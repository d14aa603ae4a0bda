//! Compute kernels: one per file in `shaders/kernels/` (and test-only `shaders/probes/`), composed
//! and validated by the build script. A kernel's WGSL file, entry point, Rust name and pipeline
//! label are the same word; specialised variants add their overrides to the label.

use std::borrow::Cow;

use super::{GpuContext, Resources};

/// How a kernel uses a binding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BindingKind {
    /// `var<uniform>`.
    Uniform,
    /// `var<storage, read>`.
    StorageRead,
    /// `var<storage, read_write>`.
    StorageReadWrite,
}

/// A resource a kernel uses, reflected from its WGSL.
#[derive(Clone, Copy, Debug)]
pub struct BindingInfo {
    /// `@binding` number in group 0.
    pub binding: u32,
    /// The WGSL variable name, which is also the name the host binds a buffer under.
    pub name: &'static str,
    /// How the kernel accesses it.
    pub kind: BindingKind,
}

/// A composed, validated kernel and its reflected interface.
#[derive(Debug)]
pub struct KernelSource {
    /// The file name = entry point name.
    pub name: &'static str,
    /// The WESL feature flag this variant was composed with (`@if(feature)`), if any.
    pub feature: Option<&'static str>,
    /// The composed WGSL.
    pub wgsl: &'static str,
    /// `@workgroup_size`.
    pub workgroup_size: [u32; 3],
    /// Every resource the kernel uses.
    pub bindings: &'static [BindingInfo],
    /// Names of the pipeline-overridable constants the kernel declares.
    pub overrides: &'static [&'static str],
}

include!(concat!(env!("OUT_DIR"), "/kernels.rs"));

/// The kernel source named `name` (panics on an unknown name: that is a programming error).
pub fn kernel_source(name: &str) -> &'static KernelSource {
    kernel_variant(name, None)
}

/// The source of kernel `name` composed with WESL feature flag `feature` on (build.rs lists the
/// variants it builds).
pub fn kernel_variant(name: &str, feature: Option<&str>) -> &'static KernelSource {
    KERNEL_SOURCES
        .iter()
        .find(|k| k.name == name && k.feature == feature)
        .unwrap_or_else(|| panic!("no kernel named `{name}` with feature {feature:?} in shaders/"))
}

/// Compute pipelines built in this process so far (each [`Kernel`] not found in its device's
/// [`KernelCache`]): the Python package's tests check that a gate sweep on one renderer builds
/// none after its first render.
static KERNELS_BUILT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// How many compute pipelines (kernels) this process has built so far.
pub fn kernels_built() -> u64 {
    KERNELS_BUILT.load(std::sync::atomic::Ordering::Relaxed)
}

/// What tells two builds of a kernel apart: its source (name and feature), its pipeline label
/// and the specialisation constants it declares, as f64 bits.
type KernelKey = (&'static str, Option<&'static str>, String, Vec<(String, u64)>);

/// The kernels one device has built, so that a process builds each specialisation once: the
/// renders of `equal-time` and `bench`, a viewer's rebuilt tracers and the Python package's
/// renderers reuse the pipelines of earlier renders instead of building them again (on CPU
/// Vulkan about 0.5 s per render of an ellipsoidal method even with the driver's disk cache).
#[derive(Default)]
pub struct KernelCache {
    built: std::sync::Mutex<std::collections::HashMap<KernelKey, (wgpu::ComputePipeline, wgpu::BindGroupLayout)>>,
}

/// A compute pipeline with its bind-group layout.
pub struct Kernel {
    /// Pipeline label (the kernel's name, with a variant in parentheses).
    pub label: String,
    /// The composed WGSL and its reflected interface.
    pub source: &'static KernelSource,
    pipeline: wgpu::ComputePipeline,
    bind_group_layout: wgpu::BindGroupLayout,
    /// The context's profiler when it was on at build time: every dispatch is timed.
    profiler: Option<super::profiler::SharedProfiler>,
}

impl Kernel {
    /// Builds kernel `name` specialised with `constants`; constants the kernel does not declare
    /// are ignored, so callers can pass one set of specialisation constants to every kernel.
    /// The pipeline label is the kernel's name, with `variant` in parentheses when one kernel
    /// serves several stages (e.g. `setup_dispatch(rays)`).
    pub fn new(ctx: &GpuContext, name: &str, variant: Option<&str>, constants: &[(&str, f64)]) -> Self {
        Self::from_source(ctx, kernel_source(name), variant, constants)
    }

    /// Like [`Kernel::new`], from the variant composed with WESL feature flag `feature`; the
    /// label is `name(feature)`.
    pub fn with_feature(ctx: &GpuContext, name: &str, feature: &str, constants: &[(&str, f64)]) -> Self {
        Self::from_source(ctx, kernel_variant(name, Some(feature)), Some(feature), constants)
    }

    fn from_source(
        ctx: &GpuContext,
        source: &'static KernelSource,
        variant: Option<&str>,
        constants: &[(&str, f64)],
    ) -> Self {
        let name = source.name;
        let used: Vec<(&str, f64)> = constants.iter().filter(|(k, _)| source.overrides.contains(k)).copied().collect();
        let label = match variant {
            Some(v) => format!("{name}({v})"),
            None => name.to_owned(),
        };
        let key: KernelKey =
            (name, source.feature, label.clone(), used.iter().map(|&(k, v)| (k.to_owned(), v.to_bits())).collect());
        let cached = ctx.kernels.built.lock().unwrap_or_else(|e| e.into_inner()).get(&key).cloned();
        let (pipeline, bind_group_layout) = match cached {
            Some(built) => built,
            None => {
                let built = Self::build(ctx, source, &label, &used);
                // Two threads that built the same kernel at once keep the first one's.
                ctx.kernels.built.lock().unwrap_or_else(|e| e.into_inner()).entry(key).or_insert(built).clone()
            }
        };
        Self { label, source, pipeline, bind_group_layout, profiler: ctx.profiler.clone() }
    }

    /// Compiles the pipeline of `source` specialised with `used` (the constants it declares).
    fn build(
        ctx: &GpuContext,
        source: &'static KernelSource,
        label: &str,
        used: &[(&str, f64)],
    ) -> (wgpu::ComputePipeline, wgpu::BindGroupLayout) {
        let name = source.name;
        // The driver receives the kernel with its constants substituted and the branches they
        // rule out removed (`specialise`), so nothing is left for the pipeline to override.
        let (shader, overrides) = if super::specialise::pruning() {
            let module = super::specialise::specialise(source, used).unwrap_or_else(|e| panic!("{e}"));
            (wgpu::ShaderSource::Naga(Cow::Owned(module)), &[][..])
        } else {
            (wgpu::ShaderSource::Wgsl(Cow::Borrowed(source.wgsl)), used)
        };
        let module =
            ctx.device.create_shader_module(wgpu::ShaderModuleDescriptor { label: Some(name), source: shader });
        let entries: Vec<wgpu::BindGroupLayoutEntry> = source
            .bindings
            .iter()
            .map(|b| wgpu::BindGroupLayoutEntry {
                binding: b.binding,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: match b.kind {
                        BindingKind::Uniform => wgpu::BufferBindingType::Uniform,
                        BindingKind::StorageRead => wgpu::BufferBindingType::Storage { read_only: true },
                        BindingKind::StorageReadWrite => wgpu::BufferBindingType::Storage { read_only: false },
                    },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            })
            .collect();
        let bind_group_layout = ctx
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: &entries });
        let layout = ctx.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &[Some(&bind_group_layout)],
            immediate_size: 0,
        });
        let pipeline = ctx.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: Some(&layout),
            module: &module,
            entry_point: Some(name),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants: overrides,
                zero_initialize_workgroup_memory: false,
            },
            cache: None,
        });
        KERNELS_BUILT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        (pipeline, bind_group_layout)
    }

    /// A bind group with every binding of the kernel taken from `resources` by name.
    pub fn bind(&self, ctx: &GpuContext, resources: &Resources) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = self
            .source
            .bindings
            .iter()
            .map(|b| wgpu::BindGroupEntry {
                binding: b.binding,
                resource: resources
                    .get(b.name)
                    .unwrap_or_else(|| panic!("kernel `{}` binds `{}`, which was never created", self.label, b.name))
                    .as_entire_binding(),
            })
            .collect();
        ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(&self.label),
            layout: &self.bind_group_layout,
            entries: &entries,
        })
    }

    /// Records a dispatch of `invocations` invocations along x.
    pub fn dispatch(&self, pass: &mut wgpu::ComputePass, bind_group: &wgpu::BindGroup, invocations: u32) {
        let pair = self.profiler.as_ref().and_then(|p| p.lock().unwrap().begin(pass, &self.label));
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, bind_group, &[]);
        pass.dispatch_workgroups(invocations.div_ceil(self.source.workgroup_size[0]), 1, 1);
        if let (Some(p), Some(pair)) = (&self.profiler, pair) {
            p.lock().unwrap().end(pass, pair);
        }
    }

    /// Records an indirect dispatch whose workgroup counts are at `offset` (bytes) in `args`.
    pub fn dispatch_indirect(
        &self,
        pass: &mut wgpu::ComputePass,
        bind_group: &wgpu::BindGroup,
        args: &wgpu::Buffer,
        offset: u64,
    ) {
        let pair = self.profiler.as_ref().and_then(|p| p.lock().unwrap().begin(pass, &self.label));
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, bind_group, &[]);
        pass.dispatch_workgroups_indirect(args, offset);
        if let (Some(p), Some(pair)) = (&self.profiler, pair) {
            p.lock().unwrap().end(pass, pair);
        }
    }
}
