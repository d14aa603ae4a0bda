//! Random numbers: one PCG32 stream per path. CPU twin of `shaders/lib/rng.wesl`.

/// PCG RXS-M-XS output permutation; also an integer hash.
pub fn pcg_hash(x: u32) -> u32 {
    let state = x.wrapping_mul(747796405).wrapping_add(2891336453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277803737);
    (word >> 22) ^ word
}

/// Initial state of the stream of sample `sample` of pixel `pixel` under render seed `seed`.
pub fn rng_seed(seed: u32, pixel: u32, sample: u32) -> u32 {
    pcg_hash(pcg_hash(pcg_hash(seed).wrapping_add(pixel)).wrapping_add(sample))
}

/// A PCG32 stream (twin of `rng_next` on a `u32` state).
#[derive(Clone, Copy, Debug)]
pub struct Rng {
    pub state: u32,
}

impl Rng {
    pub fn new(seed: u32, pixel: u32, sample: u32) -> Self {
        Self { state: rng_seed(seed, pixel, sample) }
    }

    /// Next uniform number in [0, 1) with 24 random bits.
    pub fn next_f32(&mut self) -> f32 {
        self.state = self.state.wrapping_mul(747796405).wrapping_add(2891336453);
        let s = self.state;
        let word = ((s >> ((s >> 28) + 4)) ^ s).wrapping_mul(277803737);
        (((word >> 22) ^ word) >> 8) as f32 * (1.0 / 16777216.0)
    }

    pub fn next_vec2(&mut self) -> glam::Vec2 {
        let a = self.next_f32();
        glam::Vec2::new(a, self.next_f32())
    }
}
