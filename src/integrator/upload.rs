//! What every method puts on the device before its own buffers: the render-wide parameters, the
//! scene, the lights, the gate and its target-length sampling, and the film.

use anyhow::Result;

use super::wavefront::{FILM_ELEMENT_BYTES, film_elements, target_cdf, upload_gate};
use super::{Method, RenderSettings};
use crate::film::target::TargetSampler;
use crate::gpu::layout::{
    MAX_UNIFORM_LIGHTS, MAX_UNIFORM_MATERIALS, Medium, NONE, RenderParams, TargetParams, TriangleShading, WaveParams,
};
use crate::gpu::resources::{ChunkLayout, SharedBuffers};
use crate::gpu::{GpuContext, Resources};
use crate::scene::PreparedScene;

/// The render-wide parameters of `settings` on `scene`, shared by every method's kernels.
pub fn render_params(scene: &PreparedScene, settings: &RenderSettings) -> RenderParams {
    let (light_bounds_min, light_bounds_max) = scene.light_bounds();
    RenderParams {
        camera: scene.scene.camera.to_gpu(settings.width, settings.height),
        gate: settings.gate.to_gpu(),
        target_length: TargetParams {
            seed: settings.seed,
            ..target_sampler(scene, settings).map(|t| t.params).unwrap_or_default()
        },
        light_bounds_min,
        image_area: scene.scene.camera.image_area(settings.width, settings.height),
        light_bounds_max,
        width: settings.width,
        height: settings.height,
        seed: settings.seed,
        max_bounces: kernel_bounces(settings),
        rr_depth: settings.rr_depth.unwrap_or(NONE),
        light_count: scene.lights.lights.len() as u32,
        node_count: scene.bvh.nodes.len() as u32,
        ray_epsilon: scene.ray_epsilon,
        one: 1.0,
        query_roulette: settings.query_roulette.unwrap_or(1.0),
        camera_medium: scene.scene.camera_medium.unwrap_or(NONE),
        ..Default::default()
    }
}

/// The scattering vertices the kernels' subpaths may have: `max_bounces`, less one in an NLOS
/// capture, whose laser spot is a bounce to the user and a light to the kernels.
pub fn kernel_bounces(settings: &RenderSettings) -> u32 {
    if settings.nlos.is_some() { settings.max_bounces.saturating_sub(1) } else { settings.max_bounces }
}

/// Target-length sampling of the settings' gate over the path lengths the scene allows with
/// its bounces (None for `none`, or when no path can reach the gate).
pub fn target_sampler(scene: &PreparedScene, settings: &RenderSettings) -> Option<TargetSampler> {
    let (shortest, longest) = match &settings.nlos {
        // A capture's paths run from a laser spot to a sensed point, with at most max_bounces + 1
        // segments counting the laser's and the sensor's, none longer than the diagonal of the
        // scene's bounds with both origins.
        Some(capture) => {
            let (lo, hi) = scene.bounds();
            let (lo, hi) = (
                lo.min(capture.sensor_origin).min(capture.laser_origin),
                hi.max(capture.sensor_origin).max(capture.laser_origin),
            );
            (0.0, (settings.max_bounces as f32 + 1.0) * (hi - lo).length())
        }
        None => match scene.path_length_bounds(settings.max_bounces) {
            // A CW gate weighs every length: its targets need a finite range.
            (shortest, longest)
                if longest.is_infinite()
                    && matches!(settings.gate, crate::film::Gate::Cw { .. } | crate::film::Gate::CwCode { .. }) =>
            {
                (shortest, scene.finite_longest_path(settings.max_bounces))
            }
            bounds => bounds,
        },
    };
    TargetSampler::new(&settings.gate, (shortest as f64, longest as f64))
}

