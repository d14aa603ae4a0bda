//! Hostile input: every case must exit non-zero with an error that names the file or option and
//! the problem, must not panic, and must write no output file. Property tests feed mutated glTF
//! documents and gate specifications to the loaders and check that they never panic.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::gltf_builder::{Camera, Material, Mesh, PointLight, Scene, quad_z, write_json};
use serde_json::{Value, json};

/// The Cornell box's glTF document (one embedded buffer).
fn cornell_box_json() -> Value {
    serde_json::from_str(&std::fs::read_to_string(common::repo_path("assets/scenes/cornell_box.gltf")).unwrap())
        .unwrap()
}

/// A quad lit by an emissive quad behind the camera, with the given first-quad positions.
fn lit_scene(positions: Vec<[f32; 3]>) -> Scene {
    let n = positions.len() as u32;
    Scene {
        meshes: vec![
            Mesh { positions, normals: None, uvs: None, indices: (0..n).collect(), material: Some(0) },
            quad_z(1.0, 1.0, false, 1),
        ],
        materials: vec![Material::diffuse([0.5; 3]), Material::emitter(2.0)],
        camera: Some(Camera { position: [0.0, 0.0, 0.5], rotation: [0.0, 0.0, 0.0, 1.0], yfov: 0.5 }),
        point_lights: vec![],
    }
}

/// Writes a lit scene whose second vertex is `vertex`, with finite POSITION bounds (as a broken
/// exporter might write them), so that only the vertex data is wrong.
fn write_with_bounds(dir: &Path, name: &str, vertex: [f32; 3]) {
    let mut doc = lit_scene(vec![[-1.0, -1.0, -1.0], vertex, [0.0, 1.0, -1.0]]).to_json();
    doc["accessors"][0]["min"] = json!([-1.0, -1.0, -1.0]);
    doc["accessors"][0]["max"] = json!([1.0, 1.0, -1.0]);
    write_json(dir, name, &doc);
}

/// A GLB container holding `doc` as its JSON chunk (buffers keep their data URIs).
fn glb(doc: &Value) -> Vec<u8> {
    let mut json = serde_json::to_vec(doc).unwrap();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len();
    let mut out = Vec::new();
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out
}

/// One hostile input: the command's arguments (`{dir}` is the case's directory, `{out}` the
/// output it must not write) and what the error must say.
struct Case {
    name: &'static str,
    args: Vec<String>,
    needles: Vec<String>,
}

/// Builds a case whose files are written by `setup` into its directory.
fn case(name: &'static str, setup: impl FnOnce(&Path) + 'static, args: Vec<String>, needles: &[&str]) -> (Case, Setup) {
    let c = Case { name, args, needles: needles.iter().map(|s| s.to_string()).collect() };
    let setup: Box<dyn FnOnce(&Path)> = Box::new(setup);
    (c, setup)
}

fn none(_: &Path) {}

