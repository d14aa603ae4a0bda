//! The BVHs: a binary one built on the host with obvhs (PLOC with reinsertion and an SAH leaf
//! collapse, on every core; the same tree on any number of them), flattened into the stackless
//! layout the ellipsoid queries walk (docs/design.md section 6.1): nodes in depth-first order,
//! an inner node's first child right after it, and a `skip` link from every node to the first
//! node after its subtree. Triangles are reordered so each leaf addresses a contiguous range.
//! Rays traverse the four-wide BVH collapsed from it (`wide`), which keeps its leaves; so can
//! the ellipsoid queries (`QuerySettings::wide`).

pub mod traverse;
pub mod wide;

use glam::{DMat3, DVec3, Vec3};
use obvhs::{BvhBuildParams, triangle::Triangle as ObvhsTriangle};
use rayon::prelude::*;

use crate::gpu::layout::{BvhNode, MAX_LEAF_TRIANGLES, NONE, NodeSurface, Triangle};
use crate::gpu::packing::pack2x16float;

/// Scenes of at most this many triangles are not traversed: every ray tests all of them (read
/// from a uniform buffer once per invocation, see shaders/lib/bvh.wesl `load_small_scene` and the
/// override SMALL_SCENE_TRIANGLES in bindings.wesl), which costs less than the BVH's box tests
/// and per-ray node loads at such sizes (measured on the Cornell box, 12 triangles). The length
/// of the WGSL arrays `small_scene_triangles`, `small_scene_shading` and `small_scene_normals`
/// (bindings.wesl).
pub const MAX_SMALL_SCENE_TRIANGLES: usize = 16;

/// The triangles the traversals test one by one (BVH order): all of them for a scene of at most
/// MAX_SMALL_SCENE_TRIANGLES, else none (the BVH is traversed).
pub fn small_scene_triangles(triangles: &[Triangle]) -> &[Triangle] {
    if triangles.len() <= MAX_SMALL_SCENE_TRIANGLES { triangles } else { &[] }
}

/// Scenes of at most this many triangles get leaves of at most 3 triangles, larger ones leaves
/// of at most 4. Smaller leaves made `path` up to 10 % and `ellipsoidal` up to 14 % faster
/// (docs/benchmarks.md, "How the BVH is built"), for about 20 % more wide nodes: at 10M
/// triangles those would overflow a 128 MiB storage binding (lavapipe's cap), which leaves
/// of 4 keep below it.
pub const SMALL_LEAVES_UP_TO: usize = 6_000_000;

/// The most triangles a leaf of the BVH of `triangles` triangles holds (see
/// [`SMALL_LEAVES_UP_TO`]).
pub fn leaf_triangles(triangles: usize) -> u32 {
    if triangles <= SMALL_LEAVES_UP_TO { 3 } else { 4 }
}

/// A flattened BVH over a triangle list.
#[derive(Clone, Debug)]
pub struct Bvh {
    /// Nodes in depth-first order with skip links.
    pub nodes: Vec<BvhNode>,
    /// `order[i]` = input index of the triangle at BVH position `i`.
    pub order: Vec<u32>,
}

impl Bvh {
    /// Builds the BVH of `triangles` (vertex positions, m).
    pub fn build(triangles: &[[Vec3; 3]]) -> Self {
        assert!(!triangles.is_empty(), "a BVH needs at least one triangle");
        let tris: Vec<ObvhsTriangle> =
            triangles.iter().map(|t| ObvhsTriangle { v0: t[0].into(), v1: t[1].into(), v2: t[2].into() }).collect();
        // A quarter of the nodes weighed for reinsertion (obvhs's medium build weighs 5 %): on the
        // fence's chain-link slivers `path` ran 12-14 % faster, `direct` 6-10 %, for 1.55 times
        // the build (docs/benchmarks.md, "How the BVH is built"); a whole pass (1.0) gained
        // little more for 4 times the build and slowed the ellipsoid queries 5-7 %.
        let params = BvhBuildParams {
            max_prims_per_leaf: leaf_triangles(triangles.len()),
            reinsertion_batch_ratio: 0.25,
            ..BvhBuildParams::medium_build()
        };
        let bvh2 = obvhs::bvh2::builder::build_bvh2_from_tris(&tris, params, &mut Default::default());
        let mut out = Bvh { nodes: Vec::with_capacity(bvh2.nodes.len()), order: Vec::with_capacity(triangles.len()) };
        out.flatten(&bvh2, 0);
        debug_assert_eq!(out.order.len(), triangles.len());
        out
    }

    fn flatten(&mut self, bvh2: &obvhs::bvh2::Bvh2, id: usize) {
        let node = &bvh2.nodes[id];
        let me = self.nodes.len();
        self.nodes.push(BvhNode { min: node.aabb.min.into(), max: node.aabb.max.into(), ..Default::default() });
        if node.is_leaf() {
            assert!(node.prim_count <= MAX_LEAF_TRIANGLES, "BVH leaf of {} triangles", node.prim_count);
            let first = self.order.len() as u32;
            for k in 0..node.prim_count {
                self.order.push(bvh2.primitive_indices[(node.first_index + k) as usize]);
            }
            self.nodes[me].leaf = (node.prim_count << 28) | first;
        } else {
            self.flatten(bvh2, node.first_index as usize);
            self.flatten(bvh2, node.first_index as usize + 1);
        }
        self.nodes[me].skip = self.nodes.len() as u32;
    }

