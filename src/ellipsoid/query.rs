//! CPU twin of `shaders/lib/ellipsoid_query.wesl`: the ellipsoid query's traversal of the
//! stackless BVH, or of the wide one with `QuerySettings::wide` (every child near the root,
//! stochastic descents into nodes that are small against the spheroid, whole small subtrees at
//! the bottom, one final descent over what is left past the allowance), the node estimate that weighs a descent's children, and the
//! triangles' reservoir weights (arcs from circular intervals, times `reflection_factor` in
//! queries for reflecting vertices). The same random numbers (pcg4d of the
//! query's key) drive the same decisions; the arithmetic is f64 on the f64 oracle's sections
//! (`super::Spheroid`), so decisions agree with the device's except at near-ties.
//!
//! It is an oracle for tests: `reached` lists what one query reaches, with each triangle's
//! weight q_i / P_i; averaged over keys that must give q_i (`pick_weight`) for every triangle
//! (the descent is unbiased), which tests check against brute force. [`QuerySettings`], the
//! query's settings, are the device's too (`RenderSettings::query`, re-exported as
//! `integrator::QuerySettings`).

use glam::{DVec3, DVec4};

use super::{Spheroid, Triangle as OracleTriangle};
use crate::bvh::wide::{WIDTH, child_box};
use crate::gpu::layout::{BvhNode, MATERIAL_DOUBLE_SIDED, Material, NONE, NodeSurface, Triangle, WIDE_LEAF, WideNode};
use crate::rng::pcg4d;

/// How an ellipsoid query traverses the BVH (shaders/lib/ellipsoid_query.wesl): every child
/// the spheroid may touch near the root, a stochastic descent (one child at a time, in
/// proportion to an estimate of the arcs below it) into nodes that are small against the
/// spheroid, and every node of the small subtrees a descent ends in. Any setting is unbiased;
/// they trade work per query against variance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QuerySettings {
    /// Nodes whose box diagonal is at most `split` times the spheroid's semi-major axis are
    /// entered by a descent (dimensionless); 0: the exhaustive query, which visits every node
    /// the spheroid may touch (cost grows with the triangles near the spheroid).
    pub split: f32,
    /// A descent visits whole subtrees of at most this many binary BVH nodes (with `wide`, of
    /// about as many leaves: [`QuerySettings::device_bottom_nodes`] wide nodes).
    pub bottom_nodes: u32,
    /// Loop iterations (node boxes and triangles) after which a query finishes with one descent
    /// over the rest of the tree: bounds every query's work, which lavapipe needs (it ends an
    /// invocation's loops after 65535 iterations in total). Unbiased like the rest.
    pub allowance: u32,
    /// Weigh a triangle's pick by its arcs' angle times the reflection factor (an estimate of
    /// its contribution per radian, zero only where the contribution is; see
    /// `ellipsoid::query::reflection_factor`); false (the default; `render --nlos` sets it): by
    /// the arcs' angle alone. Both unbiased.
    pub reflection_weights: bool,
    /// Walk the wide BVH (four children per node, a stack of subtrees; `render --query-tree
    /// wide`) instead of the binary one (false, the default). Unbiased like the rest; on
    /// lavapipe 20-30% slower per sample (docs/benchmarks.md).
    pub wide: bool,
}

impl QuerySettings {
    /// The exhaustive query (every node the spheroid may touch, up to the allowance).
    pub const EXHAUSTIVE: Self =
        Self { split: 0.0, bottom_nodes: 31, allowance: 4096, reflection_weights: false, wide: false };

    /// The device's QUERY_BOTTOM_NODES: `bottom_nodes` for the binary BVH; for the wide one,
    /// subtrees of about as many leaves, (bottom_nodes - 1) / 6 wide nodes (a binary subtree
    /// of L leaves has 2 L - 1 nodes, a wide one about (L - 1) / 3), at least 1 and at most
    /// [`MAX_BOTTOM_NODES`].
    pub fn device_bottom_nodes(&self) -> u32 {
        if self.wide { (self.bottom_nodes.saturating_sub(1) / 6).clamp(1, MAX_BOTTOM_NODES) } else { self.bottom_nodes }
    }
}

