//! The observation (see [`crate::task`]): its table ([`OBSERVATION`]: index, name, unit, scale)
//! and how it is computed from a state, with or without the sensor model.

use nalgebra::Vector3;

use crate::physics::capture::Snapshot;
use crate::task::sensors::{SensedLayout, Sensors};

/// Number of observation values.
pub const OBS_DIM: usize = 25;
/// Every observation value lies in [-OBS_BOUND, OBS_BOUND].
pub const OBS_BOUND: f32 = 10.0;
/// Number of action values (flap commands).
pub const ACT_DIM: usize = 4;

/// What the observation is computed from: the state's [`Snapshot`] and the episode's constants.
#[derive(Debug, Clone, Copy)]
pub struct ObservationInputs<'a> {
    /// Everything observable about the state.
    pub snapshot: &'a Snapshot,
    /// The ACCD's open-loop equilibrium position (TA frame), m.
    pub equilibrium: &'a Vector3<f64>,
    /// The flap limit, rad.
    pub flap_limit: f64,
    /// The capture window, s.
    pub capture_window: f64,
}

impl ObservationInputs<'_> {
    /// +1 or -1: the sign that puts the attitude quaternion in the hemisphere w >= 0 (q and -q
    /// are the same attitude; the observation shows one of them).
    #[inline]
    pub fn hemisphere(&self) -> f64 {
        if self.snapshot.attitude.w < 0.0 {
            -1.0
        } else {
            1.0
        }
    }
}

