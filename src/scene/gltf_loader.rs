//! glTF 2.0 loading (docs/design.md section 3): triangles with node transforms baked in, the first
//! camera (with its thin lens from extras), materials (a Lambertian lobe from baseColor x
//! texture blended with a GGX conductor by metallic), emissive materials as area lights,
//! KHR_lights_punctual point, spot and directional lights. Every problem is reported with the
//! file's name. Materials and their textures are read in `materials`.

mod materials;

use std::path::Path;

use anyhow::{Context as _, Result, anyhow, bail};
use glam::{Mat3, Mat4, Vec2, Vec3};

use super::camera::ThinLens;
use super::{CameraDesc, DirectionalLight, MaterialDesc, PointLight, Scene, SceneTriangle, SpotCone, SpotFalloff};
pub use materials::srgb_to_linear;

/// The glTF extensions gatetrace implements; any other is refused when a file requires it
/// (`extensionsRequired`) and warned about when a file uses it.
pub const IMPLEMENTED_EXTENSIONS: [&str; 2] = ["KHR_lights_punctual", "KHR_materials_emissive_strength"];

/// Material extensions that let light pass through a surface or into a medium behind it. Every
/// surface gatetrace renders is opaque, which no approximation of these comes near (glass would
/// render as a coloured wall), so a material using one is refused unless
/// [`LoadOptions::allow_unsupported_materials`] is set; other unimplemented material extensions
/// (clearcoat, sheen, specular, ...) are ignored with a warning.
pub const TRANSMISSIVE_EXTENSIONS: [&str; 3] =
    ["KHR_materials_transmission", "KHR_materials_volume", "KHR_materials_diffuse_transmission"];

/// How a scene file is loaded.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// Time (s of the animation clock) at which node animations are sampled and baked in like
    /// static transforms (see `animation`); `None`: the rest pose.
    pub time: Option<f64>,
    /// Loading for an NLOS capture (`crate::nlos`), whose laser and sensor replace the scene's
    /// lights and camera: both are optional. Without a camera node, a placeholder pinhole at the
    /// centre of the triangles' bounds stands in (captures never look through it).
    pub capture: bool,
    /// Render materials with a [`TRANSMISSIVE_EXTENSIONS`] extension as the opaque surfaces their
    /// core glTF properties describe, with a warning, instead of refusing the scene.
    pub allow_unsupported_materials: bool,
    /// A Mitsuba XML scene's parameters (name, value): each replaces the file's `<default>` for
    /// `$name` (`mitsuba -D name=value`; `render --define`). A glTF file takes none.
    pub parameters: Vec<(String, String)>,
    /// A homogeneous fog filling all space (`Scene::add_fog`; `render --fog`), applied by
    /// `load_scene_with`.
    pub fog: Option<super::MediumDesc>,
}

/// Loads a `.gltf` or `.glb` file in its rest pose (animations not applied).
pub fn load_gltf(path: &Path) -> Result<Scene> {
    load_gltf_with(path, &LoadOptions::default())
}

/// Loads a `.gltf` or `.glb` file; with `time` (s of the animation clock), its node animations
/// are sampled at that time and baked in like static transforms (see `animation`).
pub fn load_gltf_at(path: &Path, time: Option<f64>) -> Result<Scene> {
    load_gltf_with(path, &LoadOptions { time, ..Default::default() })
}

/// Loads a `.gltf` or `.glb` file for an NLOS capture (see [`LoadOptions::capture`]).
pub fn load_gltf_for_capture(path: &Path) -> Result<Scene> {
    load_gltf_with(path, &LoadOptions { capture: true, ..Default::default() })
}

