//! The pathlength importance W (docs/design.md section 2): the gates, their kernel parameters
//! and the CPU twin of `shaders/lib/gate.wesl`; `parse` reads `--gate` specs and gate tables.

mod parse;

use std::path::PathBuf;

use anyhow::{Context as _, Result, bail, ensure};

use crate::gpu::layout;
use crate::units::SPEED_OF_LIGHT;
pub use parse::{describe_lengths, read_gate_table, time_unit_hint};

/// A sensor's pathlength importance. All lengths are optical path lengths in metres.
#[derive(Clone, Debug, PartialEq)]
pub enum Gate {
    /// W = 1: the steady-state image.
    None,
    /// W = 1 on [start, end), 0 elsewhere.
    Box {
        /// Start (m).
        start: f64,
        /// End (m), excluded.
        end: f64,
    },
    /// W = exp(-(l - mean)^2 / (2 sigma^2)), peak 1.
    Gaussian {
        /// Mean (m).
        mean: f64,
        /// Standard deviation (m).
        sigma: f64,
    },
    /// W = cos(2 pi f l / c + phase): continuous-wave time of flight (signed).
    Cw {
        /// Modulation frequency (Hz).
        frequency_hz: f64,
        /// Phase (degrees).
        phase_deg: f64,
    },
    /// W = C(f l / c + phase / 360): a continuous-wave code's correlation C of one period (a
    /// function of the phase in periods), repeated (see [`CwCode`]).
    CwCode {
        /// Modulation frequency (Hz): the code repeats every c / f of optical path.
        frequency_hz: f64,
        /// Phase (degrees): W(l) = C(l / lambda + phase / 360), so a positive phase moves the
        /// code to shorter paths, as for `Cw`.
        phase_deg: f64,
        /// The code.
        code: CwCode,
    },
    /// Piecewise-linear W through (length, weight) points, 0 outside them.
    Table {
        /// (length m, weight) points, increasing in length.
        points: Vec<(f64, f64)>,
        /// The CSV file they came from.
        source: PathBuf,
    },
    /// `bins` boxes [start + i width, start + (i + 1) width): a transient cube.
    Transient {
        /// Start of bin 0 (m).
        start: f64,
        /// Bin width (m).
        width: f64,
        /// Number of bins.
        bins: u32,
    },
}

/// GATE_KIND values of the kernels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum GateKind {
    /// W = 1.
    None = 0,
    /// W = 1 on [start, end).
    Box = 1,
    /// Gaussian W.
    Gaussian = 2,
    /// Continuous-wave cosine W.
    Cw = 3,
    /// Tabulated W.
    Table = 4,
    /// One box per bin.
    Transient = 5,
    /// A continuous-wave code: one period of piecewise-linear W, repeated.
    CwCode = 6,
}

/// Correlation functions of continuous-wave time-of-flight codes (illumination modulation
/// against sensor demodulation) as the pathlength importance of one measurement: C(x) over one
/// period x in [0, 1), piecewise linear, peak 1. The shapes are those of the paper's reference
/// implementation of CW-ToF in time-gated rendering (Pediredla et al. 2019) and, for the K = 4
/// Hamiltonian code, of Gupta et al. 2018 ("What are optimal coding functions for
/// time-of-flight imaging?").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CwCode {
    /// Square-wave modulation and demodulation (50 % duty), DC removed: a triangle wave, +1 at
    /// x = 0, -1 at x = 1/2 (signed, zero mean).
    Square,
    /// Hamiltonian code, K = 3: a pulse of 1/6 duty against a square demodulation of 1/2 duty.
    /// C rises from 0 to 1 over [0, 1/6), stays 1 to 1/2, falls to 0 at 2/3 and is 0 to the end
    /// of the period. The K = 3 measurements are this code at phases 0, 120 and 240 degrees.
    Hamiltonian3,
    /// Hamiltonian code, K = 4, measurement `i` (1 to 4): a pulse of 1/12 duty against the
    /// binary demodulation 000001111110, 001111110000, 111000011100 or 100011000111 (twelfths of
    /// the period). C equals the demodulation's bit k at x = k/12, linear in between.
    Hamiltonian4(u8),
    /// An m-sequence of `chips` chips per period (idealised autocorrelation): 1 at x = 0,
    /// falling linearly over one chip either side to a floor of 1/chips.
    MSequence {
        /// Chips per period (at least 2).
        chips: u32,
    },
    /// The depth-selective code of Tadano et al. 2015 (the paper's Fig. 9): the sum of
    /// `neighbours` m-sequence correlations shifted by one chip each, less their overlapping
    /// floors. A trapezoid on the floor 1/chips: 1 from x = 0 to (neighbours - 1)/chips,
    /// falling to the floor over the next chip and rising over the last chip of the period.
    /// Paths in the trapezoid weigh about `chips` times the others: the sensor selects a range
    /// of depths.
    DepthSelective {
        /// Chips per period (at least neighbours + 1).
        chips: u32,
        /// Chips of the flat top plus one (at least 1).
        neighbours: u32,
    },
}

