//! NLOS captures in Mitsuba XML scenes: mitransient's `nlos_capture_meter` on a relay wall, its
//! `projector` laser and `transient_nlos_path`'s capture settings, read into the
//! [`SceneCapture`] a render of the file becomes (docs/nlos.md, "Captures from Mitsuba XML").
//!
//! Both generations of the meter's properties are read. mitransient 1.3.1 places the laser where
//! its projector stands and aims it from Python (`mitransient.nlos.focus_emitter_at_*`), with
//! the scan in the integrator's `capture_type` (an exhaustive scan's laser spots are its sensed
//! points, `force_equal_illumination_scanning`, with the film's `exhaustive_scan` and
//! `laser_scan_width` / `_height`) and confocal grids as `original_film_width` / `_height` over a
//! 1 x 1 film. Its earlier meter, for which mitransient's own examples
//! (`nlos_Z.xml`) and TAL's files are written, takes `laser_origin`, `laser_lookat_pixel` (a film
//! position, (x, y) / film size in the wall's (u, v)) or `laser_lookat_3d`, and `confocal`.
//! Without an aim the laser points along its projector's axis (its `to_world`'s +z), as
//! `transient_nlos_path` aims a single scan. The relay wall must be a `rectangle`: mitransient
//! lays its grid by the shape's `sample_position`, which only a rectangle maps onto the wall's
//! (u, v) uniformly (Mitsuba's rectangle: to_world of (2u - 1, 2v - 1, 0)).

use anyhow::Result;
use glam::{Mat4, Vec2, Vec3};

use super::Builder;
use super::xml::{Element, Object};
use crate::scene::{Scan, SceneCapture, SceneSettings};

/// Where a meter aims the laser.
#[derive(Clone, Copy, Debug)]
enum Aim {
    /// A film position (x, y) (the earlier meter's `laser_lookat_pixel`).
    Pixel(Vec2),
    /// A world point on the wall (`laser_lookat_3d`), m.
    Point(Vec3),
}

/// An `nlos_capture_meter` as read, on the relay wall it is a child of.
#[derive(Clone, Debug)]
pub(super) struct Meter<'e> {
    element: &'e Element,
    /// The relay wall's node name.
    wall: String,
    /// The wall rectangle's to_world.
    wall_to_world: Mat4,
    sensor_origin: Vec3,
    laser_origin: Option<Vec3>,
    aim: Option<Aim>,
    /// The earlier meter's `confocal`, or a grid given as `original_film_*` (1.3.1's confocal).
    confocal: Option<bool>,
    /// The earlier meter's `account_first_and_last_bounces`.
    count_first_and_last: Option<bool>,
    /// The grid of sensed points (the film's size, or `original_film_*`).
    grid: (u32, u32),
    /// The film's grid of laser spots (`exhaustive_scan`, `laser_scan_width` / `_height`).
    laser_grid: Option<(u32, u32)>,
    /// The render settings of its film and sampler (the grid, time bins, samples and seed).
    settings: SceneSettings,
}

/// A `projector` emitter: mitransient's laser.
#[derive(Clone, Debug)]
pub(super) struct Projector<'e> {
    element: &'e Element,
    position: Vec3,
    /// Unit axis (its to_world's +z).
    axis: Vec3,
    /// Irradiance (W m^-2 per channel) at 1 m on its axis, `scale` applied.
    irradiance: Vec3,
}

/// What a scene holds of a capture: its meter, its projectors and what its integrator says.
#[derive(Clone, Debug, Default)]
pub(super) struct CaptureParts<'e> {
    pub meter: Option<Meter<'e>>,
    pub projectors: Vec<Projector<'e>>,
    /// The integrator is `transient_nlos_path`.
    pub nlos_integrator: bool,
    /// `capture_type`, with the element that says so.
    pub integrator_scan: Option<(Scan, &'e Element)>,
    /// The integrator's `account_first_and_last_bounces`.
    pub integrator_count_first_and_last: Option<bool>,
}

