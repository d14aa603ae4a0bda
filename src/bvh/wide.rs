//! The wide BVH that rays traverse (closest hits and shadow rays; and ellipsoid queries with
//! `QuerySettings::wide`): four children per node, their boxes inline and quantised to 8 bits
//! per plane, so a node is one 64-byte cache line (`WideNode`). It is collapsed from the binary
//! BVH (`Bvh`), whose leaves it keeps: the triangles stay in BVH order and a leaf is the same
//! `(count << 28) | first` in both trees.
//!
//! Why: on CPU Vulkan every storage read is a loop over the SIMD group's lanes, and on large
//! meshes every node visit waits for memory. Four children per node make a ray's path through
//! the tree half as long; quantised boxes make the node a quarter of four binary nodes' bytes.
//!
//! This file is also the CPU twin of the traversal in `shaders/lib/bvh.wesl`: the same stack
//! traversal (children visited nearest first, leaves tested after the node loop, a step
//! budget), the same resumable fallback, the same f32 arithmetic.

use glam::Vec3;

use super::Bvh;
use super::traverse::safe_inverse;
use crate::gpu::layout::{Hit, NONE, NodeSurface, Triangle, WIDE_LEAF, WideNode};

/// Children per node.
pub const WIDTH: usize = 4;

/// Nodes at the top of the tree numbered breadth-first: the levels every ray visits lie together
/// in the first 64 KiB of the nodes. (The kernels once read them from a uniform copy on CPU
/// devices, which stopped paying: docs/benchmarks.md, "Node words and stack entries".)
pub const TOP_NODES: usize = 1024;

/// Entries of a stack traversal's stack (`STACK_SIZE` in bvh.wesl). A traversal that would need
/// more stops, and goes on in resume mode.
pub const STACK_SIZE: u32 = 32;

/// Most steps (node expansions and leaf tests, in either mode) one invocation's traversal takes
/// before it stops, to be resumed by a later dispatch (the TRAVERSAL_BUDGET override of
/// shaders/lib/bvh.wesl, passed to every kernel). A step runs at most 10 loop iterations, so a
/// traversal stays far below lavapipe's 65535 per invocation; in BVHs of any sensible quality a
/// ray takes a few dozen steps and never stops.
pub const TRAVERSAL_BUDGET: u32 = 6000;

/// `resume` of a traversal that has not started (bvh.wesl TRAVERSAL_START).
pub const TRAVERSAL_START: u32 = 0;
/// `resume` of a traversal that is complete (bvh.wesl TRAVERSAL_COMPLETE).
pub const TRAVERSAL_COMPLETE: u32 = u32::MAX;

/// The wide BVH and what the host needs to know of its shape.
#[derive(Clone, Debug, Default)]
pub struct WideBvh {
    /// The top of the tree breadth-first (the root first, at most `TOP_NODES`), then the other
    /// nodes depth-first.
    pub nodes: Vec<WideNode>,
    /// Leaves (slots holding triangles).
    pub leaves: usize,
    /// Inner nodes on the longest path from the root to a leaf, the root included.
    pub depth: usize,
    /// Per node and slot, the binary node the child was collapsed from (`NONE`: empty slot).
    pub sources: Vec<[u32; WIDTH]>,
}

/// Surface area of a box (m^2), the collapse's priority.
fn half_area(lo: Vec3, hi: Vec3) -> f32 {
    let e = hi - lo;
    e.x * e.y + e.y * e.z + e.z * e.x
}

impl WideBvh {
    /// Collapses `bvh` into four-wide nodes: each wide node takes the two children of a binary
    /// node and opens the largest-area inner one among its children until it has four (or only
    /// leaves).
    pub fn build(bvh: &Bvh) -> Self {
        let nodes = &bvh.nodes;
        assert!(!nodes.is_empty(), "a wide BVH needs a binary one");
        let mut wide = WideBvh::default();
        // A scene of one leaf: a root with that leaf as its only child.
        let root_children = if nodes[0].leaf != 0 { vec![0] } else { vec![1, nodes[1].skip as usize] };
        wide.emit(bvh, root_children, NONE, 1);
        wide.top_levels_first();
        wide
    }

