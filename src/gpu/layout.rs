//! The single home of the `#[repr(C)]` structs shared with WGSL.
//!
//! Keep in sync with `shaders/lib/layout.wesl`: `tests/layout.rs` reflects the WGSL with naga and
//! checks every member offset and struct size against these definitions.
//! Units: metres, optical path length in metres, radiance W m^-2 sr^-1, intensity W sr^-1.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// "No triangle / light / texture" in index fields (WGSL `NONE`).
pub const NONE: u32 = u32::MAX;
/// [`TriangleShading::flags`]: the vertex normals are the mesh's own.
pub const SHADING_HAS_NORMALS: u32 = 1;
/// [`Material::flags`]: both faces reflect (and emit).
pub const MATERIAL_DOUBLE_SIDED: u32 = 1;
/// [`Material::flags`]: a plastic, a Lambertian base under a dielectric coat (the `plastic_*`
/// members; Mitsuba's `plastic` and `roughplastic`).
pub const MATERIAL_PLASTIC: u32 = 2;
/// [`Material::flags`]: a plastic whose base's albedo also scales its internal reflections
/// (Mitsuba's `nonlinear`).
pub const MATERIAL_PLASTIC_NONLINEAR: u32 = 4;
/// [`Material::flags`]: a smooth dielectric interface such as glass (`eta`, `specular`, and
/// `base_color` as its transmittance factor; Mitsuba's `dielectric`).
pub const MATERIAL_DIELECTRIC: u32 = 8;
/// [`Material::flags`], with [`MATERIAL_DIELECTRIC`]: a thin pane (Mitsuba's `thindielectric`),
/// which passes light straight through, its internal reflections summed into its reflectance.
pub const MATERIAL_THIN: u32 = 16;
/// [`Material::flags`]: the conductor lobe's Fresnel term is the exact one of the complex index
/// `conductor_eta` + i `conductor_k` (times `base_color`), not Schlick's from `base_color`.
pub const MATERIAL_CONDUCTOR_INDEX: u32 = 32;
/// [`Material::flags`], with [`MATERIAL_DIELECTRIC`]: a rough interface (Mitsuba's
/// `roughdielectric`): GGX microfacets of `alpha`, reflecting and refracting as Walter et al.
/// (2007); not a delta BSDF.
pub const MATERIAL_ROUGH: u32 = 64;
/// [`Material::flags`]: no surface at all (Mitsuba's `null` BSDF), only the boundary between
/// `exterior_medium` and `interior_medium`, which rays cross without a vertex.
pub const MATERIAL_NULL: u32 = 128;
/// [`Material::flags`]: the surface declares the media on its sides (`interior_medium`,
/// `exterior_medium`; [`NONE`]: vacuum), and a ray leaving it travels in the one on the side it
/// leaves. Without it, a ray leaving the surface stays in the medium it came through.
pub const MATERIAL_MEDIUM_TRANSITION: u32 = 256;
/// [`TextureInfo::wrap`]: u clamps to the edge instead of repeating.
pub const TEXTURE_CLAMP_U: u32 = 1;
/// [`TextureInfo::wrap`]: v clamps to the edge instead of repeating.
pub const TEXTURE_CLAMP_V: u32 = 2;
/// [`TextureInfo::wrap`]: lookups take the nearest texel instead of filtering bilinearly.
pub const TEXTURE_NEAREST: u32 = 4;
/// [`Light::kind`]: an emissive triangle.
pub const LIGHT_AREA: u32 = 0;
/// [`Light::kind`]: a point or spot light.
pub const LIGHT_POINT: u32 = 1;
/// [`Light::kind`]: a directional light.
pub const LIGHT_DIRECTIONAL: u32 = 2;
/// [`Light::flags`]: an area light that emits from both faces.
pub const LIGHT_DOUBLE_SIDED: u32 = 1;
/// [`Light::flags`]: a spot light's intensity falls linearly in the angle between its cones
/// (Mitsuba's spot), not as the square of a ramp in the cosine (glTF's).
pub const LIGHT_SPOT_LINEAR_IN_ANGLE: u32 = 2;
/// First bit of [`Light::flags`] that holds, in scenes with media, the medium a light's
/// subpaths start in: its index in the media table + 1, 0 for vacuum (10 bits). From bit
/// [`VERTEX_IOR_SHIFT`] the flags hold the index of refraction there, as a vertex's do.
pub const LIGHT_MEDIUM_SHIFT: u32 = 6;
/// First bit of a subpath vertex's (and a light's) flags that holds the index of refraction
/// there: (index - 1) x 8192 as a signed 16-bit integer (`VERTEX_IOR_SHIFT` in layout.wesl).
pub const VERTEX_IOR_SHIFT: u32 = 16;
/// Largest triangle count a BVH leaf can hold (4 bits of `BvhNode::leaf`).
pub const MAX_LEAF_TRIANGLES: u32 = 15;
/// Largest triangle index a BVH leaf can address (28 bits of `BvhNode::leaf`).
pub const MAX_TRIANGLES: u32 = (1 << 28) - 1;
/// Most materials the kernels read from the uniform buffer `uniform_materials` (bindings.wesl);
/// scenes with more read the storage buffer `materials`.
pub const MAX_UNIFORM_MATERIALS: usize = 256;
/// Most lights the kernels read from the uniform buffers `uniform_lights` and
/// `uniform_light_cdf` (bindings.wesl); scenes with more read `lights` and `light_cdf`.
pub const MAX_UNIFORM_LIGHTS: usize = 256;

