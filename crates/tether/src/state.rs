//! The tether's state: time, generalized coordinates and their rates.

use nalgebra::Vector3;

use crate::direction::{angle_rates, angles, DirectionJet};
use crate::error::{Result, TetherError};

/// Below this cos(psi) a state is refused: a segment within 0.06 degrees of the lateral axis.
const MIN_COS_PSI: f64 = 1e-3;

/// Time (s), coordinates `q = [s, phi_1, psi_1, ..., phi_n, psi_n]` and rates `qd` (see
/// [`crate::dynamics`] for the layout and [`crate::direction`] for the angles).
#[derive(Debug, Clone, PartialEq)]
pub struct TetherState {
    /// Simulation time, s.
    pub time: f64,
    /// Generalized coordinates: elongation s (m), then (phi, psi) per segment (rad).
    pub q: Vec<f64>,
    /// Their rates: s' (m/s), then (phi', psi') per segment (rad/s).
    pub qd: Vec<f64>,
}

impl TetherState {
    /// A straight tether of `segments` segments all along `direction` (any non-zero vector), at
    /// rest, with elongation `elongation` (m), at time 0.
    pub fn straight(segments: usize, direction: Vector3<f64>, elongation: f64) -> Result<Self> {
        let dirs = vec![direction; segments];
        let rates = vec![Vector3::zeros(); segments];
        TetherState::from_directions(&dirs, &rates, elongation, 0.0)
    }

    /// A state from each segment's direction (m, any length, normalised here) and the rate of its
    /// unit direction (1/s; the component along the direction is removed), the elongation (m) and
    /// its rate (m/s), at time 0.
    pub fn from_directions(
        directions: &[Vector3<f64>],
        direction_rates: &[Vector3<f64>],
        elongation: f64,
        elongation_rate: f64,
    ) -> Result<Self> {
        let n = directions.len();
        if n == 0 {
            return Err(TetherError::WrongSize {
                what: "directions",
                expected: 1,
                found: 0,
            });
        }
        if direction_rates.len() != n {
            return Err(TetherError::WrongSize {
                what: "direction_rates",
                expected: n,
                found: direction_rates.len(),
            });
        }
        let mut q = vec![0.0; 2 * n + 1];
        let mut qd = vec![0.0; 2 * n + 1];
        check_finite("elongation", elongation)?;
        check_finite("elongation_rate", elongation_rate)?;
        q[0] = elongation;
        qd[0] = elongation_rate;
        for (k, (d, r)) in directions.iter().zip(direction_rates).enumerate() {
            let norm = d.norm();
            if !(norm.is_finite() && norm > 0.0) {
                return Err(TetherError::InvalidState {
                    field: format!("directions[{k}]"),
                    value: format!("{:?}", d.as_slice()),
                    reason: "must be a finite, non-zero vector".into(),
                });
            }
            if !r.iter().all(|v| v.is_finite()) {
                return Err(TetherError::InvalidState {
                    field: format!("direction_rates[{k}]"),
                    value: format!("{:?}", r.as_slice()),
                    reason: "must be finite".into(),
                });
            }
            let (phi, psi) = angles(d);
            if libm::cos(psi) < MIN_COS_PSI {
                return Err(TetherError::InvalidState {
                    field: format!("directions[{k}]"),
                    value: format!("{:?}", d.as_slice()),
                    reason:
                        "points along the lateral (y) axis, where the angle chart is singular; \
                             |y| / |direction| must be below 0.9999995"
                            .into(),
                });
            }
            let (phi_d, psi_d) = angle_rates(phi, psi, r);
            q[1 + 2 * k] = phi;
            q[2 + 2 * k] = psi;
            qd[1 + 2 * k] = phi_d;
            qd[2 + 2 * k] = psi_d;
        }
        Ok(TetherState { time: 0.0, q, qd })
    }

    /// A state from angle arrays (rad, rad/s) and elongation, at time 0. All arrays have length n.
    pub fn from_angles(
        phi: &[f64],
        psi: &[f64],
        phi_rate: &[f64],
        psi_rate: &[f64],
        elongation: f64,
        elongation_rate: f64,
    ) -> Result<Self> {
        let n = phi.len();
        for (what, v) in [("psi", psi), ("phi_rate", phi_rate), ("psi_rate", psi_rate)] {
            if v.len() != n {
                return Err(TetherError::WrongSize {
                    what,
                    expected: n,
                    found: v.len(),
                });
            }
        }
        let mut q = Vec::with_capacity(2 * n + 1);
        let mut qd = Vec::with_capacity(2 * n + 1);
        q.push(elongation);
        qd.push(elongation_rate);
        for k in 0..n {
            q.extend([phi[k], psi[k]]);
            qd.extend([phi_rate[k], psi_rate[k]]);
        }
        let state = TetherState { time: 0.0, q, qd };
        state.validate()?;
        Ok(state)
    }

