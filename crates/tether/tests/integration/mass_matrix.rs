//! The mass matrix is symmetric positive definite and equals the Hessian of the kinetic energy,
//! which is computed here independently from finite differences of the positions (paper Eq. 3).

use crate::common;

use accd_tether::{TetherConfig, TetherModel};
use common::{eig_range, kinetic_energy_fd};
use proptest::prelude::*;

fn config(n: usize, tip_mass: f64) -> TetherConfig {
    TetherConfig {
        segments: n,
        length: 12.0 * n as f64,
        tip_mass,
        ..TetherConfig::table3()
    }
}

/// A state: elongation, then per segment phi anywhere and psi within 70 degrees of the plane.
fn state(n: usize) -> impl Strategy<Value = Vec<f64>> {
    (
        -0.05f64..0.5,
        proptest::collection::vec((-3.1f64..3.1, -1.2f64..1.2), n),
    )
        .prop_map(|(s, angles)| {
            let mut q = vec![s];
            for (phi, psi) in angles {
                q.extend([phi, psi]);
            }
            q
        })
}

fn case() -> impl Strategy<Value = (usize, f64, Vec<f64>)> {
    (1usize..=12, 0.0f64..100.0).prop_flat_map(|(n, tip)| (Just(n), Just(tip), state(n)))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn mass_matrix_is_spd_and_matches_kinetic_energy((n, tip, q) in case()) {
        let cfg = config(n, tip);
        let mut model = TetherModel::new(&cfg).unwrap();
        let m = model.mass_matrix(&q).unwrap();
        let dim = cfg.dofs();
        prop_assert_eq!(m.nrows(), dim);
        // Symmetric.
        prop_assert!((&m - m.transpose()).amax() == 0.0);
        // Positive definite.
        let (lo, hi) = eig_range(&m);
        prop_assert!(lo > 0.0, "smallest eigenvalue {lo}");
        prop_assert!(m.clone().cholesky().is_some());
        // Polarisation of the quadratic form T(v) = v^T M v / 2:
        // M_ij = T(u_i + u_j) - T(u_i) - T(u_j) for unit vectors u.
        let unit = |i: usize| { let mut v = vec![0.0; dim]; v[i] = 1.0; v };
        let t_single: Vec<f64> = (0..dim).map(|i| kinetic_energy_fd(&cfg, &q, &unit(i))).collect();
        let scale = hi;
        for i in 0..dim {
            prop_assert!((2.0 * t_single[i] - m[(i, i)]).abs() < 1e-6 * scale,
                "M[{i},{i}] = {} vs 2T = {}", m[(i, i)], 2.0 * t_single[i]);
            for j in 0..i {
                let mut v = unit(i);
                v[j] = 1.0;
                let mij = kinetic_energy_fd(&cfg, &q, &v) - t_single[i] - t_single[j];
                prop_assert!((mij - m[(i, j)]).abs() < 1e-6 * scale,
                    "M[{i},{j}] = {} vs finite differences {}", m[(i, j)], mij);
            }
        }
    }
}
