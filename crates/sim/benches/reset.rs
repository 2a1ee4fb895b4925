//! A reset of a randomized episode (its parameters drawn from a new wake seed, its open-loop
//! equilibrium solved from the base's, a new simulation) against an agent step of the same
//! episode and the 40 s time settle that resets used before: the reset's cost in agent steps.

use std::sync::Arc;

use accd_sim::task::episode::drawn_config;
use accd_sim::{EnvConfig, Episode, Equilibrium, Parameters, Seeds};
use criterion::{criterion_group, criterion_main, Criterion};

fn seeds(wake: u64) -> Seeds {
    Seeds {
        initial: wake,
        wake,
        rlv: wake,
    }
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("randomized_reset");
    let mut base = EnvConfig::default();
    base.randomization.enabled = true;
    let config = Arc::new(base.clone().validated().unwrap());
    let eq = Arc::new(Equilibrium::settle(&config).unwrap());
    let mut episode = Episode::new(Arc::clone(&config), eq.clone(), seeds(1_000_000_000)).unwrap();
    // Held-out wake seeds, one new draw per reset.
    let mut wake = 1_000_000_000u64;
    group.bench_function("reset_new_draw", |b| {
        b.iter(|| {
            wake += 1;
            episode.reset(seeds(wake)).unwrap()
        })
    });
    let mut episode = Episode::new(Arc::clone(&config), eq.clone(), seeds(7)).unwrap();
    group.bench_function("agent_step", |b| {
        b.iter(|| {
            if episode.done() {
                // The same draw again: no new equilibrium.
                episode.reset(seeds(7)).unwrap();
            }
            episode.step(&[0.1, -0.1, 0.05, 0.0]).unwrap()
        })
    });
    let drawn = drawn_config(&base, &Parameters::draw(&base.randomization, 1_000_000_003)).unwrap();
    group.sample_size(10);
    group.bench_function("settle_40s", |b| {
        b.iter(|| Equilibrium::settle(&drawn).unwrap())
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
