//! The one format of saved states (snapshots for `get_state`/`set_state` and pickling): plain
//! serde-derived state types, encoded with [postcard] (a compact binary serde format whose wire
//! format is documented and stable since postcard 1.0), behind a fixed header that says what the
//! blob is and protects it with a checksum.
//!
//! # Layout (all integers little-endian)
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 8 | magic, `ACCDSNAP` in ASCII ([`MAGIC`]) |
//! | 8 | 4 | format version, u32 ([`FORMAT_VERSION`]) |
//! | 12 | 4 | kind of object, u32 ([`StateKind`]) |
//! | 16 | 8 | number of envs, u64 (1 for a single env or a capture simulation) |
//! | 24 | 32 | SHA-256 of the configuration's canonical JSON ([`config_hash`]) |
//! | 56 | 8 | payload length in bytes, u64 |
//! | 64 | 4 | CRC-32 (IEEE, as zlib's `crc32`) of bytes 0..64 and the payload, u32 |
//! | 68 | n | payload: the state type of the kind, postcard-encoded |
//!
//! The configuration, the aerodynamic and wake tables are not in the payload: a state is
//! restored into an object built from the same configuration, which the config hash pins (a
//! table given by a file path is pinned by its path, a table given inline by its contents).
//!
//! # Reading
//! [`decode`] checks, in this order, and stops at the first failure with a [`StateError`] that
//! says what is wrong: the magic (a blob of the hand-written codec of format version 2,
//! `ACCDST02`, is recognised and refused with [`StateError::OldFormat`]), the version, the
//! length, the checksum, the kind, the number of envs, the config hash, then the payload's
//! decoding (every byte consumed). Owners then check the decoded state's structure against the
//! object (lengths, indices) before they change anything; a state is applied whole or not at all.
//!
//! # Version policy
//! [`FORMAT_VERSION`] changes with any change of the header or of a state type below (a field
//! added, removed, reordered or retyped; postcard is not self-describing, so the types *are* the
//! format). A reader accepts its own version only and refuses others with
//! [`StateError::Version`]; states are snapshots of a running program, not archives, so no
//! migration is kept. `tests::payload_layout_is_pinned` fails when the encoding of the state
//! types changes, as a reminder.
//!
//! [postcard]: https://docs.rs/postcard

use serde::de::DeserializeOwned;
use serde::Serialize;
use sha2::{Digest, Sha256};
use thiserror::Error;

/// The first 8 bytes of every state.
pub const MAGIC: [u8; 8] = *b"ACCDSNAP";
/// The format version written and the only one read. Version 5 split the sensor model's state
/// into one state per sensor, each with its own stream; version 4 added the sensor model's state
/// to the episode's; version 2 was the hand-written codec (magic `ACCDST02`), version 1 its
/// predecessor.
pub const FORMAT_VERSION: u32 = 5;
/// Bytes before the payload.
pub const HEADER_LEN: usize = 68;
/// The magic of format version 2 (the hand-written codec of `accd_sim::codec`).
const OLD_MAGIC: &[u8; 8] = b"ACCDST02";

/// What a state is a state of (the header's kind field).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StateKind {
    /// One [`crate::CaptureSim`] (Python `accd_gym.CaptureSim`).
    CaptureSim,
    /// An `accd_batch::BatchEnv` saved from Rust.
    Batch,
    /// Python's single env, `accd_gym.InAirCaptureEnv`.
    SingleEnv,
    /// Python's gymnasium vector env, `accd_gym.InAirCaptureVectorEnv`.
    VectorEnv,
    /// Python's stable-baselines3 VecEnv, `accd_gym.sb3.AccdVecEnv`.
    Sb3VecEnv,
}

impl StateKind {
    const ALL: [StateKind; 5] = [
        StateKind::CaptureSim,
        StateKind::Batch,
        StateKind::SingleEnv,
        StateKind::VectorEnv,
        StateKind::Sb3VecEnv,
    ];

    /// The code in the header.
    pub fn code(self) -> u32 {
        match self {
            StateKind::CaptureSim => 1,
            StateKind::Batch => 2,
            StateKind::SingleEnv => 3,
            StateKind::VectorEnv => 4,
            StateKind::Sb3VecEnv => 5,
        }
    }

    /// The kind of a header code.
    pub fn from_code(code: u32) -> Option<StateKind> {
        StateKind::ALL.into_iter().find(|k| k.code() == code)
    }

