//! Randomized physics (domain randomization): per episode, the tether's length and diameter, the
//! ACCD's mass and aerodynamic coefficients, the wake's angle of attack and strength, the towing
//! speed and the ambient turbulence level are drawn from ranges ([`RandomizationConfig`]).
//!
//! # Parameter seeds
//! The draw comes from the episode's **wake seed** on its own labelled stream
//! ([`PARAMETERS_STREAM`], "PARAMS  "), independent of the turbulence the same seed generates: the
//! wake seed is the episode's scenario seed. So the training and held-out parameter sets are
//! disjoint by construction, exactly as the wake seeds are (training draws seeds from
//! [0, 10^9), evaluation uses the held-out seeds [10^9, 10^9 + 1000)), and evaluation episode k
//! meets the same physics whatever the batch size, thread count or machine. No other stream of
//! the episode moves when randomization is switched on.
//!
//! # What is drawn (uniform in each range, in this order)
//! | parameter | default range | what follows from it |
//! |---|---|---|
//! | tether length | 150-300 m | the paper's lengths (section 4.2); 30 segments whatever the length |
//! | tether diameter | 16-32 mm | Table 2's UHMWPE diameters: mass per length, breaking tension, EA and EI from the rope model ([`accd_tether::material`]) |
//! | ACCD mass | 40-60 kg | +-20 % of the calibrated 50 kg; the inertia follows (solid cylinder) unless `accd.inertia` fixes it |
//! | force coefficients | x 0.85-1.15 | `accd.force_coefficient_scale`: +-15 %, the spread of RANS vs wind-tunnel force coefficients on finned bodies |
//! | moment coefficients | x 0.8-1.2 | `accd.moment_coefficient_scale`: +-20 % on static moments, control effectiveness and damping |
//! | wake angle of attack | 0-8 deg | `wake.alpha_deg`: the tables' range (the TA from cruise to high angle of attack) |
//! | wake strength | x 0.7-1.3 | `wake.strength`: +-30 % on the mean wake (and its turbulence) |
//! | towing speed | 170-200 m/s | `aircraft.airspeed` around the paper's 185 m/s |
//! | ambient turbulence | 0-2.8 m/s RMS | `turbulence.ambient` as a MIL-F-8785C level of that RMS (533.4 m), none to moderate |
//!
//! A range with equal ends fixes the parameter. Each episode then solves its own open-loop
//! equilibrium from the base configuration's (episodes start around it and the boom is placed
//! relative to it, [`crate::BoomConfig::nominal`]; [`crate::Equilibrium::solve_near`],
//! [`crate::task::static_equilibrium`]): at most 200 physics steps per reset (75-150 measured),
//! which a reset with the same parameters (the same wake seed) skips.

use accd_spec::{join, out_of_range, OutOfRange, Rules};
use accd_tether::{Material, TetherConfig};
use serde::{Deserialize, Serialize};

use crate::config::CaptureConfig;
use crate::physics::turbulence::AmbientTurbulence;
use crate::rng::Stream;

/// ChaCha stream label of the parameter draw ("PARAMS  " in ASCII), on the wake seed.
pub const PARAMETERS_STREAM: u64 = u64::from_be_bytes(*b"PARAMS  ");

/// MIL-F-8785C's length scale at altitude, m (the ambient turbulence's, [`AmbientTurbulence`]).
const AMBIENT_LENGTH_SCALE_M: f64 = 533.4;

accd_spec::config_struct! {
    /// Ranges of the physical parameters drawn per episode (module docs). Each is
    /// `[low, high]`, uniform; equal ends fix the parameter.
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    pub struct RandomizationConfig {
        pub enabled: bool = false, "", "",
            "draw the physical parameters below per episode from its wake seed";
        pub tether_length: [f64; 2] = [150.0, 300.0], "m", "[10, 5000]",
            "range of the tether's length (the paper's 150-300 m)";
        pub tether_diameter: [f64; 2] = [0.016, 0.032], "m", "[0.004, 0.1]",
            "range of the tether's diameter (Table 2's UHMWPE 16-32 mm; mass, strength and stiffness follow)";
        pub accd_mass: [f64; 2] = [40.0, 60.0], "kg", "(0, 1000]", "range of the ACCD's mass";
        pub force_coefficient_scale: [f64; 2] = [0.85, 1.15], "-", "(0, 10]",
            "range of the factor on the ACCD's force coefficients";
        pub moment_coefficient_scale: [f64; 2] = [0.8, 1.2], "-", "(0, 10]",
            "range of the factor on the ACCD's moment coefficients and damping";
        pub wake_alpha_deg: [f64; 2] = [0.0, 8.0], "deg", "[0, 90]",
            "range of the TA's angle of attack (within the wake tables' angles)";
        pub wake_strength: [f64; 2] = [0.7, 1.3], "-", "[0, 5]", "range of the factor on the mean wake";
        pub airspeed: [f64; 2] = [170.0, 200.0], "m/s", "[1, 400]", "range of the towing speed";
        pub ambient_sigma_mps: [f64; 2] = [0.0, 2.8], "m/s", "[0, 50]",
            "range of the ambient turbulence's RMS per component (MIL-F-8785C, 533.4 m; 0: none)";
    }
}

