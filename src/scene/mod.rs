//! Scenes: loading (glTF 2.0, docs/design.md section 3, and Mitsuba 3 XML, module `mitsuba`; files
//! in other formats are refused with how to convert them), the baked world-space description, and
//! the CPU twins of the kernels' scene functions (camera, lights, surfaces, materials).

pub mod animation;
pub mod bsdf;
pub mod camera;
pub mod formats;
pub mod gltf_loader;
pub mod lights;
pub mod materials;
pub mod medium;
pub mod mitsuba;
pub mod plastic;
pub mod prepared;
pub mod surface;

use glam::{Vec2, Vec3};

pub use camera::{CameraDesc, ThinLens};
pub use gltf_loader::{LoadOptions, load_gltf, load_gltf_at, load_gltf_for_capture, load_gltf_with};
pub use medium::{MediumDesc, MediumInterface};
pub use prepared::PreparedScene;

/// Loads a scene file as `options` say: a Mitsuba 3 XML scene (recognised by its content) with
/// the `mitsuba` loader, anything else as glTF 2.0 (which refuses other formats with what they
/// are and how to convert them); with `options.fog`, filled with that fog.
pub fn load_scene_with(path: &std::path::Path, options: &LoadOptions) -> anyhow::Result<Scene> {
    let mut scene = if formats::is_mitsuba_xml(path) {
        mitsuba::load_mitsuba(path, options)?
    } else {
        load_gltf_with(path, options)?
    };
    if let Some(fog) = &options.fog {
        scene.add_fog(fog.clone())?;
    }
    Ok(scene)
}

/// The render settings the scene file at `path` carries ([`SceneSettings`]; none for glTF) with
/// a Mitsuba scene's `parameters` given, read without loading its geometry.
pub fn scene_settings(path: &std::path::Path, parameters: &[(String, String)]) -> anyhow::Result<SceneSettings> {
    if formats::is_mitsuba_xml(path) { mitsuba::read_settings(path, parameters) } else { Ok(SceneSettings::default()) }
}

/// Render settings a scene file carries (a Mitsuba scene's film, sampler and integrator): the
/// defaults of a render of it, each overridden by the command line's option. glTF files carry none.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SceneSettings {
    /// Image size in pixels (width, height): `--res`.
    pub resolution: Option<(u32, u32)>,
    /// Samples per pixel: `--spp`.
    pub spp: Option<u64>,
    /// Scattering vertices of the longest path: `--max-bounces`.
    pub max_bounces: Option<u32>,
    /// A gate as `--gate` takes it (lengths in metres), e.g. a transient film's time bins.
    pub gate: Option<String>,
    /// Random seed: `--seed`.
    pub seed: Option<u32>,
    /// The NLOS capture the file describes, which a render of it becomes (`--nlos`).
    pub capture: Option<SceneCapture>,
}

/// The relay wall's node name when none is given (an NLOS capture's, `crate::nlos`).
pub const DEFAULT_RELAY_WALL: &str = "relay_wall";

/// How the laser moves during a capture (`--nlos`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Scan {
    /// One laser spot for the whole grid of sensed points.
    Single,
    /// The laser spot follows the sensed point: each pixel is lit at the point it senses.
    Confocal,
    /// Every laser spot of a laser grid with every sensed point: one single-scan capture per
    /// laser spot.
    Exhaustive,
}

impl Scan {
    /// The name on the command line and in metadata.
    pub fn name(self) -> &'static str {
        match self {
            Scan::Single => "single",
            Scan::Confocal => "confocal",
            Scan::Exhaustive => "exhaustive",
        }
    }
}

