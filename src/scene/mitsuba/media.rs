//! Participating media of Mitsuba scenes: `homogeneous` media, and `heterogeneous` ones whose
//! extinction (a `gridvolume`: a `.vol` file of one channel), and optionally albedo on the same
//! voxels (one channel or three), is a grid, with a `hg` or `isotropic` phase
//! function, bounded by shapes with a `null` BSDF (their `interior` and `exterior` media) or
//! around the sensor.

use anyhow::Result;

use super::Builder;
use super::xml::{Element, Object};
use crate::scene::medium::{DensityGrid, read_vol};
use crate::scene::{MediumDesc, MediumInterface};

/// A heterogeneous medium's `<volume>` child: a constant, or a grid (its values in
/// `DensityGrid::values`, `channels` per voxel) with the largest value it declares
/// (`max_value`) or holds.
enum Volume {
    Constant(glam::Vec3),
    Grid { grid: DensityGrid, max: f32, channels: u32 },
}

impl<'e> Builder<'e> {
    /// The index of the medium a `<medium>` element describes (each element read once).
    pub(super) fn medium(&mut self, e: &'e Element) -> Result<u32> {
        let key = e as *const Element as usize;
        if let Some(&m) = self.medium_of.get(&key) {
            return Ok(m);
        }
        e.only_attributes(&["type", "id", "name"])?;
        let o = Object::new(e);
        let kind = o.kind()?;
        if kind != "homogeneous" && kind != "heterogeneous" {
            return Err(
                e.error(format!("the medium `{kind}` is not rendered (homogeneous and heterogeneous media are)"))
            );
        }
        let scale = o.float("scale")?.unwrap_or(1.0);
        // A heterogeneous medium's sigma_t and albedo may be <volume> children.
        let mut volumes = std::collections::HashMap::new();
        for v in e.children.iter().filter(|c| c.tag == "volume") {
            if kind != "heterogeneous" {
                return Err(v.error("a homogeneous medium takes no <volume> (a heterogeneous one does)"));
            }
            let name = v.required("name")?;
            if name != "sigma_t" && name != "albedo" {
                return Err(v.error(format!("a medium's volume is `sigma_t` or `albedo`, not `{name}`")));
            }
            if volumes.insert(name, self.volume(v)?).is_some() {
                return Err(v.error(format!("a second `{name}`")));
            }
        }
        let (sigma, mut grid) = match volumes.remove("sigma_t") {
            Some(Volume::Grid { channels, .. }) if channels != 1 => {
                return Err(e.error(format!(
                    "the sigma_t grid has {channels} channels: an extinction that differs between channels is not \
                     rendered (give a grid of one channel)"
                )));
            }
            Some(Volume::Grid { mut grid, max, .. }) => {
                if !(max > 0.0) {
                    return Err(e.error("the sigma_t grid holds no extinction anywhere (its largest value is 0)"));
                }
                // The values as shares of the largest: the majorant sigma_t is max x scale.
                grid.values.iter_mut().for_each(|v| *v /= max);
                (glam::Vec3::splat(max * scale), Some(grid))
            }
            Some(Volume::Constant(c)) => (c * scale, None),
            None => (o.color("sigma_t")?.unwrap_or(glam::Vec3::ONE) * scale, None),
        };
        if sigma.max_element() - sigma.min_element() > 1e-6 * sigma.max_element() {
            return Err(e.error(format!(
                "sigma_t differs between channels ({sigma}): give one extinction coefficient (m^-1) for all three"
            )));
        }
        let sigma_t = sigma.x;
        if !(sigma_t > 0.0 && sigma_t.is_finite()) {
            return Err(e.error(format!("sigma_t x scale = {sigma_t} is not a positive extinction coefficient (m^-1)")));
        }
        let albedo = match volumes.remove("albedo") {
            Some(Volume::Constant(c)) => c,
            Some(Volume::Grid { grid: albedos, channels, .. }) => {
                let at = e.children.iter().find(|c| c.tag == "volume" && c.attribute("name") == Some("albedo"));
                let at = at.unwrap_or(e);
                let Some(extinction) = grid.as_mut() else {
                    return Err(at.error(
                        "an albedo grid is read on the voxels of a sigma_t grid: give sigma_t as a gridvolume too",
                    ));
                };
                let same_box = albedos.world_to_grid.abs_diff_eq(extinction.world_to_grid, 1e-5);
                if !same_box || albedos.nearest != extinction.nearest {
                    return Err(at.error("the albedo grid must share the sigma_t grid's to_world and filter_type"));
                }
                extinction
                    .set_albedo(albedos.resolution, channels, albedos.values)
                    .map_err(|err| at.error(format!("{err:#}")))?;
                glam::Vec3::ONE
            }
            None => o.color("albedo")?.unwrap_or(glam::Vec3::splat(0.75)),
        };
        if albedo.min_element() < 0.0 || albedo.max_element() > 1.0 {
            return Err(e.error(format!("albedo {albedo} is not within [0, 1]")));
        }
        // How emitters are sampled changes the noise, not the image.
        o.ignore(&["sample_emitters", "has_spectral_extinction"]);
        let mut g = 0.0;
        let mut phases = e.children.iter().filter(|c| c.tag == "phase");
        if let Some(phase) = phases.next() {
            phase.only_attributes(&["type", "id", "name"])?;
            let p = Object::new(phase);
            match p.kind()? {
                "isotropic" => {}
                "hg" => {
                    g = p.float("g")?.unwrap_or(0.8);
                    if !(g > -1.0 && g < 1.0) {
                        return Err(phase.error(format!("g {g} is not within (-1, 1)")));
                    }
                }
                other => {
                    return Err(
                        phase.error(format!("the phase function `{other}` is not rendered (hg and isotropic are)"))
                    );
                }
            }
            p.finish(&[])?;
            if let Some(second) = phases.next() {
                return Err(second.error("a medium takes one phase function"));
            }
        }
        o.finish(&["phase", "volume"])?;
        self.media.push(MediumDesc { name: e.at(), sigma_t, albedo, g, grid });
        let m = self.media.len() as u32 - 1;
        self.medium_of.insert(key, m);
        Ok(m)
    }

