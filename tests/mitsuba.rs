//! Mitsuba 3 XML scenes (src/scene/mitsuba): what the loader reads from a file that uses every
//! part of it (assets/scenes/mitsuba_box, written by tools/scenes/make_mitsuba_scene.py), renders
//! of it against Mitsuba 3.9.1 + mitransient 1.3.1 rendering the same file
//! (tests/data/mitsuba_box_peer), the XML Cornell box against the glTF one, and the file's render
//! settings as the command line's defaults.

mod common;

use std::process::Command;

use common::peer::{check_image, check_transient};
use common::stats::{sidak, t_critical};
use gatetrace::film::Gate;
use gatetrace::integrator::{Method, RenderSettings};
use gatetrace::scene::{LoadOptions, PreparedScene, Scene, SceneSettings, load_scene_with};
use glam::Vec3;

fn mitsuba_box() -> Scene {
    load_scene_with(&common::repo_path("assets/scenes/mitsuba_box/scene.xml"), &LoadOptions::default()).unwrap()
}

/// Total area (m^2) of a named node's triangles.
fn area(scene: &Scene, node: &str) -> f32 {
    let n = scene.node(node).unwrap_or_else(|| panic!("no node {node}"));
    scene.triangles[n.triangles.clone()].iter().map(|t| t.area()).sum()
}

