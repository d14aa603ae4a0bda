//! The sensor, its film and sampler, and the integrator of a Mitsuba XML scene: the camera and
//! the render settings the file carries ([`crate::scene::SceneSettings`]: resolution, samples, seed, depth,
//! time bins).

use anyhow::Result;
use glam::Vec3;

use super::Builder;
use super::xml::{Element, Object};
use crate::scene::CameraDesc;
use crate::scene::camera::ThinLens;

impl<'e> Builder<'e> {
    /// Reads a perspective or thin-lens sensor: the camera, its film and its sampler.
    pub(super) fn sensor(&mut self, e: &'e Element) -> Result<()> {
        e.only_attributes(&["type", "id", "name"])?;
        if self.camera.is_some() {
            self.warn(e, "a second sensor: gatetrace renders from the first");
            return Ok(());
        }
        let o = Object::new(e);
        let kind = o.kind()?;
        if kind == "nlos_capture_meter" {
            return Err(e.error("an nlos_capture_meter belongs inside its relay wall's <shape>"));
        }
        if !matches!(kind, "perspective" | "thinlens") {
            return Err(e.error(format!("the sensor `{kind}` is not read (perspective and thinlens are)")));
        }
        let to_world = o.transform("to_world")?;
        // Mitsuba's default near clip plane.
        let near_clip = o.float("near_clip")?.unwrap_or(0.01);
        o.ignore(&["far_clip"]);
        for offset in ["principal_point_offset_x", "principal_point_offset_y"] {
            if o.float(offset)?.is_some_and(|x| x != 0.0) {
                return Err(e.error(format!("a non-zero `{offset}` is not rendered")));
            }
        }
        if o.string("focal_length")?.is_some() {
            return Err(e.error("give the field of view as `fov` (degrees): `focal_length` is not read"));
        }
        let fov = o.float("fov")?.ok_or_else(|| e.error("`fov` (degrees) is missing"))?;
        if !(fov > 0.0 && fov < 180.0) {
            return Err(e.error(format!("fov {fov} is not in (0, 180) degrees")));
        }
        let fov_axis = o.string("fov_axis")?.unwrap_or("x");
        let lens = if kind == "thinlens" {
            let radius = o.float("aperture_radius")?.ok_or_else(|| e.error("`aperture_radius` is missing"))?;
            let focus = o.float("focus_distance")?.unwrap_or(0.0);
            Some(ThinLens::new(radius, focus).map_err(|err| e.error(err))?)
        } else {
            // A pinhole: its focus distance changes nothing.
            o.ignore(&["focus_distance"]);
            None
        };
        let (width, height, bin_width, laser_grid) = self.film(e)?;
        if laser_grid.is_some() {
            return Err(e.error("a film with exhaustive_scan belongs to an NLOS capture meter"));
        }
        if let Some(bin_width) = bin_width.filter(|&w| near_clip > 0.01 * w) {
            self.warn(
                e,
                format!(
                    "mitransient measures the camera's segment from the near clip plane (near_clip {near_clip}: its \
                     path lengths are near_clip / cos(angle to the view axis) shorter, {:.2} bins or more); gatetrace \
                     measures it from the pinhole, so its transient comes that much later than mitransient's render \
                     of this file (set near_clip well below the bin width, {bin_width}, to compare them)",
                    near_clip / bin_width
                ),
            );
        }
        self.sampler(e)?;
        self.camera_medium = self.sensor_medium(e)?;
        o.finish(&["film", "sampler", "medium", "ref"])?;
        let (w, h) = (width as f32, height as f32);
        let tan = (0.5 * fov.to_radians()).tan();
        let tan_y = match fov_axis {
            "x" => tan * h / w,
            "y" => tan,
            "diagonal" => tan * h / (w * w + h * h).sqrt(),
            "smaller" if w <= h => tan * h / w,
            "smaller" => tan,
            "larger" if w >= h => tan * h / w,
            "larger" => tan,
            other => return Err(e.error(format!("fov_axis `{other}` is not x, y, diagonal, smaller or larger"))),
        };
        let camera = CameraDesc {
            position: to_world.transform_point3(Vec3::ZERO),
            // Mitsuba's camera looks along local +z with +y up and +x to the image's left.
            right: -to_world.transform_vector3(Vec3::X).normalize(),
            up: to_world.transform_vector3(Vec3::Y).normalize(),
            forward: to_world.transform_vector3(Vec3::Z).normalize(),
            yfov: 2.0 * tan_y.atan(),
            lens,
        };
        if ![camera.right, camera.up, camera.forward].iter().all(|v| v.is_finite()) {
            return Err(e.error("the sensor's to_world is degenerate"));
        }
        self.camera = Some(camera);
        Ok(())
    }