    /// Renumbers the nodes so that the first `TOP_NODES` are the top of the tree in
    /// breadth-first order (the root first); the others keep their depth-first order.
    fn top_levels_first(&mut self) {
        let n = self.nodes.len();
        let top = n.min(TOP_NODES);
        let mut order = Vec::with_capacity(n);
        let mut placed = vec![false; n];
        order.push(0usize);
        placed[0] = true;
        let mut next = 0;
        while order.len() < top && next < order.len() {
            let node = self.nodes[order[next]];
            next += 1;
            for &c in &node.children {
                if c < WIDE_LEAF && order.len() < top {
                    order.push(c as usize);
                    placed[c as usize] = true;
                }
            }
        }
        order.extend((0..n).filter(|&i| !placed[i]));
        let mut new_index = vec![0u32; n];
        for (new, &old) in order.iter().enumerate() {
            new_index[old] = new as u32;
        }
        let nodes: Vec<WideNode> = order
            .iter()
            .map(|&old| {
                let mut node = self.nodes[old];
                for c in node.children.iter_mut() {
                    if *c < WIDE_LEAF {
                        *c = new_index[*c as usize];
                    }
                }
                if node.parent != NONE {
                    node.parent = (new_index[(node.parent >> 2) as usize] << 2) | (node.parent & 3);
                }
                node
            })
            .collect();
        self.sources = order.iter().map(|&old| self.sources[old]).collect();
        self.nodes = nodes;
    }

    /// Appends the wide node whose children are the binary nodes `kids` (before opening), and
    /// recursively their subtrees; returns its index.
    fn emit(&mut self, bvh: &Bvh, mut kids: Vec<usize>, parent: u32, depth: usize) -> u32 {
        let nodes = &bvh.nodes;
        let children_of = |i: usize| [i + 1, nodes[i + 1].skip as usize];
        while kids.len() < WIDTH {
            let widest = kids.iter().enumerate().filter(|(_, k)| nodes[**k].leaf == 0).max_by(|a, b| {
                half_area(nodes[*a.1].min, nodes[*a.1].max).total_cmp(&half_area(nodes[*b.1].min, nodes[*b.1].max))
            });
            let Some((slot, &k)) = widest else { break };
            let [first, second] = children_of(k);
            kids[slot] = first;
            kids.insert(slot + 1, second);
        }
        self.depth = self.depth.max(depth);
        let me = self.nodes.len() as u32;
        let boxes: Vec<(Vec3, Vec3)> = kids.iter().map(|&k| (nodes[k].min, nodes[k].max)).collect();
        self.nodes.push(quantise(&boxes, parent));
        self.sources.push(std::array::from_fn(|slot| kids.get(slot).map_or(NONE, |&k| k as u32)));
        for (slot, &k) in kids.iter().enumerate() {
            self.nodes[me as usize].children[slot] = if nodes[k].leaf != 0 {
                assert!(nodes[k].leaf >> 28 <= WIDTH as u32, "wide BVH leaf of {} triangles", nodes[k].leaf >> 28);
                self.leaves += 1;
                nodes[k].leaf
            } else {
                let child = self.emit(bvh, children_of(k).to_vec(), (me << 2) | slot as u32, depth + 1);
                assert!(child < WIDE_LEAF, "more wide BVH nodes than a child index addresses");
                child
            };
        }
        self.nodes[me as usize].subtree = self.nodes.len() as u32 - me;
        me
    }

    /// Per node and slot (`4 node + slot`), what the ellipsoid queries' descent knows of the
    /// child's triangles, from the binary nodes' `sums` (`Bvh::surface_sums`): their covariance
    /// is stored over the squared diagonal of the child's box as the kernels decode it.
    pub fn child_surfaces(&self, sums: &[super::SurfaceSums]) -> Vec<NodeSurface> {
        use rayon::prelude::*;
        self.nodes
            .par_iter()
            .zip(&self.sources)
            .flat_map_iter(|(node, sources)| {
                sources.iter().enumerate().map(move |(slot, &k)| {
                    if k == NONE {
                        NodeSurface::default()
                    } else {
                        let (lo, hi) = child_box(node, slot);
                        sums[k as usize].surface(lo.as_dvec3(), hi.as_dvec3())
                    }
                })
            })
            .collect()
    }

