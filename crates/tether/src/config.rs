//! Tether configuration: plain serde data, validated before a model is built.

use accd_spec::Fields;
use serde::{Deserialize, Serialize};

use crate::error::{Result, TetherError};
use crate::state::TetherState;

/// Standard gravity, m/s^2 (ISO 80000-3).
pub const STANDARD_GRAVITY: f64 = 9.80665;

accd_spec::config_struct! {
    /// Physical and numerical parameters of one tether. SI units throughout.
    ///
    /// The tether is `segments` identical rigid rods of length `l = length / segments` and mass
    /// `m = mass_per_length * l` (rod inertia `m l^2 / 12` about axes normal to the rod), hung from the
    /// towing aircraft through one axial visco-elastic element and carrying a lumped tip mass.
    ///
    /// Damping follows the paper's Table 3, which gives coefficients *per unit mass*:
    /// * joint (bending) damping `c_b = joint_damping_per_mass * m` (N m s), i.e. scaled by the mass of
    ///   one segment, as in Fritzkowski & Kaminski's equations divided through by the segment mass;
    /// * axial damping `c_s = axial_damping_per_mass * m_tot` (N s/m), scaled by the total tether mass
    ///   `m_tot = mass_per_length * length` that the axial element carries. For Table 3 this gives a
    ///   damping ratio of about 0.85 of the axial mode with a 50 kg tip body.
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, default)]
    pub struct TetherConfig {
        pub segments: usize = 30, "-", "[1, 1000]", "number of rigid segments n (Table 3: 30)";
        pub length: f64 = 250.0, "m", "(0, 5000]", "unstretched length L (Table 3)";
        pub mass_per_length: f64 = 82.25 / 250.0, "kg/m", "(0, 100]",
            "mass per unit length (Table 3: 82.25 kg over 250 m)";
        pub diameter: f64 = 0.024, "m", "(0, 0.5]", "diameter d; sets the aerodynamic areas";
        pub axial_stiffness: f64 = 157_431.5, "N/m", "(0, 1e12]",
            "axial stiffness k of the whole tether, EA / L (Table 3)";
        pub axial_damping_per_mass: f64 = 100.0, "N s/(m kg)", "[0, 1e6]",
            "axial damping per unit tether mass c_k (Table 3)";
        pub flexural_rigidity: f64 = 170.0, "N m^2", "[0, 1e9]",
            "flexural rigidity EI of the joints' bending springs, the paper's k_t (Table 3)";
        pub joint_damping_per_mass: f64 = 1.0, "N m s/kg", "[0, 1e6]",
            "joint damping per unit segment mass c1 (Table 3)";
        /// 0.35: the tether's Reynolds number (about 1.8e5) is at the cylinder drag crisis, and
        /// the paper's settled depths imply a value well under the subcritical 1.2. 0.35 with the
        /// 50 kg stand-in body of [`crate::reference::StandInBody::accd`] puts the settled depths
        /// of 250 m UHMWPE, 250 m steel and 300 m UHMWPE at 54.5, 118 and 63.7 m (paper: about
        /// 50, over 100, about 70).
        pub normal_drag_coefficient: f64 = 0.35, "-", "[0, 5]",
            "cross-flow (normal) drag coefficient C_n";
        pub tangential_drag_coefficient: f64 = 0.01, "-", "[0, 1]",
            "skin-friction (tangential) drag coefficient C_t, on the wetted area pi d l";
        pub tip_mass: f64 = 0.0, "kg", "[0, 1e6]", "lumped mass at the free end (the capturing device)";
        /// Not used by the dynamics; reported so that users can detect overload.
        pub breaking_tension: f64 = 550e3, "N", "(0, 1e9]",
            "breaking (maximum allowable) tension (Table 2, UHMWPE 24 mm)";
        pub gravity: f64 = STANDARD_GRAVITY, "m/s^2", "[0, 100]",
            "gravitational acceleration, along +z of the towing-aircraft frame";
        pub time_step: f64 = 0.01, "s", "(0, 1]", "fixed RK4 step (paper section 4)";
        /// `"attachment"`: the paper's simplified model, one visco-elastic element at the
        /// attachment point (2n + 1 coordinates). `"distributed"`: the paper's full model (section
        /// 2.3.6), a spring-damper in every segment with stiffness `n k` and damping `n c_s`, so
        /// that the static stretch under a tip load is the same (3n coordinates; see
        /// [`crate::dynamics`]). Omitted from the JSON when it is the default, so that default
        /// configurations serialize as before.
        #[serde(skip_serializing_if = "Elasticity::is_attachment")]
        pub elasticity: Elasticity = Elasticity::Attachment, "", "",
            "where the axial elasticity sits: \"attachment\" (one element, the paper's simplified model) or \"distributed\" (one per segment)";
        /// `"relative"`: the air velocity relative to each segment's centre, so a swinging tether
        /// is damped by its own motion through the air. `"free_stream"`: a literal reading of the
        /// paper's Eq. 9 (`u = U_inf cos(phi) cos(psi)`, no segment velocity): the drag depends on
        /// the segments' angles but does not damp their motion (for the sweeps of
        /// `docs/paper-reproduction.md`; the tip body's drag stays relative). Omitted from the
        /// JSON when it is the default.
        #[serde(skip_serializing_if = "DragVelocity::is_relative")]
        pub drag_velocity: DragVelocity = DragVelocity::Relative, "", "",
            "which velocity the segments' drag is computed from: \"relative\" or \"free_stream\" (Eq. 9 read literally)";
        /// `"explicit"`: classical RK4 for every mode, substepped for the fastest (the axial
        /// element's included). `"implicit_axial"`: the linearly implicit Rosenbrock-W method
        /// ROS34PW2 (order 3, L-stable, [`crate::implicit`]) with the axial spring-dampers in its
        /// matrix, so that stiff axial elements (the distributed elasticity, or k up to 1e12 N/m)
        /// run at the step the slow dynamics need; the other modes are explicit in it, with
        /// their own stability limit ([`ROSENBROCK_STABILITY_LIMIT`]). Omitted from the JSON when
        /// it is the default.
        #[serde(skip_serializing_if = "Scheme::is_explicit")]
        pub scheme: Scheme = Scheme::Explicit, "", "",
            "time integration: \"explicit\" (RK4, the axial elements substepped explicitly) or \"implicit_axial\" (Rosenbrock-W ROS34PW2 with the axial spring-dampers implicit)";
    }
}

