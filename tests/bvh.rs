//! The BVHs: the binary BVH's stackless layout and CPU traversal against brute force; the wide
//! BVH's collapse and quantisation, its CPU traversal (both modes, any budget) against brute
//! force, the GPU traversal against the CPU twin, and the split (multi-binding) layout against
//! the single-binding one.

mod common;

use gatetrace::bvh::Bvh;
use gatetrace::bvh::traverse::{brute_force_closest, trace_any, trace_closest};
use gatetrace::bvh::wide::{self, WideBvh};
use gatetrace::gpu::layout::{NONE, Triangle};
use gatetrace::integrator::path::MAX_SHADOW_RESUMES;
use gatetrace::integrator::{Integrator, Method, PathTracer, RenderSettings};
use gatetrace::rng::Rng;
use glam::Vec3;

fn bvh_triangles(soup: &[[Vec3; 3]], bvh: &Bvh) -> Vec<Triangle> {
    bvh.order
        .iter()
        .map(|&i| {
            let [a, b, c] = soup[i as usize];
            Triangle { v0: a, e1: b - a, e2: c - a, source: i, ..Default::default() }
        })
        .collect()
}

/// Random rays from inside and around the soup; one in four ignores a random triangle.
fn random_rays(n: usize, triangles: usize, seed: u32) -> Vec<(Vec3, Vec3, f32, u32)> {
    let mut rng = Rng::new(seed, 1, 0);
    (0..n)
        .map(|i| {
            let o = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 3.0 - 1.5;
            let d = (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5).normalize_or(Vec3::X);
            let t_max = if i % 3 == 0 { 0.5 + rng.next_f32() } else { 1e30 };
            let ignore = if i % 4 == 0 { (rng.next_f32() * triangles as f32) as u32 } else { NONE };
            (o, d, t_max, ignore)
        })
        .collect()
}

#[test]
fn bvh_layout_is_a_valid_stackless_tree() {
    let soup = common::random_soup(3000, 7);
    let bvh = Bvh::build(&soup);
    // Every triangle appears exactly once.
    let mut seen = vec![false; soup.len()];
    for &i in &bvh.order {
        assert!(!seen[i as usize], "triangle {i} in two leaves");
        seen[i as usize] = true;
    }
    assert!(seen.iter().all(|&s| s));
    // Skip links point forward and past the node; inner nodes contain their children's boxes.
    let nodes = &bvh.nodes;
    assert_eq!(nodes[0].skip as usize, nodes.len());
    for (i, n) in nodes.iter().enumerate() {
        assert!(n.skip as usize > i && n.skip as usize <= nodes.len());
        if n.leaf == 0 {
            let child = &nodes[i + 1];
            assert!(child.min.cmpge(n.min).all() && child.max.cmple(n.max).all());
            let second = &nodes[child.skip as usize];
            assert!(second.min.cmpge(n.min).all() && second.max.cmple(n.max).all());
            assert_eq!(second.skip, n.skip, "second child's subtree must end where its parent's does");
        } else {
            for k in n.leaf_range().unwrap() {
                for p in soup[bvh.order[k as usize] as usize] {
                    assert!(p.cmpge(n.min - 1e-6).all() && p.cmple(n.max + 1e-6).all());
                }
            }
        }
    }
}

#[test]
fn bvh_is_the_same_on_any_number_of_threads() {
    // The build runs on every core; the tree (which the ellipsoid queries' random descent walks)
    // must not depend on how many there are, or shards rendered on different machines would not
    // merge into the bits of the unsplit render.
    let soup = common::random_soup(20_000, 11);
    let build = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| Bvh::build(&soup))
    };
    let one = build(1);
    let bytes = |b: &Bvh| (bytemuck::cast_slice::<_, u8>(&b.nodes).to_vec(), b.order.clone());
    for threads in [2, 3, 8] {
        for _ in 0..2 {
            assert!(
                bytes(&build(threads)) == bytes(&one),
                "the BVH built on {threads} threads differs from one thread's"
            );
        }
    }
}

