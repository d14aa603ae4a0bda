//! The band index of an NLOS capture (shaders/lib/band_index.wesl): per pixel and per bin of
//! a transient gate, the clusters of the BVH (subtrees of at most [`cluster_nodes`] nodes)
//! whose triangles reach into the bin's shell of three-bounce path lengths, each with its mass
//! there (the area of its triangles' strips, each weighted by the contribution per unit area
//! at its centroid). `ellipsoidal`'s connections between a pixel's laser spot and its sensed
//! point then become shell connections: a cluster of the bin drawn in proportion to the masses,
//! a triangle of it in proportion to its own, and a point of its strip whose path length lies
//! in the bin, estimating the bin's whole integral, so that the target length is integrated
//! over the bin rather than drawn. The masses also share out each pixel's visits to its bins
//! (instead of a pilot render). On a 327,680-triangle hidden sphere (4 ps bins, 10 s) the error
//! at equal time fell 2,400-fold against the stochastic descent (docs/nlos.md, "Shell connections
//! from the band index").
//!
//! Built on the device in two passes over the clusters, batched so that no invocation's loops
//! run past lavapipe's 65,535 iterations: `count_band_entries` counts each pixel's entries per
//! bin, the host turns the counts into offsets, and `fill_band_entries` writes the entries with
//! cumulative masses. One invocation walks one pixel's clusters in order, so the index, and the
//! render, are the same bits in every run.

use anyhow::Result;
use glam::Vec3;

use crate::gpu::layout::{BvhNode, RenderParams, Triangle};
use crate::gpu::resources::{MAX_CHUNKS, chunk_names, read_buffer};
use crate::gpu::{GpuContext, Kernel, Resources};
use crate::scene::PreparedScene;

/// `render --band-index auto` builds the index for scenes of more triangles than this besides
/// the relay wall: a smaller hidden scene takes the queries, which search it whole, exactly. On
/// flat letters facing the wall (the example's 8 triangles, `nlos_z.xml`'s 6) the queries had
/// less error than shell connections (1/100 at 1 ps on the letter, 1/82 on the Z at 4 ps; 10 s
/// captures); on the staircases of 20 and 60 triangles (`nlos_staircase.xml`,
/// `nlos_staircase_boxes.xml`, 4 ps) shell connections had 0.76 and 0.61 of the queries' error
/// (docs/nlos.md, "Across hidden scenes"). The capture cuts the triangles of such small scenes
/// into pieces for the index (`crate::nlos::prepare_for_shells`), so that they make clusters.
pub const AUTO_MIN_TRIANGLES: usize = 16;

/// Most nodes of a cluster's subtree in scenes of more than SMALL_CLUSTERS_UP_TO triangles (31:
/// at most 16 leaves of up to `crate::bvh::leaf_triangles` triangles).
pub const CLUSTER_NODES: u32 = 31;

/// Most nodes of a cluster's subtree in scenes of at most SMALL_CLUSTERS_UP_TO triangles (7: at
/// most 4 leaves, 16 triangles). A shell connection weighs every triangle of its cluster, so
/// smaller clusters cost less per sample, while the index holds more entries and takes longer
/// to build. 3 s captures (confocal 16x16, 4 ps bins) had 0.77, 0.79 and 0.84 of the error with
/// 31-node clusters on the panels, the staircase and the boxes (5,976 to 28,266 triangles once
/// prepared), but the 327,680-triangle sphere's 34,545 clusters took 2.6 s to index where 9,734
/// took 2.0 s, and a 3 s capture then had 28 times the error (docs/nlos.md, "Across hidden
/// scenes").
pub const SMALL_CLUSTER_NODES: u32 = 7;

/// Scenes of at most this many triangles (the relay wall's and the pieces' included) make
/// clusters of SMALL_CLUSTER_NODES nodes.
pub const SMALL_CLUSTERS_UP_TO: usize = 65_536;

/// Most nodes of a cluster's subtree for a prepared scene of `triangles` triangles.
pub fn cluster_nodes(triangles: usize) -> u32 {
    if triangles <= SMALL_CLUSTERS_UP_TO { SMALL_CLUSTER_NODES } else { CLUSTER_NODES }
}

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
    /// Entries over every pixel and index bin.
    pub entries: u64,
    /// Strata of the gate per index bin.
    pub ratio: u32,
    /// Dispatches of the two passes.
    pub batches: usize,
    /// Wall-clock seconds the build took.
    pub seconds: f64,
}