/// Renders the Cornell box (8x8, 4 spp, 2 bounces, `extra` options) to `dir/out.npy` with a
/// checkpoint beside it.
fn checkpointed(dir: &Path, extra: &[&str]) {
    let out = dir.join("out.npy");
    let o = Command::new(env!("CARGO_BIN_EXE_gatetrace"))
        .args(["render", "--res", "8x8", "--spp", "4", "--max-bounces", "2", "--checkpoint-every", "0", "--out"])
        .arg(&out)
        .args(extra)
        .output()
        .unwrap();
    assert!(o.status.success() && dir.join("out.npy.checkpoint").exists(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// Renders shards `indices` of 4 of the Cornell box (8x8, 8 spp, `extra` options) to
/// `dir/I.shard`.
fn shards(dir: &Path, indices: &[u32], extra: &[&str]) {
    for i in indices {
        let o = Command::new(env!("CARGO_BIN_EXE_gatetrace"))
            .args(["render", "--res", "8x8", "--spp", "8", "--max-bounces", "2", "--shard", &format!("{i}/4"), "--out"])
            .arg(dir.join(format!("{i}.shard")))
            .args(extra)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
}

/// Writes the Cornell box changed by `edit` as `name`.
fn box_with(name: &'static str, edit: impl FnOnce(&mut Value) + 'static) -> impl FnOnce(&Path) {
    move |dir: &Path| {
        let mut doc = cornell_box_json();
        edit(&mut doc);
        write_json(dir, name, &doc);
    }
}

/// Gives material `material` of `doc` the glTF extension `extension` (with `value`) and lists
/// it in `extensionsUsed`.
fn add_material_extension(doc: &mut Value, material: usize, extension: &str, value: Value) {
    doc["materials"][material]["extensions"][extension] = value;
    doc["extensionsUsed"].as_array_mut().unwrap().push(json!(extension));
}

/// A small Wavefront OBJ quad, as Blender writes one.
const OBJ_QUAD: &str = "# Blender 4.2\nmtllib plane.mtl\no Plane\nv -1 0 1\nv 1 0 1\nv -1 0 -1\nv 1 0 -1\n\
                        vn 0 1 0\nusemtl Material\ns 0\nf 1//1 2//1 4//1 3//1\n";

/// A small Mitsuba 3 scene whose mesh file is missing.
const MITSUBA_XML: &str = "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<scene version=\"3.0.0\">\n  \
                           <integrator type=\"path\"/>\n  <shape type=\"obj\">\n    \
                           <string name=\"filename\" value=\"plane.obj\"/>\n  </shape>\n</scene>\n";

/// What a case writes into its directory before the command runs.
type Setup = Box<dyn FnOnce(&Path)>;

/// A Mitsuba serialized file of two shapes (tools/scenes/make_mitsuba_scene.py).
const SERIALIZED: &[u8] = include_bytes!("../assets/scenes/mitsuba_box/shapes.serialized");

/// A Mitsuba 3 scene with a camera and a lit rectangle (lines 1 to 4), then `body` from line 5.
fn xml_with(body: &str) -> String {
    format!(
        "<?xml version=\"1.0\"?>\n<scene version=\"3.0.0\">\n<sensor type=\"perspective\"><float name=\"fov\" \
         value=\"40\"/><transform name=\"to_world\"><lookat origin=\"0, 0, 2\" target=\"0, 0, 0\" up=\"0, 1, 0\"/>\
         </transform></sensor>\n<shape type=\"rectangle\"><emitter type=\"area\"><rgb name=\"radiance\" \
         value=\"1\"/></emitter></shape>\n{body}\n</scene>\n"
    )
}

/// A case rendering `xml_with(body)` as scene.xml (with `files`: name and content of each
/// file written beside it).
fn xml_case(
    name: &'static str,
    body: &'static str,
    files: &'static [(&str, &[u8])],
    needles: &[&str],
) -> (Case, Setup) {
    let args = ["render", "{dir}/scene.xml", "--res", "8x8", "--spp", "1", "--out", "{out}"];
    case(
        name,
        move |d| {
            std::fs::write(d.join("scene.xml"), xml_with(body)).unwrap();
            for (file, content) in files {
                std::fs::write(d.join(file), content).unwrap();
            }
        },
        args.iter().map(|s| s.to_string()).collect(),
        needles,
    )
}

/// A Mitsuba 3 NLOS capture: the integrator (line 3), a projector laser (line 4), the relay wall
/// carrying its capture meter (line 5) and a hidden panel (line 6).
const CAPTURE_XML: &str = "<?xml version=\"1.0\"?>\n<scene version=\"3.0.0\">\n<integrator \
     type=\"transient_nlos_path\"><boolean name=\"nlos_laser_sampling\" value=\"true\"/></integrator>\n<emitter type=\"projector\"/>\n<shape type=\"rectangle\" id=\"wall\"><sensor \
     type=\"nlos_capture_meter\"><point name=\"sensor_origin\" value=\"0, 0, 1\"/><point name=\"laser_origin\" \
     value=\"0, 0, 1\"/><point name=\"laser_lookat_pixel\" value=\"4, 4, 0\"/><film type=\"transient_hdr_film\">\
     <integer name=\"width\" value=\"8\"/><integer name=\"height\" value=\"8\"/><integer name=\"temporal_bins\" \
     value=\"10\"/><float name=\"start_opl\" value=\"1\"/><float name=\"bin_width_opl\" value=\"0.1\"/></film>\
     </sensor></shape>\n<shape type=\"rectangle\"><transform name=\"to_world\"><rotate y=\"1\" angle=\"180\"/>\
     <translate z=\"1\"/></transform></shape>\n</scene>\n";

/// A case rendering [`CAPTURE_XML`] with each (from, to) of `edits` replaced, as scene.xml.
fn capture_case(name: &'static str, edits: &'static [(&str, &str)], needles: &[&str]) -> (Case, Setup) {
    let args = ["render", "{dir}/scene.xml", "--spp", "1", "--out", "{out}"];
    case(
        name,
        move |d| {
            let mut xml = CAPTURE_XML.to_owned();
            for (from, to) in edits {
                assert!(xml.contains(from), "{name}: `{from}` is not in the capture scene");
                xml = xml.replace(from, to);
            }
            std::fs::write(d.join("scene.xml"), xml).unwrap();
        },
        args.iter().map(|s| s.to_string()).collect(),
        needles,
    )
}

fn cases() -> Vec<(Case, Setup)> {
    // `render SCENE` of a tiny image with `extra` options, writing {out}.
    let render = |scene: &str, extra: &[&str]| -> Vec<String> {
        let tiny = ["--res", "8x8", "--spp", "1", "--max-bounces", "2"];
        let tail = ["--out", "{out}"];
        std::iter::once("render")
            .chain([scene])
            .chain(tiny)
            .chain(extra.iter().copied())
            .chain(tail)
            .map(String::from)
            .collect()
    };
    // `render` of the default scene with `extra` options, writing {out}.
    let default_scene = |extra: &[&str]| -> Vec<String> {
        std::iter::once("render").chain(extra.iter().copied()).chain(["--out", "{out}"]).map(String::from).collect()
    };
    let plain = |args: &[&str]| -> Vec<String> { args.iter().map(|s| s.to_string()).collect() };
    vec![
        // --- files that are not glTF ---
        case(
            "empty file",
            |d| std::fs::write(d.join("empty.gltf"), b"").unwrap(),
            render("{dir}/empty.gltf", &[]),
            &["empty.gltf", "not a valid glTF"],
        ),
        case(
            "malformed JSON",
            |d| std::fs::write(d.join("bad.gltf"), b"{\"asset\": {\"version\": \"2.0\"},").unwrap(),
            render("{dir}/bad.gltf", &[]),
            &["bad.gltf", "not a valid glTF"],
        ),
        case(
            "truncated glTF",
            |d| {
                let text = std::fs::read(common::repo_path("assets/scenes/cornell_box.gltf")).unwrap();
                std::fs::write(d.join("half.gltf"), &text[..text.len() / 2]).unwrap();
            },
            render("{dir}/half.gltf", &[]),
            &["half.gltf", "not a valid glTF"],
        ),
        case(
            "truncated GLB",
            |d| {
                let bytes = glb(&cornell_box_json());
                std::fs::write(d.join("half.glb"), &bytes[..bytes.len() / 2]).unwrap();
            },
            render("{dir}/half.glb", &[]),
            &["half.glb", "not a valid glTF"],
        ),
        case("missing scene file", none, render("{dir}/nowhere.gltf", &[]), &["nowhere.gltf", "cannot read"]),
        // --- scenes in other formats: what the file is, what gatetrace reads, how to convert ---
        case(
            "OBJ mesh",
            |d| std::fs::write(d.join("plane.obj"), OBJ_QUAD).unwrap(),
            render("{dir}/plane.obj", &[]),
            &[
                "plane.obj",
                "Wavefront OBJ",
                "glTF 2.0 scenes (.gltf or .glb) and Mitsuba 3 XML scenes",
                "File > Export > glTF 2.0",
                "<shape type=\"obj\">",
            ],
        ),
        case(
            "Mitsuba XML scene whose mesh is missing",
            |d| std::fs::write(d.join("scene.xml"), MITSUBA_XML).unwrap(),
            render("{dir}/scene.xml", &[]),
            &["scene.xml:4: <shape type=\"obj\">", "plane.obj: cannot read the mesh"],
        ),
        case(
            "Mitsuba XML named .gltf",
            |d| std::fs::write(d.join("misnamed.gltf"), MITSUBA_XML).unwrap(),
            render("{dir}/misnamed.gltf", &[]),
            &["misnamed.gltf:4", "plane.obj"],
        ),
        // --- Mitsuba XML: malformed, or outside the subset gatetrace renders (file:line: <element>) ---
        xml_case("XML not well-formed", "<shape type=\"cube\">", &[], &["scene.xml", "not well-formed XML"]),
        case(
            "XML whose root is not <scene>",
            |d| std::fs::write(d.join("scene.xml"), "<root>\n<scene/>\n</root>\n").unwrap(),
            render("{dir}/scene.xml", &[]),
            &["scene.xml:1: <root>", "not <scene>"],
        ),
        xml_case(
            "XML parameter without a default",
            "<shape type=\"sphere\"><float name=\"radius\" value=\"$r\"/></shape>",
            &[],
            &["scene.xml:5: <float name=\"radius\">", "$r", "<default name=\"r\""],
        ),
        xml_case("XML unknown shape", "<shape type=\"teapot\"/>", &[], &["scene.xml:5", "the shape `teapot`"]),
        xml_case(
            "XML thin dielectric with a texture",
            "<shape type=\"cube\"><bsdf type=\"thindielectric\"><texture type=\"checkerboard\" \
             name=\"specular_transmittance\"/></bsdf></shape>",
            &[],
            &["scene.xml:5: <texture type=\"checkerboard\" name=\"specular_transmittance\">", "a dielectric's textures are not read"],
        ),
        xml_case(
            "XML rough dielectric of anisotropic roughness",
            "<bsdf type=\"roughdielectric\" id=\"p\"><float name=\"alpha_u\" value=\"0.1\"/>\
             <float name=\"alpha_v\" value=\"0.3\"/></bsdf><shape type=\"cube\"><ref id=\"p\"/></shape>",
            &[],
            &["<bsdf type=\"roughdielectric\" id=\"p\">", "anisotropic roughness (alpha_u, alpha_v) is not rendered"],
        ),
        case(
            "XML rough glass rendered by ellipsoidal connections",
            |d| {
                let glass = "<shape type=\"sphere\"><bsdf type=\"roughdielectric\"/></shape>";
                std::fs::write(d.join("scene.xml"), xml_with(glass)).unwrap()
            },
            render("{dir}/scene.xml", &["--method", "ellipsoidal", "--gate", "box:2..2.1"]),
            &["dielectric (glass)", "`ellipsoidal` alone would leave them out", "--method combined"],
        ),
        case(
            "XML glass rendered by ellipsoidal connections",
            |d| {
                let glass = "<shape type=\"sphere\"><bsdf type=\"dielectric\"/></shape>";
                std::fs::write(d.join("scene.xml"), xml_with(glass)).unwrap()
            },
            render("{dir}/scene.xml", &["--method", "ellipsoidal", "--gate", "box:2..2.1"]),
            &["dielectric (glass)", "`ellipsoidal` alone would leave them out", "--method combined"],
        ),
        xml_case(
            "XML dielectric whose indices are equal",
            "<shape type=\"cube\"><bsdf type=\"dielectric\"><float name=\"int_ior\" value=\"1.3\"/>\
             <float name=\"ext_ior\" value=\"1.3\"/></bsdf></shape>",
            &[],
            &["scene.xml:5: <bsdf type=\"dielectric\">", "int_ior and ext_ior are both 1.3"],
        ),
        xml_case(
            "XML plastic of an unknown named index",
            "<shape type=\"cube\"><bsdf type=\"plastic\"><string name=\"int_ior\" value=\"unobtainium\"/></bsdf></shape>",
            &[],
            &["scene.xml:5: <bsdf type=\"plastic\">", "`unobtainium` (int_ior) is not a known material", "bk7"],
        ),
        xml_case(
            "XML plastic whose coat does not refract",
            "<shape type=\"cube\"><bsdf type=\"roughplastic\"><float name=\"int_ior\" value=\"1.2\"/>\
             <float name=\"ext_ior\" value=\"1.2\"/></bsdf></shape>",
            &[],
            &["scene.xml:5: <bsdf type=\"roughplastic\">", "int_ior and ext_ior are both 1.2"],
        ),
        xml_case(
            "XML plastic of an index below 1",
            "<shape type=\"cube\"><bsdf type=\"plastic\"><float name=\"int_ior\" value=\"0.5\"/></bsdf></shape>",
            &[],
            &["scene.xml:5: <bsdf type=\"plastic\">", "int_ior 0.5 is not an index of refraction in [1, 10]"],
        ),
        xml_case(
            "XML plastic with a coloured specular reflectance",
            "<shape type=\"cube\"><bsdf type=\"roughplastic\">\
             <rgb name=\"specular_reflectance\" value=\"1, 0.5, 0.5\"/></bsdf></shape>",
            &[],
            &["scene.xml:5: <bsdf type=\"roughplastic\">", "a coloured specular_reflectance"],
        ),
        xml_case(
            "XML plastic with a texture under another name",
            "<shape type=\"cube\"><bsdf type=\"roughplastic\"><texture type=\"checkerboard\" name=\"reflectance\"/>\
             </bsdf></shape>",
            &[],
            &["scene.xml:5: <texture type=\"checkerboard\" name=\"reflectance\">", "takes one texture, named `diffuse_reflectance`"],
        ),
        xml_case(
            "XML property gatetrace does not read",
            "<shape type=\"cube\"><bsdf type=\"diffuse\"><float name=\"sheen\" value=\"1\"/></bsdf></shape>",
            &[],
            &["scene.xml:5: <float name=\"sheen\">", "not read by gatetrace's <bsdf type=\"diffuse\">"],
        ),
        xml_case(
            "XML reference to a missing id",
            "<shape type=\"cube\"><ref id=\"nowhere\"/></shape>",
            &[],
            &["scene.xml:5: <ref id=\"nowhere\">", "no object has the id `nowhere`"],
        ),
        xml_case(
            "XML reference to an object of another kind",
            "<shape type=\"cube\" id=\"c\"/><shape type=\"cube\"><ref id=\"c\"/></shape>",
            &[],
            &["`c` is a <shape>, where a <bsdf> is needed"],
        ),
        xml_case(
            "XML id given twice",
            "<bsdf type=\"diffuse\" id=\"a\"/>\n<bsdf type=\"diffuse\" id=\"a\"/>",
            &[],
            &["scene.xml:6", "the id `a` is given twice (first at line 5)"],
        ),
        xml_case(
            "XML OBJ face naming a missing vertex",
            "<shape type=\"obj\"><string name=\"filename\" value=\"bad.obj\"/></shape>",
            &[("bad.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n")],
            &["scene.xml:5: <shape type=\"obj\">", "bad.obj"],
        ),
        xml_case(
            "XML PLY without faces",
            "<shape type=\"ply\"><string name=\"filename\" value=\"points.ply\"/></shape>",
            &[("points.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n")],
            &["scene.xml:5", "points.ply: the PLY file has no `face` element"],
        ),
        xml_case(
            "XML PLY that is not PLY",
            "<shape type=\"ply\"><string name=\"filename\" value=\"junk.ply\"/></shape>",
            &[("junk.ply", b"\x00\x01 not a mesh")],
            &["scene.xml:5", "junk.ply: not a readable PLY mesh"],
        ),
        xml_case(
            "XML PLY face out of range",
            "<shape type=\"ply\"><string name=\"filename\" value=\"tri.ply\"/></shape>",
            &[("tri.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n")],
            &["tri.ply: face 0 names vertex 7, out of range (3 vertices)"],
        ),
        xml_case(
            "XML serialized mesh that is not one",
            "<shape type=\"serialized\"><string name=\"filename\" value=\"junk.serialized\"/></shape>",
            &[("junk.serialized", b"\x1c\x04\x04\x00 not zlib at all, and no offsets")],
            &["scene.xml:5", "junk.serialized: not a readable Mitsuba serialized mesh"],
        ),
        xml_case(
            "XML serialized shape index beyond the file",
            "<shape type=\"serialized\"><string name=\"filename\" value=\"shapes.serialized\"/>\
             <integer name=\"shape_index\" value=\"7\"/></shape>",
            &[("shapes.serialized", SERIALIZED)],
            &["shapes.serialized: shape_index 7: the file holds 2 shape(s)"],
        ),
        case(
            "XML bitmap claiming 100,000 x 100,000 texels",
            |d| {
                // A PNG of a huge header and almost no data: the size is read before any texel.
                let chunk = |kind: &[u8], data: &[u8]| {
                    let mut crc = flate2::Crc::new();
                    crc.update(kind);
                    crc.update(data);
                    [&(data.len() as u32).to_be_bytes()[..], kind, data, &crc.sum().to_be_bytes()].concat()
                };
                let ihdr = [&100_000u32.to_be_bytes()[..], &100_000u32.to_be_bytes(), &[8, 2, 0, 0, 0]].concat();
                let png = [
                    &b"\x89PNG\r\n\x1a\n"[..],
                    &chunk(b"IHDR", &ihdr),
                    &chunk(b"IDAT", &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01]),
                    &chunk(b"IEND", &[]),
                ]
                .concat();
                std::fs::write(d.join("huge.png"), png).unwrap();
                let body = "<shape type=\"cube\"><bsdf type=\"diffuse\"><texture type=\"bitmap\" name=\"reflectance\">\
                            <string name=\"filename\" value=\"huge.png\"/></texture></bsdf></shape>";
                std::fs::write(d.join("scene.xml"), xml_with(body)).unwrap();
            },
            render("{dir}/scene.xml", &[]),
            &["huge.png: a 100000 x 100000 image is larger than the 67108864 texels a texture may hold"],
        ),
        xml_case("XML include of a missing file", "<include filename=\"gone.xml\"/>", &[], &["scene.xml:5: <include>", "gone.xml: cannot read"]),
        case(
            "XML nested a hundred thousand levels deep",
            |d| {
                let xml = format!("<scene version=\"3.0.0\">{}{}</scene>", "<shape>".repeat(100_000), "</shape>".repeat(100_000));
                std::fs::write(d.join("scene.xml"), xml).unwrap()
            },
            render("{dir}/scene.xml", &[]),
            &["scene.xml:1", "elements nest deeper than 64 levels"],
        ),
        xml_case("XML include of itself", "<include filename=\"scene.xml\"/>", &[], &["includes nest deeper than 16 files"]),
        xml_case(
            "XML unknown transform operation",
            "<shape type=\"cube\"><transform name=\"to_world\"><shear value=\"1\"/></transform></shape>",
            &[],
            &["scene.xml:5: <shear>", "not a transform operation"],
        ),
        xml_case(
            "XML rotation about a zero axis",
            "<shape type=\"cube\"><transform name=\"to_world\"><rotate angle=\"30\"/></transform></shape>",
            &[],
            &["<rotate>", "the rotation axis is zero"],
        ),
        xml_case(
            "XML colour of two numbers",
            "<shape type=\"cube\"><bsdf type=\"diffuse\"><rgb name=\"reflectance\" value=\"0.1, 0.2\"/></bsdf></shape>",
            &[],
            &["<rgb name=\"reflectance\">", "needs 3 numbers"],
        ),
        xml_case(
            "XML sampled spectrum",
            "<shape type=\"cube\"><bsdf type=\"diffuse\"><spectrum name=\"reflectance\" value=\"400:0.1, 700:0.5\"/></bsdf></shape>",
            &[],
            &["<spectrum name=\"reflectance\">", "spectra sampled at wavelengths are not read"],
        ),
        xml_case(
            "XML number that is not one",
            "<shape type=\"sphere\"><float name=\"radius\" value=\"big\"/></shape>",
            &[],
            &["scene.xml:5: <float name=\"radius\">", "`big` is not a finite number"],
        ),
        xml_case(
            "XML reflectance above one",
            "<shape type=\"cube\"><bsdf type=\"diffuse\"><rgb name=\"reflectance\" value=\"2\"/></bsdf></shape>",
            &[],
            &["<bsdf type=\"diffuse\">", "outside [0, 1]"],
        ),
        case(
            "XML without a sensor",
            |d| std::fs::write(d.join("scene.xml"), "<scene version=\"3.0.0\"><shape type=\"cube\"/></scene>").unwrap(),
            render("{dir}/scene.xml", &[]),
            &["scene.xml: no <sensor>"],
        ),
        xml_case(
            "XML spot light wider than a hemisphere",
            "<emitter type=\"spot\"><float name=\"cutoff_angle\" value=\"120\"/></emitter>",
            &[],
            &["scene.xml:5: <emitter type=\"spot\">", "cutoff_angle 120", "<= 90"],
        ),
        xml_case(
            "XML projector in a camera scene",
            "<emitter type=\"projector\"/>",
            &[],
            &["scene.xml:5: <emitter type=\"projector\">", "light NLOS captures only"],
        ),
        xml_case("XML area emitter outside a shape", "<emitter type=\"area\"/>", &[], &["belongs inside a <shape>"]),
        xml_case(
            "XML NLOS integrator keeping one depth",
            "<integrator type=\"transient_nlos_path\"><integer name=\"filter_depth\" value=\"3\"/></integrator>",
            &[],
            &["scene.xml:5: <integrator type=\"transient_nlos_path\">", "`filter_depth` 3 keeps the paths of one depth"],
        ),
        capture_case(
            "XML capture without laser sampling",
            &[("<boolean name=\"nlos_laser_sampling\" value=\"true\"/>", "")],
            &["scene.xml:3: <integrator type=\"transient_nlos_path\">", "nlos_laser_sampling must be true"],
        ),
        xml_case(
            "XML NLOS integrator in a camera scene",
            "<integrator type=\"transient_nlos_path\"><boolean name=\"nlos_laser_sampling\" value=\"true\"/></integrator>",
            &[],
            &["scene.xml: transient_nlos_path renders NLOS captures", "render a camera image with transient_path"],
        ),
        capture_case(
            "XML capture meter on a cube",
            &[("<shape type=\"rectangle\" id=\"wall\">", "<shape type=\"cube\" id=\"wall\">")],
            &["scene.xml:5: <sensor type=\"nlos_capture_meter\">", "the relay wall must be a `rectangle`"],
        ),
        capture_case(
            "XML capture meter outside a shape",
            &[("<shape type=\"rectangle\" id=\"wall\"><sensor", "<sensor"), ("</sensor></shape>", "</sensor>")],
            &["scene.xml:5: <sensor type=\"nlos_capture_meter\">", "belongs inside its relay wall's <shape>"],
        ),
        capture_case(
            "XML capture without a laser",
            &[("<emitter type=\"projector\"/>", "")],
            &["scene.xml:5: <sensor type=\"nlos_capture_meter\">", "lit by one projector emitter", "has 0"],
        ),
        capture_case(
            "XML capture with two lasers",
            &[("<emitter type=\"projector\"/>", "<emitter type=\"projector\"/><emitter type=\"projector\"/>")],
            &["lit by one projector emitter", "has 2"],
        ),
        capture_case(
            "XML capture with a camera integrator",
            &[(
                "<integrator type=\"transient_nlos_path\"><boolean name=\"nlos_laser_sampling\" value=\"true\"/></integrator>",
                "<integrator type=\"transient_path\"/>",
            )],
            &["scene.xml:5:", "rendered with the integrator transient_nlos_path"],
        ),
        capture_case(
            "XML laser aimed off the film",
            &[("value=\"4, 4, 0\"", "value=\"12, 4, 0\"")],
            &["laser_lookat_pixel (12, 4) lies outside the 8 x 8 film"],
        ),
        capture_case(
            "XML laser missing the relay wall",
            &[("<point name=\"laser_lookat_pixel\" value=\"4, 4, 0\"/>", "")],
            &["scene.xml:4: <emitter type=\"projector\">", "misses the relay wall `wall`"],
        ),
        capture_case(
            "XML exhaustive capture without its film's laser grid",
            &[("<boolean name=\"nlos_laser_sampling\" value=\"true\"/>", "<boolean name=\"nlos_laser_sampling\" \
               value=\"true\"/><integer name=\"capture_type\" value=\"3\"/>")],
            &["scene.xml:5:", "needs exhaustive_scan true with laser_scan_width and _height"],
        ),
        capture_case(
            "XML exhaustive capture with laser spots of their own",
            &[
                ("<boolean name=\"nlos_laser_sampling\" value=\"true\"/>", "<boolean name=\"nlos_laser_sampling\" \
                  value=\"true\"/><integer name=\"capture_type\" value=\"3\"/><boolean \
                  name=\"force_equal_illumination_scanning\" value=\"false\"/>"),
            ],
            &["scene.xml:3:", "force_equal_illumination_scanning false"],
        ),
        capture_case(
            "XML exhaustive capture of another laser grid",
            &[
                ("<boolean name=\"nlos_laser_sampling\" value=\"true\"/>", "<boolean name=\"nlos_laser_sampling\" \
                  value=\"true\"/><integer name=\"capture_type\" value=\"3\"/>"),
                ("<integer name=\"width\" value=\"8\"/>", "<boolean name=\"exhaustive_scan\" value=\"true\"/><integer \
                  name=\"laser_scan_width\" value=\"4\"/><integer name=\"laser_scan_height\" value=\"4\"/><integer \
                  name=\"width\" value=\"8\"/>"),
            ],
            &["laser grid (4 x 4) must be its grid of sensed points (8 x 8)"],
        ),
        capture_case(
            "XML capture whose scan is said twice",
            &[
                ("<boolean name=\"nlos_laser_sampling\" value=\"true\"/>", "<boolean name=\"nlos_laser_sampling\" \
                  value=\"true\"/><string name=\"capture_type\" value=\"single\"/>"),
                ("<point name=\"sensor_origin\"", "<boolean name=\"confocal\" value=\"true\"/><point name=\"sensor_origin\""),
            ],
            &["scene.xml:3:", "capture_type says single but the capture meter's confocal is true"],
        ),
        capture_case(
            "XML laser aimed at two places",
            &[("<point name=\"laser_origin\"", "<point name=\"laser_lookat_3d\" value=\"0, 0, 0\"/><point name=\"laser_origin\"")],
            &["give laser_lookat_pixel or laser_lookat_3d, not both"],
        ),
        capture_case(
            "XML capture meter with two films' grid",
            &[("<point name=\"sensor_origin\"", "<integer name=\"original_film_width\" value=\"16\"/><point name=\"sensor_origin\"")],
            &["give both original_film_width and original_film_height"],
        ),
        capture_case(
            "XML projector of no light",
            &[("<emitter type=\"projector\"/>", "<emitter type=\"projector\"><rgb name=\"irradiance\" value=\"0\"/></emitter>")],
            &["scene.xml:4: <emitter type=\"projector\">", "must be non-negative and not zero"],
        ),

        xml_case(
            "XML integrator of another kind",
            "<integrator type=\"bdpt\"/>",
            &[],
            &["scene.xml:5: <integrator type=\"bdpt\">", "the integrator `bdpt` is not read"],
        ),
        xml_case(
            "XML camera unwarp",
            "<integrator type=\"transient_path\"><boolean name=\"camera_unwarp\" value=\"true\"/></integrator>",
            &[],
            &["`camera_unwarp` true is not rendered"],
        ),
        xml_case(
            "XML texture of an unknown kind",
            "<shape type=\"cube\"><bsdf type=\"diffuse\"><texture type=\"gradient\" name=\"reflectance\"/></bsdf></shape>",
            &[],
            &["<texture type=\"gradient\" name=\"reflectance\">", "the texture `gradient` is not read"],
        ),
        xml_case(
            "XML bitmap that is not an image",
            "<shape type=\"cube\"><bsdf type=\"diffuse\"><texture type=\"bitmap\" name=\"reflectance\">\
             <string name=\"filename\" value=\"wood.png\"/></texture></bsdf></shape>",
            &[("wood.png", b"not a png")],
            &["scene.xml:5: <texture type=\"bitmap\" name=\"reflectance\">", "wood.png: cannot decode the image"],
        ),
        xml_case(
            "XML emitter on a two-sided shape",
            "<shape type=\"cube\"><bsdf type=\"twosided\"><bsdf type=\"diffuse\"/></bsdf><emitter type=\"area\"/></shape>",
            &[],
            &["<emitter type=\"area\">", "twosided BSDF"],
        ),
        xml_case(
            "XML conductor of an unknown material",
            "<shape type=\"cube\"><bsdf type=\"conductor\"><string name=\"material\" value=\"Unobtainium\"/></bsdf></shape>",
            &[],
            &["the conductor `Unobtainium` is not known", "Au, Be"],
        ),
        xml_case(
            "XML conductor of a negative index",
            "<shape type=\"cube\"><bsdf type=\"conductor\"><rgb name=\"eta\" value=\"0.2, -1, 1\"/></bsdf></shape>",
            &[],
            &["scene.xml:5: <bsdf type=\"conductor\">", "must not be negative"],
        ),
        case(
            "Mitsuba parameter without a value",
            none,
            plain(&["render", "-D", "spp", "--out", "{out}"]),
            &["`spp` is not NAME=VALUE"],
        ),
        case(
            "Mitsuba parameter for a glTF scene",
            none,
            plain(&["render", "--res", "8x8", "-D", "spp=4", "--out", "{out}"]),
            &["cornell_box.gltf", "parameters (here `spp`) apply to Mitsuba XML scenes"],
        ),
        xml_case(
            "XML medium of an unknown kind",
            "<shape type=\"cube\"><bsdf type=\"null\"/><medium type=\"fog\" name=\"interior\"/></shape>",
            &[],
            &["scene.xml:5: <medium type=\"fog\" name=\"interior\">", "the medium `fog` is not rendered"],
        ),
        xml_case(
            "XML medium of coloured extinction",
            "<shape type=\"cube\"><bsdf type=\"null\"/><medium type=\"homogeneous\" name=\"interior\">\
             <rgb name=\"sigma_t\" value=\"1, 2, 3\"/></medium></shape>",
            &[],
            &["<medium type=\"homogeneous\" name=\"interior\">", "sigma_t differs between channels"],
        ),
        xml_case(
            "XML emitter on a null surface",
            "<shape type=\"cube\"><bsdf type=\"null\"/><emitter type=\"area\"/></shape>",
            &[],
            &["<bsdf type=\"null\">", "area emitter on a `null` surface"],
        ),
        case(
            "fog of no extinction",
            none,
            plain(&["render", "--res", "8x8", "--spp", "1", "--fog", "0,0.9", "--out", "{out}"]),
            &["--fog", "the extinction 0 m^-1 is not positive"],
        ),
        case(
            "fog around glass that declares no media",
            |d| {
                let body = "<shape type=\"sphere\" id=\"ball\"><bsdf type=\"dielectric\"/></shape>";
                std::fs::write(d.join("scene.xml"), xml_with(body)).unwrap();
            },
            plain(&["render", "{dir}/scene.xml", "--res", "8x8", "--spp", "1", "--fog", "0.5", "--out", "{out}"]),
            &["scene.xml", "the glass `", "declares no media", "`interior` and `exterior`"],
        ),
        case(
            "XML heterogeneous medium whose grid file is cut short",
            |d| {
                gatetrace::scene::medium::write_vol(&d.join("smoke.vol"), [2, 2, 2], &[0.5; 8]).unwrap();
                let bytes = std::fs::read(d.join("smoke.vol")).unwrap();
                std::fs::write(d.join("smoke.vol"), &bytes[..bytes.len() - 4]).unwrap();
                let body = "<shape type=\"cube\"><bsdf type=\"null\"/><medium type=\"heterogeneous\" name=\"interior\">\
                            <volume type=\"gridvolume\" name=\"sigma_t\"><string name=\"filename\" value=\"smoke.vol\"/>\
                            </volume></medium></shape>";
                std::fs::write(d.join("scene.xml"), xml_with(body)).unwrap();
            },
            render("{dir}/scene.xml", &[]),
            &["scene.xml:", "<volume type=\"gridvolume\" name=\"sigma_t\">", "smoke.vol", "bytes where a 2 x 2 x 2 grid"],
        ),
        case(
            "XML extinction grid of three channels",
            |d| {
                gatetrace::scene::medium::write_vol(&d.join("smoke.vol"), [2, 2, 2], &[0.5; 24]).unwrap();
                let body = "<shape type=\"cube\"><bsdf type=\"null\"/><medium type=\"heterogeneous\" name=\"interior\">\
                            <volume type=\"gridvolume\" name=\"sigma_t\"><string name=\"filename\" value=\"smoke.vol\"/>\
                            </volume></medium></shape>";
                std::fs::write(d.join("scene.xml"), xml_with(body)).unwrap();
            },
            render("{dir}/scene.xml", &[]),
            &["scene.xml:", "<medium type=\"heterogeneous\" name=\"interior\">", "the sigma_t grid has 3 channels"],
        ),
        case(
            "XML albedo grid over a constant extinction",
            |d| {
                gatetrace::scene::medium::write_vol(&d.join("albedo.vol"), [2, 2, 2], &[0.5; 8]).unwrap();
                let body = "<shape type=\"cube\"><bsdf type=\"null\"/><medium type=\"heterogeneous\" name=\"interior\">\
                            <float name=\"sigma_t\" value=\"2\"/>\
                            <volume type=\"gridvolume\" name=\"albedo\"><string name=\"filename\" value=\"albedo.vol\"/>\
                            </volume></medium></shape>";
                std::fs::write(d.join("scene.xml"), xml_with(body)).unwrap();
            },
            render("{dir}/scene.xml", &[]),
            &["scene.xml:", "<volume type=\"gridvolume\" name=\"albedo\">", "give sigma_t as a gridvolume too"],
        ),
        case(
            "XML albedo grid on other voxels than the extinction's",
            |d| {
                gatetrace::scene::medium::write_vol(&d.join("smoke.vol"), [2, 2, 2], &[0.5; 8]).unwrap();
                gatetrace::scene::medium::write_vol(&d.join("albedo.vol"), [4, 2, 1], &[0.5; 8]).unwrap();
                let body = "<shape type=\"cube\"><bsdf type=\"null\"/><medium type=\"heterogeneous\" name=\"interior\">\
                            <volume type=\"gridvolume\" name=\"sigma_t\"><string name=\"filename\" value=\"smoke.vol\"/>\
                            </volume>\
                            <volume type=\"gridvolume\" name=\"albedo\"><string name=\"filename\" value=\"albedo.vol\"/>\
                            </volume></medium></shape>";
                std::fs::write(d.join("scene.xml"), xml_with(body)).unwrap();
            },
            render("{dir}/scene.xml", &[]),
            &["scene.xml:", "the albedo grid (4 x 2 x 1) must share the extinction grid's voxels (2 x 2 x 2)"],
        ),
        case(
            "XML medium and a directional light with a combined render",
            |d| {
                let body = "<shape type=\"cube\"><bsdf type=\"null\"/><medium type=\"homogeneous\" name=\"interior\"/></shape>\
                            <emitter type=\"directional\"><vector name=\"direction\" value=\"0, -1, 0\"/></emitter>";
                std::fs::write(d.join("scene.xml"), xml_with(body)).unwrap();
            },
            plain(&[
                "render",
                "{dir}/scene.xml",
                "--res",
                "8x8",
                "--spp",
                "1",
                "--method",
                "combined",
                "--gate",
                "box:3..3.1",
                "--out",
                "{out}",
            ]),
            &["scene.xml", "--method combined does not weigh connections to directional lights", "--method direct"],
        ),
        case(
            "XML field of view of zero",
            |d| {
                let xml = "<scene version=\"3.0.0\">\n<sensor type=\"perspective\"><float name=\"fov\" value=\"0\"/></sensor>\
                           </scene>";
                std::fs::write(d.join("scene.xml"), xml).unwrap()
            },
            render("{dir}/scene.xml", &[]),
            &["scene.xml:2: <sensor type=\"perspective\">", "fov 0 is not in (0, 180) degrees"],
        ),
        case(
            "XML scene with an animation time",
            |d| std::fs::write(d.join("scene.xml"), xml_with("")).unwrap(),
            plain(&["render", "{dir}/scene.xml", "--res", "8x8", "--frames", "2", "--anim-time", "0..1", "--out", "{dir}/f_{frame}.npy"]),
            &["scene.xml", "a Mitsuba XML scene is static"],
        ),
        case(
            "OBJ named .glb",
            |d| std::fs::write(d.join("misnamed.glb"), OBJ_QUAD).unwrap(),
            render("{dir}/misnamed.glb", &[]),
            &["misnamed.glb", "Wavefront OBJ", "by its content"],
        ),
        case(
            "PLY named .gltf",
            |d| std::fs::write(d.join("mesh.gltf"), "ply\nformat ascii 1.0\nelement vertex 0\nend_header\n").unwrap(),
            render("{dir}/mesh.gltf", &[]),
            &["mesh.gltf", "PLY", "Stanford PLY"],
        ),
        case(
            "FBX by its extension",
            |d| std::fs::write(d.join("rig.fbx"), b"\x00\x01\x02 binary").unwrap(),
            render("{dir}/rig.fbx", &[]),
            &["rig.fbx", "FBX", "by its extension", "File > Import > FBX"],
        ),
        // --- glTF extensions gatetrace does not implement ---
        case(
            "transmissive material",
            box_with("glass.gltf", |d| {
                add_material_extension(d, 1, "KHR_materials_transmission", json!({"transmissionFactor": 1.0}))
            }),
            render("{dir}/glass.gltf", &[]),
            &["glass.gltf", "material `red`", "KHR_materials_transmission", "--allow-unsupported-materials"],
        ),
        case(
            "volume material",
            box_with("volume.gltf", |d| {
                add_material_extension(d, 0, "KHR_materials_volume", json!({"thicknessFactor": 0.1}))
            }),
            render("{dir}/volume.gltf", &[]),
            &["volume.gltf", "material `white`", "KHR_materials_volume", "not implemented"],
        ),
        case(
            "required extension not implemented",
            box_with("required.gltf", |d| {
                add_material_extension(d, 1, "KHR_materials_transmission", json!({"transmissionFactor": 1.0}));
                d["extensionsRequired"] = json!(["KHR_materials_transmission"]);
            }),
            render("{dir}/required.gltf", &["--allow-unsupported-materials"]),
            &["required.gltf", "KHR_materials_transmission", "extensionsRequired", "does not implement"],
        ),
        // --- buffers and images ---
        case(
            "missing buffer",
            box_with("missing_buffer.gltf", |d| d["buffers"][0]["uri"] = json!("gone.bin")),
            render("{dir}/missing_buffer.gltf", &[]),
            &["missing_buffer.gltf", "cannot load a buffer"],
        ),
        case(
            "short buffer",
            box_with("short_buffer.gltf", |d| {
                let n = d["buffers"][0]["byteLength"].as_u64().unwrap();
                d["buffers"][0]["byteLength"] = json!(n + 64);
            }),
            render("{dir}/short_buffer.gltf", &[]),
            &["short_buffer.gltf", "buffer"],
        ),
        case(
            "missing image",
            box_with("missing_image.gltf", |d| {
                d["images"] = json!([{"uri": "gone.png"}]);
                d["textures"] = json!([{"source": 0}]);
                d["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
            }),
            render("{dir}/missing_image.gltf", &[]),
            &["missing_image.gltf", "cannot load an image"],
        ),
        case(
            "corrupt image",
            |d| {
                std::fs::write(d.join("noise.png"), b"\x89PNG\r\n\x1a\n this is not a PNG").unwrap();
                box_with("corrupt_image.gltf", |d| {
                    d["images"] = json!([{"uri": "noise.png"}]);
                    d["textures"] = json!([{"source": 0}]);
                    d["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
                })(d)
            },
            render("{dir}/corrupt_image.gltf", &[]),
            &["corrupt_image.gltf", "image"],
        ),
        // --- accessors ---
        case(
            "POSITION accessor of type SCALAR",
            box_with("scalar_positions.gltf", |d| {
                // min and max stay VEC3-sized, so only the type is wrong.
                d["accessors"][0]["type"] = json!("SCALAR");
            }),
            render("{dir}/scalar_positions.gltf", &[]),
            &["scalar_positions.gltf", "POSITION", "VEC3"],
        ),
        case(
            "POSITION accessor of unsigned bytes",
            box_with("byte_positions.gltf", |d| d["accessors"][0]["componentType"] = json!(5121)),
            render("{dir}/byte_positions.gltf", &[]),
            &["byte_positions.gltf", "POSITION", "float"],
        ),
        case(
            "index accessor of type VEC2",
            box_with("vec2_indices.gltf", |d| {
                // Half the count, so that the bytes still fit the view and only the type is wrong.
                d["accessors"][2]["type"] = json!("VEC2");
                d["accessors"][2]["count"] = json!(3);
            }),
            render("{dir}/vec2_indices.gltf", &[]),
            &["vec2_indices.gltf", "indices", "SCALAR"],
        ),
        case(
            "accessor of no elements",
            box_with("empty_accessor.gltf", |d| d["accessors"][0]["count"] = json!(0)),
            render("{dir}/empty_accessor.gltf", &[]),
            &["empty_accessor.gltf", "accessors[0]", "count 0"],
        ),
        case(
            "buffer view past its buffer",
            box_with("long_view.gltf", |d| d["bufferViews"][1]["byteLength"] = json!(18_446_744_073_709_551_615u64)),
            render("{dir}/long_view.gltf", &[]),
            &["long_view.gltf", "bufferViews[1]", "outside buffer 0"],
        ),
        case(
            "accessor past its buffer",
            box_with("long_accessor.gltf", |d| d["accessors"][0]["count"] = json!(4000)),
            render("{dir}/long_accessor.gltf", &[]),
            &["long_accessor.gltf"],
        ),
        case(
            "index out of range",
            |d| {
                let mut s = lit_scene(vec![[-1.0, -1.0, -1.0], [1.0, -1.0, -1.0], [0.0, 1.0, -1.0]]);
                s.meshes[0].indices = vec![0, 1, 7];
                s.write(d, "bad_index.gltf");
            },
            render("{dir}/bad_index.gltf", &[]),
            &["bad_index.gltf", "index 7 is out of range"],
        ),
        // --- coordinates ---
        case(
            "NaN vertex",
            |d| write_with_bounds(d, "nan.gltf", [f32::NAN, -1.0, -1.0]),
            render("{dir}/nan.gltf", &[]),
            &["nan.gltf", "vertex 1 is not finite"],
        ),
        case(
            "infinite vertex",
            |d| write_with_bounds(d, "inf.gltf", [1.0, f32::INFINITY, -1.0]),
            render("{dir}/inf.gltf", &[]),
            &["inf.gltf", "vertex 1 is not finite"],
        ),
        case(
            "non-finite vertex without bounds",
            |d| {
                lit_scene(vec![[-1.0, -1.0, -1.0], [f32::INFINITY, -1.0, -1.0], [0.0, 1.0, -1.0]])
                    .write(d, "inf_no_bounds.gltf");
            },
            render("{dir}/inf_no_bounds.gltf", &[]),
            &["inf_no_bounds.gltf", "POSITION", "min"],
        ),
        case(
            "vertex at 1e30 m",
            |d| {
                lit_scene(vec![[-1.0, -1.0, -1.0], [1e30, -1.0, -1.0], [0.0, 1.0, -1.0]]).write(d, "far_vertex.gltf");
            },
            render("{dir}/far_vertex.gltf", &[]),
            &["far_vertex.gltf", "1e30", "m"],
        ),
        case(
            "node translated by 1e30 m",
            box_with("far_node.gltf", |d| d["nodes"][0]["translation"] = json!([1e30, 0.0, 0.0])),
            render("{dir}/far_node.gltf", &[]),
            &["far_node.gltf", "node `floor`", "1e30"],
        ),
        case(
            "only degenerate triangles",
            |d| {
                let mut s = lit_scene(vec![[0.0, 0.0, -1.0]; 6]);
                s.meshes[1] = Mesh {
                    positions: vec![[1.0, 1.0, 1.0]; 3],
                    normals: None,
                    uvs: None,
                    indices: vec![0, 1, 2],
                    material: Some(1),
                };
                s.write(d, "degenerate.gltf");
            },
            render("{dir}/degenerate.gltf", &[]),
            &["degenerate.gltf", "zero area"],
        ),
        // --- camera and lights ---
        case(
            "no camera",
            |d| {
                let mut s = lit_scene(vec![[-1.0, -1.0, -1.0], [1.0, -1.0, -1.0], [0.0, 1.0, -1.0]]);
                s.camera = None;
                s.write(d, "no_camera.gltf");
            },
            render("{dir}/no_camera.gltf", &[]),
            &["no_camera.gltf", "no camera"],
        ),
        case(
            "no light",
            box_with("no_light.gltf", |d| {
                for m in d["materials"].as_array_mut().unwrap() {
                    m.as_object_mut().unwrap().remove("emissiveFactor");
                }
            }),
            render("{dir}/no_light.gltf", &[]),
            &["no_light.gltf", "no light"],
        ),
        case(
            "zero-power light",
            |d| {
                let mut s = lit_scene(vec![[-1.0, -1.0, -1.0], [1.0, -1.0, -1.0], [0.0, 1.0, -1.0]]);
                s.materials[1] = Material::diffuse([0.5; 3]);
                s.point_lights = vec![PointLight { position: [0.0, 0.0, 0.0], intensity: 0.0 }];
                s.write(d, "dark_light.gltf");
            },
            render("{dir}/dark_light.gltf", &[]),
            &["dark_light.gltf", "no power"],
        ),
        // --- animations ---
        case(
            "animation keys out of order",
            |d| {
                let mut doc: Value = serde_json::from_str(
                    &std::fs::read_to_string(common::repo_path("assets/scenes/cornell_box_moving_block.gltf")).unwrap(),
                )
                .unwrap();
                let input = doc["animations"][0]["samplers"][0]["input"].as_u64().unwrap() as usize;
                doc["accessors"][input]["count"] = json!(1);
                doc["animations"][0]["samplers"][0]["output"] = json!(input);
                write_json(d, "bad_animation.gltf", &doc);
            },
            render("{dir}/bad_animation.gltf", &["--anim-time", "0.5"]),
            &["bad_animation.gltf", "animation"],
        ),
        case(
            "--anim-time without animation",
            none,
            default_scene(&["--res", "8x8", "--spp", "1", "--anim-time", "0.5"]),
            &["--anim-time", "no animation"],
        ),
        // --- gates ---
        case(
            "box gate ending before it starts",
            none,
            default_scene(&["--gate", "box:3.2..3.1"]),
            &["--gate box:3.2..3.1", "must exceed"],
        ),
        case(
            "gaussian gate with sigma 0",
            none,
            default_scene(&["--gate", "gaussian:3,0"]),
            &["--gate gaussian:3,0", "sigma"],
        ),
        case(
            "cw gate at a negative frequency",
            none,
            default_scene(&["--gate", "cw:-20e6,0"]),
            &["--gate cw:-20e6,0", "frequency"],
        ),
        case(
            "cw gate with an unknown code",
            none,
            default_scene(&["--gate", "cw:20e6,0,zigzag"]),
            &["--gate cw:20e6,0,zigzag", "unknown cw code"],
        ),
        case(
            "transient gate of 0 bins",
            none,
            default_scene(&["--gate", "transient:3,0.01,0"]),
            &["--gate transient:3,0.01,0", "bins"],
        ),
        case(
            "transient gate of negative width",
            none,
            default_scene(&["--gate", "transient:3,-0.01,8"]),
            &["--gate transient:3,-0.01,8", "width"],
        ),
        case(
            "unknown gate kind",
            none,
            default_scene(&["--gate", "wobble:1"]),
            &["--gate wobble:1", "unknown gate kind"],
        ),
        case(
            "gate length that is no number",
            none,
            default_scene(&["--gate", "box:1x..2"]),
            &["--gate box:1x..2", "not a length"],
        ),
        case(
            "malformed gate table",
            |d| std::fs::write(d.join("gate.csv"), "3.0,1.0\n3.1,heavy\n").unwrap(),
            default_scene(&["--gate", "table:{dir}/gate.csv"]),
            &["gate.csv:2", "length,weight"],
        ),
        case(
            "gate table with decreasing lengths",
            |d| std::fs::write(d.join("gate.csv"), "3.1,1.0\n3.0,0.5\n").unwrap(),
            default_scene(&["--gate", "table:{dir}/gate.csv"]),
            &["gate.csv", "increase"],
        ),
        case("missing gate table", none, default_scene(&["--gate", "table:{dir}/none.csv"]), &["none.csv"]),
        // --- sizes and counts ---
        case("zero resolution", none, default_scene(&["--res", "0x4"]), &["--res", "resolution"]),
        case("negative resolution", none, default_scene(&["--res", "-4x4"]), &["--res"]),
        case("absurd resolution", none, default_scene(&["--res", "100000x100000"]), &["--res", "16384"]),
        case("zero spp", none, default_scene(&["--spp", "0"]), &["--spp", "at least 1"]),
        case("negative spp", none, default_scene(&["--spp", "-3"]), &["--spp"]),
        case("absurd spp", none, default_scene(&["--spp", "100000000000000000000"]), &["--spp"]),
        case("negative time", none, default_scene(&["--time", "-1"]), &["--time", "positive"]),
        case("negative bounces", none, default_scene(&["--max-bounces", "-1"]), &["--max-bounces"]),
        case("absurd bounces", none, default_scene(&["--max-bounces", "5000000"]), &["--max-bounces"]),
        case(
            "too many bidirectional bounces",
            none,
            default_scene(&["--method", "direct", "--max-bounces", "30"]),
            &["at most 24 bounces"],
        ),
        case(
            "transient cube that cannot fit",
            none,
            default_scene(&["--res", "16384x16384", "--gate", "transient:3,0.001,4096"]),
            &["--res 16384x16384", "4096 bins", "GiB"],
        ),
        // --- methods and options ---
        case("unknown method", none, default_scene(&["--method", "magic"]), &["--method", "magic"]),
        case("--spp with --time", none, default_scene(&["--spp", "4", "--time", "2"]), &["--spp", "--time"]),
        case(
            "ellipsoidal without a gate",
            none,
            default_scene(&["--method", "ellipsoidal"]),
            &["ellipsoidal", "draws target path lengths from the gate"],
        ),
        case(
            "--debug-strategy without direct",
            none,
            default_scene(&["--debug-strategy", "1,2"]),
            &["--debug-strategy", "needs --method direct"],
        ),
        case(
            "--target-pilot with path",
            none,
            default_scene(&["--target-pilot", "16"]),
            &["--target-pilot", "ellipsoidal"],
        ),
        case(
            "--ellipsoidal-share without combined",
            none,
            default_scene(&["--method", "direct", "--gate", "box:3.0..3.2", "--ellipsoidal-share", "2"]),
            &["--ellipsoidal-share", "--method combined only"],
        ),
        case(
            "--ellipsoidal-share out of range",
            none,
            default_scene(&["--method", "combined", "--gate", "box:3.0..3.2", "--ellipsoidal-share", "100"]),
            &["--ellipsoidal-share 100", "1/8 to 8"],
        ),
        case(
            "--query-roulette without ellipsoidal",
            none,
            default_scene(&["--method", "direct", "--gate", "box:3.0..3.2", "--query-roulette", "0.5"]),
            &["--query-roulette", "--method ellipsoidal"],
        ),
        case(
            "--query-roulette out of range",
            none,
            default_scene(&["--method", "ellipsoidal", "--gate", "box:3.0..3.2", "--query-roulette", "0"]),
            &["--query-roulette 0", "0.0625 to 1"],
        ),
        case("a lens without focus", none, default_scene(&["--aperture-radius", "0.1"]), &["give --focus-distance"]),
        case(
            "a negative focus distance",
            none,
            default_scene(&["--aperture-radius", "0.1", "--focus-distance", "-2"]),
            &["--aperture-radius/--focus-distance", "focus distance -2 m is not a positive length"],
        ),
        case(
            "a NaN aperture",
            none,
            default_scene(&["--aperture-radius", "nan", "--focus-distance", "2"]),
            &["--aperture-radius/--focus-distance", "aperture radius NaN m"],
        ),
        case(
            "a strategy that does not exist",
            none,
            default_scene(&["--method", "direct", "--debug-strategy", "0,1"]),
            &["--debug-strategy", "not a strategy"],
        ),
        case(
            "a strategy of one number",
            none,
            default_scene(&["--method", "direct", "--debug-strategy", "1"]),
            &["--debug-strategy", "S,T"],
        ),
        // --- checkpoints ---
        case(
            "--resume without a checkpoint",
            none,
            default_scene(&["--res", "8x8", "--resume"]),
            &["--resume", "out.npy.checkpoint"],
        ),
        case(
            "--resume with another seed",
            |d| checkpointed(d, &["--seed", "1"]),
            default_scene(&["--res", "8x8", "--spp", "8", "--max-bounces", "2", "--seed", "2", "--resume"]),
            &["out.npy.checkpoint", "another render", "seed: 1"],
        ),
        case(
            "--resume to fewer samples than taken",
            |d| checkpointed(d, &[]),
            default_scene(&["--res", "8x8", "--spp", "2", "--max-bounces", "2", "--resume"]),
            &["out.npy.checkpoint", "4 spp already"],
        ),
        case(
            "--resume from a corrupt checkpoint",
            |d| std::fs::write(d.join("out.npy.checkpoint"), b"GATETRACE-CHECKPOINT\n{").unwrap(),
            default_scene(&["--res", "8x8", "--resume"]),
            &["out.npy.checkpoint", "header"],
        ),
        case(
            "negative --checkpoint-every",
            none,
            default_scene(&["--checkpoint-every", "-1"]),
            &["--checkpoint-every", "seconds"],
        ),
        case(
            "--resume of an NLOS capture",
            none,
            render(
                &common::repo_path("assets/scenes/nlos_letter.gltf").display().to_string(),
                &["--nlos", "confocal", "--resume"],
            ),
            &["--resume", "NLOS"],
        ),
        // --- shards ---
        case("--shard with --time", none, default_scene(&["--shard", "0/2", "--time", "1"]), &["--shard", "--spp"]),
        case(
            "--shard of auto",
            none,
            default_scene(&["--shard", "0/2", "--method", "auto", "--gate", "box:3.14..3.19"]),
            &["--shard", "auto"],
        ),
        case("--shard past its count", none, default_scene(&["--shard", "4/4"]), &["--shard", "0 <= I < N"]),
        case("--shard that is no fraction", none, default_scene(&["--shard", "half"]), &["--shard", "I/N"]),
        case(
            "merge with a shard missing",
            |d| shards(d, &[0, 1, 3], &[]),
            plain(&["merge", "{dir}/0.shard", "{dir}/1.shard", "{dir}/3.shard", "--out", "{out}"]),
            &["shards 2 of 4 are missing"],
        ),
        case(
            "merge with a shard twice",
            |d| shards(d, &[0, 1, 2, 3], &[]),
            plain(&[
                "merge",
                "{dir}/0.shard",
                "{dir}/1.shard",
                "{dir}/1.shard",
                "{dir}/2.shard",
                "{dir}/3.shard",
                "--out",
                "{out}",
            ]),
            &["1.shard", "both shard 1/4"],
        ),
        case(
            "merge of shards of two renders",
            |d| {
                shards(d, &[0, 1, 2], &[]);
                shards(d, &[3], &["--seed", "5"]);
            },
            plain(&["merge", "{dir}/0.shard", "{dir}/1.shard", "{dir}/2.shard", "{dir}/3.shard", "--out", "{out}"]),
            &["3.shard", "not a shard of the render", "seed: 0"],
        ),
        case(
            "merge of a checkpoint",
            |d| checkpointed(d, &[]),
            plain(&["merge", "{dir}/out.npy.checkpoint", "--out", "{dir}/m.npy"]),
            &["out.npy.checkpoint", "not a shard"],
        ),
        // --- outputs ---
        case(
            "unknown output format",
            none,
            plain(&["render", "--res", "8x8", "--out", "{dir}/image.tiff"]),
            &["image.tiff", ".exr or .npy", ".png"],
        ),
        case(
            "preview bin beyond the gate's bins",
            none,
            plain(&[
                "render",
                "--res",
                "8x8",
                "--gate",
                "transient:3,0.1,4",
                "--preview-bin",
                "4",
                "--out",
                "{dir}/p.png",
            ]),
            &["--preview-bin 4", "4 bin(s)"],
        ),
        case(
            "exposure for a data output",
            none,
            plain(&["render", "--res", "8x8", "--exposure", "2", "--out", "{out}"]),
            &["--exposure", ".png previews"],
        ),
        case(
            "output under a regular file",
            |d| std::fs::write(d.join("file"), b"").unwrap(),
            plain(&["render", "--res", "8x8", "--out", "{dir}/file/x.npy", "--mkdir"]),
            &["file", "cannot create the directory"],
        ),
        case(
            "output in a missing directory",
            none,
            plain(&["render", "--res", "8x8", "--out", "{dir}/missing/x.npy"]),
            &["{dir}/missing: no such directory", "--mkdir"],
        ),
        case(
            "merge into a missing directory",
            |d| shards(d, &[0, 1, 2, 3], &[]),
            plain(&[
                "merge",
                "{dir}/0.shard",
                "{dir}/1.shard",
                "{dir}/2.shard",
                "{dir}/3.shard",
                "--out",
                "{dir}/missing/m.npy",
            ]),
            &["{dir}/missing: no such directory"],
        ),
        case(
            "output that is a directory",
            |d| std::fs::create_dir(d.join("x.npy")).unwrap(),
            plain(&["render", "--res", "8x8", "--out", "{dir}/x.npy"]),
            &["x.npy", "cannot write the output file"],
        ),
        // Unwritable even for root (CI runs as root, for whom permission bits do not count).
        case(
            "output on a read-only file system",
            none,
            plain(&["render", "--res", "8x8", "--out", "/proc/gatetrace.npy"]),
            &["/proc/gatetrace.npy", "cannot write the output file"],
        ),
    ]
}

/// The files under `dir`, recursively, as paths relative to it.
fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            out.extend(files_under(&path));
        } else {
            out.push(path);
        }
    }
    out.sort();
    out
}

#[test]
fn every_bad_input_gets_a_clear_error_and_no_output() {
    let root = common::scratch_dir("bad_input");
    let all = cases();
    assert!(all.len() >= 25, "the suite must keep at least 25 cases");
    let mut failures = Vec::new();
    for (i, (c, setup)) in all.into_iter().enumerate() {
        let dir = root.join(format!("case_{i:02}"));
        std::fs::create_dir_all(&dir).unwrap();
        setup(&dir);
        let before = files_under(&dir);
        let d = dir.to_str().unwrap();
        let out = format!("{d}/out.npy");
        let args: Vec<String> = c.args.iter().map(|a| a.replace("{dir}", d).replace("{out}", &out)).collect();
        let o = Command::new(env!("CARGO_BIN_EXE_gatetrace")).args(&args).output().expect("the binary runs");
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        let needles: Vec<String> = c.needles.iter().map(|n| n.replace("{dir}", d)).collect();
        let mut problems = Vec::new();
        if o.status.success() {
            problems.push("exited with status 0".to_owned());
        }
        if err.contains("panicked") || o.status.code().is_none() {
            problems.push("panicked or was killed".to_owned());
        }
        for n in &needles {
            if !err.contains(n.as_str()) {
                problems.push(format!("error does not mention `{n}`"));
            }
        }
        let written: Vec<_> = files_under(&dir).into_iter().filter(|f| !before.contains(f)).collect();
        if !written.is_empty() {
            problems.push(format!("wrote {written:?}"));
        }
        if !problems.is_empty() {
            failures.push(format!(
                "{} ({}): {}\n    stderr: {}",
                c.name,
                args.join(" "),
                problems.join("; "),
                err.trim()
            ));
        }
    }
    assert!(failures.is_empty(), "{} cases failed:\n{}", failures.len(), failures.join("\n"));
}

/// Renders `scene` (8x8, 1 spp) with `extra` options to `dir/out.npy` and returns whether it
/// succeeded and its stderr.
fn render_tiny(dir: &Path, scene: &Path, extra: &[&str]) -> (bool, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_gatetrace"))
        .arg("render")
        .arg(scene)
        .args(["--res", "8x8", "--spp", "1", "--max-bounces", "2", "--out"])
        .arg(dir.join("out.npy"))
        .args(extra)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!err.contains("panicked"), "{err}");
    (o.status.success(), err)
}

#[test]
fn unimplemented_extensions_render_with_a_warning_naming_them() {
    let dir = common::scratch_dir("unimplemented_extensions");
    let write = |name: &str, edit: &dyn Fn(&mut Value)| {
        let mut doc = cornell_box_json();
        edit(&mut doc);
        write_json(&dir, name, &doc);
        dir.join(name)
    };

    // Glass, allowed: rendered as an opaque surface, with a warning naming the material.
    let glass = write("glass.gltf", &|d| {
        add_material_extension(d, 1, "KHR_materials_transmission", json!({"transmissionFactor": 1.0}))
    });
    let (ok, err) = render_tiny(&dir, &glass, &["--allow-unsupported-materials"]);
    assert!(ok, "{err}");
    assert!(
        err.contains("warning: ")
            && err.contains("glass.gltf")
            && err.contains("material `red`")
            && err.contains("KHR_materials_transmission")
            && err.contains("opaque surface"),
        "{err}"
    );

    // A material extension that does not let light through: ignored with a warning.
    let coated = write("coated.gltf", &|d| {
        add_material_extension(d, 0, "KHR_materials_clearcoat", json!({"clearcoatFactor": 1.0}))
    });
    let (ok, err) = render_tiny(&dir, &coated, &[]);
    assert!(ok, "{err}");
    assert!(
        err.contains("coated.gltf") && err.contains("material `white`") && err.contains("KHR_materials_clearcoat"),
        "{err}"
    );

    // An extension listed in extensionsUsed that no material carries.
    let listed = write("listed.gltf", &|d| {
        d["extensionsUsed"].as_array_mut().unwrap().push(json!("KHR_materials_transmission"))
    });
    let (ok, err) = render_tiny(&dir, &listed, &[]);
    assert!(ok, "{err}");
    assert!(
        err.contains("warning: ")
            && err.contains("listed.gltf")
            && err.contains("KHR_materials_transmission")
            && err.contains("extensionsUsed"),
        "{err}"
    );

    // The scene as shipped uses only what gatetrace implements: no warning.
    let (ok, err) = render_tiny(&dir, &common::repo_path("assets/scenes/cornell_box.gltf"), &[]);
    assert!(ok && !err.contains("warning"), "{err}");
}

/// The library returns what loading ignored instead of printing it: the loaded scene's
/// `warnings` name the file, the material and the extension, and the scene loads.
#[test]
fn the_library_returns_load_warnings_to_its_caller() {
    let dir = common::scratch_dir("load_warnings");
    let mut doc = cornell_box_json();
    add_material_extension(&mut doc, 0, "KHR_materials_clearcoat", json!({"clearcoatFactor": 1.0}));
    write_json(&dir, "coated.gltf", &doc);
    let scene = gatetrace::scene::load_gltf(&dir.join("coated.gltf")).expect("a scene with an ignored extension loads");
    assert_eq!(scene.warnings.len(), 1, "{:?}", scene.warnings);
    let warning = &scene.warnings[0];
    assert!(
        warning.contains("coated.gltf")
            && warning.contains("material `white`")
            && warning.contains("KHR_materials_clearcoat"),
        "{warning}"
    );
    let plain = gatetrace::scene::load_gltf(&common::repo_path("assets/scenes/cornell_box.gltf")).unwrap();
    assert!(plain.warnings.is_empty(), "{:?}", plain.warnings);
}

mod properties {
    use super::*;
    use gatetrace::film::Gate;
    use gatetrace::scene::{PreparedScene, load_gltf, load_gltf_at, load_gltf_for_capture};
    use proptest::prelude::*;

    /// Values a mutation may put anywhere in a document: numbers at and beyond every limit,
    /// strings, and the other JSON types.
    fn hostile_value() -> impl Strategy<Value = Value> {
        prop_oneof![
            Just(json!(0)),
            Just(json!(-1)),
            Just(json!(1)),
            Just(json!(3)),
            Just(json!(4_294_967_295u64)),
            Just(json!(18_446_744_073_709_551_615u64)),
            Just(json!(-9_223_372_036_854_775_807i64)),
            Just(json!(1e30)),
            Just(json!(-1e30)),
            Just(json!(1e-40)),
            Just(json!(f64::MAX)),
            Just(json!(0.5)),
            Just(json!("")),
            Just(json!("VEC3")),
            Just(json!("SCALAR")),
            Just(json!("data:application/octet-stream;base64,AAAA")),
            Just(json!("../../../../etc/passwd")),
            Just(json!(null)),
            Just(json!(true)),
            Just(json!([])),
            Just(json!({})),
            Just(json!([1e30, 1e30, 1e30])),
            Just(json!([0, 0, 0, 0])),
            any::<i32>().prop_map(|v| json!(v)),
            any::<f32>().prop_filter("JSON numbers are finite", |v| v.is_finite()).prop_map(|v| json!(v)),
        ]
    }

    /// One edit of a document: the `pick`-th value in a depth-first walk is replaced by
    /// `value`, removed from its object or array, or (for an array) duplicated.
    #[derive(Clone, Debug)]
    struct Edit {
        pick: usize,
        action: u8,
        value: Value,
    }

    fn edit() -> impl Strategy<Value = Edit> {
        (any::<usize>(), 0u8..4, hostile_value()).prop_map(|(pick, action, value)| Edit { pick, action, value })
    }

    /// Counts the values of `doc` (depth first, the root included).
    fn count(doc: &Value) -> usize {
        1 + match doc {
            Value::Array(a) => a.iter().map(count).sum(),
            Value::Object(o) => o.values().map(count).sum(),
            _ => 0,
        }
    }

    /// Applies `e` to the value numbered `*left` (counting down, depth first); true once done.
    fn apply(doc: &mut Value, left: &mut usize, e: &Edit) -> bool {
        // Children are edited through their parent, so a value can be removed.
        let children: Vec<(Option<String>, usize)> = match doc {
            Value::Array(a) => (0..a.len()).map(|i| (None, i)).collect(),
            Value::Object(o) => o.keys().cloned().map(|k| (Some(k), 0)).collect(),
            _ => return false,
        };
        for (key, index) in children {
            if *left == 0 {
                break;
            }
            *left -= 1;
            if *left == 0 {
                match (doc, key, e.action) {
                    (Value::Object(o), Some(k), 0) => {
                        o.remove(&k);
                    }
                    (Value::Array(a), None, 0) => {
                        a.remove(index);
                    }
                    (Value::Array(a), None, 1) => {
                        let copy = a[index].clone();
                        a.push(copy);
                    }
                    (Value::Object(o), Some(k), _) => {
                        o.insert(k, e.value.clone());
                    }
                    (Value::Array(a), None, _) => a[index] = e.value.clone(),
                    _ => unreachable!(),
                }
                return true;
            }
            let child = match (&mut *doc, key) {
                (Value::Object(o), Some(k)) => o.get_mut(&k).unwrap(),
                (Value::Array(a), None) => &mut a[index],
                _ => unreachable!(),
            };
            if apply(child, left, e) {
                return true;
            }
        }
        false
    }

    /// Loads `path` every way the renderer does and prepares what loads (BVH build included):
    /// errors are fine, panics are not.
    fn load_every_way(path: &Path) {
        if let Ok(scene) = load_gltf(path) {
            let _ = PreparedScene::new(scene);
        }
        if let Ok(scene) = load_gltf_at(path, Some(0.5)) {
            let _ = PreparedScene::new(scene);
        }
        if let Ok(scene) = load_gltf_for_capture(path) {
            let _ = PreparedScene::new(scene);
        }
    }

    fn scratch(name: &str) -> PathBuf {
        let dir = common::repo_path("target/test-scratch").join(name);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// The documents mutated: the Cornell box, an animated scene and the NLOS example.
    fn base_document() -> impl Strategy<Value = Value> {
        ["cornell_box.gltf", "cornell_box_moving_block.gltf", "nlos_letter.gltf", "cornell_box_spot.gltf"]
            .map(|name| {
                let text = std::fs::read_to_string(common::repo_path(&format!("assets/scenes/{name}"))).unwrap();
                serde_json::from_str::<Value>(&text).unwrap()
            })
            .into_iter()
            .map(Just)
            .collect::<Vec<_>>()
            .into_iter()
            .fold(None::<BoxedStrategy<Value>>, |acc, s| {
                Some(match acc {
                    None => s.boxed(),
                    Some(a) => prop_oneof![a, s].boxed(),
                })
            })
            .unwrap()
    }

    /// Attribute values a mutation may put into a Mitsuba XML scene.
    fn hostile_attribute() -> impl Strategy<Value = String> {
        prop::sample::select(vec![
            "",
            "0",
            "-1",
            "1e30",
            "-1e30",
            "1e-40",
            "nan",
            "inf",
            "4294967296",
            "0, 0, 0",
            "1 2",
            "1,2,3,4",
            "$",
            "$nope",
            "$spp",
            "true",
            "false",
            "sphere",
            "obj",
            "diffuse",
            "twosided",
            "ggx",
            "x",
            "diagonal",
            "scene.xml",
            "materials.xml",
            "../../../../etc/passwd",
            "block.obj",
            "tetrahedron.ply",
            "quadrants.png",
            "white",
            "camera",
            "360",
            "-90",
        ])
        .prop_map(str::to_owned)
    }

    /// One edit of a Mitsuba scene's text: the `pick`-th attribute value replaced by `value`, or
    /// the `pick`-th element of one line (`<... />`) removed or repeated (so most edits leave
    /// well-formed XML for the loader to judge).
    fn edit_xml(text: &str, pick: usize, action: u8, value: &str) -> String {
        let lines: Vec<&str> = text.lines().collect();
        let whole: Vec<usize> =
            (0..lines.len()).filter(|&i| lines[i].trim_start().starts_with('<') && lines[i].ends_with("/>")).collect();
        let line = whole[pick % whole.len()];
        match action {
            0 => lines.iter().enumerate().filter(|(i, _)| *i != line).map(|(_, l)| *l).collect::<Vec<_>>().join("\n"),
            1 => {
                let mut out = lines.clone();
                out.insert(line, lines[line]);
                out.join("\n")
            }
            _ => {
                // Attribute values are the text between a `="` and the next `"`.
                let starts: Vec<usize> = text.match_indices("=\"").map(|(i, _)| i + 2).collect();
                let Some(&start) = starts.get(pick % starts.len().max(1)) else { return text.to_owned() };
                let end = start + text[start..].find('"').unwrap_or(0);
                format!("{}{}{}", &text[..start], value.replace('"', ""), &text[end..])
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 300, failure_persistence: None, ..ProptestConfig::default() })]

        /// Mitsuba XML scenes with 1 to 4 edits (attribute values replaced, lines removed or
        /// repeated), in the scene or its included file, and their meshes with bytes overwritten,
        /// load or fail with an error; what loads can be prepared.
        #[test]
        fn mutated_mitsuba_scenes_never_panic(
            edits in prop::collection::vec((any::<usize>(), 0u8..4, hostile_attribute(), any::<bool>()), 1..5),
            flips in prop::collection::vec((any::<usize>(), any::<u8>(), 0usize..3), 0..3),
        ) {
            let source = common::repo_path("assets/scenes/mitsuba_box");
            let dir = scratch(&format!("properties_xml_{:?}", std::thread::current().id()).replace(['(', ')'], ""));
            for file in ["scene.xml", "materials.xml", "block.obj", "tetrahedron.ply", "quadrants.png", "shapes.serialized"] {
                std::fs::copy(source.join(file), dir.join(file)).unwrap();
            }
            for (pick, action, value, included) in &edits {
                let file = dir.join(if *included { "materials.xml" } else { "scene.xml" });
                let text = std::fs::read_to_string(&file).unwrap();
                std::fs::write(&file, edit_xml(&text, *pick, *action, value)).unwrap();
            }
            for (at, byte, mesh) in flips {
                let file = dir.join(["tetrahedron.ply", "block.obj", "shapes.serialized"][mesh]);
                let mut bytes = std::fs::read(&file).unwrap();
                let n = bytes.len();
                bytes[at % n] = byte;
                std::fs::write(&file, bytes).unwrap();
            }
            let path = dir.join("scene.xml");
            let _ = gatetrace::scene::scene_settings(&path, &[]);
            if let Ok(scene) = gatetrace::scene::load_scene_with(&path, &Default::default()) {
                let _ = PreparedScene::new(scene);
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 1000, failure_persistence: None, ..ProptestConfig::default() })]

        /// Edited documents (1 to 4 edits anywhere in the JSON) load or fail with an error.
        #[test]
        fn mutated_gltf_documents_never_panic(doc in base_document(), edits in prop::collection::vec(edit(), 1..5)) {
            let mut doc = doc;
            for e in &edits {
                let mut left = e.pick % count(&doc);
                if left > 0 {
                    apply(&mut doc, &mut left, e);
                }
            }
            let dir = scratch("properties_gltf");
            let path = dir.join(format!("mutated_{:?}.gltf", std::thread::current().id()).replace(['(', ')'], ""));
            std::fs::write(&path, serde_json::to_vec(&doc).unwrap()).unwrap();
            load_every_way(&path);
        }

        /// Files with bytes overwritten or cut (text glTF and GLB) load or fail with an error.
        #[test]
        fn corrupted_gltf_bytes_never_panic(as_glb in any::<bool>(), flips in prop::collection::vec((any::<usize>(), any::<u8>()), 0..8),
                                            cut in any::<usize>()) {
            let doc = cornell_box_json();
            let mut bytes = if as_glb { glb(&doc) } else { serde_json::to_vec(&doc).unwrap() };
            for (at, byte) in flips {
                let n = bytes.len();
                bytes[at % n] = byte;
            }
            bytes.truncate(bytes.len() - cut % (bytes.len() / 4 + 1));
            let dir = scratch("properties_bytes");
            let path = dir.join(if as_glb { "corrupt.glb" } else { "corrupt.gltf" });
            std::fs::write(&path, &bytes).unwrap();
            load_every_way(&path);
        }

        /// Gate specifications built from every kind and hostile numbers parse or fail with an
        /// error, and what parses can be described, binned and uploaded.
        #[test]
        fn gate_specifications_never_panic(
            kind in prop::sample::select(vec!["none", "box", "gaussian", "cw", "transient", "table", "", "BOX", "wobble"]),
            numbers in prop::collection::vec(prop::sample::select(vec![
                "0", "-0", "1", "3.1", "-2", "1e308", "1e-320", "nan", "inf", "-inf", "4294967296", "18446744073709551616",
                "3ps", "1.5ns", "2mm", "1e9ns", "", " ", "x", "20e6", "90", "sine", "square", "ham4:9", "mseq:1",
                "depthsel:3:9", "mseq:1000000",
            ]), 0..5),
            separators in prop::collection::vec(prop::sample::select(vec![",", "..", ":", ";"]), 5),
        ) {
            let mut spec = format!("{kind}:");
            for (i, n) in numbers.iter().enumerate() {
                if i > 0 {
                    spec.push_str(separators[i]);
                }
                spec.push_str(n);
            }
            for s in [spec.clone(), spec.trim_end_matches(':').to_owned()] {
                if let Ok(gate) = Gate::parse(&s) {
                    let _ = (gate.describe(), gate.bins(), gate.to_gpu(), gate.table(), gate.max_length(), gate.min_length());
                    for i in 0..gate.bins().min(4) {
                        let _ = gate.bin_range(i);
                    }
                    let _ = gate.shifted(0.25);
                }
            }
        }
    }
}
