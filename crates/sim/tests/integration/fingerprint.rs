//! The physics fingerprint on the Rust side: every output of a fixed set of episodes, hashed,
//! equals the recorded digest whatever the processor and build. `scripts/test.sh` runs it with
//! the native arithmetic and again with `ACCD_GYM_ARITHMETIC=portable` (the build of a processor
//! without AVX2 and FMA); built for aarch64 it passes under qemu-aarch64 too (docs/decisions.md,
//! "One arithmetic on every processor").

use std::sync::Arc;

use accd_sim::{AmbientTurbulence, EnvConfig, Episode, Equilibrium, Seeds};
use sha2::{Digest, Sha256};

/// SHA-256 of the observations, rewards, distances and end flags of two episodes of 150 agent
/// steps each, in calm and in severe ambient turbulence, under fixed varying flap commands.
fn fingerprint() -> String {
    let mut hash = Sha256::new();
    for (j, ambient) in [AmbientTurbulence::None, AmbientTurbulence::Severe]
        .into_iter()
        .enumerate()
    {
        let mut config = EnvConfig::default();
        config.physics.turbulence.ambient = ambient;
        let config = Arc::new(config.validated().unwrap());
        let eq = Arc::new(Equilibrium::settle(&config).unwrap());
        let seeds = Seeds {
            initial: 7 + j as u64,
            wake: 107 + j as u64,
            rlv: 207 + j as u64,
        };
        let mut episode = Episode::new(config, eq, seeds).unwrap();
        for obs in episode.observation() {
            hash.update(obs.to_bits().to_le_bytes());
        }
        for k in 0..150 {
            let t = 0.1 * k as f32 + j as f32;
            let action = [0.3 * t.sin(), -0.3 * t.cos(), 0.2 * (2.0 * t).sin(), 0.1];
            let out = episode.step(&action).unwrap();
            for obs in episode.observation() {
                hash.update(obs.to_bits().to_le_bytes());
            }
            for v in [
                out.reward,
                out.distance,
                out.relative_speed,
                out.peak_tension,
            ] {
                hash.update(v.to_bits().to_le_bytes());
            }
            hash.update([u8::from(out.terminated), u8::from(out.truncated)]);
            if out.terminated || out.truncated {
                break;
            }
        }
    }
    hash.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

/// Recorded with the native build on x86-64; the portable build and aarch64 give the same.
const RECORDED: &str = "43db5a41386b2d71314ea7cf435784116203a203321ce0f043c093f237138729";

#[test]
fn every_output_of_the_fixed_episodes_is_the_recorded_one() {
    let digest = fingerprint();
    eprintln!(
        "fingerprint {digest} (arithmetic: {})",
        accd_tether::arithmetic()
    );
    assert_eq!(digest, RECORDED);
}
