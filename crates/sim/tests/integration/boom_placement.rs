//! The boom's formation is placed relative to the open-loop equilibrium of each configuration
//! (`boom.placement`, crates/sim/src/physics/boom.rs): the default task keeps its boom bit for bit, every
//! other configuration gets the same relative geometry.

use accd_sim::{BoomPlacement, EnvConfig, Equilibrium};
use accd_tether::{Material, TetherConfig};
use nalgebra::Vector3;

fn settle(config: EnvConfig) -> Equilibrium {
    Equilibrium::settle(&config.validated().unwrap()).unwrap()
}

fn bits(v: &Vector3<f64>) -> [u64; 3] {
    [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()]
}

#[test]
fn the_default_configuration_keeps_its_boom_to_the_bit() {
    let offset = Vector3::from(EnvConfig::default().physics.boom.offset);
    let eq = settle(EnvConfig::default());
    assert_eq!(
        bits(&eq.boom_nominal),
        bits(&offset),
        "{:?}",
        eq.boom_nominal
    );
    // The exact air scheme settles a few ulps elsewhere; its own reference keeps it exact too.
    let mut exact = EnvConfig::default();
    exact.physics.wake.sampling = accd_sim::AirSampling::PerStage;
    let eq_exact = settle(exact);
    assert_eq!(bits(&eq_exact.boom_nominal), bits(&offset));
    // And the relative geometry is what the module docs say: about 3 m to starboard and 3.8 m
    // above the capture point's equilibrium.
    let rel = offset - eq.capture_point;
    assert!(
        (rel.y - 3.0).abs() < 0.05 && (-4.5..-3.0).contains(&rel.z),
        "{rel:?}"
    );
}

#[test]
fn other_tethers_get_the_same_relative_geometry() {
    let default = settle(EnvConfig::default());
    let rel = default.boom_nominal - default.capture_point;
    for (length, diameter) in [(150.0, 0.024), (300.0, 0.024), (250.0, 0.032)] {
        let mut config = EnvConfig::default();
        config.physics.tether =
            TetherConfig::from_material(Material::Uhmwpe, length, diameter).unwrap();
        let eq = settle(config.clone());
        let here = eq.boom_nominal - eq.capture_point;
        assert!(
            (here - rel).norm() < 1e-9,
            "{length} m, {diameter} m: {here:?} vs {rel:?}"
        );
        assert!(eq.outside_limits.is_none(), "{:?}", eq.outside_limits);
        // The absolute placement leaves it where the default tether's equilibrium is: metres off
        // the new equilibrium (the task the first versions posed).
        config.physics.boom.placement = BoomPlacement::Absolute;
        let absolute = settle(config);
        let offset = Vector3::from(EnvConfig::default().physics.boom.offset);
        assert_eq!(bits(&absolute.boom_nominal), bits(&offset));
        let off = (absolute.boom_nominal - absolute.capture_point - rel).norm();
        assert!(
            off > 1.0,
            "{length} m, {diameter} m: equilibrium moved only {off} m"
        );
    }
}

#[test]
fn an_explicit_offset_from_the_equilibrium_is_used_as_given() {
    let mut config = EnvConfig::default();
    config.physics.boom.offset_from_equilibrium = Some([1.0, -2.0, 5.0]);
    let eq = settle(config);
    let expected = eq.capture_point + Vector3::new(1.0, -2.0, 5.0);
    assert_eq!(bits(&eq.boom_nominal), bits(&expected));
}