    /// What it is, for messages.
    pub fn name(self) -> &'static str {
        match self {
            StateKind::CaptureSim => "a CaptureSim",
            StateKind::Batch => "a Rust BatchEnv",
            StateKind::SingleEnv => "a single env (InAirCaptureEnv)",
            StateKind::VectorEnv => "a gymnasium vector env (InAirCaptureVectorEnv)",
            StateKind::Sb3VecEnv => "a stable-baselines3 VecEnv (AccdVecEnv)",
        }
    }
}

fn kind_name(code: u32) -> String {
    match StateKind::from_code(code) {
        Some(k) => k.name().to_owned(),
        None => format!("an unknown kind (code {code})"),
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// A state that cannot be restored, and why. Nothing was changed when one is returned.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum StateError {
    /// The blob does not start with [`MAGIC`].
    #[error(
        "not an accd-gym state: {len} bytes that do not start with the magic bytes \"ACCDSNAP\""
    )]
    NotAState {
        /// Length of the blob.
        len: usize,
    },
    /// A state of the hand-written codec (format version 2).
    #[error("a state in the old format (magic \"ACCDST02\", format version 2): the state format changed in version {FORMAT_VERSION} and old states cannot be read; save the state again with this version of accd-gym")]
    OldFormat,
    /// Another format version.
    #[error("a state of format version {found}; this version of accd-gym reads format version {supported} only (the state format changed)")]
    Version {
        /// The version in the header.
        found: u32,
        /// The version this build reads.
        supported: u32,
    },
    /// Fewer bytes than the header says.
    #[error("truncated state: {found} bytes, expected {expected}")]
    Truncated {
        /// Bytes the header (or the header itself) needs.
        expected: u64,
        /// Bytes given.
        found: usize,
    },
    /// More bytes than the header says.
    #[error("state has trailing bytes: {found} bytes, expected {expected}")]
    TrailingBytes {
        /// Bytes the header says.
        expected: u64,
        /// Bytes given.
        found: usize,
    },
    /// The checksum does not match: the bytes were changed.
    #[error("corrupted state: the CRC-32 of its contents is {computed:08x}, the header says {stored:08x}")]
    Checksum {
        /// In the header.
        stored: u32,
        /// Of the bytes given.
        computed: u32,
    },
    /// A state of another kind of object.
    #[error("a state of {found}, expected a state of {}", .expected.name())]
    Kind {
        /// The kind restoring.
        expected: StateKind,
        /// What the header says, in words.
        found: String,
    },
    /// A state of another number of envs.
    #[error("a state of {found} envs, expected a state of {expected} envs")]
    NumEnvs {
        /// Envs of the object restoring.
        expected: u64,
        /// Envs in the state.
        found: u64,
    },
    /// A state of another configuration.
    #[error("a state of another configuration (config hash {found}, this object's {expected}): restore it into an object built with the same configuration")]
    Config {
        /// This object's config hash (first 8 bytes, hex).
        expected: String,
        /// The state's (first 8 bytes, hex).
        found: String,
    },
    /// The payload does not decode as the state type of its kind.
    #[error("malformed state payload: {reason}")]
    Payload {
        /// The decoder's message.
        reason: String,
    },
    /// A decoded field does not fit the object (a length, an index).
    #[error("invalid state: `{field}` = {value}, expected {allowed}")]
    Invalid {
        /// Dotted name of the field.
        field: String,
        /// The value found, printed.
        value: String,
        /// What fits, in words.
        allowed: String,
    },
}

impl StateError {
    /// Shorthand for [`StateError::Invalid`].
    pub fn invalid(field: &str, value: impl std::fmt::Display, allowed: impl Into<String>) -> Self {
        StateError::Invalid {
            field: field.to_owned(),
            value: value.to_string(),
            allowed: allowed.into(),
        }
    }
}

/// Fails unless `found == expected` (a decoded length against the object's).
pub fn check_len(field: &str, found: usize, expected: usize) -> Result<(), StateError> {
    if found != expected {
        return Err(StateError::invalid(
            field,
            format!("{found} values"),
            format!("{expected} values (the length of this configuration)"),
        ));
    }
    Ok(())
}

/// What a state must be to be restored into an object.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Expected {
    /// The object's kind.
    pub kind: StateKind,
    /// Its [`config_hash`].
    pub config_hash: [u8; 32],
    /// Its number of envs.
    pub num_envs: u64,
}

