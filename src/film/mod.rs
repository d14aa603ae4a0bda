//! The film: per-pixel, per-bin radiance estimates, and their output as EXR or NPY with the
//! render's metadata.

pub mod gate;
pub mod output;
pub mod target;

pub use gate::{CwCode, Gate, GateKind};

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

/// Double-float accumulation (hi, lo) + value, |lo| <= ulp(hi) / 2: the CPU twin of the
/// kernels' film accumulation (`compensated_add` in `shaders/lib/chunked.wesl`). hi + lo is the
/// total, to about 48 significant bits.
pub fn compensated_add(acc: [f32; 2], value: f32) -> [f32; 2] {
    let s = acc[0] + value;
    let v = s - acc[0];
    let error = (acc[0] - (s - v)) + (value - v);
    let t = error + acc[1];
    let hi = s + t;
    [hi, t - (hi - s)]
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compensated_sums_do_not_drift() {
        // 2^22 additions of 0.1: a plain f32 sum is off by percents, the compensated one by
        // about one f32 ulp of the total.
        let n = 1 << 22;
        let (mut plain, mut acc) = (0.0f32, [0.0f32; 2]);
        for _ in 0..n {
            plain += 0.1;
            acc = compensated_add(acc, 0.1);
        }
        let exact = n as f64 * 0.1f32 as f64;
        assert!(((plain as f64 - exact) / exact).abs() > 1e-3, "the plain sum should drift");
        let total = acc[0] as f64 + acc[1] as f64;
        assert!(((total - exact) / exact).abs() < 2.0 * f32::EPSILON as f64, "{total} vs {exact}");
    }
}
