//! glTF loading: conventions (transforms, lights, materials, textures) and clear errors that
//! name the file for every kind of bad input.

mod common;

use common::gltf_builder::{Camera, Material, Mesh, PointLight, Scene, png_rgb8, quad_z, write_json};
use gatetrace::integrator::RenderSettings;
use gatetrace::scene::{PreparedScene, load_gltf};
use serde_json::json;

fn lit_quad() -> Scene {
    Scene {
        meshes: vec![quad_z(1.0, -1.0, true, 0)],
        materials: vec![Material::emitter(2.0)],
        camera: Some(Camera { position: [0.0; 3], rotation: [0.0, 0.0, 0.0, 1.0], yfov: 0.5 }),
        point_lights: vec![],
    }
}

/// Loads `doc` written as `name` and returns the error message (the load must fail).
fn load_error(dir: &std::path::Path, name: &str, doc: &serde_json::Value) -> String {
    let path = write_json(dir, name, doc);
    let err = load_gltf(&path).expect_err("loading must fail");
    let message = format!("{err:#}");
    assert!(message.contains(name), "the error must name the file: {message}");
    message
}

#[test]
fn cornell_box_loads_with_its_documented_conventions() {
    let scene = load_gltf(&common::repo_path("assets/scenes/cornell_box.gltf")).unwrap();
    assert_eq!(scene.triangles.len(), 12);
    assert_eq!(scene.dropped_degenerate, 0);
    assert!((scene.camera.position - glam::Vec3::new(0.0, 0.0, 2.0)).length() < 1e-6);
    assert!((scene.camera.forward - glam::Vec3::NEG_Z).length() < 1e-6);
    assert!((scene.camera.yfov - 40f32.to_radians()).abs() < 1e-6);
    let emissive: Vec<_> = scene.materials.iter().filter(|m| m.is_emissive()).collect();
    assert_eq!(emissive.len(), 1);
    assert_eq!(emissive[0].emission, glam::Vec3::splat(10.0), "emissiveFactor x KHR_materials_emissive_strength");
    // The winding (front face) agrees with the authored normals everywhere.
    for t in &scene.triangles {
        let n = (t.positions[1] - t.positions[0]).cross(t.positions[2] - t.positions[0]).normalize();
        for vn in t.normals.unwrap() {
            assert!(n.dot(vn) > 0.99);
        }
    }
    // The shortest path light -> wall -> camera is 1.9403 m (docs/design.md section 3): the light
    // is 1 mm below the ceiling, so its nearest wall point is the ceiling edge behind it.
}

#[test]
fn node_transforms_are_baked_and_the_camera_follows_its_parents() {
    // The emitter quad (z = -1, facing +z) is rotated +90 deg about y to x = -1 facing +x and
    // translated; the camera gets the same rotation through a parent node, to look down -x.
    let mut doc = lit_quad().to_json();
    doc["nodes"][0]["translation"] = json!([0.0, 0.0, 0.5]);
    doc["nodes"][0]["rotation"] = json!([0.0, 0.70710678, 0.0, 0.70710678]); // quad now faces +x
    let camera = doc["nodes"][1].clone();
    doc["nodes"][1] = json!({"children": [2], "rotation": [0.0, 0.70710678, 0.0, 0.70710678]});
    doc["nodes"].as_array_mut().unwrap().push(camera);
    doc["scenes"][0]["nodes"] = json!([0, 1]);
    let dir = common::scratch_dir("transforms");
    let scene = load_gltf(&write_json(&dir, "rotated.gltf", &doc)).unwrap();
    assert!((scene.camera.forward - glam::Vec3::NEG_X).length() < 1e-5);
    for t in &scene.triangles {
        for p in t.positions {
            // Rotation maps (x, y, z) to (z, y, -x); then the translation adds 0.5 to z.
            assert!((p.x + 1.0).abs() < 1e-5 && (p.z - 0.5).abs() < 1.0 + 1e-5, "quad baked to x = -1 (got {p})");
        }
    }
    let ctx = common::gpu();
    let prepared = PreparedScene::new(scene).unwrap();
    let film =
        common::render_films(ctx, &prepared, &RenderSettings { width: 8, height: 8, ..Default::default() }, 1, 2)
            .remove(0);
    assert!(film.data.iter().all(|&v| v == 2.0), "the rotated camera sees the emitter in every pixel");
}