/// Loads a `.gltf` or `.glb` file as `options` say. A file in another format (OBJ, PLY, Mitsuba
/// XML, ...: see `formats`) is refused with what it is and how to convert it.
pub fn load_gltf_with(path: &Path, options: &LoadOptions) -> Result<Scene> {
    let name = path.display().to_string();
    if let Some((parameter, _)) = options.parameters.first() {
        bail!("{name}: parameters (here `{parameter}`) apply to Mitsuba XML scenes, not to glTF files");
    }
    let bytes = std::fs::read(path).with_context(|| format!("{name}: cannot read the scene file"))?;
    if let Some(error) = super::formats::foreign_format_error(&name, path, &bytes) {
        bail!(error);
    }
    let gltf = parse_gltf(&name, path, &bytes)?;
    let base = path.parent().unwrap_or(Path::new("."));
    let buffers = gltf::import_buffers(&gltf.document, Some(base), gltf.blob.clone())
        .map_err(|e| anyhow!("{name}: cannot load a buffer: {e}"))?;
    let images = gltf::import_images(&gltf.document, Some(base), &buffers)
        .map_err(|e| anyhow!("{name}: cannot load an image: {e}"))?;
    let pose = match options.time {
        Some(t) => super::animation::sample_animations(&name, &gltf.document, &buffers, t)?,
        None => Default::default(),
    };
    Loader {
        name: &name,
        base,
        buffers: &buffers,
        images: &images,
        pose,
        capture: options.capture,
        allow_unsupported_materials: options.allow_unsupported_materials,
        warnings: Default::default(),
    }
    .load(&gltf.document)
}

/// Parses and validates a glTF or GLB file's bytes (`name`: the file in messages), as
/// `gltf::Gltf::from_slice` does, but first refuses extensions the file requires that gatetrace
/// does not implement and checks what that validation indexes without checking (gltf-json 1.4.1
/// panics on a primitive whose POSITION names no accessor), and afterwards the byte ranges the
/// crate's readers compute unchecked (`check_buffer_ranges`).
fn parse_gltf(name: &str, path: &Path, bytes: &[u8]) -> Result<gltf::Gltf> {
    use gltf::json::validation::{Error, Validate};
    let invalid =
        |e: String| anyhow!("{name}: not a valid glTF 2.0 file: {e}{}", super::formats::supported_formats_hint(path));
    let gltf = gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| invalid(e.to_string()))?;
    let root = gltf.document.as_json();
    if let Some(extension) = root.extensions_required.iter().find(|e| !IMPLEMENTED_EXTENSIONS.contains(&e.as_str())) {
        bail!(
            "{name}: the file requires the glTF extension {extension} (extensionsRequired), which gatetrace does not \
             implement (it implements {}): export the scene without it",
            IMPLEMENTED_EXTENSIONS.join(", ")
        );
    }
    let mut errors = Vec::new();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            let position = primitive.attributes.get(&gltf::json::validation::Checked::Valid(gltf::Semantic::Positions));
            if position.is_some_and(|a| a.value() >= root.accessors.len()) {
                let path = gltf::json::Path::new().field("meshes").index(m).field("primitives").index(p);
                errors.push((path.field("attributes").key("POSITION"), Error::IndexOutOfBounds));
            }
        }
    }
    if errors.is_empty() {
        root.validate(root, gltf::json::Path::new, &mut |path, error| errors.push((path(), error)));
    }
    if !errors.is_empty() {
        return Err(invalid(gltf::Error::Validation(errors).to_string()));
    }
    check_buffer_ranges(&gltf.document).map_err(invalid)?;
    Ok(gltf)
}

