//! The LQR baseline's design: an LQR on the plant, a steady-state Kalman filter with disturbance
//! states, and the offset-free reference, for one configuration's linearization
//! ([`crate::task::linearize`]).
//!
//! # Observer state
//! `z = (dx, w, r, r')` (`nz = n + 8`): the plant state `dx = x - x*` (`n` entries), the wind
//! bias `w` at the ACCD (y, z; a random walk standing for the mean wake's error and slow
//! turbulence), the boom tip relative to the trim capture point `r` and its velocity `r'`
//! (constant velocity driven by white acceleration):
//!
//! ```text
//! z+ = F z + G u,   F = [[A, E, 0, 0], [0, I2, 0, 0], [0, 0, I3, T I3], [0, 0, 0, I3]],   G = [B; 0]
//! y_m - y*_m = H z,  H = [C_m, 0, S_p, S_v]
//! ```
//!
//! `y_m`: every observation but `time_left` ([`MEASURED`]); the `boom_rel` rows read `r` and `r'`
//! times their scales (`S_p`, `S_v`). `T` = the agent step.
//!
//! # Kalman filter
//! Steady-state gain `L = P H^T (H P H^T + V)^-1`, `P` the stabilizing solution of the filter's
//! Riccati equation (the LQR equation of `(F^T, H^T, W, V)`, [`solve_dare`]). Process noise `W`:
//! `wind_white^2 E E^T` (turbulence as white wind at the ACCD) plus `(model_noise 1000 h_i)^2`
//! on each plant state (`h_i` its finite-difference step: 1 mm of the elongation, 1 mrad of an
//! angle, 0.01 rad/s of a rate per step), `wind_walk^2` on `w`, 1e-6 m^2 on `r`, `boom_accel^2`
//! on `r'`. Measurement noise `V`: diagonal, `meas_noise` times [`measurement_sigma`] times the
//! observation's scale, squared.
//!
//! # LQR
//! `K = (R + B^T P B)^-1 B^T P A` with `P` the stabilizing solution of
//! the LQR's Riccati equation, `Q = q_position P_yz^T P_yz + q_velocity V^T V + q_attitude
//! (attitude error) + q_rate (body rates) + 1e-9 I` (`P_yz`: the capture point's y and z per
//! state; `V`: its velocity, all three axes, since the closing speed counts), `R = r_flap I`.
//!
//! # Reference (offset-free tracking)
//! The steady state `(dx_ss, u_ss)` with `(A - I) dx_ss + B u_ss + E w = 0` that puts the capture
//! point's y and z on `r_y, r_z`: the minimum-norm one in scaled units (states in units of
//! 1000 times their finite-difference steps, commands in flap-limit units; the roll angle is
//! neutral, so there is a family), by a Householder factorization ([`min_norm_solve`]). Along
//! track (x) nothing is tracked. The control law is `u = clip(-K dx + K_ff (w_y, w_z, r_y, r_z),
//! -1, 1)` with `K_ff = u_ss + K dx_ss` per unit of each.
//!
//! Every step of the design is fixed-order arithmetic ([`crate::control::matrix`]): the same
//! design, bit for bit, on every CPU and with any number of threads.

use crate::control::matrix::{min_norm_solve, spectral_radius, Lu, Matrix};
use crate::control::riccati::{solve_dare, DareSolution};
use crate::error::{Result, SimError};
use crate::task::linearize::{Linearization, WIND_DIM};
use crate::task::observation::{observation_index, ACT_DIM, OBSERVATION, OBS_DIM};

/// Observer states beyond the plant's: the wind bias (2), the boom tip (3) and its velocity (3).
pub const EXTRA_STATES: usize = WIND_DIM + 3 + 3;

/// Number of observation entries the filter reads (all but `time_left`).
pub const MEASURED_DIM: usize = OBS_DIM - 1;

/// The observation entries the filter reads, in observation order: all but `time_left`.
pub const MEASURED: [usize; MEASURED_DIM] = {
    let mut out = [0; MEASURED_DIM];
    let mut i = 0;
    let mut k = 0;
    while i < OBS_DIM {
        if !is_time_left(OBSERVATION[i].name.as_bytes()) {
            out[k] = i;
            k += 1;
        }
        i += 1;
    }
    out
};

