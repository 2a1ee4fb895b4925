//! Per-episode seeds: every episode of every env gets its own independent
//! streams, derived from a base seed, the env's index and the episode's index; wake seeds come
//! from a training range, a fixed value or an explicit evaluation list.
//!
//! # Derivation
//! With `h` SplitMix64's output mix ([`accd_sim::rng::splitmix64_mix`], a bijection with full
//! avalanche) and fixed odd constants `A`, `B`:
//!
//! ```text
//! key     = h(h(h(base) ^ h(A)) ^ h(episode + B))
//! initial = h(key ^ "INITIAL ")          (ASCII labels as big-endian u64)
//! rlv     = h(key ^ "RLV BOOM")
//! wake    = TRAINING_WAKE_SEEDS.start + h(key ^ "WAKESEED") mod len(TRAINING_WAKE_SEEDS)
//!           (unless the schedule fixes it)
//! ```
//!
//! The pair (base, episode) is hashed as a whole, never added: neighbouring base seeds give
//! unrelated keys. A batch seeds env `i` as gymnasium's `SyncVectorEnv` and stable-baselines3's
//! `DummyVecEnv` seed their sub-envs: an int seed `s` gives env `i` the base `s + i`, a list gives
//! each env its own base, so env `i` replays the single env seeded with its base. An env's
//! episodes depend only on (base, episode index), so results are the same whatever the batch
//! size or thread count. (`h(A)` is the term of an env index that earlier versions hashed too,
//! at its value 0: episodes of a single env or of per-env list seeds are bitwise the ones
//! recorded before.)
//!
//! # Training, validation and held-out wake seeds
//! Training draws wake seeds from [`TRAINING_WAKE_SEEDS`] = [0, 10^9). The held-out set
//! [`HELD_OUT_WAKE_SEEDS`] = [10^9, 10^9 + 1000) lies outside it: no training draw can produce
//! a held-out seed (the draw above maps into the training range by construction; the modulo
//! bias is below 10^9 / 2^64). The validation set [`VALIDATION_WAKE_SEEDS`], the range's last
//! 1000 seeds, holds episodes of the training distribution on which choices are made; a draw
//! that lands in it (one in 10^6) is drawn again from `h` of its own hash until it does not, so
//! training never sees a validation wake either, and every other draw is the formula's above.
//! Evaluation passes an explicit list (by default the held-out set) as [`WakeSchedule::List`].

use std::ops::Range;

use accd_sim::rng::splitmix64_mix as h;
use accd_sim::Seeds;

/// Wake seeds training draws from.
pub const TRAINING_WAKE_SEEDS: Range<u64> = 0..1_000_000_000;
/// Wake seeds kept for held-out evaluation; training never draws them.
pub const HELD_OUT_WAKE_SEEDS: Range<u64> = 1_000_000_000..1_000_001_000;
/// Wake seeds for validation (choosing runs, methods, hyperparameters): the training range's last
/// 1000, of the training distribution; training never draws them either.
pub const VALIDATION_WAKE_SEEDS: Range<u64> =
    TRAINING_WAKE_SEEDS.end - 1000..TRAINING_WAKE_SEEDS.end;

// The two sets are disjoint (checked at compile time).
const _: () = assert!(TRAINING_WAKE_SEEDS.end <= HELD_OUT_WAKE_SEEDS.start);

const A: u64 = 0x2545_F491_4F6C_DD1D;
const B: u64 = 0x9E37_79B9_7F4A_7C15;
const INITIAL: u64 = u64::from_be_bytes(*b"INITIAL ");
const RLV: u64 = u64::from_be_bytes(*b"RLV BOOM");
const WAKE: u64 = u64::from_be_bytes(*b"WAKESEED");

/// Where an episode's wake seed comes from.
#[derive(Debug, Clone, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum WakeSchedule {
    /// Drawn from [`TRAINING_WAKE_SEEDS`] with the episode's other seeds.
    #[default]
    Training,
    /// The same for every episode.
    Fixed(u64),
    /// Cycled through: env `i`'s episode `e` of a batch of `n` uses entry `(i + e n) mod len`.
    List(Vec<u64>),
}

impl WakeSchedule {
    /// The schedule a config asks for: `wake_seeds` over `wake_seed` over training draws.
    pub fn from_config(config: &accd_sim::EnvConfig) -> WakeSchedule {
        match (&config.wake_seeds, config.wake_seed) {
            (Some(list), _) => WakeSchedule::List(list.clone()),
            (None, Some(seed)) => WakeSchedule::Fixed(seed),
            (None, None) => WakeSchedule::Training,
        }
    }
}