/// One triangle in BVH leaf order: vertex 0 and the edges to vertices 1 and 2 (m).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Triangle {
    /// Vertex 0 (m).
    pub v0: Vec3,
    /// Index into the material table.
    pub material: u32,
    /// v1 - v0 (m).
    pub e1: Vec3,
    /// Index into the light table, or [`NONE`].
    pub light: u32,
    /// Edge v1 - v0 (m) is `e1`; this is v2 - v0 (m).
    pub e2: Vec3,
    /// Index of the triangle in load order.
    pub source: u32,
}

/// Vertex normals (unit, world space) and texture coordinates of a triangle.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct TriangleShading {
    /// Unit normal at vertex 0.
    pub n0: Vec3,
    /// Texture coordinate u of vertex 0.
    pub u0: f32,
    /// Unit normal at vertex 1.
    pub n1: Vec3,
    /// Texture coordinate v of vertex 0.
    pub v0: f32,
    /// Unit normal at vertex 2.
    pub n2: Vec3,
    /// Texture coordinate u of vertex 1.
    pub u1: f32,
    /// Texture coordinate v of vertex 1.
    pub v1: f32,
    /// Texture coordinate u of vertex 2.
    pub u2: f32,
    /// Texture coordinate v of vertex 2.
    pub v2: f32,
    /// [`SHADING_HAS_NORMALS`].
    pub flags: u32,
}

/// A node of the stackless BVH (depth-first order, `skip` = first node after the subtree).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct BvhNode {
    /// Box minimum corner (m).
    pub min: Vec3,
    /// First node after this node's subtree (the node count ends a traversal).
    pub skip: u32,
    /// Box maximum corner (m).
    pub max: Vec3,
    /// 0 for an inner node; for a leaf `(count << 28) | first`.
    pub leaf: u32,
}

impl BvhNode {
    /// The triangles of a leaf (BVH positions); None for an inner node.
    pub fn leaf_range(&self) -> Option<std::ops::Range<u32>> {
        (self.leaf != 0).then(|| {
            let first = self.leaf & MAX_TRIANGLES;
            first..first + (self.leaf >> 28)
        })
    }
}

