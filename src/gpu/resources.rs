//! Buffers by name: the host creates each buffer under the name its WGSL binding has, and
//! kernels bind whatever they declare (see `Kernel::bind`).

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use anyhow::{Result, bail};
use wgpu::util::DeviceExt as _;

use super::GpuContext;

/// A set of named buffers.
#[derive(Clone, Default)]
pub struct Resources {
    buffers: HashMap<&'static str, wgpu::Buffer>,
}

impl Resources {
    /// The buffer named `name`.
    pub fn get(&self, name: &str) -> Option<&wgpu::Buffer> {
        self.buffers.get(name)
    }

    /// Adds (or replaces) the buffer named `name`.
    pub fn insert(&mut self, name: &'static str, buffer: wgpu::Buffer) {
        self.buffers.insert(name, buffer);
    }

    /// Adds every buffer of `shared` under its name (handles to the same buffers).
    pub fn share(&mut self, shared: &Resources) {
        for (&name, buffer) in &shared.buffers {
            self.insert(name, buffer.clone());
        }
    }

    /// A copy with the buffers of names `a` and `b` exchanged (queue ping-pong).
    pub fn swapped(&self, a: &'static str, b: &'static str) -> Self {
        let mut out = self.clone();
        let (x, y) = (self.buffers[a].clone(), self.buffers[b].clone());
        out.buffers.insert(a, y);
        out.buffers.insert(b, x);
        out
    }

    /// Creates storage buffer `name` holding `data` (at least one element and 16 bytes, so empty
    /// tables still bind).
    pub fn storage_init<T: bytemuck::Pod>(&mut self, ctx: &GpuContext, name: &'static str, data: &[T]) -> Result<()> {
        let data_bytes = bytemuck::cast_slice::<T, u8>(data);
        check_size(ctx, name, data_bytes.len() as u64)?;
        // Padded where short of storage_init_bytes (tiny tables); a scene's arrays go as they
        // are, without a copy (459 MiB of triangles for ten million).
        let size = storage_init_bytes(data) as usize;
        let bytes = if data_bytes.len() == size {
            std::borrow::Cow::Borrowed(data_bytes)
        } else {
            let mut padded = data_bytes.to_vec();
            padded.resize(size, 0);
            std::borrow::Cow::Owned(padded)
        };
        let buffer = ctx.allocate(name, bytes.len() as u64, || {
            ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(name),
                contents: &bytes,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            })
        })?;
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
        let buffer = ctx.allocate(name, size, || {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(name),
                size: size.max(16),
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_DST
                    | wgpu::BufferUsages::COPY_SRC
                    | extra,
                mapped_at_creation: false,
            })
        })?;
        self.insert(name, buffer);
        Ok(())
    }

    /// Creates uniform buffer `name` holding the array `values`.
    pub fn uniform_slice_init<T: bytemuck::Pod>(&mut self, ctx: &GpuContext, name: &'static str, values: &[T]) {
        let buffer = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(name),
            contents: bytemuck::cast_slice(values),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });
        self.insert(name, buffer);
    }

    /// Creates uniform buffer `name` holding `value`.
    pub fn uniform_init<T: bytemuck::Pod>(&mut self, ctx: &GpuContext, name: &'static str, value: &T) {
        self.uniform_slice_init(ctx, name, std::slice::from_ref(value));
    }
}

/// How an array is laid out over up to [`MAX_CHUNKS`] bindings (fewer for some arrays, see
/// [`chunk_names`]): as many elements in each binding as fit, the last one holding the rest.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ChunkLayout {
    /// Elements per chunk; 0 when the array fits one binding (the kernels' <NAME>_PER_CHUNK).
    pub per_chunk: u64,
    /// Number of bindings in use.
    pub chunks: u32,
}

/// Most bindings an array may be split into (`name`, `name_1`, `name_2`, `name_3` in WGSL).
pub const MAX_CHUNKS: u64 = 4;

