//! Prints an episode's outcomes step by step (for looking at the task's behaviour).
use std::sync::Arc;

use accd_sim::{EnvConfig, Episode, Equilibrium, Seeds};

fn main() {
    let config = Arc::new(EnvConfig::default());
    let t = std::time::Instant::now();
    let eq = Arc::new(Equilibrium::settle(&config).unwrap());
    eprintln!("settle {:?}: position {:?}", t.elapsed(), eq.position);
    let mut ep = Episode::new(
        config,
        eq,
        Seeds {
            initial: 3,
            wake: 4,
            rlv: 5,
        },
    )
    .unwrap();
    eprintln!("obs0 {:?}", ep.observation());
    let t = std::time::Instant::now();
    for k in 0..700 {
        let o = ep.step(&[0.0; 4]).unwrap();
        if k % 50 == 0 || o.terminated || o.truncated {
            eprintln!("{k}: {o:?}");
        }
        if o.terminated || o.truncated {
            eprintln!("obs {:?} div {:?}", ep.observation(), ep.divergence());
            break;
        }
    }
    eprintln!("episode {:?}", t.elapsed());
}