#[test]
fn a_mitsuba_scene_loads_as_written() {
    let scene = mitsuba_box();
    // The one approximation the file asks for: the slab's smooth plastic coat.
    assert_eq!(scene.warnings.len(), 1, "{:?}", scene.warnings);
    assert!(scene.warnings[0].contains("smooth plastic"), "{:?}", scene.warnings);
    // Film, sampler and integrator: the render's defaults ($res, $spp, $bins substituted).
    let expected = SceneSettings {
        resolution: Some((32, 32)),
        spp: Some(64),
        max_bounces: Some(5),
        gate: Some("transient:1.94,0.1,20".into()),
        seed: None,
        capture: None,
    };
    assert_eq!(scene.settings, expected);
    // The camera: at (0, 0, 2) looking down -z, 40 degrees across the smaller (equal) axis.
    let c = scene.camera;
    assert!(c.position.abs_diff_eq(Vec3::new(0.0, 0.0, 2.0), 1e-6));
    assert!(c.forward.abs_diff_eq(Vec3::NEG_Z, 1e-6) && c.right.abs_diff_eq(Vec3::X, 1e-6));
    assert!(c.up.abs_diff_eq(Vec3::Y, 1e-6) && (c.yfov - 40f32.to_radians()).abs() < 1e-6);
    // Shapes: triangle counts, areas and places after their transforms.
    let count = |node: &str| scene.node(node).unwrap().triangles.len();
    assert_eq!([count("floor"), count("block"), count("tetrahedron"), count("slab")], [2, 12, 4, 12]);
    assert!((area(&scene, "floor") - 1.0).abs() < 1e-5);
    let block = 2.0 * (0.24 * 0.4 + 0.24 * 0.24 + 0.24 * 0.4);
    assert!((area(&scene, "block") - block).abs() < 1e-5, "OBJ quads, scaled");
    let slab = 2.0 * (0.3 * 0.04 + 0.3 * 0.2 + 0.04 * 0.2);
    assert!((area(&scene, "slab") - slab).abs() < 1e-5, "cube, scaled");
    // Curved shapes have their analytic areas (to f32 sums), their vertices within the
    // tessellation error of the surface.
    let relative = |got: f32, exact: f32| (got - exact).abs() / exact;
    let pi = std::f32::consts::PI;
    assert!(relative(area(&scene, "ball"), 4.0 * pi * 0.15 * 0.15) < 1e-4, "sphere");
    assert!(relative(area(&scene, "post"), 2.0 * pi * 0.05 * 0.3) < 1e-4, "cylinder");
    assert!(relative(area(&scene, "plate"), pi * 0.01) < 1e-4, "disk");
    let ball = &scene.triangles[scene.node("ball").unwrap().triangles.clone()];
    let error = gatetrace::scene::mitsuba::TESSELLATION_ERROR * 0.15;
    for p in ball.iter().flat_map(|t| t.positions) {
        assert!((p.distance(Vec3::new(0.2, -0.35, 0.15)) - 0.15).abs() < error, "sphere vertices lie near it");
    }
    // The serialized file's second shape (double precision), a pyramid of 0.2 m squared base.
    assert_eq!(count("pyramid"), 6);
    let base = 0.2 * 0.2;
    let slant = 0.1 * (0.12f32 * 0.12 + 0.1 * 0.1).sqrt() * 4.0;
    assert!((area(&scene, "pyramid") - (base + slant)).abs() < 1e-5, "serialized");
    let tetrahedron = &scene.triangles[scene.node("tetrahedron").unwrap().triangles.clone()];
    let lowest = tetrahedron.iter().flat_map(|t| t.positions).map(|p| p.y).fold(f32::INFINITY, f32::min);
    assert!((lowest + 0.5).abs() < 1e-6, "the PLY tetrahedron stands on the floor (matrix)");
    // The shapegroup's cube, once per instance, each moved by its instance.
    let pillars: Vec<_> = scene.nodes.iter().filter(|n| n.name == "pillar cube").collect();
    assert_eq!(pillars.len(), 2);
    assert!(pillars.iter().all(|n| n.triangles.len() == 12));
    assert!(pillars[0].position.abs_diff_eq(Vec3::new(-0.4, -0.4, -0.4), 1e-6));
    assert!(pillars[1].position.abs_diff_eq(Vec3::new(0.4, -0.4, -0.4), 1e-6));
    // face_normals drops the OBJ's normals; the sphere keeps the true sphere's.
    assert!(scene.triangles[scene.node("block").unwrap().triangles.clone()].iter().all(|t| t.normals.is_none()));
    assert!(ball.iter().all(|t| t.normals.is_some()));
    // Materials: the included file's BSDFs (with its default), twosided, the conductor, textures.
    let material =
        |node: &str| &scene.materials[scene.triangles[scene.node(node).unwrap().triangles.start].material as usize];
    assert_eq!(material("ceiling").base_color, Vec3::splat(0.8));
    assert!(material("post").double_sided && !material("ceiling").double_sided);
    assert_eq!((material("ball").metallic, material("ball").base_color), (1.0, Vec3::ONE));
    assert!((material("ball").roughness - 0.2f32.sqrt()).abs() < 1e-6);
    let (eta, k) = material("ball").conductor_index.expect("gold's complex index");
    assert!((eta.x - 0.143036).abs() < 1e-6 && (k.z - 1.60336).abs() < 1e-6, "Mitsuba's RGB gold");
    assert_eq!(material("light").emission, Vec3::splat(10.0));
    // Plastics: a rough one (eta as given, Mitsuba's default ext_ior of air), a textured
    // nonlinear one, a smooth one whose index is named (bk7).
    let coat = |node: &str| material(node).plastic.expect("a plastic");
    assert!((coat("block").eta - 1.5 / 1.000277).abs() < 1e-6 && !coat("block").nonlinear);
    assert!((material("block").roughness - 0.15f32.sqrt()).abs() < 1e-6);
    assert_eq!(material("block").base_color, Vec3::new(0.25, 0.45, 0.7));
    assert!(coat("pyramid").nonlinear && coat("pyramid").specular == 0.8);
    assert!(material("pyramid").base_color_texture.is_some() && !coat("pyramid").smooth);
    assert!(coat("slab").smooth && (coat("slab").eta - 1.5046 / 1.000277).abs() < 1e-6);
    let spot = scene.point_lights[1].spot.expect("the spot light");
    assert!((spot.outer - 25f32.to_radians()).abs() < 1e-6 && (spot.inner - 10f32.to_radians()).abs() < 1e-6);
    assert_eq!(spot.falloff, gatetrace::scene::SpotFalloff::LinearInAngle);
    assert_eq!(scene.textures.len(), 3);
    let checker = &scene.textures[material("floor").base_color_texture.unwrap() as usize];
    assert!(checker.nearest && (checker.width, checker.height) == (2, 2));
    let floor = &scene.triangles[scene.node("floor").unwrap().triangles.clone()];
    let largest_uv = floor.iter().flat_map(|t| t.uvs).fold(0.0f32, |m, uv| m.max(uv.x).max(uv.y));
    assert_eq!(largest_uv, 4.0, "to_uv scales the floor's uv by 4");
}