/// Checks, with arithmetic that cannot overflow, that every buffer view lies in its buffer and
/// every accessor (and each part of a sparse one) in its view, with a count of at least 1 and
/// a stride of at least an element: the gltf crate computes these ranges unchecked (an
/// overflow panics in a debug build and slices wrongly in a release build).
fn check_buffer_ranges(doc: &gltf::Document) -> Result<(), String> {
    use gltf::json::accessor::ComponentType;
    use gltf::json::validation::Checked;
    for view in doc.views() {
        let buffer = view.buffer();
        let end = (view.offset() as u64).checked_add(view.length() as u64);
        if end.is_none_or(|end| end > buffer.length() as u64) {
            return Err(format!(
                "bufferViews[{}]: {} bytes from byte {} lie outside buffer {} ({} bytes)",
                view.index(),
                view.length(),
                view.offset(),
                buffer.index(),
                buffer.length()
            ));
        }
    }
    // `count` elements of `size` bytes, `stride` apart from byte `offset`, must lie in `view`.
    let fits = |what: &str, view: gltf::buffer::View, offset: usize, stride: usize, count: usize, size: usize| {
        let end = (count as u64 - 1)
            .checked_mul(stride as u64)
            .and_then(|e| e.checked_add(offset as u64))
            .and_then(|e| e.checked_add(size as u64));
        match end {
            Some(end) if stride >= size && end <= view.length() as u64 => Ok(()),
            _ => Err(format!(
                "{what}: {count} elements of {size} bytes, {stride} bytes apart from byte {offset}, do not fit buffer view \
                 {} ({} bytes)",
                view.index(),
                view.length()
            )),
        }
    };
    for a in doc.accessors() {
        let what = format!("accessors[{}]", a.index());
        if a.count() == 0 {
            return Err(format!("{what}: count 0 (glTF requires at least 1)"));
        }
        let size = a.size();
        if let Some(view) = a.view() {
            let stride = view.stride().unwrap_or(size);
            fits(&what, view, a.offset(), stride, a.count(), size)?;
        }
        if let Some(sparse) = doc.as_json().accessors[a.index()].sparse.as_ref() {
            let integer = matches!(sparse.indices.component_type,
                Checked::Valid(t) if matches!(t.0, ComponentType::U8 | ComponentType::U16 | ComponentType::U32));
            if !integer {
                return Err(format!("{what}: sparse indices must be unsigned bytes, shorts or ints"));
            }
            let sparse = a.sparse().expect("checked above");
            if sparse.count() == 0 || sparse.count() > a.count() {
                return Err(format!("{what}: {} sparse values for {} elements", sparse.count(), a.count()));
            }
            let (indices, values) = (sparse.indices(), sparse.values());
            let index_size = indices.index_type().size();
            fits(
                &format!("{what}.sparse.indices"),
                indices.view(),
                indices.offset(),
                index_size,
                sparse.count(),
                index_size,
            )?;
            fits(&format!("{what}.sparse.values"), values.view(), values.offset(), size, sparse.count(), size)?;
        }
    }
    Ok(())
}

struct Loader<'a> {
    name: &'a str,
    /// The directory the file's relative paths start from (its buffers, images and grids).
    base: &'a Path,
    buffers: &'a [gltf::buffer::Data],
    images: &'a [gltf::image::Data],
    /// Local transforms of animated nodes at the requested time (node index -> matrix).
    pose: std::collections::HashMap<usize, Mat4>,
    /// Loading for an NLOS capture: no camera or light is required.
    capture: bool,
    /// See [`LoadOptions::allow_unsupported_materials`].
    allow_unsupported_materials: bool,
    /// What the file holds that is ignored or changed ([`Scene::warnings`]).
    warnings: std::cell::RefCell<Vec<String>>,
}

/// What the scene-graph walk collects.
#[derive(Default)]
struct Collected {
    triangles: Vec<SceneTriangle>,
    point_lights: Vec<PointLight>,
    directional_lights: Vec<DirectionalLight>,
    camera: Option<CameraDesc>,
    dropped_degenerate: usize,
    nodes: Vec<super::NamedNode>,
    /// TEXCOORD_0 of the triangles of the named node being loaded, while all its primitives have
    /// them (None for unnamed nodes: only named ones can be looked up).
    texcoords: Option<Vec<[Vec2; 3]>>,
}