accd_spec::no_range!(Elasticity, DragVelocity, Scheme);

/// How a step integrates the chain ([`TetherConfig::scheme`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Scheme {
    /// Classical RK4 ([`crate::Rk4`]) for every mode, substepped for the fastest: the default.
    #[default]
    Explicit,
    /// The Rosenbrock-W method ROS34PW2 ([`crate::Rosenbrock`]) with the axial spring-dampers
    /// (the attachment element, or every element of the distributed elasticity) in its matrix.
    ImplicitAxial,
}

impl Scheme {
    /// Whether this is the default, [`Scheme::Explicit`].
    pub fn is_explicit(&self) -> bool {
        *self == Scheme::Explicit
    }

    /// The integrator's name: `"RK4"` or `"ROS34PW2"`.
    pub fn integrator(&self) -> &'static str {
        match self {
            Scheme::Explicit => "RK4",
            Scheme::ImplicitAxial => "ROS34PW2",
        }
    }

    /// The name used in JSON.
    pub fn name(&self) -> &'static str {
        match self {
            Scheme::Explicit => "explicit",
            Scheme::ImplicitAxial => "implicit_axial",
        }
    }
}

impl<'de> Deserialize<'de> for Scheme {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        match name.as_str() {
            "explicit" => Ok(Scheme::Explicit),
            "implicit_axial" => Ok(Scheme::ImplicitAxial),
            other => Err(serde::de::Error::custom(format!(
                "invalid value of `scheme`: {other:?}; allowed: \"explicit\" or \"implicit_axial\""
            ))),
        }
    }
}

/// Which velocity the segments' aerodynamic drag sees ([`TetherConfig::drag_velocity`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DragVelocity {
    /// The air velocity relative to the segment's centre (the default).
    #[default]
    Relative,
    /// The air velocity alone (the paper's Eq. 9 read literally).
    FreeStream,
}