/// Most chips of an m-sequence or depth-selective code: f32 path lengths (a unit in the last
/// place is about 1 um at 10 m) must resolve a chip at the frequencies these codes use.
pub const MAX_CHIPS: u32 = 4096;

/// The Hamiltonian K = 4 demodulations (bits of twelfths of the period).
const HAMILTONIAN4: [&str; 4] = ["000001111110", "001111110000", "111000011100", "100011000111"];

impl CwCode {
    /// The code as `parse` reads it.
    pub fn name(&self) -> String {
        match self {
            CwCode::Square => "square".into(),
            CwCode::Hamiltonian3 => "ham3".into(),
            CwCode::Hamiltonian4(i) => format!("ham4:{i}"),
            CwCode::MSequence { chips } => format!("mseq:{chips}"),
            CwCode::DepthSelective { chips, neighbours } => format!("depthsel:{chips}:{neighbours}"),
        }
    }

    /// The largest |dC/dx| (per period) over the code's linear pieces.
    pub fn steepest_slope(&self) -> f64 {
        let p = self.breakpoints();
        p.windows(2)
            .filter(|w| w[1].0 > w[0].0)
            .map(|w| ((w[1].1 - w[0].1) / (w[1].0 - w[0].0)).abs())
            .fold(0.0, f64::max)
    }

    /// One period of C as (x, C(x)) points from x = 0 to x = 1 (C(1) = C(0)), x in periods,
    /// nondecreasing; C is linear between them.
    pub fn breakpoints(&self) -> Vec<(f64, f64)> {
        match *self {
            CwCode::Square => vec![(0.0, 1.0), (0.5, -1.0), (1.0, 1.0)],
            CwCode::Hamiltonian3 => vec![(0.0, 0.0), (1.0 / 6.0, 1.0), (0.5, 1.0), (2.0 / 3.0, 0.0), (1.0, 0.0)],
            CwCode::Hamiltonian4(i) => {
                let bits: Vec<f64> = HAMILTONIAN4[i as usize - 1].bytes().map(|b| (b - b'0') as f64).collect();
                (0..=12).map(|k| (k as f64 / 12.0, bits[k % 12])).collect()
            }
            CwCode::MSequence { chips } => {
                let (p, floor) = (chips as f64, 1.0 / chips as f64);
                vec![(0.0, 1.0), (1.0 / p, floor), (1.0 - 1.0 / p, floor), (1.0, 1.0)]
            }
            CwCode::DepthSelective { chips, neighbours } => {
                let (p, n) = (chips as f64, neighbours as f64);
                let floor = 1.0 / p;
                vec![(0.0, 1.0), ((n - 1.0) / p, 1.0), (n / p, floor), (1.0 - 1.0 / p, floor), (1.0, 1.0)]
            }
        }
    }
}

