//! The reinforcement-learning task: its configuration ([`config`]), the
//! observation ([`observation`], optionally through the [`sensors`]), the reward and the
//! episode-end conditions (computed in [`episode`], which steps one episode), the domain
//! randomization ([`randomization`]) and the plant's linearization for controller design
//! ([`linearize`]).
//!
//! # Action
//! Four flap commands in [-1, 1] (right, left, top, bottom; the order of [`crate::physics::accd::mix`]),
//! scaled by the flap limit (`accd.flap_limit_deg`, 15 degrees by default). Values outside
//! [-1, 1] are clipped; non-finite values are an error. Held for one agent step
//! ([`EnvConfig::agent_step`], 0.1 s = 10 physics steps by default).
//!
//! # Observation
//! `OBS_DIM` float32 values, each a physical quantity times a fixed scale, clipped to
//! [-`OBS_BOUND`, `OBS_BOUND`]. Vectors are in the TA frame (x forward, y starboard, z down)
//! unless stated. See [`OBSERVATION`] for the table (index, name, unit, scale).
//!
//! With `sensors.enabled` the observation is what the sensor model ([`crate::task::sensors`]) measures
//! of these quantities (same layout, names and scales); the reward and the episode end below
//! always use the true state.
//!
//! # Reward (per agent step)
//! With `d` the distance from the capture point to the boom tip at the end of the step (m),
//! `a` the action, `a'` the previous action (zero at the start):
//!
//! ```text
//! r = w_p exp(-d / lambda)                      proximity, in (0, w_p]
//!   - w_e sum(a^2) / 4                          control effort, in [0, w_e]
//!   - w_s sum(((a - a') / 2)^2) / 4             control rate, in [0, w_s]
//!   + [captured] (w_c + w_p * steps_left)       capture bonus
//!   - [overload or envelope exit or diverged] w_f
//! ```
//!
//! `steps_left` is the number of agent steps left in the capture window after this one: a
//! capture is always worth at least as much as hovering next to the boom for the rest of the
//! window, so an agent gains nothing by delaying it. Defaults: `w_p` 1, `lambda` 10 m,
//! `w_e` 0.05, `w_s` 0.05, `w_c` 100, `w_f` 50 ([`RewardConfig`]). Bounds: see
//! [`RewardConfig::bounds`].
//!
//! # Episode end
//! | condition | kind | checked |
//! |---|---|---|
//! | capture: capture point within `boom.capture_radius` of the boom tip at a relative speed under `boom.max_closing_speed` | terminated | every physics step |
//! | overload: attachment tension above `limits.overload_fraction` times the tether's breaking tension | terminated | every physics step |
//! | envelope exit: distance to the boom over `limits.max_distance`, the ACCD's nose more than `limits.max_tilt_deg` off the flight direction, a pitch/yaw rate over `limits.max_body_rate` (tumbling) or a roll rate over `limits.max_roll_rate` | terminated | every agent step |
//! | diverged: the simulation reported an error or a non-finite state (every physics step), or an implausible one: the ACCD faster than twice the airspeed relative to the aircraft or a body rate over 1000 rad/s (every agent step); the last good observation is kept | terminated | see left |
//! | capture window (`capture_window`, 70 s) elapsed | truncated | every agent step |

pub mod config;
pub mod episode;
pub mod linearize;
pub mod observation;
pub mod randomization;
pub mod sensors;
pub mod state_steps;
pub mod static_equilibrium;

pub use config::{EnvConfig, InitialConfig, LimitsConfig, RewardConfig};
pub use observation::{
    observation_index, ObservationField, ObservationInputs, ACT_DIM, OBSERVATION, OBS_BOUND,
    OBS_DIM,
};
