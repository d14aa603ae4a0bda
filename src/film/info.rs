//! `gatetrace info FILE`: what an output holds, read back from the file and its metadata (the
//! NPY file's JSON sidecar, the EXR file's `gatetrace.*` attributes, the PNG preview's text
//! chunks): its layout, the gate in metres, the units and how it was rendered.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context as _, Result, bail};

use super::output::{Metadata, OutputFormat, sidecar_path};

/// An output file as `gatetrace info` reports it.
#[derive(Clone, Debug)]
pub struct FileInfo {
    /// The file's format.
    pub format: OutputFormat,
    /// Array shape (NPY: as stored; EXR: [height, width, layers, channels]; PNG: [height,
    /// width, 3] bytes).
    pub shape: Vec<usize>,
    /// What the axes of `shape` are, e.g. `[H, W, T, 3]: rows (top first), columns, bins, RGB`.
    pub layout: String,
    /// The render's metadata, as written beside or into the file (empty when there is none).
    pub metadata: Metadata,
    /// Where the metadata came from (the sidecar's path, or the file's own attributes).
    pub metadata_source: String,
}

/// Reads what `path` (an .npy, .exr or .png written by gatetrace) holds, without its pixels.
pub fn file_info(path: &Path) -> Result<FileInfo> {
    let name = path.display();
    ensure_exists(path)?;
    let format = OutputFormat::of(path)?;
    match format {
        OutputFormat::Npy => {
            let shape = npy_shape(path)?;
            let layout = match shape.len() {
                3 => "[H, W, 3]: rows (top first), columns, RGB".to_owned(),
                4 => "[H, W, T, 3]: rows (top first), columns, transient bins, RGB".to_owned(),
                5 => "[grid_y, grid_x, T, 3] of an NLOS capture with a leading axis".to_owned(),
                6 => "[laser_y, laser_x, grid_y, grid_x, T, 3]: an exhaustive NLOS capture".to_owned(),
                _ => format!("{} axes", shape.len()),
            };
            let sidecar = sidecar_path(path);
            let (metadata, metadata_source) = if sidecar.exists() {
                let text = std::fs::read_to_string(&sidecar)
                    .with_context(|| format!("{}: cannot read the sidecar", sidecar.display()))?;
                let map: serde_json::Map<String, serde_json::Value> =
                    serde_json::from_str(&text).with_context(|| format!("{}: not a JSON object", sidecar.display()))?;
                (map.into_iter().collect(), sidecar.display().to_string())
            } else {
                (Metadata::new(), format!("none: {} is missing", sidecar.display()))
            };
            Ok(FileInfo { format, shape, layout, metadata, metadata_source })
        }
        OutputFormat::Exr => {
            let meta = exr::meta::MetaData::read_from_file(path, false)
                .with_context(|| format!("{name}: not a readable OpenEXR file"))?;
            let header = meta.headers.first().with_context(|| format!("{name}: an EXR file without layers"))?;
            let size = header.layer_size;
            let layers = meta.headers.len();
            let channels = header.channels.list.len();
            let mut metadata = Metadata::new();
            for h in meta.headers.iter().take(1) {
                for (k, v) in h.shared_attributes.other.iter().chain(h.own_attributes.other.iter()) {
                    let (Some(key), exr::meta::attribute::AttributeValue::Text(text)) =
                        (k.to_string().strip_prefix("gatetrace.").map(str::to_owned), v)
                    else {
                        continue;
                    };
                    if key == "bin_range" {
                        continue;
                    }
                    let text = text.to_string();
                    let value = serde_json::from_str(&text).unwrap_or(serde_json::Value::String(text));
                    metadata.push((key, value));
                }
            }
            Ok(FileInfo {
                format,
                shape: vec![size.height(), size.width(), layers, channels],
                layout: format!(
                    "{layers} layer(s) of {}x{} pixels (one per transient bin, named binNNNNN, each with its \
                     gatetrace.bin_range), {channels} channels",
                    size.width(),
                    size.height()
                ),
                metadata,
                metadata_source: "the file's gatetrace.* attributes".into(),
            })
        }
        OutputFormat::Png => {
            let file = std::fs::File::open(path).with_context(|| format!("{name}: cannot open"))?;
            let reader = png::Decoder::new(std::io::BufReader::new(file))
                .read_info()
                .with_context(|| format!("{name}: not a PNG file"))?;
            let (w, h) = (reader.info().width as usize, reader.info().height as usize);
            Ok(FileInfo {
                format,
                shape: vec![h, w, 3],
                layout: "a tone-mapped 8-bit sRGB preview (not data: the metadata's `preview` says how it was made)"
                    .into(),
                metadata: super::preview::read_preview_metadata(path)?,
                metadata_source: "the file's gatetrace.* text chunks".into(),
            })
        }
    }
}

