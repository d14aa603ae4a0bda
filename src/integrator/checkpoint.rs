//! Resumable renders. A [`RenderState`] is everything a render has accumulated between passes
//! (the film's sums, the sample counters, the random-sequence and target-length state, and a
//! method's host-side sums); `Integrator::save_state` takes it and `Integrator::load_state`
//! puts it into a freshly built integrator of the same settings, whose next passes then
//! continue exactly where the saved render stopped. A checkpoint file holds one state with a
//! fingerprint of the render (scene file, settings, version), so that a resume refuses a
//! state made by another render.
//!
//! File layout: the line `GATETRACE-CHECKPOINT`, one line of JSON (format, fingerprint,
//! counters, the names and byte lengths of the blobs), then the blobs back to back.

use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, anyhow, bail, ensure};
use serde_json::{Value, json};

use super::{Method, RenderSettings};

/// The first line of a checkpoint file.
const MAGIC: &[u8] = b"GATETRACE-CHECKPOINT\n";
/// Version of the layout of the header and blobs.
const FORMAT: u64 = 1;

/// What a render has accumulated, in a form that survives the process.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderState {
    /// The method whose integrator made the state (for `auto`, the method it chose).
    pub method: Method,
    /// Samples per pixel in the film.
    pub samples_in_film: u64,
    /// Index of the next sample to trace.
    pub next_sample: u64,
    /// Seconds of rendering so far (a time budget counts them).
    pub rendering_seconds: f64,
    /// Named byte blobs: device buffers and host-side values, as each integrator names them.
    pub blobs: Vec<(String, Vec<u8>)>,
}

impl RenderState {
    /// The blob called `name` (an error naming it when the state lacks it).
    pub fn blob(&self, name: &str) -> Result<&[u8]> {
        self.blobs
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, b)| b.as_slice())
            .ok_or_else(|| anyhow!("the checkpoint has no `{name}`: it was made by another kind of render"))
    }

    /// The blob called `name` as `count` values of T.
    pub fn values<T: bytemuck::Pod>(&self, name: &str, count: usize) -> Result<Vec<T>> {
        let bytes = self.blob(name)?;
        ensure!(
            bytes.len() == count * size_of::<T>(),
            "the checkpoint's `{name}` holds {} bytes, this render's {}: it was made by another render",
            bytes.len(),
            count * size_of::<T>()
        );
        Ok(bytemuck::pod_collect_to_vec(bytes))
    }

    /// The blob called `name` as values of T, however many it holds.
    pub fn all_values<T: bytemuck::Pod>(&self, name: &str) -> Result<Vec<T>> {
        let bytes = self.blob(name)?;
        ensure!(bytes.len() % size_of::<T>() == 0, "the checkpoint's `{name}` is cut off");
        Ok(bytemuck::pod_collect_to_vec(bytes))
    }

    /// Adds blob `name` holding `values`.
    pub fn push<T: bytemuck::Pod>(&mut self, name: &str, values: &[T]) {
        self.blobs.push((name.to_owned(), bytemuck::cast_slice(values).to_vec()));
    }
}

/// Where the checkpoint of the render written to `out` lives: beside it, `OUT.checkpoint`.
pub fn checkpoint_path(out: &Path) -> PathBuf {
    let mut name = out.as_os_str().to_owned();
    name.push(".checkpoint");
    PathBuf::from(name)
}

/// What identifies a render: the scene file (its path and a hash of its bytes), every setting
/// (`RenderSettings`, the seed included; not the budget), gatetrace's version, and `extra`
/// (e.g. an animation time or a camera override). Equal fingerprints continue each other.
pub fn fingerprint(
    scene: &Path,
    settings: &RenderSettings,
    extra: &[(&str, String)],
) -> Result<BTreeMap<String, String>> {
    let bytes = std::fs::read(scene).with_context(|| format!("{}: cannot read the scene file", scene.display()))?;
    let mut f = BTreeMap::new();
    f.insert("gatetrace_version".into(), env!("CARGO_PKG_VERSION").into());
    f.insert("scene".into(), scene.display().to_string());
    f.insert("scene_fnv1a64".into(), format!("{:016x}", fnv1a64(&bytes)));
    f.insert("settings".into(), format!("{settings:?}"));
    for (k, v) in extra {
        f.insert((*k).into(), v.clone());
    }
    Ok(f)
}

/// FNV-1a, 64 bits: a fast hash that tells a changed scene file from the one a checkpoint
/// was made from (not a cryptographic hash).
fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3))
}

/// Writes `state` with its `fingerprint` to `path` (atomically: an interrupted write never
/// leaves a torn checkpoint).
pub fn write_checkpoint(path: &Path, fingerprint: &BTreeMap<String, String>, state: &RenderState) -> Result<()> {
    write_state_file(path, fingerprint, state, serde_json::Map::new())
}

