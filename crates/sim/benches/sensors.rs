//! The sensor model's own cost per agent step of the sensors tier's defaults: ten physics
//! steps (the vision history and its measurements), one observation sensed and delayed. The
//! physics is left out (it is the same with or without sensors), so the figure is the sensors'
//! share alone.

use accd_sim::task::observation::{OBS_DIM, SENSED_LAYOUT};
use accd_sim::{Sensors, SensorsConfig};
use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::Vector3;
use std::hint::black_box;

/// The physics step of the default configuration, s.
const TIME_STEP: f64 = 0.01;

fn bench(c: &mut Criterion) {
    let config = SensorsConfig {
        enabled: true,
        delay_steps: 1,
        ..SensorsConfig::default()
    };
    let mut sensors = Sensors::new(&config, TIME_STEP, SENSED_LAYOUT);
    sensors.reset(7, &Vector3::new(-20.0, 1.0, 2.0));
    let mut raw = [0.0f64; OBS_DIM];
    raw[SENSED_LAYOUT.attitude] = 1.0;
    raw[SENSED_LAYOUT.tension] = 1.0e4;
    let mut obs = [0.0f32; OBS_DIM];
    let mut n = 0u64;
    c.bench_function("sensors_agent_step", |b| {
        b.iter(|| {
            for _ in 0..10 {
                n += 1;
                let x = n as f64 * 1e-3;
                sensors.physics_step(&Vector3::new(-20.0 + x, 1.0 - x, 2.0));
            }
            let mut r = raw;
            sensors.sense(&mut r);
            for (o, v) in obs.iter_mut().zip(&r) {
                *o = *v as f32;
            }
            sensors.delay(&mut obs);
            black_box(&obs);
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
