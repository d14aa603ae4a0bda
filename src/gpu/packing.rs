//! Half-float packing as WGSL's `pack2x16float` and `unpack2x16float` do it, for the tables the
//! kernels read as half floats (texels, the BVH nodes' spreads).

use glam::Vec2;

/// WGSL's pack2x16float: two f32 to IEEE half floats, `a` in the low 16 bits.
pub fn pack2x16float(a: f32, b: f32) -> u32 {
    f32_to_f16(a) as u32 | (f32_to_f16(b) as u32) << 16
}

/// WGSL's unpack2x16float.
pub fn unpack2x16float(x: u32) -> Vec2 {
    Vec2::new(f16_to_f32(x as u16), f16_to_f32((x >> 16) as u16))
}

/// Round-to-nearest-even f32 -> f16 bits (finite inputs; overflow saturates to infinity).
fn f32_to_f16(v: f32) -> u16 {
    let bits = v.to_bits();
    let sign = ((bits >> 16) & 0x8000) as u16;
    let exp = ((bits >> 23) & 0xff) as i32;
    let mant = bits & 0x7f_ffff;
    if exp == 0xff {
        return sign | 0x7c00 | if mant != 0 { 0x200 } else { 0 };
    }
    let e = exp - 127 + 15;
    if e >= 0x1f {
        return sign | 0x7c00;
    }
    if e <= 0 {
        if e < -10 {
            return sign;
        }
        let m = mant | 0x80_0000;
        let shift = (14 - e) as u32;
        let half = m >> shift;
        let rem = m & ((1 << shift) - 1);
        let halfway = 1 << (shift - 1);
        let round = rem > halfway || (rem == halfway && half & 1 == 1);
        return sign | (half + round as u32) as u16;
    }
    let half = ((e as u32) << 10) | (mant >> 13);
    let rem = mant & 0x1fff;
    let round = rem > 0x1000 || (rem == 0x1000 && half & 1 == 1);
    sign | (half + round as u32) as u16
}

fn f16_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = (h >> 10) & 0x1f;
    let mant = (h & 0x3ff) as f32;
    match exp {
        0 => sign * mant * 2f32.powi(-24),
        0x1f => {
            if mant == 0.0 {
                sign * f32::INFINITY
            } else {
                f32::NAN
            }
        }
        e => sign * (1.0 + mant / 1024.0) * 2f32.powi(e as i32 - 15),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn half_floats_round_to_nearest_even() {
        for v in [0.0f32, 1.0, -2.5, 0.21586, 65504.0, 6.1e-5, 3.0e-7, 1e-8] {
            let back = unpack2x16float(pack2x16float(v, -v));
            let tol = v.abs() / 2048.0 + 6e-8;
            assert!((back.x - v).abs() <= tol && (back.y + v).abs() <= tol, "{v} -> {back}");
        }
        assert_eq!(pack2x16float(1.0, 0.0), 0x3c00);
        // One half-float ulp at 1 is 4/4096.
        assert_eq!(pack2x16float(1.0 + 2.0 / 4096.0, 0.0), 0x3c00, "a tie rounds to even");
        assert_eq!(pack2x16float(1.0 + 6.0 / 4096.0, 0.0), 0x3c02, "a tie rounds to even");
        assert_eq!(pack2x16float(1.0 + 3.0 / 4096.0, 0.0), 0x3c01);
        assert!(unpack2x16float(pack2x16float(1e6, 0.0)).x.is_infinite());
    }
}
