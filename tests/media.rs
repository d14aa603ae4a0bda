//! Participating media (src/scene/medium.rs, shaders/lib/medium.wesl): the WGSL phase function
//! and its sampling against their CPU twins and against the phase function's own distribution,
//! light through absorbing media (homogeneous and on grids) against closed forms, and white
//! furnaces. Renders of scattering media
//! against mitransient are in tests/mitsuba.rs (`fog_agrees_with_mitransient_with_path`).

mod common;

use common::stats::{chi2_test, sidak, t_critical};
use gatetrace::film::Gate;
use gatetrace::integrator::{Method, PathTracer, RenderSettings};
use gatetrace::rng::Rng;
use gatetrace::scene::medium::{hg_phase, sample_hg};
use gatetrace::scene::{LoadOptions, PreparedScene, load_scene_with};
use glam::Vec3;

/// The probe's direction of travel for polar angle `theta` (its azimuth fixed).
fn direction(theta: f32) -> Vec3 {
    Vec3::new(theta.sin() * 0.6, theta.sin() * 0.8, theta.cos())
}

#[test]
fn wgsl_phase_sampling_matches_its_twin_and_its_density() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let tracer = PathTracer::new(ctx, &scene, &RenderSettings { width: 8, height: 8, ..Default::default() }).unwrap();
    let mut rng = Rng::new(5, 0, 0);
    let gs = [-0.6f32, 0.0, 0.5, 0.9];
    let input: Vec<[f32; 4]> =
        (0..8192).map(|i| [rng.next_f32(), rng.next_f32(), gs[i % 4], 3.0 * rng.next_f32()]).collect();
    let out = common::run_probe(ctx, &tracer, "probe_functions", &[("FUNCTION", 22.0)], &input, input.len());
    for (i, (x, g)) in input.iter().zip(&out).enumerate() {
        let (w, pdf) = sample_hg(direction(x[3]), x[2], [x[0], x[1]]);
        let gpu = Vec3::new(g[0], g[1], g[2]);
        assert!(gpu.abs_diff_eq(w, 2e-5), "record {i}: GPU direction {gpu} vs CPU {w}");
        assert!((g[3] - pdf).abs() <= 1e-4 * pdf, "record {i}: GPU pdf {} vs CPU {pdf}", g[3]);
        // The density is the phase function at the sampled cosine.
        let mu = gpu.dot(direction(x[3]).normalize());
        assert!((g[3] - hg_phase(mu, x[2])).abs() <= 2e-3 * g[3] + 1e-6, "record {i}: pdf {} at mu {mu}", g[3]);
    }
    // The sampled cosines follow the phase function: chi-square over 40 cells of mu for each g.
    for &g in &gs {
        let n = 40;
        let input: Vec<[f32; 4]> =
            (0..100_000).map(|_| [rng.next_f32(), rng.next_f32(), g, 3.0 * rng.next_f32()]).collect();
        let out = common::run_probe(ctx, &tracer, "probe_functions", &[("FUNCTION", 22.0)], &input, input.len());
        let mut observed = vec![0.0; n];
        for (x, o) in input.iter().zip(&out) {
            let mu = Vec3::new(o[0], o[1], o[2]).dot(direction(x[3]).normalize()).clamp(-1.0, 1.0);
            observed[(((mu + 1.0) * 0.5 * n as f32) as usize).min(n - 1)] += 1.0;
        }
        let expected: Vec<f64> = (0..n)
            .map(|c| {
                // 2 pi times the phase function integrated over the cell (midpoint rule, 200 steps).
                let (lo, width) = (-1.0 + 2.0 * c as f64 / n as f64, 2.0 / n as f64);
                let steps = 200;
                (0..steps)
                    .map(|k| {
                        let mu = lo + width * (k as f64 + 0.5) / steps as f64;
                        2.0 * std::f64::consts::PI * hg_phase(mu as f32, g) as f64 * width / steps as f64
                    })
                    .sum::<f64>()
                    * input.len() as f64
            })
            .collect();
        let (stat, dof, p) = chi2_test(&observed, &expected);
        println!("g {g}: chi-square {stat:.1} over {dof} dof, p {p:.3}");
        assert!(p > 1e-3, "g {g}: the sampled cosines do not follow the phase function (p = {p})");
    }
}

/// The image mean over 8 films of each of the transient's two bins and three channels,
/// [bin 0: r, g, b, bin 1: r, g, b], per film.
fn film_means(films: &[gatetrace::film::Film]) -> Vec<Vec<f64>> {
    films
        .iter()
        .map(|f| {
            let pixels = (f.width * f.height) as f64;
            let mut m = vec![0.0; 6];
            for (i, v) in f.data.iter().enumerate() {
                m[i % 6] += *v as f64 / pixels;
            }
            m
        })
        .collect()
}

/// The mean over the image of exp(-sigma_t d) for a square image of `w` pixels a side and field
/// of view `fov_deg` (degrees) looking straight at a plane `distance` (m) away, d the distance a
/// ray travels in the medium: `depth` (m) along the axis, over the cosine of the ray's angle (each
/// pixel averaged over 16 x 16 points).
fn mean_transmittance(w: u32, fov_deg: f64, sigma_t: f64, depth: f64) -> f64 {
    let tan = (0.5 * fov_deg).to_radians().tan();
    let mut total = 0.0;
    for p in 0..(w * w) {
        let (px, py) = (p % w, p / w);
        for k in 0..256 {
            let x = (2.0 * (px as f64 + (k % 16) as f64 / 16.0 + 1.0 / 32.0) / w as f64 - 1.0) * tan;
            let y = (2.0 * (py as f64 + (k / 16) as f64 / 16.0 + 1.0 / 32.0) / w as f64 - 1.0) * tan;
            total += (-sigma_t * depth * (1.0 + x * x + y * y).sqrt()).exp() / 256.0;
        }
    }
    total / (w * w) as f64
}

/// Each channel's image mean in the first bin agrees with `exact` (Student's t over the films,
/// Sidak over the channels), and the second bin holds no light.
fn assert_first_bin_is(films: &[gatetrace::film::Film], exact: f64) {
    let means = film_means(films);
    let limit = t_critical(sidak(0.001, 3), (films.len() - 1) as f64);
    for c in 0..3 {
        let x: Vec<f64> = means.iter().map(|m| m[c]).collect();
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (x.len() - 1) as f64 / x.len() as f64;
        let z = (mean - exact) / var.sqrt();
        println!("channel {c}: {mean:.6} against exp(-sigma_t d) {exact:.6}, z {z:+.2}");
        assert!(z.abs() < limit, "channel {c}: {mean} against {exact} (z = {z:.2}, limit {limit:.2})");
        let late: f64 = means.iter().map(|m| m[3 + c]).sum();
        assert_eq!(late, 0.0, "channel {c}: light outside the straight ray's bin");
    }
}