#[test]
fn point_lights_and_default_materials_load() {
    let mut s = lit_quad();
    s.materials = vec![Material::diffuse([0.5; 3])];
    s.point_lights = vec![PointLight { position: [0.0, 1.0, 0.0], intensity: 3.0 }];
    s.meshes.push(Mesh { material: None, ..quad_z(0.5, -3.0, true, 0) });
    let dir = common::scratch_dir("point_lights");
    let scene = load_gltf(&s.write(&dir, "point.gltf")).unwrap();
    assert_eq!(scene.point_lights.len(), 1);
    assert_eq!(scene.point_lights[0].position, glam::Vec3::Y);
    assert_eq!(scene.point_lights[0].intensity, glam::Vec3::splat(3.0));
    assert_eq!(scene.materials.len(), 2, "glTF's default material is added for primitives without one");
    assert_eq!(scene.triangles[2].material, 1);
}

#[test]
fn zero_area_triangles_are_dropped_and_counted() {
    let mut s = lit_quad();
    let mut degenerate = quad_z(1.0, -2.0, true, 0);
    degenerate.positions[1] = degenerate.positions[0]; // both triangles use vertex 0 and 1
    s.meshes.push(degenerate);
    let dir = common::scratch_dir("degenerate");
    let scene = load_gltf(&s.write(&dir, "degenerate.gltf")).unwrap();
    assert_eq!(scene.dropped_degenerate, 1);
    assert_eq!(scene.triangles.len(), 3);
}

#[test]
fn bad_files_give_clear_errors() {
    let dir = common::scratch_dir("bad_files");
    let missing = dir.join("does_not_exist.gltf");
    let e = format!("{:#}", load_gltf(&missing).unwrap_err());
    assert!(e.contains("does_not_exist.gltf") && e.contains("cannot read"), "{e}");

    std::fs::write(dir.join("malformed.gltf"), "{ this is not json").unwrap();
    let e = format!("{:#}", load_gltf(&dir.join("malformed.gltf")).unwrap_err());
    assert!(e.contains("malformed.gltf") && e.contains("not a valid glTF"), "{e}");

    let mut doc = lit_quad().to_json();
    doc["buffers"][0]["uri"] = json!("missing.bin");
    let e = load_error(&dir, "missing_buffer.gltf", &doc);
    assert!(e.contains("buffer"), "{e}");

    let mut s = lit_quad();
    s.camera = None;
    let e = load_error(&dir, "no_camera.gltf", &s.to_json());
    assert!(e.contains("no camera"), "{e}");

    let mut s = lit_quad();
    s.materials = vec![Material::diffuse([0.5; 3])];
    let e = load_error(&dir, "no_light.gltf", &s.to_json());
    assert!(e.contains("no light"), "{e}");

    let mut s = lit_quad();
    s.meshes[0].positions[2] = [f32::NAN, 0.0, -1.0];
    let e = load_error(&dir, "nan_vertex.gltf", &s.to_json());
    assert!(e.contains("not finite"), "{e}");

    let mut doc = lit_quad().to_json();
    doc["cameras"][0] =
        json!({"type": "orthographic", "orthographic": {"xmag": 1.0, "ymag": 1.0, "znear": 0.1, "zfar": 10.0}});
    let e = load_error(&dir, "orthographic.gltf", &doc);
    assert!(e.contains("orthographic"), "{e}");

    let mut doc = lit_quad().to_json();
    doc["meshes"][0]["primitives"][0]["indices"] = json!(99);
    let e = load_error(&dir, "bad_accessor.gltf", &doc);
    assert!(!e.is_empty());

    let mut doc = lit_quad().to_json();
    doc["extensionsUsed"] = json!(["KHR_lights_punctual"]);
    doc["extensions"] = json!({"KHR_lights_punctual": {"lights": [{"type": "spot", "spot": {"innerConeAngle": 0.6, "outerConeAngle": 0.5}}]}});
    doc["nodes"]
        .as_array_mut()
        .unwrap()
        .push(json!({"name": "lamp", "extensions": {"KHR_lights_punctual": {"light": 0}}}));
    doc["scenes"][0]["nodes"] = json!([0, 1, 2]);
    let e = load_error(&dir, "spot.gltf", &doc);
    assert!(e.contains("spot cone angles") && e.contains("lamp") && e.contains("spot.gltf"), "{e}");

    // Thin-lens extras on the camera node: both lengths, positive, numbers.
    let camera_node =
        lit_quad().to_json()["nodes"].as_array().unwrap().iter().position(|n| n.get("camera").is_some()).unwrap();
    for (extras, needle) in [
        (json!({"aperture_radius": 0.1}), "needs `focus_distance`"),
        (json!({"focus_distance": 2.0}), "needs `aperture_radius`"),
        (json!({"aperture_radius": -0.1, "focus_distance": 2.0}), "aperture radius -0.1 m is not a positive length"),
        (json!({"aperture_radius": 0.1, "focus_distance": 0.0}), "focus distance 0 m is not a positive length"),
        (json!({"aperture_radius": "wide", "focus_distance": 2.0}), "not a number of metres"),
    ] {
        let mut doc = lit_quad().to_json();
        doc["nodes"][camera_node]["extras"] = extras.clone();
        let e = load_error(&dir, "lens.gltf", &doc);
        assert!(e.contains(needle) && e.contains("lens.gltf") && e.contains("camera extras"), "{extras}: {e}");
    }
}

