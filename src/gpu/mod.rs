//! GPU plumbing: the headless device, the structs shared with WGSL, the kernels, the buffers
//! they bind by name and WGSL's half-float packing.

pub mod context;
pub mod kernels;
pub mod layout;
pub mod packing;
pub mod profiler;
pub mod resources;
pub mod specialise;

pub use context::GpuContext;
pub use kernels::Kernel;
pub use resources::Resources;