/// An NLOS capture a scene file describes (a Mitsuba XML scene's `nlos_capture_meter` on its
/// relay wall, lit by a `projector`): the defaults of the capture a render of the file becomes,
/// each overridden by the command line's option (`--nlos`, `--relay-wall`, `--sensor-origin`,
/// `--laser-origin`, `--laser-spot`, `--laser-power`, `--count-first-last`).
#[derive(Clone, Debug, PartialEq)]
pub struct SceneCapture {
    /// How the laser moves.
    pub scan: Scan,
    /// Exhaustive scans: the grid of laser spots, width x height.
    pub laser_grid: Option<(u32, u32)>,
    /// The relay wall's node name.
    pub relay_wall: String,
    /// Where the sensor looks at the wall from (m).
    pub sensor_origin: Vec3,
    /// Where the laser starts (m).
    pub laser_origin: Vec3,
    /// Single scans: the laser's spot, texture coordinates (u, v) of the relay wall.
    pub laser_spot: Vec2,
    /// The laser: mitransient's projector of this irradiance (W m^-2 per channel at 1 m on its
    /// axis; `crate::nlos::Laser::Projector`).
    pub projector_irradiance: Vec3,
    /// Count the laser origin -> spot and sensed point -> sensor origin segments in path lengths.
    pub count_first_and_last: bool,
}

/// A triangle in world space with its shading attributes, in load order.
#[derive(Clone, Debug)]
pub struct SceneTriangle {
    /// Vertices (m), counter-clockwise about the front face.
    pub positions: [Vec3; 3],
    /// Unit vertex normals, when the mesh has them.
    pub normals: Option<[Vec3; 3]>,
    /// Texture coordinates of the base-colour texture's set (zero when absent).
    pub uvs: [Vec2; 3],
    /// Index into `Scene::materials`.
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
    /// The glTF material's name (may be empty).
    pub name: String,
    /// Linear RGB base colour.
    pub base_color: Vec3,
    /// Index into `Scene::textures`.
    pub base_color_texture: Option<u32>,
    /// Radiance (W m^-2 sr^-1) = emissiveFactor x emissive strength.
    pub emission: Vec3,
    /// glTF `doubleSided`: both faces reflect and emit.
    pub double_sided: bool,
    /// glTF metallic factor.
    pub metallic: f32,
    /// glTF roughness factor; GGX alpha is its square.
    pub roughness: f32,
    /// A plastic's coat over the Lambertian base (albedo `base_color`); `metallic` is then 0.
    pub plastic: Option<PlasticCoat>,
    /// A smooth dielectric interface (glass); `base_color` is then its transmittance factor,
    /// `metallic` 0, and the material double-sided.
    pub dielectric: Option<Dielectric>,
    /// The complex index of refraction (eta, k; RGB) of the conductor lobe, whose Fresnel term is
    /// then the exact one (times `base_color`) instead of Schlick's from `base_color`.
    pub conductor_index: Option<(Vec3, Vec3)>,
    /// The media on its two sides as the scene declares them: where it declares any, a ray
    /// leaving the surface, scattered or passing through, travels in the one on the side it
    /// leaves (vacuum where one is not declared); where it declares none (the default), the ray
    /// stays in the medium it came through.
    pub media: MediumInterface,
    /// No surface at all (Mitsuba's `null` BSDF), only the boundary between its two media, which
    /// rays cross without a vertex; its other members are then unused.
    pub null: bool,
}

/// A smooth dielectric interface, such as glass (Mitsuba's `dielectric`): light is reflected
/// with the Fresnel reflectance and refracted otherwise; inside, path lengths count `eta` times
/// the distance travelled.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dielectric {
    /// Relative index of refraction, inside (behind the triangles' front faces) over outside.
    pub eta: f32,
    /// Factor of the reflected light (Mitsuba's specular_reflectance, 0..1).
    pub specular: f32,
    /// A thin pane (Mitsuba's `thindielectric`): light passes straight through, path lengths
    /// are unchanged, and the reflectance sums the pane's internal reflections.
    pub thin: bool,
    /// GGX alpha of a rough interface (Mitsuba's `roughdielectric`, Walter et al. 2007); 0 for a
    /// smooth one (a delta BSDF). A thin pane is smooth.
    pub alpha: f32,
}

/// The dielectric coat of a plastic material (Mitsuba's `plastic`, `roughplastic`): an interface
/// of GGX roughness alpha = roughness² over a Lambertian base (`scene::plastic` has the model).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlasticCoat {
    /// Relative index of refraction, inside over outside (Mitsuba's int_ior / ext_ior).
    pub eta: f32,
    /// Factor of the coat's specular reflection (Mitsuba's specular_reflectance, 0..1).
    pub specular: f32,
    /// The base's albedo also scales its internal reflections (Mitsuba's `nonlinear`).
    pub nonlinear: bool,
    /// A smooth coat (Mitsuba's `plastic`), rendered at the smallest roughness with the published
    /// fit for its internal reflectance; else rough (`roughplastic`).
    pub smooth: bool,
}