impl Default for QuerySettings {
    fn default() -> Self {
        Self { split: 1.0, bottom_nodes: 31, allowance: 4096, reflection_weights: false, wide: false }
    }
}

/// The scene as the query sees it: BVH nodes (binary and wide), their triangle areas (total,
/// emitting), the triangles in BVH order and the materials.
#[derive(Clone, Copy)]
pub struct QueryScene<'a> {
    /// Stackless BVH nodes (depth-first, skip links).
    pub nodes: &'a [BvhNode],
    /// Per node: the area and spread of its triangles.
    pub node_surfaces: &'a [NodeSurface],
    /// Wide BVH nodes (queries with `QuerySettings::wide`).
    pub wide: &'a [WideNode],
    /// Per wide node and slot (`4 node + slot`): the area and spread of the child's triangles.
    pub child_surfaces: &'a [NodeSurface],
    /// Triangles in BVH order.
    pub triangles: &'a [Triangle],
    /// The materials the triangles index (albedo and sides weigh reflecting queries' picks).
    pub materials: &'a [Material],
}

impl<'a> QueryScene<'a> {
    /// The query view of a prepared scene.
    pub fn of(scene: &'a crate::scene::PreparedScene) -> Self {
        Self {
            nodes: &scene.bvh.nodes,
            node_surfaces: &scene.node_surfaces,
            wide: &scene.wide.nodes,
            child_surfaces: &scene.child_surfaces,
            triangles: &scene.triangles,
            materials: &scene.materials,
        }
    }
}

/// One ellipsoid query: the spheroid and what prunes it.
#[derive(Clone, Copy, Debug)]
pub struct Query {
    /// Light-side focus x_s (m).
    pub focus_s: DVec3,
    /// Camera-side focus x_c (m).
    pub focus_c: DVec3,
    /// tau_e, the sum of distances to the foci (m).
    pub tau_e: f64,
    /// Triangles left out (the foci's own), or NONE.
    pub ignore: [u32; 2],
    /// Count only emitting triangles.
    pub lights_only: bool,
    /// Half-spaces the ends reach: points with dot(xyz, x) < w cannot be connected (xyz = 0:
    /// none).
    pub reach: [DVec4; 2],
}

/// What one query reached: triangles with their weights q_i / P_i, and its work.
#[derive(Clone, Debug, Default)]
pub struct Reached {
    /// (triangle in BVH order, weight q / P) in the order the device tests them.
    pub triangles: Vec<(u32, f64)>,
    /// Traversal and triangle loop iterations.
    pub iterations: u32,
}

impl Reached {
    /// W, the sum of the weights (an unbiased estimate of the sum of q over the scene).
    pub fn total(&self) -> f64 {
        self.triangles.iter().map(|t| t.1).sum()
    }
}

/// The density of `node_estimate` never falls below this fraction of its peak.
pub const ESTIMATE_FLOOR: f64 = 0.05;
/// Leaves the device batches before testing their triangles (ellipsoid_query.wesl LEAF_BATCH).
const LEAF_BATCH: usize = 16;

fn unit_float(h: u32) -> f64 {
    (h >> 8) as f64 / 16_777_216.0
}

fn distance_to_box(p: DVec3, lo: DVec3, hi: DVec3) -> f64 {
    (lo - p).max(p - hi).max(DVec3::ZERO).length()
}

fn box_behind(lo: DVec3, hi: DVec3, h: DVec4) -> bool {
    let n = h.truncate();
    let corner = DVec3::new(
        if n.x > 0.0 { hi.x } else { lo.x },
        if n.y > 0.0 { hi.y } else { lo.y },
        if n.z > 0.0 { hi.z } else { lo.z },
    );
    n.dot(corner) < h.w
}