impl DragVelocity {
    /// Whether this is the default, [`DragVelocity::Relative`].
    pub fn is_relative(&self) -> bool {
        *self == DragVelocity::Relative
    }

    /// The name used in JSON.
    pub fn name(&self) -> &'static str {
        match self {
            DragVelocity::Relative => "relative",
            DragVelocity::FreeStream => "free_stream",
        }
    }

    /// The weight of the segment's own velocity in its drag: 1 (relative) or 0 (free stream).
    pub fn segment_velocity_weight(&self) -> f64 {
        match self {
            DragVelocity::Relative => 1.0,
            DragVelocity::FreeStream => 0.0,
        }
    }
}

impl<'de> Deserialize<'de> for DragVelocity {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        match name.as_str() {
            "relative" => Ok(DragVelocity::Relative),
            "free_stream" => Ok(DragVelocity::FreeStream),
            other => Err(serde::de::Error::custom(format!(
                "invalid value of `drag_velocity`: {other:?}; allowed: \"relative\" or \"free_stream\""
            ))),
        }
    }
}

/// Each field's range is all there is to check ([`TetherConfig::check_stability`] is a rule of
/// the stepping, with the tension it is run at).
impl accd_spec::Rules for TetherConfig {}

/// Where the tether's axial elasticity sits ([`TetherConfig::elasticity`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Elasticity {
    /// One visco-elastic element (k, c_s) at the attachment point, along segment 1: the paper's
    /// simplified model and the default.
    #[default]
    Attachment,
    /// A visco-elastic element (n k, n c_s) at the inboard end of every segment: the paper's full
    /// model.
    Distributed,
}

impl Elasticity {
    /// Whether this is the default, [`Elasticity::Attachment`].
    pub fn is_attachment(&self) -> bool {
        *self == Elasticity::Attachment
    }

    /// The name used in JSON.
    pub fn name(&self) -> &'static str {
        match self {
            Elasticity::Attachment => "attachment",
            Elasticity::Distributed => "distributed",
        }
    }
}

impl<'de> Deserialize<'de> for Elasticity {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        match name.as_str() {
            "attachment" => Ok(Elasticity::Attachment),
            "distributed" => Ok(Elasticity::Distributed),
            other => Err(serde::de::Error::custom(format!(
                "invalid value of `elasticity`: {other:?}; allowed: \"attachment\" or \"distributed\""
            ))),
        }
    }
}

/// The largest `|lambda| dt` a step may take, where `lambda` is the fastest eigenvalue of the
/// linearised chain ([`TetherConfig::fastest_rate`]). Classical RK4 is stable up to 2.83 on the
/// imaginary axis and 2.79 on the negative real axis; 2.5 leaves a margin for the estimate.
pub const RK4_STABILITY_LIMIT: f64 = 2.5;

/// The largest `|lambda| dt` a step of [`Scheme::ImplicitAxial`] may take over the modes it
/// treats explicitly (everything but the axial spring-dampers). With its matrix zero on them,
/// ROS34PW2 is an explicit four-stage method of order 3 there, stable up to 1.50 on the
/// imaginary axis and 1.99 on the negative real axis; 1.3 leaves the margin
/// [`RK4_STABILITY_LIMIT`] leaves RK4. Half RK4's limit: where the zig-zag mode passes 1.3 /
/// [`TetherConfig::time_step`] (Table 3's towed chain at 0.01 s from n = 100) this scheme takes
/// twice RK4's substeps.
pub const ROSENBROCK_STABILITY_LIMIT: f64 = 1.3;

/// The most RK4 substeps one step of [`TetherConfig::time_step`] is split into; a configuration
/// needing more is refused with the largest stable step in the message.
pub const MAX_SUBSTEPS: usize = 64;