#[test]
fn cpu_traversal_matches_brute_force() {
    let soup = common::random_soup(2000, 11);
    let bvh = Bvh::build(&soup);
    let tris = bvh_triangles(&soup, &bvh);
    let mut hits = 0;
    for (o, d, t_max, ignore) in random_rays(20_000, tris.len(), 3) {
        let a = trace_closest(&bvh.nodes, &tris, o, d, t_max, ignore);
        let b = brute_force_closest(&tris, o, d, t_max, ignore);
        // Same intersection routine, so equal hits are bitwise equal; ties in t may pick either.
        assert_eq!(a.t, b.t, "closest distance differs for ray {o} {d}");
        if a.triangle != b.triangle {
            assert_ne!(a.triangle, NONE);
        }
        let any = trace_any(&bvh.nodes, &tris, o, d, t_max, ignore, NONE);
        assert_eq!(any, b.triangle != NONE, "any-hit disagrees with closest-hit for ray {o} {d}");
        hits += (b.triangle != NONE) as usize;
    }
    assert!(hits > 2000 && hits < 18_000, "the ray set should both hit and miss ({hits} hits)");
}

#[test]
fn wide_bvh_is_a_conservative_collapse() {
    // A soup (a deep, irregular tree) and the Cornell box (huge and tiny children side by side).
    for (name, soup) in [
        ("soup", common::random_soup(3000, 7)),
        ("cornell box", common::cornell_box().scene.triangles.iter().map(|t| t.positions).collect()),
    ] {
        let bvh = Bvh::build(&soup);
        let wide = WideBvh::build(&bvh);
        let mut seen = vec![0u32; soup.len()];
        let mut leaves = 0;
        for (i, node) in wide.nodes.iter().enumerate() {
            if i > 0 {
                // The parent link names a node before this one whose slot holds it.
                let (parent, slot) = ((node.parent >> 2) as usize, (node.parent & 3) as usize);
                assert!(parent < i && wide.nodes[parent].children[slot] == i as u32, "{name}: node {i}'s parent link");
            } else {
                assert_eq!(node.parent, NONE);
            }
            // The subtree count: this node and its inner children's subtrees (depth-first, so
            // they end where the next sibling of this node would start).
            let inner: Vec<u32> =
                node.children.iter().copied().filter(|&c| c < gatetrace::gpu::layout::WIDE_LEAF).collect();
            let below: u32 = inner.iter().map(|&c| wide.nodes[c as usize].subtree).sum();
            assert_eq!(node.subtree, 1 + below, "{name}: node {i}'s subtree count");
            for (slot, &child) in node.children.iter().enumerate() {
                // Each slot knows the binary node it was collapsed from (its leaf word, if a leaf).
                let source = wide.sources[i][slot];
                assert_eq!(source == NONE, child == NONE, "{name}: node {i} slot {slot}'s source");
                if child == NONE {
                    continue;
                }
                if child >= gatetrace::gpu::layout::WIDE_LEAF {
                    assert_eq!(bvh.nodes[source as usize].leaf, child, "{name}: node {i} slot {slot}'s source leaf");
                }
                let (lo, hi) = wide::child_box(node, slot);
                // Every triangle below the slot lies inside its decoded box, exactly.
                let range = if child >= gatetrace::gpu::layout::WIDE_LEAF {
                    leaves += 1;
                    let first = child & (gatetrace::gpu::layout::WIDE_LEAF - 1);
                    first..first + (child >> 28)
                } else {
                    assert!(child as usize > i, "{name}: children follow their parent");
                    let below = subtree_triangles(&wide, child);
                    below.start..below.end
                };
                for k in range {
                    if child >= gatetrace::gpu::layout::WIDE_LEAF {
                        seen[k as usize] += 1;
                    }
                    for p in soup[bvh.order[k as usize] as usize] {
                        assert!(
                            p.cmpge(lo).all() && p.cmple(hi).all(),
                            "{name}: triangle {k} pokes out of node {i} slot {slot}: {p} not in {lo}..{hi}"
                        );
                    }
                }
            }
        }
        assert!(seen.iter().all(|&n| n == 1), "{name}: every triangle is in exactly one leaf");
        assert_eq!(leaves, wide.leaves);
        // Four children per node, except where the binary tree ran out of inner nodes.
        let full = wide.nodes.iter().filter(|n| n.children.iter().all(|&c| c != NONE)).count();
        println!(
            "{name}: {} binary nodes -> {} wide nodes ({full} full), {} leaves, depth {}",
            bvh.nodes.len(),
            wide.nodes.len(),
            wide.leaves,
            wide.depth
        );
        assert!(wide.nodes.len() * 3 <= bvh.nodes.len(), "{name}: the collapse leaves too many nodes");
    }
}