/// The key of episode `episode` under base seed `base`.
pub fn episode_key(base: u64, episode: u64) -> u64 {
    h(h(h(base) ^ h(A)) ^ h(episode.wrapping_add(B)))
}

/// A training wake seed drawn from `key`, never one of [`VALIDATION_WAKE_SEEDS`].
pub fn training_wake_seed(key: u64) -> u64 {
    let len = TRAINING_WAKE_SEEDS.end - TRAINING_WAKE_SEEDS.start;
    let mut draw = h(key ^ WAKE);
    loop {
        let seed = TRAINING_WAKE_SEEDS.start + draw % len;
        if !VALIDATION_WAKE_SEEDS.contains(&seed) {
            return seed;
        }
        draw = h(draw);
    }
}

/// The seeds of episode `episode` under base seed `base`, for env `env` of a batch of
/// `num_envs` (the env's place in the batch only picks its entry of a wake-seed list).
pub fn episode_seeds(
    base: u64,
    episode: u64,
    env: u64,
    num_envs: u64,
    schedule: &WakeSchedule,
) -> Seeds {
    let key = episode_key(base, episode);
    let wake = match schedule {
        WakeSchedule::Training => training_wake_seed(key),
        WakeSchedule::Fixed(seed) => *seed,
        WakeSchedule::List(list) => {
            let len = list.len() as u64;
            let i = (env % len + (episode % len) * (num_envs % len)) % len;
            list[i as usize]
        }
    };
    Seeds {
        initial: h(key ^ INITIAL),
        wake,
        rlv: h(key ^ RLV),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;

    #[test]
    fn neighbouring_bases_and_episodes_share_no_streams() {
        let mut seen = HashSet::new();
        for base in 0..400u64 {
            for episode in 0..20u64 {
                let s = episode_seeds(base, episode, 0, 1, &WakeSchedule::Training);
                assert!(seen.insert(s.initial), "initial seed repeated");
                assert!(seen.insert(s.rlv), "rlv seed repeated");
                // The env's place in the batch does not change its streams.
                assert_eq!(
                    episode_seeds(base, episode, 3, 7, &WakeSchedule::Training),
                    s
                );
            }
        }
    }

    #[test]
    fn training_never_draws_a_held_out_wake_seed() {
        for base in 0..200u64 {
            for env in 0..50u64 {
                let s = episode_seeds(base ^ env, env, env, 50, &WakeSchedule::Training);
                assert!(TRAINING_WAKE_SEEDS.contains(&s.wake));
                assert!(!HELD_OUT_WAKE_SEEDS.contains(&s.wake));
            }
        }
    }

    #[test]
    fn a_draw_in_the_validation_tail_is_drawn_again_and_no_other_draw_moves() {
        let len = TRAINING_WAKE_SEEDS.end - TRAINING_WAKE_SEEDS.start;
        let first = |key: u64| TRAINING_WAKE_SEEDS.start + h(key ^ WAKE) % len;
        // The keys whose first draw lands in the validation tail (about one in 10^6).
        let landing: Vec<u64> = (0..20_000_000u64)
            .filter(|&k| VALIDATION_WAKE_SEEDS.contains(&first(k)))
            .take(3)
            .collect();
        assert!(
            !landing.is_empty(),
            "no first draw in the validation tail among 2e7 keys"
        );
        for &k in &landing {
            let s = training_wake_seed(k);
            assert!(TRAINING_WAKE_SEEDS.contains(&s) && !VALIDATION_WAKE_SEEDS.contains(&s));
            assert_eq!(s, TRAINING_WAKE_SEEDS.start + h(h(k ^ WAKE)) % len);
        }
        for k in 0..100_000u64 {
            if !landing.contains(&k) {
                assert_eq!(training_wake_seed(k), first(k));
            }
        }
        assert_eq!(
            VALIDATION_WAKE_SEEDS.end - VALIDATION_WAKE_SEEDS.start,
            1000
        );
    }

    #[test]
    fn a_list_is_cycled_across_envs_then_episodes() {
        let list = WakeSchedule::List(vec![10, 11, 12, 13, 14]);
        let got: Vec<u64> = (0..3u64)
            .flat_map(|e| (0..2u64).map(move |i| (i, e)))
            .map(|(i, e)| episode_seeds(1, e, i, 2, &list).wake)
            .collect();
        assert_eq!(got, vec![10, 11, 12, 13, 14, 10]);
        assert_eq!(episode_seeds(1, 0, 0, 1, &WakeSchedule::Fixed(77)).wake, 77);
    }
}
