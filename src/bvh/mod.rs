//! The BVH: built on the host with obvhs (PLOC with reinsertion and an SAH leaf collapse), then
//! flattened into the stackless layout every traversal uses (DESIGN.md section 6): nodes in
//! depth-first order, an inner node's first child right after it, and a `skip` link from every
//! node to the first node after its subtree. Triangles are reordered so each leaf addresses a
//! contiguous range.

pub mod traverse;

use glam::Vec3;
use obvhs::{BvhBuildParams, triangle::Triangle as ObvhsTriangle};

use crate::gpu::layout::{BvhNode, MAX_LEAF_TRIANGLES};

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
        let tris: Vec<ObvhsTriangle> = triangles
            .iter()
            .map(|t| ObvhsTriangle { v0: t[0].into(), v1: t[1].into(), v2: t[2].into() })
            .collect();
        let params = BvhBuildParams { max_prims_per_leaf: 4, ..BvhBuildParams::medium_build() };
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

    /// `position[i]` = BVH position of input triangle `i` (inverse of `order`).
    pub fn positions(&self) -> Vec<u32> {
        let mut position = vec![0u32; self.order.len()];
        for (p, &i) in self.order.iter().enumerate() {
            position[i as usize] = p as u32;
        }
        position
    }
}
