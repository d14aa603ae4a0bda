//! The band index of an NLOS capture (shaders/lib/band_index.wesl): per pixel and per bin of
//! a transient gate, the clusters of the BVH (subtrees of at most [`CLUSTER_NODES`] nodes)
//! whose triangles reach into the bin's shell of three-bounce path lengths, each with its mass
//! there (the area of its triangles' strips, each weighted by the contribution per unit area
//! at its centroid). `ellipsoidal`'s connections between a pixel's laser spot and its sensed
//! point then become shell connections: a cluster of the bin drawn in proportion to the masses,
//! a triangle of it in proportion to its own, and a point of its strip whose path length lies
//! in the bin, estimating the bin's whole integral, so that the target length is integrated
//! over the bin rather than drawn. The masses also share out each pixel's visits to its bins
//! (instead of a pilot render). On a 327,680-triangle hidden sphere (4 ps bins, 10 s) the error
//! at equal time fell 2,400-fold against the stochastic descent (README, NLOS captures).
//!
//! Built on the device in two passes over the clusters, batched so that no invocation's loops
//! run past lavapipe's 65,535 iterations: `count_band_entries` counts each pixel's entries per
//! bin, the host turns the counts into offsets, and `fill_band_entries` writes the entries with
//! cumulative masses. One invocation walks one pixel's clusters in order, so the index, and the
//! render, are the same bits in every run.

use anyhow::Result;
use glam::Vec3;

use crate::gpu::layout::{BvhNode, RenderParams, Triangle};
use crate::scene::PreparedScene;
use crate::gpu::resources::{MAX_CHUNKS, chunk_names, read_buffer};
use crate::gpu::{GpuContext, Kernel, Resources};

/// Most nodes of a cluster's subtree (31: at most 16 leaves of up to 4 triangles).
pub const CLUSTER_NODES: u32 = 31;

/// Loop iterations one invocation of a build pass may spend on one batch of clusters (bounded
/// from the clusters' sizes, well below lavapipe's 65,535, after which it ends an invocation's
/// loops). A cluster whose bound alone exceeds it (large triangles over fine bins) leaves the
/// capture without an index.
const BATCH_ITERATIONS: u64 = 48_000;

/// Strata the fill pass sums per walk over a cluster's triangles (band_index.wesl BAND_WINDOW).
const WINDOW: u64 = 64;

/// Names of the index's buffers (bindings.wesl).
const BUFFERS: [&str; 10] = [
    "band_clusters",
    "band_offsets",
    "band_entries",
    "band_entries_1",
    "band_entries_2",
    "band_entries_3",
    "band_cursors",
    "band_sums",
    "band_build",
    "band_ranges",
];

/// log2 of the entries per chunk of band_entries for bindings of at most `limit` bytes (the
/// specialisation constant BAND_ENTRIES_CHUNK_BITS, fixed before the index's size is known).
pub fn entries_chunk_bits(limit: u64) -> u32 {
    (63 - (limit / 8).max(1).leading_zeros()).min(30)
}

/// The clusters of a BVH: the largest subtrees of at most `max_nodes` nodes, in node order, as
/// (root, node after the subtree, first triangle, end of its triangles). They partition the
/// leaves, and a subtree's triangles are contiguous (leaves address them in depth-first order).
pub fn clusters(nodes: &[BvhNode], max_nodes: u32) -> Vec<[u32; 4]> {
    let mut out = Vec::new();
    let mut i = 0u32;
    while (i as usize) < nodes.len() {
        let skip = nodes[i as usize].skip;
        if skip - i > max_nodes && nodes[i as usize].leaf == 0 {
            i += 1;
            continue;
        }
        let (mut first, mut end) = (u32::MAX, 0);
        for node in &nodes[i as usize..skip as usize] {
            if let Some(range) = node.leaf_range() {
                first = first.min(range.start);
                end = end.max(range.end);
            }
        }
        out.push([i, skip, first, end]);
        i = skip;
    }
    out
}

