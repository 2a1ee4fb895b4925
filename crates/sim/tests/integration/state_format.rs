//! Saved states of a capture simulation through the state format: a restored simulation
//! continues bit for bit (per-stage and per-lane turbulence alike), and a corrupted, truncated
//! or foreign blob is a [`SimError::State`] that leaves the simulation as it was.

use accd_sim::state_format::{self, StateError, StateKind};
use accd_sim::AirState;
use accd_sim::{CaptureConfig, CaptureSim, LaneStreams, Seeds, SimError};

fn seeds() -> Seeds {
    Seeds {
        initial: 1,
        wake: 42,
        rlv: 7,
    }
}

fn command(k: usize) -> [f64; 4] {
    let a = 0.2 * (k as f64 * 0.13).sin();
    [a, a, -0.5 * a, 0.1]
}

/// Positions and attitudes of `steps` steps, as bits.
fn run(sim: &mut CaptureSim, from: usize, steps: usize) -> Vec<u64> {
    let mut out = Vec::new();
    for k in from..from + steps {
        sim.step(command(k)).unwrap();
        let s = sim.snapshot().unwrap();
        out.extend(s.position.iter().map(|v| v.to_bits()));
        out.extend(s.attitude.coords.iter().map(|v| v.to_bits()));
        out.extend(s.boom_tip.iter().map(|v| v.to_bits()));
    }
    out
}

fn per_lane() -> CaptureConfig {
    let mut c = CaptureConfig::default();
    c.turbulence.lane_streams = LaneStreams::PerLane;
    c.wake.sampling = accd_sim::AirSampling::PerStep;
    c
}

/// The exact air scheme (the default of the first releases): one shared lane stream, per-stage sampling.
fn exact() -> CaptureConfig {
    let mut c = CaptureConfig::default();
    c.turbulence.lane_streams = LaneStreams::Shared;
    c.turbulence.normal_sampler = accd_sim::NormalSampler::BoxMuller;
    c.wake.sampling = accd_sim::AirSampling::PerStage;
    c
}

#[test]
fn a_saved_simulation_continues_bit_for_bit() {
    for config in [
        CaptureConfig::default(),
        per_lane(),
        exact(),
        CaptureConfig::calm(),
    ] {
        let mut a = CaptureSim::new(&config.clone().validated().unwrap(), seeds()).unwrap();
        run(&mut a, 0, 120);
        let saved = a.save().unwrap();
        let mut b =
            CaptureSim::new(&config.clone().validated().unwrap(), Seeds::default()).unwrap();
        b.load(&saved).unwrap();
        assert_eq!(run(&mut a, 120, 150), run(&mut b, 120, 150));
        assert_eq!(a.state(), b.state());
    }
}

#[test]
fn foreign_corrupted_and_truncated_states_change_nothing() {
    let config = CaptureConfig::default();
    let mut a = CaptureSim::new(&config.clone().validated().unwrap(), seeds()).unwrap();
    run(&mut a, 0, 30);
    let saved = a.save().unwrap();
    let mut b = CaptureSim::new(&config.clone().validated().unwrap(), Seeds::default()).unwrap();
    run(&mut b, 0, 5);
    let before = b.state();
    let state_error = |r: Result<(), SimError>| match r {
        Err(SimError::State(e)) => e,
        other => panic!("expected a state error, got {other:?}"),
    };

    let mut flipped = saved.clone();
    flipped[saved.len() / 2] ^= 0x10;
    assert!(matches!(
        state_error(b.load(&flipped)),
        StateError::Checksum { .. }
    ));
    assert!(matches!(
        state_error(b.load(&saved[..saved.len() - 1])),
        StateError::Truncated { .. }
    ));
    let calm = CaptureSim::new(&CaptureConfig::calm().validated().unwrap(), seeds()).unwrap();
    assert!(matches!(
        state_error(b.load(&calm.save().unwrap())),
        StateError::Config { .. }
    ));
    // The same state under another kind.
    let hash = state_format::config_hash(&config).unwrap();
    let as_batch = state_format::encode(StateKind::Batch, &hash, 1, &a.state()).unwrap();
    let e = state_error(b.load(&as_batch));
    assert!(e.to_string().contains("Rust BatchEnv"), "{e}");
    // A well-formed blob whose state does not fit: a turbulence history of another length.
    let mut wrong = a.state();
    match &mut wrong.air {
        AirState::Turbulence(t) => t.ring.truncate(10),
        AirState::Steady => panic!("the default config has turbulence"),
    }
    let blob = state_format::encode(StateKind::CaptureSim, &hash, 1, &wrong).unwrap();
    let e = state_error(b.load(&blob));
    assert!(e.to_string().contains("turbulence.ring"), "{e}");
    // The calm simulation's steady air into a turbulent one.
    let mut steady = a.state();
    steady.air = AirState::Steady;
    let e = state_error(b.set_state(steady));
    assert!(e.to_string().contains("steady"), "{e}");
    assert_eq!(b.state(), before, "nothing half-applied");
}

#[test]
fn per_lane_states_check_their_lanes() {
    let config = per_lane();
    let mut a = CaptureSim::new(&config.clone().validated().unwrap(), seeds()).unwrap();
    run(&mut a, 0, 20);
    let good = a.state();
    let lanes = |s: &mut accd_sim::CaptureState| match &mut s.air {
        AirState::Turbulence(t) => t.lanes.as_mut().expect("per-lane streams").clone(),
        AirState::Steady => unreachable!(),
    };
    let mut s = good.clone();
    let generated = lanes(&mut s).generated;
    assert!(!generated.is_empty(), "the tether's lanes are generated");
    let with = |f: &dyn Fn(&mut accd_sim::physics::turbulence::LaneState)| {
        let mut s = good.clone();
        if let AirState::Turbulence(t) = &mut s.air {
            f(t.lanes.as_mut().unwrap());
        }
        s
    };
    let before = a.state();
    for (bad, what) in [
        (with(&|l| l.generated.push(l.generated[0])), "generated"),
        (with(&|l| l.generated.push(10_000)), "generated"),
        (with(&|l| l.covered = Some([0, 1000, 0, 0])), "covered"),
        (
            with(&|l| l.streams.pop().map(drop).unwrap_or(())),
            "streams",
        ),
    ] {
        let e = a.set_state(bad).unwrap_err().to_string();
        assert!(e.contains(what), "{what}: {e}");
        assert_eq!(a.state(), before);
    }
    // The clock must sit on the gust grid as `advance` leaves it.
    let mut bad = good.clone();
    if let AirState::Turbulence(t) = &mut bad.air {
        t.newest += 5;
    }
    let e = a.set_state(bad).unwrap_err().to_string();
    assert!(e.contains("turbulence.time"), "{e}");
    a.set_state(good).unwrap();
}
