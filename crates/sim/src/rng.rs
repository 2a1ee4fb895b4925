//! Seeds and random streams. Every random quantity of an episode comes from a labelled stream
//! of a 64-bit seed, portable and stable across versions:
//!
//! * **Streams** ([`stream_rng`]): ChaCha8 ([`rand_chacha::ChaCha8Rng`], a fixed algorithm) whose
//!   256-bit key is four successive SplitMix64 outputs started at the seed (little-endian), and
//!   whose ChaCha stream (nonce) is a fixed label per use ([`WAKE_LANES_STREAM`],
//!   [`AMBIENT_STREAM`], [`RLV_STREAM`], one per sensor by name ([`sensor_stream`]); the initial
//!   conditions' label is `crate::task::episode::INITIAL_STREAM`). SplitMix64's output function
//!   is a bijective avalanche mix, so neighbouring seeds give unrelated keys; distinct labels give
//!   independent streams.
//! * **Gaussians** ([`Stream::gaussian`]), by one of two samplers ([`NormalSampler`]):
//!   - **Box-Muller**, written here, on two uniforms from the top 53 bits of one `u64` each,
//!     `u1 = 1 - m1 2^-53` in (0, 1], `u2 = m2 2^-53` in [0, 1):
//!     `r = sqrt(-2 ln u1)`, `z0 = r cos(2 pi u2)`, `z1 = r sin(2 pi u2)`; both used, in that
//!     order. It goes through the platform's `ln`, `sqrt`, `sin` and `cos`, so it is bitwise
//!     identical on one platform and may differ in the last bits across math libraries.
//!   - **Ziggurat** (Marsaglia & Tsang 2000), `rand_distr::StandardNormal` 0.6 built without its
//!     `std` feature: about one `u64` per deviate, no trigonometry (4-5x cheaper), and its rare
//!     tail draws use `libm`'s pure-Rust `ln`/`exp`, so the deviates are bitwise identical on
//!     every platform. The version is pinned in `Cargo.lock`; a change of its algorithm would
//!     show in `tests/test_physics_hash.py`.
//!
//! The `u64` streams are identical on every platform.

use rand_chacha::ChaCha8Rng;
use rand_core::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

/// The end of the one range of every seed a user gives (config `wake_seed`/`wake_seeds`, a
/// reset's seed, a batch's base seeds, `seed + i` included): [0, 2^63), the non-negative
/// values of a signed 64-bit integer. Seeds leave the core in infos as int64 (gymnasium
/// batches Python ints into int64 arrays), so a seed of 2^63 or more would wrap there.
pub const SEED_END: u64 = 1 << 63;

/// [`SEED_END`] in words, for the messages: `[0, 2^63)`.
pub const SEED_RANGE: &str = "[0, 2^63)";

/// ChaCha stream label of the wake turbulence lanes ("WAKELANE" in ASCII).
pub const WAKE_LANES_STREAM: u64 = u64::from_be_bytes(*b"WAKELANE");
/// ChaCha stream label of the ambient turbulence ("AMBIENT " in ASCII).
pub const AMBIENT_STREAM: u64 = u64::from_be_bytes(*b"AMBIENT ");

/// ChaCha stream label of the RLV's motion ("RLV BOOM" in ASCII).
pub const RLV_STREAM: u64 = u64::from_be_bytes(*b"RLV BOOM");

/// The ChaCha stream label of the sensor named `name` (a component of [`crate::task::sensors`],
/// keyed by the episode's initial-conditions seed): the 64-bit FNV-1a hash ([`fnv1a`]) of the
/// bytes of `"SENSORS "` followed by the name's, e.g. `"SENSORS vision"`. Each sensor draws from a
/// stream of its own, so what one sensor draws never shifts another's numbers; no physics stream
/// reads them, so switching the sensors on changes no physics.
pub const fn sensor_stream(name: &str) -> u64 {
    fnv1a(fnv1a(FNV_OFFSET_BASIS, b"SENSORS "), name.as_bytes())
}

