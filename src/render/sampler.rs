//! The numbers each pixel sample's path draws: independent uniforms (PCG32, [`crate::rng`])
//! or a shuffled, scrambled Sobol' sequence (the index shuffle of Burley, "Practical
//! Hash-based Owen Scrambling", JCGT 2020, with a random digital shift of the values), chosen
//! by [`SamplerKind`].
//!
//! Either way a path's numbers are a function of `(seed, pixel, sample index, draw number)`
//! only, so an image depends on the seed alone, never on how pixels are spread over threads
//! or tiles.
//!
//! The Sobol' sampler gives each of the first [`SOBOL_PADS`] draws of a path (a 1D or 2D
//! "pad": the pixel position, a light sample, a BSDF sample, ...) the first one or two
//! dimensions of the Sobol' sequence at the path's sample index, with the index shuffled
//! (Owen's scramble of its bits) and the values XORed with random bits, both keyed by hashes of
//! the pixel, the seed and the draw number (so pads are independent of each other and pixels
//! of each other). Later draws are hashed uniforms. Within a pixel the samples of each pad are stratified: the first `2^k`
//! samples of a 2D pad put one point in each of `2^k` elementary intervals of every shape,
//! which lowers the noise of smooth integrands (direct light from area lights, the first
//! bounces) per sample.

pub use crate::rng::Rng;
use crate::rng::RngStreams;

/// How a path's random numbers are made.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum SamplerKind {
    /// Independent uniforms (PCG32), one generator per pixel sample.
    Independent,
    /// Shuffled, Owen-scrambled Sobol' points per draw (the default): less noise per sample.
    #[default]
    Sobol,
}

impl SamplerKind {
    /// Every kind, in the order the CLI lists them.
    pub const ALL: [SamplerKind; 2] = [SamplerKind::Sobol, SamplerKind::Independent];

    /// The kind's name on the command line and in Python (`sobol`, `independent`).
    pub fn name(self) -> &'static str {
        match self {
            SamplerKind::Independent => "independent",
            SamplerKind::Sobol => "sobol",
        }
    }
}

impl std::fmt::Display for SamplerKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for SamplerKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL.into_iter().find(|k| k.name() == s).ok_or_else(|| {
            let names: Vec<&str> = Self::ALL.iter().map(|k| k.name()).collect();
            format!("unknown sampler {s:?} (expected one of: {})", names.join(", "))
        })
    }
}

/// The samplers of every pixel sample of one render: [`SamplerSource::sampler`] gives the
/// numbers of one pixel sample.
#[derive(Clone, Copy, Debug)]
pub struct SamplerSource {
    kind: SamplerKind,
    streams: RngStreams,
    /// The seed hashed to 32 bits, for the Sobol' scrambles.
    key: u32,
}

impl SamplerSource {
    /// The samplers of a render of `kind` seeded `seed`.
    pub fn new(kind: SamplerKind, seed: u64) -> Self {
        let key = hash32(seed as u32 ^ hash32((seed >> 32) as u32 ^ 0x5bd1_e995));
        Self { kind, streams: Rng::streams(seed), key }
    }

    /// The numbers of sample `index` of pixel `pixel`.
    #[inline]
    pub fn sampler(&self, pixel: usize, index: u32) -> Sampler {
        self.pixel(pixel).sampler(index)
    }

    /// The samplers of pixel `pixel`'s samples (what they share computed once).
    #[inline]
    pub fn pixel(&self, pixel: usize) -> PixelSamplers {
        let key = hash32(self.key ^ hash32(pixel as u32) ^ hash32((pixel as u64 >> 32) as u32 ^ 0x68e3_1da4));
        PixelSamplers { kind: self.kind, streams: self.streams, pixel, key }
    }
}

/// The samplers of one pixel's samples ([`SamplerSource::pixel`]).
#[derive(Clone, Copy, Debug)]
pub struct PixelSamplers {
    kind: SamplerKind,
    streams: RngStreams,
    pixel: usize,
    /// The pixel's (and seed's) hash, for the Sobol' scrambles.
    key: u32,
}

impl PixelSamplers {
    /// The numbers of the pixel's sample `index`.
    #[inline]
    pub fn sampler(&self, index: u32) -> Sampler {
        match self.kind {
            SamplerKind::Independent => {
                Sampler::Independent(self.streams.stream(super::sample_stream(self.pixel, index)))
            }
            SamplerKind::Sobol => {
                Sampler::Sobol(SobolPath { index_reversed: index.reverse_bits(), key: self.key, pad: 0 })
            }
        }
    }
}