/// A lamp of radiance 1 filling the view of a camera 3 m from it, with the straight rays' path
/// lengths in the first of two 0.1 m bins from 2.95 m.
fn lamp_scene(medium: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="4"/>
        <float name="near_clip" value="1e-5"/>
        <transform name="to_world"><lookat origin="0, 0, 2" target="0, 0, 0" up="0, 1, 0"/></transform>
    </sensor>
    <shape type="rectangle">
        <transform name="to_world"><translate z="-1"/></transform>
        <emitter type="area"><rgb name="radiance" value="1"/></emitter>
    </shape>
    {medium}
</scene>"#
    )
}

fn render_lamp(name: &str, xml: &str, fog: Option<&str>) -> Vec<gatetrace::film::Film> {
    let dir = common::scratch_dir(name);
    let path = dir.join("scene.xml");
    std::fs::write(&path, xml).unwrap();
    let fog = fog.map(|f| gatetrace::scene::MediumDesc::parse_fog(f).unwrap());
    let scene =
        PreparedScene::new(load_scene_with(&path, &LoadOptions { fog, ..Default::default() }).unwrap()).unwrap();
    lamp_films(&scene)
}

/// 8 films of 1,024 samples per pixel of an 8 x 8 lamp scene, in two bins of 0.1 m from 2.95 m.
fn lamp_films(scene: &PreparedScene) -> Vec<gatetrace::film::Film> {
    let settings = RenderSettings {
        width: 8,
        height: 8,
        gate: Gate::parse("transient:2.95,0.1,2").unwrap(),
        seed: 3,
        ..Default::default()
    };
    common::render_films(common::gpu(), scene, &settings, 8, 1024)
}

/// A camera standing in a purely absorbing fog (albedo 0, extinction 0.4 m^-1; `LoadOptions::fog`,
/// `render --fog`) looking at a lamp 3 m away sees exp(-0.4 d), d the whole ray's length: camera
/// rays start in the camera's medium.
#[test]
fn a_camera_in_an_absorbing_fog_sees_a_lamp_attenuated_over_the_whole_ray() {
    let films = render_lamp("absorbing_fog", &lamp_scene(""), Some("0.4,0,0"));
    assert_first_bin_is(&films, mean_transmittance(8, 4.0, 0.4, 3.0));
}

/// A cube 1 m wide (moved by `moved`, transform elements) of purely absorbing medium (albedo 0,
/// extinction 1.5 m^-1) bounded by a `null` surface.
fn absorbing_slab(moved: &str) -> String {
    format!(
        r#"<shape type="cube">
        <transform name="to_world"><scale value="0.5"/>{moved}</transform>
        <bsdf type="null"/>
        <medium type="homogeneous" name="interior">
            <float name="sigma_t" value="1.5"/>
            <rgb name="albedo" value="0"/>
        </medium>
    </shape>"#
    )
}

/// A camera looking through a slab of purely absorbing medium (albedo 0, extinction 1.5 m^-1,
/// 1 m thick between two `null` faces) at an emitter of radiance 1: each pixel sees exp(-1.5 d),
/// d the ray's length in the slab (1 / cos of its angle to the axis), all of it at the path length
/// of the straight ray (a transient of two bins around 3 m).
#[test]
fn light_through_an_absorbing_slab_is_attenuated_by_its_transmittance() {
    let films = render_lamp("absorbing_slab", &lamp_scene(&absorbing_slab("")), None);
    assert_first_bin_is(&films, mean_transmittance(8, 4.0, 1.5, 1.0));
}

