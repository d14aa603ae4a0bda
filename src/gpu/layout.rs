//! The single home of the `#[repr(C)]` structs shared with WGSL.
//!
//! Keep in sync with `shaders/lib/layout.wesl`: `tests/layout.rs` reflects the WGSL with naga and
//! checks every member offset and struct size against these definitions.
//! Units: metres, optical path length in metres, radiance W m^-2 sr^-1, intensity W sr^-1.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// "No triangle / light / texture" in index fields (WGSL `NONE`).
pub const NONE: u32 = u32::MAX;
pub const SHADING_HAS_NORMALS: u32 = 1;
pub const MATERIAL_DOUBLE_SIDED: u32 = 1;
pub const MATERIAL_EMISSIVE: u32 = 2;
pub const TEXTURE_CLAMP_U: u32 = 1;
pub const TEXTURE_CLAMP_V: u32 = 2;
pub const LIGHT_AREA: u32 = 0;
pub const LIGHT_POINT: u32 = 1;
pub const LIGHT_DOUBLE_SIDED: u32 = 1;
/// Largest triangle count a BVH leaf can hold (4 bits of `BvhNode::leaf`).
pub const MAX_LEAF_TRIANGLES: u32 = 15;
/// Largest triangle index a BVH leaf can address (28 bits of `BvhNode::leaf`).
pub const MAX_TRIANGLES: u32 = (1 << 28) - 1;

/// One triangle in BVH leaf order: vertex 0 and the edges to vertices 1 and 2 (m).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Triangle {
    pub v0: Vec3,
    /// Index into the material table.
    pub material: u32,
    pub e1: Vec3,
    /// Index into the light table, or [`NONE`].
    pub light: u32,
    pub e2: Vec3,
    /// Index of the triangle in load order.
    pub source: u32,
}

/// Vertex normals (unit, world space) and texture coordinates of a triangle.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct TriangleShading {
    pub n0: Vec3,
    pub u0: f32,
    pub n1: Vec3,
    pub v0: f32,
    pub n2: Vec3,
    pub u1: f32,
    pub v1: f32,
    pub u2: f32,
    pub v2: f32,
    /// [`SHADING_HAS_NORMALS`].
    pub flags: u32,
}

/// A node of the stackless BVH (depth-first order, `skip` = first node after the subtree).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct BvhNode {
    pub min: Vec3,
    pub skip: u32,
    pub max: Vec3,
    /// 0 for an inner node; for a leaf `(count << 28) | first`.
    pub leaf: u32,
}

impl BvhNode {
    pub fn leaf_range(&self) -> Option<std::ops::Range<u32>> {
        (self.leaf != 0).then(|| {
            let first = self.leaf & MAX_TRIANGLES;
            first..first + (self.leaf >> 28)
        })
    }
}

/// A surface material; this version shades the Lambertian lobe with albedo `base_color`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Material {
    /// Linear RGB albedo (times the texture when `base_color_texture` is not [`NONE`]).
    pub base_color: Vec3,
    pub base_color_texture: u32,
    /// Emitted radiance (W m^-2 sr^-1).
    pub emission: Vec3,
    /// [`MATERIAL_DOUBLE_SIDED`], [`MATERIAL_EMISSIVE`].
    pub flags: u32,
    pub metallic: f32,
    pub roughness: f32,
    pub reserved0: u32,
    pub reserved1: u32,
}

/// Where one texture's texels lie in the texel buffer.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct TextureInfo {
    pub offset: u32,
    pub width: u32,
    pub height: u32,
    /// [`TEXTURE_CLAMP_U`] | [`TEXTURE_CLAMP_V`].
    pub wrap: u32,
}

/// An area light (one emissive triangle) or a point light.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Light {
    /// Point light position (m).
    pub position: Vec3,
    /// [`LIGHT_AREA`] or [`LIGHT_POINT`].
    pub kind: u32,
    /// Radiance (area, W m^-2 sr^-1) or intensity (point, W sr^-1).
    pub emission: Vec3,
    /// Emitting triangle (BVH order) or [`NONE`].
    pub triangle: u32,
    /// Triangle area (m^2).
    pub area: f32,
    /// Probability that light sampling picks this light.
    pub select_pdf: f32,
    /// [`LIGHT_DOUBLE_SIDED`].
    pub flags: u32,
    pub reserved: u32,
}

/// Pinhole camera in world space.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Camera {
    /// Pinhole position (m).
    pub position: Vec3,
    /// tan(yfov / 2).
    pub tan_half_fov_y: f32,
    pub right: Vec3,
    /// Width / height.
    pub aspect: f32,
    pub up: Vec3,
    pub reserved0: u32,
    pub forward: Vec3,
    pub reserved1: u32,
}

/// Pathlength importance parameters; see `shaders/lib/layout.wesl` for the meaning per kind.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Gate {
    pub bins: u32,
    pub table_len: u32,
    pub reserved0: u32,
    pub reserved1: u32,
    pub p0: f32,
    pub p1: f32,
    /// Upper end of the support (m); `f32::MAX` when unbounded.
    pub max_length: f32,
    pub reserved2: f32,
}

/// Settings that hold for a whole render.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct RenderParams {
    pub camera: Camera,
    pub gate: Gate,
    pub width: u32,
    pub height: u32,
    pub seed: u32,
    pub max_bounces: u32,
    /// Russian roulette starts at this depth ([`NONE`]: never).
    pub rr_depth: u32,
    pub light_count: u32,
    pub node_count: u32,
    pub triangle_count: u32,
    /// Ray-origin offset scale (m).
    pub ray_epsilon: f32,
    pub reserved0: u32,
    pub reserved1: u32,
    pub reserved2: u32,
}

/// Settings of one wave of samples.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct WaveParams {
    pub sample_base: u32,
    pub samples: u32,
    pub slot_count: u32,
    pub reserved: u32,
}

/// State of one path between wavefront stages.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct PathState {
    pub origin: Vec3,
    /// Optical path length from the pinhole to `origin` (m).
    pub path_length: f32,
    pub direction: Vec3,
    /// Solid-angle pdf of `direction` (sr^-1); 0 for camera rays.
    pub bsdf_pdf: f32,
    pub throughput: Vec3,
    pub depth: u32,
    pub pixel: u32,
    pub rng: u32,
    pub origin_triangle: u32,
    pub reserved: u32,
}

/// Closest hit of a ray.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Hit {
    /// Distance along the unit direction (m).
    pub t: f32,
    /// Triangle (BVH order) or [`NONE`].
    pub triangle: u32,
    pub b1: f32,
    pub b2: f32,
}

/// A queued next-event shadow ray.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct ShadowRay {
    pub origin: Vec3,
    pub t_max: f32,
    pub direction: Vec3,
    pub slot: u32,
    pub ignore0: u32,
    pub ignore1: u32,
    pub reserved0: u32,
    pub reserved1: u32,
}

/// A radiance contribution and the optical path length it belongs to.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Contribution {
    pub radiance: Vec3,
    pub path_length: f32,
}

/// Queue lengths of a wavefront round (atomics in WGSL).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct QueueCounters {
    pub rays: u32,
    pub next_rays: u32,
    pub shadow_rays: u32,
    pub reserved: u32,
}

/// `shaders/lib/layout.wesl` composed to WGSL by the build script (for the layout test).
pub const LAYOUT_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/layout.wgsl"));
