//! Previews: a film as an 8-bit sRGB PNG for a quick look (`render --out x.png`). The tone
//! curve is the viewer's linear one (`shaders/kernels/resolve_display.wesl`, of which
//! [`tone_srgb`] is the CPU twin): value times 2^exposure, negative values (CW gates) as their
//! magnitude, clamped to [0, 1], sRGB-encoded. A transient film becomes a contact sheet: at most
//! [`MAX_TILES`] tiles, each the sum of a run of consecutive bins, in reading order, all at one
//! exposure so that tiles compare; or one chosen bin.
//!
//! A preview is for looking, not for measuring: keep `.exr` or `.npy` for the data. Its
//! metadata (PNG iTXt chunks `gatetrace.KEY`, values as in the JSON sidecar) says what it shows
//! and at what exposure.

use std::path::Path;

use anyhow::{Context as _, Result, ensure};

use super::{Film, Metadata, replace_atomically};

/// Most tiles of a contact sheet (8 x 8).
pub const MAX_TILES: u32 = 64;
/// Pixels between a contact sheet's tiles (dark grey).
pub const TILE_GAP: u32 = 2;
const GAP_GREY: u8 = 48;

/// What a preview shows, as the command line's `--preview-bin` and `--exposure` ask.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PreviewSettings {
    /// One bin of a transient film (from 0); None: the image, or the contact sheet of all bins.
    pub bin: Option<u32>,
    /// Exposure (EV: values are scaled by 2^EV before the tone curve); None: automatic, the
    /// 99th percentile of the nonzero magnitudes shown maps to 1 ([`auto_exposure_ev`]).
    pub exposure_ev: Option<f32>,
}

/// A tone-mapped picture: 8-bit sRGB RGB rows, top first.
#[derive(Clone, Debug)]
pub struct Preview {
    /// Width (pixels).
    pub width: u32,
    /// Height (pixels).
    pub height: u32,
    /// R, G, B bytes, row by row from the top.
    pub rgb: Vec<u8>,
    /// The exposure applied (EV).
    pub exposure_ev: f32,
    /// The film's bins each tile sums, [first, last] inclusive, in reading order (one entry for
    /// a single image or bin).
    pub tiles: Vec<[u32; 2]>,
    /// Tiles per row of the sheet.
    pub columns: u32,
}

/// Exposure (EV) that maps the 99th percentile of the nonzero magnitudes among `values` to 1;
/// None when every value is zero.
pub fn auto_exposure_ev(values: impl Iterator<Item = f32>) -> Option<f32> {
    let mut magnitudes: Vec<f32> = values.map(f32::abs).filter(|v| *v > 0.0 && v.is_finite()).collect();
    if magnitudes.is_empty() {
        return None;
    }
    magnitudes.sort_by(f32::total_cmp);
    Some(-magnitudes[(magnitudes.len() - 1) * 99 / 100].log2())
}

/// Linear-light value in [0, 1] to sRGB-encoded (IEC 61966-2-1).
pub fn srgb_encode(x: f32) -> f32 {
    if x <= 0.003_130_8 { 12.92 * x } else { 1.055 * x.powf(1.0 / 2.4) - 0.055 }
}

/// CPU twin of resolve_display's linear tone: |value| x `scale`, clamped to [0, 1], sRGB-encoded,
/// as a byte.
pub fn tone_srgb(value: f32, scale: f32) -> u8 {
    (srgb_encode((value.abs() * scale).clamp(0.0, 1.0)) * 255.0).round() as u8
}

