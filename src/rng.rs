//! Deterministic random numbers: a small, seedable generator with independent streams, for
//! everything that needs reproducible randomness — the renderer (one stream per pixel
//! sample), the ray sets, the procedural meshes, tests and benches.
//!
//! The generator is PCG32 (O'Neill, "PCG: A Family of Simple Fast Space-Efficient
//! Statistically Good Algorithms for Random Number Generation", 2014), seeded through
//! SplitMix64: `Rng::new(seed, stream)` gives the same numbers for the same pair on every
//! machine and thread count.

/// A PCG32 (XSH-RR) generator.
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
    inc: u64,
}

#[inline]
fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The generators of every stream of one seed: [`RngStreams::stream`] is
/// [`Rng::new`]`(seed, stream)` with the seed's part computed once.
#[derive(Clone, Copy, Debug)]
pub struct RngStreams {
    /// `splitmix64(seed)`.
    mixed_seed: u64,
}

impl RngStreams {
    /// The generator of stream `stream`: the same numbers as `Rng::new(seed, stream)`.
    #[inline]
    pub fn stream(&self, stream: u64) -> Rng {
        // PCG32's seeding (`state = 0`, a step, `state += seed`, a step) in closed form.
        let inc = stream_increment(stream);
        Rng { state: inc.wrapping_add(self.mixed_seed).wrapping_mul(PCG_MULTIPLIER).wrapping_add(inc), inc }
    }
}

/// PCG32's increment (odd) for stream `stream`.
#[inline]
fn stream_increment(stream: u64) -> u64 {
    (splitmix64(stream ^ 0xDA3E_39CB_94B9_5BDB) << 1) | 1
}

/// PCG32's LCG multiplier.
const PCG_MULTIPLIER: u64 = 6_364_136_223_846_793_005;

impl Rng {
    /// A generator for stream `stream` (e.g. a pixel index) of the render seeded `seed`.
    pub fn new(seed: u64, stream: u64) -> Self {
        let mut r = Self { state: 0, inc: stream_increment(stream) };
        r.next_u32();
        r.state = r.state.wrapping_add(splitmix64(seed));
        r.next_u32();
        r
    }

    /// The generators of every stream of `seed` (for many streams of one seed).
    pub fn streams(seed: u64) -> RngStreams {
        RngStreams { mixed_seed: splitmix64(seed) }
    }

    /// The next 32 random bits.
    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(PCG_MULTIPLIER).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// Uniform in `[0, 1)`.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    /// Two uniforms in `[0, 1)`.
    #[inline]
    pub fn next_2d(&mut self) -> (f32, f32) {
        (self.next_f32(), self.next_f32())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_the_generators_of_new() {
        for seed in [0, 1, 7, u64::MAX, 0x1234_5678_9ABC_DEF0] {
            let streams = Rng::streams(seed);
            for stream in [0, 1, 2, 1 << 32 | 5, u64::MAX, 0xDA3E_39CB_94B9_5BDB] {
                let (mut a, mut b) = (Rng::new(seed, stream), streams.stream(stream));
                let (a, b): (Vec<u32>, Vec<u32>) =
                    ((0..8).map(|_| a.next_u32()).collect(), (0..8).map(|_| b.next_u32()).collect());
                assert_eq!(a, b, "seed {seed}, stream {stream}");
            }
        }
    }

    #[test]
    fn uniform_mean_and_range() {
        let mut r = Rng::new(7, 3);
        let n = 100_000;
        let mut sum = 0.0f64;
        for _ in 0..n {
            let x = r.next_f32();
            assert!((0.0..1.0).contains(&x));
            sum += x as f64;
        }
        // Standard error of the mean is 1/sqrt(12 n) ~ 0.0009.
        assert!((sum / n as f64 - 0.5).abs() < 0.004);
    }

    #[test]
    fn streams_differ_and_repeat() {
        let a: Vec<u32> = (0..4)
            .map({
                let mut r = Rng::new(1, 1);
                move |_| r.next_u32()
            })
            .collect();
        let b: Vec<u32> = (0..4)
            .map({
                let mut r = Rng::new(1, 2);
                move |_| r.next_u32()
            })
            .collect();
        let c: Vec<u32> = (0..4)
            .map({
                let mut r = Rng::new(1, 1);
                move |_| r.next_u32()
            })
            .collect();
        assert_ne!(a, b);
        assert_eq!(a, c);
    }
}
