//! Mitsuba 3 XML scenes (docs/scenes.md, "Mitsuba 3 XML scenes"): the subset that maps exactly
//! onto what gatetrace renders, read into the same [`Scene`] as a glTF file. Everything outside
//! it is an error naming the file, line and element; nothing is substituted silently.
//!
//! - Structure: `<default>` and `$name` parameters (a value given in [`LoadOptions::parameters`]
//!   replaces the default), `<include>`, `id` and `<ref>`, nested objects.
//! - Transforms: `translate`, `rotate`, `scale`, `matrix`, `lookat` (module `xml`).
//! - Shapes: `obj`, `ply`, `serialized`, `rectangle`, `cube`, `sphere`, `disk`, `cylinder`
//!   (module `shapes`), with `to_world`, `flip_normals`, `face_normals` (mesh files without
//!   normals are shaded smoothly, as Mitsuba does); `shapegroup` and `instance` (each instance's
//!   copies baked in).
//! - BSDFs (module `materials`): `diffuse`, `conductor` and `roughconductor` (GGX; a smooth
//!   conductor is GGX at gatetrace's smallest roughness), `plastic` and `roughplastic`
//!   (`scene::plastic`), `twosided`.
//! - Textures of a diffuse reflectance: `bitmap` (PNG, JPEG, EXR) and `checkerboard`, with
//!   `to_uv` (baked into the texture coordinates of the shapes that use them).
//! - Emitters: `area` (on a shape), `point`, `spot` (its falloff linear in angle), `directional`.
//! - Sensors (module `sensors`): `perspective` and `thinlens`, with `hdrfilm` or mitransient's
//!   `transient_hdr_film` and a sampler; the integrator `path` or `transient_path`. Their
//!   resolution, samples, depth and time bins become the render's defaults ([`SceneSettings`]).
//! - NLOS captures (module `capture`): mitransient's `nlos_capture_meter` on a `rectangle` relay
//!   wall, a `projector` laser and `transient_nlos_path`, read into [`super::SceneCapture`].
//!
//! Lengths are the file's own units, read as metres: a gate or `start_opl` in the file's units
//! means the same path lengths.

mod capture;
mod conductors;
mod materials;
mod media;
mod sensors;
mod shapes;
mod xml;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use glam::{Mat3, Mat4, Vec3};

pub use shapes::TESSELLATION_ERROR;
use xml::{Element, Object};

use super::{
    CameraDesc, DirectionalLight, LoadOptions, MaterialDesc, MediumDesc, MediumInterface, NamedNode, PointLight, Scene,
    SceneSettings, SceneTriangle, TextureData,
};

/// Loads a Mitsuba 3 XML scene (see the module's header).
pub fn load_mitsuba(path: &Path, options: &LoadOptions) -> Result<Scene> {
    let name = path.display().to_string();
    if options.time.is_some() {
        bail!("{name}: animation times apply to glTF animations; a Mitsuba XML scene is static");
    }
    let (root, warnings) = xml::read_scene(path, &options.parameters)?;
    let default = default_bsdf();
    let mut b = Builder::new(path, &root, &default)?;
    b.warnings = warnings;
    b.for_capture = options.capture;
    for child in &root.children {
        match child.tag.as_str() {
            "default" => {}
            "shape" => b.shape(child, Mat4::IDENTITY)?,
            "emitter" => b.emitter(child)?,
            "sensor" => b.sensor(child)?,
            "integrator" => b.integrator(child)?,
            // Read where a shape refers to them.
            "bsdf" | "texture" | "medium" => {}
            other => return Err(child.error(format!("<{other}> is not understood at the top of a scene"))),
        }
    }
    b.finish()
}

/// The render settings a Mitsuba XML scene carries (its first sensor's film and sampler, and its
/// integrator) with `parameters` given, read without loading its meshes.
pub fn read_settings(path: &Path, parameters: &[(String, String)]) -> Result<SceneSettings> {
    let (root, _) = xml::read_scene(path, parameters)?;
    let default = default_bsdf();
    let mut b = Builder::new(path, &root, &default)?;
    for child in &root.children {
        match child.tag.as_str() {
            "sensor" => b.sensor(child)?,
            "integrator" => b.integrator(child)?,
            "shape" => {
                if let Some(meter) = child.children.iter().find(|c| c.tag == "sensor") {
                    let to_world = Object::new(child).transform("to_world")?;
                    b.capture_meter(meter, child, &relay_wall_name(child), to_world)?;
                }
            }
            "emitter" if child.attribute("type") == Some("projector") => b.projector(child)?,
            _ => {}
        }
    }
    b.finish_capture()?;
    Ok(b.settings)
}