/// The preview of `film` that `settings` asks for.
pub fn preview(film: &Film, settings: PreviewSettings) -> Result<Preview> {
    let (w, h, bins) = (film.width, film.height, film.bins);
    let tiles: Vec<[u32; 2]> = match settings.bin {
        Some(b) => {
            ensure!(b < bins, "--preview-bin {b}: the film has {bins} bin(s), 0 to {}", bins - 1);
            vec![[b, b]]
        }
        None => {
            let n = bins.min(MAX_TILES);
            (0..n).map(|t| [t * bins / n, (t + 1) * bins / n - 1]).collect()
        }
    };
    // Each tile's RGB values (pixel-major), summed over its bins.
    let pixels = (w * h) as usize;
    let values: Vec<Vec<f32>> = tiles
        .iter()
        .map(|&[first, last]| {
            let mut v = vec![0f32; pixels * 3];
            for p in 0..pixels {
                for b in first..=last {
                    let at = (p * bins as usize + b as usize) * 3;
                    for c in 0..3 {
                        v[p * 3 + c] += film.data[at + c];
                    }
                }
            }
            v
        })
        .collect();
    // An automatic exposure is rounded to 1/100 EV, so the metadata states it exactly.
    let exposure_ev = settings
        .exposure_ev
        .or_else(|| auto_exposure_ev(values.iter().flatten().copied()).map(|ev| (ev * 100.0).round() / 100.0))
        .unwrap_or(0.0);
    let scale = exposure_ev.exp2();
    let columns = (tiles.len() as f64).sqrt().ceil() as u32;
    let rows = (tiles.len() as u32).div_ceil(columns);
    let width = columns * w + (columns - 1) * TILE_GAP;
    let height = rows * h + (rows - 1) * TILE_GAP;
    let mut rgb = vec![GAP_GREY; (width * height * 3) as usize];
    for (t, v) in values.iter().enumerate() {
        let (x0, y0) = ((t as u32 % columns) * (w + TILE_GAP), (t as u32 / columns) * (h + TILE_GAP));
        for y in 0..h {
            for x in 0..w {
                let to = (((y0 + y) * width + x0 + x) * 3) as usize;
                let from = ((y * w + x) * 3) as usize;
                for c in 0..3 {
                    rgb[to + c] = tone_srgb(v[from + c], scale);
                }
            }
        }
    }
    Ok(Preview { width, height, rgb, exposure_ev, tiles, columns })
}

/// What a preview adds to its metadata: the exposure, the tone curve and what each tile shows.
pub fn preview_metadata(p: &Preview, bin_ranges: &[(f64, f64)]) -> serde_json::Value {
    let tiles: Vec<serde_json::Value> = p
        .tiles
        .iter()
        .map(|&[first, last]| {
            let mut tile = serde_json::json!({ "bins": [first, last] });
            if let (Some(start), Some(end)) = (bin_ranges.get(first as usize), bin_ranges.get(last as usize)) {
                tile["start_m"] = start.0.into();
                tile["end_m"] = end.1.into();
            }
            tile
        })
        .collect();
    // The f32 exposure as the decimal it prints as (0.1, not 0.10000000149011612).
    let ev: f64 = p.exposure_ev.to_string().parse().expect("a finite f32 prints as a number");
    serde_json::json!({
        "exposure_ev": ev,
        "scale": ev.exp2(),
        "tone": "value x scale, magnitude of negative values, clamped to [0, 1], sRGB-encoded 8 bits",
        "columns": p.columns,
        "tiles": tiles,
    })
}

/// Writes `film`'s preview to `path` (PNG), with `metadata` and the preview's own as iTXt
/// chunks `gatetrace.KEY` (strings as they are, other values as JSON). `bin_ranges`: the
/// [start, end) lengths (m) of a transient film's bins.
pub fn write_preview(
    path: &Path,
    film: &Film,
    metadata: &Metadata,
    bin_ranges: &[(f64, f64)],
    settings: PreviewSettings,
) -> Result<Preview> {
    let p = preview(film, settings)?;
    let mut text = metadata.clone();
    text.push(("preview".into(), preview_metadata(&p, bin_ranges)));
    let encode = |tmp: &Path| -> Result<()> {
        let file = std::fs::File::create(tmp)?;
        let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), p.width, p.height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        for (k, v) in &text {
            let value = match v {
                serde_json::Value::String(s) => s.clone(),
                other => other.to_string(),
            };
            encoder.add_itxt_chunk(format!("gatetrace.{k}"), value)?;
        }
        let mut writer = encoder.write_header()?;
        writer.write_image_data(&p.rgb)?;
        writer.finish()?;
        Ok(())
    };
    replace_atomically(path, encode).with_context(|| format!("{}: cannot write the PNG preview", path.display()))?;
    Ok(p)
}