impl Gate {
    /// Checks that the kernels can evaluate the gate (positive widths and frequencies, lengths
    /// that f32 resolves, nothing below zero length).
    pub fn validate(&self) -> Result<()> {
        // The kernels evaluate W in f32: a gate must stay distinct from its neighbours there.
        let f32_distinct = |a: f64, b: f64| (b as f32) > (a as f32);
        match *self {
            Gate::Box { start, end } if end > start && !f32_distinct(start, end) => {
                bail!("box gate [{start}, {end}) m is narrower than f32 resolution at that length")
            }
            Gate::Gaussian { mean, sigma } if sigma > 0.0 && sigma < 1e-6 * mean.abs().max(1.0) => {
                bail!("gaussian gate: sigma {sigma} m is below f32 resolution (1e-6 of the mean, or of 1 m)")
            }
            Gate::Transient { start, width, .. } if width > 0.0 && !f32_distinct(start, start + width) => {
                bail!("transient gate: bins of {width} m are narrower than f32 resolution at {start} m")
            }
            Gate::Box { start, end } if !(end > start) => bail!("box gate: end {end} m must exceed start {start} m"),
            Gate::Box { start, .. } if start < 0.0 => bail!("box gate: start {start} m is negative"),
            Gate::Gaussian { sigma, .. } if !(sigma > 0.0) => bail!("gaussian gate: sigma {sigma} m must be positive"),
            Gate::Cw { frequency_hz, .. } | Gate::CwCode { frequency_hz, .. }
                if !(frequency_hz > 0.0 && frequency_hz.is_finite()) =>
            {
                bail!("cw gate: frequency {frequency_hz} Hz must be positive")
            }
            Gate::Cw { phase_deg, .. } | Gate::CwCode { phase_deg, .. } if !phase_deg.is_finite() => {
                bail!("cw gate: phase {phase_deg} degrees must be finite")
            }
            Gate::Transient { width, .. } if !(width > 0.0) => {
                bail!("transient gate: bin width {width} m must be positive")
            }
            Gate::Transient { start, .. } if start < 0.0 => bail!("transient gate: start {start} m is negative"),
            _ => Ok(()),
        }
    }

    /// The same gate moved later by `d` metres of optical path (earlier when negative): W'(l) =
    /// W(l - d). For a CW gate this is a phase change of -360 f d / c degrees. The steady state
    /// has nothing to move; a shift that pushes a gate below zero length is an error.
    pub fn shifted(&self, d: f64) -> Result<Self> {
        let gate = match self.clone() {
            Gate::None if d == 0.0 => Gate::None,
            Gate::None => bail!("the `none` gate (steady state) cannot be shifted; give a gate to step"),
            Gate::Box { start, end } => Gate::Box { start: start + d, end: end + d },
            Gate::Gaussian { mean, sigma } => Gate::Gaussian { mean: mean + d, sigma },
            Gate::Cw { frequency_hz, phase_deg } => {
                Gate::Cw { frequency_hz, phase_deg: phase_deg - 360.0 * frequency_hz * d / SPEED_OF_LIGHT }
            }
            Gate::CwCode { frequency_hz, phase_deg, code } => {
                Gate::CwCode { frequency_hz, phase_deg: phase_deg - 360.0 * frequency_hz * d / SPEED_OF_LIGHT, code }
            }
            Gate::Table { points, source } => {
                let points: Vec<(f64, f64)> = points.iter().map(|&(l, w)| (l + d, w)).collect();
                ensure!(
                    points[0].0 >= 0.0,
                    "table gate {} shifted by {d} m starts below zero length",
                    source.display()
                );
                Gate::Table { points, source }
            }
            Gate::Transient { start, width, bins } => Gate::Transient { start: start + d, width, bins },
        };
        gate.validate().with_context(|| format!("{} shifted by {d} m", self.describe()))?;
        Ok(gate)
    }

    /// Whether W is negative for some path lengths (CW gates whose correlation goes below zero,
    /// tables with negative weights): such a gate's images are signed.
    pub fn is_signed(&self) -> bool {
        match self {
            Gate::Cw { .. } => true,
            Gate::CwCode { code, .. } => code.breakpoints().iter().any(|&(_, c)| c < 0.0),
            Gate::Table { points, .. } => points.iter().any(|&(_, w)| w < 0.0),
            _ => false,
        }
    }

