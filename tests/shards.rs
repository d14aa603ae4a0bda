//! Shards: `render --shard I/N` renders a slice of each pixel's samples and `gatetrace merge`
//! adds the slices into the image of the unsplit render, bit for bit, with every method.

mod common;

use std::path::Path;
use std::process::Command;

fn gatetrace(args: &[&str]) {
    let o = Command::new(env!("CARGO_BIN_EXE_gatetrace")).args(args).output().expect("the binary runs");
    assert!(o.status.success(), "gatetrace {}: {}", args.join(" "), String::from_utf8_lossy(&o.stderr));
}

/// Renders `options` whole and as `count` shards (merged in reverse order), and checks that
/// the two files are identical and the image not black.
fn check_shards(dir: &Path, label: &str, options: &[&str], count: u32) {
    let whole = dir.join(format!("{label}_whole.npy"));
    let merged = dir.join(format!("{label}_merged.npy"));
    let mut args = vec!["render"];
    args.extend_from_slice(options);
    gatetrace(&[&args[..], &["--out", whole.to_str().unwrap()]].concat());
    let mut parts = Vec::new();
    for i in 0..count {
        let part = dir.join(format!("{label}.{i}.shard")).to_str().unwrap().to_owned();
        let shard = format!("{i}/{count}");
        gatetrace(&[&args[..], &["--shard", &shard, "--out", &part]].concat());
        parts.push(part);
    }
    let mut merge = vec!["merge".to_owned()];
    merge.extend(parts.iter().rev().cloned());
    merge.extend(["--out".to_owned(), merged.to_str().unwrap().to_owned()]);
    gatetrace(&merge.iter().map(String::as_str).collect::<Vec<_>>());
    let (a, b) = (std::fs::read(&whole).unwrap(), std::fs::read(&merged).unwrap());
    assert!(a == b, "{label}: the merged image differs from the unsplit render");
    let (_, data) = gatetrace::film::output::read_npy_f32(&merged).unwrap();
    assert!(data.iter().any(|&v| v > 0.0), "{label}: black image");
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(merged.with_extension("json")).unwrap()).unwrap();
    assert_eq!(meta["shards"], count);
}

#[test]
fn merged_shards_equal_the_unsplit_render_for_every_method() {
    let dir = common::scratch_dir("shards");
    let common_options = ["--res", "24x24", "--max-bounces", "4", "--samples-per-pass", "8", "--seed", "3"];
    for (label, method, gate, spp) in [
        ("path_steady", "path", "none", "30"),
        ("path_transient", "path", "transient:3.0,0.05,6", "30"),
        ("direct_box", "direct", "box:3.14..3.19", "30"),
        ("ellipsoidal_box", "ellipsoidal", "box:3.14..3.19", "30"),
        ("ellipsoidal_transient", "ellipsoidal", "transient:3.0,0.05,6", "30"),
    ] {
        let mut options: Vec<&str> = common_options.to_vec();
        options.extend(["--method", method, "--gate", gate, "--spp", spp]);
        check_shards(&dir, label, &options, 4);
    }
    // More shards than samples: some shards hold none.
    check_shards(&dir, "direct_sparse", &["--res", "8x8", "--max-bounces", "2", "--method", "direct", "--spp", "3"], 5);
}