impl<'e> Builder<'e> {
    /// Reads `transient_nlos_path`'s capture settings from its object (the properties it shares
    /// with `transient_path` are read by the caller; its `max_depth` counts one vertex fewer
    /// than the path has, the laser spot). Sampling choices that leave the mean unchanged are
    /// ignored; laser sampling must be on.
    pub(super) fn nlos_integrator(&mut self, o: &Object<'e>) -> Result<()> {
        let e = o.element;
        self.capture.nlos_integrator = true;
        o.ignore(&[
            "nlos_hidden_geometry_sampling",
            "nlos_hidden_geometry_sampling_do_rroulette",
            "nlos_hidden_geometry_sampling_includes_relay_wall",
        ]);
        for key in ["filter_depth", "filter_bounces"] {
            if let Some(depth) = o.integer(key)?.filter(|&d| d != -1) {
                return Err(e.error(format!(
                    "`{key}` {depth} keeps the paths of one depth only; gatetrace renders every depth up to \
                     --max-bounces"
                )));
            }
        }
        if o.boolean("nlos_laser_sampling")? != Some(true) {
            return Err(e.error(
                "nlos_laser_sampling must be true: gatetrace's laser lights one point of the relay wall, as \
                 mitransient's laser sampling does (without it mitransient lights the projector's footprint, and \
                 its capture's scale and depth differ)",
            ));
        }
        if let Some(kind) = o.float_or_name("capture_type")? {
            // An integer (CaptureType's value) or its name.
            let name = match kind {
                Ok(1.0) => "single",
                Ok(2.0) => "confocal",
                Ok(3.0) => "exhaustive",
                Ok(_) => "",
                Err(name) => name,
            };
            let scan = match name.to_ascii_lowercase().as_str() {
                "single" => Scan::Single,
                "confocal" => Scan::Confocal,
                "exhaustive" => Scan::Exhaustive,
                _ => return Err(e.error("`capture_type` must be single (1), confocal (2) or exhaustive (3)")),
            };
            self.capture.integrator_scan = Some((scan, e));
        }
        if o.boolean("force_equal_illumination_scanning")? == Some(false) {
            return Err(e.error(
                "force_equal_illumination_scanning false lays an exhaustive scan's laser spots by a projector's \
                 grid of rays, which gatetrace does not read: its laser spots are the sensed points",
            ));
        }
        // Used only where the scanning is not forced equal.
        o.ignore(&["illumination_scan_fov"]);
        self.capture.integrator_count_first_and_last = o.boolean("account_first_and_last_bounces")?;
        Ok(())
    }