impl ChunkLayout {
    /// Layout of `count` elements of `element_size` bytes with at most `limit` bytes per binding.
    pub fn new(name: &str, count: u64, element_size: u64, limit: u64) -> Result<Self> {
        if count * element_size <= limit {
            return Ok(Self { per_chunk: 0, chunks: 1 });
        }
        let per_chunk = (limit / element_size).min(u32::MAX as u64);
        let chunks = if per_chunk == 0 { u64::MAX } else { count.div_ceil(per_chunk) };
        let most = split_array_names(name).map_or(MAX_CHUNKS, |names| names.len() as u64);
        if chunks > most {
            bail!(
                "`{name}` needs {:.1} MiB, more than {most} bindings of {:.1} MiB allow on this device; \
                 reduce its size (the film: resolution and bins; scene arrays: triangle count)",
                (count * element_size) as f64 / 1048576.0,
                limit as f64 / 1048576.0
            );
        }
        Ok(Self { per_chunk, chunks: chunks as u32 })
    }

    /// Element range of chunk `c` for an array of `count` elements.
    pub fn range(&self, c: u32, count: u64) -> std::ops::Range<u64> {
        if self.per_chunk == 0 {
            return 0..count;
        }
        let size = self.per_chunk;
        (c as u64 * size).min(count)..((c as u64 + 1) * size).min(count)
    }
}

/// Bytes of the buffer [`Resources::storage_init`] makes of `data`: its bytes, padded to at least
/// 16 and one element (so a host that rewrites the buffer later compares against this size).
pub fn storage_init_bytes<T: bytemuck::Pod>(data: &[T]) -> u64 {
    size_of_val(data).max(16).max(size_of::<T>()) as u64
}

/// WGSL names of the chunks of array `name` (bindings.wesl): four for most arrays, three for
/// the binary BVH's (the ellipsoidal connections bind both BVHs, and a kernel may bind at most
/// 32 storage buffers).
pub fn chunk_names(name: &str) -> &'static [&'static str] {
    split_array_names(name).unwrap_or_else(|| panic!("`{name}` is not a split array"))
}

/// [`chunk_names`], or None for a name that is not a split array.
fn split_array_names(name: &str) -> Option<&'static [&'static str]> {
    Some(match name {
        "triangles" => &["triangles", "triangles_1", "triangles_2", "triangles_3"],
        "triangle_shading" => &["triangle_shading", "triangle_shading_1", "triangle_shading_2", "triangle_shading_3"],
        "bvh_nodes" => &["bvh_nodes", "bvh_nodes_1", "bvh_nodes_2"],
        "bvh_node_surfaces" => &["bvh_node_surfaces", "bvh_node_surfaces_1", "bvh_node_surfaces_2"],
        "film" => &["film", "film_1", "film_2", "film_3"],
        "band_entries" => &["band_entries", "band_entries_1", "band_entries_2", "band_entries_3"],
        _ => return None,
    })
}

impl Resources {
    /// Creates split storage array `name` holding `data`, at most `limit` bytes per binding;
    /// unused chunks get a tiny placeholder buffer.
    pub fn storage_chunked_init<T: bytemuck::Pod>(
        &mut self,
        ctx: &GpuContext,
        name: &'static str,
        data: &[T],
        limit: u64,
    ) -> Result<ChunkLayout> {
        let layout = ChunkLayout::new(name, data.len() as u64, size_of::<T>() as u64, limit)?;
        for (c, &chunk_name) in chunk_names(name).iter().enumerate() {
            let r = layout.range(c as u32, data.len() as u64);
            self.storage_init(ctx, chunk_name, &data[r.start as usize..r.end as usize])?;
        }
        Ok(layout)
    }

    /// Creates zeroed split storage array `name` of `count` elements of `element_size` bytes.
    pub fn storage_chunked_zeroed(
        &mut self,
        ctx: &GpuContext,
        name: &'static str,
        count: u64,
        element_size: u64,
        limit: u64,
    ) -> Result<ChunkLayout> {
        let layout = ChunkLayout::new(name, count, element_size, limit)?;
        for (c, &chunk_name) in chunk_names(name).iter().enumerate() {
            let r = layout.range(c as u32, count);
            self.storage_zeroed(ctx, chunk_name, (r.end - r.start) * element_size, wgpu::BufferUsages::empty())?;
        }
        Ok(layout)
    }