/// A node of the wide BVH that rays traverse (`bvh::wide`): four children whose boxes are
/// stored inline, quantised to 8 bits per plane on a grid of steps 2^e (m) from `origin`, so a
/// node is one 64-byte cache line. The first [`crate::bvh::wide::TOP_NODES`] nodes are the top of
/// the tree breadth-first (the root first), the rest depth-first.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct WideNode {
    /// The planes' grid in one 16-byte word (one vector load in the kernels): its origin's f32
    /// bits, then the biased exponents of its steps (see [`WideNode::origin`] and
    /// [`WideNode::exponents`]).
    pub grid: [u32; 4],
    /// Quantised lower and upper x planes, then y planes, one byte per child (child k in bits
    /// 8k..8k+7): a child's box is origin + step * [lo, hi] on each axis, rounded outwards.
    pub planes_xy: [u32; 4],
    /// Quantised lower and upper z planes, as `planes_xy`.
    pub planes_z: [u32; 2],
    /// `(parent << 2) | slot`: the parent node and this node's slot in it ([`NONE`] at the
    /// root); resumed traversals climb with it.
    pub parent: u32,
    /// Wide nodes in the subtree rooted here, itself included: wide ellipsoid queries visit
    /// subtrees of at most QUERY_BOTTOM_NODES nodes whole (shaders/lib/ellipsoid_query.wesl).
    pub subtree: u32,
    /// Per slot: a child node's index (below [`WIDE_LEAF`]), a leaf `(count << 28) | first`
    /// (count 1 to 4, BVH positions as in [`BvhNode::leaf`]), or [`NONE`] for an empty slot.
    pub children: [u32; 4],
}

impl WideNode {
    /// Origin of the planes' grid (m): the lower corner of the union of the children's boxes.
    pub fn origin(&self) -> Vec3 {
        Vec3::new(f32::from_bits(self.grid[0]), f32::from_bits(self.grid[1]), f32::from_bits(self.grid[2]))
    }

    /// Biased exponents e + 127 of the grid's steps 2^e (m): bits 0-7 x, 8-15 y, 16-23 z.
    pub fn exponents(&self) -> u32 {
        self.grid[3]
    }
}

/// [`WideNode::children`] at or above this value are leaves (or [`NONE`]).
pub const WIDE_LEAF: u32 = 1 << 28;

/// What the ellipsoid queries' stochastic descent knows of the surface below a node: the area
/// of its triangles and the first two moments of a point drawn uniformly on them, from which
/// `node_estimate` (shaders/lib/ellipsoid_query.wesl) predicts the density of path length over
/// the node. One per binary BVH node in node order, or (for queries over the wide BVH) one per
/// wide node and slot, `4 node + slot`, zero for an empty slot.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct NodeSurface {
    /// The area-weighted centroid of the node's triangles (m); the box centre when they have
    /// no area.
    pub centroid: Vec3,
    /// Total area of the node's triangles (m^2).
    pub area: f32,
    /// Total area of its emitting triangles (m^2).
    pub light_area: f32,
    /// Covariance of a point drawn uniformly on the triangles (m^2) divided by the squared
    /// diagonal of the node's box (a wide child's as the kernels decode it; so in [-1, 1]), as
    /// three pack2x16float words: (xx, yy), (zz, xy), (xz, yz).
    pub spread: [u32; 3],
}

