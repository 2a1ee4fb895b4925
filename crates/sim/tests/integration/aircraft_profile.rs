//! A scripted acceleration of the towing aircraft reaches the tether as the rheonomous
//! constraint: the apparent force and the growing airspeed pull harder on the attachment, and
//! after the manoeuvre the system settles again at the new speed.

use accd_sim::physics::aircraft::AccelerationSegment;
use accd_sim::{CaptureConfig, CaptureSim, Seeds};

#[test]
fn forward_acceleration_loads_the_tether_and_changes_the_free_stream() {
    let a = 2.0;
    let mut config = CaptureConfig::calm();
    config.aircraft.acceleration_profile = vec![AccelerationSegment {
        start: 40.0,
        end: 45.0,
        acceleration: [a, 0.0, 0.0],
    }];
    let mut sim = CaptureSim::new(&config.clone().validated().unwrap(), Seeds::default()).unwrap();
    sim.step_many(4000, [0.0; 4]).unwrap();
    let before = sim.snapshot().unwrap();
    sim.step_many(250, [0.0; 4]).unwrap();
    let during = sim.snapshot().unwrap();
    sim.step_many(4000, [0.0; 4]).unwrap();
    let after = sim.snapshot().unwrap();
    let tether = config.tether_with_tip();
    let inertial_pull = (tether.total_mass() + tether.tip_mass) * a;
    eprintln!(
        "tension {:.0} N before, {:.0} N while accelerating at {a} m/s^2 (m a = {inertial_pull:.0} N), {:.0} N at {:.0} m/s after; \
         depth {:.1} -> {:.1} m",
        before.attachment_tension,
        during.attachment_tension,
        after.attachment_tension,
        after.aircraft_velocity.x,
        before.position.z,
        after.position.z
    );
    assert_eq!(before.aircraft_velocity.x, 185.0);
    assert!((after.aircraft_velocity.x - (185.0 + 5.0 * a)).abs() < 1e-9);
    assert!(during.attachment_tension - before.attachment_tension > 0.8 * inertial_pull);
    // Faster flight: more drag on the tether and the ACCD, so it trails higher and pulls harder.
    assert!(after.attachment_tension > before.attachment_tension);
    assert!(after.position.z < before.position.z);
    assert!(after.velocity.norm() < 0.05, "settled again");
}