/// The 64-bit FNV-1a offset basis (Fowler, Noll & Vo; IETF draft-eastlake-fnv).
pub const FNV_OFFSET_BASIS: u64 = 0xCBF2_9CE4_8422_2325;

/// 64-bit FNV-1a of `bytes` continuing from `hash` ([`FNV_OFFSET_BASIS`] to start): for each
/// byte, `hash = (hash ^ byte) * 0x100000001B3` (mod 2^64).
pub const fn fnv1a(mut hash: u64, bytes: &[u8]) -> u64 {
    let mut i = 0;
    while i < bytes.len() {
        hash = (hash ^ bytes[i] as u64).wrapping_mul(0x0000_0100_0000_01B3);
        i += 1;
    }
    hash
}

/// SplitMix64's output function (Steele, Lea & Flood 2014): a bijective avalanche mix of `z`.
pub fn splitmix64_mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The ChaCha8 generator of stream `stream` for `seed`: key = SplitMix64 outputs 1..=4 from
/// state `seed` (state += 0x9E3779B97F4A7C15 before each output), little-endian; ChaCha stream
/// (nonce) = `stream`; word position 0.
pub fn stream_rng(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut key = [0u8; 32];
    let mut state = seed;
    for chunk in key.chunks_exact_mut(8) {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        chunk.copy_from_slice(&splitmix64_mix(state).to_le_bytes());
    }
    let mut rng = ChaCha8Rng::from_seed(key);
    rng.set_stream(stream);
    rng
}

/// How a [`Stream`] turns its `u64`s into standard normal deviates (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NormalSampler {
    /// Box-Muller, two deviates from two `u64`s (sin, cos, ln, sqrt).
    BoxMuller,
    /// The ziggurat of `rand_distr::StandardNormal`, about one `u64` per deviate.
    #[default]
    Ziggurat,
}

/// A random stream: uniform and standard normal deviates from one ChaCha8 stream.
#[derive(Debug, Clone)]
pub struct Stream {
    rng: ChaCha8Rng,
    spare: Option<f64>,
    sampler: NormalSampler,
}

impl Stream {
    /// The deviates of stream `stream` for `seed` ([`stream_rng`]), normals by Box-Muller.
    pub fn new(seed: u64, stream: u64) -> Stream {
        Stream::with_sampler(seed, stream, NormalSampler::BoxMuller)
    }

    /// The deviates of stream `stream` for `seed`, normals by `sampler`.
    pub fn with_sampler(seed: u64, stream: u64, sampler: NormalSampler) -> Stream {
        Stream {
            rng: stream_rng(seed, stream),
            spare: None,
            sampler,
        }
    }

    /// The stream's exact position (key, stream label, word position, spare deviate).
    pub fn state(&self) -> StreamState {
        StreamState {
            chacha: ChaChaState {
                seed: self.rng.get_seed(),
                stream: self.rng.get_stream(),
                word_pos: self.rng.get_word_pos(),
            },
            spare: self.spare,
        }
    }

    /// The stream at `state`, normals by `sampler` (a configuration choice, not part of the
    /// state): it continues exactly where the saved one was.
    pub fn from_state(state: &StreamState, sampler: NormalSampler) -> Stream {
        let mut rng = ChaCha8Rng::from_seed(state.chacha.seed);
        rng.set_stream(state.chacha.stream);
        rng.set_word_pos(state.chacha.word_pos);
        Stream {
            rng,
            spare: state.spare,
            sampler,
        }
    }