/// A surface material: a Lambertian lobe and a GGX conductor lobe blended by `metallic`, or with
/// [`MATERIAL_PLASTIC`] a Lambertian base under a dielectric GGX coat.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Material {
    /// Linear RGB albedo (times the texture when `base_color_texture` is not [`NONE`]).
    pub base_color: Vec3,
    /// Index into the texture table, or [`NONE`].
    pub base_color_texture: u32,
    /// Emitted radiance (W m^-2 sr^-1).
    pub emission: Vec3,
    /// [`MATERIAL_DOUBLE_SIDED`] | [`MATERIAL_PLASTIC`] | [`MATERIAL_PLASTIC_NONLINEAR`] |
    /// [`MATERIAL_DIELECTRIC`] | [`MATERIAL_THIN`] | [`MATERIAL_CONDUCTOR_INDEX`] | [`MATERIAL_ROUGH`] |
    /// [`MATERIAL_NULL`] | [`MATERIAL_MEDIUM_TRANSITION`].
    pub flags: u32,
    /// Weight of the conductor lobe (glTF metallic factor, 0..1); 0 for a plastic.
    pub metallic: f32,
    /// GGX alpha = roughness^2, at least [`MIN_ALPHA`].
    pub alpha: f32,
    /// A plastic's coat or a dielectric: relative index of refraction, inside (behind the
    /// triangles' front faces) over outside.
    pub eta: f32,
    /// A plastic's coat: index into the texture table of its transmittance table
    /// (`scene::plastic::transmittance_table`, red channel).
    pub plastic_table: u32,
    /// A plastic's coat or a dielectric: factor of its specular reflection.
    pub specular: f32,
    /// A plastic's coat: the fraction of diffuse light it reflects back into the base.
    pub plastic_internal_reflectance: f32,
    /// A plastic's coat: specular weight of its lobe choice, s / (s + mean albedo).
    pub plastic_specular_weight: f32,
    /// With [`MATERIAL_MEDIUM_TRANSITION`]: the medium behind the triangles' front faces (an
    /// index of the media table), or [`NONE`] for vacuum.
    pub interior_medium: u32,
    /// With [`MATERIAL_CONDUCTOR_INDEX`]: the real part of the conductor's complex index of
    /// refraction (RGB), relative to the outside.
    pub conductor_eta: Vec3,
    /// With [`MATERIAL_MEDIUM_TRANSITION`]: the medium in front of them, or [`NONE`] for vacuum.
    pub exterior_medium: u32,
    /// With [`MATERIAL_CONDUCTOR_INDEX`]: its imaginary part, the extinction coefficient (RGB).
    pub conductor_k: Vec3,
    /// Padding.
    pub reserved2: u32,
}

/// A participating medium (`shaders/lib/medium.wesl`; `scene::MediumDesc` as loaded): light
/// travelling a distance t through it is attenuated by exp(-integral of sigma_t), and a share
/// `albedo` of what it loses is scattered by the Henyey-Greenstein phase function of mean cosine
/// `g`. Homogeneous (`grid` = [`NONE`]): sigma_t is the extinction everywhere. Heterogeneous:
/// the extinction at a point is sigma_t (the majorant) times the grid's value there, a share in
/// [0, 1], and zero outside the grid's box.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Medium {
    /// Single-scattering albedo sigma_s / sigma_t (linear RGB, 0..1).
    pub albedo: Vec3,
    /// Extinction coefficient (m^-1), the same in every channel; a grid's largest.
    pub sigma_t: f32,
    /// Mean cosine of the scattering angle (-1..1; 0 isotropic, > 0 forward).
    pub g: f32,
    /// First value of the medium's grid in `medium_densities` (x fastest, then y, then z), or
    /// [`NONE`] for a homogeneous medium.
    pub grid: u32,
    /// 1 when grid lookups take the nearest value, 0 when they interpolate trilinearly (values at
    /// the voxels' centres, clamped at the box's faces).
    pub grid_nearest: u32,
    /// First value of the albedo grid in `medium_densities` (the same voxels as the extinction's,
    /// looked up alike, times `albedo`), or [`NONE`] where `albedo` holds everywhere.
    pub albedo_grid: u32,
    /// Voxels along x, y and z.
    pub grid_resolution: [u32; 3],
    /// Padding.
    pub reserved1: u32,
    /// Rows of the affine map from world space (m) to the grid's unit cube.
    pub world_to_grid: [[f32; 4]; 3],
}

/// Where one texture's texels lie in the texel buffer.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct TextureInfo {
    /// First texel in the texel buffer.
    pub offset: u32,
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// [`TEXTURE_CLAMP_U`] | [`TEXTURE_CLAMP_V`] | [`TEXTURE_NEAREST`].
    pub wrap: u32,
}

