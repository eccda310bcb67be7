//! The real data of `../shared/data` for the Rust tests and benches: where it is, which
//! matrices it holds ([`VPRBENCH`], [`TECHNIQUES`]; `scripts/shared_data.py` lists the
//! same for the Python tests and benches), and the Nordland HOG descriptors.
//!
//! A test that needs the data is `#[ignore = "needs ../shared/data DATASET: why"]` (the
//! folder it reads, and what it checks there), so that `cargo test` reports it ignored,
//! with that reason, not passed, where the data may be absent; `scripts/test.sh` runs
//! them with `--include-ignored` when `../shared/data` is there.
//! Run by hand without the data, such a test returns at once after a note on standard
//! error naming it (written to the stream itself, which the harness does not capture).

use std::io::Write as _;
use std::path::{Path, PathBuf};

use ndarray::{Array2, s};

/// The VPR-Bench datasets of `../shared/data`, each a folder of `S_{technique}.npy`
/// (|DB| x |Q|, in the technique's own dtype) and `GT.npy`, with the number of queries
/// the paper's protocol calibrates on (10%).
pub const VPRBENCH: [(&str, usize); 2] = [("vprbench-corridor", 11), ("vprbench-spedtest", 60)];

/// The VPR-Bench techniques of each dataset: with the two Nordland HOG matrices (single
/// frame and an 11-frame sequence), the 22 real matrices the benches report on.
pub const TECHNIQUES: [&str; 10] = [
    "AMOSNet",
    "AlexNet_VPR",
    "CALC",
    "CoHOG",
    "HOG",
    "HybridNet",
    "NetVLAD",
    "RegionVLAD",
    "ap-gem-r101",
    "denseVLAD",
];

/// `../shared/data/rel`, or `None` (with the note) when `../shared/data` is absent.
pub fn shared(rel: &str) -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    if dir.is_dir() {
        return Some(dir.join(rel));
    }
    let thread = std::thread::current();
    let test = thread.name().unwrap_or("a test");
    let _ = writeln!(std::io::stderr(), "skipped {test}: ../shared/data is absent");
    None
}

/// Nordland HOG: the database (winter) and the first `n_q` query (summer)
/// descriptors, 756-D float32; `None` without `../shared/data`.
pub fn nordland(n_q: usize) -> Option<(Array2<f32>, Array2<f32>)> {
    // npyz, not the core's reader: the core's own unit tests use this crate, which
    // therefore does not depend on the core (a dependency back on it would build the
    // core before its unit tests, not beside them).
    let read = |name: &str| -> Option<Array2<f32>> {
        let bytes = std::fs::read(shared(name)?).unwrap();
        let npy = npyz::NpyFile::new(&bytes[..]).unwrap();
        assert_eq!(npy.order(), npyz::Order::C, "{name} is C order");
        let shape: Vec<usize> = npy.shape().iter().map(|&n| n as usize).collect();
        let values: Vec<f32> = npy.into_vec().unwrap();
        Some(Array2::from_shape_vec((shape[0], shape[1]), values).unwrap())
    };
    let (db, q) = (
        read("nordland-hog/db_winter.npy")?,
        read("nordland-hog/query_summer.npy")?,
    );
    assert_eq!((db.dim(), q.dim()), ((3576, 756), (3576, 756)));
    Some((db, q.slice(s![..n_q, ..]).to_owned()))
}