#[test]
fn wide_bvh_numbers_its_top_breadth_first() {
    // The first TOP_NODES nodes are the top of the tree (a breadth-first walk from the root in
    // slot order), and the nodes below them keep the depth-first order of the collapse, which
    // keeps a subtree's nodes close in memory. A soup of 16,000 triangles has a few thousand wide nodes, more than TOP_NODES.
    let soup = common::random_soup(16_000, 5);
    let wide = WideBvh::build(&Bvh::build(&soup));
    let n = wide.nodes.len();
    assert!(n > 2 * wide::TOP_NODES, "the tree should outgrow the top ({n} nodes)");
    let inner = |i: usize| wide.nodes[i].children.into_iter().filter(|&c| c < gatetrace::gpu::layout::WIDE_LEAF);
    let mut breadth_first = vec![0usize];
    let mut next = 0;
    while breadth_first.len() < wide::TOP_NODES {
        breadth_first.extend(inner(breadth_first[next]).map(|c| c as usize));
        next += 1;
    }
    breadth_first.truncate(wide::TOP_NODES);
    assert_eq!(breadth_first, (0..wide::TOP_NODES).collect::<Vec<_>>(), "the top is not numbered breadth-first");
    // Depth-first below the top: a pre-order walk that skips the top's nodes meets the others in
    // increasing order.
    let mut stack = vec![0usize];
    let mut below = Vec::new();
    while let Some(i) = stack.pop() {
        if i >= wide::TOP_NODES {
            below.push(i);
        }
        stack.extend(inner(i).map(|c| c as usize).collect::<Vec<_>>().into_iter().rev());
    }
    assert_eq!(below, (wide::TOP_NODES..n).collect::<Vec<_>>(), "the nodes below the top are not depth-first");
}

/// The triangle range (BVH positions) below wide node `node`.
fn subtree_triangles(wide: &WideBvh, node: u32) -> std::ops::Range<u32> {
    let (mut lo, mut hi) = (u32::MAX, 0);
    for &child in &wide.nodes[node as usize].children {
        if child == NONE {
            continue;
        }
        let r = if child >= gatetrace::gpu::layout::WIDE_LEAF {
            let first = child & (gatetrace::gpu::layout::WIDE_LEAF - 1);
            first..first + (child >> 28)
        } else {
            subtree_triangles(wide, child)
        };
        lo = lo.min(r.start);
        hi = hi.max(r.end);
    }
    lo..hi
}

#[test]
fn wide_traversal_matches_brute_force_at_any_budget() {
    // Budgets of 1 to 3 steps stop nearly every ray (in stack mode, then again and again in
    // resume mode), a stack of 32 entries is full in deep trees: every call sequence must find
    // what brute force finds.
    let soup = common::random_soup(2000, 11);
    let bvh = Bvh::build(&soup);
    let wide = WideBvh::build(&bvh);
    let tris = bvh_triangles(&soup, &bvh);
    let (mut hits, mut stops) = (0, 0u64);
    for (i, (o, d, t_max, ignore)) in random_rays(6000, tris.len(), 3).into_iter().enumerate() {
        let b = brute_force_closest(&tris, o, d, t_max, ignore);
        let budget = [1, 2, 3, wide::TRAVERSAL_BUDGET][i % 4];
        let (a, n) = wide::trace_closest_in_steps(&wide, &tris, (o, d, t_max), ignore, budget);
        stops += n as u64;
        // The wide twin tests triangles without the early division: t may differ in the last
        // bits, and a tie may pick either triangle.
        assert!(
            (a.t - b.t).abs() <= 1e-6 * b.t.max(1.0),
            "ray {i} (budget {budget}): t {} vs brute force {}",
            a.t,
            b.t
        );
        if a.triangle != b.triangle {
            assert!(
                a.triangle != NONE && b.triangle != NONE,
                "ray {i}: hit {} vs brute force {}",
                a.triangle,
                b.triangle
            );
        }
        let (any, _) = wide::trace_any_in_steps(&wide, &tris, (o, d, t_max), (ignore, NONE), budget);
        assert_eq!(any, b.triangle != NONE, "ray {i} (budget {budget}): any-hit disagrees with brute force");
        hits += (b.triangle != NONE) as usize;
    }
    assert!(hits > 600 && stops > 3000, "the rays should hit and stop often ({hits} hits, {stops} stops)");
}