    /// Whether a traversal of this BVH can stop before it is complete (the RESUMABLE override):
    /// when its stack could overflow (three entries pushed per level) or a ray that expands
    /// every node and tests every leaf would exceed the step budget.
    pub fn traversals_can_stop(&self) -> bool {
        3 * self.depth as u64 > STACK_SIZE as u64 || (self.nodes.len() + self.leaves) as u64 > TRAVERSAL_BUDGET as u64
    }

    /// Most times one traversal can stop before it is complete: once in stack mode, then once
    /// per TRAVERSAL_BUDGET steps of resume mode, which visits each node once from its parent
    /// and once more after each of its inner children.
    pub fn most_stops(&self) -> u32 {
        let resume_steps = 2 * self.nodes.len() as u64;
        (1 + resume_steps.div_ceil(TRAVERSAL_BUDGET as u64)).min(u32::MAX as u64) as u32
    }
}

/// Quantises the children's `boxes` (m) into a node with no children yet: per axis the grid
/// origin is the lowest plane and the step 2^e the smallest for which 255 steps span the
/// planes and every decoded plane lies on its box's outer side (f32 decoding as the kernels
/// do: origin + q * step).
fn quantise(boxes: &[(Vec3, Vec3)], parent: u32) -> WideNode {
    let mut node = WideNode { parent, children: [NONE; WIDTH], ..Default::default() };
    let mut origin = [0f32; 3];
    let mut planes = [[0u32; 2]; 3];
    for axis in 0..3 {
        let lo = boxes.iter().map(|b| b.0[axis]).fold(f32::INFINITY, f32::min);
        let hi = boxes.iter().map(|b| b.1[axis]).fold(f32::NEG_INFINITY, f32::max);
        origin[axis] = lo;
        let extent = (hi - lo) as f64;
        let mut e = if extent > 0.0 { (extent / 255.0).log2().ceil() as i32 } else { -126 };
        e = e.clamp(-126, 127);
        let words = loop {
            let step = 2f32.powi(e);
            let decode = |q: u32| lo + q as f32 * step;
            let mut words = [0u32; 2];
            let mut ok = true;
            for (k, &(blo, bhi)) in boxes.iter().enumerate() {
                let (blo, bhi) = (blo[axis], bhi[axis]);
                let mut qlo = (((blo - lo) as f64 / step as f64).floor().clamp(0.0, 255.0)) as u32;
                while qlo > 0 && decode(qlo) > blo {
                    qlo -= 1;
                }
                let mut qhi = (((bhi - lo) as f64 / step as f64).ceil().clamp(0.0, 255.0)) as u32;
                while qhi < 255 && decode(qhi) < bhi {
                    qhi += 1;
                }
                ok &= decode(qlo) <= blo && decode(qhi) >= bhi;
                words[0] |= qlo << (8 * k);
                words[1] |= qhi << (8 * k);
            }
            if ok || e == 127 {
                break words;
            }
            e += 1;
        };
        node.grid[3] |= ((e + 127) as u32) << (8 * axis);
        planes[axis] = words;
    }
    node.grid[..3].copy_from_slice(&origin.map(f32::to_bits));
    node.planes_xy = [planes[0][0], planes[0][1], planes[1][0], planes[1][1]];
    node.planes_z = planes[2];
    node
}

/// The grid step 2^e (m) of each axis of `node`.
fn steps(node: &WideNode) -> Vec3 {
    let e = |axis: u32| f32::from_bits(((node.exponents() >> (8 * axis)) & 255) << 23);
    Vec3::new(e(0), e(1), e(2))
}

/// The decoded box of `node`'s child `slot` (m): what a ray is tested against, up to the
/// rounding of the test itself.
pub fn child_box(node: &WideNode, slot: usize) -> (Vec3, Vec3) {
    let step = steps(node);
    let byte = |w: u32| ((w >> (8 * slot)) & 255) as f32;
    let [lx, hx, ly, hy] = node.planes_xy;
    let [lz, hz] = node.planes_z;
    (
        node.origin() + step * Vec3::new(byte(lx), byte(ly), byte(lz)),
        node.origin() + step * Vec3::new(byte(hx), byte(hy), byte(hz)),
    )
}