impl Loader<'_> {
    /// Records a warning for [`Scene::warnings`] (`text` names the file).
    fn warn(&self, text: String) {
        self.warnings.borrow_mut().push(text);
    }

    fn load(&self, doc: &gltf::Document) -> Result<Scene> {
        let name = self.name;
        let scene = doc
            .default_scene()
            .or_else(|| doc.scenes().next())
            .ok_or_else(|| anyhow!("{name}: the file has no scene"))?;
        let mut textures = Vec::new();
        let mut texture_of_image = std::collections::HashMap::new();
        let mut media = Vec::new();
        let mut materials = Vec::new();
        for m in doc.materials() {
            materials.push(self.material(&m, &mut textures, &mut texture_of_image, &mut media)?);
        }
        // Extensions declared but found on no material (where `material` reports them): on
        // textures, meshes or nodes, or nowhere.
        for extension in &doc.as_json().extensions_used {
            let on_a_material = doc.materials().any(|m| m.extension_value(extension).is_some());
            if !IMPLEMENTED_EXTENSIONS.contains(&extension.as_str()) && !on_a_material {
                self.warn(format!(
                    "{name}: the file uses the glTF extension {extension} (extensionsUsed), which gatetrace does not \
                     implement: ignored"
                ));
            }
        }
        // Primitives without a material get glTF's default material (white, one-sided).
        let default_material = materials.len() as u32;
        materials.push(MaterialDesc {
            name: "(default)".into(),
            base_color: Vec3::ONE,
            base_color_texture: None,
            emission: Vec3::ZERO,
            double_sided: false,
            metallic: 1.0,
            roughness: 1.0,
            plastic: None,
            dielectric: None,
            conductor_index: None,
            media: Default::default(),
            null: false,
        });

        let mut c = Collected::default();
        for node in scene.nodes() {
            self.walk(&node, Mat4::IDENTITY, &materials, default_material, &mut c)?;
        }
        let camera = match c.camera {
            Some(camera) => camera,
            None if self.capture => CameraDesc::placeholder(&c.triangles),
            None => bail!(
                "{name}: no camera: gatetrace renders from the first perspective camera node of the scene (an NLOS \
                 capture, --nlos, needs none)"
            ),
        };
        if c.triangles.is_empty() && c.dropped_degenerate > 0 {
            bail!("{name}: all {} triangles of the scene have zero area", c.dropped_degenerate);
        }
        if c.triangles.is_empty() {
            bail!("{name}: the scene has no triangles");
        }
        let emissive = c.triangles.iter().any(|t| materials[t.material as usize].is_emissive());
        let punctual = c.point_lights.len() + c.directional_lights.len();
        if !emissive && punctual == 0 && !self.capture {
            bail!(
                "{name}: no light: add an emissive material (emissiveFactor, KHR_materials_emissive_strength) \
                 or a KHR_lights_punctual light (an NLOS capture, --nlos, needs none)"
            );
        }
        let powered = c.point_lights.iter().any(|l| l.intensity.max_element() > 0.0)
            || c.directional_lights.iter().any(|l| l.irradiance.max_element() > 0.0);
        if !emissive && !powered && !self.capture {
            bail!(
                "{name}: the scene's {punctual} KHR_lights_punctual lights emit no power (intensity 0) and no material \
                 is emissive: the image would be black"
            );
        }
        if c.triangles.len() > crate::gpu::layout::MAX_TRIANGLES as usize {
            bail!("{name}: {} triangles exceed the supported {}", c.triangles.len(), crate::gpu::layout::MAX_TRIANGLES);
        }
        if c.dropped_degenerate > 0 {
            self.warn(format!("{name}: dropped {} zero-area triangles", c.dropped_degenerate));
        }
        Ok(Scene {
            source: name.to_owned(),
            triangles: c.triangles,
            materials,
            textures,
            point_lights: c.point_lights,
            directional_lights: c.directional_lights,
            camera,
            dropped_degenerate: c.dropped_degenerate,
            nodes: c.nodes,
            warnings: self.warnings.take(),
            settings: Default::default(),
            media,
            camera_medium: None,
        })
    }

    fn walk(
        &self,
        node: &gltf::Node,
        parent: Mat4,
        materials: &[MaterialDesc],
        default_material: u32,
        c: &mut Collected,
    ) -> Result<()> {
        let name = self.name;
        let node_name = node.name().map(|n| format!("node `{n}`")).unwrap_or(format!("node {}", node.index()));
        let local = match self.pose.get(&node.index()) {
            Some(&m) => m,
            None => Mat4::from_cols_array_2d(&node.transform().matrix()),
        };
        let world = parent * local;
        if !world.is_finite() {
            bail!("{name}: {node_name} has a non-finite transform");
        }
        if let Some(camera) = node.camera()
            && c.camera.is_none()
        {
            c.camera = Some(self.camera(&camera, node, world, &node_name)?);
        }
        if let Some(light) = node.light() {
            self.punctual_light(&light, world, &node_name, c)?;
        }
        let first = c.triangles.len();
        c.texcoords = node.name().map(|_| Vec::new());
        if let Some(mesh) = node.mesh() {
            self.mesh(&mesh, world, &node_name, default_material, materials, c)?;
        }
        let texcoords = c.texcoords.take();
        if let Some(n) = node.name() {
            c.nodes.push(super::NamedNode {
                name: n.to_owned(),
                position: world.transform_point3(Vec3::ZERO),
                triangles: first..c.triangles.len(),
                texcoords,
            });
        }
        for child in node.children() {
            self.walk(&child, world, materials, default_material, c)?;
        }
        Ok(())
    }

    fn camera(&self, camera: &gltf::Camera, node: &gltf::Node, world: Mat4, node_name: &str) -> Result<CameraDesc> {
        let name = self.name;
        let gltf::camera::Projection::Perspective(p) = camera.projection() else {
            bail!("{name}: {node_name}: orthographic cameras are not supported (use a perspective camera)");
        };
        let yfov = p.yfov();
        if !(yfov.is_finite() && yfov > 0.0 && yfov < std::f32::consts::PI) {
            bail!("{name}: {node_name}: camera yfov {yfov} rad is not in (0, pi)");
        }
        let (scale, rotation, position) = world.to_scale_rotation_translation();
        let frame = Mat3::from_quat(rotation);
        let camera = CameraDesc {
            position,
            right: frame.x_axis.normalize(),
            up: frame.y_axis.normalize(),
            forward: (-frame.z_axis).normalize(),
            yfov,
            lens: thin_lens(node.extras().as_deref().or(camera.extras().as_deref()))
                .map_err(|e| anyhow!("{name}: {node_name}: camera extras: {e}"))?,
        };
        let finite = [camera.position, camera.right, camera.up, camera.forward].iter().all(|v| v.is_finite());
        if !finite || scale.min_element().abs() < 1e-12 {
            bail!("{name}: {node_name}: the camera's transform is degenerate (zero scale or non-finite)");
        }
        Ok(camera)
    }

    fn punctual_light(
        &self,
        light: &gltf::khr_lights_punctual::Light,
        world: Mat4,
        node_name: &str,
        c: &mut Collected,
    ) -> Result<()> {
        let name = self.name;
        match light.kind() {
            kind @ (gltf::khr_lights_punctual::Kind::Point | gltf::khr_lights_punctual::Kind::Spot { .. }) => {
                let intensity = Vec3::from(light.color()) * light.intensity();
                if !intensity.is_finite() || intensity.min_element() < 0.0 {
                    bail!("{name}: {node_name}: light intensity {intensity} is not finite and non-negative");
                }
                let spot = match kind {
                    gltf::khr_lights_punctual::Kind::Spot { inner_cone_angle, outer_cone_angle } => {
                        let (inner, outer) = (inner_cone_angle, outer_cone_angle);
                        if !(inner.is_finite()
                            && outer.is_finite()
                            && 0.0 <= inner
                            && inner < outer
                            && outer <= std::f32::consts::FRAC_PI_2 + 1e-6)
                        {
                            bail!(
                                "{name}: {node_name}: spot cone angles inner {inner} rad, outer {outer} rad: glTF \
                                 needs 0 <= inner < outer <= pi/2"
                            );
                        }
                        Some(SpotCone {
                            direction: light_direction(world, name, node_name)?,
                            inner,
                            outer,
                            falloff: SpotFalloff::CosineRampSquared,
                        })
                    }
                    _ => None,
                };
                c.point_lights.push(PointLight { position: world.transform_point3(Vec3::ZERO), intensity, spot });
                Ok(())
            }
            gltf::khr_lights_punctual::Kind::Directional => {
                let irradiance = Vec3::from(light.color()) * light.intensity();
                if !irradiance.is_finite() || irradiance.min_element() < 0.0 {
                    bail!(
                        "{name}: {node_name}: directional light irradiance {irradiance} is not finite and non-negative"
                    );
                }
                let direction = light_direction(world, name, node_name)?;
                c.directional_lights.push(DirectionalLight { direction, irradiance });
                Ok(())
            }
        }
    }

    fn mesh(
        &self,
        mesh: &gltf::Mesh,
        world: Mat4,
        node_name: &str,
        default_material: u32,
        materials: &[MaterialDesc],
        c: &mut Collected,
    ) -> Result<()> {
        let name = self.name;
        let normal_matrix = Mat3::from_mat4(world).inverse().transpose();
        let mesh_name = mesh.name().map(|n| format!("mesh `{n}`")).unwrap_or(format!("mesh {}", mesh.index()));
        for (pi, prim) in mesh.primitives().enumerate() {
            let what = format!("{node_name}, {mesh_name}, primitive {pi}");
            if prim.mode() != gltf::mesh::Mode::Triangles {
                bail!("{name}: {what}: primitive mode {:?} is not supported (triangles only)", prim.mode());
            }
            check_accessors(&prim).map_err(|e| anyhow!("{name}: {what}: {e}"))?;
            let reader = prim.reader(|b| self.buffers.get(b.index()).map(|d| d.0.as_slice()));
            let positions: Vec<Vec3> = reader
                .read_positions()
                .ok_or_else(|| anyhow!("{name}: {what}: no POSITION attribute"))?
                .map(|p| world.transform_point3(Vec3::from(p)))
                .collect();
            if let Some(bad) = positions.iter().position(|p| !p.is_finite()) {
                bail!("{name}: {what}: vertex {bad} is not finite");
            }
            if let Some((i, p)) = positions.iter().enumerate().find(|(_, p)| p.abs().max_element() > MAX_COORDINATE) {
                bail!(
                    "{name}: {what}: vertex {i} has a coordinate of {:e} m, beyond the +-{MAX_COORDINATE:e} m gatetrace \
                     accepts (f32 coordinates are 64 m apart there: keep the scene near the origin)",
                    p.abs().max_element()
                );
            }
            let normals: Option<Vec<Vec3>> = reader
                .read_normals()
                .map(|it| it.map(|n| (normal_matrix * Vec3::from(n)).normalize_or_zero()).collect());
            let material = prim.material().index().map_or(default_material, |i| i as u32);
            let uv_set = materials[material as usize]
                .base_color_texture
                .and(prim.material().pbr_metallic_roughness().base_color_texture().map(|t| t.tex_coord()));
            let uvs: Option<Vec<Vec2>> =
                uv_set.and_then(|set| reader.read_tex_coords(set)).map(|it| it.into_f32().map(Vec2::from).collect());
            // A named node's TEXCOORD_0, whatever the material: an NLOS capture lays its grid on the
            // relay wall's (the base-colour set again when that is set 0).
            let texcoord0: Option<Vec<Vec2>> = match (&c.texcoords, uv_set) {
                (None, _) => None,
                (Some(_), Some(0)) => uvs.clone(),
                (Some(_), _) => reader.read_tex_coords(0).map(|it| it.into_f32().map(Vec2::from).collect()),
            }
            .filter(|t| t.len() == positions.len());
            if texcoord0.is_none() {
                c.texcoords = None;
            }
            let indices: Vec<u32> = match reader.read_indices() {
                Some(it) => it.into_u32().collect(),
                None => (0..positions.len() as u32).collect(),
            };
            if !indices.len().is_multiple_of(3) {
                bail!("{name}: {what}: {} indices is not a multiple of 3", indices.len());
            }
            if let Some(&i) = indices.iter().find(|&&i| i as usize >= positions.len()) {
                bail!("{name}: {what}: index {i} is out of range ({} vertices)", positions.len());
            }
            if normals.as_ref().is_some_and(|n| n.len() != positions.len())
                || uvs.as_ref().is_some_and(|u| u.len() != positions.len())
            {
                bail!("{name}: {what}: attribute counts differ from the POSITION count");
            }
            for tri in indices.chunks_exact(3) {
                let [a, b, cc] = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
                let t = SceneTriangle {
                    positions: [positions[a], positions[b], positions[cc]],
                    normals: normals.as_ref().map(|n| [n[a], n[b], n[cc]]),
                    uvs: uvs.as_ref().map_or([Vec2::ZERO; 3], |u| [u[a], u[b], u[cc]]),
                    material,
                };
                let area = t.area();
                if !area.is_finite() {
                    bail!("{name}: {what}: a triangle's area overflows f32 (coordinates too large)");
                }
                if area <= 0.0 {
                    c.dropped_degenerate += 1;
                    continue;
                }
                c.triangles.push(t);
                if let (Some(all), Some(t0)) = (c.texcoords.as_mut(), &texcoord0) {
                    all.push([t0[a], t0[b], t0[cc]]);
                }
            }
        }
        Ok(())
    }
}

