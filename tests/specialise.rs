//! Kernels specialised on the host (`src/gpu/specialise.rs`): overrides substituted and the
//! branches they rule out removed before the driver sees them.
//!
//! - Every kernel, specialised with its overrides' defaults and with each `bool` override set
//!   all on and all off, is a valid module with no overrides left (CPU only).
//! - The pruning removes what a scene does not need: `connect_ellipsoidal` without dielectrics
//!   or plastic keeps none of their functions, and keeps them where the scene has them.
//! - Renders are bit for bit the same pruned and with `GATETRACE_NO_PRUNING=1` (wgpu
//!   substituting the constants and the driver seeing every branch): `path` on the glossy box
//!   with a transient gate, `combined` (both families) on glass and plastic with a CW gate,
//!   `ellipsoidal` in fog, and an NLOS capture.

use std::path::Path;
use std::process::Command;

use gatetrace::gpu::kernels::{KERNEL_SOURCES, KernelSource};
use gatetrace::gpu::specialise::specialise;
use naga::valid::{Capabilities, ValidationFlags, Validator};

mod common;

/// The names of `source`'s `bool` overrides.
fn bool_overrides(source: &KernelSource) -> Vec<&'static str> {
    let module = naga::front::wgsl::parse_str(source.wgsl).unwrap();
    source
        .overrides
        .iter()
        .copied()
        .filter(|&name| {
            module.overrides.iter().any(|(_, o)| {
                o.name.as_deref() == Some(name)
                    && matches!(module.types[o.ty].inner, naga::TypeInner::Scalar(s) if s.kind == naga::ScalarKind::Bool)
            })
        })
        .collect()
}

fn function_names(module: &naga::Module) -> Vec<String> {
    module.functions.iter().filter_map(|(_, f)| f.name.clone()).collect()
}

#[test]
fn every_kernel_specialises_to_a_valid_module_without_overrides() {
    for source in KERNEL_SOURCES {
        let bools = bool_overrides(source);
        let settings: [Vec<(&str, f64)>; 3] =
            [Vec::new(), bools.iter().map(|&b| (b, 1.0)).collect(), bools.iter().map(|&b| (b, 0.0)).collect()];
        for constants in &settings {
            let what = format!("{}({:?}) with {constants:?}", source.name, source.feature);
            let module = specialise(source, constants).unwrap_or_else(|e| panic!("{what}: {e}"));
            assert!(module.overrides.is_empty(), "{what}: overrides left");
            assert_eq!(module.entry_points.len(), 1, "{what}");
            Validator::new(ValidationFlags::all(), Capabilities::all())
                .validate(&module)
                .unwrap_or_else(|e| panic!("{what}: the specialised module is invalid: {e:?}"));
        }
    }
}

#[test]
fn pruning_removes_the_materials_a_scene_lacks() {
    let source = KERNEL_SOURCES.iter().find(|k| k.name == "connect_ellipsoidal" && k.feature.is_none()).unwrap();
    let materials = |dielectric: f64, plastic: f64| {
        let constants = [("HAS_DIELECTRIC", dielectric), ("HAS_PLASTIC", plastic), ("HAS_MEDIA", 0.0), ("NLOS", 0.0)];
        function_names(&specialise(source, &constants).unwrap())
    };
    let diffuse = materials(0.0, 0.0);
    let glass = materials(1.0, 0.0);
    let plastic = materials(0.0, 1.0);
    for name in ["rough_dielectric_pdf", "rough_dielectric_eval", "fresnel_dielectric"] {
        assert!(!diffuse.contains(&name.to_owned()), "{name} kept without dielectrics: {diffuse:?}");
        assert!(glass.contains(&name.to_owned()), "{name} removed with dielectrics: {glass:?}");
    }
    assert!(!diffuse.iter().any(|n| n.starts_with("plastic_")), "plastic kept without plastic: {diffuse:?}");
    assert!(plastic.iter().any(|n| n.starts_with("plastic_")), "plastic removed with plastic: {plastic:?}");
    assert!(diffuse.len() < glass.len(), "{} functions without dielectrics, {} with", diffuse.len(), glass.len());
}

/// Renders `args` to an NPY, pruned or not, and returns its values.
fn render(dir: &Path, name: &str, args: &[&str], pruning: bool) -> Vec<f32> {
    let out = dir.join(format!("{name}_{}.npy", if pruning { "pruned" } else { "unpruned" }));
    let mut command = Command::new(env!("CARGO_BIN_EXE_gatetrace"));
    command.arg("render").args(args).args(["--seed", "7", "-o", out.to_str().unwrap()]);
    if !pruning {
        command.env("GATETRACE_NO_PRUNING", "1");
    }
    let o = command.output().expect("the binary runs");
    assert!(o.status.success(), "{name}: {}", String::from_utf8_lossy(&o.stderr));
    gatetrace::film::output::read_npy_f32(&out).unwrap().1
}

#[test]
fn pruned_kernels_render_the_same_bits_as_the_driver_specialising() {
    let dir = common::scratch_dir("specialise");
    let scene = |file: &str| common::repo_path("assets/scenes").join(file).to_str().unwrap().to_owned();
    let (glossy, glass, fog, letter) = (
        scene("cornell_box_glossy.gltf"),
        scene("glass_plastic_box.xml"),
        scene("fog_box.xml"),
        scene("nlos_letter.gltf"),
    );
    let small = ["--res", "16x16", "--spp", "2", "--max-bounces", "4"];
    let cases: [(&str, Vec<&str>); 4] = [
        ("path_transient", vec![&glossy, "--method", "path", "--gate", "transient:3.0,0.1,4"]),
        ("combined_glass_cw", vec![&glass, "--method", "combined", "--gate", "cw:1e8,30", "--ellipsoidal-share", "1"]),
        ("ellipsoidal_fog", vec![&fog, "--method", "ellipsoidal", "--gate", "box:3.16..3.2"]),
        (
            "nlos",
            [vec![&letter, "--nlos", "confocal", "--res", "4x4"], vec!["--gate", "transient:3.002ns,16ps,20"]].concat(),
        ),
    ];
    for (name, args) in cases {
        let args: Vec<&str> =
            if name == "nlos" { [args, vec!["--max-bounces", "3"]].concat() } else { [args, small.to_vec()].concat() };
        let pruned = render(&dir, name, &args, true);
        let unpruned = render(&dir, name, &args, false);
        assert!(pruned.iter().any(|&v| v > 0.0), "{name}: a black image");
        let same = pruned.iter().zip(&unpruned).all(|(a, b)| a.to_bits() == b.to_bits());
        assert!(same && pruned.len() == unpruned.len(), "{name}: the pruned kernels render another image");
    }
}
