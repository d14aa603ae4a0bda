//! Sequences of frames (`render --frames N`): gate sweeps (`--gate-step`) and moving scenes
//! (`--anim-time`). Everything about frame i (its gate, scene time, seed and output name) is a
//! function of the command line and i alone, so `--frame-range A..B` renders exactly the frames
//! a full run would, bit for bit, and a sequence can be split across processes or machines.

use std::path::PathBuf;

use anyhow::{Context as _, Result, bail, ensure};

use crate::film::Gate;

/// A sequence of frames and the part of it to render.
#[derive(Clone, Debug, PartialEq)]
pub struct FramePlan {
    /// Frames in the whole sequence (>= 1).
    pub count: u32,
    /// Gate shift per frame (m of optical path): frame i sees the gate moved by i x step.
    pub gate_step: f64,
    /// Animation clock of the first and last frame (s), sampled at `count` evenly spaced times;
    /// None: the scene as loaded (its rest pose).
    pub anim_time: Option<(f64, f64)>,
    /// First and last frame to render (inclusive, 0-based).
    pub range: (u32, u32),
}

impl FramePlan {
    /// A plan of `count` frames; `range` defaults to all of them. Errors name the option.
    pub fn new(count: u32, gate_step: f64, anim_time: Option<(f64, f64)>, range: Option<(u32, u32)>) -> Result<Self> {
        ensure!(count >= 1, "--frames must be at least 1");
        ensure!(gate_step.is_finite(), "--gate-step must be finite");
        let range = range.unwrap_or((0, count - 1));
        ensure!(
            range.0 <= range.1 && range.1 < count,
            "--frame-range {}..{} does not lie within the {count} frames 0..{}",
            range.0,
            range.1,
            count - 1
        );
        if let Some((t0, t1)) = anim_time {
            ensure!(t0.is_finite() && t1.is_finite(), "--anim-time {t0}..{t1}: give finite times in seconds");
        }
        Ok(Self { count, gate_step, anim_time, range })
    }

    /// The frames to render, in order.
    pub fn frames(&self) -> std::ops::RangeInclusive<u32> {
        self.range.0..=self.range.1
    }

    /// Frame `frame`'s gate: `gate` moved by frame x step.
    pub fn gate(&self, gate: &Gate, frame: u32) -> Result<Gate> {
        if self.gate_step == 0.0 {
            return Ok(gate.clone());
        }
        gate.shifted(self.gate_step * frame as f64).with_context(|| format!("frame {frame} of --gate-step"))
    }

    /// Frame `frame`'s animation time (s): `count` evenly spaced times from t0 to t1 (t0 alone
    /// for one frame).
    pub fn anim_time(&self, frame: u32) -> Option<f64> {
        let (t0, t1) = self.anim_time?;
        Some(if self.count == 1 { t0 } else { t0 + (t1 - t0) * frame as f64 / (self.count - 1) as f64 })
    }
}

/// Frame `frame`'s render seed: `seed` for frame 0 (so frame 0 is the single image of the same
/// seed), then steps of the golden-ratio constant 0x9E3779B9 (mod 2^32).
pub fn frame_seed(seed: u32, frame: u32) -> u32 {
    seed.wrapping_add(frame.wrapping_mul(0x9E37_79B9))
}

/// Parses `A..B` (inclusive) or `A` (one frame).
pub fn parse_frame_range(text: &str) -> Result<(u32, u32)> {
    let number = |s: &str| {
        s.trim()
            .parse::<u32>()
            .with_context(|| format!("`{text}` is not a frame range: give A..B or A (0-based frames)"))
    };
    match text.split_once("..") {
        Some((a, b)) => Ok((number(a)?, number(b)?)),
        None => {
            let a = number(text)?;
            Ok((a, a))
        }
    }
}

/// Parses `T0..T1`, or `T0` alone for one time (seconds of the scene's animation clock).
pub fn parse_time_range(text: &str) -> Result<(f64, f64)> {
    let bad = || format!("`{text}` is not a time range: give T0..T1 or T0 in seconds, e.g. 0..2.5");
    let seconds = |t: &str| t.trim().trim_end_matches('s').parse::<f64>().with_context(bad);
    match text.split_once("..") {
        Some((a, b)) => Ok((seconds(a)?, seconds(b)?)),
        None => {
            let t = seconds(text)?;
            Ok((t, t))
        }
    }
}