#[test]
fn gpu_traversal_matches_cpu_twin() {
    // The Cornell box (a shallow tree) and a soup of 2000 triangles (a deep one), with random
    // rays from inside and around them. Both sides run the same Moller-Trumbore arithmetic in
    // f32; the device may fuse multiply-adds, which changes t by a few ulps (allowed: 1e-5
    // relative, about 80 ulps) and can flip a hit only for rays grazing an edge or a tie.
    let ctx = common::gpu();
    // The large soup's tree outgrows the top numbered breadth-first (wide::TOP_NODES), so its
    // rays read nodes of both orders.
    for (name, scene, scale) in [
        ("cornell box", common::cornell_box(), 0.6f32),
        ("soup", common::soup_scene(2000, 11, "gpu_soup"), 0.4),
        ("large soup", common::soup_scene(12_000, 13, "gpu_large_soup"), 0.4),
    ] {
        if name == "large soup" {
            assert!(scene.wide.nodes.len() > wide::TOP_NODES, "{} wide nodes", scene.wide.nodes.len());
        }
        let tracer =
            PathTracer::new(ctx, &scene, &RenderSettings { width: 8, height: 8, ..Default::default() }).unwrap();
        let rays = random_rays(4096, scene.triangles.len(), 5);
        let mut input = Vec::new();
        for (o, d, t_max, ignore) in &rays {
            input.push([o.x * scale, o.y * scale, o.z * scale, t_max.min(1e30)]);
            input.push([d.x, d.y, d.z, f32::from_bits(*ignore)]);
        }
        let out = common::run_probe(ctx, &tracer, "probe_trace", &[], &input, 2 * rays.len());
        let mut hits = 0;
        for (i, (o, d, t_max, ignore)) in rays.iter().enumerate() {
            let o = *o * scale;
            let cpu = wide::trace_closest(&scene.wide, &scene.triangles, o, *d, *t_max, *ignore);
            let (gpu_t, gpu_tri) = (out[2 * i][0], out[2 * i][1].to_bits());
            if gpu_tri != cpu.triangle {
                // Only near-ties: both hit, at the same distance.
                assert!(
                    gpu_tri != NONE && cpu.triangle != NONE && (gpu_t - cpu.t).abs() <= 1e-5 * cpu.t,
                    "{name} ray {i}: GPU triangle {gpu_tri} at {gpu_t}, CPU {} at {}",
                    cpu.triangle,
                    cpu.t
                );
                continue;
            }
            if cpu.triangle != NONE {
                hits += 1;
                assert!((gpu_t - cpu.t).abs() <= 1e-5 * cpu.t.max(1.0), "{name} ray {i}: t {gpu_t} vs {}", cpu.t);
                // Barycentrics are ratios of the same dot products: 1e-4 absolute allows for
                // fused multiply-adds in near-degenerate (grazing) cases.
                assert!((out[2 * i][2] - cpu.b1).abs() < 1e-4 && (out[2 * i][3] - cpu.b2).abs() < 1e-4);
            }
            let cpu_any = wide::trace_any(&scene.wide, &scene.triangles, o, *d, *t_max, *ignore, NONE);
            assert_eq!(out[2 * i + 1][0] == 1.0, cpu_any, "{name} ray {i}: any-hit differs");
        }
        assert!(hits > 1000, "{name}: too few hits ({hits}) to test anything");
    }
}