/// Bounds of L(x) = |x - x_s| + |x - x_c| over the box: (nearest points to each focus, farthest
/// corners from each focus).
pub fn path_length_range(lo: DVec3, hi: DVec3, fs: DVec3, fc: DVec3) -> (f64, f64) {
    let centre = 0.5 * (lo + hi);
    let far = |f: DVec3| {
        DVec3::new(
            if f.x < centre.x { hi.x } else { lo.x },
            if f.y < centre.y { hi.y } else { lo.y },
            if f.z < centre.z { hi.z } else { lo.z },
        )
        .distance(f)
    };
    (distance_to_box(fs, lo, hi) + distance_to_box(fc, lo, hi), far(fs) + far(fc))
}

/// The spheroid's axis-aligned bounds, widened by 1e-5 as on the device.
fn spheroid_bounds(q: &Query) -> (DVec3, DVec3) {
    let sp = Spheroid { focus_s: q.focus_s, focus_c: q.focus_c, length: q.tau_e };
    let (lo, hi) = sp.bounds();
    let (m, half) = (0.5 * (lo + hi), 0.5 * (hi - lo) * (1.0 + 1e-5));
    (m - half, m + half)
}

/// Estimate of the arc measure below a node with box [lo, hi] and surface `surface` (twin of
/// `node_estimate`): zero exactly when the box cannot hold a counted point of the spheroid.
pub fn node_estimate(lo: DVec3, hi: DVec3, surface: &NodeSurface, q: &Query, bounds: (DVec3, DVec3)) -> f64 {
    let area = if q.lights_only { surface.light_area } else { surface.area } as f64;
    if area <= 0.0
        || hi.cmplt(bounds.0).any()
        || lo.cmpgt(bounds.1).any()
        || box_behind(lo, hi, q.reach[0])
        || box_behind(lo, hi, q.reach[1])
    {
        return 0.0;
    }
    let (shortest, longest) = path_length_range(lo, hi, q.focus_s, q.focus_c);
    if shortest > q.tau_e || longest < q.tau_e {
        return 0.0;
    }
    if q.lights_only {
        let c = 0.5 * (lo + hi);
        let centre = (c.distance(q.focus_s) + c.distance(q.focus_c)).clamp(shortest, longest);
        let rise = if q.tau_e <= centre {
            (q.tau_e - shortest) / (centre - shortest).max(1e-30)
        } else {
            (longest - q.tau_e) / (longest - centre).max(1e-30)
        };
        let width = (longest - shortest).max(1e-6 * q.tau_e);
        return area * (2.0 / width) * rise.clamp(ESTIMATE_FLOOR, 1.0);
    }
    let (mean, sd) = path_length_moments(lo, hi, surface, q);
    let t = (q.tau_e - mean) / sd;
    let semicircle = (4.0 - t * t).max(0.0).sqrt() / std::f64::consts::TAU;
    area / sd * semicircle.max(ESTIMATE_FLOOR / std::f64::consts::PI)
}

/// Mean and standard deviation of the path length |x - x_s| + |x - x_c| of a point x drawn
/// uniformly on a node's triangles: the mean to second order about their centroid, the
/// deviation to first order (twin of `path_length_moments`).
pub fn path_length_moments(lo: DVec3, hi: DVec3, surface: &NodeSurface, q: &Query) -> (f64, f64) {
    use crate::gpu::packing::unpack2x16float;
    let scale = (hi - lo).length_squared();
    let [a, b, c] = surface.spread.map(|w| unpack2x16float(w).as_dvec2() * scale);
    let cov = glam::DMat3::from_cols(DVec3::new(a.x, b.y, c.x), DVec3::new(b.y, a.y, c.y), DVec3::new(c.x, c.y, b.x));
    let centroid = surface.centroid.as_dvec3();
    let trace = a.x + a.y + b.x;
    let floor = 1e-6 * q.tau_e;
    let mut mean = 0.0;
    let mut gradient = DVec3::ZERO;
    for focus in [q.focus_s, q.focus_c] {
        let d = centroid - focus;
        let r = d.length().max(floor);
        let u = d / r;
        gradient += u;
        // The Hessian of |x - f| is (I - u u^T) / r, and E[delta^T H delta] = tr(H cov).
        mean += r + 0.5 * (trace - u.dot(cov * u)) / r;
    }
    (mean, gradient.dot(cov * gradient).max(0.0).sqrt().max(floor))
}