/// What the stability estimate of a step ([`TetherConfig::fastest_rate`]) reads from the state
/// and the surroundings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepLoad {
    /// The largest tension along the chain, N.
    pub tension: f64,
    /// Air density, kg/m^3.
    pub density: f64,
    /// Speed of the air past the tether, m/s.
    pub airspeed: f64,
    /// The fastest segment's angular rate, rad/s.
    pub max_rate: f64,
    /// Mass the axial element moves, kg: `1 / (M^-1)_00`, exactly (the axial damping is rank
    /// one, so `c_s / axial_mass` is its mode's rate). The whole tether and tip for a straight
    /// chain, far less where a kink lets the chain beyond it swing instead of following
    /// ([`crate::TetherModel::axial_mass`]).
    pub axial_mass: f64,
}

impl StepLoad {
    /// A straight chain at rest carrying `tension` in air of `density` at `airspeed`, with
    /// `tip_mass` (kg) at its end.
    pub fn at_rest(
        config: &TetherConfig,
        tension: f64,
        density: f64,
        airspeed: f64,
        tip_mass: f64,
    ) -> StepLoad {
        StepLoad {
            tension,
            density,
            airspeed,
            max_rate: 0.0,
            axial_mass: config.total_mass() + tip_mass,
        }
    }

    /// The load of `state`: the tension is the larger of the axial element's (`k s` and
    /// `k s + c_s s'`) and the hanging weight, the fastest rate the largest angular rate, and
    /// `axial_mass` (kg) the effective mass the axial element moves at this state,
    /// `1 / (M^-1)_00` ([`crate::TetherModel::axial_mass`] after evaluating the accelerations
    /// there; [`StepLoad::of_coordinates`] for the coordinates alone).
    pub fn of_state(
        config: &TetherConfig,
        state: &TetherState,
        tip_mass: f64,
        density: f64,
        airspeed: f64,
        axial_mass: f64,
    ) -> StepLoad {
        StepLoad::of_coordinates(
            config, &state.q, &state.qd, tip_mass, density, airspeed, axial_mass,
        )
    }

    /// [`StepLoad::of_state`] from the coordinates `q` and rates `qd`.
    pub fn of_coordinates(
        config: &TetherConfig,
        q: &[f64],
        qd: &[f64],
        tip_mass: f64,
        density: f64,
        airspeed: f64,
        axial_mass: f64,
    ) -> StepLoad {
        let elastic = config.element_stiffness() * q[0];
        let tension = elastic
            .abs()
            .max((elastic + config.element_damping() * qd[0]).abs())
            .max((config.total_mass() + tip_mass) * config.gravity);
        // The angle rates only (the distributed model's stretch rates follow them in qd).
        let angles = qd.len().min(2 * config.segments + 1);
        let max_rate = qd[..angles]
            .iter()
            .skip(1)
            .fold(0.0, |m: f64, v| m.max(v.abs()));
        StepLoad {
            tension,
            density,
            airspeed,
            max_rate,
            axial_mass,
        }
    }
}

impl TetherConfig {
    /// Table 3 of the paper: the tether selected for In-Air Capturing (24 mm UHMWPE, 250 m, n = 30).
    pub fn table3() -> Self {
        TetherConfig::default()
    }

    /// Table 1 of the paper: the 10 m verification case (n = 4, m_tot = 5 kg, k = 10 kN/m,
    /// c1 = 20 N m s/kg), hanging in vacuum.
    ///
    /// Table 1 gives one damping coefficient, c1; we apply it to the joints and to the axial
    /// element alike. It gives no bending stiffness, diameter or breaking tension: bending is off,
    /// the drag coefficients are zero (the case is in vacuum), and the diameter (10 mm) and breaking
    /// tension (100 kN) only fill their fields.
    pub fn table1() -> Self {
        let length = 10.0;
        let total_mass = 5.0;
        let c1 = 20.0;
        TetherConfig {
            segments: 4,
            length,
            mass_per_length: total_mass / length,
            diameter: 0.01,
            axial_stiffness: 10_000.0,
            axial_damping_per_mass: c1,
            flexural_rigidity: 0.0,
            joint_damping_per_mass: c1,
            normal_drag_coefficient: 0.0,
            tangential_drag_coefficient: 0.0,
            tip_mass: 0.0,
            breaking_tension: 100e3,
            gravity: STANDARD_GRAVITY,
            time_step: 0.01,
            elasticity: Elasticity::Attachment,
            drag_velocity: DragVelocity::Relative,
            scheme: Scheme::Explicit,
        }
    }