/// The `gatetrace.KEY` text chunks of a PNG preview, as (KEY, value) with JSON values parsed.
pub fn read_preview_metadata(path: &Path) -> Result<Metadata> {
    let file = std::fs::File::open(path).with_context(|| format!("{}: cannot open", path.display()))?;
    let reader = png::Decoder::new(std::io::BufReader::new(file))
        .read_info()
        .with_context(|| format!("{}: not a PNG file", path.display()))?;
    let info = reader.info();
    let mut out = Metadata::new();
    let latin1 = info.uncompressed_latin1_text.iter().map(|t| (t.keyword.clone(), t.text.clone()));
    let utf8 = info.utf8_text.iter().filter_map(|t| Some((t.keyword.clone(), t.get_text().ok()?)));
    for (k, v) in latin1.chain(utf8) {
        if let Some(key) = k.strip_prefix("gatetrace.") {
            let value = serde_json::from_str(&v).unwrap_or(serde_json::Value::String(v));
            out.push((key.to_owned(), value));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn film(width: u32, height: u32, bins: u32, value: impl Fn(u32, u32, u32) -> f32) -> Film {
        let mut f = Film::zeroed(width, height, bins);
        for p in 0..width * height {
            for b in 0..bins {
                for c in 0..3 {
                    f.data[((p * bins + b) * 3 + c) as usize] = value(p, b, c);
                }
            }
        }
        f
    }

    #[test]
    fn the_tone_curve_is_the_viewers() {
        assert_eq!(tone_srgb(0.0, 1.0), 0);
        assert_eq!(tone_srgb(1.0, 1.0), 255);
        assert_eq!(tone_srgb(-4.0, 0.25), 255, "negative values show their magnitude");
        assert_eq!(tone_srgb(0.5, 1.0), 188, "sRGB encoding of 0.5");
        assert_eq!(tone_srgb(0.002, 1.0), 7, "the linear toe");
    }

    #[test]
    fn auto_exposure_maps_the_99th_percentile_to_one() {
        let values = (1..=1000).map(|i| i as f32 / 100.0);
        let ev = auto_exposure_ev(values.chain([0.0; 500])).unwrap();
        assert!((ev.exp2() * 9.90 - 1.0).abs() < 1e-4, "{ev}");
        assert_eq!(auto_exposure_ev([0.0, 0.0].into_iter()), None);
    }

    #[test]
    fn a_transient_becomes_a_contact_sheet_of_summed_bins() {
        // 100 bins -> 64 tiles of one or two bins, 8 x 8 tiles of 3 x 2 pixels.
        let f = film(3, 2, 100, |_, b, _| b as f32);
        let p = preview(&f, PreviewSettings { bin: None, exposure_ev: Some(-8.0) }).unwrap();
        assert_eq!((p.columns, p.tiles.len()), (8, 64));
        assert_eq!((p.width, p.height), (8 * 3 + 7 * TILE_GAP, 8 * 2 + 7 * TILE_GAP));
        assert_eq!(p.tiles[0], [0, 0]);
        assert_eq!(p.tiles[63], [98, 99]);
        assert_eq!(p.tiles.iter().map(|t| t[1] - t[0] + 1).sum::<u32>(), 100, "every bin in one tile");
        // The last tile (bins 98 and 99: 197 x 2^-8) at the bottom right.
        let at = |x: u32, y: u32| p.rgb[((y * p.width + x) * 3) as usize];
        assert_eq!(at(p.width - 1, p.height - 1), tone_srgb(197.0, 2f32.powi(-8)));
        assert_eq!(at(3, 0), GAP_GREY, "the gap after the first tile");
        let one = preview(&f, PreviewSettings { bin: Some(8), exposure_ev: Some(-3.0) }).unwrap();
        assert_eq!((one.width, one.height, one.tiles.clone()), (3, 2, vec![[8, 8]]));
        assert!(one.rgb.iter().all(|&v| v == 255), "bin 8 at 2^-3 is white");
        assert!(preview(&f, PreviewSettings { bin: Some(100), exposure_ev: None }).is_err());
    }
}