impl BandIndexSummary {
    /// The figures in words, for the render's metadata.
    pub fn describe(&self) -> String {
        format!(
            "{} clusters, {} entries over bins of {} strata, built in {:.2} s ({} dispatches)",
            self.clusters, self.entries, self.ratio, self.seconds, self.batches
        )
    }
}

/// Why a capture goes without its band index.
#[derive(Clone, Debug)]
pub enum BuildStop {
    /// The index does not fit this capture (its loops, its entries' bindings, the device).
    Unfit(String),
    /// Its build would outlast the render's time budget: a longer render may build it.
    OutOfTime(String),
}

impl BuildStop {
    /// Why, in words.
    pub fn why(&self) -> &str {
        match self {
            BuildStop::Unfit(why) | BuildStop::OutOfTime(why) => why,
        }
    }
}

/// The band index's build kernels and clusters, bound to one capture.
pub struct BandIndex {
    count: Kernel,
    fill: Kernel,
    /// The clusters' loop bounds at one stratum per index bin, in cluster order.
    costs: Vec<ClusterCost>,
    clusters: usize,
    /// Why the capture goes without the index, found before building it.
    refused: Option<String>,
}

/// (first cluster, clusters, first index bin, end of index bins) of each dispatch of a pass.
type Batches = Vec<[u32; 4]>;

