//! A scene in the kernels' layout: triangles and shading in BVH order, the flattened BVH,
//! materials, textures and lights. CPU twins and tests read the same arrays the GPU gets.

use anyhow::Result;
use rayon::prelude::*;

use super::lights::LightTable;
use super::materials::gpu_materials_and_textures;
use super::{Scene, TriangleBounds};
use crate::bvh::Bvh;
use crate::bvh::wide::WideBvh;
use crate::gpu::layout::{
    MATERIAL_DIELECTRIC, MATERIAL_NULL, MATERIAL_PLASTIC, MATERIAL_ROUGH, Material, NONE, NodeSurface,
    SHADING_HAS_NORMALS, TextureInfo, Triangle, TriangleShading,
};

/// Everything the kernels read about a scene.
#[derive(Clone, Debug)]
pub struct PreparedScene {
    /// The scene as loaded.
    pub scene: Scene,
    /// Its BVH.
    pub bvh: Bvh,
    /// The wide BVH that rays traverse, collapsed from `bvh` (same leaves and triangle order).
    pub wide: WideBvh,
    /// Triangles in BVH order.
    pub triangles: Vec<Triangle>,
    /// Per BVH node: the area and spread of its triangles, see `Bvh::node_surfaces`.
    pub node_surfaces: Vec<NodeSurface>,
    /// Per wide BVH node and slot (`4 node + slot`): the same of the child's triangles, see
    /// `WideBvh::child_surfaces` (queries over the wide BVH, `QuerySettings::wide`).
    pub child_surfaces: Vec<NodeSurface>,
    /// Per triangle (BVH order): unit normal from an f64 cross product, octahedral
    /// (`surface::triangle_normal`).
    pub normals: Vec<[f32; 2]>,
    /// Shading attributes in BVH order.
    pub shading: Vec<TriangleShading>,
    /// GPU materials.
    pub materials: Vec<Material>,
    /// Where each texture lies in `texels`.
    pub texture_infos: Vec<TextureInfo>,
    /// All texels, two pack2x16float words each.
    pub texels: Vec<[u32; 2]>,
    /// Lights and their selection CDF.
    pub lights: LightTable,
    /// Ray-origin offset scale (m), 1e-6 of the extent of the scene's triangles.
    pub ray_epsilon: f32,
    /// The key of the scene's arrays on a device ([`UploadId`]).
    upload_id: UploadId,
    /// The bounds of its triangles and lights (`Scene::triangle_bounds`), which every tracer
    /// asks for.
    pub triangle_bounds: TriangleBounds,
}

/// A number unique to each [`PreparedScene`] of the process, under which a device keeps the
/// scene's arrays once uploaded (`integrator::upload::scene_buffers`), so that every tracer of
/// the scene on that device binds the same buffers. A clone gets a number of its own. The
/// arrays of a scene must not change once it has been rendered: tracers built later would read
/// the arrays as first uploaded.
#[derive(Debug)]
pub struct UploadId(u64);

impl UploadId {
    fn fresh() -> Self {
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
        Self(NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed))
    }
}

impl Clone for UploadId {
    /// A new number: a clone's arrays may be changed before it is rendered.
    fn clone(&self) -> Self {
        Self::fresh()
    }
}

impl PreparedScene {
    /// Builds the BVH, reorders the triangles into its leaves and builds the light table.
    pub fn new(scene: Scene) -> Result<Self> {
        let positions: Vec<_> = scene.triangles.iter().map(|t| t.positions).collect();
        let bvh = Bvh::build(&positions);
        let position_of = bvh.positions();
        let triangle_bounds = scene.triangle_bounds();
        let lights = LightTable::build(&scene, &position_of, &triangle_bounds);
        let mut light_of_triangle = vec![NONE; scene.triangles.len()];
        for (l, &src) in lights.source_triangle.iter().enumerate() {
            if src != NONE {
                light_of_triangle[src as usize] = l as u32;
            }
        }
        // Each triangle in BVH order on every core (each entry a function of its triangle alone).
        let (triangles, (normals, shading)): (Vec<_>, (Vec<_>, Vec<_>)) = bvh
            .order
            .par_iter()
            .map(|&i| {
                let t = &scene.triangles[i as usize];
                let [a, b, c] = t.positions;
                let geometric = super::surface::triangle_normal(t.positions);
                let triangle = Triangle {
                    v0: a,
                    material: t.material,
                    e1: b - a,
                    light: light_of_triangle[i as usize],
                    e2: c - a,
                    source: i,
                };
                let n = t.normals.unwrap_or([(b - a).cross(c - a).normalize(); 3]);
                let shading = TriangleShading {
                    n0: n[0],
                    u0: t.uvs[0].x,
                    n1: n[1],
                    v0: t.uvs[0].y,
                    n2: n[2],
                    u1: t.uvs[1].x,
                    v1: t.uvs[1].y,
                    u2: t.uvs[2].x,
                    v2: t.uvs[2].y,
                    flags: match t.normals {
                        Some(n) if !normals_are_flat(n, super::surface::octahedral_decode(geometric)) => {
                            SHADING_HAS_NORMALS
                        }
                        _ => 0,
                    },
                };
                (triangle, (geometric, shading))
            })
            .unzip();
        let (materials, texture_infos, texels) = gpu_materials_and_textures(&scene);
        let ray_epsilon = 1e-6 * triangle_bounds.extent();
        let wide = WideBvh::build(&bvh);
        let sums = bvh.surface_sums(&triangles);
        let node_surfaces = bvh.node_surfaces(&sums);
        let child_surfaces = wide.child_surfaces(&sums);
        drop(sums);
        Ok(Self {
            materials,
            scene,
            bvh,
            wide,
            triangles,
            node_surfaces,
            child_surfaces,
            normals,
            shading,
            texture_infos,
            texels,
            lights,
            ray_epsilon,
            upload_id: UploadId::fresh(),
            triangle_bounds,
        })
    }