/// Every range `[low, high]` with `low <= high`.
impl Rules for RandomizationConfig {
    fn check_rules(&self, prefix: &str) -> std::result::Result<(), OutOfRange> {
        for (name, [lo, hi]) in self.ranges() {
            if lo > hi {
                return Err(out_of_range(
                    &join(prefix, name),
                    format!("[{lo}, {hi}]"),
                    "[low, high] with low <= high",
                ));
            }
        }
        Ok(())
    }
}

impl RandomizationConfig {
    /// The ranges in drawing order, by name.
    fn ranges(&self) -> [(&'static str, [f64; 2]); 9] {
        [
            ("tether_length", self.tether_length),
            ("tether_diameter", self.tether_diameter),
            ("accd_mass", self.accd_mass),
            ("force_coefficient_scale", self.force_coefficient_scale),
            ("moment_coefficient_scale", self.moment_coefficient_scale),
            ("wake_alpha_deg", self.wake_alpha_deg),
            ("wake_strength", self.wake_strength),
            ("airspeed", self.airspeed),
            ("ambient_sigma_mps", self.ambient_sigma_mps),
        ]
    }
}

/// One episode's drawn physical parameters (SI but where the name says).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Parameters {
    /// Tether length, m.
    pub tether_length: f64,
    /// Tether diameter, m.
    pub tether_diameter: f64,
    /// ACCD mass, kg.
    pub accd_mass: f64,
    /// Factor on the force coefficients.
    pub force_coefficient_scale: f64,
    /// Factor on the moment coefficients.
    pub moment_coefficient_scale: f64,
    /// TA angle of attack, deg.
    pub wake_alpha_deg: f64,
    /// Factor on the mean wake.
    pub wake_strength: f64,
    /// Towing speed, m/s.
    pub airspeed: f64,
    /// Ambient turbulence RMS per component, m/s.
    pub ambient_sigma_mps: f64,
}

impl Parameters {
    /// Names of the fields, in drawing order (the order of [`Parameters::values`]).
    pub const NAMES: [&'static str; 9] = [
        "tether_length",
        "tether_diameter",
        "accd_mass",
        "force_coefficient_scale",
        "moment_coefficient_scale",
        "wake_alpha_deg",
        "wake_strength",
        "airspeed",
        "ambient_sigma_mps",
    ];

    /// The parameters of the episode with wake seed `wake_seed`: one uniform per range from the
    /// stream [`PARAMETERS_STREAM`] of that seed, in [`Parameters::NAMES`]'s order.
    pub fn draw(config: &RandomizationConfig, wake_seed: u64) -> Parameters {
        let mut stream = Stream::new(wake_seed, PARAMETERS_STREAM);
        let mut v = [0.0; 9];
        for (out, (_, [lo, hi])) in v.iter_mut().zip(config.ranges()) {
            // Drawn even for a fixed parameter, so that fixing one does not move the others.
            let u = stream.uniform();
            *out = if lo == hi { lo } else { lo + (hi - lo) * u };
        }
        Parameters::from_values(v)
    }

    /// Every parameter at the low (`upper` false) or the high end of its range: with both
    /// corners buildable, so is every draw of the box between them (each parameter's checks
    /// are intervals).
    pub fn corner(config: &RandomizationConfig, upper: bool) -> Parameters {
        Parameters::from_values(
            config
                .ranges()
                .map(|(_, [lo, hi])| if upper { hi } else { lo }),
        )
    }

    fn from_values(v: [f64; 9]) -> Parameters {
        Parameters {
            tether_length: v[0],
            tether_diameter: v[1],
            accd_mass: v[2],
            force_coefficient_scale: v[3],
            moment_coefficient_scale: v[4],
            wake_alpha_deg: v[5],
            wake_strength: v[6],
            airspeed: v[7],
            ambient_sigma_mps: v[8],
        }
    }

    /// The values in [`Parameters::NAMES`]'s order.
    pub fn values(&self) -> [f64; 9] {
        [
            self.tether_length,
            self.tether_diameter,
            self.accd_mass,
            self.force_coefficient_scale,
            self.moment_coefficient_scale,
            self.wake_alpha_deg,
            self.wake_strength,
            self.airspeed,
            self.ambient_sigma_mps,
        ]
    }