/// The random numbers of one path (one pixel sample), drawn in order.
#[derive(Clone, Debug)]
pub enum Sampler {
    /// Independent uniforms.
    Independent(Rng),
    /// Scrambled Sobol' points, one pad per draw.
    Sobol(SobolPath),
}

impl Sampler {
    /// A uniform in `[0, 1)`.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        match self {
            Sampler::Independent(r) => r.next_f32(),
            Sampler::Sobol(s) => s.next_1d(),
        }
    }

    /// Two uniforms in `[0, 1)`, stratified together.
    #[inline]
    pub fn next_2d(&mut self) -> (f32, f32) {
        match self {
            Sampler::Independent(r) => r.next_2d(),
            Sampler::Sobol(s) => s.next_2d(),
        }
    }
}

/// A path's place in the scrambled Sobol' sequence: its sample index within the pixel (bits
/// reversed, as the index shuffle takes it), the pixel's (and seed's) hash, and the number of
/// draws made so far.
///
/// A pad's point is `sobol(d, i) ^ s_d` for dimensions `d = 0, 1`, where `i` is the index
/// shuffled by Owen's scramble, `i = rev(lk_hash(rev(index), s0))` (`lk_hash`). With `j =
/// lk_hash(rev(index), s0)`, dimension 0 (whose generator matrix reverses the bits) is `j`
/// itself and dimension 1 is `sobol_1(rev(j))`, a linear map read from tables
/// (`sobol_dim1_of_reversed`): no bit reversal per draw.
// Tried: Owen-scrambled values (Burley's `nested_uniform_scramble` of each dimension) instead
// of the digital shift: the same back-wall noise on the built-in box at 128 spp and a third
// more shading time (PERFORMANCE.md, "Sobol' samples").
#[derive(Clone, Debug)]
pub struct SobolPath {
    index_reversed: u32,
    key: u32,
    pad: u32,
}

impl SobolPath {
    /// The seed of the next pad's scrambles.
    #[inline]
    fn next_pad(&mut self) -> u32 {
        let seed = hash32(self.key ^ self.pad.wrapping_mul(0x9e37_79b9));
        self.pad += 1;
        seed
    }

    #[inline]
    fn next_1d(&mut self) -> f32 {
        if self.pad >= SOBOL_PADS {
            return unit(self.next_hashed());
        }
        let seed = self.next_pad();
        unit(lk_hash(self.index_reversed, seed) ^ sub_seed(seed, 0x68e3_1da5))
    }

    #[inline]
    fn next_2d(&mut self) -> (f32, f32) {
        if self.pad >= SOBOL_PADS {
            let h = self.next_hashed();
            return (unit(h), unit(hash32(h ^ 0x2f6b_9a31)));
        }
        let seed = self.next_pad();
        let j = lk_hash(self.index_reversed, seed);
        (unit(j ^ sub_seed(seed, 0x68e3_1da5)), unit(sobol_dim1_of_reversed(j) ^ sub_seed(seed, 0xb529_7a4d)))
    }

    /// A pad past [`SOBOL_PADS`]: a hash of the path's key, sample index and pad number (a
    /// counter-based generator: independent uniforms, as cheap as a PCG step).
    #[inline]
    fn next_hashed(&mut self) -> u32 {
        let h = hash32(self.key ^ hash32(self.index_reversed ^ self.pad.wrapping_mul(0x9e37_79b9)));
        self.pad += 1;
        h
    }
}

/// Paths whose draws [`SobolLanes`] makes at once.
pub const SOBOL_LANES: usize = 8;

/// The Sobol' draws of up to [`SOBOL_LANES`] paths at once: lane `j` draws what its path's
/// [`Sampler::Sobol`] would, bit for bit, and advances only when its bit of the draw's mask is
/// set. Each draw is straight-line integer arithmetic over the lanes (no branch per lane), which
/// the compiler vectorises for the ISA the caller is compiled for: the lane shader runs it
/// inside its ISA dispatch.
#[derive(Clone, Copy, Debug, Default)]
pub struct SobolLanes {
    index_reversed: [u32; SOBOL_LANES],
    key: [u32; SOBOL_LANES],
    pad: [u32; SOBOL_LANES],
}

impl SobolLanes {
    /// Takes `sampler`'s place in the sequence into lane `j`; false (lane untouched) when it
    /// is not a Sobol' sampler.
    #[inline]
    pub fn load(&mut self, j: usize, sampler: &Sampler) -> bool {
        let Sampler::Sobol(s) = sampler else { return false };
        (self.index_reversed[j], self.key[j], self.pad[j]) = (s.index_reversed, s.key, s.pad);
        true
    }