impl MaterialDesc {
    /// A `null` material named `name`: no surface, only the boundary between the `media` on its
    /// two sides.
    pub fn null_boundary(name: String, media: MediumInterface) -> Self {
        MaterialDesc {
            name,
            base_color: Vec3::ZERO,
            base_color_texture: None,
            emission: Vec3::ZERO,
            double_sided: true,
            metallic: 0.0,
            roughness: 1.0,
            plastic: None,
            dielectric: None,
            conductor_index: None,
            media,
            null: true,
        }
    }

    /// True when the material emits (any emission channel above zero).
    pub fn is_emissive(&self) -> bool {
        self.emission.max_element() > 0.0
    }
}

/// A decoded texture: linear RGB texels, row 0 at v = 0.
#[derive(Clone, Debug)]
pub struct TextureData {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Linear RGB texels, row-major.
    pub texels: Vec<Vec3>,
    /// u clamps to the edge instead of repeating.
    pub clamp_u: bool,
    /// v clamps to the edge instead of repeating.
    pub clamp_v: bool,
    /// Lookups take the nearest texel instead of filtering bilinearly.
    pub nearest: bool,
}

/// A point or spot light (KHR_lights_punctual).
#[derive(Clone, Debug)]
pub struct PointLight {
    /// Position (m).
    pub position: Vec3,
    /// Intensity (W sr^-1 per channel) = colour x intensity; on the beam's axis for a spot.
    pub intensity: Vec3,
    /// The beam of a spot light; `None` for a point light, which shines equally everywhere.
    pub spot: Option<SpotCone>,
}

/// The beam of a spot light: full intensity within `inner` of its axis, falling to zero at
/// `outer` along the profile `falloff` (`spot_falloff` in lights.wesl).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpotCone {
    /// Unit axis of the beam (world space).
    pub direction: Vec3,
    /// Inner cone half-angle (rad), 0 <= inner <= outer (equal: a hard edge).
    pub inner: f32,
    /// Outer cone half-angle (rad), at most pi/2.
    pub outer: f32,
    /// How the intensity falls from the inner cone to the outer one.
    pub falloff: SpotFalloff,
}

/// How a spot light's intensity falls between its inner and outer cones.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpotFalloff {
    /// The square of a ramp linear in the cosine of the angle to the axis (glTF
    /// KHR_lights_punctual's recommended falloff).
    CosineRampSquared,
    /// A ramp linear in the angle itself (Mitsuba 3's `spot` emitter, from `beam_width` to
    /// `cutoff_angle`).
    LinearInAngle,
}

impl SpotCone {
    /// Relative intensity (0 to 1) toward unit direction `w` (twin of `spot_falloff`).
    pub fn falloff(&self, w: Vec3) -> f32 {
        let linear_in_angle = self.falloff == SpotFalloff::LinearInAngle;
        spot_falloff(w.dot(self.direction), self.outer.cos(), self.inner.cos(), linear_in_angle)
    }
}

/// The falloff of a spot light whose cone half-angles have cosines `cos_outer` <= `cos_inner`
/// at cosine `cd` to its axis: 0 outside the outer cone, 1 inside the inner one, between them
/// the square of the ramp linear in the cosine, or with `linear_in_angle` the ramp linear in the
/// angle (twin of `spot_falloff`); a hard edge when the two cosines are equal (a point light has
/// both at -1: 1 everywhere).
pub fn spot_falloff(cd: f32, cos_outer: f32, cos_inner: f32, linear_in_angle: bool) -> f32 {
    if cd < cos_outer {
        return 0.0;
    }
    let span = cos_inner - cos_outer;
    if span <= 0.0 || cd >= cos_inner {
        return 1.0;
    }
    if linear_in_angle {
        let outer = cos_outer.clamp(-1.0, 1.0).acos();
        return ((outer - cd.clamp(-1.0, 1.0).acos()) / (outer - cos_inner.clamp(-1.0, 1.0).acos())).clamp(0.0, 1.0);
    }
    let ramp = ((cd - cos_outer) / span).clamp(0.0, 1.0);
    ramp * ramp
}