    /// Per node, the area of the triangles below it, of the emitting ones among them, and the
    /// centroid and covariance of a point drawn uniformly on them (`NodeSurface`), from the
    /// nodes' [`Bvh::surface_sums`]: what the ellipsoid queries' stochastic descent weighs
    /// children by (shaders/lib/ellipsoid_query.wesl `node_estimate`).
    pub fn node_surfaces(&self, sums: &[SurfaceSums]) -> Vec<NodeSurface> {
        sums.par_iter().zip(&self.nodes).map(|(s, node)| s.surface(node.min.as_dvec3(), node.max.as_dvec3())).collect()
    }

    /// Per node, the area of the triangles below it, of the emitting ones among them, and their
    /// area-weighted first and second moments of position, for `triangles` in BVH order, summed
    /// in f64: what [`Bvh::node_surfaces`] and `WideBvh::child_surfaces` are made from.
    pub fn surface_sums(&self, triangles: &[Triangle]) -> Vec<SurfaceSums> {
        // The leaves on every core (each leaf's triangles in order, so the sums are the same
        // however many threads run) ...
        let mut sums: Vec<SurfaceSums> = self
            .nodes
            .par_iter()
            .map(|node| match node.leaf_range() {
                Some(range) => range.fold(SurfaceSums::ZERO, |s, k| {
                    let t = &triangles[k as usize];
                    let a = t.v0.as_dvec3();
                    let (b, c) = (a + t.e1.as_dvec3(), a + t.e2.as_dvec3());
                    let area = 0.5 * t.e1.as_dvec3().cross(t.e2.as_dvec3()).length();
                    // A uniform point of triangle abc: E[x] = (a + b + c) / 3 and
                    // E[x x^T] = (a a^T + b b^T + c c^T + (a + b + c)(a + b + c)^T) / 12.
                    let sum = a + b + c;
                    SurfaceSums {
                        area: s.area + area,
                        light_area: s.light_area + if t.light == NONE { 0.0 } else { area },
                        first: s.first + area / 3.0 * sum,
                        second: s.second + (outer(a) + outer(b) + outer(c) + outer(sum)) * (area / 12.0),
                    }
                }),
                None => SurfaceSums::ZERO,
            })
            .collect();
        // ... then the inner nodes: children follow their parent in depth-first order, so fill
        // from the back.
        for i in (0..self.nodes.len()).rev() {
            if self.nodes[i].leaf_range().is_none() {
                let (a, b) = (sums[i + 1], sums[self.nodes[i + 1].skip as usize]);
                sums[i] = SurfaceSums {
                    area: a.area + b.area,
                    light_area: a.light_area + b.light_area,
                    first: a.first + b.first,
                    second: a.second + b.second,
                };
            }
        }
        sums
    }

    /// `position[i]` = BVH position of input triangle `i` (inverse of `order`).
    pub fn positions(&self) -> Vec<u32> {
        let mut position = vec![0u32; self.order.len()];
        for (p, &i) in self.order.iter().enumerate() {
            position[i as usize] = p as u32;
        }
        position
    }
}

fn outer(v: DVec3) -> DMat3 {
    DMat3::from_cols(v * v.x, v * v.y, v * v.z)
}

/// The area, emitting area and area-weighted first and second moments of position of the
/// triangles below a node (m^2, m^2, m^3, m^4), summed in f64 (`Bvh::surface_sums`).
#[derive(Clone, Copy, Debug)]
pub struct SurfaceSums {
    /// Total area (m^2).
    pub area: f64,
    /// Total area of the emitting triangles (m^2).
    pub light_area: f64,
    /// Sum of area times the mean position (m^3).
    pub first: DVec3,
    /// Sum of area times the mean of x x^T (m^4).
    pub second: DMat3,
}

impl SurfaceSums {
    // (Not derived: glam's default matrix is the identity.)
    const ZERO: Self = Self { area: 0.0, light_area: 0.0, first: DVec3::ZERO, second: DMat3::ZERO };

    /// The `NodeSurface` of these triangles in a box [lo, hi] (m) that holds them: the
    /// covariance is stored over the box's squared diagonal.
    pub fn surface(&self, lo: DVec3, hi: DVec3) -> NodeSurface {
        if self.area <= 0.0 {
            return NodeSurface {
                centroid: (0.5 * (lo + hi)).as_vec3(),
                light_area: self.light_area as f32,
                ..Default::default()
            };
        }
        let mean = self.first / self.area;
        let m = self.second * (1.0 / self.area) - outer(mean);
        let scale = 1.0 / (hi - lo).length_squared().max(f64::MIN_POSITIVE);
        let w = |a: f64, b: f64| pack2x16float((a * scale) as f32, (b * scale) as f32);
        NodeSurface {
            centroid: mean.as_vec3(),
            area: self.area as f32,
            light_area: self.light_area as f32,
            spread: [w(m.x_axis.x, m.y_axis.y), w(m.z_axis.z, m.y_axis.x), w(m.z_axis.x, m.z_axis.y)],
        }
    }
}
