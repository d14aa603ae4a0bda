//! Target path lengths drawn from the gate, for ellipsoidal connections (docs/design.md section 4.3):
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
//!
//! A pilot render can share out extra visits (`visit_tables`): a pixel's samples then run in
//! cycles of strata + extra, each bin visited once and as many more times as the pixel's
//! row of `target_visits` gives it (`target_visit`), with 1 / p scaled to match. A pixel whose
//! light arrives in a few hundred of 4000 bins then spends most samples there, while every bin
//! keeps a visit a cycle, and `stratum_factors` still divides each bin by its own visits.

use super::gate::{Gate, gate_bin_position, gate_weight};
use crate::gpu::layout::{GateParams, TargetParams};
use crate::rng::pcg4d;
use crate::units::SPEED_OF_LIGHT;

/// Cells of the target table (fewest, for cw codes).
pub const TARGET_CELLS: u32 = 1024;
/// Most cells of a cw code's target table.
pub const MAX_TARGET_CELLS: u32 = 1 << 16;

/// The largest |C| of a cw code's period `points` (see `CwCode::breakpoints`) at its breakpoints
/// with phase in [x0, x1] (periods; every breakpoint when the range spans a period).
fn largest_between(points: &[(f64, f64)], x0: f64, x1: f64) -> f64 {
    let whole = x1 - x0 >= 1.0;
    let (a, b) = (x0 - x0.floor(), x1 - x0.floor());
    points
        .iter()
        .filter(|&&(x, _)| whole || (x >= a && x <= b) || (x + 1.0 >= a && x + 1.0 <= b))
        .map(|p| p.1.abs())
        .fold(0.0, f64::max)
}

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
            Gate::Cw { .. } | Gate::CwCode { .. } => path_range,
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
        // A cw code gets cells of at most half its narrowest feature (up to MAX_TARGET_CELLS),
        // and each cell's exact bound (the largest |W| at its ends and at the code's
        // breakpoints within it).
        let code = match gate {
            Gate::CwCode { frequency_hz, phase_deg, code } => {
                Some((frequency_hz / SPEED_OF_LIGHT, phase_deg / 360.0, code.breakpoints()))
            }
            _ => None,
        };
        let cells = match &code {
            Some((per_metre, _, points)) => {
                let narrowest = points.windows(2).map(|p| p[1].0 - p[0].0).filter(|&d| d > 0.0).fold(1.0, f64::min);
                let periods = (hi - lo) * per_metre;
                ((periods * 2.0 / narrowest).ceil() as u64).clamp(TARGET_CELLS as u64, MAX_TARGET_CELLS as u64) as u32
            }
            None => TARGET_CELLS,
        };
        let h = (hi - lo) / cells as f64;
        let mut masses: Vec<f64> = (0..cells)
            .map(|i| {
                let a = lo + i as f64 * h;
                let sampled = w(a).max(w(a + 0.5 * h)).max(w(a + h));
                match &code {
                    Some((per_metre, phase, points)) => {
                        sampled.max(largest_between(points, a * per_metre + phase, (a + h) * per_metre + phase))
                    }
                    None => sampled,
                }
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
            cells,
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

    /// Target length tau (m) and 1 / p(tau) (m) of sample `sample` of pixel `pixel` when the
    /// sampler is stratified, with parameters `t` (this sampler's plus the film's seed, first
    /// sample and extra visits) and the pixel's row of `target_visits` (`row`, empty without
    /// extra visits), and the bin tau lies in (twin of `stratified_target_length`).
    pub fn stratified_sample(&self, t: &TargetParams, row: &[u32], pixel: u32, sample: u32) -> (f32, f32, u32) {
        let v = target_visit(t, row, pixel, sample);
        let bin = t.first_bin + v.stratum;
        // The r-th visit of the bin takes the r-th low-discrepancy number.
        let xi = target_u(pcg4d([pixel, bin, t.seed, TAU_STREAM])[0], v.visit);
        let (p0, p1) = (self.gate.p0, self.gate.p1);
        let mut tau = p0 + (bin as f32 + xi) * p1;
        for _ in 0..8 {
            let x = gate_bin_position(&self.gate, tau);
            if x == bin as f32 {
                break;
            }
            tau = f32::from_bits(if x < bin as f32 { tau.to_bits() + 1 } else { tau.to_bits() - 1 });
        }
        (tau, (t.strata + t.extra) as f32 * p1 / v.per_cycle as f32, bin)
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

/// The stride g of a sequence (o + i g) mod n over `n` positions (the bins' base visits, the
/// extra visits' positions): coprime to n, so n consecutive steps meet every position once, and
/// with the smallest partial quotients in the continued fraction of g / n, so that every prefix
/// of the sequence spreads evenly too (the largest gap of its first m points stays within a
/// small factor of n / m), taking the one nearest n (golden ratio - 1) among equals. The
/// integer nearest n (golden ratio - 1) alone can be poor: for n = 2100 it is 1297, whose
/// quotient 30 puts the first 280 points in pairs 2 apart with gaps of 47 between them.
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
    // The largest partial quotient of g / n (g coprime to n, 0 < g < n).
    let largest_quotient = |g: u32| {
        let (mut a, mut b, mut largest) = (n, g, 0);
        while b != 0 {
            largest = largest.max(a / b);
            (a, b) = (b, a % b);
        }
        largest
    };
    let g = (n as f64 * 0.618_033_988_749_894_8).round() as u32;
    // Candidates in order of distance from g; a quotient of 3 or less is as good as it gets
    // for most n, so the search stops at the first such one (or after 4096 candidates).
    let mut best: Option<(u32, u32)> = None;
    for c in (0..n.min(2048)).flat_map(|d| [g + d, g.wrapping_sub(d)]).filter(|&c| c > 0 && c < n && gcd(c, n) == 1) {
        let q = largest_quotient(c);
        if best.is_none_or(|(b, _)| q < b) {
            best = Some((q, c));
        }
        if q <= 3 {
            break;
        }
    }
    best.map_or(1, |(_, c)| c)
}

/// The stratum (0 .. strata, a bin after `first_bin`) of base visit `visit` of pixel `pixel`:
/// (o + (visit mod n) stride) mod n with o a hash of the pixel and the seed (twin of the
/// kernels' `target_stratum`).
pub fn stratum(t: &TargetParams, seed: u32, pixel: u32, visit: u32) -> u32 {
    let n = t.strata;
    let offset = pcg4d([pixel, seed, TAU_STREAM, 0])[0] % n;
    (offset + (visit % n) * t.stride % n) % n
}

/// Where a sample's stratified target length goes (twin of the kernels' `TargetVisit`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TargetVisit {
    /// The bin after `first_bin` (0 .. strata).
    pub stratum: u32,
    /// Index of the visit among the stratum's visits in the film.
    pub visit: u32,
    /// The stratum's visits per cycle: 1 plus its extra visits.
    pub per_cycle: u32,
}

/// What position `q` (0 .. strata + extra) of a cycle with extra visits holds: `(true, b)` for
/// the cycle's base visit b (0 .. strata), `(false, i)` for its extra visit i (0 .. extra). With
/// r = extra / strata (integer division), the first strata (r + 1) positions are runs of one base
/// visit and r extra ones, the rest extra visits: a capture that stops within its first cycle
/// (4000 bins and 60,000 extra visits a cycle) has still spent r / (r + 1) of its samples where
/// the allocation puts them, not all of them on one visit per bin (twin of the kernels'
/// `cycle_slot`).
pub fn cycle_slot(t: &TargetParams, q: u32) -> (bool, u32) {
    let run = t.extra / t.strata + 1;
    if q >= t.strata * run {
        (false, q - t.strata)
    } else if q.is_multiple_of(run) {
        (true, q / run)
    } else {
        (false, q - q / run - 1)
    }
}

/// Base visits among the first `q` positions of a cycle with extra visits (see `cycle_slot`).
pub fn base_visits_before(t: &TargetParams, q: u64) -> u64 {
    let (n, run) = (t.strata as u64, (t.extra / t.strata + 1) as u64);
    q.div_ceil(run).min(n)
}

/// The visit of sample `sample` (the kernels' index, from `t.film_first_sample`) of pixel
/// `pixel`, whose row of `target_visits` is `row` (`strata + 1` cumulative extra visits; empty
/// when `t.extra` = 0). A pixel's samples run in cycles of strata + extra: strata of a cycle's
/// positions (`cycle_slot`) visit each bin once (`stratum`), the other extra visit bin j
/// row[j + 1] - row[j] times in a golden-ratio order from a random start (twin of the kernels'
/// `target_visit`).
pub fn target_visit(t: &TargetParams, row: &[u32], pixel: u32, sample: u32) -> TargetVisit {
    let n = t.strata;
    let s = sample.wrapping_sub(t.film_first_sample);
    let cycle = n + t.extra;
    let (round, q) = (s / cycle, s % cycle);
    if t.extra == 0 {
        return TargetVisit { stratum: stratum(t, t.seed, pixel, s), visit: round, per_cycle: 1 };
    }
    let (base, index) = cycle_slot(t, q);
    let (j, k) = if base {
        (stratum(t, t.seed, pixel, round * n + index), 0)
    } else {
        let k = extra_position(t, pixel, index);
        (extra_stratum(row, k), k)
    };
    let per_cycle = 1 + row[j as usize + 1] - row[j as usize];
    let visit = round * per_cycle + if base { 0 } else { 1 + k - row[j as usize] };
    TargetVisit { stratum: j, visit, per_cycle }
}

/// Position (0 .. t.extra) of extra visit `i` of a cycle of pixel `pixel`.
fn extra_position(t: &TargetParams, pixel: u32, i: u32) -> u32 {
    extra_position_from(t, pcg4d([pixel, t.seed, TAU_STREAM, 1])[0] % t.extra, i)
}

/// Position (0 .. t.extra) of extra visit `i` of a cycle whose extra visits start at `start`.
fn extra_position_from(t: &TargetParams, start: u32, i: u32) -> u32 {
    (start + i * t.extra_stride % t.extra) % t.extra
}

/// The stratum j with row[j] <= k < row[j + 1].
fn extra_stratum(row: &[u32], k: u32) -> u32 {
    (row.partition_point(|&c| c <= k) - 1).min(row.len() - 2) as u32
}

/// Film factors of a stratified render after `samples` samples per pixel (prepared once per
/// film, then [`StratumFactors::pixel`] per pixel). The film's division by `samples` and the
/// weight 1 / p = cycle x width / per_cycle_j assumed samples x per_cycle_j / cycle samples in
/// stratum j; a factor samples per_cycle_j / (cycle c_j) turns the bin into its samples' sum
/// over c_j:
/// - c_j = count_j, the samples the bin had, when the bin is sure to have had one whatever the
///   random offsets: after the film's first cycle's base visits (`base_visits_before`) every
///   bin is, and before that a bin of e_j extra visits a cycle is once e_j is at least the
///   largest gap between the extra positions drawn so far (the golden-ratio positions of the
///   first X extra visits of a cycle leave gaps that do not depend on the random start). The
///   bin's estimate is then the mean over its own samples, free of the error of its count.
/// - c_j = B / strata + X e_j / extra, the expected count over the random offsets of the bins'
///   sequence and of the extra visits' order (B base and X extra visits so far), for the other
///   bins, which may not have had a sample yet; the estimate stays unbiased, if noisier.
///
/// Without extra visits, the film's first `strata` samples meet each bin once and before that
/// the factor is 1 (`pixel` returns None: nothing to change).
pub struct StratumFactors {
    t: TargetParams,
    samples: u64,
    /// Base and extra visits of the film's first cycle so far, when it has not ended.
    partial: Option<(u64, u64)>,
    /// The largest gap between the extra positions of the first cycle so far: a bin of at
    /// least this many extra visits a cycle has had one (u32::MAX: none is sure to).
    sure_from: u32,
}

impl StratumFactors {
    /// Factors of a film of `samples` samples per pixel with target parameters `t`.
    pub fn new(t: &TargetParams, samples: u64) -> Self {
        let (n, extra) = (t.strata as u64, t.extra as u64);
        let mut partial = None;
        let mut sure_from = u32::MAX;
        if n > 0 && extra > 0 && samples < n + extra {
            let base = base_visits_before(t, samples);
            if base < n {
                let x = samples - base;
                partial = Some((base, x));
                if x > 0 {
                    let mut points: Vec<u32> = (0..x as u32).map(|i| extra_position_from(t, 0, i)).collect();
                    points.sort_unstable();
                    let wrap = points[0] + t.extra - points[points.len() - 1];
                    sure_from = points.windows(2).map(|w| w[1] - w[0]).fold(wrap, u32::max);
                }
            }
        }
        StratumFactors { t: *t, samples, partial, sure_from }
    }

    /// Writes the factors of pixel `pixel`, whose row of `target_visits` is `row` (empty without
    /// extra visits), into `factors` (strata values); None when there is nothing to change.
    pub fn pixel(&self, row: &[u32], pixel: u32, factors: &mut [f32]) -> Option<()> {
        let t = &self.t;
        let n = t.strata as u64;
        let samples = self.samples;
        let cycle = n + t.extra as u64;
        if n == 0 || (samples < n && t.extra == 0) {
            return None;
        }
        let extra_of = |j: usize| if t.extra == 0 { 0 } else { row[j + 1] - row[j] };
        let factor = |j: usize, count: f64| (samples as f64 * (1 + extra_of(j)) as f64 / (cycle as f64 * count)) as f32;
        let rounds = samples / cycle;
        let mut counts: Vec<u64> = (0..n as usize).map(|j| rounds * (1 + extra_of(j)) as u64).collect();
        // Any cycle-long run of samples meets stratum j per_cycle_j times; the rest are counted.
        if self.partial.is_none() || (0..n as usize).any(|j| extra_of(j) >= self.sure_from) {
            for s in rounds * cycle..samples {
                counts[target_visit(t, row, pixel, t.film_first_sample.wrapping_add(s as u32)).stratum as usize] += 1;
            }
        }
        for (j, f) in factors.iter_mut().enumerate() {
            *f = match self.partial {
                Some((base, x)) if extra_of(j) < self.sure_from => {
                    factor(j, base as f64 / n as f64 + x as f64 * extra_of(j) as f64 / t.extra as f64)
                }
                _ if counts[j] == 0 => return None,
                _ => factor(j, counts[j] as f64),
            };
        }
        Some(())
    }
}

/// The factors of [`StratumFactors`] for one pixel (`StratumFactors::new(t, samples).pixel(row,
/// pixel, factors)`; prepare them once per film where there are many pixels).
pub fn stratum_factors(t: &TargetParams, row: &[u32], pixel: u32, samples: u64, factors: &mut [f32]) -> Option<()> {
    StratumFactors::new(t, samples).pixel(row, pixel, factors)
}

/// Samples per pixel after which every bin of a stratified render has had a sample: the base
/// visits of the first cycle (`cycle_slot`), `strata` without extra visits.
pub fn samples_to_visit_every_bin(t: &TargetParams) -> u64 {
    let n = t.strata as u64;
    if t.extra == 0 || n == 0 { n } else { (n - 1) * (t.extra / t.strata + 1) as u64 + 1 }
}

/// Most visits per cycle beyond one per bin (`TargetParams::extra`), so that a pixel's extra
/// positions fit 32-bit arithmetic.
pub const MAX_EXTRA_VISITS: u32 = 65_535;
/// Extra visits per cycle per stratified bin that a pilot render shares out (`visit_tables`):
/// a bin the pilot saw nothing near still gets 1 of every EXTRA_VISITS_PER_BIN + 1 visits. On a
/// 327,680-triangle hidden object (confocal 16x16, 4 ps bins, K = 1, 10 s) 3, 7 and 15 gave the
/// same error within 5 % at 4 ps; 3 was 1.2x worse at 100 ps.
pub const EXTRA_VISITS_PER_BIN: u32 = 7;
/// Cells a pixel's pilot transient is summed over before its extra visits are shared out (at
/// most the strata): a pilot of a few hundred samples per pixel leaves most fine bins empty.
pub const PILOT_CELLS: u32 = 128;
/// A cell's pilot mass is the largest within this many cells of it (the pilot leaves gaps
/// inside a transient's support).
pub const PILOT_SPREAD: usize = 2;
/// Share of the extra visits `visit_tables` spreads evenly over the bins whatever the pilot
/// saw, so that the bins of an arrival the pilot missed get more than one visit a cycle. It was
/// needed while the bins' stride let a 256-sample pilot visit them in pairs with gaps of 36 bins
/// (the example letter at 4 ps: the pilot alone 18x the error of no pilot, with this share 3x);
/// with evenly spreading strides (`golden_stride`), shares of 0 and 0.5 gave 1,251-2,242x and
/// 1,314-2,567x mitransient's accuracy at 1 to 100 ps (10 s, one run each), and it stays as
/// insurance for pilots too short to see every arrival.
pub const PILOT_UNIFORM_SHARE: f64 = 0.5;

/// Extra visits shaped by a pilot estimate of a stratified render (`t.strata` > 0): returns
/// `t.extra` (EXTRA_VISITS_PER_BIN per bin, at most MAX_EXTRA_VISITS) and the `target_visits`
/// rows, pixel after pixel, `strata + 1` cumulative counts each. Of a pixel's extra visits,
/// PILOT_UNIFORM_SHARE go to its bins evenly and the rest in proportion to the pilot's mass
/// near them (|values| summed over the channels and over PILOT_CELLS cells of bins, then the
/// largest within PILOT_SPREAD cells), each cell's share spread evenly over its bins, their
/// running sum rounded; a pixel the pilot saw nothing in gets them all evenly. Any allocation
/// is unbiased (every bin keeps a visit a cycle and the film divides each bin by its visits);
/// this one puts samples where the light is.
///
/// `film`: the pilot's [pixel][bin][3] values (`bins` per pixel).
pub fn visit_tables(t: &TargetParams, film: &[f32], bins: usize) -> (u32, Vec<u32>) {
    assert!(t.strata > 0 && film.len().is_multiple_of(3 * bins));
    let n = t.strata as usize;
    let extra = (EXTRA_VISITS_PER_BIN as u64 * n as u64).min(MAX_EXTRA_VISITS as u64) as u32;
    let cells = (PILOT_CELLS as usize).min(n);
    // Bin j of the strata lies in cell j cells / n.
    let cell_of = |j: usize| j * cells / n;
    let mut bins_in_cell = vec![0usize; cells];
    (0..n).for_each(|j| bins_in_cell[cell_of(j)] += 1);
    let first = t.first_bin as usize;
    let mut rows = Vec::with_capacity(film.len() / (3 * bins) * (n + 1));
    let (mut masses, mut spread) = (vec![0.0f64; cells], vec![0.0f64; cells]);
    for pixel in film.chunks(3 * bins) {
        masses.iter_mut().for_each(|m| *m = 0.0);
        for j in 0..n {
            let base = (first + j) * 3;
            masses[cell_of(j)] += pixel[base..base + 3].iter().map(|v| v.abs() as f64).sum::<f64>();
        }
        for (c, m) in spread.iter_mut().enumerate() {
            *m = masses[c.saturating_sub(PILOT_SPREAD)..(c + PILOT_SPREAD + 1).min(cells)]
                .iter()
                .cloned()
                .fold(0.0, f64::max);
        }
        // Bin j's share of the pixel's extra visits, their running sum rounded: the row.
        let share = |j: usize| spread[cell_of(j)] / bins_in_cell[cell_of(j)] as f64;
        let total: f64 = (0..n).map(share).sum();
        let even = !(total.is_finite() && total > 0.0);
        let mut acc = 0.0f64;
        rows.push(0);
        for j in 0..n {
            acc += if even {
                1.0 / n as f64
            } else {
                (1.0 - PILOT_UNIFORM_SHARE) * share(j) / total + PILOT_UNIFORM_SHARE / n as f64
            };
            rows.push(if j + 1 == n { extra } else { ((extra as f64 * acc).round() as u32).min(extra) });
        }
    }
    (extra, rows)
}

/// Extra visits per cycle per stratified bin that the masses of an NLOS capture's band index
/// share out (`visit_tables_from_masses`): the masses are exact, so a cycle spends 1 of
/// BAND_EXTRA_VISITS_PER_BIN + 1 visits on bins they show dark.
pub const BAND_EXTRA_VISITS_PER_BIN: u32 = 15;

/// Share of a pixel's weight [`visit_tables_from_masses`] spreads evenly over its bins before
/// the floors and the rest follow it: insurance where the band index's masses, which leave out
/// visibility and the variance of a bin's estimates, misjudge where samples are needed.
/// Confocal 16x16 captures at 4 ps, 10 s, MSE over three captures relative to a share of 0.25:
/// the 327,680-triangle hidden sphere 3.2x with 0 (its arrivals' tails, of little mass, got
/// almost no samples) and 1.5x with 0.5; the panels 0.75x with 0; the staircase and the Z the
/// same within noise.
pub const BAND_UNIFORM_SHARE: f64 = 0.25;

/// Extra visits shaped by per-bin weights known before the render (an NLOS capture's band-index
/// masses, `masses[pixel][stratum]`, `t.strata` per pixel): returns `t.extra`
/// (BAND_EXTRA_VISITS_PER_BIN per bin, at most MAX_EXTRA_VISITS) and the `target_visits` rows, as
/// [`visit_tables`] does (a pixel of no weight gets them evenly).
///
/// With n bins and E extra visits, a bin's share w is BAND_UNIFORM_SHARE / n plus the rest in
/// proportion to its weight. In a cycle of n + E visits the bin first gets its floor, (n + E)
/// min(w, 1/n) visits rounded up (at least its base visit): never fewer than an even allocation
/// (1/n of the samples) or one in proportion to w, whichever is smaller, so that no bin the
/// weights show lit is starved by brighter ones. The floors fit the cycle (their sum is at most
/// n + E, as the min(w, 1/n) sum to at most 1; rounded down instead where rounding up would not
/// fit), and the visits left over go in proportion to w, their running sum rounded.
pub fn visit_tables_from_masses(t: &TargetParams, masses: &[f32]) -> (u32, Vec<u32>) {
    let n = t.strata as usize;
    assert!(n > 0 && masses.len().is_multiple_of(n));
    let extra = (BAND_EXTRA_VISITS_PER_BIN as u64 * n as u64).min(MAX_EXTRA_VISITS as u64) as u32;
    let cycle = (n as u64 + extra as u64) as f64;
    let even = 1.0 / n as f64;
    let mut rows = Vec::with_capacity(masses.len() / n * (n + 1));
    let (mut shares, mut floors) = (vec![0.0f64; n], vec![0u64; n]);
    for pixel in masses.chunks(n) {
        let weight = |m: f32| if m.is_finite() && m > 0.0 { m as f64 } else { 0.0 };
        let total: f64 = pixel.iter().map(|&m| weight(m)).sum();
        let lit = total.is_finite() && total > 0.0;
        for (w, &m) in shares.iter_mut().zip(pixel) {
            *w = if lit { BAND_UNIFORM_SHARE * even + (1.0 - BAND_UNIFORM_SHARE) * weight(m) / total } else { even };
        }
        // Each bin's floor in extra visits (less a millionth of a visit, so that a floor that
        // is whole in exact arithmetic does not round up).
        let mut fill = |round: fn(f64) -> f64| {
            for (f, w) in floors.iter_mut().zip(&shares) {
                *f = round(cycle * w.min(even) - 1e-6).max(1.0) as u64 - 1;
            }
            floors.iter().sum::<u64>()
        };
        let mut floored = fill(f64::ceil);
        if floored > extra as u64 {
            floored = fill(f64::floor);
        }
        let left = (extra as u64 - floored) as f64;
        let (mut acc, mut placed) = (0.0f64, 0u64);
        rows.push(0);
        for j in 0..n {
            acc += shares[j];
            placed += floors[j];
            let up_to = if j + 1 == n { extra as u64 } else { placed + (left * acc).round() as u64 };
            rows.push(up_to.min(extra as u64) as u32);
        }
    }
    (extra, rows)
}

/// The low-discrepancy uniform number of sample `sample` of a pixel whose random offset is
/// `offset` (bits of a uniform u32): fract(offset + sample x (golden ratio - 1)) in 32-bit fixed
/// point. Each sample's number is uniform (the offset is), and a pixel's samples spread evenly
/// over [0, 1), so its target lengths cover the gate evenly (twin of `target_u`).
pub fn target_u(offset: u32, sample: u32) -> f32 {
    let x = offset.wrapping_add(sample.wrapping_mul(2_654_435_769));
    (x >> 8) as f32 * (1.0 / 16_777_216.0)
}