#[test]
fn thin_lens_extras_and_spot_cones_load() {
    let dir = common::scratch_dir("lens_and_spot");
    let camera_node =
        lit_quad().to_json()["nodes"].as_array().unwrap().iter().position(|n| n.get("camera").is_some()).unwrap();
    let mut doc = lit_quad().to_json();
    doc["nodes"][camera_node]["extras"] = json!({"aperture_radius": 0.05, "focus_distance": 3.0, "note": "kept"});
    doc["extensionsUsed"] = json!(["KHR_lights_punctual"]);
    doc["extensions"] = json!({"KHR_lights_punctual": {"lights": [
        {"type": "spot", "intensity": 2.0, "spot": {"innerConeAngle": 0.25, "outerConeAngle": 0.5}}]}});
    // The spot looks along its node's -z turned 90 degrees about +x: straight down.
    let s = std::f32::consts::FRAC_1_SQRT_2;
    doc["nodes"].as_array_mut().unwrap().push(json!({"name": "lamp", "translation": [0.0, 1.0, 0.0],
        "rotation": [-s, 0.0, 0.0, s], "extensions": {"KHR_lights_punctual": {"light": 0}}}));
    let count = doc["nodes"].as_array().unwrap().len();
    doc["scenes"][0]["nodes"] = json!((0..count).collect::<Vec<_>>());
    let scene = load_gltf(&write_json(&dir, "lens_and_spot.gltf", &doc)).unwrap();
    assert_eq!(scene.camera.lens, Some(gatetrace::scene::ThinLens { aperture_radius: 0.05, focus_distance: 3.0 }));
    let spot = scene.point_lights[0].spot.expect("a spot cone");
    assert!((spot.direction - glam::Vec3::NEG_Y).length() < 1e-6, "{}", spot.direction);
    assert_eq!((spot.inner, spot.outer), (0.25, 0.5));
    assert_eq!(spot.falloff(glam::Vec3::NEG_Y), 1.0);
    assert_eq!(spot.falloff(glam::Vec3::X), 0.0);
    // Halfway between the cones' cosines the ramp is 1/2, squared.
    let c = 0.5 * (0.25f32.cos() + 0.5f32.cos());
    let w = glam::Vec3::new((1.0 - c * c).sqrt(), -c, 0.0);
    assert!((spot.falloff(w) - 0.25).abs() < 1e-4, "{}", spot.falloff(w));
    // An aperture radius of 0 is a pinhole.
    doc["nodes"][camera_node]["extras"] = json!({"aperture_radius": 0.0, "focus_distance": 3.0});
    assert_eq!(load_gltf(&write_json(&dir, "pinhole.gltf", &doc)).unwrap().camera.lens, None);
}