    /// Uniform in [0, 1), from the top 53 bits of one `u64`.
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        (self.rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// The next N(0, 1) deviate.
    #[inline(always)]
    pub fn gaussian(&mut self) -> f64 {
        if self.sampler == NormalSampler::Ziggurat {
            return StandardNormal.sample(&mut self.rng);
        }
        self.box_muller()
    }

    /// [`Stream::gaussian`] by Box-Muller (a pair per two draws).
    #[inline(never)]
    fn box_muller(&mut self) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        const SCALE: f64 = 1.0 / (1u64 << 53) as f64;
        let u1 = 1.0 - (self.rng.next_u64() >> 11) as f64 * SCALE;
        let u2 = (self.rng.next_u64() >> 11) as f64 * SCALE;
        let r = (-2.0 * libm::log(u1)).sqrt();
        let (s, c) = libm::sincos(std::f64::consts::TAU * u2);
        self.spare = Some(r * s);
        r * c
    }
}

/// The seeds of an episode's independent random streams.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Seeds {
    /// Initial conditions.
    pub initial: u64,
    /// Wake turbulence (the "wake seed").
    pub wake: u64,
    /// RLV motion (the boom).
    pub rlv: u64,
}

/// The position of a ChaCha8 generator ([`rand_chacha::ChaCha8Rng`]).
///
/// Part of the state format: a change is a change of [`crate::state_format::FORMAT_VERSION`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ChaChaState {
    /// The 256-bit key (the seed expanded by SplitMix64, [`crate::rng::stream_rng`]).
    pub seed: [u8; 32],
    /// The ChaCha stream (nonce), the label of the use.
    pub stream: u64,
    /// The word position (32-bit words consumed).
    pub word_pos: u128,
}

/// A [`crate::rng::Stream`]: its generator and the spare Box-Muller deviate (the sampler is
/// configuration).
///
/// Part of the state format: a change is a change of [`crate::state_format::FORMAT_VERSION`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StreamState {
    /// The generator.
    pub chacha: ChaChaState,
    /// The second deviate of the last Box-Muller pair, not yet returned.
    pub spare: Option<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every use has its own label: the streams of one seed are independent.
    #[test]
    fn stream_labels_are_distinct() {
        let labels = [
            WAKE_LANES_STREAM,
            AMBIENT_STREAM,
            RLV_STREAM,
            crate::task::episode::INITIAL_STREAM,
            crate::task::randomization::PARAMETERS_STREAM,
            sensor_stream("vision"),
            sensor_stream("gyro"),
            sensor_stream("ahrs"),
            sensor_stream("gnss"),
            sensor_stream("load_cell"),
        ];
        for (i, a) in labels.iter().enumerate() {
            assert!(labels[i + 1..].iter().all(|b| a != b), "{a:x}");
        }
    }

    /// FNV-1a against the published test vectors of its authors' reference code (`""`, `"a"`,
    /// `"foobar"`), and a sensor's label is the hash of `"SENSORS "` and its name.
    #[test]
    fn sensor_labels_are_fnv1a_of_the_prefixed_name() {
        assert_eq!(fnv1a(FNV_OFFSET_BASIS, b""), 0xCBF2_9CE4_8422_2325);
        assert_eq!(fnv1a(FNV_OFFSET_BASIS, b"a"), 0xAF63_DC4C_8601_EC8C);
        assert_eq!(fnv1a(FNV_OFFSET_BASIS, b"foobar"), 0x8594_4171_F739_67E8);
        assert_eq!(
            sensor_stream("vision"),
            fnv1a(FNV_OFFSET_BASIS, b"SENSORS vision")
        );
        assert_ne!(sensor_stream("vision"), sensor_stream("vision2"));
    }

    #[test]
    fn saved_stream_continues_exactly() {
        let mut a = Stream::new(42, RLV_STREAM);
        for _ in 0..5 {
            a.gaussian();
        }
        a.uniform();
        let bytes = postcard::to_allocvec(&a.state()).unwrap();
        let state: StreamState = postcard::from_bytes(&bytes).unwrap();
        let mut b = Stream::from_state(&state, NormalSampler::BoxMuller);
        for _ in 0..100 {
            assert_eq!(a.gaussian().to_bits(), b.gaussian().to_bits());
            assert_eq!(a.uniform().to_bits(), b.uniform().to_bits());
        }
    }
}
