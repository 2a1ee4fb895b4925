//! The axial part of one stage of a linearly implicit step, as the caller gives it
//! ([`AxialStage`]) and as the solvers read it.

/// The axial part of one stage of a linearly implicit step ([`crate::implicit`]): where the
/// axial elements' springs and dampers are evaluated, and the step-scaled stiffness and damping
/// added to their rows of the mass matrix.
///
/// [`crate::TetherModel::accelerations_axial`] solves
///
/// ```text
/// (M(q) + (gamma_h c + gamma_h^2 k) P^T P) x = Q(t, q, q')  with every element's force
///                                                            -k s~ - c s~' in place of -k s - c s'
/// ```
///
/// where `P` picks the stretch coordinates, `(k, c)` are one element's stiffness and damping
/// ([`crate::TetherConfig::element_stiffness`], [`crate::TetherConfig::element_damping`]) and `(s~, s~')` are
/// the stretch entries of `stretch` and `stretch_rate`. The kinematics (lever arms, drift) use
/// `q` and `q'` as always. With `gamma_h = 0` and `(s~, s~') = (s, s')` this is `M q'' = Q`.
#[derive(Debug, Clone, Copy)]
pub struct AxialStage<'a> {
    /// Full-length (dofs) array whose stretch entries the springs are evaluated at, m.
    pub stretch: &'a [f64],
    /// Full-length (dofs) array whose stretch entries the dampers are evaluated at, m/s.
    pub stretch_rate: &'a [f64],
    /// The step-scaled factor `gamma h`, s.
    pub gamma_h: f64,
}

/// The axial stage as the solvers read it: the springs' arguments and the added mass, kg.
#[derive(Debug, Clone, Copy)]
pub(crate) struct AxialSolve<'a> {
    pub stretch: &'a [f64],
    pub stretch_rate: &'a [f64],
    pub added_mass: f64,
}