/// The circular interval of eccentric angle an edge from p along `edge` allows (twin of
/// `edge_interval`): (centre, half width), half width pi for every angle, -1 for none.
fn edge_interval(section: &super::Section, n: DVec3, p: DVec3, edge: DVec3) -> (f64, f64) {
    use std::f64::consts::PI;
    let alpha = section.m1 * edge.cross(section.u).dot(n);
    let beta = section.m2 * edge.cross(section.v).dot(n);
    let gamma = -edge.cross(section.centre - p).dot(n);
    let r = alpha.hypot(beta);
    if r <= 0.0 {
        return (0.0, if gamma <= 0.0 { PI } else { -1.0 });
    }
    let ratio = gamma / r;
    if ratio <= -1.0 {
        (0.0, PI)
    } else if ratio >= 1.0 {
        (0.0, -1.0)
    } else {
        (beta.atan2(alpha), ratio.acos())
    }
}

/// The total angle of the section's arcs inside the triangle, from the three edges' circular
/// intervals (twin of `arc_weight`; equals `clip_arcs(..).total`, which tests check).
pub fn arc_weight(spheroid: &Spheroid, triangle: &OracleTriangle) -> f64 {
    use std::f64::consts::{PI, TAU};
    let n = triangle.normal();
    let Some(section) = spheroid.section(triangle.vertices[0], n) else { return 0.0 };
    let mut intervals: Vec<(f64, f64)> = (0..3)
        .map(|i| {
            let p = triangle.vertices[i];
            edge_interval(&section, n, p, triangle.vertices[(i + 1) % 3] - p)
        })
        .collect();
    if intervals.iter().any(|i| i.1 < 0.0) {
        return 0.0;
    }
    intervals.sort_by(|a, b| a.1.total_cmp(&b.1));
    let a = intervals[0];
    if a.1 >= PI {
        return TAU;
    }
    let start = a.0 - a.1;
    let length = 2.0 * a.1;
    let pieces = |(centre, half): (f64, f64)| -> [(f64, f64); 2] {
        if half >= PI {
            return [(-1.0, TAU + 1.0), (0.0, 0.0)];
        }
        let lo = (centre - half - start).rem_euclid(TAU);
        [(lo, lo + 2.0 * half), (lo - TAU, lo + 2.0 * half - TAU)]
    };
    let mut total = 0.0;
    for b in pieces(intervals[1]) {
        for c in pieces(intervals[2]) {
            total += (length.min(b.1.min(c.1)) - 0.0f64.max(b.0.max(c.0))).max(0.0);
        }
    }
    total.min(length)
}

/// The factor a triangle's arc weight is multiplied by in a query for reflecting vertices (twin
/// of `reflection_factor`): the material's largest albedo channel (a plastic: or its coat's
/// specular factor, if larger) times a bound on the cosines
/// towards the foci, min(1, |h_s| / r) min(1, |h_c| / r) (h: a focus's signed distance to the
/// triangle's plane; r = (tau_e - d) / 2, the least distance from a focus to the spheroid); 0
/// where every connection through the triangle is (foci on opposite sides or in its plane,
/// within `PLANE_GUARD` tau_e, both behind a one-sided surface, a black material).
pub fn reflection_factor(q: &Query, triangle: &OracleTriangle, material: &Material) -> f64 {
    let (n, v0) = (triangle.normal(), triangle.vertices[0]);
    let (hs, hc) = (n.dot(q.focus_s - v0), n.dot(q.focus_c - v0));
    let guard = PLANE_GUARD * q.tau_e;
    let in_plane = hs.abs() <= guard || hc.abs() <= guard;
    if !(hs * hc > 0.0) || in_plane || (hc < 0.0 && material.flags & MATERIAL_DOUBLE_SIDED == 0) {
        return 0.0;
    }
    let nearest = 0.5 * (q.tau_e - q.focus_s.distance(q.focus_c));
    let albedo = material.base_color.max_element().max(material.specular);
    albedo as f64 * (hs.abs() / nearest).min(1.0) * (hc.abs() / nearest).min(1.0)
}