#[test]
fn base_color_textures_are_decoded_and_sampled_like_the_cpu_twin() {
    use gatetrace::scene::materials::texture_bilinear;
    // A 2x2 sRGB texture on the quad.
    let texels: [u8; 12] = [255, 0, 0, 0, 255, 0, 0, 0, 255, 128, 128, 128];
    let dir = common::scratch_dir("textures");
    std::fs::write(dir.join("checker.png"), png_rgb8(2, 2, &texels)).unwrap();
    let mut s = lit_quad();
    s.materials = vec![Material::diffuse([1.0, 0.5, 1.0])];
    s.point_lights = vec![PointLight { position: [0.0; 3], intensity: 1.0 }];
    let mut doc = s.to_json();
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
    doc["textures"] = json!([{"source": 0, "sampler": 0}]);
    doc["samplers"] = json!([{"wrapS": 10497, "wrapT": 33071}]);
    doc["images"] = json!([{"uri": "checker.png"}]);
    let path = write_json(&dir, "textured_base.gltf", &doc);
    let scene = load_gltf(&path).unwrap();
    assert_eq!(scene.textures.len(), 1);
    let tex = &scene.textures[0];
    assert_eq!((tex.width, tex.height, tex.clamp_u, tex.clamp_v), (2, 2, false, true));
    assert_eq!(tex.texels[0], glam::Vec3::new(1.0, 0.0, 0.0));
    let grey = gatetrace::scene::gltf_loader::srgb_to_linear(128.0 / 255.0);
    assert!((tex.texels[3] - glam::Vec3::splat(grey)).length() < 1e-6 && (grey - 0.2158605).abs() < 1e-6);
    // TEXCOORD_0 maps the quad's corners to the texture's corners.
    for tri in &scene.triangles {
        for (p, uv) in tri.positions.iter().zip(tri.uvs) {
            assert_eq!(uv, glam::Vec2::new(0.5 * (p.x + 1.0), 0.5 * (p.y + 1.0)));
        }
    }
    // WGSL texture lookups against the CPU twin, filtered and (as a Mitsuba checkerboard's)
    // nearest.
    let ctx = common::gpu();
    let mut prepared = None;
    for nearest in [false, true] {
        let mut scene = scene.clone();
        scene.textures[0].nearest = nearest;
        let scene = PreparedScene::new(scene).unwrap();
        let tracer = gatetrace::integrator::PathTracer::new(
            ctx,
            &scene,
            &RenderSettings { width: 4, height: 4, ..Default::default() },
        )
        .unwrap();
        let mut rng = gatetrace::rng::Rng::new(5, 5, 5);
        let input: Vec<[f32; 4]> = (0..2048)
            .map(|_| [f32::from_bits(0), 3.0 * rng.next_f32() - 1.0, 3.0 * rng.next_f32() - 1.0, 0.0])
            .collect();
        let out = common::run_probe(ctx, &tracer, "probe_functions", &[("FUNCTION", 7.0)], &input, input.len());
        for (x, g) in input.iter().zip(out) {
            let uv = glam::Vec2::new(x[1], x[2]);
            let c = texture_bilinear(&scene.texture_infos, &scene.texels, 0, uv);
            for k in 0..3 {
                assert!(
                    (g[k] - c[k]).abs() < 1e-5,
                    "texture at {uv} (nearest {nearest}): GPU {} vs CPU {}",
                    g[k],
                    c[k]
                );
            }
            if nearest {
                // The texel holding uv: u repeats, v clamps (the sampler above).
                let column = (2.0 * uv.x).floor().rem_euclid(2.0) as usize;
                let row = (2.0 * uv.y).floor().clamp(0.0, 1.0) as usize;
                let expected = scene.scene.textures[0].texels[row * 2 + column];
                assert!((c - expected).abs().max_element() <= expected.max_element() / 2048.0, "nearest at {uv}");
            }
        }
        prepared = Some(scene);
    }
    let prepared = prepared.unwrap();
    // The texel storage is half precision: the red texel's green channel is exactly 0 and the
    // grey texel is within half-float rounding (2^-11 relative).
    let t = texture_bilinear(&prepared.texture_infos, &prepared.texels, 0, glam::Vec2::new(0.75, 0.75));
    assert!((t.x - grey).abs() <= grey / 2048.0);
}