/// [`write_checkpoint`] with `extra` entries in the header (a shard's index and metadata).
pub fn write_state_file(
    path: &Path,
    fingerprint: &BTreeMap<String, String>,
    state: &RenderState,
    extra: serde_json::Map<String, Value>,
) -> Result<()> {
    let mut header = json!({
        "format": FORMAT,
        "fingerprint": fingerprint,
        "method": state.method.name(),
        "samples_in_film": state.samples_in_film,
        "next_sample": state.next_sample,
        "rendering_seconds": state.rendering_seconds,
        "blobs": state.blobs.iter().map(|(n, b)| json!({"name": n, "bytes": b.len()})).collect::<Vec<_>>(),
    });
    header.as_object_mut().expect("an object").extend(extra);
    let write = |tmp: &Path| -> Result<()> {
        let mut file = std::io::BufWriter::new(std::fs::File::create(tmp)?);
        file.write_all(MAGIC)?;
        file.write_all(serde_json::to_string(&header)?.as_bytes())?;
        file.write_all(b"\n")?;
        for (_, blob) in &state.blobs {
            file.write_all(blob)?;
        }
        file.into_inner().map_err(|e| e.into_error())?.sync_all()?;
        Ok(())
    };
    crate::film::output::replace_atomically(path, write)
        .with_context(|| format!("{}: cannot write the checkpoint", path.display()))
}

/// Reads the checkpoint at `path` and checks that it was made by the render `fingerprint`
/// describes; the error names the file and the first difference.
pub fn read_checkpoint(path: &Path, fingerprint: &BTreeMap<String, String>) -> Result<RenderState> {
    let (saved, state, _) = read_state_file(path)?;
    check_fingerprint(path, "the checkpoint was made by another render", &saved, fingerprint)?;
    Ok(state)
}

/// An error "`path`: `problem` (key: `A` then, `B` now)" for the first entry where the
/// fingerprint `saved` differs from `now` (entries of either).
pub fn check_fingerprint(
    path: &Path,
    problem: &str,
    saved: &BTreeMap<String, String>,
    now: &BTreeMap<String, String>,
) -> Result<()> {
    for key in now.keys().chain(saved.keys()) {
        let then = saved.get(key).map(String::as_str).unwrap_or("(none)");
        let value = now.get(key).map(String::as_str).unwrap_or("(none)");
        if then != value {
            bail!("{}: {problem} ({key}: {})", path.display(), first_difference(then, value));
        }
    }
    Ok(())
}

/// Reads a state file (a checkpoint or a shard): its fingerprint, its state and its whole
/// header (for the entries `write_state_file` added).
pub fn read_state_file(path: &Path) -> Result<(BTreeMap<String, String>, RenderState, Value)> {
    let name = path.display();
    let bytes = std::fs::read(path).with_context(|| format!("{name}: cannot read the checkpoint"))?;
    let body = bytes.strip_prefix(MAGIC).ok_or_else(|| anyhow!("{name}: not a gatetrace checkpoint"))?;
    let end =
        body.iter().position(|&b| b == b'\n').ok_or_else(|| anyhow!("{name}: the checkpoint's header is cut off"))?;
    let header: Value = serde_json::from_slice(&body[..end])
        .map_err(|e| anyhow!("{name}: the checkpoint's header is not valid: {e}"))?;
    let bad = |what: &str| anyhow!("{name}: the checkpoint's header lacks a valid `{what}`");
    let format = header["format"].as_u64().ok_or_else(|| bad("format"))?;
    ensure!(format == FORMAT, "{name}: checkpoint format {format}, this gatetrace reads format {FORMAT}");
    let saved: BTreeMap<String, String> =
        serde_json::from_value(header["fingerprint"].clone()).map_err(|_| bad("fingerprint"))?;
    let method = match header["method"].as_str().ok_or_else(|| bad("method"))? {
        "path" => Method::Path,
        "direct" => Method::Direct,
        "ellipsoidal" => Method::Ellipsoidal,
        other => bail!("{name}: the checkpoint names an unknown method `{other}`"),
    };
    let mut data = &body[end + 1..];
    let mut blobs = Vec::new();
    for b in header["blobs"].as_array().ok_or_else(|| bad("blobs"))? {
        let blob_name = b["name"].as_str().ok_or_else(|| bad("blobs"))?;
        let len = b["bytes"].as_u64().ok_or_else(|| bad("blobs"))? as usize;
        ensure!(len <= data.len(), "{name}: the checkpoint is cut off in `{blob_name}`");
        blobs.push((blob_name.to_owned(), data[..len].to_vec()));
        data = &data[len..];
    }
    ensure!(data.is_empty(), "{name}: {} bytes follow the checkpoint's last blob", data.len());
    let state = RenderState {
        method,
        samples_in_film: header["samples_in_film"].as_u64().ok_or_else(|| bad("samples_in_film"))?,
        next_sample: header["next_sample"].as_u64().ok_or_else(|| bad("next_sample"))?,
        rendering_seconds: header["rendering_seconds"].as_f64().ok_or_else(|| bad("rendering_seconds"))?,
        blobs,
    };
    Ok((saved, state, header))
}