/// One light: an emissive triangle (area light), a point or spot light, or a directional light.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Light {
    /// Point or spot light: position (m). Directional light: centre of the sphere bounding the
    /// scene. Area light: unused.
    pub position: Vec3,
    /// [`LIGHT_AREA`], [`LIGHT_POINT`] (a point or spot light) or [`LIGHT_DIRECTIONAL`].
    pub kind: u32,
    /// Area light: radiance (W m^-2 sr^-1). Point or spot light: intensity (W sr^-1), on the
    /// beam's axis for a spot. Directional light: irradiance (W m^-2) on a surface facing it.
    pub emission: Vec3,
    /// Area light: the emitting triangle (BVH order). Otherwise [`NONE`].
    pub triangle: u32,
    /// Spot light: unit axis of the beam. Directional light: unit direction of travel. Point
    /// light: +z (unused).
    pub direction: Vec3,
    /// Area light: the triangle's area (m^2). Directional light: area (m^2) of the disk its
    /// light subpaths start on, pi r^2 for the bounding sphere's radius r.
    pub area: f32,
    /// Probability that light sampling picks this light.
    pub select_pdf: f32,
    /// [`LIGHT_DOUBLE_SIDED`] | [`LIGHT_SPOT_LINEAR_IN_ANGLE`], from bit [`LIGHT_MEDIUM_SHIFT`]
    /// the light's medium and from bit [`VERTEX_IOR_SHIFT`] the index of refraction where it stands.
    pub flags: u32,
    /// Point or spot light: cosine of the outer cone half-angle (-1 for a point light and for
    /// a directional light).
    pub cos_outer: f32,
    /// Point or spot light: cosine of the inner cone half-angle (-1 for a point light and for
    /// a directional light).
    pub cos_inner: f32,
}

/// The camera in world space: a pinhole, or a thin lens centred on `position`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Camera {
    /// Pinhole position, or the centre of the lens (m).
    pub position: Vec3,
    /// tan(yfov / 2).
    pub tan_half_fov_y: f32,
    /// Unit vector along +x of the image.
    pub right: Vec3,
    /// Width / height.
    pub aspect: f32,
    /// Unit vector along +y of the image (up).
    pub up: Vec3,
    /// Radius of the lens (m), in the plane through `position` normal to `forward`; 0 for a
    /// pinhole.
    pub lens_radius: f32,
    /// Unit viewing direction.
    pub forward: Vec3,
    /// Distance (m) along `forward` of the plane in focus; 1 for a pinhole (unused there).
    pub focus_distance: f32,
}

/// The kernels' gate parameters (the kind is the GATE_KIND override); built by
/// `film::Gate::to_gpu`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct GateParams {
    /// Film bins per pixel (1 unless transient).
    pub bins: u32,
    /// Points of a table gate, or of a cw code's period.
    pub table_len: u32,
    /// Padding.
    pub reserved0: u32,
    /// Padding.
    pub reserved1: u32,
    /// box: start (m); gaussian: mean (m); cw: 2 pi f / c (rad/m); transient: start (m);
    /// table: first tabulated length (m); cw code: f / c (periods per metre).
    pub p0: f32,
    /// box: end (m); gaussian: sigma (m); cw: phase (rad); transient: bin width (m);
    /// table: last tabulated length (m); cw code: phase (periods, in [0, 1)).
    pub p1: f32,
    /// Upper end of the support (m); `f32::MAX` when unbounded.
    pub max_length: f32,
    /// Padding.
    pub reserved2: f32,
}

/// How target path lengths are drawn from the gate (see `TargetParams` in layout.wesl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct TargetParams {
    /// Shortest target length (m).
    pub lo: f32,
    /// Longest target length (m).
    pub hi: f32,
    /// Cells of the target CDF (0: none).
    pub cells: u32,
    /// Transient gates: bins the target lengths are stratified over (0: not stratified).
    pub strata: u32,
    /// The first of the stratified bins.
    pub first_bin: u32,
    /// Stride of a pixel's sequence of bins: coprime to `strata`, near strata x 0.618.
    pub stride: u32,
    /// Seed of the hashes that randomise target lengths (strata order, offsets within bins):
    /// the render seed for a film's first estimate, re-drawn at each film reset so that
    /// successive estimates are independent.
    pub seed: u32,
    /// Stratified gates: visits per cycle beyond one per bin, shared out among each pixel's
    /// bins by `target_visits` (see `film::target::visit_tables`); 0: each bin once a cycle.
    pub extra: u32,
    /// Stride of a pixel's sequence of extra visits: coprime to `extra`, near extra x 0.618.
    pub extra_stride: u32,
    /// Index of the film's first sample (u32, wrapping): a pixel's cycles of visits start there.
    pub film_first_sample: u32,
    /// 1 once the band index of an NLOS capture is built (`nlos::band_index`): its
    /// three-bounce ellipsoidal connections are then drawn from it.
    pub band_index: u32,
    /// Padding.
    pub reserved2: u32,
}