/// A focus nearer a triangle's plane than this times tau_e lies in it for `reflection_factor`
/// (twin of the device's PLANE_GUARD).
pub const PLANE_GUARD: f64 = 1e-6;

/// A triangle's reservoir weight in query `q` (twin of the device's): its arcs' total angle,
/// times `reflection_factor` unless the query counts emitters only or
/// `settings.reflection_weights` is false.
pub fn pick_weight(q: &Query, triangle: &OracleTriangle, material: &Material, settings: &QuerySettings) -> f64 {
    let spheroid = Spheroid { focus_s: q.focus_s, focus_c: q.focus_c, length: q.tau_e };
    let weight = arc_weight(&spheroid, triangle);
    if q.lights_only || !settings.reflection_weights || weight <= 0.0 {
        weight
    } else {
        weight * reflection_factor(q, triangle, material)
    }
}

fn oracle_triangle(t: &Triangle) -> OracleTriangle {
    let v0 = t.v0.as_dvec3();
    OracleTriangle { vertices: [v0, v0 + t.e1.as_dvec3(), v0 + t.e2.as_dvec3()] }
}

/// The uniform number of a query's descent step at node `i` (its own stream of the key).
fn step_number(key: [u32; 3], i: usize) -> f64 {
    unit_float(pcg4d([key[0], key[1], key[2] ^ 0x85eb_ca6b, i as u32])[0])
}

/// The uniform number with which the final descent weighs the subtree at node `i`.
fn rest_number(key: [u32; 3], i: usize) -> f64 {
    unit_float(pcg4d([key[0], key[1], key[2] ^ 0xc2b2_ae35, i as u32])[0])
}

/// Tests the triangles of the batched `leaves` (leaf word, 1 / P), in order, and adds those the
/// spheroid cuts to `out` with their weights q / P (twin of the batch loop and
/// `offer_triangle`).
fn test_leaves(
    scene: QueryScene<'_>,
    q: &Query,
    settings: &QuerySettings,
    leaves: &mut Vec<(u32, f64)>,
    out: &mut Reached,
) {
    for (leaf, inv_p) in leaves.drain(..) {
        let first = leaf & 0x0fff_ffff;
        for t in first..first + (leaf >> 28) {
            out.iterations += 1;
            let tri = &scene.triangles[t as usize];
            if q.ignore.contains(&t) || (q.lights_only && tri.light == NONE) {
                continue;
            }
            let o = oracle_triangle(tri);
            let lo = o.vertices[0].min(o.vertices[1]).min(o.vertices[2]);
            let hi = o.vertices[0].max(o.vertices[1]).max(o.vertices[2]);
            if box_behind(lo, hi, q.reach[0]) || box_behind(lo, hi, q.reach[1]) {
                continue;
            }
            let weight = pick_weight(q, &o, &scene.materials[tri.material as usize], settings);
            if weight > 0.0 {
                out.triangles.push((t, weight * inv_p));
            }
        }
    }
}

fn is_bottom(i: usize, node: &BvhNode, settings: &QuerySettings) -> bool {
    node.leaf != 0 || (node.skip as usize - i) as u32 <= settings.bottom_nodes
}

