//! Target path lengths drawn from the gate, for ellipsoidal connections (DESIGN.md section 4.3):
//! every camera sample gets one target length tau with density p(tau) and the weight
//! W(tau) / p(tau) (signed for CW and table gates). CPU twin of shaders/lib/target_length.wesl.
//!
//! One scheme serves every gate: [lo, hi) (the gate's support within the path lengths the scene
//! allows) is cut into equal cells, each cell gets a mass bounding |W| on it (the largest of |W|
//! at its ends and middle, and at least 1e-6 of the largest mass, so that p > 0 wherever W may
//! be nonzero), and tau is drawn cell by mass, then uniformly within the cell. The weight uses
//! the exact W, so the estimate is unbiased however coarse the table: a box gate gets equal
//! masses (tau uniform, weight b - a), a Gaussian a close bound of its bell (8 sigma each side),
//! a CW gate the envelope |cos|.
//!
//! Transient gates are stratified instead: [lo, hi) is whole bins, and a pixel's samples visit
//! them in a fixed order from a random start, each uniformly within its bin and a bin's visits
//! spread over it by the golden-ratio sequence (`stratified_sample`), so n consecutive samples
//! meet each of the n bins once. The film then divides each bin by the samples it actually had
//! (`stratum_factors`) rather than by their expected number: with tau drawn uniformly (or by a
//! low-discrepancy sequence) a bin of a few samples per pixel has a count off by one in a
//! sizeable share of pixels, an error of 1 / count that dominates the variance of fine
//! transients rendered by ellipsoidal connections.

use super::gate::{Gate, gate_bin_position, gate_weight};
use crate::gpu::layout::{GateParams, TargetParams};
use crate::rng::pcg4d;

/// Cells of the target table.
pub const TARGET_CELLS: u32 = 1024;

/// Target-length sampling of one gate.
#[derive(Clone, Debug)]
pub struct TargetSampler {
    /// Parameters for the kernels.
    pub params: TargetParams,
    /// Cumulative masses, `cells + 1` values from 0 to 1.
    pub cdf: Vec<f32>,
    gate: GateParams,
    kind: super::gate::GateKind,
    table: Vec<[f32; 2]>,
}

impl TargetSampler {
    /// The sampler of `gate` for paths whose lengths lie in `path_range` (m); None when the gate
    /// has no support there (or is `none`, which has no finite support).
    pub fn new(gate: &Gate, path_range: (f64, f64)) -> Option<Self> {
        let (mut lo, mut hi) = match gate {
            Gate::None => return None,
            Gate::Box { start, end } => (*start, *end),
            Gate::Gaussian { mean, sigma } => (mean - 8.0 * sigma, mean + 8.0 * sigma),
            Gate::Cw { .. } => path_range,
            Gate::Table { points, .. } => (points.first()?.0, points.last()?.0),
            Gate::Transient { start, width, bins } => (*start, start + width * *bins as f64),
        };
        lo = lo.max(path_range.0);
        hi = hi.min(path_range.1);
        if !(hi > lo) {
            return None;
        }
        // Transient gates: whole bins, stratified (see `stratified_sample`).
        let mut strata = None;
        if let Gate::Transient { start, width, bins } = *gate {
            let first = ((lo - start) / width).floor().clamp(0.0, bins as f64 - 1.0) as u32;
            let end = (((hi - start) / width).ceil() as u32).clamp(first + 1, bins);
            (lo, hi) = (start + first as f64 * width, start + end as f64 * width);
            let n = end - first;
            if n <= MAX_STRATA {
                strata = Some((n, first));
            }
        }
        let g = gate.to_gpu();
        let kind = gate.kind();
        let table = gate.table();
        let w = |l: f64| gate_weight(kind, &g, &table, l as f32).abs() as f64;
        let h = (hi - lo) / TARGET_CELLS as f64;
        let mut masses: Vec<f64> = (0..TARGET_CELLS)
            .map(|i| {
                let a = lo + i as f64 * h;
                w(a).max(w(a + 0.5 * h)).max(w(a + h))
            })
            .collect();
        let top = masses.iter().cloned().fold(0.0, f64::max);
        if !(top > 0.0) {
            return None;
        }
        for m in &mut masses {
            *m = m.max(1e-6 * top);
        }
        let total: f64 = masses.iter().sum();
        let mut cdf = Vec::with_capacity(masses.len() + 1);
        let mut acc = 0.0;
        cdf.push(0.0);
        for m in &masses {
            acc += m;
            cdf.push((acc / total) as f32);
        }
        *cdf.last_mut().unwrap() = 1.0;
        let (strata, first_bin) = strata.unwrap_or((0, 0));
        let params = TargetParams {
            lo: lo as f32,
            hi: hi as f32,
            cells: TARGET_CELLS,
            strata,
            first_bin,
            stride: golden_stride(strata),
            ..Default::default()
        };
        Some(Self { params, cdf, gate: g, kind, table })
    }

    /// Target length tau (m) and 1 / p(tau) (m) for u in [0, 1) (twin of `sample_target_length`);
    /// the estimate's weight is W(tau) / p(tau).
    pub fn sample(&self, u: f32) -> (f32, f32) {
        let n = self.params.cells as usize;
        // The cell i with cdf[i] <= u < cdf[i + 1].
        let (mut lo, mut hi) = (0usize, n - 1);
        while lo < hi {
            let mid = (lo + hi).div_ceil(2);
            if self.cdf[mid] <= u {
                lo = mid;
            } else {
                hi = mid - 1;
            }
        }
        let i = lo;
        let mass = self.cdf[i + 1] - self.cdf[i];
        let frac = ((u - self.cdf[i]) / mass).clamp(0.0, 1.0);
        let h = (self.params.hi - self.params.lo) / n as f32;
        let length = self.params.lo + (i as f32 + frac) * h;
        // p(tau) = mass / h.
        (length, h / mass)
    }