/// A directional light (KHR_lights_punctual): a plane wave. Its light starts (path length 0)
/// on the plane normal to `direction` that touches the sphere bounding the scene on the side
/// the light comes from, so a point x receives it after d . (x - c) + r metres (c, r: the
/// bounding sphere of [`Scene::bounds`]).
#[derive(Clone, Debug)]
pub struct DirectionalLight {
    /// Unit direction of travel (world space).
    pub direction: Vec3,
    /// Irradiance (W m^-2 per channel) on a surface facing the light = colour x intensity.
    pub irradiance: Vec3,
}

/// A named node of the glTF scene: where it is and which triangles it contributed (what an NLOS
/// capture needs to find its relay wall and its sensor and laser origins by name).
#[derive(Clone, Debug)]
pub struct NamedNode {
    /// The glTF node's name.
    pub name: String,
    /// The node's origin in world space (m).
    pub position: Vec3,
    /// Its mesh's triangles: indices into `Scene::triangles` (load order); empty without a mesh.
    pub triangles: std::ops::Range<usize>,
    /// TEXCOORD_0 of each of those triangles, when every primitive of the mesh has them.
    pub texcoords: Option<Vec<[Vec2; 3]>>,
}

/// A scene baked to world space, ready for BVH build and upload.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Where the scene came from (for messages and metadata).
    pub source: String,
    /// World-space triangles in load order.
    pub triangles: Vec<SceneTriangle>,
    /// Materials, glTF's default material last.
    pub materials: Vec<MaterialDesc>,
    /// Decoded base-colour textures.
    pub textures: Vec<TextureData>,
    /// KHR_lights_punctual point and spot lights.
    pub point_lights: Vec<PointLight>,
    /// KHR_lights_punctual directional lights.
    pub directional_lights: Vec<DirectionalLight>,
    /// The first camera of the scene.
    pub camera: CameraDesc,
    /// Zero-area triangles dropped at load.
    pub dropped_degenerate: usize,
    /// The scene's named nodes, in the order they were visited.
    pub nodes: Vec<NamedNode>,
    /// What loading ignored or changed (unimplemented extensions, ignored textures, clamped
    /// roughness, dropped triangles), one message each, naming the file: the library prints
    /// nothing, its caller shows them (the command line as `warning: ...` lines on stderr).
    pub warnings: Vec<String>,
    /// Render settings the file carries (defaults of a render).
    pub settings: SceneSettings,
    /// Participating media, which materials bound (`MaterialDesc::media`, `MaterialDesc::null`).
    pub media: Vec<MediumDesc>,
    /// The medium the camera stands in (an index of `media`), None for vacuum.
    pub camera_medium: Option<u32>,
}

/// Optical depths of fog beyond which [`Scene::finite_longest_path`] ends a scene's path lengths:
/// exp(-40) is 4e-18.
pub const FOG_TAIL_DEPTHS: f32 = 40.0;

impl Scene {
    /// True when light travels through a participating medium somewhere in the scene.
    pub fn has_media(&self) -> bool {
        !self.media.is_empty()
    }

    /// True where a point or spot light stands inside a medium that scatters there (extinction
    /// and albedo above zero at its position). Next-event estimation alone reaches a delta light
    /// from the medium's vertices: an estimate weighs 1/d^2 at a vertex d (m) from the light, and
    /// such vertices have a density of order d^2 dd, so the estimates' second moment, of order
    /// the integral of d^-2 dd, diverges at the light. `path`'s estimator then has infinite
    /// variance (its rare vertices next to the light ruin the images they land in), where the
    /// bidirectional methods' light subpaths, which start at the light and scatter in the
    /// medium, carry those paths with finite variance (their MIS weights fall as d^4 on the
    /// next-event strategy). Area lights are reached by phase sampling too, whose MIS keeps
    /// `path`'s variance finite.
    pub fn has_delta_light_in_scattering_medium(&self) -> bool {
        self.point_lights.iter().any(|l| {
            medium::medium_at(self, l.position).is_some_and(|m| {
                let m = &self.media[m as usize];
                let share = m.grid.as_ref().map_or(1.0, |g| g.share(l.position));
                let albedo = m.grid.as_ref().and_then(|g| g.albedo_at(l.position)).unwrap_or(Vec3::ONE) * m.albedo;
                m.sigma_t * share > 0.0 && albedo.max_element() > 0.0
            })
        })
    }