/// One row of the observation table: what the value is and how it is computed.
#[derive(Debug, Clone, Copy)]
pub struct ObservationField {
    /// Name (also the key users see).
    pub name: &'static str,
    /// Unit of the physical quantity.
    pub unit: &'static str,
    /// The observation value is the quantity times this scale (then clipped).
    pub scale: f64,
    /// What it is.
    pub description: &'static str,
    /// The physical quantity (in `unit`) at a state.
    pub value: fn(&ObservationInputs<'_>) -> f64,
}

/// The observation table, in index order: the one declaration the observation values
/// ([`observe`]), the names, the docs and Python's index constants come from.
pub const OBSERVATION: [ObservationField; OBS_DIM] = [
    ObservationField {
        name: "boom_rel_x",
        unit: "m",
        scale: 0.05,
        description: "boom tip minus capture point, x (forward)",
        value: |o| o.snapshot.boom_tip.x - o.snapshot.capture_point.x,
    },
    ObservationField {
        name: "boom_rel_y",
        unit: "m",
        scale: 0.05,
        description: "boom tip minus capture point, y (starboard)",
        value: |o| o.snapshot.boom_tip.y - o.snapshot.capture_point.y,
    },
    ObservationField {
        name: "boom_rel_z",
        unit: "m",
        scale: 0.05,
        description: "boom tip minus capture point, z (down)",
        value: |o| o.snapshot.boom_tip.z - o.snapshot.capture_point.z,
    },
    ObservationField {
        name: "boom_rel_vx",
        unit: "m/s",
        scale: 0.1,
        description: "boom-tip velocity minus capture-point velocity, x",
        value: |o| o.snapshot.boom_velocity.x - o.snapshot.capture_point_velocity.x,
    },
    ObservationField {
        name: "boom_rel_vy",
        unit: "m/s",
        scale: 0.1,
        description: "boom-tip velocity minus capture-point velocity, y",
        value: |o| o.snapshot.boom_velocity.y - o.snapshot.capture_point_velocity.y,
    },
    ObservationField {
        name: "boom_rel_vz",
        unit: "m/s",
        scale: 0.1,
        description: "boom-tip velocity minus capture-point velocity, z",
        value: |o| o.snapshot.boom_velocity.z - o.snapshot.capture_point_velocity.z,
    },
    ObservationField {
        name: "accd_dx",
        unit: "m",
        scale: 0.05,
        description: "ACCD position minus its open-loop equilibrium, x",
        value: |o| o.snapshot.position.x - o.equilibrium.x,
    },
    ObservationField {
        name: "accd_dy",
        unit: "m",
        scale: 0.05,
        description: "ACCD position minus its open-loop equilibrium, y",
        value: |o| o.snapshot.position.y - o.equilibrium.y,
    },
    ObservationField {
        name: "accd_dz",
        unit: "m",
        scale: 0.05,
        description: "ACCD position minus its open-loop equilibrium, z",
        value: |o| o.snapshot.position.z - o.equilibrium.z,
    },
    ObservationField {
        name: "accd_vx",
        unit: "m/s",
        scale: 0.1,
        description: "ACCD velocity relative to the aircraft, x",
        value: |o| o.snapshot.velocity.x,
    },
    ObservationField {
        name: "accd_vy",
        unit: "m/s",
        scale: 0.1,
        description: "ACCD velocity relative to the aircraft, y",
        value: |o| o.snapshot.velocity.y,
    },
    ObservationField {
        name: "accd_vz",
        unit: "m/s",
        scale: 0.1,
        description: "ACCD velocity relative to the aircraft, z",
        value: |o| o.snapshot.velocity.z,
    },
    ObservationField {
        name: "quat_w",
        unit: "-",
        scale: 1.0,
        description: "attitude quaternion body -> TA frame, scalar part (>= 0)",
        value: |o| o.hemisphere() * o.snapshot.attitude.w,
    },
    ObservationField {
        name: "quat_x",
        unit: "-",
        scale: 1.0,
        description: "attitude quaternion, x part",
        value: |o| o.hemisphere() * o.snapshot.attitude.i,
    },
    ObservationField {
        name: "quat_y",
        unit: "-",
        scale: 1.0,
        description: "attitude quaternion, y part",
        value: |o| o.hemisphere() * o.snapshot.attitude.j,
    },
    ObservationField {
        name: "quat_z",
        unit: "-",
        scale: 1.0,
        description: "attitude quaternion, z part",
        value: |o| o.hemisphere() * o.snapshot.attitude.k,
    },
    ObservationField {
        name: "rate_p",
        unit: "rad/s",
        scale: 0.5,
        description: "body roll rate",
        value: |o| o.snapshot.omega.x,
    },
    ObservationField {
        name: "rate_q",
        unit: "rad/s",
        scale: 0.5,
        description: "body pitch rate",
        value: |o| o.snapshot.omega.y,
    },
    ObservationField {
        name: "rate_r",
        unit: "rad/s",
        scale: 0.5,
        description: "body yaw rate",
        value: |o| o.snapshot.omega.z,
    },
    ObservationField {
        name: "flap_right",
        unit: "-",
        scale: 1.0,
        description: "right flap deflection / accd.flap_limit_deg",
        value: |o| o.snapshot.deflection[0] / o.flap_limit,
    },
    ObservationField {
        name: "flap_left",
        unit: "-",
        scale: 1.0,
        description: "left flap deflection / accd.flap_limit_deg",
        value: |o| o.snapshot.deflection[1] / o.flap_limit,
    },
    ObservationField {
        name: "flap_top",
        unit: "-",
        scale: 1.0,
        description: "top flap deflection / accd.flap_limit_deg",
        value: |o| o.snapshot.deflection[2] / o.flap_limit,
    },
    ObservationField {
        name: "flap_bottom",
        unit: "-",
        scale: 1.0,
        description: "bottom flap deflection / accd.flap_limit_deg",
        value: |o| o.snapshot.deflection[3] / o.flap_limit,
    },
    ObservationField {
        name: "tension",
        unit: "N",
        scale: 0.0001,
        description: "tension at the attachment",
        value: |o| o.snapshot.attachment_tension,
    },
    ObservationField {
        name: "time_left",
        unit: "-",
        scale: 1.0,
        description: "time left in the capture window / capture_window",
        value: |o| (o.capture_window - o.snapshot.time) / o.capture_window,
    },
];

/// The index of the observation entry `name`, if there is one.
pub fn observation_index(name: &str) -> Option<usize> {
    OBSERVATION.iter().position(|f| f.name == name)
}

/// The index of the observation entry `name`, at compile time (a name not in the table is a
/// compile error).
const fn index_of(name: &str) -> usize {
    let mut i = 0;
    while i < OBS_DIM {
        let a = OBSERVATION[i].name.as_bytes();
        let b = name.as_bytes();
        if a.len() == b.len() {
            let mut k = 0;
            while k < a.len() && a[k] == b[k] {
                k += 1;
            }
            if k == a.len() {
                return i;
            }
        }
        i += 1;
    }
    panic!("not an observation entry")
}

/// Where the sensor model ([`crate::task::sensors`]) finds the quantities it senses in the
/// observation; each group is contiguous in the table (`sensed_layout_matches_the_table`).
pub const SENSED_LAYOUT: SensedLayout = SensedLayout {
    dim: OBS_DIM,
    boom_rel: index_of("boom_rel_x"),
    boom_rel_rate: index_of("boom_rel_vx"),
    position: index_of("accd_dx"),
    velocity: index_of("accd_vx"),
    attitude: index_of("quat_w"),
    body_rates: index_of("rate_p"),
    tension: index_of("tension"),
};

/// The physical quantities of the observation of `inputs` (in their units, before scaling)
/// into `raw`; false if one is not finite.
pub fn raw_observation(inputs: &ObservationInputs<'_>, raw: &mut [f64; OBS_DIM]) -> bool {
    for (v, field) in raw.iter_mut().zip(&OBSERVATION) {
        *v = (field.value)(inputs);
    }
    raw.iter().all(|v| v.is_finite())
}

/// Each quantity of `raw` times its scale, clipped to [-[`OBS_BOUND`], [`OBS_BOUND`]], into `out`.
pub fn scale_observation(raw: &[f64; OBS_DIM], out: &mut [f32; OBS_DIM]) {
    for (o, (v, field)) in out.iter_mut().zip(raw.iter().zip(&OBSERVATION)) {
        *o = ((v * field.scale) as f32).clamp(-OBS_BOUND, OBS_BOUND);
    }
}

/// The observation of `inputs` into `out` (each quantity times its scale, clipped to
/// [-[`OBS_BOUND`], [`OBS_BOUND`]]) if every quantity is finite; false (and `out` unchanged)
/// otherwise.
pub fn observe(inputs: &ObservationInputs<'_>, out: &mut [f32; OBS_DIM]) -> bool {
    let mut raw = [0.0; OBS_DIM];
    if !raw_observation(inputs, &mut raw) {
        return false;
    }
    scale_observation(&raw, out);
    true
}

/// [`observe`] through `sensors`: the true quantities checked finite (false and `out` unchanged
/// otherwise), then measured ([`Sensors::sense`]), scaled and clipped, then delayed
/// ([`Sensors::delay`]).
pub fn observe_sensed(
    inputs: &ObservationInputs<'_>,
    sensors: &mut Sensors,
    out: &mut [f32; OBS_DIM],
) -> bool {
    let mut raw = [0.0; OBS_DIM];
    if !raw_observation(inputs, &mut raw) {
        return false;
    }
    sensors.sense(&mut raw);
    scale_observation(&raw, out);
    sensors.delay(out);
    true
}

/// Angle between the body's nose (body x) and the flight direction (TA x), rad.
pub fn tilt(attitude: &nalgebra::UnitQuaternion<f64>) -> f64 {
    let nose = attitude.transform_vector(&Vector3::x());
    libm::acos(nose.x.clamp(-1.0, 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sensors' groups are contiguous runs of the table, in the order the layout says.
    #[test]
    fn sensed_layout_matches_the_table() {
        let l = SENSED_LAYOUT;
        let runs: [(usize, &[&str]); 7] = [
            (l.boom_rel, &["boom_rel_x", "boom_rel_y", "boom_rel_z"]),
            (
                l.boom_rel_rate,
                &["boom_rel_vx", "boom_rel_vy", "boom_rel_vz"],
            ),
            (l.position, &["accd_dx", "accd_dy", "accd_dz"]),
            (l.velocity, &["accd_vx", "accd_vy", "accd_vz"]),
            (l.attitude, &["quat_w", "quat_x", "quat_y", "quat_z"]),
            (l.body_rates, &["rate_p", "rate_q", "rate_r"]),
            (l.tension, &["tension"]),
        ];
        for (start, names) in runs {
            for (k, name) in names.iter().enumerate() {
                assert_eq!(OBSERVATION[start + k].name, *name);
            }
        }
        assert_eq!(l.dim, OBS_DIM);
    }

    #[test]
    fn observation_table_is_complete() {
        let mut names: Vec<_> = OBSERVATION.iter().map(|f| f.name).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), OBS_DIM);
        assert!(OBSERVATION.iter().all(|f| f.scale > 0.0));
    }
}