/// What [`upload_scene`] returns: the resources, the specialisation constants (name, value) of
/// the scene and the gate, and the film's chunk layout.
pub type Upload = (Resources, Vec<(&'static str, f64)>, ChunkLayout);

/// Uploads what every method's kernels read (params, scene, lights, the gate's data) and creates
/// the film; returns the resources, the specialisation constants of the scene and the gate, and the
/// film's chunk layout.
pub fn upload_scene(
    ctx: &GpuContext,
    scene: &PreparedScene,
    settings: &RenderSettings,
    params: &RenderParams,
    limit: u64,
) -> Result<Upload> {
    let gate = &settings.gate;
    let mut r = Resources::default();
    r.uniform_init(ctx, "wave", &WaveParams::default());
    let shared = scene_buffers(ctx, scene, settings.query.wide, limit)?;
    r.share(&shared.resources);
    let layout = |name: &str| shared.layouts[name];
    let (triangles, triangle_shading) = (layout("triangles"), layout("triangle_shading"));
    let (bvh_nodes, bvh_node_surfaces) = (layout("bvh_nodes"), layout("bvh_node_surfaces"));
    let small_scene = crate::bvh::small_scene_triangles(&scene.triangles);
    let small = small_scene.len();
    let small_normals: Vec<[f32; 4]> = scene.normals[..small].iter().map(|n| [n[0], n[1], 0.0, 0.0]).collect();
    let max_small = crate::bvh::MAX_SMALL_SCENE_TRIANGLES;
    r.uniform_slice_init(ctx, "small_scene_triangles", &padded_table(small_scene, max_small));
    r.uniform_slice_init(ctx, "small_scene_shading", &padded_table(&scene.shading[..small], max_small));
    r.uniform_slice_init(ctx, "small_scene_normals", &padded_table(&small_normals, max_small));
    let tables_in_uniforms =
        scene.materials.len() <= MAX_UNIFORM_MATERIALS && scene.lights.lights.len() <= MAX_UNIFORM_LIGHTS;
    r.uniform_slice_init(ctx, "uniform_materials", &padded_table(&scene.materials, MAX_UNIFORM_MATERIALS));
    r.uniform_slice_init(ctx, "uniform_lights", &padded_table(&scene.lights.lights, MAX_UNIFORM_LIGHTS));
    r.uniform_slice_init(ctx, "uniform_light_cdf", &padded_table(&scene.lights.cdf, MAX_UNIFORM_LIGHTS));
    let cdf = target_cdf(target_sampler(scene, settings).as_ref());
    upload_gate(ctx, &mut r, params, &gate.table(), &cdf)?;
    let wall_points = match &settings.nlos {
        Some(capture) => crate::nlos::wall_points(scene, capture, settings.width, settings.height)?,
        None => vec![crate::gpu::layout::WallPoint::default()],
    };
    r.storage_init(ctx, "wall_points", &wall_points)?;
    // Extra target-length visits come from a pilot render (BidirectionalTracer), if any.
    r.storage_init(ctx, "target_visits", &[0u32])?;
    r.uniform_slice_init(ctx, "camera_mis_scales", &[[0u32; 4]; super::bidirectional::camera_pilot::SCALE_WORDS]);
    r.storage_init(ctx, "pixel_moments", &[0.0f32])?;
    let film_len = film_elements(settings)?;
    check_film_memory(ctx, settings, film_len)?;
    let film = r.storage_chunked_zeroed(ctx, "film", film_len, FILM_ELEMENT_BYTES, limit)?;
    let flag = |b: bool| b as u32 as f64;
    let constants = vec![
        ("GATE_KIND", gate.kind() as u32 as f64),
        ("HAS_TEXTURES", flag(scene.has_textures())),
        ("HAS_SHADING_NORMALS", flag(scene.has_shading_normals())),
        ("HAS_POINT_LIGHTS", flag(scene.has_point_lights())),
        ("HAS_DIRECTIONAL_LIGHTS", flag(!scene.scene.directional_lights.is_empty())),
        ("HAS_GLOSSY", flag(scene.has_glossy())),
        ("HAS_PLASTIC", flag(scene.has_plastic())),
        ("HAS_DIELECTRIC", flag(scene.has_dielectric())),
        ("HAS_MEDIA", flag(scene.scene.has_media())),
        ("HAS_GRID_MEDIA", flag(scene.scene.media.iter().any(|m| m.grid.is_some()))),
        ("NULL_SURFACES", flag(scene.has_null_surfaces())),
        ("TRIANGLES_PER_CHUNK", triangles.per_chunk as f64),
        ("TRIANGLE_SHADING_PER_CHUNK", triangle_shading.per_chunk as f64),
        ("BVH_NODES_PER_CHUNK", bvh_nodes.per_chunk as f64),
        ("BVH_NODE_SURFACES_PER_CHUNK", bvh_node_surfaces.per_chunk as f64),
        ("FILM_PER_CHUNK", film.per_chunk as f64),
        ("TRAVERSAL_BUDGET", crate::bvh::wide::TRAVERSAL_BUDGET as f64),
        ("SMALL_SCENE_TRIANGLES", small as f64),
        ("SCENE_TABLES_IN_UNIFORMS", flag(tables_in_uniforms)),
        ("RESUMABLE", flag(scene.wide.traversals_can_stop())),
        ("NLOS", flag(settings.nlos.is_some())),
        ("THIN_LENS", flag(scene.scene.camera.lens_radius() > 0.0)),
        ("STRATIFIED_TARGETS", flag(params.target_length.strata > 0)),
    ];
    Ok((r, constants, film))
}

/// The scene's arrays on the device, which every method's kernels read and none writes:
/// triangles, their shading and normals, both BVHs and the node surfaces of the ellipsoid
/// queries (over the wide BVH's children where `wide`), materials, media, textures and lights,
/// split into bindings of at most `limit` bytes. Uploaded once per device for a scene, `wide`
/// and `limit` (`GpuContext::scene_buffers`): the tracers of one render (its pilots, the halves
/// of `combined`, the render itself) and later renders of the same scene bind the same buffers.
/// On the 1,310,720-triangle sphere, one upload took 1.3-1.4 s on lavapipe, and an
/// `ellipsoidal --time` render made three.
pub fn scene_buffers(
    ctx: &GpuContext,
    scene: &PreparedScene,
    wide: bool,
    limit: u64,
) -> Result<std::sync::Arc<SharedBuffers>> {
    ctx.scene_buffers.get_or_make([scene.upload_id(), wide as u64, limit], || {
        let mut r = Resources::default();
        let mut layouts = std::collections::HashMap::new();
        layouts.insert("triangles", r.storage_chunked_init(ctx, "triangles", &scene.triangles, limit)?);
        // The kernels read shading data only for vertex normals and texture coordinates
        // (scene.wesl `surface_at`): flat untextured scenes upload none (64 bytes a triangle,
        // which would not fit the bindings of a 10-million-triangle mesh on lavapipe).
        let shading: &[TriangleShading] =
            if scene.has_shading_normals() || scene.has_textures() { &scene.shading } else { &scene.shading[..1] };
        layouts.insert("triangle_shading", r.storage_chunked_init(ctx, "triangle_shading", shading, limit)?);
        layouts.insert("bvh_nodes", r.storage_chunked_init(ctx, "bvh_nodes", &scene.bvh.nodes, limit)?);
        r.storage_init(ctx, "wide_nodes", &scene.wide.nodes)?;
        // Queries over the wide BVH read one surface per wide node and slot in the same binding.
        let surfaces = if wide { &scene.child_surfaces } else { &scene.node_surfaces };
        layouts.insert("bvh_node_surfaces", r.storage_chunked_init(ctx, "bvh_node_surfaces", surfaces, limit)?);
        r.storage_init(ctx, "triangle_normals", &scene.normals)?;
        r.storage_init(ctx, "materials", &scene.materials)?;
        // One unused entry in scenes without media or grids (a binding cannot be empty).
        let mut densities = Vec::new();
        let mut media = Vec::new();
        for m in &scene.scene.media {
            media.push(m.to_gpu(densities.len() as u32));
            densities.extend(m.grid.iter().flat_map(|g| g.densities()));
        }
        if media.is_empty() {
            media.push(Medium::default());
        }
        if densities.is_empty() {
            densities.push(0.0f32);
        }
        r.storage_init(ctx, "media", &media)?;
        r.storage_init(ctx, "medium_densities", &densities)?;
        r.storage_init(ctx, "texture_infos", &scene.texture_infos)?;
        r.storage_init(ctx, "texels", &scene.texels)?;
        r.storage_init(ctx, "lights", &scene.lights.lights)?;
        r.storage_init(ctx, "light_cdf", &scene.lights.cdf)?;
        Ok(SharedBuffers { resources: r, layouts })
    })
}

/// Refuses, before anything is allocated, a render whose films do not fit the memory available
/// (MemAvailable of /proc/meminfo): the host holds about three copies of each film when the
/// image is read back (staging buffer, sums, saved state) plus the f32 image, and a CPU device
/// (lavapipe) keeps the films themselves in the same memory. A GPU's free memory cannot be
/// asked for portably: there, running out is reported when a buffer is created
/// (`GpuContext::allocate`) or at the next wait (`GpuContext::wait_idle`).
fn check_film_memory(ctx: &GpuContext, settings: &RenderSettings, elements: u64) -> Result<()> {
    let films = if settings.method == Method::Path { 1 } else { 2 };
    let device = elements * FILM_ELEMENT_BYTES * films;
    let host = elements * (3 * FILM_ELEMENT_BYTES * films + 8);
    let needed = host + if ctx.is_cpu() { device } else { 0 };
    let available = std::fs::read_to_string("/proc/meminfo").ok().and_then(|m| {
        let line = m.lines().find(|l| l.starts_with("MemAvailable:"))?;
        line.split_whitespace().nth(1)?.parse::<u64>().ok().map(|kib| kib * 1024)
    });
    if let Some(available) = available {
        let gib = |b: u64| b as f64 / (1u64 << 30) as f64;
        anyhow::ensure!(
            needed <= available,
            "--res {}x{} with {} bins: the film{} and {} copies need about {:.1} GiB of memory, more than the {:.1} GiB \
             available; reduce the resolution or the bins",
            settings.width,
            settings.height,
            settings.gate.bins(),
            if films > 1 { "s of a bidirectional method" } else { "" },
            if films > 1 { "their" } else { "its" },
            gib(needed),
            gib(available)
        );
    }
    Ok(())
}

/// The first `len` elements of `table`, zero-padded to `len`: the contents of a uniform buffer
/// holding a fixed-length WGSL array (unused when the table is longer, see the overrides that
/// select them).
fn padded_table<T: bytemuck::Pod + Default>(table: &[T], len: usize) -> Vec<T> {
    let mut padded = table[..table.len().min(len)].to_vec();
    padded.resize(len, T::default());
    padded
}
