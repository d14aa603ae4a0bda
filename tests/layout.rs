//! Every struct shared with WGSL has the same member names, offsets and size on both sides:
//! the WGSL is reflected with naga and compared with `offset_of!` on the Rust twin.

use std::mem::{offset_of, size_of};

use gatetrace::gpu::layout::*;

/// (struct name, size, [(member, offset)]) of the Rust twins, in declaration order.
macro_rules! rust_layout {
    ($($ty:ident { $($field:ident),* $(,)? })*) => {
        vec![$((stringify!($ty), size_of::<$ty>(), vec![$((stringify!($field), offset_of!($ty, $field))),*])),*]
    };
}

#[test]
fn wgsl_structs_match_rust_structs() {
    let rust = rust_layout! {
        Triangle { v0, material, e1, light, e2, source }
        TriangleShading { n0, u0, n1, v0, n2, u1, v1, u2, v2, flags }
        BvhNode { min, skip, max, leaf }
        WideNode { grid, planes_xy, planes_z, parent, subtree, children }
        NodeSurface { centroid, area, light_area, spread }
        Material { base_color, base_color_texture, emission, flags, metallic, alpha, eta, plastic_table,
                   specular, plastic_internal_reflectance, plastic_specular_weight, interior_medium, conductor_eta, exterior_medium,
                   conductor_k, reserved2 }
        TextureInfo { offset, width, height, wrap }
        Medium { albedo, sigma_t, g, grid, grid_nearest, albedo_grid, grid_resolution, reserved1, world_to_grid }
        Light { position, kind, emission, triangle, direction, area, select_pdf, flags, cos_outer, cos_inner }
        Camera { position, tan_half_fov_y, right, aspect, up, lens_radius, forward, focus_distance }
        GateParams { bins, table_len, reserved0, reserved1, p0, p1, max_length, reserved2 }
        TargetParams { lo, hi, cells, strata, first_bin, stride, seed, extra, extra_stride, film_first_sample, band_index, reserved2 }
        RenderParams { camera, gate, target_length, light_bounds_min, image_area, light_bounds_max, camera_medium, width, height, seed, max_bounces, rr_depth, light_count, node_count, ray_epsilon, one,
                       family_ratio, family_medium_ratio, query_roulette }
        WaveParams { sample_base, samples, pixel_base, pixel_count, slot_count, tracers_per_pixel, reserved1, reserved2 }
        PathState { origin, path_length, direction, bsdf_pdf, throughput, depth, origin_triangle, dimension, traversal,
                    side }
        Hit { t, triangle, b1, b2 }
        ShadowRay { origin, t_max, direction, waiting, ignore0, ignore1, resume, medium }
        Contribution { radiance, path_length }
        PathVertex { position, path_length, normal, material, shading_normal, triangle, throughput, flags, pdf_fwd,
                     pdf_rev, uv }
        Splat { radiance, path_length, pixel, reserved0, reserved1, reserved2 }
        QueueCounters { rays, next_rays, shadow_rays, truncated_traversals, ellipsoid_queries, unfinished_shadow_rays, invalid_contributions }
        WallPoint { position, length_offset, origin, triangle, power, b1, b2, reserved0, reserved1, reserved2 }
        DisplayParams { inverse_spp, exposure, curve, bin, decades, stride, signed, reserved2 }
    };
    let module = naga::front::wgsl::parse_str(LAYOUT_WGSL).expect("layout.wgsl parses");
    let mut wgsl_structs = Vec::new();
    for (_, ty) in module.types.iter() {
        if let (Some(name), naga::TypeInner::Struct { members, span }) = (&ty.name, &ty.inner) {
            let members: Vec<(String, usize)> =
                members.iter().map(|m| (m.name.clone().unwrap_or_default(), m.offset as usize)).collect();
            wgsl_structs.push((name.clone(), *span as usize, members));
        }
    }
    // Structs used only inside kernels (Frame, Surface, LightSample) live in other modules.
    for (name, size, members) in &rust {
        let (_, wgsl_size, wgsl_members) = wgsl_structs
            .iter()
            .find(|(n, _, _)| n == name)
            .unwrap_or_else(|| panic!("struct {name} is not in shaders/lib/layout.wesl"));
        let rust_members: Vec<(String, usize)> = members.iter().map(|(m, o)| (m.to_string(), *o)).collect();
        assert_eq!(&rust_members, wgsl_members, "member names or offsets of {name} differ (Rust vs WGSL)");
        assert_eq!(size, wgsl_size, "size of {name} differs (Rust vs WGSL)");
    }
    let rust_names: Vec<&str> = rust.iter().map(|(n, _, _)| *n).collect();
    for (name, _, _) in &wgsl_structs {
        assert!(rust_names.contains(&name.as_str()), "WGSL struct {name} has no Rust twin in src/gpu/layout.rs");
    }
}

