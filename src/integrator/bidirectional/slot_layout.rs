//! What one slot of a bidirectional wave holds (its two subpaths, their connections, the shadow
//! rays they wait for, its ellipsoid queries), how many slots one binding can hold, and the
//! kernels' constants and buffers that follow from it. A slot is one camera subpath and one light
//! subpath of one pixel sample (see the module above).

use anyhow::Result;

use crate::gpu::layout::{Contribution, Hit, PathState, PathVertex, ShadowRay, Splat};
use crate::gpu::{GpuContext, resources::Resources};
use crate::integrator::wavefront::MAX_SLOTS_PER_DISPATCH;
use crate::integrator::{Method, RenderSettings};
use crate::scene::PreparedScene;

/// Bytes one slot takes in each array that grows with the wave (each must fit one binding).
#[derive(Clone, Copy, Debug)]
pub(super) struct SlotBytes {
    /// `subpath_vertices`: both subpaths' vertices.
    pub vertices: u64,
    /// `contributions`: camera-subpath contributions waiting for their shadow rays.
    pub contributions: u64,
    /// `splats`: light-tracing (t = 1) contributions waiting for theirs.
    pub splats: u64,
    /// `shadow_queue`: the shadow rays queued for both (at least one entry's worth).
    pub shadow_rays: u64,
    /// `paths`: the two subpaths' states.
    pub paths: u64,
    /// `ellipsoid_queries`: one 16-byte entry per query the slot can make.
    pub queries: u64,
}

impl SlotBytes {
    fn each(&self) -> [u64; 6] {
        [self.vertices, self.contributions, self.splats, self.shadow_rays, self.paths, self.queries]
    }

    /// Bytes of one slot in all of them.
    pub fn total(&self) -> u64 {
        self.each().iter().sum()
    }
}

/// The layout of a slot for one render's settings and scene.
#[derive(Clone, Copy, Debug)]
pub(super) struct SlotLayout {
    /// Scattering vertices a kernel traces at most (`kernel_bounces`), B.
    pub bounces: u32,
    /// Camera subpath vertices kept: the pinhole and up to B + 1 more.
    pub camera_vertices: u64,
    /// Light subpath vertices kept: the light and up to B more.
    pub light_vertices: u64,
    /// Ellipsoidal connections (else direct ones).
    pub ellipsoidal: bool,
    /// Ellipsoidal connections also join camera vertices 1 ..= B to directional lights
    /// (connect_spherical; a capture has none): one more splat per vertex, one more vertex traced.
    pub directional: bool,
    /// An NLOS capture (its sensed point is camera vertex 1, so queries start at t = 2).
    pub nlos: bool,
    /// Connections drawn per ellipsoid query, K (1 for direct connections' counts).
    pub connections_per_query: u64,
    /// connect_ellipsoidal traces its shadow rays itself and sums a query's K camera-subpath
    /// contributions into one: ellipsoidal connections in BVHs whose traversals cannot stop, in
    /// scenes without media (trace_shadow_rays takes the media's transmittances).
    pub inline_shadow_rays: bool,
    /// Ellipsoidal connections through vertices in media (connect_medium).
    pub medium_connections: bool,
    /// Contributions a slot can wait on (t >= 2).
    pub contributions_per_slot: u64,
    /// Light-tracing contributions a slot can wait on (t = 1).
    pub splats_per_slot: u64,
    /// Ellipsoid queries of a slot: the pairs (s, t) with s, t >= 1 and s + t <= B + 1.
    pub queries_per_slot: u64,
    /// Bytes per slot of each array.
    pub bytes: SlotBytes,
}

impl SlotLayout {
    pub fn new(scene: &PreparedScene, settings: &RenderSettings) -> Self {
        let b = crate::integrator::kernel_bounces(settings);
        let camera_vertices = b as u64 + 2;
        let light_vertices = b as u64 + 1;
        let ellipsoidal = settings.method == Method::Ellipsoidal;
        let directional = ellipsoidal && settings.nlos.is_none() && !scene.scene.directional_lights.is_empty();
        // Ellipsoidal connections need two shadow rays each, and K slots per strategy.
        let rays_per_connection = if ellipsoidal { 2 } else { 1 };
        let k = settings.connections_per_query as u64;
        // Where traversals can stop at the step budget, shadow rays that stop resume in later passes.
        let inline_shadow_rays = ellipsoidal && !scene.wide.traversals_can_stop() && !scene.scene.has_media();
        let medium_connections = ellipsoidal && scene.scene.has_media();
        let contributions_per_slot =
            camera_vertices * (camera_vertices - 1) / 2 * if inline_shadow_rays { 1 } else { k };
        let splats_per_slot = light_vertices * k + if directional { b as u64 } else { 0 };
        let queued_rays_per_slot =
            if inline_shadow_rays { 0 } else { rays_per_connection * (contributions_per_slot + splats_per_slot) };
        let queries_per_slot = if ellipsoidal { (b as u64 * (b as u64 + 1) / 2).max(1) } else { 1 };
        let bytes = SlotBytes {
            vertices: (camera_vertices + light_vertices) * size_of::<PathVertex>() as u64,
            contributions: contributions_per_slot * size_of::<Contribution>() as u64,
            splats: splats_per_slot * size_of::<Splat>() as u64,
            shadow_rays: queued_rays_per_slot.max(1) * size_of::<ShadowRay>() as u64,
            paths: 2 * size_of::<PathState>() as u64,
            queries: queries_per_slot * 16,
        };
        Self {
            bounces: b,
            camera_vertices,
            light_vertices,
            ellipsoidal,
            directional,
            nlos: settings.nlos.is_some(),
            connections_per_query: k,
            inline_shadow_rays,
            medium_connections,
            contributions_per_slot,
            splats_per_slot,
            queries_per_slot,
            bytes,
        }
    }