/// A decoded header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Header {
    /// Format version.
    pub version: u32,
    /// Kind code ([`StateKind::code`]).
    pub kind: u32,
    /// Number of envs.
    pub num_envs: u64,
    /// SHA-256 of the configuration's canonical JSON.
    pub config_hash: [u8; 32],
    /// Payload length, bytes.
    pub payload_len: u64,
    /// CRC-32 of bytes 0..64 and the payload.
    pub checksum: u32,
}

/// The SHA-256 of a configuration's canonical JSON: serde_json's encoding with every object's
/// keys sorted (so a reordering of fields in the source does not change it), no whitespace.
/// Stable across runs, platforms and builds (unlike Rust's `DefaultHasher`).
pub fn config_hash<T: Serialize>(config: &T) -> Result<[u8; 32], StateError> {
    let value = serde_json::to_value(config).map_err(|e| StateError::Payload {
        reason: format!("the configuration cannot be encoded as JSON: {e}"),
    })?;
    let mut text = String::new();
    canonical(&value, &mut text);
    Ok(Sha256::digest(text.as_bytes()).into())
}

fn canonical(value: &serde_json::Value, out: &mut String) {
    use serde_json::Value;
    match value {
        Value::Object(map) => {
            let mut keys: Vec<&String> = map.keys().collect();
            keys.sort();
            out.push('{');
            for (i, k) in keys.into_iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                out.push_str(&Value::String(k.clone()).to_string());
                out.push(':');
                canonical(&map[k], out);
            }
            out.push('}');
        }
        Value::Array(items) => {
            out.push('[');
            for (i, v) in items.iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                canonical(v, out);
            }
            out.push(']');
        }
        other => out.push_str(&other.to_string()),
    }
}

fn crc(header: &[u8], payload: &[u8]) -> u32 {
    let mut h = crc32fast::Hasher::new();
    h.update(header);
    h.update(payload);
    h.finalize()
}

/// Encodes `payload` behind a header for an object of `kind`, `num_envs` envs and config hash
/// `config_hash`.
pub fn encode<T: Serialize>(
    kind: StateKind,
    config_hash: &[u8; 32],
    num_envs: u64,
    payload: &T,
) -> Result<Vec<u8>, StateError> {
    let body = postcard::to_allocvec(payload).map_err(|e| StateError::Payload {
        reason: format!("cannot encode: {e}"),
    })?;
    let mut out = Vec::with_capacity(HEADER_LEN + body.len());
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&kind.code().to_le_bytes());
    out.extend_from_slice(&num_envs.to_le_bytes());
    out.extend_from_slice(config_hash);
    out.extend_from_slice(&(body.len() as u64).to_le_bytes());
    let sum = crc(&out, &body);
    out.extend_from_slice(&sum.to_le_bytes());
    out.extend_from_slice(&body);
    Ok(out)
}

fn le<const N: usize>(bytes: &[u8], at: usize) -> [u8; N] {
    let mut out = [0u8; N];
    out.copy_from_slice(&bytes[at..at + N]);
    out
}

/// Reads and checks the header: magic, version, length and checksum (not what it describes).
pub fn read_header(bytes: &[u8]) -> Result<Header, StateError> {
    let n = bytes.len().min(MAGIC.len());
    if bytes[..n] != MAGIC[..n] {
        let old = bytes.starts_with(OLD_MAGIC) || bytes.get(2..10) == Some(&OLD_MAGIC[..]);
        return Err(if old {
            StateError::OldFormat
        } else {
            StateError::NotAState { len: bytes.len() }
        });
    }
    if bytes.len() < 12 {
        return Err(StateError::Truncated {
            expected: HEADER_LEN as u64,
            found: bytes.len(),
        });
    }
    let version = u32::from_le_bytes(le(bytes, 8));
    if version != FORMAT_VERSION {
        return Err(StateError::Version {
            found: version,
            supported: FORMAT_VERSION,
        });
    }
    if bytes.len() < HEADER_LEN {
        return Err(StateError::Truncated {
            expected: HEADER_LEN as u64,
            found: bytes.len(),
        });
    }
    let header = Header {
        version,
        kind: u32::from_le_bytes(le(bytes, 12)),
        num_envs: u64::from_le_bytes(le(bytes, 16)),
        config_hash: le(bytes, 24),
        payload_len: u64::from_le_bytes(le(bytes, 56)),
        checksum: u32::from_le_bytes(le(bytes, 64)),
    };
    let total = (HEADER_LEN as u64).saturating_add(header.payload_len);
    if (bytes.len() as u64) < total {
        return Err(StateError::Truncated {
            expected: total,
            found: bytes.len(),
        });
    }
    if (bytes.len() as u64) > total {
        return Err(StateError::TrailingBytes {
            expected: total,
            found: bytes.len(),
        });
    }
    let computed = crc(&bytes[..64], &bytes[HEADER_LEN..]);
    if computed != header.checksum {
        return Err(StateError::Checksum {
            stored: header.checksum,
            computed,
        });
    }
    Ok(header)
}