    /// The kernels' specialisation for this gate.
    pub fn kind(&self) -> GateKind {
        match self {
            Gate::None => GateKind::None,
            Gate::Box { .. } => GateKind::Box,
            Gate::Gaussian { .. } => GateKind::Gaussian,
            Gate::Cw { .. } => GateKind::Cw,
            Gate::CwCode { .. } => GateKind::CwCode,
            Gate::Table { .. } => GateKind::Table,
            Gate::Transient { .. } => GateKind::Transient,
        }
    }

    /// Film bins per pixel (1 unless transient).
    pub fn bins(&self) -> u32 {
        match self {
            Gate::Transient { bins, .. } => *bins,
            _ => 1,
        }
    }

    /// [start, end) of bin `i` (m), transient gates only.
    pub fn bin_range(&self, i: u32) -> Option<(f64, f64)> {
        match *self {
            Gate::Transient { start, width, .. } => Some((start + width * i as f64, start + width * (i + 1) as f64)),
            _ => None,
        }
    }

    /// Upper end of the support (m); None when unbounded.
    pub fn max_length(&self) -> Option<f64> {
        match self {
            Gate::Box { end, .. } => Some(*end),
            Gate::Table { points, .. } => points.last().map(|p| p.0),
            Gate::Transient { start, width, bins } => Some(start + width * *bins as f64),
            _ => None,
        }
    }

    /// Lower end of the support (m): paths shorter than this have W = 0.
    pub fn min_length(&self) -> f64 {
        match self {
            Gate::Box { start, .. } | Gate::Transient { start, .. } => *start,
            Gate::Table { points, .. } => points[0].0,
            _ => 0.0,
        }
    }

    /// The (length, weight) table for the GPU: a table gate's points, a cw code's period
    /// ((phase in periods, weight)); empty for the other gates.
    pub fn table(&self) -> Vec<[f32; 2]> {
        match self {
            Gate::Table { points, .. } => points.iter().map(|&(l, w)| [l as f32, w as f32]).collect(),
            Gate::CwCode { code, .. } => code.breakpoints().iter().map(|&(x, w)| [x as f32, w as f32]).collect(),
            _ => Vec::new(),
        }
    }

    /// The kernels' gate parameters.
    pub fn to_gpu(&self) -> layout::GateParams {
        let (p0, p1) = match *self {
            Gate::None => (0.0, 0.0),
            Gate::Box { start, end } => (start, end),
            Gate::Gaussian { mean, sigma } => (mean, sigma),
            Gate::Cw { frequency_hz, phase_deg } => {
                (2.0 * std::f64::consts::PI * frequency_hz / SPEED_OF_LIGHT, phase_deg.to_radians())
            }
            // Periods per metre and the phase in periods, in [0, 1).
            Gate::CwCode { frequency_hz, phase_deg, .. } => {
                (frequency_hz / SPEED_OF_LIGHT, (phase_deg / 360.0).rem_euclid(1.0))
            }
            Gate::Table { ref points, .. } => (points[0].0, points[points.len() - 1].0),
            Gate::Transient { start, width, .. } => (start, width),
        };
        layout::GateParams {
            bins: self.bins(),
            table_len: self.table().len() as u32,
            p0: p0 as f32,
            p1: p1 as f32,
            max_length: self.max_length().map_or(f32::MAX, |m| m as f32),
            ..Default::default()
        }
    }

