//! The light table and light sampling. CPU twin of `shaders/lib/lights.wesl`.
//!
//! Every emissive triangle is an area light and every KHR_lights_punctual point or spot light a
//! point light (a spot's cone shapes its intensity), every directional light a plane wave;
//! next-event estimation picks one with probability proportional to its power.

use glam::{Vec2, Vec3};

use super::{Scene, TriangleBounds, medium};
use crate::gpu::layout::{
    LIGHT_AREA, LIGHT_DIRECTIONAL, LIGHT_DOUBLE_SIDED, LIGHT_MEDIUM_SHIFT, LIGHT_POINT, LIGHT_SPOT_LINEAR_IN_ANGLE,
    Light, NONE, Triangle, VERTEX_IOR_SHIFT,
};
use crate::sampling::sample_triangle_barycentrics;

/// Where light `l` (from scene triangle `source`, or NONE) stands: the media on its front and back,
/// and the index of refraction there. An area light whose material declares media has those (its
/// exterior in front); otherwise the medium found at a point just off each face
/// ([`medium::medium_at`]). A point light's are both the medium at its position; a directional
/// light's the camera's. The index is that of glass the light lies inside
/// ([`medium::index_of_refraction_at`], in front of an area light), 1 elsewhere.
fn light_space(scene: &Scene, l: &Light, source: u32) -> (Option<u32>, Option<u32>, f32) {
    match l.kind {
        LIGHT_AREA => {
            let t = &scene.triangles[source as usize];
            let [a, b, c] = t.positions;
            let n = (b - a).cross(c - a).normalize_or_zero();
            let centre = (a + b + c) / 3.0;
            let offset = 1e-4 * (1.0 + centre.abs().max_element());
            let (front, back) = (centre + offset * n, centre - offset * n);
            let ior = medium::index_of_refraction_at(scene, front);
            let media = scene.materials[t.material as usize].media;
            if media != medium::MediumInterface::default() {
                return (media.exterior, media.interior, ior);
            }
            (medium::medium_at(scene, front), medium::medium_at(scene, back), ior)
        }
        LIGHT_POINT => {
            let m = medium::medium_at(scene, l.position);
            (m, m, medium::index_of_refraction_at(scene, l.position))
        }
        _ => (scene.camera_medium, scene.camera_medium, 1.0),
    }
}

/// Lights with their selection CDF.
#[derive(Clone, Debug, Default)]
pub struct LightTable {
    /// The lights, area lights first.
    pub lights: Vec<Light>,
    /// cdf[i] = P(pick a light with index <= i); the last entry is 1.
    pub cdf: Vec<f32>,
    /// For each light, the scene triangle (load order) it comes from, or NONE.
    pub source_triangle: Vec<u32>,
    /// In scenes with media: a double-sided area light has different media on its two faces
    /// (its light subpaths would start in either; bidirectional methods refuse the scene).
    pub two_sided_media: bool,
}

impl LightTable {
    /// Builds the table; `bvh_position[i]` is where scene triangle `i` lies in BVH order, and
    /// `triangles` the scene's [`TriangleBounds`] (directional lights start on its bounding
    /// sphere).
    pub fn build(scene: &Scene, bvh_position: &[u32], triangles: &TriangleBounds) -> Self {
        let mut lights = Vec::new();
        let mut source_triangle = Vec::new();
        let mut power = Vec::new();
        for (i, t) in scene.triangles.iter().enumerate() {
            let m = &scene.materials[t.material as usize];
            if !m.is_emissive() {
                continue;
            }
            let area = t.area();
            let sides = if m.double_sided { 2.0 } else { 1.0 };
            power.push(sides * std::f64::consts::PI * area as f64 * mean(m.emission));
            lights.push(Light {
                kind: LIGHT_AREA,
                emission: m.emission,
                triangle: bvh_position[i],
                area,
                flags: if m.double_sided { LIGHT_DOUBLE_SIDED } else { 0 },
                ..Default::default()
            });
            source_triangle.push(i as u32);
        }
        for p in &scene.point_lights {
            // A point light is a spot whose cone is the whole sphere.
            let (direction, cos_outer, cos_inner) = match p.spot {
                Some(s) => (s.direction, s.outer.cos(), s.inner.cos()),
                None => (Vec3::Z, -1.0, -1.0),
            };
            let linear = p.spot.is_some_and(|s| s.falloff == crate::scene::SpotFalloff::LinearInAngle);
            // Power over the cone, the falloff's ramp counted as half (4 pi I for a point).
            let solid_angle = 2.0 * std::f64::consts::PI * (1.0 - 0.5 * (cos_outer as f64 + cos_inner as f64));
            power.push(solid_angle * mean(p.intensity));
            lights.push(Light {
                position: p.position,
                kind: LIGHT_POINT,
                emission: p.intensity,
                triangle: NONE,
                direction,
                cos_outer,
                cos_inner,
                flags: if linear { LIGHT_SPOT_LINEAR_IN_ANGLE } else { 0 },
                ..Default::default()
            });
            source_triangle.push(NONE);
        }
        let (centre, radius) = scene.bounding_sphere_with(triangles);
        for l in &scene.directional_lights {
            // Light subpaths start on the disk where the plane wave enters the bounding sphere.
            let disk = std::f32::consts::PI * radius * radius;
            power.push(disk as f64 * mean(l.irradiance));
            lights.push(Light {
                position: centre,
                kind: LIGHT_DIRECTIONAL,
                emission: l.irradiance,
                triangle: NONE,
                direction: l.direction,
                area: disk,
                cos_outer: -1.0,
                cos_inner: -1.0,
                ..Default::default()
            });
            source_triangle.push(NONE);
        }
        let total: f64 = power.iter().sum();
        if total <= 0.0 {
            power.iter_mut().for_each(|p| *p = 1.0);
        }
        let total: f64 = power.iter().sum();
        let mut cdf = Vec::with_capacity(power.len());
        let mut acc = 0.0;
        for (l, p) in lights.iter_mut().zip(&power) {
            acc += p;
            cdf.push((acc / total) as f32);
            l.select_pdf = (p / total) as f32;
        }
        if let Some(last) = cdf.last_mut() {
            *last = 1.0;
        }
        let mut two_sided_media = false;
        let glass = scene.materials.iter().any(|m| m.dielectric.is_some_and(|d| !d.thin));
        if scene.has_media() || glass {
            for (l, &source) in lights.iter_mut().zip(&source_triangle) {
                let (front, back, ior) = light_space(scene, l, source);
                two_sided_media |= l.flags & LIGHT_DOUBLE_SIDED != 0 && front != back;
                l.flags |= front.map_or(0, |m| (m + 1) << LIGHT_MEDIUM_SHIFT) | ior_bits(ior);
            }
        }
        Self { lights, cdf, source_triangle, two_sided_media }
    }

