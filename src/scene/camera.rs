//! The camera: a pinhole, or a thin lens. CPU twin of `shaders/lib/camera.wesl`.

use glam::{Vec2, Vec3};

use crate::gpu::layout::Camera;
use crate::sampling::sample_disk;

/// A perspective camera in world space: a pinhole at `position`, or a thin lens centred there.
#[derive(Clone, Copy, Debug)]
pub struct CameraDesc {
    /// Pinhole position, or the centre of the lens (m).
    pub position: Vec3,
    /// Unit vector along +x of the image.
    pub right: Vec3,
    /// Unit vector along +y of the image.
    pub up: Vec3,
    /// Unit viewing direction.
    pub forward: Vec3,
    /// Vertical field of view (rad).
    pub yfov: f32,
    /// The thin lens, or `None` for a pinhole.
    pub lens: Option<ThinLens>,
}

/// A thin lens: a disk normal to the viewing direction, and the plane it brings into focus.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThinLens {
    /// Radius of the lens (m), > 0.
    pub aperture_radius: f32,
    /// Distance (m) along the viewing direction from the lens to the plane in focus, > 0.
    pub focus_distance: f32,
}

impl ThinLens {
    /// A thin lens; both lengths must be finite and positive.
    pub fn new(aperture_radius: f32, focus_distance: f32) -> anyhow::Result<Self> {
        if !(aperture_radius.is_finite() && aperture_radius > 0.0) {
            anyhow::bail!("aperture radius {aperture_radius} m is not a positive length");
        }
        if !(focus_distance.is_finite() && focus_distance > 0.0) {
            anyhow::bail!("focus distance {focus_distance} m is not a positive length");
        }
        Ok(Self { aperture_radius, focus_distance })
    }
}

impl CameraDesc {
    /// The camera of a scene loaded for an NLOS capture without one: a pinhole at the centre of
    /// the triangles' bounds (captures never look through it).
    pub fn placeholder(triangles: &[super::SceneTriangle]) -> Self {
        let (lo, hi) = triangles
            .iter()
            .flat_map(|t| t.positions)
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(p), hi.max(p)));
        CameraDesc {
            position: 0.5 * (lo + hi),
            right: Vec3::X,
            up: Vec3::Y,
            forward: Vec3::NEG_Z,
            yfov: 1.0,
            lens: None,
        }
    }

    /// Overrides the lens from the scene file: `aperture_radius` (m; 0 makes a pinhole) and
    /// `focus_distance` (m) replace the file's where given. A radius without any focus distance
    /// is an error whose hint names `focus_option`, the caller's way of giving one (the command
    /// line's `--focus-distance METRES`, the Python package's `focus_distance=...`).
    pub fn override_lens(
        &mut self,
        aperture_radius: Option<f32>,
        focus_distance: Option<f32>,
        focus_option: &str,
    ) -> anyhow::Result<()> {
        if aperture_radius.is_none() && focus_distance.is_none() {
            return Ok(());
        }
        let old = self.lens;
        let radius = aperture_radius.or(old.map(|l| l.aperture_radius)).unwrap_or(0.0);
        let focus = focus_distance.or(old.map(|l| l.focus_distance));
        self.lens = match (radius, focus) {
            (0.0, _) => None,
            (r, Some(f)) => Some(ThinLens::new(r, f)?),
            (_, None) => anyhow::bail!("a thin lens needs a focus distance: give {focus_option} (the camera has none)"),
        };
        Ok(())
    }

    /// `pinhole`, or the thin lens's aperture radius and focus distance (m), as outputs'
    /// metadata records the camera.
    pub fn describe(&self) -> String {
        match self.lens {
            None => "pinhole".into(),
            Some(l) => {
                format!("thin lens: aperture radius {} m, focus distance {} m", l.aperture_radius, l.focus_distance)
            }
        }
    }

    /// The GPU camera for an image of `width` x `height` pixels (aspect from the resolution).
    pub fn to_gpu(&self, width: u32, height: u32) -> Camera {
        let (lens_radius, focus_distance) = match self.lens {
            Some(l) => (l.aperture_radius, l.focus_distance),
            None => (0.0, 1.0),
        };
        Camera {
            position: self.position,
            tan_half_fov_y: (0.5 * self.yfov).tan(),
            right: self.right,
            aspect: width as f32 / height as f32,
            up: self.up,
            lens_radius,
            forward: self.forward,
            focus_distance,
        }
    }

    /// Area of the whole image on the image plane at unit distance from the pinhole
    /// (4 tan^2(yfov/2) width/height): the pinhole's importance is 1 / (area cos^4).
    pub fn image_area(&self, width: u32, height: u32) -> f32 {
        let t = (0.5 * self.yfov).tan();
        4.0 * t * t * width as f32 / height as f32
    }

    /// The lens radius (m): 0 for a pinhole.
    pub fn lens_radius(&self) -> f32 {
        self.lens.map_or(0.0, |l| l.aperture_radius)
    }
}

/// Unit direction of the pinhole ray (from the lens centre) through film position `film`
/// (pixels from the top-left corner, y down).
pub fn camera_direction(camera: &Camera, film: Vec2, width: u32, height: u32) -> Vec3 {
    let ndc_x = 2.0 * film.x / width as f32 - 1.0;
    let ndc_y = 1.0 - 2.0 * film.y / height as f32;
    let x = ndc_x * camera.tan_half_fov_y * camera.aspect;
    let y = ndc_y * camera.tan_half_fov_y;
    (camera.forward + x * camera.right + y * camera.up).normalize()
}

/// The camera ray through film position `film` (pixels) as (origin, unit direction): the
/// pinhole ray, or for a thin lens the ray from the lens point that `u_lens` in [0, 1)^2 picks
/// uniformly on the disk to where the pinhole ray meets the plane in focus (twin of
/// `camera_path`).
pub fn camera_ray(camera: &Camera, film: Vec2, u_lens: Vec2, width: u32, height: u32) -> (Vec3, Vec3) {
    let direction = camera_direction(camera, film, width, height);
    if camera.lens_radius <= 0.0 {
        return (camera.position, direction);
    }
    let disk = camera.lens_radius * sample_disk(u_lens);
    let origin = camera.position + disk.x * camera.right + disk.y * camera.up;
    let in_focus = camera.position + direction * (camera.focus_distance / direction.dot(camera.forward));
    (origin, (in_focus - origin).normalize())
}

/// Where the ray leaving lens point `lens` along unit direction `w` lands on the image:
/// (x, y, c) with x, y in [-1, 1] inside the image (x right, y up) and c the cosine to the
/// viewing direction; meaningless unless c > 0 (twin of `image_coordinates`).
pub fn image_coordinates(camera: &Camera, lens: Vec3, w: Vec3) -> Vec3 {
    let c = w.dot(camera.forward);
    let v = (lens - camera.position) * (1.0 / camera.focus_distance) + w * (1.0 / c);
    Vec3::new(
        v.dot(camera.right) / (camera.tan_half_fov_y * camera.aspect),
        v.dot(camera.up) / camera.tan_half_fov_y,
        c,
    )
}