/// Largest magnitude (m) of a vertex coordinate: at 1e9 m neighbouring f32 values are 64 m apart,
/// and much further out squared lengths overflow f32.
pub const MAX_COORDINATE: f32 = 1e9;

/// Checks that a primitive's accessors have the types glTF 2.0 requires of them (the reader
/// would reinterpret others): POSITION and NORMAL float VEC3, TEXCOORD_n VEC2 of floats or
/// normalised unsigned bytes or shorts, indices SCALAR unsigned bytes, shorts or ints.
fn check_accessors(prim: &gltf::Primitive) -> Result<()> {
    use gltf::Semantic;
    use gltf::accessor::{DataType as D, Dimensions};
    let describe = |a: &gltf::Accessor| {
        let dimensions = match a.dimensions() {
            Dimensions::Scalar => "SCALAR",
            Dimensions::Vec2 => "VEC2",
            Dimensions::Vec3 => "VEC3",
            Dimensions::Vec4 => "VEC4",
            Dimensions::Mat2 => "MAT2",
            Dimensions::Mat3 => "MAT3",
            Dimensions::Mat4 => "MAT4",
        };
        let component = match a.data_type() {
            D::I8 => "byte",
            D::U8 => "unsigned byte",
            D::I16 => "short",
            D::U16 => "unsigned short",
            D::U32 => "unsigned int",
            D::F32 => "float",
        };
        format!("accessor {} ({dimensions} of {component})", a.index())
    };
    for (semantic, a) in prim.attributes() {
        let (ok, needs) = match &semantic {
            Semantic::Positions | Semantic::Normals => {
                (a.dimensions() == Dimensions::Vec3 && a.data_type() == D::F32, "VEC3 of float")
            }
            Semantic::TexCoords(_) => (
                a.dimensions() == Dimensions::Vec2
                    && (a.data_type() == D::F32 || (a.normalized() && matches!(a.data_type(), D::U8 | D::U16))),
                "VEC2 of float or normalised unsigned byte or short",
            ),
            _ => (true, ""),
        };
        if !ok {
            let label = match &semantic {
                Semantic::Positions => "POSITION".to_owned(),
                Semantic::Normals => "NORMAL".to_owned(),
                Semantic::TexCoords(n) => format!("TEXCOORD_{n}"),
                other => format!("{other:?}"),
            };
            bail!("{label} is {}, but glTF 2.0 requires {needs}", describe(&a));
        }
    }
    if let Some(a) = prim.indices()
        && !(a.dimensions() == Dimensions::Scalar && matches!(a.data_type(), D::U8 | D::U16 | D::U32))
    {
        bail!("indices are {}, but glTF 2.0 requires SCALAR of unsigned byte, short or int", describe(&a));
    }
    Ok(())
}

