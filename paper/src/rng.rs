//! SplitMix64 (Steele, Lea, Flood 2014) and Box–Muller: the seeded
//! generator of the data set `data/kr270/measurements.csv`, written out so
//! the file is the same bit for bit with any version of any crate. The host
//! tests draw their synthetic data from the same generator.

/// A tiny generator with a fixed definition.
#[derive(Debug, Clone)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in (0, 1): 53 random bits, never 0.
    pub fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// Uniform in `(lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Standard normal by Box–Muller (one of the pair; the other is dropped
    /// to keep the stream simple).
    pub fn normal(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        libm::sqrt(-2.0 * libm::log(u1)) * libm::cos(2.0 * core::f64::consts::PI * u2)
    }

    /// `10^U(lo, hi)`: log-uniform in `(10^lo, 10^hi)`.
    pub fn log_uniform(&mut self, lo: f64, hi: f64) -> f64 {
        libm::pow(10.0, self.range(lo, hi))
    }
}