    /// The sensor's film: its size (Mitsuba's default 768 x 576), and for mitransient's
    /// `transient_hdr_film` the time bins as a default transient gate, their width, and with
    /// `exhaustive_scan` its grid of laser spots.
    #[allow(clippy::type_complexity)]
    pub(super) fn film(&mut self, sensor: &'e Element) -> Result<(u32, u32, Option<f32>, Option<(u32, u32)>)> {
        let Some(film) = sensor.children.iter().find(|c| c.tag == "film") else {
            return Ok((768, 576, None, None));
        };
        film.only_attributes(&["type", "id", "name"])?;
        let o = Object::new(film);
        let kind = o.kind()?;
        if !matches!(kind, "hdrfilm" | "transient_hdr_film") {
            return Err(film.error(format!("the film `{kind}` is not read (hdrfilm and transient_hdr_film are)")));
        }
        let size = |key: &str, default: i64| -> Result<u32> {
            let v = o.integer(key)?.unwrap_or(default);
            u32::try_from(v)
                .ok()
                .filter(|&v| v > 0)
                .ok_or_else(|| film.error(format!("{key} {v} is not a positive size")))
        };
        let (width, height) = (size("width", 768)?, size("height", 576)?);
        o.ignore(&["pixel_format", "component_format", "sample_border", "banner", "file_format"]);
        let (mut bin_width, mut laser_grid) = (None, None);
        if kind == "transient_hdr_film" {
            let bins = o.integer("temporal_bins")?.ok_or_else(|| film.error("`temporal_bins` is missing"))?;
            let start = o.float("start_opl")?.ok_or_else(|| film.error("`start_opl` is missing"))?;
            let width = o.float("bin_width_opl")?.ok_or_else(|| film.error("`bin_width_opl` is missing"))?;
            if o.boolean("auto_detect_bins")? == Some(true) {
                return Err(film.error("auto_detect_bins is not read: give start_opl and bin_width_opl"));
            }
            if bins < 1 || width <= 0.0 {
                return Err(film.error("temporal_bins and bin_width_opl must be positive"));
            }
            self.settings.gate = Some(format!("transient:{start},{width},{bins}"));
            bin_width = Some(width);
            // The laser's grid counts only in an exhaustive scan (mitransient reads it only then).
            let laser = (o.integer("laser_scan_width")?, o.integer("laser_scan_height")?);
            if o.boolean("exhaustive_scan")? == Some(true) {
                laser_grid = Some((size("laser_scan_width", 0)?, size("laser_scan_height", 0)?));
            } else if laser != (None, None) {
                self.warn(film, "laser_scan_width and _height count only with exhaustive_scan true");
            }
        }
        for filter in film.children.iter().filter(|c| c.tag == "rfilter") {
            match filter.attribute("type") {
                Some("box") if filter.children.is_empty() => {}
                Some(kind) => self.warn(
                    filter,
                    format!("the reconstruction filter `{kind}` is rendered as gatetrace's box filter (one pixel)"),
                ),
                None => return Err(filter.error("the attribute `type` is missing")),
            }
        }
        o.finish(&["rfilter"])?;
        self.settings.resolution = Some((width, height));
        Ok((width, height, bin_width, laser_grid))
    }

    /// Reads a sensor's sampler: the render's samples per pixel and seed.
    pub(super) fn sampler(&mut self, sensor: &'e Element) -> Result<()> {
        let Some(sampler) = sensor.children.iter().find(|c| c.tag == "sampler") else { return Ok(()) };
        sampler.only_attributes(&["type", "id", "name"])?;
        let o = Object::new(sampler);
        // gatetrace draws its own random numbers: the sampler's type does not change the mean.
        let count = o.integer("sample_count")?;
        let seed = o.integer("seed")?;
        o.ignore(&["jitter", "scramble"]);
        o.finish(&[])?;
        if let Some(n) = count {
            self.settings.spp = Some(
                u64::try_from(n)
                    .ok()
                    .filter(|&n| n > 0)
                    .ok_or_else(|| sampler.error(format!("sample_count {n} is not a positive number")))?,
            );
        }
        if let Some(s) = seed {
            self.settings.seed = Some(u32::try_from(s).map_err(|_| sampler.error(format!("seed {s} is not a u32")))?);
        }
        Ok(())
    }

    /// Reads the integrator: its depth and, for `transient_nlos_path`, the capture's settings.
    pub(super) fn integrator(&mut self, e: &'e Element) -> Result<()> {
        e.only_attributes(&["type", "id", "name"])?;
        if std::mem::replace(&mut self.integrator_seen, true) {
            return Err(e.error("a scene takes one integrator"));
        }
        let o = Object::new(e);
        if o.kind()? == "transient_prbvolpath" {
            self.transient_prbvolpath = Some(e);
        }
        match o.kind()? {
            // The volumetric path tracers render the same light as the surface ones where no medium is.
            "path" | "transient_path" | "volpath" | "volpathmis" | "prbvolpath" | "transient_prbvolpath" => {}
            "transient_nlos_path" => self.nlos_integrator(&o)?,
            other => {
                return Err(e.error(format!(
                    "the integrator `{other}` is not read (path, transient_path, volpath, prbvolpath and \
                     transient_prbvolpath are)"
                )));
            }
        }
        let refuse_true = |key: &str, why: &str| -> Result<()> {
            match o.boolean(key)? {
                Some(true) => Err(e.error(format!("`{key}` true is not rendered: {why}"))),
                _ => Ok(()),
            }
        };
        refuse_true("camera_unwarp", "gatetrace's path lengths include the segment to the camera")?;
        refuse_true("hide_emitters", "lights seen directly are always rendered")?;
        refuse_true("discard_direct_paths", "the paths of one bounce are always rendered")?;
        if let Some(filter) = o.string("temporal_filter")?
            && filter != "box"
        {
            return Err(e.error(format!("temporal_filter `{filter}`: gatetrace's transient bins are boxes")));
        }
        // Russian roulette and block sizes do not change the mean.
        o.ignore(&["rr_depth", "block_size", "gaussian_stddev"]);
        // A path of depth d has d - 1 scattering vertices; transient_nlos_path's laser sampling
        // adds the laser spot to the longest (its connection through the spot is not counted).
        let spot = self.capture.nlos_integrator as i64;
        if let Some(depth) = o.integer("max_depth")? {
            match depth {
                -1 => self.warn(e, "max_depth -1 (no limit): the render's --max-bounces applies"),
                d if d >= 1 => self.settings.max_bounces = Some((d - 1 + spot) as u32),
                d => return Err(e.error(format!("max_depth {d} renders nothing"))),
            }
        }
        o.finish(&[])
    }
}