    /// Most slots of one wave: each array within a binding of `limit` bytes, and the dispatches
    /// over both subpaths and over the queries within MAX_SLOTS_PER_DISPATCH invocations.
    pub fn fit(&self, limit: u64) -> u64 {
        let fit = self.bytes.each().iter().map(|&bytes| limit / bytes).min().unwrap();
        fit.min(MAX_SLOTS_PER_DISPATCH / 2).min(MAX_SLOTS_PER_DISPATCH / self.queries_per_slot)
    }

    /// Camera and light subpath vertices traced. Ellipsoidal queries join camera vertex t - 1
    /// and light vertex s - 1 with s, t >= 1 (t >= 2 in a capture) and s + t <= B + 1: deeper
    /// vertices are never used, so their rays are not traced. Connections to a directional
    /// light use camera vertices up to B.
    pub fn traced_vertices(&self) -> (u64, u64) {
        if !self.ellipsoidal {
            return (self.camera_vertices, self.light_vertices);
        }
        let b = self.bounces as u64;
        let t_min = if self.nlos { 2 } else { 1 };
        let camera = if self.directional { b + 1 } else { b.max(t_min) };
        (camera, (b + 1).saturating_sub(t_min).max(1))
    }

    /// The kernels' constants of the layout (override names of subpath.wesl and connections.wesl).
    pub fn constants(&self) -> Vec<(&'static str, f64)> {
        let (camera_traced, light_traced) = self.traced_vertices();
        let k = self.connections_per_query;
        // connect_spherical's splats at the end: one (a light seen directly, or an NLOS
        // capture's spot seen from the sensed point), and one per camera vertex 1 ..= B joined
        // to a directional light.
        let end_splats = if self.ellipsoidal { 1 + if self.directional { self.bounces as u64 } else { 0 } } else { 0 };
        vec![
            ("CAMERA_VERTICES", self.camera_vertices as f64),
            ("LIGHT_VERTICES", self.light_vertices as f64),
            ("CAMERA_VERTICES_TRACED", camera_traced as f64),
            ("LIGHT_VERTICES_TRACED", light_traced as f64),
            ("CONTRIBUTIONS_PER_SLOT", self.contributions_per_slot as f64),
            ("CONTRIBUTIONS_PER_STRATEGY", if self.inline_shadow_rays { 1.0 } else { k as f64 }),
            ("SPLATS_PER_SLOT", self.splats_per_slot as f64),
            ("SPLATS_PER_LIGHT_VERTEX", if self.ellipsoidal { k as f64 } else { 1.0 }),
            ("END_SPLATS", end_splats as f64),
        ]
    }

    /// The wave's buffers for `slots` slots, zeroed. With shadow rays traced on the spot,
    /// light-tracing contributions go straight to splat_film and nothing is queued: `splats` and
    /// `shadow_queue` keep one slot's worth.
    pub fn allocate(&self, ctx: &GpuContext, r: &mut Resources, slots: u64) -> Result<()> {
        let none = wgpu::BufferUsages::empty();
        let bytes = &self.bytes;
        let queued = |per_slot: u64| if self.inline_shadow_rays { per_slot } else { slots * per_slot };
        r.storage_zeroed(ctx, "paths", slots * bytes.paths, none)?;
        r.storage_zeroed(ctx, "hits", 2 * slots * size_of::<Hit>() as u64, none)?;
        r.storage_zeroed(ctx, "ray_queue", 2 * slots * 4, none)?;
        r.storage_zeroed(ctx, "next_ray_queue", 2 * slots * 4, none)?;
        r.storage_zeroed(ctx, "subpath_vertices", slots * bytes.vertices, none)?;
        r.storage_zeroed(ctx, "subpath_lengths", 2 * slots * 4, none)?;
        r.storage_zeroed(ctx, "contributions", slots * bytes.contributions, none)?;
        // Only the path tracer sums contributions per path (accumulate SUM_PER_PATH).
        r.storage_zeroed(ctx, "path_radiance", 4, none)?;
        r.storage_zeroed(ctx, "splats", queued(bytes.splats), none)?;
        r.storage_zeroed(ctx, "shadow_queue", queued(bytes.shadow_rays), none)?;
        r.storage_zeroed(ctx, "ellipsoid_queries", if self.ellipsoidal { slots * bytes.queries } else { 16 }, none)?;
        r.storage_zeroed(ctx, "targets", 8 * slots, none)?;
        Ok(())
    }
}
