//! Classical controllers designed on the linearized plant ([`crate::task::linearize`]): the LQR
//! baseline with its steady-state Kalman filter, and the MPC baseline on the same filter.
//!
//! * [`matrix`]: dense matrices whose every operation runs in one fixed order of floating-point
//!   operations (no BLAS, no run-time kernel choice): the same bits on every CPU.
//! * [`riccati`]: the discrete algebraic Riccati equation by the structured doubling algorithm.
//! * [`lqr`]: the design (LQR gain, Kalman gain, offset-free reference) of one configuration.
//! * [`filter`]: the per-step work (predict, update, control law) of one env.
//! * [`controller`]: one env's controller as a batch steps it beside the env (the LQR and the
//!   MPC, each with its env's state).
//! * [`mpc`]: the MPC baseline, a condensed QP on the filter's estimate with the flap limits and
//!   the capture conditions (closing speed, capture radius) as constraints.
//! * [`qp`]: the exact dense QP solver the MPC uses (the Goldfarb-Idnani dual active-set method).

pub mod controller;
pub mod filter;
pub mod lqr;
pub mod matrix;
pub mod mpc;
pub mod qp;
pub mod riccati;