    /// Reads the `nlos_capture_meter` `e` on the shape `wall` (named `name`, placed by
    /// `to_world`): its origins, aim, scan, film (the grid and time bins) and sampler.
    pub(super) fn capture_meter(
        &mut self,
        e: &'e Element,
        wall: &'e Element,
        name: &str,
        to_world: Mat4,
    ) -> Result<()> {
        e.only_attributes(&["type", "id", "name"])?;
        if let Some(first) = &self.capture.meter {
            return Err(e.error(format!(
                "a second nlos_capture_meter (the first is at line {}): gatetrace renders one capture",
                first.element.line
            )));
        }
        let o = Object::new(e);
        if o.kind()? != "nlos_capture_meter" {
            return Err(e.error("a shape carries only an `nlos_capture_meter` sensor (an NLOS capture's relay wall)"));
        }
        if wall.attribute("type") != Some("rectangle") {
            return Err(e.error(
                "the relay wall must be a `rectangle`: mitransient lays the grid of sensed points by the shape's \
                 sample_position, which only a rectangle maps onto the wall uniformly",
            ));
        }
        let sensor_origin = o.point("sensor_origin")?.unwrap_or(Vec3::ZERO);
        let laser_origin = o.point("laser_origin")?;
        let pixel = o.point("laser_lookat_pixel")?;
        let point = o.point("laser_lookat_3d")?;
        let aim = match (pixel, point) {
            (Some(_), Some(_)) => return Err(e.error("give laser_lookat_pixel or laser_lookat_3d, not both")),
            (Some(p), None) => Some(Aim::Pixel(p.truncate())),
            (None, Some(p)) => Some(Aim::Point(p)),
            (None, None) => None,
        };
        let confocal = o.boolean("confocal")?;
        let count_first_and_last = o.boolean("account_first_and_last_bounces")?;
        let original = (o.integer("original_film_width")?, o.integer("original_film_height")?);
        // The meter's film and sampler are the capture's settings, kept apart from a camera's.
        let camera_settings = std::mem::take(&mut self.settings);
        let (width, height, _, laser_grid) = self.film(e)?;
        let grid = match original {
            (None, None) => (width, height),
            (Some(w), Some(h)) => {
                if (width, height) != (1, 1) {
                    return Err(e.error(format!(
                        "original_film_width and _height give a confocal grid, whose film is 1 x 1 (not {width} x \
                         {height})"
                    )));
                }
                let size = |v: i64| u32::try_from(v).ok().filter(|&v| v > 0);
                let (Some(w), Some(h)) = (size(w), size(h)) else {
                    return Err(e.error(format!("original film size {w} x {h} is not positive")));
                };
                if confocal == Some(false) {
                    return Err(e.error("original_film_width and _height give a confocal grid, but confocal is false"));
                }
                (w, h)
            }
            _ => return Err(e.error("give both original_film_width and original_film_height")),
        };
        let confocal = confocal.or((original.0.is_some()).then_some(true));
        self.sampler(e)?;
        let settings = std::mem::replace(&mut self.settings, camera_settings);
        let mut projectors = e.children.iter().filter(|c| c.tag == "emitter");
        if let Some(p) = projectors.next() {
            self.projector(p)?;
        }
        if let Some(second) = projectors.next() {
            return Err(second.error("a capture meter takes one (projector) emitter"));
        }
        o.finish(&["film", "sampler", "emitter"])?;
        self.capture.meter = Some(Meter {
            element: e,
            wall: name.to_owned(),
            wall_to_world: to_world,
            sensor_origin,
            laser_origin,
            aim,
            confocal,
            count_first_and_last,
            grid,
            laser_grid,
            settings,
        });
        Ok(())
    }

    /// Reads a `projector` emitter (a capture's laser); its texture and field of view do not
    /// change a capture (the laser lights one point).
    pub(super) fn projector(&mut self, e: &'e Element) -> Result<()> {
        e.only_attributes(&["type", "id", "name"])?;
        let o = Object::new(e);
        if let Some(t) = e.children.iter().find(|c| matches!(c.tag.as_str(), "texture" | "ref")) {
            return Err(t.error("a projector's texture is not read: a capture's laser lights one point"));
        }
        let to_world = o.transform("to_world")?;
        let irradiance = o.color("irradiance")?.unwrap_or(Vec3::ONE) * o.float("scale")?.unwrap_or(1.0);
        if !(irradiance.min_element() >= 0.0 && irradiance.max_element() > 0.0) {
            return Err(e.error(format!("the projector's irradiance {irradiance} must be non-negative and not zero")));
        }
        o.ignore(&["fov", "fov_axis"]);
        o.finish(&[])?;
        let axis = to_world.transform_vector3(Vec3::Z).try_normalize().ok_or_else(|| e.error("degenerate to_world"))?;
        self.capture.projectors.push(Projector {
            element: e,
            position: to_world.transform_point3(Vec3::ZERO),
            axis,
            irradiance,
        });
        Ok(())
    }

    /// The capture the scene describes, once every element is read, set in its settings with
    /// its meter's film and sampler (they replace a camera's): None without a meter.
    pub(super) fn finish_capture(&mut self) -> Result<Option<SceneCapture>> {
        let Some(capture) = self.scene_capture()? else { return Ok(None) };
        let meter = self.capture.meter.as_ref().expect("a capture has a meter");
        let m = &meter.settings;
        let s = &mut self.settings;
        s.resolution = Some(meter.grid);
        s.gate = m.gate.clone();
        s.spp = m.spp;
        s.seed = m.seed;
        s.capture = Some(capture.clone());
        Ok(Some(capture))
    }

