//! Warps of uniform numbers and the MIS heuristic. CPU twin of `shaders/lib/sampling.wesl`.

use glam::{Vec2, Vec3};

/// Orthonormal basis (t, b, n) around the unit vector `n` (Duff et al. 2017).
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    /// First tangent.
    pub t: Vec3,
    /// Second tangent.
    pub b: Vec3,
    /// The normal.
    pub n: Vec3,
}

impl Frame {
    /// The frame around unit vector `n` (twin of `frame_from_normal`).
    pub fn from_normal(n: Vec3) -> Self {
        let sign = if n.z >= 0.0 { 1.0 } else { -1.0 };
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        Self {
            t: Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
            b: Vec3::new(b, sign + n.y * n.y * a, -n.y),
            n,
        }
    }

    /// Local coordinates (x along t, y along b, z along n) to world space (twin of `frame_to_world`).
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.t * v.x + self.b * v.y + self.n * v.z
    }

    /// World-space vector to local coordinates (twin of `frame_to_local`).
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.t), v.dot(self.b), v.dot(self.n))
    }
}

/// Cosine-weighted direction about +z; pdf = z / pi (sr^-1).
pub fn sample_cosine_hemisphere(u: Vec2) -> Vec3 {
    let r = u.x.sqrt();
    let phi = 2.0 * std::f32::consts::PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), (1.0 - u.x).max(0.0).sqrt())
}

/// Uniform point of the unit disk (polar mapping); pdf = 1 / pi (twin of `sample_disk`).
pub fn sample_disk(u: Vec2) -> Vec2 {
    let r = u.x.sqrt();
    let phi = 2.0 * std::f32::consts::PI * u.y;
    Vec2::new(r * phi.cos(), r * phi.sin())
}

/// Uniform point on a triangle as barycentrics (b1, b2) of v1 and v2; pdf = 1 / area.
pub fn sample_triangle_barycentrics(u: Vec2) -> Vec2 {
    let su = u.x.sqrt();
    Vec2::new(u.y * su, (1.0 - u.y) * su)
}

/// Power heuristic (beta = 2) from the ratio of the pdfs, so huge pdfs do not overflow
/// (twin of `power_heuristic`).
pub fn power_heuristic(a: f32, b: f32) -> f32 {
    let (pa, pb) = (a.min(f32::MAX), b.min(f32::MAX));
    if pa <= 0.0 {
        return 0.0;
    }
    let r = pa.min(pb) / pa.max(pb);
    let w_larger = 1.0 / (1.0 + r * r);
    if pa >= pb { w_larger } else { r * r * w_larger }
}
