//! Four tethers stepped together (`Tether::step_four`: the recursion's sweeps four AVX2 lanes
//! wide, `Rk4::advance_adaptive_four`) step bit for bit as each steps alone: states, times,
//! tensions and errors, whatever their configurations, surroundings and substeps.

use accd_tether::{reference, LockstepWork, Tether, TetherConfig, TetherModel, UniformFlow};
use nalgebra::Vector3;

/// Lane j's tether: Table 3 with `segments`, its length, tip mass and stiffness varied by lane,
/// towed in its own side wind, and advanced `j` tenths of a second so that the four states
/// differ.
fn lane(j: usize, segments: usize, time_step: f64) -> (Tether, UniformFlow) {
    let cfg = TetherConfig {
        segments,
        time_step,
        length: 250.0 - 15.0 * j as f64,
        tip_mass: 50.0 + 6.0 * j as f64,
        axial_stiffness: TetherConfig::table3().axial_stiffness * (1.0 + 0.2 * j as f64),
        ..TetherConfig::table3()
    };
    let (cfg, towed) = reference::towed(&cfg, reference::StandInBody::accd()).unwrap();
    let flow = UniformFlow {
        velocity: towed.velocity + Vector3::new(0.0, 4.0 - 2.0 * j as f64, 1.0),
        ..towed
    };
    let mut t = Tether::new(&cfg).unwrap();
    t.step_many((10.0 * j as f64 * 0.01 / time_step) as usize, &flow)
        .unwrap();
    (t, flow)
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// Steps `four` together and `alone` one by one `steps` times, comparing everything after
/// every step; returns how many lane-steps failed (with the same error both ways).
fn compare(
    four: &mut [Tether],
    alone: &mut [Tether],
    flows: &[UniformFlow],
    steps: usize,
) -> usize {
    let mut work = LockstepWork::default();
    let mut failures = 0;
    for step in 0..steps {
        let results = {
            let [a, b, c, d] = four else { unreachable!() };
            Tether::step_four([a, b, c, d], std::array::from_fn(|j| &flows[j]), &mut work)
        };
        for (j, together) in results.into_iter().enumerate() {
            let single = alone[j].step(&flows[j]);
            let what = format!("step {step}, lane {j}");
            match (&together, &single) {
                (Ok(()), Ok(())) => {}
                (Err(a), Err(b)) => {
                    assert_eq!(a.to_string(), b.to_string(), "{what}");
                    failures += 1;
                }
                _ => panic!("{what}: together {together:?}, alone {single:?}"),
            }
            let (x, y) = (four[j].state(), alone[j].state());
            assert_eq!(x.time.to_bits(), y.time.to_bits(), "{what}");
            assert_eq!(bits(&x.q), bits(&y.q), "{what}");
            assert_eq!(bits(&x.qd), bits(&y.qd), "{what}");
            assert_eq!(
                four[j].attachment_tension().to_bits(),
                alone[j].attachment_tension().to_bits(),
                "{what}"
            );
            assert_eq!(
                four[j].model_mut().axial_mass().to_bits(),
                alone[j].model_mut().axial_mass().to_bits(),
                "{what}"
            );
        }
    }
    failures
}

#[test]
fn four_tethers_in_lockstep_step_as_each_alone() {
    let (mut four, flows): (Vec<Tether>, Vec<UniformFlow>) =
        (0..4).map(|j| lane(j, 30, 0.01)).unzip();
    // One lane swinging hard from the start.
    let mut state = four[2].state().clone();
    for (i, v) in state.qd.iter_mut().enumerate().skip(1) {
        *v += 0.3 * ((i as f64) * 0.7).sin();
    }
    four[2].set_state(state).unwrap();
    let mut alone = four.clone();
    // (The processors CI runs on have AVX2 and FMA; elsewhere the four step one by one.)
    let models: Vec<TetherModel> = four
        .iter()
        .map(|t| TetherModel::new(t.config()).unwrap())
        .collect();
    #[cfg(target_arch = "x86_64")]
    assert_eq!(
        TetherModel::lockstep_eligible(std::array::from_fn(|j| &models[j])),
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    );
    assert_eq!(compare(&mut four, &mut alone, &flows, 400), 0);
}

/// A lane pulled by an absurd tip force diverges inside a step taken in lockstep: its error
/// and its kept state are those of its own step, and the other lanes go on.
#[test]
fn a_lane_diverging_in_lockstep_leaves_the_others_as_alone() {
    let (mut four, mut flows): (Vec<Tether>, Vec<UniformFlow>) =
        (0..4).map(|j| lane(j, 30, 0.01)).unzip();
    flows[1].tip_force = Vector3::new(0.0, 0.0, 1e13);
    let mut alone = four.clone();
    assert!(compare(&mut four, &mut alone, &flows, 20) >= 1);
}

/// Lanes that choose different substeps (n = 300 at 0.01 s needs two or more where the chain
/// is taut, at 0.004 s one), a lane that diverges (absurd rates), and four tethers of
/// different segment counts (not eligible for lanes) all step exactly as alone.
#[test]
fn substeps_errors_and_mixed_chains_step_as_alone() {
    let (mut four, flows): (Vec<Tether>, Vec<UniformFlow>) = [0.01, 0.004, 0.01, 0.004]
        .iter()
        .enumerate()
        .map(|(j, &dt)| lane(j, 300, dt))
        .unzip();
    let mut state = four[3].state().clone();
    for v in state.qd.iter_mut().skip(1) {
        *v = 4.0e3;
    }
    four[3].set_state(state).unwrap();
    let mut alone = four.clone();
    let failures = compare(&mut four, &mut alone, &flows, 30);
    assert!(failures >= 1, "the absurd lane fails");

    // Four alike at 0.01 s: two or more substeps each, chosen alike, taken in lockstep.
    let (mut alike, flows): (Vec<Tether>, Vec<UniformFlow>) =
        (0..4).map(|_| lane(0, 300, 0.01)).unzip();
    let mut alone = alike.clone();
    assert_eq!(compare(&mut alike, &mut alone, &flows, 30), 0);

    let (mut mixed, flows): (Vec<Tether>, Vec<UniformFlow>) = [10, 30, 30, 61]
        .iter()
        .enumerate()
        .map(|(j, &n)| lane(j, n, 0.01))
        .unzip();
    let mut alone = mixed.clone();
    assert_eq!(compare(&mut mixed, &mut alone, &flows, 100), 0);
}