const fn is_time_left(name: &[u8]) -> bool {
    let t = b"time_left";
    if name.len() != t.len() {
        return false;
    }
    let mut i = 0;
    while i < t.len() {
        if name[i] != t[i] {
            return false;
        }
        i += 1;
    }
    true
}

/// The relative cut of the reference solve: a factor below this is rank deficiency.
pub const REFERENCE_RCOND: f64 = 1e-10;

/// The measurement noise of an observation entry in its physical unit (before `meas_noise`):
/// 1 cm for positions, 1 cm/s for velocities, 1e-4 for the quaternion and the flaps, 1e-3 rad/s
/// for body rates, 100 N for the tension. `None` for an entry the filter does not read.
pub fn measurement_sigma(name: &str) -> Option<f64> {
    Some(match name {
        "boom_rel_x" | "boom_rel_y" | "boom_rel_z" | "accd_dx" | "accd_dy" | "accd_dz" => 0.01,
        "boom_rel_vx" | "boom_rel_vy" | "boom_rel_vz" | "accd_vx" | "accd_vy" | "accd_vz" => 0.01,
        "quat_w" | "quat_x" | "quat_y" | "quat_z" => 1e-4,
        "rate_p" | "rate_q" | "rate_r" => 1e-3,
        "flap_right" | "flap_left" | "flap_top" | "flap_bottom" => 1e-4,
        "tension" => 100.0,
        _ => return None,
    })
}

/// The LQR's weights and the Kalman filter's noise levels (every one positive and finite).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LqrTuning {
    /// Weight of the capture point's lateral and vertical offset, 1/m^2.
    pub q_position: f64,
    /// Weight of the capture point's velocity, s^2/m^2.
    pub q_velocity: f64,
    /// Weight of the attitude error, 1/rad^2.
    pub q_attitude: f64,
    /// Weight of the body rates, s^2/rad^2.
    pub q_rate: f64,
    /// Weight of each flap command, per flap-limit unit squared.
    pub r_flap: f64,
    /// White wind at the ACCD, m/s.
    pub wind_white: f64,
    /// Random walk of the wind bias, m/s per step.
    pub wind_walk: f64,
    /// The boom's random acceleration, m/s per step.
    pub boom_accel: f64,
    /// Scale of the plant's process noise (-).
    pub model_noise: f64,
    /// Scale of the measurement noise (-).
    pub meas_noise: f64,
}

impl LqrTuning {
    /// The field names, in declaration order.
    pub const FIELDS: [&'static str; 10] = [
        "q_position",
        "q_velocity",
        "q_attitude",
        "q_rate",
        "r_flap",
        "wind_white",
        "wind_walk",
        "boom_accel",
        "model_noise",
        "meas_noise",
    ];

    /// The tuning from its values in [`Self::FIELDS`] order; an error naming the field, the value
    /// and the allowed range for one that is not positive and finite.
    pub fn new(values: [f64; 10]) -> Result<Self> {
        for (name, v) in Self::FIELDS.iter().zip(values) {
            if !(v.is_finite() && v > 0.0) {
                return Err(SimError::invalid_config(
                    &format!("lqr.{name}"),
                    v,
                    "(0, inf)",
                ));
            }
        }
        let [q_position, q_velocity, q_attitude, q_rate, r_flap, wind_white, wind_walk, boom_accel, model_noise, meas_noise] =
            values;
        Ok(Self {
            q_position,
            q_velocity,
            q_attitude,
            q_rate,
            r_flap,
            wind_white,
            wind_walk,
            boom_accel,
            model_noise,
            meas_noise,
        })
    }
}

/// One design (see the module docs).
#[derive(Debug, Clone)]
pub struct LqrDesign {
    /// The tuning it was designed with.
    pub tuning: LqrTuning,
    /// Plant states `n`.
    pub n: usize,
    /// `F` (nz x nz).
    pub f: Matrix,
    /// `G` (nz x 4).
    pub g: Matrix,
    /// `H` ([`MEASURED_DIM`] x nz).
    pub h: Matrix,
    /// The Kalman gain `L` (nz x [`MEASURED_DIM`]).
    pub l: Matrix,
    /// The LQR gain `K` (4 x n).
    pub k: Matrix,
    /// The reference gain `K_ff` (4 x 4: per `w_y`, `w_z`, `r_y`, `r_z`).
    pub k_ff: Matrix,
    /// The LQR's state weight `Q` (n x n).
    pub q: Matrix,
    /// The reference's steady state `dx_ss` per unit of `w_y`, `w_z`, `r_y`, `r_z` (n x 4).
    pub x_ss: Matrix,
    /// The reference's steady command `u_ss` per unit of `w_y`, `w_z`, `r_y`, `r_z` (4 x 4).
    pub u_ss: Matrix,
    /// The measured observation at the trim, `y*_m`.
    pub y_trim: [f64; MEASURED_DIM],
    /// The LQR's Riccati solution and how it was found.
    pub lqr: DareSolution,
    /// The filter's Riccati solution and how it was found.
    pub filter: DareSolution,
    /// The spectral radius of `(I - L H) F` (the estimate error's dynamics).
    pub observer_radius: f64,
}