/// Settings that hold for a whole render.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct RenderParams {
    /// The pinhole camera.
    pub camera: Camera,
    /// The pathlength importance.
    pub gate: GateParams,
    /// Target-length sampling (ellipsoidal connections).
    pub target_length: TargetParams,
    /// Lower corner of the bounds of where paths start on lights (m; all of space with a
    /// directional light: [`crate::scene::Scene::light_bounds`]).
    pub light_bounds_min: Vec3,
    /// Area of the whole image on the image plane at unit distance (4 tan^2(yfov/2) aspect).
    pub image_area: f32,
    /// Upper corner of the bounds of where paths start on lights (m).
    pub light_bounds_max: Vec3,
    /// The medium the camera stands in (an index of the media table), or [`NONE`] for vacuum.
    pub camera_medium: u32,
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Render seed.
    pub seed: u32,
    /// Largest number of scattering vertices of a path.
    pub max_bounces: u32,
    /// Russian roulette starts at this depth ([`NONE`]: never).
    pub rr_depth: u32,
    /// Entries of the light table.
    pub light_count: u32,
    /// Nodes of the BVH.
    pub node_count: u32,
    /// Ray-origin offset scale (m).
    pub ray_epsilon: f32,
    /// Always 1.0 (an opaque one for the kernels' error-free sums).
    pub one: f32,
    /// A combined render's ellipsoidal connections per direct one in its family weights
    /// (dimensionless: K per spheroid times the ellipsoidal half's samples per direct sample);
    /// 0 in renders of one method.
    pub family_ratio: f32,
    /// A combined render's connections through a vertex in a participating medium per direct
    /// one, one per spheroid (dimensionless: the ellipsoidal half's samples per direct sample);
    /// 0 in renders of one method.
    pub family_medium_ratio: f32,
    /// `ellipsoidal`: the probability with which a sample makes each ellipsoid query for paths
    /// of two or more scattering vertices (dimensionless; see
    /// [`crate::integrator::query_roulette`]); 1: every query.
    pub query_roulette: f32,
}

/// Settings of one wave: samples `sample_base..sample_base + samples` of the pixels
/// `pixel_base..pixel_base + pixel_count` (row-major), one path slot each
/// (slot = sample_in_wave * pixel_count + pixel_in_wave).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct WaveParams {
    /// First sample index of the wave.
    pub sample_base: u32,
    /// Samples per pixel in the wave.
    pub samples: u32,
    /// First pixel of the wave.
    pub pixel_base: u32,
    /// Pixels in the wave.
    pub pixel_count: u32,
    /// `pixel_count * samples`.
    pub slot_count: u32,
    /// Invocations of trace_paths per pixel, each tracing every `tracers_per_pixel`-th sample of
    /// its pixel (path tracer, whole paths only; 0 elsewhere).
    pub tracers_per_pixel: u32,
    /// Padding.
    pub reserved1: u32,
    /// Padding.
    pub reserved2: u32,
}

/// State of one path between wavefront stages.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct PathState {
    /// The path's last vertex (m): the pinhole or a surface point.
    pub origin: Vec3,
    /// Optical path length from the pinhole to `origin` (m).
    pub path_length: f32,
    /// Unit direction of the next ray.
    pub direction: Vec3,
    /// Solid-angle pdf of `direction` (sr^-1); 0 for camera rays.
    pub bsdf_pdf: f32,
    /// Product of f cos / pdf so far.
    pub throughput: Vec3,
    /// Scattering vertices so far (low 16 bits) and, in scenes with media, the medium the next
    /// ray travels through (high 16 bits: its index + 1, 0 for vacuum).
    pub depth: u32,
    /// Triangle under `origin`, or [`NONE`].
    pub origin_triangle: u32,
    /// Random numbers drawn so far (pixel and sample follow from the path's slot).
    pub dimension: u32,
    /// Where the closest-hit traversal of the path's ray resumes in a later round (a resume
    /// position, `bvh::wide::resume_position`); 0 while it has not started or has finished.
    pub traversal: u32,
    /// Its sign: the side of `origin_triangle` the ray leaves (+ front, - back; 0 at the pinhole
    /// and point lights). Its magnitude: the index of refraction the ray travels through (1 in
    /// air). A vertex in a medium has no triangle and keeps the index (positive).
    pub side: f32,
}