/// Next-event estimation alone and BSDF (and phase) sampling alone (`LightStrategy`) render
/// `transient` (20 bins) alike: 16 films of `spp` each (seeds `seed`, `seed` + 1), compared per
/// bin and channel over the image (sampling alone reaches a small lamp too rarely for blocks of
/// pixels: many hold none of its samples in a bin at all), Sidak-corrected.
fn light_strategies_agree_per_bin(
    label: &str,
    ctx: &gatetrace::gpu::GpuContext,
    scene: &PreparedScene,
    transient: &RenderSettings,
    spp: u32,
    seed: u32,
) {
    use gatetrace::integrator::LightStrategy;
    let films = |light_strategy, seed| {
        let settings = RenderSettings { light_strategy, seed, ..transient.clone() };
        common::render_films(ctx, scene, &settings, 16, spp)
    };
    let (a, b) = (films(LightStrategy::NextEvent, seed), films(LightStrategy::Bsdf, seed + 1));
    let groups = 20 * 3;
    let z = common::compare_films(&a, &b, groups, |i| Some(i % groups));
    let limit = t_critical(sidak(common::peer::ALPHA, groups), 15.0);
    for (g, (xa, xb, score)) in z.iter().enumerate() {
        println!("{label}, bin {} channel {}: next-event {xa:.6}, sampled {xb:.6}, z {score:+.2}", g / 3, g % 3);
        assert!(
            score.abs() < limit,
            "{label}: bin {} channel {}: {xa} against {xb} (z = {score:.2}, limit {limit:.2})",
            g / 3,
            g % 3
        );
    }
}

/// Renders `scene` with `path` (at most `max_bounces` bounces, seeds from `seed`) as the peer
/// data in tests/data/NAME_peer hold it: steady 64×64 (8 × 64 spp) against `steady`, and a
/// transient 16×16 of 20 bins of 0.1 m from 1.94 m (8 × 512 spp) against `transient_16x16`.
/// Returns the transient's settings.
fn path_agrees_with_peer(
    ctx: &gatetrace::gpu::GpuContext,
    scene: &PreparedScene,
    name: &str,
    max_bounces: u32,
    seed: u32,
) -> RenderSettings {
    let steady = RenderSettings { width: 64, height: 64, max_bounces, seed, ..Default::default() };
    let films = common::render_films(ctx, scene, &steady, 8, 64);
    check_image(&format!("{name}_steady"), &films, &format!("{name}_peer/steady"));
    let transient = RenderSettings {
        width: 16,
        height: 16,
        gate: Gate::parse("transient:1.94,0.1,20").unwrap(),
        seed: seed + 1,
        ..steady
    };
    let films = common::render_films(ctx, scene, &transient, 8, 512);
    check_transient(&format!("{name}_transient"), &films, &format!("{name}_peer/transient_16x16"), 20);
    transient
}

#[test]
fn a_mitsuba_scene_agrees_with_mitransient_rendering_the_same_file() {
    let ctx = common::gpu();
    let mut scene = mitsuba_box();
    assert_eq!(scene.settings.max_bounces, Some(5));
    scene.settings = SceneSettings::default();
    let scene = PreparedScene::new(scene).unwrap();
    let transient = path_agrees_with_peer(ctx, &scene, "mitsuba_box", 5, 3);
    for method in [Method::Direct, Method::Ellipsoidal] {
        let settings = RenderSettings { method, seed: 5, ..transient.clone() };
        let films = common::render_films(ctx, &scene, &settings, 8, 128);
        check_transient(&format!("mitsuba_box_transient_{method:?}"), &films, "mitsuba_box_peer/transient_16x16", 20);
    }
}

#[test]
fn the_mitsuba_cornell_box_renders_as_the_gltf_one() {
    let ctx = common::gpu();
    let xml = load_scene_with(&common::repo_path("assets/scenes/cornell_box.xml"), &LoadOptions::default()).unwrap();
    assert_eq!(xml.settings.max_bounces, Some(5));
    assert_eq!(xml.triangles.len(), 12);
    let xml = PreparedScene::new(xml).unwrap();
    let gltf = common::cornell_box();
    for method in [Method::Path, Method::Direct] {
        let settings = RenderSettings { width: 32, height: 32, max_bounces: 5, method, ..Default::default() };
        let a = common::render_films(ctx, &xml, &RenderSettings { seed: 1, ..settings.clone() }, 8, 32);
        let b = common::render_films(ctx, &gltf, &RenderSettings { seed: 2, ..settings }, 8, 32);
        common::assert_films_agree(&format!("XML and glTF Cornell box, {method:?}"), &a, &b, 8, 0.01);
    }
}

/// Renders `args` with the binary and returns the output's JSON sidecar and the stderr.
fn render_metadata(name: &str, args: &[&str]) -> (serde_json::Value, String) {
    let dir = common::scratch_dir(name);
    let out = dir.join("out.npy");
    let o =
        Command::new(env!("CARGO_BIN_EXE_gatetrace")).arg("render").args(args).arg("--out").arg(&out).output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{stderr}");
    (serde_json::from_str(&std::fs::read_to_string(dir.join("out.json")).unwrap()).unwrap(), stderr)
}

