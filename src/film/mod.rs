//! The film: per-pixel, per-bin radiance estimates; the metadata every output carries and the
//! atomic file replacement every writer uses (here, below the writers, so that `output` and
//! `preview` do not import each other); the outputs themselves (EXR, NPY, PNG previews).

pub mod fixed;
pub mod gate;
pub mod info;
pub mod output;
pub mod preview;
pub mod target;

pub use gate::{CwCode, Gate, GateKind};

use std::path::{Path, PathBuf};

use anyhow::Result;

/// Pixel estimates of a render: `data[((y * width + x) * bins + bin) * 3 + channel]`, row 0 at
/// the top (the [H, W, T, 3] layout of mitransient). Values are bin-integrated radiance
/// (W m^-2 sr^-1) weighted by the gate's W, averaged over `spp` samples per pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Film {
    /// Width (pixels).
    pub width: u32,
    /// Height (pixels).
    pub height: u32,
    /// Bins per pixel (1 unless transient).
    pub bins: u32,
    /// Samples per pixel averaged.
    pub spp: u64,
    /// Values, [H, W, T, 3] row-major.
    pub data: Vec<f32>,
}

impl Film {
    /// A black film of `width` x `height` pixels and `bins` bins.
    pub fn zeroed(width: u32, height: u32, bins: u32) -> Self {
        Self { width, height, bins, spp: 0, data: vec![0.0; (width * height * bins * 3) as usize] }
    }

    /// Estimate of pixel (x, y), bin `bin`.
    pub fn get(&self, x: u32, y: u32, bin: u32) -> [f32; 3] {
        let i = (((y * self.width + x) * self.bins + bin) * 3) as usize;
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }

    /// The image summed over bins ([H, W, 3]).
    pub fn sum_bins(&self) -> Film {
        let mut out = Film::zeroed(self.width, self.height, 1);
        out.spp = self.spp;
        for p in 0..(self.width * self.height) as usize {
            for b in 0..self.bins as usize {
                for c in 0..3 {
                    out.data[p * 3 + c] += self.data[(p * self.bins as usize + b) * 3 + c];
                }
            }
        }
        out
    }

    /// Mean over all pixels (and bins summed) per channel.
    pub fn mean_rgb(&self) -> [f64; 3] {
        let mut acc = [0.0f64; 3];
        for (i, v) in self.data.iter().enumerate() {
            acc[i % 3] += *v as f64;
        }
        let n = (self.width * self.height) as f64;
        acc.map(|a| a / n)
    }

    /// True when every value is finite.
    pub fn all_finite(&self) -> bool {
        self.data.iter().all(|v| v.is_finite())
    }
}

/// What is recorded with every output: (key, value) pairs in order, e.g. scene, method, gate,
/// spp, seed, elapsed seconds, adapter. Values are typed: numbers are JSON numbers (with the
/// unit in the key or in `units`), flags booleans, absent settings null. An NPY file's JSON
/// sidecar holds them as they are; an EXR file's attributes are text (strings as they are, other
/// values as JSON).
pub type Metadata = Vec<(String, serde_json::Value)>;

/// Writes `path` through `write` into a temporary file beside it that is then renamed over it,
/// so that a reader (or a process killed while writing) never sees a partly written file.
pub fn replace_atomically(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".partial");
    let tmp = PathBuf::from(tmp);
    let result = write(&tmp).and_then(|_| std::fs::rename(&tmp, path).map_err(Into::into));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}