/// Checks a state against what the object restoring it expects and decodes its payload (every
/// byte must be consumed). The caller then checks the decoded value's structure.
pub fn decode<T: DeserializeOwned>(bytes: &[u8], expected: &Expected) -> Result<T, StateError> {
    let header = read_header(bytes)?;
    if header.kind != expected.kind.code() {
        return Err(StateError::Kind {
            expected: expected.kind,
            found: kind_name(header.kind),
        });
    }
    if header.num_envs != expected.num_envs {
        return Err(StateError::NumEnvs {
            expected: expected.num_envs,
            found: header.num_envs,
        });
    }
    if header.config_hash != expected.config_hash {
        return Err(StateError::Config {
            expected: hex(&expected.config_hash[..8]),
            found: hex(&header.config_hash[..8]),
        });
    }
    let (value, rest) =
        postcard::take_from_bytes::<T>(&bytes[HEADER_LEN..]).map_err(|e| StateError::Payload {
            reason: format!("{e}"),
        })?;
    if !rest.is_empty() {
        return Err(StateError::Payload {
            reason: format!("{} bytes left after the state", rest.len()),
        });
    }
    Ok(value)
}

// The state types live beside their owners (rng, boom, turbulence, air, capture, episode), each
// documented as part of the format: any change of one is a change of the format (bump FORMAT_VERSION; the layout is pinned
// by `payload_layout_is_pinned`).

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::air::AirState;
    use crate::physics::boom::BoomState;
    use crate::physics::capture::CaptureState;
    use crate::physics::turbulence::{LaneState, TurbulenceState};
    use crate::rng::{ChaChaState, Seeds, StreamState};
    use crate::task::episode::EpisodeState;
    use crate::task::observation::ACT_DIM;
    use crate::task::sensors::ahrs::AhrsState;
    use crate::task::sensors::delay_line::DelayLineState;
    use crate::task::sensors::gnss::GnssState;
    use crate::task::sensors::gyro::GyroState;
    use crate::task::sensors::load_cell::LoadCellState;
    use crate::task::sensors::vision::VisionState;
    use crate::task::sensors::{ComponentStates, SensorState};
    use serde::Deserialize;

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Sample {
        a: u64,
        b: Vec<f64>,
        c: Option<String>,
    }

    fn sample() -> Sample {
        Sample {
            a: 7,
            b: vec![-0.1, f64::MIN_POSITIVE, 1e300],
            c: Some("x".into()),
        }
    }

    const HASH: [u8; 32] = [3; 32];

    fn expected() -> Expected {
        Expected {
            kind: StateKind::VectorEnv,
            config_hash: HASH,
            num_envs: 4,
        }
    }

    fn blob() -> Vec<u8> {
        encode(StateKind::VectorEnv, &HASH, 4, &sample()).unwrap()
    }

    #[test]
    fn header_layout_and_round_trip() {
        let bytes = blob();
        assert_eq!(&bytes[..8], b"ACCDSNAP");
        assert_eq!(u32::from_le_bytes(le(&bytes, 8)), FORMAT_VERSION);
        assert_eq!(u32::from_le_bytes(le(&bytes, 12)), 4);
        assert_eq!(u64::from_le_bytes(le(&bytes, 16)), 4);
        assert_eq!(&bytes[24..56], &HASH);
        let payload = (bytes.len() - HEADER_LEN) as u64;
        assert_eq!(u64::from_le_bytes(le(&bytes, 56)), payload);
        // The checksum is zlib's CRC-32 of everything but itself (check value of "123456789").
        assert_eq!(crc(b"1234", b"56789"), 0xCBF4_3926);
        let mut without = bytes[..64].to_vec();
        without.extend_from_slice(&bytes[HEADER_LEN..]);
        assert_eq!(
            u32::from_le_bytes(le(&bytes, 64)),
            crc32fast::hash(&without)
        );
        let back: Sample = decode(&bytes, &expected()).unwrap();
        assert_eq!(back, sample());
        assert_eq!(back.b[1].to_bits(), f64::MIN_POSITIVE.to_bits());
    }

    #[test]
    fn every_bit_flip_and_truncation_is_refused() {
        let bytes = blob();
        for bit in 0..bytes.len() * 8 {
            let mut b = bytes.clone();
            b[bit / 8] ^= 1 << (bit % 8);
            assert!(decode::<Sample>(&b, &expected()).is_err(), "bit {bit}");
        }
        for cut in 0..bytes.len() {
            let e = decode::<Sample>(&bytes[..cut], &expected()).unwrap_err();
            assert!(matches!(e, StateError::Truncated { .. }), "{cut}: {e}");
        }
        let mut longer = bytes.clone();
        longer.push(0);
        let e = decode::<Sample>(&longer, &expected()).unwrap_err();
        assert!(matches!(e, StateError::TrailingBytes { .. }), "{e}");
    }

    #[test]
    fn foreign_states_name_what_differs() {
        let bytes = blob();
        let other = |kind, hash, n| Expected {
            kind,
            config_hash: hash,
            num_envs: n,
        };
        let e = decode::<Sample>(&bytes, &other(StateKind::SingleEnv, HASH, 4)).unwrap_err();
        assert!(e.to_string().contains("gymnasium vector env"), "{e}");
        assert!(e.to_string().contains("InAirCaptureEnv"), "{e}");
        let e = decode::<Sample>(&bytes, &other(StateKind::VectorEnv, HASH, 3)).unwrap_err();
        assert_eq!(
            e,
            StateError::NumEnvs {
                expected: 3,
                found: 4
            }
        );
        let e = decode::<Sample>(&bytes, &other(StateKind::VectorEnv, [4; 32], 4)).unwrap_err();
        assert!(e.to_string().contains("another configuration"), "{e}");
        // A payload of another type.
        let wrong = encode(StateKind::VectorEnv, &HASH, 4, &(1u8, 2u8)).unwrap();
        let e = decode::<Sample>(&wrong, &expected()).unwrap_err();
        assert!(matches!(e, StateError::Payload { .. }), "{e}");
        // Another version.
        let mut v = bytes.clone();
        v[8..12].copy_from_slice(&2u32.to_le_bytes());
        let e = decode::<Sample>(&v, &expected()).unwrap_err();
        assert!(e.to_string().contains("format changed"), "{e}");
    }

    #[test]
    fn old_format_and_random_bytes_are_recognised() {
        let mut old = b"ACCDST02".to_vec();
        old.extend_from_slice(&[0; 40]);
        assert_eq!(read_header(&old).unwrap_err(), StateError::OldFormat);
        // The Python envs put two flag bytes before it.
        let mut py = vec![0u8, 1];
        py.extend_from_slice(&old);
        let e = read_header(&py).unwrap_err();
        assert!(e.to_string().contains("format changed"), "{e}");
        assert!(matches!(
            read_header(b"hello world, not a state at all"),
            Err(StateError::NotAState { .. })
        ));
        assert!(matches!(
            read_header(b""),
            Err(StateError::Truncated { .. })
        ));
    }

    /// The postcard encoding of a stream, byte by byte after postcard's wire specification:
    /// a fixed array is its elements, unsigned integers are LEB128 varints, an `Option` a 0/1
    /// tag, an `f64` its 8 little-endian bytes.
    #[test]
    fn stream_state_encodes_as_the_postcard_spec_says() {
        let state = StreamState {
            chacha: ChaChaState {
                seed: [9; 32],
                stream: 300,
                word_pos: 5,
            },
            spare: Some(1.5),
        };
        let mut want = vec![9u8; 32];
        want.extend_from_slice(&[0xAC, 0x02]); // 300 = 0b10_0101100
        want.push(5);
        want.push(1);
        want.extend_from_slice(&1.5f64.to_le_bytes());
        assert_eq!(postcard::to_allocvec(&state).unwrap(), want);
        let none = StreamState {
            spare: None,
            ..state
        };
        assert_eq!(postcard::to_allocvec(&none).unwrap().len(), 32 + 2 + 1 + 1);
    }

    /// Pins the encoding of every state type of this module: when it fails, the format changed,
    /// so bump [`FORMAT_VERSION`] and then update the digest (printed by the failure).
    #[test]
    fn payload_layout_is_pinned() {
        let stream = StreamState {
            chacha: ChaChaState {
                seed: [1; 32],
                stream: 2,
                word_pos: 3,
            },
            spare: Some(0.5),
        };
        let state = EpisodeState {
            sim: CaptureState {
                time_origin: 0.25,
                steps: 4,
                time: 1.25,
                q: vec![0.1, 0.2, 0.3],
                qd: vec![-0.1, -0.2, -0.3],
                attitude: [0.0, 0.1, 0.2, 0.97],
                omega: [1.0, 2.0, 3.0],
                flap_command: [0.1; 4],
                flap_deflection: [0.05; 4],
                boom: BoomState {
                    base: [1.0; 3],
                    phase: [2.0; 3],
                    perturbation: [3.0; 3],
                    previous_tip: [4.0; 3],
                    velocity: [5.0; 3],
                    along: 6.0,
                    stream,
                },
                air: AirState::Turbulence(Box::new(TurbulenceState {
                    seed: 11,
                    time: 0.5,
                    newest: 50,
                    ring: vec![0.5f32; 6],
                    processes: vec![0.25; 3],
                    wake_stream: stream,
                    ambient_stream: stream,
                    lanes: Some(LaneState {
                        streams: vec![stream; 2],
                        generated: vec![1, 0],
                        covered: Some([0, 0, 0, 1]),
                    }),
                })),
            },
            steps: 9,
            seeds: Seeds {
                initial: 1,
                wake: 2,
                rlv: 3,
            },
            previous_action: [0.5; ACT_DIM],
            observation: vec![0.125; 3],
            distance: 2.5,
            done: false,
            divergence: Some("x".into()),
            sensors: Some(SensorState {
                components: ComponentStates {
                    vision: VisionState {
                        stream,
                        history: vec![[1.5; 3]; 2],
                        head: 1,
                        steps: 7,
                        next_update: 3,
                        lost: true,
                        last: [0.75; 3],
                        last_time: 0.5,
                        previous: [0.25; 3],
                        previous_time: 0.45,
                        received: 2,
                        dropped: 1,
                    },
                    gyro: GyroState {
                        stream,
                        bias: [0.01; 3],
                    },
                    ahrs: AhrsState {
                        stream,
                        bias: [0.02; 3],
                    },
                    gnss: GnssState { stream },
                    load_cell: LoadCellState { stream },
                },
                delay: DelayLineState {
                    observations: vec![0.5f32; 2],
                    head: 0,
                    filled: true,
                },
            }),
        };
        let bytes = postcard::to_allocvec(&state).unwrap();
        let digest = hex(&Sha256::digest(&bytes));
        assert_eq!(
            (FORMAT_VERSION, bytes.len(), digest.as_str()),
            (
                5,
                1056,
                "a56b580dba4374ad54ee5b011831990c78e4f83c64fa0188f944550618b6ebce"
            ),
            "the state types' encoding changed: bump FORMAT_VERSION, then pin the new digest"
        );
    }

    #[test]
    fn config_hash_is_canonical_and_stable() {
        #[derive(Serialize)]
        struct A {
            x: f64,
            y: Vec<u32>,
        }
        #[derive(Serialize)]
        struct B {
            y: Vec<u32>,
            x: f64,
        }
        let a = config_hash(&A {
            x: 0.1,
            y: vec![1, 2],
        })
        .unwrap();
        let b = config_hash(&B {
            y: vec![1, 2],
            x: 0.1,
        })
        .unwrap();
        assert_eq!(a, b, "field order does not matter");
        // SHA-256 of the canonical text, computed independently (`printf %s '{"x":0.1,"y":[1,2]}'
        // | sha256sum`).
        assert_eq!(
            hex(&a),
            "ccd46ccfc151e495ad4311f1f22fc4bedc4ed84ca843be84808c766398db1dac"
        );
        let c = config_hash(&A {
            x: 0.2,
            y: vec![1, 2],
        })
        .unwrap();
        assert_ne!(a, c);
    }
}
