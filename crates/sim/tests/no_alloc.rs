//! Sampling the wake and the turbulence, advancing and resetting the turbulence, and stepping a
//! tether in the wake field allocate nothing on the heap.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use accd_sim::physics::turbulence::AmbientTurbulence;
mod support;

use accd_tether::{reference, Surroundings, Tether};
use nalgebra::Vector3;
use support::wake_field::{wake_field, WakeFieldConfig};

struct Counting;

thread_local! {
    /// Allocations made by this thread: the tests run in parallel threads and must not count
    /// each other's.
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn count() {
    let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
}

fn allocations() -> usize {
    ALLOCATIONS.with(Cell::get)
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn sampling_advancing_and_stepping_do_not_allocate() {
    let (cfg, flow) = reference::towed_table3();
    let mut config = WakeFieldConfig::default();
    config.turbulence.ambient = AmbientTurbulence::Moderate;
    let mut field = wake_field(&config, 3)
        .unwrap()
        .with_tip_drag_area(flow.tip_drag_area);
    let mut tether = Tether::new(&cfg).unwrap();
    tether.step(&field).unwrap();
    field.advance(cfg.time_step).unwrap();
    let points = [
        Vector3::new(-100.0, 2.0, 20.0),
        Vector3::new(-240.0, 0.0, 50.0),
        Vector3::new(-2000.0, 0.0, 0.0),
    ];
    let before = allocations();
    let mut acc = Vector3::zeros();
    for i in 0..300 {
        tether.step(&field).unwrap();
        field.advance(cfg.time_step).unwrap();
        for p in &points {
            let w = field.wake().sample(p);
            acc += w.velocity + field.turbulence().sample(p, w.tke);
            acc += field.air_velocity(0.0, p);
            acc += field.tip_force(0.0, p, &Vector3::zeros());
        }
        if i == 150 {
            field.reset(4);
        }
    }
    let after = allocations();
    assert!(acc.iter().all(|v| v.is_finite()));
    assert_eq!(after - before, 0, "{} allocations", after - before);
}

#[test]
fn capture_episode_steps_without_allocating() {
    let mut config = accd_sim::CaptureConfig::default();
    config.turbulence.ambient = AmbientTurbulence::Light;
    let mut sim = accd_sim::CaptureSim::new(
        &config.clone().validated().unwrap(),
        accd_sim::Seeds {
            initial: 1,
            wake: 2,
            rlv: 3,
        },
    )
    .unwrap();
    let mut tensions = vec![0.0; config.tether.segments + 1];
    sim.step([0.1, -0.1, 0.05, 0.0]).unwrap();
    let before = allocations();
    for i in 0..300 {
        let k = i as f64 * 0.01;
        sim.step([0.1 * k.sin(), -0.1, 0.05 * k.cos(), 0.0])
            .unwrap();
        let _ = sim.snapshot().unwrap();
        sim.tensions(&mut tensions).unwrap();
    }
    let after = allocations();
    assert_eq!(
        after - before,
        0,
        "{} allocations in 300 capture steps",
        after - before
    );
}

#[test]
fn rl_episodes_step_and_reset_without_allocating() {
    use std::sync::Arc;
    let config = Arc::new(
        accd_sim::EnvConfig {
            capture_window: 1.0,
            initial: accd_sim::task::InitialConfig {
                settle_time: 10.0,
                ..Default::default()
            },
            ..Default::default()
        }
        .validated()
        .unwrap(),
    );
    let eq = Arc::new(accd_sim::Equilibrium::settle(&config).unwrap());
    let seeds = |k: u64| accd_sim::Seeds {
        initial: k,
        wake: k + 1,
        rlv: k + 2,
    };
    let mut episode = accd_sim::Episode::new(config, eq, seeds(0)).unwrap();
    episode.step(&[0.0; 4]).unwrap();
    let before = allocations();
    for k in 0..100u64 {
        let a = (k as f32 * 0.3).sin();
        let o = episode.step(&[a, a, -a, 0.2]).unwrap();
        if o.terminated || o.truncated {
            episode.reset(seeds(k)).unwrap();
        }
    }
    let after = allocations();
    assert_eq!(
        after - before,
        0,
        "{} allocations in 100 agent steps",
        after - before
    );
}

#[test]
fn the_lqr_filter_step_does_not_allocate() {
    use accd_sim::control::filter::LqrFilter;
    use accd_sim::control::lqr::{EXTRA_STATES, MEASURED_DIM};
    use accd_sim::control::matrix::Matrix;
    use accd_sim::{ACT_DIM, OBS_DIM};

    let n = 20;
    let nz = n + EXTRA_STATES;
    let m = |r: usize, c: usize, s: f64| Matrix::from_fn(r, c, |i, j| s / (1 + i + j) as f64);
    let filter = LqrFilter::from_parts(
        n,
        &m(nz, nz, 0.5),
        &m(nz, ACT_DIM, 1.0),
        &m(MEASURED_DIM, nz, 1.0),
        &m(nz, MEASURED_DIM, 0.1),
        &m(ACT_DIM, n, 0.1),
        &m(ACT_DIM, 4, 1.0),
        [0.0; MEASURED_DIM],
    )
    .unwrap();
    let mut state = filter.new_state();
    let obs = [0.1; OBS_DIM];
    let mut command = [0.0_f32; ACT_DIM];
    filter.step(&mut state, &obs, &mut command).unwrap();
    let before = allocations();
    for _ in 0..10 {
        filter.step(&mut state, &obs, &mut command).unwrap();
    }
    assert_eq!(allocations() - before, 0);
}