    /// Moves `sampler` (the one lane `j` was loaded from) past the draws lane `j` made.
    #[inline]
    pub fn store(&self, j: usize, sampler: &mut Sampler) {
        if let Sampler::Sobol(s) = sampler {
            debug_assert_eq!((s.index_reversed, s.key), (self.index_reversed[j], self.key[j]), "lane {j}'s sampler");
            s.pad = self.pad[j];
        }
    }

    /// [`Sampler::next_2d`] of the lanes of `mask` into `u[0][j], u[1][j]`; the other lanes
    /// of `u` keep their values.
    #[inline(always)]
    // Five arrays in lockstep, indexed by lane.
    #[allow(clippy::needless_range_loop)]
    pub fn next_2d(&mut self, mask: u32, u: &mut [[f32; SOBOL_LANES]; 2]) {
        for j in 0..SOBOL_LANES {
            let (index_reversed, key, pad) = (self.index_reversed[j], self.key[j], self.pad[j]);
            // `SobolPath::next_2d` before and after SOBOL_PADS, both computed, one kept.
            let seed = hash32(key ^ pad.wrapping_mul(0x9e37_79b9));
            let shuffled = lk_hash(index_reversed, seed);
            let sobol = (
                shuffled ^ sub_seed(seed, 0x68e3_1da5),
                sobol_dim1_of_reversed(shuffled) ^ sub_seed(seed, 0xb529_7a4d),
            );
            let h = hash32(key ^ hash32(index_reversed ^ pad.wrapping_mul(0x9e37_79b9)));
            let hashed = (h, hash32(h ^ 0x2f6b_9a31));
            let (x, y) = if pad < SOBOL_PADS { sobol } else { hashed };
            let on = mask >> j & 1;
            if on != 0 {
                (u[0][j], u[1][j]) = (unit(x), unit(y));
            }
            self.pad[j] = pad + on;
        }
    }

    /// [`Sampler::next_f32`] of the lanes of `mask` into `u[j]` (the first coordinate of a 2D
    /// draw: `SobolPath::next_1d` is `next_2d`'s `x`); the other lanes of `u` keep their values.
    #[inline(always)]
    pub fn next_1d(&mut self, mask: u32, u: &mut [f32; SOBOL_LANES]) {
        let mut uv = [*u, [0.0; SOBOL_LANES]];
        self.next_2d(mask, &mut uv);
        *u = uv[0];
    }

    /// Skips one draw (1D or 2D) in the lanes of `mask`, as a draw whose value is not used.
    #[inline(always)]
    pub fn skip(&mut self, mask: u32) {
        for j in 0..SOBOL_LANES {
            self.pad[j] += mask >> j & 1;
        }
    }
}

/// Draws of a path that take scrambled Sobol' points; later draws take independent hashed
/// uniforms. Stratification pays in the first bounces' pixel, light and BSDF samples, where the
/// integrand is smooth; deeper draws gain little from it and a Sobol' pad costs several times a
/// hashed one.
pub const SOBOL_PADS: u32 = 8;

/// A second seed from a pad's seed (the scrambles of its two dimensions differ).
#[inline(always)]
fn sub_seed(seed: u32, odd: u32) -> u32 {
    let s = seed.wrapping_mul(odd);
    s ^ (s >> 15)
}

/// The top 24 bits of `x` as a float in `[0, 1)`.
#[inline(always)]
fn unit(x: u32) -> f32 {
    (x >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

/// A 32-bit integer hash (the finaliser of MurmurHash3).
#[inline(always)]
fn hash32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x85eb_ca6b);
    x ^= x >> 13;
    x = x.wrapping_mul(0xc2b2_ae35);
    x ^ (x >> 16)
}

/// Laine and Karras's hash: a nested uniform (Owen) scramble of a binary fraction written
/// with its bits reversed (least significant first), so each output bit depends only on the
/// input bits below it (Burley 2020). Owen's scramble of `x` is `rev(lk_hash(rev(x), seed))`.
#[inline(always)]
fn lk_hash(mut x: u32, seed: u32) -> u32 {
    x = x.wrapping_add(seed);
    x ^= x.wrapping_mul(0x6c50_b47c);
    x ^= x.wrapping_mul(0xb82f_1e52);
    x ^= x.wrapping_mul(0xc7af_e638);
    x ^= x.wrapping_mul(0x8d22_f6e6);
    x
}