/// Per slot, the distance (m) at which the ray enters the child's box, or FAR when it misses
/// the box within (0, t_max) or the slot is empty (twin of bvh.wesl `intersect_children`).
pub fn intersect_children(node: &WideNode, origin: Vec3, inv_dir: Vec3, t_max: f32) -> [f32; WIDTH] {
    let scale = steps(node) * inv_dir;
    let offset = (node.origin() - origin) * inv_dir;
    let [lx, hx, ly, hy] = node.planes_xy;
    let [lz, hz] = node.planes_z;
    let plane = |w: u32, k: usize, axis: usize| (((w >> (8 * k)) & 255) as f32).mul_add(scale[axis], offset[axis]);
    std::array::from_fn(|k| {
        let (t0x, t1x) = (plane(lx, k, 0), plane(hx, k, 0));
        let (t0y, t1y) = (plane(ly, k, 1), plane(hy, k, 1));
        let (t0z, t1z) = (plane(lz, k, 2), plane(hz, k, 2));
        let near = t0x.min(t1x).max(t0y.min(t1y)).max(t0z.min(t1z).max(0.0));
        let far = t0x.max(t1x).min(t0y.max(t1y)).min(t0z.max(t1z).min(t_max));
        if near <= far && node.children[k] != NONE { near } else { FAR }
    })
}

/// "Missed" in [`intersect_children`]; "no hit yet" as a ray parameter (m) (bvh.wesl FAR).
pub const FAR: f32 = 3.0e38;

/// Ray against a triangle without its division: (t, b1, b2, d), each of t, b1, b2 times
/// d = |det| > 0, or all zero for a miss (twin of bvh.wesl `intersect_triangle_scaled`).
pub fn intersect_triangle_scaled(origin: Vec3, direction: Vec3, tri: &Triangle) -> [f32; 4] {
    let p = direction.cross(tri.e2);
    let det = tri.e1.dot(p);
    let s = origin - tri.v0;
    let q = s.cross(tri.e1);
    let sign = if det < 0.0 { -1.0 } else { 1.0 };
    let d = det.abs();
    let b1 = s.dot(p) * sign;
    let b2 = direction.dot(q) * sign;
    let t = tri.e2.dot(q) * sign;
    if d > 0.0 && b1 >= 0.0 && b2 >= 0.0 && b1 + b2 <= d && t > 0.0 { [t, b1, b2, d] } else { [0.0; 4] }
}

/// What a traversal looks for: the closest hit (ignoring one triangle) or any hit within t_max
/// (ignoring two).
#[derive(Clone, Copy)]
enum Query {
    Closest { ignore: u32 },
    Any { ignore0: u32, ignore1: u32 },
}

/// State of one traversal between calls: the best hit so far (for any-hit rays, a hit means
/// the ray is occluded) and where to resume.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Traversal {
    /// Closest hit so far (t = the ray's t_max, triangle NONE, while none).
    pub hit: Hit,
    /// TRAVERSAL_START, TRAVERSAL_COMPLETE, or a resume-mode position.
    pub resume: u32,
}

/// Tests leaf `leaf`'s triangles; true when an any-hit query is decided.
fn test_leaf(triangles: &[Triangle], leaf: u32, origin: Vec3, direction: Vec3, query: Query, best: &mut Hit) -> bool {
    let first = leaf & (WIDE_LEAF - 1);
    for k in first..first + (leaf >> 28) {
        let h = intersect_triangle_scaled(origin, direction, &triangles[k as usize]);
        match query {
            Query::Closest { ignore } => {
                if h[3] > 0.0 && h[0] < best.t * h[3] && k != ignore {
                    *best = Hit { t: h[0] / h[3], triangle: k, b1: h[1] / h[3], b2: h[2] / h[3] };
                }
            }
            Query::Any { ignore0, ignore1 } => {
                if h[3] > 0.0 && h[0] < best.t * h[3] && k != ignore0 && k != ignore1 {
                    best.triangle = k;
                    return true;
                }
            }
        }
    }
    false
}