#[test]
fn the_files_render_settings_are_defaults_the_command_line_overrides() {
    let scene = common::repo_path("assets/scenes/mitsuba_box/scene.xml");
    let scene = scene.to_str().unwrap();
    let (m, _) = render_metadata("mitsuba_settings", &[scene, "--res", "8x8"]);
    assert_eq!(m["resolution"], serde_json::json!([8, 8]), "--res given");
    assert_eq!(m["spp"], 64, "the sampler's sample_count");
    assert_eq!(m["max_bounces"], 5, "the integrator's max_depth 6");
    assert_eq!(m["gate"], "transient:1.94,0.1,20", "the transient film's bins");
    let (m, _) = render_metadata(
        "mitsuba_settings_overridden",
        &[scene, "--res", "4x4", "--spp", "2", "--max-bounces", "1", "--gate", "none"],
    );
    assert_eq!((m["spp"].clone(), m["max_bounces"].clone(), m["gate"].clone()), (2.into(), 1.into(), "none".into()));
    // Parameters replace the file's defaults ($res, $spp, $bins), as mitsuba -D does; one the
    // file does not use is said.
    let (m, stderr) = render_metadata(
        "mitsuba_parameters",
        &[scene, "-D", "res=6", "--define", "spp=3", "-D", "bins=4", "-D", "nope=1"],
    );
    assert_eq!(m["resolution"], serde_json::json!([6, 6]));
    assert_eq!((m["spp"].clone(), m["gate"].clone()), (3.into(), "transient:1.94,0.1,4".into()));
    assert!(stderr.contains("the parameter `nope` is given, but the scene uses no $nope"), "{stderr}");
}

/// A plastic whose base is black reflects only through its coat, so the estimates that steer
/// ellipsoid queries (`--query-weights reflection`) must not weigh it zero (they would drop its
/// paths). The Cornell box with a black-based rough plastic floor and a sphere renders alike by
/// path tracing and by direct and ellipsoidal connections (either query weights) behind a
/// transient gate.
#[test]
fn a_black_plastic_reflects_through_its_coat_with_every_method() {
    let ctx = common::gpu();
    let xml = std::fs::read_to_string(common::repo_path("assets/scenes/cornell_box.xml"))
        .unwrap()
        .replacen(
            "<ref id=\"white\"/>",
            "<bsdf type=\"roughplastic\"><string name=\"distribution\" value=\"ggx\"/><float name=\"alpha\" \
         value=\"0.2\"/><rgb name=\"diffuse_reflectance\" value=\"0\"/></bsdf>",
            1,
        )
        .replace(
            "</scene>",
            "<shape type=\"sphere\"><point name=\"center\" x=\"0.1\" y=\"-0.3\" z=\"0\"/><float name=\"radius\" \
         value=\"0.2\"/><ref id=\"white\"/></shape></scene>",
        );
    let dir = common::scratch_dir("black_plastic");
    std::fs::write(dir.join("scene.xml"), xml).unwrap();
    let scene = load_scene_with(&dir.join("scene.xml"), &LoadOptions::default()).unwrap();
    let floor = &scene.materials[scene.triangles[scene.node("floor").unwrap().triangles.start].material as usize];
    assert!(floor.plastic.is_some() && floor.base_color == Vec3::ZERO);
    let scene = PreparedScene::new(scene).unwrap();
    let settings = RenderSettings {
        width: 16,
        height: 16,
        max_bounces: 3,
        gate: Gate::parse("transient:1.94,0.25,6").unwrap(),
        ..Default::default()
    };
    let reference = common::render_films(ctx, &scene, &RenderSettings { seed: 1, ..settings.clone() }, 8, 256);
    for (method, reflection_weights) in
        [(Method::Direct, false), (Method::Ellipsoidal, false), (Method::Ellipsoidal, true)]
    {
        let mut s = RenderSettings { method, seed: 2, ..settings.clone() };
        s.query.reflection_weights = reflection_weights;
        let films = common::render_films(ctx, &scene, &s, 8, 64);
        let label = format!("black plastic floor, {method:?}, reflection weights {reflection_weights}");
        common::assert_films_agree(&label, &films, &reference, 4, 0.01);
    }
}