#[test]
fn split_buffers_render_identically() {
    use gatetrace::film::Gate;
    use gatetrace::gpu::resources::ChunkLayout;
    // Vertex normals, so that the shading data is uploaded (and split) too.
    let scene = common::soup_scene_with(60, 3, "split_buffers", true);
    assert!(scene.has_shading_normals());
    // Find a binding limit that splits every array into 2-4 chunks; the transient film's size
    // is tuned with its bin count.
    let (t, n) = (scene.triangles.len() as u64, scene.bvh.nodes.len() as u64);
    let (width, height) = (8u32, 8u32);
    let splits = |limit: u64, bins: u64| {
        let film = 3 * (width * height) as u64 * bins;
        [
            ("triangles", t, 48),
            ("triangle_shading", t, 64),
            ("bvh_nodes", n, 32),
            ("bvh_node_surfaces", n, 32),
            ("film", film, gatetrace::integrator::FILM_ELEMENT_BYTES),
        ]
        .iter()
        .all(|&(name, count, size)| ChunkLayout::new(name, count, size, limit).is_ok_and(|l| l.chunks >= 2))
    };
    // It must also be small enough that a wave holds fewer slots (paths) than there are pixels.
    let splits_waves =
        |limit: u64| limit / (size_of::<gatetrace::gpu::layout::PathState>() as u64) < (width * height) as u64;
    let (limit, bins) = (64..4096u64)
        .flat_map(|l| (1..64u64).map(move |b| (l, b)))
        .find(|&(l, b)| splits(l, b) && splits_waves(l))
        .expect("some binding limit splits every array and every pass");
    let gate = Gate::Transient { start: 0.0, width: 10.0 / bins as f64, bins: bins as u32 };
    let base = RenderSettings { width, height, max_bounces: 3, seed: 9, gate, ..Default::default() };
    let split = RenderSettings { binding_limit: Some(limit), ..base.clone() };
    let ctx = common::gpu();
    // The tiny limit also splits each pass into several waves of a few pixels. The film's
    // fixed-point sums are exact, so the different grouping of additions changes no bit.
    let tiled = PathTracer::new(ctx, &scene, &split).unwrap();
    assert!(tiled.waves_per_pass() > 1);
    drop(tiled);
    let a = common::render_films(ctx, &scene, &base, 1, 16).remove(0);
    let b = common::render_films(ctx, &scene, &split, 1, 16).remove(0);
    assert!(a.data.iter().filter(|&&v| v > 0.0).count() > 20, "the test image is nearly black");
    assert_eq!(a.data, b.data, "limit {limit} B, {bins} bins: split layout changed the image");
    // Ellipsoid queries read the split node surfaces too. Their light-tracing image is one
    // binding, so this render has a box gate (one bin) and the smallest limit that holds it.
    // Its sums are exact, so the two images are the same bits, while a misread node surface
    // changes the descents' choices and so the image's noise.
    // (A 4x4 image, so that a limit holding its light-tracing sums still splits the nodes.)
    let splat_image = 3 * gatetrace::integrator::FILM_ELEMENT_BYTES * 16;
    let fits = |l: u64| {
        [("triangles", t, 48), ("triangle_shading", t, 64), ("bvh_nodes", n, 32)]
            .iter()
            .all(|&(name, count, size)| ChunkLayout::new(name, count, size, l).is_ok())
    };
    let limit = (splat_image..1 << 20)
        .find(|&l| fits(l) && ChunkLayout::new("bvh_node_surfaces", n, 32, l).is_ok_and(|c| c.chunks >= 2))
        .expect("a binding limit that holds the light-tracing image splits the node surfaces");
    let gate = Gate::Box { start: 0.0, end: 10.0 };
    let base = RenderSettings { method: Method::Ellipsoidal, gate, width: 4, height: 4, ..base };
    let split = RenderSettings { binding_limit: Some(limit), ..base.clone() };
    let a = common::render_films(ctx, &scene, &base, 1, 64).remove(0);
    let b = common::render_films(ctx, &scene, &split, 1, 64).remove(0);
    let lit = a.data.iter().filter(|&&v| v > 0.0).count();
    assert!(lit > 20, "the ellipsoidal test image is nearly black ({lit} of 48 values lit)");
    assert_eq!(a.data, b.data, "ellipsoidal, limit {limit} B: split node surfaces changed the image");
    // Queries over the wide BVH read one surface per wide node and slot from the same bindings.
    let children = scene.child_surfaces.len() as u64;
    let limit = (splat_image..1 << 20)
        .find(|&l| fits(l) && ChunkLayout::new("bvh_node_surfaces", children, 32, l).is_ok_and(|c| c.chunks >= 2))
        .expect("a binding limit that holds the light-tracing image splits the wide children's surfaces");
    let query = gatetrace::integrator::QuerySettings { wide: true, ..Default::default() };
    let base = RenderSettings { query, ..base };
    let split = RenderSettings { binding_limit: Some(limit), ..base.clone() };
    let a = common::render_films(ctx, &scene, &base, 1, 64).remove(0);
    let b = common::render_films(ctx, &scene, &split, 1, 64).remove(0);
    assert!(a.data.iter().filter(|&&v| v > 0.0).count() > 20, "the wide ellipsoidal test image is nearly black");
    assert_eq!(a.data, b.data, "wide ellipsoidal, limit {limit} B: split child surfaces changed the image");
}