/// One call of the traversal (twin of bvh.wesl `trace_closest_from` / `trace_any_from`) with at
/// most `budget` steps.
fn traverse(
    nodes: &[WideNode],
    triangles: &[Triangle],
    origin: Vec3,
    direction: Vec3,
    query: Query,
    state: Traversal,
    budget: u32,
) -> Traversal {
    let inv_dir = safe_inverse(direction);
    let mut best = state.hit;
    let closest = matches!(query, Query::Closest { .. });
    let mut steps = 0u32;
    if state.resume == TRAVERSAL_START {
        let mut stack = Vec::<(u32, f32)>::with_capacity(STACK_SIZE as usize);
        let mut current = 0u32;
        loop {
            // Nodes until a leaf (or the end, or the budget).
            let mut leaf = 0u32;
            let mut stopped = false;
            loop {
                if current == NONE {
                    let Some((node, t)) = stack.pop() else { break };
                    if closest && t >= best.t {
                        continue;
                    }
                    current = node;
                }
                if current >= WIDE_LEAF {
                    leaf = current;
                    current = NONE;
                    break;
                }
                if steps >= budget || stack.len() as u32 + 3 > STACK_SIZE {
                    stopped = true;
                    break;
                }
                steps += 1;
                let node = &nodes[current as usize];
                let t_near = intersect_children(node, origin, inv_dir, best.t);
                let mut order: [(f32, u32); WIDTH] = std::array::from_fn(|k| (t_near[k], node.children[k]));
                if closest {
                    sort4(&mut order);
                }
                for &(t, child) in order[1..].iter().rev() {
                    if t < FAR {
                        stack.push((child, t));
                    }
                }
                current = if order[0].0 < FAR { order[0].1 } else { NONE };
            }
            if stopped {
                return Traversal { hit: best, resume: resume_position(0, 0) };
            }
            if leaf == 0 {
                return Traversal { hit: best, resume: TRAVERSAL_COMPLETE };
            }
            steps += 1;
            if test_leaf(triangles, leaf, origin, direction, query, &mut best) {
                return Traversal { hit: best, resume: TRAVERSAL_COMPLETE };
            }
        }
    }
    // Resume mode: a step visits node `index` from slot `slot` on: it tests the leaves it hits
    // there in slot order and descends into the first inner child it hits, or climbs to the
    // parent's next slot when none is left.
    let mut at = state.resume - 1;
    loop {
        if steps >= budget {
            return Traversal { hit: best, resume: at + 1 };
        }
        steps += 1;
        let index = at >> 2;
        let node = &nodes[index as usize];
        let t_near = intersect_children(node, origin, inv_dir, best.t);
        let mut descend = None;
        for k in (at & 3) as usize..WIDTH {
            let child = node.children[k];
            if t_near[k] < FAR && child < WIDE_LEAF {
                descend = Some(child << 2);
                break;
            }
            if t_near[k] < FAR && test_leaf(triangles, child, origin, direction, query, &mut best) {
                return Traversal { hit: best, resume: TRAVERSAL_COMPLETE };
            }
        }
        if let Some(child) = descend {
            at = child;
            continue;
        }
        // Every slot done: the parent's next slot, climbing out of finished nodes.
        let mut up = node.parent;
        loop {
            if up == NONE {
                return Traversal { hit: best, resume: TRAVERSAL_COMPLETE };
            }
            if up & 3 < 3 {
                at = up + 1;
                break;
            }
            up = nodes[(up >> 2) as usize].parent;
        }
    }
}

/// `resume` of resume mode at `node`'s slot `slot` (twin of bvh.wesl `resume_position`).
pub fn resume_position(node: u32, slot: u32) -> u32 {
    ((node << 2) | slot) + 1
}

/// Sorts four (distance, child) pairs by distance with the kernels' network of five
/// compare-exchanges (a stable order for equal distances, as in WGSL `select`).
fn sort4(p: &mut [(f32, u32); WIDTH]) {
    let mut cs = |i: usize, j: usize| {
        if p[j].0 < p[i].0 {
            p.swap(i, j);
        }
    };
    cs(0, 1);
    cs(2, 3);
    cs(0, 2);
    cs(1, 3);
    cs(1, 2);
}

