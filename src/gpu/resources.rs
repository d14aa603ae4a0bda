//! Buffers by name: the host creates each buffer under the name its WGSL binding has, and
//! kernels bind whatever they declare (see `Kernel::bind`).

use std::collections::HashMap;

use anyhow::{Result, bail};
use wgpu::util::DeviceExt as _;

use super::GpuContext;

/// A set of named buffers.
#[derive(Clone, Default)]
pub struct Resources {
    buffers: HashMap<&'static str, wgpu::Buffer>,
}

impl Resources {
    pub fn get(&self, name: &str) -> Option<&wgpu::Buffer> {
        self.buffers.get(name)
    }

    pub fn insert(&mut self, name: &'static str, buffer: wgpu::Buffer) {
        self.buffers.insert(name, buffer);
    }

    /// A copy with the buffers of names `a` and `b` exchanged (queue ping-pong).
    pub fn swapped(&self, a: &'static str, b: &'static str) -> Self {
        let mut out = self.clone();
        let (x, y) = (self.buffers[a].clone(), self.buffers[b].clone());
        out.buffers.insert(a, y);
        out.buffers.insert(b, x);
        out
    }

    /// Creates storage buffer `name` holding `data` (at least 16 bytes, so empty tables still bind).
    pub fn storage_init<T: bytemuck::Pod>(&mut self, ctx: &GpuContext, name: &'static str, data: &[T]) -> Result<()> {
        let mut bytes = bytemuck::cast_slice::<T, u8>(data).to_vec();
        check_size(ctx, name, bytes.len() as u64)?;
        bytes.resize(bytes.len().max(16), 0);
        let buffer = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(name),
            contents: &bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
        });
        self.insert(name, buffer);
        Ok(())
    }

    /// Creates a zeroed storage buffer `name` of `size` bytes (extra usages added to STORAGE).
    pub fn storage_zeroed(
        &mut self,
        ctx: &GpuContext,
        name: &'static str,
        size: u64,
        extra: wgpu::BufferUsages,
    ) -> Result<()> {
        check_size(ctx, name, size)?;
        let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(name),
            size: size.max(16),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC | extra,
            mapped_at_creation: false,
        });
        self.insert(name, buffer);
        Ok(())
    }

    /// Creates uniform buffer `name` holding `value`.
    pub fn uniform_init<T: bytemuck::Pod>(&mut self, ctx: &GpuContext, name: &'static str, value: &T) {
        let buffer = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(name),
            contents: bytemuck::bytes_of(value),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });
        self.insert(name, buffer);
    }
}

fn check_size(ctx: &GpuContext, name: &str, size: u64) -> Result<()> {
    let max = ctx.max_binding_size();
    if size > max {
        bail!(
            "buffer `{name}` needs {:.1} MiB but adapter `{}` binds at most {:.1} MiB per buffer; \
             reduce the resolution, bins or samples per wave, or the scene's size",
            size as f64 / 1048576.0,
            ctx.adapter_info.name,
            max as f64 / 1048576.0
        );
    }
    Ok(())
}

/// Reads a buffer back to the host (blocking). The buffer needs COPY_SRC.
pub fn read_buffer<T: bytemuck::Pod>(ctx: &GpuContext, buffer: &wgpu::Buffer, count: usize) -> Result<Vec<T>> {
    let size = (count * std::mem::size_of::<T>()) as u64;
    if size == 0 {
        return Ok(Vec::new());
    }
    let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
    encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
    ctx.queue.submit([encoder.finish()]);
    let slice = staging.slice(..);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    ctx.wait_idle()?;
    rx.recv()??;
    let data = bytemuck::pod_collect_to_vec::<u8, T>(&slice.get_mapped_range()?);
    staging.unmap();
    Ok(data)
}
