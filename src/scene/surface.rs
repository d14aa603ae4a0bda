//! Surface points of ray hits. CPU twin of `shaders/lib/scene.wesl`.

use glam::{DVec3, Vec2, Vec3};

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

/// Octahedral coordinates of a unit vector (x, y in [-1, 1]): what `triangle_normals` stores.
pub fn octahedral_encode(n: DVec3) -> [f32; 2] {
    let p = n / (n.x.abs() + n.y.abs() + n.z.abs());
    let sign = |v: f64| if v >= 0.0 { 1.0 } else { -1.0 };
    if p.z >= 0.0 {
        [p.x as f32, p.y as f32]
    } else {
        [((1.0 - p.y.abs()) * sign(p.x)) as f32, ((1.0 - p.x.abs()) * sign(p.y)) as f32]
    }
}

/// The unit vector of octahedral coordinates `o` (twin of `octahedral_decode`).
pub fn octahedral_decode(o: [f32; 2]) -> Vec3 {
    let mut n = Vec3::new(o[0], o[1], 1.0 - o[0].abs() - o[1].abs());
    if n.z < 0.0 {
        let sign = |v: f32| if v >= 0.0 { 1.0 } else { -1.0 };
        n = Vec3::new((1.0 - n.y.abs()) * sign(n.x), (1.0 - n.x.abs()) * sign(n.y), n.z);
    }
    n.normalize()
}

/// The unit normal (counter-clockwise winding) of the triangle with vertices `p`, from an f64
/// cross product (exact to rounding for slivers too), in octahedral coordinates.
pub fn triangle_normal(p: [Vec3; 3]) -> [f32; 2] {
    let [a, b, c] = p.map(|v| v.as_dvec3());
    octahedral_encode((b - a).cross(c - a).normalize())
}

/// The surface point of `hit` (twin of `surface_at`; `normals` as `triangle_normals`).
pub fn surface_at(triangles: &[Triangle], shading: &[TriangleShading], normals: &[[f32; 2]], hit: &Hit) -> Surface {
    let tri = &triangles[hit.triangle as usize];
    let sh = &shading[hit.triangle as usize];
    let b0 = 1.0 - hit.b1 - hit.b2;
    let position = tri.v0 + hit.b1 * tri.e1 + hit.b2 * tri.e2;
    let ng = octahedral_decode(normals[hit.triangle as usize]);
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