#[test]
fn textured_albedo_renders_like_the_equal_base_color() {
    // A plane lit from the camera, once with base colour g and once with base colour 1 times a
    // 1x1 texture that decodes to g. Same seed, same paths: pixels agree within the texture's
    // half-float storage (2^-11 relative) and f32 rounding.
    let dir = common::scratch_dir("textured_render");
    let g = gatetrace::scene::gltf_loader::srgb_to_linear(128.0 / 255.0);
    std::fs::write(dir.join("grey.png"), png_rgb8(1, 1, &[128, 128, 128])).unwrap();
    let mut s = lit_quad();
    s.point_lights = vec![PointLight { position: [0.0; 3], intensity: 1.0 }];
    s.materials = vec![Material::diffuse([g; 3])];
    let plain = PreparedScene::new(load_gltf(&s.write(&dir, "plain.gltf")).unwrap()).unwrap();
    s.materials = vec![Material::diffuse([1.0; 3])];
    let mut doc = s.to_json();
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
    doc["textures"] = json!([{"source": 0}]);
    doc["images"] = json!([{"uri": "grey.png"}]);
    let textured = PreparedScene::new(load_gltf(&write_json(&dir, "textured.gltf", &doc)).unwrap()).unwrap();
    assert!(textured.has_textures() && !plain.has_textures());
    let ctx = common::gpu();
    let settings = RenderSettings { width: 16, height: 16, max_bounces: 2, ..Default::default() };
    let a = common::render_films(ctx, &plain, &settings, 1, 8).remove(0);
    let b = common::render_films(ctx, &textured, &settings, 1, 8).remove(0);
    assert!(a.data.iter().all(|&v| v > 0.0));
    for (x, y) in a.data.iter().zip(&b.data) {
        assert!((x - y).abs() <= x * (1.0 / 2048.0 + 1e-6), "untextured {x} vs textured {y}");
    }
}

/// The example NLOS scene (tools/scenes/make_nlos_scene.py) is set up as its description says: from
/// the sensor and laser origin every point of the relay wall is in sight and the hidden letter
/// is not (the occluder is in the way), and the wall and the letter see each other.
#[test]
fn example_nlos_scene_hides_the_letter_from_the_origin() {
    use gatetrace::bvh::traverse::trace_any;
    use gatetrace::gpu::layout::NONE;
    use glam::Vec3;

    let path = common::repo_path("assets/scenes/nlos_letter.gltf");
    let doc: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let o = &doc["extras"]["nlos"]["sensor_origin"];
    let origin = Vec3::new(o[0].as_f64().unwrap() as f32, o[1].as_f64().unwrap() as f32, o[2].as_f64().unwrap() as f32);
    let scene = PreparedScene::new(load_gltf(&path).unwrap()).unwrap();
    assert!((scene.scene.camera.position - origin).length() < 1e-6, "the camera sits at the origin");
    let (nodes, triangles) = (&scene.bvh.nodes, &scene.triangles);
    let in_plane_z = |z: f32| -> Vec<Vec3> {
        triangles
            .iter()
            .filter(|t| [t.v0, t.v0 + t.e1, t.v0 + t.e2].iter().all(|v| (v.z - z).abs() < 1e-6))
            .map(|t| t.v0 + (t.e1 + t.e2) / 3.0)
            .collect()
    };
    let letter = in_plane_z(0.5);
    assert_eq!(letter.len(), 6, "the Z is three quads");
    assert_eq!(in_plane_z(0.0).len(), 2, "the relay wall is one quad");
    // Segments stop 0.1 mm short of their end, so the surface they end on does not count.
    let blocked = |from: Vec3, to: Vec3| {
        let d = to - from;
        let length = d.length();
        trace_any(nodes, triangles, from, d / length, length - 1e-4, NONE, NONE)
    };
    let wall_points: Vec<Vec3> = (0..11)
        .flat_map(|i| (0..11).map(move |j| Vec3::new(-0.49 + 0.098 * i as f32, -0.49 + 0.098 * j as f32, 0.0)))
        .collect();
    for &w in &wall_points {
        assert!(!blocked(origin, w), "wall point {w} is hidden from the origin");
        for &l in &letter {
            assert!(!blocked(w + Vec3::Z * 1e-4, l), "wall point {w} does not see letter point {l}");
        }
    }
    for &l in &letter {
        assert!(blocked(origin, l), "letter point {l} is in sight of the origin");
    }
}