    /// The gate as numbers, for outputs' metadata (`gate_parameters`): `kind` (`none`, `box`,
    /// `gaussian`, `cw`, `table`, `transient`) and that kind's fields, lengths in metres of
    /// optical path (`_m`), frequencies in Hz, phases in degrees. Every kind with a bounded
    /// support also has `start_m` and `end_m`; a transient gate has `bin_width_m` and `bins`
    /// (bin i covers [start_m + i bin_width_m, start_m + (i + 1) bin_width_m)). Whatever units
    /// the spec was typed in (`ns`, `ps`, `mm`), these are metres.
    pub fn parameters(&self) -> serde_json::Value {
        use serde_json::json;
        match self {
            Gate::None => json!({ "kind": "none" }),
            Gate::Box { start, end } => {
                json!({ "kind": "box", "start_m": start, "end_m": end, "width_m": end - start })
            }
            Gate::Gaussian { mean, sigma } => json!({ "kind": "gaussian", "mean_m": mean, "sigma_m": sigma }),
            Gate::Cw { frequency_hz, phase_deg } => json!({
                "kind": "cw", "frequency_hz": frequency_hz, "phase_deg": phase_deg, "code": "sine",
                "period_m": SPEED_OF_LIGHT / frequency_hz,
            }),
            Gate::CwCode { frequency_hz, phase_deg, code } => json!({
                "kind": "cw", "frequency_hz": frequency_hz, "phase_deg": phase_deg, "code": code.name(),
                "period_m": SPEED_OF_LIGHT / frequency_hz,
            }),
            Gate::Table { points, source } => json!({
                "kind": "table", "source": source.display().to_string(), "start_m": points[0].0,
                "end_m": points[points.len() - 1].0, "points_m_weight": points.iter().map(|&(l, w)| [l, w]).collect::<Vec<_>>(),
            }),
            Gate::Transient { start, width, bins } => json!({
                "kind": "transient", "start_m": start, "bin_width_m": width, "bins": bins,
                "end_m": start + width * *bins as f64,
            }),
        }
    }

    /// A short human-readable description, with times alongside lengths.
    pub fn describe(&self) -> String {
        let ps = crate::units::metres_to_ps;
        // At most 9 decimals (nanometres), trailing zeros dropped: shifted gates print cleanly.
        let short = |x: f64| {
            let s = format!("{x:.9}");
            s.trim_end_matches('0').trim_end_matches('.').to_owned()
        };
        match self {
            Gate::None => "none (steady state)".into(),
            Gate::Box { start, end } => format!(
                "box [{} m, {} m) (width {:.4} m = {:.2} ps)",
                short(*start),
                short(*end),
                end - start,
                ps(end - start)
            ),
            Gate::Gaussian { mean, sigma } => {
                format!("gaussian mean {} m, sigma {} m ({:.2} ps)", short(*mean), short(*sigma), ps(*sigma))
            }
            Gate::Cw { frequency_hz, phase_deg } => format!("cw {frequency_hz} Hz, phase {} deg", short(*phase_deg)),
            Gate::CwCode { frequency_hz, phase_deg, code } => format!(
                "cw {frequency_hz} Hz, phase {} deg, code {} (period {:.4} m = {:.2} ps)",
                short(*phase_deg),
                code.name(),
                SPEED_OF_LIGHT / frequency_hz,
                ps(SPEED_OF_LIGHT / frequency_hz)
            ),
            Gate::Table { points, source } => format!("table {} ({} points)", source.display(), points.len()),
            Gate::Transient { start, width, bins } => {
                format!("transient {bins} bins of {} m ({:.2} ps) from {} m", short(*width), ps(*width), short(*start))
            }
        }
    }
}

/// CPU twin of the kernels' gate for a given GPU parameter block and kind.
pub fn gate_weight(kind: GateKind, g: &layout::GateParams, table: &[[f32; 2]], path_length: f32) -> f32 {
    match kind {
        GateKind::None => 1.0,
        GateKind::Box => (path_length >= g.p0 && path_length < g.p1) as u32 as f32,
        GateKind::Gaussian => {
            let z = (path_length - g.p0) / g.p1;
            (-0.5 * z * z).exp()
        }
        GateKind::Cw => (g.p0 * path_length + g.p1).cos(),
        GateKind::CwCode => {
            let x = g.p0 * path_length + g.p1;
            gate_table_lookup(table, x - x.floor())
        }
        GateKind::Table => gate_table_lookup(table, path_length),
        GateKind::Transient => (gate_bin(kind, g, path_length) >= 0) as u32 as f32,
    }
}

/// CPU twin of `gate_bin`: the transient bin of a length, -1 outside, 0 for other gates.
pub fn gate_bin(kind: GateKind, g: &layout::GateParams, path_length: f32) -> i32 {
    if kind != GateKind::Transient {
        return 0;
    }
    let x = gate_bin_position(g, path_length);
    if x < 0.0 || x >= g.bins as f32 { -1 } else { x as i32 }
}