#[test]
fn deep_traversals_are_right_or_reported() {
    // 120000 slab triangles perpendicular to x: each one's box contains the x axis but the
    // triangle misses it (its edge y + z = 0.1 passes beside the axis), so a ray along the axis
    // visits every node before reaching the wall behind them. Lavapipe ends a shader's loops
    // after 65535 iterations in total; a traversal cut short must be counted, never silent.
    let n = 120_000;
    let scene = slab_field(n, Slabs::OnAxis, "deep_traversal");
    assert!(scene.bvh.nodes.len() > 65_535, "{} nodes", scene.bvh.nodes.len());
    let cpu = trace_closest(&scene.bvh.nodes, &scene.triangles, Vec3::new(-1.0, 0.0, 0.0), Vec3::X, 1e30, NONE);
    assert_eq!(scene.triangles[cpu.triangle as usize].source, n as u32, "the CPU twin hits the wall");
    let ctx = common::gpu();
    let tracer = PathTracer::new(ctx, &scene, &RenderSettings { width: 2, height: 2, ..Default::default() }).unwrap();
    // One ray does a closest-hit and an any-hit traversal: about twice the loop budget.
    let input = [[-1.0, 0.0, 0.0, 1e30], [1.0, 0.0, 0.0, f32::from_bits(NONE)]];
    let out = common::run_probe(ctx, &tracer, "probe_trace", &[], &input, 2);
    let right = out[0][1].to_bits() == cpu.triangle && (out[0][0] - 21.0).abs() < 1e-4 && out[1][0] == 1.0;
    let truncated = tracer.truncated_traversals().unwrap();
    assert!(right || truncated > 0, "a traversal went wrong without being reported: {out:?}");
    // A ray that starts past the slabs needs few visits and must be right either way.
    let input = [[11.0, 0.0, 0.0, 1e30], [1.0, 0.0, 0.0, f32::from_bits(NONE)]];
    let out = common::run_probe(ctx, &tracer, "probe_trace", &[], &input, 2);
    assert_eq!(out[0][1].to_bits(), cpu.triangle);
    assert_eq!(out[1][0], 1.0);
    assert_eq!(tracer.truncated_traversals().unwrap(), truncated, "short traversals are not cut");
}

/// Where `slab_field` puts its slabs.
#[derive(Clone, Copy, PartialEq)]
enum Slabs {
    /// Left out: the wall alone.
    None,
    /// Around the x axis, which every ray of the test crosses.
    OnAxis,
    /// 3 m higher (y), beside every camera and shadow ray: a BVH as large, which no ray of the
    /// test traverses deeply.
    Aside,
}

/// The slab field of `deep_traversals_are_right_or_reported` (`count` triangles 0.1 mm apart
/// whose boxes all contain the x axis, which every triangle misses) in front of a
/// double-sided wall at x = 20, lit by a point light near a camera that looks along the axis;
/// `slabs` may leave them out or move them aside.
fn slab_field(count: usize, slabs: Slabs, name: &str) -> gatetrace::scene::PreparedScene {
    use common::gltf_builder::{Camera, Material, Mesh, PointLight, Scene};
    use gatetrace::scene::{PreparedScene, load_gltf};
    let mut mesh = Mesh { positions: vec![], normals: None, uvs: None, indices: vec![], material: Some(0) };
    let lift = if slabs == Slabs::Aside { 3.0 } else { 0.0 };
    for i in 0..if slabs == Slabs::None { 0 } else { count } {
        let x = i as f32 * 1e-4;
        for p in [[x, 1.0 + lift, -0.9], [x, 1.0 + lift, 1.0], [x, -0.9 + lift, 1.0]] {
            mesh.indices.push(mesh.positions.len() as u32);
            mesh.positions.push(p);
        }
    }
    let wall = Mesh {
        positions: vec![[20.0, -1.0, -1.0], [20.0, 1.0, -1.0], [20.0, 0.0, 1.0]],
        normals: None,
        uvs: None,
        indices: vec![0, 1, 2],
        material: Some(0),
    };
    let gltf = Scene {
        meshes: if slabs == Slabs::None { vec![wall] } else { vec![mesh, wall] },
        materials: vec![Material { double_sided: true, ..Material::diffuse([0.5; 3]) }],
        // Looking along +x (-z turned by -90 degrees about y); a field of view narrow enough
        // that no camera ray meets a slab.
        camera: Some(Camera {
            position: [-1.0, -0.05, -0.05],
            rotation: [0.0, -0.70710678, 0.0, 0.70710678],
            yfov: 0.01,
        }),
        point_lights: vec![PointLight { position: [-0.5, -0.05, -0.05], intensity: 100.0 }],
    };
    let dir = common::scratch_dir(name);
    PreparedScene::new(load_gltf(&gltf.write(&dir, "slabs.gltf")).unwrap()).unwrap()
}