/// The unit direction a KHR_lights_punctual spot or directional light points in: its node's -z
/// in world space; an error when the node's transform collapses it.
fn light_direction(world: Mat4, name: &str, node_name: &str) -> Result<Vec3> {
    let direction = world.transform_vector3(Vec3::NEG_Z).normalize();
    if !direction.is_finite() {
        bail!("{name}: {node_name}: the light's transform is degenerate (no direction)");
    }
    Ok(direction)
}

/// The thin lens described by a camera node's `extras` (`aperture_radius` and `focus_distance`,
/// both in metres; docs/design.md section 3), or `None` (a pinhole) when there are none or the
/// aperture radius is 0.
pub fn thin_lens(extras: Option<&serde_json::value::RawValue>) -> Result<Option<ThinLens>> {
    let Some(raw) = extras else { return Ok(None) };
    let value: serde_json::Value = serde_json::from_str(raw.get())?;
    let number = |key: &str| -> Result<Option<f32>> {
        match value.get(key) {
            None => Ok(None),
            Some(v) => match v.as_f64() {
                Some(x) => Ok(Some(x as f32)),
                None => bail!("`{key}` is {v}, not a number of metres"),
            },
        }
    };
    let radius = number("aperture_radius")?;
    let focus = number("focus_distance")?;
    match (radius, focus) {
        (None, None) => Ok(None),
        (Some(0.0), _) => Ok(None),
        (Some(r), Some(f)) => ThinLens::new(r, f).map(Some),
        (Some(_), None) => bail!("`aperture_radius` needs `focus_distance` (m) beside it"),
        (None, Some(_)) => bail!("`focus_distance` needs `aperture_radius` (m) beside it"),
    }
}
