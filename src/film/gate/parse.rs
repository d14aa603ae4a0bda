//! Parsing `--gate` specs: the gate kinds and their parameters, continuous-wave codes, gate
//! tables from CSV files, and the hint for times typed as metres.

use std::path::Path;

use anyhow::{Context as _, Result, bail, ensure};

use super::{CwCode, Gate, MAX_CHIPS};
use crate::units::parse_length;

impl CwCode {
    /// Parses `square`, `ham3`, `ham4:I`, `mseq[:CHIPS]` and `depthsel[:CHIPS[:NEIGHBOURS]]`
    /// (defaults 32 chips, 3 neighbours); None for `sine`, the plain `cw` gate.
    pub fn parse(spec: &str) -> Result<Option<Self>> {
        let mut parts = spec.trim().split(':');
        let name = parts.next().unwrap_or("");
        let args: Vec<&str> = parts.collect();
        let number = |i: usize, default: u32, what: &str| -> Result<u32> {
            match args.get(i) {
                None => Ok(default),
                Some(a) => a
                    .trim()
                    .parse::<u32>()
                    .with_context(|| format!("cw code `{spec}`: {what} `{a}` is not a whole number")),
            }
        };
        let most = |n: usize| -> Result<()> {
            ensure!(args.len() <= n, "cw code `{spec}`: too many parameters");
            Ok(())
        };
        let code = match name {
            "sine" => {
                most(0)?;
                return Ok(None);
            }
            "square" => {
                most(0)?;
                CwCode::Square
            }
            "ham3" => {
                most(0)?;
                CwCode::Hamiltonian3
            }
            "ham4" => {
                most(1)?;
                let i = number(0, 0, "measurement")?;
                ensure!((1..=4).contains(&i), "cw code `{spec}`: give the K = 4 measurement 1 to 4, e.g. ham4:2");
                CwCode::Hamiltonian4(i as u8)
            }
            "mseq" => {
                most(1)?;
                CwCode::MSequence { chips: number(0, 32, "chips")? }
            }
            "depthsel" => {
                most(2)?;
                CwCode::DepthSelective { chips: number(0, 32, "chips")?, neighbours: number(1, 3, "neighbours")? }
            }
            other => bail!(
                "unknown cw code `{other}`: use sine, square, ham3, ham4:I, mseq[:CHIPS] or depthsel[:CHIPS[:NEIGHBOURS]]"
            ),
        };
        match code {
            CwCode::MSequence { chips } => {
                ensure!(chips >= 2, "cw code `{spec}`: an m-sequence needs at least 2 chips")
            }
            CwCode::DepthSelective { chips, neighbours } => ensure!(
                neighbours >= 1 && chips > neighbours && chips <= MAX_CHIPS,
                "cw code `{spec}`: depth selection needs 1 <= neighbours < chips <= {MAX_CHIPS}"
            ),
            _ => {}
        }
        if let CwCode::MSequence { chips } = code {
            ensure!(chips <= MAX_CHIPS, "cw code `{spec}`: at most {MAX_CHIPS} chips");
        }
        Ok(Some(code))
    }
}

impl Gate {
    /// Parses `none`, `box:A..B`, `gaussian:MU,SIGMA`, `cw:FREQ_HZ,PHASE_DEG[,CODE]` (see
    /// [`CwCode::parse`]), `table:FILE.csv`, `transient:START,WIDTH,BINS`. Lengths accept `m`, `mm`, `ps`, `ns` suffixes.
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
                let (f, phase, code) = match args.split(',').collect::<Vec<_>>()[..] {
                    [f, phase] => (f, phase, None),
                    [f, phase, code] => (f, phase, CwCode::parse(code)?),
                    _ => bail!(
                        "cw gate: expected cw:FREQ_HZ,PHASE_DEG[,CODE], e.g. cw:20e6,90 or cw:4.7e9,0,depthsel, got `cw:{args}`"
                    ),
                };
                let frequency_hz = parse_number(f, "cw frequency (Hz)")?;
                let phase_deg = parse_number(phase, "cw phase (degrees)")?;
                match code {
                    None => Gate::Cw { frequency_hz, phase_deg },
                    Some(code) => Gate::CwCode { frequency_hz, phase_deg, code },
                }
            }
            "table" => {
                let path = Path::new(args.trim());
                Gate::Table { points: read_gate_table(path)?, source: path.to_owned() }
            }
            "transient" => {
                let [start, width, bins] = split_n(args, "transient:START,WIDTH,BINS")?;
                let bins = bins
                    .trim()
                    .parse::<u32>()
                    .ok()
                    .filter(|&b| b > 0)
                    .with_context(|| format!("transient gate: `{bins}` is not a positive number of bins"))?;
                Gate::Transient { start: parse_length(start)?, width: parse_length(width)?, bins }
            }
            other => bail!(
                "unknown gate kind `{other}`: use none, box:A..B, gaussian:MU,SIGMA, cw:FREQ_HZ,PHASE_DEG[,CODE], \
                 table:FILE.csv or transient:START,WIDTH,BINS"
            ),
        };
        gate.validate()?;
        Ok(gate)
    }
}

/// Where the lengths of `spec` (a box, transient or gaussian gate) carry no unit, and read as
/// nanoseconds or picoseconds would land within the scene's path lengths `range` (m), the spec
/// the user probably meant, said in a sentence; None otherwise. For a gate that caught no light.
pub fn time_unit_hint(spec: &str, (shortest, longest): (f64, f64)) -> Option<String> {
    let (kind, args) = spec.split_once(':')?;
    // The spec with `unit` after each length, and the lengths' extent (m) read that way.
    let with_unit = |unit: &str| -> Option<(String, f64, f64)> {
        let fields: Vec<&str> = match kind.trim() {
            "box" => args.split("..").collect(),
            "transient" | "gaussian" => args.split(',').collect(),
            _ => return None,
        };
        let lengths = if kind.trim() == "transient" { 2 } else { fields.len() };
        if fields.len() < lengths || fields[..lengths].iter().any(|f| f.trim().chars().any(char::is_alphabetic)) {
            return None;
        }
        let written: Vec<String> = fields
            .iter()
            .enumerate()
            .map(|(i, f)| if i < lengths { format!("{}{unit}", f.trim()) } else { f.to_string() })
            .collect();
        let separator = if kind.trim() == "box" { ".." } else { "," };
        let candidate = format!("{}:{}", kind.trim(), written.join(separator));
        let (lo, hi) = match Gate::parse(&candidate).ok()? {
            Gate::Gaussian { mean, sigma } => (mean - 3.0 * sigma, mean + 3.0 * sigma),
            gate => (gate.min_length(), gate.max_length()?),
        };
        Some((candidate, lo, hi))
    };
    ["ns", "ps"].iter().find_map(|unit| {
        let (candidate, lo, hi) = with_unit(unit)?;
        (lo < longest && hi > shortest).then(|| {
            format!(
                "lengths without a unit are metres of optical path; read as {unit} the gate would be `{candidate}` \
                 ({lo:.4} to {hi:.4} m), within this scene's path lengths ({})",
                describe_lengths(shortest, longest)
            )
        })
    })
}

/// A scene's range of path lengths (m) in words: "A to B m", or "A m and longer" where there
/// is no longest (fog that fills the scene, `Scene::path_length_bounds`).
pub fn describe_lengths(shortest: f64, longest: f64) -> String {
    if longest.is_finite() {
        format!("{shortest:.3} to {longest:.3} m")
    } else {
        format!("{shortest:.3} m and longer, through the fog that fills the scene")
    }
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