/// Glass (`assets/scenes/glass_box.xml`: a BK7 sphere and a thin pane in the Cornell box)
/// agrees with mitransient rendering the same file, steady and as a transient, where every path
/// through the sphere is longer by (eta - 1) times its distance in glass: with `path`, with
/// `direct` (delta vertices in both subpaths, connections only between the others) and as a
/// combined render (paths through glass from its direct half alone). `ellipsoidal` alone
/// refuses the scene with what to do instead, and `auto` leaves it out.
#[test]
fn glass_agrees_with_mitransient_with_path_direct_and_combined() {
    let ctx = common::gpu();
    let scene = load_scene_with(&common::repo_path("assets/scenes/glass_box.xml"), &LoadOptions::default()).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    assert_eq!(scene.settings.max_bounces, Some(7));
    let scene = PreparedScene::new(scene).unwrap();
    let transient = path_agrees_with_peer(ctx, &scene, "glass_box", 7, 7);
    // The light's reflection in the sphere (Fresnel reflectance about 4%) is found only by camera
    // subpaths that choose to reflect there, as in path tracing; at 16×16 one pixel holds it, and
    // its part beyond 2.54 m (bin 6) needs thousands of samples per pixel to be seen at all.
    let direct = RenderSettings { method: Method::Direct, seed: 9, ..transient.clone() };
    let films = common::render_films(ctx, &scene, &direct, 8, 512);
    check_transient("glass_box_transient_direct", &films, "glass_box_peer/transient_16x16", 20);
    let steady = RenderSettings { width: 64, height: 64, gate: Gate::None, seed: 11, ..direct.clone() };
    let films = common::render_films(ctx, &scene, &steady, 8, 32);
    check_image("glass_box_steady_direct", &films, "glass_box_peer/steady");
    let combined = RenderSettings { method: Method::Combined, seed: 13, ..transient.clone() };
    let films = common::render_films(ctx, &scene, &combined, 8, 512);
    check_transient("glass_box_transient_combined", &films, "glass_box_peer/transient_16x16", 20);
    let error = gatetrace::integrator::create_integrator(
        ctx,
        &scene,
        &RenderSettings { method: Method::Ellipsoidal, ..transient.clone() },
    )
    .err()
    .expect("ellipsoidal connections alone cannot sample paths through glass");
    let text = format!("{error:#}");
    assert!(text.contains("dielectric") && text.contains("--method combined"), "{text}");
    let settings = RenderSettings { method: Method::Auto, ..transient };
    assert_eq!(gatetrace::integrator::auto::candidate_methods(&settings, &scene), vec![Method::Path, Method::Direct]);
}

/// Glass and plastic with every method (`assets/scenes/glass_plastic_box.xml`: a BK7 sphere, a
/// rough-plastic block and a checkerboard floor in the Cornell box) agree with mitransient
/// rendering the same file: `path` and `direct` steady and as transients, and the combined
/// method (ellipsoidal connections, with direct ones for the paths through glass that no spheroid
/// vertex can join; gated renders only) as a transient.
#[test]
fn glass_and_plastic_agree_with_mitransient_with_every_method() {
    let ctx = common::gpu();
    let scene =
        load_scene_with(&common::repo_path("assets/scenes/glass_plastic_box.xml"), &LoadOptions::default()).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    let material =
        |node: &str| &scene.materials[scene.triangles[scene.node(node).unwrap().triangles.start].material as usize];
    assert!(material("glass ball").dielectric.is_some() && material("plastic block").plastic.is_some());
    assert!(material("floor").base_color_texture.is_some());
    let scene = PreparedScene::new(scene).unwrap();
    let transient = path_agrees_with_peer(ctx, &scene, "glass_plastic_box", 7, 29);
    let direct = RenderSettings { method: Method::Direct, seed: 31, ..transient.clone() };
    let films = common::render_films(ctx, &scene, &direct, 8, 256);
    check_transient("glass_plastic_box_transient_direct", &films, "glass_plastic_box_peer/transient_16x16", 20);
    let steady = RenderSettings { width: 64, height: 64, gate: Gate::None, seed: 32, ..direct };
    let films = common::render_films(ctx, &scene, &steady, 8, 16);
    check_image("glass_plastic_box_steady_direct", &films, "glass_plastic_box_peer/steady");
    let combined = RenderSettings { method: Method::Combined, seed: 33, ..transient };
    let films = common::render_films(ctx, &scene, &combined, 8, 256);
    check_transient("glass_plastic_box_transient_combined", &films, "glass_plastic_box_peer/transient_16x16", 20);
}