    /// `Scene::path_length_bounds` from the bounds kept at preparation.
    pub fn path_length_bounds(&self, max_bounces: u32) -> (f32, f32) {
        self.scene.path_length_bounds_with(&self.triangle_bounds, max_bounces)
    }

    /// `Scene::finite_longest_path` from the bounds kept at preparation.
    pub fn finite_longest_path(&self, max_bounces: u32) -> f32 {
        self.scene.finite_longest_path_with(&self.triangle_bounds, max_bounces)
    }

    /// `Scene::light_bounds` from the bounds kept at preparation.
    pub fn light_bounds(&self) -> (glam::Vec3, glam::Vec3) {
        self.scene.light_bounds_with(&self.triangle_bounds)
    }

    /// `Scene::bounds` from the bounds kept at preparation.
    pub fn bounds(&self) -> (glam::Vec3, glam::Vec3) {
        self.scene.bounds_with(&self.triangle_bounds)
    }

    /// The key of the scene's arrays on a device, unique to this scene in the process
    /// ([`UploadId`]).
    pub fn upload_id(&self) -> u64 {
        self.upload_id.0
    }

    /// True when some triangle has vertex normals that differ from its geometric normal
    /// (SHADING_HAS_NORMALS): else the kernels never read the shading normals.
    pub fn has_shading_normals(&self) -> bool {
        self.shading.iter().any(|s| s.flags & SHADING_HAS_NORMALS != 0)
    }

    /// True when some material has a base-colour texture or a plastic's transmittance table.
    pub fn has_textures(&self) -> bool {
        !self.texture_infos.is_empty()
    }

    /// True when some material has a conductor lobe (metallic > 0).
    pub fn has_glossy(&self) -> bool {
        self.materials.iter().any(|m| m.metallic > 0.0)
    }

    /// True when some material is a plastic ([`MATERIAL_PLASTIC`]).
    pub fn has_plastic(&self) -> bool {
        self.materials.iter().any(|m| m.flags & MATERIAL_PLASTIC != 0)
    }

    /// True when some material is a dielectric ([`MATERIAL_DIELECTRIC`]), smooth or rough.
    pub fn has_dielectric(&self) -> bool {
        self.materials.iter().any(|m| m.flags & MATERIAL_DIELECTRIC != 0)
    }

    /// True when some material is a null surface ([`MATERIAL_NULL`]: a boundary of media only),
    /// which closest hits treat specially (`bvh.wesl` NULL_SURFACES).
    pub fn has_null_surfaces(&self) -> bool {
        self.materials.iter().any(|m| m.flags & MATERIAL_NULL != 0)
    }

    /// True when some material is a rough dielectric ([`MATERIAL_ROUGH`]): `ellipsoidal` alone does
    /// not render it.
    pub fn has_rough_dielectric(&self) -> bool {
        self.materials.iter().any(|m| m.flags & MATERIAL_ROUGH != 0)
    }

    /// True when the scene has point lights.
    pub fn has_point_lights(&self) -> bool {
        !self.scene.point_lights.is_empty()
    }
}

/// Whether a triangle's vertex normals all equal its geometric normal to f32 precision (flat
/// shading, as in most CAD and box scenes): interpolating them gives the geometric normal back,
/// so the triangle is shaded without them.
fn normals_are_flat(normals: [glam::Vec3; 3], geometric: glam::Vec3) -> bool {
    normals.iter().all(|n| (n.normalize_or_zero() - geometric).abs().max_element() <= 4.0 * f32::EPSILON)
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    /// Vertex normals equal to the geometric normal (any length) are flat; one tilted by
    /// 1e-3 rad is not.
    #[test]
    fn flat_normals_are_recognised() {
        let up = Vec3::Y;
        assert!(super::normals_are_flat([up, 2.0 * up, up], up));
        let tilted = Vec3::new(1e-3, 1.0, 0.0).normalize();
        assert!(!super::normals_are_flat([up, up, tilted], up));
        assert!(!super::normals_are_flat([-up, -up, -up], up));
    }
}