/// One call of the closest-hit traversal from `state` with at most `budget` steps (twin of
/// bvh.wesl `trace_closest_from`, whose budget is TRAVERSAL_BUDGET).
pub fn trace_closest_from(
    nodes: &[WideNode],
    triangles: &[Triangle],
    origin: Vec3,
    direction: Vec3,
    ignore: u32,
    state: Traversal,
    budget: u32,
) -> Traversal {
    traverse(nodes, triangles, origin, direction, Query::Closest { ignore }, state, budget)
}

/// One call of the any-hit traversal from `resume` with at most `budget` steps (twin of
/// bvh.wesl `trace_any_from`): the ray is occluded when the returned hit has a triangle.
#[allow(clippy::too_many_arguments)]
pub fn trace_any_from(
    nodes: &[WideNode],
    triangles: &[Triangle],
    origin: Vec3,
    direction: Vec3,
    t_max: f32,
    (ignore0, ignore1): (u32, u32),
    resume: u32,
    budget: u32,
) -> Traversal {
    let state = Traversal { hit: Hit { t: t_max, triangle: NONE, b1: 0.0, b2: 0.0 }, resume };
    traverse(nodes, triangles, origin, direction, Query::Any { ignore0, ignore1 }, state, budget)
}

/// The closest hit with t in (0, t_max), ignoring `ignore`, in calls of at most `budget` steps
/// until complete; with the stops counted.
pub fn trace_closest_in_steps(
    bvh: &WideBvh,
    triangles: &[Triangle],
    (origin, direction, t_max): (Vec3, Vec3, f32),
    ignore: u32,
    budget: u32,
) -> (Hit, u32) {
    let mut state = Traversal { hit: Hit { t: t_max, triangle: NONE, b1: 0.0, b2: 0.0 }, resume: TRAVERSAL_START };
    for stops in 0.. {
        state = trace_closest_from(&bvh.nodes, triangles, origin, direction, ignore, state, budget);
        if state.resume == TRAVERSAL_COMPLETE {
            return (state.hit, stops);
        }
    }
    unreachable!()
}

/// Whether any triangle other than `ignore0` and `ignore1` is hit with t in (0, t_max), in calls
/// of at most `budget` steps until decided; with the stops counted.
pub fn trace_any_in_steps(
    bvh: &WideBvh,
    triangles: &[Triangle],
    (origin, direction, t_max): (Vec3, Vec3, f32),
    ignore: (u32, u32),
    budget: u32,
) -> (bool, u32) {
    let mut resume = TRAVERSAL_START;
    for stops in 0.. {
        let r = trace_any_from(&bvh.nodes, triangles, origin, direction, t_max, ignore, resume, budget);
        if r.hit.triangle != NONE {
            return (true, stops);
        }
        if r.resume == TRAVERSAL_COMPLETE {
            return (false, stops);
        }
        resume = r.resume;
    }
    unreachable!()
}

/// The closest hit with t in (0, t_max), ignoring `ignore` (the kernels' traversal, resumed
/// until complete).
pub fn trace_closest(
    bvh: &WideBvh,
    triangles: &[Triangle],
    origin: Vec3,
    direction: Vec3,
    t_max: f32,
    ignore: u32,
) -> Hit {
    trace_closest_in_steps(bvh, triangles, (origin, direction, t_max), ignore, TRAVERSAL_BUDGET).0
}

/// Whether any triangle other than `ignore0` and `ignore1` is hit with t in (0, t_max) (the
/// kernels' traversal, resumed until decided).
pub fn trace_any(
    bvh: &WideBvh,
    triangles: &[Triangle],
    origin: Vec3,
    direction: Vec3,
    t_max: f32,
    ignore0: u32,
    ignore1: u32,
) -> bool {
    trace_any_in_steps(bvh, triangles, (origin, direction, t_max), (ignore0, ignore1), TRAVERSAL_BUDGET).0
}
