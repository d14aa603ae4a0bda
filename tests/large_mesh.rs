//! A scene of 327,692 triangles (the Cornell box holding a displaced geodesic sphere, as
//! tools/scenes/make_sphere_scene.py --frequency 128 writes it): large enough that exhaustive ellipsoid
//! queries overran lavapipe's loop budget of 65535 iterations per invocation when one
//! invocation ran all of a sample's queries. The stochastic descent bounds every query; here no
//! traversal is cut short and `ellipsoidal` agrees with `direct` (image means |z| < 4, 8x8
//! blocks Sidak-corrected, variances measured over independent batches).

mod common;

use gatetrace::ellipsoid::query::{Query, QueryScene, reached};
use gatetrace::film::Gate;
use gatetrace::gpu::layout::NONE;
use gatetrace::integrator::{BidirectionalTracer, Integrator, Method, QuerySettings, RenderSettings};
use glam::{DVec3, DVec4};

#[test]
fn ellipsoidal_on_a_large_mesh_is_never_cut_short_and_agrees_with_direct() {
    let scene = common::sphere_scene(128);
    assert_eq!(scene.triangles.len(), 327_692);

    // What an exhaustive query costs here (CPU twin, loop iterations over nodes and triangles),
    // for spheroids of a 5-bounce render: a sample's 15 queries in one invocation overran the
    // budget.
    let light = DVec3::new(0.0, 0.499, 0.0);
    let camera = DVec3::new(0.0, 0.0, 2.0);
    let on_sphere = DVec3::new(0.1, 0.02, 0.1);
    let floor = DVec3::new(-0.3, -0.5, 0.2);
    let exhaustive = QuerySettings { allowance: u32::MAX, ..QuerySettings::EXHAUSTIVE };
    let spheroids = [(light, camera, 1.1), (light, floor, 0.5), (on_sphere, camera, 0.8), (floor, on_sphere, 0.4)];
    let cost: f64 = spheroids
        .iter()
        .map(|&(fs, fc, extra)| {
            let q = Query {
                focus_s: fs,
                focus_c: fc,
                tau_e: fs.distance(fc) + extra,
                ignore: [NONE; 2],
                lights_only: false,
                reach: [DVec4::ZERO; 2],
            };
            reached(QueryScene::of(&scene), &q, &exhaustive, u32::MAX, [1, 2, 3]).iterations as f64
        })
        .sum::<f64>()
        / spheroids.len() as f64;
    println!("exhaustive query: {cost:.0} loop iterations on average; 15 of them {:.0}", 15.0 * cost);
    assert!(15.0 * cost > 65_535.0, "the scene is too small to show anything ({cost:.0} iterations per query)");

    let ctx = common::gpu();
    let gate = Gate::Box { start: 3.0, end: 3.3 };
    let settings = |method, seed| RenderSettings {
        width: 32,
        height: 32,
        max_bounces: 5,
        method,
        gate: gate.clone(),
        seed,
        ..Default::default()
    };
    let mut direct = BidirectionalTracer::new(ctx, &scene, &settings(Method::Direct, 600)).unwrap();
    let direct_films = common::films_of(&mut direct, 16, 32);
    let mut ellipsoidal =
        BidirectionalTracer::new(ctx, &scene, &RenderSettings { stats: true, ..settings(Method::Ellipsoidal, 601) })
            .unwrap();
    let ellipsoidal_films = common::films_of(&mut ellipsoidal, 16, 8);
    let (iterations, tested) = ellipsoidal.query_cost().unwrap();
    println!("ellipsoidal: {iterations:.1} loop iterations and {tested:.1} triangles tested per query");
    assert_eq!(direct.truncated_traversals().unwrap(), 0, "direct: traversals cut short");
    assert_eq!(ellipsoidal.truncated_traversals().unwrap(), 0, "ellipsoidal: traversals cut short");
    common::assert_films_agree(
        "ellipsoidal vs direct, 327,692 triangles, box [3.0, 3.3)",
        &ellipsoidal_films,
        &direct_films,
        8,
        0.01,
    );
}