/// True when `pattern` names frames: it holds `{frame}` or `{frame:0N}`.
pub fn is_frame_pattern(pattern: &str) -> bool {
    pattern.contains("{frame}") || pattern.contains("{frame:")
}

/// The output path of frame `frame`: `{frame}` in `pattern` becomes the frame number, `{frame:0N}`
/// the number zero-padded to N digits (`frames/f_{frame:04}.npy` -> `frames/f_0007.npy`).
pub fn frame_path(pattern: &str, frame: u32) -> Result<PathBuf> {
    let Some(open) = pattern.find("{frame") else {
        bail!("output `{pattern}` names no frame: put {{frame}} or {{frame:04}} in it, e.g. frames/f_{{frame:04}}.npy");
    };
    let close = open + pattern[open..].find('}').with_context(|| format!("output `{pattern}`: unclosed {{frame"))?;
    let spec = &pattern[open + "{frame".len()..close];
    let number = match spec {
        "" => frame.to_string(),
        _ => {
            let digits =
                spec.strip_prefix(":0").and_then(|d| d.parse::<usize>().ok()).filter(|&d| d <= 12).with_context(
                    || format!("output `{pattern}`: `{{frame{spec}}}` is not {{frame}} or {{frame:0N}}"),
                )?;
            format!("{frame:0digits$}")
        }
    };
    let rest = &pattern[close + 1..];
    ensure!(!is_frame_pattern(rest), "output `{pattern}`: name the frame once");
    Ok(PathBuf::from(format!("{}{number}{rest}", &pattern[..open])))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_zero_keeps_the_seed_and_later_frames_differ() {
        assert_eq!(frame_seed(7, 0), 7);
        let seeds: std::collections::HashSet<u32> = (0..1000).map(|f| frame_seed(7, f)).collect();
        assert_eq!(seeds.len(), 1000);
    }

    #[test]
    fn patterns_name_each_frame() {
        assert_eq!(frame_path("frames/f_{frame:04}.npy", 7).unwrap(), PathBuf::from("frames/f_0007.npy"));
        assert_eq!(frame_path("f{frame}.exr", 12).unwrap(), PathBuf::from("f12.exr"));
        assert!(frame_path("f.exr", 1).is_err());
        assert!(frame_path("f{frame:x}.exr", 1).is_err());
        assert!(frame_path("f{frame}_{frame}.exr", 1).is_err());
    }

    #[test]
    fn ranges_and_plans_are_checked() {
        assert_eq!(parse_frame_range("1..1").unwrap(), (1, 1));
        assert_eq!(parse_frame_range("3").unwrap(), (3, 3));
        assert!(parse_frame_range("a..2").is_err());
        assert_eq!(parse_time_range("0..2.5s").unwrap(), (0.0, 2.5));
        assert_eq!(parse_time_range("0.65").unwrap(), (0.65, 0.65));
        assert!(FramePlan::new(3, 0.05, None, Some((2, 3))).is_err());
        assert!(FramePlan::new(0, 0.05, None, None).is_err());
        let plan = FramePlan::new(5, 0.05, Some((1.0, 2.0)), None).unwrap();
        assert_eq!(plan.frames().collect::<Vec<_>>(), vec![0, 1, 2, 3, 4]);
        assert_eq!(plan.anim_time(4), Some(2.0));
        assert_eq!(plan.anim_time(2), Some(1.5));
    }

    #[test]
    fn gates_move_by_the_step() {
        let plan = FramePlan::new(3, 0.05, None, None).unwrap();
        let gate = Gate::Box { start: 3.14, end: 3.19 };
        match plan.gate(&gate, 2).unwrap() {
            Gate::Box { start, end } => assert!((start - 3.24).abs() < 1e-12 && (end - 3.29).abs() < 1e-12),
            g => panic!("{g:?}"),
        }
        assert!(plan.gate(&Gate::None, 1).is_err());
        // A CW gate moved by one modulation wavelength is the same gate.
        let cw = Gate::Cw { frequency_hz: 30e6, phase_deg: 90.0 };
        let wavelength = crate::units::SPEED_OF_LIGHT / 30e6;
        match cw.shifted(wavelength).unwrap() {
            Gate::Cw { phase_deg, .. } => assert!((phase_deg - (90.0 - 360.0)).abs() < 1e-9),
            g => panic!("{g:?}"),
        }
        // Box gates must stay at non-negative lengths.
        assert!(gate.shifted(-4.0).is_err());
    }
}
