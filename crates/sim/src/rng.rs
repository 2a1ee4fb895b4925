//! Seeds and random streams. Every random quantity of an episode comes from a named stream
//! derived from a 64-bit seed, so that streams are independent, portable and stable across
//! versions: ChaCha8 (rand_chacha) seeded with the SplitMix64 hash of (seed, stream label), and
//! Gaussian variates by the Box-Muller transform written here (not a library sampler whose
//! algorithm might change).

use rand_chacha::ChaCha8Rng;
use rand_core::{Rng, SeedableRng};

/// SplitMix64 finaliser: a bijective 64-bit mix with good avalanche.
#[inline]
pub fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The 32-byte ChaCha key of stream `label` of `seed`: four rounds of SplitMix64 over the seed
/// mixed with the label, so that neighbouring seeds and different labels share no key.
pub fn stream_key(seed: u64, label: &str) -> [u8; 32] {
    let mut h = splitmix64(seed);
    for b in label.bytes() {
        h = splitmix64(h ^ u64::from(b));
    }
    let mut key = [0u8; 32];
    for (i, chunk) in key.chunks_mut(8).enumerate() {
        h = splitmix64(h ^ (i as u64 + 1));
        chunk.copy_from_slice(&h.to_le_bytes());
    }
    key
}

/// A random stream: ChaCha8 with a cached second Box-Muller variate.
#[derive(Debug, Clone)]
pub struct Stream {
    rng: ChaCha8Rng,
    spare: Option<f64>,
}

impl Stream {
    /// Stream `label` of `seed`.
    pub fn new(seed: u64, label: &str) -> Self {
        Stream {
            rng: ChaCha8Rng::from_seed(stream_key(seed, label)),
            spare: None,
        }
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn uniform(&mut self) -> f64 {
        (self.rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Standard normal variate (Box-Muller; the second variate of each pair is kept for the next call).
    pub fn gaussian(&mut self) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        // 1 - uniform() is in (0, 1], so the logarithm is finite.
        let r = (-2.0 * (1.0 - self.uniform()).ln()).sqrt();
        let theta = 2.0 * std::f64::consts::PI * self.uniform();
        let (s, c) = theta.sin_cos();
        self.spare = Some(r * s);
        r * c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_reproducible_and_distinct() {
        let a: Vec<f64> = (0..5)
            .map({
                let mut s = Stream::new(42, "wake");
                move |_| s.uniform()
            })
            .collect();
        let b: Vec<f64> = (0..5)
            .map({
                let mut s = Stream::new(42, "wake");
                move |_| s.uniform()
            })
            .collect();
        assert_eq!(a, b);
        let mut other = Stream::new(43, "wake");
        let mut label = Stream::new(42, "boom");
        assert_ne!(a[0], other.uniform());
        assert_ne!(a[0], label.uniform());
    }

    #[test]
    fn gaussian_moments() {
        let mut s = Stream::new(1, "test");
        let n = 200_000;
        let xs: Vec<f64> = (0..n).map(|_| s.gaussian()).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        let kurt = xs.iter().map(|x| (x - mean).powi(4)).sum::<f64>() / n as f64 / (var * var);
        // Standard errors: mean 1/sqrt(n) = 0.0022, variance sqrt(2/n) = 0.0032, kurtosis ~0.011.
        assert!(mean.abs() < 0.01, "{mean}");
        assert!((var - 1.0).abs() < 0.015, "{var}");
        assert!((kurt - 3.0).abs() < 0.06, "{kurt}");
    }
}
