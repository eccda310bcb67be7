//! The README's Rust example. Cargo.toml: qtvpr = { path = "crates/qtvpr", features = ["npy"] } (a clone's path; `npy` reads files)
use std::path::Path;

use qtvpr::npy::{read_ground_truth, read_scores};
use qtvpr::{Calibration, Defaults, Matching, Params};

fn main() -> qtvpr::Result<()> {
    // The embedded Corridor traverse, |DB| x |Q| .npy files (memory-mapped), from the clone's root.
    let s_cal = read_scores(Path::new("data/corridor/cal_S.npy"))?;
    let gt = read_ground_truth(Path::new("data/corridor/cal_GT.npy"), None)?; // bool or 0/1
    let s_val = read_scores(Path::new("data/corridor/deploy_S.npy"))?; // no ground truth needed
    let cal = Calibration::new(s_cal.view(), &gt, Matching::Single)?;
    // k, precision, segment size, gate and its parameters: None is the default (k = 10, ...).
    let params = Params::resolve(&Defaults::default(), None, None, Some(25), None, Default::default())?;
    let out = cal.transfer(s_val.view(), &params)?;
    for seg in &out.segments {
        println!("queries {}..{}: accept score >= {}", seg.start, seg.end, seg.threshold);
    }
    Ok(())
}