    /// Fills all space with `fog` (the camera's medium, which no surface of a scene without
    /// media changes: every ray travels in it). A scene with media of its own is refused.
    pub fn add_fog(&mut self, fog: MediumDesc) -> anyhow::Result<()> {
        anyhow::ensure!(
            !self.has_media(),
            "{}: the scene has participating media of its own; a fog fills scenes without any",
            self.source
        );
        self.media.push(fog);
        self.camera_medium = Some(0);
        Ok(())
    }

    /// The first node named `name`.
    pub fn node(&self, name: &str) -> Option<&NamedNode> {
        self.nodes.iter().find(|n| n.name == name)
    }

    /// The corners' bounds and the nearest light of the scene's triangles, in one pass over them
    /// ([`TriangleBounds`]; a [`PreparedScene`] keeps them).
    pub fn triangle_bounds(&self) -> TriangleBounds {
        let camera = self.camera.position;
        let mut b = TriangleBounds::default();
        for t in &self.triangles {
            for p in t.positions {
                b.all.0 = b.all.0.min(p);
                b.all.1 = b.all.1.max(p);
            }
            if self.materials[t.material as usize].is_emissive() {
                for p in t.positions {
                    b.emitting.0 = b.emitting.0.min(p);
                    b.emitting.1 = b.emitting.1.max(p);
                }
                b.nearest_emitter = b.nearest_emitter.min(distance_to_triangle(camera, t.positions));
            }
        }
        b
    }

