use accd_tether::{reference, Solver, Tether};
fn main() {
    let (cfg, flow) = reference::towed_table3();
    let mut a = Tether::new(&cfg).unwrap();
    let mut b = Tether::new(&cfg).unwrap();
    b.model_mut().set_solver(Solver::Dense);
    for i in 0..6000 {
        let ra = a.step(&flow);
        let rb = b.step(&flow);
        if ra.is_err() || rb.is_err() {
            println!("step {i}: {ra:?} {rb:?}");
            break;
        }
        if i % 250 == 0 {
            let d: f64 = a
                .state()
                .q
                .iter()
                .zip(&b.state().q)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max);
            let (p, v) = a.tip_state();
            println!(
                "t {:.2}: max |dq| {d:.2e}, s {:.4}, tip {:.1?} v {:.2}",
                a.state().time,
                a.state().q[0],
                p.as_slice(),
                v.norm()
            );
        }
    }
}