/// Closest hit of a ray.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Hit {
    /// Distance along the unit direction (m).
    pub t: f32,
    /// Triangle (BVH order) or [`NONE`].
    pub triangle: u32,
    /// Barycentric coordinate of vertex 1.
    pub b1: f32,
    /// Barycentric coordinate of vertex 2.
    pub b2: f32,
}

/// A queued shadow ray of a connection.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct ShadowRay {
    /// Ray origin (m), offset from the surface.
    pub origin: Vec3,
    /// Distance to the light sample (m).
    pub t_max: f32,
    /// Unit direction.
    pub direction: Vec3,
    /// Index of the contribution waiting for this ray; [`SPLAT_WAITING`] | index for a splat.
    pub waiting: u32,
    /// Triangle to ignore (the origin's).
    pub ignore0: u32,
    /// Triangle to ignore (the light's).
    pub ignore1: u32,
    /// Where the traversal resumes in a later pass (a resume position, `bvh::wide::resume_position`);
    /// 0 before the first pass and once the ray is decided.
    pub resume: u32,
    /// In scenes with media: the medium the ray starts in (its index in the media table,
    /// [`NONE`] for vacuum); the waiting contribution takes the transmittance. Unused otherwise.
    pub medium: u32,
}

/// Bits of a subpath vertex's flags that hold its medium (`VERTEX_MEDIUM_BITS` in layout.wesl).
pub const VERTEX_MEDIUM_BITS: u32 = 10;

/// Marks a shadow ray's target as an index into the splat buffer.
pub const SPLAT_WAITING: u32 = 0x8000_0000;

/// A radiance contribution and the optical path length it belongs to.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Contribution {
    /// Radiance estimate (W m^-2 sr^-1), before the gate's weight.
    pub radiance: Vec3,
    /// Optical path length of the contribution's path (m).
    pub path_length: f32,
}

/// Queue lengths of a wavefront round (atomics in WGSL).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct QueueCounters {
    /// Paths in `ray_queue` this round.
    pub rays: u32,
    /// Paths pushed to `next_ray_queue`.
    pub next_rays: u32,
    /// Rays pushed to `shadow_queue`.
    pub shadow_rays: u32,
    /// Traversals the device cut short (lavapipe's loop limit); never reset during a render.
    pub truncated_traversals: u32,
    /// Entries pushed to `ellipsoid_queries` (reset with the ray counters).
    pub ellipsoid_queries: u32,
    /// Shadow rays the last trace_shadow_rays pass left unfinished.
    pub unfinished_shadow_rays: u32,
    /// Contributions the film could not hold (NaN, infinite, or 2^63 or more); never reset
    /// during a render.
    pub invalid_contributions: u32,
}

/// One vertex of a bidirectional subpath (see `PathVertex` in layout.wesl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct PathVertex {
    /// Position (m).
    pub position: Vec3,
    /// Optical path length from the subpath's start (m).
    pub path_length: f32,
    /// Unit geometric normal on the arrival side (m).
    pub normal: Vec3,
    /// Material index (surface) or light index (light vertex).
    pub material: u32,
    /// Unit shading normal on the arrival side.
    pub shading_normal: Vec3,
    /// Triangle (BVH order) or [`NONE`].
    pub triangle: u32,
    /// Subpath throughput up to the vertex.
    pub throughput: Vec3,
    /// Vertex kind and flags.
    pub flags: u32,
    /// Forward area density (m^-2).
    pub pdf_fwd: f32,
    /// Reverse area density (m^-2).
    pub pdf_rev: f32,
    /// Texture coordinates (surface vertices); (g, sigma_t) for a medium vertex, g its phase
    /// function's mean cosine and sigma_t its extinction there (m^-1).
    pub uv: glam::Vec2,
}