/// Why a capture renders without its band index, or None when the index fits.
pub fn unfit(params: &RenderParams, limit: u64) -> Option<String> {
    let cells = params.width as u64 * params.height as u64 * params.target_length.strata as u64;
    (params.target_length.strata == 0).then(|| "the gate is not a transient one".to_owned()).or_else(|| {
        ((cells + 1) * 4 > limit).then(|| format!("{cells} pixel bins need more than one binding of {limit} bytes"))
    })
}

/// Creates 16-byte stand-ins for the index's buffers, which connect_ellipsoidal binds even when
/// it does not use them.
pub fn placeholders(ctx: &GpuContext, r: &mut Resources) -> Result<()> {
    for name in BUFFERS {
        if name == "band_build" {
            r.uniform_init(ctx, name, &[0u32; 8]);
        } else {
            r.storage_zeroed(ctx, name, 16, wgpu::BufferUsages::empty())?;
        }
    }
    Ok(())
}

/// What a built index holds, for the render's metadata.
#[derive(Clone, Copy, Debug, Default)]
pub struct BandIndexSummary {
    /// Clusters of the BVH.
    pub clusters: usize,
    /// Entries over every pixel and bin.
    pub entries: u64,
    /// Dispatches of the two passes.
    pub batches: usize,
    /// Wall-clock seconds the build took.
    pub seconds: f64,
}

/// The band index's build kernels and batches, bound to one capture.
pub struct BandIndex {
    count: Kernel,
    fill: Kernel,
    /// (first cluster, clusters, first stratum, end of strata) of each dispatch of the count
    /// and fill passes.
    count_batches: Vec<[u32; 4]>,
    fill_batches: Vec<[u32; 4]>,
    clusters: usize,
    /// Why the capture goes without the index, found before building it.
    refused: Option<String>,
    /// band_ranges holds every pixel's clusters' strata (else the fill pass recomputes them).
    ranges: bool,
}