/// Everything one query reaches (twin of `query_ellipsoid`), in the device's order: the
/// traversal with `settings` (over the binary BVH, or the wide one with `settings.wide`) and at
/// most `allowance` loop iterations before the final descent, with the random numbers of `key`.
pub fn reached(scene: QueryScene<'_>, q: &Query, settings: &QuerySettings, allowance: u32, key: [u32; 3]) -> Reached {
    if settings.wide {
        reached_wide(scene, q, settings, allowance, key)
    } else {
        reached_binary(scene, q, settings, allowance, key)
    }
}

/// [`reached`] over the binary BVH (twin of `query_binary`).
fn reached_binary(
    scene: QueryScene<'_>,
    q: &Query,
    settings: &QuerySettings,
    allowance: u32,
    key: [u32; 3],
) -> Reached {
    let mut out = Reached::default();
    if q.tau_e <= q.focus_s.distance(q.focus_c) {
        return out;
    }
    let bounds = spheroid_bounds(q);
    let nodes = scene.nodes;
    let count = nodes.len();
    let estimate =
        |i: usize| node_estimate(nodes[i].min.as_dvec3(), nodes[i].max.as_dvec3(), &scene.node_surfaces[i], q, bounds);
    let (step_key, rest_key) = (|i: usize| step_number(key, i), |i: usize| rest_number(key, i));
    let split_size = settings.split as f64 * 0.5 * q.tau_e;
    let mut leaves: Vec<(u32, f64)> = Vec::new();
    let flush = |leaves: &mut Vec<(u32, f64)>, out: &mut Reached| test_leaves(scene, q, settings, leaves, out);
    // Descends from node i (inner, not bottom) with 1 / P = inv_p; returns the bottom subtree
    // reached (its root and 1 / P) or None when the descent dies.
    let descend = |mut i: usize, mut inv_p: f64, iterations: &mut u32| -> Option<(usize, f64)> {
        loop {
            let (a, b) = (i + 1, nodes[i + 1].skip as usize);
            *iterations += 2;
            let (wa, wb) = (estimate(a), estimate(b));
            let total = wa + wb;
            if total <= 0.0 {
                return None;
            }
            let (chosen, weight) = if step_key(i) * total >= wa { (b, wb) } else { (a, wa) };
            inv_p *= total / weight;
            i = chosen;
            if is_bottom(i, &nodes[i], settings) {
                return Some((i, inv_p));
            }
        }
    };
    // Visits the subtree [i, end) whole with 1 / P = inv_p, batching its leaves.
    let visit = |start: usize, end: usize, inv_p: f64, iterations: &mut u32, leaves: &mut Vec<(u32, f64)>| {
        let mut i = start;
        while i < end {
            *iterations += 1;
            if estimate(i) <= 0.0 {
                i = nodes[i].skip as usize;
            } else if nodes[i].leaf != 0 {
                leaves.push((nodes[i].leaf, inv_p));
                i = nodes[i].skip as usize;
            } else {
                i += 1;
            }
        }
    };
    let mut i = 0;
    let mut iterations = 0u32;
    while i < count {
        while leaves.len() >= LEAF_BATCH {
            let mut full: Vec<(u32, f64)> = leaves.drain(..LEAF_BATCH).collect();
            flush(&mut full, &mut out);
        }
        iterations += 1;
        if iterations_so_far(&out, iterations) > allowance {
            // The rest of the tree: the subtrees at i, skip(i), ... ; one by its estimate.
            let (mut total, mut chosen) = (0.0, None);
            let mut j = i;
            while j < count {
                let w = estimate(j);
                total += w;
                if w > 0.0 && rest_key(j) * total < w {
                    chosen = Some((j, w));
                }
                j = nodes[j].skip as usize;
                if j < count {
                    iterations += 1;
                }
            }
            if let Some((j, w)) = chosen {
                let inv_p = total / w;
                let bottom = if is_bottom(j, &nodes[j], settings) {
                    Some((j, inv_p))
                } else {
                    descend(j, inv_p, &mut iterations)
                };
                if let Some((r, inv_p)) = bottom {
                    visit(r, nodes[r].skip as usize, inv_p, &mut iterations, &mut leaves);
                }
            }
            break;
        }
        let node = &nodes[i];
        if estimate(i) <= 0.0 {
            i = node.skip as usize;
        } else if node.leaf != 0 {
            leaves.push((node.leaf, 1.0));
            i = node.skip as usize;
        } else if !is_bottom(i, node, settings) && (node.max - node.min).as_dvec3().length() <= split_size {
            if let Some((r, inv_p)) = descend(i, 1.0, &mut iterations) {
                visit(r, nodes[r].skip as usize, inv_p, &mut iterations, &mut leaves);
            }
            i = node.skip as usize;
        } else {
            i += 1;
        }
    }
    out.iterations += iterations;
    flush(&mut leaves, &mut out);
    out
}