/// The slabs of `deep_traversals_resume_until_they_are_complete`.
const SLABS_TO_RESUME: usize = 80_000;

#[test]
fn deep_traversals_resume_until_they_are_complete() {
    // Every camera ray and every shadow ray crosses the whole slab field: far more steps than
    // one invocation may take (TRAVERSAL_BUDGET). Closest-hit traversals resume in later
    // rounds and shadow rays in resume passes: nothing is cut short, and the images equal
    // those of the wall alone (same random numbers, same hits, same lights).
    use gatetrace::integrator::{Method, create_integrator};
    // 80,000 slabs: a traversal stops several times, and at most MAX_SHADOW_RESUMES times
    // (more is counted as cut short, which the test rules out).
    let ctx = common::gpu();
    let with = slab_field(SLABS_TO_RESUME, Slabs::OnAxis, "slabs_with");
    let without = slab_field(0, Slabs::None, "slabs_without");
    let steps = with.wide.nodes.len() + with.wide.leaves;
    assert!(steps as u32 > 4 * wide::TRAVERSAL_BUDGET, "{steps} steps to visit every node and leaf");
    let stops = with.wide.most_stops();
    assert!(stops <= MAX_SHADOW_RESUMES, "{stops} stops of a traversal, above {MAX_SHADOW_RESUMES}");
    for method in [Method::Path, Method::Direct] {
        let settings = RenderSettings { width: 4, height: 4, max_bounces: 1, method, seed: 3, ..Default::default() };
        let render = |scene| {
            let mut tracer = create_integrator(ctx, scene, &settings).unwrap();
            tracer.render_samples(16).unwrap();
            (tracer.film().unwrap(), tracer.truncated_traversals().unwrap())
        };
        let ((a, cut), (b, _)) = (render(&with), render(&without));
        assert_eq!(cut, 0, "{method:?}: {cut} traversals cut short");
        let mean = b.mean_rgb()[0] as f32;
        assert!(mean > 0.0, "{method:?}: the wall is black");
        for (i, (x, y)) in a.data.iter().zip(&b.data).enumerate() {
            assert!(
                (x - y).abs() <= 1e-4 * y.abs().max(mean),
                "{method:?} element {i}: {x} with the slabs, {y} without"
            );
        }
        println!("{method:?}: image mean {mean:.5} with and without the slabs");
    }
    // The path tracer gives shadow rays no resume passes while its film is backed up before
    // each pass: the first pass here cut shadow rays short, was undone and traced again with
    // resume passes (the image above), which the tracer then keeps. Beside the rays a BVH as
    // large needs none: nothing is cut short, and the image is the wall's.
    let settings = RenderSettings { width: 4, height: 4, max_bounces: 1, seed: 3, ..Default::default() };
    let render = |scene| {
        let mut tracer = PathTracer::new(ctx, scene, &settings).unwrap();
        assert_eq!(tracer.shadow_resume_passes(), 0, "a new path tracer starts without resume passes");
        tracer.render_samples(16).unwrap();
        (tracer.shadow_resume_passes(), tracer.film().unwrap(), tracer.truncated_traversals().unwrap())
    };
    let (resumes, _, cut) = render(&with);
    assert!(resumes > 0 && cut == 0, "slabs on the axis: {resumes} resume passes, {cut} traversals cut short");
    let aside = slab_field(SLABS_TO_RESUME, Slabs::Aside, "slabs_aside");
    assert!(aside.wide.traversals_can_stop(), "the BVH of the slabs aside has resumable traversals");
    let (resumes, a, cut) = render(&aside);
    let (_, b, _) = render(&without);
    assert_eq!((resumes, cut), (0, 0), "slabs aside: resume passes and traversals cut short");
    let mean = b.mean_rgb()[0] as f32;
    for (i, (x, y)) in a.data.iter().zip(&b.data).enumerate() {
        assert!((x - y).abs() <= 1e-4 * y.abs().max(mean), "path, element {i}: {x} with the slabs aside, {y} without");
    }
}