    fn scene_capture(&self) -> Result<Option<SceneCapture>> {
        let parts = &self.capture;
        let Some(meter) = &parts.meter else {
            if parts.nlos_integrator {
                return Err(anyhow::anyhow!(
                    "{}: transient_nlos_path renders NLOS captures, and the scene has no nlos_capture_meter (on its \
                     relay wall): render a camera image with transient_path",
                    self.name
                ));
            }
            if let Some(p) = parts.projectors.first() {
                return Err(p
                    .element
                    .error("projector emitters light NLOS captures only (an nlos_capture_meter on the relay wall)"));
            }
            return Ok(None);
        };
        let e = meter.element;
        if !parts.nlos_integrator {
            return Err(e.error("an nlos_capture_meter is rendered with the integrator transient_nlos_path"));
        }
        let [projector] = &parts.projectors[..] else {
            return Err(e.error(format!(
                "a capture is lit by one projector emitter (its laser); the scene has {}",
                parts.projectors.len()
            )));
        };
        let scan = match (parts.integrator_scan, meter.confocal) {
            (Some((a, at)), Some(b)) if (a == Scan::Confocal) != b => {
                return Err(at.error(format!("capture_type says {} but the capture meter's confocal is {b}", a.name())));
            }
            (Some((a, _)), _) => a,
            (None, Some(true)) => Scan::Confocal,
            (None, _) => Scan::Single,
        };
        match (scan, meter.laser_grid) {
            (Scan::Exhaustive, Some(laser)) if laser != meter.grid => {
                return Err(e.error(format!(
                    "an exhaustive scan's laser grid ({} x {}) must be its grid of sensed points ({} x {}), as \
                     force_equal_illumination_scanning asks",
                    laser.0, laser.1, meter.grid.0, meter.grid.1
                )));
            }
            (Scan::Exhaustive, None) => {
                return Err(e.error(
                    "an exhaustive capture's film needs exhaustive_scan true with laser_scan_width and _height",
                ));
            }
            (Scan::Single | Scan::Confocal, Some(_)) => {
                return Err(e.error("the film's exhaustive_scan needs capture_type exhaustive"));
            }
            _ => {}
        }
        let laser_origin = meter.laser_origin.unwrap_or(projector.position);
        let inverse = meter.wall_to_world.inverse();
        // (u, v) of a point of the wall's plane in its local frame.
        let uv_of = |local: Vec3| Vec2::new(0.5 * (local.x + 1.0), 0.5 * (local.y + 1.0));
        let on_wall = |uv: Vec2| (0.0..=1.0).contains(&uv.x) && (0.0..=1.0).contains(&uv.y);
        let laser_spot = match meter.aim {
            // Confocal and exhaustive scans aim at each sensed point.
            _ if scan != Scan::Single => Vec2::splat(0.5),
            Some(Aim::Pixel(p)) => {
                let uv = p / Vec2::new(meter.grid.0 as f32, meter.grid.1 as f32);
                if !on_wall(uv) {
                    return Err(e.error(format!(
                        "laser_lookat_pixel ({}, {}) lies outside the {} x {} film",
                        p.x, p.y, meter.grid.0, meter.grid.1
                    )));
                }
                uv
            }
            Some(Aim::Point(p)) => {
                let local = inverse.transform_point3(p);
                let uv = uv_of(local);
                if local.z.abs() > 1e-3 || !on_wall(uv) {
                    return Err(e.error(format!("laser_lookat_3d {p} is not a point of the relay wall")));
                }
                uv
            }
            None => {
                let o = inverse.transform_point3(laser_origin);
                let d = inverse.transform_vector3(projector.axis);
                let t = -o.z / d.z;
                let uv = uv_of(o + t * d);
                if !(t > 0.0 && t.is_finite() && on_wall(uv)) {
                    return Err(projector.element.error(format!(
                        "the laser at {laser_origin} points along {} and misses the relay wall `{}`: aim it (its \
                         to_world, or the capture meter's laser_lookat_pixel)",
                        projector.axis, meter.wall
                    )));
                }
                uv
            }
        };
        Ok(Some(SceneCapture {
            scan,
            laser_grid: meter.laser_grid,
            relay_wall: meter.wall.clone(),
            sensor_origin: meter.sensor_origin,
            laser_origin,
            laser_spot,
            projector_irradiance: projector.irradiance,
            count_first_and_last: parts.integrator_count_first_and_last.or(meter.count_first_and_last).unwrap_or(false),
        }))
    }
}