/// Traversal iterations of a query so far (the device's allowance counts both loops).
fn iterations_so_far(out: &Reached, iterations: u32) -> u32 {
    out.iterations + iterations
}

/// Entries of a query's stack (ellipsoid_query.wesl QUERY_STACK).
pub const QUERY_STACK: usize = 32;
/// The largest `bottom_nodes` that takes effect (ellipsoid_query.wesl MAX_BOTTOM_NODES): a
/// subtree visited whole pushes at most that many entries, which the stack must hold.
pub const MAX_BOTTOM_NODES: u32 = 16;

/// What a query's stack entry asks for (ellipsoid_query.wesl TOP, START, BELOW).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Entry {
    /// Visit every child the spheroid may touch (the node's estimate, for the final descent).
    Top(f64),
    /// A descent (or, for a small subtree, a whole visit) starts here (the node's estimate).
    Start(f64),
    /// Within a descent or a whole visit, reached with probability 1 / the value.
    Below(f64),
}

/// [`reached`] over the wide BVH (twin of `query_wide`).
fn reached_wide(scene: QueryScene<'_>, q: &Query, settings: &QuerySettings, allowance: u32, key: [u32; 3]) -> Reached {
    let mut out = Reached::default();
    if q.tau_e <= q.focus_s.distance(q.focus_c) {
        return out;
    }
    let bounds = spheroid_bounds(q);
    let nodes = scene.wide;
    let bottom_nodes = settings.device_bottom_nodes() as usize;
    // Whole visits of small subtrees need the estimates' zeros only, and weigh by the counted
    // area (as the device's `surface_estimate` with `modelled` false); descent steps and
    // top-level visits (whose children's estimates weigh the final descent) use the model.
    let estimates = |n: usize, modelled: bool| -> [f64; WIDTH] {
        std::array::from_fn(|slot| {
            if nodes[n].children[slot] == NONE {
                return 0.0;
            }
            let (lo, hi) = child_box(&nodes[n], slot);
            let surface = &scene.child_surfaces[WIDTH * n + slot];
            let estimate = node_estimate(lo.as_dvec3(), hi.as_dvec3(), surface, q, bounds);
            match modelled {
                true => estimate,
                false if estimate > 0.0 => (if q.lights_only { surface.light_area } else { surface.area }) as f64,
                false => 0.0,
            }
        })
    };
    let (step_key, rest_key) = (|n: usize| step_number(key, n), |n: usize| rest_number(key, n));
    let split_size = settings.split as f64 * 0.5 * q.tau_e;
    let flush = |leaves: &mut Vec<(u32, f64)>, out: &mut Reached| test_leaves(scene, q, settings, leaves, out);
    let mut stack: Vec<(usize, Entry)> = vec![(0, Entry::Top(1.0))];
    let mut leaves: Vec<(u32, f64)> = Vec::new();
    let mut iterations = 0u32;
    while let Some((n, mut entry)) = stack.pop() {
        if leaves.len() > LEAF_BATCH - WIDTH {
            flush(&mut leaves, &mut out);
        }
        iterations += 1;
        if !matches!(entry, Entry::Below(_)) && out.iterations + iterations > allowance {
            // Over the allowance: the subtrees left (this one and the stack's, all at the top
            // level) partition what is left to visit; one is chosen in proportion to its
            // estimate, then descended into.
            let (mut total, mut chosen) = (0.0, None);
            for &(m, e) in std::iter::once(&(n, entry)).chain(stack.iter().rev()) {
                let (Entry::Top(w) | Entry::Start(w)) = e else { unreachable!("below entries are on top") };
                if m != n {
                    iterations += 1;
                }
                total += w;
                // (The first entry is kept whenever its estimate is positive, as u < 1.)
                if w > 0.0 && (m == n || rest_key(m) * total < w) {
                    chosen = Some((m, w));
                }
            }
            stack.clear();
            if let Some((m, w)) = chosen {
                stack.push((m, Entry::Below(total / w)));
            }
            continue;
        }
        let node = &nodes[n];
        let top_fits = stack.len() + WIDTH + bottom_nodes <= QUERY_STACK;
        if matches!(entry, Entry::Top(_)) && !top_fits {
            entry = Entry::Start(0.0);
        }
        let whole = matches!(entry, Entry::Top(_)) || node.subtree as usize <= bottom_nodes;
        let e = estimates(n, !whole || matches!(entry, Entry::Top(_)));
        let inv_p = match entry {
            Entry::Top(_) => {
                for slot in (0..WIDTH).rev() {
                    let child = node.children[slot];
                    if e[slot] <= 0.0 {
                        continue;
                    }
                    if child >= WIDE_LEAF {
                        leaves.push((child, 1.0));
                    } else {
                        let (lo, hi) = child_box(node, slot);
                        let small = ((hi - lo).length() as f64) <= split_size;
                        stack.push((child as usize, if small { Entry::Start(e[slot]) } else { Entry::Top(e[slot]) }));
                    }
                }
                continue;
            }
            Entry::Start(_) => 1.0,
            Entry::Below(inv_p) => inv_p,
        };
        if node.subtree as usize <= bottom_nodes {
            // A small subtree: every child, at the probability it was reached with.
            for slot in (0..WIDTH).rev() {
                let child = node.children[slot];
                if e[slot] <= 0.0 {
                    continue;
                }
                if child >= WIDE_LEAF {
                    leaves.push((child, inv_p));
                } else {
                    stack.push((child as usize, Entry::Below(inv_p)));
                }
            }
            continue;
        }
        // A descent step: one child, in proportion to its estimate.
        let total: f64 = e.iter().sum();
        if total <= 0.0 {
            continue;
        }
        let u = step_key(n) * total;
        let mut cumulative = 0.0;
        let slot = (0..WIDTH)
            .find(|&s| {
                cumulative += e[s];
                u < cumulative
            })
            .unwrap_or_else(|| (0..WIDTH).rev().find(|&s| e[s] > 0.0).unwrap());
        let inv_p = inv_p * total / e[slot];
        let child = node.children[slot];
        if child >= WIDE_LEAF {
            leaves.push((child, inv_p));
        } else {
            stack.push((child as usize, Entry::Below(inv_p)));
        }
    }
    out.iterations += iterations;
    flush(&mut leaves, &mut out);
    out
}

/// The triangle reservoir lane `lane` (0..8) of the device keeps for this query (twin of the
/// reservoirs in `query_ellipsoid`): the last reached triangle t whose number u_t (from pcg4d of
/// the key and t) has u_t x (sum of weights so far) < its weight. None when nothing was reached.
pub fn pick(reached: &Reached, key: [u32; 3], lane: usize) -> Option<u32> {
    let mut sum = 0.0;
    let mut picked = None;
    for &(t, weight) in &reached.triangles {
        sum += weight;
        let h = pcg4d([key[0], key[1], key[2], t]);
        let h = if lane < 4 { h } else { pcg4d(h) };
        if unit_float(h[lane % 4]) * sum < weight {
            picked = Some(t);
        }
    }
    picked
}
