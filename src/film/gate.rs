//! The pathlength importance W (DESIGN.md section 2): parsing `--gate` specs and the CPU twin of
//! `shaders/lib/gate.wesl`.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, bail, ensure};

use crate::gpu::layout;
use crate::units::{SPEED_OF_LIGHT, parse_length};

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
}

impl Gate {
    /// Parses `none`, `box:A..B`, `gaussian:MU,SIGMA`, `cw:FREQ_HZ,PHASE_DEG`, `table:FILE.csv`,
    /// `transient:START,WIDTH,BINS`. Lengths accept `m`, `mm`, `ps`, `ns` suffixes.
    pub fn parse(spec: &str) -> Result<Self> {
        let (kind, args) = spec.split_once(':').unwrap_or((spec, ""));
        let gate = match kind.trim() {
            "none" if args.is_empty() => Gate::None,
            "none" => bail!("the `none` gate takes no parameters (got `{args}`)"),
            "box" => {
                let (a, b) = args.split_once("..").context("box gate: expected box:START..END, e.g. box:3.14..3.19")?;
                Gate::Box { start: parse_length(a)?, end: parse_length(b)? }
            }
            "gaussian" => {
                let [mu, sigma] = split_n(args, "gaussian:MEAN,SIGMA")?;
                Gate::Gaussian { mean: parse_length(mu)?, sigma: parse_length(sigma)? }
            }
            "cw" => {
                let [f, phase] = split_n(args, "cw:FREQ_HZ,PHASE_DEG")?;
                let frequency_hz = parse_number(f, "cw frequency (Hz)")?;
                let phase_deg = parse_number(phase, "cw phase (degrees)")?;
                Gate::Cw { frequency_hz, phase_deg }
            }
            "table" => {
                let path = Path::new(args.trim());
                Gate::Table { points: read_gate_table(path)?, source: path.to_owned() }
            }
            "transient" => {
                let [start, width, bins] = split_n(args, "transient:START,WIDTH,BINS")?;
                let bins = bins.trim().parse::<u32>().ok().filter(|&b| b > 0).with_context(|| {
                    format!("transient gate: `{bins}` is not a positive number of bins")
                })?;
                Gate::Transient { start: parse_length(start)?, width: parse_length(width)?, bins }
            }
            other => bail!(
                "unknown gate kind `{other}`: use none, box:A..B, gaussian:MU,SIGMA, cw:FREQ_HZ,PHASE_DEG, \
                 table:FILE.csv or transient:START,WIDTH,BINS"
            ),
        };
        gate.validate()?;
        Ok(gate)
    }

    fn validate(&self) -> Result<()> {
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
            Gate::Cw { frequency_hz, .. } if !(frequency_hz > 0.0) => {
                bail!("cw gate: frequency {frequency_hz} Hz must be positive")
            }
            Gate::Transient { width, .. } if !(width > 0.0) => bail!("transient gate: bin width {width} m must be positive"),
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
            Gate::Table { points, source } => {
                let points: Vec<(f64, f64)> = points.iter().map(|&(l, w)| (l + d, w)).collect();
                ensure!(points[0].0 >= 0.0, "table gate {} shifted by {d} m starts below zero length", source.display());
                Gate::Table { points, source }
            }
            Gate::Transient { start, width, bins } => Gate::Transient { start: start + d, width, bins },
        };
        gate.validate().with_context(|| format!("{} shifted by {d} m", self.describe()))?;
        Ok(gate)
    }

    /// The kernels' specialisation for this gate.
    pub fn kind(&self) -> GateKind {
        match self {
            Gate::None => GateKind::None,
            Gate::Box { .. } => GateKind::Box,
            Gate::Gaussian { .. } => GateKind::Gaussian,
            Gate::Cw { .. } => GateKind::Cw,
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

    /// The (length, weight) table for the GPU (empty unless a table gate).
    pub fn table(&self) -> Vec<[f32; 2]> {
        match self {
            Gate::Table { points, .. } => points.iter().map(|&(l, w)| [l as f32, w as f32]).collect(),
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

/// Reads a gate table: CSV lines `length,weight` (length in m or with a unit suffix), sorted by
/// length; `#` comments and one header line are allowed.
pub fn read_gate_table(path: &Path) -> Result<Vec<(f64, f64)>> {
    let name = path.display();
    let text = std::fs::read_to_string(path).with_context(|| format!("{name}: cannot read the gate table"))?;
    let mut points = Vec::new();
    let mut first_row = true;
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let header_allowed = std::mem::replace(&mut first_row, false);
        let mut fields = line.split([',', ';', '\t']).map(str::trim);
        let (Some(l), Some(w), None) = (fields.next(), fields.next(), fields.next()) else {
            bail!("{name}:{}: expected two columns `length,weight`, got `{line}`", i + 1);
        };
        match (parse_length(l), w.parse::<f64>()) {
            (Ok(l), Ok(w)) if w.is_finite() => points.push((l, w)),
            _ if header_allowed => continue, // header line
            _ => bail!("{name}:{}: `{line}` is not `length,weight`", i + 1),
        }
    }
    if points.len() < 2 {
        bail!("{name}: a gate table needs at least two points");
    }
    if points.windows(2).any(|w| !(w[1].0 > w[0].0)) {
        bail!("{name}: lengths must increase strictly from line to line");
    }
    Ok(points)
}

fn split_n<'a, const N: usize>(args: &'a str, usage: &str) -> Result<[&'a str; N]> {
    let parts: Vec<&str> = args.split(',').collect();
    parts.try_into().map_err(|_| anyhow::anyhow!("expected {usage}, got `{args}`"))
}

fn parse_number(s: &str, what: &str) -> Result<f64> {
    s.trim().parse::<f64>().ok().filter(|v| v.is_finite()).with_context(|| format!("{what}: `{s}` is not a number"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_into_gates() {
        assert_eq!(Gate::parse("none").unwrap(), Gate::None);
        assert_eq!(Gate::parse("box:3.14..3.19").unwrap(), Gate::Box { start: 3.14, end: 3.19 });
        assert_eq!(Gate::parse("gaussian:3,0.01").unwrap(), Gate::Gaussian { mean: 3.0, sigma: 0.01 });
        assert_eq!(Gate::parse("cw:20e6,90").unwrap(), Gate::Cw { frequency_hz: 20e6, phase_deg: 90.0 });
        assert_eq!(Gate::parse("transient:1.94,0.1,20").unwrap(), Gate::Transient { start: 1.94, width: 0.1, bins: 20 });
        let Gate::Transient { start, width, .. } = Gate::parse("transient:10ns,12.5ps,8").unwrap() else { panic!() };
        assert!((start - 2.99792458).abs() < 1e-12 && (width - 3.747405725e-3).abs() < 1e-12);
        for bad in ["none:foo", "box:3.14..3.140000001", "gaussian:3,1e-50", "transient:1000,1e-9,3", "box:3", "box:3..2", "gaussian:1", "gaussian:1,0", "cw:-5,0", "transient:0,0.1,0", "transient:0,0,3", "x"] {
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
        assert_eq!((gate_bin(t.kind(), &g, 0.99), gate_bin(t.kind(), &g, 1.0), gate_bin(t.kind(), &g, 2.99)), (-1, 0, 3));
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
}