    /// Number of segments of the attachment layout (2n + 1 coordinates); for the distributed
    /// layout (3n) ask the config.
    pub fn segments(&self) -> usize {
        self.q.len() / 2
    }

    /// This state (attachment layout, 2n + 1 coordinates) in the distributed elasticity's layout
    /// ([`crate::distributed`], 3n coordinates): the same geometry and rates, with the
    /// elongation on segment 1's element and the elements of segments 2 ... n unstretched.
    /// Errors if the state is not in the attachment layout.
    pub fn to_distributed(&self) -> Result<TetherState> {
        if self.q.len() != self.qd.len() || self.q.len() % 2 != 1 {
            return Err(TetherError::WrongSize {
                what: "q (attachment layout, 2n + 1)",
                expected: 2 * self.segments() + 1,
                found: self.q.len(),
            });
        }
        let n = self.segments();
        let mut q = self.q.clone();
        let mut qd = self.qd.clone();
        q.resize(3 * n, 0.0);
        qd.resize(3 * n, 0.0);
        Ok(TetherState {
            time: self.time,
            q,
            qd,
        })
    }

    /// Elongation s of the axial element, m.
    pub fn elongation(&self) -> f64 {
        self.q[0]
    }

    /// Unit direction of segment `k` (0-based).
    pub fn direction(&self, k: usize) -> Vector3<f64> {
        DirectionJet::new(self.q[1 + 2 * k], self.q[2 + 2 * k]).e
    }

    /// Rate of the unit direction of segment `k` (0-based), 1/s.
    pub fn direction_rate(&self, k: usize) -> Vector3<f64> {
        DirectionJet::new(self.q[1 + 2 * k], self.q[2 + 2 * k])
            .rate(self.qd[1 + 2 * k], self.qd[2 + 2 * k])
    }

    /// Checks that every value is finite and no segment sits at the coordinate singularity
    /// (attachment layout, 2n + 1 coordinates).
    pub fn validate(&self) -> Result<()> {
        if self.q.len() != self.qd.len() || self.q.len() % 2 != 1 {
            return Err(TetherError::WrongSize {
                what: "qd",
                expected: self.q.len(),
                found: self.qd.len(),
            });
        }
        self.validate_values(self.segments())
    }

    /// [`TetherState::validate`] for a state of `segments` segments in either layout (2n + 1
    /// coordinates for the attachment element, 3n for the distributed elasticity).
    pub fn validate_for(&self, segments: usize) -> Result<()> {
        let n = segments;
        if self.q.len() != 2 * n + 1 && self.q.len() != 3 * n {
            return Err(TetherError::WrongSize {
                what: "q",
                expected: 2 * n + 1,
                found: self.q.len(),
            });
        }
        if self.qd.len() != self.q.len() {
            return Err(TetherError::WrongSize {
                what: "qd",
                expected: self.q.len(),
                found: self.qd.len(),
            });
        }
        self.validate_values(n)
    }

    fn validate_values(&self, segments: usize) -> Result<()> {
        check_finite("time", self.time)?;
        for (name, v) in [("q", &self.q), ("qd", &self.qd)] {
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(TetherError::InvalidState {
                    field: format!("{name}[{i}]"),
                    value: v[i].to_string(),
                    reason: "must be finite".into(),
                });
            }
        }
        for k in 0..segments {
            let psi = self.q[2 + 2 * k];
            if libm::cos(psi).abs() < MIN_COS_PSI {
                return Err(TetherError::InvalidState {
                    field: format!("psi[{k}]"),
                    value: psi.to_string(),
                    reason: "is at the coordinate singularity (|cos psi| < 1e-3)".into(),
                });
            }
        }
        Ok(())
    }
}

fn check_finite(field: &str, value: f64) -> Result<()> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(TetherError::InvalidState {
            field: field.into(),
            value: value.to_string(),
            reason: "must be finite".into(),
        })
    }
}
