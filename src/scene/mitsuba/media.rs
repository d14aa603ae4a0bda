//! Participating media of Mitsuba scenes: `homogeneous` media with a `hg` or `isotropic` phase
//! function, bounded by shapes with a `null` BSDF (their `interior` and `exterior` media) or
//! around the sensor.

use anyhow::Result;

use super::Builder;
use super::xml::{Element, Object};
use crate::scene::{MediumDesc, MediumInterface};

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
        if kind != "homogeneous" {
            return Err(e.error(format!("the medium `{kind}` is not rendered (homogeneous media are)")));
        }
        let scale = o.float("scale")?.unwrap_or(1.0);
        let sigma = o.color("sigma_t")?.unwrap_or(glam::Vec3::ONE) * scale;
        if sigma.max_element() - sigma.min_element() > 1e-6 * sigma.max_element() {
            return Err(e.error(format!(
                "sigma_t differs between channels ({sigma}): give one extinction coefficient (m^-1) for all three"
            )));
        }
        let sigma_t = sigma.x;
        if !(sigma_t > 0.0 && sigma_t.is_finite()) {
            return Err(e.error(format!("sigma_t x scale = {sigma_t} is not a positive extinction coefficient (m^-1)")));
        }
        let albedo = o.color("albedo")?.unwrap_or(glam::Vec3::splat(0.75));
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
        o.finish(&["phase"])?;
        self.media.push(MediumDesc { name: e.at(), sigma_t, albedo, g });
        let m = self.media.len() as u32 - 1;
        self.medium_of.insert(key, m);
        Ok(m)
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