/// A light-tracing contribution waiting for its shadow ray.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Splat {
    /// Radiance estimate (W m^-2 sr^-1) before the gate's weight.
    pub radiance: Vec3,
    /// Optical path length (m).
    pub path_length: f32,
    /// Row-major pixel index.
    pub pixel: u32,
    /// Padding.
    pub reserved0: u32,
    /// Padding.
    pub reserved1: u32,
    /// Padding.
    pub reserved2: u32,
}

/// A point of an NLOS capture's relay wall, as the kernels read it from `wall_points`: a sensed
/// point (what the camera ray of a grid cell hits) or a laser spot (what the beam hits). Both are
/// the first hit of a ray from `origin` (the sensor or the laser origin), found on the host.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct WallPoint {
    /// The point (m).
    pub position: Vec3,
    /// Path length (m) that paths through the point start with: a sensed point's is minus its
    /// distance from the sensor origin (the path's first segment is traced, then not counted)
    /// or 0 when that segment counts; a laser spot's is 0, or its distance from the laser origin
    /// when that segment counts.
    pub length_offset: f32,
    /// The sensor origin (sensed points) or the laser origin (laser spots) (m).
    pub origin: Vec3,
    /// The point's triangle (BVH order): the wall's, or what lies in front of it seen from the
    /// origin (NONE only in hand-made tables: the capture set-up always finds one).
    pub triangle: u32,
    /// Laser spots: the beam's power per channel (W); zero for sensed points.
    pub power: Vec3,
    /// Barycentric coordinate of the point on its triangle (weight of vertex 1).
    pub b1: f32,
    /// Barycentric coordinate of the point on its triangle (weight of vertex 2).
    pub b2: f32,
    /// Padding.
    pub reserved0: u32,
    /// Padding.
    pub reserved1: u32,
    /// Padding.
    pub reserved2: u32,
}

/// Smallest GGX alpha: rougher than this keeps every density finite in f32.
pub const MIN_ALPHA: f32 = 1e-3;

/// `shaders/lib/layout.wesl` composed to WGSL by the build script (for the layout test).
pub const LAYOUT_WGSL: &str = include_str!(concat!(env!("OUT_DIR"), "/layout.wgsl"));

/// How `resolve_display` maps the film to the viewer's pixels.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct DisplayParams {
    /// 1 / samples per pixel of the film.
    pub inverse_spp: f32,
    /// Multiplier of the mean radiance before the tone curve (2^EV).
    pub exposure: f32,
    /// [`DISPLAY_LINEAR`] or [`DISPLAY_LOG`].
    pub curve: u32,
    /// Film bin shown (0 unless transient).
    pub bin: u32,
    /// Decades below 1 that [`DISPLAY_LOG`] spans (black at 10^-decades).
    pub decades: f32,
    /// Pixels per row of `display` (rows padded for texture copies).
    pub stride: u32,
    /// 1: show the luminance, signed, on a diverging map ([`DISPLAY_POSITIVE`] above zero,
    /// [`DISPLAY_NEGATIVE`] below, black at zero, brightness through the tone curve); 0: the
    /// RGB image (negative values show their magnitude).
    pub signed: u32,
    /// Padding.
    pub reserved2: u32,
}

/// Tone curve: clamp to [0, 1], then sRGB encoding.
pub const DISPLAY_LINEAR: u32 = 0;
/// Tone curve: log10 of the value mapped from [-decades, 0] to [0, 1].
pub const DISPLAY_LOG: u32 = 1;
/// Signed display: the colour of positive values at full brightness (sRGB-encoded, each channel
/// times the tone curve's value of the magnitude).
pub const DISPLAY_POSITIVE: [f32; 3] = [1.0, 0.5, 0.0];
/// Signed display: the colour of negative values (see [`DISPLAY_POSITIVE`]).
pub const DISPLAY_NEGATIVE: [f32; 3] = [0.0, 0.5, 1.0];