/// Rough glass (`assets/scenes/rough_glass_box.xml`: the glass box's sphere frosted, GGX alpha
/// 0.2). Its steady image agrees with mitransient rendering the same file, with `path` and with
/// `direct` (connections ending at the frosted surface on either side). In time it is checked
/// against itself: next-event estimation alone (light reaching a vertex through the frosted
/// surface counts the medium beyond it) and BSDF sampling alone (the refracted ray's own length)
/// agree bin by bin, and `direct` agrees with `path` bin by bin. (mitransient 1.3.1 counts a
/// next-event connection through a rough dielectric in the medium the path arrived through, so
/// its transient of this scene holds the light that leaves the sphere towards the lamp about
/// 0.3 m late; its steady image is right.) A combined render (no spheroid's vertex on or next
/// to the frosted surface: those paths come from its direct half) agrees with `path` bin by bin;
/// `ellipsoidal` alone refuses the scene with what to do instead, and `auto` measures `path` and
/// `direct`.
#[test]
fn rough_glass_agrees_with_mitransient_and_its_strategies_agree_in_time() {
    let ctx = common::gpu();
    let scene =
        load_scene_with(&common::repo_path("assets/scenes/rough_glass_box.xml"), &LoadOptions::default()).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    let scene = PreparedScene::new(scene).unwrap();
    assert!(scene.has_rough_dielectric());
    let steady = RenderSettings { width: 64, height: 64, max_bounces: 7, seed: 17, ..Default::default() };
    let films = common::render_films(ctx, &scene, &steady, 8, 64);
    check_image("rough_glass_box_steady", &films, "rough_glass_box_peer/steady");
    let transient =
        RenderSettings { width: 16, height: 16, gate: Gate::parse("transient:1.94,0.1,20").unwrap(), ..steady.clone() };
    light_strategies_agree_per_bin("rough glass", ctx, &scene, &transient, 512, 18);
    let direct = RenderSettings { method: Method::Direct, seed: 19, ..steady.clone() };
    let films = common::render_films(ctx, &scene, &direct, 8, 16);
    check_image("rough_glass_box_steady_direct", &films, "rough_glass_box_peer/steady");
    let path = common::render_films(ctx, &scene, &RenderSettings { seed: 20, ..transient.clone() }, 8, 512);
    let direct = RenderSettings { method: Method::Direct, seed: 21, ..transient.clone() };
    let films = common::render_films(ctx, &scene, &direct, 8, 256);
    common::assert_films_agree("rough glass, direct against path", &films, &path, 4, 0.001);
    let combined = RenderSettings { method: Method::Combined, seed: 22, ..transient.clone() };
    let films = common::render_films(ctx, &scene, &combined, 8, 128);
    common::assert_films_agree("rough glass, combined against path", &films, &path, 4, 0.001);
    let ellipsoidal = RenderSettings { method: Method::Ellipsoidal, ..transient.clone() };
    let error = gatetrace::integrator::create_integrator(ctx, &scene, &ellipsoidal)
        .err()
        .expect("ellipsoidal connections alone cannot sample paths through rough glass");
    let text = format!("{error:#}");
    assert!(text.contains("dielectric") && text.contains("--method combined"), "{text}");
    let settings = RenderSettings { method: Method::Auto, ..transient };
    assert_eq!(gatetrace::integrator::auto::candidate_methods(&settings, &scene), vec![Method::Path, Method::Direct]);
}

/// Fog (`assets/scenes/fog_box.xml`: a cube of homogeneous fog bounded by a `null` surface in
/// the Cornell box; extinction 4 m^-1, a coloured albedo, Henyey-Greenstein g = 0.5) agrees with
/// mitransient's `transient_prbvolpath` rendering the same file, steady and as a transient, with
/// `path`. Its two ways of reaching the light, next-event estimation alone (through the fog's
/// surface, attenuated by the fog) and phase and BSDF sampling alone, agree bin by bin. `direct`
/// (subpaths that scatter in the fog), `ellipsoidal` (spheroid vertices on surfaces and in the
/// fog) and `combined` (both families, its weights counting the fog's spheroid vertices too)
/// agree with mitransient's transient too, and `auto` weighs `path`, `direct` and `ellipsoidal`.
#[test]
fn fog_agrees_with_mitransient_with_path() {
    let ctx = common::gpu();
    let scene = load_scene_with(&common::repo_path("assets/scenes/fog_box.xml"), &LoadOptions::default()).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    assert_eq!(scene.settings.max_bounces, Some(7));
    assert_eq!(scene.media.len(), 1);
    let fog = &scene.media[0];
    assert_eq!((fog.sigma_t, fog.g), (4.0, 0.5));
    assert!(fog.albedo.abs_diff_eq(Vec3::new(0.9, 0.7, 0.4), 1e-6));
    assert_eq!(scene.camera_medium, None);
    let scene = PreparedScene::new(scene).unwrap();
    let transient = path_agrees_with_peer(ctx, &scene, "fog_box", 7, 17);
    light_strategies_agree_per_bin("fog", ctx, &scene, &transient, 256, 19);
    let direct = RenderSettings { method: Method::Direct, seed: 29, ..transient.clone() };
    let films = common::render_films(ctx, &scene, &direct, 8, 128);
    check_transient("fog_box_transient_direct", &films, "fog_box_peer/transient_16x16", 20);
    let ellipsoidal = RenderSettings { method: Method::Ellipsoidal, seed: 31, ..transient.clone() };
    let films = common::render_films(ctx, &scene, &ellipsoidal, 8, 128);
    check_transient("fog_box_transient_ellipsoidal", &films, "fog_box_peer/transient_16x16", 20);
    let combined = RenderSettings { method: Method::Combined, seed: 37, ..transient.clone() };
    let films = common::render_films(ctx, &scene, &combined, 8, 64);
    check_transient("fog_box_transient_combined", &films, "fog_box_peer/transient_16x16", 20);
    let settings = RenderSettings { method: Method::Auto, ..transient };
    assert_eq!(
        gatetrace::integrator::auto::candidate_methods(&settings, &scene),
        vec![Method::Path, Method::Direct, Method::Ellipsoidal]
    );
}

