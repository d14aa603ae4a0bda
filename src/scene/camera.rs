//! The pinhole camera. CPU twin of `shaders/lib/camera.wesl`.

use glam::{Vec2, Vec3};

use crate::gpu::layout::Camera;

/// A perspective pinhole camera in world space.
#[derive(Clone, Copy, Debug)]
pub struct CameraDesc {
    /// Pinhole position (m).
    pub position: Vec3,
    /// Unit vectors: image right, image up, viewing direction.
    /// Unit vector along +x of the image.
    pub right: Vec3,
    /// Unit vector along +y of the image.
    pub up: Vec3,
    /// Unit viewing direction.
    pub forward: Vec3,
    /// Vertical field of view (rad).
    pub yfov: f32,
}

impl CameraDesc {
    /// The GPU camera for an image of `width` x `height` pixels (aspect from the resolution).
    pub fn to_gpu(&self, width: u32, height: u32) -> Camera {
        Camera {
            position: self.position,
            tan_half_fov_y: (0.5 * self.yfov).tan(),
            right: self.right,
            aspect: width as f32 / height as f32,
            up: self.up,
            reserved0: 0,
            forward: self.forward,
            reserved1: 0,
        }
    }

    /// Area of the whole image on the image plane at unit distance from the pinhole
    /// (4 tan^2(yfov/2) width/height): the pinhole's importance is 1 / (area cos^4).
    pub fn image_area(&self, width: u32, height: u32) -> f32 {
        let t = (0.5 * self.yfov).tan();
        4.0 * t * t * width as f32 / height as f32
    }
}

/// Unit direction through film position `film` (pixels from the top-left corner, y down).
pub fn camera_direction(camera: &Camera, film: Vec2, width: u32, height: u32) -> Vec3 {
    let ndc_x = 2.0 * film.x / width as f32 - 1.0;
    let ndc_y = 1.0 - 2.0 * film.y / height as f32;
    let x = ndc_x * camera.tan_half_fov_y * camera.aspect;
    let y = ndc_y * camera.tan_half_fov_y;
    (camera.forward + x * camera.right + y * camera.up).normalize()
}