impl LqrDesign {
    /// Observer states `nz = n + 8`.
    pub fn nz(&self) -> usize {
        self.n + EXTRA_STATES
    }

    /// The spectral radius of `A - B K`.
    pub fn closed_loop_radius(&self) -> f64 {
        self.lqr.closed_loop_radius
    }
}

fn to_matrix(m: &nalgebra::DMatrix<f64>) -> Matrix {
    Matrix::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)])
}

fn index(name: &str) -> usize {
    observation_index(name).expect("a name of the observation table")
}

/// Designs the LQR, its Kalman filter and its reference for `lin` with `tuning` (see the module
/// docs). [`SimError::Design`] when a Riccati equation has no acceptable stabilizing solution or
/// the reference problem is rank deficient.
pub fn design(lin: &Linearization, tuning: &LqrTuning) -> Result<LqrDesign> {
    let t = tuning;
    let a = to_matrix(&lin.a);
    let b = to_matrix(&lin.b);
    let e = to_matrix(&lin.e);
    let c = to_matrix(&lin.c);
    let n = a.rows();
    let names = &lin.state_names;
    let state = |name: &str| {
        names
            .iter()
            .position(|s| s == name)
            .expect("a state of the linearization")
    };
    let boom_pos = [
        index("boom_rel_x"),
        index("boom_rel_y"),
        index("boom_rel_z"),
    ];
    let boom_vel = [
        index("boom_rel_vx"),
        index("boom_rel_vy"),
        index("boom_rel_vz"),
    ];
    let sp = OBSERVATION[boom_pos[0]].scale;
    let sv = OBSERVATION[boom_vel[0]].scale;
    // The capture point (m) and its velocity (m/s) per state: minus the boom rows of C.
    let cp = Matrix::from_fn(3, n, |i, j| -c[(boom_pos[i], j)] / sp);
    let cpv = Matrix::from_fn(3, n, |i, j| -c[(boom_vel[i], j)] / sv);
    let cp_yz = cp.block(1, 0, 2, n);

    // LQR on the plant.
    let mut q = cp_yz
        .scale(t.q_position)
        .tr_mul(&cp_yz)
        .add(&cpv.scale(t.q_velocity).tr_mul(&cpv))
        .add(&Matrix::identity(n).scale(1e-9));
    for s in ["att_x", "att_y", "att_z"] {
        let i = state(s);
        q[(i, i)] += t.q_attitude;
    }
    for s in ["p", "q", "r"] {
        let i = state(s);
        q[(i, i)] += t.q_rate;
    }
    let r = Matrix::identity(ACT_DIM).scale(t.r_flap);
    let lqr = solve_dare(&a, &b, &q, &r, "LQR design")?;
    let k = lqr.gain.clone();

    // Offset-free target: (A - I) dx + B u = -E w, cp_yz dx = r_yz, minimum norm in scaled units.
    let cols = n + ACT_DIM;
    let d: Vec<f64> = lin
        .steps
        .iter()
        .map(|h| h * 1e3)
        .chain(std::iter::repeat_n(1.0, ACT_DIM))
        .collect();
    let m = Matrix::from_fn(n + 2, cols, |i, j| {
        let v = if i < n {
            if j < n {
                a[(i, j)] - if i == j { 1.0 } else { 0.0 }
            } else {
                b[(i, j - n)]
            }
        } else if j < n {
            cp_yz[(i - n, j)]
        } else {
            0.0
        };
        v * d[j]
    });
    let rhs = Matrix::from_fn(n + 2, 4, |i, j| match (i < n, j < WIND_DIM) {
        (true, true) => -e[(i, j)],
        (false, false) if i - n == j - WIND_DIM => 1.0,
        _ => 0.0,
    });
    let scaled = min_norm_solve(&m, &rhs, REFERENCE_RCOND).map_err(|ratio| SimError::Design {
        what: "reference".into(),
        reason: format!(
            "the steady-state problem is rank deficient (pivot ratio {ratio:.3e} under {REFERENCE_RCOND:.0e})"
        ),
    })?;
    let sol = Matrix::from_fn(cols, 4, |i, j| d[i] * scaled[(i, j)]);
    let x_ss = sol.block(0, 0, n, 4);
    let u_ss = sol.block(n, 0, ACT_DIM, 4);
    let k_ff = u_ss.add(&k.mul(&x_ss));

    // Observer on z = (dx, w, r, r').
    let nz = n + EXTRA_STATES;
    let (iw, ir, iv) = (n, n + WIND_DIM, n + WIND_DIM + 3);
    let mut f = Matrix::zeros(nz, nz);
    f.set_block(0, 0, &a);
    f.set_block(0, iw, &e);
    for i in 0..WIND_DIM {
        f[(iw + i, iw + i)] = 1.0;
    }
    for i in 0..3 {
        f[(ir + i, ir + i)] = 1.0;
        f[(ir + i, iv + i)] = lin.dt;
        f[(iv + i, iv + i)] = 1.0;
    }
    let mut g = Matrix::zeros(nz, ACT_DIM);
    g.set_block(0, 0, &b);
    let mut h = Matrix::zeros(MEASURED_DIM, nz);
    for (row, &obs) in MEASURED.iter().enumerate() {
        for j in 0..n {
            h[(row, j)] = c[(obs, j)];
        }
        for axis in 0..3 {
            if obs == boom_pos[axis] {
                h[(row, ir + axis)] = sp;
            }
            if obs == boom_vel[axis] {
                h[(row, iv + axis)] = sv;
            }
        }
    }
    let mut qn = Matrix::zeros(nz, nz);
    let wind = e.scale(t.wind_white * t.wind_white).mul_tr(&e);
    qn.set_block(0, 0, &wind);
    for (i, step) in lin.steps.iter().enumerate() {
        let s = t.model_noise * 1e3 * step;
        qn[(i, i)] += s * s;
    }
    for i in 0..WIND_DIM {
        qn[(iw + i, iw + i)] = t.wind_walk * t.wind_walk;
    }
    for i in 0..3 {
        qn[(ir + i, ir + i)] = 1e-6;
        qn[(iv + i, iv + i)] = t.boom_accel * t.boom_accel;
    }
    let sigma: Vec<f64> = MEASURED
        .iter()
        .map(|&i| {
            let field = &OBSERVATION[i];
            let s = t.meas_noise
                * measurement_sigma(field.name).expect("every measured entry has a noise")
                * field.scale;
            s * s
        })
        .collect();
    let rn = Matrix::diagonal(&sigma);
    let filter = solve_dare(&f.transpose(), &h.transpose(), &qn, &rn, "Kalman filter")?;
    // L = P H^T S^-1 = (S^-1 H P)^T with S = H P H^T + V symmetric.
    let hp = h.mul(&filter.x);
    let s = hp.mul_tr(&h).add(&rn).symmetric_part();
    let s_lu = Lu::new(&s).ok_or_else(|| SimError::Design {
        what: "Kalman filter".into(),
        reason: "the innovation covariance H P H^T + V is singular".into(),
    })?;
    let l = s_lu.solve(&hp).transpose();
    let observer_radius = spectral_radius(&Matrix::identity(nz).sub(&l.mul(&h)).mul(&f));
    if observer_radius.is_nan() || observer_radius >= 1.0 {
        return Err(SimError::Design {
            what: "Kalman filter".into(),
            reason: format!(
                "the estimate error is not stable (spectral radius {observer_radius:.6})"
            ),
        });
    }
    let mut y_trim = [0.0; MEASURED_DIM];
    for (y, &i) in y_trim.iter_mut().zip(MEASURED.iter()) {
        *y = lin.trim_observation[i];
    }
    Ok(LqrDesign {
        tuning: *t,
        n,
        f,
        g,
        h,
        l,
        k,
        k_ff,
        q,
        x_ss,
        u_ss,
        y_trim,
        lqr,
        filter,
        observer_radius,
    })
}