/// connect_direct's per-slot MIS ratio sums hold one entry per subpath vertex in private arrays
/// of MAX_SUBPATH_VERTICES entries: the host's longest subpath (MAX_BOUNCES + 2 vertices) must
/// fit, read from the composed kernel's constant.
#[test]
fn connect_direct_holds_the_longest_subpath() {
    let value = kernel_u32_const("connect_direct", "MAX_SUBPATH_VERTICES");
    assert_eq!(value, gatetrace::integrator::bidirectional::MAX_BOUNCES + 2);
}

/// The lengths of the uniform tables the host pads to are the lengths the kernels declare.
#[test]
fn uniform_tables_have_the_host_lengths() {
    for (name, host) in [
        ("MAX_SMALL_SCENE_TRIANGLES", gatetrace::bvh::MAX_SMALL_SCENE_TRIANGLES),
        ("MAX_UNIFORM_MATERIALS", gatetrace::gpu::layout::MAX_UNIFORM_MATERIALS),
        ("MAX_UNIFORM_LIGHTS", gatetrace::gpu::layout::MAX_UNIFORM_LIGHTS),
    ] {
        assert_eq!(kernel_u32_const("extend_paths", name) as usize, host, "{name}: WGSL vs host");
    }
}

/// The value of u32 constant `name` in kernel `kernel` as composed.
fn kernel_u32_const(kernel: &str, name: &str) -> u32 {
    let source = gatetrace::gpu::kernels::kernel_source(kernel);
    let module = naga::front::wgsl::parse_str(source.wgsl).unwrap_or_else(|e| panic!("{kernel} parses: {e}"));
    let (_, constant) = module
        .constants
        .iter()
        .find(|(_, c)| c.name.as_deref() == Some(name))
        .unwrap_or_else(|| panic!("{kernel} declares {name}"));
    match module.global_expressions[constant.init] {
        naga::Expression::Literal(naga::Literal::U32(v)) => v,
        ref e => panic!("{name} is not a u32 literal: {e:?}"),
    }
}

/// Arrays stored as vector words (bindings.wesl: the BVH's nodes and node surfaces as
/// `NodeWords`, unpacked by chunked.wesl; the shadow queue as `ShadowRayWords`, read and written by
/// shadow_queue.wesl) hold the bytes of one Rust struct per element, as uploaded or as the host
/// sizes them.
#[test]
fn stored_words_are_the_bytes_of_one_struct() {
    for (kernel, binding, words, rust_size) in [
        ("connect_ellipsoidal", "bvh_nodes", "NodeWords", size_of::<BvhNode>()),
        ("connect_ellipsoidal", "bvh_node_surfaces", "NodeWords", size_of::<NodeSurface>()),
        ("trace_shadow_rays", "shadow_queue", "ShadowRayWords", size_of::<ShadowRay>()),
    ] {
        let source = gatetrace::gpu::kernels::kernel_source(kernel);
        let module = naga::front::wgsl::parse_str(source.wgsl).unwrap_or_else(|e| panic!("{kernel} parses: {e}"));
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).expect("layouts");
        // The binding and its chunks (bvh_nodes_1, ...), but not bvh_node_surfaces for bvh_nodes.
        let chunk = |name: &str| {
            name.strip_prefix(binding)
                .is_some_and(|rest| rest.is_empty() || rest.trim_start_matches('_').parse::<u32>().is_ok())
        };
        let mut checked = 0;
        for (_, var) in module.global_variables.iter() {
            let name = var.name.as_deref().unwrap_or_default();
            if !chunk(name) {
                continue;
            }
            let naga::TypeInner::Array { base, stride, .. } = module.types[var.ty].inner else {
                panic!("{name} is not an array");
            };
            assert_eq!(module.types[base].name.as_deref(), Some(words), "{name}'s elements");
            assert_eq!(stride as usize, rust_size, "{name}: stride of its words vs the Rust struct");
            assert_eq!(layouter[base].size as usize, rust_size, "{name}: size of its words vs the Rust struct");
            checked += 1;
        }
        assert!(checked >= 1, "{kernel} binds {binding}");
    }
}
