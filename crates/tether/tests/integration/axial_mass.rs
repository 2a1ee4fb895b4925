//! The effective axial mass `1 / (M^-1)_00` that the substep estimate reads
//! ([`TetherModel::axial_mass`]): the recursion's root system and the dense solve's
//! Cholesky factor against the inverse of the dense mass matrix (`TetherModel::mass_matrix`), at
//! random bent and folded states for n = 1 ... 50.

use crate::common;

use accd_tether::direction::{angles, direction};
use accd_tether::{reference, Solver, TetherConfig, TetherModel};
use common::{SplitMix, V3};

/// A random state: elongation, directions (a quarter of the joints folded to 150-179 degrees,
/// the rest bent by up to 70 degrees) and rates.
fn random_state(rng: &mut SplitMix, n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut q = vec![rng.range(-0.02, 0.3)];
    let mut qd = vec![rng.range(-2.0, 2.0)];
    let mut e = direction(rng.range(-3.1, 3.1), rng.range(-1.2, 1.2));
    for k in 0..n {
        if k > 0 {
            let helper = if e.x.abs() < 0.9 { V3::x() } else { V3::y() };
            let u = e.cross(&helper).normalize();
            let v = e.cross(&u);
            let a = rng.range(0.0, std::f64::consts::TAU);
            let axis = u * a.cos() + v * a.sin();
            let angle = if rng.next() < 0.25 {
                rng.range(150.0, 179.0)
            } else {
                rng.range(0.0, 70.0)
            }
            .to_radians();
            e = e * angle.cos() + axis.cross(&e) * angle.sin();
            if e.y.abs() > 0.95 {
                e = direction(rng.range(-3.1, 3.1), rng.range(-1.2, 1.2));
            }
        }
        let (phi, psi) = angles(&e);
        q.extend([phi, psi]);
        qd.extend([rng.range(-1.5, 1.5), rng.range(-1.5, 1.5)]);
    }
    (q, qd)
}

#[test]
fn axial_mass_is_the_inverse_of_the_inverse_mass_matrix_corner() {
    let mut rng = SplitMix(0xA81A_1013);
    let mut worst = 0.0f64;
    let mut lowest = f64::INFINITY;
    for n in 1..=50usize {
        let cfg = TetherConfig {
            segments: n,
            mass_per_length: [0.275, 10.0, 50.0][n % 3],
            ..TetherConfig::table3()
        };
        let (cfg, flow) = reference::towed(&cfg, reference::StandInBody::accd()).unwrap();
        let straight = cfg.total_mass() + cfg.tip_mass;
        let mut rec = TetherModel::new(&cfg).unwrap();
        let mut dense = TetherModel::new(&cfg).unwrap();
        dense.set_solver(Solver::Dense);
        // Before any evaluation: the straight chain's.
        assert_eq!(rec.axial_mass(), straight);
        let dim = cfg.dofs();
        let mut qdd = vec![0.0; dim];
        for case in 0..8 {
            let (q, qd) = random_state(&mut rng, n);
            let m = rec.mass_matrix(&q).unwrap();
            let inv = m.clone().try_inverse().expect("M is SPD");
            let exact = 1.0 / inv[(0, 0)];
            rec.accelerations(0.0, &q, &qd, &flow, &mut qdd).unwrap();
            dense.accelerations(0.0, &q, &qd, &flow, &mut qdd).unwrap();
            for (solver, got) in [
                ("recursive", rec.axial_mass()),
                ("dense", dense.axial_mass()),
            ] {
                let err = (got - exact).abs() / exact;
                assert!(
                    err <= 1e-9,
                    "n = {n}, case {case}, {solver}: {got} against 1/(M^-1)_00 = {exact} \
                     (relative {err:e})"
                );
                worst = worst.max(err);
            }
            // Between one segment's mass and the whole chain's (M_00 = m_tot + M_t).
            assert!(
                exact >= cfg.segment_mass() * (1.0 - 1e-12),
                "n = {n}: {exact}"
            );
            assert!(exact <= m[(0, 0)] * (1.0 + 1e-12), "n = {n}: {exact}");
            assert!((m[(0, 0)] - straight).abs() <= 1e-9 * straight);
            lowest = lowest.min(exact / straight);
        }
    }
    // The bent states move far less than the straight chain: the estimate's old assumption.
    assert!(lowest < 0.5, "lowest ratio {lowest}");
    eprintln!("worst relative difference {worst:e}; lowest m_eff / (m_tot + M_t) {lowest:.3}");
}

#[test]
fn a_straight_chain_moves_all_of_its_mass() {
    for n in [1usize, 7, 30] {
        let cfg = TetherConfig {
            segments: n,
            ..TetherConfig::table3()
        };
        let (cfg, flow) = reference::towed(&cfg, reference::StandInBody::accd()).unwrap();
        let mut model = TetherModel::new(&cfg).unwrap();
        let (phi, psi) = angles(&V3::new(-1.0, 0.0, 0.0));
        let mut q = vec![0.01];
        for _ in 0..n {
            q.extend([phi, psi]);
        }
        let qd = vec![0.0; cfg.dofs()];
        let mut qdd = vec![0.0; cfg.dofs()];
        model.accelerations(0.0, &q, &qd, &flow, &mut qdd).unwrap();
        let straight = cfg.total_mass() + cfg.tip_mass;
        let err = (model.axial_mass() - straight).abs() / straight;
        assert!(
            err <= 1e-12,
            "n = {n}: {} against {straight}",
            model.axial_mass()
        );
    }
}