/// A null boundary lying on a surface: the absorbing slab of the test above with its back face in
/// the lamp's plane (a block of fog resting on the lamp). A ray meets the null face and the lamp
/// at the same distance; the lamp is taken (bvh.wesl NULL_SURFACES), so every pixel still sees
/// exp(-1.5 d), with the scene's triangles tested one by one (14 of them) and through the BVH (a
/// sphere out of view adds hundreds).
#[test]
fn a_null_boundary_on_a_surface_yields_to_the_surface() {
    let slab = absorbing_slab(r#"<translate z="-0.5"/>"#);
    let sphere =
        r#"<shape type="sphere"><point name="center" x="0" y="0" z="5"/><float name="radius" value="0.1"/></shape>"#;
    for (name, extra) in [("tie_small_scene", ""), ("tie_bvh", sphere)] {
        let films = render_lamp(name, &lamp_scene(&format!("{slab}{extra}")), None);
        assert_first_bin_is(&films, mean_transmittance(8, 4.0, 1.5, 1.0));
    }
}

/// A white furnace of fog: a camera inside a closed box whose walls emit radiance 1 inwards and
/// reflect nothing, filled with fog that absorbs nothing (albedo 1, extinction 1.5 m^-1, g = 0.6;
/// `LoadOptions::fog`). Every path scatters until it reaches a wall, so every pixel sees radiance 1
/// whatever the fog does (the bounce limit cuts a share below 10^-9), with emission reached by
/// light sampling from the fog and by phase sampling, weighed against each other.
#[test]
fn a_white_furnace_of_fog_shows_the_walls_radiance() {
    let xml = r#"<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="65"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="60"/>
        <transform name="to_world"><lookat origin="0, 0, 0" target="0, 0, -1" up="0, 1, 0"/></transform>
    </sensor>
"#
    .to_owned()
        + FURNACE_WALLS;
    let dir = common::scratch_dir("fog_furnace");
    let path = dir.join("scene.xml");
    std::fs::write(&path, xml).unwrap();
    let fog = Some(gatetrace::scene::MediumDesc::parse_fog("1.5,1,0.6").unwrap());
    let scene = load_scene_with(&path, &LoadOptions { fog, ..Default::default() }).unwrap();
    assert_furnace_is_white(scene, 5);
}

/// The walls of the white furnaces, closing their scenes: a cube about the origin, 2 m wide, whose
/// inside emits radiance 1 and reflects nothing.
const FURNACE_WALLS: &str = r#"<shape type="cube">
        <boolean name="flip_normals" value="true"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>
        <emitter type="area"><rgb name="radiance" value="1"/></emitter>
    </shape>
</scene>"#;

/// Renders a white furnace (`scene`: the camera in a non-absorbing medium inside walls that emit
/// radiance 1 and reflect nothing) at 8 x 8 pixels, 8 films of 256 samples per pixel from `seed`,
/// and asserts that each channel's image mean is 1 (Student's t over the films, Sidak over the
/// channels).
fn assert_furnace_is_white(scene: gatetrace::scene::Scene, seed: u32) {
    let max_bounces = scene.settings.max_bounces.unwrap();
    let scene = PreparedScene::new(scene).unwrap();
    let settings = RenderSettings { width: 8, height: 8, max_bounces, seed, ..Default::default() };
    let films = common::render_films(common::gpu(), &scene, &settings, 8, 256);
    let limit = t_critical(sidak(0.001, 3), (films.len() - 1) as f64);
    for c in 0..3 {
        let x: Vec<f64> =
            films.iter().map(|f| f.data.iter().skip(c).step_by(3).map(|&v| v as f64).sum::<f64>() / 64.0).collect();
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (x.len() - 1) as f64 / x.len() as f64;
        let z = (mean - 1.0) / var.sqrt();
        println!("channel {c}: {mean:.6} (standard error {:.6}), z {z:+.2}", var.sqrt());
        assert!(z.abs() < limit, "channel {c}: {mean} against 1 (z = {z:.2}, limit {limit:.2})");
    }
}

/// The absorbing slab again, as a glTF scene: a cube whose material's `extras.medium` makes it the
/// boundary of an absorbing medium (docs/scenes.md) between the camera and the lamp, against the
/// same closed form, homogeneous and on a grid (`extras.medium.grid`); a medium without an
/// extinction, and a grid without its box, are refused, naming the material.
#[test]
fn a_gltf_material_with_a_medium_bounds_it() {
    use common::gltf_builder::{Camera, Material, Mesh, Scene, quad_z, write_json};
    // A unit cube about the origin, wound outwards.
    let positions: Vec<[f32; 3]> =
        (0..8).map(|i| [(i & 1) as f32 - 0.5, ((i >> 1) & 1) as f32 - 0.5, ((i >> 2) & 1) as f32 - 0.5]).collect();
    let indices = vec![
        0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4, 2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6, 1, 3, 5, 3, 7, 5,
    ];
    let cube = Mesh { positions, normals: None, uvs: None, indices, material: Some(1) };
    let scene = Scene {
        meshes: vec![quad_z(1.0, -1.0, true, 0), cube],
        materials: vec![Material::emitter(1.0), Material::diffuse([0.5; 3])],
        camera: Some(Camera { position: [0.0, 0.0, 2.0], rotation: [0.0, 0.0, 0.0, 1.0], yfov: 4f32.to_radians() }),
        point_lights: vec![],
    };
    let dir = common::scratch_dir("gltf_medium");
    let mut doc = scene.to_json();
    doc["materials"][1]["name"] = "slab".into();
    doc["materials"][1]["extras"] = serde_json::json!({"medium": {"sigma_t": 1.5, "albedo": 0.0}});
    let path = write_json(&dir, "slab.gltf", &doc);
    let loaded = load_scene_with(&path, &LoadOptions::default()).unwrap();
    assert_eq!(loaded.media.len(), 1);
    assert!(loaded.materials[1].null && loaded.materials[1].media.interior == Some(0));
    let films = lamp_films(&PreparedScene::new(loaded).unwrap());
    assert_first_bin_is(&films, mean_transmittance(8, 4.0, 1.5, 1.0));
    doc["materials"][1]["extras"] = serde_json::json!({"medium": {"albedo": 0.5}});
    let path = write_json(&dir, "no_extinction.gltf", &doc);
    let error = format!("{:#}", load_scene_with(&path, &LoadOptions::default()).unwrap_err());
    assert!(error.contains("no_extinction.gltf") && error.contains("`slab`") && error.contains("sigma_t"), "{error}");
    // On a grid (`extras.medium.grid`): the graded slab of
    // light_through_a_graded_grid_medium_is_attenuated_by_its_transmittance, its voxels over the
    // cube's box, with an albedo grid of three channels read alongside.
    let values = [0.1, 0.4, 1.0, 0.25, 0.6];
    gatetrace::scene::medium::write_vol(&dir.join("graded.vol"), [1, 1, 5], &values).unwrap();
    gatetrace::scene::medium::write_vol(&dir.join("albedo.vol"), [1, 1, 5], &[0.0; 15]).unwrap();
    for filter in ["trilinear", "nearest"] {
        let grid = serde_json::json!({"uri": "graded.vol", "min": [-0.5, -0.5, -0.5], "max": [0.5, 0.5, 0.5],
            "filter": filter, "albedo": "albedo.vol"});
        doc["materials"][1]["extras"] = serde_json::json!({"medium": {"sigma_t": 1.5, "grid": grid}});
        let path = write_json(&dir, "graded.gltf", &doc);
        let loaded = load_scene_with(&path, &LoadOptions::default()).unwrap();
        let grid = loaded.media[0].grid.as_ref().expect("a grid medium");
        assert_eq!(
            (grid.resolution, grid.nearest, grid.albedo.as_ref().map(Vec::len)),
            ([1, 1, 5], filter == "nearest", Some(15))
        );
        let films = lamp_films(&PreparedScene::new(loaded).unwrap());
        println!("grid, filter {filter}:");
        let mean = 1.5 * values.iter().sum::<f32>() as f64 / values.len() as f64;
        assert_first_bin_is(&films, mean_transmittance(8, 4.0, mean, 1.0));
    }
    doc["materials"][1]["extras"] = serde_json::json!({"medium": {"sigma_t": 1.5, "grid": {"uri": "graded.vol"}}});
    let path = write_json(&dir, "no_box.gltf", &doc);
    let error = format!("{:#}", load_scene_with(&path, &LoadOptions::default()).unwrap_err());
    assert!(error.contains("no_box.gltf") && error.contains("`slab`") && error.contains("`min`"), "{error}");
}

/// A heterogeneous medium's `sigma_t` grid (a `.vol` file written to `dir`): `values` along z
/// (one voxel across x and y), over the unit cube placed on [-0.5, 0.5]^3, looked up with
/// `filter`, with extinction `scale` times the values (m^-1) and albedo `albedo`.
fn graded_medium(dir: &std::path::Path, values: &[f32], filter: &str, scale: f32, albedo: f32, id: &str) -> String {
    let vol = dir.join(format!("{id}.vol"));
    gatetrace::scene::medium::write_vol(&vol, [1, 1, values.len() as u32], values).unwrap();
    format!(
        r#"<medium type="heterogeneous" id="{id}">
            <volume type="gridvolume" name="sigma_t">
                <string name="filename" value="{id}.vol"/>
                <string name="filter_type" value="{filter}"/>
                <transform name="to_world"><translate value="-0.5, -0.5, -0.5"/></transform>
            </volume>
            <float name="scale" value="{scale}"/>
            <rgb name="albedo" value="{albedo}"/>
        </medium>"#
    )
}

/// Light through a slab of purely absorbing heterogeneous medium, its extinction graded along
/// the view axis on a grid of five voxels (0.2 to 3 m^-1, 1 m thick between two `null` faces):
/// whether interpolated between the voxels' centres (clamped at the faces) or taken from the
/// nearest voxel, the extinction integrates to the voxels' mean times the ray's length in the
/// slab, so each pixel sees exp(-mean d) (delta tracking against the majorant).
#[test]
fn light_through_a_graded_grid_medium_is_attenuated_by_its_transmittance() {
    let dir = common::scratch_dir("graded_grid");
    let values = [0.1, 0.4, 1.0, 0.25, 0.6];
    let mean = 1.5 * values.iter().sum::<f32>() as f64 / values.len() as f64;
    for filter in ["trilinear", "nearest"] {
        let medium = graded_medium(&dir, &values, filter, 1.5, 0.0, "graded");
        let slab = format!(
            r#"{medium}
            <shape type="cube">
                <transform name="to_world"><scale value="0.5"/></transform>
                <bsdf type="null"/>
                <ref id="graded" name="interior"/>
            </shape>"#
        );
        let path = dir.join("scene.xml");
        std::fs::write(&path, lamp_scene(&slab)).unwrap();
        let films = lamp_films(&PreparedScene::new(load_scene_with(&path, &LoadOptions::default()).unwrap()).unwrap());
        println!("filter {filter}:");
        assert_first_bin_is(&films, mean_transmittance(8, 4.0, mean, 1.0));
    }
}

/// A white furnace of heterogeneous fog: the camera inside a closed box whose walls emit
/// radiance 1 and reflect nothing, standing in a medium that absorbs nothing (albedo 1) and
/// whose extinction (up to 4 m^-1) varies on a grid of 4 x 4 x 4 voxels over the box's middle
/// (nothing outside it). Every pixel sees radiance 1, with light sampled from the medium through
/// shadow rays whose transmittance is ratio tracked, and emission reached by phase sampling,
/// weighed against each other.
#[test]
fn a_white_furnace_of_heterogeneous_fog_shows_the_walls_radiance() {
    let dir = common::scratch_dir("grid_furnace");
    let values: Vec<f32> = (0..64).map(|i| ((i * 37) % 64) as f32 / 63.0).collect();
    gatetrace::scene::medium::write_vol(&dir.join("fog.vol"), [4, 4, 4], &values).unwrap();
    let xml = r#"<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="65"/></integrator>
    <medium type="heterogeneous" id="fog">
        <volume type="gridvolume" name="sigma_t">
            <string name="filename" value="fog.vol"/>
            <transform name="to_world"><scale value="1.2"/><translate value="-0.6, -0.6, -0.6"/></transform>
        </volume>
        <float name="scale" value="4"/>
        <rgb name="albedo" value="1"/>
        <phase type="hg"><float name="g" value="0.5"/></phase>
    </medium>
    <sensor type="perspective">
        <float name="fov" value="60"/>
        <transform name="to_world"><lookat origin="0, 0, 0.8" target="0, 0, -1" up="0, 1, 0"/></transform>
        <ref id="fog"/>
    </sensor>
"#
    .to_owned()
        + FURNACE_WALLS;
    let path = dir.join("scene.xml");
    std::fs::write(&path, xml).unwrap();
    let scene = load_scene_with(&path, &LoadOptions::default()).unwrap();
    assert!(scene.media[0].grid.is_some(), "the medium is on a grid");
    assert_furnace_is_white(scene, 7);
}

/// A fog box whose medium is `medium` (an XML `<medium name="interior">`, its grids `files` of
/// 2 x 2 x 2 voxels), lit by the Cornell box's light, as a transient of 12 bins of 0.1 m from
/// 1.94 m: 8 films of 16 x 16 pixels, paths of at most `max_bounces` vertices.
fn fog_box_transient(
    name: &str,
    medium: &str,
    files: &[(&str, &[f32])],
    max_bounces: u32,
) -> Vec<gatetrace::film::Film> {
    let settings = RenderSettings {
        width: 16,
        height: 16,
        max_bounces,
        gate: Gate::parse("transient:1.94,0.1,12").unwrap(),
        seed: 11,
        ..Default::default()
    };
    common::render_films(common::gpu(), &fog_box(name, medium, files, ""), &settings, 8, 256)
}

/// The Cornell box holding a cube of fog whose medium is `medium` (an XML `<medium
/// name="interior">`, its grids `files` of 2 x 2 x 2 voxels), and `extra` (XML elements).
fn fog_box(name: &str, medium: &str, files: &[(&str, &[f32])], extra: &str) -> PreparedScene {
    let dir = common::scratch_dir(name);
    for (file, values) in files {
        gatetrace::scene::medium::write_vol(&dir.join(file), [2, 2, 2], values).unwrap();
    }
    let box_xml = std::fs::read_to_string(common::repo_path("assets/scenes/cornell_box.xml")).unwrap();
    let fog = format!(
        r#"<shape type="cube">
        <transform name="to_world"><scale value="0.25"/><translate value="0.05, -0.2, 0.05"/></transform>
        <bsdf type="null"/>
        {medium}
    </shape>
    {extra}
</scene>"#
    );
    let path = dir.join("scene.xml");
    std::fs::write(&path, box_xml.replace("</scene>", &fog)).unwrap();
    PreparedScene::new(load_scene_with(&path, &LoadOptions::default()).unwrap()).unwrap()
}

/// The Cornell box with `extra` (XML elements), filled with fog around the camera (`--fog
/// 1.5,0.8,0.6`): every ray travels in it, and no surface changes it.
fn fogged_box(name: &str, extra: &str) -> PreparedScene {
    fogged_box_in(name, extra, "1.5,0.8,0.6", true)
}

/// The Cornell box (without its area light unless `area_light`) with `extra` (XML elements),
/// filled with the fog `--fog fog` around the camera.
fn fogged_box_in(name: &str, extra: &str, fog: &str, area_light: bool) -> PreparedScene {
    let dir = common::scratch_dir(name);
    let mut box_xml = std::fs::read_to_string(common::repo_path("assets/scenes/cornell_box.xml")).unwrap();
    if !area_light {
        let start = box_xml.find("<emitter type=\"area\">").expect("the Cornell box has an area light");
        let end = start + box_xml[start..].find("</emitter>").unwrap() + "</emitter>".len();
        box_xml.replace_range(start..end, "");
    }
    std::fs::write(dir.join("scene.xml"), box_xml.replace("</scene>", &format!("{extra}</scene>"))).unwrap();
    let fog = Some(gatetrace::scene::MediumDesc::parse_fog(fog).unwrap());
    PreparedScene::new(load_scene_with(&dir.join("scene.xml"), &LoadOptions { fog, ..Default::default() }).unwrap())
        .unwrap()
}

/// `direct` through media (subpaths that scatter in them, connections attenuated by the media
/// they cross, densities without the transmittance in the MIS weights) agrees with `path`, per
/// bin and 4 x 4 block of a transient: in the fog box lit by the box's light and a spot outside
/// the fog; in the box filled with fog around the camera, whose lights' subpaths start in it; with
/// a point light inside a cube of fog (its subpaths start in the cube's medium, found from the
/// cube's faces); and in a heterogeneous fog (delta tracking in the subpaths, ratio tracking in
/// the connections).
#[test]
fn direct_agrees_with_path_in_media() {
    let ctx = common::gpu();
    let lamp_in_fog = r#"<emitter type="point">
        <point name="position" value="-0.2, 0.3, 0.1"/>
        <rgb name="intensity" value="0.3"/>
    </emitter>
    <shape type="cube">
        <transform name="to_world"><scale value="0.15"/><translate value="-0.2, 0.3, 0.1"/></transform>
        <bsdf type="null"/>
        <medium type="homogeneous" name="interior">
            <float name="sigma_t" value="6"/>
            <rgb name="albedo" value="0.9, 0.8, 0.6"/>
            <phase type="hg"><float name="g" value="-0.3"/></phase>
        </medium>
    </shape>"#;
    let scenes = [
        (fog_box("direct_fog_box", CONNECTED_FOG, &[], FOG_SPOT), "the fog box with a spot light"),
        (fogged_box("direct_fogged_box", FOG_SPOT), "the box filled with fog"),
        (fog_box("direct_lamp_in_fog", CONNECTED_FOG, &[], lamp_in_fog), "a point light inside fog"),
        (
            fog_box("direct_grid_fog", &fog_box_grid_medium("0.8"), &[("density.vol", &FOG_BOX_DENSITY)], ""),
            "a heterogeneous fog",
        ),
    ];
    for (k, (scene, name)) in scenes.iter().enumerate() {
        let settings = |method, seed| connection_settings("transient:1.94,0.1,12", method, seed);
        let path = common::render_films(ctx, scene, &settings(Method::Path, 31 + k as u32), 8, 256);
        let direct = common::render_films(ctx, scene, &settings(Method::Direct, 41 + k as u32), 8, 64);
        common::assert_films_agree(&format!("direct against path in {name}"), &direct, &path, 4, 0.001);
    }
}

/// Ellipsoidal connections in media: surface vertices found by the ellipsoid queries (both
/// segments attenuated) and vertices placed in the fog itself (connect_medium) agree with direct
/// connections per bin and 4 x 4 block, as a transient and behind a narrow box gate, in the fog
/// box with a spot light and in the box filled with fog around the camera, and behind the gate
/// in a heterogeneous fog. (Its transient is left out: the first light from the top of that
/// dense fog reaches some blocks in fewer than one ellipsoidal sample of a thousand, which
/// places the vertex without regard to the extinction, so a few hundred samples per pixel see
/// none of it; docs/design.md section 5.9.)
#[test]
fn ellipsoidal_agrees_with_direct_in_media() {
    let ctx = common::gpu();
    let fog = fog_box("ellipsoidal_fog_box", CONNECTED_FOG, &[], FOG_SPOT);
    let fogged = fogged_box("ellipsoidal_fogged_box", FOG_SPOT);
    let grid = fog_box("ellipsoidal_grid_fog", &fog_box_grid_medium("0.8"), &[("density.vol", &FOG_BOX_DENSITY)], "");
    for (k, (scene, name, gate, spp)) in [
        (&fog, "the fog box with a spot light", "transient:1.94,0.1,12", 32),
        (&fog, "the fog box with a spot light", "box:2.6..2.62", 32),
        (&fogged, "the box filled with fog", "transient:1.94,0.1,12", 32),
        (&fogged, "the box filled with fog", "box:3.3..3.32", 32),
        (&grid, "a heterogeneous fog", "box:2.6..2.62", 32),
    ]
    .into_iter()
    .enumerate()
    {
        let settings = |method, seed| connection_settings(gate, method, seed);
        let direct = common::render_films(ctx, scene, &settings(Method::Direct, 61 + k as u32), 8, 4 * spp);
        let ellipsoidal = common::render_films(ctx, scene, &settings(Method::Ellipsoidal, 71 + k as u32), 8, spp);
        common::assert_films_agree(
            &format!("ellipsoidal against direct in {name} on {gate}"),
            &ellipsoidal,
            &direct,
            4,
            0.001,
        );
    }
}

/// The query roulette in media: a pair it leaves out has neither its surface vertex
/// (connect_ellipsoidal) nor its vertex in the fog (connect_medium), and both weigh a pair it
/// keeps by the inverse of its probability, so the image agrees with `direct`'s.
#[test]
fn ellipsoidal_with_a_query_roulette_agrees_with_direct_in_media() {
    let ctx = common::gpu();
    let fog = fog_box("roulette_fog_box", CONNECTED_FOG, &[], FOG_SPOT);
    let gate = "box:2.6..2.62";
    let direct = common::render_films(ctx, &fog, &connection_settings(gate, Method::Direct, 81), 8, 128);
    let rouletted = RenderSettings { query_roulette: Some(0.25), ..connection_settings(gate, Method::Ellipsoidal, 82) };
    let ellipsoidal = common::render_films(ctx, &fog, &rouletted, 8, 32);
    common::assert_films_agree(
        &format!("ellipsoidal, query roulette 0.25, against direct on {gate}"),
        &ellipsoidal,
        &direct,
        4,
        0.001,
    );
}

/// Fog that fills all space (`--fog`) bounds no path's length: a camera subpath may scatter far
/// beyond the geometry and come back. The path-length bounds say so (no longest, where the fog
/// box's, bounded by its `null` cube, stay finite), and behind a gate beyond the longest path
/// within the Cornell box's bounds with 5 bounces (12 m, against 10.9 m) `ellipsoidal` agrees with
/// `direct` on the light that is there, per 4 x 4 block (with the box's bound as the longest, the
/// gate is refused as unreachable and no sample is traced).
#[test]
fn fog_that_fills_all_space_bounds_no_path_length() {
    let ctx = common::gpu();
    let thin = fogged_box_in("unbounded_thin_fog", FOG_SPOT, "0.1,0.9,0.6", true);
    let bounded = fog_box("unbounded_fog_box", CONNECTED_FOG, &[], FOG_SPOT);
    // (The fog box's triangles span the Cornell box: its bound is the box's.)
    let within_box = bounded.scene.path_length_bounds(5).1;
    assert!(thin.scene.path_length_bounds(5).1.is_infinite(), "the fog that fills all space has a longest path");
    assert!(bounded.scene.path_length_bounds(5).1.is_finite(), "the fog box's paths have no longest");
    assert!(within_box < 12.0, "the Cornell box's longest path with 5 bounces is {within_box} m");
    let cw = connection_settings("cw:3e7,0", Method::Ellipsoidal, 0);
    let range = gatetrace::integrator::target_sampler(&thin, &RenderSettings { max_bounces: 5, ..cw });
    assert!(range.is_some_and(|t| t.params.hi.is_finite()), "a CW gate's targets need a finite range");
    let gate = "box:12..12.5";
    let settings = |method, seed| RenderSettings { max_bounces: 5, ..connection_settings(gate, method, seed) };
    assert_eq!(gatetrace::integrator::unreachable_gate(&thin, &settings(Method::Direct, 0)), None);
    let direct = common::render_films(ctx, &thin, &settings(Method::Direct, 91), 8, 512);
    let ellipsoidal = common::render_films(ctx, &thin, &settings(Method::Ellipsoidal, 93), 8, 128);
    for (method, films) in [("direct", &direct), ("ellipsoidal", &ellipsoidal)] {
        let total: f64 = films.iter().flat_map(|f| f.data.iter()).map(|&v| v as f64).sum();
        assert!(total > 0.0, "{method} renders nothing behind {gate}");
    }
    common::assert_films_agree(&format!("ellipsoidal against direct behind {gate}"), &ellipsoidal, &direct, 4, 0.001);
}

/// `combined` in media: its direct half's subpaths scatter in the fog, its ellipsoidal half places
/// spheroid vertices on surfaces and in the fog, and the family weights count both
/// (family_mis.wesl medium_vertex_density); the sum agrees with `direct`, per 4 x 4 block, in the
/// fog box (a transient and a narrow gate), in the box filled with fog around the camera (with a
/// query roulette of 1/4, which both halves' weights count) and in a heterogeneous fog. The weights' sums to one are tested on random paths in tests/mis.rs; here
/// both halves must form them alike from what the kernels store (a medium vertex's extinction in
/// its uv.y: with connect_medium's vertex storing none, the fog box's transient fails at z = 5.3).
#[test]
fn combined_agrees_with_direct_in_media() {
    let ctx = common::gpu();
    let fog = fog_box("combined_fog_box", CONNECTED_FOG, &[], FOG_SPOT);
    let fogged = fogged_box("combined_fogged_box", FOG_SPOT);
    let grid = fog_box("combined_grid_fog", &fog_box_grid_medium("0.8"), &[("density.vol", &FOG_BOX_DENSITY)], "");
    for (k, (scene, name, gate)) in [
        (&fog, "the fog box with a spot light", "transient:1.94,0.1,12"),
        (&fog, "the fog box with a spot light", "box:2.6..2.62"),
        (&fogged, "the box filled with fog", "box:3.3..3.32"),
        (&grid, "a heterogeneous fog", "box:2.6..2.62"),
    ]
    .into_iter()
    .enumerate()
    {
        let settings = |method, seed| connection_settings(gate, method, seed);
        let direct = common::render_films(ctx, scene, &settings(Method::Direct, 91 + k as u32), 8, 128);
        let roulette = (k == 2).then_some(0.25);
        let combined_settings =
            RenderSettings { query_roulette: roulette, ..settings(Method::Combined, 95 + k as u32) };
        let combined = common::render_films(ctx, scene, &combined_settings, 8, 24);
        common::assert_films_agree(
            &format!("combined against direct in {name} on {gate}"),
            &combined,
            &direct,
            4,
            0.001,
        );
    }
}

/// A directional light in media: its wave enters the Cornell box through the open front, crosses
/// the fog box (bounded by a `null` cube) and lights the walls behind it. `direct` (light subpaths
/// from the wave's disk, which enter the fog through its boundary, and connections to the light
/// drawn anew where its ray starts) and `ellipsoidal` (camera vertices in the fog joined to the
/// light too, connect_spherical) agree with `path`, per bin and 4 x 4 block of a transient and
/// behind a narrow box gate. So do both in the box filled with fog around the camera, where the
/// wave starts inside the fog and lights only the beam its subpaths start in (lights.wesl
/// directional_reaches: with next-event estimation lighting fog outside it too, `direct`'s
/// transient bin 1 fails at z = -4.2), and where camera subpaths scatter in fog outside the
/// geometry's bounds, nearer to where the wave starts than to those bounds (Scene::light_bounds:
/// with the geometry's bounds as the lights' in extend_subpaths' closing distance, `direct`
/// behind the gate fails at z = -5.2).
#[test]
fn a_directional_light_in_media_agrees_with_path() {
    let ctx = common::gpu();
    let sun = r#"<emitter type="directional">
        <vector name="direction" value="0.2, -0.6, -1"/>
        <rgb name="irradiance" value="1.5"/>
    </emitter>"#;
    let fog = fog_box("directional_fog_box", CONNECTED_FOG, &[], sun);
    let fogged = fogged_box("directional_fogged_box", sun);
    let sunlit = fogged_box_in("directional_sunlit_fogged_box", sun, "1.5,0.8,0.6", false);
    assert_eq!((fog.scene.directional_lights.len(), fogged.scene.directional_lights.len()), (1, 1));
    // `auto` weighs only the methods that render each scene behind a gate.
    let gated = connection_settings("box:2.6..2.62", Method::Auto, 0);
    let candidates = |scene| gatetrace::integrator::auto::candidate_methods(&gated, scene);
    assert_eq!(candidates(&fog), vec![Method::Path, Method::Direct, Method::Ellipsoidal]);
    assert_eq!(candidates(&fogged), vec![Method::Path, Method::Direct, Method::Ellipsoidal]);
    // (scene, its name, gate, most bounces, path's and the other methods' samples per pixel)
    let cases = [
        (&fog, "the fog box", "transient:1.5,0.5,10", 4, 512, 128),
        (&fog, "the fog box", "box:2.6..2.62", 4, 1024, 128),
        (&fogged, "the box filled with fog", "transient:1.5,0.5,10", 4, 1024, 128),
        (&sunlit, "the box filled with fog, lit by the sun alone", "box:2.6..2.62", 5, 4096, 512),
    ];
    for (k, (scene, name, gate, bounces, path_spp, spp)) in cases.into_iter().enumerate() {
        let settings =
            |method, seed| RenderSettings { max_bounces: bounces, ..connection_settings(gate, method, seed) };
        let path = common::render_films(ctx, scene, &settings(Method::Path, 81 + k as u32), 8, path_spp);
        for method in [Method::Direct, Method::Ellipsoidal] {
            let seed = 83 + 2 * (method == Method::Ellipsoidal) as u32;
            let films = common::render_films(ctx, scene, &settings(method, seed + k as u32), 8, spp);
            common::assert_films_agree(
                &format!("{} against path with a directional light in {name} on {gate}", method.name()),
                &films,
                &path,
                4,
                0.001,
            );
        }
    }
}

/// 16 x 16 pixels, 4 bounces, `gate` (a gate spec), `method` and `seed`: the settings of the
/// connection tests in media.
fn connection_settings(gate: &str, method: Method, seed: u32) -> RenderSettings {
    RenderSettings {
        width: 16,
        height: 16,
        max_bounces: 4,
        gate: Gate::parse(gate).unwrap(),
        method,
        seed,
        ..Default::default()
    }
}

/// `auto` leaves `path` out where a point or spot light stands in a scattering medium (its
/// next-event estimates from vertices next to the light have infinite variance): behind a gate
/// it weighs `direct` and `ellipsoidal`, and in the steady state it renders `direct` without a
/// pilot. A spot outside the fog, an area light in fog and a fog that absorbs only keep `path`.
#[test]
fn auto_leaves_out_path_where_a_delta_light_stands_in_fog() {
    let gated = connection_settings("box:2.6..2.62", Method::Auto, 0);
    let steady = connection_settings("none", Method::Auto, 0);
    let candidates = |settings: &RenderSettings, scene| gatetrace::integrator::auto::candidate_methods(settings, scene);
    let spot_in_fog = fogged_box_in("spot_in_fog", FOG_SPOT, "1.5,0.8,0.6", false);
    assert!(spot_in_fog.scene.has_delta_light_in_scattering_medium());
    assert_eq!(candidates(&gated, &spot_in_fog), vec![Method::Direct, Method::Ellipsoidal]);
    assert_eq!(candidates(&steady, &spot_in_fog), vec![Method::Direct]);
    let road = load_scene_with(&common::repo_path("assets/scenes/fog_road.xml"), &LoadOptions::default()).unwrap();
    assert!(road.has_delta_light_in_scattering_medium(), "fog_road.xml's flash stands in its fog");

    // The spot outside the fog's cube; an area light in fog; fog that scatters nothing.
    let spot_outside = fog_box("spot_outside_fog", CONNECTED_FOG, &[], FOG_SPOT);
    let area_in_fog = fogged_box("area_light_in_fog", "");
    let absorbing = fogged_box_in("spot_in_absorbing_fog", FOG_SPOT, "1.5,0", false);
    for (scene, name) in [
        (&spot_outside, "a spot outside the fog"),
        (&area_in_fog, "an area light in fog"),
        (&absorbing, "a spot in fog of albedo 0"),
    ] {
        assert!(!scene.scene.has_delta_light_in_scattering_medium(), "{name}");
        assert_eq!(candidates(&gated, scene), vec![Method::Path, Method::Direct, Method::Ellipsoidal], "{name}");
        assert_eq!(candidates(&steady, scene), vec![Method::Path, Method::Direct], "{name}");
    }

    let ctx = common::gpu();
    let settings = RenderSettings { seed: 7, ..steady };
    let output =
        gatetrace::integrator::render(ctx, &spot_in_fog, &settings, gatetrace::integrator::Budget::Samples(2), |_| {})
            .unwrap();
    let choice = output.choice.unwrap();
    assert_eq!((choice.chosen, choice.pilot_seconds), (Method::Direct, 0.0), "{choice:?}");
    assert!(choice.reason.contains("infinite variance"), "{}", choice.reason);
    assert_eq!(output.film.spp, 2);
}

/// Forward-scattering fog for the medium connections' tests, and a spot light within the box
/// (a delta light, which only next-event estimation and medium connections reach).
const CONNECTED_FOG: &str = r#"<medium type="homogeneous" name="interior">
            <float name="sigma_t" value="3"/>
            <rgb name="albedo" value="0.8, 0.9, 0.7"/>
            <phase type="hg"><float name="g" value="0.5"/></phase>
        </medium>"#;
const FOG_SPOT: &str = r#"<emitter type="spot">
        <transform name="to_world"><lookat origin="-0.6, 0.6, 0.3" target="0.1, -0.2, 0" up="0, 1, 0"/></transform>
        <rgb name="intensity" value="0.8"/>
        <float name="cutoff_angle" value="30"/>
    </emitter>"#;

/// Medium connections change the sampling, not the estimate: the fog box's transient and a narrow
/// box gate agree with free flights alone, per bin and 4 x 4 block, with an area light and a spot
/// light; so do those of the Cornell box filled with fog around the camera, where flights end on
/// the walls.
#[test]
fn medium_connections_agree_with_free_flights_alone() {
    let ctx = common::gpu();
    let fog_box = fog_box("connected_fog", CONNECTED_FOG, &[], FOG_SPOT);
    let fogged_box = fogged_box("fogged_box", FOG_SPOT);
    for (scene, name, gate, spp) in [
        (&fog_box, "the fog box", "transient:1.94,0.1,12", 256),
        (&fog_box, "the fog box", "box:2.6..2.62", 512),
        (&fogged_box, "the fogged box", "transient:1.94,0.1,12", 256),
        (&fogged_box, "the fogged box", "box:3.3..3.32", 512),
    ] {
        let render = |medium_connections| {
            let settings = RenderSettings {
                width: 16,
                height: 16,
                max_bounces: 4,
                gate: Gate::parse(gate).unwrap(),
                seed: 5,
                medium_connections,
                ..Default::default()
            };
            common::render_films(ctx, scene, &settings, 8, spp)
        };
        let label = format!("medium connections in {name} on {gate}");
        common::assert_films_agree(&label, &render(true), &render(false), 4, 0.001);
    }
}

/// A grid holding half its majorant everywhere (`max_value` twice its values) is the
/// homogeneous medium of half the majorant: delta tracking then rejects half its tentative
/// collisions, and a path that passes them counts their stretches in its length, so the
/// transients agree bin by bin. (mitransient 1.3.1's `transient_prbvolpath` leaves those
/// stretches out of its path lengths.)
#[test]
fn null_collisions_count_in_the_path_length() {
    let homogeneous = r#"<medium type="homogeneous" name="interior">
            <float name="sigma_t" value="4"/>
            <rgb name="albedo" value="0.9"/>
        </medium>"#;
    let gridded = r#"<medium type="heterogeneous" name="interior">
            <volume type="gridvolume" name="sigma_t">
                <string name="filename" value="half.vol"/>
                <float name="max_value" value="1"/>
                <transform name="to_world"><translate value="-0.5, -0.5, -0.5"/><scale value="0.5"/>
                    <translate value="0.05, -0.2, 0.05"/></transform>
            </volume>
            <float name="scale" value="8"/>
            <rgb name="albedo" value="0.9"/>
        </medium>"#;
    let a = fog_box_transient("half_homogeneous", homogeneous, &[], 8);
    let b = fog_box_transient("half_grid", gridded, &[("half.vol", &[0.5; 8])], 8);
    common::assert_films_agree("homogeneous against a grid at half its majorant", &a, &b, 8, 0.001);
}

/// The fog box's heterogeneous medium (its extinction the grid `density.vol`, nearest voxels,
/// scale 8 m^-1) with albedo `albedo`: an XML element, an `<rgb>` or a `<volume>`.
fn fog_box_grid_medium(albedo: &str) -> String {
    let volume = |name: &str, file: &str| {
        format!(
            r#"<volume type="gridvolume" name="{name}">
                <string name="filename" value="{file}"/>
                <string name="filter_type" value="nearest"/>
                <transform name="to_world"><translate value="-0.5, -0.5, -0.5"/><scale value="0.5"/>
                    <translate value="0.05, -0.2, 0.05"/></transform>
            </volume>"#
        )
    };
    let albedo = match albedo.strip_suffix(".vol") {
        Some(_) => volume("albedo", albedo),
        None => format!(r#"<rgb name="albedo" value="{albedo}"/>"#),
    };
    format!(
        r#"<medium type="heterogeneous" name="interior">
            {}
            <float name="scale" value="8"/>
            {albedo}
        </medium>"#,
        volume("sigma_t", "density.vol")
    )
}

/// Extinction of the fog box's grid (shares of its largest, 8 m^-1), voxel by voxel (x fastest).
const FOG_BOX_DENSITY: [f32; 8] = [0.9, 0.3, 1.0, 0.5, 0.2, 0.8, 0.6, 0.4];

/// An albedo grid holding one value everywhere renders exactly as that albedo given once, a grey
/// one of one channel and a coloured one of three: the same random numbers make the same paths,
/// and each collision's albedo is looked up on the grid (after the extinction's values in
/// `medium_densities`, three values a voxel).
#[test]
fn an_albedo_grid_of_one_value_is_that_albedo() {
    let colour = [0.9f32, 0.6, 0.3];
    let cases: [(&str, Vec<f32>); 2] = [("0.7", vec![0.7; 8]), ("0.9, 0.6, 0.3", colour.repeat(8))];
    for (k, (albedo, grid_values)) in cases.iter().enumerate() {
        let one = fog_box_transient(
            &format!("albedo_constant_{k}"),
            &fog_box_grid_medium(albedo),
            &[("density.vol", &FOG_BOX_DENSITY)],
            8,
        );
        let grid = fog_box_transient(
            &format!("albedo_grid_{k}"),
            &fog_box_grid_medium("albedo.vol"),
            &[("density.vol", &FOG_BOX_DENSITY), ("albedo.vol", grid_values)],
            8,
        );
        let total = |films: &[gatetrace::film::Film], c: usize| {
            films.iter().flat_map(|f| f.data.iter().skip(c).step_by(3)).map(|&v| v as f64).sum::<f64>()
        };
        let totals = |films: &[gatetrace::film::Film]| [0, 1, 2].map(|c| total(films, c));
        println!("albedo {albedo}: one albedo {:?}, albedo grid {:?}", totals(&one), totals(&grid));
        assert!(total(&one, 0) > 0.0);
        for (a, b) in one.iter().zip(&grid) {
            assert!(a.data == b.data, "an albedo grid of {albedo} everywhere rendered another image than that albedo");
        }
    }
}

/// With one scattering vertex a path's weight is linear in the albedo where it scatters, and the
/// albedo steers no sampling: with the same seed the four renders trace the same paths, so the
/// images with the albedo grid 1 on the fog's x < 0.05 half (0 on the other) and on the other
/// half add up to those with albedo 1 and 0 everywhere, to rounding. And the light the two halves
/// scatter falls on different sides of the image.
#[test]
fn an_albedo_grid_weighs_each_collision_by_the_albedo_where_it_lies() {
    let left: Vec<f32> = (0..8).map(|i| if i % 2 == 0 { 1.0 } else { 0.0 }).collect();
    let right: Vec<f32> = left.iter().map(|a| 1.0 - a).collect();
    let render = |name: &str, albedo: &[f32]| {
        fog_box_transient(
            name,
            &fog_box_grid_medium("albedo.vol"),
            &[("density.vol", &FOG_BOX_DENSITY), ("albedo.vol", albedo)],
            1,
        )
    };
    let renders = [
        render("albedo_left", &left),
        render("albedo_right", &right),
        render("albedo_one", &[1.0; 8]),
        render("albedo_zero", &[0.0; 8]),
    ];
    // Per film: the radiance summed over bins and channels, in the image's left and right halves.
    let halves = |films: &[gatetrace::film::Film]| -> Vec<[f64; 2]> {
        films
            .iter()
            .map(|f| {
                let per_pixel = f.data.len() / 256;
                let mut sums = [0.0; 2];
                for (i, v) in f.data.iter().enumerate() {
                    let x = (i / per_pixel) % 16;
                    sums[(x >= 8) as usize] += *v as f64;
                }
                sums
            })
            .collect()
    };
    let h: Vec<Vec<[f64; 2]>> = renders.iter().map(|r| halves(r)).collect();
    let total = |k: usize| h[k].iter().map(|s| s[0] + s[1]).sum::<f64>();
    let difference = total(0) + total(1) - total(2) - total(3);
    println!("left + right - one - zero = {difference:.3e} (one: {:.6})", total(2));
    assert!(difference.abs() <= 1e-5 * total(2), "left + right - one - zero = {difference} (one: {})", total(2));
    // The light each half scatters: its image less the albedo-0 image, and its share on the
    // image's left.
    let side = |k: usize, s: usize| h[k].iter().zip(&h[3]).map(|(x, zero)| x[s] - zero[s]).sum::<f64>();
    let share = |k: usize| side(k, 0) / (side(k, 0) + side(k, 1));
    let scattered = side(2, 0) + side(2, 1);
    println!(
        "scattered light on the image's left: from x < 0.05 {:.3}, from x > 0.05 {:.3} (all scattered {scattered:.5})",
        share(0),
        share(1)
    );
    assert!(scattered > 0.0);
    assert!((share(0) - share(1)).abs() > 0.3, "both halves scatter light onto the same side of the image");
}

/// The kernels' placement of a medium connection's vertex (`spheroid_crossing`, probe_functions
/// 23) against its f64 oracle on the same f32 inputs: foci 1 cm to 100 m apart,
/// lengths from 1.001 to 11 times that distance, and directions over the sphere or within 0.1
/// rad of the one towards the light (where the spheroid grazes the ray and dtau/dt nears 0). No
/// output is NaN or infinite, and the 99th percentile of the relative errors of t and of dtau/dt
/// is at most 1e-5.
#[test]
fn medium_connection_placement_stays_accurate_in_f32() {
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let tracer = PathTracer::new(ctx, &scene, &RenderSettings { width: 8, height: 8, ..Default::default() }).unwrap();
    let mut rng = Rng::new(23, 0, 0);
    let mut u = move || rng.next_f32();
    let n = 30_000;
    let mut input = Vec::with_capacity(3 * n);
    for i in 0..n {
        let sphere = |a: f32, b: f32| {
            let z = 2.0 * a - 1.0;
            let s = (1.0 - z * z).max(0.0).sqrt();
            Vec3::new(s * (6.2831855 * b).cos(), s * (6.2831855 * b).sin(), z)
        };
        let o = (Vec3::new(u(), u(), u()) - 0.5) * 20.0;
        let d = 10f32.powf(-2.0 + 4.0 * u());
        let y = o + d * sphere(u(), u());
        let r = d * (1.0 + 10f32.powf(-3.0 + 4.0 * u()));
        let w = if i % 2 == 0 {
            sphere(u(), u())
        } else {
            // Within 0.1 rad of the direction towards y.
            let towards = (y - o).normalize();
            (towards + 10f32.powf(-3.0 + 2.0 * u()) * sphere(u(), u())).normalize()
        };
        input.extend([[o.x, o.y, o.z, r], [w.x, w.y, w.z, 0.0], [y.x, y.y, y.z, 0.0]]);
    }
    let out = common::run_probe(ctx, &tracer, "probe_functions", &[("FUNCTION", 23.0)], &input, n);
    let (mut t_errors, mut rate_errors) = (Vec::new(), Vec::new());
    for (i, g) in out.iter().enumerate() {
        let [a, w, y] = [input[3 * i], input[3 * i + 1], input[3 * i + 2]];
        let (o, w, y) = (Vec3::new(a[0], a[1], a[2]), Vec3::new(w[0], w[1], w[2]), Vec3::new(y[0], y[1], y[2]));
        let (t, rate) = gatetrace::scene::medium::medium_connection_oracle(o, w, y, a[3]).unwrap();
        assert!(g[0].is_finite() && g[1].is_finite(), "case {i}: t {} rate {}", g[0], g[1]);
        t_errors.push((g[0] as f64 - t).abs() / t);
        rate_errors.push((g[1] as f64 - rate).abs() / rate);
    }
    let mut p99s = vec![];
    for (what, errors) in [("t", &mut t_errors), ("dtau/dt", &mut rate_errors)] {
        errors.sort_by(f64::total_cmp);
        let p99 = errors[errors.len() * 99 / 100];
        println!(
            "{what}: relative error median {:.1e}, p99 {p99:.1e}, max {:.1e}",
            errors[errors.len() / 2],
            errors[errors.len() - 1]
        );
        p99s.push((what, p99));
    }
    for (what, p99) in p99s {
        assert!(p99 <= 1e-5, "{what}: p99 relative error {p99:.2e}");
    }
}