    /// Parses a JSON document, rejecting unknown keys, and validates it. Missing keys take
    /// Table 3's values.
    pub fn from_json(text: &str) -> Result<Self> {
        let config: TetherConfig =
            serde_json::from_str(text).map_err(|e| TetherError::ConfigParse {
                message: e.to_string(),
            })?;
        config.validate()?;
        Ok(config)
    }

    /// Serializes to JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).expect("a config of plain numbers always serializes")
    }

    /// Checks every field against its declared range ([`Fields::FIELDS`]); errors name the
    /// field as declared (`length`; the capture configuration adds `tether.`).
    pub fn validate(&self) -> Result<()> {
        Ok(self.check_fields("")?)
    }

    /// [`TetherConfig::validate`] and the rule a configuration to be stepped must also meet: a
    /// step that substepping can keep stable for the chain hanging still
    /// ([`TetherConfig::check_stability`] at [`TetherConfig::static_tension`]). The model alone
    /// (linearisations, mass matrices) needs only the first.
    pub fn validate_for_stepping(&self) -> Result<()> {
        self.validate()?;
        self.check_stability(self.static_tension(), 0.0, 0.0, self.tip_mass)
    }

    /// Segment length l = L / n, m.
    pub fn segment_length(&self) -> f64 {
        self.length / self.segments as f64
    }

    /// Segment mass m = mu l, kg.
    pub fn segment_mass(&self) -> f64 {
        self.mass_per_length * self.segment_length()
    }

    /// Total tether mass mu L, kg.
    pub fn total_mass(&self) -> f64 {
        self.mass_per_length * self.length
    }

    /// Joint damping coefficient c_b = c1 m, N m s.
    pub fn joint_damping(&self) -> f64 {
        self.joint_damping_per_mass * self.segment_mass()
    }

    /// Axial damping coefficient c_s = c_k m_tot, N s/m.
    pub fn axial_damping(&self) -> f64 {
        self.axial_damping_per_mass * self.total_mass()
    }

    /// Number of generalized coordinates: 2n + 1 for the attachment element, 3n for the
    /// distributed elasticity.
    pub fn dofs(&self) -> usize {
        match self.elasticity {
            Elasticity::Attachment => 2 * self.segments + 1,
            Elasticity::Distributed => 3 * self.segments,
        }
    }

    /// Whether the elasticity is distributed over the segments.
    pub fn is_distributed(&self) -> bool {
        self.elasticity == Elasticity::Distributed
    }

    /// Stiffness of one axial element, N/m: k at the attachment, n k per segment when
    /// distributed (n springs n k in series are k).
    pub fn element_stiffness(&self) -> f64 {
        match self.elasticity {
            Elasticity::Attachment => self.axial_stiffness,
            Elasticity::Distributed => self.segments as f64 * self.axial_stiffness,
        }
    }

    /// Damping of one axial element, N s/m: c_s at the attachment, n c_s per segment when
    /// distributed.
    pub fn element_damping(&self) -> f64 {
        match self.elasticity {
            Elasticity::Attachment => self.axial_damping(),
            Elasticity::Distributed => self.segments as f64 * self.axial_damping(),
        }
    }

    /// Magnitude of the fastest eigenvalue of the linearised chain under `load`, 1/s.
    ///
    /// Two modes bound it. The zig-zag of the rods (neighbours turning opposite ways about
    /// their centres): for one rod of mass `m = mu l` and inertia `I = m l^2 / 12`, the tension
    /// `T` at both ends restores it with `T l`, the two bending springs (`EI / l` each, the joint
    /// angle twice the rod's) with `4 EI / l`, joint damping and the linearised cross-flow drag
    /// damp it. The axial element (`k`, `c_s`) moving the chain's apparent mass `M_a` along
    /// segment 1. For each, `|lambda| = sigma / 2 + sqrt(sigma^2 / 4 + omega^2)`, with
    ///
    /// ```text
    /// zig-zag: omega^2 = 12 T / (mu l^2) + 48 EI / (mu l^4),  sigma = 48 c1 / l^2 + rho C_n d V / mu
    /// axial:   omega^2 = k / M_a,                              sigma = c_s / M_a
    /// ```
    ///
    /// and `2 Omega` is added for a segment turning at `Omega` (a whipping end: centrifugal and
    /// gyroscopic terms grow perturbations at rates of order `Omega`).
    ///
    /// At n = 300 (Table 3 otherwise) and 3.4 kN the zig-zag gives about 480 rad/s: RK4 at
    /// 0.01 s is outside its stability region there, at n = 30 (about 45 rad/s) far inside.
    /// `M_a` is the exact `1 / (M^-1)_00` of the state ([`StepLoad::axial_mass`]): for a towed
    /// 10 or 50 kg/m tether it falls to a quarter of the straight chain's, and with it the
    /// damping mode's rate climbs past what one step at 0.01 s can take.
    pub fn fastest_rate(&self, load: &StepLoad) -> f64 {
        let l = self.segment_length();
        let mu = self.mass_per_length;
        let mode = |omega2: f64, sigma: f64| 0.5 * sigma + (0.25 * sigma * sigma + omega2).sqrt();
        let zigzag = mode(
            12.0 * load.tension.abs() / (mu * l * l)
                + 48.0 * self.flexural_rigidity / (mu * ((l * l) * (l * l))),
            48.0 * self.joint_damping_per_mass / (l * l)
                + load.density.abs()
                    * self.normal_drag_coefficient
                    * self.diameter
                    * load.airspeed.abs()
                    / mu,
        );
        if self.scheme == Scheme::ImplicitAxial {
            // The axial spring-dampers are in the Rosenbrock matrix (their modes damped, not
            // resolved): only the other modes bound the step.
            return zigzag + 2.0 * load.max_rate.abs();
        }
        let m_a = load.axial_mass.max(self.segment_mass());
        let axial = mode(self.axial_stiffness / m_a, self.axial_damping() / m_a);
        let fastest = zigzag.max(axial);
        let fastest = if self.is_distributed() {
            // The highest axial mode of n rods of mass m joined by springs n k and dampers n c_s:
            // by Gershgorin's theorem the stiffness and damping matrices' eigenvalues (per unit
            // mass) are at most 4 n k / m and 4 n c_s / m, i.e. omega_max <= 2 sqrt(n k / m).
            let m = self.segment_mass();
            fastest.max(mode(
                4.0 * self.element_stiffness() / m,
                4.0 * self.element_damping() / m,
            ))
        } else {
            fastest
        };
        fastest + 2.0 * load.max_rate.abs()
    }

    /// The largest `|lambda| dt` of the modes [`TetherConfig::fastest_rate`] counts that a step
    /// of this configuration's [`TetherConfig::scheme`] may take: [`RK4_STABILITY_LIMIT`] or
    /// [`ROSENBROCK_STABILITY_LIMIT`].
    pub fn stability_limit(&self) -> f64 {
        match self.scheme {
            Scheme::Explicit => RK4_STABILITY_LIMIT,
            Scheme::ImplicitAxial => ROSENBROCK_STABILITY_LIMIT,
        }
    }

    /// Substeps per [`TetherConfig::time_step`] that keep `|lambda| dt / k` within the scheme's
    /// [`TetherConfig::stability_limit`] under `load` (at least 1). Not capped: compare with
    /// [`MAX_SUBSTEPS`].
    pub fn substeps_for(&self, load: &StepLoad) -> usize {
        let r = self.fastest_rate(load) * self.time_step;
        if !r.is_finite() {
            return usize::MAX;
        }
        ((r / self.stability_limit()).ceil() as usize).max(1)
    }

    /// Checks that the step can be kept stable by substepping for a straight chain at rest
    /// carrying `tension` (N) in air of `density` at `airspeed`, with `tip_mass`: at most
    /// [`MAX_SUBSTEPS`] substeps. The error names the largest step stable without substeps.
    pub fn check_stability(
        &self,
        tension: f64,
        density: f64,
        airspeed: f64,
        tip_mass: f64,
    ) -> Result<()> {
        let load = StepLoad::at_rest(self, tension, density, airspeed, tip_mass);
        let k = self.substeps_for(&load);
        if k <= MAX_SUBSTEPS {
            return Ok(());
        }
        let stable = self.stability_limit() / self.fastest_rate(&load);
        let implicit = TetherConfig {
            scheme: Scheme::ImplicitAxial,
            ..self.clone()
        };
        let implicit_takes_it =
            self.scheme == Scheme::Explicit && implicit.substeps_for(&load) <= MAX_SUBSTEPS;
        Err(TetherError::invalid_config(
            "time_step",
            self.time_step,
            &format!(
                "(0, {:.3e}] s for this discretization: segments = {} and length = {} m make \
                 segments of {:.3} m, which with mass_per_length = {} kg/m, flexural_rigidity = {} \
                 N m^2, joint_damping_per_mass = {}, axial_stiffness = {} N/m, \
                 axial_damping_per_mass = {} and an estimated peak tension of {:.3e} N give a \
                 fastest mode needing {k} {} substeps (at most {MAX_SUBSTEPS} are \
                 taken; the largest stable step is {stable:.3e} s): use fewer segments, a longer \
                 tether or a shorter time_step{}",
                stable * MAX_SUBSTEPS as f64,
                self.segments,
                self.length,
                self.segment_length(),
                self.mass_per_length,
                self.flexural_rigidity,
                self.joint_damping_per_mass,
                self.axial_stiffness,
                self.axial_damping_per_mass,
                tension,
                self.scheme.integrator(),
                if implicit_takes_it {
                    " (the axial elements are the stiff modes: scheme = \"implicit_axial\" \
                     integrates them implicitly and takes this step)"
                } else {
                    ""
                }
            ),
        ))
    }

    /// A bound of the tension the tether carries hanging still: its weight and the tip's, N.
    pub fn static_tension(&self) -> f64 {
        (self.total_mass() + self.tip_mass) * self.gravity
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_valid() {
        TetherConfig::table1().validate().unwrap();
        TetherConfig::table3().validate().unwrap();
        for name in [
            "steel-250m-24mm",
            "uhmwpe-300m-24mm",
            "uhmwpe-150m-16mm",
            "kevlar-250m-20mm",
        ] {
            TetherConfig::preset(name).unwrap().validate().unwrap();
        }
    }

    #[test]
    fn table3_derived_quantities() {
        let c = TetherConfig::table3();
        assert!((c.total_mass() - 82.25).abs() < 1e-12);
        assert_eq!(c.dofs(), 61);
        assert!((c.segment_length() - 250.0 / 30.0).abs() < 1e-12);
    }

    #[test]
    fn bad_values_name_field_value_and_range() {
        let mut c = TetherConfig::table3();
        c.length = -3.0;
        let msg = c.validate().unwrap_err().to_string();
        assert!(
            msg.contains("`length`") && msg.contains("-3") && msg.contains("(0, 5000] m"),
            "{msg}"
        );
        let mut c = TetherConfig::table3();
        c.time_step = f64::NAN;
        assert!(c.validate().unwrap_err().to_string().contains("time_step"));
        let mut c = TetherConfig::table3();
        c.segments = 0;
        assert!(c.validate().unwrap_err().to_string().contains("[1, 1000]"));
    }

    #[test]
    fn json_rejects_unknown_keys_and_fills_defaults() {
        let err = TetherConfig::from_json(r#"{"lenght": 3}"#)
            .unwrap_err()
            .to_string();
        assert!(err.contains("lenght"), "{err}");
        let c = TetherConfig::from_json(r#"{"length": 300}"#).unwrap();
        assert_eq!(c.length, 300.0);
        assert_eq!(c.segments, 30);
        let round = TetherConfig::from_json(&c.to_json()).unwrap();
        assert_eq!(round, c);
        assert!(TetherConfig::from_json(r#"{"length": -1}"#).is_err());
    }

    #[test]
    fn preset_names_parse() {
        let c = TetherConfig::preset("steel-250m-24mm").unwrap();
        assert!((c.mass_per_length - 2.34).abs() < 1e-12);
        assert!(TetherConfig::preset("steel-250-24").is_err());
        assert!(TetherConfig::preset("nope")
            .unwrap_err()
            .to_string()
            .contains("preset"));
    }
}