/// The second dimension of the Sobol' sequence at the index whose bits reversed are `j`:
/// `sobol_1(rev(j))`, where `sobol_1`'s generator matrix is Pascal's triangle mod 2 (direction
/// `k` is `v_k = v_{k-1} ^ (v_{k-1} >> 1)`, `v_0 = 2^31`). Linear over GF(2), so read a byte of
/// `j` at a time from tables.
#[inline(always)]
fn sobol_dim1_of_reversed(j: u32) -> u32 {
    let t = &SOBOL_DIM1_OF_REVERSED_BYTES;
    t[0][(j & 0xff) as usize]
        ^ t[1][(j >> 8 & 0xff) as usize]
        ^ t[2][(j >> 16 & 0xff) as usize]
        ^ t[3][(j >> 24) as usize]
}

/// `SOBOL_DIM1_OF_REVERSED_BYTES[b][v]`: [`sobol_dim1_of_reversed`] of byte value `v` at byte `b`.
static SOBOL_DIM1_OF_REVERSED_BYTES: [[u32; 256]; 4] = sobol_dim1_of_reversed_tables();

const fn sobol_dim1_of_reversed_tables() -> [[u32; 256]; 4] {
    let mut dirs = [0u32; 32];
    dirs[0] = 1 << 31;
    let mut k = 1;
    while k < 32 {
        dirs[k] = dirs[k - 1] ^ (dirs[k - 1] >> 1);
        k += 1;
    }
    // Bit `b` of `j` is bit `31 - b` of the index, whose direction is `dirs[31 - b]`.
    let mut t = [[0u32; 256]; 4];
    let mut byte = 0;
    while byte < 4 {
        let mut v = 0;
        while v < 256 {
            let mut x = 0;
            let mut bit = 0;
            while bit < 8 {
                if v >> bit & 1 == 1 {
                    x ^= dirs[31 - (8 * byte + bit)];
                }
                bit += 1;
            }
            t[byte][v] = x;
            v += 1;
        }
        byte += 1;
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bitwise Sobol' second dimension, from its direction numbers.
    fn sobol_dim1_bitwise(mut index: u32) -> u32 {
        let (mut v, mut x) = (1u32 << 31, 0u32);
        while index != 0 {
            if index & 1 == 1 {
                x ^= v;
            }
            index >>= 1;
            v ^= v >> 1;
        }
        x
    }

    /// Eight paths drawn together equal each path drawn alone, bit for bit, whatever the
    /// masks, before and after the Sobol' pads run out.
    #[test]
    fn sobol_lanes_draw_what_each_path_draws() {
        let source = SamplerSource::new(SamplerKind::Sobol, 99);
        let mut rng = Rng::new(3, 4);
        for round in 0..200u32 {
            let mut alone: Vec<Sampler> =
                (0..SOBOL_LANES).map(|j| source.sampler(round as usize * 31 + j, rng.next_u32() % 4096)).collect();
            // Lanes start at different places in their paths.
            for (j, s) in alone.iter_mut().enumerate() {
                for _ in 0..(round as usize + j) % 11 {
                    s.next_f32();
                }
            }
            let start = alone.clone();
            let mut together = SobolLanes::default();
            for (j, s) in alone.iter().enumerate() {
                assert!(together.load(j, s));
            }
            let mut u = [[-1.0f32; SOBOL_LANES]; 2];
            for draw in 0..12 {
                let mask = rng.next_u32() & 0xff;
                let before = u;
                match draw % 4 {
                    2 => together.skip(mask),
                    3 => together.next_1d(mask, &mut u[0]),
                    _ => together.next_2d(mask, &mut u),
                }
                for (j, s) in alone.iter_mut().enumerate() {
                    let want = match (mask >> j & 1 != 0, draw % 4) {
                        (false, _) => (before[0][j], before[1][j]),
                        (true, 2) => {
                            s.next_f32();
                            (before[0][j], before[1][j])
                        }
                        (true, 3) => (s.next_f32(), before[1][j]),
                        (true, _) => s.next_2d(),
                    };
                    assert_eq!((u[0][j], u[1][j]), want, "round {round} draw {draw} lane {j}");
                }
            }
            for (j, s) in alone.iter().enumerate() {
                let mut stored = start[j].clone();
                together.store(j, &mut stored);
                // The same place in the sequence: the next draws agree.
                assert_eq!(stored.clone().next_2d(), s.clone().next_2d(), "round {round} lane {j}");
            }
        }
        assert!(!SobolLanes::default().load(0, &Sampler::Independent(Rng::new(1, 1))));
    }

    #[test]
    fn tables_give_the_bitwise_second_dimension() {
        let mut rng = Rng::new(1, 2);
        let dim1 = |i: u32| sobol_dim1_of_reversed(i.reverse_bits());
        for i in (0..4096).chain((0..4096).map(|_| rng.next_u32())) {
            assert_eq!(dim1(i), sobol_dim1_bitwise(i), "index {i}");
        }
        // The first points of the (0, 2)-sequence: 0, 1/2, then 3/4 and 1/4.
        assert_eq!([dim1(0), dim1(1), dim1(2), dim1(3)], [0, 1 << 31, 3 << 30, 1 << 30]);
    }

    /// The pads computed in the reversed domain are the formula as written: the Sobol' points
    /// at the Owen-scrambled index, XOR-scrambled.
    #[test]
    fn pads_are_shuffled_scrambled_sobol() {
        let nus = |x: u32, seed: u32| lk_hash(x.reverse_bits(), seed).reverse_bits();
        let source = SamplerSource::new(SamplerKind::Sobol, 11);
        for (pixel, index) in [(0usize, 0u32), (3, 1), (77, 12), (1000, 1023)] {
            let Sampler::Sobol(mut path) = source.sampler(pixel, index) else { unreachable!() };
            let mut copy = path.clone();
            let seed = copy.next_pad();
            let i = nus(index, seed);
            let x = i.reverse_bits() ^ sub_seed(seed, 0x68e3_1da5);
            let y = sobol_dim1_bitwise(i) ^ sub_seed(seed, 0xb529_7a4d);
            assert_eq!(path.next_2d(), (unit(x), unit(y)));
        }
    }

    /// The first `2^k` samples of a 2D pad put exactly one point in each of the `2^k`
    /// elementary intervals of every shape `2^a × 2^(k-a)` (a (0, k, 2)-net), in every pixel
    /// and pad: the stratification that the scrambles must keep.
    #[test]
    fn each_pad_is_a_02_net_in_every_pixel() {
        let source = SamplerSource::new(SamplerKind::Sobol, 7);
        for pixel in [0usize, 1, 12345, 1 << 33] {
            for k in [2u32, 4, 6] {
                let n = 1u32 << k;
                let pads: Vec<Vec<(f32, f32)>> = (0..n)
                    .map(|i| {
                        let mut s = source.sampler(pixel, i);
                        (0..3).map(|_| s.next_2d()).collect()
                    })
                    .collect();
                for pad in 0..3 {
                    for a in 0..=k {
                        let (nx, ny) = (1u32 << a, 1u32 << (k - a));
                        let mut seen = vec![false; n as usize];
                        for p in &pads {
                            let (x, y) = p[pad];
                            let cell = (y * ny as f32) as u32 * nx + (x * nx as f32) as u32;
                            assert!(!seen[cell as usize], "pixel {pixel}, pad {pad}, {nx}x{ny}: two points in a cell");
                            seen[cell as usize] = true;
                        }
                    }
                }
            }
        }
    }

    /// Uniform over the whole: the mean and variance of many pixels' first points are those of
    /// a uniform variable, and pixels and pads differ.
    #[test]
    fn pads_and_pixels_are_scrambled_apart() {
        let source = SamplerSource::new(SamplerKind::Sobol, 3);
        let n = 20000;
        let xs: Vec<f32> = (0..n).map(|p| source.sampler(p, 0).next_f32()).collect();
        let mean = xs.iter().map(|&x| x as f64).sum::<f64>() / n as f64;
        let var = xs.iter().map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / n as f64;
        assert!((mean - 0.5).abs() < 0.01 && (var - 1.0 / 12.0).abs() < 0.005, "mean {mean}, variance {var}");
        let mut s = source.sampler(5, 3);
        let (a, b) = (s.next_2d(), s.next_2d());
        assert_ne!(a, b);
        assert_ne!(source.sampler(5, 3).next_2d(), source.sampler(6, 3).next_2d());
        assert_ne!(SamplerSource::new(SamplerKind::Sobol, 4).sampler(5, 3).next_2d(), a);
    }

    #[test]
    fn names_round_trip() {
        for k in SamplerKind::ALL {
            assert_eq!(k.name().parse::<SamplerKind>(), Ok(k));
        }
        assert!("halton".parse::<SamplerKind>().unwrap_err().contains("sobol, independent"));
    }
}