    /// Axis-aligned bounds of all triangles and the camera (its lens included) (m).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.bounds_with(&self.triangle_bounds())
    }

    /// [`Scene::bounds`] from the scene's [`TriangleBounds`].
    pub fn bounds_with(&self, triangles: &TriangleBounds) -> (Vec3, Vec3) {
        let lens = Vec3::splat(self.camera.lens_radius());
        let mut lo = (self.camera.position - lens).min(triangles.all.0);
        let mut hi = (self.camera.position + lens).max(triangles.all.1);
        for l in &self.point_lights {
            lo = lo.min(l.position);
            hi = hi.max(l.position);
        }
        (lo, hi)
    }

    /// The sphere bounding [`Scene::bounds`], as (centre, radius) (m), a little enlarged: where
    /// directional lights start their light.
    pub fn bounding_sphere(&self) -> (Vec3, f32) {
        self.bounding_sphere_with(&self.triangle_bounds())
    }

    /// [`Scene::bounding_sphere`] from the scene's [`TriangleBounds`].
    pub fn bounding_sphere_with(&self, triangles: &TriangleBounds) -> (Vec3, f32) {
        let (lo, hi) = self.bounds_with(triangles);
        let radius = 0.5 * (hi - lo).length();
        (0.5 * (lo + hi), radius * (1.0 + 1e-4) + 1e-6)
    }

    /// Axis-aligned bounds of the points where a path can start on a light, the closing
    /// distances of camera subpaths (params.light_bounds_min/max): every emitting triangle and
    /// point light; with a directional light, all of space, since its wave reaches fog that
    /// fills the scene outside the geometry's bounds (a camera subpath's vertex there may be
    /// nearer to where the wave starts than to those bounds); an empty box (min > max) when the
    /// scene has no light.
    pub fn light_bounds(&self) -> (Vec3, Vec3) {
        self.light_bounds_with(&self.triangle_bounds())
    }

    /// [`Scene::light_bounds`] from the scene's [`TriangleBounds`].
    pub fn light_bounds_with(&self, triangles: &TriangleBounds) -> (Vec3, Vec3) {
        if !self.directional_lights.is_empty() {
            return (Vec3::splat(-f32::MAX), Vec3::splat(f32::MAX));
        }
        self.local_light_bounds(triangles)
    }

    /// Axis-aligned bounds of every emitting triangle and point light (m); an empty box (min >
    /// max) when the scene has none.
    fn local_light_bounds(&self, triangles: &TriangleBounds) -> (Vec3, Vec3) {
        let (mut lo, mut hi) = triangles.emitting;
        for l in &self.point_lights {
            lo = lo.min(l.position);
            hi = hi.max(l.position);
        }
        (lo, hi)
    }

    /// The extinction (m^-1) of the fog that fills the space beyond the geometry's bounds, if
    /// any: the camera's medium where no surface that declares media has another outside it
    /// (`--fog`, or a sensor's medium that no `null` shape encloses). Paths that scatter there
    /// have no longest length.
    pub fn fog_beyond_bounds(&self) -> Option<f32> {
        let fog = self.camera_medium?;
        let enclosed = self
            .materials
            .iter()
            .any(|m| m.media != medium::MediumInterface::default() && m.media.exterior != Some(fog));
        (!enclosed).then(|| self.media[fog as usize].sigma_t)
    }

    /// Shortest and longest optical path length (m) any light path with at most `max_bounces`
    /// scattering vertices can have: at least the distance from the pinhole to the nearest
    /// light less the lens radius; at most the farthest reach from the lens into the triangles'
    /// bounds, plus a diagonal of those bounds per further bounce, plus the farthest reach from
    /// them to a light (each segment's longest length between two boxes is between corners);
    /// no longest (infinity) where fog fills the space beyond those bounds
    /// ([`Scene::fog_beyond_bounds`]), in which paths scatter as far as they travel.
    pub fn path_length_bounds(&self, max_bounces: u32) -> (f32, f32) {
        self.path_length_bounds_with(&self.triangle_bounds(), max_bounces)
    }

    /// [`Scene::path_length_bounds`] from the scene's [`TriangleBounds`].
    pub fn path_length_bounds_with(&self, triangles: &TriangleBounds, max_bounces: u32) -> (f32, f32) {
        let camera = self.camera.position;
        let mut shortest = triangles.nearest_emitter;
        for l in &self.point_lights {
            shortest = shortest.min(camera.distance(l.position));
        }
        // A directional light's path length grows by at most the distance travelled, so no path
        // is shorter than the camera's own distance from where the wave starts.
        let (centre, radius) = self.bounding_sphere_with(triangles);
        for l in &self.directional_lights {
            shortest = shortest.min((l.direction.dot(camera - centre) + radius).max(0.0));
        }
        let shortest = (shortest - self.camera.lens_radius()).max(0.0);
        let longest =
            if self.fog_beyond_bounds().is_some() { f32::INFINITY } else { self.longest_path(triangles, max_bounces) };
        (shortest, longest)
    }

    /// A finite stand-in (m) for the longest optical path where [`Scene::path_length_bounds`]
    /// has none (fog beyond the geometry's bounds): the longest path within those bounds plus
    /// FOG_TAIL_DEPTHS optical depths of the fog per vertex and way. A vertex at distance δ outside
    /// the bounds (which hold the camera) lengthens its path by at most 2δ and the path travels
    /// at least δ in the fog to reach it, so in a homogeneous fog a longer path keeps less than
    /// exp(-FOG_TAIL_DEPTHS) of its light (a grid's extinction, below its largest, may keep
    /// more); for ranges that must be finite (a CW gate's target lengths, the viewer's gate
    /// slider). The same as path_length_bounds' longest elsewhere.
    pub fn finite_longest_path(&self, max_bounces: u32) -> f32 {
        self.finite_longest_path_with(&self.triangle_bounds(), max_bounces)
    }

    /// [`Scene::finite_longest_path`] from the scene's [`TriangleBounds`].
    pub fn finite_longest_path_with(&self, triangles: &TriangleBounds, max_bounces: u32) -> f32 {
        let longest = self.longest_path(triangles, max_bounces);
        match self.fog_beyond_bounds() {
            Some(sigma_t) => longest + 2.0 * max_bounces as f32 * FOG_TAIL_DEPTHS / sigma_t.max(1e-6),
            None => longest,
        }
    }

    /// The longest optical path (m) with at most `max_bounces` scattering vertices, all of them
    /// on triangles (see [`Scene::path_length_bounds`]), enlarged by 1e-4 of itself against
    /// rounding.
    fn longest_path(&self, triangles: &TriangleBounds, max_bounces: u32) -> f32 {
        let corners = |(lo, hi): (Vec3, Vec3)| -> [Vec3; 8] {
            std::array::from_fn(|i| Vec3::new([lo.x, hi.x][i & 1], [lo.y, hi.y][(i >> 1) & 1], [lo.z, hi.z][i >> 2]))
        };
        // Farthest points of two boxes from each other (m).
        let reach = |a: &[Vec3], b: &[Vec3]| -> f32 {
            a.iter().flat_map(|p| b.iter().map(move |q| p.distance(*q))).fold(0.0, f32::max)
        };
        let lens = self.camera.lens_radius();
        let camera = [self.camera.position];
        let (lo, hi) = self.local_light_bounds(triangles);
        let lights = if lo.cmple(hi).all() { corners((lo, hi)).to_vec() } else { Vec::new() };
        // A directional light's path starts on the plane tangent to the bounding sphere.
        let directional =
            if self.directional_lights.is_empty() { 0.0 } else { 2.0 * self.bounding_sphere_with(triangles).1 };
        let longest = if max_bounces == 0 || self.triangles.is_empty() {
            lens + reach(&camera, &lights).max(directional)
        } else {
            let (lo, hi) = triangles.all;
            let surfaces = corners((lo, hi));
            lens + reach(&camera, &surfaces)
                + (max_bounces - 1) as f32 * (hi - lo).length()
                + reach(&surfaces, &lights).max(directional)
        };
        longest * (1.0 + 1e-4)
    }

    /// Diagonal of the triangles' bounds (m), the camera and point lights left out: the
    /// geometry's scale for relative tolerances.
    pub fn triangle_extent(&self) -> f32 {
        self.triangle_bounds().extent()
    }
}