    /// Reads split array `name` of `count` elements back to the host.
    pub fn read_chunked<T: bytemuck::Pod>(
        &self,
        ctx: &GpuContext,
        name: &'static str,
        layout: ChunkLayout,
        count: u64,
    ) -> Result<Vec<T>> {
        let mut out = Vec::with_capacity(count as usize);
        for c in 0..layout.chunks {
            let r = layout.range(c, count);
            out.extend(read_buffer::<T>(
                ctx,
                &self.buffers[chunk_names(name)[c as usize]],
                (r.end - r.start) as usize,
            )?);
        }
        Ok(out)
    }

    /// Writes `data` over split array `name` (as many elements as it was created with).
    pub fn write_chunked<T: bytemuck::Pod>(
        &self,
        ctx: &GpuContext,
        name: &'static str,
        layout: ChunkLayout,
        data: &[T],
    ) {
        for c in 0..layout.chunks {
            let r = layout.range(c, data.len() as u64);
            let bytes = bytemuck::cast_slice(&data[r.start as usize..r.end as usize]);
            ctx.queue.write_buffer(&self.buffers[chunk_names(name)[c as usize]], 0, bytes);
        }
    }

    /// Zeroes every chunk of split array `name`.
    pub fn clear_chunked(&self, encoder: &mut wgpu::CommandEncoder, name: &'static str) {
        for chunk_name in chunk_names(name) {
            encoder.clear_buffer(&self.buffers[chunk_name], 0, None);
        }
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
    let staging = ctx.allocate("readback", size, || {
        ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    })?;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunk_layouts_cover_the_array_in_full_chunks() {
        assert_eq!(ChunkLayout::new("a", 10, 4, 40).unwrap(), ChunkLayout { per_chunk: 0, chunks: 1 });
        let l = ChunkLayout::new("a", 60, 48, 1000).unwrap();
        assert_eq!(l, ChunkLayout { per_chunk: 20, chunks: 3 }, "20 fit a binding");
        let covered: Vec<u64> = (0..l.chunks).flat_map(|c| l.range(c, 60)).collect();
        assert_eq!(covered, (0..60).collect::<Vec<_>>());
        assert!(ChunkLayout::new("a", 1000, 48, 1000).is_err(), "more than four chunks");
        assert!(ChunkLayout::new("a", 3, 48, 40).is_err(), "an element larger than a binding");
        // The binary BVH's arrays take three chunks at most (its kernels' binding count).
        assert_eq!(ChunkLayout::new("bvh_nodes", 48, 32, 512).unwrap(), ChunkLayout { per_chunk: 16, chunks: 3 });
        assert!(ChunkLayout::new("bvh_nodes", 49, 32, 512).is_err(), "more than three chunks");
    }
}

/// Buffers that every tracer of one scene on a device reads and none writes (the scene's
/// arrays), with the layouts of the split ones by name: made once per device and key, then
/// bound by each tracer (`integrator::upload::scene_buffers`).
pub struct SharedBuffers {
    /// The buffers, under their WGSL names.
    pub resources: Resources,
    /// The chunk layout of each split array among them.
    pub layouts: HashMap<&'static str, ChunkLayout>,
}

/// The [`SharedBuffers`] a device made last and the key they were made for. One entry: a render's
/// tracers (pilots, halves, the render itself) and later renders of the same scene share it,
/// and another scene's buffers replace it.
#[derive(Default)]
pub struct SharedBufferCache {
    last: Mutex<Option<([u64; 3], Arc<SharedBuffers>)>>,
}

impl SharedBufferCache {
    /// The buffers made for `key`: the last ones where they were made for it, else `make`'s,
    /// which then replace them.
    pub fn get_or_make(
        &self,
        key: [u64; 3],
        make: impl FnOnce() -> Result<SharedBuffers>,
    ) -> Result<Arc<SharedBuffers>> {
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((made_for, buffers)) = last.as_ref()
            && *made_for == key
        {
            return Ok(buffers.clone());
        }
        // The previous buffers go first, so that a device never holds two scenes for the cache
        // (tracers still rendering that scene keep their own handles to its buffers).
        *last = None;
        let buffers = Arc::new(make()?);
        *last = Some((key, buffers.clone()));
        Ok(buffers)
    }
}