/// Maps every `id` in the tree to its element; an id given twice is an error.
fn collect_ids<'e>(e: &'e Element, ids: &mut HashMap<String, &'e Element>) -> Result<()> {
    if let Some(id) = e.attribute("id").filter(|_| e.tag != "ref")
        && let Some(first) = ids.insert(id.to_owned(), e)
    {
        return Err(e.error(format!("the id `{id}` is given twice (first at line {})", first.line)));
    }
    e.children.iter().try_for_each(|c| collect_ids(c, ids))
}

struct Builder<'e> {
    name: String,
    base: PathBuf,
    ids: HashMap<String, &'e Element>,
    /// Mitsuba's default BSDF, for shapes without one.
    default_bsdf: &'e Element,
    materials: Vec<MaterialDesc>,
    /// The uv map of each material's texture (`to_uv`), baked into its triangles' uvs.
    uv_maps: HashMap<u32, glam::Affine2>,
    textures: Vec<TextureData>,
    /// Texture index per texture element address.
    texture_of: HashMap<usize, u32>,
    /// Material index per (BSDF element address, emitted radiance bits).
    material_of: HashMap<(usize, [u32; 3], MediumInterface), u32>,
    triangles: Vec<SceneTriangle>,
    point_lights: Vec<PointLight>,
    directional_lights: Vec<DirectionalLight>,
    camera: Option<CameraDesc>,
    nodes: Vec<NamedNode>,
    warnings: Vec<String>,
    dropped_degenerate: usize,
    settings: SceneSettings,
    integrator_seen: bool,
    /// What the scene holds of an NLOS capture.
    capture: capture::CaptureParts<'e>,
    /// Loading for an NLOS capture ([`LoadOptions::capture`]): no camera or light is needed.
    for_capture: bool,
    /// Media as read, each `<medium>` element's index by its address.
    media: Vec<MediumDesc>,
    medium_of: HashMap<usize, u32>,
    /// The medium the sensor stands in.
    camera_medium: Option<u32>,
    /// The integrator, when it is mitransient's transient_prbvolpath.
    transient_prbvolpath: Option<&'e Element>,
}

impl<'e> Builder<'e> {
    /// A builder for the scene `root` read from `path`.
    fn new(path: &Path, root: &'e Element, default_bsdf: &'e Element) -> Result<Self> {
        root.only_attributes(&["version"])?;
        let mut ids = HashMap::new();
        collect_ids(root, &mut ids)?;
        Ok(Builder {
            name: path.display().to_string(),
            base: path.parent().map(Path::to_path_buf).unwrap_or_default(),
            ids,
            default_bsdf,
            materials: Vec::new(),
            uv_maps: HashMap::new(),
            textures: Vec::new(),
            texture_of: HashMap::new(),
            material_of: HashMap::new(),
            triangles: Vec::new(),
            point_lights: Vec::new(),
            directional_lights: Vec::new(),
            camera: None,
            nodes: Vec::new(),
            warnings: Vec::new(),
            dropped_degenerate: 0,
            settings: SceneSettings::default(),
            integrator_seen: false,
            capture: Default::default(),
            for_capture: false,
            media: Vec::new(),
            medium_of: HashMap::new(),
            camera_medium: None,
            transient_prbvolpath: None,
        })
    }

    fn warn(&mut self, e: &Element, text: impl std::fmt::Display) {
        self.warnings.push(format!("{}: {text}", e.at()));
    }

