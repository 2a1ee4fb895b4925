//! Writes the analytic default wake tables (0 and 8 deg) as JSON files, as examples of the format
//! users can write from their own CFD.
//!
//! `cargo run -p accd-sim --example export_wake_tables -- [DIR]` writes `DIR/wake_alpha0.json` and
//! `DIR/wake_alpha8.json` (DIR defaults to the current directory). Point
//! `wake.tables = {"low": ..., "high": ...}` of a config at them to load them back.

use std::path::PathBuf;

use accd_sim::physics::wake::AnalyticWake;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| ".".into()));
    std::fs::create_dir_all(&dir)?;
    for (name, model) in [
        ("wake_alpha0.json", AnalyticWake::alpha_0()),
        ("wake_alpha8.json", AnalyticWake::alpha_8()),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, model.table().to_json_string())?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