/// What the bounds of a scene's path lengths and lights need from its triangles, gathered in one
/// pass ([`Scene::triangle_bounds`]): a scene of ten million triangles takes a fraction of a
/// second per pass, and every tracer asks for those bounds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleBounds {
    /// Axis-aligned bounds of every triangle's corners (m); empty (min > max) without triangles.
    pub all: (Vec3, Vec3),
    /// The same of the emitting triangles (m); empty without.
    pub emitting: (Vec3, Vec3),
    /// Distance from the camera's pinhole to the nearest emitting triangle (m); infinite without.
    pub nearest_emitter: f32,
}

impl TriangleBounds {
    /// Diagonal of the triangles' bounds (m), at least the least positive f32
    /// ([`Scene::triangle_extent`]).
    pub fn extent(&self) -> f32 {
        (self.all.1 - self.all.0).length().max(f32::MIN_POSITIVE)
    }
}

impl Default for TriangleBounds {
    /// No triangle: empty boxes, no emitter.
    fn default() -> Self {
        let empty = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        Self { all: empty, emitting: empty, nearest_emitter: f32::INFINITY }
    }
}

/// Distance from `p` to the closest point of triangle `t` (Ericson, Real-Time Collision
/// Detection, 5.1.5).
pub fn distance_to_triangle(p: Vec3, t: [Vec3; 3]) -> f32 {
    let [a, b, c] = t;
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return p.distance(a);
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return p.distance(b);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return p.distance(a + ab * (d1 / (d1 - d3)));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return p.distance(c);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return p.distance(a + ac * (d2 / (d2 - d6)));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return p.distance(b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))));
    }
    let denom = 1.0 / (va + vb + vc);
    p.distance(a + ab * (vb * denom) + ac * (vc * denom))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_triangle_distance_covers_every_region() {
        let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
        assert_eq!(distance_to_triangle(Vec3::new(0.2, 0.2, 3.0), t), 3.0, "face");
        assert_eq!(distance_to_triangle(Vec3::new(-1.0, -1.0, 0.0), t), 2f32.sqrt(), "vertex a");
        assert_eq!(distance_to_triangle(Vec3::new(2.0, 0.0, 0.0), t), 1.0, "vertex b");
        assert_eq!(distance_to_triangle(Vec3::new(0.0, 3.0, 0.0), t), 2.0, "vertex c");
        assert_eq!(distance_to_triangle(Vec3::new(0.5, -2.0, 0.0), t), 2.0, "edge ab");
        assert_eq!(distance_to_triangle(Vec3::new(-2.0, 0.5, 0.0), t), 2.0, "edge ac");
        assert!((distance_to_triangle(Vec3::new(1.0, 1.0, 0.0), t) - 0.5f32.sqrt()).abs() < 1e-6, "edge bc");
    }
}