    /// W(tau) of the sampler's gate (m^0; signed for CW and table gates).
    pub fn weight(&self, length: f32) -> f32 {
        gate_weight(self.kind, &self.gate, &self.table, length)
    }

    /// Target length tau (m) and 1 / p(tau) (m) of sample `sample` of pixel `pixel` in a render
    /// with seed `seed` when the sampler is stratified (`params.strata` > 0; twin of
    /// `stratified_target_length`), and the bin it lies in.
    pub fn stratified_sample(&self, seed: u32, pixel: u32, sample: u32) -> (f32, f32, u32) {
        let t = &self.params;
        let bin = t.first_bin + stratum(t, seed, pixel, sample);
        // The r-th visit of the bin (r = sample / n) takes the r-th low-discrepancy number.
        let xi = target_u(pcg4d([pixel, bin, seed, TAU_STREAM])[0], sample / t.strata);
        let (p0, p1) = (self.gate.p0, self.gate.p1);
        let mut tau = p0 + (bin as f32 + xi) * p1;
        for _ in 0..8 {
            let x = gate_bin_position(&self.gate, tau);
            if x == bin as f32 {
                break;
            }
            tau = f32::from_bits(if x < bin as f32 { tau.to_bits() + 1 } else { tau.to_bits() - 1 });
        }
        (tau, t.strata as f32 * p1, bin)
    }
}

/// Most bins a transient gate's target lengths are stratified over (so that a pixel's stratum
/// fits 32-bit arithmetic); wider gates draw them from the table like the other gates.
pub const MAX_STRATA: u32 = 65_535;

/// Fourth word of the hashes that seed a pixel's target lengths (twin of the kernels' TAU_STREAM).
const TAU_STREAM: u32 = 0x7461_756e;

/// The target-length seed of the film after one with `seed` (`TargetParams::seed`): a film reset
/// draws new strata orders and offsets within bins, so that successive estimates of one render
/// are independent randomisations rather than continuations of one low-discrepancy sequence.
pub fn next_target_seed(seed: u32) -> u32 {
    pcg4d([seed, TAU_STREAM, 0, 1])[0]
}

/// The stride of the bin sequence over `n` strata: the integer nearest n (golden ratio - 1) that
/// is coprime to n, so n consecutive samples meet every bin once and fewer spread evenly.
pub fn golden_stride(n: u32) -> u32 {
    if n <= 2 {
        return 1;
    }
    let gcd = |mut a: u32, mut b: u32| {
        while b != 0 {
            (a, b) = (b, a % b);
        }
        a
    };
    let g = (n as f64 * 0.618_033_988_749_894_8).round() as u32;
    (0..n).flat_map(|d| [g + d, g.wrapping_sub(d)]).find(|&c| c > 0 && c < n && gcd(c, n) == 1).unwrap_or(1)
}

/// The stratum (0 .. strata, a bin after `first_bin`) of sample `sample` of pixel `pixel`:
/// (o + (sample mod n) stride) mod n with o a hash of the pixel and the seed (twin of the
/// kernels' `target_stratum`).
pub fn stratum(t: &TargetParams, seed: u32, pixel: u32, sample: u32) -> u32 {
    let n = t.strata;
    let offset = pcg4d([pixel, seed, TAU_STREAM, 0])[0] % n;
    (offset + (sample % n) * t.stride % n) % n
}

/// Film factors of a stratified render: `samples` samples per pixel from sample index
/// `first_sample` gave the pixel's stratum j `count_j` samples, where the film's division by
/// `samples` assumed samples / n; factor_j = samples / (n count_j) turns bin first_bin + j into
/// the mean over its own samples. That mean is unbiased only when every bin has a sample, so
/// this returns None when samples < n (the plain mean is unbiased too). Writes the factors of
/// pixel `pixel` into `factors` (n values).
pub fn stratum_factors(t: &TargetParams, seed: u32, pixel: u32, first_sample: u64, samples: u64, factors: &mut [f32]) -> Option<()> {
    let n = t.strata as u64;
    if n == 0 || samples < n {
        return None;
    }
    let (rounds, extra) = (samples / n, samples % n);
    let mut counts = vec![rounds as u32; n as usize];
    // n consecutive samples meet every stratum once (the stride is coprime to n); the `extra`
    // last ones meet `extra` strata once more.
    for k in 0..extra {
        counts[stratum(t, seed, pixel, (first_sample + rounds * n + k) as u32) as usize] += 1;
    }
    for (f, c) in factors.iter_mut().zip(counts) {
        *f = (samples as f64 / (n as f64 * c as f64)) as f32;
    }
    Some(())
}

/// The low-discrepancy uniform number of sample `sample` of a pixel whose random offset is
/// `offset` (bits of a uniform u32): fract(offset + sample x (golden ratio - 1)) in 32-bit fixed
/// point. Each sample's number is uniform (the offset is), and a pixel's samples spread evenly
/// over [0, 1), so its target lengths cover the gate evenly (twin of `target_u`).
pub fn target_u(offset: u32, sample: u32) -> f32 {
    let x = offset.wrapping_add(sample.wrapping_mul(2_654_435_769));
    (x >> 8) as f32 * (1.0 / 16_777_216.0)
}
