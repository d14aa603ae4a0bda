//! Random numbers: counter-based, one stream per path. CPU twin of `shaders/lib/rng.wesl`
//! (`pcg4d`, `Rng`, `rng_next` there; `pcg4d`, [`Rng`], [`Rng::next_f32`] here). And
//! [`Xorshift64Star`], a small sequential generator for reproducible test inputs and stress
//! configurations (no render uses it).

/// The 4D PCG hash of Jarzynski and Olano ("Hash Functions for GPU Rendering", JCGT 2020).
pub fn pcg4d(input: [u32; 4]) -> [u32; 4] {
    let mut v = input.map(|x| x.wrapping_mul(1664525).wrapping_add(1013904223));
    let mix = |v: &mut [u32; 4]| {
        v[0] = v[0].wrapping_add(v[1].wrapping_mul(v[3]));
        v[1] = v[1].wrapping_add(v[2].wrapping_mul(v[0]));
        v[2] = v[2].wrapping_add(v[0].wrapping_mul(v[1]));
        v[3] = v[3].wrapping_add(v[1].wrapping_mul(v[2]));
    };
    mix(&mut v);
    v = v.map(|x| x ^ (x >> 16));
    mix(&mut v);
    v
}

/// The random stream of one path: number i is a hash of (pixel, sample, seed, i).
#[derive(Clone, Copy, Debug)]
pub struct Rng {
    /// Pixel index (row-major).
    pub pixel: u32,
    /// Sample index within the pixel.
    pub sample: u32,
    /// Render seed.
    pub seed: u32,
    /// Numbers drawn so far.
    pub dimension: u32,
}

impl Rng {
    /// The stream of sample `sample` of pixel `pixel` under render seed `seed`.
    pub fn new(seed: u32, pixel: u32, sample: u32) -> Self {
        Self { pixel, sample, seed, dimension: 0 }
    }

    /// Next uniform number in [0, 1) with 24 random bits (twin of `rng_next`).
    pub fn next_f32(&mut self) -> f32 {
        let h = pcg4d([self.pixel, self.sample, self.seed, self.dimension]);
        self.dimension = self.dimension.wrapping_add(1);
        (h[0] >> 8) as f32 * (1.0 / 16777216.0)
    }

    /// Two numbers (twin of `rng_next2`).
    pub fn next_vec2(&mut self) -> glam::Vec2 {
        let a = self.next_f32();
        glam::Vec2::new(a, self.next_f32())
    }
}

/// The seed word of light subpaths' streams under render seed `seed` (twin of
/// `light_stream_seed` in subpath.wesl): a full hash, so that a slot's camera and light streams
/// share no input bits.
pub fn light_stream_seed(seed: u32) -> u32 {
    pcg4d([seed, 0x6c69_6768, 0x9e37_79b9, 1])[0]
}

/// xorshift64* (Vigna, "An experimental exploration of Marsaglia's xorshift generators,
/// scrambled", 2016): a sequential generator of reproducible inputs for tests and stress
/// configurations. The state must not be 0.
#[derive(Clone, Debug)]
pub struct Xorshift64Star(pub u64);

impl Xorshift64Star {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545F4914F6CDD1D)
    }

    /// Next uniform number in [0, 1) with 53 random bits (the top ones).
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Next uniform number in [0, 1) with 24 random bits (the top ones).
    pub fn next_f32(&mut self) -> f32 {
        ((self.next_u64() >> 40) as f32) / (1u64 << 24) as f32
    }

    /// A uniform point of the cube [-1, 1]^3 (x, y, z drawn in that order by `next_f64`).
    pub fn next_dvec3(&mut self) -> glam::DVec3 {
        glam::DVec3::new(self.next_f64(), self.next_f64(), self.next_f64()) * 2.0 - glam::DVec3::ONE
    }

    /// A uniform point of the cube [-1, 1]^3 in f32 (x, y, z drawn in that order by `next_f32`).
    pub fn next_vec3(&mut self) -> glam::Vec3 {
        glam::Vec3::new(self.next_f32(), self.next_f32(), self.next_f32()) * 2.0 - glam::Vec3::ONE
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fraction of (pixel, sample) pairs whose camera and light streams give numbers with the
    /// same 7 low bits (of the 24 used) at the same dimension, for light streams made by `light`.
    fn low_bit_agreement(light: impl Fn(u32, u32) -> Rng) -> f64 {
        let mut same = 0;
        let mut total = 0;
        for pixel in 0..64 {
            for sample in 0..64 {
                let mut camera = Rng::new(7, pixel, sample);
                let mut light = light(pixel, sample);
                for _ in 0..8 {
                    let (a, b) = (camera.next_f32(), light.next_f32());
                    same += (((a * 16777216.0) as u32 & 127) == ((b * 16777216.0) as u32 & 127)) as u32;
                    total += 1;
                }
            }
        }
        same as f64 / total as f64
    }

    #[test]
    fn camera_and_light_streams_are_independent() {
        // Independent streams agree in 7 bits with probability 1/128 (32768 draws: 256 +- 16).
        let hashed = low_bit_agreement(|p, s| Rng::new(light_stream_seed(7), p, s));
        assert!((hashed - 1.0 / 128.0).abs() < 5.0 * (1.0f64 / 128.0 / 32768.0).sqrt(), "agreement {hashed}");
        // Offsetting the dimension by 2^31 instead leaves pcg4d's low output bits equal.
        let offset = low_bit_agreement(|p, s| Rng { dimension: 1 << 31, ..Rng::new(7, p, s) });
        assert!(offset > 0.5, "agreement {offset}");
    }
}