/// CPU twin of `gate_bin_position`: floor((path_length - start) / width) of a transient gate.
pub fn gate_bin_position(g: &layout::GateParams, path_length: f32) -> f32 {
    ((path_length - g.p0) / g.p1).floor()
}

fn gate_table_lookup(table: &[[f32; 2]], l: f32) -> f32 {
    let n = table.len();
    if n == 0 || l < table[0][0] || l > table[n - 1][0] {
        return 0.0;
    }
    let i = table.partition_point(|p| p[0] <= l) - 1;
    if i == n - 1 {
        return table[i][1];
    }
    let (a, b) = (table[i], table[i + 1]);
    let f = (l - a[0]) / (b[0] - a[0]).max(1e-30);
    a[1] + (b[1] - a[1]) * f.clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_typed_as_metres_are_recognised() {
        let range = (1.94, 7.4);
        let hint = time_unit_hint("box:10.474..10.641", range).unwrap();
        assert!(hint.contains("`box:10.474ns..10.641ns`") && hint.contains("3.1400 to 3.1901 m"), "{hint}");
        let hint = time_unit_hint("transient:10474,333.6,8", range).unwrap();
        assert!(hint.contains("`transient:10474ps,333.6ps,8`"), "{hint}");
        assert!(time_unit_hint("gaussian:10.5,0.05", range).unwrap().contains("`gaussian:10.5ns,0.05ns`"));
        // Units given, lengths out of the scene's range either way, or kinds without lengths.
        for spec in ["box:10.474ns..10.641ns", "box:10.4m..10.6", "box:1000..1001", "cw:20e6,90", "none"] {
            assert_eq!(time_unit_hint(spec, range), None, "{spec}");
        }
    }

    #[test]
    fn specs_parse_into_gates() {
        assert_eq!(Gate::parse("none").unwrap(), Gate::None);
        assert_eq!(Gate::parse("box:3.14..3.19").unwrap(), Gate::Box { start: 3.14, end: 3.19 });
        assert_eq!(Gate::parse("gaussian:3,0.01").unwrap(), Gate::Gaussian { mean: 3.0, sigma: 0.01 });
        assert_eq!(Gate::parse("cw:20e6,90").unwrap(), Gate::Cw { frequency_hz: 20e6, phase_deg: 90.0 });
        assert_eq!(
            Gate::parse("transient:1.94,0.1,20").unwrap(),
            Gate::Transient { start: 1.94, width: 0.1, bins: 20 }
        );
        let Gate::Transient { start, width, .. } = Gate::parse("transient:10ns,12.5ps,8").unwrap() else { panic!() };
        assert!((start - 2.99792458).abs() < 1e-12 && (width - 3.747405725e-3).abs() < 1e-12);
        for bad in [
            "none:foo",
            "box:3.14..3.140000001",
            "gaussian:3,1e-50",
            "transient:1000,1e-9,3",
            "box:3",
            "box:3..2",
            "gaussian:1",
            "gaussian:1,0",
            "cw:-5,0",
            "transient:0,0.1,0",
            "transient:0,0,3",
            "x",
        ] {
            assert!(Gate::parse(bad).is_err(), "`{bad}` must be rejected");
        }
    }

    #[test]
    fn cpu_weights_follow_the_definitions() {
        let eval = |g: &Gate, l: f32| gate_weight(g.kind(), &g.to_gpu(), &g.table(), l);
        let b = Gate::parse("box:1..2").unwrap();
        assert_eq!((eval(&b, 0.99), eval(&b, 1.0), eval(&b, 1.99), eval(&b, 2.0)), (0.0, 1.0, 1.0, 0.0));
        let g = Gate::parse("gaussian:3,0.5").unwrap();
        assert_eq!(eval(&g, 3.0), 1.0);
        assert!((eval(&g, 3.5) - (-0.5f32).exp()).abs() < 1e-6);
        // cw at 149.896229 MHz has a 2 m wavelength: W(0.5 m) = cos(pi / 2 + phase).
        let c = Gate::parse("cw:149.896229e6,0").unwrap();
        assert!(eval(&c, 0.5).abs() < 1e-5 && (eval(&c, 1.0) + 1.0).abs() < 1e-5);
        let t = Gate::parse("transient:1,0.5,4").unwrap();
        let g = t.to_gpu();
        assert_eq!(
            (gate_bin(t.kind(), &g, 0.99), gate_bin(t.kind(), &g, 1.0), gate_bin(t.kind(), &g, 2.99)),
            (-1, 0, 3)
        );
        assert_eq!(gate_bin(t.kind(), &g, 3.0), -1);
        assert_eq!(t.max_length(), Some(3.0));
        assert_eq!(t.bin_range(1), Some((1.5, 2.0)));
    }

    #[test]
    fn tables_interpolate_linearly_and_report_bad_rows() {
        let dir = std::env::temp_dir().join(format!("gatetrace_gate_table_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let good = dir.join("good.csv");
        std::fs::write(&good, "# trapezoid\nlength,weight\n1.0,0\n2.0,1\n3.0,1\n4,0\n").unwrap();
        let t = Gate::parse(&format!("table:{}", good.display())).unwrap();
        let eval = |l: f32| gate_weight(t.kind(), &t.to_gpu(), &t.table(), l);
        assert_eq!((eval(0.5), eval(1.5), eval(2.5), eval(3.75), eval(4.5)), (0.0, 0.5, 1.0, 0.25, 0.0));
        let bad = dir.join("bad.csv");
        std::fs::write(&bad, "1.0,0\n2.0\n").unwrap();
        let e = format!("{:#}", Gate::parse(&format!("table:{}", bad.display())).unwrap_err());
        assert!(e.contains("bad.csv:2"), "{e}");
        std::fs::write(&bad, "1.0,0\n0.5,1\n").unwrap();
        assert!(format!("{:#}", Gate::parse(&format!("table:{}", bad.display())).unwrap_err()).contains("increase"));
    }

    #[test]
    fn cw_codes_parse_and_have_their_shapes() {
        let code = |spec: &str| match Gate::parse(spec).unwrap() {
            Gate::CwCode { code, frequency_hz, phase_deg } => {
                assert_eq!((frequency_hz, phase_deg), (1e9, 30.0));
                code
            }
            other => panic!("{spec}: {other:?}"),
        };
        assert_eq!(Gate::parse("cw:1e9,30,sine").unwrap(), Gate::Cw { frequency_hz: 1e9, phase_deg: 30.0 });
        assert_eq!(code("cw:1e9,30,square"), CwCode::Square);
        assert_eq!(code("cw:1e9,30,ham3"), CwCode::Hamiltonian3);
        assert_eq!(code("cw:1e9,30,ham4:3"), CwCode::Hamiltonian4(3));
        assert_eq!(code("cw:1e9,30,mseq"), CwCode::MSequence { chips: 32 });
        assert_eq!(code("cw:1e9,30,depthsel"), CwCode::DepthSelective { chips: 32, neighbours: 3 });
        assert_eq!(code("cw:1e9,30,depthsel:64:5"), CwCode::DepthSelective { chips: 64, neighbours: 5 });
        for bad in [
            "cw:1e9,30,ham4",
            "cw:1e9,30,ham4:0",
            "cw:1e9,30,mseq:1",
            "cw:1e9,30,depthsel:4:4",
            "cw:1e9,30,depthsel:4:0",
            "cw:1e9,30,cosine",
            "cw:1e9,30,ham3:1",
            "cw:0,30,square",
            "cw:1e9,inf,square",
            "cw:1e9,30,square,1",
        ] {
            assert!(Gate::parse(bad).is_err(), "{bad} should not parse");
        }
        let at = |c: CwCode, x: f64| -> f64 {
            let p = c.breakpoints();
            let i = p.partition_point(|q| q.0 <= x) - 1;
            if i + 1 == p.len() {
                p[i].1
            } else {
                p[i].1 + (p[i + 1].1 - p[i].1) * (x - p[i].0) / (p[i + 1].0 - p[i].0)
            }
        };
        let integral =
            |c: CwCode| c.breakpoints().windows(2).map(|w| 0.5 * (w[0].1 + w[1].1) * (w[1].0 - w[0].0)).sum::<f64>();
        for c in [
            CwCode::Square,
            CwCode::Hamiltonian3,
            CwCode::Hamiltonian4(1),
            CwCode::Hamiltonian4(4),
            CwCode::MSequence { chips: 7 },
            CwCode::DepthSelective { chips: 32, neighbours: 3 },
        ] {
            let p = c.breakpoints();
            assert_eq!((p[0].0, p[p.len() - 1].0), (0.0, 1.0), "{c:?} spans one period");
            assert_eq!(p[0].1, p[p.len() - 1].1, "{c:?} is periodic");
            assert!(p.windows(2).all(|w| w[0].0 <= w[1].0), "{c:?}: x nondecreasing");
            assert_eq!(p.iter().map(|q| q.1).fold(f64::MIN, f64::max), 1.0, "{c:?}: peak 1");
            assert_eq!(CwCode::parse(&c.name()).unwrap(), Some(c));
        }
        // Square: a triangle of zero mean.
        assert_eq!((at(CwCode::Square, 0.25), at(CwCode::Square, 0.5), integral(CwCode::Square)), (0.0, -1.0, 0.0));
        // Hamiltonian K = 3: a third of a period at 1, ramps of a sixth.
        assert_eq!(
            (at(CwCode::Hamiltonian3, 1.0 / 12.0), at(CwCode::Hamiltonian3, 0.4), at(CwCode::Hamiltonian3, 0.8)),
            (0.5, 1.0, 0.0)
        );
        assert!((integral(CwCode::Hamiltonian3) - 0.5).abs() < 1e-12);
        // Hamiltonian K = 4: at every twelfth the four measurements form a code word, and
        // neighbouring words differ in one measurement (a Hamiltonian cycle of 12 words).
        let words: Vec<u32> = (0..12)
            .map(|k| (1..=4u8).map(|i| at(CwCode::Hamiltonian4(i), k as f64 / 12.0) as u32).fold(0, |w, b| 2 * w + b))
            .collect();
        assert!((0..12).all(|k| (words[k] ^ words[(k + 1) % 12]).count_ones() == 1), "{words:?}");
        assert_eq!(words.iter().collect::<std::collections::HashSet<_>>().len(), 12);
        // m-sequence and depth selection: a floor of 1/chips; depth selection's period integral
        // is (n + 1 - n/P) / P and its top (n - 1) chips wide.
        assert_eq!(at(CwCode::MSequence { chips: 8 }, 0.5), 0.125);
        let ds = CwCode::DepthSelective { chips: 32, neighbours: 3 };
        assert_eq!((at(ds, 1.5 / 32.0), at(ds, 2.5 / 32.0), at(ds, 0.5)), (1.0, (1.0 + 1.0 / 32.0) / 2.0, 1.0 / 32.0));
        assert!((integral(ds) - (4.0 - 3.0 / 32.0) / 32.0).abs() < 1e-12);
        // W(l) = C(f l / c + phase / 360), on the CPU twin.
        let gate = Gate::parse("cw:299792458,90,ham3").unwrap();
        let (kind, g, table) = (gate.kind(), gate.to_gpu(), gate.table());
        assert_eq!(kind, GateKind::CwCode);
        for l in [0.1f32, 0.35, 2.6, 7.95] {
            let x = (l as f64 + 0.25).fract();
            assert!((gate_weight(kind, &g, &table, l) as f64 - at(CwCode::Hamiltonian3, x)).abs() < 1e-5, "W({l})");
        }
        // Shifting a code later by d is a phase change of -360 f d / c, as for the sine.
        let later = gate.shifted(0.25).unwrap();
        let (g2, t2) = (later.to_gpu(), later.table());
        assert!((gate_weight(kind, &g2, &t2, 2.85) - gate_weight(kind, &g, &table, 2.6)).abs() < 1e-5);
    }
}
