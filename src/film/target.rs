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

use super::gate::{Gate, gate_weight};
use crate::gpu::layout::{GateParams, TargetParams};

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
        let params = TargetParams { lo: lo as f32, hi: hi as f32, cells: TARGET_CELLS, reserved: 0 };
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
}

/// The low-discrepancy uniform number of sample `sample` of a pixel whose random offset is
/// `offset` (bits of a uniform u32): fract(offset + sample x (golden ratio - 1)) in 32-bit fixed
/// point. Each sample's number is uniform (the offset is), and a pixel's samples spread evenly
/// over [0, 1), so its target lengths cover the gate evenly (twin of `target_u`).
pub fn target_u(offset: u32, sample: u32) -> f32 {
    let x = offset.wrapping_add(sample.wrapping_mul(2_654_435_769));
    (x >> 8) as f32 * (1.0 / 16_777_216.0)
}
