//! The film's sums: 128-bit two's-complement fixed point in units of 2^-64, the CPU twin of
//! `shaders/lib/fixed.wesl`. Every f32 contribution is rounded to a multiple of 2^-64, down or up
//! at random with the probabilities that make the rounding unbiased (the random bits hash the
//! value's bits with a key, so a contribution rounds the same however the additions are
//! grouped), and the integers are added exactly. Sums therefore do not depend on the order of
//! additions: atomics, pass sizes, resumed renders and merged shards all give the same bits.
//! Range: +-2^63 (9.2e18); resolution 2^-64 (5.4e-20); values from 2^-40 (1e-12) up keep full
//! f32 precision.

use crate::rng::pcg4d;

/// The value of one unit of a fixed-point sum: 2^-64.
pub const UNIT: f64 = 1.0 / 18_446_744_073_709_551_616.0;

/// `x` in units of 2^-64, rounded as the kernels round it with random bits from (`key`,
/// `seed`); None for NaN, infinities and magnitudes of 2^63 or more (which the kernels count as
/// invalid contributions and add as 0).
pub fn fixed_from_f32(x: f32, key: u32, seed: u32) -> Option<i128> {
    let bits = x.to_bits();
    let biased = (bits >> 23) & 0xff;
    if biased >= 127 + 63 {
        return None;
    }
    let m = if biased == 0 { bits & 0x7f_ffff } else { (bits & 0x7f_ffff) | 0x80_0000 } as i128;
    let k = biased.max(1) as i32 - 150 + 64;
    let magnitude = if k >= 0 {
        m << k
    } else {
        let j = (-k) as u32;
        let random = pcg4d([bits, key, 0x9e37_79b9, seed])[0];
        let up = if j < 24 {
            (random >> (32 - j)) < (m as u32 & ((1 << j) - 1))
        } else {
            (random >> 8) as f32 * (-24.0f32).exp2() < m as f32 * (-(j as f32)).exp2()
        };
        (m >> j.min(127)) + up as i128
    };
    Some(if x < 0.0 { -magnitude } else { magnitude })
}

/// The four 32-bit words of `v` (two's complement, least significant first), as the device
/// stores them.
pub fn to_words(v: i128) -> [u32; 4] {
    let u = v as u128;
    [u as u32, (u >> 32) as u32, (u >> 64) as u32, (u >> 96) as u32]
}

/// The fixed-point number the device stores as `words`.
pub fn from_words(words: [u32; 4]) -> i128 {
    (words[0] as u128 | (words[1] as u128) << 32 | (words[2] as u128) << 64 | (words[3] as u128) << 96) as i128
}

/// The value of the fixed-point sum `v`.
pub fn to_f64(v: i128) -> f64 {
    v as f64 * UNIT
}

/// The key the kernels round film element `element` with (`element_key` in film.wesl).
pub fn element_key(element: u32) -> u32 {
    element.wrapping_mul(0x9e37_79b9).wrapping_add(0x7f4a_7c15)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_round_trip_and_rounding_is_unbiased() {
        // Multiples of 2^-64 within range are exact.
        for x in [0.0f32, 1.0, -1.0, 0.5, 3.0e9, -7.25e-12, f32::MIN_POSITIVE, 1.0e18] {
            let v = fixed_from_f32(x, 1, 2).unwrap();
            if x.abs() >= 2f32.powi(-40) {
                assert_eq!(to_f64(v), x as f64, "{x}");
            }
            assert_eq!(from_words(to_words(v)), v);
        }
        assert!(fixed_from_f32(f32::NAN, 0, 0).is_none() && fixed_from_f32(f32::INFINITY, 0, 0).is_none());
        assert!(fixed_from_f32(2f32.powi(63), 0, 0).is_none() && fixed_from_f32(2f32.powi(62), 0, 0).is_some());
        // A value of 0.3 units rounds up in about 30 % of the keys; the mean is 0.3 units.
        for units in [0.3f64, 2.7, 1e-3] {
            let x = (units * UNIT) as f32;
            let n = 200_000;
            let sum: i128 = (0..n).map(|k| fixed_from_f32(x, k, 7).unwrap()).sum();
            let mean = sum as f64 / n as f64;
            let exact = x as f64 / UNIT;
            let sigma = (exact.fract() * (1.0 - exact.fract()) / n as f64).sqrt();
            assert!((mean - exact).abs() < 5.0 * sigma + 1e-6, "{units} units: mean {mean}, exact {exact}");
        }
        // Sums are exact in any order.
        let values: Vec<i128> =
            (0..1000).map(|i| fixed_from_f32((i as f32 * 0.37).sin() * 1e3, i, 3).unwrap()).collect();
        let forward: i128 = values.iter().sum();
        let backward: i128 = values.iter().rev().sum();
        assert_eq!(forward, backward);
    }
}
