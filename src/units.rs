//! Lengths at the user interface. Time is optical path length in metres (c = 1); `ps` and `ns`
//! are converted with c = 0.299792458 mm/ps (docs/design.md section 1).

use anyhow::{Result, bail};

/// Speed of light (m/s).
pub const SPEED_OF_LIGHT: f64 = 299_792_458.0;

/// Parses a path length: a number of metres, optionally with a unit suffix `m`, `mm`, `um`,
/// `ps` or `ns` (times are converted to the distance light travels in that time).
pub fn parse_length(text: &str) -> Result<f64> {
    let s = text.trim();
    let units: [(&str, f64); 5] =
        [("mm", 1e-3), ("um", 1e-6), ("ps", SPEED_OF_LIGHT * 1e-12), ("ns", SPEED_OF_LIGHT * 1e-9), ("m", 1.0)];
    let (number, scale) =
        units.iter().find_map(|(suffix, scale)| s.strip_suffix(suffix).map(|n| (n.trim(), *scale))).unwrap_or((s, 1.0));
    match number.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v * scale),
        _ => bail!("`{text}` is not a length: give metres (3.14, 3.14m, 2.5mm) or a time (12.5ps, 1ns)"),
    }
}

/// Metres of optical path as picoseconds of flight.
pub fn metres_to_ps(metres: f64) -> f64 {
    metres / (SPEED_OF_LIGHT * 1e-12)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_and_times_convert_with_c() {
        assert_eq!(parse_length("3.14").unwrap(), 3.14);
        assert_eq!(parse_length("3.14m").unwrap(), 3.14);
        assert!((parse_length("2.5mm").unwrap() - 0.0025).abs() < 1e-15);
        // docs/design.md section 1: 12.5 ps = 3.747 mm, 200 ps = 59.96 mm, 1 ns = 299.79 mm.
        assert!((parse_length("12.5ps").unwrap() - 3.747405725e-3).abs() < 1e-12);
        assert!((parse_length("200 ps").unwrap() - 0.0599584916).abs() < 1e-10);
        assert!((parse_length("1ns").unwrap() - 0.299792458).abs() < 1e-12);
        assert!((metres_to_ps(0.299792458) - 1000.0).abs() < 1e-9);
        for bad in ["", "abc", "1.2.3", "5s", "nan", "inf"] {
            assert!(parse_length(bad).is_err(), "`{bad}` must be rejected");
        }
    }
}
