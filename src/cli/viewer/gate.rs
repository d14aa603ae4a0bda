//! The viewer's gate controls: every kind's parameters, the gate they make, and the scrub step.

use std::path::PathBuf;

use eframe::egui;

use gatetrace::film::{CwCode, Gate};

/// Gate kinds the viewer offers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GateChoice {
    /// Steady state.
    None,
    /// W = 1 on [τ − width/2, τ + width/2).
    Box,
    /// Gaussian of mean τ and standard deviation width.
    Gaussian,
    /// A cube of bins rendered together; one bin is shown.
    Transient,
    /// Continuous-wave gate (cosine, or one period of a code), signed.
    Cw,
    /// Tabulated W, moved through time as a whole.
    Table,
}

/// The window's gate controls: the parameters of every kind, so that switching kinds and back
/// keeps each kind's settings.
#[derive(Clone, Debug)]
pub struct GateControls {
    /// The kind rendered.
    pub kind: GateChoice,
    /// Box and Gaussian gates: centre τ (m of optical path).
    pub tau: f64,
    /// Box gates: width; Gaussian gates: standard deviation (m).
    pub width: f64,
    /// Transient gates: start of bin 0 (m).
    pub transient_start: f64,
    /// Transient gates: bin width (m).
    pub bin_width: f64,
    /// Transient gates: number of bins.
    pub bins: u32,
    /// Transient gates: the bin shown (0 to bins - 1).
    pub bin: u32,
    /// CW gates: modulation frequency (Hz).
    pub frequency_hz: f64,
    /// CW gates: phase (degrees).
    pub phase_deg: f64,
    /// CW gates: the code's correlation over one period (None: a cosine).
    pub code: Option<CwCode>,
    /// Table gates: the table's (length m, weight) points as read, and its file.
    pub table: Option<(Vec<(f64, f64)>, PathBuf)>,
    /// Table gates: how far the table is moved to longer paths (m).
    pub table_shift: f64,
}

impl GateControls {
    /// Controls showing `gate`, with `bin` shown for a transient gate; the other kinds start
    /// from defaults within `lengths`, the scene's range of path lengths (m).
    pub fn new(gate: &Gate, bin: u32, lengths: (f64, f64)) -> Self {
        let (lo, hi) = length_range(lengths);
        let mut c = GateControls {
            kind: GateChoice::None,
            tau: 3.165,
            width: 0.05,
            transient_start: lo,
            bin_width: (hi - lo) / 32.0,
            bins: 32,
            bin: 0,
            frequency_hz: 100e6,
            phase_deg: 0.0,
            code: None,
            table: None,
            table_shift: 0.0,
        };
        match gate.clone() {
            Gate::None => {}
            Gate::Box { start, end } => (c.kind, c.tau, c.width) = (GateChoice::Box, 0.5 * (start + end), end - start),
            Gate::Gaussian { mean, sigma } => (c.kind, c.tau, c.width) = (GateChoice::Gaussian, mean, sigma),
            Gate::Transient { start, width, bins } => {
                (c.kind, c.transient_start, c.bin_width, c.bins, c.bin) =
                    (GateChoice::Transient, start, width, bins, bin.min(bins - 1))
            }
            Gate::Cw { frequency_hz, phase_deg } => {
                (c.kind, c.frequency_hz, c.phase_deg) = (GateChoice::Cw, frequency_hz, phase_deg)
            }
            Gate::CwCode { frequency_hz, phase_deg, code } => {
                (c.kind, c.frequency_hz, c.phase_deg, c.code) = (GateChoice::Cw, frequency_hz, phase_deg, Some(code))
            }
            Gate::Table { points, source } => (c.kind, c.table) = (GateChoice::Table, Some((points, source))),
        }
        c
    }

    /// The gate the controls describe.
    pub fn gate(&self) -> Gate {
        match self.kind {
            GateChoice::None => Gate::None,
            GateChoice::Box => {
                let start = (self.tau - 0.5 * self.width).max(0.0);
                Gate::Box { start, end: start + self.width }
            }
            GateChoice::Gaussian => Gate::Gaussian { mean: self.tau, sigma: self.width },
            GateChoice::Transient => {
                Gate::Transient { start: self.transient_start, width: self.bin_width, bins: self.bins.max(1) }
            }
            GateChoice::Cw => match self.code {
                None => Gate::Cw { frequency_hz: self.frequency_hz, phase_deg: self.phase_deg },
                Some(code) => Gate::CwCode { frequency_hz: self.frequency_hz, phase_deg: self.phase_deg, code },
            },
            GateChoice::Table => match &self.table {
                Some((points, source)) => Gate::Table {
                    points: points.iter().map(|&(l, w)| (l + self.table_shift, w)).collect(),
                    source: source.clone(),
                },
                None => Gate::None,
            },
        }
    }

    /// The transient bin shown (0 for other gates).
    pub fn shown_bin(&self) -> u32 {
        if self.kind == GateChoice::Transient { self.bin.min(self.bins.max(1) - 1) } else { 0 }
    }

    /// Moves the gate `d` metres of optical path later (earlier when negative): τ for box and
    /// Gaussian gates, the table's shift, the CW phase by -360 f d / c degrees, and for a
    /// transient gate the bin shown by d / bin width bins (rounded, kept within the cube).
    pub fn step(&mut self, d: f64) {
        match self.kind {
            GateChoice::None => {}
            GateChoice::Box | GateChoice::Gaussian => self.tau += d,
            GateChoice::Table => self.table_shift += d,
            GateChoice::Cw => self.phase_deg -= 360.0 * self.frequency_hz * d / gatetrace::units::SPEED_OF_LIGHT,
            GateChoice::Transient => {
                let bin = self.bin as f64 + (d / self.bin_width).round();
                self.bin = bin.clamp(0.0, (self.bins.max(1) - 1) as f64) as u32;
            }
        }
    }
}

/// Sliders keep values from the command line outside their range (only dragging is bounded):
/// a gate or bounce count given at start is rendered as given.
pub(super) const KEEP: egui::SliderClamping = egui::SliderClamping::Edits;

/// The range of path lengths (m) the sliders span: from just below the shortest path the scene
/// allows, over at most four times that (long tails carry little light).
pub(super) fn length_range(lengths: (f64, f64)) -> (f64, f64) {
    (lengths.0 * 0.95, lengths.0 + (lengths.1 - lengths.0).min(4.0 * lengths.0.max(0.5)))
}
