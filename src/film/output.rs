//! Writing (and reading back) films: OpenEXR with one layer per transient bin and the metadata
//! as string attributes, or NumPy `.npy` (float32 [H, W, 3] or [H, W, T, 3]) with a JSON sidecar.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, bail};

use super::Film;
pub use super::{Metadata, replace_atomically};

/// Output file formats, chosen by the file name's extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputFormat {
    /// OpenEXR.
    Exr,
    /// NumPy `.npy` with a `.json` metadata sidecar.
    Npy,
    /// A tone-mapped 8-bit sRGB preview (`super::preview`), its metadata in text chunks.
    Png,
}

impl OutputFormat {
    /// The format of `path` (`.exr`, `.npy` or `.png`, any case).
    pub fn of(path: &Path) -> Result<Self> {
        match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
            Some("exr") => Ok(Self::Exr),
            Some("npy") => Ok(Self::Npy),
            Some("png") => Ok(Self::Png),
            _ => bail!(
                "{}: unknown output format: the file name must end in .exr or .npy (data), or .png (a preview)",
                path.display()
            ),
        }
    }
}

/// Checks before a render that `path` can be written: its directory exists (or is created, with
/// `create_directory`), and the file opens for writing (a file that did not exist is removed
/// again). A missing directory is an error naming it: a mistyped path never creates directories.
pub fn check_writable(path: &Path, create_directory: bool) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        if create_directory {
            std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create the directory", dir.display()))?;
        } else if !dir.is_dir() {
            bail!(
                "{}: no such directory (for the output {}): create it, or pass --mkdir to have it created",
                dir.display(),
                path.display()
            );
        }
    }
    let existed = path.exists();
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .with_context(|| format!("{}: cannot write the output file", path.display()))?;
    if !existed {
        let _ = std::fs::remove_file(path);
    }
    Ok(())
}

/// Writes `film` to `path`; the format follows the extension (`.exr`, `.npy`, or `.png` for a
/// preview with the default [`super::preview::PreviewSettings`]).
/// `bin_ranges` are the [start, end) lengths (m) of transient bins, for EXR layer attributes.
pub fn write_film(path: &Path, film: &Film, metadata: &Metadata, bin_ranges: &[(f64, f64)]) -> Result<()> {
    write_film_with(path, film, metadata, bin_ranges, &serde_json::Map::new())
}

/// [`write_film`] with `extras`, structured values added to an NPY file's JSON sidecar (an EXR
/// file gets them as JSON text attributes).
pub fn write_film_with(
    path: &Path,
    film: &Film,
    metadata: &Metadata,
    bin_ranges: &[(f64, f64)],
    extras: &serde_json::Map<String, serde_json::Value>,
) -> Result<()> {
    if !film.all_finite() {
        bail!("refusing to write {}: the film holds non-finite values", path.display());
    }
    match OutputFormat::of(path)? {
        OutputFormat::Exr => {
            let mut metadata = metadata.clone();
            metadata.extend(extras.iter().map(|(k, v)| (k.clone(), v.clone())));
            write_exr(path, film, &metadata, bin_ranges)
        }
        OutputFormat::Npy => {
            write_npy(path, film)?;
            write_sidecar(path, metadata, extras)
        }
        OutputFormat::Png => {
            let mut metadata = metadata.clone();
            metadata.extend(extras.iter().map(|(k, v)| (k.clone(), v.clone())));
            super::preview::write_preview(path, film, &metadata, bin_ranges, Default::default()).map(|_| ())
        }
    }
}

/// Writes the JSON sidecar of `npy`: one object of `metadata` and `extras`.
pub fn write_sidecar(
    npy: &Path,
    metadata: &Metadata,
    extras: &serde_json::Map<String, serde_json::Value>,
) -> Result<()> {
    let sidecar = sidecar_path(npy);
    let mut map: serde_json::Map<String, serde_json::Value> =
        metadata.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
    map.extend(extras.clone());
    let text = serde_json::to_string_pretty(&map)? + "\n";
    replace_atomically(&sidecar, |tmp| std::fs::write(tmp, &text).map_err(Into::into))
        .with_context(|| format!("{}: cannot write the metadata", sidecar.display()))
}

/// `x.npy` -> `x.json`.
pub fn sidecar_path(npy: &Path) -> PathBuf {
    npy.with_extension("json")
}

fn write_exr(path: &Path, film: &Film, metadata: &Metadata, bin_ranges: &[(f64, f64)]) -> Result<()> {
    use exr::prelude::*;
    let (w, h) = (film.width as usize, film.height as usize);
    let mut attributes = ImageAttributes::new(IntegerBounds::from_dimensions((w, h)));
    for (k, v) in metadata {
        let text = match v {
            serde_json::Value::String(s) => s.clone(),
            other => other.to_string(),
        };
        attributes
            .other
            .insert(Text::from(format!("gatetrace.{k}").as_str()), AttributeValue::Text(Text::from(text.as_str())));
    }
    let bins = film.bins as usize;
    let layers: Vec<_> = (0..bins)
        .map(|b| {
            let channel = |c: usize| -> Vec<f32> { (0..w * h).map(|p| film.data[(p * bins + b) * 3 + c]).collect() };
            let mut layer_attributes = LayerAttributes::default();
            if bins > 1 {
                layer_attributes.layer_name = Some(Text::from(format!("bin{b:05}").as_str()));
                if let Some(&(start, end)) = bin_ranges.get(b) {
                    let range = format!("[{start}, {end}) m of optical path");
                    layer_attributes
                        .other
                        .insert(Text::from("gatetrace.bin_range"), AttributeValue::Text(Text::from(range.as_str())));
                }
            }
            Layer::new(
                (w, h),
                layer_attributes,
                Encoding::FAST_LOSSLESS,
                AnyChannels::sort(SmallVec::from_vec(vec![
                    AnyChannel::new("R", FlatSamples::F32(channel(0))),
                    AnyChannel::new("G", FlatSamples::F32(channel(1))),
                    AnyChannel::new("B", FlatSamples::F32(channel(2))),
                ])),
            )
        })
        .collect();
    let image = Image::from_layers(attributes, layers);
    replace_atomically(path, |tmp| image.write().non_parallel().to_file(tmp).map_err(Into::into))
        .with_context(|| format!("{}: cannot write the EXR file", path.display()))
}

