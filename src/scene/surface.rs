//! Surface points of ray hits. CPU twin of `shaders/lib/scene.wesl`.

use glam::{Vec2, Vec3};

use crate::gpu::layout::{Hit, SHADING_HAS_NORMALS, Triangle, TriangleShading};

/// A point on the scene's surface (twin of WGSL `Surface`).
#[derive(Clone, Copy, Debug)]
pub struct Surface {
    /// The point (m).
    pub position: Vec3,
    /// Unit normal of the triangle's front face.
    pub geometric_normal: Vec3,
    /// Unit interpolated vertex normal.
    pub shading_normal: Vec3,
    /// Texture coordinates.
    pub uv: Vec2,
    /// Material index.
    pub material: u32,
    /// Light index, or NONE.
    pub light: u32,
}

/// The surface point of `hit` (twin of `surface_at`).
pub fn surface_at(triangles: &[Triangle], shading: &[TriangleShading], hit: &Hit) -> Surface {
    let tri = &triangles[hit.triangle as usize];
    let sh = &shading[hit.triangle as usize];
    let b0 = 1.0 - hit.b1 - hit.b2;
    let position = tri.v0 + hit.b1 * tri.e1 + hit.b2 * tri.e2;
    let ng = tri.e1.cross(tri.e2).normalize();
    let mut ns = ng;
    if sh.flags & SHADING_HAS_NORMALS != 0 {
        let n = b0 * sh.n0 + hit.b1 * sh.n1 + hit.b2 * sh.n2;
        if n.length() > 0.0 {
            ns = n.normalize();
        }
    }
    let uv = b0 * Vec2::new(sh.u0, sh.v0) + hit.b1 * Vec2::new(sh.u1, sh.v1) + hit.b2 * Vec2::new(sh.u2, sh.v2);
    Surface { position, geometric_normal: ng, shading_normal: ns, uv, material: tri.material, light: tri.light }
}

/// Ray origin just off the surface (twin of `offset_ray_origin`).
pub fn offset_ray_origin(p: Vec3, side_normal: Vec3, ray_epsilon: f32) -> Vec3 {
    p + side_normal * (ray_epsilon + 4e-6 * p.abs().max_element())
}
