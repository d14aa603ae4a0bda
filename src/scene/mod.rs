//! Scenes: loading (glTF 2.0, DESIGN.md section 3), the baked world-space description, and the
//! CPU twins of the kernels' scene functions (camera, lights, surfaces, materials).

pub mod camera;
pub mod gltf_loader;
pub mod lights;
pub mod materials;
pub mod prepared;
pub mod surface;

use glam::{Vec2, Vec3};

pub use camera::CameraDesc;
pub use gltf_loader::load_gltf;
pub use prepared::PreparedScene;

/// A triangle in world space with its shading attributes, in load order.
#[derive(Clone, Debug)]
pub struct SceneTriangle {
    /// Vertices (m), counter-clockwise about the front face.
    pub positions: [Vec3; 3],
    /// Unit vertex normals, when the mesh has them.
    pub normals: Option<[Vec3; 3]>,
    /// Texture coordinates of the base-colour texture's set (zero when absent).
    pub uvs: [Vec2; 3],
    pub material: u32,
}

impl SceneTriangle {
    /// Area (m^2).
    pub fn area(&self) -> f32 {
        let [a, b, c] = self.positions;
        0.5 * (b - a).cross(c - a).length()
    }
}

/// A material as loaded (glTF metallic-roughness).
#[derive(Clone, Debug)]
pub struct MaterialDesc {
    pub name: String,
    /// Linear RGB base colour.
    pub base_color: Vec3,
    /// Index into `Scene::textures`.
    pub base_color_texture: Option<u32>,
    /// Radiance (W m^-2 sr^-1) = emissiveFactor x emissive strength.
    pub emission: Vec3,
    pub double_sided: bool,
    pub metallic: f32,
    pub roughness: f32,
}

impl MaterialDesc {
    pub fn is_emissive(&self) -> bool {
        self.emission.max_element() > 0.0
    }
}

/// A decoded texture: linear RGB texels, row 0 at v = 0.
#[derive(Clone, Debug)]
pub struct TextureData {
    pub width: u32,
    pub height: u32,
    pub texels: Vec<Vec3>,
    pub clamp_u: bool,
    pub clamp_v: bool,
}

/// A point light (KHR_lights_punctual).
#[derive(Clone, Debug)]
pub struct PointLight {
    pub position: Vec3,
    /// Intensity (W sr^-1 per channel) = colour x intensity.
    pub intensity: Vec3,
}

/// A scene baked to world space, ready for BVH build and upload.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Where the scene came from (for messages and metadata).
    pub source: String,
    pub triangles: Vec<SceneTriangle>,
    pub materials: Vec<MaterialDesc>,
    pub textures: Vec<TextureData>,
    pub point_lights: Vec<PointLight>,
    pub camera: CameraDesc,
    /// Zero-area triangles dropped at load.
    pub dropped_degenerate: usize,
}

impl Scene {
    /// Axis-aligned bounds of all triangles and the camera (m).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut lo = self.camera.position;
        let mut hi = self.camera.position;
        for t in &self.triangles {
            for p in t.positions {
                lo = lo.min(p);
                hi = hi.max(p);
            }
        }
        for l in &self.point_lights {
            lo = lo.min(l.position);
            hi = hi.max(l.position);
        }
        (lo, hi)
    }

    /// Length of the bounds' diagonal (m): the scene's scale for relative tolerances.
    pub fn extent(&self) -> f32 {
        let (lo, hi) = self.bounds();
        (hi - lo).length().max(f32::MIN_POSITIVE)
    }
}