/// A slab of fog in front of a diffuse target (`assets/scenes/fog_slab.xml`: fog of extinction
/// 0.6 m^-1 and optical depth 1.08 between the camera and a grey wall 3 m away, lit by a small
/// area light beside the camera) agrees with mitransient's `transient_prbvolpath` rendering the
/// same file, with `path`, `direct` and `ellipsoidal`: as a transient cube (the image mean of
/// each of its 10 bins of 0.5 m and each channel), and behind the gate on the wall's return,
/// `box:6.0..6.5`, which is the peer's bin 8 (its channel means and 8x8-pixel blocks). The
/// return (6.01 to 6.41 m) lies within one bin: the peer's paths come out shorter by its offset
/// ray origins at each crossing of the fog's `null` faces, and with bins of 0.2 m the edge at
/// 6.2 m moved 0.25 % of that bin's light (tests/data/fog_slab_peer/README.md).
#[test]
fn a_fog_slab_before_a_target_agrees_with_mitransient_as_a_transient_and_behind_a_gate() {
    let ctx = common::gpu();
    let scene = load_scene_with(&common::repo_path("assets/scenes/fog_slab.xml"), &LoadOptions::default()).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    assert_eq!((scene.settings.max_bounces, scene.media.len()), (Some(5), 1));
    let scene = PreparedScene::new(scene).unwrap();
    let (bins, gate_bin) = (10, 8);
    let (shape, peer_mean) = common::reference("fog_slab_peer/transient_16x16_mean.npy");
    let (_, peer_var) = common::reference("fog_slab_peer/transient_16x16_var.npy");
    assert_eq!(shape, [16, 16, bins, 3]);
    // The peer's bin 8 as an image: pixel p, channel c at ((p * bins) + 8) * 3 + c.
    let bin = |values: &[f32]| -> Vec<f32> {
        (0..16 * 16 * 3).map(|i| values[((i / 3) * bins + gate_bin) * 3 + i % 3]).collect()
    };
    let (gate_mean, gate_var) = (bin(&peer_mean), bin(&peer_var));
    let transient = RenderSettings {
        width: 16,
        height: 16,
        max_bounces: 5,
        gate: Gate::parse("transient:2,0.5,10").unwrap(),
        ..Default::default()
    };
    for (method, spp, seed) in [(Method::Path, 512, 41), (Method::Direct, 128, 43), (Method::Ellipsoidal, 64, 47)] {
        let name = method.name();
        let settings = RenderSettings { method, seed, ..transient.clone() };
        let films = common::render_films(ctx, &scene, &settings, 8, spp);
        check_transient(&format!("fog_slab_transient_{name}"), &films, "fog_slab_peer/transient_16x16", bins);

        let gated = RenderSettings { gate: Gate::parse("box:6.0..6.5").unwrap(), seed: seed + 1, ..settings };
        let films = common::render_films(ctx, &scene, &gated, 8, spp);
        common::peer::check_image_values(&format!("fog_slab_gate_{name}"), &films, &[16, 16, 3], &gate_mean, &gate_var);
    }
}