impl BandIndex {
    /// Creates the index's buffers (the offsets and entries as stand-ins until `build`) and its
    /// kernels, and batches the clusters of the scene's BVH for the bins of `params` (whose gate
    /// must be stratified and fit bindings of `limit` bytes, see [`unfit`]).
    pub fn new(
        ctx: &GpuContext,
        r: &mut Resources,
        scene: &PreparedScene,
        params: &RenderParams,
        constants: &[(&'static str, f64)],
        limit: u64,
    ) -> Result<Self> {
        let clusters = clusters(&scene.bvh.nodes, CLUSTER_NODES);
        let cells = params.width as u64 * params.height as u64 * params.target_length.strata as u64;
        placeholders(ctx, r)?;
        r.storage_init(ctx, "band_clusters", &clusters)?;
        r.storage_zeroed(ctx, "band_cursors", cells * 4, wgpu::BufferUsages::empty())?;
        r.storage_zeroed(ctx, "band_sums", cells * 4, wgpu::BufferUsages::empty())?;
        let range_bytes = params.width as u64 * params.height as u64 * clusters.len() as u64 * 4;
        let ranges = params.target_length.strata <= u16::MAX as u32 && range_bytes <= limit;
        if ranges {
            r.storage_zeroed(ctx, "band_ranges", range_bytes, wgpu::BufferUsages::empty())?;
        }
        let width = params.gate.p1 as f64;
        let strata = params.target_length.strata;
        let mut refused = (clusters.len() < 2)
            .then(|| "the BVH is one cluster, which every query searches whole anyway".to_owned());
        // Count batches: whole clusters. Fill batches: whole clusters, or one cluster over a range
        // of strata where filling it whole would take one invocation past the budget.
        let (mut count_batches, mut fill_batches) = (Vec::new(), Vec::new());
        let (mut count_first, mut count_spent) = (0u32, 0u64);
        let (mut fill_first, mut fill_spent) = (0u32, 0u64);
        for (c, cluster) in clusters.iter().enumerate() {
            let c = c as u32;
            let cost = cluster_cost(&scene.bvh.nodes, &scene.triangles, cluster, width);
            if count_spent + cost.count > BATCH_ITERATIONS && c > count_first {
                count_batches.push([count_first, c - count_first, 0, strata]);
                (count_first, count_spent) = (c, 0);
            }
            count_spent += cost.count;
            if cost.count > BATCH_ITERATIONS || cost.per_window + cost.range > BATCH_ITERATIONS {
                refused.get_or_insert_with(|| {
                    format!(
                        "cluster {c} ({} triangles) would take more loop iterations to index at these bins than one \
                         invocation may run",
                        cluster[3] - cluster[2]
                    )
                });
            }
            if cost.whole() <= BATCH_ITERATIONS {
                if fill_spent + cost.whole() > BATCH_ITERATIONS && c > fill_first {
                    fill_batches.push([fill_first, c - fill_first, 0, strata]);
                    (fill_first, fill_spent) = (c, 0);
                }
                fill_spent += cost.whole();
                continue;
            }
            // Too costly whole: the batch so far, then this cluster over ranges of strata, each of
            // `per` windows (split dispatches align windows to multiples of WINDOW).
            if c > fill_first {
                fill_batches.push([fill_first, c - fill_first, 0, strata]);
            }
            let per = (BATCH_ITERATIONS.saturating_sub(cost.range) / cost.per_window.max(1)).max(1) as u32;
            let step = per * WINDOW as u32;
            let mut lo = 0;
            while lo < strata {
                fill_batches.push([c, 1, lo, (lo + step).min(strata)]);
                lo += step;
            }
            (fill_first, fill_spent) = (c + 1, 0);
        }
        if count_first < clusters.len() as u32 {
            count_batches.push([count_first, clusters.len() as u32 - count_first, 0, strata]);
        }
        if fill_first < clusters.len() as u32 {
            fill_batches.push([fill_first, clusters.len() as u32 - fill_first, 0, strata]);
        }
        let mut constants = constants.to_vec();
        constants.push(("BAND_INDEX", 1.0));
        Ok(Self {
            count: Kernel::new(ctx, "count_band_entries", None, &constants),
            fill: Kernel::new(ctx, "fill_band_entries", None, &constants),
            count_batches,
            fill_batches,
            clusters: clusters.len(),
            refused,
            ranges,
        })
    }

    /// Builds the index for the capture of `params` into `r`'s buffers: its figures when it was
    /// built (then `params.target_length.band_index` is 1 and the caller must bind its kernels
    /// to the new band_offsets and band_entries), or why the capture goes without it (the
    /// entries do not fit MAX_CHUNKS bindings of `limit` bytes).
    pub fn build(
        &self,
        ctx: &GpuContext,
        r: &mut Resources,
        params: &mut RenderParams,
        limit: u64,
    ) -> Result<std::result::Result<BandIndexSummary, String>> {
        if let Some(why) = &self.refused {
            return Ok(Err(why.clone()));
        }
        let start = std::time::Instant::now();
        let pixels = params.width * params.height;
        let cells = pixels as usize * params.target_length.strata as usize;
        let clear = |r: &Resources| {
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            encoder.clear_buffer(r.get("band_cursors").unwrap(), 0, None);
            encoder.clear_buffer(r.get("band_sums").unwrap(), 0, None);
            ctx.queue.submit([encoder.finish()]);
        };
        // One submission per pass: every batch binds its own copy of band_build.
        let run = |kernel: &Kernel, batches: &[[u32; 4]], r: &Resources| {
            let groups: Vec<wgpu::BindGroup> = batches
                .iter()
                .map(|&[first, count, lo, hi]| {
                    let mut batch = r.clone();
                    batch.uniform_init(ctx, "band_build", &[[first, count, self.ranges as u32, 0], [lo, hi, 0, 0]]);
                    kernel.bind(ctx, &batch)
                })
                .collect();
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                for group in &groups {
                    kernel.dispatch(&mut pass, group, pixels);
                }
            }
            ctx.queue.submit([encoder.finish()]);
        };
        clear(r);
        run(&self.count, &self.count_batches, r);
        ctx.wait_idle()?;
        let counts: Vec<u32> = read_buffer(ctx, r.get("band_cursors").unwrap(), cells)?;
        let mut offsets = Vec::with_capacity(cells + 1);
        let mut total = 0u64;
        for &n in &counts {
            offsets.push(total as u32);
            total += n as u64;
        }
        offsets.push(total as u32);
        let per_chunk = 1u64 << entries_chunk_bits(limit);
        if total > MAX_CHUNKS * per_chunk {
            return Ok(Err(format!(
                "its {total} entries need more than {MAX_CHUNKS} bindings of {} bytes",
                per_chunk * 8
            )));
        }
        r.storage_init(ctx, "band_offsets", &offsets)?;
        // The fill pass writes each bin's entries from its offset on.
        ctx.queue.write_buffer(r.get("band_cursors").unwrap(), 0, bytemuck::cast_slice(&offsets[..cells]));
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        encoder.clear_buffer(r.get("band_sums").unwrap(), 0, None);
        ctx.queue.submit([encoder.finish()]);
        for (c, name) in chunk_names("band_entries").into_iter().enumerate() {
            let entries = total.saturating_sub(c as u64 * per_chunk).min(per_chunk);
            r.storage_zeroed(ctx, name, entries.max(2) * 8, wgpu::BufferUsages::empty())?;
        }
        run(&self.fill, &self.fill_batches, r);
        ctx.wait_idle()?;
        // Every bin's cursor must have reached the next bin's offset: a device that cut an
        // invocation's loops short would leave entries unwritten, and the index biased.
        let cursors: Vec<u32> = read_buffer(ctx, r.get("band_cursors").unwrap(), cells)?;
        if let Some(k) = (0..cells).find(|&k| cursors[k] != offsets[k + 1]) {
            return Ok(Err(format!(
                "the device cut its build short (pixel {}, bin {}: {} of {} entries written)",
                k / params.target_length.strata as usize,
                k % params.target_length.strata as usize,
                cursors[k] - offsets[k],
                offsets[k + 1] - offsets[k]
            )));
        }
        params.target_length.band_index = 1;
        ctx.queue.write_buffer(r.get("params").unwrap(), 0, bytemuck::bytes_of(params));
        Ok(Ok(BandIndexSummary {
            clusters: self.clusters,
            entries: total,
            batches: self.count_batches.len() + self.fill_batches.len(),
            seconds: start.elapsed().as_secs_f64(),
        }))
    }
}

/// Longest edge (m) of the pieces a triangle's mass is modelled in, and most pieces per edge
/// (band_index.wesl BAND_PIECE, BAND_MAX_PIECES).
const PIECE: f32 = 0.02;
const MAX_PIECES: u32 = 8;

/// Pieces per edge of a triangle of longest edge `longest` (band_index.wesl `band_pieces`),
/// rounded up where f32 rounding could make the device's count one more.
fn pieces(longest: f32) -> u64 {
    (longest * (1.0 + 1e-5) / PIECE).ceil().clamp(1.0, MAX_PIECES as f32) as u64
}

/// Bounds on the loop iterations one invocation spends on a cluster, with bins `width` metres
/// wide (|grad L| <= 2, so a cluster's path lengths span at most 2 x its box diagonal and a
/// piece's at most 2 x its longest edge).
struct ClusterCost {
    /// The count pass: the triangles' walk for the range, then the range's bins.
    count: u64,
    /// The fill pass's range (a walk of the triangles where band_ranges is not kept).
    range: u64,
    /// The fill pass per window of WINDOW strata: every triangle's pieces, their bins in the
    /// window, the window's writes.
    per_window: u64,
    /// Windows the cluster's range may span.
    windows: u64,
}

impl ClusterCost {
    /// The fill pass over the whole cluster.
    fn whole(&self) -> u64 {
        self.range + self.windows * self.per_window
    }
}

fn cluster_cost(nodes: &[BvhNode], triangles: &[Triangle], cluster: &[u32; 4], width: f64) -> ClusterCost {
    let root = &nodes[cluster[0] as usize];
    let bins = |length: f64| (2.0 * length / width).ceil().min(1e12) as u64 + 3;
    let span = bins((root.max - root.min).length() as f64);
    let count = (cluster[3] - cluster[2]) as u64;
    let per_window: u64 = (cluster[2]..cluster[3])
        .map(|t| {
            let tri = &triangles[t as usize];
            let longest = tri.e1.length().max(tri.e2.length()).max((tri.e2 - tri.e1).length());
            let k = pieces(longest);
            2 + k + 2 * k * k * (1 + bins(longest as f64 / k as f64).min(WINDOW))
        })
        .sum();
    ClusterCost {
        count: 2 * count + span + 2,
        range: 2 * count + 2,
        per_window: per_window + 2 * WINDOW + 2,
        windows: span.div_ceil(WINDOW) + 1,
    }
}

/// F(x): the share of a triangle's area where the linear function with sorted vertex values
/// a <= b <= c is below x (the tent distribution; twin of band_index.wesl `tent_cdf`).
pub fn tent_cdf(a: f32, b: f32, c: f32, x: f32) -> f32 {
    if x <= a {
        0.0
    } else if x >= c {
        1.0
    } else if x < b {
        (x - a) * (x - a) / ((c - a) * (b - a))
    } else {
        1.0 - (c - x) * (c - x) / ((c - a) * (c - b))
    }
}

/// A point uniform on the strip lo <= L_int < hi of triangle `v`, L_int the linear function of
/// values `l` at its vertices (twin of band_index.wesl `strip_point`): L_int = x from u1 by
/// inverting the tent over [lo, hi), then the point at u2 along the segment L_int = x.
pub fn strip_point(v: [Vec3; 3], l: [f32; 3], lo: f32, hi: f32, u1: f32, u2: f32) -> Vec3 {
    let (mut pa, mut pb, mut pc) = (v[0], v[1], v[2]);
    let (mut a, mut b, mut c) = (l[0], l[1], l[2]);
    if b < a {
        (pa, pb, a, b) = (pb, pa, b, a);
    }
    if c < b {
        (pb, pc, b, c) = (pc, pb, c, b);
    }
    if b < a {
        (pa, pb, a, b) = (pb, pa, b, a);
    }
    if !(c > a) {
        let r = u1.sqrt();
        return pa + r * (1.0 - u2) * (pb - pa) + r * u2 * (pc - pa);
    }
    let f0 = tent_cdf(a, b, c, lo);
    let f = f0 + u1 * (tent_cdf(a, b, c, hi) - f0);
    let x = if b > a && f * (c - a) <= b - a {
        a + (f * (c - a) * (b - a)).sqrt()
    } else {
        c - ((1.0 - f).max(0.0) * (c - a) * (c - b)).sqrt()
    }
    .clamp(lo, hi);
    let p = pa.lerp(pc, ((x - a) / (c - a)).clamp(0.0, 1.0));
    let q = if x < b && b > a {
        pa.lerp(pb, ((x - a) / (b - a)).clamp(0.0, 1.0))
    } else if c > b {
        pb.lerp(pc, ((x - b) / (c - b)).clamp(0.0, 1.0))
    } else {
        pb
    };
    p.lerp(q, u2)
}

/// eps of a piece `v` (band_index.wesl `band_piece_range`, without its f32 margin): an upper
/// bound of L_int - L over the triangle, L(x) = |x - spot| + |x - sensed| and L_int its linear
/// interpolant from the vertices. L is convex with curvature at most K = 1/d_s + 1/d_c (d lower
/// bounds of the distances to the foci), so L_int - L <= K/2 max sum_i lambda_i |x - v_i|^2 <=
/// K e^2 / 6 (e the longest edge; the sum is sum_{i<j} lambda_i lambda_j |v_i - v_j|^2).
pub fn interpolation_bound(v: [Vec3; 3], spot: Vec3, sensed: Vec3) -> f32 {
    let centroid = (v[0] + v[1] + v[2]) / 3.0;
    let (ds, dc) = (centroid.distance(spot), centroid.distance(sensed));
    let reach = v.iter().map(|p| p.distance_squared(centroid)).fold(0.0f32, f32::max).sqrt();
    let longest2 = v[0].distance_squared(v[1]).max(v[0].distance_squared(v[2])).max(v[1].distance_squared(v[2]));
    let curvature = 1.0 / (ds - reach).max(1e-4 * ds) + 1.0 / (dc - reach).max(1e-4 * dc);
    curvature * longest2 / 6.0
}