/// The state of the render whose disjoint slices of samples `parts` hold (shards): the sums of
/// their films (`film` and `splat_film`, exact fixed point, so the result is the unsplit
/// render's bit for bit) and their samples. Everything else (method, parameters, target
/// visits, pilot) must be equal in every part; `names` name the parts in errors.
pub fn merge_states(parts: &[RenderState], names: &[String]) -> Result<RenderState> {
    let first = parts.first().ok_or_else(|| anyhow!("no parts to merge"))?;
    let summed = ["film", "splat_film"];
    let mut merged = first.clone();
    for (part, name) in parts.iter().zip(names).skip(1) {
        ensure!(
            part.method == first.method,
            "{name}: rendered with {}, {} with {}",
            part.method.name(),
            names[0],
            first.method.name()
        );
        let layout = |s: &RenderState| s.blobs.iter().map(|(n, b)| (n.clone(), b.len())).collect::<Vec<_>>();
        ensure!(layout(part) == layout(first), "{name}: its sums do not have the shape of {}'s", names[0]);
        for ((blob_name, sum), (_, add)) in merged.blobs.iter_mut().zip(&part.blobs) {
            if summed.contains(&blob_name.as_str()) {
                for (a, b) in sum.chunks_exact_mut(16).zip(add.chunks_exact(16)) {
                    let total = i128::from_le_bytes(a.try_into().unwrap())
                        .wrapping_add(i128::from_le_bytes(b.try_into().unwrap()));
                    a.copy_from_slice(&total.to_le_bytes());
                }
            } else {
                ensure!(
                    sum == add,
                    "{name}: its `{blob_name}` differs from {}'s: the parts are not slices of one render",
                    names[0]
                );
            }
        }
        merged.samples_in_film += part.samples_in_film;
        merged.next_sample = merged.next_sample.max(part.next_sample);
        merged.rendering_seconds += part.rendering_seconds;
    }
    Ok(merged)
}

/// "`A` then, `B` now" for the first comma-separated field where two fingerprint values
/// differ (the whole values when they have no commas).
fn first_difference(then: &str, now: &str) -> String {
    let (a, b): (Vec<&str>, Vec<&str>) = (then.split(", ").collect(), now.split(", ").collect());
    let i = a.iter().zip(&b).position(|(x, y)| x != y).unwrap_or(a.len().min(b.len()));
    let pick = |v: &[&str]| v.get(i).copied().unwrap_or("(nothing)").to_owned();
    format!("`{}` then, `{}` now", pick(&a), pick(&b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checkpoints_round_trip_and_refuse_other_renders() {
        let dir = std::env::temp_dir().join(format!("gatetrace_checkpoint_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("x.npy.checkpoint");
        let mut state = RenderState {
            method: Method::Direct,
            samples_in_film: 12,
            next_sample: 20,
            rendering_seconds: 1.5,
            blobs: Vec::new(),
        };
        state.push("film", &[1.0f32, 2.0, 3.0]);
        state.push("empty", &[] as &[u32]);
        state.push("sums", &[0.25f64]);
        let f: BTreeMap<String, String> = [("settings".to_string(), "a, b, c".to_string())].into();
        write_checkpoint(&path, &f, &state).unwrap();
        assert_eq!(read_checkpoint(&path, &f).unwrap(), state);
        assert_eq!(state.values::<f32>("film", 3).unwrap(), vec![1.0, 2.0, 3.0]);
        assert!(state.values::<f32>("film", 4).is_err());

        let other: BTreeMap<String, String> = [("settings".to_string(), "a, x, c".to_string())].into();
        let e = format!("{:#}", read_checkpoint(&path, &other).unwrap_err());
        assert!(e.contains("x.npy.checkpoint") && e.contains("another render (settings: `b` then, `x` now)"), "{e}");

        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 3]).unwrap();
        let e = format!("{:#}", read_checkpoint(&path, &f).unwrap_err());
        assert!(e.contains("cut off in `sums`"), "{e}");
        std::fs::write(&path, b"hello").unwrap();
        assert!(format!("{:#}", read_checkpoint(&path, &f).unwrap_err()).contains("not a gatetrace checkpoint"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