/// A medium bounded by glass (`assets/scenes/murky_glass_box.xml`: a water sphere of index 1.33
/// holding a scattering medium, extinction 6 m^-1, g = 0.6) agrees with mitransient's
/// `transient_prbvolpath` rendering the same file, steady and as a transient, with `path`: light
/// refracts into the medium, scatters there, and every stretch inside, from the surface to a
/// scattering vertex and between two of them, counts the index times its distance. `direct`
/// agrees with `path` there, as a transient, and so it does with the sphere frosted (rough glass)
/// and a lamp inside it.
#[test]
fn a_medium_inside_glass_agrees_with_mitransient_with_path() {
    let ctx = common::gpu();
    let scene =
        load_scene_with(&common::repo_path("assets/scenes/murky_glass_box.xml"), &LoadOptions::default()).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    assert_eq!((scene.settings.max_bounces, scene.media.len()), (Some(31), 1));
    let ball = &scene.materials[scene.triangles[scene.node("murky ball").unwrap().triangles.start].material as usize];
    assert!(!ball.null && (ball.dielectric.unwrap().eta - 1.33).abs() < 1e-6);
    assert_eq!((ball.media.interior, ball.media.exterior), (Some(0), None));
    let scene = PreparedScene::new(scene).unwrap();
    let transient = path_agrees_with_peer(ctx, &scene, "murky_glass_box", 31, 23);
    // `direct` through the glass into the medium (delta vertices on the sphere, scattering
    // vertices inside it at the water's index) against `path`, at 8 bounces.
    let settings = |method, seed| RenderSettings { method, seed, max_bounces: 8, ..transient.clone() };
    let path = common::render_films(ctx, &scene, &settings(Method::Path, 25), 8, 256);
    let direct = common::render_films(ctx, &scene, &settings(Method::Direct, 27), 8, 64);
    common::assert_films_agree("murky glass, direct against path", &direct, &path, 4, 0.001);
    // The same sphere frosted (rough glass, GGX alpha 0.3) with a lamp at its centre: connections
    // end on its surface (one that leaves through it starts in the medium beyond), and the lamp's
    // subpaths start in the water's medium and index (counted at the index of air, bin 1 fails at
    // z = -10.8).
    let dir = common::scratch_dir("frosted_murky_glass");
    let xml = std::fs::read_to_string(common::repo_path("assets/scenes/murky_glass_box.xml")).unwrap();
    let lamp = r#"<emitter type="point"><point name="position" value="0.1, -0.3, 0.05"/>
        <rgb name="intensity" value="0.2"/></emitter>
</scene>"#;
    let frosted = xml
        .replacen(r#"<bsdf type="dielectric">"#, r#"<bsdf type="roughdielectric"><float name="alpha" value="0.3"/>"#, 1)
        .replace("</scene>", lamp);
    assert_ne!(frosted, xml);
    std::fs::write(dir.join("scene.xml"), frosted).unwrap();
    let scene = PreparedScene::new(load_scene_with(&dir.join("scene.xml"), &LoadOptions::default()).unwrap()).unwrap();
    assert!(scene.has_rough_dielectric());
    let path = common::render_films(ctx, &scene, &settings(Method::Path, 28), 8, 256);
    let direct = common::render_films(ctx, &scene, &settings(Method::Direct, 30), 8, 64);
    common::assert_films_agree("frosted murky glass, direct against path", &direct, &path, 4, 0.001);
}

/// A heterogeneous medium (`assets/scenes/smoke_box/scene.xml`: a puff of smoke whose
/// extinction, up to 40 m^-1, is a grid of 12^3 voxels over a turned box, its albedo an RGB grid
/// on the same voxels, bounded by a `null` cube) agrees with mitransient's
/// `transient_prbvolpath` rendering the same file, steady (32×32), with `path`: delta tracking
/// for free flights, ratio tracking for shadow rays, trilinear lookups clamped at the box's
/// faces, the albedo where each scattering lies, and the grids placed by their `to_world`. Not in
/// time: mitransient 1.3.1 leaves the stretches before rejected (null) collisions out of its
/// path lengths (tests/media.rs `null_collisions_count_in_the_path_length` checks gatetrace's).
#[test]
fn a_heterogeneous_medium_agrees_with_mitransient_with_path() {
    let ctx = common::gpu();
    let scene =
        load_scene_with(&common::repo_path("assets/scenes/smoke_box/scene.xml"), &LoadOptions::default()).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    assert_eq!((scene.settings.max_bounces, scene.media.len()), (Some(31), 1));
    let grid = scene.media[0].grid.as_ref().expect("the smoke is on a grid");
    assert_eq!((grid.resolution, scene.media[0].sigma_t), ([12, 12, 12], 40.0));
    assert_eq!(grid.albedo.as_ref().map(Vec::len), Some(3 * 12 * 12 * 12));
    let scene = PreparedScene::new(scene).unwrap();
    let steady = RenderSettings { width: 32, height: 32, max_bounces: 31, seed: 41, ..Default::default() };
    let films = common::render_films(ctx, &scene, &steady, 8, 64);
    check_image("smoke_box_steady", &films, "smoke_box_peer/steady");
}
