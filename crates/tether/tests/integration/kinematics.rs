//! The two walks along the chain agree: `centres_and_tip_batch` (the kinematics pass with
//! vectorised sin/cos) against `centres_and_tip` (scalar, libm) at random states, n = 1 ... 300.

use crate::common;

use accd_tether::{TetherConfig, TetherModel};
use common::{SplitMix, V3};

#[test]
fn batch_walk_equals_scalar_walk_to_rounding() {
    let mut rng = SplitMix(0x5eed);
    for n in [1, 2, 3, 5, 8, 30, 101, 300] {
        let cfg = TetherConfig {
            segments: n,
            ..TetherConfig::table3()
        };
        let mut model = TetherModel::new(&cfg).unwrap();
        let dofs = 2 * n + 1;
        for _ in 0..20 {
            let mut q = vec![0.0; dofs];
            let mut qd = vec![0.0; dofs];
            q[0] = rng.range(-0.5, 0.5);
            qd[0] = rng.range(-1.0, 1.0);
            for k in 0..n {
                q[1 + 2 * k] = rng.range(-40.0, 40.0); // phi: far outside one turn too
                q[2 + 2 * k] = rng.range(-1.4, 1.4); // psi: up to 80 degrees sideways
                qd[1 + 2 * k] = rng.range(-3.0, 3.0);
                qd[2 + 2 * k] = rng.range(-3.0, 3.0);
            }
            let (mut a, mut b) = (vec![V3::zeros(); n], vec![V3::zeros(); n]);
            let (tip_a, vel_a) = model.centres_and_tip(&q, &qd, &mut a).unwrap();
            let (tip_b, vel_b) = model.centres_and_tip_batch(&q, &qd, &mut b).unwrap();
            let length = cfg.length;
            for (x, y) in a.iter().zip(&b) {
                assert!((x - y).norm() <= 1e-13 * length, "n = {n}: {x} vs {y}");
            }
            assert!((tip_a - tip_b).norm() <= 1e-13 * length, "n = {n}");
            let speed = vel_a.norm().max(1.0);
            assert!(
                (vel_a - vel_b).norm() <= 1e-12 * speed,
                "n = {n}: {vel_a} vs {vel_b}"
            );
        }
        assert!(model
            .centres_and_tip_batch(
                &vec![0.0; dofs - 1],
                &vec![0.0; dofs],
                &mut vec![V3::zeros(); n]
            )
            .is_err());
    }
}