    /// The element a `<ref id>` names, which must have tag `tag`.
    fn resolve(&self, r: &'e Element, tag: &str) -> Result<&'e Element> {
        r.only_attributes(&["id", "name"])?;
        let id = r.required("id")?;
        let target = self.ids.get(id).ok_or_else(|| r.error(format!("no object has the id `{id}`")))?;
        if target.tag != tag {
            return Err(r.error(format!("`{id}` is a <{}>, where a <{tag}> is needed", target.tag)));
        }
        Ok(target)
    }

    /// The BSDF of a shape: its one `<bsdf>` or `<ref>` child, or None for Mitsuba's default.
    fn shape_bsdf(&self, shape: &'e Element) -> Result<Option<&'e Element>> {
        let mut found = None;
        for c in &shape.children {
            let bsdf = match c.tag.as_str() {
                "bsdf" => c,
                // A shape's media are references named for their side.
                "ref" if matches!(c.attribute("name"), Some("interior" | "exterior")) => continue,
                "ref" => self.resolve(c, "bsdf")?,
                _ => continue,
            };
            if found.replace(bsdf).is_some() {
                return Err(c.error("a shape takes one BSDF"));
            }
        }
        Ok(found)
    }

    /// The material index of a shape's BSDF with its emitted radiance and the media on its two
    /// sides (a `null` BSDF: no surface, only their boundary).
    fn material(&mut self, bsdf: Option<&'e Element>, radiance: Vec3, media: MediumInterface) -> Result<u32> {
        let bsdf = bsdf.unwrap_or(self.default_bsdf);
        let key = (bsdf as *const Element as usize, radiance.to_array().map(f32::to_bits), media);
        if let Some(&m) = self.material_of.get(&key) {
            return Ok(m);
        }
        let desc = if bsdf.attribute("type") == Some("null") {
            bsdf.only_attributes(&["type", "id", "name"])?;
            Object::new(bsdf).finish(&[])?;
            MaterialDesc::null_boundary("null".into(), media)
        } else {
            let s = self.surface(bsdf)?;
            if let Some((_, map)) = s.texture {
                self.uv_maps.insert(self.materials.len() as u32, map);
            }
            MaterialDesc {
                name: s.name,
                base_color: s.base_color,
                base_color_texture: s.texture.map(|(t, _)| t),
                emission: radiance,
                double_sided: s.double_sided,
                metallic: s.metallic,
                roughness: s.roughness,
                plastic: s.plastic,
                dielectric: s.dielectric,
                conductor_index: s.conductor_index,
                media,
                null: false,
            }
        };
        self.materials.push(desc);
        let m = self.materials.len() as u32 - 1;
        self.material_of.insert(key, m);
        Ok(m)
    }

    /// Adds a shape, its own `to_world` applied after `parent` (an instance's), or the shapes of
    /// the group an `instance` refers to; a `shapegroup` adds nothing by itself.
    fn shape(&mut self, e: &'e Element, parent: Mat4) -> Result<()> {
        e.only_attributes(&["type", "id", "name"])?;
        let o = Object::new(e);
        let kind = o.kind()?;
        if kind == "shapegroup" {
            for c in &e.children {
                if c.tag != "shape" {
                    return Err(c.error("a shapegroup holds shapes only"));
                }
                if c.attribute("type").is_some_and(|t| matches!(t, "shapegroup" | "instance")) {
                    return Err(c.error("nested shapegroups and instances are not read"));
                }
                if let Some(emitter) = c.children.iter().find(|g| g.tag == "emitter") {
                    return Err(emitter.error("a shape in a shapegroup cannot emit (as in Mitsuba)"));
                }
            }
            return Ok(());
        }
        if kind == "instance" {
            let to_world = parent * o.transform("to_world")?;
            let groups: Vec<&Element> =
                e.children.iter().filter(|c| matches!(c.tag.as_str(), "ref" | "shape")).collect();
            let [group] = groups[..] else { return Err(e.error("an instance refers to one shapegroup")) };
            let group = if group.tag == "ref" { self.resolve(group, "shape")? } else { group };
            if group.attribute("type") != Some("shapegroup") {
                return Err(group.error("an instance refers to a shapegroup"));
            }
            o.finish(&["ref", "shape"])?;
            self.shape(group, Mat4::IDENTITY)?;
            for member in &group.children {
                self.shape(member, to_world)?;
            }
            return Ok(());
        }
        let mut to_world = parent * o.transform("to_world")?;
        let file = |o: &Object| -> Result<PathBuf> {
            let f = o.string("filename")?.ok_or_else(|| e.error("`filename` is missing"))?;
            Ok(self.base.join(f))
        };
        let mesh = match kind {
            "obj" => {
                let flip = o.boolean("flip_tex_coords")?.unwrap_or(true);
                shapes::read_obj(&file(&o)?, flip)
            }
            "ply" => shapes::read_ply(&file(&o)?),
            "rectangle" => Ok(shapes::rectangle()),
            "cube" => Ok(shapes::cube()),
            "disk" => Ok(shapes::disk()),
            "sphere" => {
                let center = o.point("center")?.unwrap_or(Vec3::ZERO);
                let radius = o.float("radius")?.unwrap_or(1.0);
                if radius <= 0.0 {
                    return Err(e.error(format!("radius {radius} is not positive")));
                }
                to_world = to_world * Mat4::from_translation(center) * Mat4::from_scale(Vec3::splat(radius));
                Ok(shapes::sphere())
            }
            "cylinder" => {
                let p0 = o.point("p0")?.unwrap_or(Vec3::ZERO);
                let p1 = o.point("p1")?.unwrap_or(Vec3::Z);
                let radius = o.float("radius")?.unwrap_or(1.0);
                let axis = p1 - p0;
                if radius <= 0.0 || axis.length() == 0.0 {
                    return Err(e.error("the cylinder needs a positive radius and p0 != p1"));
                }
                let z = axis.normalize();
                let (x, y) = z.any_orthonormal_pair();
                let frame = Mat4::from_mat3(Mat3::from_cols(x * radius, y * radius, axis));
                to_world = to_world * Mat4::from_translation(p0) * frame;
                Ok(shapes::cylinder())
            }
            "serialized" => {
                let index = o.integer("shape_index")?.unwrap_or(0);
                let index = u32::try_from(index).map_err(|_| e.error(format!("shape_index {index} is negative")))?;
                shapes::read_serialized(&file(&o)?, index)
            }
            other => return Err(e.error(format!("the shape `{other}` is not read by gatetrace"))),
        };
        let mut mesh = mesh.map_err(|err| e.error(format!("{err:#}")))?;
        if o.boolean("face_normals")?.unwrap_or(false) {
            mesh.normals = None;
        } else if matches!(kind, "obj" | "ply" | "serialized") {
            // Mitsuba shades a mesh file without normals smoothly.
            mesh.smooth_normals();
        }
        let flip = o.boolean("flip_normals")?.unwrap_or(false);
        let bsdf = self.shape_bsdf(e)?;
        let mut radiance = Vec3::ZERO;
        let mut emitters = e.children.iter().filter(|c| c.tag == "emitter");
        if let Some(emitter) = emitters.next() {
            emitter.only_attributes(&["type", "id", "name"])?;
            let eo = Object::new(emitter);
            if eo.kind()? != "area" {
                return Err(emitter.error("a shape carries only `area` emitters"));
            }
            radiance = eo.color("radiance")?.unwrap_or(Vec3::ONE);
            if radiance.min_element() < 0.0 {
                return Err(emitter.error("negative radiance"));
            }
            eo.finish(&[])?;
            if let Some(second) = emitters.next() {
                return Err(second.error("a shape takes one emitter"));
            }
            if bsdf.is_some_and(|b| b.attribute("type") == Some("twosided")) {
                return Err(emitter.error(
                    "an area emitter on a shape with a twosided BSDF: gatetrace's two-sided materials emit from \
                     both faces, Mitsuba's area emitters from the front only",
                ));
            }
        }
        o.finish(&["bsdf", "ref", "emitter", "sensor", "medium"])?;
        let media = self.shape_media(e)?;
        if let Some(null) = bsdf.filter(|b| b.attribute("type") == Some("null")) {
            if radiance != Vec3::ZERO {
                return Err(null.error("an area emitter on a `null` surface (which is not there) is not rendered"));
            }
            if media == MediumInterface::default() {
                // Nothing there and no medium bounded: the shape changes nothing.
                return Ok(());
            }
        }
        let material = self.material(bsdf, radiance, media)?;
        let mut sensors = e.children.iter().filter(|c| c.tag == "sensor");
        let Some(meter) = sensors.next() else {
            return self.add_mesh(e, &mesh, to_world, flip, material, e.attribute("id").or(e.attribute("name")));
        };
        if let Some(second) = sensors.next() {
            return Err(second.error("a shape carries one sensor"));
        }
        if parent != Mat4::IDENTITY {
            return Err(meter.error("a relay wall in an instance is not read"));
        }
        let wall = relay_wall_name(e);
        self.capture_meter(meter, e, &wall, to_world)?;
        self.add_mesh(e, &mesh, to_world, flip, material, Some(&wall))
    }

    /// Adds a mesh's triangles in world space (a named node when `node` names it).
    fn add_mesh(
        &mut self,
        e: &Element,
        mesh: &shapes::Mesh,
        to_world: Mat4,
        flip: bool,
        material: u32,
        node: Option<&str>,
    ) -> Result<()> {
        let normal_matrix = Mat3::from_mat4(to_world).inverse().transpose();
        let positions: Vec<Vec3> = mesh.positions.iter().map(|&p| to_world.transform_point3(p)).collect();
        if let Some(p) = positions.iter().find(|p| p.abs().max_element() > super::gltf_loader::MAX_COORDINATE) {
            return Err(e.error(format!("a vertex lies at {p}, beyond the coordinates gatetrace accepts")));
        }
        let sign = if flip { -1.0 } else { 1.0 };
        let normals: Option<Vec<Vec3>> =
            mesh.normals.as_ref().map(|n| n.iter().map(|&v| sign * (normal_matrix * v).normalize_or_zero()).collect());
        // A triangle with a vanishing vertex normal keeps its own flat normal.
        let usable = |n: [Vec3; 3]| n.iter().all(|v| v.length_squared() > 0.5);
        let first = self.triangles.len();
        let uv_map = self.uv_maps.get(&material).copied().unwrap_or(glam::Affine2::IDENTITY);
        for t in mesh.indices.chunks_exact(3) {
            let [a, b, c] = [t[0] as usize, t[1] as usize, t[2] as usize];
            let [a, b, c] = if flip { [a, c, b] } else { [a, b, c] };
            let triangle = SceneTriangle {
                positions: [positions[a], positions[b], positions[c]],
                normals: normals.as_ref().map(|n| [n[a], n[b], n[c]]).filter(|n| usable(*n)),
                uvs: mesh
                    .uvs
                    .as_ref()
                    .map_or([glam::Vec2::ZERO; 3], |u| [u[a], u[b], u[c]].map(|t| uv_map.transform_point2(t))),
                material,
            };
            if triangle.area() > 0.0 {
                self.triangles.push(triangle);
            } else {
                self.dropped_degenerate += 1;
            }
        }
        if let Some(id) = node {
            self.nodes.push(NamedNode {
                name: id.to_owned(),
                position: to_world.transform_point3(Vec3::ZERO),
                triangles: first..self.triangles.len(),
                texcoords: mesh.uvs.as_ref().map(|_| self.triangles[first..].iter().map(|t| t.uvs).collect()),
            });
        }
        Ok(())
    }

    fn emitter(&mut self, e: &'e Element) -> Result<()> {
        e.only_attributes(&["type", "id", "name"])?;
        let o = Object::new(e);
        match o.kind()? {
            "point" => {
                let to_world = o.transform("to_world")?;
                let position = o.point("position")?.unwrap_or(Vec3::ZERO);
                let intensity = o.color("intensity")?.unwrap_or(Vec3::ONE);
                if intensity.min_element() < 0.0 {
                    return Err(e.error("negative intensity"));
                }
                o.finish(&[])?;
                self.point_lights.push(PointLight {
                    position: to_world.transform_point3(position),
                    intensity,
                    spot: None,
                });
            }
            "directional" => {
                let to_world = o.transform("to_world")?;
                let direction = o.point("direction")?.unwrap_or(Vec3::Z);
                let direction = to_world
                    .transform_vector3(direction)
                    .try_normalize()
                    .ok_or_else(|| e.error("the light's direction is zero"))?;
                let irradiance = o.color("irradiance")?.unwrap_or(Vec3::ONE);
                if irradiance.min_element() < 0.0 {
                    return Err(e.error("negative irradiance"));
                }
                o.finish(&[])?;
                self.directional_lights.push(DirectionalLight { direction, irradiance });
            }
            "area" => return Err(e.error("an area emitter belongs inside a <shape>")),
            "spot" => {
                if let Some(t) = e.children.iter().find(|c| matches!(c.tag.as_str(), "texture" | "ref")) {
                    return Err(t.error("a spot light's texture is not rendered"));
                }
                let to_world = o.transform("to_world")?;
                let intensity = o.color("intensity")?.unwrap_or(Vec3::ONE);
                let cutoff = o.float("cutoff_angle")?.unwrap_or(20.0);
                let beam = o.float("beam_width")?.unwrap_or(0.75 * cutoff);
                if intensity.min_element() < 0.0 {
                    return Err(e.error("negative intensity"));
                }
                if !(cutoff > 0.0 && cutoff <= 90.0 && beam >= 0.0 && beam <= cutoff) {
                    return Err(e.error(format!(
                        "cutoff_angle {cutoff} and beam_width {beam} (degrees): gatetrace renders spots of 0 <= \
                         beam_width <= cutoff_angle <= 90"
                    )));
                }
                o.finish(&[])?;
                let direction = to_world
                    .transform_vector3(Vec3::Z)
                    .try_normalize()
                    .ok_or_else(|| e.error("the light's to_world is degenerate"))?;
                let spot = super::SpotCone {
                    direction,
                    inner: beam.to_radians(),
                    outer: cutoff.to_radians(),
                    falloff: super::SpotFalloff::LinearInAngle,
                };
                let position = to_world.transform_point3(Vec3::ZERO);
                self.point_lights.push(PointLight { position, intensity, spot: Some(spot) });
            }
            "projector" => self.projector(e)?,
            kind @ ("constant" | "envmap" | "sunsky") => {
                return Err(e.error(format!("environment lighting (`{kind}`) is not rendered")));
            }
            other => return Err(e.error(format!("the emitter `{other}` is not rendered by gatetrace"))),
        }
        Ok(())
    }

    fn finish(mut self) -> Result<Scene> {
        let capture = self.finish_capture()?;
        let name = self.name;
        if let Some(c) = capture.as_ref().filter(|_| !self.for_capture) {
            bail!(
                "{name}: the scene describes an NLOS capture (an nlos_capture_meter on `{}`): render it with \
                 `gatetrace render` (or `gatetrace.capture` in Python); a camera image needs a perspective sensor",
                c.relay_wall
            );
        }
        let for_capture = self.for_capture;
        let camera = match self.camera {
            Some(camera) => camera,
            None if for_capture => super::CameraDesc::placeholder(&self.triangles),
            None => bail!("{name}: no <sensor>: gatetrace renders from a perspective sensor"),
        };
        if self.triangles.is_empty() {
            bail!("{name}: the scene has no triangles");
        }
        if self.triangles.len() > crate::gpu::layout::MAX_TRIANGLES as usize {
            bail!(
                "{name}: {} triangles exceed the supported {}",
                self.triangles.len(),
                crate::gpu::layout::MAX_TRIANGLES
            );
        }
        let emissive = self.triangles.iter().any(|t| self.materials[t.material as usize].is_emissive());
        let powered = self.point_lights.iter().any(|l| l.intensity.max_element() > 0.0)
            || self.directional_lights.iter().any(|l| l.irradiance.max_element() > 0.0);
        if !emissive && !powered && !for_capture {
            bail!("{name}: no emitter gives light (area emitters on shapes, point and directional emitters)");
        }
        let mut warnings = self.warnings;
        if let (Some(integrator), Some(_)) = (self.transient_prbvolpath, self.camera_medium) {
            warnings.push(format!(
                "{}: the sensor stands in a medium: gatetrace starts camera rays in it, while mitransient 1.3.1's \
                 transient_prbvolpath starts them in vacuum whatever the sensor's medium",
                integrator.at()
            ));
        }
        if self.dropped_degenerate > 0 {
            warnings.push(format!("{name}: dropped {} zero-area triangles", self.dropped_degenerate));
        }
        Ok(Scene {
            source: name,
            triangles: self.triangles,
            materials: self.materials,
            textures: self.textures,
            point_lights: self.point_lights,
            directional_lights: self.directional_lights,
            camera,
            dropped_degenerate: self.dropped_degenerate,
            nodes: self.nodes,
            warnings,
            settings: self.settings,
            media: self.media,
            camera_medium: self.camera_medium,
        })
    }
}

/// The node name of a relay wall (a shape carrying a capture meter): its id, else `relay_wall`.
fn relay_wall_name(shape: &Element) -> String {
    shape.attribute("id").or(shape.attribute("name")).unwrap_or(super::DEFAULT_RELAY_WALL).to_owned()
}

/// Mitsuba's default BSDF (diffuse, reflectance 0.5) as an element.
fn default_bsdf() -> Element {
    Element {
        tag: "bsdf".into(),
        attributes: vec![("type".into(), "diffuse".into()), ("id".into(), "(default)".into())],
        children: Vec::new(),
        file: "(Mitsuba's default BSDF)".into(),
        line: 1,
    }
}
