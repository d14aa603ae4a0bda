//! Non-line-of-sight (NLOS) capture: a laser lights a spot on a visible relay wall, light goes
//! around the corner to hidden objects and back, and a time-resolved sensor records the light
//! leaving a grid of points on the wall (shaders/lib/nlos.wesl).
//!
//! Conventions (those of Mitsuba 3 + mitransient's `nlos_capture_meter`, so that outputs compare
//! bin for bin):
//! - The relay wall is a mesh node of the scene, named (`relay_wall` by default). Its TEXCOORD_0
//!   parameterises it: grid cell (i, j) of a W x H grid is sensed at the wall point of texture
//!   coordinates ((i + 0.5) / W, (j + 0.5) / H). Pixel (i, j) of the image (row j) is that cell,
//!   so the output's [grid_y, grid_x] is [j, i].
//! - A pixel's value is the radiance (W m^-2 sr^-1) leaving its sensed point towards the sensor
//!   origin, binned by path length: the ray from the sensor origin to the point is traced, and
//!   the first surface it hits is the sensed point.
//! - The laser is a beam of power P (W) from the laser origin towards a target on the wall; the
//!   first surface it hits is the spot. The spot reflects the beam with the wall's BSDF, so it
//!   acts as a point light of radiant intensity P f(to laser, w) cos(w) (W sr^-1). A Mitsuba XML
//!   capture's laser is mitransient's projector, whose P depends on the spot ([`Laser`]).
//! - Path lengths run from the laser spot to the sensed point. The laser origin -> spot and
//!   sensed point -> sensor origin segments are added only with `count_first_and_last`
//!   (mitransient's `account_first_and_last_bounces`, off by default there and here).
//! - Bounces count every scattering vertex, the laser spot and the sensed point included: the
//!   classic three-bounce path spot -> hidden point -> sensed point has 3.
//! - The scene's own lights take no part in a capture.
//!
//! Module layout: this module holds the capture's types; `geometry` the relay wall's points (the
//! sensed points and laser spots) and the capture's record; `shells` the hidden scene's
//! preparation for the band index's shell connections; `band_index` the index itself, built on
//! the device. These are the pieces the integrators render a capture's pixels with, below them;
//! `crate::capture`, above the integrators, runs a capture (its defaults, one render per laser
//! spot, its output).

pub mod band_index;
mod geometry;
mod shells;

use glam::{Vec2, Vec3};

pub use geometry::{
    WallTarget, capture_record, cell_uv, check_capture, origin_from_nodes, wall_normal, wall_point_at, wall_points,
    wall_points_and_warnings, wall_target_at,
};
pub use shells::{
    ConvexSolid, FINER_CUTS, MAX_REFINE_PIECES, MAX_REFINED_TRIANGLES, MAX_SOLID_TRIANGLES, REFINE_FINEST_BIN,
    ShellPreparation, close_surfaces, convex_solids, drop_buried_pieces, prepare_for_shells, refine_for_shells,
};

pub use crate::scene::{DEFAULT_RELAY_WALL, Scan};

/// Where one render's laser spot lies.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LaserAim {
    /// Aimed at the wall point of texture coordinates (u, v) for every pixel.
    Spot(Vec2),
    /// Aimed at each pixel's sensed point (confocal).
    Confocal,
}

/// One NLOS render: the wall, the origins, the laser (what [`crate::integrator::RenderSettings`]
/// carries). The image's width and height are the grid of sensed points.
#[derive(Clone, Debug, PartialEq)]
pub struct NlosCapture {
    /// Name of the relay wall's glTF node.
    pub relay_wall: String,
    /// Where the sensor looks at the wall from (m).
    pub sensor_origin: Vec3,
    /// Where the laser beam starts (m).
    pub laser_origin: Vec3,
    /// Where the beam is aimed.
    pub aim: LaserAim,
    /// The laser's power at its spot.
    pub laser: Laser,
    /// Count the laser origin -> spot and sensed point -> sensor origin segments in path lengths.
    pub count_first_and_last: bool,
}

/// What lights the laser spot: the power the spot receives (W per channel).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Laser {
    /// A beam of this power (W), whatever the spot's distance and slant.
    Beam(f32),
    /// mitransient's `projector` of this irradiance (W m^-2 per channel at 1 m on its axis), as
    /// its `transient_nlos_path` lights a spot with it: a spot at distance d whose normal makes
    /// the angle theta with the beam receives pi E cos(theta) / d^2 (W). A Mitsuba XML capture's
    /// laser.
    Projector(Vec3),
}

impl Laser {
    /// The power (W per channel) a spot at `spot` with unit normal `normal` receives from a laser
    /// at `origin` (m).
    pub fn spot_power(&self, origin: Vec3, spot: Vec3, normal: Vec3) -> Vec3 {
        match *self {
            Laser::Beam(power) => Vec3::splat(power),
            Laser::Projector(irradiance) => {
                let to_origin = origin - spot;
                let d2 = to_origin.length_squared();
                let cos = normal.dot(to_origin).abs() / d2.sqrt();
                if d2 > 0.0 { irradiance * (std::f32::consts::PI * cos / d2) } else { Vec3::ZERO }
            }
        }
    }

    /// Checks that the laser gives a positive, finite power.
    pub fn check(&self) -> anyhow::Result<()> {
        match *self {
            Laser::Beam(power) => {
                anyhow::ensure!(power.is_finite() && power > 0.0, "laser power {power} W must be positive")
            }
            Laser::Projector(e) => anyhow::ensure!(
                e.is_finite() && e.min_element() >= 0.0 && e.max_element() > 0.0,
                "the projector's irradiance {e} W m^-2 must be finite, non-negative and positive in some channel"
            ),
        }
        Ok(())
    }
}