    /// Index of the light whose CDF interval holds `u` in [0, 1) (as `select_light` in WGSL).
    pub fn select(&self, u: f32) -> usize {
        let (mut lo, mut hi) = (0usize, self.cdf.len() - 1);
        while lo < hi {
            let mid = (lo + hi) / 2;
            if u < self.cdf[mid] { hi = mid } else { lo = mid + 1 }
        }
        lo
    }

    /// Samples a point on a light (twin of `sample_light`); `triangles` in BVH order.
    pub fn sample(&self, triangles: &[Triangle], u_select: f32, u: Vec2) -> LightSample {
        let index = self.select(u_select);
        let light = &self.lights[index];
        if light.kind == LIGHT_DIRECTIONAL {
            // Where the light starts depends on the point it lights (directional_origin).
            return LightSample {
                position: light.position,
                normal: light.direction,
                emission: light.emission,
                pdf: light.select_pdf,
                is_delta: true,
                is_directional: true,
                double_sided: false,
                triangle: light.triangle,
            };
        }
        if light.kind == LIGHT_POINT {
            return LightSample {
                position: light.position,
                normal: Vec3::ZERO,
                emission: light.emission,
                pdf: light.select_pdf,
                is_delta: true,
                is_directional: false,
                double_sided: false,
                triangle: light.triangle,
            };
        }
        let tri = &triangles[light.triangle as usize];
        let b = sample_triangle_barycentrics(u);
        LightSample {
            position: tri.v0 + b.x * tri.e1 + b.y * tri.e2,
            normal: tri.e1.cross(tri.e2).normalize(),
            emission: light.emission,
            pdf: light.select_pdf / light.area,
            is_delta: false,
            is_directional: false,
            double_sided: light.flags & LIGHT_DOUBLE_SIDED != 0,
            triangle: light.triangle,
        }
    }
}

/// A sampled point on a light (twin of WGSL `LightSample`).
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// The sampled point (m).
    pub position: Vec3,
    /// Unit front normal of an area light; zero for point lights.
    pub normal: Vec3,
    /// Radiance (area, W m^-2 sr^-1) or intensity (point, W sr^-1).
    pub emission: Vec3,
    /// Area pdf with selection (m^-2) for area lights; selection probability for point lights.
    pub pdf: f32,
    /// A point, spot or directional light (a delta: reached by light sampling only).
    pub is_delta: bool,
    /// A directional light: `position` is the bounding sphere's centre and `normal` the
    /// direction of travel.
    pub is_directional: bool,
    /// An area light that emits from both faces.
    pub double_sided: bool,
    /// The emitting triangle (BVH order), or NONE.
    pub triangle: u32,
}

fn mean(v: Vec3) -> f64 {
    (v.x as f64 + v.y as f64 + v.z as f64) / 3.0
}

/// The flag bits that store index of refraction `ior` from bit [`VERTEX_IOR_SHIFT`], as subpath
/// vertices' flags hold it (`vertex_ior_bits` in subpath.wesl): (ior - 1) x 8192 as a signed
/// 16-bit integer.
fn ior_bits(ior: f32) -> u32 {
    let q = ((ior - 1.0) * 8192.0).round().clamp(-32768.0, 32767.0) as i32;
    (q as u32) << VERTEX_IOR_SHIFT
}