fn ensure_exists(path: &Path) -> Result<()> {
    if !path.is_file() {
        bail!("{}: no such file", path.display());
    }
    Ok(())
}

/// The shape in an .npy file's header (its first 64 KiB at most).
fn npy_shape(path: &Path) -> Result<Vec<usize>> {
    use std::io::Read as _;
    let mut head = Vec::new();
    let file = std::fs::File::open(path).with_context(|| format!("{}: cannot open", path.display()))?;
    file.take(65_536).read_to_end(&mut head).with_context(|| format!("{}: cannot read", path.display()))?;
    Ok(super::output::read_npy_header(path, &head)?.0)
}

impl FileInfo {
    /// The metadata value under `key`.
    pub fn get(&self, key: &str) -> Option<&serde_json::Value> {
        self.metadata.iter().find(|(k, _)| k == key).map(|(_, v)| v)
    }

    /// A few lines for a terminal: layout, gate, units, render, preview.
    pub fn to_text(&self, path: &Path) -> String {
        let mut s = String::new();
        let shape: Vec<String> = self.shape.iter().map(|d| d.to_string()).collect();
        let format = match self.format {
            OutputFormat::Npy => "NPY float32",
            OutputFormat::Exr => "OpenEXR float32",
            OutputFormat::Png => "PNG preview",
        };
        let _ = writeln!(s, "{}: {format} [{}]", path.display(), shape.join(", "));
        let _ = writeln!(s, "  layout: {}", self.layout);
        let text = |v: &serde_json::Value| match v {
            serde_json::Value::String(t) => t.clone(),
            other => other.to_string(),
        };
        if let Some(gate) = self.get("gate") {
            let described = self.get("gate_description").map(|d| format!(" = {}", text(d))).unwrap_or_default();
            let _ = writeln!(s, "  gate: {}{described}", text(gate));
        }
        if let Some(serde_json::Value::Object(p)) = self.get("gate_parameters") {
            let fields: Vec<String> = p
                .iter()
                .filter(|(k, _)| k.as_str() != "points_m_weight")
                .map(|(k, v)| format!("{k} {}", text(v)))
                .collect();
            let _ = writeln!(s, "  gate in metres: {}", fields.join(", "));
        }
        if let Some(units) = self.get("units") {
            let _ = writeln!(s, "  units: {}", text(units));
        }
        let render: Vec<String> = ["method", "spp", "seed", "max_bounces", "rendering_seconds", "adapter"]
            .iter()
            .filter_map(|k| self.get(k).map(|v| format!("{k} {}", text(v))))
            .collect();
        if !render.is_empty() {
            let _ = writeln!(s, "  render: {}", render.join(", "));
        }
        if let Some(scene) = self.get("scene") {
            let _ = writeln!(s, "  scene: {}", text(scene));
        }
        if let Some(p) = self.get("preview") {
            let _ = writeln!(
                s,
                "  preview: exposure {} EV (x{:.4}), {} tile(s), {} per row",
                p["exposure_ev"],
                p["scale"].as_f64().unwrap_or(f64::NAN),
                p["tiles"].as_array().map_or(0, Vec::len),
                p["columns"]
            );
        }
        if let Some(warning) = self.get("warning") {
            let _ = writeln!(s, "  warning: {}", text(warning));
        }
        let _ = writeln!(
            s,
            "  metadata: {} keys from {} (gatetrace info --json prints them all)",
            self.metadata.len(),
            self.metadata_source
        );
        s
    }

    /// Everything as one JSON object: format, shape, layout, metadata_source, metadata.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "format": format!("{:?}", self.format).to_ascii_lowercase(),
            "shape": self.shape,
            "layout": self.layout,
            "metadata_source": self.metadata_source,
            "metadata": self.metadata.iter().cloned().collect::<serde_json::Map<_, _>>(),
        })
    }
}