    /// A heterogeneous medium's `<volume>`: `constvolume` (its `value`) or `gridvolume` (its
    /// `filename`, a `.vol` file of one or three channels, over the unit cube placed by `to_world`;
    /// `filter_type` trilinear or nearest; `wrap_mode` clamp; `max_value`, a majorant at least
    /// the grid's largest value).
    fn volume(&self, v: &'e Element) -> Result<Volume> {
        v.only_attributes(&["type", "name"])?;
        let o = Object::new(v);
        let volume = match o.kind()? {
            "constvolume" => Volume::Constant(o.color("value")?.unwrap_or(glam::Vec3::ONE)),
            "gridvolume" | "grid" => {
                let file = o.string("filename")?.ok_or_else(|| v.error("`filename` is missing"))?;
                let (resolution, channels, values) =
                    read_vol(&self.base.join(file)).map_err(|err| v.error(format!("{err:#}")))?;
                let nearest = match o.string("filter_type")?.unwrap_or("trilinear") {
                    "trilinear" => false,
                    "nearest" => true,
                    other => return Err(v.error(format!("filter_type `{other}` is not trilinear or nearest"))),
                };
                match o.string("wrap_mode")?.unwrap_or("clamp") {
                    "clamp" => {}
                    other => return Err(v.error(format!("wrap_mode `{other}` is not rendered (clamp is)"))),
                }
                if o.boolean("use_grid_bbox")?.unwrap_or(false) {
                    return Err(v.error("use_grid_bbox is not read: place the grid's unit cube with to_world"));
                }
                let to_world = o.transform("to_world")?;
                if !(to_world.determinant().abs() > 0.0) {
                    return Err(v.error("to_world flattens the grid's box (its determinant is 0)"));
                }
                let largest = values.iter().fold(0.0f32, |a, &b| a.max(b));
                let max = match o.float("max_value")? {
                    Some(m) if m < largest => {
                        return Err(v.error(format!(
                            "max_value {m} is below the grid's largest value {largest}: it must bound the grid"
                        )));
                    }
                    Some(m) => m,
                    None => largest,
                };
                o.ignore(&["raw", "accel"]);
                let world_to_grid = to_world.inverse();
                Volume::Grid {
                    grid: DensityGrid { resolution, values, world_to_grid, nearest, albedo: None },
                    max,
                    channels,
                }
            }
            other => {
                return Err(v.error(format!("the volume `{other}` is not rendered (constvolume and gridvolume are)")));
            }
        };
        o.finish(&[])?;
        Ok(volume)
    }

    /// The media on a shape's two sides: its `<medium name="interior|exterior">` children and
    /// `<ref name="interior|exterior">` references (vacuum where it names none).
    pub(super) fn shape_media(&mut self, shape: &'e Element) -> Result<MediumInterface> {
        let mut interface = MediumInterface::default();
        for c in &shape.children {
            let medium = match (c.tag.as_str(), c.attribute("name")) {
                ("medium", _) => c,
                ("ref", Some("interior" | "exterior")) => self.resolve(c, "medium")?,
                _ => continue,
            };
            let side = match c.attribute("name") {
                Some("interior") => &mut interface.interior,
                Some("exterior") => &mut interface.exterior,
                _ => return Err(c.error("a shape's medium is named `interior` or `exterior`")),
            };
            let index = self.medium(medium)?;
            if side.replace(index).is_some() {
                return Err(c.error("a shape takes one interior and one exterior medium"));
            }
        }
        Ok(interface)
    }

    /// The medium a sensor stands in: its `<medium>` child or `<ref>` to one (None: vacuum).
    pub(super) fn sensor_medium(&mut self, sensor: &'e Element) -> Result<Option<u32>> {
        let mut found = None;
        for c in &sensor.children {
            let medium = match c.tag.as_str() {
                "medium" => c,
                "ref" => self.resolve(c, "medium")?,
                _ => continue,
            };
            let index = self.medium(medium)?;
            if found.replace(index).is_some() {
                return Err(c.error("a sensor stands in one medium"));
            }
        }
        Ok(found)
    }
}