    /// Writes these parameters into `physics`: the tether a UHMWPE rope of the drawn length and
    /// diameter (mass, breaking tension, EA and EI from Table 2's rope model; segments, damping,
    /// drag and step as they were), the ACCD's mass and coefficient factors, the wake's angle and
    /// strength, the airspeed, and the ambient turbulence (none at 0 m/s). The episode's whole
    /// configuration is [`crate::task::episode::drawn_config`].
    pub fn apply_to(&self, physics: &mut CaptureConfig) {
        let rope = Material::Uhmwpe;
        let d = self.tether_diameter;
        physics.tether = TetherConfig {
            length: self.tether_length,
            diameter: d,
            mass_per_length: rope.mass_per_length(d),
            axial_stiffness: rope.axial_rigidity(d) / self.tether_length,
            flexural_rigidity: rope.flexural_rigidity(d),
            breaking_tension: rope.max_tension(d),
            ..physics.tether.clone()
        };
        physics.accd.mass = self.accd_mass;
        physics.accd.force_coefficient_scale = self.force_coefficient_scale;
        physics.accd.moment_coefficient_scale = self.moment_coefficient_scale;
        physics.wake.alpha_deg = self.wake_alpha_deg;
        physics.wake.strength = self.wake_strength;
        physics.aircraft.airspeed = self.airspeed;
        physics.turbulence.ambient = if self.ambient_sigma_mps > 0.0 {
            AmbientTurbulence::Custom {
                sigma_mps: self.ambient_sigma_mps,
                length_scale_m: AMBIENT_LENGTH_SCALE_M,
            }
        } else {
            AmbientTurbulence::None
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_are_deterministic_within_their_ranges_and_differ_between_seeds() {
        let config = RandomizationConfig {
            enabled: true,
            ..RandomizationConfig::default()
        };
        let a = Parameters::draw(&config, 7);
        assert_eq!(a, Parameters::draw(&config, 7));
        assert_ne!(a, Parameters::draw(&config, 8));
        let mut lo = [f64::INFINITY; 9];
        let mut hi = [f64::NEG_INFINITY; 9];
        for seed in 0..2000 {
            let v = Parameters::draw(&config, seed).values();
            for i in 0..9 {
                lo[i] = lo[i].min(v[i]);
                hi[i] = hi[i].max(v[i]);
            }
        }
        for (i, (name, [a, b])) in config.ranges().iter().enumerate() {
            assert_eq!(*name, Parameters::NAMES[i]);
            // 2000 uniforms cover all but about 1/2000 of the range at each end.
            let span = b - a;
            assert!(lo[i] >= *a && lo[i] < a + 0.005 * span, "{name}: {}", lo[i]);
            assert!(hi[i] < *b && hi[i] > b - 0.005 * span, "{name}: {}", hi[i]);
        }
    }

    #[test]
    fn fixing_one_range_leaves_the_other_draws_alone() {
        let free = RandomizationConfig::default();
        let fixed = RandomizationConfig {
            accd_mass: [55.0, 55.0],
            ..RandomizationConfig::default()
        };
        let (a, b) = (Parameters::draw(&free, 3), Parameters::draw(&fixed, 3));
        assert_eq!(b.accd_mass, 55.0);
        let (va, vb) = (a.values(), b.values());
        for i in (0..9).filter(|&i| i != 2) {
            assert_eq!(va[i].to_bits(), vb[i].to_bits(), "{}", Parameters::NAMES[i]);
        }
    }

    #[test]
    fn applied_parameters_follow_the_rope_model() {
        let p = Parameters {
            tether_length: 250.0,
            tether_diameter: 0.024,
            ..Parameters::draw(&RandomizationConfig::default(), 1)
        };
        let mut c = crate::EnvConfig::default();
        p.apply_to(&mut c.physics);
        let t3 = TetherConfig::table3();
        // 250 m of 24 mm UHMWPE is Table 3's tether.
        for (a, b) in [
            (c.physics.tether.mass_per_length, t3.mass_per_length),
            (c.physics.tether.axial_stiffness, t3.axial_stiffness),
            (c.physics.tether.flexural_rigidity, t3.flexural_rigidity),
            (c.physics.tether.breaking_tension, t3.breaking_tension),
        ] {
            assert!((a - b).abs() <= 1e-9 * b.abs(), "{a} vs {b}");
        }
        assert_eq!(c.physics.aircraft.airspeed, p.airspeed);
    }

    #[test]
    fn an_inverted_range_is_refused_by_name() {
        let mut c = crate::EnvConfig::default();
        c.randomization.airspeed = [200.0, 170.0];
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("randomization.airspeed"), "{e}");
    }
}