/// Writes float32 [H, W, 3] (one bin) or [H, W, T, 3] in NumPy's format (version 1.0, C order).
pub fn write_npy(path: &Path, film: &Film) -> Result<()> {
    let shape = if film.bins == 1 {
        vec![film.height as usize, film.width as usize, 3]
    } else {
        vec![film.height as usize, film.width as usize, film.bins as usize, 3]
    };
    write_npy_f32(path, &shape, &film.data)
}

/// Writes a little-endian float32 C-order array.
pub fn write_npy_f32(path: &Path, shape: &[usize], data: &[f32]) -> Result<()> {
    assert_eq!(shape.iter().product::<usize>(), data.len());
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let tuple = if dims.len() == 1 { format!("({},)", dims[0]) } else { format!("({})", dims.join(", ")) };
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {tuple}, }}");
    // Magic (6) + version (2) + length (2) + header + '\n' is a multiple of 64.
    let total = 10 + header.len() + 1;
    header.push_str(&" ".repeat(total.next_multiple_of(64) - total));
    header.push('\n');
    let mut bytes = Vec::with_capacity(10 + header.len() + data.len() * 4);
    bytes.extend_from_slice(b"\x93NUMPY\x01\x00");
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    for v in data {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    replace_atomically(path, |tmp| std::fs::write(tmp, &bytes).map_err(Into::into))
        .with_context(|| format!("{}: cannot write", path.display()))
}

/// The header of a C-order `.npy` file whose first bytes are `bytes`: (shape, dtype descr,
/// offset of the data). `path` names the file in errors.
pub fn read_npy_header(path: &Path, bytes: &[u8]) -> Result<(Vec<usize>, String, usize)> {
    let name = path.display();
    if bytes.len() < 12 || &bytes[..6] != b"\x93NUMPY" {
        bail!("{name}: not a .npy file");
    }
    let (header_len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 => (u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize, 12),
        v => bail!("{name}: unsupported .npy version {v}"),
    };
    let header = bytes.get(start..start + header_len).with_context(|| format!("{name}: truncated .npy header"))?;
    let header = std::str::from_utf8(header).with_context(|| format!("{name}: npy header"))?;
    if header.contains("'fortran_order': True") {
        bail!("{name}: Fortran-order arrays are not supported");
    }
    let descr = header.split("'descr':").nth(1).and_then(|s| s.split('\'').nth(1)).context("npy descr")?;
    let shape_text = header.split("'shape':").nth(1).and_then(|s| s.split(['(', ')']).nth(1)).context("npy shape")?;
    let shape: Vec<usize> = shape_text
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse())
        .collect::<Result<_, _>>()
        .with_context(|| format!("{name}: bad shape `{shape_text}`"))?;
    Ok((shape, descr.to_owned(), start + header_len))
}

/// Reads a little-endian float32 (or float64, converted) C-order `.npy` file: (shape, data).
pub fn read_npy_f32(path: &Path) -> Result<(Vec<usize>, Vec<f32>)> {
    let name = path.display();
    let bytes = std::fs::read(path).with_context(|| format!("{name}: cannot read"))?;
    let (shape, descr, offset) = read_npy_header(path, &bytes)?;
    let body = &bytes[offset..];
    let count: usize = shape.iter().product();
    let data: Vec<f32> = match descr.as_str() {
        "<f4" => body.chunks_exact(4).take(count).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect(),
        "<f8" => body.chunks_exact(8).take(count).map(|c| f64::from_le_bytes(c.try_into().unwrap()) as f32).collect(),
        other => bail!("{name}: unsupported dtype {other}"),
    };
    if data.len() != count {
        bail!("{name}: file is shorter than its shape {shape:?}");
    }
    Ok((shape, data))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn npy_round_trips() {
        let dir = std::env::temp_dir().join(format!("gatetrace_npy_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let film = Film { width: 3, height: 2, bins: 4, spp: 1, data: (0..72).map(|i| i as f32 * 0.5).collect() };
        let path = dir.join("cube.npy");
        write_npy(&path, &film).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!((bytes.len() - 72 * 4) % 64, 0, "header padded to 64 bytes");
        let (shape, data) = read_npy_f32(&path).unwrap();
        assert_eq!(shape, vec![2, 3, 4, 3]);
        assert_eq!(data, film.data);
        let bad = Film { data: vec![f32::NAN; 72], ..film };
        assert!(write_film(&path, &bad, &vec![], &[]).is_err(), "non-finite films are refused");
        assert_eq!(OutputFormat::of(Path::new("A.EXR")).unwrap(), OutputFormat::Exr);
        assert!(OutputFormat::of(Path::new("a.tiff")).is_err());
    }
}