impl BandIndex {
    /// Creates the index's buffers (the offsets and entries as stand-ins until `build`) and its
    /// kernels for the clusters of the scene's BVH and the bins of `params` (whose gate must be
    /// stratified and fit bindings of `limit` bytes, see [`unfit`]).
    pub fn new(
        ctx: &GpuContext,
        r: &mut Resources,
        scene: &PreparedScene,
        params: &RenderParams,
        constants: &[(&'static str, f64)],
        limit: u64,
    ) -> Result<Self> {
        let clusters = clusters(&scene.bvh.nodes, cluster_nodes(scene.triangles.len()));
        let cells = params.width as u64 * params.height as u64 * params.target_length.strata as u64;
        placeholders(ctx, r)?;
        r.storage_init(ctx, "band_clusters", &clusters)?;
        r.storage_zeroed(ctx, "band_cursors", cells * 4, wgpu::BufferUsages::empty())?;
        r.storage_zeroed(ctx, "band_sums", cells * 4, wgpu::BufferUsages::empty())?;
        let range_bytes = params.width as u64 * params.height as u64 * clusters.len() as u64 * 4;
        // band_ranges holds every pixel's clusters' index bins where it fits (BAND_RANGES; else
        // the fill pass works them out again).
        let ranges = params.target_length.strata <= u16::MAX as u32 && range_bytes <= limit;
        if ranges {
            r.storage_zeroed(ctx, "band_ranges", range_bytes, wgpu::BufferUsages::empty())?;
        }
        let width = params.gate.p1 as f64;
        let refused =
            (clusters.len() < 2).then(|| "the BVH is one cluster, which every query searches whole anyway".to_owned());
        let costs = clusters.iter().map(|c| cluster_cost(&scene.bvh.nodes, &scene.triangles, c, width)).collect();
        let mut constants = constants.to_vec();
        constants.push(("BAND_INDEX", 1.0));
        constants.push(("BAND_RANGES", ranges as u32 as f64));
        Ok(Self {
            count: Kernel::new(ctx, "count_band_entries", None, &constants),
            fill: Kernel::new(ctx, "fill_band_entries", None, &constants),
            costs,
            clusters: clusters.len(),
            refused,
        })
    }

    /// The count and fill passes' dispatches for index bins of `ratio` strata (of `strata`),
    /// or why a cluster cannot be indexed at them: count batches hold whole clusters; fill
    /// batches whole clusters, or one cluster over a range of bins where filling it whole would
    /// take one invocation past the budget.
    fn batches(&self, ratio: u32, strata: u32) -> std::result::Result<(Batches, Batches), String> {
        let bins = strata.div_ceil(ratio);
        let (mut count_batches, mut fill_batches) = (Vec::new(), Vec::new());
        let (mut count_first, mut count_spent) = (0u32, 0u64);
        let (mut fill_first, mut fill_spent) = (0u32, 0u64);
        for (c, cost) in self.costs.iter().enumerate() {
            let c = c as u32;
            let cost = cost.at_ratio(ratio);
            if count_spent + cost.count > BATCH_ITERATIONS && c > count_first {
                count_batches.push([count_first, c - count_first, 0, bins]);
                (count_first, count_spent) = (c, 0);
            }
            count_spent += cost.count;
            if cost.count > BATCH_ITERATIONS || cost.range + 1 + cost.per_window + cost.triangle_bins > BATCH_ITERATIONS
            {
                return Err(format!(
                    "cluster {c} would take more loop iterations to index at these bins than one invocation may run"
                ));
            }
            if cost.whole() <= BATCH_ITERATIONS {
                if fill_spent + cost.whole() > BATCH_ITERATIONS && c > fill_first {
                    fill_batches.push([fill_first, c - fill_first, 0, bins]);
                    (fill_first, fill_spent) = (c, 0);
                }
                fill_spent += cost.whole();
                continue;
            }
            // Too costly whole: the batch so far, then this cluster over ranges of bins, each of
            // `per` windows (split dispatches align windows to multiples of WINDOW).
            if c > fill_first {
                fill_batches.push([fill_first, c - fill_first, 0, bins]);
            }
            let per =
                (BATCH_ITERATIONS.saturating_sub(cost.range + 1 + cost.triangle_bins) / cost.per_window).max(1) as u32;
            let step = per * WINDOW as u32;
            let mut lo = 0;
            while lo < bins {
                fill_batches.push([c, 1, lo, (lo + step).min(bins)]);
                lo += step;
            }
            (fill_first, fill_spent) = (c + 1, 0);
        }
        let n = self.costs.len() as u32;
        if count_first < n {
            count_batches.push([count_first, n - count_first, 0, bins]);
        }
        if fill_first < n {
            fill_batches.push([fill_first, n - fill_first, 0, bins]);
        }
        Ok((count_batches, fill_batches))
    }

    /// Builds the index for the capture of `params` into `r`'s buffers: its figures when it was
    /// built (then `params.target_length.band_index` is its strata per index bin and the caller
    /// must bind its kernels to the new band_offsets and band_entries), or why the capture goes
    /// without it. Index bins are single strata unless their entries would not fit MAX_CHUNKS
    /// bindings of `limit` bytes; then as many strata per bin as make them fit.
    ///
    /// With a time `budget` (s, the render's), the count pass runs a dispatch at a time, and the
    /// build stops where it would not end within the budget (see [`BuildClock`]): a capture that
    /// would spend its whole budget on the index renders without it.
    pub fn build(
        &self,
        ctx: &GpuContext,
        r: &mut Resources,
        params: &mut RenderParams,
        limit: u64,
        budget: Option<f64>,
    ) -> Result<std::result::Result<BandIndexSummary, BuildStop>> {
        if let Some(why) = &self.refused {
            return Ok(Err(BuildStop::Unfit(why.clone())));
        }
        let start = std::time::Instant::now();
        let pixels = params.width * params.height;
        let strata = params.target_length.strata;
        let clear = |r: &Resources| {
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            encoder.clear_buffer(r.get("band_cursors").unwrap(), 0, None);
            encoder.clear_buffer(r.get("band_sums").unwrap(), 0, None);
            ctx.queue.submit([encoder.finish()]);
        };
        // One submission per pass: every batch binds its own copy of band_build.
        let run = |kernel: &Kernel, batches: &[[u32; 4]], ratio: u32, r: &Resources| {
            let groups: Vec<wgpu::BindGroup> = batches
                .iter()
                .map(|&[first, count, lo, hi]| {
                    let mut batch = r.clone();
                    batch.uniform_init(ctx, "band_build", &[[first, count, 0, 0], [lo, hi, ratio, 0]]);
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
        let per_chunk = 1u64 << entries_chunk_bits(limit);
        let capacity = MAX_CHUNKS * per_chunk;
        // Single strata where they fit: a cluster drawn for a wider bin may not reach the
        // stratum at hand, and its weight then varies with how much of the bin it covers (on the
        // 327,680-triangle sphere, 4 strata of 4 ps a bin had 1000x the error of single ones).
        let mut ratio = 1u32;
        let mut dispatches = 0;
        let (cells, offsets, total, fill_batches) = loop {
            let (count_batches, fill_batches) = match self.batches(ratio, strata) {
                Ok(b) => b,
                Err(why) => return Ok(Err(BuildStop::Unfit(why))),
            };
            clear(r);
            match budget {
                None => {
                    run(&self.count, &count_batches, ratio, r);
                    ctx.wait_idle()?;
                }
                Some(budget) => {
                    let costs: Vec<u64> = count_batches
                        .iter()
                        .map(|&[first, n, ..]| {
                            self.costs[first as usize..(first + n) as usize]
                                .iter()
                                .map(|c| c.at_ratio(ratio).count)
                                .sum()
                        })
                        .collect();
                    let mut clock = BuildClock::new(start, budget, costs.iter().sum());
                    for (batch, cost) in count_batches.iter().zip(costs) {
                        run(&self.count, std::slice::from_ref(batch), ratio, r);
                        ctx.wait_idle()?;
                        if let Some(why) = clock.count_done(cost) {
                            return Ok(Err(BuildStop::OutOfTime(why)));
                        }
                    }
                }
            }
            dispatches += count_batches.len();
            let cells = pixels as usize * strata.div_ceil(ratio) as usize;
            let counts: Vec<u32> = read_buffer(ctx, r.get("band_cursors").unwrap(), cells)?;
            let mut offsets = Vec::with_capacity(cells + 1);
            let mut total = 0u64;
            for &n in &counts {
                offsets.push(total as u32);
                total += n as u64;
            }
            offsets.push(total as u32);
            if total <= capacity {
                break (cells, offsets, total, fill_batches);
            }
            // Entries fall about in proportion to the bins' width: more strata per bin.
            let next = ((ratio as f64 * total as f64 / capacity as f64 * 1.25).ceil() as u32).max(ratio + 1);
            if ratio >= strata || total > u32::MAX as u64 {
                return Ok(Err(BuildStop::Unfit(format!(
                    "its {total} entries need more than {MAX_CHUNKS} bindings of {} bytes",
                    per_chunk * 8
                ))));
            }
            ratio = next.min(strata);
        };
        r.storage_init(ctx, "band_offsets", &offsets)?;
        // The fill pass writes each bin's entries from its offset on.
        ctx.queue.write_buffer(r.get("band_cursors").unwrap(), 0, bytemuck::cast_slice(&offsets[..cells]));
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        encoder.clear_buffer(r.get("band_sums").unwrap(), 0, None);
        ctx.queue.submit([encoder.finish()]);
        for (c, name) in chunk_names("band_entries").iter().enumerate() {
            let entries = total.saturating_sub(c as u64 * per_chunk).min(per_chunk);
            r.storage_zeroed(ctx, name, entries.max(2) * 8, wgpu::BufferUsages::empty())?;
        }
        run(&self.fill, &fill_batches, ratio, r);
        dispatches += fill_batches.len();
        ctx.wait_idle()?;
        // Every bin's cursor must have reached the next bin's offset: a device that cut an
        // invocation's loops short would leave entries unwritten, and the index biased.
        let cursors: Vec<u32> = read_buffer(ctx, r.get("band_cursors").unwrap(), cells)?;
        let bins = strata.div_ceil(ratio) as usize;
        if let Some(k) = (0..cells).find(|&k| cursors[k] != offsets[k + 1]) {
            return Ok(Err(BuildStop::Unfit(format!(
                "the device cut its build short (pixel {}, index bin {}: {} of {} entries written)",
                k / bins,
                k % bins,
                cursors[k] - offsets[k],
                offsets[k + 1] - offsets[k]
            ))));
        }
        params.target_length.band_index = ratio;
        ctx.queue.write_buffer(r.get("params").unwrap(), 0, bytemuck::bytes_of(params));
        Ok(Ok(BandIndexSummary {
            clusters: self.clusters,
            entries: total,
            ratio,
            batches: dispatches,
            seconds: start.elapsed().as_secs_f64(),
        }))
    }
}

/// How many times a render's budget the build predicted from its first count dispatch alone must
/// take to be stopped there.
const FIRST_DISPATCH_MARGIN: f64 = 3.0;

/// Whether a build under way ends within a render's time budget. Its fill pass costs about what
/// its count pass does (4.0 s and 3.8 s on the 327,680-triangle sphere, confocal 16 x 16, 1,000
/// bins of 4 ps, on llvmpipe with 2 cores), so a build is predicted at twice its count pass,
/// whose rate is measured past its first dispatch (which may hold the kernel's compilation).
pub struct BuildClock {
    start: std::time::Instant,
    /// The render's time budget (s).
    budget: f64,
    /// The count pass's cost (loop iterations) in all, and done so far.
    total: u64,
    done: u64,
    /// Seconds and cost when the first dispatch ended.
    first: Option<(f64, u64)>,
}

impl BuildClock {
    /// A clock for a build that started at `start`, within `budget` seconds, whose count pass
    /// costs `total` loop iterations.
    pub fn new(start: std::time::Instant, budget: f64, total: u64) -> Self {
        Self { start, budget, total: total.max(1), done: 0, first: None }
    }

    /// Records a count dispatch of `cost` ended now; returns why the build stops where the
    /// build predicted from the count pass's rate ends past the budget.
    pub fn count_done(&mut self, cost: u64) -> Option<String> {
        self.done += cost;
        let now = self.start.elapsed().as_secs_f64();
        let predicted = match self.first {
            None => {
                self.first = Some((now, self.done));
                // The first dispatch's time may hold the kernel's compilation: it stops the
                // build only where its rate predicts FIRST_DISPATCH_MARGIN times the budget.
                let predicted = 2.0 * now * self.total as f64 / self.done as f64;
                (self.done >= self.total || predicted > FIRST_DISPATCH_MARGIN * self.budget).then_some(predicted)?
            }
            Some((t0, c0)) => {
                let rate = (now - t0) / (self.done - c0).max(1) as f64;
                now + rate * (self.total - self.done) as f64 + rate * self.total as f64
            }
        };
        (predicted > self.budget).then(|| {
            format!(
                "its build would take about {predicted:.1} s (seen after {now:.1} s), more than the render's {:.1} s \
                 budget: give a longer --time, or --spp",
                self.budget
            )
        })
    }
}

/// Per-stratum masses from an index's per-bin masses (`ratio` strata per bin, `strata` per
/// pixel): each stratum gets its bin's mass shared evenly, which is all the index knows of it.
pub fn strata_masses(bins: &[f32], ratio: u32, strata: u32) -> Vec<f32> {
    let per_pixel = strata.div_ceil(ratio) as usize;
    bins.chunks(per_pixel)
        .flat_map(|pixel| {
            (0..strata).map(move |j| {
                let b = (j / ratio) as usize;
                let width = (strata - b as u32 * ratio).min(ratio);
                pixel[b] / width as f32
            })
        })
        .collect()
}

/// Bounds on the loop iterations one invocation spends on a cluster, with index bins one
/// stratum wide (|grad L| <= 2, so a cluster's path lengths span at most 2 x its box diagonal
/// and a triangle's at most 2 x its longest edge); `at_ratio` scales them to wider bins.
#[derive(Clone, Copy, Debug)]
struct ClusterCost {
    /// The cluster's triangles.
    triangles: u64,
    /// Strata its path lengths may span, and the sum over its triangles of the strata each may.
    span: u64,
    triangle_spans: u64,
}

/// A ClusterCost's bounds at index bins of a ratio: the passes' loop iterations (lavapipe
/// counts every back edge of every loop, nested and in called functions alike).
struct PassCost {
    /// The count pass: the walk of the triangles for the range, then the range's bins.
    count: u64,
    /// The fill pass's range (a walk of the triangles where band_ranges is not kept).
    range: u64,
    /// The fill pass per window of at most WINDOW bins: the window, its masses' setup and
    /// writes, the walk of the triangles.
    per_window: u64,
    /// The fill pass's triangles' bins over all windows: each triangle's bins once, plus one
    /// more wherever a window boundary cuts them.
    triangle_bins: u64,
    /// Windows the cluster's range may span.
    windows: u64,
}

impl PassCost {
    /// The fill pass over the whole cluster.
    fn whole(&self) -> u64 {
        self.range + 1 + self.windows * self.per_window + self.triangle_bins
    }
}

impl ClusterCost {
    fn at_ratio(&self, ratio: u32) -> PassCost {
        let bins = |strata: u64| strata.div_ceil(ratio as u64) + 1;
        PassCost {
            count: self.triangles + bins(self.span) + 2,
            range: self.triangles + 1,
            per_window: 1 + 2 * WINDOW.min(bins(self.span)) + self.triangles,
            triangle_bins: 2 * (self.triangle_spans.div_ceil(ratio as u64) + 2 * self.triangles),
            windows: bins(self.span).div_ceil(WINDOW) + 1,
        }
    }
}

fn cluster_cost(nodes: &[BvhNode], triangles: &[Triangle], cluster: &[u32; 4], width: f64) -> ClusterCost {
    let root = &nodes[cluster[0] as usize];
    let strata = |length: f64| (2.0 * length / width).ceil().min(1e12) as u64 + 3;
    let triangle_spans = (cluster[2]..cluster[3])
        .map(|t| {
            let tri = &triangles[t as usize];
            strata(tri.e1.length().max(tri.e2.length()).max((tri.e2 - tri.e1).length()) as f64)
        })
        .sum();
    ClusterCost {
        triangles: (cluster[3] - cluster[2]) as u64,
        span: strata((root.max - root.min).length() as f64),
        triangle_spans,
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
